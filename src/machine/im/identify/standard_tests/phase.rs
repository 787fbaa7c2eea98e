//! The per-phase quantities of one supply reading of the no-load or the
//! locked-rotor test, for the winding's connection: the step both
//! reductions start from, with the one check they share (a reading whose
//! power is not below its apparent power has no reactive part).

use super::error::StandardTestsError;
use crate::model::Connection;
use crate::record::SupplyReading;

/// One reading per phase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PhaseReading {
    /// Phase voltage, V.
    pub v: f64,
    /// Phase current, A.
    pub i: f64,
    /// Active power per phase, W.
    pub p: f64,
    /// Reactive power per phase, var.
    pub q: f64,
}

impl PhaseReading {
    /// Reading `r`, the `k`-th (from 0) of the `test` (for the error),
    /// of a winding connected as `connection`; refused when its power is
    /// not below its apparent power.
    pub(super) fn of(
        r: &SupplyReading,
        k: usize,
        test: &'static str,
        connection: Connection,
    ) -> Result<PhaseReading, StandardTestsError> {
        let v = connection.phase_voltage(r.line_voltage);
        let i = connection.phase_current(r.line_current);
        let (p, s) = (r.input_power / 3.0, v * i);
        if p >= s {
            return Err(StandardTestsError::PowerFactor {
                test,
                index: k + 1,
                segment: r.segment,
                power: r.input_power,
                apparent: 3.0 * s,
            });
        }
        Ok(PhaseReading {
            v,
            i,
            p,
            q: (s * s - p * p).sqrt(),
        })
    }
}
