//! Pasek's abacus, computed from the exact step response of the armature
//! current (the seed paper's Eq. 10) instead of read off its Fig. 4.
//!
//! With time in units of τe (`x = t/τe`) and the current in units of
//! `ΔU/Ra`, Eq. 10 becomes
//!
//! ```text
//! y(s) = (μ + λ·s) / (s·(1 + (λ + μ)·s + λ·s²))
//! ```
//!
//! so the response depends on λ = τm/τe and μ = Ra·f/(K² + Ra·f) only. Its
//! poles `p1,2 = (λ+μ)(−1 ± a)/(2λ)`, `a² = 1 − 4λ/(λ+μ)²`, are real for
//! λ ≥ λ*(μ) = 2 − μ + 2√(1 − μ) (≈ 4 − 2μ); below, they are complex.
//!
//! [`CurrentStep`] evaluates `y(x) = μ + R1·e^(p1·x) + R2·e^(p2·x)` with
//! complex arithmetic (so it covers both cases), finds the peak `x1` as the
//! first zero of `y'`, and gives `δ = y(2·x1)/y(x1)`. [`invert_delta`]
//! inverts δ(λ) for λ by bisection: δ is continuous and strictly
//! increasing in λ on the real-pole range (checked in a test), so a
//! bracketing bisection converges unconditionally, to f64 resolution in
//! at most 200 halvings, without a dependency; that is all a 1-D monotone
//! inversion needs.
//!
//! [`paper_t1_over_tau_e`] and [`paper_delta`] are the paper's closed
//! forms (Eqs. 15 and 17 with the appendix's L1..L4), kept to test them
//! against the exact abacus; `docs/identification-dc.md` records where
//! they disagree.

use nalgebra::Complex;

/// The smallest λ with real poles for a given μ (0 ≤ μ < 1):
/// `(λ + μ)² = 4λ`, larger root.
pub fn real_pole_threshold(mu: f64) -> f64 {
    2.0 - mu + 2.0 * (1.0 - mu).sqrt()
}

/// The normalised current step response for one (λ, μ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentStep {
    /// λ = τm/τe.
    pub lambda: f64,
    /// μ = Ra·f/(K² + Ra·f).
    pub mu: f64,
    p1: Complex<f64>,
    p2: Complex<f64>,
    r1: Complex<f64>,
    r2: Complex<f64>,
}

impl CurrentStep {
    /// The response for `lambda > 0`, `0 ≤ mu < 1`; `None` outside that
    /// or exactly at the double pole (where the partial fractions fail;
    /// any λ a hair away works).
    pub fn new(lambda: f64, mu: f64) -> Option<CurrentStep> {
        if !(lambda > 0.0 && lambda.is_finite() && (0.0..1.0).contains(&mu)) {
            return None;
        }
        let b = lambda + mu;
        let disc = Complex::new(b * b - 4.0 * lambda, 0.0).sqrt();
        let p1 = (-b + disc) / (2.0 * lambda);
        let p2 = (-b - disc) / (2.0 * lambda);
        let gap = p1 - p2;
        if gap.norm() <= 1e-12 * p1.norm() {
            return None;
        }
        let r1 = (mu + lambda * p1) / (lambda * p1 * gap);
        let r2 = -(mu + lambda * p2) / (lambda * p2 * gap);
        Some(CurrentStep {
            lambda,
            mu,
            p1,
            p2,
            r1,
            r2,
        })
    }

    /// True when both poles are real.
    pub fn real_poles(&self) -> bool {
        self.p1.im == 0.0
    }

    /// `y(x) = Ra·Δi(x·τe)/ΔU`.
    pub fn value(&self, x: f64) -> f64 {
        (self.r1 * (self.p1 * x).exp() + self.r2 * (self.p2 * x).exp()).re + self.mu
    }

    /// `dy/dx`.
    pub fn slope(&self, x: f64) -> f64 {
        (self.r1 * self.p1 * (self.p1 * x).exp() + self.r2 * self.p2 * (self.p2 * x).exp()).re
    }

    /// The first peak `x1 = t1/τe` (first zero of `y'` after 0), `None`
    /// when the response rises monotonically.
    pub fn peak(&self) -> Option<f64> {
        // y' = 0  ⇔  e^((p1 − p2)·x) = (μ + λ·p2)/(μ + λ·p1).
        let ratio = (self.mu + self.lambda * self.p2) / (self.mu + self.lambda * self.p1);
        let gap = self.p1 - self.p2;
        let x = if self.real_poles() {
            if ratio.re.is_nan() || ratio.re <= 1.0 {
                return None;
            }
            ratio.re.ln() / gap.re
        } else {
            // Conjugate poles: |ratio| = 1, gap = 2iω; the first positive x.
            let mut theta = ratio.arg();
            if theta <= 0.0 {
                theta += std::f64::consts::TAU;
            }
            theta / gap.im
        };
        (x.is_finite() && x > 0.0).then_some(x)
    }

    /// `δ = y(2·x1)/y(x1)` (Eq. 16), `None` without a peak.
    pub fn delta(&self) -> Option<f64> {
        let x1 = self.peak()?;
        Some(self.value(2.0 * x1) / self.value(x1))
    }
}

/// Why δ could not be inverted.
#[derive(Debug, Clone, PartialEq)]
pub enum AbacusError {
    /// δ below the abacus's range: the poles are complex.
    ComplexPoles {
        /// The measured δ.
        delta: f64,
        /// The smallest δ real poles give at this μ.
        delta_min: f64,
        /// The real-pole threshold λ*.
        lambda_min: f64,
    },
    /// δ at or above the value for the largest λ tabulated: the current
    /// hump is too flat to resolve τe.
    TooLarge {
        /// The measured δ.
        delta: f64,
        /// δ at the largest λ.
        delta_max: f64,
        /// The largest λ.
        lambda_max: f64,
    },
    /// μ outside [0, 1).
    BadMu(f64),
}

impl std::fmt::Display for AbacusError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AbacusError::ComplexPoles {
                delta,
                delta_min,
                lambda_min,
            } => write!(
                f,
                "δ = {delta:.4} is below {delta_min:.4}, the smallest value real poles give \
                 (λ ≥ {lambda_min:.3}): the poles are complex"
            ),
            AbacusError::TooLarge {
                delta,
                delta_max,
                lambda_max,
            } => write!(
                f,
                "δ = {delta:.4} is at or above {delta_max:.4} (λ = {lambda_max:.0}): \
                 the current hump is too flat to resolve the electrical time constant"
            ),
            AbacusError::BadMu(mu) => write!(f, "μ = {mu} is outside [0, 1)"),
        }
    }
}

/// The largest λ the inversion searches (τm/τe beyond this leaves a
/// current hump indistinguishable from a first-order lag).
pub const LAMBDA_MAX: f64 = 1e5;

/// Invert the abacus: the λ whose exact response gives `delta` at `mu`,
/// with `x1 = t1/τe` at that λ.
pub fn invert_delta(delta: f64, mu: f64) -> Result<(f64, f64), AbacusError> {
    if !(0.0..1.0).contains(&mu) {
        return Err(AbacusError::BadMu(mu));
    }
    let lambda_min = real_pole_threshold(mu) * (1.0 + 1e-9);
    let at = |l: f64| {
        CurrentStep::new(l, mu)
            .and_then(|c| c.delta())
            .unwrap_or(f64::NAN)
    };
    let (d_lo, d_hi) = (at(lambda_min), at(LAMBDA_MAX));
    if delta.is_nan() || d_lo.is_nan() || delta < d_lo {
        return Err(AbacusError::ComplexPoles {
            delta,
            delta_min: d_lo,
            lambda_min,
        });
    }
    if d_hi.is_nan() || delta >= d_hi {
        return Err(AbacusError::TooLarge {
            delta,
            delta_max: d_hi,
            lambda_max: LAMBDA_MAX,
        });
    }
    // Bisect in ln λ (the abacus spans decades).
    let (mut lo, mut hi) = (lambda_min.ln(), LAMBDA_MAX.ln());
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if at(mid.exp()) < delta {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let lambda = (0.5 * (lo + hi)).exp();
    let x1 = CurrentStep::new(lambda, mu)
        .and_then(|c| c.peak())
        .expect("a real-pole response inside the abacus has a peak");
    Ok((lambda, x1))
}

/// The paper's ratio `(1 + a − 2μ)/(1 − a + 2μ)` with
/// `a = √(1 − 4λ/(λ+μ)²)`; `None` for complex poles.
fn paper_ratio(lambda: f64, mu: f64) -> Option<(f64, f64)> {
    let a2 = 1.0 - 4.0 * lambda / (lambda + mu).powi(2);
    (a2 > 0.0).then(|| {
        let a = a2.sqrt();
        (a, (1.0 + a - 2.0 * mu) / (1.0 - a + 2.0 * mu))
    })
}

/// The paper's Eq. 15, as printed: `t1/τe = λ/((λ+μ)·a)·ln((1+a−2μ)/(1−a+2μ))`.
pub fn paper_t1_over_tau_e(lambda: f64, mu: f64) -> Option<f64> {
    let (a, r) = paper_ratio(lambda, mu)?;
    Some(lambda / ((lambda + mu) * a) * r.ln())
}

/// The paper's Eq. 17 with the appendix's L1..L4, as printed (per unit
/// ΔU/Ra, which cancels).
pub fn paper_delta(lambda: f64, mu: f64) -> Option<f64> {
    let (a, r) = paper_ratio(lambda, mu)?;
    let l1 = r.powf(-1.0 / a) * (r - 1.0 / r);
    let l2 = 1.0 / (2.0 * a) * r.powf(1.0 / a) * ((1.0 - a) / r - (1.0 + a) * r);
    let l3 = r.powf(-1.0 / (2.0 * a)) * (r.sqrt() - 1.0 / r.sqrt());
    let l4 =
        1.0 / (2.0 * a) * r.powf(-1.0 / (2.0 * a)) * ((1.0 - a) / r.sqrt() - (1.0 + a) * r.sqrt());
    let c = lambda / (a * (lambda + mu));
    // f·ΔU/(K² + Ra·f) = μ·ΔU/Ra.
    Some((c * l1 + mu * (1.0 + l2)) / (c * l3 + mu * (1.0 + l4)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{DcMotor, DcParams, Terminal};

    /// The seed paper's μ (its Table 4: Ra 30.9, K 1.323, f 0.0005).
    const MU: f64 = 30.9 * 0.0005 / (1.323 * 1.323 + 30.9 * 0.0005);

    /// The peak of `y` found by brute force: dense grid, then golden section.
    fn numeric_peak(c: &CurrentStep) -> f64 {
        let grid = (1..200_000).map(|k| k as f64 * 1e-4);
        let first_fall = grid
            .clone()
            .find(|&x| c.value(x + 1e-4) < c.value(x))
            .unwrap();
        let (mut lo, mut hi) = (first_fall - 1e-4, first_fall + 1e-4);
        let g = (5f64.sqrt() - 1.0) / 2.0;
        for _ in 0..100 {
            let (m1, m2) = (hi - g * (hi - lo), lo + g * (hi - lo));
            if c.value(m1) < c.value(m2) {
                lo = m1;
            } else {
                hi = m2;
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn response_starts_at_zero_and_matches_the_simulated_motor() {
        // A motor with real poles (λ ≈ 43): simulate a 100 V step from rest
        // (no static torque) and compare with ΔU/Ra·y(t/τe).
        let p = DcParams {
            la: 0.0387,
            tst: 0.0,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        let mu = p.ra * p.f / (p.k * p.k + p.ra * p.f);
        let c = CurrentStep::new(p.tau_m() / p.tau_e(), mu).unwrap();
        assert!(c.real_poles());
        assert!(c.value(0.0).abs() < 1e-12);
        assert!((c.slope(0.0) - 1.0).abs() < 1e-9, "di/dt(0) = ΔU/La");
        let dt = 1e-4;
        let motor = DcMotor::new(p, dt).unwrap();
        let mut x = Default::default();
        for k in 1..3000 {
            x = motor.step(&x, Terminal::Driven(100.0));
            let expect = 100.0 / p.ra * c.value(k as f64 * dt / p.tau_e());
            assert!((x.current - expect).abs() < 1e-9, "step {k}");
        }
        // And with complex poles (the seed motor, λ ≈ 2.1).
        let p = DcParams {
            tst: 0.0,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        let c = CurrentStep::new(p.tau_m() / p.tau_e(), mu).unwrap();
        assert!(!c.real_poles());
        let motor = DcMotor::new(p, 5e-4).unwrap();
        let mut x = Default::default();
        for k in 1..2000 {
            x = motor.step(&x, Terminal::Driven(188.0));
            let expect = 188.0 / p.ra * c.value(k as f64 * 5e-4 / p.tau_e());
            assert!((x.current - expect).abs() < 1e-9, "step {k}");
        }
    }

    #[test]
    fn peak_is_the_numeric_maximum_real_and_complex() {
        for &(lambda, mu) in &[(4.5, MU), (8.0, 0.0), (30.0, 0.05), (2.1, MU), (3.9, 0.0)] {
            let c = CurrentStep::new(lambda, mu).unwrap();
            let x1 = c.peak().unwrap();
            let numeric = numeric_peak(&c);
            assert!((x1 - numeric).abs() < 1e-6, "λ {lambda}: {x1} vs {numeric}");
            assert!(c.slope(x1).abs() < 1e-9);
        }
        // Critically damped, μ = 0: y = x·e^(−x/2)/… peaks at x = 2, δ = 2/e.
        let c = CurrentStep::new(4.0 * (1.0 + 1e-7), 0.0).unwrap();
        assert!((c.peak().unwrap() - 2.0).abs() < 1e-3);
        assert!((c.delta().unwrap() - 2.0 / std::f64::consts::E).abs() < 1e-4);
    }

    #[test]
    fn threshold_solves_a_squared_equals_zero() {
        for mu in [0.0, 0.00874, 0.1, 0.5] {
            let l = real_pole_threshold(mu);
            assert!((1.0 - 4.0 * l / (l + mu).powi(2)).abs() < 1e-12, "μ {mu}");
            assert!(CurrentStep::new(l * 1.001, mu).unwrap().real_poles());
            assert!(!CurrentStep::new(l * 0.999, mu).unwrap().real_poles());
        }
    }

    #[test]
    fn delta_rises_strictly_with_lambda_and_complex_poles_fall_below_the_range() {
        for mu in [0.0, 0.00874, 0.05, 0.2] {
            let l0 = real_pole_threshold(mu);
            let d_min = CurrentStep::new(l0 * (1.0 + 1e-9), mu)
                .unwrap()
                .delta()
                .unwrap();
            let mut last = d_min;
            for k in 1..=400 {
                let l = l0 * (LAMBDA_MAX / l0).powf(k as f64 / 400.0);
                let d = CurrentStep::new(l, mu).unwrap().delta().unwrap();
                assert!(d > last, "μ {mu}: δ({l}) = {d} ≤ {last}");
                last = d;
            }
            // Below the threshold (complex poles) δ is smaller still, so a
            // measured δ under the range says "complex poles".
            for k in 1..40 {
                let l = l0 * (1.0 - k as f64 / 50.0);
                let d = CurrentStep::new(l, mu).unwrap().delta().unwrap();
                assert!(d < d_min, "μ {mu}: complex λ {l} gives δ {d} ≥ {d_min}");
            }
        }
    }

    #[test]
    fn inversion_round_trips() {
        for mu in [0.0, MU, 0.1] {
            for lambda in [4.2, 4.5, 6.0, 20.0, 300.0, 5e4] {
                let c = CurrentStep::new(lambda, mu).unwrap();
                let (l, x1) = invert_delta(c.delta().unwrap(), mu).unwrap();
                assert!(((l - lambda) / lambda).abs() < 1e-7, "{l} vs {lambda}");
                assert!((x1 - c.peak().unwrap()).abs() < 1e-7);
            }
        }
        assert!(matches!(
            invert_delta(0.70, MU),
            Err(AbacusError::ComplexPoles { .. })
        ));
        assert!(matches!(
            invert_delta(0.99999, MU),
            Err(AbacusError::TooLarge { .. })
        ));
        assert!(invert_delta(0.8, 1.2).is_err());
    }
}
