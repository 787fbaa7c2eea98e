//! The one adapter from a residual function to the
//! `levenberg_marquardt` solver, for the fits over a dynamic number of
//! parameters (the slip sweep's circuit fit, the joint standard-test fit,
//! the induction machine's diagnosis fits).
//!
//! A fit states its residuals and their Jacobian as functions of the
//! parameters ([`Residuals`]); [`AtParams`] holds the solver's current
//! parameters beside it and answers the solver. Outside the valid region
//! (no residuals, or residuals that are not finite) it answers a large
//! finite residual, so that the trial step is rejected and the trust
//! region shrinks: `None` would end the run.

use std::ops::{Deref, DerefMut};

use levenberg_marquardt::LeastSquaresProblem;
use nalgebra::storage::Owned;
use nalgebra::{DMatrix, DVector, Dyn};

/// The residual answered outside the valid region (also by the slip
/// sweep's own solver, `machine::im::identify::lm_solver`).
pub(crate) const OUTSIDE: f64 = 1e100;

/// A least-squares fit: its residuals and their Jacobian at any parameter
/// vector.
pub(crate) trait Residuals {
    /// How many residuals the fit has.
    fn rows(&self) -> usize;
    /// The residuals at `x`; `None` outside the valid region.
    fn residuals_at(&self, x: &DVector<f64>) -> Option<DVector<f64>>;
    /// Their Jacobian at `x`; `None` where it is not defined or not finite.
    fn jacobian_at(&self, x: &DVector<f64>) -> Option<DMatrix<f64>>;
}

/// A fit at the solver's current parameters: what the solver minimises,
/// and what it hands back. It dereferences to the fit.
pub(crate) struct AtParams<P> {
    /// The fit.
    pub problem: P,
    /// The current parameters.
    pub x: DVector<f64>,
}

impl<P> Deref for AtParams<P> {
    type Target = P;

    fn deref(&self) -> &P {
        &self.problem
    }
}

impl<P> DerefMut for AtParams<P> {
    fn deref_mut(&mut self) -> &mut P {
        &mut self.problem
    }
}

impl<P: Residuals> LeastSquaresProblem<f64, Dyn, Dyn> for AtParams<P> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(
            self.problem
                .residuals_at(&self.x)
                .filter(|r| r.iter().all(|v| v.is_finite()))
                .unwrap_or_else(|| DVector::from_element(self.problem.rows(), OUTSIDE)),
        )
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.problem.jacobian_at(&self.x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `r(x) = x - 3` for x ≥ 0, undefined below.
    struct Shifted;

    impl Residuals for Shifted {
        fn rows(&self) -> usize {
            1
        }

        fn residuals_at(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
            (x[0] >= 0.0).then(|| DVector::from_element(1, x[0] - 3.0))
        }

        fn jacobian_at(&self, _x: &DVector<f64>) -> Option<DMatrix<f64>> {
            Some(DMatrix::from_element(1, 1, 1.0))
        }
    }

    #[test]
    fn outside_the_valid_region_the_residual_is_large_and_finite() {
        let p = AtParams {
            problem: Shifted,
            x: DVector::from_element(1, -1.0),
        };
        assert_eq!(p.residuals(), Some(DVector::from_element(1, OUTSIDE)));
    }

    #[test]
    fn the_solver_reaches_the_minimum_through_the_adapter() {
        let p = AtParams {
            problem: Shifted,
            x: DVector::from_element(1, 10.0),
        };
        let (p, report) = levenberg_marquardt::LevenbergMarquardt::new().minimize(p);
        assert!(report.termination.was_successful());
        assert!((p.x[0] - 3.0).abs() < 1e-9, "{}", p.x[0]);
    }
}
