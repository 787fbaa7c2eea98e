//! Unmodelled effects: the contract's vocabulary, and the hook through
//! which an effect plugs into the DC model.
//!
//! The nominal model is the seed paper's Eqs. 1–2. An effect adds a
//! physically parameterised term (a voltage drop, a torque, a factor on a
//! nominal parameter). With any effect attached the DC model integrates
//! with a fixed-step RK4 instead of the exact zero-order hold.

use std::fmt::Debug;

use serde::{Deserialize, Serialize};

use super::DcState;

/// The machine an effect applies to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Machine {
    /// Separately excited DC motor.
    Dc,
    /// Induction machine.
    Induction,
}

/// The contract's vocabulary of unmodelled effects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    /// Constant friction torque opposing motion, beside viscous friction.
    CoulombFriction,
    /// Near-constant brush voltage drop in the direction of the current.
    BrushDrop,
    /// Flux (so K) falls as armature current rises.
    ArmatureReaction,
    /// Armature inductance falls as current rises.
    InductanceSaturation,
    /// Winding resistance rises as the winding heats.
    ThermalDrift,
    /// Current or speed reading lags the true value.
    SensorLag,
    /// Elastic shaft between motor and load: a torsional resonance.
    ShaftCompliance,
    /// Core loss resistance in parallel with the magnetising reactance.
    IronLoss,
    /// Rotor resistance and leakage change with slip frequency.
    DeepBar,
    /// Magnetising reactance falls as the air-gap voltage rises.
    MainFluxSaturation,
    /// Leakage reactances fall at high current.
    LeakageSaturation,
    /// Extra loss growing with the square of the load current.
    StrayLoadLoss,
}

impl Effect {
    /// Every effect of the vocabulary.
    pub const ALL: [Effect; 12] = [
        Effect::CoulombFriction,
        Effect::BrushDrop,
        Effect::ArmatureReaction,
        Effect::InductanceSaturation,
        Effect::ThermalDrift,
        Effect::SensorLag,
        Effect::ShaftCompliance,
        Effect::IronLoss,
        Effect::DeepBar,
        Effect::MainFluxSaturation,
        Effect::LeakageSaturation,
        Effect::StrayLoadLoss,
    ];

    /// Whether the effect applies to `machine` (thermal drift: both).
    pub fn applies_to(self, machine: Machine) -> bool {
        use Effect::*;
        match self {
            ThermalDrift => true,
            CoulombFriction | BrushDrop | ArmatureReaction | InductanceSaturation | SensorLag
            | ShaftCompliance => machine == Machine::Dc,
            IronLoss | DeepBar | MainFluxSaturation | LeakageSaturation | StrayLoadLoss => {
                machine == Machine::Induction
            }
        }
    }
}

/// An effect's contribution to the DC equations, evaluated at a state.
///
/// Every hook defaults to "no contribution", so an effect implements only
/// the terms it has. The model then reads
///
/// ```text
/// La·g_L·di/dt = U − Ra·g_R·i − K·g_K·ω − v_drop
/// J·dω/dt      = K·g_K·i − f·ω − (Tst + t_extra)·sign(ω)
/// ```
pub trait DcEffect: Debug + Send + Sync {
    /// The vocabulary name of the effect.
    fn effect(&self) -> Effect;
    /// Extra voltage drop across the armature, V, signed with the current.
    fn voltage_drop(&self, _x: &DcState) -> f64 {
        0.0
    }
    /// Extra friction torque magnitude opposing motion, N·m.
    fn friction_torque(&self, _x: &DcState) -> f64 {
        0.0
    }
    /// Factor on K (flux), 1 for none.
    fn flux_factor(&self, _x: &DcState) -> f64 {
        1.0
    }
    /// Factor on La, 1 for none.
    fn inductance_factor(&self, _x: &DcState) -> f64 {
        1.0
    }
    /// Factor on Ra, 1 for none.
    fn resistance_factor(&self, _x: &DcState) -> f64 {
        1.0
    }
}

/// Brush drop: `v_drop = Vb·tanh(i/i0)`, a constant drop once the current
/// is well above `i0` (smooth through zero so the integrator stays stable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrushDrop {
    /// Drop at full conduction, V.
    pub volts: f64,
    /// Current scale of the transition through zero, A.
    pub knee_amperes: f64,
}

impl DcEffect for BrushDrop {
    fn effect(&self) -> Effect {
        Effect::BrushDrop
    }
    fn voltage_drop(&self, x: &DcState) -> f64 {
        self.volts * (x.current / self.knee_amperes).tanh()
    }
}

/// Coulomb friction: a constant torque opposing motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoulombFriction {
    /// Friction torque, N·m.
    pub torque: f64,
}

impl DcEffect for CoulombFriction {
    fn effect(&self) -> Effect {
        Effect::CoulombFriction
    }
    fn friction_torque(&self, _x: &DcState) -> f64 {
        self.torque
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vocabulary_splits_by_machine() {
        let dc = Effect::ALL
            .iter()
            .filter(|e| e.applies_to(Machine::Dc))
            .count();
        let im = Effect::ALL
            .iter()
            .filter(|e| e.applies_to(Machine::Induction))
            .count();
        assert_eq!(dc, 7);
        assert_eq!(im, 6);
        let name = serde_json::to_string(&Effect::MainFluxSaturation).unwrap();
        assert_eq!(name, "\"main_flux_saturation\"");
    }

    #[test]
    fn brush_drop_follows_current_sign() {
        let b = BrushDrop {
            volts: 2.0,
            knee_amperes: 0.01,
        };
        let on = DcState {
            current: 1.0,
            ..Default::default()
        };
        let rev = DcState {
            current: -1.0,
            ..Default::default()
        };
        assert!((b.voltage_drop(&on) - 2.0).abs() < 1e-9);
        assert!((b.voltage_drop(&rev) + 2.0).abs() < 1e-9);
    }
}
