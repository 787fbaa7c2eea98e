//! The safety supervisor around an induction-machine slip sweep on the
//! simulated rig: both stages (the supply VFD, then the dynamometer) are
//! commanded to their safe state on a trip, an operator abort or an
//! emergency stop, before the cause is recorded, and the record says why.
//!
//! Time is tokio's paused clock with the simulated rig paced at it.

use std::sync::{Arc, Mutex, OnceLock};

use async_trait::async_trait;
use motorbench::bench::{
    supervise_stages, NoProgress, Outcome, RecordSink, SafetyMonitor, StopCause, SupervisorHandle,
    SupervisorTiming,
};
use motorbench::machine::im::{
    run_im_sweep, sim_im_rig, sweep_channels, ImRunConfig, SimDyno, SimVfd,
};
use motorbench::record::EventLevel;
use motorbench_drivers::{DriverError, PowerStage, StageCapabilities};

/// What the stages saw of a stop: `(stage, cause already recorded?)` per
/// safe-state command, in order.
type Log = Arc<Mutex<Vec<(String, bool)>>>;

/// A stage that notes each safe-state command and whether the
/// supervisor had recorded a stop by then.
struct Noting {
    inner: Box<dyn PowerStage>,
    name: &'static str,
    log: Log,
    handle: Arc<OnceLock<SupervisorHandle>>,
}

#[async_trait]
impl PowerStage for Noting {
    fn id(&self) -> &str {
        self.inner.id()
    }
    fn capabilities(&self) -> StageCapabilities {
        self.inner.capabilities()
    }
    async fn set_setpoint(&mut self, v: f64) -> Result<(), DriverError> {
        self.inner.set_setpoint(v).await
    }
    async fn set_output_enabled(&mut self, on: bool) -> Result<(), DriverError> {
        self.inner.set_output_enabled(on).await
    }
    async fn safe_state(&mut self) -> Result<(), DriverError> {
        let recorded = self.handle.get().is_some_and(|h| h.stopped().is_some());
        self.log
            .lock()
            .unwrap()
            .push((self.name.to_string(), recorded));
        self.inner.safe_state().await
    }
}

struct Ran {
    outcome: Outcome,
    log: Vec<(String, bool)>,
    vfd: SimVfd,
    dyno: SimDyno,
    events: Vec<(EventLevel, String)>,
    stop_kind: Option<&'static str>,
}

/// Run the shipped IM configuration's sweep under supervision, its
/// current limit at `max_current`; `stop_at_s` asks for `cause` once the
/// test time passes it.
async fn run(max_current: f64, stop_at: Option<(f64, StopCause)>) -> Ran {
    run_with(|cfg| cfg.common.limits.max_current = max_current, stop_at).await
}

/// [`run`] with the configuration edited by `edit`.
async fn run_with(edit: impl FnOnce(&mut ImRunConfig), stop_at: Option<(f64, StopCause)>) -> Ran {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-im.toml");
    let mut cfg = ImRunConfig::load(std::path::Path::new(path)).unwrap();
    edit(&mut cfg);
    cfg.plan.slips.truncate(12);
    cfg.plan.voltages.truncate(1);
    let sim = cfg.simulated.clone().unwrap();
    let (vfd, dyno, sensors) = sim_im_rig(sim).unwrap();
    let sensors = sensors.paced();
    let channels = motorbench_drivers::SensorStream::channels(&sensors).to_vec();
    let monitor = SafetyMonitor::new(
        cfg.common.limits,
        cfg.common.supervision.clone(),
        &channels,
        Some(cfg.plan.encoder_counts_per_rev),
        0.0,
    )
    .unwrap();
    let log: Log = Arc::default();
    let handle_slot = Arc::new(OnceLock::new());
    let noting = |inner: Box<dyn PowerStage>, name| -> Box<dyn PowerStage> {
        Box::new(Noting {
            inner,
            name,
            log: log.clone(),
            handle: handle_slot.clone(),
        })
    };
    let record_channels = sweep_channels(&channels, vfd.id(), dyno.id());
    let s = supervise_stages(
        vec![
            (
                noting(Box::new(vfd.clone()), "supply"),
                cfg.common.limits.max_voltage,
            ),
            (
                noting(Box::new(dyno.clone()), "dynamometer"),
                cfg.common.limits.max_speed,
            ),
        ],
        Box::new(sensors),
        monitor,
        SupervisorTiming::new(
            cfg.common.supervision.bus_loss_timeout,
            cfg.common.sample_rate_hz,
        ),
    );
    handle_slot.set(s.handle.clone()).unwrap();
    let handle = s.handle.clone();
    let [mut supply, mut dynamometer]: [_; 2] = s.stages.try_into().ok().unwrap();
    let mut sensors = s.sensors;
    let mut sink = RecordSink::new(None, None, record_channels);
    let stopper = stop_at.map(|(at_s, cause)| {
        let h = handle.clone();
        tokio::spawn(async move {
            let mut readings = h.readings();
            let _ = readings.wait_for(|r| r.t_s >= at_s).await;
            h.stop(cause).await
        })
    });
    let outcome = run_im_sweep(
        &cfg.plan,
        &cfg.safety_rules(),
        &mut supply,
        &mut dynamometer,
        &mut sensors,
        &mut sink,
        &NoProgress,
        // As the daemon does: the sweep's own trips go to the supervisor.
        &handle,
    )
    .await
    .unwrap();
    if let Some(t) = stopper {
        t.abort();
    }
    let stop_kind = handle.stopped().map(|s| s.cause.kind());
    handle.finish().await;
    let (_, record) = sink.into_parts();
    let log = log.lock().unwrap().clone();
    Ran {
        outcome,
        log,
        vfd,
        dyno,
        events: record
            .events
            .iter()
            .map(|(_, e)| (e.level, e.message.clone()))
            .collect(),
        stop_kind,
    }
}

fn assert_both_safe_first(r: &Ran) {
    // The supervisor's commands come first, supply then dynamometer, each
    // before the stop was recorded; the sweep's own safe state follows.
    assert!(r.log.len() >= 2, "{:?}", r.log);
    assert_eq!(r.log[0], ("supply".to_string(), false), "{:?}", r.log);
    assert_eq!(r.log[1], ("dynamometer".to_string(), false), "{:?}", r.log);
    assert!(!r.vfd.output_enabled(), "supply output off");
    assert_eq!(r.dyno.command(), (0.0, true), "dynamometer braking to rest");
    assert!(
        matches!(r.outcome, Outcome::Aborted { .. }),
        "{:?}",
        r.outcome
    );
    assert!(
        r.events
            .iter()
            .any(|(l, m)| *l == EventLevel::Abort && m.contains("supply off, dynamometer braking")),
        "{:?}",
        r.events
    );
}

#[tokio::test(start_paused = true)]
async fn a_current_trip_makes_both_stages_safe_before_the_cause_is_recorded() {
    // Locked rotor at 400 V draws about 48 A: a 30 A limit trips mid-sweep.
    let r = run(30.0, None).await;
    assert_eq!(r.stop_kind, Some("limit"));
    assert_both_safe_first(&r);
}

#[tokio::test(start_paused = true)]
async fn the_sweeps_own_heating_budget_trips_through_the_supervisor() {
    // Only the sweep's monitor counts I²t here (the supervisor's is built
    // without the plan's budget): spent, the sweep hands the stop to the
    // supervisor, which makes both stages safe and latches the rig.
    let r = run_with(|cfg| cfg.plan.max_i2t_s = 0.5, None).await;
    assert_eq!(r.stop_kind, Some("heating_budget"), "{:?}", r.events);
    assert_both_safe_first(&r);
    assert!(
        r.events.iter().any(|(l, m)| *l == EventLevel::Abort
            && m.contains("stopped by the safety supervisor")
            && m.contains("heating budget spent")),
        "{:?}",
        r.events
    );
}

#[tokio::test(start_paused = true)]
async fn an_operator_abort_and_an_emergency_stop_make_both_stages_safe() {
    for cause in [
        StopCause::OperatorAbort,
        StopCause::EmergencyStop {
            source: "API".into(),
        },
        StopCause::Shutdown,
    ] {
        let kind = cause.kind();
        let r = run(70.0, Some((3.0, cause))).await;
        assert_eq!(r.stop_kind, Some(kind));
        assert_both_safe_first(&r);
    }
}

#[tokio::test(start_paused = true)]
async fn without_a_stop_the_sweep_completes_under_supervision() {
    let r = run(70.0, None).await;
    assert_eq!(r.outcome, Outcome::Completed);
    assert_eq!(r.stop_kind, None);
    // Only the sweep's own safe state at the end, both stages.
    assert_eq!(r.log.len(), 2, "{:?}", r.log);
    assert!(!r.vfd.output_enabled());
}
