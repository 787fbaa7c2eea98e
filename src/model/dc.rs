//! The separately excited DC motor of the seed paper (Eqs. 1–2):
//!
//! ```text
//! La·di/dt = U − Ra·i − K·ω
//! J·dω/dt  = K·i − f·ω − Tst·sign(ω)
//! ```
//!
//! with the static torque `Tst` acting as a friction that also holds the
//! rotor at rest while `|K·i| ≤ Tst`. The linear part is simulated exactly
//! by a zero-order hold (matrix exponential) over the state `[i, ω, θ]`
//! with inputs `[U, Tst·sign(ω)]`; a sign change of ω inside a step stops
//! the rotor at the end of that step (an error of at most one step in the
//! stopping instant). With effects attached ([`DcEffect`]) the model
//! integrates with fixed-step RK4 instead.

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::{DcEffect, Zoh};

/// Parameters of the DC motor, SI units, named as in the data contract.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DcParams {
    /// Armature resistance, Ω.
    #[serde(rename = "Ra")]
    pub ra: f64,
    /// Armature inductance, H.
    #[serde(rename = "La")]
    pub la: f64,
    /// Torque and back-EMF constant, V·s/rad = N·m/A.
    #[serde(rename = "K")]
    pub k: f64,
    /// Rotor (and load) inertia, kg·m².
    #[serde(rename = "J")]
    pub j: f64,
    /// Viscous friction, N·m·s/rad.
    #[serde(rename = "f")]
    pub f: f64,
    /// Static torque (constant friction and load), N·m.
    #[serde(rename = "Tst", default)]
    pub tst: f64,
}

/// A parameter set that cannot describe a motor.
#[derive(Debug, Error, PartialEq)]
#[error("motor parameter {name} = {value} is invalid: {reason}")]
pub struct ParamError {
    /// Contract name of the parameter.
    pub name: &'static str,
    /// The value given.
    pub value: f64,
    /// Why it is refused.
    pub reason: &'static str,
}

impl DcParams {
    /// The seed paper's Table 4, moments-method column.
    pub const SEED_TABLE4_MOMENTS: DcParams = DcParams {
        ra: 30.9,
        la: 0.803,
        k: 1.323,
        j: 0.0031,
        f: 0.0005,
        tst: 0.128,
    };

    /// Check every parameter is finite and physical.
    pub fn validate(&self) -> Result<(), ParamError> {
        let strictly_positive = [
            ("Ra", self.ra),
            ("La", self.la),
            ("K", self.k),
            ("J", self.j),
        ];
        for (name, value) in strictly_positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(ParamError {
                    name,
                    value,
                    reason: "must be a finite number > 0",
                });
            }
        }
        for (name, value) in [("f", self.f), ("Tst", self.tst)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ParamError {
                    name,
                    value,
                    reason: "must be a finite number ≥ 0",
                });
            }
        }
        Ok(())
    }

    /// Electrical time constant τe = La/Ra, s.
    pub fn tau_e(&self) -> f64 {
        self.la / self.ra
    }

    /// Mechanical time constant τm = Ra·J/(K² + Ra·f), s (Eq. 10).
    pub fn tau_m(&self) -> f64 {
        self.ra * self.j / (self.k * self.k + self.ra * self.f)
    }

    /// Steady state under a constant voltage `u` (turning forward when the
    /// torque overcomes `Tst`, at rest otherwise).
    pub fn steady_state(&self, u: f64) -> DcState {
        let d = self.k * self.k + self.ra * self.f;
        let current = (self.f * u + self.k * self.tst * u.signum()) / d;
        let speed = (u - self.ra * current) / self.k;
        if speed * u > 0.0 {
            DcState {
                current,
                speed,
                angle: 0.0,
            }
        } else {
            DcState {
                current: u / self.ra,
                speed: 0.0,
                angle: 0.0,
            }
        }
    }
}

/// State of the motor.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DcState {
    /// Armature current, A.
    pub current: f64,
    /// Shaft speed, rad/s.
    pub speed: f64,
    /// Shaft angle, rad (unwrapped).
    pub angle: f64,
}

/// What the armature terminals are connected to during a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Terminal {
    /// Driven by a voltage source, V.
    Driven(f64),
    /// Open circuit: no current flows; the terminal voltage is the back-EMF.
    Open,
}

/// A DC motor ready to simulate with a fixed step.
#[derive(Debug)]
pub struct DcMotor {
    params: DcParams,
    dt: f64,
    driven: Zoh<3, 2>,
    open: Zoh<2, 1>,
    effects: Vec<Box<dyn DcEffect>>,
    substeps: usize,
}

impl DcMotor {
    /// Prepare the motor for steps of `dt` seconds.
    pub fn new(params: DcParams, dt: f64) -> Result<DcMotor, ParamError> {
        let driven = DcMotor::driven_zoh_of(&params, dt)?;
        let p = &params;
        let a_open = SMatrix::<f64, 2, 2>::new(-p.f / p.j, 0.0, 1.0, 0.0);
        let b_open = SMatrix::<f64, 2, 1>::new(-1.0 / p.j, 0.0);
        // RK4 sub-steps: at least 40 per fastest time constant.
        let fastest = p.tau_e().min(p.tau_m());
        let substeps = ((dt * 40.0 / fastest).ceil() as usize).clamp(1, 10_000);
        Ok(DcMotor {
            params,
            dt,
            driven,
            open: Zoh::new(&a_open, &b_open, dt),
            effects: Vec::new(),
            substeps,
        })
    }

    /// The exact step of the driven motor (state `[i, ω, θ]`, inputs
    /// `[U, T_load]`) over `dt` seconds, alone: what
    /// [`DcMotor::driven_zoh`] gives without the rest of a motor (a
    /// simulation that steps many parameter sets needs only this).
    pub fn driven_zoh_of(params: &DcParams, dt: f64) -> Result<Zoh<3, 2>, ParamError> {
        params.validate()?;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ParamError {
                name: "dt",
                value: dt,
                reason: "must be a finite number > 0",
            });
        }
        let p = params;
        let a = SMatrix::<f64, 3, 3>::new(
            -p.ra / p.la,
            -p.k / p.la,
            0.0, //
            p.k / p.j,
            -p.f / p.j,
            0.0, //
            0.0,
            1.0,
            0.0,
        );
        let b = SMatrix::<f64, 3, 2>::new(1.0 / p.la, 0.0, 0.0, -1.0 / p.j, 0.0, 0.0);
        Ok(Zoh::new(&a, &b, dt))
    }

    /// Attach an unmodelled effect; the motor then integrates with RK4.
    pub fn with_effect(mut self, effect: Box<dyn DcEffect>) -> DcMotor {
        self.effects.push(effect);
        self
    }

    /// The nominal parameters.
    pub fn params(&self) -> &DcParams {
        &self.params
    }

    /// The step, seconds.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The exact discretisation of the driven motor: state `[i, ω, θ]`,
    /// inputs `[U, Tst·dir]`, for loops that simulate many samples and
    /// cannot afford [`DcMotor::step`]'s generality.
    pub fn driven_zoh(&self) -> &Zoh<3, 2> {
        &self.driven
    }

    /// Advance one step of `dt` with the terminal held as given.
    pub fn step(&self, x: &DcState, terminal: Terminal) -> DcState {
        if self.effects.is_empty() {
            self.step_exact(x, terminal)
        } else {
            let h = self.dt / self.substeps as f64;
            let mut s = *x;
            for _ in 0..self.substeps {
                s = self.rk4(&s, terminal, h);
            }
            s
        }
    }

    /// Direction the friction opposes: the motion, or at rest the torque
    /// that would start it. `None` while stuck at rest.
    fn direction(speed: f64, drive_torque: f64, friction: f64) -> Option<f64> {
        if speed != 0.0 {
            Some(speed.signum())
        } else if friction == 0.0 {
            // Nothing to overcome: the sign of a zero torque is immaterial.
            Some(1.0)
        } else if drive_torque.abs() > friction {
            Some(drive_torque.signum())
        } else {
            None
        }
    }

    fn step_exact(&self, x: &DcState, terminal: Terminal) -> DcState {
        let p = &self.params;
        match terminal {
            Terminal::Driven(u) => match Self::direction(x.speed, p.k * x.current, p.tst) {
                None => {
                    // Rotor held by static torque: only the electrical circuit moves.
                    let i_ss = u / p.ra;
                    let decay = (-self.dt / p.tau_e()).exp();
                    DcState {
                        current: i_ss + (x.current - i_ss) * decay,
                        ..*x
                    }
                }
                Some(dir) => {
                    let s = SVector::<f64, 3>::new(x.current, x.speed, x.angle);
                    let n = self
                        .driven
                        .step(&s, &SVector::<f64, 2>::new(u, p.tst * dir));
                    let speed = if n[1] * dir < 0.0 { 0.0 } else { n[1] };
                    DcState {
                        current: n[0],
                        speed,
                        angle: n[2],
                    }
                }
            },
            Terminal::Open => match Self::direction(x.speed, 0.0, p.tst) {
                None => DcState { current: 0.0, ..*x },
                Some(dir) => {
                    let s = SVector::<f64, 2>::new(x.speed, x.angle);
                    let n = self.open.step(&s, &SVector::<f64, 1>::new(p.tst * dir));
                    let speed = if n[0] * dir < 0.0 { 0.0 } else { n[0] };
                    DcState {
                        current: 0.0,
                        speed,
                        angle: n[1],
                    }
                }
            },
        }
    }

    /// Time derivative `(di/dt, dω/dt, dθ/dt)` with effects, given the
    /// friction direction fixed for the step.
    fn derivative(&self, x: &DcState, terminal: Terminal, dir: Option<f64>) -> [f64; 3] {
        let p = &self.params;
        let (mut g_k, mut g_l, mut g_r, mut v_drop, mut t_fric) = (1.0, 1.0, 1.0, 0.0, p.tst);
        for e in &self.effects {
            g_k *= e.flux_factor(x);
            g_l *= e.inductance_factor(x);
            g_r *= e.resistance_factor(x);
            v_drop += e.voltage_drop(x);
            t_fric += e.friction_torque(x);
        }
        let di = match terminal {
            Terminal::Driven(u) => {
                (u - p.ra * g_r * x.current - p.k * g_k * x.speed - v_drop) / (p.la * g_l)
            }
            Terminal::Open => 0.0,
        };
        let dw = match dir {
            Some(d) => (p.k * g_k * x.current - p.f * x.speed - t_fric * d) / p.j,
            None => 0.0,
        };
        [di, dw, x.speed]
    }

    fn rk4(&self, x: &DcState, terminal: Terminal, h: f64) -> DcState {
        let x = if terminal == Terminal::Open {
            DcState { current: 0.0, ..*x }
        } else {
            *x
        };
        let friction = self.params.tst
            + self
                .effects
                .iter()
                .map(|e| e.friction_torque(&x))
                .sum::<f64>();
        let g_k: f64 = self.effects.iter().map(|e| e.flux_factor(&x)).product();
        let dir = Self::direction(x.speed, self.params.k * g_k * x.current, friction);
        let add = |s: &DcState, k: &[f64; 3], c: f64| DcState {
            current: s.current + c * k[0],
            speed: s.speed + c * k[1],
            angle: s.angle + c * k[2],
        };
        let k1 = self.derivative(&x, terminal, dir);
        let k2 = self.derivative(&add(&x, &k1, h / 2.0), terminal, dir);
        let k3 = self.derivative(&add(&x, &k2, h / 2.0), terminal, dir);
        let k4 = self.derivative(&add(&x, &k3, h), terminal, dir);
        let mut n = x;
        for (idx, v) in [&mut n.current, &mut n.speed, &mut n.angle]
            .into_iter()
            .enumerate()
        {
            *v += h / 6.0 * (k1[idx] + 2.0 * k2[idx] + 2.0 * k3[idx] + k4[idx]);
        }
        if let Some(d) = dir {
            if n.speed * d < 0.0 {
                n.speed = 0.0;
            }
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{BrushDrop, CoulombFriction};
    use nalgebra::Complex;

    /// Eq. 13 (current) and the matching speed response for a voltage step
    /// `du` from rest with no static torque, evaluated with complex time
    /// constants so it covers real and complex poles alike.
    fn analytic_step(p: &DcParams, du: f64, t: f64) -> (f64, f64) {
        let (te, tm) = (p.tau_e(), p.tau_m());
        let mu = p.ra * p.f / (p.k * p.k + p.ra * p.f);
        // Poles of 1 + (τm + μτe)s + τmτe s²; T = −1/p.
        let (a2, a1) = (tm * te, tm + mu * te);
        let disc = Complex::new(a1 * a1 - 4.0 * a2, 0.0).sqrt();
        let p1 = (-a1 + disc) / (2.0 * a2);
        let p2 = (-a1 - disc) / (2.0 * a2);
        let (t1, t2) = (-1.0 / p1, -1.0 / p2);
        let e1 = (-t / t1).exp();
        let e2 = (-t / t2).exp();
        let d = p.k * p.k + p.ra * p.f;
        let i = du * p.j / d
            * ((e2 - e1) / (t2 - t1) + p.f / p.j * (1.0 + (t1 * e1 - t2 * e2) / (t2 - t1)));
        let w = p.k * du / d * (1.0 + (t1 * e1 - t2 * e2) / (t2 - t1));
        (i.re, w.re)
    }

    /// Simulate `steps` steps of `dt` after a voltage step `du` and assert
    /// the current and speed stay on the analytic step response.
    fn assert_matches_analytic_step(p: DcParams, du: f64, dt: f64, steps: usize) {
        let motor = DcMotor::new(p, dt).unwrap();
        let mut x = DcState::default();
        let (mut ei, mut ew) = (0.0f64, 0.0f64);
        for k in 1..=steps {
            x = motor.step(&x, Terminal::Driven(du));
            let (i, w) = analytic_step(&p, du, k as f64 * dt);
            ei = ei.max((x.current - i).abs());
            ew = ew.max((x.speed - w).abs());
        }
        assert!(
            ei < 1e-9 && ew < 1e-7,
            "current error {ei}, speed error {ew}"
        );
    }

    #[test]
    fn exact_simulation_matches_analytic_step_with_complex_poles() {
        // The seed motor without static torque: λ ≈ 2.1, complex poles.
        let p = DcParams {
            tst: 0.0,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        assert_matches_analytic_step(p, 188.0, 5e-4, 2000);
    }

    #[test]
    fn exact_simulation_matches_analytic_step_with_real_poles() {
        // Small inductance: λ ≈ 43, real poles.
        let p = DcParams {
            la: 0.0387,
            tst: 0.0,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        assert!(p.tau_m() / p.tau_e() > 4.0);
        assert_matches_analytic_step(p, 100.0, 1e-4, 5000);
    }

    /// The state of `p` after `steps` steps of `dt` at the voltage `u`,
    /// from rest.
    fn driven_from_rest(p: DcParams, dt: f64, u: f64, steps: usize) -> DcState {
        let motor = DcMotor::new(p, dt).unwrap();
        let mut x = DcState::default();
        for _ in 0..steps {
            x = motor.step(&x, Terminal::Driven(u));
        }
        x
    }

    #[test]
    fn settles_at_the_steady_state_with_static_torque() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let x = driven_from_rest(p, 5e-4, 60.0, 8000);
        let ss = p.steady_state(60.0);
        // The seed's Table 2, initial mode: 0.113 A, 400 r/min (≈ 41.9 rad/s).
        assert!((x.current - ss.current).abs() < 1e-9 && (ss.current - 0.113).abs() < 5e-4);
        assert!(
            (x.speed - ss.speed).abs() < 1e-7
                && (ss.speed * 60.0 / std::f64::consts::TAU - 400.0).abs() < 10.0
        );
    }

    #[test]
    fn static_torque_holds_the_rotor_below_breakaway() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        // K·i = K·U/Ra < Tst for U < 2.99 V.
        let x = driven_from_rest(p, 1e-3, 2.0, 2000);
        assert_eq!(x.speed, 0.0);
        assert!((x.current - 2.0 / p.ra).abs() < 1e-9);
    }

    #[test]
    fn open_circuit_coasts_to_rest() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let motor = DcMotor::new(p, 1e-3).unwrap();
        let mut x = p.steady_state(248.0);
        let mut stopped_at = None;
        for k in 0..20_000 {
            x = motor.step(&x, Terminal::Open);
            assert_eq!(x.current, 0.0);
            if x.speed == 0.0 && stopped_at.is_none() {
                stopped_at = Some(k as f64 * 1e-3);
            }
        }
        // ω(t) = (ω0 + Tst/f)e^(−t f/J) − Tst/f reaches 0 at t = (J/f)·ln(1 + ω0·f/Tst).
        let w0 = p.steady_state(248.0).speed;
        let t_stop = p.j / p.f * (1.0 + w0 * p.f / p.tst).ln();
        let got = stopped_at.expect("rotor stops");
        assert!((got - t_stop).abs() < 2e-3, "{got} vs {t_stop}");
    }

    #[test]
    fn rk4_with_null_effects_matches_exact() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let exact = DcMotor::new(p, 5e-4).unwrap();
        let rk = DcMotor::new(p, 5e-4)
            .unwrap()
            .with_effect(Box::new(CoulombFriction { torque: 0.0 }))
            .with_effect(Box::new(BrushDrop {
                volts: 0.0,
                knee_amperes: 0.01,
            }));
        let (mut a, mut b) = (p.steady_state(60.0), p.steady_state(60.0));
        for _ in 0..2000 {
            a = exact.step(&a, Terminal::Driven(248.0));
            b = rk.step(&b, Terminal::Driven(248.0));
            assert!((a.current - b.current).abs() < 1e-7, "{a:?} {b:?}");
            assert!((a.speed - b.speed).abs() < 1e-5, "{a:?} {b:?}");
        }
    }

    #[test]
    fn brush_drop_lowers_the_steady_speed_by_drop_over_k() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let rk = DcMotor::new(p, 1e-3)
            .unwrap()
            .with_effect(Box::new(BrushDrop {
                volts: 2.0,
                knee_amperes: 1e-3,
            }));
        let mut x = p.steady_state(150.0);
        for _ in 0..5000 {
            x = rk.step(&x, Terminal::Driven(150.0));
        }
        let expected = p.steady_state(148.0);
        assert!(
            (x.speed - expected.speed).abs() < 1e-3,
            "{} vs {}",
            x.speed,
            expected.speed
        );
    }

    #[test]
    fn invalid_parameters_are_refused_by_name() {
        let p = DcParams {
            la: -1.0,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        let err = DcMotor::new(p, 1e-3).unwrap_err();
        assert_eq!(err.name, "La");
        assert!(err.to_string().contains("La = -1"));
    }
}
