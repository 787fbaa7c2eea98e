//! Commissioning: run a configured test on its rig, record it, identify
//! the motor, and write the report files. The CLI's `run` and the
//! end-to-end tests both go through [`commission`].

use std::path::{Path, PathBuf};

use thiserror::Error;
use tokio::sync::watch;

use super::{
    build_rig, plan_steps, record_channels, run_test, BenchError, Outcome, Progress, RecordSink,
};
use crate::config::{Config, Plan};
use crate::diagnose::{attach_diagnosis, write_residual_svg, ResidualPlot};
use crate::identify::{identify_dc, Identification};
use crate::model::DcParams;
use crate::record::{
    Entry, Record, RecordError, Recorder, RecorderStats, SegmentKind, TestMeta, QUEUE_CAPACITY,
    SCHEMA_VERSION,
};
use crate::report::{plot::PlotError, segment_plots, write_segments_svg};

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
#[derive(Debug)]
pub struct Commissioned {
    /// How the test ended.
    pub outcome: Outcome,
    /// The MCAP record.
    pub mcap_path: PathBuf,
    /// The identification report (contract JSON).
    pub report_path: PathBuf,
    /// Measured against simulated current and speed, per segment.
    pub svg_path: PathBuf,
    /// Held-out residuals before and after the diagnosis' effect, when diagnosed.
    pub residuals_svg_path: Option<PathBuf>,
    /// What the recorder wrote.
    pub stats: RecorderStats,
    /// The identification.
    pub identification: Identification,
    /// The data identification ran on.
    pub record: Record,
    /// The simulated motor's true parameters (simulated rig only).
    pub truth: Option<DcParams>,
}

/// Why commissioning could not finish.
#[derive(Debug, Error)]
pub enum CommissionError {
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
    Rig(String),
    /// The plot could not be written.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// The diagnosis' residual plot could not be written.
    #[error("residual plot: {0}")]
    ResidualPlot(String),
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

/// A file stem from the motor id and the start time, unique in `dir`.
pub(super) fn unique_stem(dir: &Path, motor_id: &str, started: &str) -> String {
    record_name(motor_id, started, |s| {
        dir.join(format!("{s}.mcap")).exists()
    })
}

/// Write the diagnosis' residual plot, when there is one, as
/// `<stem>.residuals.svg` in `dir`; its path.
pub(super) fn write_residuals(
    dir: &Path,
    stem: &str,
    plot: Option<&ResidualPlot>,
) -> Result<Option<PathBuf>, CommissionError> {
    plot.map(|plot| {
        let path = dir.join(format!("{stem}.residuals.svg"));
        write_residual_svg(plot, &path).map_err(CommissionError::ResidualPlot)?;
        Ok(path)
    })
    .transpose()
}

/// Run `cfg`'s test on its rig, record it to MCAP, identify the motor and
/// write the report files. An aborted test still yields its record and
/// whatever identification the data allows.
pub async fn commission(
    cfg: &Config,
    opts: &CommissionOptions,
    progress: &dyn Progress,
    shutdown: &watch::Receiver<bool>,
) -> Result<Commissioned, CommissionError> {
    let io = |path: &Path| {
        let path = path.display().to_string();
        move |source| CommissionError::Io { path, source }
    };
    std::fs::create_dir_all(&opts.out_dir).map_err(io(&opts.out_dir))?;
    let mut rig = build_rig(cfg, opts.realtime)
        .await
        .map_err(|e| CommissionError::Rig(e.to_string()))?;
    let counts_per_rev = rig.counts_per_rev;
    let truth = rig.truth;
    let channels = record_channels(rig.sensors.channels(), rig.stage.id());
    let started_at = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
    let stem = unique_stem(&opts.out_dir, &cfg.motor_id, &started_at);
    let kind = match cfg.plan {
        Plan::DcStep { .. } => SegmentKind::DcStep,
        Plan::DcCoastdown { .. } => SegmentKind::DcCoastdown,
    };
    let meta = TestMeta {
        schema_version: SCHEMA_VERSION.to_string(),
        kind,
        motor_id: cfg.motor_id.clone(),
        started_at,
        nameplate: cfg.nameplate.clone(),
        config: cfg.text.clone(),
    };
    let mcap_path = opts.out_dir.join(format!("{stem}.mcap"));
    let recorder = Recorder::start(&mcap_path, &meta, &channels, QUEUE_CAPACITY)?;
    let mut sink = RecordSink::new(Some(recorder), Some(meta), channels);
    let steps = plan_steps(&cfg.plan);
    let outcome = run_test(
        cfg,
        &steps,
        rig.stage.as_mut(),
        rig.sensors.as_mut(),
        counts_per_rev,
        &mut sink,
        progress,
        shutdown,
    )
    .await?;
    let t_end = sink.last_t_ns();
    let (recorder, record) = sink.into_parts();
    let recorder = recorder.expect("commissioning always records");

    // Identification is CPU work: keep it off the reactor.
    let diagnose = opts.diagnose;
    let (identification, record, residuals) = tokio::task::spawn_blocking(move || {
        let mut identification = identify_dc(&record);
        let residuals = diagnose
            .then(|| attach_diagnosis(&mut identification.report, &record, SegmentKind::DcStep))
            .flatten();
        (identification, record, residuals)
    })
    .await
    .map_err(|e| CommissionError::Rig(format!("identification task failed: {e}")))?;
    let report_value =
        serde_json::to_value(&identification.report).expect("a report always serialises");
    recorder
        .send(Entry::Result {
            t_ns: t_end,
            report: report_value,
        })
        .await?;
    let stats = recorder.finish().await?;

    let report_path = opts.out_dir.join(format!("{stem}.report.json"));
    std::fs::write(&report_path, identification.report.to_json_pretty() + "\n")
        .map_err(io(&report_path))?;
    let svg_path = opts.out_dir.join(format!("{stem}.svg"));
    write_segments_svg(&svg_path, &segment_plots(&record, &identification))?;
    let residuals_svg_path = write_residuals(&opts.out_dir, &stem, residuals.as_ref())?;
    progress.done(match &outcome {
        Outcome::Completed => "test complete",
        Outcome::Aborted { .. } => "test aborted",
    });
    Ok(Commissioned {
        outcome,
        mcap_path,
        report_path,
        svg_path,
        residuals_svg_path,
        stats,
        identification,
        record,
        truth,
    })
}
