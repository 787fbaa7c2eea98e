//! The safety supervisor at run time: a task that owns the sensor stream,
//! checks every batch before the sequencer sees it, watches for bus loss,
//! pets the power stage's heartbeat while healthy, and on any reason to
//! stop commands the safe state *first*, then records the cause, then
//! hands the sequencer an error so the test ends as aborted.
//!
//! [`supervise`] splits a rig into (and [`supervise_stages`], for a rig with
//! several stages such as the induction-machine rig's supply VFD and
//! dynamometer):
//!
//! - an [`InterlockedStage`] per stage for the sequencer: it forwards
//!   commands to the stage until the supervisor stops the test, then
//!   refuses all but the safe state (and set points beyond the limit,
//!   always);
//! - [`SupervisedSensors`] for the sequencer: the batches the supervisor
//!   has checked, then, after a stop, one more batch read after the safe
//!   state took effect (so the record shows it) and an error
//!   ([`super::SUPERVISOR_ID`]) whose text is the cause;
//! - a [`SupervisorHandle`] for the daemon: operator stops, the trip,
//!   health, the latest readings.
//!
//! Operator stops ([`SupervisorHandle::stop`]) and the trips the sequencer
//! sees before the supervisor does ([`SupervisorHandle::trip`], through
//! [`super::StopPath`]) take the same path as the supervisor's own trips;
//! the reply comes once the safe-state command has returned. With
//! several stages every stage is commanded to its safe state at once (the
//! commands go out in the order the stages were given: the supply first),
//! and the stop is recorded once all have returned.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex as StdMutex};
use std::time::Duration;

use async_trait::async_trait;
use motorbench_drivers::{
    ChannelInfo, ChannelStats, DriverError, PowerStage, SampleBatch, SensorStream,
    StageCapabilities,
};
use tokio::sync::{mpsc, oneshot, watch, Mutex, MutexGuard, Notify};
use tokio::time::Instant;

use super::escalation::escalate;
use super::supervisor::{Readings, SafetyMonitor, StopCause, SUPERVISOR_ID};

/// The power stage, shared by the sequencer's [`InterlockedStage`] and the
/// supervisor task.
type SharedStage = Arc<Mutex<Box<dyn PowerStage>>>;

/// What the supervisor did about a stop.
#[derive(Debug, Clone, PartialEq)]
pub struct StopReport {
    /// Why.
    pub cause: StopCause,
    /// Data time of the latest batch when the stop was requested or the
    /// trip detected, ns.
    pub requested_t_ns: u64,
    /// The safe-state command's result.
    pub safe_state: Result<(), String>,
    /// Wall-clock time from the request (or detection) to the return of
    /// the safe-state command.
    pub safe_after: Duration,
    /// Data time of the first batch read after the safe-state command
    /// returned, ns (when one came).
    pub first_safe_t_ns: Option<u64>,
    /// The escalation's steps, when a stage's output stayed on after the
    /// safe command (see `bench/escalation.rs`), in order.
    pub escalation: Vec<String>,
}

impl StopReport {
    /// One line for a person and for the record.
    pub fn describe(&self) -> String {
        let safe = match &self.safe_state {
            Ok(()) => format!(
                "rig commanded to its safe state {:.3} ms after the {} (test time {:.4} s)",
                self.safe_after.as_secs_f64() * 1e3,
                if matches!(
                    self.cause,
                    StopCause::OperatorAbort
                        | StopCause::Shutdown
                        | StopCause::EmergencyStop { .. }
                ) {
                    "request"
                } else {
                    "detection"
                },
                self.requested_t_ns as f64 * 1e-9
            ),
            Err(e) => format!("SAFE-STATE COMMAND FAILED: {e}"),
        };
        format!("{}; {safe}", self.cause)
    }
}

/// State shared by the supervisor task and its handles.
#[derive(Debug)]
struct Shared {
    stopped: AtomicBool,
    /// Why, from the moment `stopped` is set (the report comes once the
    /// safe-state commands have returned), so a command refused meanwhile
    /// names the cause.
    cause: StdMutex<Option<StopCause>>,
    stop: StdMutex<Option<StopReport>>,
    safe_state_failed: AtomicBool,
    /// Milliseconds since `epoch` at the task's latest loop.
    alive_ms: AtomicU64,
    epoch: Instant,
}

impl Shared {
    fn touch(&self) {
        let ms = self.epoch.elapsed().as_millis() as u64;
        self.alive_ms.store(ms, Ordering::Relaxed);
    }
}

fn lock<T>(m: &StdMutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Commands to the supervisor task.
enum Command {
    /// The cause, when it was requested, the data time of the reading
    /// that showed it (for a trip seen by the sequencer), the reply.
    Stop(StopCause, Instant, Option<u64>, oneshot::Sender<StopReport>),
    Finish,
}

/// How the supervisor ended.
#[derive(Debug, Clone)]
pub struct SupervisorSummary {
    /// The stop, if there was one.
    pub stop: Option<StopReport>,
    /// Winding rise above ambient at the end, K.
    pub winding_rise_k: f64,
    /// Batches checked.
    pub batches: u64,
    /// Heartbeats sent to the power stage.
    pub heartbeats: u64,
}

/// The daemon's view of a running supervisor.
#[derive(Debug, Clone)]
pub struct SupervisorHandle {
    commands: mpsc::Sender<Command>,
    shared: Arc<Shared>,
    readings: watch::Receiver<Readings>,
    loop_period: Duration,
}

impl std::fmt::Debug for Command {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Command::Stop(c, ..) => write!(f, "Stop({c})"),
            Command::Finish => write!(f, "Finish"),
        }
    }
}

impl SupervisorHandle {
    /// Stop the test: the safe state first, then the cause is recorded.
    /// Returns once the safe-state command has returned; `None` when the
    /// supervisor has already finished. A second stop returns the first
    /// one's report.
    pub async fn stop(&self, cause: StopCause) -> Option<StopReport> {
        self.request(cause, None).await
    }

    /// A trip the sequencer saw first, in the reading at data time `t_ns`:
    /// the same path as [`SupervisorHandle::stop`] (safe state, latch,
    /// record), with the stop dated at that reading.
    pub async fn trip(&self, cause: StopCause, t_ns: u64) -> Option<StopReport> {
        self.request(cause, Some(t_ns)).await
    }

    async fn request(&self, cause: StopCause, t_ns: Option<u64>) -> Option<StopReport> {
        let (tx, rx) = oneshot::channel();
        let requested = Instant::now();
        self.commands
            .send(Command::Stop(cause, requested, t_ns, tx))
            .await
            .ok()?;
        rx.await.ok()
    }

    /// The stop, once there is one.
    pub fn stopped(&self) -> Option<StopReport> {
        lock(&self.shared.stop).clone()
    }

    /// The latest readings.
    pub fn readings(&self) -> watch::Receiver<Readings> {
        self.readings.clone()
    }

    /// Healthy: the task is looping (it loops at least every heartbeat
    /// period) and no safe-state command has failed.
    pub fn healthy(&self) -> bool {
        let now = self.shared.epoch.elapsed().as_millis() as u64;
        let alive = self.shared.alive_ms.load(Ordering::Relaxed);
        let stale_ms = (4 * self.loop_period.as_millis() as u64).max(1000);
        !self.shared.safe_state_failed.load(Ordering::Relaxed)
            && now.saturating_sub(alive) <= stale_ms
    }

    /// Ask the task to end (after the sequencer is done).
    pub async fn finish(&self) {
        let _ = self.commands.send(Command::Finish).await;
    }
}

/// The power stage as the sequencer sees it. See the module docs.
pub struct InterlockedStage {
    id: String,
    capabilities: StageCapabilities,
    stage: SharedStage,
    shared: Arc<Shared>,
    max_setpoint: f64,
}

impl InterlockedStage {
    fn refuse(&self, what: &str) -> DriverError {
        let why = lock(&self.shared.cause).as_ref().map_or_else(
            || "the test was stopped".to_string(),
            |cause| cause.to_string(),
        );
        DriverError::Device {
            device: SUPERVISOR_ID.into(),
            reason: format!("{what} refused after the stop: {why}"),
        }
    }

    /// The stage, locked, to command `what`: refused once the test is
    /// stopped. Checked under the lock: a stop takes the lock before
    /// commanding the safe state, so nothing gets past it.
    async fn unless_stopped(
        &self,
        what: &str,
    ) -> Result<MutexGuard<'_, Box<dyn PowerStage>>, DriverError> {
        let stage = self.stage.lock().await;
        if self.shared.stopped.load(Ordering::SeqCst) {
            return Err(self.refuse(what));
        }
        Ok(stage)
    }
}

#[async_trait]
impl PowerStage for InterlockedStage {
    fn id(&self) -> &str {
        &self.id
    }

    fn capabilities(&self) -> StageCapabilities {
        self.capabilities
    }

    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError> {
        if !value.is_finite() || value.abs() > self.max_setpoint {
            return Err(DriverError::Device {
                device: SUPERVISOR_ID.into(),
                reason: format!(
                    "set point {value} is beyond the limit ±{}",
                    self.max_setpoint
                ),
            });
        }
        self.unless_stopped("set point")
            .await?
            .set_setpoint(value)
            .await
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        let mut stage = self.stage.lock().await;
        if enabled && self.shared.stopped.load(Ordering::SeqCst) {
            return Err(self.refuse("output enable"));
        }
        stage.set_output_enabled(enabled).await
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        self.stage.lock().await.safe_state().await
    }

    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        self.stage.lock().await.read_output_enabled().await
    }

    async fn set_current_limit(&mut self, amperes: f64) -> Result<(), DriverError> {
        self.unless_stopped("current limit")
            .await?
            .set_current_limit(amperes)
            .await
    }

    async fn set_frequency(&mut self, hz: f64) -> Result<(), DriverError> {
        self.unless_stopped("frequency")
            .await?
            .set_frequency(hz)
            .await
    }
}

/// The sensor stream as the sequencer sees it. See the module docs.
pub struct SupervisedSensors {
    id: String,
    channels: Vec<ChannelInfo>,
    rx: mpsc::Receiver<Result<SampleBatch, DriverError>>,
    telemetry: Arc<StdMutex<Telemetry>>,
    /// A stream on a virtual clock: each call asks the supervisor for one
    /// batch (see [`read_next`]).
    demand: Option<Arc<Notify>>,
}

/// The supervised stream's own sampling statistics and warnings, relayed
/// from the supervisor task (which owns the stream) to the sequencer, so
/// a supervised record keeps them like an unsupervised one.
#[derive(Default)]
struct Telemetry {
    stats: Vec<ChannelStats>,
    warnings: Vec<String>,
}

#[async_trait]
impl SensorStream for SupervisedSensors {
    fn id(&self) -> &str {
        &self.id
    }

    fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        if let Some(demand) = &self.demand {
            demand.notify_one();
        }
        match self.rx.recv().await {
            Some(r) => r,
            None => Err(DriverError::Ended {
                device: SUPERVISOR_ID.into(),
            }),
        }
    }

    fn sampling_stats(&self) -> Vec<ChannelStats> {
        lock_telemetry(&self.telemetry).stats.clone()
    }

    fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut lock_telemetry(&self.telemetry).warnings)
    }
}

fn lock_telemetry(t: &StdMutex<Telemetry>) -> std::sync::MutexGuard<'_, Telemetry> {
    t.lock().unwrap_or_else(|e| e.into_inner())
}

/// A rig under supervision. See the module docs.
pub struct Supervised {
    /// For the sequencer.
    pub stage: InterlockedStage,
    /// For the sequencer.
    pub sensors: SupervisedSensors,
    /// For the daemon.
    pub handle: SupervisorHandle,
    /// The task; its result once [`SupervisorHandle::finish`] was called.
    pub task: tokio::task::JoinHandle<SupervisorSummary>,
}

/// Timing of the supervisor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupervisorTiming {
    /// No batch for this long is a bus loss.
    pub bus_loss: Duration,
    /// Batches the sequencer may fall behind before it counts as stalled.
    pub queue: usize,
}

impl SupervisorTiming {
    /// From the configured bus-loss timeout and the sample rate: the
    /// queue holds two bus-loss timeouts of batches (at least 64).
    pub fn new(bus_loss_s: f64, sample_rate_hz: f64) -> SupervisorTiming {
        SupervisorTiming {
            bus_loss: Duration::from_secs_f64(bus_loss_s),
            queue: ((2.0 * bus_loss_s * sample_rate_hz).ceil() as usize).max(64),
        }
    }
}

type ReadResult = (
    Box<dyn SensorStream>,
    Result<Result<SampleBatch, DriverError>, tokio::time::error::Elapsed>,
);

/// The next read of `sensors`. A stream on a virtual clock is read only
/// when the sequencer asks for a batch (`demand`): its simulation advances
/// only as it is read, so reading ahead would run the plant ahead of the
/// plan's commands (a step would reach the record late) and fill the
/// queue, a stall of nothing. A live stream is read on regardless, so a
/// stalled sequencer is caught.
fn read_next(
    mut sensors: Box<dyn SensorStream>,
    bus_loss: Duration,
    telemetry: Arc<StdMutex<Telemetry>>,
    demand: Option<Arc<Notify>>,
) -> std::pin::Pin<Box<dyn std::future::Future<Output = ReadResult> + Send>> {
    Box::pin(async move {
        if let Some(demand) = demand {
            demand.notified().await;
        }
        let r = tokio::time::timeout(bus_loss, sensors.next_batch()).await;
        let warnings = sensors.take_warnings();
        let stats = sensors.sampling_stats();
        let mut t = lock_telemetry(&telemetry);
        t.warnings.extend(warnings);
        t.stats = stats;
        drop(t);
        (sensors, r)
    })
}

/// Put `stage` and `sensors` under supervision and start the supervisor
/// task (on the current tokio runtime). `max_setpoint` bounds every set
/// point the sequencer may command.
pub fn supervise(
    stage: Box<dyn PowerStage>,
    sensors: Box<dyn SensorStream>,
    monitor: SafetyMonitor,
    timing: SupervisorTiming,
    max_setpoint: f64,
) -> Supervised {
    let s = supervise_stages(vec![(stage, max_setpoint)], sensors, monitor, timing);
    Supervised {
        stage: s.stages.into_iter().next().expect("one stage in, one out"),
        sensors: s.sensors,
        handle: s.handle,
        task: s.task,
    }
}

/// A rig of several stages under supervision. See the module docs.
pub struct SupervisedStages {
    /// For the sequencer, in the order given.
    pub stages: Vec<InterlockedStage>,
    /// For the sequencer.
    pub sensors: SupervisedSensors,
    /// For the daemon.
    pub handle: SupervisorHandle,
    /// The task; its result once [`SupervisorHandle::finish`] was called.
    pub task: tokio::task::JoinHandle<SupervisorSummary>,
}

/// Put several stages (each with the bound of its set points) and one
/// sensor stream under supervision and start the supervisor task. A stop
/// commands every stage to its safe state at once, in the order given
/// (put the stage that feeds the machine first).
pub fn supervise_stages(
    stages: Vec<(Box<dyn PowerStage>, f64)>,
    sensors: Box<dyn SensorStream>,
    monitor: SafetyMonitor,
    timing: SupervisorTiming,
) -> SupervisedStages {
    let shared = Arc::new(Shared {
        stopped: AtomicBool::new(false),
        cause: StdMutex::new(None),
        stop: StdMutex::new(None),
        safe_state_failed: AtomicBool::new(false),
        alive_ms: AtomicU64::new(0),
        epoch: Instant::now(),
    });
    let heartbeat = stages
        .iter()
        .filter_map(|(s, _)| s.heartbeat_timeout())
        .min()
        .map(|t| t / 4);
    let loop_period = heartbeat
        .unwrap_or(Duration::from_millis(100))
        .min(Duration::from_millis(100));
    let mut interlocked = Vec::new();
    let mut shared_stages = Vec::new();
    for (stage, max_setpoint) in stages {
        let id = stage.id().to_string();
        let capabilities = stage.capabilities();
        let stage: SharedStage = Arc::new(Mutex::new(stage));
        shared_stages.push(stage.clone());
        interlocked.push(InterlockedStage {
            id,
            capabilities,
            stage,
            shared: shared.clone(),
            max_setpoint,
        });
    }
    let (batch_tx, batch_rx) = mpsc::channel(timing.queue);
    let (cmd_tx, cmd_rx) = mpsc::channel(8);
    let (readings_tx, readings_rx) = watch::channel(monitor.readings());
    let telemetry = Arc::new(StdMutex::new(Telemetry::default()));
    let demand = sensors.virtual_clock().then(|| Arc::new(Notify::new()));
    let sensors_out = SupervisedSensors {
        id: sensors.id().to_string(),
        channels: sensors.channels().to_vec(),
        rx: batch_rx,
        telemetry: telemetry.clone(),
        demand: demand.clone(),
    };
    let task = Task {
        stages: shared_stages,
        shared: shared.clone(),
        monitor,
        batch_tx,
        readings: readings_tx,
        stream_id: sensors.id().to_string(),
        timing,
        heartbeat,
        loop_period,
        heartbeats: 0,
        batches: 0,
        stop_delivered: false,
        read_after_safe: false,
        telemetry,
        demand,
    };
    let task = tokio::spawn(task.run(sensors, cmd_rx));
    SupervisedStages {
        stages: interlocked,
        sensors: sensors_out,
        handle: SupervisorHandle {
            commands: cmd_tx,
            shared,
            readings: readings_rx,
            loop_period,
        },
        task,
    }
}

struct Task {
    stages: Vec<SharedStage>,
    shared: Arc<Shared>,
    monitor: SafetyMonitor,
    batch_tx: mpsc::Sender<Result<SampleBatch, DriverError>>,
    readings: watch::Sender<Readings>,
    stream_id: String,
    timing: SupervisorTiming,
    heartbeat: Option<Duration>,
    loop_period: Duration,
    heartbeats: u64,
    batches: u64,
    /// The error has been handed to the sequencer.
    stop_delivered: bool,
    /// The read in flight began after the safe-state command returned.
    read_after_safe: bool,
    /// Where the stream's statistics and warnings go for the sequencer.
    telemetry: Arc<StdMutex<Telemetry>>,
    /// The sequencer's requests for a batch, when the stream is on a
    /// virtual clock (see [`read_next`]).
    demand: Option<Arc<Notify>>,
}

impl Task {
    async fn run(
        mut self,
        sensors: Box<dyn SensorStream>,
        mut commands: mpsc::Receiver<Command>,
    ) -> SupervisorSummary {
        self.shared.touch();
        let mut read = read_next(
            sensors,
            self.timing.bus_loss,
            self.telemetry.clone(),
            self.demand.clone(),
        );
        let mut tick = tokio::time::interval(self.loop_period);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        // On a virtual clock the stage's watchdog runs on data time, which
        // outpaces the wall clock: the heartbeat goes out every loop period
        // of data time as well.
        let loop_period_ns = self.loop_period.as_nanos() as u64;
        let mut next_data_pet = self.demand.as_ref().map(|_| 0u64);
        let mut reading = true;
        loop {
            tokio::select! {
                biased;
                cmd = commands.recv() => match cmd {
                    Some(Command::Stop(cause, requested, t_ns, reply)) => {
                        let report = self.stop_at(cause, requested, t_ns).await;
                        let _ = reply.send(report);
                        if !reading {
                            self.deliver_stop().await;
                        }
                    }
                    Some(Command::Finish) | None => break,
                },
                // Before the read: when the sensors deliver in a burst
                // (catching up after a stall) the heartbeat still goes out.
                _ = tick.tick() => {
                    self.pet().await;
                }
                (sensors, result) = &mut read, if reading => {
                    let read_after_safe = self.read_after_safe;
                    match result {
                        Err(_) => {
                            let cause = StopCause::BusLoss {
                                stream: self.stream_id.clone(),
                                timeout_s: self.timing.bus_loss.as_secs_f64(),
                            };
                            self.stop(cause, Instant::now()).await;
                            reading = false;
                            self.deliver_stop().await;
                        }
                        Ok(Err(e)) => {
                            let cause = StopCause::DeviceFault(e.to_string());
                            self.stop(cause, Instant::now()).await;
                            reading = false;
                            self.deliver_stop().await;
                        }
                        Ok(Ok(batch)) => {
                            self.batches += 1;
                            if let Some(next) = next_data_pet.as_mut() {
                                if batch.t_ns >= *next {
                                    *next = batch.t_ns + loop_period_ns;
                                    self.pet().await;
                                }
                            }
                            let check = self.monitor.check(&batch);
                            let _ = self.readings.send(self.monitor.readings());
                            if let Err(cause) = check {
                                self.stop(cause, Instant::now()).await;
                            }
                            let t_ns = batch.t_ns;
                            if self.shared.stopped.load(Ordering::SeqCst) {
                                if read_after_safe {
                                    if let Some(s) = lock(&self.shared.stop).as_mut() {
                                        s.first_safe_t_ns.get_or_insert(t_ns);
                                    }
                                }
                                // The offending batch, and batches up to the
                                // first one read after the safe state, still
                                // go to the record.
                                self.forward(Ok(batch)).await;
                                // The supervisor reads on after the stop (the
                                // readings stay live until the daemon finishes
                                // it), but the sequencer gets no more batches.
                                if read_after_safe {
                                    self.deliver_stop().await;
                                }
                            } else {
                                self.forward(Ok(batch)).await;
                            }
                        }
                    }
                    read = read_next(
                        sensors,
                        self.timing.bus_loss,
                        self.telemetry.clone(),
                        self.demand.clone(),
                    );
                    self.read_after_safe = self.shared.stopped.load(Ordering::SeqCst);
                },
            }
            self.shared.touch();
        }
        SupervisorSummary {
            stop: lock(&self.shared.stop).clone(),
            winding_rise_k: self.monitor.winding().rise_k(),
            batches: self.batches,
            heartbeats: self.heartbeats,
        }
    }

    /// Pet the stage's heartbeat while healthy.
    async fn pet(&mut self) {
        if self.heartbeat.is_none() || self.shared.safe_state_failed.load(Ordering::Relaxed) {
            return;
        }
        for stage in self.stages.clone() {
            let mut stage = stage.lock().await;
            if stage.heartbeat_timeout().is_none() {
                continue;
            }
            let result = stage.heartbeat().await;
            let id = stage.id().to_string();
            drop(stage);
            match result {
                Ok(()) => self.heartbeats += 1,
                Err(e) => {
                    let cause = StopCause::DeviceFault(format!("{id} heartbeat: {e}"));
                    self.stop(cause, Instant::now()).await;
                    return;
                }
            }
        }
    }

    /// Queue an item for the sequencer; a full queue means it stalled.
    async fn forward(&mut self, item: Result<SampleBatch, DriverError>) {
        if self.stop_delivered {
            return;
        }
        match self.batch_tx.try_send(item) {
            Ok(()) => {}
            Err(mpsc::error::TrySendError::Full(_)) => {
                self.stop(StopCause::SequencerStalled, Instant::now()).await;
            }
            // The sequencer is gone (the test ended): nothing to hand on.
            Err(mpsc::error::TrySendError::Closed(_)) => {}
        }
    }

    /// Hand the sequencer the error that ends the test.
    async fn deliver_stop(&mut self) {
        if self.stop_delivered {
            return;
        }
        let Some(report) = lock(&self.shared.stop).clone() else {
            return;
        };
        let error = DriverError::Device {
            device: SUPERVISOR_ID.into(),
            reason: report.describe(),
        };
        // After a stall the queue is full: make room for the error by
        // letting the batch wait asynchronously; the sequencer reads the
        // backlog first.
        let tx = self.batch_tx.clone();
        self.stop_delivered = true;
        tokio::spawn(async move {
            let _ = tx.send(Err(error)).await;
        });
    }

    /// The safe state first, then the cause recorded. A second stop keeps
    /// the first report.
    async fn stop(&mut self, cause: StopCause, requested: Instant) -> StopReport {
        self.stop_at(cause, requested, None).await
    }

    /// [`Task::stop`], dated at `t_ns` (data time) when given, else at the
    /// latest batch checked.
    async fn stop_at(
        &mut self,
        cause: StopCause,
        requested: Instant,
        t_ns: Option<u64>,
    ) -> StopReport {
        if let Some(first) = lock(&self.shared.stop).clone() {
            return first;
        }
        *lock(&self.shared.cause) = Some(cause.clone());
        self.shared.stopped.store(true, Ordering::SeqCst);
        // Every stage at once; each under its lock, so no command of the
        // sequencer's gets past it.
        let results = futures_util::future::join_all(self.stages.iter().map(|stage| async move {
            let mut stage = stage.lock().await;
            stage.safe_state().await
        }))
        .await;
        let safe_after = requested.elapsed();
        // A stage that acknowledged the safe command may not have acted on
        // it: read back, escalate (a failed command is reported as such).
        let last_resort = self.monitor.supervision().last_resort.clone();
        let mut escalation = Vec::new();
        let mut failures: Vec<(String, String)> = Vec::new();
        for (stage, r) in self.stages.iter().zip(results) {
            let mut stage = stage.lock().await;
            let id = stage.id().to_string();
            if let Err(e) = r {
                failures.push((id, e.to_string()));
                continue;
            }
            let e = escalate(stage.as_mut(), last_resort.as_ref()).await;
            escalation.extend(e.steps);
            if let Err(e) = e.outcome {
                failures.push((id, e));
            }
        }
        let safe_state = match failures.as_slice() {
            [] => Ok(()),
            [(_, e)] if self.stages.len() == 1 => Err(e.clone()),
            many => Err(many
                .iter()
                .map(|(id, e)| format!("{id}: {e}"))
                .collect::<Vec<_>>()
                .join("; ")),
        };
        if safe_state.is_err() {
            self.shared.safe_state_failed.store(true, Ordering::Relaxed);
        }
        let report = StopReport {
            cause,
            requested_t_ns: t_ns.unwrap_or_else(|| self.monitor.last_t_ns()),
            safe_state,
            safe_after,
            first_safe_t_ns: None,
            escalation,
        };
        match &report.safe_state {
            Ok(()) => tracing::warn!(target: "motorbench::supervisor", "{}", report.describe()),
            Err(_) => tracing::error!(target: "motorbench::supervisor", "{}", report.describe()),
        }
        *lock(&self.shared.stop) = Some(report.clone());
        report
    }
}
