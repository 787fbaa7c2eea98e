//! The blind benchmark of the sim-to-real diagnosis, end to end through
//! the CLI: `motorbench blind generate` simulates the fixed-seed suite
//! (records as contract CSV files, the truth in its own file), `motorbench
//! blind score` diagnoses every case from its files alone and then compares
//! with the truth.
//!
//! Issue 7's bar is the verdict right in at least 90 % of the cases, no
//! false alarm on `none`, gap_after within twice the noise floor wherever
//! the verdict is right. All three hold on this seed's classic suite
//! (`--plans classic`: settled staircases; last measured: 44 of 46 right,
//! none of the 7 `none` cases named an effect, all 44 right verdicts within
//! twice the noise floor; docs/diagnosis.md), and this test asserts them as
//! the issue states them. The wide suite (the default: ramps, PRBS, closed
//! loops, short holds) is generated and checked here but scored by
//! `scripts/blind-benchmark.sh`: the DC methods still refuse records whose
//! levels do not settle (docs/diagnosis-dc.md, Status), and scoring it
//! would double this test's time.

use crate::common;

use common::{motorbench, text};
use motorbench::diagnose::blind::{Manifest, PlanKind, SuiteScore, TruthFile};

#[test]
fn fixed_seed_suite_meets_the_verdict_bar() {
    let dir = tempfile::tempdir().unwrap();
    // The wide suite: every plan, holds of 2–12 time constants.
    let wide = dir.path().join("wide");
    let out = motorbench(&["blind", "generate", "--out", wide.to_str().unwrap()]);
    assert!(out.status.success(), "{:?}", text(&out));
    let truth: TruthFile =
        serde_json::from_str(&std::fs::read_to_string(wide.join("truth.json")).unwrap()).unwrap();
    for plan in PlanKind::ALL {
        let cases: Vec<_> = truth
            .cases
            .iter()
            .filter(|(_, t)| t.plan == plan.name())
            .collect();
        assert!(cases.len() >= 4, "{} {} cases", cases.len(), plan.name());
    }
    let holds: Vec<f64> = truth
        .cases
        .iter()
        .filter_map(|(_, t)| t.setup.get("hold_tau").copied())
        .collect();
    assert!(holds.iter().any(|h| *h < 4.0), "{holds:?}");

    let suite = dir.path().join("suite");
    let suite_arg = suite.to_str().unwrap();
    let out = motorbench(&[
        "blind", "generate", "--out", suite_arg, "--plans", "classic",
    ]);
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
    let out = motorbench(&[
        "blind",
        "generate",
        "--out",
        again.to_str().unwrap(),
        "--plans",
        "classic",
    ]);
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
