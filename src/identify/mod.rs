//! Parameter identification from a [`Record`].
//!
//! Today: the steady-state method (the seed paper's Eqs. 7, 9, 39 and 44,
//! generalised to a least-squares fit over every settled level of a
//! staircase). Identification is a pure function of the record, so a
//! replayed record gives the same report, bit for bit.

mod levels;
mod nrmse;
mod output_error;
mod simulate;
mod stats;
mod steady_state;

pub use levels::{is_coastdown, settled_level, SettledLevel};
pub use nrmse::nrmse;
pub use output_error::{
    output_error, ChannelNoise, HeldOut, OutputErrorFit, OutputErrorOptions, SegmentStart,
    SpeedReading, Uncertainty, PARAM_KEYS, PARAM_UNITS,
};
pub use simulate::simulate_segment;
pub use steady_state::{SteadyStateEstimate, SteadyStateFit};

use crate::record::{Record, SegmentKind};
use crate::report::{IdentificationReport, MethodReport};

/// A model's response on one segment, for plots.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedSegment {
    /// Segment index.
    pub index: u32,
    /// Model name, e.g. `steady_state`.
    pub model: String,
    /// Current on the segment's time base, A.
    pub current: Vec<f64>,
    /// Speed on the segment's time base, rad/s.
    pub speed: Vec<f64>,
}

/// Everything identification produced: the contract report and the
/// details behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// The report per the data contract.
    pub report: IdentificationReport,
    /// The steady-state levels found, one per step segment.
    pub levels: Vec<SettledLevel>,
    /// The steady-state fit, when it applied.
    pub steady_state: Option<SteadyStateFit>,
    /// Model responses per segment, for plots.
    pub simulated: Vec<SimulatedSegment>,
    /// The output-error fit, when it applied.
    pub output_error: Option<OutputErrorFit>,
}

/// Identify a DC motor from a `dc_step` / `dc_coastdown` record.
pub fn identify_dc(record: &Record) -> Identification {
    let mut report = IdentificationReport::new(SegmentKind::DcStep.as_str());
    let mut levels = Vec::new();
    for seg in &record.segments {
        if seg.time.is_empty() {
            report.warnings.push(format!(
                "segment {} ({}) has no samples of armature voltage, current and speed",
                seg.index, seg.label
            ));
            continue;
        }
        if seg.kind == Some(SegmentKind::DcCoastdown) || is_coastdown(seg) {
            continue;
        }
        match settled_level(seg) {
            Some(level) if level.settled => levels.push(level),
            Some(level) => report.warnings.push(format!(
                "segment {} ({}) had not settled at its end (current or speed still moving): its level is not used",
                level.segment, level.label
            )),
            None => report.warnings.push(format!("segment {} ({}) is too short to find a level", seg.index, seg.label)),
        }
    }
    if let Some(r) = &record.recovery {
        report.warnings.push(format!(
            "the record was damaged: {} messages recovered ({})",
            r.messages, r.reason
        ));
    }

    let fit = steady_state::fit(record, &levels);
    let (method, steady_state, mut simulated) = match fit {
        Ok(fit) => {
            report.warnings.extend(fit.warnings.iter().cloned());
            let simulated = fit.simulate(record);
            (fit.method_report(), Some(fit), simulated)
        }
        Err(reason) => (MethodReport::not_applicable(reason), None, Vec::new()),
    };
    report.methods.insert("steady_state".into(), method);

    let oe = output_error(record, None, &OutputErrorOptions::default());
    let (method, output_error) = match oe {
        Ok(fit) => {
            report.warnings.extend(fit.warnings.iter().cloned());
            simulated.extend(fit.simulated.iter().cloned());
            (fit.method_report(), Some(fit))
        }
        Err(reason) => (MethodReport::not_applicable(reason), None),
    };
    report.methods.insert("output_error".into(), method);

    report.best = best_method(&report);
    Identification {
        report,
        levels,
        steady_state,
        simulated,
        output_error,
    }
}

/// The applicable method with the lowest validation NRMSE; without any
/// validation score, the first applicable one.
fn best_method(report: &IdentificationReport) -> Option<String> {
    let applicable = || report.methods.iter().filter(|(_, m)| m.applies);
    applicable()
        .filter_map(|(k, m)| m.validation_nrmse.map(|v| (k, v)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(k, _)| k.clone())
        .or_else(|| applicable().next().map(|(k, _)| k.clone()))
}
