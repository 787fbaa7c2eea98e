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

#[cfg(test)]
mod tests {
    use crate::config::{Backend, CanTransport, Config, ConfigError};

    fn shipped() -> (String, String) {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-modbus-can-dc.toml");
        (path.to_string(), std::fs::read_to_string(path).unwrap())
    }

    fn with(replace: &str, by: &str) -> Result<Config, ConfigError> {
        let (path, text) = shipped();
        assert!(text.contains(replace), "{replace}");
        Config::parse(&path, &text.replace(replace, by))
    }

    fn key_of(e: ConfigError) -> String {
        match e {
            ConfigError::Invalid { key, .. } => key,
            other => panic!("not an invalid value: {other}"),
        }
    }

    const CHANNELS: &str =
        "channels = { encoder_count = { signal = \"position\", rate_Hz = 500 } }";

    #[test]
    fn the_shipped_config_merges_the_can_encoder() {
        let (path, text) = shipped();
        let cfg = Config::parse(&path, &text).unwrap();
        let Backend::Modbus { rig, .. } = &cfg.backend else {
            panic!("modbus")
        };
        let can = rig.can.as_ref().unwrap();
        assert!(matches!(
            can.transport,
            CanTransport::Slcan { port: None, .. }
        ));
        assert_eq!(rig.rate_of("encoder_count"), Some(500.0));
        assert_eq!(rig.rate_of("armature_current"), Some(1000.0));
        assert_eq!(rig.merge_window.as_millis(), 10);
    }

    #[test]
    fn bad_can_sections_name_their_key() {
        let cases = [
            (
                CHANNELS,
                "channels = { encoder_count = { signal = \"angle\" } }",
                "rig.modbus.can.channels.encoder_count",
            ),
            (
                CHANNELS,
                "channels = { encoder_count = { signal = \"position\", rate_Hz = -1 } }",
                "rig.modbus.can.channels.encoder_count.rate_Hz",
            ),
            (
                CHANNELS,
                "channels = { armature_current = \"position\", encoder_count = \"position\" }",
                "rig.modbus.can.channels.armature_current",
            ),
            (
                "bitrate = 500000",
                "bitrate = 300000",
                "rig.modbus.can.bitrate",
            ),
            (
                "transport = \"slcan\"",
                "transport = \"socketcan\"",
                "rig.modbus.can.transport",
            ),
            (
                "transport = \"slcan\"",
                "transport = \"slcan\"\npath = \"/dev/ttyACM0\"",
                "rig.modbus.can",
            ),
            (
                "dbc = \"devices/cia406-encoder.dbc\"",
                "dbc = \"devices/no-such.dbc\"",
                "rig.modbus.can.dbc",
            ),
            (
                "channels = { armature_voltage = \"0\", armature_current = \"1\" }",
                "channels = { armature_voltage = \"0\", armature_current = { key = \"1\", rate_Hz = 500 } }",
                "rig.modbus.sensors.channels.armature_current.rate_Hz",
            ),
            (
                "merge_window_ms = 10 ",
                "merge_window_ms = 5000 ",
                "rig.modbus.merge_window_ms",
            ),
        ];
        for (from, to, key) in cases {
            let e = with(from, to).expect_err(to);
            let text = e.to_string();
            assert!(text.contains("sim-modbus-can-dc.toml"), "{text}");
            assert_eq!(key_of(e), key, "{to}");
        }
        // Without the CAN section nothing gives the encoder count.
        let (path, text) = shipped();
        let cut = text.find("[rig.modbus.can]").unwrap();
        let end = text[cut..].find("\n\n").unwrap() + cut;
        let e = Config::parse(&path, &format!("{}{}", &text[..cut], &text[end..])).unwrap_err();
        assert_eq!(key_of(e), "rig.modbus.sensors.channels");
    }

    #[test]
    fn a_real_rig_names_its_adapter_or_interface() {
        let (path, text) = shipped();
        let real = text
            .replace("simulate = \"tcp\"", "")
            .replace(
                "unit_id = 1\n\n[rig.modbus.sensors]",
                "unit_id = 1\ntransport = \"tcp\"\naddress = \"192.168.0.20:502\"\n\n[rig.modbus.sensors]",
            )
            .replace(
                "framing = \"binary\"",
                "framing = \"binary\"\npath = \"/dev/ttyUSB1\"\nbaud_rate = 921600",
            );
        let e = Config::parse(&path, &real).unwrap_err();
        assert_eq!(key_of(e), "rig.modbus.can.path");
        let slcan = real.replace(
            "transport = \"slcan\"",
            "transport = \"slcan\"\npath = \"/dev/ttyACM0\"",
        );
        let cfg = Config::parse(&path, &slcan).unwrap();
        let Backend::Modbus { rig, .. } = &cfg.backend else {
            panic!("modbus")
        };
        match &rig.can.as_ref().unwrap().transport {
            CanTransport::Slcan {
                port: Some(p),
                bitrate: Some(_),
            } => assert_eq!((p.path.as_str(), p.baud_rate), ("/dev/ttyACM0", 115_200)),
            other => panic!("{other:?}"),
        }
        let socketcan = real
            .replace(
                "transport = \"slcan\"",
                "transport = \"socketcan\"\ninterface = \"can0\"",
            )
            .replace("bitrate = 500000", "");
        let cfg = Config::parse(&path, &socketcan).unwrap();
        let Backend::Modbus { rig, .. } = &cfg.backend else {
            panic!("modbus")
        };
        assert_eq!(
            rig.can.as_ref().unwrap().transport,
            CanTransport::SocketCan {
                interface: "can0".into()
            }
        );
    }
}
