//! End to end: limits, faults and operator stops put the power stage in
//! its safe state before anything else, and the record says why.

use async_trait::async_trait;
use motorbench::bench::{BenchError, NoProgress, Outcome, RecordSink};
use motorbench::config::{Config, Plan};
use motorbench::machine::dc::{plan_steps, record_channels, run_test, sim_rig, SimSensors};
use motorbench::record::{EventLevel, Record};
use motorbench_drivers::{ChannelInfo, DriverError, SampleBatch, SensorStream};

fn config(edit: impl FnOnce(&mut Config)) -> Config {
    let mut cfg = Config::embedded_default();
    cfg.plan = Plan::DcStep {
        levels: vec![60.0, 248.0],
        coastdown: false,
    };
    edit(&mut cfg);
    cfg
}

/// Sensors that fail after a number of batches (a pulled cable), or that
/// hide some of their channels.
struct Faulty {
    inner: SimSensors,
    channels: Vec<ChannelInfo>,
    batches_left: Option<usize>,
}

#[async_trait]
impl SensorStream for Faulty {
    fn id(&self) -> &str {
        self.inner.id()
    }
    fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }
    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        match &mut self.batches_left {
            Some(0) => Err(DriverError::Link {
                device: "sim-daq".into(),
                reason: "cable pulled".into(),
            }),
            Some(n) => {
                *n -= 1;
                self.inner.next_batch().await
            }
            None => self.inner.next_batch().await,
        }
    }
}

struct Ran {
    outcome: Result<Outcome, BenchError>,
    record: Record,
    output_enabled: bool,
    setpoint: f64,
}

/// Run `cfg` on the simulated rig, the stage and the sensors sharing one
/// plant; `fail_after` batches the sensors fail; `hide` channels dropped.
async fn run(cfg: &Config, fail_after: Option<usize>, hide_encoder: bool, stop: bool) -> Ran {
    let sim = cfg.backend.simulated().expect("a simulated rig");
    let (mut stage, inner) = sim_rig(sim, cfg.common.sample_rate_hz, false).unwrap();
    let mut channels = inner.channels().to_vec();
    if hide_encoder {
        channels.retain(|c| c.quantity != "encoder_count");
    }
    let mut sensors = Faulty {
        inner,
        channels,
        batches_left: fail_after,
    };
    let mut sink = RecordSink::new(
        None,
        None,
        record_channels(sensors.channels(), "sim-supply"),
    );
    let (tx, rx) = tokio::sync::watch::channel(false);
    if stop {
        tx.send(true).unwrap();
    }
    let steps = plan_steps(&cfg.plan);
    let outcome = run_test(
        cfg,
        &steps,
        &mut stage,
        &mut sensors,
        10_000.0,
        &mut sink,
        &NoProgress,
        &rx,
    )
    .await;
    let (_, record) = sink.into_parts();
    Ran {
        outcome,
        record,
        output_enabled: stage.output_enabled(),
        setpoint: stage.setpoint(),
    }
}

fn abort_event(record: &Record) -> (u64, String) {
    let (t, e) = record
        .events
        .iter()
        .find(|(_, e)| e.level == EventLevel::Abort)
        .expect("an abort event");
    (*t, e.message.clone())
}

#[tokio::test]
async fn speed_limit_trips_on_the_monitors_estimate_and_the_stage_is_safe() {
    let cfg = config(|c| c.common.limits.max_speed = 100.0);
    let ran = run(&cfg, None, false, false).await;
    let Ok(Outcome::Aborted { reason }) = ran.outcome else {
        panic!("expected an abort")
    };
    assert!(
        reason.contains("speed") && reason.contains("safe state"),
        "{reason}"
    );
    assert!(!ran.output_enabled, "output disabled");
    assert_eq!(ran.setpoint, 0.0);
    let (t_abort, _) = abort_event(&ran.record);
    // The safety monitor (the daemon's check too) estimates speed over
    // four encoder periods and trips on two estimates beyond the limit in
    // a row: the sample that tripped is recorded, beyond the limit, within
    // eight periods of the first recorded (one-period, so noisier) speed
    // beyond it (the four-period window lags by up to four, the second
    // estimate adds one, the one-period speed's noise crosses early), and
    // nothing was sampled after it.
    let seg = &ran.record.segments[1];
    let first = seg
        .speed
        .iter()
        .position(|w| w.abs() > 100.0)
        .expect("speeds beyond the limit are recorded");
    let k = seg.time.len() - 1;
    assert_eq!((seg.time[k] * 1e9).round() as u64, t_abort);
    assert!(seg.speed[k].abs() > 100.0, "{}", seg.speed[k]);
    let periods = (seg.time[k] - seg.time[first]) * cfg.common.sample_rate_hz;
    assert!(periods.round() <= 8.0, "tripped {periods} periods late");
    assert!(
        seg.label.ends_with("248 V"),
        "the open segment was closed: {}",
        seg.label
    );
}

#[tokio::test]
async fn current_is_held_by_the_supply_below_the_trip_limit() {
    // A 1.2 A trip limit: the supply limits at 90 % of it, so the 1.3 A
    // start-up peak is held by the supply and the test completes.
    let cfg = config(|c| {
        c.common.limits.max_current = 1.2;
        c.plan = Plan::DcStep {
            levels: vec![60.0, 70.0],
            coastdown: false,
        };
    });
    let ran = run(&cfg, None, false, false).await;
    assert_eq!(ran.outcome.unwrap(), Outcome::Completed);
    let peak = ran.record.segments[0]
        .current
        .iter()
        .fold(0.0f64, |m, i| m.max(*i));
    assert!(peak < 1.2 && peak > 1.0, "peak {peak} A held near 1.08 A");
    assert!(!ran.output_enabled, "a completed test also ends safe");
}

#[tokio::test]
async fn sensor_link_failure_aborts_safely() {
    let ran = run(&config(|_| {}), Some(1500), false, false).await;
    assert!(matches!(ran.outcome, Ok(Outcome::Aborted { .. })));
    assert!(!ran.output_enabled);
    let (_, message) = abort_event(&ran.record);
    assert!(
        message.contains("cable pulled") && message.contains("safe state"),
        "{message}"
    );
}

#[tokio::test]
async fn operator_stop_aborts_before_the_first_sample() {
    let ran = run(&config(|_| {}), None, false, true).await;
    assert!(
        matches!(&ran.outcome, Ok(Outcome::Aborted { reason }) if reason.contains("operator stop"))
    );
    assert!(!ran.output_enabled);
    assert!(ran.record.segments.iter().all(|s| s.time.is_empty()));
}

#[tokio::test]
async fn missing_channel_is_refused_before_driving() {
    let ran = run(&config(|_| {}), None, true, false).await;
    let err = ran.outcome.unwrap_err().to_string();
    assert!(err.contains("encoder_count"), "{err}");
    assert!(!ran.output_enabled);
}
