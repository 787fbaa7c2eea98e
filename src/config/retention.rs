//! The `[records]` section: how long the daemon keeps records, by total
//! size and by age.

use serde::Deserialize;

use super::ConfigError;

/// Default size limit of a rig's records, GiB.
pub const DEFAULT_MAX_TOTAL_GIB: f64 = 20.0;

/// Raw `[records]` table.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRetention {
    #[serde(rename = "max_total_GiB")]
    max_total_gib: Option<f64>,
    max_age_days: Option<f64>,
}

/// The validated `[records]` section. The daemon deletes a rig's oldest
/// finished records (MCAP, report, plot) until both limits hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Retention {
    /// Largest total size of the rig's records, bytes.
    pub max_total_bytes: u64,
    /// Records older than this are deleted, s; `None`: no age limit.
    pub max_age_s: Option<f64>,
}

impl RawRetention {
    /// Validate; `source` names the file in errors.
    pub(crate) fn validate(self, source: &str) -> Result<Retention, ConfigError> {
        let invalid = |key: &str, reason: String| ConfigError::Invalid {
            line: None,
            path: source.to_string(),
            key: format!("records.{key}"),
            reason,
        };
        let gib = self.max_total_gib.unwrap_or(DEFAULT_MAX_TOTAL_GIB);
        if !(gib.is_finite() && gib > 0.0) {
            return Err(invalid(
                "max_total_GiB",
                format!("{gib} must be a finite number > 0"),
            ));
        }
        let max_age_s = match self.max_age_days {
            None => None,
            Some(d) if d.is_finite() && d > 0.0 => Some(d * 86_400.0),
            Some(d) => {
                return Err(invalid(
                    "max_age_days",
                    format!("{d} must be a finite number > 0 (leave it out for no age limit)"),
                ))
            }
        };
        Ok(Retention {
            max_total_bytes: (gib * 1024.0 * 1024.0 * 1024.0) as u64,
            max_age_s,
        })
    }
}
