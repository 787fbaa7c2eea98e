//! What every test configuration holds, whatever its machine: the file it
//! came from, the motor's id and nameplate, the sample rate, `[limits]`,
//! `[supervisor]`, `[records]` and the faults injected on purpose.
//!
//! Each machine's schema reads its own tables (`[rig]`, `[test]`) and
//! hands the shared ones to [`RawCommon::validate`], so that the shared
//! keys are checked once, the same way for every machine, and the
//! session, the daemon and the CLI read them from one [`CommonConfig`].
//! The raw tables stay fields of each machine's raw file layout (not a
//! flattened struct): serde's `flatten` does not combine with
//! `deny_unknown_fields`, and unknown keys must be refused by name.

use serde::Deserialize;

use super::{
    invalid, validate_faults, ConfigError, FaultPlan, FaultRig, Limits, RawFault, RawRetention,
    RawSupervisor, Retention, Supervision,
};

/// The validated keys every test configuration holds.
#[derive(Debug, Clone, PartialEq)]
pub struct CommonConfig {
    /// Where it came from (a path, or the embedded default's name).
    pub source: String,
    /// The text as given (recorded in the MCAP metadata).
    pub text: String,
    /// Motor id (`motor.id`).
    pub motor_id: String,
    /// Nameplate as a JSON object (`[motor.nameplate]`).
    pub nameplate: serde_json::Value,
    /// Samples per second of the sensors (the poll rate behind Modbus), Hz.
    pub sample_rate_hz: f64,
    /// The test's limits (`[limits]`).
    pub limits: Limits,
    /// What the safety supervisor enforces beyond `limits`
    /// (`[supervisor]`).
    pub supervision: Supervision,
    /// How long the daemon keeps this rig's records (`[records]`).
    pub retention: Retention,
    /// The faults injected on purpose (`[[fault]]`); empty on a real test.
    pub faults: FaultPlan,
}

/// `[motor]`: the machine under test.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMotor {
    /// `motor.id`.
    pub id: String,
    /// `[motor.nameplate]`: free keys; each machine reads the ones it
    /// needs.
    #[serde(default)]
    pub nameplate: toml::Table,
}

/// A test configuration file as read, for either machine: the shared
/// tables and the machine's own (`S` the rig's `[rig.simulated]`, `M` its
/// `[rig.modbus]`, `L` the `[limits]`, `T` the `[test]`). One layout, so
/// that the machines' files cannot drift apart.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFile<S, M, L, T> {
    /// `[motor]`.
    pub motor: RawMotor,
    /// `[rig]`.
    pub rig: RawRig<S, M>,
    /// `[limits]`.
    pub limits: L,
    /// `[test]`.
    pub test: T,
    /// `[supervisor]`.
    #[serde(default)]
    pub supervisor: RawSupervisor,
    /// `[records]`.
    #[serde(default)]
    pub records: RawRetention,
    /// `[[fault]]`.
    #[serde(default)]
    pub fault: Vec<RawFault>,
}

/// `[rig]` as read: the backend, the sample rate, and the machine's
/// simulated and Modbus tables.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRig<S, M> {
    /// `rig.backend`.
    pub backend: String,
    /// `rig.sample_rate_Hz`.
    #[serde(rename = "sample_rate_Hz")]
    pub sample_rate_hz: f64,
    /// `[rig.simulated]`.
    pub simulated: Option<S>,
    /// `[rig.modbus]`.
    pub modbus: Option<M>,
}

/// The shared tables of a file, as read.
pub(crate) struct RawCommon {
    /// `[motor]`.
    pub motor: RawMotor,
    /// `[supervisor]`.
    pub supervisor: RawSupervisor,
    /// `[records]`.
    pub records: RawRetention,
    /// `[[fault]]`.
    pub fault: Vec<RawFault>,
}

impl RawCommon {
    /// Validate the shared tables of `text` (from `source`) for a test
    /// at `sample_rate_hz` (validated by the machine, which needs it
    /// first) within `limits` (the machine fills in its defaults), on a
    /// rig that offers `rig` to the faults.
    pub(crate) fn validate(
        self,
        source: &str,
        text: &str,
        sample_rate_hz: f64,
        limits: Limits,
        rig: FaultRig<'_>,
    ) -> Result<CommonConfig, ConfigError> {
        if self.motor.id.trim().is_empty() {
            return Err(invalid(source, "motor.id", "must not be empty"));
        }
        let nameplate = serde_json::to_value(&self.motor.nameplate)
            .map_err(|e| invalid(source, "motor.nameplate", e.to_string()))?;
        let supervision = self.supervisor.validate(source, &limits, &nameplate)?;
        let retention = self.records.validate(source)?;
        let faults = validate_faults(source, self.fault, rig)?;
        Ok(CommonConfig {
            source: source.to_string(),
            text: text.to_string(),
            motor_id: self.motor.id,
            nameplate,
            sample_rate_hz,
            limits,
            supervision,
            retention,
            faults,
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::config::{TestConfig, DEFAULT_CONFIG};

    const SIM_IM: &str = include_str!("../../config/sim-im.toml");

    /// The shared keys are checked once for every machine: an empty
    /// motor id was refused in a DC file and taken in an induction
    /// machine's before they were.
    #[test]
    fn every_machine_refuses_an_empty_motor_id_by_key_and_line() {
        for (name, text) in [("dc.toml", DEFAULT_CONFIG), ("im.toml", SIM_IM)] {
            let id = text
                .lines()
                .find(|l| l.starts_with("id = "))
                .unwrap_or_else(|| panic!("{name} has no motor id"));
            let blank = text.replacen(id, "id = \" \"", 1);
            let err = TestConfig::parse(name, &blank).unwrap_err().to_string();
            let line = blank.lines().position(|l| l == "id = \" \"").unwrap() + 1;
            assert!(err.contains("motor.id"), "{name}: {err}");
            assert!(err.contains("must not be empty"), "{name}: {err}");
            assert!(err.starts_with(&format!("{name}:{line}")), "{name}: {err}");
        }
    }

    #[test]
    fn the_shared_keys_read_the_same_for_every_machine() {
        let dc = TestConfig::parse("dc.toml", DEFAULT_CONFIG).unwrap();
        let im = TestConfig::parse("im.toml", SIM_IM).unwrap();
        for (cfg, source, text) in [(&dc, "dc.toml", DEFAULT_CONFIG), (&im, "im.toml", SIM_IM)] {
            let c = cfg.common();
            assert_eq!(c.source, source);
            assert_eq!(c.text, text);
            assert!(c.nameplate.is_object(), "{source}");
            assert!(c.sample_rate_hz > 0.0, "{source}");
            assert!(c.faults.is_empty(), "{source}");
        }
    }
}
