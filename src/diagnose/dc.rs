//! DC motor diagnosis (to be built: see the module docs of `diagnose`).

use super::{DiagnoseError, DiagnoseOptions, DiagnosisRun};
use crate::record::Record;

/// Diagnose a `dc_step` record.
pub fn diagnose_dc(
    _record: &Record,
    _options: &DiagnoseOptions,
) -> Result<DiagnosisRun, DiagnoseError> {
    Err(DiagnoseError::NotEnoughData(
        "DC diagnosis is not built yet".into(),
    ))
}
