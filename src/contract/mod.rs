//! The data contract's types, as serde reads and writes them: the
//! identification report (`/bench/result`, `report.json`, `--json`) with
//! its methods and parameters, the diagnosis, and the contract's version.
//! This module depends on nothing else in the crate, so identification,
//! diagnosis, the report renderers and the record all build on it without
//! importing one another. The extensions motorbench makes to the contract
//! are listed in `docs/data-contract.md`.

mod diagnosis;
mod report;
mod standard_tests;

pub use diagnosis::{
    reportable, Candidate, Diagnosis, Gap, GapRegion, LookAlike, NominalFit, ParamCorrection,
    RegionAxis, ResidualEvidence, Verdict,
};
pub use report::{
    render_warnings, unphysical_param, IdentificationReport, MethodReport, ParamEstimate,
    Provenance,
};
pub use standard_tests::{LockedRotorRow, NoLoadRow, StandardTestTables, XmCurve};

/// The contract version this motorbench writes.
///
/// Version 2 changed only the MCAP record (wall-clock `log_time`, events
/// in Foxglove's log shape; see `docs/data-contract.md`); a report's JSON
/// is the same in both but for its `schema_version`.
pub const SCHEMA_VERSION: &str = "2";

/// Every contract version this motorbench reads, oldest first: a record
/// written under any of them replays.
pub const READ_SCHEMA_VERSIONS: [&str; 2] = ["1", "2"];
