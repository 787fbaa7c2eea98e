//! The identification report as the data contract defines it
//! (`motorbench identify … --json`, `/bench/result`), with motorbench's
//! additive keys (`diagnosis`, `provenance`, `standard_tests`).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::{Diagnosis, StandardTestTables, SCHEMA_VERSION};

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

/// Units whose quantity is positive: a resistance, inductance or
/// reactance, an inertia, a torque constant.
const POSITIVE_UNITS: [&str; 4] = ["ohm", "H", "kg*m^2", "V*s/rad"];

/// Units whose quantity is never negative: a friction or load torque, a
/// viscous friction coefficient, a loss (friction and windage, core loss).
const NON_NEGATIVE_UNITS: [&str; 3] = ["N*m", "N*m*s/rad", "W"];

impl ParamEstimate {
    /// Why this estimate of `name` lies outside the physical range its
    /// unit implies (not a finite number; a resistance at or below 0; a
    /// friction torque below 0), if it does.
    pub fn unphysical(&self, name: &str) -> Option<String> {
        let unit = self.unit.as_str();
        let v = self.value;
        if !v.is_finite() {
            Some(format!("{name} = {v} {unit}, not a finite number"))
        } else if POSITIVE_UNITS.contains(&unit) && v <= 0.0 {
            Some(format!("{name} = {v:.4e} {unit}, not above 0"))
        } else if NON_NEGATIVE_UNITS.contains(&unit) && v < 0.0 {
            Some(format!("{name} = {v:.4e} {unit}, below 0"))
        } else {
            None
        }
    }
}

/// The first of `params` outside its physical range, named.
pub fn unphysical_param(params: &BTreeMap<String, ParamEstimate>) -> Option<String> {
    params.iter().find_map(|(name, p)| p.unphysical(name))
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
    /// What the rig warned of while the test ran (the record's warning
    /// events, each with its test time): a level that did not settle, an
    /// encoder that disagrees with the dynamometer, a safe-state command
    /// that failed. Read from the record, not computed by the analysis. An
    /// additive extension of the contract; absent where there were none
    /// (and on CSV data, which has no events).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub test_warnings: Vec<String>,
    /// The sim-to-real diagnosis, when one was run (`run`, `replay`; not
    /// `identify`). The contract's `/bench/result` is "the identification
    /// (and diagnosis) report".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diagnosis: Option<Box<Diagnosis>>,
    /// Where the report comes from, when it comes from a test (`run`, the
    /// daemon, `replay`): an additive extension of the contract.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<Provenance>,
    /// The tables of the induction machine's classical reduction (method
    /// `standard_tests`), when the record holds a no-load or locked-rotor
    /// test: an additive extension of the contract.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub standard_tests: Option<StandardTestTables>,
    /// `true` on the identification a test records as `/bench/result` as
    /// soon as it exists, before its diagnosis runs: the record's last
    /// `/bench/result` is then the whole report (with the diagnosis), and
    /// this one stays only if the process died before it. An additive
    /// extension of the contract; absent (`false`) on every other report.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub diagnosis_pending: bool,
}

/// Where a report comes from: the motor, the test's start, the record and
/// the files written beside it, the motorbench that wrote it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The motor's id (the record's `motorbench.test` metadata).
    pub motor_id: String,
    /// When the test started, RFC 3339 (the record's metadata).
    pub started_at: String,
    /// The record's file name.
    pub record: String,
    /// The files written beside the record with this report (report,
    /// plots), by name; empty for a replay.
    pub files: Vec<String>,
    /// The version of motorbench that made this report.
    pub motorbench_version: String,
}

impl Provenance {
    /// The provenance of a report on `record` (a file name) of the test
    /// of `motor_id` started at `started_at`, with `files` written beside
    /// it.
    pub fn new(motor_id: &str, started_at: &str, record: &str, files: Vec<String>) -> Provenance {
        Provenance {
            motor_id: motor_id.to_string(),
            started_at: started_at.to_string(),
            record: record.to_string(),
            files,
            motorbench_version: env!("CARGO_PKG_VERSION").to_string(),
        }
    }
}

/// The warnings of `report` for a person: the analysis' own, then what the
/// rig warned of during the test (nothing when it has neither).
pub fn render_warnings(out: &mut String, report: &IdentificationReport) {
    use std::fmt::Write;
    for (title, list) in [
        ("warnings", &report.warnings),
        ("warnings during the test", &report.test_warnings),
    ] {
        if !list.is_empty() {
            let _ = writeln!(out, "\n{title}:");
            for w in list {
                let _ = writeln!(out, "  - {w}");
            }
        }
    }
}

#[cfg(test)]
impl IdentificationReport {
    /// A `dc_step` report whose best method, `output_error`, holds
    /// `params` (key, value, unit) without intervals: what the checks of
    /// a best method's values read.
    pub(crate) fn with_best_params(params: &[(&str, f64, &str)]) -> IdentificationReport {
        let params = params
            .iter()
            .map(|&(key, value, unit)| {
                let estimate = ParamEstimate {
                    value,
                    ci95: None,
                    unit: unit.into(),
                };
                (key.to_string(), estimate)
            })
            .collect();
        let mut report = IdentificationReport::new("dc_step");
        report.methods.insert(
            "output_error".into(),
            MethodReport::fitted(params, Some(0.01)),
        );
        report.best = Some("output_error".into());
        report
    }
}

impl IdentificationReport {
    /// The parameters of the best method, where there is one.
    pub fn best_params(&self) -> Option<&BTreeMap<String, ParamEstimate>> {
        self.methods.get(self.best.as_deref()?)?.params.as_ref()
    }

    /// An empty report of `kind`.
    pub fn new(kind: &str) -> IdentificationReport {
        IdentificationReport {
            schema_version: SCHEMA_VERSION.to_string(),
            kind: kind.to_string(),
            methods: BTreeMap::new(),
            best: None,
            warnings: Vec::new(),
            test_warnings: Vec::new(),
            diagnosis: None,
            provenance: None,
            standard_tests: None,
            diagnosis_pending: false,
        }
    }

    /// Every method whose parameters leave their physical range is made
    /// not to apply, with the parameter named: the record does not meet
    /// that method's assumptions, and a negative resistance or friction is
    /// no answer. Call before choosing `best`.
    /// An interval with a bound that is not a finite number is dropped
    /// (the parameter's interval is then undetermined, `ci95: null`); one
    /// that reaches below 0 for a quantity that cannot (a resistance, an
    /// inductance, a friction: a symmetric interval of a poorly
    /// determined estimate) is cut at 0, the interval within the
    /// physical range.
    pub fn refuse_unphysical(&mut self) {
        for method in self.methods.values_mut() {
            for p in method.params.iter_mut().flat_map(|ps| ps.values_mut()) {
                if p.ci95.is_some_and(|ci| !ci.iter().all(|b| b.is_finite())) {
                    p.ci95 = None;
                }
                let unit = p.unit.as_str();
                if POSITIVE_UNITS.contains(&unit) || NON_NEGATIVE_UNITS.contains(&unit) {
                    if let Some(ci) = p.ci95.as_mut() {
                        ci[0] = ci[0].max(0.0);
                    }
                }
            }
            let Some(why) = method.params.as_ref().and_then(unphysical_param) else {
                continue;
            };
            *method = MethodReport::not_applicable(format!(
                "the fit gives {why}, outside its physical range: the record does not \
                 meet this method's assumptions"
            ));
        }
    }

    /// A held-out NRMSE is a score only below 1 (the held-out data's own
    /// mean scores 1): a method whose model, fitted without the held-out
    /// data, predicts them worse than their mean gets no
    /// `validation_nrmse`, and a warning gives the number and what it
    /// means. Its parameters stay, as what the fitting data give. Returns
    /// the methods it unscored, for [`IdentificationReport::warn_if_best_failed`].
    pub fn unscore_failed_predictions(&mut self) -> Vec<String> {
        let mut failed = Vec::new();
        for (name, method) in &mut self.methods {
            let Some(v) = method
                .validation_nrmse
                .filter(|v| !(v.is_finite() && *v < 1.0))
            else {
                continue;
            };
            self.warnings.push(format!(
                "{name}: held-out NRMSE {v:.3e}, not reported as a score: the model fitted \
                 without the held-out data predicts them worse than their own mean (a model \
                 that misfits this record, or held-out data unlike the rest)"
            ));
            method.validation_nrmse = None;
            failed.push(name.clone());
        }
        failed
    }

    /// Where the best method is one of `failed` (its model predicted the
    /// held-out data worse than their mean), a warning says so beside the
    /// best: its values fit the record, but the record does not validate
    /// them.
    pub fn warn_if_best_failed(&mut self, failed: &[String]) {
        let Some(best) = self
            .best
            .as_deref()
            .filter(|b| failed.iter().any(|f| f == b))
        else {
            return;
        };
        self.warnings.push(format!(
            "best: {best}, though its model, fitted without the held-out data, predicts them \
             worse than their mean: its values fit this record, which does not validate them \
             (an effect the model lacks, which `motorbench diagnose` names where one of \
             its candidates explains the gap, or a machine the model does not describe)"
        ));
    }

    /// The report as JSON text (pretty, stable key order).
    pub fn to_json_pretty(&self) -> String {
        serde_json::to_string_pretty(self).expect("a report always serialises")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A held-out NRMSE of 1 or more (or not finite) is no score: it is
    /// left out with a warning naming the method and the number; one below
    /// 1 stays.
    #[test]
    fn a_prediction_worse_than_the_mean_is_no_score() {
        let mut report = IdentificationReport::with_best_params(&[("K", 0.05, "V*s/rad")]);
        let fitted = |v: f64| MethodReport::fitted(BTreeMap::new(), Some(v));
        report.methods.insert("equation_error".into(), fitted(8.37));
        report.methods.insert("moments".into(), fitted(f64::NAN));
        let failed = report.unscore_failed_predictions();
        assert_eq!(failed, ["equation_error", "moments"]);
        assert_eq!(report.methods["output_error"].validation_nrmse, Some(0.01));
        for name in ["equation_error", "moments"] {
            assert_eq!(report.methods[name].validation_nrmse, None, "{name}");
            assert!(
                report
                    .warnings
                    .iter()
                    .any(|w| w.starts_with(&format!("{name}: held-out NRMSE"))),
                "{:?}",
                report.warnings
            );
        }
        assert!(report.warnings.iter().any(|w| w.contains("8.370e0")));
    }

    /// A best method whose held-out prediction failed gets a warning
    /// beside the best; a best that was not unscored gets none.
    #[test]
    fn a_best_whose_prediction_failed_is_said_to_be_unvalidated() {
        let mut report = IdentificationReport::with_best_params(&[("K", 0.05, "V*s/rad")]);
        let said = |r: &IdentificationReport| {
            r.warnings
                .iter()
                .filter(|w| w.starts_with("best: output_error, though its model"))
                .count()
        };
        report.warn_if_best_failed(&["equation_error".into()]);
        assert_eq!(said(&report), 0, "{:?}", report.warnings);
        report.warn_if_best_failed(&["equation_error".into(), "output_error".into()]);
        assert_eq!(said(&report), 1, "{:?}", report.warnings);
    }

    #[test]
    fn a_method_outside_the_physical_range_does_not_apply() {
        let est = |value: f64, unit: &str| ParamEstimate {
            value,
            ci95: None,
            unit: unit.into(),
        };
        assert!(est(0.0, "ohm").unphysical("Ra").is_some());
        assert!(est(f64::NAN, "H").unphysical("La").is_some());
        assert!(est(f64::INFINITY, "N*m").unphysical("Tst").is_some());
        assert!(est(f64::INFINITY, "V").unphysical("dU").is_some());
        assert!(est(0.0, "N*m").unphysical("Tst").is_none());
        assert!(est(-1e-9, "N*m*s/rad").unphysical("f").is_some());
        assert!(est(-3.0, "V").unphysical("dU").is_none(), "V is signed");
        let mut r = IdentificationReport::new("dc_step");
        let method = |params: Vec<(&str, ParamEstimate)>| MethodReport {
            applies: true,
            params: Some(
                params
                    .into_iter()
                    .map(|(k, v)| (k.to_string(), v))
                    .collect(),
            ),
            validation_nrmse: Some(0.01),
            reason: None,
        };
        r.methods.insert(
            "steady_state".into(),
            method(vec![("Ra", est(-0.99, "ohm")), ("K", est(1.3, "V*s/rad"))]),
        );
        let mut wide = est(30.9, "ohm");
        wide.ci95 = Some([30.0, f64::INFINITY]);
        r.methods
            .insert("moments".into(), method(vec![("Ra", wide)]));
        r.refuse_unphysical();
        let refused = &r.methods["steady_state"];
        assert!(!refused.applies && refused.params.is_none());
        assert!(refused
            .reason
            .as_deref()
            .unwrap()
            .contains("Ra = -9.9000e-1 ohm"));
        assert!(r.methods["moments"].applies);
        let ra = &r.methods["moments"].params.as_ref().unwrap()["Ra"];
        assert_eq!(ra.ci95, None, "an unbounded interval is undetermined");
    }

    #[test]
    fn an_interval_below_zero_is_cut_at_zero_where_the_quantity_cannot_go() {
        let est = |value: f64, ci: [f64; 2], unit: &str| ParamEstimate {
            value,
            ci95: Some(ci),
            unit: unit.into(),
        };
        let mut r = IdentificationReport::new("dc_step");
        let params = BTreeMap::from([
            ("Ra".to_string(), est(0.258, [-10.892, 11.408], "ohm")),
            ("f".to_string(), est(1e-6, [-2e-6, 4e-6], "N*m*s/rad")),
            ("dU".to_string(), est(0.5, [-1.0, 2.0], "V")),
            ("K".to_string(), est(1.3, [1.2, 1.4], "V*s/rad")),
        ]);
        r.methods
            .insert("steady_state".into(), MethodReport::fitted(params, None));
        r.refuse_unphysical();
        let p = r.methods["steady_state"].params.as_ref().unwrap();
        assert_eq!(p["Ra"].ci95, Some([0.0, 11.408]));
        assert_eq!(p["f"].ci95, Some([0.0, 4e-6]));
        assert_eq!(p["dU"].ci95, Some([-1.0, 2.0]), "a voltage is signed");
        assert_eq!(p["K"].ci95, Some([1.2, 1.4]));
    }

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
        assert_eq!(v["schema_version"], "2");
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
