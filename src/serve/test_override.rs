//! A start request may override the rig configuration's `[test]` table
//! (the plan, its levels, the settle rules): the request's keys replace
//! the configuration's, and the result is validated like any
//! configuration file, so a bad override is refused with the key named.

use crate::config::{Config, ConfigError};
use crate::machine::im::ImRunConfig;

/// Keys that describe one plan; a request naming a `plan` drops the
/// configuration's ones so they cannot clash with the new plan.
const PLAN_KEYS: [&str; 3] = ["levels_V", "coastdown", "coastdown_from_V"];

/// `cfg` with `test` (a JSON object with the keys of `[test]`) applied.
/// The configuration text of the result (recorded in the MCAP) is the
/// resolved TOML.
pub fn with_test_override(
    cfg: &Config,
    test: &serde_json::Map<String, serde_json::Value>,
) -> Result<Config, ConfigError> {
    let source = format!("{} with the request's [test]", cfg.common.source);
    let text = merged_text(&cfg.common.text, test, &source, &PLAN_KEYS)?;
    Config::parse_composed(&source, &text)
}

/// An induction-machine sweep configuration with `test` applied, as
/// [`with_test_override`] does for a DC one (profile paths stay relative
/// to the configuration's own directory).
pub fn with_im_test_override(
    cfg: &ImRunConfig,
    test: &serde_json::Map<String, serde_json::Value>,
) -> Result<ImRunConfig, ConfigError> {
    let source = format!("{} with the request's [test]", cfg.common.source);
    let text = merged_text(&cfg.common.text, test, &source, &[])?;
    let dir = std::path::Path::new(&cfg.common.source)
        .parent()
        .unwrap_or(std::path::Path::new("."));
    ImRunConfig::parse_composed(&source, dir, &text)
}

/// `text` (a configuration) with the keys of `test` merged into its
/// `[test]` table (a request naming `plan` drops `plan_keys` first), as
/// TOML text.
fn merged_text(
    text: &str,
    test: &serde_json::Map<String, serde_json::Value>,
    source: &str,
    plan_keys: &[&str],
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
        for k in plan_keys {
            base.remove(*k);
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
    use super::*;
    use crate::config::Plan;
    use serde_json::json;

    fn apply(v: serde_json::Value) -> Result<Config, ConfigError> {
        with_test_override(&Config::embedded_default(), v.as_object().unwrap())
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
        let cfg = ImRunConfig::load(std::path::Path::new(path)).unwrap();
        let t = json!({"points": 8, "voltages_V": [300], "settle": {"average_samples": 20}});
        let c = with_im_test_override(&cfg, t.as_object().unwrap()).unwrap();
        assert_eq!(c.plan.slips.len(), 8);
        assert_eq!(c.plan.voltages, vec![300.0]);
        assert_eq!(c.plan.average_samples, 20);
        assert_eq!(c.plan.settle_window, 25, "other settle keys kept");
        assert!(
            c.modbus.is_some(),
            "profiles found beside the configuration"
        );
        let e = with_im_test_override(&cfg, json!({"points": 2}).as_object().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("test.points") && e.contains("request"), "{e}");
        let e = with_im_test_override(&cfg, json!({"plan": "dc_step"}).as_object().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("im_slip_sweep"), "{e}");
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
