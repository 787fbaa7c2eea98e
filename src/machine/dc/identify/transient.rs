//! A transient method's report (Pasek's, the moments'): the estimate from
//! the step it is fitted on, intervals from the spread over the other
//! steps, and the validation NRMSE on the segments it was not fitted on.
//!
//! - The fit step is the largest voltage rise between two turning,
//!   settled levels ([`super::step::fit_step`]).
//! - La, J, f and Tst get a 95 % interval from the estimates of every
//!   usable step (the fit step included): value ± t(n−1)·sd, the spread a
//!   single step's estimate has; La and J (∝ Ra and ≈ 1/Ra) add the
//!   steady state's relative uncertainty of Ra in quadrature, which no
//!   spread over steps can show (every step uses the same Ra). It needs
//!   three steps; with fewer, `ci95` is null. Ra and K are the steady-state fit's, with its
//!   intervals.
//! - Validation: the full model with these parameters is simulated on
//!   every other step segment with the measured voltage
//!   ([`super::simulate_segment`]); a segment's NRMSE is the mean over
//!   current and speed, and the method's is the mean over segments.

use super::{is_coastdown, nrmse, simulate_segment, SimulatedSegment, SteadyStateFit};
use crate::identify::stats::t975;
use crate::model::DcParams;
use crate::record::{DcSegment, Record, SegmentKind};
use crate::report::{MethodReport, ParamEstimate};

/// Contract keys and units, in [`as_array`] order.
pub const KEYS: [(&str, &str); 6] = [
    ("Ra", "ohm"),
    ("La", "H"),
    ("K", "V*s/rad"),
    ("J", "kg*m^2"),
    ("f", "N*m*s/rad"),
    ("Tst", "N*m"),
];

/// `[Ra, La, K, J, f, Tst]`.
pub fn as_array(p: &DcParams) -> [f64; 6] {
    [p.ra, p.la, p.k, p.j, p.f, p.tst]
}

/// A transient method's result.
#[derive(Debug, Clone, PartialEq)]
pub struct TransientFit {
    /// Method key, e.g. `moments`.
    pub method: String,
    /// The segment fitted on.
    pub fit_segment: u32,
    /// The parameters from the fit step.
    pub params: DcParams,
    /// Every usable step's parameters (the fit step's included).
    pub per_step: Vec<(u32, DcParams)>,
    /// 95 % intervals in [`KEYS`] order.
    pub ci95: [Option<[f64; 2]>; 6],
    /// Mean NRMSE on the step segments not fitted on.
    pub validation_nrmse: Option<f64>,
    /// Findings worth a user's attention.
    pub warnings: Vec<String>,
}

/// `value ± t(n−1)·sd(all)`, for three or more values.
pub fn spread_interval(value: f64, all: &[f64]) -> Option<[f64; 2]> {
    let n = all.len();
    if n < 3 {
        return None;
    }
    let m = all.iter().sum::<f64>() / n as f64;
    let sd = (all.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    let h = t975(n - 1) * sd;
    h.is_finite().then_some([value - h, value + h])
}

/// The parameters made simulable: a negative f or Tst (noise) becomes 0.
fn simulable(p: &DcParams) -> DcParams {
    DcParams {
        f: p.f.max(0.0),
        tst: p.tst.max(0.0),
        ..*p
    }
}

/// Whether a segment is a step (not a coast-down, not empty).
pub fn is_step_segment(seg: &DcSegment) -> bool {
    !seg.time.is_empty() && seg.kind != Some(SegmentKind::DcCoastdown) && !is_coastdown(seg)
}

/// The contract's NRMSE of one segment (mean over current and speed).
pub fn segment_nrmse(params: &DcParams, seg: &DcSegment) -> Option<f64> {
    let (i, w) = simulate_segment(&simulable(params), seg).ok()?;
    let parts: Vec<f64> = [nrmse(&seg.current, &i), nrmse(&seg.speed, &w)]
        .into_iter()
        .flatten()
        .collect();
    (!parts.is_empty()).then(|| parts.iter().sum::<f64>() / parts.len() as f64)
}

/// The model's response on every step segment, for plots.
pub fn simulate_steps(params: &DcParams, record: &Record, model: &str) -> Vec<SimulatedSegment> {
    record
        .segments
        .iter()
        .filter(|s| is_step_segment(s))
        .filter_map(|s| {
            let (current, speed) = simulate_segment(&simulable(params), s).ok()?;
            Some(SimulatedSegment {
                index: s.index,
                model: model.to_string(),
                current,
                speed,
            })
        })
        .collect()
}

/// Build the report of `method` from its per-step estimates.
pub fn assemble(
    method: &str,
    record: &Record,
    fit_segment: u32,
    per_step: Vec<(u32, DcParams)>,
    ss: &SteadyStateFit,
) -> TransientFit {
    let params = per_step
        .iter()
        .find(|(s, _)| *s == fit_segment)
        .map(|(_, p)| *p)
        .expect("the fit step has an estimate");
    let values = as_array(&params);
    // La = Ra·τe and J ≈ τm·K²/Ra carry Ra's relative uncertainty too.
    let ra_rel = ss.std_error[1] / ss.estimate.ra.abs();
    let ci95 = std::array::from_fn(|n| match n {
        0 => ss.ci95[1],
        2 => ss.ci95[0],
        _ => {
            let all: Vec<f64> = per_step.iter().map(|(_, p)| as_array(p)[n]).collect();
            let [lo, hi] = spread_interval(values[n], &all)?;
            let extra = if n == 1 || n == 3 {
                1.96 * ra_rel * values[n].abs()
            } else {
                0.0
            };
            let h = (((hi - lo) / 2.0).powi(2) + extra * extra).sqrt();
            Some([values[n] - h, values[n] + h])
        }
    });
    let mut warnings = Vec::new();
    if params.f < 0.0 || params.tst < 0.0 {
        warnings.push(format!(
            "{method}: f = {:.3e}, Tst = {:.3e} from segment {fit_segment}; the validation \
             simulates with negative values set to 0",
            params.f, params.tst
        ));
    }
    let scores: Vec<f64> = record
        .segments
        .iter()
        .filter(|s| is_step_segment(s) && s.index != fit_segment)
        .filter_map(|s| segment_nrmse(&params, s))
        .collect();
    let validation_nrmse =
        (!scores.is_empty()).then(|| scores.iter().sum::<f64>() / scores.len() as f64);
    TransientFit {
        method: method.to_string(),
        fit_segment,
        params,
        per_step,
        ci95,
        validation_nrmse,
        warnings,
    }
}

impl TransientFit {
    /// The contract's view.
    pub fn method_report(&self) -> MethodReport {
        let values = as_array(&self.params);
        let params = KEYS
            .iter()
            .zip(values)
            .zip(self.ci95)
            .map(|(((key, unit), value), ci95)| {
                (
                    key.to_string(),
                    ParamEstimate {
                        value,
                        ci95,
                        unit: unit.to_string(),
                    },
                )
            })
            .collect();
        MethodReport::fitted(params, self.validation_nrmse)
    }

    /// The range of each parameter over the steps, in [`KEYS`] order.
    pub fn step_range(&self) -> [[f64; 2]; 6] {
        std::array::from_fn(|n| {
            let v = self.per_step.iter().map(|(_, p)| as_array(p)[n]);
            [
                v.clone().fold(f64::INFINITY, f64::min),
                v.fold(f64::NEG_INFINITY, f64::max),
            ]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_interval_needs_three_values_and_uses_student_t() {
        assert_eq!(spread_interval(1.0, &[1.0, 2.0]), None);
        let [lo, hi] = spread_interval(2.0, &[1.0, 2.0, 3.0]).unwrap();
        // sd = 1, t(2) = 4.302653 (table value).
        assert!((hi - 2.0 - 4.302_653).abs() < 1e-5 && (2.0 - lo - 4.302_653).abs() < 1e-5);
    }
}
