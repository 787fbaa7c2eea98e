//! Commissioning an induction machine: run the `im_slip_sweep` plan of an
//! [`ImRunConfig`] on its rig (simulated, or behind Modbus), record it to MCAP, identify the
//! machine (the paper's recursive estimator and LM), and write the report
//! and the sweep plot. `motorbench run --config config/sim-im.toml` goes
//! through [`commission_im`].

use std::path::{Path, PathBuf};

use tokio::sync::watch;

use super::commission::{unique_stem, write_residuals};
use super::{
    build_im_rig, run_im_sweep, sweep_channels, CommissionError, CommissionOptions, ImRunConfig,
    NoProgress, Outcome, RecordSink,
};
use crate::diagnose::attach_diagnosis;
use crate::identify::{identify_im, ImIdentification};
use crate::model::ImCircuit;
use crate::record::{
    Entry, Record, Recorder, RecorderStats, SegmentKind, TestMeta, QUEUE_CAPACITY, SCHEMA_VERSION,
};
use crate::report::plot::PlotError;
use crate::report::write_im_svg;

/// What an induction-machine commissioning run produced.
#[derive(Debug)]
pub struct ImCommissioned {
    /// How the test ended.
    pub outcome: Outcome,
    /// The MCAP record.
    pub mcap_path: PathBuf,
    /// The identification report (contract JSON).
    pub report_path: PathBuf,
    /// Current and power against slip, measured and fitted.
    pub svg_path: PathBuf,
    /// Held-out residuals before and after the diagnosis' effect, when diagnosed.
    pub residuals_svg_path: Option<PathBuf>,
    /// What the recorder wrote.
    pub stats: RecorderStats,
    /// The identification.
    pub identification: ImIdentification,
    /// The data identification ran on.
    pub record: Record,
    /// The simulated machine's circuit (simulated rigs only).
    pub truth: Option<ImCircuit>,
}

/// Run `cfg`'s sweep, record it, identify the machine, write the files.
/// An aborted sweep still yields its record and whatever identification
/// its points allow. The in-process simulated rig runs on its virtual
/// clock (as fast as the CPU allows) unless `opts.realtime` paces it at the
/// wall clock; a rig behind Modbus always runs on the wall clock.
pub async fn commission_im(
    cfg: &ImRunConfig,
    opts: &CommissionOptions,
    shutdown: &watch::Receiver<bool>,
) -> Result<ImCommissioned, CommissionError> {
    let io = |path: &Path| {
        let path = path.display().to_string();
        move |source| CommissionError::Io { path, source }
    };
    std::fs::create_dir_all(&opts.out_dir).map_err(io(&opts.out_dir))?;
    let rig = build_im_rig(cfg, opts.realtime)
        .await
        .map_err(|e| CommissionError::Rig(e.to_string()))?;
    let (mut vfd, mut dyno, mut sensors, truth, _served) = (
        rig.supply,
        rig.dynamometer,
        rig.sensors,
        rig.truth,
        rig.served,
    );
    let channels = sweep_channels(sensors.channels(), vfd.id(), dyno.id());
    let started_at = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
    let stem = unique_stem(&opts.out_dir, &cfg.motor_id, &started_at);
    let meta = TestMeta {
        schema_version: SCHEMA_VERSION.to_string(),
        kind: SegmentKind::ImSlipSweep,
        motor_id: cfg.motor_id.clone(),
        started_at,
        nameplate: cfg.nameplate.clone(),
        config: cfg.text.clone(),
    };
    let mcap_path = opts.out_dir.join(format!("{stem}.mcap"));
    let recorder = Recorder::start(&mcap_path, &meta, &channels, QUEUE_CAPACITY)?;
    let mut sink = RecordSink::new(Some(recorder), Some(meta), channels);
    let outcome = run_im_sweep(
        &cfg.plan,
        &cfg.safety_rules(),
        vfd.as_mut(),
        dyno.as_mut(),
        sensors.as_mut(),
        &mut sink,
        &NoProgress,
        shutdown,
    )
    .await?;
    let t_end = sink.last_t_ns();
    let (recorder, record) = sink.into_parts();
    let recorder = recorder.expect("commissioning always records");
    let model = cfg.model;
    let diagnose = opts.diagnose;
    let (identification, record, residuals) = tokio::task::spawn_blocking(move || {
        let mut identification = identify_im(&record, None, model);
        let residuals = diagnose
            .then(|| {
                attach_diagnosis(
                    &mut identification.report,
                    &record,
                    SegmentKind::ImSlipSweep,
                )
            })
            .flatten();
        (identification, record, residuals)
    })
    .await
    .map_err(|e| CommissionError::Rig(format!("identification task failed: {e}")))?;
    let report = serde_json::to_value(&identification.report).expect("a report always serialises");
    recorder
        .send(Entry::Result {
            t_ns: t_end,
            report,
        })
        .await?;
    let stats = recorder.finish().await?;
    let report_path = opts.out_dir.join(format!("{stem}.report.json"));
    std::fs::write(&report_path, identification.report.to_json_pretty() + "\n")
        .map_err(io(&report_path))?;
    let svg_path = opts.out_dir.join(format!("{stem}.svg"));
    write_im_svg(&svg_path, &identification).map_err(|reason| {
        CommissionError::Plot(PlotError::Render {
            path: Some(svg_path.clone()),
            reason,
        })
    })?;
    let residuals_svg_path = write_residuals(&opts.out_dir, &stem, residuals.as_ref())?;
    Ok(ImCommissioned {
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
