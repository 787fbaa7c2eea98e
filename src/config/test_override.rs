//! A start request may override the rig configuration's `[test]` table
//! (the plan, its levels, the settle rules): the request's keys replace
//! the configuration's, and the result is validated like any
//! configuration file ([`super::TestConfig::with_test`]), so a bad
//! override is refused with the key named.

use super::ConfigError;

/// Keys that describe one plan; a request naming a `plan` drops the
/// configuration's ones so they cannot clash with the new plan.
const PLAN_KEYS: [&str; 3] = ["levels_V", "coastdown", "coastdown_from_V"];

/// `text` (a configuration) with the keys of `test` merged into its
/// `[test]` table (a request naming `plan` drops the [`PLAN_KEYS`] first),
/// as TOML text; `source` names the result in errors.
pub(crate) fn merged_test(
    text: &str,
    test: &serde_json::Map<String, serde_json::Value>,
    source: &str,
) -> Result<String, ConfigError> {
    let invalid = |key: String, reason: String| ConfigError::Invalid {
        line: None,
        path: source.to_string(),
        key,
        reason,
    };
    let mut doc: toml::Table = toml::from_str(text).map_err(|e| {
        invalid(
            "test".into(),
            format!("the configuration text does not parse again: {e}"),
        )
    })?;
    let base = doc
        .entry("test")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    let Some(base) = base.as_table_mut() else {
        return Err(invalid("test".into(), "is not a table".into()));
    };
    if test.contains_key("plan") {
        for k in PLAN_KEYS {
            base.remove(k);
        }
    }
    for (key, value) in test {
        let value = toml::Value::try_from(value).map_err(|e| {
            invalid(
                format!("test.{key}"),
                format!("cannot be a TOML value: {e}"),
            )
        })?;
        match (base.get_mut(key), value) {
            (Some(toml::Value::Table(old)), toml::Value::Table(new)) => {
                for (k, v) in new {
                    old.insert(k, v);
                }
            }
            (_, value) => {
                base.insert(key.clone(), value);
            }
        }
    }
    toml::to_string(&doc).map_err(|e| invalid("test".into(), e.to_string()))
}

#[cfg(test)]
mod tests {
    use crate::config::{Config, ConfigError, Plan, TestConfig};
    use crate::machine::im::ImRunConfig;
    use serde_json::json;

    fn apply(v: serde_json::Value) -> Result<Config, ConfigError> {
        let dc = TestConfig::Dc(Box::new(Config::embedded_default()));
        match dc.with_test(v.as_object().unwrap())? {
            TestConfig::Dc(c) => Ok(*c),
            TestConfig::Im(_) => panic!("a DC rig's configuration became an IM one"),
        }
    }

    fn apply_im(cfg: &TestConfig, v: serde_json::Value) -> Result<ImRunConfig, ConfigError> {
        match cfg.with_test(v.as_object().unwrap())? {
            TestConfig::Im(c) => Ok(*c),
            TestConfig::Dc(_) => panic!("an IM rig's configuration became a DC one"),
        }
    }

    #[test]
    fn levels_and_settle_rules_are_replaced() {
        let c =
            apply(json!({"levels_V": [60, 248], "coastdown": false, "settle": {"hold_s": 0.2}}))
                .unwrap();
        assert_eq!(
            c.plan,
            Plan::DcStep {
                levels: vec![60.0, 248.0],
                coastdown: false
            }
        );
        assert_eq!(c.settle.hold_s, 0.2);
        assert_eq!(c.settle.window_s, 0.1, "other settle keys kept");
        assert!(
            c.common.text.contains("levels_V = [60, 248]"),
            "{}",
            c.common.text
        );
    }

    #[test]
    fn a_new_plan_drops_the_old_plans_keys() {
        let c = apply(json!({"plan": "dc_coastdown", "coastdown_from_V": 200})).unwrap();
        assert_eq!(c.plan, Plan::DcCoastdown { from: 200.0 });
    }

    #[test]
    fn an_im_sweep_takes_its_own_test_keys() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-modbus-im.toml");
        let cfg = TestConfig::load(std::path::Path::new(path)).unwrap();
        let t = json!({"points": 8, "voltages_V": [300], "settle": {"average_samples": 20}});
        let c = apply_im(&cfg, t).unwrap();
        assert_eq!(c.plan.slips.len(), 8);
        assert_eq!(c.plan.voltages, vec![300.0]);
        assert_eq!(c.plan.average_samples, 20);
        assert_eq!(c.plan.settle_window, 25, "other settle keys kept");
        assert!(
            c.modbus.is_some(),
            "profiles found beside the configuration"
        );
        let e = apply_im(&cfg, json!({"points": 2}))
            .unwrap_err()
            .to_string();
        assert!(e.contains("test.points") && e.contains("request"), "{e}");
    }

    #[test]
    fn a_plan_of_another_machine_is_refused_by_key() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-im.toml");
        let im = TestConfig::load(std::path::Path::new(path)).unwrap();
        // The standard tests are the same machine's plan.
        let c = apply_im(&im, json!({"plan": "im_standard_tests"})).unwrap();
        assert!(c.standard.is_some());
        let e = apply_im(&im, json!({"plan": "dc_step"}))
            .unwrap_err()
            .to_string();
        assert!(e.contains("test.plan") && e.contains("request"), "{e}");
        assert!(
            e.contains("im_slip_sweep") && e.contains("induction"),
            "{e}"
        );
        let e = apply(json!({"plan": "im_slip_sweep"}))
            .unwrap_err()
            .to_string();
        assert!(e.contains("test.plan") && e.contains("dc_step"), "{e}");
    }

    #[test]
    fn bad_overrides_name_the_key() {
        let e = apply(json!({"levels_V": [60, 600]}))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("test.levels_V[1]") && e.contains("request"),
            "{e}"
        );
        let e = apply(json!({"levels": [60, 248]})).unwrap_err().to_string();
        assert!(e.contains("levels"), "{e}");
        let e = apply(json!({"coastdown": null})).unwrap_err().to_string();
        assert!(e.contains("test.coastdown"), "{e}");
    }
}
