//! End to end: the `dc_coastdown` plan on the simulated rig.

use crate::common::dry_run;
use motorbench::bench::Outcome;
use motorbench::config::Config;
use motorbench::record::SegmentKind;

#[tokio::test]
async fn coastdown_plan_runs_up_then_decays_to_rest_with_no_current() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim-dc-coastdown.toml");
    let cfg = Config::load(&path).unwrap();
    let (_dir, done) = dry_run::commission(&cfg).await;
    assert_eq!(done.outcome, Outcome::Completed);
    let segs = &done.record.segments;
    assert_eq!(segs.len(), 2);
    assert_eq!(segs[0].kind, Some(SegmentKind::DcStep));
    assert_eq!(segs[1].kind, Some(SegmentKind::DcCoastdown));
    let c = &segs[1];
    // From about 183.6 rad/s at 248 V the seed motor stops after
    // (J/f)·ln(1 + ω0·f/Tst) ≈ 3.35 s.
    let w0 = c.speed[5];
    assert!((w0 - 183.6).abs() < 2.0, "starting speed {w0}");
    let stop = c
        .speed
        .iter()
        .position(|&w| w == 0.0)
        .expect("comes to rest");
    let t_stop = c.time[stop] - c.time[0];
    assert!((t_stop - 3.35).abs() < 0.1, "stopped after {t_stop} s");
    // The terminal voltage during the coast-down is the back-EMF K·ω.
    let k = c.voltage[2000] / c.speed[2000];
    assert!(
        (k - 1.323).abs() < 0.01,
        "back-EMF constant from the open terminals: {k}"
    );
    // One step alone gives no steady-state identification, but the
    // methods driven by the measured voltage identify the motor from it.
    let report = &done.analysis.report();
    assert!(
        !report.methods["steady_state"].applies,
        "{:?}",
        report.methods["steady_state"]
    );
    let best = report.best.as_deref().expect("a method applies");
    let k = report.methods[best].params.as_ref().unwrap()["K"].value;
    assert!((k - 1.323).abs() < 0.01 * 1.323, "K {k} from {best}");
}
