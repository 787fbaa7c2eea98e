//! Machine models: equations, unmodelled effects, simulation.
//!
//! Shared by the simulated rig (which produces data) and identification
//! (which fits the same equations to data). Units are SI throughout.

mod dc;
mod effects;
mod zoh;

pub use dc::{DcMotor, DcParams, DcState, ParamError, Terminal};
pub use effects::{BrushDrop, CoulombFriction, DcEffect, Effect, Machine};
pub use zoh::Zoh;
