//! Uncertainty of the output-error fit from the Jacobian at the optimum:
//! the covariance of the log-parameters, 95 % intervals mapped back to the
//! natural parameters, the correlation matrix, and warnings for parameters
//! the data do not determine.
//!
//! The covariance is a sandwich `(JᵀJ)⁻¹·(S_r + S_u)·(JᵀJ)⁻¹` rather than
//! the textbook `s²·(JᵀJ)⁻¹`, which assumes white residuals of one
//! variance. The record's residuals are neither: the speed from encoder
//! counts has a quantisation noise that is larger during transients than
//! over the settled tails the weights come from, and is correlated from
//! one sample to the next; misfit is correlated over time constants.
//!
//! - `S_r = Σ_b g_b·g_bᵀ` with `g_b = Σ_{k∈b} J_kᵀ·r_k` over blocks `b` of
//!   consecutive samples within a segment: the residuals' own variance,
//!   whatever its level per channel and sample, and its correlation
//!   within a block.
//! - `S_u = σu²·Σ_j a_j·a_jᵀ`: what the noise of the measured *voltage*
//!   adds. It drives the simulation, so its effect on the estimate is
//!   not visible in the residuals at its real size (see
//!   [`super::input_noise`]).
//!
//! The intervals are Wald intervals in log space, `p·exp(±t·σ_ln)`: they
//! are asymmetric in the natural parameter and never include zero or
//! negative values. The log-space correlation is also the correlation of
//! the linearised natural parameters (the transform is diagonal).

use nalgebra::{DVector, Dyn, Matrix6, OMatrix, U6};

use super::problem::{to_array, NP};
use crate::identify::stats::t975;
use crate::model::DcParams;

/// Contract keys of the parameters, in fit order.
pub const PARAM_KEYS: [&str; NP] = ["Ra", "La", "K", "J", "f", "Tst"];

/// A 95 % interval wider than this fraction of the value (half width)
/// means the record does not determine the parameter.
const POOR_HALF_WIDTH: f64 = 0.5;

/// Correlation beyond which two parameters are reported as inseparable.
const HIGH_CORRELATION: f64 = 0.99;

/// Singular values of the column-normalised Jacobian below this fraction
/// of the largest are treated as zero: a direction the data do not see.
const NULL_SINGULAR: f64 = 1e-7;

/// What the Jacobian says about the estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// Standard error of `ln p` per parameter, from the sandwich
    /// (infinite where undetermined).
    pub std_ln: [f64; NP],
    /// 95 % interval per parameter, natural units; `None` where the data
    /// do not determine it.
    pub ci95: [Option<[f64; 2]>; NP],
    /// Correlation matrix of the estimates (NaN where undetermined).
    pub correlation: [[f64; NP]; NP],
    /// Singular values of the Jacobian with unit-norm columns, largest
    /// first, divided by the largest.
    pub relative_singular_values: [f64; NP],
    /// Weighted residual variance `s²` (1 when the residuals are at the
    /// noise level estimated from the settled tails).
    pub residual_variance: f64,
    /// Degrees of freedom: residuals minus parameters.
    pub dof: usize,
    /// Standard error of `ln p` from the classic `s²·(JᵀJ)⁻¹`, which
    /// assumes white residuals of one variance (for comparison).
    pub std_ln_classic: [f64; NP],
    /// `(JᵀJ)⁻¹` of the log-parameters on the directions the data
    /// determine (NaN in the rows and columns of the others).
    pub jtj_inverse: Matrix6<f64>,
    /// Per parameter: undetermined, poorly determined or hard to separate
    /// from another one.
    pub flagged: [bool; NP],
    /// Per parameter: undetermined, or its 95 % interval wider than
    /// ±50 % (the record hardly determines it).
    pub poorly_determined: [bool; NP],
    /// Parameters the data do not determine, and why.
    pub warnings: Vec<String>,
}

/// The uncertainty of `params` given the Jacobian `jac` of the weighted
/// residuals `r` with respect to the log-parameters; `segment_rows` are
/// the residual rows of each segment in order, `block_rows` the rows per
/// block of `S_r`, `input_scores` is `S_u`.
pub fn uncertainty(
    jac: &OMatrix<f64, Dyn, U6>,
    r: &DVector<f64>,
    params: &DcParams,
    segment_rows: &[usize],
    block_rows: usize,
    input_scores: &Matrix6<f64>,
) -> Uncertainty {
    let m = r.len();
    let dof = m.saturating_sub(NP).max(1);
    let s2 = r.norm_squared() / dof as f64;
    let jtj: Matrix6<f64> = jac.tr_mul(jac);
    let scale: [f64; NP] = std::array::from_fn(|n| jtj[(n, n)].sqrt());
    // A non-finite entry counts as no information (the eigen-decomposition
    // need not converge on a NaN).
    let normalised = Matrix6::from_fn(|a, b| {
        let v = jtj[(a, b)] / (scale[a] * scale[b]);
        if scale[a] > 0.0 && scale[b] > 0.0 && v.is_finite() {
            v
        } else {
            0.0
        }
    });
    let eig = normalised.symmetric_eigen();
    let mut order: Vec<usize> = (0..NP).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let sv = |n: usize| eig.eigenvalues[n].max(0.0).sqrt();
    let largest = sv(order[0]);
    let relative_singular_values: [f64; NP] = std::array::from_fn(|n| {
        if largest > 0.0 {
            sv(order[n]) / largest
        } else {
            0.0
        }
    });

    // Inverse of the normalised matrix on the directions the data see;
    // parameters in an unseen direction get an infinite variance.
    let mut inverse = Matrix6::<f64>::zeros();
    let mut undetermined = [false; NP];
    let mut null_directions = Vec::new();
    for n in 0..NP {
        let v = eig.eigenvectors.column(n);
        if largest > 0.0 && sv(n) > NULL_SINGULAR * largest {
            inverse += v * v.transpose() / eig.eigenvalues[n];
        } else {
            let involved: Vec<usize> = (0..NP).filter(|&p| v[p].abs() > 0.1).collect();
            for &p in &involved {
                undetermined[p] = true;
            }
            null_directions.push(involved);
        }
    }
    for (n, undetermined) in undetermined.iter_mut().enumerate() {
        if scale[n] == 0.0 {
            *undetermined = true;
        }
    }
    // (JᵀJ)⁻¹ on the seen directions (zero on the others for the products).
    let h_inv = Matrix6::from_fn(|a, b| {
        if undetermined[a] || undetermined[b] {
            0.0
        } else {
            inverse[(a, b)] / (scale[a] * scale[b])
        }
    });
    let meat = block_scores(jac, r, segment_rows, block_rows) + input_scores;
    let mark = |m: Matrix6<f64>| {
        Matrix6::from_fn(|a, b| {
            if undetermined[a] || undetermined[b] {
                f64::NAN
            } else {
                m[(a, b)]
            }
        })
    };
    let cov = mark(h_inv * meat * h_inv);
    let std_of = |cov: &Matrix6<f64>| -> [f64; NP] {
        std::array::from_fn(|n| {
            if undetermined[n] {
                f64::INFINITY
            } else {
                cov[(n, n)].max(0.0).sqrt()
            }
        })
    };
    let std_ln = std_of(&cov);
    let std_ln_classic = std_of(&mark(h_inv * s2));
    let correlation: [[f64; NP]; NP] = std::array::from_fn(|a| {
        std::array::from_fn(|b| {
            let c = cov[(a, b)] / (std_ln[a] * std_ln[b]);
            if a == b && c.is_finite() {
                1.0
            } else {
                c
            }
        })
    });
    let values = to_array(params);
    let ci95 = intervals(params, &std_ln, dof);

    let mut warnings = Vec::new();
    let mut flagged = undetermined;
    let mut poorly_determined = undetermined;
    for involved in &null_directions {
        let names: Vec<&str> = involved.iter().map(|&p| PARAM_KEYS[p]).collect();
        warnings.push(format!(
            "{} not identifiable from this record: the Jacobian has a (near) zero singular value \
             in their direction, so the data constrain only a combination of them; no interval given",
            names.join(", ")
        ));
    }
    for n in 0..NP {
        if let Some([lo, hi]) = ci95[n] {
            let half = (hi - lo) / 2.0 / values[n];
            if half > POOR_HALF_WIDTH {
                flagged[n] = true;
                poorly_determined[n] = true;
                warnings.push(format!(
                    "{} is poorly determined by this record: 95 % interval [{lo:.4e}, {hi:.4e}] \
                     (±{:.0} % of the estimate)",
                    PARAM_KEYS[n],
                    100.0 * half
                ));
            }
        }
    }
    for a in 0..NP {
        for b in a + 1..NP {
            let c = correlation[a][b];
            if c.abs() > HIGH_CORRELATION {
                flagged[a] = true;
                flagged[b] = true;
                warnings.push(format!(
                    "{} and {} are hard to separate with this record: correlation {c:+.4}",
                    PARAM_KEYS[a], PARAM_KEYS[b]
                ));
            }
        }
    }
    Uncertainty {
        std_ln,
        ci95,
        correlation,
        relative_singular_values,
        residual_variance: s2,
        dof,
        flagged,
        poorly_determined,
        std_ln_classic,
        jtj_inverse: mark(h_inv),
        warnings,
    }
}

/// 95 % intervals `p·exp(±t·σ_ln)` about `params` (`None` where σ_ln is
/// infinite).
pub fn intervals(params: &DcParams, std_ln: &[f64; NP], dof: usize) -> [Option<[f64; 2]>; NP] {
    let t = t975(dof);
    let values = to_array(params);
    std::array::from_fn(|n| {
        let h = t * std_ln[n];
        h.is_finite()
            .then(|| [values[n] * (-h).exp(), values[n] * h.exp()])
    })
}

/// `Σ_b g_b·g_bᵀ` over blocks `b` of `block_rows` consecutive residual
/// rows within each segment, `g_b = Σ_{rows in b} J_rowᵀ·r_row`.
fn block_scores(
    jac: &OMatrix<f64, Dyn, U6>,
    r: &DVector<f64>,
    segment_rows: &[usize],
    block_rows: usize,
) -> Matrix6<f64> {
    let mut s = Matrix6::zeros();
    let mut row = 0;
    for &rows in segment_rows {
        let end = row + rows;
        while row < end {
            let stop = (row + block_rows.max(1)).min(end);
            let mut g = nalgebra::Vector6::<f64>::zeros();
            for k in row..stop {
                let rk = r[k];
                for n in 0..NP {
                    g[n] += jac[(k, n)] * rk;
                }
            }
            s += g * g.transpose();
            row = stop;
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> DcParams {
        DcParams::SEED_TABLE4_MOMENTS
    }

    #[test]
    fn independent_columns_give_the_textbook_intervals() {
        // J = [C; C] with C = diag(c): JᵀJ = 2·C², residuals ±2.
        let c = [1.0, 2.0, 4.0, 0.5, 10.0, 3.0];
        let jac =
            OMatrix::<f64, Dyn, U6>::from_fn(12, |r, col| if r % 6 == col { c[col] } else { 0.0 });
        let r = DVector::from_fn(12, |k, _| if k % 2 == 0 { 2.0 } else { -2.0 });
        let extra = Matrix6::from_diagonal(&nalgebra::Vector6::from_fn(|n, _| n as f64));
        let u = uncertainty(&jac, &r, &params(), &[12], 1, &extra);
        // Classic: s² = Σr²/(m − p) = 48/6.
        let s2 = 48.0 / 6.0;
        assert!((u.residual_variance - s2).abs() < 1e-12);
        let t = t975(6);
        let values = to_array(&params());
        for n in 0..NP {
            let h = 2.0 * c[n] * c[n];
            let classic = (s2 / h).sqrt();
            assert!((u.std_ln_classic[n] - classic).abs() < 1e-12);
            // Sandwich: (S_r + S_u)/h² with S_r = Σ_k c²·r_k² = 8·c².
            let sandwich = ((8.0 * c[n] * c[n] + n as f64) / (h * h)).sqrt();
            assert!((u.std_ln[n] - sandwich).abs() < 1e-12, "{n}");
            let [lo, hi] = u.ci95[n].unwrap();
            assert!((lo - values[n] * (-t * sandwich).exp()).abs() < 1e-12 * values[n]);
            assert!((hi - values[n] * (t * sandwich).exp()).abs() < 1e-12 * values[n]);
            // Symmetric in log space: the estimate is the geometric mean.
            assert!((lo * hi - values[n] * values[n]).abs() < 1e-9 * values[n] * values[n]);
        }
        assert_eq!(u.correlation[0][0], 1.0);
        assert!(u.correlation[0][1].abs() < 1e-12);
        assert!(u
            .relative_singular_values
            .iter()
            .all(|s| (*s - 1.0).abs() < 1e-12));
        // J (c = 0.5) is poorly determined, f (c = 10) is not.
        assert!(u.flagged[3] && !u.flagged[4]);
    }

    #[test]
    fn blocks_capture_correlated_residuals() {
        // Residuals equal in pairs: blocks of 2 rows see twice the
        // variance that single rows see.
        let jac = OMatrix::<f64, Dyn, U6>::from_fn(40, |_, col| if col == 0 { 1.0 } else { 0.0 });
        let r = DVector::from_fn(40, |k, _| if (k / 2) % 2 == 0 { 1.0 } else { -1.0 });
        let single = block_scores(&jac, &r, &[40], 1);
        let pairs = block_scores(&jac, &r, &[40], 2);
        assert!((single[(0, 0)] - 40.0).abs() < 1e-12);
        assert!((pairs[(0, 0)] - 80.0).abs() < 1e-12);
        // Blocks never straddle segments: two segments of 2 rows each.
        let r = DVector::from_vec(vec![1.0, 1.0, 1.0, 1.0]);
        let jac4 = OMatrix::<f64, Dyn, U6>::from_fn(4, |_, col| if col == 0 { 1.0 } else { 0.0 });
        assert!((block_scores(&jac4, &r, &[2, 2], 4)[(0, 0)] - 8.0).abs() < 1e-12);
    }

    #[test]
    fn collinear_columns_are_named_and_get_no_interval() {
        // Columns 3 (J) and 4 (f) identical: only their sum is seen.
        let jac = OMatrix::<f64, Dyn, U6>::from_fn(60, |r, col| {
            let x = r as f64 / 60.0;
            match col {
                0 => 1.0,
                1 => x,
                2 => x * x,
                3 | 4 => (3.0 * x).sin(),
                _ => (7.0 * x).cos(),
            }
        });
        let r = DVector::from_fn(60, |k, _| ((k * 7919) % 13) as f64 / 13.0 - 0.5);
        let u = uncertainty(&jac, &r, &params(), &[r.len()], 2, &Matrix6::zeros());
        assert!(u.ci95[3].is_none() && u.ci95[4].is_none());
        assert!(u.ci95[0].is_some());
        assert!(u.relative_singular_values[5] < 1e-7);
        assert!(
            u.warnings
                .iter()
                .any(|w| w.starts_with("J, f not identifiable")),
            "{:?}",
            u.warnings
        );
    }

    #[test]
    fn strong_correlation_and_wide_intervals_are_reported() {
        // Columns 0 and 1 nearly equal: correlation ≈ −1, wide intervals.
        let jac = OMatrix::<f64, Dyn, U6>::from_fn(40, |r, col| {
            let x = r as f64 / 40.0;
            match col {
                0 => 1.0,
                1 => 1.0 + 1e-3 * (13.0 * x).sin(),
                2 => x,
                3 => x * x,
                4 => (5.0 * x).sin(),
                _ => (9.0 * x).cos(),
            }
        });
        let r = DVector::from_fn(40, |k, _| if k % 2 == 0 { 0.5 } else { -0.5 });
        let u = uncertainty(&jac, &r, &params(), &[r.len()], 2, &Matrix6::zeros());
        assert!(u.correlation[0][1] < -0.99, "{}", u.correlation[0][1]);
        assert!(u
            .warnings
            .iter()
            .any(|w| w.contains("Ra and La are hard to separate")));
        assert!(u
            .warnings
            .iter()
            .any(|w| w.starts_with("Ra is poorly determined")));
    }
}
