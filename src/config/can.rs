//! `[rig.modbus.can]`: sensor channels carried as signals of a DBC file
//! on a CAN bus, reached through an SLCAN adapter (a USB-CAN adapter's
//! serial port) or a SocketCAN interface. With `rig.modbus.simulate`, the
//! simulated CANopen encoder sends them over SLCAN on a pseudo-terminal.
//!
//! ```toml
//! [rig.modbus.can]
//! dbc = "devices/cia406-encoder.dbc"   # relative to this file
//! transport = "slcan"          # or "socketcan"
//! path = "/dev/ttyACM0"        # slcan: the adapter's port (leave out with rig.modbus.simulate)
//! baud_rate = 115200           # slcan: the serial line (USB adapters ignore it)
//! bitrate = 500000             # slcan: CAN bit rate the adapter opens the bus at (default: as configured in the adapter)
//! # interface = "can0"         # socketcan
//! channels = { encoder_count = { signal = "position", rate_Hz = 500 } }
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use motorbench_drivers::can::{SignalMap, SlcanBitrate};
use motorbench_drivers::serial::port::{Parity, SerialSettings};
use serde::Deserialize;

use super::sensor_channels::{ChannelField, RawChannel, SensorChannel};

/// Raw `[rig.modbus.can]` table.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCanLink {
    dbc: String,
    transport: Option<String>,
    path: Option<String>,
    baud_rate: Option<u32>,
    parity: Option<Parity>,
    stop_bits: Option<u8>,
    bitrate: Option<u32>,
    interface: Option<String>,
    channels: BTreeMap<String, RawChannel>,
}

/// How the CAN bus is reached.
#[derive(Debug, Clone, PartialEq)]
pub enum CanTransport {
    /// An SLCAN (Lawicel) adapter on a serial port.
    Slcan {
        /// The port (`None`: served by the simulated rig).
        port: Option<SerialSettings>,
        /// The CAN bit rate to open the bus at (`None`: the adapter's).
        bitrate: Option<SlcanBitrate>,
    },
    /// A Linux SocketCAN interface.
    SocketCan {
        /// Interface name, e.g. `can0`.
        interface: String,
    },
}

/// The CAN sensors, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct CanLink {
    /// The DBC file, as resolved.
    pub dbc_path: String,
    /// Its signals.
    pub map: SignalMap,
    /// How the bus is reached.
    pub transport: CanTransport,
    /// The channels (`name` is the signal).
    pub channels: Vec<SensorChannel>,
}

impl RawCanLink {
    /// Validate; `dir` resolves the DBC path; `simulated` when the
    /// simulated rig serves the bus; `default_rate` fills channels without
    /// a rate. Errors are `(key, reason)`.
    pub(super) fn validate(
        self,
        dir: &Path,
        simulated: bool,
        default_rate: f64,
    ) -> Result<CanLink, (String, String)> {
        const KEY: &str = "rig.modbus.can";
        let path = dir.join(&self.dbc);
        let dbc_path = path.display().to_string();
        let text = std::fs::read_to_string(&path).map_err(|e| {
            (
                format!("{KEY}.dbc"),
                format!("{dbc_path}: cannot read: {e}"),
            )
        })?;
        let map = SignalMap::parse(&dbc_path, &text)
            .map_err(|e| (format!("{KEY}.dbc"), e.to_string()))?;
        let bitrate = match self.bitrate {
            None => None,
            Some(b) => Some(SlcanBitrate::from_bits_per_s(b).ok_or_else(|| {
                (
                    format!("{KEY}.bitrate"),
                    format!("{b} bit/s is not an SLCAN rate (10k, 20k, 50k, 100k, 125k, 250k, 500k, 800k, 1M)"),
                )
            })?),
        };
        let transport = match (self.transport.as_deref(), simulated) {
            (Some("socketcan"), true) => {
                return Err((
                    format!("{KEY}.transport"),
                    "the simulated encoder is served over SLCAN: use \"slcan\" or leave it out"
                        .into(),
                ))
            }
            (None | Some("slcan"), true) => {
                if self.path.is_some() || self.interface.is_some() {
                    return Err((
                        KEY.into(),
                        "path and interface come from rig.modbus.simulate here: leave them out"
                            .into(),
                    ));
                }
                CanTransport::Slcan {
                    port: None,
                    bitrate,
                }
            }
            (Some("slcan"), false) => {
                let p = self.path.ok_or_else(|| {
                    (
                        format!("{KEY}.path"),
                        "missing: the SLCAN adapter's serial port".into(),
                    )
                })?;
                if self.interface.is_some() {
                    return Err((
                        format!("{KEY}.interface"),
                        "is for transport = \"socketcan\"".into(),
                    ));
                }
                CanTransport::Slcan {
                    port: Some(SerialSettings {
                        path: p,
                        baud_rate: self.baud_rate.unwrap_or(115_200),
                        parity: self.parity.unwrap_or_default(),
                        stop_bits: self.stop_bits.unwrap_or(1),
                    }),
                    bitrate,
                }
            }
            (Some("socketcan"), false) => {
                let interface = self.interface.ok_or_else(|| {
                    (
                        format!("{KEY}.interface"),
                        "missing: the SocketCAN interface, e.g. \"can0\"".into(),
                    )
                })?;
                if self.path.is_some() || self.baud_rate.is_some() || bitrate.is_some() {
                    return Err((
                        KEY.into(),
                        "path, baud_rate and bitrate are for transport = \"slcan\" (SocketCAN's bit rate is set with `ip link`)".into(),
                    ));
                }
                CanTransport::SocketCan { interface }
            }
            (None, false) => {
                return Err((
                    format!("{KEY}.transport"),
                    "missing: \"slcan\" or \"socketcan\"".into(),
                ))
            }
            (Some(other), _) => {
                return Err((
                    format!("{KEY}.transport"),
                    format!("\"{other}\": use \"slcan\" or \"socketcan\""),
                ))
            }
        };
        if self.channels.is_empty() {
            return Err((
                format!("{KEY}.channels"),
                "empty: name at least one signal".into(),
            ));
        }
        let mut channels = Vec::new();
        for (quantity, raw) in self.channels {
            let key = format!("{KEY}.channels.{quantity}");
            let c = raw.validate(&quantity, &key, ChannelField::Signal, default_rate, Ok(()))?;
            if map.find(&c.name).is_none() {
                return Err((key, format!("{dbc_path} has no signal `{}`", c.name)));
            }
            channels.push(c);
        }
        Ok(CanLink {
            dbc_path,
            map,
            transport,
            channels,
        })
    }
}
