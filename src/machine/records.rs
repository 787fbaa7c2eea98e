//! A record read without a rig (CSV files, an MCAP file, a blind case),
//! mapped to its machine: the checks a loaded record gets, the preparation
//! its machine's methods need, its analysis and its diagnosis. The one place a record
//! kind is mapped to a machine, as
//! [`crate::config::TestConfig::into_machine`] is for a plan: the CLI's
//! `identify`, `diagnose` and `replay`, the blind benchmark and the fuzz
//! targets call these and do not branch on the machine themselves.

use std::path::{Path, PathBuf};

use super::dc::{analyse_dc, prepare_dc_record};
use super::im::{analyse_im, recorded_model};
use super::Analysed;
use crate::diagnose::{diagnose_dc, diagnose_im, DiagnoseError, DiagnoseOptions, DiagnosisRun};
use crate::identify::{
    check_input_power, check_plausible_files, ImplausibleFile, ImplausiblePower,
};
use crate::model::{Connection, ImModel, Machine};
use crate::record::{ColumnMap, Record, SegmentKind};

/// What the analysis of a record takes beside it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AnalyseOptions {
    /// Induction machine: the winding connection (overrides the
    /// nameplate's).
    pub connection: Option<Connection>,
    /// Induction machine: the circuit to fit; `None` takes the one the
    /// record's configuration named, else single cage with iron loss.
    pub im_model: Option<ImModel>,
}

/// Why a record loaded from files cannot be analysed: values no machine
/// of its kind gives.
#[derive(Debug, thiserror::Error)]
pub enum ImplausibleRecord {
    /// A DC record's value out of any plausible range (the file named).
    #[error(transparent)]
    Dc(#[from] ImplausibleFile),
    /// An induction machine's input power that no machine draws, and the
    /// file, where the record is one file.
    #[error("{}{power}", file.as_ref().map(|f| format!("{}: ", f.display())).unwrap_or_default())]
    Im {
        /// The record's file, when it is one.
        file: Option<PathBuf>,
        /// What is wrong with the power.
        power: ImplausiblePower,
    },
}

/// Check a record of `kind` loaded from `files` for values its machine
/// cannot give (a DC record's voltage, current or speed beyond any rig's,
/// an induction machine's power factor above 1 or far below any
/// machine's), naming the file (`columns`: the CSV columns' map the
/// record was loaded with).
pub fn check_record(
    record: &Record,
    kind: SegmentKind,
    files: &[PathBuf],
    columns: &ColumnMap,
) -> Result<(), ImplausibleRecord> {
    match kind.machine() {
        Machine::Dc => Ok(check_plausible_files(record, kind, files, columns)?),
        Machine::Induction => check_input_power(record).map_err(|power| ImplausibleRecord::Im {
            file: only(files).map(Path::to_path_buf),
            power,
        }),
    }
}

/// The one file of `files`, if there is only one.
fn only(files: &[PathBuf]) -> Option<&Path> {
    match files {
        [one] => Some(one),
        _ => None,
    }
}

/// A record of `kind` made ready for its machine's methods: a DC record
/// as [`prepare_dc_record`] makes it (a single segment split, gaps cut,
/// the voltage's timing checked, or moved when `voltage_as_issued`); an
/// induction machine's as it is.
pub fn ready_record(record: Record, kind: SegmentKind, voltage_as_issued: bool) -> Record {
    match kind.machine() {
        Machine::Dc => prepare_dc_record(record, voltage_as_issued),
        Machine::Induction => record,
    }
}

/// Diagnose `record` as a test of `kind`: the DC diagnosis for `dc_step`
/// and `dc_coastdown` records, the induction machine's for its sweep and
/// standard tests.
pub fn diagnose(
    record: &Record,
    kind: SegmentKind,
    options: &DiagnoseOptions,
) -> Result<DiagnosisRun, DiagnoseError> {
    match kind.machine() {
        Machine::Dc => diagnose_dc(record, options),
        Machine::Induction => diagnose_im(record, options),
    }
}

/// Identify `record`, a test of `kind`, and diagnose it when `diagnose`.
pub fn analyse(
    record: &Record,
    kind: SegmentKind,
    options: &AnalyseOptions,
    diagnose: bool,
) -> Analysed {
    match kind.machine() {
        Machine::Dc => analyse_dc(record, None, diagnose),
        Machine::Induction => {
            let model = options.im_model.unwrap_or_else(|| recorded_model(record));
            analyse_im(record, options.connection, model, diagnose)
        }
    }
}

/// Analyse a record of any machine (`replay`) by its content: an
/// induction machine's record (one that holds operating points or
/// standard-test readings) by the circuit its configuration named (else
/// single cage with iron loss), any other as a DC record.
pub fn analyse_record(record: &Record, diagnose: bool) -> Analysed {
    analyse(
        record,
        record_analysis_kind(record),
        &AnalyseOptions::default(),
        diagnose,
    )
}

/// The kind [`analyse_record`] analyses `record` as (and diagnoses it
/// as, with [`Analysed::diagnose`]).
pub fn record_analysis_kind(record: &Record) -> SegmentKind {
    if record.operating_points.is_empty() && record.standard_tests.is_empty() {
        SegmentKind::DcStep
    } else {
        SegmentKind::ImSlipSweep
    }
}
