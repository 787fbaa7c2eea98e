//! Is the armature voltage a controller's output? A closed loop feeds the
//! speed reading's noise back into the voltage, so the voltage's sample to
//! sample changes follow the speed reading's changes of the same or the
//! previous sample. In open loop the voltage is set by a plan (steps,
//! ramps, PRBS): between its edges it changes only by its own reading
//! noise, which nothing in the speed reading follows within a sample (the
//! rotor's response to the voltage takes a mechanical time constant).
//!
//! Closed-loop data correlates the input with the noise of the regressors:
//! least squares on the measured current and speed, and output error
//! (which takes the voltage as exact), are biased by it; the report then
//! prefers equation error's instrumental-variable estimate.

use crate::record::DcSegment;

/// The finding: the correlation of the voltage's changes with the speed
/// reading's changes at the lag where it is largest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feedback {
    /// Correlation coefficient (negative for a controller that lowers the
    /// voltage when the speed reads high).
    pub correlation: f64,
    /// Lag in samples (0: the same sample, 1: the speed a sample before).
    pub lag: usize,
    /// Sample pairs the correlation is taken over.
    pub samples: usize,
}

/// Fewest sample pairs for a verdict.
const MIN_PAIRS: usize = 200;

/// Changes larger than this many robust standard deviations of the
/// voltage's changes are a plan's edges, not feedback, and are left out.
const EDGE: f64 = 5.0;

/// Significance of the test: |r| over this many standard errors of a zero
/// correlation (1/√n); four is a false alarm about once in 16 000 records.
const SIGNIFICANCE: f64 = 4.0;

/// The feedback found in `segments`, if the voltage's changes follow the
/// speed reading's significantly.
pub fn detect(segments: &[&DcSegment]) -> Option<Feedback> {
    let diffs = |y: &[f64]| y.windows(2).map(|w| w[1] - w[0]).collect::<Vec<f64>>();
    let mut pooled: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    let mut all_du = Vec::new();
    for seg in segments {
        let (du, dw) = (diffs(&seg.voltage), diffs(&seg.speed));
        all_du.extend(du.iter().map(|v| v.abs()));
        pooled.push((du, dw));
    }
    if all_du.len() < MIN_PAIRS {
        return None;
    }
    all_du.sort_by(f64::total_cmp);
    // Median absolute change → standard deviation of a zero-mean normal.
    let scale = all_du[all_du.len() / 2] / 0.6745;
    if !(scale > 0.0 && scale.is_finite()) {
        // The voltage holds exactly between edges: nothing is fed back.
        return None;
    }
    let mut best: Option<Feedback> = None;
    for lag in 0..=1 {
        let (mut n, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0usize, 0.0, 0.0, 0.0, 0.0, 0.0);
        for (du, dw) in &pooled {
            for k in lag..du.len() {
                let (x, y) = (du[k], dw[k - lag]);
                if x.abs() > EDGE * scale {
                    continue;
                }
                n += 1;
                sx += x;
                sy += y;
                sxx += x * x;
                syy += y * y;
                sxy += x * y;
            }
        }
        if n < MIN_PAIRS {
            continue;
        }
        let nf = n as f64;
        let cov = sxy - sx * sy / nf;
        let var = (sxx - sx * sx / nf) * (syy - sy * sy / nf);
        if var.is_nan() || var <= 0.0 {
            continue;
        }
        let r = cov / var.sqrt();
        if r.abs() * nf.sqrt() > SIGNIFICANCE && best.is_none_or(|b| r.abs() > b.correlation.abs())
        {
            best = Some(Feedback {
                correlation: r,
                lag,
                samples: n,
            });
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn segment(u: Vec<f64>, w: Vec<f64>) -> DcSegment {
        DcSegment {
            time: (0..u.len()).map(|k| k as f64 * 1e-3).collect(),
            current: vec![0.0; u.len()],
            voltage: u,
            speed: w,
            ..Default::default()
        }
    }

    /// A deterministic noise sequence in [−0.5, 0.5).
    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    #[test]
    fn a_controller_reading_the_speed_is_found() {
        let n = 2000;
        let e = noise(n, 1);
        let ue = noise(n, 2);
        // Speed reading: a slow ramp plus noise; voltage: a P controller
        // on it plus its own reading noise.
        let w: Vec<f64> = (0..n).map(|k| 0.01 * k as f64 + e[k]).collect();
        let u: Vec<f64> = (0..n).map(|k| 50.0 - 2.0 * w[k] + 0.5 * ue[k]).collect();
        let f = detect(&[&segment(u, w.clone())]).expect("feedback");
        assert!(f.correlation < -0.5, "{f:?}");
        assert_eq!(f.lag, 0);
    }

    #[test]
    fn a_planned_voltage_is_not_feedback() {
        let n = 2000;
        let e = noise(n, 3);
        let ue = noise(n, 4);
        // Steps and a ramp with reading noise; the speed follows slowly.
        let u: Vec<f64> = (0..n)
            .map(|k| 20.0 * ((k / 400) % 2) as f64 + 0.01 * k as f64 + 0.1 * ue[k])
            .collect();
        let mut w = vec![0.0; n];
        for k in 1..n {
            w[k] = w[k - 1] + 0.01 * (u[k - 1] - w[k - 1]);
        }
        let w: Vec<f64> = w.iter().zip(&e).map(|(a, b)| a + b).collect();
        assert_eq!(detect(&[&segment(u, w)]), None);
    }
}
