//! Steady-state per-phase equivalent circuit of a three-phase squirrel-cage
//! induction machine (the seed paper's Figs. 1 and 2), with complex
//! impedances.
//!
//! ```text
//!   Rs   jXs            ┌──── Rr/s + jXr ────┐   (single cage), or the
//!  ─/\/\─mmm─┬────┬─────┤                    │    parallel of Rr1/s + jXr1
//!            Rfe  jXm   └────────────────────┘    and Rr2/s + jXr2 (double)
//! ```
//!
//! All impedances are per phase of the winding as connected, in Ω at the
//! supply (test) frequency. The circuit takes the **phase** voltage, the
//! voltage across one winding: `V_line/√3` in star, `V_line` in delta. The
//! paper's Eqs. 1–2 (`I = V·√((C²+D²)/(A²+B²))`, `P = 3V²(AC−BD)/(A²+B²)`)
//! are per-phase formulas, so "V is the line voltage" holds only for a
//! delta winding, where `I` is then the phase current (the line current is
//! √3 times larger). For a star winding `V` is `V_line/√3`; putting the line
//! voltage there overstates the current by √3 and the power by 3.
//! [`Connection`] converts between line and phase quantities.
//!
//! The torque uses the air-gap power: `T = P_ag·p/ω` with `p` the number of
//! **pole pairs** (the paper's Eqs. 3 and 8 leave `p` undefined; with the
//! number of poles the torque would be twice too large).
//!
//! The slip may be 0 (synchronous speed): the rotor branch is written as an
//! admittance `s/(Rr + j·s·Xr)`, which is finite there.

use nalgebra::Complex;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A complex number of `f64`.
pub type C64 = Complex<f64>;

const J: C64 = C64 { re: 0.0, im: 1.0 };

/// How the three stator windings are connected to the supply lines.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Connection {
    /// Star (wye): phase voltage = line voltage / √3, phase current = line current.
    Star,
    /// Delta: phase voltage = line voltage, phase current = line current / √3.
    Delta,
}

impl Connection {
    /// The contract's name, `star` or `delta`.
    pub fn as_str(self) -> &'static str {
        match self {
            Connection::Star => "star",
            Connection::Delta => "delta",
        }
    }

    /// Parse `star`/`wye`/`y` or `delta`/`d` (any case).
    pub fn parse(s: &str) -> Option<Connection> {
        match s.trim().to_ascii_lowercase().as_str() {
            "star" | "wye" | "y" => Some(Connection::Star),
            "delta" | "d" => Some(Connection::Delta),
            _ => None,
        }
    }

    /// Voltage across one winding from the RMS line-to-line voltage.
    pub fn phase_voltage(self, line_voltage: f64) -> f64 {
        match self {
            Connection::Star => line_voltage / 3f64.sqrt(),
            Connection::Delta => line_voltage,
        }
    }

    /// Current in one winding from the RMS line current.
    pub fn phase_current(self, line_current: f64) -> f64 {
        match self {
            Connection::Star => line_current,
            Connection::Delta => line_current / 3f64.sqrt(),
        }
    }

    /// RMS line-to-line voltage from the voltage across one winding.
    pub fn line_voltage(self, phase_voltage: f64) -> f64 {
        match self {
            Connection::Star => phase_voltage * 3f64.sqrt(),
            Connection::Delta => phase_voltage,
        }
    }

    /// RMS line current from the current in one winding.
    pub fn line_current(self, phase_current: f64) -> f64 {
        match self {
            Connection::Star => phase_current,
            Connection::Delta => phase_current * 3f64.sqrt(),
        }
    }
}

impl std::fmt::Display for Connection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One circuit element, named by its data-contract key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum ImParam {
    /// Stator resistance.
    Rs,
    /// Stator leakage reactance.
    Xs,
    /// Magnetising reactance.
    Xm,
    /// Iron-loss resistance (parallel to Xm).
    Rfe,
    /// Rotor resistance (single cage).
    Rr,
    /// Rotor leakage reactance (single cage).
    Xr,
    /// Resistance of cage 1 (double cage; by convention the outer,
    /// starting cage: the one with the smaller Xr/Rr).
    Rr1,
    /// Resistance of cage 2 (double cage; the inner, running cage).
    Rr2,
    /// Leakage reactance of cage 1.
    Xr1,
    /// Leakage reactance of cage 2.
    Xr2,
}

impl ImParam {
    /// The contract key (`Rs`, `Xs`, …).
    pub fn key(self) -> &'static str {
        match self {
            ImParam::Rs => "Rs",
            ImParam::Xs => "Xs",
            ImParam::Xm => "Xm",
            ImParam::Rfe => "Rfe",
            ImParam::Rr => "Rr",
            ImParam::Xr => "Xr",
            ImParam::Rr1 => "Rr1",
            ImParam::Rr2 => "Rr2",
            ImParam::Xr1 => "Xr1",
            ImParam::Xr2 => "Xr2",
        }
    }

    /// Parse a contract key (exact case).
    pub fn parse(key: &str) -> Option<ImParam> {
        ImParam::ALL.iter().copied().find(|p| p.key() == key)
    }

    /// Every parameter.
    pub const ALL: [ImParam; 10] = [
        ImParam::Rs,
        ImParam::Xs,
        ImParam::Xm,
        ImParam::Rfe,
        ImParam::Rr,
        ImParam::Xr,
        ImParam::Rr1,
        ImParam::Rr2,
        ImParam::Xr1,
        ImParam::Xr2,
    ];
}

impl std::fmt::Display for ImParam {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.key())
    }
}

/// Which equivalent circuit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ImModel {
    /// Single cage without iron loss (Fig. 1 with Rfe → ∞).
    Single,
    /// Single cage with iron loss (Fig. 1, Eqs. 1–7).
    SingleFe,
    /// Double cage without iron loss (Fig. 2, Eqs. 8–14).
    Double,
    /// Double cage with iron loss (not in the paper; for completeness).
    DoubleFe,
}

impl ImModel {
    /// CLI name: `single`, `single-fe`, `double`, `double-fe`.
    pub fn as_str(self) -> &'static str {
        match self {
            ImModel::Single => "single",
            ImModel::SingleFe => "single-fe",
            ImModel::Double => "double",
            ImModel::DoubleFe => "double-fe",
        }
    }

    /// Parse a CLI name.
    pub fn parse(s: &str) -> Option<ImModel> {
        match s {
            "single" => Some(ImModel::Single),
            "single-fe" => Some(ImModel::SingleFe),
            "double" => Some(ImModel::Double),
            "double-fe" => Some(ImModel::DoubleFe),
            _ => None,
        }
    }

    /// The model's parameters in a fixed order.
    pub fn params(self) -> &'static [ImParam] {
        use ImParam::*;
        match self {
            ImModel::Single => &[Rs, Xs, Xm, Rr, Xr],
            ImModel::SingleFe => &[Rs, Xs, Xm, Rfe, Rr, Xr],
            ImModel::Double => &[Rs, Xs, Xm, Rr1, Rr2, Xr1, Xr2],
            ImModel::DoubleFe => &[Rs, Xs, Xm, Rfe, Rr1, Rr2, Xr1, Xr2],
        }
    }

    /// Whether the model has the iron-loss resistance.
    pub fn has_iron_loss(self) -> bool {
        matches!(self, ImModel::SingleFe | ImModel::DoubleFe)
    }

    /// Whether the model has two rotor cages.
    pub fn is_double(self) -> bool {
        matches!(self, ImModel::Double | ImModel::DoubleFe)
    }
}

impl std::fmt::Display for ImModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The rotor branch.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum RotorCage {
    /// One cage: `Rr/s + jXr`.
    Single {
        /// Rotor resistance, Ω.
        rr: f64,
        /// Rotor leakage reactance, Ω.
        xr: f64,
    },
    /// Two cages in parallel: `Rr1/s + jXr1` ∥ `Rr2/s + jXr2`.
    Double {
        /// Cage 1 resistance, Ω.
        rr1: f64,
        /// Cage 2 resistance, Ω.
        rr2: f64,
        /// Cage 1 leakage reactance, Ω.
        xr1: f64,
        /// Cage 2 leakage reactance, Ω.
        xr2: f64,
    },
}

/// A circuit element that cannot describe a machine.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ImCircuitError {
    /// A value is not a finite number > 0.
    #[error("induction-machine parameter {param} = {value} must be a finite number > 0")]
    NotPositive {
        /// The parameter.
        param: ImParam,
        /// The value given.
        value: f64,
    },
    /// The parameter does not belong to the model.
    #[error("parameter {param} is not part of the {model} model")]
    NotInModel {
        /// The parameter.
        param: ImParam,
        /// The model.
        model: ImModel,
    },
    /// A value list does not match the model's parameter list.
    #[error("the {model} model has {expected} parameters, {given} given")]
    WrongLength {
        /// The model.
        model: ImModel,
        /// Its parameter count.
        expected: usize,
        /// The count given.
        given: usize,
    },
}

/// The seed paper's "true" double-cage machine (Sec. IV), per unit: the
/// circuit the simulated studies, tests and benches scale to their rating
/// (see [`ImCircuit::from_per_unit`]).
pub const SEED_DOUBLE_CAGE_PU: ImCircuit = ImCircuit {
    rs: 0.00778,
    xs: 0.123,
    xm: 4.3,
    rfe: None,
    rotor: RotorCage::Double {
        rr1: 0.0693,
        rr2: 0.0132,
        xr1: 0.00843,
        xr2: 0.1162,
    },
};

/// The per-phase equivalent circuit, Ω at the test frequency.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImCircuit {
    /// Stator resistance, Ω.
    pub rs: f64,
    /// Stator leakage reactance, Ω.
    pub xs: f64,
    /// Magnetising reactance, Ω.
    pub xm: f64,
    /// Iron-loss resistance, Ω (`None`: no iron loss).
    pub rfe: Option<f64>,
    /// Rotor branch.
    pub rotor: RotorCage,
}

/// The supply and machine data that turn the circuit into terminal values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImSupply {
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// Supply frequency, Hz.
    pub frequency: f64,
    /// Winding connection.
    pub connection: Connection,
    /// Pole pairs (4 poles → 2).
    pub pole_pairs: u32,
}

/// Terminal quantities at one slip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImOperatingPoint {
    /// Slip (0 synchronous, 1 locked rotor).
    pub slip: f64,
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// RMS line current, A.
    pub line_current: f64,
    /// RMS current in one winding, A.
    pub phase_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Power factor `P/(√3·V·I)`.
    pub power_factor: f64,
    /// Air-gap power, W.
    pub air_gap_power: f64,
    /// Electromagnetic torque, N·m.
    pub torque: f64,
    /// Shaft speed, rad/s.
    pub speed: f64,
}

/// A per-unit base: rated phase voltage and phase current.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PerUnitBase {
    /// Base (rated) phase voltage, V.
    pub phase_voltage: f64,
    /// Base (rated) phase current, A.
    pub phase_current: f64,
}

impl PerUnitBase {
    /// The base from rated line values and the connection.
    pub fn from_rating(
        line_voltage: f64,
        line_current: f64,
        connection: Connection,
    ) -> PerUnitBase {
        PerUnitBase {
            phase_voltage: connection.phase_voltage(line_voltage),
            phase_current: connection.phase_current(line_current),
        }
    }

    /// Base impedance, Ω.
    pub fn impedance(&self) -> f64 {
        self.phase_voltage / self.phase_current
    }

    /// Base power (three-phase), W.
    pub fn power(&self) -> f64 {
        3.0 * self.phase_voltage * self.phase_current
    }
}

/// Admittance `s/(R + j·s·X)` of `R/s + jX`, finite at `s = 0`, and its
/// derivatives with respect to `R` and `X`.
#[inline(always)]
fn branch_admittance(s: f64, r: f64, x: f64) -> (C64, C64, C64) {
    let d = C64::new(r, s * x);
    let y = C64::new(s, 0.0) / d;
    let (dr, dx) = branch_derivatives(s, d);
    (y, dr, dx)
}

/// The derivatives of [`branch_admittance`] with respect to `R` and `X`,
/// from its denominator `d = R + j·s·X`.
#[inline(always)]
fn branch_derivatives(s: f64, d: C64) -> (C64, C64) {
    let d2 = d * d;
    (-C64::new(s, 0.0) / d2, -J * (s * s) / d2)
}

impl ImCircuit {
    /// The model this circuit is an instance of.
    pub fn model(&self) -> ImModel {
        match (&self.rotor, self.rfe.is_some()) {
            (RotorCage::Single { .. }, false) => ImModel::Single,
            (RotorCage::Single { .. }, true) => ImModel::SingleFe,
            (RotorCage::Double { .. }, false) => ImModel::Double,
            (RotorCage::Double { .. }, true) => ImModel::DoubleFe,
        }
    }

    /// A circuit of `model` from values in the order of [`ImModel::params`].
    pub fn from_values(model: ImModel, values: &[f64]) -> Result<ImCircuit, ImCircuitError> {
        let params = model.params();
        if values.len() != params.len() {
            return Err(ImCircuitError::WrongLength {
                model,
                expected: params.len(),
                given: values.len(),
            });
        }
        let rotor = if model.is_double() {
            RotorCage::Double {
                rr1: 1.0,
                rr2: 1.0,
                xr1: 1.0,
                xr2: 1.0,
            }
        } else {
            RotorCage::Single { rr: 1.0, xr: 1.0 }
        };
        let mut c = ImCircuit {
            rs: 1.0,
            xs: 1.0,
            xm: 1.0,
            rfe: model.has_iron_loss().then_some(1.0),
            rotor,
        };
        for (&p, &v) in params.iter().zip(values) {
            c.set(p, v)?;
        }
        Ok(c)
    }

    /// The values in the order of [`ImModel::params`].
    pub fn values(&self) -> Vec<f64> {
        self.model()
            .params()
            .iter()
            .map(|&p| self.get(p).expect("a model's own parameter"))
            .collect()
    }

    /// One element's value; `None` when the model lacks it.
    pub fn get(&self, param: ImParam) -> Option<f64> {
        match (param, &self.rotor) {
            (ImParam::Rs, _) => Some(self.rs),
            (ImParam::Xs, _) => Some(self.xs),
            (ImParam::Xm, _) => Some(self.xm),
            (ImParam::Rfe, _) => self.rfe,
            (ImParam::Rr, RotorCage::Single { rr, .. }) => Some(*rr),
            (ImParam::Xr, RotorCage::Single { xr, .. }) => Some(*xr),
            (ImParam::Rr1, RotorCage::Double { rr1, .. }) => Some(*rr1),
            (ImParam::Rr2, RotorCage::Double { rr2, .. }) => Some(*rr2),
            (ImParam::Xr1, RotorCage::Double { xr1, .. }) => Some(*xr1),
            (ImParam::Xr2, RotorCage::Double { xr2, .. }) => Some(*xr2),
            _ => None,
        }
    }

    /// Set one element (a finite value > 0 that the model has).
    pub fn set(&mut self, param: ImParam, value: f64) -> Result<(), ImCircuitError> {
        if !(value.is_finite() && value > 0.0) {
            return Err(ImCircuitError::NotPositive { param, value });
        }
        let model = self.model();
        let slot = match (param, &mut self.rotor) {
            (ImParam::Rs, _) => &mut self.rs,
            (ImParam::Xs, _) => &mut self.xs,
            (ImParam::Xm, _) => &mut self.xm,
            (ImParam::Rfe, _) => match &mut self.rfe {
                Some(r) => r,
                None => return Err(ImCircuitError::NotInModel { param, model }),
            },
            (ImParam::Rr, RotorCage::Single { rr, .. }) => rr,
            (ImParam::Xr, RotorCage::Single { xr, .. }) => xr,
            (ImParam::Rr1, RotorCage::Double { rr1, .. }) => rr1,
            (ImParam::Rr2, RotorCage::Double { rr2, .. }) => rr2,
            (ImParam::Xr1, RotorCage::Double { xr1, .. }) => xr1,
            (ImParam::Xr2, RotorCage::Double { xr2, .. }) => xr2,
            _ => return Err(ImCircuitError::NotInModel { param, model }),
        };
        *slot = value;
        Ok(())
    }

    /// Check every element is a finite number > 0.
    pub fn validate(&self) -> Result<(), ImCircuitError> {
        for &p in self.model().params() {
            let v = self.get(p).expect("own parameter");
            if !(v.is_finite() && v > 0.0) {
                return Err(ImCircuitError::NotPositive { param: p, value: v });
            }
        }
        Ok(())
    }

    /// Every impedance multiplied by `factor` (e.g. `1/Z_base` for per unit).
    pub fn scaled(&self, factor: f64) -> ImCircuit {
        let mut c = *self;
        for &p in self.model().params() {
            let v = self.get(p).expect("own parameter") * factor;
            // Scaling by a positive factor keeps positive values positive;
            // a non-positive factor is the caller's error, kept visible.
            if let Some(slot) = c.slot_mut(p) {
                *slot = v;
            }
        }
        c
    }

    fn slot_mut(&mut self, param: ImParam) -> Option<&mut f64> {
        match (param, &mut self.rotor) {
            (ImParam::Rs, _) => Some(&mut self.rs),
            (ImParam::Xs, _) => Some(&mut self.xs),
            (ImParam::Xm, _) => Some(&mut self.xm),
            (ImParam::Rfe, _) => self.rfe.as_mut(),
            (ImParam::Rr, RotorCage::Single { rr, .. }) => Some(rr),
            (ImParam::Xr, RotorCage::Single { xr, .. }) => Some(xr),
            (ImParam::Rr1, RotorCage::Double { rr1, .. }) => Some(rr1),
            (ImParam::Rr2, RotorCage::Double { rr2, .. }) => Some(rr2),
            (ImParam::Xr1, RotorCage::Double { xr1, .. }) => Some(xr1),
            (ImParam::Xr2, RotorCage::Double { xr2, .. }) => Some(xr2),
            _ => None,
        }
    }

    /// The circuit in per unit of `base`.
    pub fn to_per_unit(&self, base: &PerUnitBase) -> ImCircuit {
        self.scaled(1.0 / base.impedance())
    }

    /// The circuit in Ω from per-unit values on `base`.
    pub fn from_per_unit(per_unit: &ImCircuit, base: &PerUnitBase) -> ImCircuit {
        per_unit.scaled(base.impedance())
    }

    /// Rotor-branch admittance at slip `s` (all cages in parallel).
    pub fn rotor_admittance(&self, s: f64) -> C64 {
        match self.rotor {
            RotorCage::Single { rr, xr } => branch_admittance(s, rr, xr).0,
            RotorCage::Double { rr1, rr2, xr1, xr2 } => {
                branch_admittance(s, rr1, xr1).0 + branch_admittance(s, rr2, xr2).0
            }
        }
    }

    /// Rotor-branch impedance at slip `s > 0`, `R(s)/s + jX(s)`; for the
    /// double cage the paper's Eqs. 13–14 give `R(s)` and `X(s)`.
    pub fn rotor_impedance(&self, s: f64) -> C64 {
        self.rotor_admittance(s).inv()
    }

    /// Rotor-branch impedance at slip `s > 0` and its derivative with
    /// respect to each of `params` (zero for non-rotor elements).
    pub fn rotor_impedance_gradient(&self, s: f64, params: &[ImParam]) -> (C64, Vec<C64>) {
        let zero = C64::new(0.0, 0.0);
        let (y, parts): (C64, Vec<(ImParam, C64)>) = match self.rotor {
            RotorCage::Single { rr, xr } => {
                let (y, dr, dx) = branch_admittance(s, rr, xr);
                (y, vec![(ImParam::Rr, dr), (ImParam::Xr, dx)])
            }
            RotorCage::Double { rr1, rr2, xr1, xr2 } => {
                let (y1, dr1, dx1) = branch_admittance(s, rr1, xr1);
                let (y2, dr2, dx2) = branch_admittance(s, rr2, xr2);
                (
                    y1 + y2,
                    vec![
                        (ImParam::Rr1, dr1),
                        (ImParam::Xr1, dx1),
                        (ImParam::Rr2, dr2),
                        (ImParam::Xr2, dx2),
                    ],
                )
            }
        };
        let z = y.inv();
        let grads = params
            .iter()
            .map(|p| {
                parts
                    .iter()
                    .find(|(q, _)| q == p)
                    .map_or(zero, |(_, dy)| -z * z * dy)
            })
            .collect();
        (z, grads)
    }

    /// Magnetising-branch admittance `1/Rfe + 1/(jXm)`.
    pub fn magnetising_admittance(&self) -> C64 {
        C64::new(self.rfe.map_or(0.0, |r| 1.0 / r), -1.0 / self.xm)
    }

    /// Input impedance per phase at slip `s` (0 ≤ s).
    pub fn impedance(&self, s: f64) -> C64 {
        let y_ag = self.magnetising_admittance() + self.rotor_admittance(s);
        C64::new(self.rs, self.xs) + y_ag.inv()
    }

    /// Input impedance and its derivative with respect to each of
    /// `params` (all must belong to the model).
    pub fn impedance_gradient(&self, s: f64, params: &[ImParam]) -> (C64, Vec<C64>) {
        let mut grads = vec![C64::new(0.0, 0.0); params.len()];
        let z = self.impedance_gradient_into(s, params, &mut grads);
        (z, grads)
    }

    /// [`ImCircuit::impedance_gradient`] without allocating: the
    /// derivatives go to `out` (at least `params.len()` long).
    pub fn impedance_gradient_into(&self, s: f64, params: &[ImParam], out: &mut [C64]) -> C64 {
        // dY_ag/dθ for the rotor elements.
        let (y_rotor, dy_rotor) = match self.rotor {
            RotorCage::Single { rr, xr } => {
                let (y, dr, dx) = branch_admittance(s, rr, xr);
                // Two of the four entries (a repeat of Rr is never found).
                let unused = (ImParam::Rr, C64::new(0.0, 0.0));
                (y, [(ImParam::Rr, dr), (ImParam::Xr, dx), unused, unused])
            }
            RotorCage::Double { rr1, rr2, xr1, xr2 } => {
                let (y1, dr1, dx1) = branch_admittance(s, rr1, xr1);
                let (y2, dr2, dx2) = branch_admittance(s, rr2, xr2);
                let dy = [
                    (ImParam::Rr1, dr1),
                    (ImParam::Xr1, dx1),
                    (ImParam::Rr2, dr2),
                    (ImParam::Xr2, dx2),
                ];
                (y1 + y2, dy)
            }
        };
        let (z, minus_z_ag2) = self.impedance_and_minus_z_ag2(y_rotor);
        for (slot, &p) in out.iter_mut().zip(params) {
            *slot = match p {
                ImParam::Rs => C64::new(1.0, 0.0),
                ImParam::Xs => J,
                ImParam::Xm => self.xm_derivative(minus_z_ag2),
                ImParam::Rfe => self.rfe_derivative(minus_z_ag2),
                other => dy_rotor
                    .iter()
                    .find(|(q, _)| *q == other)
                    .map_or(C64::new(f64::NAN, f64::NAN), |(_, dy)| minus_z_ag2 * dy),
            };
        }
        z
    }

    /// The input impedance from the rotor admittance `y_rotor`, and
    /// `−Z_ag²` (`Z_ag` the air-gap impedance): `dZ/dθ = −Z_ag²·dY_ag/dθ`.
    #[inline(always)]
    fn impedance_and_minus_z_ag2(&self, y_rotor: C64) -> (C64, C64) {
        let z_ag = self.air_gap_impedance(y_rotor);
        (C64::new(self.rs, self.xs) + z_ag, -z_ag * z_ag)
    }

    /// The air-gap impedance `Z_ag = 1/(Y_m + Y_rotor)` from the rotor
    /// admittance.
    #[inline(always)]
    fn air_gap_impedance(&self, y_rotor: C64) -> C64 {
        let mut y_ag = self.magnetising_admittance();
        y_ag += y_rotor;
        y_ag.inv()
    }

    /// `dZ/dXm` from `−Z_ag²`.
    #[inline(always)]
    fn xm_derivative(&self, minus_z_ag2: C64) -> C64 {
        minus_z_ag2 * J / (self.xm * self.xm)
    }

    /// `dZ/dRfe` from `−Z_ag²`.
    #[inline(always)]
    fn rfe_derivative(&self, minus_z_ag2: C64) -> C64 {
        let r = self.rfe.unwrap_or(f64::INFINITY);
        minus_z_ag2 * (-1.0 / (r * r))
    }

    /// The air-gap impedance, the input impedance and its inverse, the
    /// input admittance `1/Z`, at every slip of `slips` (into `z_ag`, `z`
    /// and `y`): [`ImCircuit::impedance`] and its inverse, to the bit, in
    /// one loop per rotor that the compiler vectorises (two slips at a
    /// time).
    pub(crate) fn impedances_into(
        &self,
        slips: &[f64],
        z_ag: &mut [C64],
        z: &mut [C64],
        y: &mut [C64],
    ) {
        let z_s = C64::new(self.rs, self.xs);
        let points = z_ag
            .iter_mut()
            .zip(z.iter_mut())
            .zip(y.iter_mut())
            .zip(slips);
        let put = |((z_ag, z), y): ((&mut C64, &mut C64), &mut C64), y_rotor: C64| {
            *z_ag = self.air_gap_impedance(y_rotor);
            *z = z_s + *z_ag;
            *y = z.inv();
        };
        match self.rotor {
            RotorCage::Single { rr, xr } => {
                for (out, &s) in points {
                    put(out, branch_admittance(s, rr, xr).0);
                }
            }
            RotorCage::Double { rr1, rr2, xr1, xr2 } => {
                for (out, &s) in points {
                    put(
                        out,
                        branch_admittance(s, rr1, xr1).0 + branch_admittance(s, rr2, xr2).0,
                    );
                }
            }
        }
    }

    /// The derivatives of [`ImCircuit::impedance_gradient_into`] at every
    /// slip of `slips` for the model's own elements
    /// ([`ImModel::params`], in its order), to the bit, from the air-gap
    /// impedances ([`ImCircuit::impedances_into`]), in loops that the
    /// compiler vectorises: the derivative with respect to the `p`-th
    /// element at slip `k` into `dz[p·slips.len() + k]`; `minus_z_ag2`
    /// is working space (`−Z_ag²`).
    pub(crate) fn impedance_derivatives_into(
        &self,
        slips: &[f64],
        z_ag: &[C64],
        minus_z_ag2: &mut [C64],
        dz: &mut [C64],
    ) {
        let n = slips.len();
        let params = self.model().params();
        let column = |p: ImParam| params.iter().position(|&q| q == p).expect("own element");
        for (m, z_ag) in minus_z_ag2.iter_mut().zip(z_ag) {
            *m = -z_ag * z_ag;
        }
        // The rotor's derivatives dY_ag/dθ go to their columns first, and
        // are multiplied by −Z_ag² below.
        match self.rotor {
            RotorCage::Single { rr, xr } => {
                let (d_rr, rest) = dz[column(ImParam::Rr) * n..].split_at_mut(n);
                let d_xr = &mut rest[(column(ImParam::Xr) - column(ImParam::Rr) - 1) * n..][..n];
                for ((d_rr, d_xr), &s) in d_rr.iter_mut().zip(d_xr).zip(slips) {
                    (*d_rr, *d_xr) = branch_derivatives(s, C64::new(rr, s * xr));
                }
            }
            RotorCage::Double { rr1, rr2, xr1, xr2 } => {
                let mut rotor = dz[column(ImParam::Rr1) * n..].chunks_exact_mut(n);
                let mut next = || rotor.next().expect("four rotor columns");
                // The double cage's rotor columns are Rr1, Rr2, Xr1, Xr2.
                let (d_rr1, d_rr2, d_xr1, d_xr2) = (next(), next(), next(), next());
                let cage_1 = d_rr1.iter_mut().zip(d_xr1.iter_mut());
                let cage_2 = d_rr2.iter_mut().zip(d_xr2.iter_mut());
                for (((d_rr1, d_xr1), (d_rr2, d_xr2)), &s) in cage_1.zip(cage_2).zip(slips) {
                    (*d_rr1, *d_xr1) = branch_derivatives(s, C64::new(rr1, s * xr1));
                    (*d_rr2, *d_xr2) = branch_derivatives(s, C64::new(rr2, s * xr2));
                }
            }
        }
        for (&p, d) in params.iter().zip(dz.chunks_exact_mut(n)) {
            let m = minus_z_ag2.iter();
            match p {
                ImParam::Rs => d.fill(C64::new(1.0, 0.0)),
                ImParam::Xs => d.fill(J),
                ImParam::Xm => d
                    .iter_mut()
                    .zip(m)
                    .for_each(|(d, &m)| *d = self.xm_derivative(m)),
                ImParam::Rfe => d
                    .iter_mut()
                    .zip(m)
                    .for_each(|(d, &m)| *d = self.rfe_derivative(m)),
                _ => d.iter_mut().zip(m).for_each(|(d, &m)| *d = m * *d),
            }
        }
    }

    /// Phase current for a phase voltage `v_phase` at slip `s`, complex
    /// (the voltage is the phase reference).
    pub fn phase_current(&self, v_phase: f64, s: f64) -> C64 {
        C64::new(v_phase, 0.0) / self.impedance(s)
    }

    /// Terminal quantities at slip `s` on `supply`.
    pub fn operating_point(&self, supply: &ImSupply, s: f64) -> ImOperatingPoint {
        let conn = supply.connection;
        let v = conn.phase_voltage(supply.line_voltage);
        let y_ag = self.magnetising_admittance() + self.rotor_admittance(s);
        let z = C64::new(self.rs, self.xs) + y_ag.inv();
        let i = C64::new(v, 0.0) / z;
        let e = C64::new(v, 0.0) - i * C64::new(self.rs, self.xs);
        let p_in = 3.0 * (C64::new(v, 0.0) * i.conj()).re;
        // Air-gap power: what the rotor branch takes, 3·|E|²·Re(Y_rotor).
        let air_gap_power = 3.0 * e.norm_sqr() * self.rotor_admittance(s).re;
        let w_sync = std::f64::consts::TAU * supply.frequency / f64::from(supply.pole_pairs);
        let phase_current = i.norm();
        ImOperatingPoint {
            slip: s,
            line_voltage: supply.line_voltage,
            line_current: conn.line_current(phase_current),
            phase_current,
            input_power: p_in,
            power_factor: if phase_current > 0.0 {
                p_in / (3.0 * v * phase_current)
            } else {
                0.0
            },
            air_gap_power,
            torque: air_gap_power / w_sync,
            speed: (1.0 - s) * w_sync,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn double_paper() -> ImCircuit {
        SEED_DOUBLE_CAGE_PU
    }

    fn single_fe() -> ImCircuit {
        ImCircuit {
            rs: 1.2,
            xs: 2.1,
            xm: 60.0,
            rfe: Some(900.0),
            rotor: RotorCage::Single { rr: 1.1, xr: 2.9 },
        }
    }

    #[test]
    fn connection_converts_line_and_phase() {
        for c in [Connection::Star, Connection::Delta] {
            assert!((c.line_voltage(c.phase_voltage(400.0)) - 400.0).abs() < 1e-12);
            assert!((c.line_current(c.phase_current(7.0)) - 7.0).abs() < 1e-12);
            assert_eq!(Connection::parse(c.as_str()), Some(c));
        }
        assert!((Connection::Star.phase_voltage(400.0) - 230.94).abs() < 0.01);
        assert!((Connection::Delta.phase_current(10.0) - 5.7735).abs() < 1e-4);
        assert_eq!(Connection::parse("triangle"), None);
    }

    #[test]
    fn power_balances_and_torque_uses_pole_pairs() {
        let c = single_fe();
        for conn in [Connection::Star, Connection::Delta] {
            let supply = ImSupply {
                line_voltage: 400.0,
                frequency: 50.0,
                connection: conn,
                pole_pairs: 2,
            };
            let op = c.operating_point(&supply, 0.04);
            let v = conn.phase_voltage(400.0);
            let i = op.phase_current;
            let e = (C64::new(v, 0.0) - c.phase_current(v, 0.04) * C64::new(c.rs, c.xs)).norm();
            // Input = stator copper + iron + air gap.
            let losses = 3.0 * i * i * c.rs + 3.0 * e * e / c.rfe.unwrap();
            assert!((op.input_power - losses - op.air_gap_power).abs() < 1e-9 * op.input_power);
            // √3·V·I·cos φ = P.
            let s3 = 3f64.sqrt() * op.line_voltage * op.line_current * op.power_factor;
            assert!((s3 - op.input_power).abs() < 1e-9 * op.input_power);
            // Air-gap power = T·ω_sync, ω_sync = 2π·50/2.
            assert!((op.torque * std::f64::consts::PI * 50.0 - op.air_gap_power).abs() < 1e-9);
            // Mechanical power = (1 − s)·P_ag = T·ω.
            assert!(
                (op.torque * op.speed - 0.96 * op.air_gap_power).abs() < 1e-9 * op.air_gap_power
            );
        }
    }

    #[test]
    fn star_and_delta_differ_by_the_phase_voltage() {
        // The same winding in delta on 230 V and in star on 400 V draws the
        // same phase current and power.
        let c = single_fe();
        let star = c.operating_point(
            &ImSupply {
                line_voltage: 230.0 * 3f64.sqrt(),
                frequency: 50.0,
                connection: Connection::Star,
                pole_pairs: 2,
            },
            0.05,
        );
        let delta = c.operating_point(
            &ImSupply {
                line_voltage: 230.0,
                frequency: 50.0,
                connection: Connection::Delta,
                pole_pairs: 2,
            },
            0.05,
        );
        assert!((star.phase_current - delta.phase_current).abs() < 1e-9);
        assert!((star.input_power - delta.input_power).abs() < 1e-6);
        assert!((delta.line_current / star.line_current - 3f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn synchronous_speed_is_finite_and_draws_only_magnetising_current() {
        let c = double_paper();
        let z0 = c.impedance(0.0);
        assert!((z0 - C64::new(c.rs, c.xs + c.xm)).norm() < 1e-12);
        let op = c.operating_point(
            &ImSupply {
                line_voltage: 1.0,
                frequency: 50.0,
                connection: Connection::Delta,
                pole_pairs: 2,
            },
            0.0,
        );
        assert_eq!(op.torque, 0.0);
    }

    #[test]
    fn values_round_trip_and_bad_values_are_refused() {
        for c in [single_fe(), double_paper()] {
            let m = c.model();
            let back = ImCircuit::from_values(m, &c.values()).unwrap();
            assert_eq!(back, c);
        }
        let mut c = double_paper();
        assert_eq!(
            c.set(ImParam::Rr, 1.0),
            Err(ImCircuitError::NotInModel {
                param: ImParam::Rr,
                model: ImModel::Double
            })
        );
        assert!(matches!(
            c.set(ImParam::Xm, -1.0),
            Err(ImCircuitError::NotPositive { .. })
        ));
        assert!(matches!(
            ImCircuit::from_values(ImModel::Single, &[1.0; 3]),
            Err(ImCircuitError::WrongLength { .. })
        ));
        for p in ImParam::ALL {
            assert_eq!(ImParam::parse(p.key()), Some(p));
        }
    }

    #[test]
    fn per_unit_round_trip() {
        let base = PerUnitBase::from_rating(400.0, 10.0, Connection::Star);
        assert!((base.impedance() - 23.094).abs() < 1e-3);
        assert!((base.power() - 3f64.sqrt() * 4000.0).abs() < 1e-9);
        let c = single_fe();
        let pu = c.to_per_unit(&base);
        assert!((pu.xm - 60.0 / base.impedance()).abs() < 1e-12);
        let back = ImCircuit::from_per_unit(&pu, &base);
        assert!((back.rs - c.rs).abs() < 1e-12 && (back.rfe.unwrap() - 900.0).abs() < 1e-9);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        for c in [single_fe(), double_paper()] {
            let params = c.model().params();
            for s in [0.0, 0.003, 0.05, 0.4, 1.0] {
                let (z, g) = c.impedance_gradient(s, params);
                assert!((z - c.impedance(s)).norm() < 1e-12);
                for (k, &p) in params.iter().enumerate() {
                    let v = c.get(p).unwrap();
                    let h = v * 1e-6;
                    let mut up = c;
                    let mut dn = c;
                    up.set(p, v + h).unwrap();
                    dn.set(p, v - h).unwrap();
                    let fd = (up.impedance(s) - dn.impedance(s)) / (2.0 * h);
                    let scale = g[k].norm().max(1e-3 * z.norm() / v);
                    assert!(
                        (fd - g[k]).norm() < 1e-6 * scale,
                        "{p} at s={s}: analytic {} vs FD {fd}",
                        g[k]
                    );
                }
            }
        }
    }

    /// Every model: single and double cage, with and without iron loss.
    fn every_model() -> [ImCircuit; 4] {
        let single = ImCircuit {
            rfe: None,
            ..single_fe()
        };
        let double_fe = ImCircuit {
            rfe: Some(0.9 * double_paper().xm),
            ..double_paper()
        };
        [single, single_fe(), double_paper(), double_fe]
    }

    #[test]
    fn the_impedances_of_all_slips_are_those_of_each_slip_to_the_bit() {
        let slips = [0.0, 1e-4, 0.003, 0.05, 0.4, 0.77, 1.0];
        let n = slips.len();
        let bits = |z: C64| (z.re.to_bits(), z.im.to_bits());
        for c in every_model() {
            let params = c.model().params();
            let zero = C64::new(0.0, 0.0);
            let (mut z_ag, mut z, mut y) = (vec![zero; n], vec![zero; n], vec![zero; n]);
            c.impedances_into(&slips, &mut z_ag, &mut z, &mut y);
            let mut m = vec![zero; n];
            let mut dz = vec![zero; n * params.len()];
            c.impedance_derivatives_into(&slips, &z_ag, &mut m, &mut dz);
            for (k, &s) in slips.iter().enumerate() {
                let mut one = vec![zero; params.len()];
                let z_one = c.impedance_gradient_into(s, params, &mut one);
                assert_eq!(bits(z[k]), bits(c.impedance(s)), "{c:?} at {s}");
                assert_eq!(bits(z[k]), bits(z_one));
                assert_eq!(bits(y[k]), bits(c.impedance(s).inv()));
                for (p, d) in one.iter().enumerate() {
                    assert_eq!(bits(dz[p * n + k]), bits(*d), "{:?} at {s}", params[p]);
                }
            }
        }
    }
}
