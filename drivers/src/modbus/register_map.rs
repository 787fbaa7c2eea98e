//! Register maps: where a device keeps each value, in which encoding, and
//! how raw values scale to SI.
//!
//! `value = raw × scale + offset`, `raw` the register content decoded per
//! [`DataType`], with multi-register types assembled per [`WordOrder`] and
//! each 16-bit word's bytes per [`ByteOrder`] (Modbus sends the high byte
//! first: [`ByteOrder::Big`] is the standard; some devices swap).

use serde::Deserialize;

/// Which Modbus table a register lives in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegisterKind {
    /// Holding registers (read 03, write 06/16), "4xxxx".
    Holding,
    /// Input registers (read 04), "3xxxx".
    Input,
    /// Coils (read 01, write 05), "0xxxx".
    Coil,
    /// Discrete inputs (read 02), "1xxxx".
    DiscreteInput,
}

/// Encoding of the raw value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DataType {
    /// One register, unsigned.
    U16,
    /// One register, two's complement.
    I16,
    /// Two registers, unsigned.
    U32,
    /// Two registers, two's complement.
    I32,
    /// Two registers, IEEE 754 single precision.
    F32,
    /// A coil or discrete input (0 or 1).
    Bool,
}

impl DataType {
    /// Registers (or bits) it occupies.
    pub fn width(self) -> u16 {
        match self {
            DataType::U16 | DataType::I16 | DataType::Bool => 1,
            DataType::U32 | DataType::I32 | DataType::F32 => 2,
        }
    }

    /// The largest magnitude of a raw value (a finite one, for `f32`).
    pub fn largest_raw(self) -> f64 {
        match self {
            DataType::Bool => 1.0,
            DataType::U16 => f64::from(u16::MAX),
            DataType::I16 => 32_768.0,
            DataType::U32 => f64::from(u32::MAX),
            DataType::I32 => 2_147_483_648.0,
            DataType::F32 => f64::from(f32::MAX),
        }
    }

    /// The type's name in a profile (`u16`, `f32`, …).
    pub fn name(self) -> &'static str {
        match self {
            DataType::U16 => "u16",
            DataType::I16 => "i16",
            DataType::U32 => "u32",
            DataType::I32 => "i32",
            DataType::F32 => "f32",
            DataType::Bool => "bool",
        }
    }
}

/// Order of the 16-bit words of a 32-bit value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WordOrder {
    /// Most significant word at the lower address ("ABCD"): the common one.
    #[default]
    HighFirst,
    /// Least significant word first ("CDAB").
    LowFirst,
}

/// Order of the two bytes inside each register.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ByteOrder {
    /// As the Modbus specification sends them: high byte first.
    #[default]
    Big,
    /// Bytes swapped in each word ("BADC" with high-first words).
    Little,
}

/// Whether the bench may write a register.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Access {
    /// Read only.
    #[default]
    Read,
    /// Read and write.
    ReadWrite,
    /// Write only (reading it is refused or meaningless).
    Write,
}

/// One named value of a device.
#[derive(Debug, Clone, PartialEq)]
pub struct Register {
    /// Name in the profile.
    pub name: String,
    /// Protocol address (0-based, as on the wire).
    pub address: u16,
    /// Table.
    pub kind: RegisterKind,
    /// Raw encoding.
    pub data_type: DataType,
    /// `value = raw × scale + offset`.
    pub scale: f64,
    /// `value = raw × scale + offset`.
    pub offset: f64,
    /// SI unit of the value.
    pub unit: String,
    /// Whether the bench may write it.
    pub access: Access,
    /// Word order of 32-bit types.
    pub word_order: WordOrder,
    /// Byte order inside each word.
    pub byte_order: ByteOrder,
}

/// A value that cannot be written to a register.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{value} {unit} does not fit register {name} (raw {raw} outside {min}..={max})")]
pub struct RangeError {
    /// Register name.
    pub name: String,
    /// The value asked for.
    pub value: f64,
    /// Its unit.
    pub unit: String,
    /// The raw value it maps to.
    pub raw: f64,
    /// Smallest raw value.
    pub min: f64,
    /// Largest raw value.
    pub max: f64,
}

impl Register {
    fn swap(&self, w: u16) -> u16 {
        match self.byte_order {
            ByteOrder::Big => w,
            ByteOrder::Little => w.swap_bytes(),
        }
    }

    fn join(&self, words: &[u16]) -> u32 {
        let (hi, lo) = match self.word_order {
            WordOrder::HighFirst => (words[0], words[1]),
            WordOrder::LowFirst => (words[1], words[0]),
        };
        (u32::from(self.swap(hi)) << 16) | u32::from(self.swap(lo))
    }

    fn split(&self, v: u32) -> Vec<u16> {
        let (hi, lo) = (self.swap((v >> 16) as u16), self.swap(v as u16));
        match self.word_order {
            WordOrder::HighFirst => vec![hi, lo],
            WordOrder::LowFirst => vec![lo, hi],
        }
    }

    /// The raw value held in `words` (exactly [`DataType::width`] of them).
    pub fn raw(&self, words: &[u16]) -> f64 {
        assert_eq!(words.len(), usize::from(self.data_type.width()));
        match self.data_type {
            DataType::U16 | DataType::Bool => f64::from(self.swap(words[0])),
            DataType::I16 => f64::from(self.swap(words[0]) as i16),
            DataType::U32 => f64::from(self.join(words)),
            DataType::I32 => f64::from(self.join(words) as i32),
            DataType::F32 => f64::from(f32::from_bits(self.join(words))),
        }
    }

    /// The value held in `words`, in SI units.
    pub fn decode(&self, words: &[u16]) -> f64 {
        self.raw(words) * self.scale + self.offset
    }

    /// The words that hold `value` (rounded to the register's resolution);
    /// an error when it falls outside the raw range.
    pub fn encode(&self, value: f64) -> Result<Vec<u16>, RangeError> {
        let raw = (value - self.offset) / self.scale;
        let (min, max) = match self.data_type {
            DataType::U16 => (0.0, f64::from(u16::MAX)),
            DataType::Bool => (0.0, 1.0),
            DataType::I16 => (f64::from(i16::MIN), f64::from(i16::MAX)),
            DataType::U32 => (0.0, f64::from(u32::MAX)),
            DataType::I32 => (f64::from(i32::MIN), f64::from(i32::MAX)),
            DataType::F32 => (f64::from(f32::MIN), f64::from(f32::MAX)),
        };
        let rounded = if self.data_type == DataType::F32 {
            raw
        } else {
            raw.round()
        };
        if !rounded.is_finite() || rounded < min || rounded > max {
            return Err(RangeError {
                name: self.name.clone(),
                value,
                unit: self.unit.clone(),
                raw,
                min,
                max,
            });
        }
        Ok(match self.data_type {
            DataType::U16 | DataType::Bool => vec![self.swap(rounded as u16)],
            DataType::I16 => vec![self.swap(rounded as i16 as u16)],
            DataType::U32 => self.split(rounded as u32),
            DataType::I32 => self.split(rounded as i32 as u32),
            DataType::F32 => self.split((rounded as f32).to_bits()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn reg(data_type: DataType, word_order: WordOrder, byte_order: ByteOrder) -> Register {
        Register {
            name: "r".into(),
            address: 0,
            kind: RegisterKind::Holding,
            data_type,
            scale: 1.0,
            offset: 0.0,
            unit: "V".into(),
            access: Access::ReadWrite,
            word_order,
            byte_order,
        }
    }

    #[test]
    fn float_in_all_four_orders_by_hand() {
        // 230.5 as IEEE 754 single is 0x43668000.
        use ByteOrder::*;
        use WordOrder::*;
        for (w, b, words) in [
            (HighFirst, Big, [0x4366, 0x8000]),    // ABCD
            (LowFirst, Big, [0x8000, 0x4366]),     // CDAB
            (HighFirst, Little, [0x6643, 0x0080]), // BADC
            (LowFirst, Little, [0x0080, 0x6643]),  // DCBA
        ] {
            let r = reg(DataType::F32, w, b);
            assert_eq!(r.decode(&words), 230.5, "{w:?} {b:?}");
            assert_eq!(r.encode(230.5).unwrap(), words.to_vec());
        }
    }

    #[test]
    fn scaled_integers_and_signs() {
        let mut r = reg(DataType::U16, WordOrder::HighFirst, ByteOrder::Big);
        r.scale = 0.01;
        assert_eq!(r.encode(12.345).unwrap(), vec![1235]);
        assert!((r.decode(&[6000]) - 60.0).abs() < 1e-12);
        let err = r.encode(700.0).unwrap_err().to_string();
        assert!(err.contains("does not fit register r"), "{err}");
        assert!(r.encode(-0.01).is_err());
        let i = reg(DataType::I16, WordOrder::HighFirst, ByteOrder::Big);
        assert_eq!(i.decode(&[0xFFFE]), -2.0);
        let i32r = reg(DataType::I32, WordOrder::LowFirst, ByteOrder::Big);
        assert_eq!(i32r.decode(&[0xFFFE, 0xFFFF]), -2.0);
        assert_eq!(i32r.encode(-70000.0).unwrap(), vec![0xEE90, 0xFFFE]);
        let mut off = reg(DataType::U16, WordOrder::HighFirst, ByteOrder::Big);
        off.offset = -40.0;
        assert_eq!(off.decode(&[65]), 25.0);
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(3), ..ProptestConfig::default() })]
        #[test]
        fn encode_then_decode_is_exact_on_the_raw_grid(raw in any::<i32>(), hi in any::<bool>(), big in any::<bool>()) {
            let w = if hi { WordOrder::HighFirst } else { WordOrder::LowFirst };
            let b = if big { ByteOrder::Big } else { ByteOrder::Little };
            let mut r = reg(DataType::I32, w, b);
            r.scale = 0.001;
            r.offset = 5.0;
            let v = f64::from(raw) * 0.001 + 5.0;
            let words = r.encode(v).unwrap();
            prop_assert_eq!(r.raw(&words), f64::from(raw));
        }
    }
}
