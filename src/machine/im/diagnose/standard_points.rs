//! A record's standard tests in the diagnosis: which of them are operating
//! points of the load test's circuit, and which are not.
//!
//! A locked-rotor reading is an operating point at slip 1, exactly what
//! the last point of a slip sweep is (a motor lab's locked-rotor segment
//! imported as `im_slip_sweep` was always diagnosed so); it joins the
//! points in recording (segment) order, so that the heat index keeps its
//! meaning. At a reduced frequency the models take the reactances, deep
//! bar's rotor frequency and the saturating flux at that frequency
//! (`PointInput::freq_ratio`): two frequencies are what separates deep bar
//! from leakage saturation. The no-load readings need their unmeasured
//! slip and the friction and windage in the power balance, and the DC
//! resistance is no operating point: those are left out, and the report
//! says so.

use crate::record::{OperatingPoint, Record};

/// Relative difference of two supply frequencies that are the same.
pub(super) const SAME_FREQUENCY: f64 = 0.01;

/// The record's operating points with its locked-rotor readings at the
/// load test's frequency added (in segment order), and a warning naming
/// what of the standard tests the diagnosis does not use; the record as it
/// is, and no warning, when it has no standard tests.
pub fn with_locked_rotor_points(record: &Record) -> (Record, Option<String>) {
    let tests = &record.standard_tests;
    if tests.is_empty() {
        return (record.clone(), None);
    }
    let sweep_frequency = record
        .operating_points
        .iter()
        .map(|p| p.frequency)
        .find(|f| f.is_finite());
    let reduced = |f: f64| match sweep_frequency {
        Some(s) if f.is_finite() => (f - s).abs() > SAME_FREQUENCY * s,
        // Where either is not given, both are the supply's.
        _ => false,
    };
    let used = &tests.locked_rotor;
    let mut out = record.clone();
    out.operating_points
        .extend(used.iter().map(|r| OperatingPoint {
            segment: r.segment,
            slip: 1.0,
            line_voltage: r.line_voltage,
            line_current: r.line_current,
            input_power: r.input_power,
            speed: 0.0,
            frequency: if r.frequency.is_finite() {
                r.frequency
            } else {
                sweep_frequency.unwrap_or(f64::NAN)
            },
            torque: None,
        }));
    // Stable: the sweep's own order within a segment stays.
    out.operating_points.sort_by_key(|p| p.segment);
    let mut left_out = Vec::new();
    let mut count = |n: usize, what: &str| {
        if n > 0 {
            left_out.push(format!("{n} {what}"));
        }
    };
    count(tests.no_load.len(), "no-load");
    count(tests.dc_resistance.len(), "DC-resistance");
    let mut warning = String::new();
    if !used.is_empty() {
        let at_reduced = used.iter().filter(|r| reduced(r.frequency)).count();
        warning.push_str(&format!(
            "the record's {} locked-rotor reading(s) are diagnosed with the load test, as \
             operating points at slip 1{}",
            used.len(),
            if at_reduced > 0 {
                format!(
                    " ({at_reduced} at another frequency, with the reactances, the bar's \
                     rotor frequency and the saturating flux at theirs)"
                )
            } else {
                String::new()
            }
        ));
    }
    if !left_out.is_empty() {
        if !warning.is_empty() {
            warning.push_str("; its ");
        } else {
            warning.push_str("the record's ");
        }
        warning.push_str(&format!(
            "{} reading(s) are not part of the diagnosis, which compares the circuit with \
             operating points of known slip only; `identify` uses them (the classical \
             reduction and the joint fit)",
            crate::excerpt::listed(&left_out)
        ));
    }
    (out, Some(warning))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{DcResistanceReading, SupplyReading};

    fn point(segment: u32, slip: f64) -> OperatingPoint {
        OperatingPoint {
            segment,
            slip,
            line_voltage: 400.0,
            line_current: 5.0,
            input_power: 2000.0,
            speed: (1.0 - slip) * 157.0,
            frequency: 50.0,
            torque: None,
        }
    }

    fn reading(segment: u32, frequency: f64) -> SupplyReading {
        SupplyReading {
            segment,
            line_voltage: 80.0,
            line_current: 6.0,
            input_power: 300.0,
            frequency,
            winding_temperature: None,
        }
    }

    #[test]
    fn locked_rotor_at_the_sweeps_frequency_joins_it_in_segment_order() {
        let mut r = Record {
            operating_points: vec![point(2, 0.01), point(2, 0.5)],
            ..Record::default()
        };
        r.standard_tests.locked_rotor = vec![reading(1, 50.0), reading(1, 12.5)];
        r.standard_tests.no_load = vec![reading(0, 50.0); 4];
        r.standard_tests.dc_resistance = vec![DcResistanceReading {
            segment: 3,
            dc_voltage: 2.0,
            dc_current: 1.0,
            winding_temperature: None,
        }];
        let (out, warning) = with_locked_rotor_points(&r);
        let slips: Vec<(u32, f64)> = out
            .operating_points
            .iter()
            .map(|p| (p.segment, p.slip))
            .collect();
        assert_eq!(slips, [(1, 1.0), (1, 1.0), (2, 0.01), (2, 0.5)]);
        let w = warning.unwrap();
        assert!(
            w.contains("2 locked-rotor reading(s) are diagnosed with the load test"),
            "{w}"
        );
        assert!(w.contains("(1 at another frequency"), "{w}");
        assert!(
            w.contains("its 4 no-load, 1 DC-resistance reading(s) are not part"),
            "{w}"
        );
    }

    #[test]
    fn a_record_without_standard_tests_is_unchanged() {
        let r = Record {
            operating_points: vec![point(0, 0.01)],
            ..Record::default()
        };
        assert_eq!(with_locked_rotor_points(&r), (r, None));
    }
}
