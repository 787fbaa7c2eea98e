//! `motorbench export`: a fresh record's segments as contract CSV give,
//! through `motorbench identify`, the report the run wrote; its channels
//! as Parquet read in pandas in one call, a column per channel and the
//! segment index, the same numbers as the CSV files.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common;

/// Runs the seed's short DC test; returns its record and report.
fn fresh_dc_record(dir: &Path) -> (PathBuf, PathBuf) {
    fresh_record("tests/mcap_corpus/seed.toml", dir)
}

/// Runs the test of `config` (from the repository root) without the
/// diagnosis; returns its record and report.
fn fresh_record(config: &str, dir: &Path) -> (PathBuf, PathBuf) {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join(config);
    let run = common::motorbench(&[
        "run",
        "--config",
        config.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--quiet",
        "--no-diagnose",
    ]);
    assert!(run.status.success(), "{}", common::text(&run).1);
    let find = |suffix: &str| {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.to_string_lossy().ends_with(suffix))
            .unwrap_or_else(|| panic!("run wrote no *{suffix}"))
    };
    (find(".mcap"), find(".report.json"))
}

/// `motorbench export … --json`: the files and the identify command.
fn export(record: &Path, out: &Path, format: &str) -> serde_json::Value {
    let run = common::motorbench(&[
        "export",
        record.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--format",
        format,
        "--json",
    ]);
    assert!(run.status.success(), "{}", common::text(&run).1);
    serde_json::from_slice(&run.stdout).unwrap()
}

/// The report file a run wrote, without its `provenance`.
fn recorded_without_provenance(report: &Path) -> serde_json::Value {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("provenance");
    v
}

/// Runs the `identify` command `export` printed, with `--json`.
fn identify_as_told(exported: &serde_json::Value) -> serde_json::Value {
    let identify: Vec<String> = exported["identify"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap().to_string())
        .collect();
    assert_eq!(identify[..3], ["motorbench", "identify", "--kind"]);
    let mut args: Vec<&str> = identify[1..].iter().map(String::as_str).collect();
    args.push("--json");
    let run = common::motorbench(&args);
    assert!(run.status.success(), "{}", common::text(&run).1);
    serde_json::from_slice(&run.stdout).unwrap()
}

#[test]
fn export_to_csv_then_identify_gives_the_report_of_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let (record, report) = fresh_dc_record(dir.path());
    let out = dir.path().join("export");
    let exported = export(&record, &out, "csv");
    let files = exported["files"].as_array().unwrap();
    assert_eq!(
        files.len(),
        4,
        "three segments and the nameplate: {files:?}"
    );
    assert_eq!(exported["identify"][3], "dc_step");
    let from_csv = identify_as_told(&exported);
    assert!(from_csv["methods"]["output_error"]["applies"] == true);
    assert_eq!(from_csv, recorded_without_provenance(&report));
}

#[test]
fn an_im_export_identifies_to_the_report_of_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let (record, report) = fresh_record("config/sim-im.toml", dir.path());
    let exported = export(&record, &dir.path().join("export"), "csv");
    assert_eq!(exported["identify"][5], "double", "the configured circuit");
    let from_csv = identify_as_told(&exported);
    assert!(from_csv["methods"]["lm"]["params"]["Rr2"]["value"].is_number());
    assert_eq!(from_csv, recorded_without_provenance(&report));
}

/// A record of the standard tests (DC resistance, no load, locked rotor,
/// load sweeps): every test is a CSV file of its own kind, and the CSV set
/// identifies to the run's report (the classical reduction and the joint
/// fit included).
#[test]
fn a_standard_tests_export_keeps_every_test() {
    let dir = tempfile::tempdir().unwrap();
    let (record, report) = fresh_record("config/sim-im-standard.toml", dir.path());
    let exported = export(&record, &dir.path().join("export"), "csv");
    let kinds: Vec<String> = exported["files"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|f| f.as_str().filter(|f| f.ends_with(".csv")))
        .map(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            let first = text.lines().next().unwrap().to_string();
            first
                .split("kind=")
                .nth(1)
                .unwrap()
                .split(' ')
                .next()
                .unwrap()
                .to_string()
        })
        .collect();
    for kind in [
        "im_dc_resistance",
        "im_no_load",
        "im_locked_rotor",
        "im_slip_sweep",
    ] {
        assert!(
            kinds.iter().any(|k| k == kind),
            "{kind} missing from {kinds:?}"
        );
    }
    let from_csv = identify_as_told(&exported);
    assert!(from_csv["methods"]["standard_tests"]["params"]["Pfw"]["value"].is_number());
    assert_eq!(from_csv, recorded_without_provenance(&report));
}

#[test]
fn parquet_reads_in_pandas_in_one_call_with_the_csv_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let (record, _) = fresh_dc_record(dir.path());
    let out = dir.path().join("export");
    let exported = export(&record, &out, "all");
    let parquet = exported["files"][0].as_str().unwrap().to_string();
    assert!(parquet.ends_with(".parquet"), "{parquet}");
    let csv: Vec<&str> = exported["files"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|f| f.as_str().filter(|f| f.ends_with(".csv")))
        .collect();

    let script = r##"
import json, sys
import pandas as pd
import pyarrow.parquet as pq

path, csvs = sys.argv[1], sys.argv[2:]
df = pd.read_parquet(path)
cols = list(df.columns)
assert cols[:3] == ["time_s", "time", "segment"], cols
for c in ["armature_voltage", "armature_current", "speed", "encoder_count", "armature_voltage_command"]:
    assert c in cols, (c, cols)
    assert str(df[c].dtype) == "float64", (c, df[c].dtype)
assert str(df["time"].dtype).startswith("datetime64[ns, UTC]"), df["time"].dtype
meta = pq.read_schema(path).metadata
test = json.loads(meta[b"motorbench.test"])
units = json.loads(meta[b"motorbench.units"])
assert units["armature_current"] == "A" and units["speed"] == "rad/s", units
# the wall clock is the start plus time_s
start = pd.Timestamp(test["started_at"])
lag = (df["time"] - start).dt.total_seconds() - df["time_s"]
assert lag.abs().max() < 1e-6, lag.abs().max()
for i, name in enumerate(csvs):
    seg = df[df["segment"] == i]
    ref = pd.read_csv(name, comment="#", float_precision="round_trip")
    got = seg[seg["armature_current"].notna()]
    assert len(got) == len(ref), (i, len(got), len(ref))
    assert (got["armature_current"].to_numpy() == ref["armature_current_A"].to_numpy()).all(), i
    assert (got["time_s"].to_numpy() == ref["time_s"].to_numpy()).all(), i
print(json.dumps({"rows": len(df), "segments": int(df["segment"].nunique()), "kind": test["kind"]}))
"##;
    let python = common::python::interpreter();
    let check = Command::new(python)
        .args(["-c", "import pandas, pyarrow"])
        .output()
        .unwrap();
    assert!(
        check.status.success(),
        "{} lacks pandas or pyarrow: run tests/run.sh (it installs tests/python/requirements.txt) \
         or set MOTORBENCH_PYTHON to a python that has them",
        python.display()
    );
    let run = Command::new(python)
        .arg("-c")
        .arg(script)
        .arg(&parquet)
        .args(&csv)
        .output()
        .unwrap();
    let (stdout, stderr) = common::text(&run);
    assert!(run.status.success(), "{stdout}\n{stderr}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(v["segments"], 3);
    assert_eq!(v["kind"], "dc_step");
    assert!(v["rows"].as_u64().unwrap() > 1000, "{v}");
}

#[test]
fn exporting_what_is_not_a_record_is_bad_input_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let bogus = dir.path().join("notes.mcap");
    std::fs::write(&bogus, "time_s,armature_voltage_V\n").unwrap();
    let run = common::motorbench(&["export", bogus.to_str().unwrap()]);
    assert_eq!(run.status.code(), Some(2));
    assert!(common::text(&run).1.contains("notes.mcap"));
}
