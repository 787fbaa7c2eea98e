//! Machine models: equations, unmodelled effects, simulation (DC motor;
//! induction-machine steady-state equivalent circuits in `im*`).
//!
//! Shared by the simulated rig (which produces data) and identification
//! (which fits the same equations to data). Units are SI throughout.

mod dc;
mod effects;
mod zoh;

pub use dc::{DcMotor, DcParams, DcState, ParamError, Terminal};
pub use effects::{BrushDrop, CoulombFriction, DcEffect, Effect, Machine};
pub use zoh::Zoh;

mod im;
mod im_closed_form;
pub(crate) mod im_effects;
mod im_equivalent;
#[cfg(test)]
pub(crate) mod im_fixtures;
mod im_lab;
mod im_standard_tests;

pub use im::{
    Connection, ImCircuit, ImCircuitError, ImModel, ImOperatingPoint, ImParam, ImSupply,
    PerUnitBase, RotorCage, C64, SEED_DOUBLE_CAGE_PU,
};
pub use im_closed_form::{DoubleCageForms, PaperTerms, SingleCageForms};
pub use im_effects::IM_EFFECTS;
pub use im_equivalent::{
    impedance_mismatch, standstill_rotor_leakage, stator_leakage_range, with_leakage_split,
    with_stator_leakage, EquivalentError, LeakageSplit,
};
pub use im_lab::{LabMachine, LabMeters, LabPoint, LabSegment, LabTerminal};
pub use im_standard_tests::{
    at_frequency, free_rotor_slip, locked_rotor_reading, no_load_reading, terminal_resistance,
    StandardReading,
};
