//! The DC blind benchmark criterion on a fixed-seed set: the verdict is
//! right in at least 90 % of cases, never an effect on a `none` case, and
//! `gap_after` within twice the noise floor where the verdict is right.

use motorbench::diagnose::blind::{simulate_dc_case, simulate_dc_case_with, DcSetup, PlanKind};
use motorbench::diagnose::{diagnose_dc, DiagnoseOptions};
use motorbench::model::Effect;
use rand::rngs::StdRng;
use rand::SeedableRng;

const EFFECTS: [Option<Effect>; 8] = [
    None,
    Some(Effect::CoulombFriction),
    Some(Effect::BrushDrop),
    Some(Effect::ArmatureReaction),
    Some(Effect::InductanceSaturation),
    Some(Effect::ThermalDrift),
    Some(Effect::SensorLag),
    Some(Effect::ShaftCompliance),
];

fn name(e: Option<Effect>) -> String {
    e.map_or("none".into(), |e| {
        serde_json::to_value(e)
            .unwrap()
            .as_str()
            .unwrap()
            .to_string()
    })
}

/// Run `per_effect` cases of every effect (and `nones` of none), on the
/// classic settled staircase or (`wide`) on the wide plans in turn;
/// returns (right, total, false alarms, right cases whose gap_after
/// exceeds twice the floor). A refused record counts as a wrong verdict.
fn run(seed: u64, per_effect: usize, nones: usize, wide: bool) -> (usize, usize, usize, usize) {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut setup_rng = StdRng::seed_from_u64(seed ^ 0x5eed);
    let (mut right, mut total, mut alarms, mut far) = (0, 0, 0, 0);
    for e in EFFECTS {
        let count = if e.is_none() { nones } else { per_effect };
        for _ in 0..count {
            let (case, plan) = if wide {
                let plan = PlanKind::ALL[total % PlanKind::ALL.len()];
                let setup = DcSetup::draw(plan, &mut setup_rng);
                (simulate_dc_case_with(e, &setup, &mut rng), plan.name())
            } else {
                (simulate_dc_case(e, &mut rng), "classic")
            };
            let run = match diagnose_dc(&case.record, &DiagnoseOptions::default()) {
                Ok(run) => run,
                Err(err) => {
                    eprintln!("truth {:<22} plan {plan:<13} refused: {err}", name(e));
                    total += 1;
                    continue;
                }
            };
            let v = &run.report.verdict;
            let ok = v.effect == name(e);
            total += 1;
            if ok {
                right += 1;
                if v.gap_after > 2.0 * case.truth.noise_floor {
                    far += 1;
                }
            }
            if e.is_none() && v.effect != "none" {
                alarms += 1;
            }
            eprintln!(
                "truth {:<22} plan {plan:<13} verdict {:<22} p {:.2e} gap {:.4} -> {:.4} floor {:.4} {}",
                name(e),
                v.effect,
                1.0 - v.confidence,
                v.gap_before,
                v.gap_after,
                case.truth.noise_floor,
                run.report
                    .candidates
                    .iter()
                    .map(|c| format!("{}:{:.1}/{:.1e}", c.effect, c.score, c.p_value))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
        }
    }
    (right, total, alarms, far)
}

fn check(seed: u64, per_effect: usize, nones: usize, wide: bool) {
    let (right, total, alarms, far) = run(seed, per_effect, nones, wide);
    eprintln!("right {right}/{total}, false alarms {alarms}, gap_after > 2·floor in {far}");
    assert_eq!(alarms, 0, "false alarms on none");
    assert!(right as f64 >= 0.9 * total as f64, "{right}/{total} right");
    assert_eq!(far, 0, "gap_after above twice the noise floor");
}

#[test]
#[ignore = "slow in debug; run with --release (last measured 9/9 right, every gap within twice the floor: docs/diagnosis-dc.md)"]
fn one_case_per_effect_and_two_nones() {
    check(7, 1, 2, false);
}

#[test]
#[ignore = "long: run with --release (last measured 24/27 right, one false alarm, one gap at 4.1x the floor: fails the bar; docs/diagnosis-dc.md)"]
fn three_cases_per_effect_and_six_nones() {
    check(2024, 3, 6, false);
}

#[test]
#[ignore = "long: run with --release; fails the bar until the DC methods apply to records whose levels do not settle (docs/diagnosis-dc.md, Status)"]
fn wide_plans_two_cases_per_effect_and_four_nones() {
    check(7, 2, 4, true);
}

/// A candidate that removes most of the gap but not all of it is named,
/// with a warning saying what it left (segments held out): seed 7's case 34 of the wide suite
/// has a 33 ms first-order lag on the current sensor of a slow motor. The
/// `sensor_lag` candidate removes 99.6 % of the nominal's excess over the
/// noise floor and leaves 2.7 floors; before the dominant-share rule the
/// verdict was `none`, with that candidate in a warning.
#[test]
fn a_dominant_effect_that_leaves_more_than_twice_the_floor_is_named_with_a_warning() {
    use motorbench::diagnose::blind::{generate_suite, SuitePlans};
    use motorbench::record::{load_record_files, ColumnMap, SegmentKind};
    let dir = tempfile::tempdir().unwrap();
    let suite = dir.path().join("suite");
    let manifest = generate_suite(&suite, 7, SuitePlans::Wide, &|_, _| {}).unwrap();
    let case = manifest.cases.iter().find(|c| c.id == "case-34").unwrap();
    let files: Vec<_> = case.files.iter().map(|f| suite.join(f)).collect();
    let record = load_record_files(
        SegmentKind::DcStep,
        &files,
        None,
        None,
        &ColumnMap::default(),
    )
    .unwrap();
    // Held out by interleaved blocks (the default) the lag is fitted on
    // every segment's range and removes the gap to the floor.
    let run = diagnose_dc(&record, &DiagnoseOptions::default()).unwrap();
    let v = &run.report.verdict;
    assert_eq!(v.effect, "sensor_lag", "{:?}", run.report.warnings);
    assert!(v.gap_after <= 2.0 * run.report.gap.noise_floor, "{v:?}");
    // Leaving one segment out, it leaves 2.7 floors: the rule's case.
    let segments = DiagnoseOptions {
        dc_interleaved: Some(false),
        ..Default::default()
    };
    let run = diagnose_dc(&record, &segments).unwrap();
    let v = &run.report.verdict;
    let floor = run.report.gap.noise_floor;
    assert_eq!(v.effect, "sensor_lag", "{:?}", run.report.warnings);
    assert!(
        v.gap_after > 2.0 * floor,
        "{} vs floor {floor}",
        v.gap_after
    );
    assert!(
        run.report
            .warnings
            .iter()
            .any(|w| w.starts_with("sensor_lag: named as the verdict, though it leaves")),
        "{:?}",
        run.report.warnings
    );
}
