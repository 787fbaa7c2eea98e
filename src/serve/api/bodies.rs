//! The API's request and answer bodies as types, so the OpenAPI document
//! (`/v1/openapi.json`, [`super::openapi`]) is generated from what the
//! handlers send and cannot drift from it.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::serve::jobs::{StopStatus, TestStatus};
use crate::serve::records_index::IndexEntry;
use crate::serve::state::{Latch, RigStatus};

/// An error answer: `{"error": CODE, "message": TEXT, …}`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ErrorBody {
    /// Machine-readable code (`not_found`, `busy`, `tripped`,
    /// `bad_request`, `unauthorized`, …).
    pub error: String,
    /// For a person.
    pub message: String,
    /// With `busy`: the running test's id.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub running_test: Option<String>,
    /// With `tripped`: the latched stop.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trip: Option<Latch>,
}

impl ErrorBody {
    /// An error with a code and a message only.
    pub fn new(error: &str, message: impl Into<String>) -> ErrorBody {
        ErrorBody {
            error: error.to_string(),
            message: message.into(),
            running_test: None,
            trip: None,
        }
    }
}

/// `GET /v1/health`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Health {
    /// False while a running test's supervisor is stuck or failed a
    /// safe-state command (then the answer is `503`).
    pub healthy: bool,
    /// The daemon's version.
    pub version: String,
    /// Rig names.
    pub rigs: Vec<String>,
}

/// `GET /v1/rigs`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct RigList {
    /// Every rig and its state.
    pub rigs: Vec<RigStatus>,
}

/// Body of a start request (optional).
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StartRequest {
    /// Keys of the configuration's `[test]` table that replace the
    /// configured ones (e.g. `{"levels_V": [60, 248], "coastdown": false}`).
    #[serde(default)]
    #[schema(value_type = Option<Object>)]
    pub test: Option<serde_json::Map<String, serde_json::Value>>,
}

/// `201` answer to a start.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Started {
    /// Test id.
    pub id: String,
    /// The rig.
    pub rig: String,
    /// The record's name (the test id).
    pub record: String,
    /// Path of the test's status.
    pub status: String,
    /// Path of the test's live feed.
    pub events: String,
}

/// `GET /v1/tests`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct TestList {
    /// The tests this daemon process has run, oldest first.
    pub tests: Vec<TestStatus>,
}

/// Answer to an abort.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Aborted {
    /// Test id.
    pub id: String,
    /// What the supervisor did.
    pub stop: StopStatus,
}

/// `GET /v1/records`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct RecordList {
    /// The index, newest first.
    pub records: Vec<IndexEntry>,
}
