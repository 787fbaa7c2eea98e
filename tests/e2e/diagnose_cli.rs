//! `motorbench diagnose` end to end: CSV files written from simulated
//! records with a known withheld effect, the contract's diagnosis JSON,
//! the residual SVG, and clear errors on data that cannot be diagnosed.

use crate::common;
use crate::common::dc_shapes;

use common::{motorbench, text};
use motorbench::diagnose::blind::{simulate_dc_case, simulate_im_case, write_case_files};
use motorbench::model::Effect;
use rand::rngs::StdRng;
use rand::SeedableRng;
use serde_json::Value;

fn args_of(files: &[std::path::PathBuf], nameplate: Option<&std::path::Path>) -> Vec<String> {
    let mut args: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    if let Some(p) = nameplate {
        args.push("--nameplate".into());
        args.push(p.display().to_string());
    }
    args
}

/// Check the contract's keys and the arithmetic between them.
fn check_contract(d: &Value) {
    let num = |v: &Value| v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"));
    for key in ["model", "params", "fit_nrmse", "validation_nrmse"] {
        assert!(d["nominal"].get(key).is_some(), "nominal.{key} missing");
    }
    let regions = d["gap"]["regions"].as_array().expect("gap.regions");
    assert!(!regions.is_empty());
    let mut total = 0.0;
    for r in regions {
        for key in ["channel", "axis", "from", "to", "label", "share"] {
            assert!(r.get(key).is_some(), "region.{key} missing in {r}");
        }
        // `voltage`: an additive extension, a no-load test's points.
        assert!(["time", "slip", "voltage"].contains(&r["axis"].as_str().unwrap()));
        let share = num(&r["share"]);
        assert!((0.0..=1.0 + 1e-9).contains(&share), "share of {r}");
        // The regions of one segment each partition the gap; a region
        // across segments (an oscillation seen in the spectrum) overlaps
        // them and is not counted in the partition.
        if r["label"] != "oscillation" {
            total += share;
        }
    }
    assert!(total <= 1.0 + 1e-9, "region shares sum to {total}");
    let candidates = d["candidates"].as_array().expect("candidates");
    assert!(!candidates.is_empty());
    for c in candidates {
        for key in ["effect", "params", "validation_nrmse", "shrink", "score"] {
            assert!(c.get(key).is_some(), "candidate.{key} missing in {c}");
        }
    }
    let v = &d["verdict"];
    let (before, after, shrink) = (
        num(&v["gap_before"]),
        num(&v["gap_after"]),
        num(&v["shrink"]),
    );
    assert!((shrink - (1.0 - after / before)).abs() < 1e-9);
    assert!((before - num(&d["nominal"]["validation_nrmse"])).abs() < 1e-12);
    let confidence = num(&v["confidence"]);
    assert!((0.0..=1.0).contains(&confidence));
}

#[test]
fn dc_record_with_brush_drop_is_diagnosed_from_csv() {
    let dir = tempfile::tempdir().unwrap();
    let case = simulate_dc_case(Some(Effect::BrushDrop), &mut StdRng::seed_from_u64(11));
    let (files, plate) = write_case_files(&case.record, dir.path()).unwrap();
    let svg = dir.path().join("residuals.svg");
    let mut args = vec![
        "diagnose".to_string(),
        "--kind".into(),
        "dc_step".into(),
        "--json".into(),
    ];
    args.extend(["--svg".into(), svg.display().to_string()]);
    args.extend(args_of(&files, plate.as_deref()));
    let out = motorbench(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let d: Value = serde_json::from_str(&stdout).unwrap();
    check_contract(&d);
    assert_eq!(d["kind"], "dc_step");
    assert_eq!(d["verdict"]["effect"], "brush_drop", "{stdout}");
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));

    // The text form says the same.
    args.retain(|a| a != "--json");
    let out = motorbench(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let (stdout, _) = text(&out);
    assert!(stdout.contains("verdict: brush_drop"), "{stdout}");
}

#[test]
fn im_record_with_iron_loss_is_diagnosed_from_csv() {
    let dir = tempfile::tempdir().unwrap();
    let case = simulate_im_case(Some(Effect::IronLoss), &mut StdRng::seed_from_u64(12));
    let (files, plate) = write_case_files(&case.record, dir.path()).unwrap();
    let mut args = vec![
        "diagnose".to_string(),
        "--kind".into(),
        "im_slip_sweep".into(),
        "--json".into(),
    ];
    args.extend(args_of(&files, plate.as_deref()));
    let out = motorbench(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let d: Value = serde_json::from_str(&stdout).unwrap();
    check_contract(&d);
    assert_eq!(d["verdict"]["effect"], "iron_loss", "{stdout}");
}

#[test]
fn data_that_cannot_be_diagnosed_gets_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    // One segment is cut into parts and diagnosed; one too short to cut
    // leaves nothing to hold out.
    let case = simulate_dc_case(None, &mut StdRng::seed_from_u64(13));
    let (files, _) = write_case_files(&case.record, dir.path()).unwrap();
    let one = files[0].display().to_string();
    let out = motorbench(&["diagnose", "--kind", "dc_step", "--json", &one]);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stdout.contains("the record holds its test in one driven segment"),
        "{stdout}"
    );
    let head: String = std::fs::read_to_string(&files[0])
        .unwrap()
        .lines()
        .take(80)
        .map(|l| format!("{l}\n"))
        .collect();
    let short = dir.path().join("short.csv");
    std::fs::write(&short, head).unwrap();
    let out = motorbench(&["diagnose", "--kind", "dc_step", short.to_str().unwrap()]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(
        stderr.contains("not enough data") && stderr.contains("record two or more segments"),
        "{stderr}"
    );

    // A malformed file: named with its line and column, exit 2.
    let bad = dir.path().join("bad.csv");
    std::fs::write(
        &bad,
        "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,1,x,0\n",
    )
    .unwrap();
    let out = motorbench(&["diagnose", "--kind", "dc_step", bad.to_str().unwrap(), &one]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.contains("bad.csv")
            && stderr.contains(":2")
            && stderr.contains("armature_current_A"),
        "{stderr}"
    );
}

/// `tests/data/dc_gap_fold`: two segments of a blind case (seed 2024,
/// case-12, a ramp staircase) whose second has a tenth of its samples cut
/// out (`scripts/robustness_sweep.py --seed 1`, perturbation `dropout`).
/// The gap cuts it in two; the short second part is the motor at rest,
/// its encoder reading 0 throughout, which no misfit can be measured
/// against. The diagnosis leaves that part out with a warning and
/// answers, with interleaved blocks held out, where it once refused the
/// whole record ("the nominal refit without segment 2 failed") and then
/// fell back to holding out whole segments.
#[test]
fn a_segment_that_cannot_be_held_out_is_left_out_not_the_record() {
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dc_gap_fold");
    let files = [data.join("segment-1.csv"), data.join("segment-5.csv")];
    let mut args = vec![
        "diagnose".to_string(),
        "--kind".into(),
        "dc_step".into(),
        "--json".into(),
    ];
    args.extend(args_of(&files, None));
    let out = motorbench(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let d: Value = serde_json::from_str(&stdout).unwrap();
    check_contract(&d);
    let warnings = d["warnings"].to_string();
    assert!(
        warnings.contains(
            "segment 2 (ramp to 31.6 V → 0 V short part 2/2) reads the same speed throughout"
        ),
        "{warnings}"
    );
    assert!(
        d["validation"]
            .as_str()
            .is_some_and(|v| v.starts_with("interleaved blocks")),
        "{stdout}"
    );
    assert!(!warnings.contains("held out instead"), "{warnings}");
    // A NaN reaches the JSON as null: only an undetermined interval may be.
    assert_eq!(nulls_but_intervals(&d), Vec::<String>::new(), "{stdout}");
}

/// The paths of `v`'s nulls other than `ci95` (an undetermined interval).
fn nulls_but_intervals(v: &Value) -> Vec<String> {
    fn walk(v: &Value, path: &str, out: &mut Vec<String>) {
        match v {
            Value::Object(m) => {
                for (k, x) in m {
                    if x.is_null() && k != "ci95" {
                        out.push(format!("{path}.{k}"));
                    }
                    walk(x, &format!("{path}.{k}"), out);
                }
            }
            Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    walk(x, &format!("{path}[{i}]"), out);
                }
            }
            _ => {}
        }
    }
    let mut out = Vec::new();
    walk(v, "", &mut out);
    out
}

#[test]
fn records_of_every_shape_are_identified_and_diagnosed() {
    let false_verdicts = identify_and_diagnose_every_shape();
    eprintln!("false verdicts (issue 13, open): {false_verdicts:?}");
}

#[test]
#[ignore = "open (issue 13): measured 3 false verdicts of 6 effect-free shapes \
            (table2: shaft_compliance, prbs: sensor_lag, speed_loop: thermal_drift) \
            before the verdict rules (e), (f) of docs/diagnosis-dc.md; not re-measured since"]
fn effect_free_records_of_every_shape_get_no_false_verdict() {
    let false_verdicts = identify_and_diagnose_every_shape();
    assert!(false_verdicts.is_empty(), "{false_verdicts:?}");
}

/// Short holds, a ringing motor, a ramp, a PRBS, a closed speed loop, all
/// effect-free: identification gives K within 1 % and Ra within 3 %
/// (asserted), and the diagnosis runs on each with a report the contract
/// accepts (asserted). Returns the diagnoses that named an effect.
fn identify_and_diagnose_every_shape() -> Vec<String> {
    let mut wrong = Vec::new();
    let mut false_verdicts = Vec::new();
    for (name, truth, drive) in dc_shapes::shapes() {
        let dir = tempfile::tempdir().unwrap();
        let record = dc_shapes::record(&truth, &drive, 5);
        let files = dc_shapes::write_csvs(&record, dir.path());
        // `motorbench COMMAND --kind dc_step --json FILES…`, its JSON.
        let json_of = |command: &str| -> Value {
            let mut args = vec![command.to_string(), "--kind".into(), "dc_step".into()];
            args.push("--json".into());
            args.extend(args_of(&files, None));
            let out = motorbench(&args.iter().map(String::as_str).collect::<Vec<_>>());
            let (stdout, stderr) = text(&out);
            assert!(out.status.success(), "{name} {command}: {stderr}");
            serde_json::from_str(&stdout).unwrap()
        };
        // Identification: equation error and output error both apply.
        let id = json_of("identify");
        for method in ["equation_error", "output_error"] {
            let m = &id["methods"][method];
            assert_eq!(m["applies"], true, "{name} {method}: {m}");
            let value = |key: &str| m["params"][key]["value"].as_f64().unwrap();
            let (k, ra) = (
                (value("K") - truth.k) / truth.k,
                (value("Ra") - truth.ra) / truth.ra,
            );
            eprintln!(
                "{name:>15} {method:>15}: K {:+.3} %, Ra {:+.3} %",
                100.0 * k,
                100.0 * ra
            );
            if k.abs() > 0.01 || ra.abs() > 0.03 {
                wrong.push(format!(
                    "{name} {method}: K {:+.2} %, Ra {:+.2} %",
                    100.0 * k,
                    100.0 * ra
                ));
            }
        }
        let d = json_of("diagnose");
        check_contract(&d);
        let verdict = d["verdict"]["effect"].as_str().unwrap_or("?").to_string();
        eprintln!("{name:>15} diagnosis: {verdict}");
        if verdict != "none" {
            false_verdicts.push(format!("{name}: {verdict}"));
        }
    }
    assert!(wrong.is_empty(), "{wrong:?}");
    false_verdicts
}

#[test]
fn an_implausible_current_names_the_file_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let (_, truth, drive) = dc_shapes::shapes().swap_remove(0);
    let mut record = dc_shapes::record(&truth, &drive, 5);
    record.segments[1].current[9] = 1e308;
    let files = dc_shapes::write_csvs(&record, dir.path());
    let mut args = vec!["diagnose".to_string(), "--kind".into(), "dc_step".into()];
    args.extend(args_of(&files, None));
    let out = motorbench(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("segment-1.csv")
            && stderr.contains("armature_current_A")
            && stderr.contains("1e308"),
        "{stderr}"
    );
}

/// A record longer than the diagnosis reads (a 40 s PRBS at 2 kHz, 80 001
/// samples in three segments) is diagnosed from windows spread over it,
/// and the report says how many samples it read and where.
#[test]
fn a_long_record_is_diagnosed_from_windows_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let truth = motorbench::model::DcParams::SEED_TABLE4_MOMENTS;
    // A pseudo-random 80 V / 220 V square wave, clocked every 20 ms.
    let prbs = |t: f64| {
        let clock = (t / 0.02) as u64;
        if (clock.wrapping_mul(2_654_435_761) >> 13) & 1 == 1 {
            220.0
        } else {
            80.0
        }
    };
    let record = dc_shapes::record(&truth, &dc_shapes::Drive::Open(Box::new(prbs), 40.0), 3);
    let samples: usize = record.segments.iter().map(|s| s.time.len()).sum();
    assert!(samples > 65_536, "{samples}");
    let files = dc_shapes::write_csvs(&record, dir.path());
    let mut args = vec!["diagnose", "--kind", "dc_step", "--json"];
    args.extend(files.iter().map(|f| f.to_str().unwrap()));
    let out = motorbench(&args);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let d: Value = serde_json::from_str(&stdout).unwrap();
    check_contract(&d);
    let note = d["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .find(|w| w.contains("more than the diagnosis reads"))
        .unwrap_or_else(|| panic!("{}", d["warnings"]));
    assert!(
        note.contains(&format!("the record holds {samples} samples")),
        "{note}"
    );
    assert_eq!(d["verdict"]["effect"], "none", "{}", d["verdict"]);
}
