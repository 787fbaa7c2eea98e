//! The induction machine: the slip sweep (`im_slip_sweep`) on a supply
//! VFD and a dynamometer, or the standard test set (`im_standard_tests`:
//! DC resistance, no load, locked rotor, then the sweep as the load test);
//! identification of the equivalent circuit, the plot of current and
//! power against slip.
//!
//! - `config` (+ `modbus_config`): the test's validated configuration;
//! - `sweep`: the sweep driven through the bench's sequencer;
//!   `standard_plan`: the standard tests before it; `stages`:
//!   the VFD and dynamometer behind their Modbus profiles;
//! - `rig`: the rig a configuration names; `sim_rig`: the simulated
//!   machine, VFD and dynamometer; `served`: the simulated rig behind
//!   Modbus;
//! - `identify/`, `diagnose/`: the circuit fits and the sim-to-real gap;
//!   `text`, `plot`: the text report and the plot;
//! - `blind_case`: the blind benchmark's induction-machine cases.

pub(crate) mod blind_case;
mod config;
pub mod diagnose;
pub mod identify;
mod modbus_config;
mod plot;
mod rig;
mod served;
mod sim_rig;
mod stages;
mod standard_config;
mod standard_plan;
mod sweep;
mod text;

pub use config::ImRunConfig;
pub use modbus_config::{ImDcSourceLink, ImModbusRig};
pub use plot::{render_im_svg, write_im_svg, DrawError, SweepPlotError};
pub use rig::{build_im_rig, ImRig, SERVED_IM_PLANT_RATE_HZ};
pub use served::{ServedImRig, ServedVfd};
pub use sim_rig::{
    sim_im_rig, SimDcSource, SimDyno, SimImRigConfig, SimImSensors, SimRigError, SimVfd,
    COPPER_ALPHA,
};
pub use stages::{DcCurrentSource, VfdDyno, VfdSupply};
pub use standard_plan::{
    ReducedFrequencyTest, StandardTestsPlan, DC_RESISTANCE_SEGMENT, LOCKED_ROTOR_SEGMENT,
    NO_LOAD_SEGMENT, REDUCED_FREQUENCY_SEGMENT, STANDARD_SEGMENTS,
};
use sweep::{run_im_plan, ImStages};
pub use sweep::{run_im_sweep, sweep_channels, ImSweepPlan};
pub use text::render_im_text;

use std::path::Path;

use async_trait::async_trait;
use motorbench_drivers::{ChannelInfo, PowerStage};

use super::{
    Analysed, Analyser, Analysis, Machine, OpenedRig, PlanDurations, PlanRig, PlotFailure,
    RigStage, Truth,
};
use crate::bench::{BenchError, Outcome, Progress, RecordSink, SafetyRules, StopPath};
use crate::config::{recorded_im_model, CommonConfig};
use crate::identify::{identify_im, ImIdentification, JOINT, STANDARD_TESTS};
use crate::model::{Connection, ImModel};
use crate::record::{ChannelSpec, Record, SegmentKind};
use crate::report::IdentificationReport;
use crate::rig::RigError;

struct ImAnalysis(ImIdentification);

impl Analysis for ImAnalysis {
    fn report(&self) -> &IdentificationReport {
        &self.0.report
    }

    fn report_mut(&mut self) -> &mut IdentificationReport {
        &mut self.0.report
    }

    fn text(&self) -> String {
        render_im_text(&self.0)
    }

    fn write_plot(&self, _record: &Record, path: &Path) -> Result<(), PlotFailure> {
        Ok(write_im_svg(path, &self.0)?)
    }

    fn refusal(&self) -> Option<String> {
        refusal(&self.0.report)
    }
}

/// Why nothing was identified, `None` where a method was: the first
/// reason of the joint fit, the circuit fit, the classical reduction and
/// the paper's estimator, in that order (the first says most of what the
/// record lacks, the estimator's least).
fn refusal(report: &IdentificationReport) -> Option<String> {
    if report.best.is_some() {
        return None;
    }
    let why = [JOINT, "lm", STANDARD_TESTS, "recursive"]
        .into_iter()
        .find_map(|key| {
            let reason = report.methods.get(key)?.reason.as_deref()?;
            Some(format!(
                "{key}: {}",
                reason.trim_start_matches("does not apply: ")
            ))
        });
    Some(match why {
        Some(why) => format!(
            "no identification method applies to this data ({why}; the other methods' \
             reasons are in the report)"
        ),
        None => "no identification method applies to this data (see the warnings)".into(),
    })
}

/// Identify an induction-machine record with the circuit `model` (the
/// winding connected as `connection`, else as the nameplate says), and
/// diagnose it when `diagnose`.
pub fn analyse_im(
    record: &Record,
    connection: Option<Connection>,
    model: ImModel,
    diagnose: bool,
) -> Analysed {
    Analysed::of(record, SegmentKind::ImSlipSweep, diagnose, |record| {
        ImAnalysis(identify_im(record, connection, model))
    })
}

/// The circuit a record's configuration named, else single cage with
/// iron loss.
pub(super) fn recorded_model(record: &Record) -> ImModel {
    record
        .meta
        .as_ref()
        .and_then(|m| recorded_im_model(&m.config))
        .unwrap_or(ImModel::SingleFe)
}

#[async_trait]
impl Machine for ImRunConfig {
    fn kind(&self) -> SegmentKind {
        SegmentKind::ImSlipSweep
    }

    fn common(&self) -> &CommonConfig {
        &self.common
    }

    fn describe(&self) -> String {
        format!(
            "{} {} on {} ({})",
            self.common.motor_id,
            match self.standard {
                Some(_) => "standard tests",
                None => "slip sweep",
            },
            self.describe_rig(),
            self.common.source
        )
    }

    fn plan_summary(&self) -> String {
        let p = &self.plan;
        let volts: Vec<String> = p.voltages.iter().map(|v| format!("{v}")).collect();
        let sweep = format!(
            "im_slip_sweep {} V at {} Hz, {} slips {}…{}",
            volts.join(", "),
            p.frequency,
            p.slips.len(),
            p.slips.first().copied().unwrap_or(0.0),
            p.slips.last().copied().unwrap_or(0.0)
        );
        match &self.standard {
            Some(s) => format!("{}; then the load test: {sweep}", s.summary()),
            None => sweep,
        }
    }

    fn safety_rules(&self) -> SafetyRules {
        ImRunConfig::safety_rules(self)
    }

    fn durations(&self) -> PlanDurations {
        let p = &self.plan;
        // A point: two settle windows and the average; at most the settle
        // timeout plus the average and a cool-down.
        let period = 1.0 / self.common.sample_rate_hz;
        let point_guess = (2 * p.settle_window + p.average_samples) as f64 * period + 0.1;
        let point_max = p.max_point_s + p.average_samples as f64 * period + p.cooldown_s;
        let mut d = PlanDurations {
            guess_s: point_guess * p.slips.len() as f64,
            timeouts_s: vec![point_max * p.slips.len() as f64; p.voltages.len()],
            kinds: vec![SegmentKind::ImSlipSweep; p.voltages.len()],
        };
        if let Some(s) = &self.standard {
            let kinds = [
                SegmentKind::ImDcResistance,
                SegmentKind::ImNoLoad,
                SegmentKind::ImLockedRotor,
                SegmentKind::ImLockedRotor,
            ];
            let points = s.points();
            d.kinds.splice(0..0, kinds.into_iter().take(points.len()));
            d.timeouts_s
                .splice(0..0, points.into_iter().map(|n| point_max * n as f64));
        }
        d
    }

    fn record_channels(&self, sensors: &[ChannelInfo], stage_ids: &[&str]) -> Vec<ChannelSpec> {
        let id = |k: usize| stage_ids.get(k).copied().unwrap_or("stage");
        let mut channels = sweep_channels(sensors, id(0), id(1));
        if let Some(s) = &self.standard {
            channels.push(ChannelSpec::command("dc_current", "A", id(2)));
            if s.reduced_frequency.is_some() {
                channels.push(ChannelSpec::command("supply_frequency", "Hz", id(0)));
            }
        }
        channels
    }

    async fn open_rig(&self, realtime: bool) -> Result<OpenedRig, RigError> {
        let rig = build_im_rig(self, realtime).await?;
        // The supply first: a stop takes the machine off the supply
        // before the dynamometer lets go of the shaft.
        let stages = vec![
            RigStage {
                name: "supply",
                stage: rig.supply,
                max_setpoint: self.common.limits.max_voltage,
            },
            RigStage {
                name: "dynamometer",
                stage: rig.dynamometer,
                max_setpoint: self.common.limits.max_speed,
            },
        ]
        .into_iter()
        .chain(rig.dc_source.map(|stage| RigStage {
            name: "DC source",
            max_setpoint: stage.capabilities().max_setpoint,
            stage,
        }))
        .collect();
        Ok(OpenedRig::new(
            stages,
            rig.sensors,
            rig.counts_per_rev,
            rig.truth,
            rig.served,
            rig.links,
        ))
    }

    async fn run_plan(
        &self,
        rig: PlanRig<'_>,
        sink: &mut RecordSink,
        progress: &dyn Progress,
        stops: StopPath<'_>,
    ) -> Result<Outcome, BenchError> {
        let (supply, dyno, dc) = match rig.stages {
            [supply, dyno] => (supply, dyno, None),
            [supply, dyno, dc] => (supply, dyno, Some(dc.as_mut() as &mut dyn PowerStage)),
            _ => unreachable!("an induction-machine rig opens two or three stages"),
        };
        let stages = ImStages {
            vfd: supply.as_mut(),
            dyno: dyno.as_mut(),
            dc,
        };
        run_im_plan(
            &self.plan,
            self.standard.as_ref(),
            &ImRunConfig::safety_rules(self),
            stages,
            rig.sensors,
            sink,
            progress,
            stops,
        )
        .await
    }

    fn analyser(&self, _truth: Option<Truth>) -> Analyser {
        let model = self.model;
        Box::new(move |record, diagnose| analyse_im(record, None, model, diagnose))
    }
}

/// Assert that one of `warnings` contains `text` (the warnings shown when
/// none does): for the tests of the induction machine's fits.
#[cfg(test)]
#[track_caller]
pub(crate) fn assert_warned(warnings: &[String], text: &str) {
    assert!(warnings.iter().any(|w| w.contains(text)), "{:?}", warnings);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::MethodReport;

    /// With no best method the refusal gives the first reason of the
    /// joint fit, the circuit fit, the classical reduction and the
    /// estimator, in that order; with a best, none.
    #[test]
    fn the_refusal_gives_the_reason_that_says_most() {
        let mut report = IdentificationReport::new("im_slip_sweep");
        let refused = |why: &str| MethodReport::not_applicable(format!("does not apply: {why}"));
        report
            .methods
            .insert("recursive".into(), refused("Rs went negative"));
        report
            .methods
            .insert("lm".into(), refused("the fit collapsed"));
        let why = refusal(&report).unwrap();
        assert!(why.contains("(lm: the fit collapsed;"), "{why}");
        report
            .methods
            .insert(JOINT.into(), refused("no no-load readings"));
        let why = refusal(&report).unwrap();
        assert!(why.contains("(joint: no no-load readings;"), "{why}");
        report.best = Some("lm".into());
        assert_eq!(refusal(&report), None);
    }
}
