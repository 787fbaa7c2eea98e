//! Winding-temperature estimate from I²t.
//!
//! A first-order thermal model of the winding: the rise above ambient, ϑ,
//! follows `τ dϑ/dt = ϑ_rated (I / I_rated)² − ϑ`, so at rated current it
//! settles at the rated rise. Over one sample period the current is taken
//! as constant and the model is stepped exactly:
//! `ϑ ← ϑ_ss + (ϑ − ϑ_ss) e^(−Δt/τ)`.

use crate::config::ThermalModel;

/// The estimated winding temperature of one motor.
#[derive(Debug, Clone, PartialEq)]
pub struct WindingTemperature {
    model: ThermalModel,
    rise: f64,
}

impl WindingTemperature {
    /// An estimate starting `initial_rise_k` above ambient.
    pub fn new(model: ThermalModel, initial_rise_k: f64) -> WindingTemperature {
        WindingTemperature {
            model,
            rise: initial_rise_k.max(0.0),
        }
    }

    /// Advance by `dt_s` seconds at a constant `current` (A).
    pub fn update(&mut self, current: f64, dt_s: f64) {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return;
        }
        let m = &self.model;
        let ratio = current / m.rated_current;
        let steady = m.rated_rise * ratio * ratio;
        self.rise = steady + (self.rise - steady) * (-dt_s / m.time_constant).exp();
    }

    /// Rise above ambient, K.
    pub fn rise_k(&self) -> f64 {
        self.rise
    }

    /// Estimated winding temperature, °C.
    pub fn celsius(&self) -> f64 {
        self.model.ambient + self.rise
    }

    /// The limit, °C.
    pub fn limit_celsius(&self) -> f64 {
        self.model.max_winding
    }

    /// True when the estimate is above the limit (or not a number).
    pub fn over_limit(&self) -> bool {
        self.celsius().is_nan() || self.celsius() > self.model.max_winding
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const M: ThermalModel = ThermalModel {
        rated_current: 2.0,
        rated_rise: 80.0,
        time_constant: 100.0,
        ambient: 40.0,
        max_winding: 130.0,
    };

    #[test]
    fn rated_current_settles_at_the_rated_rise() {
        let mut w = WindingTemperature::new(M, 0.0);
        w.update(2.0, 100.0);
        // One time constant: 1 − 1/e of the rise.
        assert!((w.rise_k() - 80.0 * (1.0 - (-1.0f64).exp())).abs() < 1e-9);
        w.update(-2.0, 10_000.0);
        assert!(
            (w.celsius() - 120.0).abs() < 1e-9,
            "sign of the current does not matter"
        );
        assert!(!w.over_limit());
        // Double the rated current: 4× the rise, over the limit in time.
        w.update(4.0, 30.0);
        assert!(w.over_limit());
        // Cooling at zero current.
        let hot = w.rise_k();
        w.update(0.0, 100.0);
        assert!((w.rise_k() - hot / std::f64::consts::E).abs() < 1e-9);
    }

    #[test]
    fn non_finite_current_is_over_limit() {
        let mut w = WindingTemperature::new(M, 0.0);
        w.update(f64::NAN, 0.001);
        assert!(w.over_limit());
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, rng_seed: proptest::test_runner::RngSeed::Fixed(6), ..ProptestConfig::default() })]
        /// Stepping is exact: n small steps at a constant current equal
        /// one big step.
        #[test]
        fn steps_compose(i in -5.0f64..5.0, rise0 in 0.0f64..100.0, n in 1usize..500, dt in 1e-4f64..1.0) {
            let mut a = WindingTemperature::new(M, rise0);
            let mut b = a.clone();
            for _ in 0..n {
                a.update(i, dt);
            }
            b.update(i, dt * n as f64);
            prop_assert!((a.rise_k() - b.rise_k()).abs() < 1e-9 * (1.0 + b.rise_k()));
        }
    }
}
