//! Several starts for the output-error fit when its start is poorly
//! conditioned (an equation-error estimate whose La or J the record hardly
//! determines): the fit runs from the start and from La and J scaled by
//! 1/4 and 4, and keeps the optimum with the lowest residual. Five bounded
//! fits instead of one; the cost surface of a DC model has few local
//! minima, but a poor start in the weakly determined direction can stall
//! the optimiser on a plateau.

use super::problem::{minimise, FitData, Minimum};
use crate::model::DcParams;

/// Scale factors tried on La and on J (one at a time).
const SCALES: [f64; 2] = [0.25, 4.0];

/// The best of the fits from `start` and its variants, and how many ran.
pub fn best_of(data: &FitData, start: &DcParams) -> (Minimum, usize) {
    let mut starts = vec![*start];
    for s in SCALES {
        starts.push(DcParams {
            la: start.la * s,
            ..*start
        });
        starts.push(DcParams {
            j: start.j * s,
            ..*start
        });
    }
    let tried = starts.len();
    let cost = |m: &Minimum| {
        if m.at.refused() {
            f64::INFINITY
        } else {
            m.at.r.norm_squared()
        }
    };
    let best = starts
        .iter()
        .map(|s| minimise(data, s))
        .min_by(|a, b| cost(a).total_cmp(&cost(b)))
        .expect("at least one start");
    (best, tried)
}
