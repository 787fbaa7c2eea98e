//! Parameter identification from a [`Record`].
//!
//! Induction machines: [`identify_im`] on a slip sweep (the seed paper's
//! recursive estimator and Levenberg–Marquardt, `im_*` files).
//!
//! DC: the steady-state method (the seed paper's Eqs. 7, 9, 39 and 44,
//! generalised to a least-squares fit over every settled level of a
//! staircase). Identification is a pure function of the record, so a
//! replayed record gives the same report, bit for bit.

mod im;
mod im_classical;
mod im_identifiability;
mod im_lm;
mod im_recursive;
mod im_sweep;
mod levels;
mod nrmse;
mod simulate;
mod stats;
mod steady_state;

pub use im::{identify_im, sweep_of, ImIdentification};
pub use im_classical::{classical_single, classical_starts};
pub use im_identifiability::{weak_directions, Identifiability, WeakDirection, STRUCTURAL_LIMIT};
pub use im_lm::{
    fit_lm, FittedParam, LmFit, LmOptions, ParamSource, ResidualScale, SplitPolicy, PRACTICAL_LIMIT,
};
pub use im_recursive::{
    paper_cost, recursive_estimate, recursive_pass, Innovation, RecursiveEstimate,
    RecursiveOptions, RecursiveStop, THETA_DOUBLE_L5, THETA_DOUBLE_L7, THETA_SINGLE_FE_L6,
    THETA_SINGLE_L4,
};
pub use im_sweep::{
    predict, predict_gradient, predict_gradient_into, slip_grid, Channels, PhaseData, SlipSweep,
    SweepNoise, SweepPoint, MAX_PARAMS,
};
pub use levels::{is_coastdown, settled_level, SettledLevel};
pub use nrmse::nrmse;
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
    let (method, steady_state, simulated) = match fit {
        Ok(fit) => {
            report.warnings.extend(fit.warnings.iter().cloned());
            let simulated = fit.simulate(record);
            (fit.method_report(), Some(fit), simulated)
        }
        Err(reason) => (MethodReport::not_applicable(reason), None, Vec::new()),
    };
    if method.applies {
        report.best = Some("steady_state".into());
    }
    report.methods.insert("steady_state".into(), method);
    Identification {
        report,
        levels,
        steady_state,
        simulated,
    }
}
