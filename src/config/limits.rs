//! The `[limits]` table: the magnitudes that abort any test (the DC
//! machine's armature, the induction machine's line quantities).

use serde::Deserialize;

/// Test limits: crossing one aborts the test and makes the rig safe.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Largest armature voltage magnitude, V.
    #[serde(rename = "max_voltage_V")]
    pub max_voltage: f64,
    /// Largest armature current magnitude, A.
    #[serde(rename = "max_current_A")]
    pub max_current: f64,
    /// Largest speed magnitude, rad/s.
    #[serde(rename = "max_speed_rad_s")]
    pub max_speed: f64,
}
