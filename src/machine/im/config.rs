//! Configuration of an `im_slip_sweep` run (TOML, `config/sim-im.toml`
//! on the simulated induction-machine rig, `config/sim-modbus-im.toml`
//! behind Modbus), or of an `im_standard_tests` run (the same keys for
//! its load test, and the optional `[test.dc_resistance]`,
//! `[test.no_load]` and `[test.locked_rotor]` tables, see
//! `standard_config`; `config/sim-im-standard.toml`), validated.
//!
//! The file has the DC configuration's layout (`[motor]`, `[rig]`,
//! `[limits]`, `[test]`, the optional `[supervisor]` (its checks run
//! under `motorbench run` and the daemon alike) and `[records]`) with the induction machine's keys; a file whose
//! `test.plan` is `"im_slip_sweep"` is one of these (the one place that
//! tells is [`crate::config::TestConfig`]).
//! `rig.backend` is `"simulated"` or `"modbus"` (see
//! [`super::ImModbusRig`]). Unknown keys are refused; every error names the
//! file and the line or the key.

use serde::Deserialize;

use super::standard_config::{RawDcResistance, RawLockedRotor, RawNoLoad, RawStandardTests};
use super::{ImModbusRig, ImSweepPlan, SimImRigConfig, StandardTestsPlan};
use crate::bench::SafetyRules;
use crate::bounds;
use crate::config::{
    bounded, invalid, syntax_error, CommonConfig, ConfigError, FaultRig, Limits, RawCommon, RawFile,
};
use crate::excerpt::quoted;
use crate::identify::slip_grid;
use crate::model::{Connection, ImCircuit, ImModel, ImParam, ImSupply};

/// A validated sweep configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ImRunConfig {
    /// What every test configuration holds: the file, the motor, the
    /// sample rate (the poll rate behind Modbus), the limits the safety
    /// supervisor enforces (line voltage, line current, shaft speed),
    /// supervision, retention, faults.
    pub common: CommonConfig,
    /// The simulated rig (with `backend = "simulated"`, or served behind
    /// the Modbus links).
    pub simulated: Option<SimImRigConfig>,
    /// The Modbus devices (with `backend = "modbus"`).
    pub modbus: Option<ImModbusRig>,
    /// The test plan: the slip sweep (the load test of the standard set).
    pub plan: ImSweepPlan,
    /// The standard tests before the sweep (plan `im_standard_tests`).
    pub standard: Option<StandardTestsPlan>,
    /// The circuit identification fits.
    pub model: ImModel,
}

/// Raw file layout; see `config/sim-im.toml` for a documented example.
type Raw = RawFile<RawSim, toml::Table, RawLimits, RawTest>;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSim {
    motor: toml::Table,
    supply: RawSupply,
    dynamometer: RawDyno,
    sensors: RawSensors,
    thermal: RawThermal,
    #[serde(default)]
    mechanical: RawMechanical,
}

/// `[rig.simulated.mechanical]`: what the shaft carries besides the
/// dynamometer.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMechanical {
    /// Friction and windage at synchronous speed, W (`∝ ω²`).
    #[serde(rename = "friction_windage_W", default)]
    friction_windage: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSupply {
    #[serde(rename = "slew_V_per_s")]
    slew: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDyno {
    time_constant_s: f64,
    max_accel_rad_s2: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSensors {
    seed: u64,
    noise_relative: f64,
    encoder_lines: u32,
    torque_sensor: bool,
    /// A winding thermometer (channel `winding_temperature`, °C).
    #[serde(default)]
    winding_sensor: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawThermal {
    #[serde(rename = "resistance_K_per_W")]
    resistance: f64,
    time_constant_s: f64,
    #[serde(rename = "ambient_C")]
    ambient: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLimits {
    #[serde(rename = "max_current_A")]
    max_current: f64,
    #[serde(rename = "max_voltage_V")]
    max_voltage: Option<f64>,
    #[serde(rename = "max_speed_rad_s")]
    max_speed: Option<f64>,
    max_i2t_s: f64,
    i2t_time_constant_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTest {
    plan: String,
    model: String,
    #[serde(rename = "voltages_V")]
    voltages: Vec<f64>,
    points: usize,
    min_slip: f64,
    #[serde(rename = "hot_current_A")]
    hot_current: f64,
    hot_point_max_s: f64,
    cooldown_s: f64,
    settle: RawSettle,
    dc_resistance: Option<RawDcResistance>,
    no_load: Option<RawNoLoad>,
    locked_rotor: Option<RawLockedRotor>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSettle {
    window_samples: usize,
    tolerance: f64,
    average_samples: usize,
    timeout_s: f64,
}

fn number(t: &toml::Table, key: &str) -> Option<f64> {
    match t.get(key)? {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

impl ImRunConfig {
    /// Read and validate a file.
    pub fn load(path: &std::path::Path) -> Result<ImRunConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        ImRunConfig::parse(&path.display().to_string(), &text)
    }

    /// Parse and validate `text`; `source` names it in errors, and its
    /// directory resolves relative profile paths.
    pub fn parse(source: &str, text: &str) -> Result<ImRunConfig, ConfigError> {
        let dir = std::path::Path::new(source)
            .parent()
            .unwrap_or(std::path::Path::new("."));
        ImRunConfig::parse_in(source, dir, text)
    }

    /// Parse and validate `text`; `source` names it in errors, with the
    /// line and the key; relative profile paths are resolved in `dir`.
    pub fn parse_in(
        source: &str,
        dir: &std::path::Path,
        text: &str,
    ) -> Result<ImRunConfig, ConfigError> {
        ImRunConfig::parse_composed(source, dir, text).map_err(|e| e.located(Some(text)))
    }

    /// As [`ImRunConfig::parse_in`], for a text the program composed (the
    /// daemon's configuration with a request's `[test]`): validation
    /// errors name the key, not a line of the composed text.
    pub(crate) fn parse_composed(
        source: &str,
        dir: &std::path::Path,
        text: &str,
    ) -> Result<ImRunConfig, ConfigError> {
        let raw: Raw = toml::from_str(text).map_err(|e| syntax_error(source, text, &e))?;
        let bad = |key: &str, why: String| invalid(source, key, why);
        let modbus = match (raw.rig.backend.as_str(), raw.rig.modbus) {
            ("simulated", None) => None,
            ("simulated", Some(_)) => {
                return Err(bad("rig.modbus", "is for rig.backend = \"modbus\"".into()))
            }
            ("modbus", Some(m)) => Some(
                ImModbusRig::parse(m, dir, raw.rig.simulated.is_some())
                    .map_err(|(key, reason)| bad(&key, reason))?,
            ),
            ("modbus", None) => {
                return Err(bad(
                    "rig.modbus",
                    "missing: backend \"modbus\" needs it".into(),
                ))
            }
            (other, _) => {
                return Err(bad(
                    "rig.backend",
                    format!("{}: want \"simulated\" or \"modbus\"", quoted(other)),
                ))
            }
        };
        let served = modbus.as_ref().is_some_and(|m| m.simulate.is_some());
        if (modbus.is_none() || served) && raw.rig.simulated.is_none() {
            return Err(bad("rig.simulated", "missing".into()));
        }
        if !(modbus.is_none() || served) && raw.rig.simulated.is_some() {
            return Err(bad(
                "rig.simulated",
                "is only used with rig.modbus.simulate: leave it out on a real rig".into(),
            ));
        }
        let standard_tables = RawStandardTests {
            dc_resistance: raw.test.dc_resistance.as_ref(),
            no_load: raw.test.no_load.as_ref(),
            locked_rotor: raw.test.locked_rotor.as_ref(),
        };
        let standard_plan = match raw.test.plan.as_str() {
            "im_standard_tests" => true,
            "im_slip_sweep" => {
                if let Some(key) = standard_tables.first_given() {
                    return Err(bad(key, "is for test.plan = \"im_standard_tests\"".into()));
                }
                false
            }
            other => {
                return Err(bad(
                    "test.plan",
                    format!(
                        "{} is not im_slip_sweep nor im_standard_tests",
                        quoted(other)
                    ),
                ))
            }
        };
        let modbus_dc_source = modbus.as_ref().is_some_and(|m| m.dc_source.is_some());
        if standard_plan
            && modbus
                .as_ref()
                .is_some_and(|m| m.dyno_coast_value.is_none())
        {
            return Err(bad(
                "rig.modbus.dynamometer.coast_value",
                "missing: the no-load test of im_standard_tests lets the shaft turn freely, which \
                 needs the value of the dynamometer's control word that coasts it (Optidrive E3: \
                 8, bit 3)"
                    .into(),
            ));
        }
        if standard_plan && modbus.is_some() && !modbus_dc_source {
            return Err(bad(
                "test.plan",
                "im_standard_tests needs a DC source for the winding-resistance test: give \
                 [rig.modbus.dc_source] (a DC supply with a current limit)"
                    .into(),
            ));
        }
        let model = ImModel::parse(&raw.test.model).ok_or_else(|| {
            bad(
                "test.model",
                format!(
                    "{}: want single, single-fe, double or double-fe",
                    quoted(&raw.test.model)
                ),
            )
        })?;
        let plate = &raw.motor.nameplate;
        let need = |key: &str| {
            number(plate, key).ok_or_else(|| {
                bad(
                    &format!("motor.nameplate.{key}"),
                    "is missing or not a number".into(),
                )
            })
        };
        let (voltage, current, frequency, poles) = (
            need("voltage_V")?,
            need("current_A")?,
            need("frequency_Hz")?,
            need("poles")?,
        );
        let connection = plate
            .get("connection")
            .and_then(|v| v.as_str())
            .and_then(Connection::parse)
            .ok_or_else(|| {
                bad(
                    "motor.nameplate.connection",
                    "must be \"star\" or \"delta\"".into(),
                )
            })?;
        if poles < 2.0 || poles % 2.0 != 0.0 {
            return Err(bad(
                "motor.nameplate.poles",
                format!("{poles} must be an even number ≥ 2"),
            ));
        }
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(bad(name, format!("{v} must be a finite number > 0")))
            }
        };
        let rate = bounded(
            source,
            "rig.sample_rate_Hz",
            bounds::sample_rate(raw.rig.sample_rate_hz),
        )?;
        positive("limits.max_current_A", raw.limits.max_current)?;
        positive("test.hot_current_A", raw.test.hot_current)?;
        if raw.test.voltages.is_empty()
            || raw
                .test
                .voltages
                .iter()
                .any(|v| !(v.is_finite() && *v > 0.0 && *v <= voltage * 1.1))
        {
            return Err(bad(
                "test.voltages_V",
                format!("must be a non-empty list in (0, {:.0}] V", voltage * 1.1),
            ));
        }
        if raw.test.points < 5 {
            return Err(bad("test.points", "must be ≥ 5".into()));
        }
        if !(raw.test.min_slip > 0.0 && raw.test.min_slip < 0.2) {
            return Err(bad("test.min_slip", "must be in (0, 0.2)".into()));
        }
        bounded(
            source,
            "test.voltages_V",
            bounds::count(raw.test.voltages.len(), bounds::MAX_LEVELS),
        )?;
        bounded(
            source,
            "test.points",
            bounds::count(raw.test.points, bounds::MAX_SWEEP_POINTS),
        )?;
        let st = &raw.test.settle;
        for (key, n) in [
            ("test.settle.window_samples", st.window_samples),
            ("test.settle.average_samples", st.average_samples),
        ] {
            bounded(source, key, bounds::window_samples(n as f64))?;
        }
        let point_s = bounded(
            source,
            "test.settle.timeout_s",
            bounds::wait_s(st.timeout_s, false),
        )?;
        let hot_s = bounded(
            source,
            "test.hot_point_max_s",
            bounds::wait_s(raw.test.hot_point_max_s, false),
        )?;
        let cooldown_s = bounded(
            source,
            "test.cooldown_s",
            bounds::wait_s(raw.test.cooldown_s.max(0.0), true),
        )?;
        let average_s = bounded(
            source,
            "test.settle.average_samples",
            bounds::wait_s(st.average_samples as f64 / rate, true),
        )?;
        // The longest the sweep can take: every point to its timeout, its
        // average and a cool-down.
        let longest = (raw.test.voltages.len() * raw.test.points) as f64
            * (point_s.max(hot_s) + average_s + cooldown_s);
        bounded(
            source,
            "test.settle.timeout_s",
            bounds::test_length(longest, rate),
        )?;
        let supply = ImSupply {
            line_voltage: voltage * 1.1,
            frequency,
            connection,
            pole_pairs: (poles / 2.0) as u32,
        };
        let simulated = match &raw.rig.simulated {
            None => None,
            Some(s) => {
                // The circuit: the model's keys, Ω per phase.
                let m = &s.motor;
                let truth_model =
                    ImModel::parse(m.get("model").and_then(|v| v.as_str()).unwrap_or(""))
                        .ok_or_else(|| {
                            bad(
                                "rig.simulated.motor.model",
                                "must be single, single-fe, double or double-fe".into(),
                            )
                        })?;
                for key in m.keys() {
                    if key != "model" && !truth_model.params().iter().any(|p| p.key() == key) {
                        return Err(bad(
                            &format!("rig.simulated.motor.{key}"),
                            format!("is not a {truth_model} parameter"),
                        ));
                    }
                }
                let values: Result<Vec<f64>, ConfigError> = truth_model
                    .params()
                    .iter()
                    .map(|p: &ImParam| {
                        number(m, p.key()).ok_or_else(|| {
                            bad(
                                &format!("rig.simulated.motor.{p}"),
                                "(ohm) is missing".into(),
                            )
                        })
                    })
                    .collect();
                let circuit = ImCircuit::from_values(truth_model, &values?)
                    .map_err(|e| bad("rig.simulated.motor", e.to_string()))?;
                Some(SimImRigConfig {
                    circuit,
                    supply,
                    sample_rate_hz: raw.rig.sample_rate_hz,
                    dyno_time_constant_s: positive(
                        "rig.simulated.dynamometer.time_constant_s",
                        s.dynamometer.time_constant_s,
                    )?,
                    dyno_max_accel: positive(
                        "rig.simulated.dynamometer.max_accel_rad_s2",
                        s.dynamometer.max_accel_rad_s2,
                    )?,
                    vfd_slew_v_per_s: positive("rig.simulated.supply.slew_V_per_s", s.supply.slew)?,
                    noise_relative: s.sensors.noise_relative.max(0.0),
                    encoder_lines: s.sensors.encoder_lines.max(1),
                    torque_sensor: s.sensors.torque_sensor,
                    thermal_resistance_k_per_w: s.thermal.resistance.max(0.0),
                    thermal_time_constant_s: positive(
                        "rig.simulated.thermal.time_constant_s",
                        s.thermal.time_constant_s,
                    )?,
                    ambient_c: s.thermal.ambient,
                    seed: s.sensors.seed,
                    friction_windage_w: {
                        let w = s.mechanical.friction_windage;
                        if !(w.is_finite() && w >= 0.0) {
                            return Err(bad(
                                "rig.simulated.mechanical.friction_windage_W",
                                format!("{w} must be a finite number ≥ 0"),
                            ));
                        }
                        w
                    },
                    // The DC source of the standard tests' resistance reading.
                    dc_source_max_current: (standard_plan || modbus_dc_source).then_some(current),
                    winding_sensor: s.sensors.winding_sensor,
                })
            }
        };
        let encoder_lines = match (&modbus, &simulated) {
            (Some(m), Some(sim)) if m.encoder_lines != sim.encoder_lines => {
                return Err(bad(
                    "rig.modbus.encoder.encoder_lines",
                    format!(
                        "{} must equal rig.simulated.sensors.encoder_lines = {}: the served counter counts the simulated encoder",
                        m.encoder_lines, sim.encoder_lines
                    ),
                ))
            }
            (Some(m), _) => m.encoder_lines,
            (None, Some(sim)) => sim.encoder_lines,
            (None, None) => unreachable!("checked above: a simulated backend has rig.simulated"),
        };
        let synchronous = std::f64::consts::TAU * frequency / f64::from(supply.pole_pairs);
        let limits = Limits {
            max_voltage: positive(
                "limits.max_voltage_V",
                raw.limits.max_voltage.unwrap_or(supply.line_voltage),
            )?,
            max_current: raw.limits.max_current,
            max_speed: positive(
                "limits.max_speed_rad_s",
                raw.limits.max_speed.unwrap_or(1.2 * synchronous),
            )?,
        };
        let standard = standard_plan
            .then(|| {
                standard_tables.validate(
                    voltage,
                    current,
                    frequency,
                    limits.max_voltage,
                    limits.max_current,
                )
            })
            .transpose()
            .map_err(|(key, why)| bad(&key, why))?;
        if let Some(s) = &standard {
            // The standard tests' readings, each to its timeout.
            let points: usize = s.points().iter().sum();
            bounded(
                source,
                "test.settle.timeout_s",
                bounds::test_length(longest + points as f64 * (point_s + average_s), rate),
            )?;
        }
        let plan = ImSweepPlan {
            voltages: raw.test.voltages.clone(),
            slips: slip_grid(raw.test.points, raw.test.min_slip),
            frequency,
            pole_pairs: supply.pole_pairs,
            settle_window: st.window_samples.max(2),
            settle_tolerance: positive("test.settle.tolerance", st.tolerance)?,
            average_samples: st.average_samples.max(1),
            max_point_s: point_s,
            rated_current: current,
            max_current: raw.limits.max_current,
            hot_current: raw.test.hot_current,
            hot_point_max_s: hot_s,
            cooldown_s,
            max_i2t_s: positive("limits.max_i2t_s", raw.limits.max_i2t_s)?,
            i2t_time_constant_s: positive(
                "limits.i2t_time_constant_s",
                raw.limits.i2t_time_constant_s,
            )?,
            encoder_counts_per_rev: 4.0 * f64::from(encoder_lines),
        };
        let served: Vec<&str> = match &modbus {
            Some(m) if m.simulate.is_some() && simulated.is_some() => {
                let mut d = vec!["supply", "dynamometer", "meter", "encoder"];
                if m.dc_source.is_some() {
                    d.push("dc_source");
                }
                d
            }
            _ => Vec::new(),
        };
        let rtu = modbus
            .as_ref()
            .is_some_and(|m| m.simulate == Some(crate::config::SimulatedTransport::Rtu));
        let stages: &[&str] = if standard.is_some() {
            &["supply", "dynamometer", "dc_source"]
        } else {
            &["supply", "dynamometer"]
        };
        let common = RawCommon {
            motor: raw.motor,
            supervisor: raw.supervisor,
            records: raw.records,
            fault: raw.fault,
        }
        .validate(
            source,
            text,
            raw.rig.sample_rate_hz,
            limits,
            FaultRig {
                served: &served,
                rtu,
                streams: &[],
                can: &[],
                stages,
                current_limit: false,
            },
        )?;
        Ok(ImRunConfig {
            common,
            simulated,
            modbus,
            plan,
            standard,
            model,
        })
    }

    /// What the sweep's safety monitor enforces: `[limits]`, the
    /// `[supervisor]` section and the plan's heating budget.
    pub fn safety_rules(&self) -> SafetyRules {
        SafetyRules::of(&self.common, Some(self.plan.heating_budget()))
    }

    /// The rig, for a person.
    pub fn describe_rig(&self) -> String {
        match &self.modbus {
            Some(m) => m.describe(),
            None => "the simulated induction-machine rig".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIM_IM: &str = include_str!("../../../config/sim-im.toml");

    #[test]
    fn shipped_config_parses() {
        let c = ImRunConfig::parse("sim-im.toml", SIM_IM).unwrap();
        assert_eq!(
            c.simulated.as_ref().unwrap().circuit.model(),
            ImModel::Double
        );
        assert!(c.modbus.is_none());
        // Defaults for the daemon's supervisor: the supply's and the dynamometer's ranges.
        assert!((c.common.limits.max_voltage - 440.0).abs() < 1e-9);
        assert!((c.common.limits.max_speed - 1.2 * std::f64::consts::PI * 50.0).abs() < 1e-9);
        assert_eq!(c.plan.pole_pairs, 2);
        assert_eq!(c.common.nameplate["connection"], "star");
    }

    #[test]
    fn numbers_that_size_memory_loops_or_waits_name_key_and_line() {
        let bad = |from: &str, to: &str| {
            assert!(SIM_IM.contains(from), "{from}");
            let text = SIM_IM.replacen(from, to, 1);
            let line = text.lines().position(|l| l.starts_with(to)).unwrap() + 1;
            (
                line,
                ImRunConfig::parse("im.toml", &text)
                    .unwrap_err()
                    .to_string(),
            )
        };
        for (from, to, key) in [
            ("points = 30", "points = 100000", "test.points"),
            (
                "window_samples = 25",
                "window_samples = 100000000000",
                "test.settle.window_samples",
            ),
            (
                "average_samples = 50",
                "average_samples = 100000000000",
                "test.settle.average_samples",
            ),
            ("timeout_s = 5", "timeout_s = 1e9", "test.settle.timeout_s"),
            (
                "hot_point_max_s = 1.5",
                "hot_point_max_s = 1e300",
                "test.hot_point_max_s",
            ),
            ("cooldown_s = 10", "cooldown_s = 1e12", "test.cooldown_s"),
            // 30 points of 3 000 s each: beyond a day.
            ("timeout_s = 5", "timeout_s = 3000", "test.settle.timeout_s"),
            (
                "sample_rate_Hz = 500",
                "sample_rate_Hz = 1e12",
                "rig.sample_rate_Hz",
            ),
        ] {
            let (line, e) = bad(from, to);
            assert!(
                e.starts_with(&format!("im.toml:{line}: {key}: ")),
                "{to}: {e}"
            );
        }
    }

    const SIM_MODBUS_IM: &str = include_str!("../../../config/sim-modbus-im.toml");

    fn modbus_source() -> String {
        concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-modbus-im.toml").to_string()
    }

    #[test]
    fn shipped_modbus_config_parses() {
        let c = ImRunConfig::parse(&modbus_source(), SIM_MODBUS_IM).unwrap();
        let m = c.modbus.as_ref().unwrap();
        assert_eq!(m.simulate, Some(crate::config::SimulatedTransport::Tcp));
        assert_eq!((m.supply.unit_id, m.dynamometer.unit_id), (1, 2));
        assert_eq!(m.supply.profile.name, "Invertek Optidrive E3");
        assert_eq!(m.meter.profile.name, "Eastron SDM630");
        assert_eq!(m.dyno_pole_pairs, 2);
        assert_eq!(c.plan.encoder_counts_per_rev, 4.0 * 4096.0);
        assert!(c.simulated.is_some());
        assert!(
            c.describe_rig().contains("Modbus TCP"),
            "{}",
            c.describe_rig()
        );
        assert_eq!(c.common.supervision.max_power, 40000.0);
        assert_eq!(m.merge_window, std::time::Duration::from_millis(10));
        for (to, window) in [
            // Left out: the drivers' default window.
            ("# ", motorbench_drivers::DEFAULT_REORDER),
            (
                "merge_window_ms = 25 ",
                std::time::Duration::from_millis(25),
            ),
        ] {
            let c = ImRunConfig::parse(
                &modbus_source(),
                &SIM_MODBUS_IM.replace("merge_window_ms = 10 ", to),
            )
            .unwrap();
            assert_eq!(c.modbus.unwrap().merge_window, window, "{to}");
        }
    }

    /// The error of `text` (the file `source`) with `from` replaced by
    /// `to` (`from` must be in it).
    fn edited_error(source: &str, text: &str, from: &str, to: &str) -> String {
        assert!(text.contains(from), "{from}");
        ImRunConfig::parse(source, &text.replace(from, to))
            .unwrap_err()
            .to_string()
    }

    /// Each edit `from` → `to` of `text` (the file `source`): its error
    /// names all of `names`.
    fn assert_edits_name(source: &str, text: &str, cases: &[(&str, &str, &[&str])]) {
        for &(from, to, names) in cases {
            let e = edited_error(source, text, from, to);
            assert!(
                names.iter().all(|n| e.contains(n)),
                "{from:?} → {to:?}: {e}"
            );
        }
    }

    #[test]
    fn modbus_errors_name_the_key() {
        let bad = |from: &str, to: &str| edited_error(&modbus_source(), SIM_MODBUS_IM, from, to);
        // Each edit `from` → `to`, and what its error must name.
        let cases: [(&str, &str, &[&str]); 12] = [
            (
                "\"motor_rated_voltage\"",
                "\"volts\"",
                &["rig.modbus.supply.voltage_register", "volts"],
            ),
            (
                "\"motor_rated_voltage\"",
                "\"output_current\"",
                &["read-only"],
            ),
            (
                "line_voltage = \"line12_voltage\", ",
                "",
                &["rig.modbus.meter.channels", "line_voltage"],
            ),
            (
                "total_power",
                "total_powr",
                &["rig.modbus.meter.channels.input_power"],
            ),
            (
                "encoder_lines = 4096       # quadrature",
                "encoder_lines = 1024 # q",
                &["must equal rig.simulated.sensors.encoder_lines"],
            ),
            (
                "merge_window_ms = 10 ",
                "merge_window_ms = 5000 ",
                &["rig.modbus.merge_window_ms", "at most 1000"],
            ),
            (
                "merge_window_ms = 10 ",
                "merge_window_ms = -1 ",
                &["rig.modbus.merge_window_ms"],
            ),
            (
                "pole_pairs = 2 ",
                "pole_pairs = 0 ",
                &["rig.modbus.dynamometer.pole_pairs"],
            ),
            (
                "simulate = \"tcp\"",
                "simulate = \"udp\"",
                &["rig.modbus.simulate"],
            ),
            (
                "[rig.modbus.encoder]",
                "[rig.modbus.counter]",
                &["rig.modbus.encoder"],
            ),
            (
                "unit_id = 3",
                "unit_id = 3\nbaud = 9600",
                &["rig.modbus.meter", "baud"],
            ),
            // Served devices take no address.
            (
                "unit_id = 4",
                "unit_id = 4\ntransport = \"tcp\"",
                &["rig.modbus.encoder"],
            ),
        ];
        assert_edits_name(&modbus_source(), SIM_MODBUS_IM, &cases);
        // A real rig has no simulated section.
        let e = bad("simulate = \"tcp\"", "");
        assert!(
            e.contains("rig.modbus.supply.transport") || e.contains("rig.simulated"),
            "{e}"
        );
    }

    const SIM_MODBUS_IM_STANDARD: &str =
        include_str!("../../../config/sim-modbus-im-standard.toml");

    #[test]
    fn shipped_modbus_standard_config_parses_and_its_standard_keys_are_checked() {
        let source = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/config/sim-modbus-im-standard.toml"
        );
        let c = ImRunConfig::parse(source, SIM_MODBUS_IM_STANDARD).unwrap();
        let m = c.modbus.as_ref().unwrap();
        let dc = m.dc_source.as_ref().unwrap();
        assert_eq!(dc.device.profile.name, "Riden RD6006");
        assert_eq!(dc.compliance_voltage, 30.0);
        assert_eq!(m.dyno_coast_value, Some(8));
        let sim = c.simulated.as_ref().unwrap();
        assert!(sim.winding_sensor);
        assert_eq!(sim.dc_source_max_current, Some(7.6));
        let reduced = c.standard.as_ref().unwrap().reduced_frequency.as_ref();
        assert_eq!(reduced.unwrap().frequency, 12.5);
        assert!(
            c.describe_rig().contains("DC source Riden RD6006"),
            "{}",
            c.describe_rig()
        );

        let section = "[rig.modbus.dc_source]";
        let start = SIM_MODBUS_IM_STANDARD.find(section).unwrap();
        let end = start + SIM_MODBUS_IM_STANDARD[start..].find("\n\n").unwrap();
        let cases: [(&str, &str, &[&str]); 6] = [
            (
                &SIM_MODBUS_IM_STANDARD[start..end],
                "",
                &["test.plan", "[rig.modbus.dc_source]"],
            ),
            (
                "coast_value = 8 ",
                "",
                &["rig.modbus.dynamometer.coast_value"],
            ),
            (
                "compliance_V = 30 ",
                "compliance_V = 100 ",
                &["rig.modbus.dc_source.compliance_V", "60"],
            ),
            (
                ", dc_current = \"current_out\"",
                "",
                &["rig.modbus.dc_source.channels", "dc_current"],
            ),
            (
                "profile = \"devices/riden-rd6006.toml\"",
                "profile = \"devices/eastron-sdm630.toml\"",
                &["rig.modbus.dc_source.profile", "[power_stage]"],
            ),
            (
                "reduced_frequency_Hz = 12.5",
                "reduced_frequency_Hz = 50",
                &["test.locked_rotor.reduced_frequency_Hz"],
            ),
        ];
        assert_edits_name(source, SIM_MODBUS_IM_STANDARD, &cases);
    }

    #[test]
    fn errors_name_the_file_and_the_key_or_line() {
        let bad = |from: &str, to: &str| edited_error("x.toml", SIM_IM, from, to);
        let e = bad("Rr2 =", "Rq2 =");
        assert!(e.contains("x.toml") && e.contains("Rq2"), "{e}");
        let e = bad("points = ", "pointz = ");
        assert!(e.starts_with("x.toml:") && e.contains("pointz"), "{e}");
        let e = bad("connection = \"star\"", "connection = \"zigzag\"");
        assert!(e.contains("connection"), "{e}");
    }
}
