//! Physical plausibility of an induction-machine record's operating
//! points, checked before any method runs: an induction machine between
//! standstill and synchronous speed (slip 0 to 1) takes electrical power
//! in, so a record whose input power is not positive at most of its points
//! has a wattmeter of reversed polarity or another quantity in that
//! column, and the user needs to hear that, not that no method applies.
//! Likewise its power factor `P/(√3·V·I)` (line quantities, either
//! connection) lies between 0 and 1: above 1 the voltage or current
//! column holds another quantity (a phase voltage in the line-voltage
//! column reads √3 too high a power factor), and a record whose every
//! power factor is below 2 % holds its power in another unit (kW: no
//! machine, even at no load, draws so little real power).

use crate::record::{OperatingPoint, Record};

/// Highest power factor a reading may show: 1 plus the meters' errors.
const MAX_POWER_FACTOR: f64 = 1.05;
/// Lowest power factor the record's highest may be.
const MIN_HIGHEST_POWER_FACTOR: f64 = 0.02;

/// Operating points no induction machine at slip 0 to 1 gives.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImplausiblePower {
    /// Input power that is not positive at most of the points.
    #[error(
        "segment {segment}, column input_power_W: the input power is not positive at {bad} of \
         {points} operating points (e.g. {example} W): an induction machine at slip 0 to 1 \
         takes power in; is the wattmeter's polarity reversed, or is this another quantity?"
    )]
    NotPositive {
        /// The segment of the first point that is not positive.
        segment: u32,
        /// Points whose input power is ≤ 0.
        bad: usize,
        /// Points in the record.
        points: usize,
        /// The first such reading, W.
        example: f64,
    },
    /// A power factor above 1 at several points.
    #[error(
        "segment {segment}, slip {slip}: input_power_W / (√3 · line_voltage_V · line_current_A) \
         = {power_factor:.3} (above 1 at {bad} of {points} operating points): a power factor \
         cannot exceed 1; is line_voltage_V a phase voltage (√3 too low), line_current_A a \
         phase current of a delta winding, or input_power_W in other units than W?"
    )]
    AboveOne {
        /// The segment of the point with the highest power factor.
        segment: u32,
        /// Its slip.
        slip: f64,
        /// Its power factor.
        power_factor: f64,
        /// Points whose power factor exceeds 1 (with the meters' errors).
        bad: usize,
        /// Points in the record.
        points: usize,
    },
    /// Every power factor below 2 %.
    #[error(
        "column input_power_W: the power factor input_power_W / (√3 · line_voltage_V · \
         line_current_A) is at most {highest:.4} over all {points} operating points (segment \
         {segment}, slip {slip}); an induction machine draws more real power than that even at \
         no load: is input_power_W in kW (it must be W), or another quantity?"
    )]
    TooLow {
        /// The segment of the point with the highest power factor.
        segment: u32,
        /// Its slip.
        slip: f64,
        /// The highest power factor of the record.
        highest: f64,
        /// Points in the record.
        points: usize,
    },
}

/// The power factor of a reading (line quantities).
fn power_factor(p: &OperatingPoint) -> f64 {
    p.input_power / (3f64.sqrt() * p.line_voltage * p.line_current)
}

/// Refuse a record whose input power is ≤ 0 at more than half of its
/// operating points (a single reading near zero at no load is noise, not
/// a reversed meter), whose power factor exceeds 1 (plus the meters'
/// errors) at two points or more and at a tenth of them or more (one
/// outlier is a glitch, not a wrong column), or whose power factor stays
/// below 2 % everywhere.
pub fn check_input_power(record: &Record) -> Result<(), ImplausiblePower> {
    let points = &record.operating_points;
    let bad: Vec<_> = points.iter().filter(|p| p.input_power <= 0.0).collect();
    if let Some(first) = bad.first().filter(|_| 2 * bad.len() > points.len()) {
        return Err(ImplausiblePower::NotPositive {
            segment: first.segment,
            bad: bad.len(),
            points: points.len(),
            example: first.input_power,
        });
    }
    let Some(highest) = points
        .iter()
        .filter(|p| power_factor(p).is_finite())
        .max_by(|a, b| power_factor(a).total_cmp(&power_factor(b)))
    else {
        return Ok(());
    };
    let above = points
        .iter()
        .filter(|p| power_factor(p) > MAX_POWER_FACTOR)
        .count();
    if above >= 2 && 10 * above >= points.len() {
        return Err(ImplausiblePower::AboveOne {
            segment: highest.segment,
            slip: highest.slip,
            power_factor: power_factor(highest),
            bad: above,
            points: points.len(),
        });
    }
    if power_factor(highest) < MIN_HIGHEST_POWER_FACTOR {
        return Err(ImplausiblePower::TooLow {
            segment: highest.segment,
            slip: highest.slip,
            highest: power_factor(highest),
            points: points.len(),
        });
    }
    Ok(())
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
                    winding_temperature: None,
                })
                .collect(),
            ..Default::default()
        }
    }

    #[test]
    fn a_reversed_wattmeter_is_refused_and_one_reading_near_zero_is_not() {
        let e = check_input_power(&record(&[-2800.0, -2700.0, -2600.0])).unwrap_err();
        assert!(
            matches!(
                e,
                ImplausiblePower::NotPositive {
                    segment: 3,
                    bad: 3,
                    points: 3,
                    ..
                }
            ),
            "{e:?}"
        );
        assert!(e.to_string().contains("input_power_W"), "{e}");
        assert!(check_input_power(&record(&[-3.0, 2700.0, 2600.0])).is_ok());
        assert!(check_input_power(&record(&[])).is_ok());
    }

    // The readings of `record` are 400 V, 5 A: an apparent power of
    // √3·400·5 = 3464 W.

    #[test]
    fn a_power_factor_above_one_is_refused_and_one_glitch_is_not() {
        // A phase voltage in the line column: √3 too high a power factor
        // (0.85 reads 1.47) where the machine is loaded.
        let e = check_input_power(&record(&[5100.0, 5000.0, 400.0, 1500.0])).unwrap_err();
        match &e {
            ImplausiblePower::AboveOne {
                segment: 3,
                bad: 2,
                points: 4,
                power_factor,
                ..
            } => assert!((power_factor - 5100.0 / 3464.1).abs() < 1e-3, "{e}"),
            other => panic!("{other:?}"),
        }
        assert!(e.to_string().contains("phase voltage"), "{e}");
        // One reading of 12 above 1 (a glitch), and readings at 1.04 (the
        // meters' errors on a power factor near 1), are not refused.
        let mut one_glitch = vec![2900.0; 11];
        one_glitch.push(4000.0);
        assert!(check_input_power(&record(&one_glitch)).is_ok());
        assert!(check_input_power(&record(&[3600.0, 3600.0, 3000.0])).is_ok());
    }

    #[test]
    fn a_record_whose_every_power_factor_is_below_two_percent_is_refused() {
        // Power in kW: 2.9 for 2900 W.
        let e = check_input_power(&record(&[2.9, 2.5, 0.3])).unwrap_err();
        assert!(
            matches!(e, ImplausiblePower::TooLow { points: 3, .. }),
            "{e:?}"
        );
        assert!(e.to_string().contains("kW"), "{e}");
        // A no-load reading of a large machine (power factor 3 %) is not.
        assert!(check_input_power(&record(&[104.0, 110.0])).is_ok());
    }
}
