//! The DC machine: the armature-voltage staircase (`dc_step`) and the
//! coast-down (`dc_coastdown`) on one power stage; identification by the
//! DC methods, the per-segment plot of measured against simulated current
//! and speed.
//!
//! - `plan`: the plan's steps; `runner`: the steps driven through the
//!   bench's sequencer, with settle detection and the supply-limit
//!   detector (`supply_limits`);
//! - `rig`: the rig a configuration names (simulated, Modbus, CAN,
//!   serial); `sim_rig`: the simulated supply and sensors; `served`: the
//!   simulated rig behind the real protocols;
//! - `config`: the test's file format and its validation ([`Config`]);
//! - `identify/`, `diagnose/`: the DC methods and the sim-to-real gap;
//!   `text`, `overlay`: the text report and the plot;
//! - `blind_case`, `blind_plan`: the blind benchmark's DC cases.

pub(crate) mod blind_case;
pub(crate) mod blind_plan;
pub(crate) mod config;
pub mod diagnose;
mod gaps;
pub mod identify;
mod join;
mod overlay;
mod plan;
mod rig;
mod runner;
mod served;
mod sim_rig;
pub(crate) mod split;
mod supply_limits;
mod text;
mod timing;

pub use gaps::{cut_at_time_gaps, fill_missing_samples};
pub use overlay::segment_plots;
pub use plan::{plan_steps, PlanStep};
pub use rig::{build_rig, Rig, SERVED_PLANT_RATE_HZ};
pub use runner::{record_channels, run_test, SUPPLY_LIMIT_FRACTION};
pub use served::ServedRig;
pub use sim_rig::{sim_rig, SimPowerStage, SimSensors};
pub use split::split_single_segment;
pub use supply_limits::SupplyLimitDetector;
pub use text::render_text;
pub use timing::prepare_dc_record;

use std::path::Path;

use async_trait::async_trait;
use motorbench_drivers::ChannelInfo;

use super::{
    Analysed, Analyser, Analysis, Machine, OpenedRig, PlanDurations, PlanRig, PlotFailure,
    RigStage, Truth,
};
use crate::bench::{BenchError, Outcome, Progress, RecordSink, SafetyRules, StopPath};
use crate::config::{CommonConfig, Config, Plan};
use crate::identify::{identify_dc, Identification};
use crate::model::DcParams;
use crate::record::{ChannelSpec, Record, SegmentKind};
use crate::report::{write_segments_svg, IdentificationReport};
use crate::rig::RigError;

/// A DC identification, with the simulated motor when there is one.
struct DcAnalysis {
    id: Identification,
    truth: Option<DcParams>,
}

impl Analysis for DcAnalysis {
    fn report(&self) -> &IdentificationReport {
        &self.id.report
    }

    fn report_mut(&mut self) -> &mut IdentificationReport {
        &mut self.id.report
    }

    fn text(&self) -> String {
        render_text(&self.id, self.truth.as_ref())
    }

    fn write_plot(&self, record: &Record, path: &Path) -> Result<(), PlotFailure> {
        Ok(write_segments_svg(path, &segment_plots(record, &self.id))?)
    }

    fn refusal(&self) -> Option<String> {
        self.id
            .refusal()
            .map(|why| format!("nothing can be identified from this data: {why}"))
    }
}

/// Identify a DC record (and diagnose it when `diagnose`); `truth` is the
/// simulated motor, for the text report.
pub fn analyse_dc(record: &Record, truth: Option<DcParams>, diagnose: bool) -> Analysed {
    Analysed::of(record, SegmentKind::DcStep, diagnose, |record| DcAnalysis {
        id: identify_dc(record),
        truth,
    })
}

#[async_trait]
impl Machine for Config {
    fn kind(&self) -> SegmentKind {
        match self.plan {
            Plan::DcStep { .. } => SegmentKind::DcStep,
            Plan::DcCoastdown { .. } => SegmentKind::DcCoastdown,
        }
    }

    fn common(&self) -> &CommonConfig {
        &self.common
    }

    fn describe(&self) -> String {
        format!(
            "{} on {} ({})",
            self.common.motor_id,
            self.backend.describe(),
            self.common.source
        )
    }

    fn plan_summary(&self) -> String {
        match &self.plan {
            Plan::DcStep { levels, coastdown } => {
                let levels: Vec<String> = levels.iter().map(|v| format!("{v}")).collect();
                let tail = if *coastdown { ", coast-down" } else { "" };
                format!("dc_step {} V{tail}", levels.join(" → "))
            }
            Plan::DcCoastdown { from } => format!("dc_coastdown from {from} V"),
        }
    }

    fn safety_rules(&self) -> SafetyRules {
        SafetyRules::of(&self.common, None)
    }

    fn durations(&self) -> PlanDurations {
        let st = self.settle;
        let steps = plan_steps(&self.plan);
        PlanDurations {
            guess_s: st.min_hold_s.max(2.0 * st.window_s) + st.hold_s,
            timeouts_s: steps
                .iter()
                .map(|s| match s {
                    PlanStep::Level { .. } => st.timeout_s + st.hold_s,
                    PlanStep::Coastdown { .. } => st.coastdown_timeout_s,
                })
                .collect(),
            kinds: steps.iter().map(PlanStep::kind).collect(),
        }
    }

    fn record_channels(&self, sensors: &[ChannelInfo], stage_ids: &[&str]) -> Vec<ChannelSpec> {
        record_channels(sensors, stage_ids.first().copied().unwrap_or("stage"))
    }

    async fn open_rig(&self, realtime: bool) -> Result<OpenedRig, RigError> {
        let rig = build_rig(self, realtime).await?;
        let stages = vec![RigStage {
            name: "power stage",
            stage: rig.stage,
            max_setpoint: self.common.limits.max_voltage,
        }];
        Ok(OpenedRig {
            modbus_probe: rig.modbus_sensors,
            ..OpenedRig::new(
                stages,
                rig.sensors,
                rig.counts_per_rev,
                rig.truth,
                rig.served,
                rig.links,
            )
        })
    }

    async fn run_plan(
        &self,
        rig: PlanRig<'_>,
        sink: &mut RecordSink,
        progress: &dyn Progress,
        stops: StopPath<'_>,
    ) -> Result<Outcome, BenchError> {
        let [stage] = rig.stages else {
            unreachable!("a DC rig opens one stage");
        };
        run_test(
            self,
            &plan_steps(&self.plan),
            stage.as_mut(),
            rig.sensors,
            rig.counts_per_rev,
            sink,
            progress,
            stops,
        )
        .await
    }

    fn analyser(&self, truth: Option<Truth>) -> Analyser {
        let truth = truth
            .and_then(|t| t.downcast::<DcParams>().ok())
            .map(|t| *t);
        Box::new(move |record, diagnose| analyse_dc(record, truth, diagnose))
    }
}
