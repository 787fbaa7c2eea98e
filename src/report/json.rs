//! The identification report as the data contract defines it
//! (`motorbench identify … --json`, `/bench/result`).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::diagnose::Diagnosis;
use crate::record::SCHEMA_VERSION;

/// One identified parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamEstimate {
    /// Estimate, SI.
    pub value: f64,
    /// 95 % confidence interval, or null where the method gives none.
    pub ci95: Option<[f64; 2]>,
    /// Unit, e.g. `ohm`.
    pub unit: String,
}

/// One method's result: parameters, or why it does not apply.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MethodReport {
    /// Whether the method applies to the data.
    pub applies: bool,
    /// Parameters by contract key (`Ra`, `K`, …), when it applies.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub params: Option<BTreeMap<String, ParamEstimate>>,
    /// NRMSE on segments the method was not fitted on; absent where it
    /// could not be computed (too few segments).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validation_nrmse: Option<f64>,
    /// Why the method does not apply.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

impl MethodReport {
    /// A method that applies: its parameters and its held-out score.
    pub fn fitted(
        params: BTreeMap<String, ParamEstimate>,
        validation_nrmse: Option<f64>,
    ) -> MethodReport {
        MethodReport {
            applies: true,
            params: Some(params),
            validation_nrmse,
            reason: None,
        }
    }

    /// A method that does not apply, and why.
    pub fn not_applicable(reason: impl Into<String>) -> MethodReport {
        MethodReport {
            applies: false,
            params: None,
            validation_nrmse: None,
            reason: Some(reason.into()),
        }
    }
}

/// The whole identification report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IdentificationReport {
    /// Contract version.
    pub schema_version: String,
    /// Test kind, e.g. `dc_step`.
    pub kind: String,
    /// Results by method key (`steady_state`, …).
    pub methods: BTreeMap<String, MethodReport>,
    /// The method whose parameters to use, if any applies.
    pub best: Option<String>,
    /// Things a user should know about the data or the fit.
    pub warnings: Vec<String>,
    /// The sim-to-real diagnosis, when one was run (`run`, `replay`; not
    /// `identify`). The contract's `/bench/result` is "the identification
    /// (and diagnosis) report".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diagnosis: Option<Box<Diagnosis>>,
}

impl IdentificationReport {
    /// An empty report of `kind`.
    pub fn new(kind: &str) -> IdentificationReport {
        IdentificationReport {
            schema_version: SCHEMA_VERSION.to_string(),
            kind: kind.to_string(),
            methods: BTreeMap::new(),
            best: None,
            warnings: Vec::new(),
            diagnosis: None,
        }
    }

    /// The report as JSON text (pretty, stable key order).
    pub fn to_json_pretty(&self) -> String {
        serde_json::to_string_pretty(self).expect("a report always serialises")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serialises_like_the_contract_example() {
        let mut r = IdentificationReport::new("dc_step");
        let params = BTreeMap::from([(
            "Ra".to_string(),
            ParamEstimate {
                value: 30.9,
                ci95: Some([30.1, 31.7]),
                unit: "ohm".into(),
            },
        )]);
        r.methods.insert(
            "output_error".into(),
            MethodReport {
                applies: true,
                params: Some(params),
                validation_nrmse: Some(0.0),
                reason: None,
            },
        );
        r.methods.insert(
            "pasek".into(),
            MethodReport::not_applicable("complex poles"),
        );
        r.best = Some("output_error".into());
        let v: serde_json::Value = serde_json::from_str(&r.to_json_pretty()).unwrap();
        assert_eq!(v["schema_version"], "1");
        assert_eq!(
            v["methods"]["output_error"]["params"]["Ra"]["ci95"][1],
            31.7
        );
        assert_eq!(
            v["methods"]["pasek"],
            serde_json::json!({"applies": false, "reason": "complex poles"})
        );
        let back: IdentificationReport = serde_json::from_value(v).unwrap();
        assert_eq!(back, r);
    }
}
