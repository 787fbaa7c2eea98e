//! The one reading path both test plans share (the DC steps and the
//! induction-machine slip sweep), without a supervisor, as `motorbench
//! run` drives it: a silent sensor ends the test after the stale-data
//! timeout (it used to stall a sweep for ever), a stop raised while a
//! batch is awaited ends the test at once (it used to wait for the next
//! batch), and the safety monitor's checks run (they used to run under the
//! daemon only), each with every stage in its safe state.
//!
//! Time is tokio's paused clock with the simulated rigs paced at it; each
//! run is bounded by a virtual-time timeout, so a stalled test fails
//! rather than hangs.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::common::abort_message;
use async_trait::async_trait;
use motorbench::bench::{BenchError, NoProgress, Outcome, RecordSink};
use motorbench::config::{Config, Plan};
use motorbench::machine::dc::{plan_steps, record_channels, run_test, sim_rig};
use motorbench::machine::im::{
    run_im_sweep, sim_im_rig, sweep_channels, ImRunConfig, SimDyno, SimVfd,
};
use motorbench::record::Record;
use motorbench_drivers::{ChannelInfo, DriverError, PowerStage, SampleBatch, SensorStream};
use tokio::sync::watch;
use tokio::time::Instant;

/// What a sensor stream does after its first `after` batches.
#[derive(Clone, Copy)]
enum Fault {
    /// Delivers nothing more.
    Silent,
    /// Silent, and raises the operator's stop 50 ms into the silence.
    SilentThenStop,
    /// Delivers its batches without this channel.
    Drops(usize),
}

/// A sensor stream that fails as told after a number of batches.
struct Failing<S> {
    inner: S,
    after: usize,
    fault: Fault,
    stop: watch::Sender<bool>,
    /// When the stop was raised.
    stopped_at: Arc<Mutex<Option<Instant>>>,
}

#[async_trait]
impl<S: SensorStream> SensorStream for Failing<S> {
    fn id(&self) -> &str {
        self.inner.id()
    }
    fn channels(&self) -> &[ChannelInfo] {
        self.inner.channels()
    }
    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        if self.after > 0 {
            self.after -= 1;
            return self.inner.next_batch().await;
        }
        match self.fault {
            Fault::Silent => std::future::pending().await,
            Fault::SilentThenStop => {
                tokio::time::sleep(Duration::from_millis(50)).await;
                *self.stopped_at.lock().unwrap() = Some(Instant::now());
                self.stop.send_replace(true);
                std::future::pending().await
            }
            Fault::Drops(channel) => {
                let mut batch = self.inner.next_batch().await?;
                batch.samples.retain(|s| s.channel != channel);
                Ok(batch)
            }
        }
    }
}

/// The operator's stop flag and a failing stream around `inner`.
fn failing<S>(inner: S, after: usize, fault: Fault) -> (Failing<S>, watch::Receiver<bool>) {
    let (stop, rx) = watch::channel(false);
    let sensors = Failing {
        inner,
        after,
        fault,
        stop,
        stopped_at: Arc::default(),
    };
    (sensors, rx)
}

/// Longest a test here may take in virtual time before it counts as stalled.
const STALLED: Duration = Duration::from_secs(3600);

struct ImRan {
    outcome: Result<Outcome, BenchError>,
    record: Record,
    vfd: SimVfd,
    dyno: SimDyno,
    /// Virtual time from the stop to the sweep's end, when a stop was raised.
    stop_to_end: Option<Duration>,
}

/// The shipped IM sweep (one voltage, twelve slips), edited by `edit`,
/// on the paced simulated rig whose stream fails after `after` batches.
async fn im_sweep(edit: impl FnOnce(&mut ImRunConfig), after: usize, fault: Fault) -> ImRan {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-im.toml");
    let mut cfg = ImRunConfig::load(std::path::Path::new(path)).unwrap();
    cfg.plan.slips.truncate(12);
    cfg.plan.voltages.truncate(1);
    edit(&mut cfg);
    let (vfd, dyno, inner) = sim_im_rig(cfg.simulated.clone().unwrap()).unwrap();
    let (mut sensors, stop) = failing(inner.paced(), after, fault);
    let stopped_at = sensors.stopped_at.clone();
    let mut sink = RecordSink::new(
        None,
        None,
        sweep_channels(sensors.channels(), vfd.id(), dyno.id()),
    );
    let (mut supply, mut dynamometer) = (vfd.clone(), dyno.clone());
    let rules = cfg.safety_rules();
    let sweep = run_im_sweep(
        &cfg.plan,
        &rules,
        &mut supply,
        &mut dynamometer,
        &mut sensors,
        &mut sink,
        &NoProgress,
        &stop,
    );
    let outcome = tokio::time::timeout(STALLED, sweep)
        .await
        .expect("the sweep stalled");
    let end = Instant::now();
    let stop_to_end = stopped_at.lock().unwrap().map(|at| end - at);
    let (_, record) = sink.into_parts();
    ImRan {
        outcome,
        record,
        vfd,
        dyno,
        stop_to_end,
    }
}

fn aborted(outcome: &Result<Outcome, BenchError>) -> String {
    match outcome {
        Ok(Outcome::Aborted { reason }) => reason.clone(),
        other => panic!("expected an abort, got {other:?}"),
    }
}

fn assert_im_safe(r: &ImRan) {
    assert!(!r.vfd.output_enabled(), "supply output off");
    assert_eq!(r.dyno.command(), (0.0, true), "dynamometer braking to rest");
    let message = abort_message(&r.record);
    assert!(
        message.contains("supply off, dynamometer braking"),
        "{message}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_silent_sensor_ends_an_im_sweep_with_both_stages_safe() {
    let r = im_sweep(|_| {}, 2000, Fault::Silent).await;
    let reason = aborted(&r.outcome);
    assert!(reason.contains("delivered nothing for 500 ms"), "{reason}");
    assert_im_safe(&r);
}

#[tokio::test(start_paused = true)]
async fn a_silent_current_channel_ends_an_im_sweep_as_a_stale_channel() {
    // The meter's current stops; voltage, power and the encoder go on.
    let r = im_sweep(|_| {}, 2000, Fault::Drops(1)).await;
    let reason = aborted(&r.outcome);
    assert!(
        reason.contains("sensor fault: stale data: no new line_current reading"),
        "{reason}"
    );
    assert_im_safe(&r);
}

#[tokio::test(start_paused = true)]
async fn a_stop_during_a_long_batch_wait_ends_the_im_sweep_at_once() {
    let r = im_sweep(|_| {}, 2000, Fault::SilentThenStop).await;
    assert_eq!(aborted(&r.outcome), "operator stop");
    // Within one sample period of the stop (500 Hz), not at the next batch
    // or the stale timeout.
    let waited = r.stop_to_end.expect("the stop was raised");
    assert!(waited <= Duration::from_millis(2), "{waited:?}");
    assert_im_safe(&r);
}

#[tokio::test(start_paused = true)]
async fn motorbench_runs_im_sweep_checks_the_supervisors_power_limit() {
    // The sweep draws kilowatts at 400 V: a 1 kW `[supervisor]` power
    // limit ends it, as it would under the daemon.
    let r = im_sweep(
        |c| c.common.supervision.max_power = 1000.0,
        usize::MAX,
        Fault::Silent,
    )
    .await;
    let reason = aborted(&r.outcome);
    assert!(reason.contains("limit tripped: power"), "{reason}");
    assert_im_safe(&r);
}

struct DcRan {
    outcome: Result<Outcome, BenchError>,
    record: Record,
    output_enabled: bool,
    setpoint: f64,
    stop_to_end: Option<Duration>,
}

/// The embedded DC test (60 V then 248 V), edited by `edit`, on the paced
/// simulated rig whose stream fails after `after` batches.
async fn dc_test(edit: impl FnOnce(&mut Config), after: usize, fault: Fault) -> DcRan {
    let mut cfg = Config::embedded_default();
    cfg.plan = Plan::DcStep {
        levels: vec![60.0, 248.0],
        coastdown: false,
    };
    edit(&mut cfg);
    let sim = cfg.backend.simulated().expect("a simulated rig");
    let (mut stage, inner) = sim_rig(sim, cfg.common.sample_rate_hz, true).unwrap();
    let (mut sensors, stop) = failing(inner, after, fault);
    let stopped_at = sensors.stopped_at.clone();
    let mut sink = RecordSink::new(
        None,
        None,
        record_channels(sensors.channels(), "sim-supply"),
    );
    let steps = plan_steps(&cfg.plan);
    let test = run_test(
        &cfg,
        &steps,
        &mut stage,
        &mut sensors,
        10_000.0,
        &mut sink,
        &NoProgress,
        &stop,
    );
    let outcome = tokio::time::timeout(STALLED, test)
        .await
        .expect("the test stalled");
    let end = Instant::now();
    let stop_to_end = stopped_at.lock().unwrap().map(|at| end - at);
    let (_, record) = sink.into_parts();
    DcRan {
        outcome,
        record,
        output_enabled: stage.output_enabled(),
        setpoint: stage.setpoint(),
        stop_to_end,
    }
}

fn assert_dc_safe(r: &DcRan) {
    assert!(!r.output_enabled, "output disabled");
    assert_eq!(r.setpoint, 0.0);
    let message = abort_message(&r.record);
    assert!(
        message.contains("power stage commanded to its safe state"),
        "{message}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_stop_during_a_long_batch_wait_ends_a_dc_test_at_once() {
    let r = dc_test(|_| {}, 1500, Fault::SilentThenStop).await;
    assert!(
        aborted(&r.outcome).starts_with("operator stop;"),
        "{:?}",
        r.outcome
    );
    // Within one sample period of the stop (2 kHz), not at the stale
    // timeout (half a second).
    let waited = r.stop_to_end.expect("the stop was raised");
    assert!(waited <= Duration::from_micros(500), "{waited:?}");
    assert_dc_safe(&r);
}

#[tokio::test(start_paused = true)]
async fn motorbench_runs_dc_test_checks_the_supervisors_power_limit() {
    // 248 V at the no-load current is tens of watts: a 20 W `[supervisor]`
    // power limit ends the test, as it would under the daemon.
    let r = dc_test(
        |c| c.common.supervision.max_power = 20.0,
        usize::MAX,
        Fault::Silent,
    )
    .await;
    let reason = aborted(&r.outcome);
    assert!(reason.contains("limit tripped: power"), "{reason}");
    assert_dc_safe(&r);
}
