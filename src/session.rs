//! One test session, whatever the machine: the rig opened
//! ([`Session::open`]), the record started under the safety supervisor
//! task ([`Session::record_to`]: the one safety path, `motorbench run` and
//! the daemon alike), the plan run through the bench's sequencer with
//! every stop going through the supervisor ([`Supervised::run`]), then
//! the analysis off the reactor, the report recorded as `/bench/result`
//! and the recorder finished ([`Recording::conclude`]).
//!
//! [`commission`] is the whole of it as `motorbench run` and the tests do
//! it, writing the report and plot files beside the record;
//! `crate::serve::jobs` wraps the same steps with the records index and
//! the live status.

use std::path::{Path, PathBuf};

use motorbench_drivers::{LinkHealth, PowerStage, SensorStream};
use thiserror::Error;
use tokio::sync::watch;

use crate::bench::{
    supervise_stages, BenchError, MonitorError, Outcome, Progress, RecordSink, SafetyMonitor,
    StopCause, StopReport, SupervisorHandle, SupervisorSummary, SupervisorTiming,
};
use crate::diagnose::{write_residual_svg, ResidualPlot};
use crate::machine::{Analysed, Analysis, Machine, PlanRig, PlotFailure, Truth};
use crate::record::{
    Entry, Event, EventLevel, Record, RecordError, Recorder, RecorderBacklog, RecorderStats,
    TestMeta, QUEUE_CAPACITY, SCHEMA_VERSION,
};
use crate::report::Provenance;
use crate::rig::RigError;

/// Why a session could not finish.
#[derive(Debug, Error)]
pub enum SessionError {
    /// A file or directory could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Recording failed.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// The bench stopped (the rig was made safe first).
    #[error(transparent)]
    Bench(#[from] BenchError),
    /// The rig could not be set up.
    #[error("rig setup: {0}")]
    Rig(#[from] RigError),
    /// The machine's safety rules do not fit its rig's channels.
    #[error("safety supervisor: {0}")]
    Safety(#[from] MonitorError),
    /// The analysis task failed (a bug; the record is as written).
    #[error("identification task failed: {0}")]
    Analysis(#[from] tokio::task::JoinError),
    /// A plot could not be written.
    #[error("{what}: {source}")]
    Plot {
        /// Which plot.
        what: &'static str,
        /// Why.
        #[source]
        source: PlotFailure,
    },
}

/// A test's rig, opened, not yet recording.
pub struct Session {
    machine: Box<dyn Machine>,
    stages: Vec<Box<dyn PowerStage>>,
    bounds: Vec<f64>,
    sensors: Box<dyn SensorStream>,
    counts_per_rev: f64,
    truth: Option<Truth>,
    keep_alive: Option<Box<dyn std::any::Any + Send>>,
    links: Vec<LinkHealth>,
}

impl Session {
    /// Open `machine`'s rig; `realtime` paces a simulated rig at the wall
    /// clock.
    pub async fn open(machine: Box<dyn Machine>, realtime: bool) -> Result<Session, SessionError> {
        let mut rig = machine.open_rig(realtime).await?;
        let plan = &machine.common().faults;
        if !plan.is_empty() {
            rig = crate::rig::fault::inject(rig, plan)?;
        }
        // The rig's buses, then the links its sensors read themselves.
        let mut links = rig.links;
        links.extend(rig.sensors.link_health());
        let (stages, bounds) = rig
            .stages
            .into_iter()
            .map(|s| (s.stage, s.max_setpoint))
            .unzip();
        Ok(Session {
            machine,
            stages,
            bounds,
            sensors: rig.sensors,
            counts_per_rev: rig.counts_per_rev,
            truth: rig.truth,
            keep_alive: rig.keep_alive,
            links,
        })
    }

    /// The test.
    pub fn machine(&self) -> &dyn Machine {
        self.machine.as_ref()
    }

    /// The health of the rig's links (requests and errors by kind), live
    /// while the test runs.
    pub fn links(&self) -> &[LinkHealth] {
        &self.links
    }

    /// The record's metadata for a test started at `started_at` (RFC 3339).
    pub fn meta(&self, started_at: String) -> TestMeta {
        TestMeta {
            schema_version: SCHEMA_VERSION.to_string(),
            kind: self.machine.kind(),
            motor_id: self.machine.common().motor_id.clone(),
            started_at,
            nameplate: self.machine.common().nameplate.clone(),
            config: self.machine.common().text.clone(),
        }
    }

    /// Start recording to `path` (the MCAP file) a test started at
    /// `started_at`, under the safety supervisor task, the one way a plan
    /// runs (`motorbench run` and the daemon alike): it checks every batch
    /// with the machine's safety rules, its thermal model starting with the
    /// winding `initial_rise_k` above ambient. The rules are checked
    /// against the rig's channels first: a mismatch creates no file. Must
    /// be called on a tokio runtime.
    pub fn record_to(
        self,
        path: &Path,
        started_at: String,
        initial_rise_k: f64,
    ) -> Result<Supervised, SessionError> {
        let monitor = self.machine.safety_rules().monitor(
            self.sensors.channels(),
            Some(self.counts_per_rev),
            initial_rise_k,
        )?;
        let stage_ids: Vec<&str> = self.stages.iter().map(|s| s.id()).collect();
        let channels = self
            .machine
            .record_channels(self.sensors.channels(), &stage_ids);
        let meta = self.meta(started_at);
        let recorder = Recorder::start(path, &meta, &channels, QUEUE_CAPACITY)?;
        let backlog = recorder.backlog();
        let sink = RecordSink::new(Some(recorder), Some(meta.clone()), channels);
        let (session, handle, task) = self.supervise(monitor);
        Ok(Supervised {
            recording: Recording {
                session,
                sink,
                meta,
                path: path.to_path_buf(),
            },
            handle,
            task,
            backlog,
        })
    }

    /// Put the rig under the safety supervisor task checking every batch
    /// with `monitor`: every stop then goes through it (the sequencer's own
    /// trips and the operator's too), and it commands every stage safe,
    /// the one that feeds the machine first.
    fn supervise(self, monitor: SafetyMonitor) -> (Session, SupervisorHandle, SupervisorTask) {
        let Session {
            machine,
            stages,
            bounds,
            sensors,
            counts_per_rev,
            truth,
            keep_alive,
            links,
        } = self;
        let common = machine.common();
        let (bus_loss_s, rate_hz) = (common.supervision.bus_loss_timeout, common.sample_rate_hz);
        let supervised = supervise_stages(
            stages.into_iter().zip(bounds.iter().copied()).collect(),
            sensors,
            monitor,
            SupervisorTiming::new(bus_loss_s, rate_hz),
        );
        let session = Session {
            machine,
            stages: supervised
                .stages
                .into_iter()
                .map(|st| Box::new(st) as Box<dyn PowerStage>)
                .collect(),
            bounds,
            sensors: Box::new(supervised.sensors),
            counts_per_rev,
            truth,
            keep_alive,
            links,
        };
        (session, supervised.handle, supervised.task)
    }
}

/// A session that records: run its plan, then conclude.
pub struct Recording {
    session: Session,
    sink: RecordSink,
    meta: TestMeta,
    /// The MCAP file.
    path: PathBuf,
}

/// A supervised recording's supervisor task.
pub type SupervisorTask = tokio::task::JoinHandle<SupervisorSummary>;

impl Recording {
    /// The test.
    pub fn machine(&self) -> &dyn Machine {
        self.session.machine()
    }

    /// Record `entry` (e.g. the supervisor's account of a stop).
    async fn push(&mut self, entry: Entry) -> Result<(), RecordError> {
        self.sink.push(entry).await
    }

    /// Close the rig (its sensors, stages and any protocol servers), then
    /// analyse the record off the reactor and finish the file. The
    /// identification is recorded as `/bench/result` as soon as it
    /// exists; when `diagnose`, that first result is marked
    /// `diagnosis_pending`, the diagnosis runs (off the reactor too) and
    /// the whole report follows as a second `/bench/result`, so a process
    /// killed during the diagnosis still leaves the identification in the
    /// record. An analysis that fails leaves the record as written (it
    /// replays); a record that cannot be finished is in
    /// [`Concluded::recorded`].
    pub async fn conclude(self, diagnose: bool) -> Result<Concluded, SessionError> {
        let Recording {
            session,
            sink,
            meta,
            path,
        } = self;
        let Session {
            machine,
            stages,
            sensors,
            truth,
            keep_alive,
            ..
        } = session;
        drop((sensors, stages, keep_alive));
        let t_end = sink.last_t_ns();
        let (recorder, record) = sink.into_parts();
        let recorder = recorder.expect("a recording session always records");
        let kind = machine.kind();
        let analyser = machine.analyser(truth);
        let (mut analysed, record) = tokio::task::spawn_blocking(move || {
            let analysed = analyser(&record, false);
            (analysed, record)
        })
        .await?;
        let stem = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        let record_name = path
            .file_name()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        let provenance =
            |files| Provenance::new(&meta.motor_id, &meta.started_at, &record_name, files);
        let mut sent = Ok(());
        let record = if diagnose {
            // The identification first: no file is written beside the
            // record with it, and the diagnosis is still to come.
            let mut early = analysed.analysis.report().clone();
            early.diagnosis_pending = true;
            early.provenance = Some(provenance(Vec::new()));
            sent = recorder.send(result_entry(t_end, &early)).await;
            let (diagnosed, record) = tokio::task::spawn_blocking(move || {
                analysed.diagnose(&record, kind);
                (analysed, record)
            })
            .await?;
            analysed = diagnosed;
            record
        } else {
            record
        };
        let files = ReportFiles::names(&stem, analysed.residuals.is_some());
        analysed.analysis.report_mut().provenance = Some(provenance(files));
        let whole = result_entry(t_end, analysed.analysis.report());
        let recorded = async {
            sent?;
            recorder.send(whole).await?;
            recorder.finish().await
        }
        .await;
        let Analysed {
            analysis,
            residuals,
        } = analysed;
        Ok(Concluded {
            analysis,
            residuals,
            record,
            recorded,
        })
    }
}

/// A report as the `/bench/result` entry at `t_ns`.
fn result_entry(t_ns: u64, report: &crate::report::IdentificationReport) -> Entry {
    Entry::Result {
        t_ns,
        report: serde_json::to_value(report).expect("a report always serialises"),
    }
}

/// A recording under the safety supervisor task, ready to run its plan.
pub struct Supervised {
    recording: Recording,
    handle: SupervisorHandle,
    task: SupervisorTask,
    backlog: RecorderBacklog,
}

/// How a supervised plan ended.
pub struct RunEnd {
    /// The plan's outcome (the rig is safe whichever it is).
    pub outcome: Result<Outcome, BenchError>,
    /// The supervisor's stop, when it stopped the test.
    pub stop: Option<StopReport>,
    /// The winding's estimated rise above ambient at the end, K.
    pub winding_rise_k: f64,
}

impl Supervised {
    /// The test.
    pub fn machine(&self) -> &dyn Machine {
        self.recording.machine()
    }

    /// The supervisor's handle: live readings, and stops (an operator's,
    /// an emergency stop) from outside the plan.
    pub fn handle(&self) -> &SupervisorHandle {
        &self.handle
    }

    /// The health of the rig's links, live while the plan runs.
    pub fn links(&self) -> &[LinkHealth] {
        self.recording.session.links()
    }

    /// The recorder's queue, live while the plan runs.
    pub fn backlog(&self) -> &RecorderBacklog {
        &self.backlog
    }

    /// Run the plan to its end; every stop comes through the supervisor.
    /// Then the supervisor's stop, if any, is recorded as an event (with
    /// the first sample read after the safe state) and the supervisor
    /// finished. The recording comes back for [`Recording::conclude`].
    pub async fn run(self, progress: &dyn Progress) -> (Recording, RunEnd) {
        let Supervised {
            mut recording,
            handle,
            task,
            ..
        } = self;
        let s = &mut recording.session;
        let rig = PlanRig {
            stages: &mut s.stages,
            sensors: s.sensors.as_mut(),
            counts_per_rev: s.counts_per_rev,
        };
        let outcome = s
            .machine
            .run_plan(rig, &mut recording.sink, progress, (&handle).into())
            .await;
        let stop = handle.stopped();
        if let Some(s) = &stop {
            if let Err(e) = recording.push(stop_event(s)).await {
                tracing::error!("recording the supervisor's stop failed: {e}");
            }
            for entry in escalation_events(s) {
                if let Err(e) = recording.push(entry).await {
                    tracing::error!("recording the supervisor's escalation failed: {e}");
                }
            }
        }
        for entry in link_events(recording.session.links(), recording.sink.last_t_ns()) {
            if let Err(e) = recording.push(entry).await {
                tracing::error!("recording the links' health failed: {e}");
            }
        }
        handle.finish().await;
        let winding_rise_k = task.await.map_or(0.0, |s| s.winding_rise_k);
        let end = RunEnd {
            outcome,
            stop,
            winding_rise_k,
        };
        (recording, end)
    }
}

/// The record's account of a supervisor's stop.
fn stop_event(s: &StopReport) -> Entry {
    let first = s.first_safe_t_ns.map_or_else(
        || "no sample was read after it".to_string(),
        |t| {
            format!(
                "first sample after it at test time {:.4} s",
                t as f64 * 1e-9
            )
        },
    );
    Entry::Event {
        t_ns: s.requested_t_ns,
        event: Event {
            level: EventLevel::Info,
            message: format!("safety supervisor: {}; {first}", s.describe()),
        },
    }
}

/// The record's account of the links that had errors or retries during
/// the test (one info event each, at `t_ns`): what a retried fault cost.
fn link_events(links: &[LinkHealth], t_ns: u64) -> Vec<Entry> {
    links
        .iter()
        .filter_map(|l| {
            let c = l.counts();
            let kinds: Vec<String> = c
                .by_kind()
                .into_iter()
                .filter(|(_, n)| *n > 0)
                .map(|(k, n)| format!("{k} {n}"))
                .collect();
            (!kinds.is_empty()).then(|| Entry::Event {
                t_ns,
                event: Event {
                    level: EventLevel::Info,
                    message: format!(
                        "link {}: {} requests; {}",
                        l.name(),
                        c.requests,
                        kinds.join(", ")
                    ),
                },
            })
        })
        .collect()
}

/// The record's account of the supervisor's escalation after a stop: one
/// abort event per step.
fn escalation_events(s: &StopReport) -> Vec<Entry> {
    s.escalation
        .iter()
        .map(|step| Entry::Event {
            t_ns: s.requested_t_ns,
            event: Event {
                level: EventLevel::Abort,
                message: format!("safety supervisor: {step}"),
            },
        })
        .collect()
}

/// A concluded test.
pub struct Concluded {
    /// Identification and diagnosis.
    pub analysis: Box<dyn Analysis>,
    /// The diagnosis' residual plot, when diagnosed.
    pub residuals: Option<ResidualPlot>,
    /// The data the analysis ran on.
    pub record: Record,
    /// What the recorder wrote, or why the record could not be finished
    /// (the analysis stands: the data it ran on is in memory).
    pub recorded: Result<RecorderStats, RecordError>,
}

/// The report, plot and residual-plot files of a concluded test.
#[derive(Debug, Clone)]
pub struct ReportFiles {
    /// `<stem>.report.json`.
    pub report: PathBuf,
    /// `<stem>.svg`.
    pub svg: PathBuf,
    /// `<stem>.residuals.svg`, when diagnosed.
    pub residuals_svg: Option<PathBuf>,
}

impl ReportFiles {
    /// The names of the files written beside the record `<stem>.mcap`:
    /// the report, the plot and, when `diagnosed`, the residual plot.
    pub fn names(stem: &str, diagnosed: bool) -> Vec<String> {
        let mut names = vec![format!("{stem}.report.json"), format!("{stem}.svg")];
        if diagnosed {
            names.push(format!("{stem}.residuals.svg"));
        }
        names
    }
}

impl Concluded {
    /// Write `<stem>.report.json`, `<stem>.svg` and, when diagnosed,
    /// `<stem>.residuals.svg` into `dir` (the names
    /// [`ReportFiles::names`] gives).
    pub fn write_files(&self, dir: &Path, stem: &str) -> Result<ReportFiles, SessionError> {
        let report = dir.join(format!("{stem}.report.json"));
        std::fs::write(&report, self.analysis.report().to_json_pretty() + "\n").map_err(
            |source| SessionError::Io {
                path: report.display().to_string(),
                source,
            },
        )?;
        let svg = dir.join(format!("{stem}.svg"));
        self.analysis
            .write_plot(&self.record, &svg)
            .map_err(|source| SessionError::Plot {
                what: "plot",
                source,
            })?;
        let residuals_svg = self
            .residuals
            .as_ref()
            .map(|plot| {
                let path = dir.join(format!("{stem}.residuals.svg"));
                write_residual_svg(plot, &path).map_err(|e| SessionError::Plot {
                    what: "residual plot",
                    source: Box::new(e),
                })?;
                Ok::<_, SessionError>(path)
            })
            .transpose()?;
        Ok(ReportFiles {
            report,
            svg,
            residuals_svg,
        })
    }
}

/// A record name from the motor id (unsafe characters replaced) and the
/// start time (punctuation dropped), with `-2`, `-3`, … appended until
/// `taken` says the name is free.
pub fn record_name(motor_id: &str, started: &str, taken: impl Fn(&str) -> bool) -> String {
    let id: String = motor_id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    let stamp: String = started
        .chars()
        .filter(|c| c.is_ascii_alphanumeric())
        .collect();
    let base = format!("{id}-{stamp}");
    (1..)
        .map(|n| {
            if n == 1 {
                base.clone()
            } else {
                format!("{base}-{n}")
            }
        })
        .find(|name| !taken(name))
        .expect("an unused name exists")
}

/// Where and how to commission.
#[derive(Debug, Clone)]
pub struct CommissionOptions {
    /// Directory for the record and report files (created if missing).
    pub out_dir: PathBuf,
    /// Pace the simulated rig at wall-clock time.
    pub realtime: bool,
    /// Diagnose the sim-to-real gap after identification (the report's
    /// `diagnosis`, and a residual plot beside the record).
    pub diagnose: bool,
}

/// What a commissioning run produced.
pub struct Commissioned {
    /// How the test ended.
    pub outcome: Outcome,
    /// The MCAP record.
    pub mcap_path: PathBuf,
    /// The report files beside it.
    pub files: ReportFiles,
    /// What the recorder wrote.
    pub stats: RecorderStats,
    /// Identification and diagnosis.
    pub analysis: Box<dyn Analysis>,
    /// The data the analysis ran on.
    pub record: Record,
}

/// Run `machine`'s test on its rig, record it to MCAP, identify (and
/// diagnose) the machine and write the report files: `motorbench run`.
/// An aborted test still yields its record and whatever identification
/// the data allows.
pub async fn commission(
    machine: Box<dyn Machine>,
    opts: &CommissionOptions,
    progress: &dyn Progress,
    shutdown: &watch::Receiver<bool>,
) -> Result<Commissioned, SessionError> {
    let dir = &opts.out_dir;
    std::fs::create_dir_all(dir).map_err(|source| SessionError::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let session = Session::open(machine, opts.realtime).await?;
    let start = crate::record::TestStart::now();
    let stem = record_name(
        &session.machine().common().motor_id,
        &start.rfc3339_seconds(),
        |s| dir.join(format!("{s}.mcap")).exists(),
    );
    let mcap_path = dir.join(format!("{stem}.mcap"));
    // A cold motor: `run` keeps no thermal memory between tests.
    let supervised = session.record_to(&mcap_path, start.rfc3339(), 0.0)?;
    let operator = supervised.handle().clone();
    let mut flag = shutdown.clone();
    let operator_stop = tokio::spawn(async move {
        if flag.wait_for(|stop| *stop).await.is_ok() {
            operator.stop(StopCause::OperatorAbort).await;
        }
    });
    let (recording, end) = supervised.run(progress).await;
    operator_stop.abort();
    let outcome = end.outcome?;
    let concluded = recording.conclude(opts.diagnose).await?;
    let files = concluded.write_files(dir, &stem)?;
    let stats = concluded.recorded?;
    progress.done(match &outcome {
        Outcome::Completed => "test complete",
        Outcome::Aborted { .. } => "test aborted",
    });
    Ok(Commissioned {
        outcome,
        mcap_path,
        files,
        stats,
        analysis: concluded.analysis,
        record: concluded.record,
    })
}
