//! The induction machine's standard tests besides the slip sweep (IEEE 112
//! Method F, IEC 60034-28, IEC 60034-2-1): the DC winding-resistance
//! reading, the no-load test at several voltages and the locked-rotor test,
//! as the record holds them for the classical reduction
//! (`machine/im/identify/standard_tests/`). Additive segment kinds of the
//! data contract: `im_dc_resistance`, `im_no_load`, `im_locked_rotor`.

/// One DC winding-resistance reading between two line terminals.
#[derive(Debug, Clone, Copy, PartialEq)]
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
#[derive(Debug, Clone, Copy, PartialEq)]
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

impl ImStandardTests {
    /// Whether the record holds none of these tests.
    pub fn is_empty(&self) -> bool {
        self.dc_resistance.is_empty() && self.no_load.is_empty() && self.locked_rotor.is_empty()
    }
}
