//! Zero-order-hold discretisation of a linear time-invariant system with
//! the matrix exponential: exact for inputs held constant over a step.

use nalgebra::{SMatrix, SVector};

/// Discrete-time form `x[k+1] = ad·x[k] + bd·u[k]` of `ẋ = A·x + B·u`.
#[derive(Debug, Clone, PartialEq)]
pub struct Zoh<const N: usize, const M: usize> {
    /// State transition over one step.
    pub ad: SMatrix<f64, N, N>,
    /// Input matrix over one step.
    pub bd: SMatrix<f64, N, M>,
    /// The step, seconds.
    pub dt: f64,
}

impl<const N: usize, const M: usize> Zoh<N, M> {
    /// Discretise `(a, b)` for step `dt` through `exp([[A, B], [0, 0]]·dt)`.
    pub fn new(a: &SMatrix<f64, N, N>, b: &SMatrix<f64, N, M>, dt: f64) -> Self {
        // The augmented matrix has size N + M; build it dynamically since
        // const generic arithmetic is not available on stable Rust.
        let n = N + M;
        let mut aug = nalgebra::DMatrix::<f64>::zeros(n, n);
        aug.view_mut((0, 0), (N, N)).copy_from(&(a * dt));
        aug.view_mut((0, N), (N, M)).copy_from(&(b * dt));
        let e = aug.exp();
        let ad = SMatrix::<f64, N, N>::from_fn(|r, c| e[(r, c)]);
        let bd = SMatrix::<f64, N, M>::from_fn(|r, c| e[(r, N + c)]);
        Zoh { ad, bd, dt }
    }

    /// Advance the state one step with the input held at `u`.
    pub fn step(&self, x: &SVector<f64, N>, u: &SVector<f64, M>) -> SVector<f64, N> {
        self.ad * x + self.bd * u
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix1, Vector1};

    #[test]
    fn first_order_lag_matches_closed_form() {
        // ẋ = -x/τ + u/τ: x(dt) = u + (x0 - u)·exp(-dt/τ).
        let tau = 0.026;
        let zoh = Zoh::<1, 1>::new(&Matrix1::new(-1.0 / tau), &Matrix1::new(1.0 / tau), 1e-3);
        let x = zoh.step(&Vector1::new(2.0), &Vector1::new(5.0));
        let expected = 5.0 + (2.0 - 5.0) * (-1e-3f64 / tau).exp();
        assert!((x[0] - expected).abs() < 1e-12, "{} vs {}", x[0], expected);
    }

    #[test]
    fn integrator_is_exact_for_ramp() {
        // ẋ1 = x2, ẋ2 = u: x1(dt) = x1 + x2·dt + u·dt²/2.
        let a = SMatrix::<f64, 2, 2>::new(0.0, 1.0, 0.0, 0.0);
        let b = SMatrix::<f64, 2, 1>::new(0.0, 1.0);
        let zoh = Zoh::new(&a, &b, 0.1);
        let x = zoh.step(
            &SVector::<f64, 2>::new(1.0, 2.0),
            &SVector::<f64, 1>::new(4.0),
        );
        assert!((x[0] - (1.0 + 0.2 + 0.02)).abs() < 1e-12);
        assert!((x[1] - 2.4).abs() < 1e-12);
    }
}
