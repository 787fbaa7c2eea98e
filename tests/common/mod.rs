//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

pub mod daemon;
pub mod dc_shapes;
pub mod dry_run;
pub mod peer;
pub mod python;
pub mod rated_motor;
pub mod replay;

use std::path::Path;
use std::process::{Command, Output};

/// Run the `motorbench` binary built for these tests.
pub fn motorbench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_motorbench"))
        .args(args)
        .output()
        .expect("motorbench runs")
}

/// The values `motorbench probe` printed for `quantity` at `step`
/// (`idle`, `on`, `safe`), in order; panics when there is none.
pub fn probed(stdout: &str, step: &str, quantity: &str) -> Vec<f64> {
    let prefix = format!("[{step:>4}] {quantity} ");
    let values: Vec<f64> = stdout
        .lines()
        .filter(|l| l.starts_with(&prefix))
        .map(|l| {
            l[prefix.len()..]
                .split_whitespace()
                .next()
                .unwrap()
                .parse()
                .unwrap_or_else(|e| panic!("{l}: {e}"))
        })
        .collect();
    assert!(!values.is_empty(), "no {step} {quantity} in:\n{stdout}");
    values
}

/// Stdout and stderr as text.
pub fn text(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Run the Python `mcap` reader check on `file`; panics with its output on
/// failure. The README's test command installs the reader; a missing
/// reader fails the test rather than skipping it.
pub fn python_check_mcap(file: &Path, expect: &[String]) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/check_mcap.py");
    let mut cmd = Command::new(python::interpreter());
    cmd.arg(script).arg(file);
    for e in expect {
        cmd.arg("--expect-topic").arg(e);
    }
    let out = cmd.output().expect("the test python runs");
    let (stdout, stderr) = text(&out);
    assert!(
        out.status.success(),
        "check_mcap.py failed:\n{stdout}\n{stderr}"
    );
    let last = stdout
        .lines()
        .last()
        .expect("check_mcap.py prints its counts last");
    serde_json::from_str(last).expect("the last line is JSON")
}

/// The message of `record`'s abort event; panics when it has none.
pub fn abort_message(record: &motorbench::record::Record) -> String {
    record
        .events
        .iter()
        .find(|(_, e)| e.level == motorbench::record::EventLevel::Abort)
        .map(|(_, e)| e.message.clone())
        .expect("an abort event")
}
