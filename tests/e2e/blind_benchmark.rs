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
//! the issue states them, on a fixed subset of that suite (every `none`
//! and induction-machine case, every second DC case with an effect: the
//! DC diagnosis is most of the suite's time). The wide suite (the default: ramps, PRBS, closed
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

    // Scored here: every `none` case and every induction-machine case,
    // and every second DC case with an effect (the DC diagnosis is most of
    // the time); `scripts/blind-benchmark.sh` scores whole suites.
    let subset = dir.path().join("subset");
    let kept = keep_a_fixed_subset(&suite, &subset);
    assert!(kept >= 30, "{kept} cases kept");
    let out = motorbench(&["blind", "score", subset.to_str().unwrap(), "--json"]);
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

/// Copy the suite in `from` to `to`, its cases cut down as the test's
/// comment says (the case files linked, not copied); the cases kept.
fn keep_a_fixed_subset(from: &std::path::Path, to: &std::path::Path) -> usize {
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(from.join(name)).unwrap()).unwrap()
    };
    let (mut manifest, truth) = (read("cases.json"), read("truth.json"));
    let effect_of = |id: &str| -> String {
        truth["cases"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c[0] == id)
            .map(|c| c[1]["effect"].as_str().unwrap().to_string())
            .unwrap()
    };
    let mut dc_effects = 0usize;
    let cases: Vec<serde_json::Value> = manifest["cases"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| {
            if c["kind"] != "dc_step" || effect_of(c["id"].as_str().unwrap()) == "none" {
                return true;
            }
            dc_effects += 1;
            dc_effects % 2 == 1
        })
        .cloned()
        .collect();
    let kept = cases.len();
    manifest["cases"] = serde_json::Value::Array(cases);
    std::fs::create_dir_all(to).unwrap();
    std::fs::write(to.join("cases.json"), manifest.to_string()).unwrap();
    std::fs::copy(from.join("truth.json"), to.join("truth.json")).unwrap();
    std::os::unix::fs::symlink(from.join("cases"), to.join("cases")).unwrap();
    kept
}
