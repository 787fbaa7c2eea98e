//! The blind benchmark of the sim-to-real diagnosis, end to end through
//! the CLI: `motorbench blind generate` simulates the fixed-seed suite
//! (records as contract CSV files, the truth in its own file), `motorbench
//! blind score` diagnoses every case from its files alone and then compares
//! with the truth.
//!
//! Issue 7's bar is the verdict right in at least 90 % of the cases, no
//! false alarm on `none`, gap_after within twice the noise floor wherever
//! the verdict is right. All three hold on this seed (last measured: 44 of
//! 46 right, none of the 7 `none` cases named an effect, all 44 right
//! verdicts within twice the noise floor; docs/diagnosis.md), and this test
//! asserts them as the issue states them.

mod common;

use common::{motorbench_release as motorbench, text};
use motorbench::diagnose::blind::{Manifest, SuiteScore};

#[test]
fn fixed_seed_suite_meets_the_verdict_bar() {
    let dir = tempfile::tempdir().unwrap();
    let suite = dir.path().join("suite");
    let suite_arg = suite.to_str().unwrap();
    let out = motorbench(&["blind", "generate", "--out", suite_arg]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "generate failed:\n{stdout}\n{stderr}");

    // The public manifest names files only inside the case directories;
    // the truth is a separate file no case file points at.
    let manifest: Manifest =
        serde_json::from_str(&std::fs::read_to_string(suite.join("cases.json")).unwrap()).unwrap();
    assert!(manifest.cases.len() >= 40);
    for case in &manifest.cases {
        for f in case.files.iter().chain(&case.nameplate) {
            assert!(f.starts_with("cases"), "{}", f.display());
            let body = std::fs::read_to_string(suite.join(f)).unwrap();
            assert!(
                !body.contains("truth"),
                "{} mentions the truth",
                f.display()
            );
        }
    }

    // Generating again with the same seed gives the same suite.
    let again = dir.path().join("again");
    let out = motorbench(&["blind", "generate", "--out", again.to_str().unwrap()]);
    assert!(out.status.success());
    assert_eq!(
        std::fs::read(suite.join("truth.json")).unwrap(),
        std::fs::read(again.join("truth.json")).unwrap()
    );
    // And refuses to overwrite a suite.
    let out = motorbench(&["blind", "generate", "--out", suite_arg]);
    assert_eq!(out.status.code(), Some(2));

    let out = motorbench(&["blind", "score", suite_arg, "--json"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "score failed:\n{stderr}");
    let score: SuiteScore = serde_json::from_str(&stdout).unwrap();
    eprintln!("{score}");
    let (alarms, nones) = score.false_alarms();
    assert!(nones >= 6);
    assert_eq!(alarms, 0, "false alarms on none:\n{score}");
    assert!(
        score.accuracy() >= 0.9,
        "accuracy {:.3}:\n{score}",
        score.accuracy()
    );
    let (floor, right) = score.noise_floor_reached();
    assert_eq!(
        floor,
        right,
        "gap_after above twice the noise floor in {} of {right} right verdicts:\n{score}",
        right - floor
    );
}
