//! Induction-machine diagnosis (to be built: see the module docs of `diagnose`).

use super::{DiagnoseError, DiagnoseOptions, DiagnosisRun};
use crate::record::Record;

/// Diagnose a `im_slip_sweep` record.
pub fn diagnose_im(
    _record: &Record,
    _options: &DiagnoseOptions,
) -> Result<DiagnosisRun, DiagnoseError> {
    Err(DiagnoseError::NotEnoughData(
        "IM diagnosis is not built yet".into(),
    ))
}
