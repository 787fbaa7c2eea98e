//! Physical plausibility of an induction-machine record's operating
//! points, checked before any method runs: an induction machine between
//! standstill and synchronous speed (slip 0 to 1) takes electrical power
//! in, so a record whose input power is not positive at most of its points
//! has a wattmeter of reversed polarity or another quantity in that
//! column, and the user needs to hear that, not that no method applies.

use crate::record::Record;

/// Input power that is not positive at most of a record's points.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "segment {segment}, column input_power_W: the input power is not positive at {bad} of \
     {points} operating points (e.g. {example} W): an induction machine at slip 0 to 1 takes \
     power in; is the wattmeter's polarity reversed, or is this another quantity?"
)]
pub struct ImplausiblePower {
    /// The segment of the first point that is not positive.
    pub segment: u32,
    /// Points whose input power is ≤ 0.
    pub bad: usize,
    /// Points in the record.
    pub points: usize,
    /// The first such reading, W.
    pub example: f64,
}

/// Refuse a record whose input power is ≤ 0 at more than half of its
/// operating points (a single reading near zero at no load is noise, not
/// a reversed meter).
pub fn check_input_power(record: &Record) -> Result<(), ImplausiblePower> {
    let points = &record.operating_points;
    let bad: Vec<_> = points.iter().filter(|p| p.input_power <= 0.0).collect();
    match bad.first() {
        Some(first) if 2 * bad.len() > points.len() => Err(ImplausiblePower {
            segment: first.segment,
            bad: bad.len(),
            points: points.len(),
            example: first.input_power,
        }),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::OperatingPoint;

    fn record(power: &[f64]) -> Record {
        Record {
            operating_points: power
                .iter()
                .map(|&p| OperatingPoint {
                    segment: 3,
                    slip: 0.05,
                    line_voltage: 400.0,
                    line_current: 5.0,
                    input_power: p,
                    speed: f64::NAN,
                    frequency: 50.0,
                    torque: None,
                })
                .collect(),
            ..Default::default()
        }
    }

    #[test]
    fn a_reversed_wattmeter_is_refused_and_one_reading_near_zero_is_not() {
        let e = check_input_power(&record(&[-2800.0, -2700.0, -2600.0])).unwrap_err();
        assert_eq!((e.segment, e.bad, e.points), (3, 3, 3));
        assert!(e.to_string().contains("input_power_W"), "{e}");
        assert!(check_input_power(&record(&[-3.0, 2700.0, 2600.0])).is_ok());
        assert!(check_input_power(&record(&[])).is_ok());
    }
}
