//! Why a DC identification method does not apply to a record.
//!
//! The text of a [`NotApplicable`] is the `reason` the report gives for
//! the method (the data contract's `methods.<name>.reason`), in terms a
//! user can act on.

/// Why a DC identification method does not apply.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NotApplicable {
    /// The record does not hold what the method needs (a segment of a
    /// kind, settled levels, a voltage step, enough samples).
    #[error("{0}")]
    Missing(String),
    /// The record holds the data, but they do not determine the
    /// parameters (equations that do not separate them, a singular
    /// system, a value outside the physical range).
    #[error("{0}")]
    Unidentifiable(String),
    /// The method needs estimates from the steady-state fit, which did
    /// not apply.
    #[error("needs {needs} from the steady-state fit, which did not apply")]
    NeedsSteadyState {
        /// The estimates needed, e.g. `K, Ra and f`.
        needs: &'static str,
    },
    /// The method did not apply at the segment it is fitted on.
    #[error("segment {segment}: {source}")]
    AtSegment {
        /// The segment's index.
        segment: u32,
        /// Why, at that segment.
        #[source]
        source: Box<NotApplicable>,
    },
}
