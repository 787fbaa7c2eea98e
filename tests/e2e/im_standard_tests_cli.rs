//! `motorbench identify` on the induction machine's standard tests end to
//! end: CSV files of a DC-resistance reading, a no-load test at nine
//! voltages and a locked-rotor test at four (simulated from a known
//! single-cage circuit with core loss and friction, 0.1 % meter errors),
//! with and without a slip sweep beside them, in; method `standard_tests`
//! with every element's interval covering its truth, the tables, and the
//! other methods unchanged, out. A missing test makes the method not apply
//! with its reason; a bad file is refused with file, line and column.

use crate::common;

use std::path::{Path, PathBuf};

use common::{motorbench, text};
use motorbench::identify::{slip_grid, SlipSweep, SweepNoise};
use motorbench::model::{
    locked_rotor_reading, no_load_reading, terminal_resistance, Connection, ImCircuit, ImSupply,
    RotorCage,
};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const PFW: f64 = 45.0;

/// Star, 400 V, 50 Hz, Xs = Xr.
fn machine() -> ImCircuit {
    ImCircuit {
        rs: 0.9,
        xs: 1.8,
        xm: 60.0,
        rfe: Some(900.0),
        rotor: RotorCage::Single { rr: 1.1, xr: 1.8 },
    }
}

struct Files {
    dc: PathBuf,
    no_load: PathBuf,
    locked: PathBuf,
    sweep: PathBuf,
    nameplate: PathBuf,
}

fn write_tests(dir: &Path) -> Files {
    let mut rng = StdRng::seed_from_u64(3);
    let noise = Normal::new(0.0, 0.001).unwrap();
    let mut read = |v: f64| v * (1.0 + noise.sample(&mut rng));
    let c = machine();
    let conn = Connection::Star;
    let r_ll = terminal_resistance(c.rs, conn);
    let mut dc = String::from(
        "# motorbench segment 0 kind=im_dc_resistance label=cold winding\n\
         dc_voltage_V,dc_current_A,winding_temperature_C\n",
    );
    for i in [2.0, 4.0, 6.0, 8.0] {
        dc.push_str(&format!("{},{i},22.0\n", read(r_ll * i)));
    }
    let mut nl = String::from(
        "# motorbench segment 1 kind=im_no_load label=no load\n\
         line_voltage_V,line_current_A,input_power_W,frequency_Hz,winding_temperature_C\n",
    );
    for v in [440.0, 400.0, 360.0, 300.0, 240.0, 200.0, 160.0, 120.0, 80.0] {
        let r = no_load_reading(&c, conn, v, PFW).unwrap();
        nl.push_str(&format!(
            "{},{},{},50,22.0\n",
            read(r.line_voltage),
            read(r.line_current),
            read(r.input_power)
        ));
    }
    let mut lr = String::from(
        "# motorbench segment 2 kind=im_locked_rotor label=locked rotor\n\
         line_voltage_V,line_current_A,input_power_W,frequency_Hz,winding_temperature_C\n",
    );
    for v in [30.0, 45.0, 60.0, 75.0] {
        let r = locked_rotor_reading(&c, conn, v, 50.0, 50.0);
        lr.push_str(&format!(
            "{},{},{},50,22.0\n",
            read(r.line_voltage),
            read(r.line_current),
            read(r.input_power)
        ));
    }
    let sweep = sweep_text(&load_test(&c), "load", None);
    let files = Files {
        dc: dir.join("dc.csv"),
        no_load: dir.join("no_load.csv"),
        locked: dir.join("locked_rotor.csv"),
        sweep: dir.join("sweep.csv"),
        nameplate: dir.join("nameplate.json"),
    };
    std::fs::write(&files.dc, dc).unwrap();
    std::fs::write(&files.no_load, nl).unwrap();
    std::fs::write(&files.locked, lr).unwrap();
    std::fs::write(&files.sweep, sweep).unwrap();
    std::fs::write(
        &files.nameplate,
        r#"{"voltage_V": 400, "current_A": 8, "frequency_Hz": 50, "poles": 4, "connection": "star", "design": "A"}"#,
    )
    .unwrap();
    files
}

/// A 30-point load test of `c` at 400 V, 0.1 % meter errors.
fn load_test(c: &ImCircuit) -> SlipSweep {
    let supply = ImSupply {
        line_voltage: 400.0,
        frequency: 50.0,
        connection: Connection::Star,
        pole_pairs: 2,
    };
    SlipSweep::simulate(
        c,
        &supply,
        &slip_grid(30, 0.005),
        &SweepNoise::relative(0.001),
        3,
        &mut StdRng::seed_from_u64(5),
    )
}

/// `sw` as segment 3's CSV file, every point at `temperature` °C where
/// given (column `winding_temperature_C`).
fn sweep_text(sw: &SlipSweep, label: &str, temperature: Option<f64>) -> String {
    let mut text = format!(
        "# motorbench segment 3 kind=im_slip_sweep label={label}\n\
         slip,line_voltage_V,line_current_A,input_power_W{}\n",
        if temperature.is_some() {
            ",winding_temperature_C"
        } else {
            ""
        }
    );
    for p in &sw.points {
        text.push_str(&format!(
            "{},{},{},{}{}\n",
            p.slip,
            p.line_voltage,
            p.line_current,
            p.input_power,
            temperature.map_or(String::new(), |t| format!(",{t}"))
        ));
    }
    text
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `motorbench identify ARGS`, which must succeed; its stdout.
fn identify(args: &[&str]) -> String {
    succeeds("identify", args)
}

/// `motorbench COMMAND ARGS`, which must succeed; its stdout.
fn succeeds(command: &str, args: &[&str]) -> String {
    let out = motorbench(&[&[command], args].concat());
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    stdout
}

#[test]
fn standard_tests_from_csv_recover_the_circuit_with_intervals() {
    let dir = tempfile::tempdir().unwrap();
    let f = write_tests(dir.path());
    let stdout = identify(&[
        "--kind",
        "im_no_load",
        s(&f.dc),
        s(&f.no_load),
        s(&f.locked),
        "--nameplate",
        s(&f.nameplate),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    // The joint fit of the three tests (no load test here) is the best.
    assert_eq!(v["best"], "joint", "{v}");
    assert_eq!(v["methods"]["lm"]["applies"], false);
    let m = &v["methods"]["standard_tests"];
    assert_eq!(m["applies"], true, "{m}");
    for (key, truth, unit) in [
        ("Rs", 0.9, "ohm"),
        ("Xs", 1.8, "ohm"),
        ("Xr", 1.8, "ohm"),
        ("Rr", 1.1, "ohm"),
        ("Xm", 60.0, "ohm"),
        ("Rfe", 900.0, "ohm"),
        ("Pfw", PFW, "W"),
    ] {
        let p = &m["params"][key];
        let (lo, hi) = (
            p["ci95"][0].as_f64().unwrap(),
            p["ci95"][1].as_f64().unwrap(),
        );
        eprintln!("{key}: {} [{lo}, {hi}] (true {truth})", p["value"]);
        assert!(
            lo <= truth && truth <= hi,
            "{key}: {truth} outside [{lo}, {hi}]"
        );
        assert_eq!(p["unit"], unit);
    }
    // The joint fit from the reduction, Rs bounded by the DC reading: to
    // 1 % of every element (0.1 % meter errors).
    let joint = &v["methods"]["joint"];
    for (key, truth) in [
        ("Rs", 0.9),
        ("Xs", 1.8),
        ("Xr", 1.8),
        ("Rr", 1.1),
        ("Xm", 60.0),
        ("Rfe", 900.0),
        ("Pfw", PFW),
    ] {
        let got = joint["params"][key]["value"].as_f64().unwrap();
        eprintln!(
            "joint {key}: {got} {} (true {truth})",
            joint["params"][key]["ci95"]
        );
        assert!(
            (got / truth - 1.0).abs() < 0.01,
            "joint {key}: {got} vs {truth}"
        );
    }
    let tables = &v["standard_tests"];
    assert_eq!(tables["no_load"].as_array().unwrap().len(), 9);
    assert_eq!(tables["locked_rotor"].as_array().unwrap().len(), 4);
    assert!(tables["xm_curve"]["coefficients"].is_array());
    let warnings = v["warnings"].as_array().unwrap();
    assert!(warnings
        .iter()
        .any(|w| w.as_str().unwrap().contains("Xs/(Xs + Xr) = 0.5")));

    // The text report prints the tables.
    let stdout = identify(&[
        "--kind",
        "im_no_load",
        s(&f.dc),
        s(&f.no_load),
        s(&f.locked),
        "--nameplate",
        s(&f.nameplate),
    ]);
    assert!(
        stdout.contains("joint  (best)")
            && stdout.contains("standard_tests\n")
            && stdout.contains("no load (per phase)")
            && stdout.contains("locked rotor (per phase)")
            && stdout.contains("Xm(V) =")
            && stdout.contains("Pfw"),
        "{stdout}"
    );
}

#[test]
fn beside_a_sweep_every_method_runs_and_a_missing_test_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let f = write_tests(dir.path());
    let stdout = identify(&[
        "--kind",
        "im_slip_sweep",
        s(&f.sweep),
        s(&f.dc),
        s(&f.no_load),
        "--nameplate",
        s(&f.nameplate),
        "--model",
        "single-fe",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["best"], "lm", "{v}");
    assert_eq!(v["methods"]["lm"]["applies"], true);
    let m = &v["methods"]["standard_tests"];
    assert_eq!(m["applies"], false);
    assert!(
        m["reason"]
            .as_str()
            .unwrap()
            .contains("no im_locked_rotor segment"),
        "{m}"
    );
    assert!(v.get("standard_tests").is_none());
}

#[test]
fn a_bad_standard_test_file_is_refused_with_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lr.csv");
    std::fs::write(
        &path,
        "# motorbench segment 2 kind=im_locked_rotor\n\
         line_voltage_V,line_current_A,input_power_W\n60,8,300\n60,-8,300\n",
    )
    .unwrap();
    let out = motorbench(&["identify", "--kind", "im_slip_sweep", s(&path)]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("lr.csv:4")
            && stderr.contains("line_current_A")
            && stderr.contains("must be > 0"),
        "{stderr}"
    );
}

/// The load test's sweep file carries each point's winding temperature
/// (`winding_temperature_C`): the load test ran with the winding at
/// 80 °C, the other tests at 22 °C. The joint fit sees Rs scaled to each
/// point's temperature and reports it at the locked-rotor test's; the
/// same file without the column leaves the warm winding's copper
/// unexplained. The diagnosis, given every point's temperature, scales
/// its Rs the same way.
#[test]
fn a_warm_load_test_with_its_temperatures_keeps_the_joint_rs_at_the_other_tests() {
    use motorbench::machine::im::COPPER_ALPHA;
    let dir = tempfile::tempdir().unwrap();
    let f = write_tests(dir.path());
    let cold = machine();
    let warm = ImCircuit {
        rs: cold.rs * (1.0 + COPPER_ALPHA * 58.0),
        ..cold
    };
    let sw = load_test(&warm);
    let write = |name: &str, temperature: Option<f64>| {
        let path = dir.path().join(name);
        std::fs::write(&path, sweep_text(&sw, "load, warm", temperature)).unwrap();
        path
    };
    let run = |command: &str, sweep: &Path| {
        let stdout = succeeds(
            command,
            &[
                "--kind",
                "im_slip_sweep",
                s(sweep),
                s(&f.dc),
                s(&f.no_load),
                s(&f.locked),
                "--nameplate",
                s(&f.nameplate),
                "--json",
            ],
        );
        serde_json::from_str::<serde_json::Value>(&stdout).unwrap()
    };
    let joint = |sweep: &Path| {
        let v = run("identify", sweep);
        assert_eq!(v["methods"]["joint"]["applies"], true, "{v}");
        v
    };
    let marked = joint(&write("warm.csv", Some(80.0)));
    let rs = marked["methods"]["joint"]["params"]["Rs"]["value"]
        .as_f64()
        .unwrap();
    assert!(
        (rs / cold.rs - 1.0).abs() < 0.01,
        "joint Rs {rs}, truth {}",
        cold.rs
    );
    let warnings = marked["warnings"].to_string();
    assert!(warnings.contains("so does each load point"), "{warnings}");
    let unmarked = joint(&write("warm_unmarked.csv", None));
    let rs_unmarked = unmarked["methods"]["joint"]["params"]["Rs"]["value"]
        .as_f64()
        .unwrap();
    println!(
        "joint Rs with the points' temperatures {rs:.5}, without {rs_unmarked:.5}, truth {}",
        cold.rs
    );
    assert!(
        (rs_unmarked / cold.rs - 1.0).abs() > 3.0 * (rs / cold.rs - 1.0).abs().max(0.001),
        "without the temperatures Rs {rs_unmarked}, with them {rs}, truth {}",
        cold.rs
    );

    // The diagnosis: with every point's temperature the stator's heating
    // is known, and its Rs is the resistance at the first point's (the
    // no-load test's 22 °C).
    let diagnosed = run("diagnose", &dir.path().join("warm.csv"));
    let warnings = diagnosed["warnings"].to_string();
    assert!(
        warnings.contains("follows the winding thermometer (22.0 to 80.0 °C"),
        "{warnings}"
    );
    // The record has core loss, which the nominal circuit can only put
    // into Rs: the verdict's corrected Rs is the one to compare.
    let corrected = |v: &serde_json::Value| {
        v["verdict"]["corrected_params"]["Rs"]["corrected"]
            .as_f64()
            .unwrap_or(f64::NAN)
    };
    let rs = corrected(&diagnosed);
    let unmarked = run("diagnose", &dir.path().join("warm_unmarked.csv"));
    assert!(
        unmarked["warnings"].to_string().contains("is on 13 of the"),
        "{unmarked}"
    );
    let rs_unmarked = corrected(&unmarked);
    println!(
        "diagnosis' corrected Rs with the points' temperatures {rs:.5} (verdict {}), without \
         {rs_unmarked:.5} (verdict {}), truth {}",
        diagnosed["verdict"]["effect"], unmarked["verdict"]["effect"], cold.rs
    );
    assert!((rs / cold.rs - 1.0).abs() < 0.02, "diagnosis' Rs {rs}");
    assert!(
        (rs_unmarked / cold.rs - 1.0).abs() > 2.0 * (rs / cold.rs - 1.0).abs(),
        "without the temperatures Rs {rs_unmarked}, with them {rs}"
    );
}
