//! End to end over the library: the safety supervisor watches a test on
//! the simulated rig independently of the sequencer, puts the rig in its
//! safe state first, and the record says why.
//!
//! Time is tokio's paused clock with the simulated rig paced at it, so the
//! bus-loss timer and the heartbeat run on the same clock as the samples.

use std::time::Duration;

use crate::common::abort_message;
use async_trait::async_trait;
use motorbench::bench::{
    supervise, NoProgress, Outcome, RecordSink, SafetyMonitor, StopCause, StopReport,
    SupervisorSummary, SupervisorTiming,
};
use motorbench::config::{Config, Plan};
use motorbench::machine::dc::{
    plan_steps, record_channels, run_test, sim_rig, SimPowerStage, SimSensors,
};
use motorbench::record::Record;
use motorbench_drivers::{
    ChannelInfo, DriverError, PowerStage, SampleBatch, SensorStream, StageCapabilities,
};

fn config(edit: impl FnOnce(&mut Config)) -> Config {
    let mut cfg = Config::embedded_default();
    cfg.plan = Plan::DcStep {
        levels: vec![60.0, 248.0, 60.0],
        coastdown: false,
    };
    edit(&mut cfg);
    cfg
}

/// Sensors that hang (a dead bus) after a number of batches.
struct Hanging {
    inner: SimSensors,
    batches_left: usize,
}

#[async_trait]
impl SensorStream for Hanging {
    fn id(&self) -> &str {
        self.inner.id()
    }
    fn channels(&self) -> &[ChannelInfo] {
        self.inner.channels()
    }
    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        if self.batches_left == 0 {
            std::future::pending::<()>().await;
        }
        self.batches_left -= 1;
        self.inner.next_batch().await
    }
}

/// A supply whose safe-state command fails (a refused write), while its
/// heartbeat still works.
struct StuckSupply(SimPowerStage);

#[async_trait]
impl PowerStage for StuckSupply {
    fn id(&self) -> &str {
        self.0.id()
    }
    fn capabilities(&self) -> StageCapabilities {
        self.0.capabilities()
    }
    async fn set_setpoint(&mut self, v: f64) -> Result<(), DriverError> {
        self.0.set_setpoint(v).await
    }
    async fn set_output_enabled(&mut self, on: bool) -> Result<(), DriverError> {
        if on {
            self.0.set_output_enabled(on).await
        } else {
            Err(DriverError::Device {
                device: "sim-supply".into(),
                reason: "write refused".into(),
            })
        }
    }
    async fn safe_state(&mut self) -> Result<(), DriverError> {
        Err(DriverError::Device {
            device: "sim-supply".into(),
            reason: "write refused".into(),
        })
    }
    fn heartbeat_timeout(&self) -> Option<Duration> {
        self.0.heartbeat_timeout()
    }
    async fn heartbeat(&mut self) -> Result<(), DriverError> {
        self.0.heartbeat().await
    }
}

enum Sensors {
    Sim,
    HangAfter(usize),
}

struct Ran {
    outcome: Outcome,
    record: Record,
    summary: SupervisorSummary,
    stop: Option<StopReport>,
    supply: SimPowerStage,
}

/// Run `cfg` under supervision; `stop_at_s` asks for `cause` once the
/// test time passes it.
async fn run(
    cfg: &Config,
    sensors: Sensors,
    stuck_supply: bool,
    stop_at: Option<(f64, StopCause)>,
) -> Ran {
    let sim = cfg.backend.simulated().expect("a simulated rig");
    let (supply, inner) = sim_rig(sim, cfg.common.sample_rate_hz, true).unwrap();
    let channels = inner.channels().to_vec();
    let sensors: Box<dyn SensorStream> = match sensors {
        Sensors::Sim => Box::new(inner),
        Sensors::HangAfter(n) => Box::new(Hanging {
            inner,
            batches_left: n,
        }),
    };
    let stage: Box<dyn PowerStage> = if stuck_supply {
        Box::new(StuckSupply(supply.clone()))
    } else {
        Box::new(supply.clone())
    };
    let counts_per_rev = 4.0 * f64::from(sim.sensors.encoder_lines);
    let monitor = SafetyMonitor::new(
        cfg.common.limits,
        cfg.common.supervision.clone(),
        &channels,
        Some(counts_per_rev),
        0.0,
    )
    .unwrap();
    let timing = SupervisorTiming::new(
        cfg.common.supervision.bus_loss_timeout,
        cfg.common.sample_rate_hz,
    );
    let mut s = supervise(
        stage,
        sensors,
        monitor,
        timing,
        cfg.common.limits.max_voltage,
    );
    let handle = s.handle.clone();
    if let Some((at, cause)) = stop_at {
        let h = handle.clone();
        tokio::spawn(async move {
            let mut readings = h.readings();
            while readings.borrow().t_s < at {
                if readings.changed().await.is_err() {
                    return;
                }
            }
            h.stop(cause).await;
        });
    }
    let mut sink = RecordSink::new(None, None, record_channels(&channels, "sim-supply"));
    let steps = plan_steps(&cfg.plan);
    let outcome = run_test(
        cfg,
        &steps,
        &mut s.stage,
        &mut s.sensors,
        counts_per_rev,
        &mut sink,
        &NoProgress,
        // As the daemon does: the sequencer's own trips go to the supervisor.
        &handle,
    )
    .await
    .unwrap();
    let stop = handle.stopped();
    // The supervisor keeps reading (and, while healthy, petting) until it
    // is finished; half a second of that lets the supply's own heartbeat
    // act where it must.
    tokio::time::sleep(Duration::from_millis(500)).await;
    handle.finish().await;
    let summary = s.task.await.unwrap();
    let (_, record) = sink.into_parts();
    Ran {
        outcome,
        record,
        summary,
        stop,
        supply,
    }
}

/// The recorded current at `t_ns`.
fn current_at(record: &Record, t_ns: u64) -> f64 {
    for seg in &record.segments {
        if let Some(k) = seg
            .time
            .iter()
            .position(|t| (t * 1e9).round() as u64 == t_ns)
        {
            return seg.current[k];
        }
    }
    panic!("no sample at {t_ns} ns")
}

#[tokio::test(start_paused = true)]
async fn operator_abort_makes_the_rig_safe_then_records_why() {
    let ran = run(
        &config(|_| {}),
        Sensors::Sim,
        false,
        Some((0.3, StopCause::OperatorAbort)),
    )
    .await;
    let Outcome::Aborted { reason } = &ran.outcome else {
        panic!("{:?}", ran.outcome)
    };
    assert!(
        reason.contains("stopped by the safety supervisor: operator abort"),
        "{reason}"
    );
    assert_eq!(abort_message(&ran.record), *reason);
    let stop = ran.stop.unwrap();
    assert_eq!(stop.safe_state, Ok(()));
    assert!(!ran.supply.output_enabled());
    // The record holds the first sample read after the safe state, and it
    // shows the armature open.
    let t_safe = stop.first_safe_t_ns.expect("a sample after the safe state");
    assert!(t_safe > stop.requested_t_ns);
    assert!(current_at(&ran.record, t_safe).abs() < 0.02);
    assert!(current_at(&ran.record, stop.requested_t_ns).abs() > 0.05);
    // An operator abort does not latch the rig.
    assert!(!stop.cause.latches());
    assert!(
        ran.summary.heartbeats > 0,
        "the supervisor petted the supply"
    );
    assert!(
        !ran.supply.heartbeat_lost(),
        "a healthy supervisor keeps the heartbeat alive after the stop"
    );
}

#[tokio::test(start_paused = true)]
async fn a_limit_only_the_supervisor_knows_trips_the_test() {
    // The 60 V → 248 V step draws ~1 kW for a moment; 500 W is a limit of
    // the supervisor only (the sequencer checks voltage, current, speed).
    let ran = run(
        &config(|c| c.common.supervision.max_power = 500.0),
        Sensors::Sim,
        false,
        None,
    )
    .await;
    let Outcome::Aborted { reason } = &ran.outcome else {
        panic!("{:?}", ran.outcome)
    };
    assert!(
        reason.contains("power") && reason.contains("500"),
        "{reason}"
    );
    let stop = ran.stop.unwrap();
    assert!(matches!(&stop.cause, StopCause::Limit(t) if t.quantity == "power"));
    assert!(stop.cause.latches());
    assert!(!ran.supply.output_enabled());
    assert!(current_at(&ran.record, stop.first_safe_t_ns.unwrap()).abs() < 0.02);
}

#[tokio::test(start_paused = true)]
async fn a_speed_limit_the_sequencer_sees_first_latches_through_the_supervisor() {
    // The sequencer estimates speed over one encoder period and trips on
    // the first estimate beyond the limit; the supervisor wants two in a
    // row over four periods, so the sequencer sees the rising 60 V → 248 V
    // shaft cross 100 rad/s first. It hands the trip to the supervisor.
    let ran = run(
        &config(|c| c.common.limits.max_speed = 100.0),
        Sensors::Sim,
        false,
        None,
    )
    .await;
    let stop = ran.stop.expect("the supervisor took the sequencer's trip");
    assert!(
        matches!(&stop.cause, StopCause::Limit(t) if t.quantity == "speed"),
        "{:?}",
        stop.cause
    );
    assert!(stop.cause.latches());
    assert_eq!(stop.safe_state, Ok(()));
    assert!(!ran.supply.output_enabled());
    let reason = abort_message(&ran.record);
    assert!(
        reason.contains("stopped by the safety supervisor: limit tripped: speed"),
        "{reason}"
    );
    // The record goes on to a sample read in the safe state.
    let t_safe = stop.first_safe_t_ns.expect("a sample after the safe state");
    assert!(t_safe > stop.requested_t_ns);
    assert!(current_at(&ran.record, t_safe).abs() < 0.02);
    assert!(current_at(&ran.record, stop.requested_t_ns).abs() > 0.05);
}

#[tokio::test(start_paused = true)]
async fn a_limit_both_checks_see_in_one_batch_leaves_the_rig_shown_safe() {
    // Held at exactly the voltage limit, the first 248 V reading above it
    // trips the supervisor and the sequencer on the same batch: the
    // record still goes on to the first sample read in the safe state.
    let ran = run(
        &config(|c| c.common.limits.max_voltage = 248.0),
        Sensors::Sim,
        false,
        None,
    )
    .await;
    let stop = ran.stop.expect("a supervisor stop");
    assert!(
        matches!(&stop.cause, StopCause::Limit(t) if t.quantity == "voltage"),
        "{:?}",
        stop.cause
    );
    let t_safe = stop.first_safe_t_ns.expect("a sample after the safe state");
    assert!(t_safe > stop.requested_t_ns);
    assert!(current_at(&ran.record, t_safe).abs() < 0.02);
    assert!(ran.record.events.iter().any(|(_, e)| e
        .message
        .contains("stopped by the safety supervisor: limit tripped: voltage")));
}

#[tokio::test(start_paused = true)]
async fn emergency_stop_by_api_takes_the_same_path() {
    let cause = StopCause::EmergencyStop {
        source: "API".into(),
    };
    let ran = run(&config(|_| {}), Sensors::Sim, false, Some((0.2, cause))).await;
    let reason = abort_message(&ran.record);
    assert!(reason.contains("emergency stop (API)"), "{reason}");
    assert!(!ran.supply.output_enabled());
}

#[tokio::test(start_paused = true)]
async fn bus_loss_trips_after_its_timeout() {
    let cfg = config(|_| {});
    let ran = run(&cfg, Sensors::HangAfter(600), false, None).await;
    let stop = ran.stop.unwrap();
    assert!(
        matches!(stop.cause, StopCause::BusLoss { .. }),
        "{:?}",
        stop.cause
    );
    assert_eq!(stop.first_safe_t_ns, None, "no data after a bus loss");
    assert!(!ran.supply.output_enabled());
    let reason = abort_message(&ran.record);
    assert!(
        reason.contains("bus loss") && reason.contains("0.25 s"),
        "{reason}"
    );
}

#[tokio::test(start_paused = true)]
async fn failed_safe_state_stops_the_heartbeat_so_the_supply_makes_itself_safe() {
    // The supervisor trips (power), its safe-state command is refused: it
    // is no longer healthy, stops petting, and the supply's own heartbeat
    // timeout switches the output off.
    let cfg = config(|c| c.common.supervision.max_power = 500.0);
    let sim = cfg.backend.simulated().expect("a simulated rig");
    let ran = run(&cfg, Sensors::Sim, true, None).await;
    let stop = ran.stop.unwrap();
    assert!(stop.safe_state.is_err());
    assert!(abort_message(&ran.record).contains("SAFE-STATE COMMAND FAILED"));
    // The stuck supply ignored every safe-state command; what switched it
    // off is its heartbeat, which nobody pets now.
    assert!(
        ran.supply.heartbeat_lost(),
        "the supply timed out by itself"
    );
    assert!(!ran.supply.output_enabled());
    assert!(sim.power_stage.heartbeat_timeout < 0.5);
}
