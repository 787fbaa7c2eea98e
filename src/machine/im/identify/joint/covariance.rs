//! The joint fit's intervals: the covariance of the parameters the
//! readings move, and the standard error of a quantity derived from them.

use nalgebra::{DMatrix, DVector};

use super::problem::STEP;

/// The share of the largest Jacobian column's norm below which a
/// parameter counts as not moved by the readings.
const UNMOVED: f64 = 1e-9;

/// The covariance of the fitted vector's free entries. A parameter the
/// readings do not move is held where it is and gets no interval: `Rs` at
/// its bound (where its map is flat), a core loss gone to nothing (`Rfe`
/// without limit, its column vanishing); the others' come with it held.
pub(super) struct Covariance {
    /// The free entries, in the vector's order.
    free: Vec<usize>,
    /// `σ²·(JᵀJ)⁻¹` over them.
    cov: DMatrix<f64>,
}

impl Covariance {
    /// From the Jacobian `j` at the solution, `Rs` held where `rs_held`,
    /// with residual variance `sigma2`.
    pub(super) fn of(j: &DMatrix<f64>, rs_held: bool, sigma2: f64) -> Option<Covariance> {
        let norms: Vec<f64> = j.column_iter().map(|c| c.norm()).collect();
        let top = norms.iter().copied().fold(0.0, f64::max);
        let free: Vec<usize> = (0..j.ncols())
            .filter(|&k| !(k == 0 && rs_held) && norms[k] > UNMOVED * top)
            .collect();
        let j = j.select_columns(&free);
        let cov = (j.transpose() * j).try_inverse()? * sigma2;
        Some(Covariance { free, cov })
    }

    /// Whether entry `k` is held because no reading moves it.
    pub(super) fn unmoved(&self, k: usize) -> bool {
        !self.free.contains(&k) && k != 0
    }

    /// The standard error of entry `k`; `None` when it is held.
    pub(super) fn se(&self, k: usize) -> Option<f64> {
        let a = self.free.iter().position(|&f| f == k)?;
        Some(self.cov[(a, a)].sqrt()).filter(|v| v.is_finite())
    }

    /// The standard error of `ln f(x)` (`value` = `f(x)`), by its forward-
    /// difference gradient over the free entries.
    pub(super) fn se_of(
        &self,
        x: &DVector<f64>,
        value: f64,
        f: &dyn Fn(&DVector<f64>) -> Option<f64>,
    ) -> Option<f64> {
        let mut g = DVector::zeros(self.free.len());
        for (a, &k) in self.free.iter().enumerate() {
            let h = STEP * x[k].abs().max(1.0);
            let mut xh = x.clone();
            xh[k] += h;
            g[a] = (f(&xh)?.ln() - value.ln()) / h;
        }
        Some((g.transpose() * &self.cov * &g)[(0, 0)].sqrt()).filter(|v| v.is_finite())
    }
}
