//! Parameter identification from a [`Record`](crate::record::Record): the
//! public paths of each machine's identification, and the numerics they
//! share.
//!
//! The code lives with its machine: `machine/dc/identify/` (the DC step
//! and coast-down methods: `steady_state`, `pasek`, `moments`,
//! `coastdown`, `equation_error`, `output_error`) and
//! `machine/im/identify/` (the slip sweep's `recursive` estimator and
//! Levenberg–Marquardt `lm`; the standard tests' classical reduction
//! `standard_tests`). Both are pure functions of the record, so a
//! replayed record gives the same report, bit for bit.

pub(crate) mod least_squares;
mod nrmse;
pub(crate) mod pieces;
pub(crate) mod square_root;
pub(crate) mod stats;
pub(crate) mod vector;

pub use crate::machine::dc::identify::*;
pub use crate::machine::im::identify::*;
pub use nrmse::nrmse;
