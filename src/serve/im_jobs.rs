//! An induction-machine slip sweep run by the daemon: the rig's two
//! stages (supply VFD first, then the dynamometer) and its sensors put
//! under one safety supervisor, so a trip, an abort, an emergency stop or
//! a shutdown commands both to their safe state (supply output off,
//! dynamometer stopped) before the cause is recorded; the record started
//! and indexed; the sweep run at the wall clock with its progress on the
//! live feed; then identification, report, plot and index as for every
//! test ([`super::jobs::conclude`]).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::SystemTime;

use tokio::sync::{watch, Mutex};

use super::jobs::{conclude, Ending, FeedProgress, Identified, JobEnd, TestRun, TestStatus};
use super::records_index::{unix_s, IndexEntry, RecordsIndex};
use crate::bench::{
    build_im_rig, run_im_sweep, supervise_stages, sweep_channels, ImRunConfig, RecordSink,
    ServedImRig, SupervisedStages, SupervisorTiming,
};
use crate::diagnose::attach_diagnosis;
use crate::identify::identify_im;
use crate::record::{Recorder, SegmentKind, TestMeta, QUEUE_CAPACITY, SCHEMA_VERSION};
use crate::report::write_im_svg;

/// The plan for a person.
pub fn im_plan_summary(cfg: &ImRunConfig) -> String {
    let p = &cfg.plan;
    let volts: Vec<String> = p.voltages.iter().map(|v| format!("{v}")).collect();
    format!(
        "im_slip_sweep {} V at {} Hz, {} slips {}…{}",
        volts.join(", "),
        p.frequency,
        p.slips.len(),
        p.slips.first().copied().unwrap_or(0.0),
        p.slips.last().copied().unwrap_or(0.0)
    )
}

/// A prepared sweep, ready to run.
pub struct ImJob {
    run: Arc<TestRun>,
    cfg: ImRunConfig,
    supervised: SupervisedStages,
    sink: RecordSink,
    index: Arc<Mutex<RecordsIndex>>,
    dir: PathBuf,
    name: String,
    /// Protocol servers of a served simulated rig, kept alive for the test.
    _served: Option<ServedImRig>,
}

/// Open the rig, put both stages under supervision, start and index the
/// record. Must be called on a tokio runtime.
pub async fn prepare_im(
    rig: &str,
    cfg: ImRunConfig,
    initial_rise_k: f64,
    index: Arc<Mutex<RecordsIndex>>,
) -> Result<(Arc<TestRun>, ImJob), String> {
    // Paced at the wall clock, like every daemon test.
    let built = build_im_rig(&cfg, true)
        .await
        .map_err(|e| format!("rig setup: {e}"))?;
    let channels = built.sensors.channels().to_vec();
    let monitor =
        cfg.safety_rules()
            .monitor(&channels, Some(built.counts_per_rev), initial_rise_k)?;
    let record_channels = sweep_channels(&channels, built.supply.id(), built.dynamometer.id());
    let now = SystemTime::now();
    let started_at = humantime::format_rfc3339_seconds(now).to_string();
    let meta = TestMeta {
        schema_version: SCHEMA_VERSION.to_string(),
        kind: SegmentKind::ImSlipSweep,
        motor_id: cfg.motor_id.clone(),
        started_at: started_at.clone(),
        nameplate: cfg.nameplate.clone(),
        config: cfg.text.clone(),
    };
    let plan = im_plan_summary(&cfg);
    let mut idx = index.lock().await;
    let name = idx.new_name(&cfg.motor_id, &started_at);
    let dir = idx.dir().to_path_buf();
    let mcap = format!("{name}.mcap");
    let recorder = Recorder::start(&dir.join(&mcap), &meta, &record_channels, QUEUE_CAPACITY)
        .map_err(|e| e.to_string())?;
    idx.insert(IndexEntry::running(
        &name,
        rig,
        &cfg.motor_id,
        SegmentKind::ImSlipSweep.as_str(),
        &plan,
        started_at,
        unix_s(now),
    ))
    .map_err(|e| e.to_string())?;
    drop(idx);

    let timing = SupervisorTiming::new(cfg.supervision.bus_loss_timeout, cfg.sample_rate_hz);
    let supervised = supervise_stages(
        vec![
            (built.supply, cfg.limits.max_voltage),
            (built.dynamometer, cfg.limits.max_speed),
        ],
        built.sensors,
        monitor,
        timing,
    );
    let (status, _) = watch::channel(TestStatus::running(&name, rig, &cfg.motor_id, plan));
    let run = Arc::new(TestRun {
        status,
        supervisor: supervised.handle.clone(),
    });
    let sink = RecordSink::new(Some(recorder), Some(meta), record_channels);
    let job = ImJob {
        run: run.clone(),
        cfg,
        supervised,
        sink,
        index,
        dir,
        name,
        _served: built.served,
    };
    Ok((run, job))
}

impl ImJob {
    /// Run the sweep to its end (completed, aborted or failed) and update
    /// the index.
    pub async fn run(self) -> JobEnd {
        let ImJob {
            run,
            cfg,
            supervised,
            mut sink,
            index,
            dir,
            name,
            _served,
        } = self;
        let SupervisedStages {
            stages,
            mut sensors,
            handle,
            task,
        } = supervised;
        let [mut supply, mut dyno]: [_; 2] = stages
            .try_into()
            .unwrap_or_else(|_| unreachable!("two stages were supervised"));
        let p = &cfg.plan;
        // A point: two settle windows and the average; at most the settle
        // timeout plus the average and a cool-down.
        let period = 1.0 / cfg.sample_rate_hz;
        let point_guess = (2 * p.settle_window + p.average_samples) as f64 * period + 0.1;
        let point_max = p.max_point_s + p.average_samples as f64 * period + p.cooldown_s;
        let progress = FeedProgress::with(
            run.clone(),
            point_guess * p.slips.len() as f64,
            vec![point_max * p.slips.len() as f64; p.voltages.len()],
            vec![SegmentKind::ImSlipSweep; p.voltages.len()],
        );
        // Every stop goes through the supervisor, the sweep's own too.
        let rules = cfg.safety_rules();
        let outcome = run_im_sweep(
            p,
            &rules,
            &mut supply,
            &mut dyno,
            &mut sensors,
            &mut sink,
            &progress,
            &handle,
        )
        .await;
        drop(sensors);
        let ending = Ending {
            run,
            handle,
            task,
            index,
            dir,
            name,
            retention: cfg.retention,
        };
        let model = cfg.model;
        conclude(ending, sink, outcome, move |record| {
            let mut identification = identify_im(&record, None, model);
            attach_diagnosis(
                &mut identification.report,
                &record,
                SegmentKind::ImSlipSweep,
            );
            Identified {
                report: identification.report.clone(),
                write_svg: Box::new(move |path| write_im_svg(path, &identification)),
            }
        })
        .await
    }
}
