//! Sensor channels of a rig configuration and their sampling rates.
//!
//! A channel maps a quantity the bench knows (`armature_current`, …) to
//! where a device carries it: a register of a Modbus profile, a key of a
//! streaming record, or a signal of a DBC file. Each channel may name its
//! own rate; without one it takes `rig.sample_rate_Hz`:
//!
//! ```toml
//! channels = { armature_voltage = "armature_voltage", armature_current = { register = "armature_current", rate_Hz = 500 } }
//! ```
//!
//! For polled devices (Modbus) the rate is the poll rate: channels of one
//! rate are read together. For devices that send on their own (a CAN
//! message, a streaming record) it is the nominal rate the loss and jitter
//! statistics are counted against.

use serde::Deserialize;

/// One channel as written: a name, or a table with a name and a rate.
#[derive(Debug, Clone, Deserialize)]
#[serde(
    untagged,
    expecting = "a name (\"armature_current\") or a table like { register = \"armature_current\", rate_Hz = 500 }"
)]
pub(super) enum RawChannel {
    /// The register, record key or signal, at the default rate.
    Name(String),
    /// With its own rate.
    Spec(RawChannelSpec),
}

/// The table form of a channel.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawChannelSpec {
    register: Option<String>,
    key: Option<String>,
    signal: Option<String>,
    #[serde(rename = "rate_Hz")]
    rate_hz: Option<f64>,
}

/// One validated sensor channel.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorChannel {
    /// The quantity the bench knows it as.
    pub quantity: String,
    /// Where the device carries it: a register name (Modbus), a record key
    /// (serial stream) or a signal name (CAN).
    pub name: String,
    /// Sampling rate, Hz (poll rate, or the nominal rate of a device that
    /// sends on its own).
    pub rate_hz: f64,
}

/// Which name a channel table takes, by where the channel comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ChannelField {
    /// `register`: a Modbus device.
    Register,
    /// `key`: a streaming record.
    Key,
    /// `signal`: a DBC signal.
    Signal,
}

impl ChannelField {
    fn name(self) -> &'static str {
        match self {
            ChannelField::Register => "register",
            ChannelField::Key => "key",
            ChannelField::Signal => "signal",
        }
    }
}

impl RawChannel {
    /// Validate the channel `quantity` at `key` (its dotted path); `field`
    /// is the name its table takes; `default_rate` fills a missing rate;
    /// `rate_allowed` is false where the device alone sets the rate.
    pub(super) fn validate(
        self,
        quantity: &str,
        key: &str,
        field: ChannelField,
        default_rate: f64,
        rate_allowed: Result<(), &str>,
    ) -> Result<SensorChannel, (String, String)> {
        let (name, rate) = match self {
            RawChannel::Name(n) => (n, None),
            RawChannel::Spec(s) => {
                let given = [
                    (ChannelField::Register, s.register),
                    (ChannelField::Key, s.key),
                    (ChannelField::Signal, s.signal),
                ];
                let mut name = None;
                for (f, v) in given {
                    match (f == field, v) {
                        (true, v) => name = v,
                        (false, Some(_)) => {
                            return Err((
                                format!("{key}.{}", f.name()),
                                format!("not here: this channel takes `{}`", field.name()),
                            ))
                        }
                        (false, None) => {}
                    }
                }
                let name = name.ok_or_else(|| {
                    (
                        format!("{key}.{}", field.name()),
                        "missing: which one carries the quantity".to_string(),
                    )
                })?;
                (name, s.rate_hz)
            }
        };
        if name.trim().is_empty() {
            return Err((key.to_string(), "the name must not be empty".into()));
        }
        let rate_hz = match rate {
            None => default_rate,
            Some(r) => {
                if let Err(why) = rate_allowed {
                    return Err((format!("{key}.rate_Hz"), why.to_string()));
                }
                crate::bounds::sample_rate(r)
                    .map_err(|why| (format!("{key}.rate_Hz"), why.to_string()))?
            }
        };
        Ok(SensorChannel {
            quantity: quantity.to_string(),
            name,
            rate_hz,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize)]
    struct T {
        c: RawChannel,
    }

    fn parse(text: &str) -> RawChannel {
        toml::from_str::<T>(text).unwrap().c
    }

    #[test]
    fn a_name_takes_the_default_rate_and_a_table_its_own() {
        let c = parse("c = \"i\"")
            .validate("q", "k", ChannelField::Register, 200.0, Ok(()))
            .unwrap();
        assert_eq!((c.name.as_str(), c.rate_hz), ("i", 200.0));
        let c = parse("c = { register = \"i\", rate_Hz = 50 }")
            .validate("q", "k", ChannelField::Register, 200.0, Ok(()))
            .unwrap();
        assert_eq!((c.name.as_str(), c.rate_hz), ("i", 50.0));
    }

    #[test]
    fn bad_channels_name_their_field() {
        let err = |text: &str, field, allowed| {
            parse(text)
                .validate("q", "x.channels.q", field, 100.0, allowed)
                .unwrap_err()
        };
        assert_eq!(
            err(
                "c = { register = \"i\", rate_Hz = 0 }",
                ChannelField::Register,
                Ok(())
            )
            .0,
            "x.channels.q.rate_Hz"
        );
        assert_eq!(
            err(
                "c = { register = \"i\", rate_Hz = 1e9 }",
                ChannelField::Register,
                Ok(())
            )
            .0,
            "x.channels.q.rate_Hz"
        );
        let (k, why) = err("c = { signal = \"p\" }", ChannelField::Register, Ok(()));
        assert_eq!(k, "x.channels.q.signal");
        assert!(why.contains("takes `register`"), "{why}");
        assert_eq!(
            err("c = { rate_Hz = 5 }", ChannelField::Key, Ok(())).0,
            "x.channels.q.key"
        );
        let (k, why) = err(
            "c = { key = \"0\", rate_Hz = 5 }",
            ChannelField::Key,
            Err("the device sets it"),
        );
        assert_eq!(
            (k.as_str(), why.as_str()),
            ("x.channels.q.rate_Hz", "the device sets it")
        );
    }

    #[test]
    fn an_unknown_table_key_is_refused_with_the_expected_forms() {
        let e = toml::from_str::<T>("c = { registr = \"i\" }").unwrap_err();
        assert!(e.message().contains("rate_Hz"), "{}", e.message());
    }
}
