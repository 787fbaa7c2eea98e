//! The blind benchmark: records simulated with one withheld effect (or
//! none) at random magnitudes, noise and quantisation levels, with the
//! truth kept apart from the record so that the diagnosis never sees it.
//!
//! - each machine simulates its own cases: `machine/dc/blind_case.rs` and
//!   `machine/im/blind_case.rs` one record each; `machine/dc/blind_plan.rs`
//!   a DC case's test plan and sensors (the classic settled staircase, or
//!   a wide draw of plans, holds, damping and sensors).
//! - [`CaseTruth`]: what was withheld; written to a separate truth file.
//! - `suite`: the case plan, the suite directory, the truth file.
//! - `score`: diagnose every case from its files, then compare with the truth.
//! - [`SuiteError`]: what went wrong, naming the suite's file.

mod error;
mod files;
mod score;
mod suite;

pub use crate::machine::dc::blind_case::{simulate_dc_case, simulate_dc_case_with};
pub use crate::machine::dc::blind_plan::{Coast, DcSetup, PlanKind, SpeedSensor};
pub use crate::machine::im::blind_case::simulate_im_case;
pub use error::SuiteError;
pub use files::write_case_files;
pub use score::{score_suite, CaseScore, SuiteScore, Tally};
pub use suite::{
    case_plan, generate_suite, suite_case, CaseEntry, Manifest, SuitePlans, TruthFile, DEFAULT_SEED,
};

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::record::Record;

/// What a blind case really holds. Never read by the diagnosis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseTruth {
    /// The withheld effect's vocabulary name, or `none`.
    pub effect: String,
    /// The effect's parameters (physical units), empty for `none`.
    pub effect_params: BTreeMap<String, f64>,
    /// The nominal parameters the record was simulated with, by contract key.
    pub nominal: BTreeMap<String, f64>,
    /// Standard deviation of the white noise added per channel.
    pub noise: BTreeMap<String, f64>,
    /// Quantisation step per channel (0 for none).
    pub quantisation: BTreeMap<String, f64>,
    /// The NRMSE a perfect model would reach: measured against the
    /// noise-free truth, averaged over channels as the contract defines a
    /// record's NRMSE, over all segments (or points).
    pub noise_floor: f64,
    /// Region labels (the contract's gap-region labels) where the effect
    /// should show most; empty for `none`.
    pub regions: Vec<String>,
    /// Who simulated the record: `motorbench` (this crate's generator) or
    /// a third-party simulator (e.g. `gym-electric-motor`).
    #[serde(default = "own_source")]
    pub source: String,
    /// The plan's name (`staircase`, `ramp`, `prbs`, `speed_loop`,
    /// `position_loop`; `sweep` for an IM slip sweep).
    #[serde(default = "staircase")]
    pub plan: String,
    /// The plan's and sensors' settings (hold in slowest time constants,
    /// damping ratio, encoder lines, ADC bits, ...), for reading a miss.
    #[serde(default)]
    pub setup: BTreeMap<String, f64>,
}

/// The source of this crate's own cases.
pub const OWN_SOURCE: &str = "motorbench";

fn own_source() -> String {
    OWN_SOURCE.to_string()
}

fn staircase() -> String {
    "staircase".to_string()
}

/// One simulated case: the record (all the diagnosis may read) and its truth.
#[derive(Debug, Clone, PartialEq)]
pub struct BlindRecord {
    /// The record.
    pub record: Record,
    /// The truth behind it.
    pub truth: CaseTruth,
}
