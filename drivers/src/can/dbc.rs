//! Signals of a DBC file, decoded from (and encoded into) CAN frames.
//!
//! `can-dbc` parses the file to its syntax tree; this module does the
//! signal extraction: Intel (little-endian, `@1`) and Motorola
//! (big-endian, `@0`) bit layouts, unsigned and two's-complement signed
//! raw values, and `physical = raw × factor + offset`. Multiplexed signals
//! are decoded only when their multiplexor switch holds their value.

use std::collections::BTreeMap;

use can_dbc::{ByteOrder, Dbc, MessageId, MultiplexIndicator, ValueType};

use super::{CanFrame, CanId};

/// A DBC file that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DbcError {
    /// The text does not parse (the parser's message names line and column).
    #[error("{path}: DBC syntax: {message}")]
    Parse {
        /// The file.
        path: String,
        /// What the parser said.
        message: String,
    },
    /// A signal does not fit its message.
    #[error("{path}: message {message}, signal {signal}: {reason}")]
    Signal {
        /// The file.
        path: String,
        /// The message name.
        message: String,
        /// The signal name.
        signal: String,
        /// Why it does not fit.
        reason: String,
    },
}

/// Where one signal sits in a frame and how it scales.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalSpec {
    /// Signal name.
    pub name: String,
    /// DBC start bit (LSB for Intel, MSB for Motorola in DBC numbering).
    pub start_bit: u32,
    /// Width in bits, 1–64.
    pub size: u32,
    /// Intel (true) or Motorola (false) layout.
    pub little_endian: bool,
    /// Two's-complement signed raw value.
    pub signed: bool,
    /// Physical = raw × factor + offset.
    pub factor: f64,
    /// Physical = raw × factor + offset.
    pub offset: f64,
    /// Unit text from the file.
    pub unit: String,
    /// `Some(v)`: present only when the message's multiplexor equals `v`.
    pub multiplexed_by: Option<u64>,
    /// This signal is the message's multiplexor switch.
    pub is_multiplexor: bool,
}

impl SignalSpec {
    /// Bit positions as (shift from the LSB of a 64-bit word, that word's
    /// byte order): the raw value sits at `word >> shift`.
    fn placement(&self) -> Option<u32> {
        if self.little_endian {
            // Frame bytes read as a little-endian u64: bit k is frame bit k.
            (self.start_bit + self.size <= 64).then_some(self.start_bit)
        } else {
            // Frame bytes read as a big-endian u64, bit 0 of that numbering
            // = MSB of byte 0. The DBC start bit is the signal's MSB in
            // "byte*8 + bit-in-byte" numbering.
            let msb = (self.start_bit / 8) * 8 + (7 - self.start_bit % 8);
            let end = msb + self.size;
            (end <= 64).then(|| 64 - end)
        }
    }

    fn mask(&self) -> u64 {
        if self.size >= 64 {
            u64::MAX
        } else {
            (1u64 << self.size) - 1
        }
    }

    fn word(&self, data: &[u8]) -> u64 {
        let mut bytes = [0u8; 8];
        bytes[..data.len().min(8)].copy_from_slice(&data[..data.len().min(8)]);
        if self.little_endian {
            u64::from_le_bytes(bytes)
        } else {
            u64::from_be_bytes(bytes)
        }
    }

    /// The raw (unscaled) value in `data`, sign-extended when signed.
    pub fn raw(&self, data: &[u8]) -> i128 {
        let shift = self.placement().expect("checked when the map was built");
        let v = (self.word(data) >> shift) & self.mask();
        if self.signed && self.size < 64 && v >> (self.size - 1) & 1 == 1 {
            i128::from(v) - (1i128 << self.size)
        } else if self.signed && self.size == 64 {
            i128::from(v as i64)
        } else {
            i128::from(v)
        }
    }

    /// The physical value in `data`.
    pub fn decode(&self, data: &[u8]) -> f64 {
        self.raw(data) as f64 * self.factor + self.offset
    }

    /// Write `physical` into `data` (rounded to the nearest raw value and
    /// saturated at the raw range).
    pub fn encode(&self, physical: f64, data: &mut [u8; 8]) {
        let raw = ((physical - self.offset) / self.factor).round();
        let (lo, hi) = if self.signed {
            (
                -(2f64.powi(self.size as i32 - 1)),
                2f64.powi(self.size as i32 - 1) - 1.0,
            )
        } else {
            (0.0, 2f64.powi(self.size as i32) - 1.0)
        };
        let raw = raw.clamp(lo, hi) as i128;
        let bits = (raw as u64) & self.mask();
        let shift = self.placement().expect("checked when the map was built");
        let mut word = self.word(data);
        word &= !(self.mask() << shift);
        word |= bits << shift;
        *data = if self.little_endian {
            word.to_le_bytes()
        } else {
            word.to_be_bytes()
        };
    }
}

/// One decoded signal.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedSignal {
    /// Signal name.
    pub name: String,
    /// Physical value.
    pub value: f64,
    /// Unit text from the file.
    pub unit: String,
}

#[derive(Debug, Clone, PartialEq)]
struct MessageSpec {
    name: String,
    size: u8,
    signals: Vec<SignalSpec>,
}

/// The messages and signals of a DBC file, by CAN id.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SignalMap {
    messages: BTreeMap<CanId, MessageSpec>,
}

impl SignalMap {
    /// Parse DBC `text`; `path` names it in errors.
    pub fn parse(path: &str, text: &str) -> Result<SignalMap, DbcError> {
        let dbc = Dbc::try_from(text).map_err(|e| DbcError::Parse {
            path: path.to_string(),
            message: e.to_string().replace('\n', " "),
        })?;
        let mut messages = BTreeMap::new();
        for m in &dbc.messages {
            let id = match m.id {
                MessageId::Standard(v) => CanId::Standard(v),
                MessageId::Extended(v) => CanId::Extended(v),
            };
            let mut signals = Vec::new();
            for s in &m.signals {
                let bad = |reason: String| DbcError::Signal {
                    path: path.to_string(),
                    message: m.name.clone(),
                    signal: s.name.clone(),
                    reason,
                };
                if s.size == 0 || s.size > 64 {
                    return Err(bad(format!("{} bits: must be 1 to 64", s.size)));
                }
                if s.factor == 0.0 || !s.factor.is_finite() {
                    return Err(bad(format!(
                        "factor {} must be finite and non-zero",
                        s.factor
                    )));
                }
                let spec = SignalSpec {
                    name: s.name.clone(),
                    start_bit: s.start_bit as u32,
                    size: s.size as u32,
                    little_endian: s.byte_order == ByteOrder::LittleEndian,
                    signed: s.value_type == ValueType::Signed,
                    factor: s.factor,
                    offset: s.offset,
                    unit: s.unit.clone(),
                    multiplexed_by: match s.multiplexer_indicator {
                        MultiplexIndicator::MultiplexedSignal(v)
                        | MultiplexIndicator::MultiplexorAndMultiplexedSignal(v) => Some(v),
                        _ => None,
                    },
                    is_multiplexor: matches!(
                        s.multiplexer_indicator,
                        MultiplexIndicator::Multiplexor
                            | MultiplexIndicator::MultiplexorAndMultiplexedSignal(_)
                    ),
                };
                match spec.placement() {
                    Some(_) if s.start_bit < 64 => {}
                    _ => {
                        return Err(bad(format!(
                            "start bit {} with {} bits lies outside 8 bytes",
                            s.start_bit, s.size
                        )))
                    }
                }
                signals.push(spec);
            }
            messages.insert(
                id,
                MessageSpec {
                    name: m.name.clone(),
                    size: m.size.min(8) as u8,
                    signals,
                },
            );
        }
        Ok(SignalMap { messages })
    }

    /// The ids of the messages in the file.
    pub fn message_ids(&self) -> impl Iterator<Item = CanId> + '_ {
        self.messages.keys().copied()
    }

    /// The message carrying `signal`, and the signal's layout.
    pub fn find(&self, signal: &str) -> Option<(CanId, &SignalSpec)> {
        self.messages.iter().find_map(|(id, m)| {
            m.signals
                .iter()
                .find(|s| s.name == signal)
                .map(|s| (*id, s))
        })
    }

    /// Every signal of a frame the file describes (`None` for an unknown
    /// id or a remote frame).
    pub fn decode(&self, frame: &CanFrame) -> Option<Vec<DecodedSignal>> {
        if frame.is_remote() {
            return None;
        }
        let m = self.messages.get(&frame.id())?;
        let data = frame.data();
        let switch = m
            .signals
            .iter()
            .find(|s| s.is_multiplexor)
            .map(|s| s.raw(data));
        Some(
            m.signals
                .iter()
                .filter(|s| match s.multiplexed_by {
                    None => true,
                    Some(v) => switch == Some(i128::from(v)),
                })
                .map(|s| DecodedSignal {
                    name: s.name.clone(),
                    value: s.decode(data),
                    unit: s.unit.clone(),
                })
                .collect(),
        )
    }

    /// A frame of message `id` carrying `values` (other signals zero).
    pub fn encode(&self, id: CanId, values: &[(&str, f64)]) -> Option<CanFrame> {
        let m = self.messages.get(&id)?;
        let mut data = [0u8; 8];
        for (name, v) in values {
            let s = m.signals.iter().find(|s| s.name == *name)?;
            s.encode(*v, &mut data);
        }
        CanFrame::new(id, &data[..usize::from(m.size)]).ok()
    }

    /// The name of message `id`.
    pub fn message_name(&self, id: CanId) -> Option<&str> {
        self.messages.get(&id).map(|m| m.name.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DBC: &str = r#"VERSION ""

NS_ :

BS_:

BU_: ENC HOST

BO_ 385 TPDO1: 8 ENC
 SG_ Position : 0|32@1+ (1,0) [0|4294967295] "count" HOST
 SG_ Speed : 32|16@1- (0.1,0) [-3276.8|3276.7] "rad/s" HOST
 SG_ Status : 48|8@1+ (1,0) [0|255] "" HOST

BO_ 2147484161 MOTO: 8 ENC
 SG_ Be12 : 7|12@0+ (1,0) [0|4095] "" HOST
 SG_ BeSigned : 11|16@0- (0.5,-10) [0|0] "V" HOST

BO_ 640 MUX: 8 ENC
 SG_ Index M : 0|8@1+ (1,0) [0|255] "" HOST
 SG_ A m1 : 8|16@1+ (1,0) [0|65535] "" HOST
 SG_ B m2 : 8|16@1+ (1,0) [0|65535] "" HOST
"#;

    fn map() -> SignalMap {
        SignalMap::parse("test.dbc", DBC).unwrap()
    }

    fn value(v: &[DecodedSignal], name: &str) -> f64 {
        v.iter().find(|s| s.name == name).unwrap().value
    }

    #[test]
    fn intel_signals_decode_by_hand_computed_bytes() {
        // Position 0x12345678, speed -12.3 rad/s = raw -123 = 0xFF85, status 7.
        let f = CanFrame::new(
            CanId::Standard(0x181),
            &[0x78, 0x56, 0x34, 0x12, 0x85, 0xFF, 0x07, 0x00],
        )
        .unwrap();
        let v = map().decode(&f).unwrap();
        assert_eq!(value(&v, "Position"), 305_419_896.0);
        assert!((value(&v, "Speed") + 12.3).abs() < 1e-9);
        assert_eq!(value(&v, "Status"), 7.0);
    }

    #[test]
    fn motorola_signals_decode_by_hand_computed_bytes() {
        // Be12: MSB at bit 7 of byte 0, 12 bits → byte0 and the high
        // nibble of byte1. BeSigned: MSB at bit 3 of byte 1, 16 bits →
        // low nibble of byte1, byte2, high nibble of byte3.
        // Be12 = 0xABC; BeSigned raw = 0xFFF6 (-10) → -10*0.5-10 = -15.
        let f = CanFrame::new(
            CanId::Extended(0x201),
            &[0xAB, 0xCF, 0xFF, 0x60, 0, 0, 0, 0],
        )
        .unwrap();
        let v = map().decode(&f).unwrap();
        assert_eq!(value(&v, "Be12"), f64::from(0xABC));
        assert_eq!(value(&v, "BeSigned"), -15.0);
    }

    #[test]
    fn multiplexed_signals_follow_their_switch() {
        let m = map();
        let f = CanFrame::new(CanId::Standard(640), &[2, 0x34, 0x12, 0, 0, 0, 0, 0]).unwrap();
        let v = m.decode(&f).unwrap();
        let names: Vec<_> = v.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, vec!["Index", "B"]);
        assert_eq!(value(&v, "B"), 4660.0);
    }

    #[test]
    fn bad_files_are_named() {
        let err = SignalMap::parse("x.dbc", "BO_ nonsense").unwrap_err();
        assert!(err.to_string().starts_with("x.dbc: DBC syntax"), "{err}");
        let bad = DBC.replace("48|8@1+", "60|8@1+");
        let err = SignalMap::parse("x.dbc", &bad).unwrap_err().to_string();
        assert!(err.contains("TPDO1") && err.contains("Status"), "{err}");
    }

    #[test]
    fn the_shipped_cia406_encoder_file_decodes_a_tpdo() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../config/devices/cia406-encoder.dbc"
        );
        let m = SignalMap::parse(path, &std::fs::read_to_string(path).unwrap()).unwrap();
        // Position 100000 = 0x000186A0, speed -1500 = 0xFA24, little-endian.
        let f = CanFrame::new(
            CanId::Standard(0x181),
            &[0xA0, 0x86, 0x01, 0x00, 0x24, 0xFA],
        )
        .unwrap();
        let v = m.decode(&f).unwrap();
        assert_eq!(value(&v, "position"), 100_000.0);
        assert_eq!(value(&v, "speed"), -1500.0);
        let (id, _) = m.find("nmt_state").unwrap();
        assert_eq!(id, CanId::Standard(0x701));
        assert_eq!(
            m.encode(
                CanId::Standard(0x181),
                &[("position", 100_000.0), ("speed", -1500.0)]
            ),
            Some(f)
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(5), ..ProptestConfig::default() })]
        #[test]
        fn encode_then_decode_returns_the_value(
            start in 0u32..64, size in 1u32..=32, little in any::<bool>(),
            signed in any::<bool>(), raw in any::<i64>()
        ) {
            let s = SignalSpec {
                name: "x".into(), start_bit: start, size, little_endian: little,
                signed, factor: 0.25, offset: 3.0, unit: String::new(),
                multiplexed_by: None, is_multiplexor: false,
            };
            prop_assume!(s.placement().is_some());
            let span = 1i64 << size;
            let raw = if signed { raw.rem_euclid(span) - span / 2 } else { raw.rem_euclid(span) };
            let physical = raw as f64 * 0.25 + 3.0;
            let mut data = [0xA5u8; 8];
            s.encode(physical, &mut data);
            prop_assert_eq!(s.raw(&data), i128::from(raw));
            prop_assert_eq!(s.decode(&data), physical);
        }
    }
}
