//! Commissioning an induction machine: run the `im_slip_sweep` plan of an
//! [`ImRunConfig`] on the simulated rig, record it to MCAP, identify the
//! machine (the paper's recursive estimator and LM), and write the report
//! and the sweep plot. `motorbench run --config config/sim-im.toml` goes
//! through [`commission_im`].

use std::path::{Path, PathBuf};

use motorbench_drivers::{PowerStage, SensorStream};
use tokio::sync::watch;

use super::commission::unique_stem;
use super::{
    run_im_sweep, sim_im_rig, sweep_channels, CommissionError, CommissionOptions, ImRunConfig,
    Outcome, RecordSink,
};
use crate::identify::{identify_im, ImIdentification};
use crate::model::ImCircuit;
use crate::record::{
    Entry, Record, Recorder, RecorderStats, SegmentKind, TestMeta, SCHEMA_VERSION,
};
use crate::report::plot::PlotError;
use crate::report::write_im_svg;

/// Recorder queue length, in entries.
const QUEUE_CAPACITY: usize = 4096;

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
    /// What the recorder wrote.
    pub stats: RecorderStats,
    /// The identification.
    pub identification: ImIdentification,
    /// The data identification ran on.
    pub record: Record,
    /// The simulated machine's circuit.
    pub truth: ImCircuit,
}

/// Run `cfg`'s sweep, record it, identify the machine, write the files.
/// An aborted sweep still yields its record and whatever identification
/// its points allow. The simulated rig runs on its virtual clock (as fast
/// as the CPU allows; `opts.realtime` does not apply to it yet).
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
    let (mut vfd, mut dyno, mut sensors) =
        sim_im_rig(cfg.rig.clone()).map_err(CommissionError::Rig)?;
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
        &mut vfd,
        &mut dyno,
        &mut sensors,
        &mut sink,
        shutdown,
    )
    .await?;
    let t_end = sink.last_t_ns();
    let (recorder, record) = sink.into_parts();
    let recorder = recorder.expect("commissioning always records");
    let model = cfg.model;
    let (identification, record) =
        tokio::task::spawn_blocking(move || (identify_im(&record, None, model), record))
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
    Ok(ImCommissioned {
        outcome,
        mcap_path,
        report_path,
        svg_path,
        stats,
        identification,
        record,
        truth: cfg.rig.circuit,
    })
}
