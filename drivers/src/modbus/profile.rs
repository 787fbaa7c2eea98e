//! Device profiles: a Modbus device's register map and, for a device that
//! drives the rig, which registers make it a power stage. Loaded from TOML
//! (`config/devices/*.toml`); every error names the file, and the line or
//! the key.
//!
//! ```toml
//! [device]
//! name = "Riden RD6006"
//! role = "dc_supply"
//! source = "where the register map comes from"
//! verification = "what was and was not checked"
//!
//! [modbus]
//! unit_id = 1
//! word_order = "high_first"   # default of every register; or "low_first"
//! byte_order = "big"          # or "little"
//! max_read_gap = 0            # undefined addresses one read may span (0: adjacent only)
//!
//! [modbus.serial]             # RTU line defaults (optional)
//! baud_rate = 115200
//! parity = "none"             # "even", "odd"
//! stop_bits = 1
//!
//! [registers.voltage_set]
//! address = 8                 # 0-based protocol address
//! kind = "holding"            # input, coil, discrete_input
//! type = "u16"                # i16, u32, i32, f32, bool
//! scale = 0.01                # value = raw × scale + offset
//! offset = 0
//! unit = "V"
//! access = "read_write"       # read, write
//!
//! [power_stage]               # optional
//! setpoint = "voltage_set"
//! enable = "output_enable"    # optional: register written with …
//! enable_value = 1            # … this raw value to enable
//! disable_value = 0           # … and this one to disable
//! current_limit = "current_set"   # optional
//! max_setpoint = 60.0
//! heartbeat = "watchdog"      # optional: written periodically with a counter
//! heartbeat_period_ms = 500
//! ```

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use serde::Deserialize;

use super::register_map::{Access, ByteOrder, DataType, Register, RegisterKind, WordOrder};
use crate::serial::port::Parity;

/// Longest heartbeat period a profile may give, ms: a supply whose own
/// keep-alive waits longer would hold its output that long after the bench
/// stopped petting it.
pub const MAX_HEARTBEAT_PERIOD_MS: u64 = 10_000;

/// A profile that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// TOML syntax, wrong type or unknown key.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// What the parser said.
        message: String,
    },
    /// A value parsed but is not usable.
    #[error("{path}: {key}: {reason}")]
    Invalid {
        /// The file.
        path: String,
        /// Dotted key path.
        key: String,
        /// Why.
        reason: String,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProfile {
    device: RawDevice,
    modbus: RawModbus,
    registers: BTreeMap<String, RawRegister>,
    power_stage: Option<RawStage>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDevice {
    name: String,
    role: String,
    source: String,
    verification: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModbus {
    unit_id: u8,
    #[serde(default)]
    word_order: WordOrder,
    #[serde(default)]
    byte_order: ByteOrder,
    #[serde(default)]
    max_read_gap: u16,
    serial: Option<SerialDefaults>,
}

/// RTU line settings a device ships with.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialDefaults {
    /// Bits per second.
    pub baud_rate: u32,
    /// Parity.
    #[serde(default)]
    pub parity: Parity,
    /// Stop bits.
    #[serde(default = "one")]
    pub stop_bits: u8,
}

fn one() -> u8 {
    1
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRegister {
    address: u16,
    kind: RegisterKind,
    #[serde(rename = "type")]
    data_type: DataType,
    #[serde(default = "unit_scale")]
    scale: f64,
    #[serde(default)]
    offset: f64,
    #[serde(default)]
    unit: String,
    #[serde(default)]
    access: Access,
    word_order: Option<WordOrder>,
    byte_order: Option<ByteOrder>,
    #[serde(default)]
    #[allow(dead_code)]
    note: String,
}

fn unit_scale() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStage {
    setpoint: String,
    enable: Option<String>,
    #[serde(default = "enable_on")]
    enable_value: u16,
    #[serde(default)]
    disable_value: u16,
    current_limit: Option<String>,
    max_setpoint: f64,
    heartbeat: Option<String>,
    heartbeat_period_ms: Option<u64>,
}

fn enable_on() -> u16 {
    1
}

/// The registers that make a device a power stage.
#[derive(Debug, Clone, PartialEq)]
pub struct StageMap {
    /// Set point register.
    pub setpoint: String,
    /// Output enable register, with its raw enable and disable values.
    pub enable: Option<(String, u16, u16)>,
    /// Current limit register.
    pub current_limit: Option<String>,
    /// Largest set point magnitude accepted, in the set point's unit.
    pub max_setpoint: f64,
    /// Heartbeat register and its period.
    pub heartbeat: Option<(String, Duration)>,
}

/// A validated device profile.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceProfile {
    /// Device name.
    pub name: String,
    /// What it is on the rig (free text: `dc_supply`, `power_meter`, …).
    pub role: String,
    /// Where the register map comes from.
    pub source: String,
    /// What was and was not verified.
    pub verification: String,
    /// Default unit id.
    pub unit_id: u8,
    /// RTU defaults, when the device has a serial port.
    pub serial: Option<SerialDefaults>,
    /// Addresses a single read may span between two registers (0: only
    /// adjacent registers share a request).
    pub max_read_gap: u16,
    /// Registers by name.
    pub registers: BTreeMap<String, Register>,
    /// Power stage registers, when the device drives the rig.
    pub power_stage: Option<StageMap>,
}

impl DeviceProfile {
    /// Load and validate a profile file.
    pub fn load(path: &Path) -> Result<DeviceProfile, ProfileError> {
        let text = std::fs::read_to_string(path).map_err(|source| ProfileError::Read {
            path: path.display().to_string(),
            source,
        })?;
        DeviceProfile::parse(&path.display().to_string(), &text)
    }

    /// A register by name.
    pub fn register(&self, name: &str) -> Option<&Register> {
        self.registers.get(name)
    }

    /// Parse and validate `text`; `path` names it in errors.
    pub fn parse(path: &str, text: &str) -> Result<DeviceProfile, ProfileError> {
        let raw: RawProfile = toml::from_str(text).map_err(|e| {
            let start = e.span().map(|s| s.start).unwrap_or(0).min(text.len());
            ProfileError::Parse {
                path: path.to_string(),
                line: text[..start].matches('\n').count() + 1,
                message: e.message().replace('\n', " ").trim().to_string(),
            }
        })?;
        let invalid = |key: &str, reason: String| ProfileError::Invalid {
            path: path.to_string(),
            key: key.to_string(),
            reason,
        };
        for (key, v) in [
            ("device.name", &raw.device.name),
            ("device.source", &raw.device.source),
            ("device.verification", &raw.device.verification),
        ] {
            if v.trim().is_empty() {
                return Err(invalid(key, "must not be empty".into()));
            }
        }
        if raw.modbus.unit_id == 0 {
            return Err(invalid(
                "modbus.unit_id",
                "0 is the broadcast address: devices never answer it".into(),
            ));
        }
        let mut registers = BTreeMap::new();
        for (name, r) in raw.registers {
            let key = format!("registers.{name}");
            if !(r.scale.is_finite() && r.scale != 0.0) {
                return Err(invalid(
                    &format!("{key}.scale"),
                    format!("{} must be finite and non-zero", r.scale),
                ));
            }
            if !r.offset.is_finite() {
                return Err(invalid(&format!("{key}.offset"), "must be finite".into()));
            }
            let largest = r.data_type.largest_raw() * r.scale.abs() + r.offset.abs();
            if !largest.is_finite() {
                return Err(invalid(
                    &format!("{key}.scale"),
                    format!(
                        "{} overflows: the largest raw {} value would read as infinity",
                        r.scale,
                        r.data_type.name()
                    ),
                ));
            }
            let bit_table = matches!(r.kind, RegisterKind::Coil | RegisterKind::DiscreteInput);
            if bit_table != (r.data_type == DataType::Bool) {
                return Err(invalid(
                    &format!("{key}.type"),
                    "coils and discrete inputs are `bool`, registers are not".into(),
                ));
            }
            let writable_table = matches!(r.kind, RegisterKind::Holding | RegisterKind::Coil);
            if r.access != Access::Read && !writable_table {
                return Err(invalid(
                    &format!("{key}.access"),
                    "input registers and discrete inputs cannot be written".into(),
                ));
            }
            if u32::from(r.address) + u32::from(r.data_type.width()) > 0x1_0000 {
                return Err(invalid(
                    &format!("{key}.address"),
                    "the value runs past address 65535".into(),
                ));
            }
            registers.insert(
                name.clone(),
                Register {
                    name,
                    address: r.address,
                    kind: r.kind,
                    data_type: r.data_type,
                    scale: r.scale,
                    offset: r.offset,
                    unit: r.unit,
                    access: r.access,
                    word_order: r.word_order.unwrap_or(raw.modbus.word_order),
                    byte_order: r.byte_order.unwrap_or(raw.modbus.byte_order),
                },
            );
        }
        let writable = |key: &str, name: &str| -> Result<String, ProfileError> {
            match registers.get(name) {
                None => Err(invalid(key, format!("no register named `{name}`"))),
                Some(r) if r.access == Access::Read => {
                    Err(invalid(key, format!("register `{name}` is read-only")))
                }
                Some(_) => Ok(name.to_string()),
            }
        };
        let power_stage = match raw.power_stage {
            None => None,
            Some(s) => {
                if !(s.max_setpoint.is_finite() && s.max_setpoint > 0.0) {
                    return Err(invalid(
                        "power_stage.max_setpoint",
                        format!("{} must be a finite number > 0", s.max_setpoint),
                    ));
                }
                let heartbeat = match (s.heartbeat, s.heartbeat_period_ms) {
                    (None, None) => None,
                    (Some(_), Some(ms)) if ms > MAX_HEARTBEAT_PERIOD_MS => {
                        return Err(invalid(
                            "power_stage.heartbeat_period_ms",
                            format!(
                                "{ms} ms: at most {MAX_HEARTBEAT_PERIOD_MS}, or the device's own watchdog cannot hold the output"
                            ),
                        ))
                    }
                    (Some(h), Some(ms)) if ms > 0 => Some((
                        writable("power_stage.heartbeat", &h)?,
                        Duration::from_millis(ms),
                    )),
                    _ => {
                        return Err(invalid(
                            "power_stage.heartbeat_period_ms",
                            "a heartbeat needs both a register and a period > 0".into(),
                        ))
                    }
                };
                Some(StageMap {
                    setpoint: writable("power_stage.setpoint", &s.setpoint)?,
                    enable: match s.enable {
                        Some(e) => Some((
                            writable("power_stage.enable", &e)?,
                            s.enable_value,
                            s.disable_value,
                        )),
                        None => None,
                    },
                    current_limit: match s.current_limit {
                        Some(c) => Some(writable("power_stage.current_limit", &c)?),
                        None => None,
                    },
                    max_setpoint: s.max_setpoint,
                    heartbeat,
                })
            }
        };
        Ok(DeviceProfile {
            name: raw.device.name,
            role: raw.device.role,
            source: raw.device.source,
            verification: raw.device.verification,
            unit_id: raw.modbus.unit_id,
            serial: raw.modbus.serial,
            max_read_gap: raw.modbus.max_read_gap,
            registers,
            power_stage,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[device]
name = "test supply"
role = "dc_supply"
source = "made up for a test"
verification = "none"

[modbus]
unit_id = 1

[registers.v_set]
address = 8
kind = "holding"
type = "u16"
scale = 0.01
unit = "V"
access = "read_write"

[registers.v_out]
address = 10
kind = "input"
type = "f32"
unit = "V"
word_order = "low_first"

[power_stage]
setpoint = "v_set"
max_setpoint = 60
"#;

    #[test]
    fn a_good_profile_loads_with_defaults_applied() {
        let p = DeviceProfile::parse("p.toml", GOOD).unwrap();
        let v = p.register("v_out").unwrap();
        assert_eq!(v.word_order, WordOrder::LowFirst);
        assert_eq!(v.byte_order, ByteOrder::Big);
        assert_eq!(p.register("v_set").unwrap().scale, 0.01);
        assert_eq!(p.power_stage.unwrap().setpoint, "v_set");
    }

    #[test]
    fn errors_name_the_file_and_the_line_or_key() {
        let e = DeviceProfile::parse(
            "p.toml",
            &GOOD.replace("kind = \"input\"", "kind = \"inptu\""),
        )
        .unwrap_err()
        .to_string();
        let line = GOOD.lines().position(|l| l == "kind = \"input\"").unwrap() + 1;
        assert!(e.starts_with(&format!("p.toml:{line}:")), "{e}");

        let e = DeviceProfile::parse(
            "p.toml",
            &GOOD.replace("setpoint = \"v_set\"", "setpoint = \"v_out\""),
        )
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            "p.toml: power_stage.setpoint: register `v_out` is read-only"
        );

        let e = DeviceProfile::parse("p.toml", &GOOD.replace("scale = 0.01", "scale = 0"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("p.toml: registers.v_set.scale:"), "{e}");

        // Found by fuzzing: a finite scale whose largest raw value reads
        // as infinity.
        let e = DeviceProfile::parse("p.toml", &GOOD.replace("scale = 0.01", "scale = 1e306"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("p.toml: registers.v_set.scale:") && e.contains("overflows"),
            "{e}"
        );

        let e = DeviceProfile::parse("p.toml", &GOOD.replace("type = \"f32\"", "type = \"bool\""))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("p.toml: registers.v_out.type:"), "{e}");

        let e = DeviceProfile::parse("p.toml", &GOOD.replace("unit_id = 1", "unit_id = 0"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("modbus.unit_id"), "{e}");

        let e = DeviceProfile::parse(
            "p.toml",
            &GOOD.replace("[power_stage]", "[power_stage]\nbogus = 1"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("bogus"), "{e}");
    }

    #[test]
    fn a_heartbeat_too_slow_for_a_watchdog_is_refused() {
        let with = |ms: u64| {
            let text = GOOD.replace(
                "max_setpoint = 60",
                &format!("max_setpoint = 60\nheartbeat = \"v_set\"\nheartbeat_period_ms = {ms}"),
            );
            DeviceProfile::parse("p.toml", &text)
        };
        assert!(with(500).unwrap().power_stage.unwrap().heartbeat.is_some());
        let e = with(10_000_000_000).unwrap_err().to_string();
        assert!(
            e.starts_with("p.toml: power_stage.heartbeat_period_ms:") && e.contains("10000"),
            "{e}"
        );
    }

    #[test]
    fn every_shipped_profile_is_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/devices");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let p = DeviceProfile::load(&path).unwrap_or_else(|e| panic!("{e}"));
                assert!(!p.registers.is_empty(), "{}", path.display());
                n += 1;
            }
        }
        assert!(n >= 3, "expected the shipped Modbus profiles, found {n}");
    }
}
