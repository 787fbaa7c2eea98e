//! The `[test.dc_resistance]`, `[test.no_load]` and `[test.locked_rotor]`
//! tables (the last with the optional locked-rotor test at reduced
//! frequency: `reduced_frequency_Hz`, `reduced_voltages_V`) of an
//! `im_standard_tests` configuration, validated into a
//! [`StandardTestsPlan`]: every key optional, its default from the
//! nameplate ([`StandardTestsPlan::from_nameplate`]); errors name the key.

use serde::Deserialize;

use super::{ReducedFrequencyTest, StandardTestsPlan};
use crate::bounds;

/// `[test.dc_resistance]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDcResistance {
    /// DC currents between two line terminals, A.
    #[serde(rename = "currents_A")]
    currents: Option<Vec<f64>>,
}

/// `[test.no_load]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawNoLoad {
    /// Line voltages, V, run from the highest down.
    #[serde(rename = "voltages_V")]
    voltages: Option<Vec<f64>>,
}

/// `[test.locked_rotor]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLockedRotor {
    /// Line voltages, V, run from the lowest up.
    #[serde(rename = "voltages_V")]
    voltages: Option<Vec<f64>>,
    /// Stop stepping up once the line current passes this, A.
    #[serde(rename = "max_current_A")]
    max_current: Option<f64>,
    /// A second locked-rotor test at this supply frequency, Hz.
    #[serde(rename = "reduced_frequency_Hz")]
    reduced_frequency: Option<f64>,
    /// Its line voltages, V, run from the lowest up.
    #[serde(rename = "reduced_voltages_V")]
    reduced_voltages: Option<Vec<f64>>,
}

/// The standard tests' tables as given (each may be left out).
#[derive(Debug, Default)]
pub(super) struct RawStandardTests<'a> {
    pub dc_resistance: Option<&'a RawDcResistance>,
    pub no_load: Option<&'a RawNoLoad>,
    pub locked_rotor: Option<&'a RawLockedRotor>,
}

impl RawStandardTests<'_> {
    /// The first table given, by its key (for a plan that takes none).
    pub fn first_given(&self) -> Option<&'static str> {
        [
            (self.dc_resistance.is_some(), "test.dc_resistance"),
            (self.no_load.is_some(), "test.no_load"),
            (self.locked_rotor.is_some(), "test.locked_rotor"),
        ]
        .into_iter()
        .find_map(|(given, key)| given.then_some(key))
    }

    /// The plan for a machine rated `line_voltage`, `line_current` and
    /// `frequency`, the supply's voltages up to `max_voltage`, currents up
    /// to `max_current` (the test's limit); `Err((key, why))`.
    pub fn validate(
        &self,
        line_voltage: f64,
        line_current: f64,
        frequency: f64,
        max_voltage: f64,
        max_current: f64,
    ) -> Result<StandardTestsPlan, (String, String)> {
        let mut plan = StandardTestsPlan::from_nameplate(line_voltage, line_current);
        let list = |key: &str, given: Option<&Vec<f64>>, top: f64, unit: &str| match given {
            None => Ok(None),
            Some(v) => {
                let bad = (
                    key.to_string(),
                    format!("must be a non-empty list in (0, {top:.1}] {unit}"),
                );
                if v.is_empty() || v.iter().any(|x| !(x.is_finite() && *x > 0.0 && *x <= top)) {
                    return Err(bad);
                }
                bounds::count(v.len(), bounds::MAX_LEVELS)
                    .map_err(|why| (key.to_string(), why.to_string()))?;
                Ok(Some(v.clone()))
            }
        };
        if let Some(v) = list(
            "test.dc_resistance.currents_A",
            self.dc_resistance.and_then(|t| t.currents.as_ref()),
            line_current,
            "A (at most rated current)",
        )? {
            plan.dc_currents = v;
        }
        let no_load = self.no_load.and_then(|t| t.voltages.as_ref());
        if let Some(v) = list("test.no_load.voltages_V", no_load, max_voltage, "V")? {
            plan.no_load_voltages = v;
        }
        let locked = self.locked_rotor.and_then(|t| t.voltages.as_ref());
        if let Some(v) = list("test.locked_rotor.voltages_V", locked, max_voltage, "V")? {
            plan.locked_rotor_voltages = v;
        }
        if let Some(a) = self.locked_rotor.and_then(|t| t.max_current) {
            if !(a.is_finite() && a > 0.0 && a < max_current) {
                return Err((
                    "test.locked_rotor.max_current_A".into(),
                    format!("{a} must be in (0, {max_current}) A, below limits.max_current_A"),
                ));
            }
            plan.locked_rotor_max_current = a;
        }
        let reduced_voltages = self.locked_rotor.and_then(|t| t.reduced_voltages.as_ref());
        match self.locked_rotor.and_then(|t| t.reduced_frequency) {
            Some(f) => {
                if !(f.is_finite() && f > 0.0 && f < frequency) {
                    return Err((
                        "test.locked_rotor.reduced_frequency_Hz".into(),
                        format!(
                            "{f} must be in (0, {frequency}) Hz, below the rated frequency \
                             (IEEE 112: at most 25 %, {} Hz)",
                            0.25 * frequency
                        ),
                    ));
                }
                let mut test = ReducedFrequencyTest::from_nameplate(line_voltage, f);
                let key = "test.locked_rotor.reduced_voltages_V";
                if let Some(v) = list(key, reduced_voltages, max_voltage, "V")? {
                    test.voltages = v;
                }
                plan.reduced_frequency = Some(test);
            }
            None if reduced_voltages.is_some() => {
                return Err((
                    "test.locked_rotor.reduced_voltages_V".into(),
                    "is for a test at reduced frequency: give reduced_frequency_Hz".into(),
                ))
            }
            None => {}
        }
        if plan
            .no_load_voltages
            .iter()
            .chain(&plan.locked_rotor_voltages)
            .any(|v| *v > max_voltage)
        {
            return Err((
                "test.no_load.voltages_V".into(),
                format!("the defaults reach {:.1} V, above the supply's {max_voltage:.1} V: give the voltages", 1.1 * line_voltage),
            ));
        }
        Ok(plan)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn left_out_keys_take_the_nameplate_defaults_and_bad_ones_are_named() {
        let none = RawStandardTests::default();
        assert_eq!(none.first_given(), None);
        let plan = none.validate(400.0, 8.0, 50.0, 440.0, 70.0).unwrap();
        assert_eq!(plan, StandardTestsPlan::from_nameplate(400.0, 8.0));

        let dc = RawDcResistance {
            currents: Some(vec![1.0, 9.0]),
        };
        let given = RawStandardTests {
            dc_resistance: Some(&dc),
            ..Default::default()
        };
        assert_eq!(given.first_given(), Some("test.dc_resistance"));
        let (key, why) = given.validate(400.0, 8.0, 50.0, 440.0, 70.0).unwrap_err();
        assert_eq!(key, "test.dc_resistance.currents_A");
        assert!(why.contains("8.0"), "{why}");

        let lr = RawLockedRotor {
            voltages: Some(vec![20.0, 40.0]),
            max_current: Some(80.0),
            ..Default::default()
        };
        let given = RawStandardTests {
            locked_rotor: Some(&lr),
            ..Default::default()
        };
        let (key, _) = given.validate(400.0, 8.0, 50.0, 440.0, 70.0).unwrap_err();
        assert_eq!(key, "test.locked_rotor.max_current_A");
        // The reduced-frequency test: its default voltages from the
        // nameplate, a frequency at or above rated refused, voltages
        // without a frequency refused.
        let lr = RawLockedRotor {
            reduced_frequency: Some(12.5),
            ..Default::default()
        };
        let given = RawStandardTests {
            locked_rotor: Some(&lr),
            ..Default::default()
        };
        let plan = given.validate(400.0, 8.0, 50.0, 440.0, 70.0).unwrap();
        assert_eq!(
            plan.reduced_frequency,
            Some(ReducedFrequencyTest::from_nameplate(400.0, 12.5))
        );
        for (f, voltages, key) in [
            (Some(50.0), None, "test.locked_rotor.reduced_frequency_Hz"),
            (
                None,
                Some(vec![10.0]),
                "test.locked_rotor.reduced_voltages_V",
            ),
            (
                Some(12.5),
                Some(vec![]),
                "test.locked_rotor.reduced_voltages_V",
            ),
        ] {
            let lr = RawLockedRotor {
                reduced_frequency: f,
                reduced_voltages: voltages,
                ..Default::default()
            };
            let given = RawStandardTests {
                locked_rotor: Some(&lr),
                ..Default::default()
            };
            let (k, _) = given.validate(400.0, 8.0, 50.0, 440.0, 70.0).unwrap_err();
            assert_eq!(k, key);
        }
        // A supply below the default no-load voltages.
        let (key, _) = none.validate(400.0, 8.0, 50.0, 400.0, 70.0).unwrap_err();
        assert_eq!(key, "test.no_load.voltages_V");
    }
}
