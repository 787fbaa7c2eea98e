//! One test run by the daemon, whatever the machine: the session
//! ([`crate::session`]) opens the rig, the rig is put under the safety
//! supervisor, the record started and indexed, the plan run, then the
//! analysis, the report files and the index updated. Progress (phase,
//! segment, current values, ETA) is published on a watch channel for the
//! API's live feed.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex as StdMutex};
use std::time::SystemTime;

use serde::Serialize;
use tokio::sync::{watch, Mutex};

use super::link_tally::LinkTally;
use super::metrics::{Metrics, TestEnd};
use super::records_index::{
    on_index, unix_s, with_locked, IndexEntry, IndexError, KeyResults, RecordOutcome, RecordsIndex,
};
use crate::bench::{Outcome, Progress, Readings, StopCause, StopReport, SupervisorHandle};
use crate::diagnose::write_residual_svg;
use crate::machine::{Machine, PlanDurations};
use crate::record::{OperatingPoint, RecorderBacklog, SegmentKind};
use crate::session::{Recording, RunEnd, Session, SessionError, Supervised};

/// Where a test is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum TestState {
    /// The plan is running on the rig.
    Running,
    /// The rig is safe; identification and the report are being made.
    Identifying,
    /// Done: see the outcome.
    Finished,
}

/// The segment being run.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct SegmentStatus {
    /// Index, from 0.
    pub index: usize,
    /// Number of segments in the plan.
    pub total: usize,
    /// Label, e.g. `60 V → 248 V`.
    pub label: String,
    /// Test kind of the segment (`dc_step`, `dc_coastdown`, `im_slip_sweep`, …).
    #[schema(value_type = String)]
    pub kind: SegmentKind,
}

/// What the supervisor did to stop the test.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct StopStatus {
    /// Machine-readable cause (`operator_abort`, `limit`, …).
    pub kind: String,
    /// For a person.
    pub message: String,
    /// Whether the safe-state command succeeded.
    pub safe_state_ok: bool,
    /// Wall-clock time from the request (or detection) to the safe-state
    /// command's return, s.
    pub safe_after_s: f64,
    /// Test time of the last sample before the request, s.
    pub requested_t_s: f64,
    /// Test time of the first sample read after the safe state, s.
    pub first_safe_sample_t_s: Option<f64>,
}

impl From<&StopReport> for StopStatus {
    fn from(r: &StopReport) -> StopStatus {
        StopStatus {
            kind: r.cause.kind().to_string(),
            message: r.describe(),
            safe_state_ok: r.safe_state.is_ok(),
            safe_after_s: r.safe_after.as_secs_f64(),
            requested_t_s: r.requested_t_ns as f64 * 1e-9,
            first_safe_sample_t_s: r.first_safe_t_ns.map(|t| t as f64 * 1e-9),
        }
    }
}

/// An operating point of a running sweep, as the live feed shows it (the
/// record's `/bench/operating_point`, SI units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, utoipa::ToSchema)]
pub struct PointStatus {
    /// Segment (the sweep's supply voltage) index.
    pub segment: u32,
    /// Slip, 0 (synchronous) to 1 (locked rotor).
    pub slip: f64,
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// RMS line current, A.
    pub line_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Shaft speed, rad/s.
    pub speed: f64,
    /// The winding thermometer's mean over the point's window, °C, where
    /// the rig has one (absent otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub winding_temperature: Option<f64>,
}

impl From<&OperatingPoint> for PointStatus {
    fn from(p: &OperatingPoint) -> PointStatus {
        PointStatus {
            segment: p.segment,
            slip: p.slip,
            line_voltage: p.line_voltage,
            line_current: p.line_current,
            input_power: p.input_power,
            speed: p.speed,
            winding_temperature: p.winding_temperature,
        }
    }
}

/// A test's status, as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct TestStatus {
    /// Test id (also the record name).
    pub id: String,
    /// The rig.
    pub rig: String,
    /// Motor under test.
    pub motor_id: String,
    /// The plan, for a person.
    pub plan: String,
    /// Where the test is.
    pub state: TestState,
    /// The segment being run.
    pub segment: Option<SegmentStatus>,
    /// Test time, s.
    pub t_s: f64,
    /// Estimated time to the end of the plan, s.
    pub eta_s: Option<f64>,
    /// Longest it can still take (every remaining step to its timeout), s.
    pub eta_max_s: Option<f64>,
    /// The latest readings the supervisor checked.
    pub values: Readings,
    /// How it ended, once finished.
    pub outcome: Option<RecordOutcome>,
    /// Why it was aborted or failed.
    pub reason: Option<String>,
    /// The supervisor's stop, if there was one.
    pub stop: Option<StopStatus>,
    /// The operating points a sweep has recorded so far, in order (empty
    /// for a test that has none).
    pub operating_points: Vec<PointStatus>,
}

impl TestStatus {
    /// The status of a test that has just started running.
    pub fn running(id: &str, rig: &str, motor_id: &str, plan: String) -> TestStatus {
        TestStatus {
            id: id.to_string(),
            rig: rig.to_string(),
            motor_id: motor_id.to_string(),
            plan,
            state: TestState::Running,
            segment: None,
            t_s: 0.0,
            eta_s: None,
            eta_max_s: None,
            values: Readings::default(),
            outcome: None,
            reason: None,
            stop: None,
            operating_points: Vec::new(),
        }
    }
}

/// A test the daemon runs or ran; shared by the API and the job.
#[derive(Debug)]
pub struct TestRun {
    pub(super) status: watch::Sender<TestStatus>,
    pub(super) supervisor: SupervisorHandle,
    links: LinkTally,
    backlog: RecorderBacklog,
}

impl TestRun {
    /// The rig's links for this test, and what the metrics took of them.
    pub fn links(&self) -> &LinkTally {
        &self.links
    }

    /// The recorder's queue of this test.
    pub fn backlog(&self) -> &RecorderBacklog {
        &self.backlog
    }

    /// Test id.
    pub fn id(&self) -> String {
        self.status.borrow().id.clone()
    }

    /// The current status, with the latest readings.
    pub fn status(&self) -> TestStatus {
        let mut s = self.status.borrow().clone();
        if s.state != TestState::Finished {
            s.values = *self.supervisor.readings().borrow();
        }
        s
    }

    /// Changes of the status (state, segment, test time, outcome).
    pub fn subscribe(&self) -> watch::Receiver<TestStatus> {
        self.status.subscribe()
    }

    /// True once the test has finished.
    pub fn finished(&self) -> bool {
        self.status.borrow().state == TestState::Finished
    }

    /// Wait until the test has finished.
    pub async fn wait_finished(&self) {
        let mut rx = self.status.subscribe();
        let _ = rx.wait_for(|s| s.state == TestState::Finished).await;
    }

    /// Stop the test through the supervisor (safe state first). `None`
    /// when the supervisor has already ended.
    pub async fn stop(&self, cause: StopCause) -> Option<StopReport> {
        self.supervisor.stop(cause).await
    }

    /// Not stuck: while the plan runs, its supervisor task keeps its own
    /// heartbeat and has not failed a safe-state command
    /// ([`SupervisorHandle::healthy`]). Once the sequencer has returned
    /// the rig is safe and the supervisor has ended on purpose, so the
    /// analysis (on a blocking thread) and a finished test are healthy.
    pub fn healthy(&self) -> bool {
        self.status.borrow().state != TestState::Running || self.supervisor.healthy()
    }
}

/// How a job ended, for the rig.
#[derive(Debug, Clone)]
pub struct JobEnd {
    /// The stop, if it latches the rig.
    pub latch: Option<StopReport>,
    /// Winding rise above ambient at the end, K.
    pub winding_rise_k: f64,
}

/// A prepared test, ready to run.
pub struct Job {
    supervised: Supervised,
    ending: Ending,
}

/// Why a test could not be set up (nothing ran; the rig was not driven).
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// The rig, its supervisor or the record could not be set up.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The records index could not be written.
    #[error(transparent)]
    Index(#[from] IndexError),
}

/// Open the rig, put it under supervision, start and index the record.
/// Must be called on a tokio runtime (it starts the supervisor task).
pub async fn prepare(
    rig: &str,
    machine: Box<dyn Machine>,
    initial_rise_k: f64,
    index: Arc<Mutex<RecordsIndex>>,
    metrics: Arc<Metrics>,
) -> Result<(Arc<TestRun>, Job), SetupError> {
    // Paced at the wall clock; a rig served behind a protocol keeps its
    // servers alive for as long as the session holds them.
    let session = Session::open(machine, true).await?;
    let m = session.machine();
    let motor_id = m.common().motor_id.clone();
    let kind = m.kind();
    let plan = m.plan_summary();
    let now = SystemTime::now();
    let started_at = humantime::format_rfc3339_seconds(now).to_string();
    let idx = Arc::clone(&index).lock_owned().await;
    let name = idx.new_name(&motor_id, &started_at);
    let dir = idx.dir().to_path_buf();
    let supervised = session.record_to(
        &dir.join(format!("{name}.mcap")),
        crate::record::TestStart::from_system_time(now).rfc3339(),
        initial_rise_k,
    )?;
    let entry = IndexEntry::running(
        &name,
        rig,
        &motor_id,
        kind.as_str(),
        &plan,
        started_at,
        unix_s(now),
    );
    with_locked(idx, move |idx| idx.insert(entry)).await?;

    let (status, _) = watch::channel(TestStatus::running(&name, rig, &motor_id, plan));
    let run = Arc::new(TestRun {
        status,
        supervisor: supervised.handle().clone(),
        links: LinkTally::new(supervised.links().to_vec()),
        backlog: supervised.backlog().clone(),
    });
    let job = Job {
        supervised,
        ending: Ending {
            run: run.clone(),
            index,
            dir,
            name,
            metrics,
            started: std::time::Instant::now(),
        },
    };
    Ok((run, job))
}

impl Job {
    /// Run the test to its end (completed, aborted or failed) and update
    /// the index. `on_safe` is awaited as soon as the sequencer has
    /// returned (the rig is safe), before the analysis and before the
    /// status says `finished`: a rig latched by the stop is latched
    /// before anyone can see its test finished and start another.
    pub async fn run<F, Fut>(self, on_safe: F)
    where
        F: FnOnce(JobEnd) -> Fut,
        Fut: std::future::Future<Output = ()>,
    {
        let Job { supervised, ending } = self;
        let progress = FeedProgress::new(ending.run.clone(), supervised.machine().durations());
        let (recording, end) = supervised.run(&progress).await;
        conclude(ending, recording, end, on_safe).await
    }
}

/// What [`conclude`] needs of a job besides its record.
struct Ending {
    /// The test (its supervisor's handle too).
    run: Arc<TestRun>,
    /// The records index.
    index: Arc<Mutex<RecordsIndex>>,
    /// The records directory.
    dir: PathBuf,
    /// The record's name.
    name: String,
    /// The daemon's metrics.
    metrics: Arc<Metrics>,
    /// When the test started (wall clock).
    started: std::time::Instant,
}

impl Ending {
    /// Count the test's end in the metrics.
    async fn count(&self, outcome: RecordOutcome, stop: Option<&StopReport>, recorder: (u64, u64)) {
        let bytes = self
            .index
            .lock()
            .await
            .get(&self.name)
            .map_or(0, |e| e.bytes);
        let rig = self.run.status.borrow().rig.clone();
        // What the links did since the last scrape (the bus tasks have
        // ended: these are their last counts).
        self.metrics.links_used(&rig, &self.run.links.take_growth());
        self.metrics.test_ended(&TestEnd {
            rig,
            outcome: outcome.as_str().to_string(),
            stop_cause: stop.map(|s| s.cause.kind().to_string()),
            duration_s: self.started.elapsed().as_secs_f64(),
            bytes,
            messages: recorder.0,
            recorder_waits: recorder.1,
        });
    }
}

/// The end of every test, once the sequencer has returned (the rig is
/// safe): the rig told how the run ended (`on_safe`), the supervisor's
/// stop recorded, the supervisor finished, the record analysed (off the
/// reactor), finished and indexed with its report and plot, the status
/// published.
async fn conclude<F, Fut>(ending: Ending, recording: Recording, ran: RunEnd, on_safe: F)
where
    F: FnOnce(JobEnd) -> Fut,
    Fut: std::future::Future<Output = ()>,
{
    let (run, index, dir, name) = (
        ending.run.clone(),
        ending.index.clone(),
        ending.dir.clone(),
        ending.name.clone(),
    );
    let retention = recording.machine().common().retention;
    let RunEnd {
        outcome,
        stop,
        winding_rise_k,
    } = ran;
    on_safe(JobEnd {
        latch: stop.clone().filter(|s| s.cause.latches()),
        winding_rise_k,
    })
    .await;
    // Every segment is on disk (the recorder flushes at each marker): a
    // daemon killed from here on leaves a record that only lacks its
    // analysis, marked so on the next start.
    let complete = name.clone();
    let updated = on_index(&index, move |idx| {
        idx.update(&complete, |e| e.data_complete = true)
    });
    if let Err(e) = updated.await {
        tracing::error!("{name}: updating the index failed: {e}");
    }
    run.status.send_modify(|s| s.state = TestState::Identifying);

    let (outcome, reason) = match &outcome {
        Ok(Outcome::Completed) => (RecordOutcome::Completed, None),
        Ok(Outcome::Aborted { reason }) => (RecordOutcome::Aborted, Some(reason.clone())),
        Err(e) => (RecordOutcome::Failed, Some(e.to_string())),
    };
    let concluded = match recording.conclude(true).await {
        Ok(concluded) => concluded,
        Err(e) => {
            // The rig is already safe; the record stays as written so far
            // (it replays).
            tracing::error!("{name}: {e}");
            let reason = Some(e.to_string());
            ending
                .count(RecordOutcome::Failed, stop.as_ref(), (0, 0))
                .await;
            finish_failed(&run, &index, &name, reason, stop.as_ref()).await;
            return;
        }
    };
    let failure = concluded
        .recorded
        .as_ref()
        .err()
        .map(|e| format!("recording failed: {e}"));
    let (messages, recorder_waits) = concluded
        .recorded
        .as_ref()
        .map_or((0, 0), |s| (s.messages, s.backpressure_waits));
    let report_name = format!("{name}.report.json");
    let svg_name = format!("{name}.svg");
    // File writing, like the analysis, stays off the reactor.
    let report_path = dir.join(&report_name);
    let svg_path = dir.join(&svg_name);
    let residuals_name = format!("{name}.residuals.svg");
    let residuals_path = dir.join(&residuals_name);
    let written = tokio::task::spawn_blocking(move || {
        let report_text = concluded.analysis.report().to_json_pretty() + "\n";
        let written = (
            std::fs::write(report_path, report_text).map_err(|e| e.to_string()),
            concluded.analysis.write_plot(&concluded.record, &svg_path),
        );
        let residuals_written = concluded.residuals.as_ref().is_some_and(|plot| {
            write_residual_svg(plot, &residuals_path)
                .map_err(|e| tracing::error!("writing the residual plot failed: {e}"))
                .is_ok()
        });
        (written, residuals_written, concluded.analysis)
    })
    .await;
    let ((report_written, svg_written), residuals_ok, analysis) = match written {
        Ok(w) => w,
        Err(e) => {
            tracing::error!("{name}: writing the report failed: {e}");
            let reason = Some(format!("writing the report failed: {e}"));
            ending
                .count(
                    RecordOutcome::Failed,
                    stop.as_ref(),
                    (messages, recorder_waits),
                )
                .await;
            finish_failed(&run, &index, &name, reason, stop.as_ref()).await;
            return;
        }
    };
    let report = analysis.report();
    let report_ok = report_written
        .map_err(|e| tracing::error!("{name}: writing the report failed: {e}"))
        .is_ok();
    let svg_ok = svg_written
        .map_err(|e| tracing::error!("{name}: writing the plot failed: {e}"))
        .is_ok();
    let key_results = report.best.as_ref().and_then(|best| {
        let params = report.methods.get(best)?.params.as_ref()?;
        Some(KeyResults {
            method: best.clone(),
            params: params.iter().map(|(k, p)| (k.clone(), p.value)).collect(),
        })
    });
    let (outcome, reason) = match failure {
        Some(f) => (RecordOutcome::Failed, Some(f)),
        None => (outcome, reason),
    };
    let finished_at = humantime::format_rfc3339_seconds(SystemTime::now()).to_string();
    let (indexed, reason_kept) = (name.clone(), reason.clone());
    let rig = run.status.borrow().rig.clone();
    let (updated, retained) = on_index(&index, move |idx| {
        let updated = idx.update(&indexed, |e| {
            e.outcome = outcome;
            e.reason = reason_kept;
            e.finished_at = Some(finished_at);
            e.key_results = key_results;
            e.report = report_ok.then_some(report_name);
            e.svg = svg_ok.then_some(svg_name);
            e.residuals_svg = residuals_ok.then_some(residuals_name);
        });
        (
            updated,
            idx.apply_retention(&rig, &retention, SystemTime::now()),
        )
    })
    .await;
    if let Err(e) = updated {
        tracing::error!("{name}: updating the index failed: {e}");
    }
    if let Err(e) = retained {
        tracing::error!("retention: {e}");
    }
    match outcome {
        RecordOutcome::Completed => tracing::info!("{name}: test complete"),
        _ => tracing::warn!(
            "{name}: test {}: {}",
            serde_json::to_value(outcome).map_or_else(
                |_| "ended".into(),
                |v| v.as_str().unwrap_or("ended").to_string()
            ),
            reason.as_deref().unwrap_or("")
        ),
    }
    ending
        .count(outcome, stop.as_ref(), (messages, recorder_waits))
        .await;
    let values = *run.supervisor.readings().borrow();
    run.status.send_modify(|s| {
        s.state = TestState::Finished;
        s.outcome = Some(outcome);
        s.reason = reason;
        s.stop = stop.as_ref().map(StopStatus::from);
        s.values = values;
        s.eta_s = Some(0.0);
        s.eta_max_s = Some(0.0);
    });
}

/// Mark a test failed in the index and its status.
async fn finish_failed(
    run: &TestRun,
    index: &Arc<Mutex<RecordsIndex>>,
    name: &str,
    reason: Option<String>,
    stop: Option<&StopReport>,
) {
    let finished_at = humantime::format_rfc3339_seconds(SystemTime::now()).to_string();
    let (indexed, reason_kept) = (name.to_string(), reason.clone());
    let updated = on_index(index, move |idx| {
        idx.update(&indexed, |e| {
            e.outcome = RecordOutcome::Failed;
            e.reason = reason_kept;
            e.finished_at = Some(finished_at);
        })
    });
    if let Err(e) = updated.await {
        tracing::error!("{name}: updating the index failed: {e}");
    }
    run.status.send_modify(|s| {
        s.state = TestState::Finished;
        s.outcome = Some(RecordOutcome::Failed);
        s.reason = reason;
        s.stop = stop.map(StopStatus::from);
    });
}

/// Publishes the sequencer's progress on the test's watch channel, with
/// an ETA.
pub struct FeedProgress {
    run: Arc<TestRun>,
    /// Expected duration of a step before any has finished, s.
    guess_s: f64,
    /// Longest duration of each step (its timeout), s.
    timeouts: Vec<f64>,
    /// Test kind of each step.
    kinds: Vec<SegmentKind>,
    eta: StdMutex<EtaState>,
    last_ms: AtomicU64,
}

#[derive(Debug, Default)]
struct EtaState {
    index: usize,
    started_s: f64,
    finished: Vec<f64>,
}

impl FeedProgress {
    /// Progress of a plan whose segments take as `durations` says.
    pub fn new(run: Arc<TestRun>, durations: PlanDurations) -> FeedProgress {
        FeedProgress {
            run,
            guess_s: durations.guess_s,
            timeouts: durations.timeouts_s,
            kinds: durations.kinds,
            eta: StdMutex::new(EtaState::default()),
            last_ms: AtomicU64::new(0),
        }
    }

    fn publish(&self, t_s: f64) {
        let eta = self.eta.lock().unwrap_or_else(|p| p.into_inner());
        let per_step = if eta.finished.is_empty() {
            self.guess_s
        } else {
            eta.finished.iter().sum::<f64>() / eta.finished.len() as f64
        };
        let in_step = (t_s - eta.started_s).max(0.0);
        let after = self.timeouts.len().saturating_sub(eta.index + 1) as f64;
        let eta_s = (per_step - in_step).max(0.0) + per_step * after;
        let eta_max_s = (self.timeouts.get(eta.index).copied().unwrap_or(0.0) - in_step).max(0.0)
            + self.timeouts.iter().skip(eta.index + 1).sum::<f64>();
        drop(eta);
        self.run.status.send_modify(|s| {
            s.t_s = t_s;
            s.eta_s = Some(eta_s);
            s.eta_max_s = Some(eta_max_s);
        });
    }
}

impl Progress for FeedProgress {
    fn segment(&self, index: usize, total: usize, label: &str) {
        let t_s = self.run.status.borrow().t_s;
        {
            let mut eta = self.eta.lock().unwrap_or_else(|p| p.into_inner());
            if index > 0 {
                let d = t_s - eta.started_s;
                eta.finished.push(d);
            }
            eta.index = index;
            eta.started_s = t_s;
        }
        let kind = self
            .kinds
            .get(index)
            .copied()
            .unwrap_or(SegmentKind::DcStep);
        self.run.status.send_modify(|s| {
            s.segment = Some(SegmentStatus {
                index,
                total,
                label: label.to_string(),
                kind,
            });
        });
        self.publish(t_s);
    }

    fn tick(&self, t_s: f64) {
        // At most every 50 ms of test time.
        let ms = (t_s * 1e3) as u64;
        if ms >= self.last_ms.load(Ordering::Relaxed) + 50 {
            self.last_ms.store(ms, Ordering::Relaxed);
            self.publish(t_s);
        }
    }

    fn done(&self, _: &str) {}

    fn operating_point(&self, point: &OperatingPoint) {
        self.run
            .status
            .send_modify(|s| s.operating_points.push(PointStatus::from(point)));
    }
}
