//! The DC machine's rig and test configuration: raw TOML structures
//! (unknown keys refused) and their validation into a [`Config`].
//!
//! Every error names the file and, for syntax or type errors, the line and
//! the key; validation errors name the key path (`limits.max_current_A`).

use std::path::Path;

use serde::Deserialize;

use crate::bounds;
use crate::config::{
    bounded, invalid, modbus, syntax_error, CanLink, CanTransport, CommonConfig, ConfigError,
    FaultRig, Limits, ModbusRig, RawCommon, RawFile, SensorLink, SimulatedTransport,
    DEFAULT_CONFIG, DEFAULT_CONFIG_NAME,
};
use crate::excerpt::quoted;
use crate::model::DcParams;

/// Raw file layout; see `config/sim-dc.toml` for a documented example.
type RawConfig = RawFile<SimulatedRig, modbus::RawModbusRig, Limits, RawTest>;

/// The simulated rig: the motor it simulates and its imperfections.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SimulatedRig {
    /// The true parameters of the simulated motor.
    pub motor: DcParams,
    /// The simulated armature supply.
    pub power_stage: SimPowerStageConfig,
    /// The simulated sensors.
    pub sensors: SimSensorConfig,
}

/// The simulated armature supply.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SimPowerStageConfig {
    /// Largest voltage it can produce, V.
    #[serde(rename = "max_voltage_V")]
    pub max_voltage: f64,
    /// Output slew rate, V/s.
    #[serde(rename = "slew_V_per_s")]
    pub slew: f64,
    /// Largest current the supply can deliver (its constant-current
    /// rating), A. The bench sets a lower limit at the start of a test.
    #[serde(rename = "current_limit_A")]
    pub current_limit: f64,
    /// Keep-alive timeout of the supply's heartbeat, s: once armed by a
    /// first heartbeat, the supply goes to its safe state by itself when
    /// not petted within this time.
    #[serde(rename = "heartbeat_timeout_s", default = "default_heartbeat_timeout")]
    pub heartbeat_timeout: f64,
}

fn default_heartbeat_timeout() -> f64 {
    0.25
}

/// The simulated sensors: noise, ADC resolution, encoder.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SimSensorConfig {
    /// Noise generator seed.
    pub seed: u64,
    /// Voltage ADC full scale (±), V.
    #[serde(rename = "voltage_full_scale_V")]
    pub voltage_full_scale: f64,
    /// Voltage ADC bits.
    pub voltage_bits: u32,
    /// Voltage noise standard deviation, V.
    #[serde(rename = "voltage_noise_V")]
    pub voltage_noise: f64,
    /// Current ADC full scale (±), A.
    #[serde(rename = "current_full_scale_A")]
    pub current_full_scale: f64,
    /// Current ADC bits.
    pub current_bits: u32,
    /// Current noise standard deviation, A.
    #[serde(rename = "current_noise_A")]
    pub current_noise: f64,
    /// Encoder lines per revolution (4 counts per line).
    pub encoder_lines: u32,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTest {
    plan: String,
    #[serde(rename = "levels_V", default)]
    levels: Vec<f64>,
    #[serde(rename = "coastdown_from_V")]
    coastdown_from: Option<f64>,
    #[serde(default)]
    coastdown: bool,
    settle: Settle,
}

/// How settling is detected at each level.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Settle {
    /// Length of each of the two compared windows, s.
    pub window_s: f64,
    /// Relative change of the window means allowed, beyond noise.
    pub tolerance: f64,
    /// Shortest time at a level before it may be called settled, s.
    pub min_hold_s: f64,
    /// Settled data kept at each level for averaging, s.
    pub hold_s: f64,
    /// Longest wait for a level to settle, s.
    pub timeout_s: f64,
    /// Longest coast-down before the test moves on, s.
    #[serde(default = "default_coastdown_timeout")]
    pub coastdown_timeout_s: f64,
}

fn default_coastdown_timeout() -> f64 {
    60.0
}

/// Which rig backend drives the test.
#[derive(Debug, Clone, PartialEq)]
pub enum Backend {
    /// The simulated rig, in process.
    Simulated(SimulatedRig),
    /// A power stage and sensors over Modbus TCP or RTU; with
    /// `simulated`, the simulated rig served behind those links.
    Modbus {
        /// The links and device profiles.
        rig: Box<ModbusRig>,
        /// The simulated rig served behind the links (`rig.modbus.simulate`).
        simulated: Option<SimulatedRig>,
    },
}

impl Backend {
    /// The simulated rig's configuration, when the test runs on one
    /// (directly or behind a protocol).
    pub fn simulated(&self) -> Option<&SimulatedRig> {
        match self {
            Backend::Simulated(sim) => Some(sim),
            Backend::Modbus { simulated, .. } => simulated.as_ref(),
        }
    }

    /// A short description for messages.
    pub fn describe(&self) -> String {
        match self {
            Backend::Simulated(_) => "the simulated rig".into(),
            Backend::Modbus {
                rig,
                simulated: Some(_),
            } => format!(
                "the simulated rig served over Modbus {}",
                match rig.simulate {
                    Some(SimulatedTransport::Rtu) => "RTU (pseudo-terminals)",
                    _ => "TCP (loopback)",
                }
            ),
            Backend::Modbus { rig, .. } => format!(
                "Modbus: {} and {}",
                rig.power_stage.profile.name,
                match &rig.sensors {
                    SensorLink::Modbus(l) => l.profile.name.clone(),
                    SensorLink::Serial { port, framing } => format!(
                        "{framing:?} records on {}",
                        port.as_ref().map_or("a serial port", |p| p.path.as_str())
                    ),
                }
            ),
        }
    }
}

/// The test plan to run.
#[derive(Debug, Clone, PartialEq)]
pub enum Plan {
    /// Armature-voltage staircase, each level held until settled, then an
    /// optional coast-down from the last level.
    DcStep {
        /// Voltage levels in order, V; the first is reached from rest.
        levels: Vec<f64>,
        /// End with a coast-down.
        coastdown: bool,
    },
    /// Run up to a voltage, settle, open the armature and let it coast.
    DcCoastdown {
        /// Voltage to settle at before opening the armature, V.
        from: f64,
    },
}

/// A validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// What every test configuration holds: the file, the motor, the
    /// sample rate, limits, supervision, retention, faults.
    pub common: CommonConfig,
    /// Rig backend.
    pub backend: Backend,
    /// The plan.
    pub plan: Plan,
    /// Settle detection.
    pub settle: Settle,
}

impl Config {
    /// Load and validate a file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Config::parse(&path.display().to_string(), &text)
    }

    /// The embedded default.
    pub fn embedded_default() -> Config {
        Config::parse(DEFAULT_CONFIG_NAME, DEFAULT_CONFIG)
            .expect("the embedded default configuration is valid")
    }

    /// Parse and validate `text`; `source` names it in errors, with the
    /// line and the key.
    pub fn parse(source: &str, text: &str) -> Result<Config, ConfigError> {
        let dir = Path::new(source).parent().unwrap_or(Path::new("."));
        Config::parse_composed(source, dir, text).map_err(|e| e.located(Some(text)))
    }

    /// Parse and validate `text` the program composed (the daemon's
    /// configuration with a request's `[test]`): errors name the key, not
    /// a line of the composed text; relative profile paths are resolved
    /// in `dir`.
    pub(crate) fn parse_composed(
        source: &str,
        dir: &Path,
        text: &str,
    ) -> Result<Config, ConfigError> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| syntax_error(source, text, &e))?;
        let invalid = |key: &str, reason: String| invalid(source, key, reason);
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(key, format!("{v} must be a finite number > 0")))
            }
        };

        bounded(
            source,
            "rig.sample_rate_Hz",
            bounds::sample_rate(raw.rig.sample_rate_hz),
        )?;
        let check_simulated = |sim: &SimulatedRig| -> Result<(), ConfigError> {
            sim.motor
                .validate()
                .map_err(|e| invalid(&format!("rig.simulated.motor.{}", e.name), e.to_string()))?;
            let ps = &sim.power_stage;
            positive("rig.simulated.power_stage.max_voltage_V", ps.max_voltage)?;
            positive("rig.simulated.power_stage.slew_V_per_s", ps.slew)?;
            positive(
                "rig.simulated.power_stage.current_limit_A",
                ps.current_limit,
            )?;
            positive(
                "rig.simulated.power_stage.heartbeat_timeout_s",
                ps.heartbeat_timeout,
            )?;
            let s = &sim.sensors;
            positive(
                "rig.simulated.sensors.voltage_full_scale_V",
                s.voltage_full_scale,
            )?;
            positive(
                "rig.simulated.sensors.current_full_scale_A",
                s.current_full_scale,
            )?;
            for (key, bits) in [
                ("voltage_bits", s.voltage_bits),
                ("current_bits", s.current_bits),
            ] {
                if !(2..=24).contains(&bits) {
                    return Err(invalid(
                        &format!("rig.simulated.sensors.{key}"),
                        format!("{bits} must be 2 to 24"),
                    ));
                }
            }
            for (key, v) in [
                ("voltage_noise_V", s.voltage_noise),
                ("current_noise_A", s.current_noise),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(invalid(
                        &format!("rig.simulated.sensors.{key}"),
                        format!("{v} must be ≥ 0"),
                    ));
                }
            }
            if s.encoder_lines == 0 {
                return Err(invalid(
                    "rig.simulated.sensors.encoder_lines",
                    "must be > 0".into(),
                ));
            }
            Ok(())
        };
        let backend = match raw.rig.backend.as_str() {
            "simulated" => {
                let sim = raw.rig.simulated.ok_or_else(|| {
                    invalid(
                        "rig.simulated",
                        "missing: backend \"simulated\" needs it".into(),
                    )
                })?;
                check_simulated(&sim)?;
                Backend::Simulated(sim)
            }
            "modbus" => {
                let m = raw.rig.modbus.ok_or_else(|| {
                    invalid("rig.modbus", "missing: backend \"modbus\" needs it".into())
                })?;
                if let Some(sim) = &raw.rig.simulated {
                    check_simulated(sim)?;
                }
                let rig = m
                    .validate(dir, raw.rig.simulated.is_some(), raw.rig.sample_rate_hz)
                    .map_err(|(key, reason)| invalid(&key, reason))?;
                let simulated = if rig.simulate.is_some() {
                    raw.rig.simulated
                } else {
                    None
                };
                Backend::Modbus {
                    rig: Box::new(rig),
                    simulated,
                }
            }
            other => {
                return Err(invalid(
                    "rig.backend",
                    format!(
                        "unknown backend {} (this version has: \"simulated\", \"modbus\")",
                        quoted(other)
                    ),
                ))
            }
        };

        positive("limits.max_voltage_V", raw.limits.max_voltage)?;
        positive("limits.max_current_A", raw.limits.max_current)?;
        positive("limits.max_speed_rad_s", raw.limits.max_speed)?;

        let level_ok = |key: &str, v: f64| {
            if !v.is_finite() || v.abs() > raw.limits.max_voltage {
                Err(invalid(
                    key,
                    format!(
                        "{v} V is beyond limits.max_voltage_V = {}",
                        raw.limits.max_voltage
                    ),
                ))
            } else {
                Ok(())
            }
        };
        let plan = match raw.test.plan.as_str() {
            "dc_step" => {
                if raw.test.coastdown_from.is_some() {
                    return Err(invalid(
                        "test.coastdown_from_V",
                        "belongs to plan \"dc_coastdown\"".into(),
                    ));
                }
                if raw.test.levels.len() < 2 {
                    return Err(invalid(
                        "test.levels_V",
                        "a staircase needs at least 2 levels".into(),
                    ));
                }
                bounded(
                    source,
                    "test.levels_V",
                    bounds::count(raw.test.levels.len(), bounds::MAX_LEVELS),
                )?;
                for (n, v) in raw.test.levels.iter().enumerate() {
                    level_ok(&format!("test.levels_V[{n}]"), *v)?;
                }
                if let Some(n) = raw.test.levels.windows(2).position(|w| w[0] == w[1]) {
                    return Err(invalid(
                        &format!("test.levels_V[{}]", n + 1),
                        "repeats the level before it: that is no step".into(),
                    ));
                }
                Plan::DcStep {
                    levels: raw.test.levels,
                    coastdown: raw.test.coastdown,
                }
            }
            "dc_coastdown" => {
                if !raw.test.levels.is_empty() || raw.test.coastdown {
                    return Err(invalid(
                        "test",
                        "plan \"dc_coastdown\" takes coastdown_from_V only".into(),
                    ));
                }
                let from = raw.test.coastdown_from.ok_or_else(|| {
                    invalid(
                        "test.coastdown_from_V",
                        "missing: plan \"dc_coastdown\" needs it".into(),
                    )
                })?;
                level_ok("test.coastdown_from_V", from)?;
                Plan::DcCoastdown { from }
            }
            other => {
                return Err(invalid(
                    "test.plan",
                    format!(
                        "unknown plan {} (this version has: \"dc_step\", \"dc_coastdown\")",
                        quoted(other)
                    ),
                ))
            }
        };

        let st = raw.test.settle;
        positive("test.settle.tolerance", st.tolerance)?;
        for (key, v, zero_ok) in [
            ("test.settle.window_s", st.window_s, false),
            ("test.settle.hold_s", st.hold_s, false),
            ("test.settle.timeout_s", st.timeout_s, false),
            (
                "test.settle.coastdown_timeout_s",
                st.coastdown_timeout_s,
                false,
            ),
            ("test.settle.min_hold_s", st.min_hold_s, true),
        ] {
            bounded(source, key, bounds::wait_s(v, zero_ok))?;
        }
        // Settling is judged on the encoder's readings.
        let encoder_rate = match &backend {
            Backend::Modbus { rig, .. } => rig.rate_of("encoder_count"),
            Backend::Simulated(_) => None,
        }
        .unwrap_or(raw.rig.sample_rate_hz);
        if st.window_s * encoder_rate < 10.0 {
            return Err(invalid(
                "test.settle.window_s",
                format!("must span at least 10 encoder readings ({encoder_rate} Hz)"),
            ));
        }
        bounded(
            source,
            "test.settle.window_s",
            bounds::window_samples(st.window_s * encoder_rate),
        )?;
        // The longest the plan can take (every level to its timeout, then
        // the coast-down to its own), read at the fastest channel's rate.
        let (steps, coastdown) = match &plan {
            Plan::DcStep { levels, coastdown } => (levels.len(), *coastdown),
            Plan::DcCoastdown { .. } => (1, true),
        };
        let longest = steps as f64 * st.timeout_s
            + if coastdown {
                st.coastdown_timeout_s
            } else {
                0.0
            };
        let fastest = match &backend {
            Backend::Modbus { rig, .. } => {
                rig.all_channels().map(|c| c.rate_hz).fold(0.0, f64::max)
            }
            Backend::Simulated(_) => 0.0,
        }
        .max(raw.rig.sample_rate_hz);
        bounded(
            source,
            "test.settle.timeout_s",
            bounds::test_length(longest, fastest),
        )?;

        // The served devices: the supply, the sensors (a streaming DAQ or
        // a Modbus one) and the CAN encoder where it is simulated behind
        // an SLCAN adapter.
        let (mut served, mut streams, mut can) = (Vec::new(), Vec::new(), Vec::new());
        let mut rtu = false;
        if let Backend::Modbus {
            rig,
            simulated: Some(_),
        } = &backend
        {
            served.extend(["power_stage", "sensors"]);
            rtu = rig.simulate == Some(SimulatedTransport::Rtu);
            if let SensorLink::Serial { .. } = rig.sensors {
                streams.push("sensors");
            }
            if let Some(CanLink {
                transport: CanTransport::Slcan { .. },
                ..
            }) = rig.can
            {
                served.push("encoder");
                streams.push("encoder");
                can.push("encoder");
            }
        }
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
            raw.limits,
            FaultRig {
                served: &served,
                rtu,
                streams: &streams,
                can: &can,
                stages: &["power_stage"],
                current_limit: true,
            },
        )?;

        Ok(Config {
            common,
            backend,
            plan,
            settle: st,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{TestConfig, DEFAULT_STALE_TIMEOUT_S};

    fn with(replace: &str, by: &str) -> Result<Config, ConfigError> {
        assert!(
            DEFAULT_CONFIG.contains(replace),
            "fixture text not found: {replace}"
        );
        Config::parse("rig.toml", &DEFAULT_CONFIG.replacen(replace, by, 1))
    }

    /// The error text of the default config with `replace` replaced by
    /// `by`, which must be refused.
    fn refused(replace: &str, by: &str) -> String {
        with(replace, by).unwrap_err().to_string()
    }

    /// The number (from 1) of the default config's first line that starts
    /// with `prefix`.
    fn line_of(prefix: &str) -> usize {
        DEFAULT_CONFIG
            .lines()
            .position(|l| l.starts_with(prefix))
            .unwrap()
            + 1
    }

    #[test]
    fn embedded_default_is_the_seed_motor() {
        let c = Config::embedded_default();
        let sim = c.backend.simulated().unwrap();
        assert_eq!(sim.motor, DcParams::SEED_TABLE4_MOMENTS);
        assert_eq!(c.common.nameplate["power_W"], 180);
        assert!(
            matches!(&c.plan, Plan::DcStep { levels, coastdown: true } if levels[0] == 60.0 && levels[1] == 248.0)
        );
    }

    #[test]
    fn every_shipped_config_is_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
        let mut n = 0;
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                TestConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
                n += 1;
            }
        }
        assert!(n >= 2, "expected the shipped example configs, found {n}");
    }

    #[test]
    fn unknown_key_is_refused_by_name_and_line() {
        let err = refused("[limits]", "[limits]\nmax_torque_Nm = 3");
        assert!(err.contains("rig.toml:"), "{err}");
        assert!(err.contains("max_torque_Nm"), "{err}");
        let line = err.split(':').nth(1).unwrap().parse::<usize>().unwrap();
        assert_eq!(line, line_of("[limits]") + 1, "{err}");
        assert!(!err.contains('\n'), "one line: {err}");
    }

    #[test]
    fn wrong_type_names_the_line() {
        let err = refused("max_current_A = 6", "max_current_A = \"six\"");
        assert!(err.contains("max_current_A"), "{err}");
    }

    #[test]
    fn invalid_values_name_the_key() {
        let err = refused("max_current_A = 6", "max_current_A = -6");
        let line = line_of("max_current_A");
        assert!(
            err.starts_with(&format!("rig.toml:{line}: limits.max_current_A:")),
            "{err}"
        );
        let err = refused("La = 0.803", "La = 0");
        assert!(err.contains("rig.simulated.motor.La"), "{err}");
        let err = refused("levels_V = [60,", "levels_V = [600,");
        assert!(err.contains("test.levels_V[0]"), "{err}");
        let err = refused("plan = \"dc_step\"", "plan = \"im_slip_sweep\"");
        assert!(
            err.contains("test.plan") && err.contains("unknown plan"),
            "{err}"
        );
        let err = refused("backend = \"simulated\"", "backend = \"canbus\"");
        assert!(err.contains("rig.backend"), "{err}");
    }

    #[test]
    fn numbers_that_size_memory_loops_or_waits_are_bounded() {
        let key_of = |r: Result<Config, ConfigError>| match r {
            Err(ConfigError::Invalid { key, line, .. }) => (key, line),
            other => panic!("not an invalid value: {other:?}"),
        };
        let (key, line) = key_of(with("sample_rate_Hz = 2000", "sample_rate_Hz = 1e12"));
        assert_eq!(key, "rig.sample_rate_Hz");
        assert_eq!(line, Some(line_of("sample_rate_Hz")));
        for (from, to, key) in [
            (
                "sample_rate_Hz = 2000",
                "sample_rate_Hz = 0.001",
                "rig.sample_rate_Hz",
            ),
            ("window_s = 0.1", "window_s = 1e7", "test.settle.window_s"),
            // 1 000 s windows at 2 kHz: two million samples per window.
            ("window_s = 0.1", "window_s = 1000", "test.settle.window_s"),
            ("\nhold_s = ", "\nhold_s = 1e9 #", "test.settle.hold_s"),
            (
                "min_hold_s = ",
                "min_hold_s = 1e9 #",
                "test.settle.min_hold_s",
            ),
            (
                "timeout_s = 10",
                "timeout_s = 1e300",
                "test.settle.timeout_s",
            ),
            (
                "coastdown_timeout_s = 60",
                "coastdown_timeout_s = 1e9",
                "test.settle.coastdown_timeout_s",
            ),
            // Each wait in range, the whole test not: 3 000 s at 2 kHz for
            // each of 27 levels is 1.6·10⁸ readings per channel.
            (
                "timeout_s = 10",
                "timeout_s = 3000",
                "test.settle.timeout_s",
            ),
        ] {
            let text = if to == "timeout_s = 3000" {
                DEFAULT_CONFIG.replacen("levels_V = [60,", "levels_V = [10, 20, 30, 40, 50, 70, 80, 90, 100, 110, 120, 130, 140, 150, 160, 170, 180, 190, 200, 60,", 1)
            } else {
                DEFAULT_CONFIG.to_string()
            };
            assert!(text.contains(from), "{from}");
            let r = Config::parse("rig.toml", &text.replacen(from, to, 1));
            assert_eq!(key_of(r).0, key, "{to}");
        }
        let levels: Vec<String> = (0..1001).map(|k| format!("{}", 1 + k % 200)).collect();
        let (key, _) = key_of(with(
            "levels_V = [60,",
            &format!("levels_V = [{}, 60,", levels.join(", ")),
        ));
        assert_eq!(key, "test.levels_V");
        let (key, _) = key_of(Config::parse(
            "rig.toml",
            &format!("{DEFAULT_CONFIG}\n[supervisor]\nbus_loss_timeout_s = 3600\n"),
        ));
        assert_eq!(key, "supervisor.bus_loss_timeout_s");
    }

    #[test]
    fn supervisor_and_records_sections_default_and_validate() {
        let c = Config::embedded_default();
        assert_eq!(c.common.supervision.max_power, 280.0 * 6.0);
        assert_eq!(
            c.common.supervision.thermal.rated_current, 1.1,
            "from the nameplate"
        );
        assert_eq!(c.common.supervision.stale_timeout, DEFAULT_STALE_TIMEOUT_S);
        assert_eq!(c.common.supervision.estop_channel, None);
        assert_eq!(c.common.retention.max_total_bytes, 20 << 30);
        assert_eq!(c.common.retention.max_age_s, None);

        let extra = "[supervisor]\nmax_power_W = 900\nestop_channel = \"emergency_stop\"\n\
            [supervisor.thermal]\ntime_constant_s = 60\nmax_winding_C = 100\n\
            [records]\nmax_total_GiB = 0.5\nmax_age_days = 30\n";
        let c = Config::parse("rig.toml", &format!("{DEFAULT_CONFIG}\n{extra}")).unwrap();
        assert_eq!(c.common.supervision.max_power, 900.0);
        assert_eq!(
            c.common.supervision.estop_channel.as_deref(),
            Some("emergency_stop")
        );
        assert_eq!(c.common.supervision.thermal.time_constant, 60.0);
        assert_eq!(c.common.supervision.thermal.max_winding, 100.0);
        assert_eq!(c.common.retention.max_total_bytes, 1 << 29);
        assert_eq!(c.common.retention.max_age_s, Some(30.0 * 86_400.0));

        let bad = |extra: &str| {
            Config::parse("rig.toml", &format!("{DEFAULT_CONFIG}\n{extra}"))
                .unwrap_err()
                .to_string()
        };
        let e = bad("[supervisor]\nmax_power_kW = 1\n");
        assert!(e.contains("rig.toml:") && e.contains("max_power_kW"), "{e}");
        let e = bad("[supervisor.thermal]\nmax_winding_C = 20\n");
        assert!(e.contains("supervisor.thermal.max_winding_C"), "{e}");
        let e = bad("[supervisor]\nbus_loss_timeout_s = 0\n");
        assert!(e.contains("supervisor.bus_loss_timeout_s"), "{e}");
        let e = bad("[records]\nmax_age_days = -1\n");
        assert!(e.contains("records.max_age_days"), "{e}");
        let e = bad("[records]\nkeep = 3\n");
        assert!(e.contains("keep"), "{e}");
        // Without a nameplate current the rated current must be given.
        let text = DEFAULT_CONFIG.replace("current_A = 1.1\n", "");
        let e = Config::parse("rig.toml", &text).unwrap_err().to_string();
        assert!(e.contains("supervisor.thermal.rated_current_A"), "{e}");
    }

    #[test]
    fn missing_file_is_named() {
        let err = Config::load(Path::new("no/such/rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("no/such/rig.toml: cannot read"), "{err}");
    }
}
