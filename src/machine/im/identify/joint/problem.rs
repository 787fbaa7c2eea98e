//! The joint fit's residuals: the readings, the circuit the parameter
//! vector holds, and the model of each reading on it (the T circuit's
//! linear branch, or the diagnosis' saturating one).

use std::cell::Cell;

use nalgebra::{DMatrix, DVector};

use crate::identify::least_squares::Residuals;
use crate::model::im_effects::{
    logistic, saturation, ImAugmentation, PointInput, SaturatingFlux, MAIN_FLUX_EXPONENT,
};
use crate::model::{
    at_frequency, no_load_reading, Connection, Effect, ImCircuit, ImSupply, RotorCage, C64,
};

use super::MIN_FRICTION_W;

/// Relative step of the finite-difference Jacobian.
pub(super) const STEP: f64 = 1e-6;

/// The parameters fitted: `Rs` (bounded), then `ln Xr`, `ln Xm`,
/// `ln Rfe`, `ln Rr`, `ln Pfw`; the saturating fit adds `ln Es`.
pub(super) const Q: usize = 6;

/// What a reading is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Test {
    /// A load point at its measured slip.
    Load(f64),
    /// A locked-rotor reading.
    LockedRotor,
    /// A no-load reading (slip not measured).
    NoLoad,
}

/// One reading in per-phase-independent terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Reading {
    pub(super) test: Test,
    pub(super) line_voltage: f64,
    pub(super) line_current: f64,
    pub(super) input_power: f64,
    pub(super) frequency: f64,
    /// The reading's stator resistance over the fitted `Rs` (its winding
    /// temperature against `Rs`'s).
    pub(super) rs_scale: f64,
}

pub(super) struct JointProblem<'a> {
    pub(super) readings: &'a [Reading],
    pub(super) connection: Connection,
    pub(super) rated_frequency: f64,
    /// `Xs/Xr`.
    pub(super) ratio: f64,
    pub(super) rs_bounds: (f64, f64),
    /// How the magnetising branch is modelled.
    pub(super) branch: Branch,
    pub(super) evaluations: Cell<usize>,
}

/// How the joint fit models the magnetising branch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Branch {
    /// The T circuit's: `Xm` and `Rfe` constant, across the air-gap
    /// voltage (as the standard tests reduce it).
    Linear,
    /// The diagnosis' model ([`crate::model::im_effects`]): `Xm` on the
    /// saturation curve of `flux`, the core loss across the same node;
    /// the vector's `Xm` holds at the air-gap voltage `e_ref`; `fit` says
    /// which of the curve's parameters the vector holds.
    Curve {
        e_ref: f64,
        flux: SaturatingFlux,
        fit: CurveFit,
    },
}

/// Which of the saturation curve's parameters the vector holds after its
/// first [`Q`] entries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum CurveFit {
    /// None: the knee held [`HELD_KNEE`] times `e_ref`, so that nothing
    /// saturates (on the stator flux: the Γ circuit's placement of the
    /// core loss, behind `Rs` alone).
    Held,
    /// `ln Es`; the exponent [`MAIN_FLUX_EXPONENT`].
    Knee,
    /// `ln Es`, then the exponent within [`EXPONENT_RANGE`] through a
    /// logistic map.
    KneeAndExponent,
}

/// The exponents the curve may take where the fit holds one: the
/// no-load test's span of voltages fixes the curve's shape.
pub(super) const EXPONENT_RANGE: (f64, f64) = (3.0, 15.0);

/// A held knee, times the reference air-gap voltage: `(E/Es)^7` below
/// 10⁻⁴⁰ at every reading.
const HELD_KNEE: f64 = 1e6;

impl JointProblem<'_> {
    /// How many parameters the fit has.
    pub(super) fn q(&self) -> usize {
        Q + match self.branch {
            Branch::Linear
            | Branch::Curve {
                fit: CurveFit::Held,
                ..
            } => 0,
            Branch::Curve {
                fit: CurveFit::Knee,
                ..
            } => 1,
            Branch::Curve {
                fit: CurveFit::KneeAndExponent,
                ..
            } => 2,
        }
    }

    /// This fit with the magnetising branch modelled as `branch`.
    pub(super) fn with(&self, branch: Branch) -> Self {
        JointProblem {
            branch,
            evaluations: Cell::new(0),
            ..*self
        }
    }

    /// The saturation curve's knee `Es` in `x` (phase air-gap voltage, V);
    /// `None` for the T circuit's linear branch.
    pub(super) fn knee(&self, x: &DVector<f64>) -> Option<f64> {
        match self.branch {
            Branch::Linear => None,
            Branch::Curve {
                e_ref,
                fit: CurveFit::Held,
                ..
            } => Some(HELD_KNEE * e_ref),
            Branch::Curve { .. } => Some(x[Q].exp()).filter(|v| v.is_finite() && *v > 0.0),
        }
    }

    /// The saturation curve's exponent in `x`.
    pub(super) fn exponent(&self, x: &DVector<f64>) -> f64 {
        match self.branch {
            Branch::Curve {
                fit: CurveFit::KneeAndExponent,
                ..
            } => {
                let (lo, hi) = EXPONENT_RANGE;
                lo + (hi - lo) * logistic(x[Q + 1])
            }
            _ => f64::from(MAIN_FLUX_EXPONENT),
        }
    }

    /// The vector entry that holds `exponent` (the inverse of
    /// [`JointProblem::exponent`]'s map).
    pub(super) fn exponent_entry(exponent: f64) -> f64 {
        let (lo, hi) = EXPONENT_RANGE;
        let share = (exponent - lo) / (hi - lo);
        (share / (1.0 - share)).ln()
    }

    /// The knee and the exponent in `x`; `None` for the linear branch.
    pub(super) fn curve(&self, x: &DVector<f64>) -> Option<(f64, f64)> {
        Some((self.knee(x)?, self.exponent(x)))
    }

    /// The fitted knee `Es` in `x`: `None` where the fit holds it.
    pub(super) fn fitted_knee(&self, x: &DVector<f64>) -> Option<f64> {
        let held = matches!(
            self.branch,
            Branch::Linear
                | Branch::Curve {
                    fit: CurveFit::Held,
                    ..
                }
        );
        (!held).then(|| self.knee(x)).flatten()
    }

    /// The unsaturated `Xm_u` of circuit `c` (whose `Xm` holds at the
    /// reference air-gap voltage) on the curve `(es, n)`.
    pub(super) fn unsaturated_xm(&self, c: &ImCircuit, (es, n): (f64, f64)) -> Option<f64> {
        let Branch::Curve { e_ref, .. } = self.branch else {
            return Some(c.xm);
        };
        Some(c.xm * (1.0 + saturation(e_ref / es, n)))
    }

    /// Whether the core loss sits across the stator flux (behind `Rs`
    /// alone) rather than the air-gap voltage.
    pub(super) fn core_loss_on_stator_flux(&self) -> bool {
        matches!(
            self.branch,
            Branch::Curve {
                flux: SaturatingFlux::Stator,
                ..
            }
        )
    }

    pub(super) fn rs(&self, z: f64) -> f64 {
        let (lo, hi) = self.rs_bounds;
        lo + (hi - lo) * 0.5 * (1.0 + z.tanh())
    }

    /// `d Rs / d z`.
    pub(super) fn rs_slope(&self, z: f64) -> f64 {
        let (lo, hi) = self.rs_bounds;
        0.5 * (hi - lo) * (1.0 - z.tanh().powi(2))
    }

    pub(super) fn unpack(&self, x: &DVector<f64>) -> Option<(ImCircuit, f64)> {
        let e = |k: usize| Some(x[k].exp()).filter(|v| v.is_finite() && *v > 0.0);
        let xr = e(1)?;
        let circuit = ImCircuit {
            rs: self.rs(x[0]),
            xs: self.ratio * xr,
            xm: e(2)?,
            rfe: Some(e(3)?),
            rotor: RotorCage::Single { rr: e(4)?, xr },
        };
        Some((circuit, e(5)?.max(MIN_FRICTION_W)))
    }

    /// Line current and input power of `r` on circuit `c` with friction
    /// `pfw`, its `Xm` on the saturation curve `(Es, n)` where given.
    pub(super) fn model(
        &self,
        c: &ImCircuit,
        pfw: f64,
        curve: Option<(f64, f64)>,
        r: &Reading,
    ) -> Option<(f64, f64)> {
        if let Some(curve) = curve {
            return self.saturating(c, pfw, curve, r);
        }
        let mut at = at_frequency(c, r.frequency / self.rated_frequency);
        at.rs *= r.rs_scale;
        let supply = ImSupply {
            line_voltage: r.line_voltage,
            frequency: r.frequency,
            connection: self.connection,
            pole_pairs: 1,
        };
        let at_slip = |s: f64| {
            let op = at.operating_point(&supply, s);
            (op.line_current, op.input_power)
        };
        match r.test {
            Test::Load(s) => Some(at_slip(s)),
            Test::LockedRotor => Some(at_slip(1.0)),
            Test::NoLoad => no_load_reading(&at, self.connection, r.line_voltage, pfw)
                .map(|n| (n.line_current, n.input_power)),
        }
    }

    /// The magnetising reactance a no-load reading at `line_voltage` (rated
    /// frequency, `Rs` as fitted) shows by the classical reduction's
    /// formula, `E²/(Q − I²·Xs)` with `E = |V − I·(Rs + jXs)|` per phase:
    /// the saturating fit's `Xm` where the reduction reports its own.
    pub(super) fn rated_xm(&self, x: &DVector<f64>, line_voltage: f64) -> Option<f64> {
        let (c, v, current) = self.no_load_phasor(x, line_voltage)?;
        let (i, q) = (current.norm(), -current.im * v);
        let e = C64::new(v, 0.0) - current * C64::new(c.rs, c.xs);
        let xm = e.norm_sqr() / (q - i * i * c.xs);
        (xm.is_finite() && xm > 0.0).then_some(xm)
    }

    /// The T circuit's `Rfe` (across the air-gap voltage `E_T`) that draws
    /// the core loss of an `Rfe` across the stator flux (`E_Γ`, behind `Rs`
    /// alone) at a no-load reading at `line_voltage`: `Rfe·(E_T/E_Γ)²`, as
    /// the classical reduction computes it from that reading.
    pub(super) fn t_equivalent_rfe(&self, x: &DVector<f64>, line_voltage: f64) -> Option<f64> {
        let (c, v, current) = self.no_load_phasor(x, line_voltage)?;
        let e_t = C64::new(v, 0.0) - current * C64::new(c.rs, c.xs);
        let e_g = C64::new(v, 0.0) - current * c.rs;
        let rfe = c.rfe? * e_t.norm_sqr() / e_g.norm_sqr();
        (rfe.is_finite() && rfe > 0.0).then_some(rfe)
    }

    /// The circuit in `x`, the phase voltage and the phase current (its
    /// phasor, the voltage's phase 0) of a no-load reading at
    /// `line_voltage`, rated frequency, `Rs` as fitted.
    pub(super) fn no_load_phasor(
        &self,
        x: &DVector<f64>,
        line_voltage: f64,
    ) -> Option<(ImCircuit, f64, C64)> {
        let (c, pfw) = self.unpack(x)?;
        let reading = Reading {
            test: Test::NoLoad,
            line_voltage,
            line_current: 1.0,
            input_power: 1.0,
            frequency: self.rated_frequency,
            rs_scale: 1.0,
        };
        let (i_line, p) = self.model(&c, pfw, self.curve(x), &reading)?;
        let v = self.connection.phase_voltage(line_voltage);
        let i = self.connection.phase_current(i_line);
        let (p, s) = (p / 3.0, v * i);
        let q = (s * s - p * p).max(0.0).sqrt();
        Some((c, v, C64::new(p / v, -q / v)))
    }

    /// [`JointProblem::model`] with `Xm` on the saturation curve
    /// `(Es, n)`: the diagnosis' model of main-flux saturation with a core loss
    /// and friction beside it, whose free-running points are the no-load
    /// readings.
    pub(super) fn saturating(
        &self,
        c: &ImCircuit,
        pfw: f64,
        (es, n): (f64, f64),
        r: &Reading,
    ) -> Option<(f64, f64)> {
        let RotorCage::Single { rr, xr } = c.rotor else {
            return None;
        };
        let model = ImAugmentation {
            friction: true,
            iron: true,
            flux: match self.branch {
                Branch::Curve { flux, .. } => flux,
                Branch::Linear => return None,
            },
            exponent: n,
            ..ImAugmentation::with(Effect::MainFluxSaturation, self.ratio)
        };
        let xm_u = self.unsaturated_xm(c, (es, n))?;
        let x = [c.rs, xm_u, rr, xr, es, c.rfe?, pfw].map(f64::ln);
        let p = PointInput {
            slip: match r.test {
                Test::Load(s) => s,
                Test::LockedRotor => 1.0,
                Test::NoLoad => 0.0,
            },
            voltage: self.connection.phase_voltage(r.line_voltage),
            heat: 0.0,
            freq_ratio: r.frequency / self.rated_frequency,
            free_running: r.test == Test::NoLoad,
            rs_scale: r.rs_scale,
        };
        let t = model.terminal(&x, &p)?;
        Some((self.connection.line_current(t.current), t.power))
    }
}

impl Residuals for JointProblem<'_> {
    fn rows(&self) -> usize {
        2 * self.readings.len()
    }

    fn residuals_at(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
        self.evaluations.set(self.evaluations.get() + 1);
        let (c, pfw) = self.unpack(x)?;
        let curve = match self.branch {
            Branch::Linear => None,
            Branch::Curve { .. } => Some(self.curve(x)?),
        };
        let mut out = DVector::zeros(2 * self.readings.len());
        for (k, r) in self.readings.iter().enumerate() {
            let (i, p) = self.model(&c, pfw, curve, r)?;
            out[2 * k] = i / r.line_current - 1.0;
            out[2 * k + 1] = p / r.input_power - 1.0;
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    fn jacobian_at(&self, x: &DVector<f64>) -> Option<DMatrix<f64>> {
        let r0 = self.residuals_at(x)?;
        let mut jac = DMatrix::zeros(r0.len(), self.q());
        for j in 0..self.q() {
            let h = STEP * x[j].abs().max(1.0);
            let mut xh = x.clone();
            xh[j] += h;
            let r = self.residuals_at(&xh)?;
            jac.set_column(j, &((r - &r0) / h));
        }
        Some(jac)
    }
}
