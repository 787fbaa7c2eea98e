//! The induction machine's standard tests besides the slip sweep (IEEE 112
//! Method F, IEC 60034-28, IEC 60034-2-1): the DC winding-resistance
//! reading, the no-load test at several voltages and the locked-rotor test,
//! as the record holds them for the classical reduction
//! (`machine/im/identify/standard_tests/`). Additive segment kinds of the
//! data contract: `im_dc_resistance`, `im_no_load`, `im_locked_rotor`;
//! on a record the rig made, each reading is one `/bench/standard_test`
//! message ([`StandardTestReading`]).

use serde::{Deserialize, Serialize};

/// Plausible winding temperatures, °C: below is a sign error or kelvin
/// mistaken for °C the other way, above is kelvin.
pub const TEMPERATURE_RANGE_C: (f64, f64) = (-60.0, 250.0);

/// Why a winding temperature `t`, °C, cannot be one (outside
/// [`TEMPERATURE_RANGE_C`]: kelvin, a sign error, not a number); `None`
/// where it can. Every reader of a temperature (CSV import, record
/// reader, slip-sweep validation) asks this one question.
pub fn implausible_temperature(t: f64) -> Option<&'static str> {
    let (lo, hi) = TEMPERATURE_RANGE_C;
    (!(lo..=hi).contains(&t)).then_some("is outside -60…250 °C (the value is in °C, not K)")
}

/// One DC winding-resistance reading between two line terminals.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DcResistanceReading {
    /// Segment index.
    pub segment: u32,
    /// DC voltage between the two terminals, V.
    pub dc_voltage: f64,
    /// DC current through them, A.
    pub dc_current: f64,
    /// Winding temperature, °C, where it was measured.
    pub winding_temperature: Option<f64>,
}

/// One steady reading of a no-load or locked-rotor test on an AC supply.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SupplyReading {
    /// Segment index.
    pub segment: u32,
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// RMS line current, A.
    pub line_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Supply frequency, Hz; NaN where the source did not give it.
    pub frequency: f64,
    /// Winding temperature, °C, where it was measured.
    pub winding_temperature: Option<f64>,
}

/// The standard tests of a record, each in file (recording) order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ImStandardTests {
    /// `im_dc_resistance` readings.
    pub dc_resistance: Vec<DcResistanceReading>,
    /// `im_no_load` readings.
    pub no_load: Vec<SupplyReading>,
    /// `im_locked_rotor` readings.
    pub locked_rotor: Vec<SupplyReading>,
}

/// One reading of a standard test as the rig records it on
/// `/bench/standard_test`: the reading's keys and `"test"`, its segment
/// kind.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "test", rename_all = "snake_case")]
pub enum StandardTestReading {
    /// An `im_dc_resistance` reading.
    ImDcResistance(DcResistanceReading),
    /// An `im_no_load` reading.
    ImNoLoad(SupplyReading),
    /// An `im_locked_rotor` reading.
    ImLockedRotor(SupplyReading),
}

impl StandardTestReading {
    /// The first value that is not a finite number (JSON cannot carry
    /// it), if any.
    pub fn non_finite_field(&self) -> Option<(&'static str, f64)> {
        let fields = match self {
            StandardTestReading::ImDcResistance(r) => vec![
                ("dc_voltage", r.dc_voltage),
                ("dc_current", r.dc_current),
                ("winding_temperature", r.winding_temperature.unwrap_or(0.0)),
            ],
            StandardTestReading::ImNoLoad(r) | StandardTestReading::ImLockedRotor(r) => vec![
                ("line_voltage", r.line_voltage),
                ("line_current", r.line_current),
                ("input_power", r.input_power),
                ("frequency", r.frequency),
                ("winding_temperature", r.winding_temperature.unwrap_or(0.0)),
            ],
        };
        fields.into_iter().find(|(_, v)| !v.is_finite())
    }

    /// The reading's winding temperature, °C, where it has one.
    pub fn winding_temperature(&self) -> Option<f64> {
        match self {
            StandardTestReading::ImDcResistance(r) => r.winding_temperature,
            StandardTestReading::ImNoLoad(r) | StandardTestReading::ImLockedRotor(r) => {
                r.winding_temperature
            }
        }
    }
}

impl ImStandardTests {
    /// Add one reading to its test's list.
    pub fn push(&mut self, reading: StandardTestReading) {
        match reading {
            StandardTestReading::ImDcResistance(r) => self.dc_resistance.push(r),
            StandardTestReading::ImNoLoad(r) => self.no_load.push(r),
            StandardTestReading::ImLockedRotor(r) => self.locked_rotor.push(r),
        }
    }

    /// Whether the record holds none of these tests.
    pub fn is_empty(&self) -> bool {
        self.dc_resistance.is_empty() && self.no_load.is_empty() && self.locked_rotor.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_temperature_in_kelvin_or_not_a_number_is_implausible_and_the_reason_names_the_range() {
        let (lo, hi) = TEMPERATURE_RANGE_C;
        for t in [lo, 20.0, hi] {
            assert_eq!(implausible_temperature(t), None, "{t}");
        }
        for t in [293.15, lo - 0.1, hi + 0.1, f64::NAN] {
            let why = implausible_temperature(t).expect("implausible");
            assert!(why.contains(&format!("{lo}…{hi} °C")), "{why}");
            assert!(why.contains("not K"), "{why}");
        }
    }
}
