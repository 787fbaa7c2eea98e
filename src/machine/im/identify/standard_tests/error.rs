//! Why the classical reduction of the standard tests does not apply: a
//! missing test, or data it cannot reduce (each with what to look at).

/// Why the standard tests cannot be reduced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StandardTestsError {
    /// Tests missing, named by their segment kinds.
    #[error(
        "{0}: the classical reduction needs the DC-resistance, no-load and locked-rotor tests"
    )]
    Missing(String),
    /// The DC readings give no resistance above 0.
    #[error("the DC readings give no positive resistance")]
    NoDcResistance,
    /// A test's readings at several frequencies.
    #[error(
        "the {test} readings are at more than one frequency ({first} Hz and {other} Hz): give \
         one segment per frequency"
    )]
    Frequencies {
        /// `no-load` or `locked-rotor`.
        test: &'static str,
        /// The first reading's frequency, Hz.
        first: f64,
        /// Another frequency, Hz.
        other: f64,
    },
    /// A reading whose power is not below its apparent power.
    #[error(
        "{test} reading {index} of segment {segment}: input power {power} W is not below \
         √3·V·I = {apparent:.1} W (a power factor of 1 or more: a wiring or scaling error)"
    )]
    PowerFactor {
        /// `no-load` or `locked-rotor`.
        test: &'static str,
        /// The reading's place in its test, from 1.
        index: usize,
        /// Its segment.
        segment: u32,
        /// Its input power, W.
        power: f64,
        /// Its apparent power, VA.
        apparent: f64,
    },
    /// The locked-rotor regressions give no impedance.
    #[error("the locked-rotor readings give no {0}")]
    LockedRotorImpedance(&'static str),
    /// Friction cannot be told from core loss.
    #[error(
        "the no-load readings used for friction and windage are at fewer than two distinct \
         voltages: the test needs several voltages to separate friction from core loss"
    )]
    FrictionVoltages,
    /// No reading leaves a magnetising reactance.
    #[error(
        "no no-load reading has reactive power above the stator leakage's (Xs = {xs:.4} Ω): no \
         magnetising reactance"
    )]
    NoMagnetising {
        /// The stator leakage taken off, Ω.
        xs: f64,
    },
    /// The fitted `Xm(V)` is not above 0 at rated voltage.
    #[error("the fitted Xm(V) gives {xm:.4e} Ω at rated voltage, not above 0")]
    XmNotPositive {
        /// `Xm` at rated voltage, Ω.
        xm: f64,
    },
    /// The locked-rotor impedance leaves no rotor branch.
    #[error(
        "the locked-rotor impedance {rlr:.4} + j{xlr:.4} Ω leaves no physical rotor branch once \
         Rs = {rs:.4} Ω, Xs = {xs:.4} Ω and Xm = {xm:.4} Ω are taken off (R_lr not above Rs: the \
         DC reading at another temperature, or a wrong connection?)"
    )]
    NoRotorBranch {
        /// Locked-rotor resistance, Ω.
        rlr: f64,
        /// Locked-rotor reactance, Ω.
        xlr: f64,
        /// Stator resistance, Ω.
        rs: f64,
        /// Stator leakage, Ω.
        xs: f64,
        /// Magnetising reactance, Ω.
        xm: f64,
    },
}
