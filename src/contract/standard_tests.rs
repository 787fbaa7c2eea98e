//! The tables of the induction machine's classical reduction (method
//! `standard_tests`): per voltage of the no-load test and per point of the
//! locked-rotor test, and the fitted magnetising-reactance curve. An
//! additive top-level key of the report, `standard_tests`, beside the
//! method's parameters (which stay in the contract's `methods` map).

use serde::{Deserialize, Serialize};

/// One no-load reading reduced; Ω per phase at the no-load frequency.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoLoadRow {
    /// Segment of the reading.
    pub segment: u32,
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// RMS line current, A.
    pub line_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Input power less the stator copper loss, W (core loss plus
    /// friction and windage).
    pub constant_losses: f64,
    /// Core loss (constant losses less friction and windage), W; null
    /// where it came out ≤ 0 (noise at a low voltage).
    pub core_loss: Option<f64>,
    /// Air-gap voltage per phase (behind the stator impedance), V.
    pub air_gap_voltage: f64,
    /// Magnetising reactance at this voltage, Ω; null where the reading's
    /// reactive power does not exceed the stator leakage's.
    pub xm: Option<f64>,
    /// Core-loss resistance at this voltage, Ω; null with `core_loss`.
    pub rfe: Option<f64>,
    /// Whether the friction-and-windage regression used this reading.
    pub in_friction_fit: bool,
}

/// One locked-rotor reading reduced; Ω per phase at the test frequency.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LockedRotorRow {
    /// Segment of the reading.
    pub segment: u32,
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// RMS line current, A.
    pub line_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Supply frequency, Hz (null when unknown).
    pub frequency: Option<f64>,
    /// `|Z_lr| = V_ph/I_ph`, Ω.
    pub zlr: f64,
    /// `R_lr = P_ph/I_ph²`, Ω.
    pub rlr: f64,
    /// `X_lr = √(Z_lr² − R_lr²)`, Ω.
    pub xlr: f64,
}

/// The magnetising reactance against line voltage, fitted by least squares
/// to the no-load table: `Xm(V) = Σ coefficients[k]·V^k` (Ω, V), valid
/// from `from_V` to `to_V`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct XmCurve {
    /// Polynomial coefficients, constant term first.
    pub coefficients: Vec<f64>,
    /// Lowest no-load voltage fitted, V.
    #[serde(rename = "from_V")]
    pub from_v: f64,
    /// Highest no-load voltage fitted, V.
    #[serde(rename = "to_V")]
    pub to_v: f64,
    /// RMS residual of the fit, Ω.
    pub rms_residual: f64,
}

/// The classical reduction's tables.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct StandardTestTables {
    /// The no-load readings, by rising voltage.
    pub no_load: Vec<NoLoadRow>,
    /// The locked-rotor readings, by rising current.
    pub locked_rotor: Vec<LockedRotorRow>,
    /// The fitted `Xm(V)`, when there are two or more no-load readings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub xm_curve: Option<XmCurve>,
}
