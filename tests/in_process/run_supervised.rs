//! `motorbench run`'s session (`session::commission`) runs every test under
//! the same safety supervisor task as the daemon, for either machine: a
//! limit trip and an operator stop both come through it (the abort names
//! the supervisor, and the record holds its account of the stop), and a
//! simulated rig on a virtual clock, read far faster than the wall clock,
//! never counts as a stalled sequencer.

use motorbench::bench::{NoProgress, Outcome};
use motorbench::config::{Config, Plan};
use motorbench::machine::im::ImRunConfig;
use motorbench::machine::Machine;
use motorbench::session::{commission, CommissionOptions, Commissioned};

fn im_config(edit: impl FnOnce(&mut String)) -> ImRunConfig {
    let mut text = include_str!("../../config/sim-im.toml").to_string();
    edit(&mut text);
    ImRunConfig::parse("sim-im.toml", &text).unwrap()
}

fn dc_config(max_speed: f64) -> Config {
    let mut cfg = Config::embedded_default();
    cfg.plan = Plan::DcStep {
        levels: vec![60.0, 248.0],
        coastdown: false,
    };
    cfg.common.limits.max_speed = max_speed;
    cfg
}

/// Commission `machine` with the operator's stop flag at `stop`.
async fn run(machine: Box<dyn Machine>, stop: bool) -> Commissioned {
    let dir = tempfile::tempdir().unwrap();
    let (_tx, rx) = tokio::sync::watch::channel(stop);
    let opts = CommissionOptions {
        out_dir: dir.path().to_path_buf(),
        realtime: false,
        diagnose: false,
    };
    commission(machine, &opts, &NoProgress, &rx).await.unwrap()
}

fn aborted(done: &Commissioned) -> &str {
    match &done.outcome {
        Outcome::Aborted { reason } => reason,
        Outcome::Completed => panic!("the test completed"),
    }
}

/// The record's account of the supervisor's stop.
fn supervisor_event(done: &Commissioned) -> Option<&str> {
    done.record
        .events
        .iter()
        .map(|(_, e)| e.message.as_str())
        .find(|m| m.starts_with("safety supervisor: "))
}

#[tokio::test]
async fn a_dc_limit_trip_under_run_goes_through_the_supervisor() {
    // At 248 V the motor runs well above 100 rad/s.
    let done = run(Box::new(dc_config(100.0)), false).await;
    let reason = aborted(&done);
    assert!(
        reason.contains("stopped by the safety supervisor: limit tripped: speed"),
        "{reason}"
    );
    let event = supervisor_event(&done).expect("the stop is recorded");
    assert!(event.contains("limit tripped: speed"), "{event}");
}

#[tokio::test]
async fn an_im_limit_trip_under_run_goes_through_the_supervisor() {
    // Locked rotor at 400 V draws about 48 A.
    let cfg = im_config(|t| *t = t.replace("max_current_A = 70 ", "max_current_A = 20 "));
    let done = run(Box::new(cfg), false).await;
    let reason = aborted(&done);
    assert!(
        reason.contains("stopped by the safety supervisor: limit tripped: current"),
        "{reason}"
    );
    assert!(supervisor_event(&done).is_some());
}

#[tokio::test]
async fn an_operator_stop_under_run_goes_through_the_supervisor() {
    let done = run(
        Box::new(dc_config(
            Config::embedded_default().common.limits.max_speed,
        )),
        true,
    )
    .await;
    let reason = aborted(&done);
    assert!(
        reason.contains("stopped by the safety supervisor: operator abort"),
        "{reason}"
    );
    let event = supervisor_event(&done).expect("the stop is recorded");
    assert!(event.contains("operator abort"), "{event}");
}

#[tokio::test]
async fn a_virtual_clock_rig_runs_to_the_end_under_the_supervisor() {
    // Both machines' whole plans, read as fast as the CPU allows: the
    // supervisor reads no faster than the sequencer takes batches.
    let dc = run(
        Box::new(dc_config(
            Config::embedded_default().common.limits.max_speed,
        )),
        false,
    )
    .await;
    assert!(matches!(dc.outcome, Outcome::Completed), "{:?}", dc.outcome);
    assert!(supervisor_event(&dc).is_none());
    let im = run(Box::new(im_config(|_| {})), false).await;
    assert!(matches!(im.outcome, Outcome::Completed), "{:?}", im.outcome);
    assert!(supervisor_event(&im).is_none());
}
