//! A record's standard tests in the diagnosis: which of them are operating
//! points of the load test's circuit, and how.
//!
//! A locked-rotor reading is an operating point at slip 1, exactly what
//! the last point of a slip sweep is (a motor lab's locked-rotor segment
//! imported as `im_slip_sweep` was always diagnosed so); it joins the
//! points in recording (segment) order, so that the heat index keeps its
//! meaning. At a reduced frequency the models take the reactances, deep
//! bar's rotor frequency and the saturating flux at that frequency
//! (`PointInput::freq_ratio`): two frequencies are what separates deep bar
//! from leakage saturation.
//!
//! A no-load reading is a free-running point: its slip is not measured,
//! and the rotor delivers the friction and windage. It joins the points
//! too, at the slip where the rotor delivers that loss, which every model
//! of the diagnosis fits (`PointInput::free_running`); a no-load sweep
//! over several voltages is where main-flux saturation and core loss show
//! most clearly. An `im_slip_sweep` segment at zero slip throughout is
//! such a test whose slip was not measured (a lab's no-load CSV imported
//! as a sweep), and is read so, with a warning. The DC resistance is no
//! operating point: it sets the stator resistance of the friction's start
//! value.

use std::collections::BTreeSet;

use crate::record::{OperatingPoint, Record, SupplyReading};

/// Relative difference of two supply frequencies that are the same.
pub(super) const SAME_FREQUENCY: f64 = 0.01;

/// A record's points as the IM diagnosis reads them.
#[derive(Debug, Clone, PartialEq)]
pub struct StandardPoints {
    /// The record with its locked-rotor and no-load readings added to its
    /// operating points, in segment order.
    pub record: Record,
    /// The segments whose points run free (no-load: slip not measured).
    pub free_running: Vec<u32>,
    /// The free-running points as no-load readings, for the friction.
    pub no_load: Vec<SupplyReading>,
    /// What the diagnosis makes of the standard tests, where there are any.
    pub warning: Option<String>,
}

impl StandardPoints {
    /// The record without its free-running points.
    pub fn without_free_running(&self) -> Record {
        let mut out = self.record.clone();
        out.operating_points
            .retain(|p| !self.free_running.contains(&p.segment));
        out
    }
}

/// The segments of `points` at exactly zero slip throughout.
fn zero_slip_segments(points: &[OperatingPoint]) -> BTreeSet<u32> {
    let all: BTreeSet<u32> = points.iter().map(|p| p.segment).collect();
    all.into_iter()
        .filter(|&s| {
            points
                .iter()
                .filter(|p| p.segment == s)
                .all(|p| p.slip == 0.0)
        })
        .collect()
}

/// The record's operating points with its locked-rotor and no-load
/// readings added (in segment order), which segments run free, and a
/// warning saying what the diagnosis makes of the standard tests; the
/// record as it is, and no warning, when it has none.
pub fn with_standard_points(record: &Record) -> StandardPoints {
    let tests = &record.standard_tests;
    let zero_slip = zero_slip_segments(&record.operating_points);
    let mut notes: Vec<String> = Vec::new();
    if !zero_slip.is_empty() {
        let list: Vec<String> = zero_slip.iter().map(u32::to_string).collect();
        notes.push(format!(
            "im_slip_sweep segment(s) {} are at zero slip throughout: read as a no-load test \
             whose slip was not measured (record them as im_no_load to say so)",
            list.join(", ")
        ));
    }
    let sweep_frequency = record
        .operating_points
        .iter()
        .filter(|p| !zero_slip.contains(&p.segment))
        .map(|p| p.frequency)
        .find(|f| f.is_finite());
    let reduced = |f: f64| match sweep_frequency {
        Some(s) if f.is_finite() => (f - s).abs() > SAME_FREQUENCY * s,
        // Where either is not given, both are the supply's.
        _ => false,
    };
    let frequency = |f: f64| {
        if f.is_finite() {
            f
        } else {
            sweep_frequency.unwrap_or(f64::NAN)
        }
    };
    let point = |r: &SupplyReading, slip: f64| OperatingPoint {
        segment: r.segment,
        slip,
        line_voltage: r.line_voltage,
        line_current: r.line_current,
        input_power: r.input_power,
        speed: if slip == 1.0 { 0.0 } else { f64::NAN },
        frequency: frequency(r.frequency),
        torque: None,
        winding_temperature: r.winding_temperature,
    };
    let mut out = record.clone();
    out.operating_points
        .extend(tests.locked_rotor.iter().map(|r| point(r, 1.0)));
    out.operating_points
        .extend(tests.no_load.iter().map(|r| point(r, 0.0)));
    // Stable: the sweep's own order within a segment stays.
    out.operating_points.sort_by_key(|p| p.segment);
    let mut no_load = tests.no_load.clone();
    no_load.extend(
        record
            .operating_points
            .iter()
            .filter(|p| zero_slip.contains(&p.segment))
            .map(|p| SupplyReading {
                segment: p.segment,
                line_voltage: p.line_voltage,
                line_current: p.line_current,
                input_power: p.input_power,
                frequency: p.frequency,
                winding_temperature: p.winding_temperature,
            }),
    );
    let free_running: Vec<u32> = tests
        .no_load
        .iter()
        .map(|r| r.segment)
        .chain(zero_slip)
        .collect::<BTreeSet<u32>>()
        .into_iter()
        .collect();
    let lr = &tests.locked_rotor;
    if !lr.is_empty() {
        let at_reduced = lr.iter().filter(|r| reduced(r.frequency)).count();
        notes.push(format!(
            "the record's {} locked-rotor reading(s) are diagnosed with the load test, as \
             operating points at slip 1{}",
            lr.len(),
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
    let dc = tests.dc_resistance.len();
    if dc > 0 {
        notes.push(if no_load.is_empty() {
            format!(
                "the record's {dc} DC-resistance reading(s) are no operating point and not part \
                 of the diagnosis; `identify` uses them (the classical reduction and the joint \
                 fit)"
            )
        } else {
            format!(
                "the record's {dc} DC-resistance reading(s) set the stator resistance of the \
                 no-load friction's start value"
            )
        });
    }
    StandardPoints {
        record: out,
        free_running,
        no_load,
        warning: (!notes.is_empty()).then(|| notes.join("; ")),
    }
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
            winding_temperature: None,
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
    fn standard_readings_join_the_sweep_in_segment_order() {
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
        let got = with_standard_points(&r);
        let slips: Vec<(u32, f64)> = got
            .record
            .operating_points
            .iter()
            .map(|p| (p.segment, p.slip))
            .collect();
        assert_eq!(
            slips,
            [
                (0, 0.0),
                (0, 0.0),
                (0, 0.0),
                (0, 0.0),
                (1, 1.0),
                (1, 1.0),
                (2, 0.01),
                (2, 0.5)
            ]
        );
        assert_eq!(got.free_running, [0]);
        assert_eq!(got.no_load.len(), 4);
        let w = got.warning.clone().unwrap();
        assert!(
            w.contains("2 locked-rotor reading(s) are diagnosed with the load test"),
            "{w}"
        );
        assert!(w.contains("(1 at another frequency"), "{w}");
        assert!(
            w.contains("1 DC-resistance reading(s) set the stator resistance"),
            "{w}"
        );
        assert_eq!(got.without_free_running().operating_points.len(), 4);
    }

    /// A lab's no-load CSV imported as a sweep has slip 0 on every row:
    /// that segment runs free, a sweep point at slip 0 among others does not.
    #[test]
    fn a_sweep_segment_at_zero_slip_throughout_is_a_no_load_test() {
        let r = Record {
            operating_points: vec![point(0, 0.0), point(0, 0.0), point(1, 0.0), point(1, 0.2)],
            ..Record::default()
        };
        let got = with_standard_points(&r);
        assert_eq!(got.free_running, [0]);
        assert_eq!(got.no_load.len(), 2);
        assert_eq!(got.record, r);
        let w = got.warning.clone().unwrap();
        assert!(
            w.contains("segment(s) 0 are at zero slip throughout"),
            "{w}"
        );
    }

    #[test]
    fn a_record_without_standard_tests_is_unchanged() {
        let r = Record {
            operating_points: vec![point(0, 0.01)],
            ..Record::default()
        };
        let got = with_standard_points(&r);
        assert!(got.free_running.is_empty() && got.no_load.is_empty());
        assert_eq!((got.record, got.warning), (r, None));
    }
}
