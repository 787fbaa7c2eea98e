//! The `modbus` rig backend: a power stage reached over Modbus TCP or RTU,
//! described by a device profile (`config/devices/*.toml`), and sensors
//! either polled over Modbus (a profile again) or streaming over a serial
//! line (the ASCII or binary protocol of `motorbench_drivers::serial`);
//! optionally with the simulated rig served behind those links so the
//! whole test runs through the real driver code.
//!
//! ```toml
//! [rig]
//! backend = "modbus"
//! sample_rate_Hz = 500          # poll rate of the sensor channels
//!
//! [rig.modbus]
//! simulate = "tcp"              # serve [rig.simulated] on loopback TCP ("rtu": PTY pairs); omit on a real rig
//! timeout_ms = 200              # deadline of every Modbus call
//! retries = 2                   # extra attempts of idempotent calls
//! max_lost_polls = 5            # failed polls in a row that end the test
//!
//! [rig.modbus.power_stage]
//! profile = "devices/riden-rd6006.toml"   # relative to this file
//! unit_id = 1                   # default: the profile's
//! transport = "tcp"             # or "rtu"
//! address = "192.168.0.20:502"  # tcp
//! # path = "/dev/ttyUSB0"       # rtu; baud_rate, parity, stop_bits default to the profile's
//!
//! [rig.modbus.sensors]
//! profile = "devices/sim-daq.toml"
//! transport = "tcp"
//! address = "192.168.0.21:502"
//! encoder_lines = 2500
//! channels = { armature_voltage = "armature_voltage", armature_current = "armature_current", encoder_count = "encoder_count" }
//! ```
//!
//! Sensors that stream over a serial line instead:
//!
//! ```toml
//! [rig.modbus.sensors]
//! transport = "serial"
//! framing = "binary"            # or "ascii"
//! path = "/dev/ttyUSB1"         # leave out with rig.modbus.simulate
//! baud_rate = 921600
//! encoder_lines = 2500
//! channels = { armature_voltage = "0", armature_current = "1", encoder_count = "2" }   # record keys
//! ```

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use motorbench_drivers::modbus::{CallPolicy, DeviceProfile};
use motorbench_drivers::serial::port::{Parity, SerialSettings};
use motorbench_drivers::serial::SerialFraming;
use serde::Deserialize;

use crate::bounds;

use super::can::{CanLink, RawCanLink};
use super::sensor_channels::{ChannelField, RawChannel, SensorChannel};

/// Raw `[rig.modbus]` table.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawModbusRig {
    simulate: Option<String>,
    #[serde(default = "default_timeout")]
    timeout_ms: u64,
    #[serde(default = "default_retries")]
    retries: u32,
    #[serde(default = "default_lost")]
    max_lost_polls: u32,
    power_stage: RawLink,
    sensors: RawSensors,
    can: Option<RawCanLink>,
    #[serde(default = "default_reorder")]
    merge_window_ms: u64,
}

fn default_timeout() -> u64 {
    200
}
fn default_retries() -> u32 {
    2
}
fn default_lost() -> u32 {
    5
}
fn default_reorder() -> u64 {
    motorbench_drivers::DEFAULT_REORDER.as_millis() as u64
}

/// `rig.modbus.simulate` (of a DC or an induction-machine rig), validated:
/// which transport serves the simulated rig, if any. Serving it needs a
/// `[rig.simulated]` section.
pub(crate) fn simulated_transport(
    simulate: Option<&str>,
    simulated_present: bool,
) -> Result<Option<SimulatedTransport>, (String, String)> {
    let transport = match simulate {
        None => None,
        Some("tcp") => Some(SimulatedTransport::Tcp),
        Some("rtu") => Some(SimulatedTransport::Rtu),
        Some(other) => {
            return Err((
                "rig.modbus.simulate".into(),
                format!("\"{other}\": use \"tcp\" or \"rtu\", or leave it out on a real rig"),
            ))
        }
    };
    if transport.is_some() && !simulated_present {
        return Err((
            "rig.simulated".into(),
            "missing: rig.modbus.simulate serves the simulated rig, which needs it".into(),
        ));
    }
    Ok(transport)
}

/// `rig.modbus.timeout_ms` and `rig.modbus.retries` (of a DC or an
/// induction-machine rig) validated against [`bounds`]: how long one bus
/// call may wait, and how often it is tried again.
pub(crate) fn call_policy(timeout_ms: u64, retries: u32) -> Result<CallPolicy, (String, String)> {
    let timeout_ms = bounds::call_timeout_ms(timeout_ms)
        .map_err(|why| ("rig.modbus.timeout_ms".to_string(), why.to_string()))?;
    let retries = bounds::at_most(retries, bounds::MAX_RETRIES)
        .map_err(|why| ("rig.modbus.retries".to_string(), why.to_string()))?;
    Ok(CallPolicy {
        timeout: Duration::from_millis(timeout_ms),
        retries,
        retry_delay: Duration::from_millis(10),
    })
}

/// `rig.modbus.merge_window_ms` (of a DC or an induction-machine rig)
/// validated: how long the merged sensor stream holds each batch to put
/// the links in time order. Every reading, and so every limit check, waits
/// that long: at most 1 s.
pub(crate) fn merge_window(ms: u64) -> Result<Duration, (String, String)> {
    if ms > 1000 {
        return Err((
            "rig.modbus.merge_window_ms".into(),
            format!(
                "{ms} ms would delay every reading (and every limit check) that long: at most 1000"
            ),
        ));
    }
    Ok(Duration::from_millis(ms))
}

/// Raw link of one Modbus device (profile, unit, where it is).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLink {
    profile: String,
    unit_id: Option<u8>,
    transport: Option<String>,
    address: Option<String>,
    path: Option<String>,
    baud_rate: Option<u32>,
    parity: Option<Parity>,
    stop_bits: Option<u8>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSensors {
    profile: Option<String>,
    unit_id: Option<u8>,
    transport: Option<String>,
    address: Option<String>,
    path: Option<String>,
    baud_rate: Option<u32>,
    parity: Option<Parity>,
    stop_bits: Option<u8>,
    framing: Option<SerialFraming>,
    encoder_lines: u32,
    channels: BTreeMap<String, RawChannel>,
}

/// Where a Modbus device is reached.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkSpec {
    /// Modbus TCP.
    Tcp(SocketAddr),
    /// Modbus RTU on a serial port.
    Rtu(SerialSettings),
    /// Served by the simulated rig (the address is known at run time).
    Simulated,
}

/// How the simulated rig is served behind the links.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimulatedTransport {
    /// Modbus TCP servers on 127.0.0.1, ports the OS picks.
    Tcp,
    /// Modbus RTU servers on pseudo-terminal pairs.
    Rtu,
}

/// One Modbus device of the rig.
#[derive(Debug, Clone, PartialEq)]
pub struct ModbusDeviceLink {
    /// The profile file, as resolved.
    pub profile_path: String,
    /// Its register map.
    pub profile: DeviceProfile,
    /// Unit id.
    pub unit_id: u8,
    /// Where it is.
    pub link: LinkSpec,
}

/// The `modbus` backend, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct ModbusRig {
    /// Serve the simulated rig behind the links.
    pub simulate: Option<SimulatedTransport>,
    /// Deadline and retries of every call.
    pub policy: CallPolicy,
    /// Failed polls in a row that end the test.
    pub max_lost_polls: u32,
    /// The device that drives the motor.
    pub power_stage: ModbusDeviceLink,
    /// Where the sensor channels come from.
    pub sensors: SensorLink,
    /// The channels of `sensors` (`name`: register name or record key),
    /// each with its rate.
    pub channels: Vec<SensorChannel>,
    /// Encoder lines per revolution (4 counts per line).
    pub encoder_lines: u32,
    /// Further channels over CAN (`[rig.modbus.can]`).
    pub can: Option<CanLink>,
    /// How long the merged sensor stream holds a batch to put the sources'
    /// batches in time order (`rig.modbus.merge_window_ms`).
    pub merge_window: Duration,
}

impl ModbusRig {
    /// Every sensor channel, wherever it comes from.
    pub fn all_channels(&self) -> impl Iterator<Item = &SensorChannel> {
        self.channels
            .iter()
            .chain(self.can.iter().flat_map(|c| c.channels.iter()))
    }

    /// The rate of the channel carrying `quantity`, Hz.
    pub fn rate_of(&self, quantity: &str) -> Option<f64> {
        self.all_channels()
            .find(|c| c.quantity == quantity)
            .map(|c| c.rate_hz)
    }
}

/// Where the sensor channels come from.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorLink {
    /// Registers of a Modbus device, polled at the sample rate.
    Modbus(Box<ModbusDeviceLink>),
    /// Records streaming over a serial line.
    Serial {
        /// The port (`None`: served by the simulated rig).
        port: Option<SerialSettings>,
        /// The line protocol.
        framing: SerialFraming,
    },
}

/// Quantities the DC bench needs from the sensors.
const REQUIRED: [&str; 3] = ["armature_voltage", "armature_current", "encoder_count"];

impl RawModbusRig {
    /// Validate; `dir` resolves relative profile paths; `default_rate`
    /// (`rig.sample_rate_Hz`) is the rate of channels that name none;
    /// errors are `(key, reason)`.
    pub(crate) fn validate(
        self,
        dir: &Path,
        simulated_present: bool,
        default_rate: f64,
    ) -> Result<ModbusRig, (String, String)> {
        let simulate = simulated_transport(self.simulate.as_deref(), simulated_present)?;
        let policy = call_policy(self.timeout_ms, self.retries)?;
        let max_lost_polls = bounds::at_most(self.max_lost_polls, bounds::MAX_LOST_POLLS)
            .map_err(|why| ("rig.modbus.max_lost_polls".to_string(), why.to_string()))?;
        let power_stage =
            self.power_stage
                .validate("rig.modbus.power_stage", dir, simulate.is_some())?;
        if power_stage.profile.power_stage.is_none() {
            return Err((
                "rig.modbus.power_stage.profile".into(),
                format!(
                    "{} has no [power_stage] section: it cannot drive the rig",
                    power_stage.profile_path
                ),
            ));
        }
        let raw = self.sensors;
        let serial = raw.transport.as_deref() == Some("serial") || raw.framing.is_some();
        let mut channels = Vec::new();
        let sensors = if serial {
            let key = "rig.modbus.sensors";
            if raw.profile.is_some() || raw.unit_id.is_some() || raw.address.is_some() {
                return Err((
                    key.into(),
                    "a serial stream takes no profile, unit_id or address".into(),
                ));
            }
            if raw.transport.as_deref() != Some("serial") {
                return Err((
                    format!("{key}.transport"),
                    "framing is for transport = \"serial\"".into(),
                ));
            }
            let framing = raw.framing.ok_or_else(|| {
                (
                    format!("{key}.framing"),
                    "missing: \"ascii\" or \"binary\"".into(),
                )
            })?;
            let port = match (simulate.is_some(), raw.path) {
                (true, None) => None,
                (true, Some(_)) => {
                    return Err((
                        format!("{key}.path"),
                        "comes from rig.modbus.simulate here: leave it out".into(),
                    ))
                }
                (false, Some(path)) => Some(SerialSettings {
                    path,
                    baud_rate: raw
                        .baud_rate
                        .ok_or_else(|| (format!("{key}.baud_rate"), "missing".into()))?,
                    parity: raw.parity.unwrap_or_default(),
                    stop_bits: raw.stop_bits.unwrap_or(1),
                }),
                (false, None) => {
                    return Err((format!("{key}.path"), "missing: the serial port".into()))
                }
            };
            for (quantity, c) in raw.channels {
                let key = format!("{key}.channels.{quantity}");
                channels.push(c.validate(
                    &quantity,
                    &key,
                    ChannelField::Key,
                    default_rate,
                    Err("a streaming device sends at its own rate: set rig.sample_rate_Hz to it"),
                )?);
            }
            SensorLink::Serial { port, framing }
        } else {
            let profile = raw.profile.ok_or_else(|| {
                (
                    "rig.modbus.sensors.profile".to_string(),
                    "missing: the device profile of the Modbus sensors".to_string(),
                )
            })?;
            let link = RawLink {
                profile,
                unit_id: raw.unit_id,
                transport: raw.transport,
                address: raw.address,
                path: raw.path,
                baud_rate: raw.baud_rate,
                parity: raw.parity,
                stop_bits: raw.stop_bits,
            }
            .validate("rig.modbus.sensors", dir, simulate.is_some())?;
            for (quantity, raw_channel) in raw.channels {
                let key = format!("rig.modbus.sensors.channels.{quantity}");
                let c = raw_channel.validate(
                    &quantity,
                    &key,
                    ChannelField::Register,
                    default_rate,
                    Ok(()),
                )?;
                let register = &c.name;
                match link.profile.register(register) {
                    None => {
                        return Err((
                            key,
                            format!("{} has no register `{register}`", link.profile_path),
                        ))
                    }
                    Some(r) if r.access == motorbench_drivers::modbus::Access::Write => {
                        return Err((key, format!("register `{register}` is write-only")))
                    }
                    Some(_) => channels.push(c),
                }
            }
            SensorLink::Modbus(Box::new(link))
        };
        let can = match self.can {
            None => None,
            Some(c) => Some(c.validate(dir, simulate.is_some(), default_rate)?),
        };
        if let Some(can) = &can {
            for c in &can.channels {
                if channels.iter().any(|s| s.quantity == c.quantity) {
                    return Err((
                        format!("rig.modbus.can.channels.{}", c.quantity),
                        "also comes from rig.modbus.sensors.channels: give each quantity one source"
                            .into(),
                    ));
                }
            }
        }
        for q in REQUIRED {
            let mut everywhere = channels.iter().chain(can.iter().flat_map(|c| &c.channels));
            if !everywhere.any(|c| c.quantity == q) {
                return Err((
                    "rig.modbus.sensors.channels".into(),
                    format!("missing `{q}`: a DC test needs armature voltage, current and the encoder count"),
                ));
            }
        }
        if raw.encoder_lines == 0 {
            return Err((
                "rig.modbus.sensors.encoder_lines".into(),
                "must be > 0".into(),
            ));
        }
        let merge_window = merge_window(self.merge_window_ms)?;
        Ok(ModbusRig {
            simulate,
            policy,
            max_lost_polls: max_lost_polls.max(1),
            power_stage,
            sensors,
            channels,
            encoder_lines: raw.encoder_lines,
            can,
            merge_window,
        })
    }
}

impl RawLink {
    /// Validate under `key`; `dir` resolves the profile path; `simulated`:
    /// the link is served by the simulated rig.
    pub(crate) fn validate(
        self,
        key: &str,
        dir: &Path,
        simulated: bool,
    ) -> Result<ModbusDeviceLink, (String, String)> {
        let path = dir.join(&self.profile);
        let profile_path = path.display().to_string();
        let profile =
            DeviceProfile::load(&path).map_err(|e| (format!("{key}.profile"), e.to_string()))?;
        let unit_id = self.unit_id.unwrap_or(profile.unit_id);
        if unit_id == 0 {
            return Err((
                format!("{key}.unit_id"),
                "0 is the broadcast address".into(),
            ));
        }
        let given = self.address.is_some() || self.path.is_some() || self.transport.is_some();
        let link = if simulated {
            if given {
                return Err((
                    key.to_string(),
                    "transport, address and path come from rig.modbus.simulate here: leave them out".into(),
                ));
            }
            LinkSpec::Simulated
        } else {
            match self.transport.as_deref() {
                Some("tcp") => {
                    let a = self.address.ok_or_else(|| {
                        (
                            format!("{key}.address"),
                            "missing: tcp needs host:port".into(),
                        )
                    })?;
                    let addr = a.parse().map_err(|e| {
                        (
                            format!("{key}.address"),
                            format!("\"{a}\" is not host:port: {e}"),
                        )
                    })?;
                    LinkSpec::Tcp(addr)
                }
                Some("rtu") => {
                    let p = self.path.ok_or_else(|| {
                        (
                            format!("{key}.path"),
                            "missing: rtu needs a serial port path".into(),
                        )
                    })?;
                    let d = profile.serial;
                    let baud = self.baud_rate.or(d.map(|s| s.baud_rate)).ok_or_else(|| {
                        (
                            format!("{key}.baud_rate"),
                            "missing (the profile has no default)".into(),
                        )
                    })?;
                    LinkSpec::Rtu(SerialSettings {
                        path: p,
                        baud_rate: baud,
                        parity: self.parity.or(d.map(|s| s.parity)).unwrap_or_default(),
                        stop_bits: self.stop_bits.or(d.map(|s| s.stop_bits)).unwrap_or(1),
                    })
                }
                Some(other) => {
                    return Err((
                        format!("{key}.transport"),
                        format!("\"{other}\": use \"tcp\" or \"rtu\""),
                    ))
                }
                None => {
                    return Err((
                        format!("{key}.transport"),
                        "missing: \"tcp\" or \"rtu\"".into(),
                    ))
                }
            }
        };
        Ok(ModbusDeviceLink {
            profile_path,
            profile,
            unit_id,
            link,
        })
    }
}
