//! Sim-to-real gap diagnosis: where the identified ("sim") model misfits
//! the record ("real"), which unmodelled effect of the contract's
//! vocabulary causes it, and how far the gap shrinks once that effect is
//! modelled — every comparison on held-out data.
//!
//! - [`crate::contract`]: the diagnosis JSON of the data contract.
//! - [`decision`]: the paired held-out test, the penalised score, noise
//!   estimates; shared by both machines.
//! - [`plot`]: residuals before and after per region, as SVG.
//! - each machine's diagnosis lives with it: `machine/dc/diagnose/`
//!   (leave-one-segment-out on a staircase) and `machine/im/diagnose/`
//!   (interleaved points, stratified by sweep, so every fold sees every
//!   supply voltage).

pub mod blind;
pub mod cli;
pub mod decision;
mod plot;
mod sign_patterns;
mod text;
mod threads;

pub use crate::contract::{
    Candidate, Diagnosis, Gap, GapRegion, LookAlike, NominalFit, ParamCorrection, RegionAxis,
    ResidualEvidence, Verdict,
};
pub use crate::machine::dc::diagnose::diagnose_dc;
/// Diagnose a record as a test of its kind, by its machine's diagnosis
/// (the mapping lives with the machines, `machine/records.rs`).
pub use crate::machine::diagnose;
pub use crate::machine::im::diagnose::diagnose_im;
pub use plot::{write_residual_svg, ResidualPanel, ResidualPlot, ResidualPlotError};
pub use text::render_diagnosis_text;
pub use threads::{par_map, worker_threads, THREADS_VAR};

use crate::model::Connection;
use crate::record::{Record, SegmentKind};
use crate::report::IdentificationReport;

/// Diagnose `record` and attach the diagnosis to `report` (as `run` and
/// `replay` do); a record that cannot be diagnosed leaves a warning
/// instead. Returns the residual plot when there is a diagnosis.
pub fn attach_diagnosis(
    report: &mut IdentificationReport,
    record: &Record,
    kind: SegmentKind,
) -> Option<ResidualPlot> {
    match diagnose(record, kind, &DiagnoseOptions::default()) {
        Ok(run) => {
            report.diagnosis = Some(Box::new(run.report));
            Some(run.plot)
        }
        Err(e) => {
            report.warnings.push(format!("diagnosis: {e}"));
            None
        }
    }
}

/// What a diagnosis needs beside the record.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DiagnoseOptions {
    /// Induction machine: winding connection (overrides the record's nameplate).
    pub connection: Option<Connection>,
    /// DC: hold out interleaved time blocks (`Some(true)`) or whole
    /// segments (`Some(false)`); `None` leaves it to
    /// `MOTORBENCH_DC_VALIDATION` (segments unless it says `interleaved`).
    pub dc_interleaved: Option<bool>,
}

/// A diagnosis and the residual series behind its plot.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnosisRun {
    /// The contract's report.
    pub report: Diagnosis,
    /// Residuals before and after the verdict's effect, per region.
    pub plot: ResidualPlot,
}

/// Why a record cannot be diagnosed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnoseError {
    /// Too little data for held-out validation (e.g. one DC segment).
    #[error("not enough data to diagnose: {0}")]
    NotEnoughData(String),
    /// The nominal model could not be fitted.
    #[error("the nominal model could not be fitted: {0}")]
    NominalFit(String),
}
