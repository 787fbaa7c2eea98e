//! The stator resistance per phase from the DC winding-resistance test:
//! the resistance between two line terminals (the slope of voltage against
//! current through the origin over the readings, each corrected to their
//! mean winding temperature), turned into the phase resistance of the
//! connection (star: half of it; delta: 3/2 of it), and corrected to
//! another test's winding temperature with copper's α.

use super::error::StandardTestsError;
use super::regression::through_origin;
use crate::machine::im::COPPER_ALPHA;
use crate::model::Connection;
use crate::record::DcResistanceReading;

/// The DC test reduced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct DcResistance {
    /// Stator resistance per phase, Ω, at `temperature`.
    pub rs: f64,
    /// Half-width of its 95 % interval (two readings or more).
    pub half_width: Option<f64>,
    /// Mean winding temperature of the readings that give one, °C.
    pub temperature: Option<f64>,
}

/// Copper's resistance at `to` °C over its resistance at `from` °C
/// (α = [`COPPER_ALPHA`] at 20 °C); 1 when either is unknown.
pub(crate) fn temperature_factor(from: Option<f64>, to: Option<f64>) -> f64 {
    match (from, to) {
        (Some(a), Some(b)) => (1.0 + COPPER_ALPHA * (b - 20.0)) / (1.0 + COPPER_ALPHA * (a - 20.0)),
        _ => 1.0,
    }
}

/// The mean of the temperatures given, if any.
pub(super) fn mean_temperature(t: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let t: Vec<f64> = t.flatten().collect();
    (!t.is_empty()).then(|| t.iter().sum::<f64>() / t.len() as f64)
}

/// Reduce the DC readings of a winding connected as `connection`.
pub(super) fn dc_resistance(
    readings: &[DcResistanceReading],
    connection: Connection,
) -> Result<DcResistance, StandardTestsError> {
    let temperature = mean_temperature(readings.iter().map(|r| r.winding_temperature));
    // Each reading's voltage as it would be at the mean temperature.
    let v: Vec<f64> = readings
        .iter()
        .map(|r| r.dc_voltage * temperature_factor(r.winding_temperature, temperature))
        .collect();
    let i: Vec<f64> = readings.iter().map(|r| r.dc_current).collect();
    let (r_line, hw) = through_origin(&i, &v)
        .filter(|(r, _)| *r > 0.0)
        .ok_or(StandardTestsError::NoDcResistance)?;
    let per_phase = match connection {
        Connection::Star => 0.5,
        Connection::Delta => 1.5,
    };
    Ok(DcResistance {
        rs: per_phase * r_line,
        half_width: hw.map(|h| per_phase * h),
        temperature,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(v: f64, i: f64, t: Option<f64>) -> DcResistanceReading {
        DcResistanceReading {
            segment: 0,
            dc_voltage: v,
            dc_current: i,
            winding_temperature: t,
        }
    }

    #[test]
    fn line_to_line_resistance_becomes_the_phase_resistance() {
        // 3 Ω between terminals: star 1.5 Ω, delta 4.5 Ω per phase.
        let r = [reading(6.0, 2.0, None), reading(12.0, 4.0, None)];
        assert!((dc_resistance(&r, Connection::Star).unwrap().rs - 1.5).abs() < 1e-12);
        assert!((dc_resistance(&r, Connection::Delta).unwrap().rs - 4.5).abs() < 1e-12);
    }

    #[test]
    fn a_textbook_dc_test() {
        // The same textbook example: 13.6 V at 28.0 A, star: R1 = 0.243 Ω.
        let d = dc_resistance(&[reading(13.6, 28.0, None)], Connection::Star).unwrap();
        assert!((d.rs - 0.243).abs() < 5e-4, "{d:?}");
        assert_eq!(d.half_width, None);
    }

    #[test]
    fn readings_at_two_temperatures_are_brought_to_their_mean() {
        // 2 Ω at 20 °C; the second reading at 40 °C reads 2·(1 + 20α).
        let hot = 2.0 * (1.0 + 20.0 * COPPER_ALPHA);
        let r = [
            reading(2.0, 1.0, Some(20.0)),
            reading(2.0 * hot, 2.0, Some(40.0)),
        ];
        let d = dc_resistance(&r, Connection::Star).unwrap();
        assert_eq!(d.temperature, Some(30.0));
        let at_30 = 2.0 * (1.0 + 10.0 * COPPER_ALPHA) / 2.0;
        assert!((d.rs - at_30).abs() < 1e-12, "{d:?}");
        assert!((temperature_factor(Some(20.0), Some(75.0)) - 1.216_15).abs() < 1e-5);
    }
}
