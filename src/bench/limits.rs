//! A limit crossed by a reading, as the safety monitor
//! ([`super::SafetyMonitor`]) reports it.

/// A limit crossed by a reading.
#[derive(Debug, Clone, PartialEq)]
pub struct Trip {
    /// The quantity, e.g. `current`.
    pub quantity: &'static str,
    /// The reading, in SI units.
    pub value: f64,
    /// The limit it crossed.
    pub limit: f64,
    /// The unit of both.
    pub unit: &'static str,
}

impl std::fmt::Display for Trip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {:.4} {} beyond the limit ±{} {}",
            self.quantity, self.value, self.unit, self.limit, self.unit
        )
    }
}
