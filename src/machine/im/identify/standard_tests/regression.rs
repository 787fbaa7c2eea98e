//! The linear regressions of the classical reduction, with 95 % intervals
//! (Student-t on the residual variance): a slope through the origin (DC
//! resistance, locked-rotor `R_lr`, `X_lr`), a straight line (friction and
//! windage against V²), a polynomial (the `Xm(V)` curve). nalgebra does
//! the algebra; a fit without a spare degree of freedom has no interval.

use nalgebra::{DMatrix, DVector};

use crate::identify::stats::t975;

/// A least-squares fit `y ≈ A·β` and what its intervals need.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Fit {
    /// The coefficients.
    pub beta: DVector<f64>,
    /// Covariance of the coefficients (residual variance × (AᵀA)⁻¹);
    /// `None` without a spare degree of freedom.
    pub cov: Option<DMatrix<f64>>,
    /// Degrees of freedom, rows − columns.
    pub dof: usize,
    /// RMS residual.
    pub rms: f64,
}

impl Fit {
    /// Half-width of the 95 % interval of coefficient `k`.
    pub fn half_width(&self, k: usize) -> Option<f64> {
        let c = self.cov.as_ref()?;
        Some(t975(self.dof) * c[(k, k)].max(0.0).sqrt()).filter(|h| h.is_finite())
    }

    /// `row·β` and the half-width of its 95 % interval (a fitted mean).
    pub fn predict(&self, row: &[f64]) -> (f64, Option<f64>) {
        let x = DVector::from_column_slice(row);
        let value = x.dot(&self.beta);
        let hw = self.cov.as_ref().map(|c| {
            let var = (x.transpose() * c * &x)[(0, 0)];
            t975(self.dof) * var.max(0.0).sqrt()
        });
        (value, hw.filter(|h| h.is_finite()))
    }
}

/// Solve `y ≈ A·β` (the columns of `a` the regressors); `None` when the
/// system is rank-deficient, short of rows or not finite.
pub(super) fn fit(a: DMatrix<f64>, y: &[f64]) -> Option<Fit> {
    let (rows, cols) = a.shape();
    let y = DVector::from_column_slice(y);
    if rows < cols || rows != y.len() || !a.iter().chain(y.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let ata = a.transpose() * &a;
    let inv = ata.try_inverse()?;
    let beta = &inv * a.transpose() * &y;
    let r = &a * &beta - &y;
    let dof = rows - cols;
    let rms = (r.norm_squared() / rows as f64).sqrt();
    let cov = (dof > 0).then(|| inv * (r.norm_squared() / dof as f64));
    beta.iter().all(|b| b.is_finite()).then_some(Fit {
        beta,
        cov,
        dof,
        rms,
    })
}

/// `y ≈ b·x`: the slope and the half-width of its 95 % interval.
pub(super) fn through_origin(x: &[f64], y: &[f64]) -> Option<(f64, Option<f64>)> {
    let f = fit(DMatrix::from_column_slice(x.len(), 1, x), y)?;
    Some((f.beta[0], f.half_width(0)))
}

/// `y ≈ a + b·x`.
pub(super) fn line(x: &[f64], y: &[f64]) -> Option<Fit> {
    polynomial(x, y, 1)
}

/// `y ≈ Σ β_k·x^k`, k = 0…`degree`.
pub(super) fn polynomial(x: &[f64], y: &[f64], degree: usize) -> Option<Fit> {
    fit(
        DMatrix::from_fn(x.len(), degree + 1, |r, c| x[r].powi(c as i32)),
        y,
    )
}

/// The powers `1, x, …, x^degree` (a row for [`Fit::predict`]).
pub(super) fn powers(x: f64, degree: usize) -> Vec<f64> {
    (0..=degree).map(|k| x.powi(k as i32)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_with_scatter_covers_its_truth_and_an_exact_one_has_no_interval() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(k, x)| 2.0 + 0.5 * x + if k % 2 == 0 { 0.01 } else { -0.01 })
            .collect();
        let f = line(&x, &y).unwrap();
        let hw = f.half_width(0).unwrap();
        assert!((f.beta[0] - 2.0).abs() < hw && hw < 0.1, "{f:?}");
        let (v, hw) = f.predict(&powers(0.0, 1));
        assert!((v - f.beta[0]).abs() < 1e-12 && hw.unwrap() > 0.0);
        let (b, hw) = through_origin(&[2.0], &[4.0]).unwrap();
        assert_eq!((b, hw), (2.0, None));
        assert!(line(&[1.0, 1.0], &[1.0, 2.0]).is_none());
    }
}
