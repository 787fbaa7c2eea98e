//! The DC models the diagnosis fits: the paper's model (Ra, La, K, J, f,
//! Tst) alone or with one augmentation from the contract's vocabulary,
//! simulated on one recorded segment from the measured voltage.
//!
//! The nominal model is simulated exactly (zero-order hold, as the
//! output-error identification does). An augmentation enters the same
//! exact discretisation as an extra voltage `ΔV` and an extra torque `ΔT`
//! evaluated on the state (predictor–corrector over each sample), so the
//! augmented model with its effect at zero IS the nominal model, sample for
//! sample: a candidate cannot win on discretisation error. Shaft compliance
//! changes the state (two masses) and has its own exact discretisation;
//! sensor lag filters the simulated reading.

use nalgebra::{SMatrix, SVector};

use crate::model::{DcMotor, DcParams, Zoh};
use crate::record::DcSegment;

/// Which channel a sensor lag delays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LagChannel {
    /// The armature-current reading.
    Current,
    /// The speed reading.
    Speed,
}

/// An augmentation of the nominal model (its parameters live in
/// [`AugModel::e`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Augment {
    /// The paper's model alone.
    Nominal,
    /// Dry friction beyond the constant static torque: a breakaway excess
    /// `Tb·exp(−|ω|/ωs)` at low speed. `e = [Tb (N·m), ωs (rad/s)]`.
    CoulombFriction,
    /// `ΔV = Vb·tanh(i/i0)`: the contact drop `Vb` reached above the knee
    /// current `i0`. `e = [Vb (V), i0 (A)]`.
    BrushDrop,
    /// `K(i) = K·(1 − κ·i²)` in the EMF and the torque. `e = [κ (1/A²)]`.
    ArmatureReaction,
    /// `La(i) = La/(1 + s·i²)`, `s = 1/Isat²`. `e = [s (1/A²)]`.
    InductanceSaturation,
    /// `Ra(t) = Ra·(1 + β·E(t))`, `E = ∫i²dt` since the record began
    /// (the winding's heat, adiabatic over a test). `e = [β (1/(A²·s))]`.
    ThermalDrift,
    /// First-order lag `τ` on one reading. `e = [τ (s)]`.
    SensorLag(LagChannel),
    /// Two masses (motor `r·J`, load `(1−r)·J`) joined by a shaft with
    /// resonance `fr` and damping ratio `ζ`; friction on the load, the
    /// encoder on the motor. `e = [fr (Hz), r, ζ]`.
    ShaftCompliance,
}

/// How a segment starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    /// At rest without current before the first sample.
    Rest,
    /// Settled at the given voltage (the level before); the first sample
    /// is that steady state.
    Settled(f64),
    /// In a measured state (current, A; speed, rad/s) at the first sample:
    /// after a level that had not settled.
    State(f64, f64),
}

/// How a segment follows the one before it in the record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Continuation {
    /// Its first sample is the previous segment's last (the boundary
    /// sample, repeated).
    Shared,
    /// Its first sample is the one after the previous segment's last.
    Next,
}

/// The model's state at the end of a simulated segment, where the next
/// segment of a continuous record starts.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EndState {
    /// Current (A), motor speed, load speed (rad/s), shaft twist (rad).
    pub(super) x: [f64; 4],
    /// The last simulated readings (current, speed).
    pub(super) reading: (f64, f64),
    /// The lagged readings of a sensor-lag model (current, speed).
    pub(super) lag: Option<(f64, f64)>,
    /// A sensor-lag model's last readings before its delay and lag
    /// (current, speed), the latest first.
    pub(super) raw: [(f64, f64); MAX_DELAY],
}

/// Longest dead time of a sensor-lag model, in samples.
pub const MAX_DELAY: usize = 2;

/// One recorded segment ready to simulate.
#[derive(Debug, Clone, Copy)]
pub struct SegmentRun<'a> {
    /// The record's segment.
    pub seg: &'a DcSegment,
    /// Sample interval, s.
    pub dt: f64,
    /// How it starts.
    pub start: Start,
    /// Armature open (coast-down): no current flows.
    pub coast: bool,
    /// `∫i²dt` of the measured current before the segment, A²·s.
    pub heat_before: f64,
    /// Whether it continues the record's previous segment without a gap.
    /// Simulated right after that segment ([`AugModel::simulate_runs`]),
    /// it starts from the model's own state at that segment's end; else
    /// (the previous segment held out or not simulated) from `start`.
    pub continues: Option<Continuation>,
}

impl SegmentRun<'_> {
    /// Samples in the segment.
    pub fn len(&self) -> usize {
        self.seg.time.len()
    }
}

/// The nominal parameters plus one augmentation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AugModel {
    /// The paper's parameters.
    pub p: DcParams,
    /// Which augmentation.
    pub aug: Augment,
    /// Its parameters (see [`Augment`]); unused entries are ignored.
    pub e: [f64; 3],
}

/// The reading path of a sensor-lag model on one run: the motor's own
/// readings delayed by whole samples, then one channel through a
/// first-order lag. The motor under it is the nominal one, so a lone
/// simulation and a lockstep one ([`super::lanes`]) both run the nominal
/// model and pass its readings through this, one sample at a time.
pub(super) struct LagFilter {
    ch: LagChannel,
    /// `e^(−dt/τ)`, 0 without a lag.
    a: f64,
    /// The dead time in whole samples (at most [`MAX_DELAY`]): a reading
    /// taken, converted or sent a sample late.
    delay: usize,
    /// A shared boundary sample is the previous segment's last reading,
    /// lagged already: the first reading is that one.
    skip: bool,
    /// The last lagged readings.
    y: Option<(f64, f64)>,
    /// The readings before the dead time, the latest first; before the
    /// record's first sample, that sample.
    raw: Option<[(f64, f64); MAX_DELAY]>,
}

impl LagFilter {
    /// The filter of the lag `e` (`[τ, dead time]`, s) on `ch` for `run`,
    /// continuing from the end of the previous run when `from` is given.
    pub(super) fn new(
        ch: LagChannel,
        e: &[f64; 3],
        run: &SegmentRun,
        from: Option<&EndState>,
    ) -> LagFilter {
        let tau = e[0].abs();
        let from = from.filter(|_| run.continues.is_some());
        LagFilter {
            ch,
            a: if tau > 0.0 {
                (-run.dt / tau).exp()
            } else {
                0.0
            },
            delay: ((e[1].abs() / run.dt).round() as usize).min(MAX_DELAY),
            skip: from.is_some() && run.continues == Some(Continuation::Shared),
            y: from.and_then(|e| e.lag),
            raw: from.filter(|e| e.lag.is_some()).map(|e| e.raw),
        }
    }

    /// Where the motor under the lag starts: the lagged model's end state
    /// without its lag.
    pub(super) fn motor_from(from: Option<&EndState>) -> Option<EndState> {
        from.map(|e| EndState { lag: None, ..*e })
    }

    /// The reading of the motor's readings `(i, w)`.
    #[inline(always)]
    pub(super) fn reading(&mut self, i: f64, w: f64) -> (f64, f64) {
        if self.skip {
            self.skip = false;
            if let Some(prev) = self.y {
                return prev;
            }
        }
        let past = self.raw.get_or_insert([(i, w); MAX_DELAY]);
        let (di, dw) = if self.delay == 0 {
            (i, w)
        } else {
            past[self.delay - 1]
        };
        past.rotate_right(1);
        past[0] = (i, w);
        let a = self.a;
        let (fi, fw) = match self.y {
            None => match self.ch {
                LagChannel::Current => (di, w),
                LagChannel::Speed => (i, dw),
            },
            Some((pi, pw)) => match self.ch {
                LagChannel::Current => (a * pi + (1.0 - a) * di, w),
                LagChannel::Speed => (i, a * pw + (1.0 - a) * dw),
            },
        };
        self.y = Some((fi, fw));
        (fi, fw)
    }

    /// The lagged model's end state, the motor's being `end`.
    pub(super) fn end(self, end: EndState) -> EndState {
        EndState {
            lag: self.y,
            raw: self.raw.unwrap_or_default(),
            reading: self.y.unwrap_or(end.reading),
            ..end
        }
    }
}

/// Exact one-sample step of the rigid driven motor, in scalars.
pub(super) struct Rigid {
    a: [[f64; 2]; 3],
    b: [[f64; 2]; 3],
    /// `e^(−dt/τe)`: the circuit's decay while the rotor is held.
    pub(super) decay: f64,
}

impl Rigid {
    pub(super) fn new(p: &DcParams, dt: f64) -> Option<Rigid> {
        let z = DcMotor::driven_zoh_of(p, dt).ok()?;
        Some(Rigid {
            a: std::array::from_fn(|r| [z.ad[(r, 0)], z.ad[(r, 1)]]),
            b: std::array::from_fn(|r| [z.bd[(r, 0)], z.bd[(r, 1)]]),
            decay: (-dt / p.tau_e()).exp(),
        })
    }

    /// `(i, ω, Δθ)` after one step from `(i, ω)` under the voltage `u`
    /// and the load torque `t`.
    #[inline]
    pub(super) fn step(&self, i: f64, w: f64, u: f64, t: f64) -> (f64, f64, f64) {
        let (a, b) = (&self.a, &self.b);
        (
            a[0][0] * i + a[0][1] * w + b[0][0] * u + b[0][1] * t,
            a[1][0] * i + a[1][1] * w + b[1][0] * u + b[1][1] * t,
            a[2][0] * i + a[2][1] * w + b[2][0] * u + b[2][1] * t,
        )
    }
}

/// Exact one-sample step of the open-armature (coast-down) rotor under a
/// constant torque `t`: `J·ω' = −f·ω − t`. Its coefficients depend on
/// the parameters and the step only, so they are computed once per
/// simulated segment, not per sample (two `exp` per sample were a quarter
/// of a diagnosis).
pub(super) struct CoastStep {
    /// `e^−x`, `x = f·dt/J`.
    a: f64,
    /// `(1 − e^−x)·J/f`.
    g: f64,
    /// `(dt − g)/f`.
    h: f64,
    /// J.
    j: f64,
}

impl CoastStep {
    pub(super) fn new(p: &DcParams, dt: f64) -> CoastStep {
        let x = p.f * dt / p.j;
        // (1 − e^−x)·J/f and (dt − that)/f, by series when x is small.
        let (g, h) = if x < 1e-6 {
            (
                dt * (1.0 - x / 2.0),
                dt * dt / (2.0 * p.j) * (1.0 - x / 3.0),
            )
        } else {
            let g = -(-x).exp_m1() * p.j / p.f;
            (g, (dt - g) / p.f)
        };
        CoastStep {
            a: (-x).exp(),
            g,
            h,
            j: p.j,
        }
    }

    /// `(ω, Δθ)` after one step from `ω` under the torque `t`.
    #[inline]
    pub(super) fn step(&self, w: f64, t: f64) -> (f64, f64) {
        let nw = self.a * w - t * self.g / self.j;
        (nw, w * self.g - t * self.h)
    }
}

/// `e^x`, with the underflow to zero below −746 taken without calling
/// `exp` (the same value: `exp` is 0 there); the breakaway term of dry
/// friction is that far below zero at every turning sample.
#[inline]
fn exp_or_zero(x: f64) -> f64 {
    if x < -746.0 {
        0.0
    } else {
        x.exp()
    }
}

/// `tanh(x)`, with its saturation at ±1 above |x| = 22 taken without
/// calling `tanh` (the same value: `tanh` rounds to ±1 there); the brush
/// drop is saturated wherever the current is well above its knee.
#[inline]
fn tanh_or_one(x: f64) -> f64 {
    if x > 22.0 {
        1.0
    } else if x < -22.0 {
        -1.0
    } else {
        x.tanh()
    }
}

impl AugModel {
    /// The nominal model.
    pub fn nominal(p: DcParams) -> AugModel {
        AugModel {
            p,
            aug: Augment::Nominal,
            e: [0.0; 3],
        }
    }

    /// `(ΔV, ΔT)` at a state; `ΔT` signed with the friction direction.
    #[inline]
    pub(super) fn perturb(&self, i: f64, w: f64, u: f64, heat: f64, dir: f64) -> (f64, f64) {
        let p = &self.p;
        match self.aug {
            Augment::CoulombFriction => (0.0, self.e[0] * exp_or_zero(-w.abs() / self.e[1]) * dir),
            Augment::BrushDrop => (self.e[0] * tanh_or_one(i / self.e[1]), 0.0),
            Augment::ArmatureReaction => {
                let d = self.e[0] * i * i;
                (-p.k * d * w, p.k * d * i)
            }
            // La·(ℓ + (1 − ℓ)/(1 + s·i²)), ℓ = e[1] the floor it falls
            // to (0: La/(1 + s·i²), the form without one).
            Augment::InductanceSaturation if self.e[1] > 0.0 => {
                let l = self.e[1];
                let g = l + (1.0 - l) / (1.0 + self.e[0] * i * i);
                ((u - p.ra * i - p.k * w) * (1.0 - 1.0 / g), 0.0)
            }
            Augment::InductanceSaturation => (-(u - p.ra * i - p.k * w) * self.e[0] * i * i, 0.0),
            Augment::ThermalDrift => (p.ra * self.e[0] * heat * i, 0.0),
            _ => (0.0, 0.0),
        }
    }

    /// Friction that must be overcome to start from rest, N·m.
    pub(super) fn breakaway(&self) -> f64 {
        match self.aug {
            Augment::CoulombFriction => self.p.tst + self.e[0].max(0.0),
            _ => self.p.tst,
        }
    }

    /// Steady state `(i, ω)` under a constant voltage with `heat` A²·s.
    pub fn steady_state(&self, u: f64, heat: f64) -> (f64, f64) {
        let p = &self.p;
        let s = p.steady_state(u);
        let (mut i, mut w) = (s.current, s.speed);
        if matches!(
            self.aug,
            Augment::Nominal
                | Augment::InductanceSaturation
                | Augment::SensorLag(_)
                | Augment::ShaftCompliance
        ) {
            return (i, w);
        }
        for _ in 0..40 {
            let g = match self.aug {
                Augment::ArmatureReaction => 1.0 - self.e[0] * i * i,
                _ => 1.0,
            };
            let ra = match self.aug {
                Augment::ThermalDrift => p.ra * (1.0 + self.e[0] * heat),
                _ => p.ra,
            };
            let vd = match self.aug {
                Augment::BrushDrop => self.e[0] * (i / self.e[1]).tanh(),
                _ => 0.0,
            };
            let t = match self.aug {
                Augment::CoulombFriction => p.tst + self.e[0] * (-w.abs() / self.e[1]).exp(),
                _ => p.tst,
            } * u.signum();
            let kg = p.k * g;
            let nw = (u - vd - ra * t / kg) / (ra * p.f / kg + kg);
            let (ni, nw) = if nw * u > 0.0 {
                ((p.f * nw + t) / kg, nw)
            } else {
                ((u - vd) / ra, 0.0)
            };
            let done = (ni - i).abs() <= 1e-12 * (1.0 + i.abs())
                && (nw - w).abs() <= 1e-12 * (1.0 + w.abs());
            (i, w) = (ni, nw);
            if done {
                break;
            }
        }
        (i, w)
    }

    /// Whether the motor is one rigid mass read without lag.
    pub(super) fn is_rigid(&self) -> bool {
        !matches!(self.aug, Augment::SensorLag(_) | Augment::ShaftCompliance)
    }

    /// Whether [`super::lanes`] steps the model in lockstep: a rigid
    /// motor, read with or without a lag (shaft compliance goes alone).
    pub(super) fn in_lockstep(&self) -> bool {
        self.aug != Augment::ShaftCompliance
    }

    /// The motor the lockstep simulation ([`super::lanes`]) steps for
    /// this model: the nominal one under a sensor lag (its readings then
    /// go through [`Self::lag_filter`]), the model itself otherwise.
    pub(super) fn motor(&self) -> AugModel {
        match self.aug {
            Augment::SensorLag(_) => AugModel::nominal(self.p),
            _ => *self,
        }
    }

    /// A sensor-lag model's reading path on `run` (continuing from `from`
    /// where given); `None` for the other models.
    pub(super) fn lag_filter(
        &self,
        run: &SegmentRun,
        from: Option<&EndState>,
    ) -> Option<LagFilter> {
        match self.aug {
            Augment::SensorLag(ch) => Some(LagFilter::new(ch, &self.e, run, from)),
            _ => None,
        }
    }

    /// Whether the model is the paper's alone (no effect to evaluate).
    #[inline]
    pub(super) fn is_nominal(&self) -> bool {
        self.aug == Augment::Nominal
    }

    /// The motor constant at the current `i`, V·s/rad.
    #[inline]
    pub(super) fn k_eff(&self, i: f64) -> f64 {
        match self.aug {
            Augment::ArmatureReaction => self.p.k * (1.0 - self.e[0] * i * i),
            _ => self.p.k,
        }
    }

    /// Whether the parameters describe a motor the simulation accepts.
    pub(super) fn valid(&self) -> bool {
        if self.p.validate().is_err() || !self.e.iter().all(|v| v.is_finite()) {
            return false;
        }
        match self.aug {
            Augment::CoulombFriction => self.e[1] > 0.0,
            Augment::ShaftCompliance => {
                self.e[0] > 0.0 && self.e[1] > 0.0 && self.e[1] < 1.0 && self.e[2] > 0.0
            }
            _ => true,
        }
    }

    /// Simulate `run`; `out(current, speed reading)` for every sample (the
    /// speed reading is the mean speed over the preceding interval, as
    /// differentiated encoder counts give it). `false` when the model
    /// refuses the parameters or the simulation diverges.
    #[cfg(test)]
    pub fn simulate(&self, run: &SegmentRun, out: &mut dyn FnMut(f64, f64)) -> bool {
        self.simulate_from(run, None, out).is_some()
    }

    /// Simulate `runs` in order, each run that continues the one before it
    /// in `runs` (the record's previous segment) from the model's state at
    /// that run's end; `out(n, current, speed reading)` for every sample of
    /// run `n`. A continuous record is thus simulated as one open-loop
    /// run from its measured voltage: the state where a segment begins is
    /// the model's, not an estimate from noisy (or coarsely quantised)
    /// readings at the end of the segment before. `false` when the model
    /// refuses the parameters or the simulation diverges.
    pub fn simulate_runs(&self, runs: &[SegmentRun], out: &mut dyn FnMut(usize, f64, f64)) -> bool {
        let mut prev: Option<(u32, EndState)> = None;
        for (n, run) in runs.iter().enumerate() {
            let from = match prev {
                Some((index, end)) if run.continues.is_some() && index + 1 == run.seg.index => {
                    Some(end)
                }
                _ => None,
            };
            match self.simulate_from(run, from.as_ref(), &mut |i, w| out(n, i, w)) {
                Some(end) => prev = Some((run.seg.index, end)),
                None => return false,
            }
        }
        true
    }

    /// [`AugModel::simulate`] from the end state of the previous segment
    /// when `from` is given (and the run continues it), returning the state
    /// at this segment's end.
    pub fn simulate_from(
        &self,
        run: &SegmentRun,
        from: Option<&EndState>,
        out: &mut dyn FnMut(f64, f64),
    ) -> Option<EndState> {
        if !self.valid() {
            return None;
        }
        let from = from.filter(|_| run.continues.is_some());
        match self.aug {
            Augment::SensorLag(ch) => {
                let mut filter = LagFilter::new(ch, &self.e, run, from);
                let end = AugModel::nominal(self.p).simulate_from(
                    run,
                    LagFilter::motor_from(from).as_ref(),
                    &mut |i, w| {
                        let (fi, fw) = filter.reading(i, w);
                        out(fi, fw)
                    },
                )?;
                Some(filter.end(end))
            }
            Augment::ShaftCompliance => self.simulate_shaft(run, from, out),
            _ => super::lanes::simulate_rigid(
                std::slice::from_ref(self),
                &[true],
                run,
                &[from.copied()],
                |_, i, w| out(i, w),
            )
            .pop()
            .flatten(),
        }
    }

    /// Two-mass model: state `[i, ωm, ωl, φ, θm]`, inputs `[U, Tst·dir]`.
    fn simulate_shaft(
        &self,
        run: &SegmentRun,
        from: Option<&EndState>,
        out: &mut dyn FnMut(f64, f64),
    ) -> Option<EndState> {
        let p = &self.p;
        let dt = run.dt;
        let inv_dt = 1.0 / dt;
        let (fr, r, zeta) = (self.e[0], self.e[1], self.e[2]);
        let (jm, jl) = (r * p.j, (1.0 - r) * p.j);
        let w0 = std::f64::consts::TAU * fr;
        let mu = jm * jl / p.j;
        let (ks, cs) = (w0 * w0 * mu, 2.0 * zeta * w0 * mu);
        #[rustfmt::skip]
        let a = SMatrix::<f64, 5, 5>::from_row_slice(&[
            -p.ra / p.la, -p.k / p.la, 0.0, 0.0, 0.0,
            p.k / jm, -cs / jm, cs / jm, -ks / jm, 0.0,
            0.0, cs / jl, -(cs + p.f) / jl, ks / jl, 0.0,
            0.0, 1.0, -1.0, 0.0, 0.0,
            0.0, 1.0, 0.0, 0.0, 0.0,
        ]);
        #[rustfmt::skip]
        let b = SMatrix::<f64, 5, 2>::from_row_slice(&[
            if run.coast { 0.0 } else { 1.0 / p.la }, 0.0,
            0.0, 0.0,
            0.0, -1.0 / jl,
            0.0, 0.0,
            0.0, 0.0,
        ]);
        let mut a = a;
        if run.coast {
            for c in 0..5 {
                a[(0, c)] = 0.0;
            }
        }
        let zoh = Zoh::new(&a, &b, dt);
        let decay = (-dt / p.tau_e()).exp();
        let u = &run.seg.voltage;
        let mut x = SVector::<f64, 5>::zeros();
        let mut last = (0.0, 0.0);
        let mut out = |i: f64, w: f64| {
            last = (i, w);
            out(i, w);
        };
        let first = match (from, run.start) {
            (Some(e), _) => {
                let i0 = if run.coast { 0.0 } else { e.x[0] };
                x = SVector::<f64, 5>::new(i0, e.x[1], e.x[2], e.x[3], 0.0);
                if run.continues == Some(Continuation::Shared) {
                    out(if run.coast { 0.0 } else { e.reading.0 }, e.reading.1);
                    1
                } else {
                    0
                }
            }
            (None, Start::Rest) => 0,
            (None, Start::Settled(u0)) => {
                let s = p.steady_state(u0);
                let twist = (p.f * s.speed + p.tst * s.speed.signum()) / ks;
                x = SVector::<f64, 5>::new(
                    if run.coast { 0.0 } else { s.current },
                    s.speed,
                    s.speed,
                    twist,
                    0.0,
                );
                out(x[0], x[1]);
                1
            }
            (None, Start::State(i0, w0)) => {
                let twist = (p.f * w0 + p.tst * w0.signum()) / ks;
                x = SVector::<f64, 5>::new(if run.coast { 0.0 } else { i0 }, w0, w0, twist, 0.0);
                out(x[0], x[1]);
                1
            }
        };
        for &uk in &u[first..] {
            let uk = if run.coast { 0.0 } else { uk };
            let at_rest = x[1] == 0.0 && x[2] == 0.0;
            let dir = if x[2] != 0.0 {
                Some(x[2].signum())
            } else if p.tst == 0.0 {
                Some(1.0)
            } else if !at_rest || (p.k * x[0]).abs() > p.tst {
                Some(if at_rest {
                    x[0].signum()
                } else {
                    x[1].signum()
                })
            } else {
                None
            };
            let th0 = x[4];
            match dir {
                None => {
                    let i_ss = uk / p.ra;
                    x[0] = if run.coast {
                        0.0
                    } else {
                        i_ss + (x[0] - i_ss) * decay
                    };
                }
                Some(d) => {
                    let load_was_moving = x[2] != 0.0;
                    x = zoh.step(&x, &SVector::<f64, 2>::new(uk, p.tst * d));
                    if x[2] * d < 0.0 && !load_was_moving {
                        // The load is still held by its friction.
                        x[2] = 0.0;
                    } else if x[2] * d < 0.0 {
                        // The load stops: the shaft relaxes with it.
                        x[1] = 0.0;
                        x[2] = 0.0;
                        x[3] = 0.0;
                    }
                }
            }
            if !x.iter().all(|v| v.is_finite()) {
                return None;
            }
            out(x[0], (x[4] - th0) * inv_dt);
        }
        Some(EndState {
            x: [x[0], x[1], x[2], x[3]],
            reading: last,
            ..EndState::default()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::dc::identify::recorded::recorded;
    use crate::model::{DcState, Terminal};

    fn staircase(p: &DcParams, dt: f64) -> DcSegment {
        // 60 V → 200 V step from the settled 60 V level, the speed read
        // as the mean over each interval.
        let (seg, mean_speed) = recorded(p, dt, p.steady_state(60.0), 1500, |k| {
            if k == 0 {
                60.0
            } else {
                200.0
            }
        });
        DcSegment {
            index: 1,
            speed: mean_speed,
            ..seg
        }
    }

    fn run(seg: &DcSegment) -> SegmentRun<'_> {
        SegmentRun {
            seg,
            dt: 5e-4,
            start: Start::Settled(60.0),
            coast: false,
            heat_before: 0.0,
            continues: None,
        }
    }

    fn sim(m: &AugModel, r: &SegmentRun) -> (Vec<f64>, Vec<f64>) {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        assert!(m.simulate(r, &mut |i, w| {
            a.push(i);
            b.push(w);
        }));
        (a, b)
    }

    /// The shortcuts give what `exp` and `tanh` give, bit for bit, so the
    /// fits are those before them.
    #[test]
    fn the_saturation_shortcuts_are_exact() {
        for x in [
            -1e6,
            -800.0,
            -746.000_001,
            -746.0,
            -745.5,
            -700.0,
            -1.0,
            0.0,
            3.0,
        ] {
            assert_eq!(exp_or_zero(x).to_bits(), x.exp().to_bits(), "exp({x})");
        }
        for x in [
            -1e9,
            -40.0,
            -22.000_001,
            -22.0,
            -19.5,
            -0.3,
            0.0,
            0.7,
            19.5,
            22.0,
            22.000_001,
            1e9,
        ] {
            assert_eq!(tanh_or_one(x).to_bits(), x.tanh().to_bits(), "tanh({x})");
        }
    }

    /// The coast-down step is the exact solution of `J·ω' = −f·ω − t`
    /// over one step: `ω(dt) = (ω0 + t/f)·e^(−f·dt/J) − t/f` and the angle
    /// its integral; the small-friction series included.
    #[test]
    fn the_coast_step_solves_the_rotor_equation() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        for (f, dt) in [(p.f, 5e-4), (1e-7, 5e-4), (0.3, 1e-3)] {
            let p = DcParams { f, ..p };
            let c = CoastStep::new(&p, dt);
            for (w, t) in [(150.0, 0.128), (-3.0, -0.2), (1e-3, 0.0)] {
                let x = f * dt / p.j;
                let want_w = (w + t / f) * (-x).exp() - t / f;
                let want_th = -(w + t / f) * p.j / f * (-x).exp_m1() - t / f * dt;
                let (got_w, got_th) = c.step(w, t);
                assert!(
                    (got_w - want_w).abs() <= 1e-9 * (1.0 + want_w.abs()),
                    "{got_w} {want_w}"
                );
                assert!(
                    (got_th - want_th).abs() <= 1e-9 * (dt + want_th.abs()),
                    "{got_th} {want_th}"
                );
            }
        }
    }

    #[test]
    fn nominal_reproduces_the_motor_and_zero_effects_are_nominal() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let seg = staircase(&p, 5e-4);
        let r = run(&seg);
        let (i0, w0) = sim(&AugModel::nominal(p), &r);
        for k in 0..seg.time.len() {
            assert!((i0[k] - seg.current[k]).abs() < 1e-9);
            assert!((w0[k] - seg.speed[k]).abs() < 1e-6, "{k}");
        }
        for aug in [
            Augment::BrushDrop,
            Augment::ArmatureReaction,
            Augment::InductanceSaturation,
            Augment::ThermalDrift,
            Augment::SensorLag(LagChannel::Current),
        ] {
            let m = AugModel {
                aug,
                ..AugModel::nominal(p)
            };
            let (i1, w1) = sim(&m, &r);
            assert!(i0.iter().zip(&i1).all(|(a, b)| (a - b).abs() < 1e-12));
            assert!(w0.iter().zip(&w1).all(|(a, b)| (a - b).abs() < 1e-9));
        }
    }

    #[test]
    fn brush_drop_matches_the_rk4_reference_model() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let dt = 5e-4;
        let motor = DcMotor::new(p, dt)
            .unwrap()
            .with_effect(Box::new(crate::model::BrushDrop {
                volts: 3.0,
                knee_amperes: 0.05,
            }));
        let seg = staircase(&p, dt);
        let m = AugModel {
            aug: Augment::BrushDrop,
            e: [3.0, 0.05, 0.0],
            p,
        };
        // Start both from the augmented steady state at 60 V.
        let (si, sw) = m.steady_state(60.0, 0.0);
        let (i1, _) = sim(&m, &run(&seg));
        let mut x = DcState {
            current: si,
            speed: sw,
            angle: 0.0,
        };
        let mut worst = 0.0f64;
        for &ik in i1.iter().skip(1) {
            x = motor.step(&x, Terminal::Driven(200.0));
            worst = worst.max((x.current - ik).abs());
        }
        assert!(worst < 2e-3, "worst current error {worst}");
    }

    #[test]
    fn stiff_shaft_approaches_the_rigid_model() {
        let p = DcParams {
            la: 0.1,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        let seg = staircase(&p, 5e-4);
        let r = run(&seg);
        let (i0, w0) = sim(&AugModel::nominal(p), &r);
        let m = AugModel {
            aug: Augment::ShaftCompliance,
            e: [400.0, 0.5, 0.7],
            ..AugModel::nominal(p)
        };
        let (i1, w1) = sim(&m, &r);
        let di = i0
            .iter()
            .zip(&i1)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let dw = w0
            .iter()
            .zip(&w1)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(di < 0.02 && dw < 0.5, "{di} {dw}");
    }

    /// A sensor lag's dead time: with no lag, the reading is the motor's
    /// one sample late (the first sample standing for the one before it);
    /// the other channel is read on time.
    #[test]
    fn a_dead_time_reads_the_channel_a_sample_late() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let seg = staircase(&p, 5e-4);
        let r = run(&seg);
        let (i0, w0) = sim(&AugModel::nominal(p), &r);
        let late = AugModel {
            aug: Augment::SensorLag(LagChannel::Current),
            e: [0.0, 5e-4, 0.0],
            ..AugModel::nominal(p)
        };
        let (i1, w1) = sim(&late, &r);
        assert_eq!(i1[0], i0[0]);
        assert_eq!(&i1[1..], &i0[..i0.len() - 1]);
        assert_eq!(w1, w0);
    }

    /// A record cut into segments (the boundary sample shared, or the next
    /// sample right after) is simulated as if it were one segment, for the
    /// rigid, the two-mass and the lagged model alike; a segment that does
    /// not continue starts from its own start.
    #[test]
    fn continued_segments_are_one_simulation() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let dt = 5e-4;
        let n = 900;
        let u = |k: usize| {
            if k < 300 {
                60.0
            } else {
                200.0 * (k as f64 * 7e-3).sin()
            }
        };
        let whole = DcSegment {
            index: 0,
            time: (0..n).map(|k| k as f64 * dt).collect(),
            voltage: (0..n).map(u).collect(),
            ..Default::default()
        };
        let cut = |from: usize, to: usize, index: u32| DcSegment {
            index,
            time: whole.time[from..to].to_vec(),
            voltage: whole.voltage[from..to].to_vec(),
            ..Default::default()
        };
        fn run(seg: &DcSegment, start: Start, continues: Option<Continuation>) -> SegmentRun<'_> {
            SegmentRun {
                seg,
                dt: 5e-4,
                start,
                coast: false,
                heat_before: 0.0,
                continues,
            }
        }
        let whole_run = run(&whole, Start::Rest, None);
        // Shared boundary at 400, then the next sample at 701.
        let segs = [cut(0, 401, 0), cut(400, 701, 1), cut(701, n, 2)];
        let parts = [
            run(&segs[0], Start::Rest, None),
            run(&segs[1], Start::State(1.0, 1.0), Some(Continuation::Shared)),
            run(&segs[2], Start::State(1.0, 1.0), Some(Continuation::Next)),
        ];
        for (aug, e) in [
            (Augment::Nominal, [40.0, 0.5, 0.1]),
            (Augment::ShaftCompliance, [40.0, 0.5, 0.1]),
            (Augment::SensorLag(LagChannel::Current), [2e-3, 0.0, 0.0]),
            // A dead time of one and of two samples before the lag.
            (Augment::SensorLag(LagChannel::Current), [2e-3, 5e-4, 0.0]),
            (Augment::SensorLag(LagChannel::Speed), [2e-3, 1e-3, 0.0]),
        ] {
            let m = AugModel {
                aug,
                e,
                ..AugModel::nominal(p)
            };
            let (wi, ww) = sim(&m, &whole_run);
            let (mut ci, mut cw): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
            let mut seen = [0usize; 3];
            assert!(m.simulate_runs(&parts, &mut |n, i, w| {
                seen[n] += 1;
                if n == 1 && seen[1] == 1 {
                    // The shared sample is the previous segment's last.
                    assert!(
                        (i - ci[400]).abs() < 1e-12 && (w - cw[400]).abs() < 1e-12,
                        "{aug:?}"
                    );
                } else {
                    ci.push(i);
                    cw.push(w);
                }
            }));
            assert_eq!(ci.len(), n);
            for k in 0..n {
                assert!((ci[k] - wi[k]).abs() < 1e-9, "{aug:?} current at {k}");
                assert!((cw[k] - ww[k]).abs() < 1e-6, "{aug:?} speed at {k}");
            }
            // Simulated alone, the second part starts from its own state.
            let (alone, _) = sim(&m, &parts[1]);
            assert!((alone[0] - 1.0).abs() < 1e-12, "{aug:?}");
        }
    }

    #[test]
    fn coast_down_stops_where_the_closed_form_says() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let seg = DcSegment {
            voltage: vec![0.0; 8000],
            time: (0..8000).map(|k| k as f64 * 1e-3).collect(),
            ..Default::default()
        };
        let r = SegmentRun {
            seg: &seg,
            dt: 1e-3,
            start: Start::Settled(248.0),
            coast: true,
            heat_before: 0.0,
            continues: None,
        };
        let (_, w) = sim(&AugModel::nominal(p), &r);
        let w0 = p.steady_state(248.0).speed;
        let t_stop = p.j / p.f * (1.0 + w0 * p.f / p.tst).ln();
        let stop = w.iter().position(|&v| v == 0.0).unwrap() as f64 * 1e-3;
        assert!((stop - t_stop).abs() < 3e-3, "{stop} vs {t_stop}");
    }
}
