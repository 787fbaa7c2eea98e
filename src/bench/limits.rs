//! Test limits: the checks that abort a test.

use crate::config::Limits;

/// A limit crossed by a reading.
#[derive(Debug, Clone, PartialEq)]
pub struct Trip {
    /// The quantity, e.g. `armature_current`.
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

/// Check one set of readings; the first limit crossed, if any. A
/// non-finite reading counts as crossing its limit.
pub fn check_limits(
    limits: &Limits,
    voltage: f64,
    current: f64,
    speed: Option<f64>,
) -> Option<Trip> {
    let checks = [
        ("armature_voltage", Some(voltage), limits.max_voltage, "V"),
        ("armature_current", Some(current), limits.max_current, "A"),
        ("speed", speed, limits.max_speed, "rad/s"),
    ];
    checks
        .into_iter()
        .find_map(|(quantity, value, limit, unit)| {
            let value = value?;
            (!value.is_finite() || value.abs() > limit).then_some(Trip {
                quantity,
                value,
                limit,
                unit,
            })
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    const L: Limits = Limits {
        max_voltage: 280.0,
        max_current: 4.0,
        max_speed: 230.0,
    };

    #[test]
    fn within_limits_passes_and_each_limit_trips() {
        assert_eq!(check_limits(&L, 248.0, 3.9, Some(229.0)), None);
        assert_eq!(
            check_limits(&L, 281.0, 0.0, None).unwrap().quantity,
            "armature_voltage"
        );
        assert_eq!(
            check_limits(&L, 0.0, -4.1, None).unwrap().quantity,
            "armature_current"
        );
        assert_eq!(
            check_limits(&L, 0.0, 0.0, Some(-231.0)).unwrap().quantity,
            "speed"
        );
        assert_eq!(
            check_limits(&L, 0.0, f64::NAN, None).unwrap().quantity,
            "armature_current"
        );
    }
}
