//! Why an induction-machine identification method does not apply.
//!
//! The text of an [`ImFitError`] is the `reason` the report gives for the
//! method (the data contract's `methods.<name>.reason`).

/// Why a fit of an induction-machine circuit to a slip sweep failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImFitError {
    /// The fit's options are not usable with its model (a fixed parameter
    /// not in the model or not > 0, a start of another model).
    #[error("{0}")]
    BadOptions(String),
    /// The sweep does not hold what the fit needs (points, a slip span).
    #[error("{0}")]
    Missing(String),
    /// The sweep holds the data, but they do not determine the circuit
    /// (no finite fit, a fit outside the valid region, a numerical
    /// failure).
    #[error("{0}")]
    Unidentifiable(String),
}

/// Why a slip sweep's operating points are not usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SweepError {
    /// The sweep has no operating points.
    #[error("the sweep has no operating points")]
    Empty,
    /// A point has a value outside its range.
    #[error("operating point {index} (segment {segment}, slip {slip}): {field} = {value} {why}")]
    BadPoint {
        /// The point's position in the sweep, from 0.
        index: usize,
        /// The point's segment.
        segment: u32,
        /// The point's slip.
        slip: f64,
        /// The field refused, e.g. `line_current`.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong with it, e.g. `is not a finite number > 0`.
        why: &'static str,
    },
}
