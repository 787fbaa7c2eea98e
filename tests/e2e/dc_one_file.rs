//! A DC record as a lab often keeps it — the whole staircase in one CSV
//! file — and the same file spoiled the ways real files are (a current
//! sensor mounted the other way round, an ADC that clips), through
//! `motorbench identify` and `diagnose`: the one file is cut at its
//! voltage steps and identified like the segmented record; a reversed
//! channel is refused naming the column; a clipping one is warned of.

use std::fmt::Write;
use std::path::{Path, PathBuf};

use crate::common;

use motorbench::bench::Outcome;
use motorbench::config::Config;
use motorbench::record::Record;

/// The record's segments (coast-down included) as one CSV file, with
/// each reading passed through `spoil(channel, value)` (channel 1 current,
/// 2 speed).
fn one_file(record: &Record, dir: &Path, name: &str, spoil: impl Fn(usize, f64) -> f64) -> PathBuf {
    let mut text = String::from("time_s,armature_voltage_V,armature_current_A,speed_rad_s\n");
    let mut last = f64::NEG_INFINITY;
    for seg in &record.segments {
        // Segments that share their boundary sample give it once.
        for k in (0..seg.time.len()).filter(|&k| seg.time[k] > last) {
            writeln!(
                text,
                "{:?},{:?},{:?},{:?}",
                seg.time[k],
                seg.voltage[k],
                spoil(1, seg.current[k]),
                spoil(2, seg.speed[k])
            )
            .unwrap();
        }
        last = seg.time[seg.time.len() - 1];
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn run(args: &[&str]) -> (bool, String, String) {
    let out = common::motorbench(args);
    let (stdout, stderr) = common::text(&out);
    (out.status.success(), stdout, stderr)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_staircase_in_one_csv_file_is_cut_at_its_steps_and_identified() {
    let config = Config::embedded_default();
    let truth = config.backend.simulated().expect("a simulated rig").motor;
    let (dir, done) = common::dry_run::commission(&config).await;
    assert_eq!(done.outcome, Outcome::Completed);
    let driven = done.record.segments.len() - 1; // the last is the coast-down
    let file = one_file(&done.record, dir.path(), "lab.csv", |_, v| v);
    let file = file.to_str().unwrap();

    let (ok, json, stderr) = run(&["identify", "--kind", "dc_step", "--json", file]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let warnings = v["warnings"].to_string();
    let note = format!("before each of its {driven} voltage steps");
    assert!(warnings.contains(&note), "{warnings}");
    // The level methods apply again, and held-out validation is computed.
    for method in [
        "steady_state",
        "equation_error",
        "moments",
        "coastdown",
        "output_error",
    ] {
        assert_eq!(
            v["methods"][method]["applies"], true,
            "{method}: {}",
            v["methods"][method]
        );
    }
    let oe = &v["methods"]["output_error"];
    assert!(oe["validation_nrmse"].is_number(), "{oe}");
    let value = |p: &str| oe["params"][p]["value"].as_f64().unwrap();
    assert!(
        (value("K") / truth.k - 1.0).abs() < 0.01,
        "K {}",
        value("K")
    );
    assert!(
        (value("Ra") / truth.ra - 1.0).abs() < 0.03,
        "Ra {}",
        value("Ra")
    );

    let (ok, json, stderr) = run(&["diagnose", "--kind", "dc_step", "--json", file]);
    assert!(ok, "{stderr}");
    let d: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(d["verdict"]["effect"].is_string(), "{d}");
    assert!(d["warnings"].to_string().contains(&note), "{d}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reversed_current_is_refused_and_a_clipping_current_is_warned_of() {
    let (dir, done) = common::dry_run::commission(&Config::embedded_default()).await;
    assert_eq!(done.outcome, Outcome::Completed);

    let reversed = one_file(&done.record, dir.path(), "reversed.csv", |c, v| {
        if c == 1 {
            -v
        } else {
            v
        }
    });
    let (ok, _, stderr) = run(&["identify", "--kind", "dc_step", reversed.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        stderr.contains("reversed.csv")
            && stderr.contains("column armature_current_A")
            && stderr.contains("polarity reversed"),
        "{stderr}"
    );

    // An ADC at 60 % of the step's current peak.
    let peak = done
        .record
        .segments
        .iter()
        .flat_map(|s| s.current.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let clip = 0.6 * peak;
    let clipped = one_file(&done.record, dir.path(), "clipped.csv", |c, v| {
        if c == 1 {
            v.clamp(-clip, clip)
        } else {
            v
        }
    });
    let (ok, json, stderr) = run(&[
        "identify",
        "--kind",
        "dc_step",
        "--json",
        clipped.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let warnings =
        serde_json::from_str::<serde_json::Value>(&json).unwrap()["warnings"].to_string();
    assert!(
        warnings.contains("column armature_current_A repeats its largest magnitude")
            && warnings.contains("clips"),
        "{warnings}"
    );
}
