//! `motorbench identify --kind im_slip_sweep` end to end: CSV files of a
//! simulated double-cage machine (two sweeps, at 230 V and 180 V, delta) in,
//! the contract JSON, the text report and the SVG out; bad input refused
//! with file, line and column.

use crate::common;

use std::path::{Path, PathBuf};

use common::{motorbench, text};
use motorbench::identify::{slip_grid, SlipSweep, SweepNoise};
use motorbench::model::{
    with_leakage_split, Connection, ImCircuit, ImSupply, LeakageSplit, SEED_DOUBLE_CAGE_PU,
};
use rand::rngs::StdRng;
use rand::SeedableRng;

fn machine() -> ImCircuit {
    // The seed paper's double cage on a 230 V delta, 4 kW base (Z_base ≈ 33 Ω).
    SEED_DOUBLE_CAGE_PU.scaled(33.0)
}

fn write_sweeps(dir: &Path) -> Vec<PathBuf> {
    let mut rng = StdRng::seed_from_u64(4);
    let mut files = Vec::new();
    for (k, v) in [230.0, 180.0].into_iter().enumerate() {
        let supply = ImSupply {
            line_voltage: v,
            frequency: 50.0,
            connection: Connection::Delta,
            pole_pairs: 2,
        };
        let sw = SlipSweep::simulate(
            &machine(),
            &supply,
            &slip_grid(40, 0.002),
            &SweepNoise::relative(0.003),
            0,
            &mut rng,
        );
        let mut csv = format!("# motorbench segment {k} kind=im_slip_sweep label={v} V\nslip,line_voltage_V,line_current_A,input_power_W,frequency_Hz\n");
        for p in &sw.points {
            csv.push_str(&format!(
                "{},{},{},{},50\n",
                p.slip, p.line_voltage, p.line_current, p.input_power
            ));
        }
        let path = dir.join(format!("sweep{k}.csv"));
        std::fs::write(&path, csv).unwrap();
        files.push(path);
    }
    files
}

#[test]
fn identify_double_cage_from_csv_json_text_and_svg() {
    let dir = tempfile::tempdir().unwrap();
    let files = write_sweeps(dir.path());
    let f: Vec<&str> = files.iter().map(|p| p.to_str().unwrap()).collect();
    let out = motorbench(&[
        "identify",
        "--kind",
        "im_slip_sweep",
        f[0],
        f[1],
        "--connection",
        "delta",
        "--model",
        "double",
        "--json",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["kind"], "im_slip_sweep");
    assert_eq!(v["best"], "lm");
    assert!(v["methods"]["recursive"]["applies"].is_boolean());
    let lm = &v["methods"]["lm"];
    assert!(lm["validation_nrmse"].as_f64().unwrap() < 0.02, "{lm}");
    // The reported circuit is the conventional member of the machine's
    // family (Xs = Xr at standstill): every interval covers it.
    let conv = with_leakage_split(&machine(), LeakageSplit::default()).unwrap();
    for key in ["Rs", "Xs", "Xm", "Rr1", "Rr2", "Xr1", "Xr2"] {
        let p = &lm["params"][key];
        let truth = conv
            .get(motorbench::model::ImParam::parse(key).unwrap())
            .unwrap();
        let (lo, hi) = (
            p["ci95"][0].as_f64().unwrap(),
            p["ci95"][1].as_f64().unwrap(),
        );
        assert!(
            lo <= truth && truth <= hi,
            "{key}: {truth} outside [{lo}, {hi}]"
        );
        assert_eq!(p["unit"], "ohm");
    }
    assert!(v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w.as_str().unwrap().contains("convention")));

    let svg = dir.path().join("sweep.svg");
    let out = motorbench(&[
        "identify",
        "--kind",
        "im_slip_sweep",
        f[0],
        f[1],
        "--connection",
        "delta",
        "--model",
        "double",
        "--svg",
        svg.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stdout.contains("lm  (best)")
            && stdout.contains("p.u.")
            && stdout.contains("by convention"),
        "{stdout}"
    );
    assert!(stdout.contains("correlation"), "{stdout}");
    assert!(std::fs::read_to_string(&svg).unwrap().starts_with("<svg"));
}

#[test]
fn bad_sweep_csv_is_refused_with_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.csv");
    std::fs::write(
        &path,
        "slip,line_voltage_V,line_current_A,input_power_W\n0.1,400,3,100\n1.2,400,3,100\n",
    )
    .unwrap();
    let out = motorbench(&[
        "identify",
        "--kind",
        "im_slip_sweep",
        path.to_str().unwrap(),
    ]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("bad.csv:3")
            && stderr.contains("slip")
            && stderr.contains("outside [0, 1]"),
        "{stderr}"
    );
}

/// A lab measures speed, not slip: the same sweeps with `speed_rpm` in
/// place of `slip` (4 poles at 50 Hz, from the nameplate) identify the
/// same circuit as with the slip.
#[test]
fn a_speed_column_with_the_nameplates_poles_identifies_like_the_slip() {
    let dir = tempfile::tempdir().unwrap();
    let files = write_sweeps(dir.path());
    let plate = dir.path().join("nameplate.json");
    std::fs::write(&plate, r#"{"poles": 4, "frequency_Hz": 50.0}"#).unwrap();
    let mut speed_files = Vec::new();
    for (k, f) in files.iter().enumerate() {
        let text = std::fs::read_to_string(f).unwrap();
        let mut out = String::new();
        for line in text.lines() {
            let converted = match line.split_once(',') {
                Some(("slip", rest)) => format!("speed_rpm,{rest}"),
                Some((s, rest)) if !line.starts_with('#') => {
                    let slip: f64 = s.parse().unwrap();
                    format!("{},{rest}", (1.0 - slip) * 1500.0)
                }
                _ => line.to_string(),
            };
            out.push_str(&converted);
            out.push('\n');
        }
        let path = dir.path().join(format!("speed{k}.csv"));
        std::fs::write(&path, out).unwrap();
        speed_files.push(path);
    }
    let identify = |files: &[PathBuf]| {
        let mut args = vec!["identify", "--kind", "im_slip_sweep", "--json"];
        args.extend(["--connection", "delta", "--model", "double"]);
        args.extend(["--nameplate", plate.to_str().unwrap()]);
        args.extend(files.iter().map(|p| p.to_str().unwrap()));
        let out = motorbench(&args);
        let (stdout, stderr) = text(&out);
        assert!(out.status.success(), "{stderr}");
        serde_json::from_str::<serde_json::Value>(&stdout).unwrap()
    };
    let (by_slip, by_speed) = (identify(&files), identify(&speed_files));
    assert_eq!(by_slip["best"], by_speed["best"]);
    let lm = |v: &serde_json::Value| v["methods"]["lm"]["params"].clone();
    let (a, b) = (lm(&by_slip), lm(&by_speed));
    let a = a.as_object().unwrap();
    assert!(!a.is_empty(), "{by_slip}");
    for (key, p) in a {
        let (x, y) = (
            p["value"].as_f64().unwrap(),
            b[key]["value"].as_f64().unwrap(),
        );
        assert!(
            (x - y).abs() <= 1e-6 * x.abs(),
            "{key}: {x} by slip, {y} by speed"
        );
    }
    // Without the poles the file says what it needs.
    let out = motorbench(&[
        "identify",
        "--kind",
        "im_slip_sweep",
        speed_files[0].to_str().unwrap(),
    ]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("column speed_rpm") && stderr.contains("poles"),
        "{stderr}"
    );
}
