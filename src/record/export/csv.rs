//! Writes a record's segments as the contract's CSV import files, one file
//! per segment, so that `motorbench identify` on them gives the report a
//! replay of the record gives.
//!
//! - DC segments: `time_s` (s since the start of the test),
//!   `armature_voltage_V`, `armature_current_A`, `speed_rad_s`: the series
//!   identification reads (on the armature-current instants, see
//!   [`crate::record::RecordBuilder`]).
//! - Induction-machine sweeps: one row per operating point, `slip`,
//!   `line_voltage_V`, `line_current_A`, `input_power_W`, `frequency_Hz`,
//!   `torque_Nm` when a point of the sweep has a torque, and
//!   `winding_temperature_C` when a point has a winding temperature.
//! - The induction machine's standard tests, one row per reading:
//!   `im_dc_resistance` (`dc_voltage_V`, `dc_current_A`), `im_no_load` and
//!   `im_locked_rotor` (`line_voltage_V`, `line_current_A`,
//!   `input_power_W`, and `frequency_Hz` where a reading has one);
//!   `winding_temperature_C` where a reading of the segment has one.
//!
//! An optional column is written when any row of the file has a value,
//! and its cell is left empty in a row that has none (the importer reads
//! an empty cell as "not measured"): no reading's value is dropped
//! because another reading lacks one.
//!
//! Every file opens with the contract's declaration
//! (`# motorbench segment <index> kind=<kind> label=<label>`) and a
//! comment naming the record. Numbers are written in Rust's shortest
//! form that reads back to the same `f64`, so the round trip is exact.

use std::fmt::Write as _;

use crate::record::csv::{COL_CURRENT, COL_SPEED, COL_TIME, COL_VOLTAGE};
use crate::record::csv_im::{
    COL_FREQUENCY, COL_INPUT_POWER, COL_LINE_CURRENT, COL_LINE_VOLTAGE, COL_SLIP, COL_TORQUE,
};
use crate::record::csv_im_tests::{COL_DC_CURRENT, COL_DC_VOLTAGE, COL_WINDING_TEMPERATURE};
use crate::record::{
    DcResistanceReading, DcSegment, ImStandardTests, OperatingPoint, Record, SegmentKind,
    SupplyReading,
};

/// One CSV file's name suffix and text.
#[derive(Debug, Clone, PartialEq)]
pub struct CsvFile {
    /// The segment it holds.
    pub segment: u32,
    /// The file's text.
    pub text: String,
}

/// The CSV files of `record`'s segments that hold data, in index order;
/// `source` (the record's file name) goes into a comment. A DC segment's
/// text is made when the iterator reaches it, so a long record's files are
/// not all held at once. `export` streams the DC files instead
/// ([`super::dc_stream`], the same bytes) and comes here only for a record
/// whose readings go back in time.
pub fn segment_files<'a>(
    record: &'a Record,
    source: &'a str,
) -> impl Iterator<Item = CsvFile> + 'a {
    let mut dc = record
        .segments
        .iter()
        .filter(|s| !s.time.is_empty())
        .peekable();
    let mut others = other_files(record, source).into_iter().peekable();
    std::iter::from_fn(move || {
        let dc_first = match (dc.peek(), others.peek()) {
            (Some(s), Some(f)) => s.index <= f.segment,
            (dc_next, _) => dc_next.is_some(),
        };
        if dc_first {
            dc.next().map(|s| CsvFile {
                segment: s.index,
                text: dc_text(s, source),
            })
        } else {
            others.next()
        }
    })
}

/// The files of `record`'s induction-machine segments, in index order.
pub(super) fn other_files(record: &Record, source: &str) -> Vec<CsvFile> {
    let mut out: Vec<CsvFile> = Vec::new();
    // A segment's label as recorded, else `default`.
    let label = |index: u32, default: String| {
        record
            .segments
            .iter()
            .find(|s| s.index == index)
            .map_or(default, |s| s.label.clone())
    };
    for index in segment_indices(record.operating_points.iter().map(|p| p.segment)) {
        let points: Vec<&OperatingPoint> = record
            .operating_points
            .iter()
            .filter(|p| p.segment == index)
            .collect();
        out.push(CsvFile {
            segment: index,
            text: im_text(
                index,
                &label(index, format!("sweep {index}")),
                &points,
                source,
            ),
        });
    }
    let tests = &record.standard_tests;
    for index in segment_indices(tests.dc_resistance.iter().map(|r| r.segment)) {
        let readings: Vec<&DcResistanceReading> = tests
            .dc_resistance
            .iter()
            .filter(|r| r.segment == index)
            .collect();
        let kind = SegmentKind::ImDcResistance;
        let mut text = preamble(index, kind, &label(index, kind.as_str().into()), source);
        let temperature = readings.iter().any(|r| r.winding_temperature.is_some());
        let _ = write!(text, "{COL_DC_VOLTAGE},{COL_DC_CURRENT}");
        column_if(&mut text, temperature, COL_WINDING_TEMPERATURE);
        text.push('\n');
        for r in readings {
            let _ = write!(text, "{:?},{:?}", r.dc_voltage, r.dc_current);
            cell_if(&mut text, temperature, r.winding_temperature);
            text.push('\n');
        }
        out.push(CsvFile {
            segment: index,
            text,
        });
    }
    let supply = supply_test_files(
        tests,
        |index, kind| label(index, kind.as_str().into()),
        Some(source),
    );
    out.extend(supply.into_iter().map(|(_, f)| f));
    out.sort_by_key(|f| f.segment);
    out
}

/// The no-load and locked-rotor tests of `tests`, one file per segment
/// with its kind, labelled by `label`; `source`, where given, goes into a
/// comment.
pub fn supply_test_files(
    tests: &ImStandardTests,
    label: impl Fn(u32, SegmentKind) -> String,
    source: Option<&str>,
) -> Vec<(SegmentKind, CsvFile)> {
    let mut out = Vec::new();
    for (kind, readings) in [
        (SegmentKind::ImNoLoad, &tests.no_load),
        (SegmentKind::ImLockedRotor, &tests.locked_rotor),
    ] {
        for index in segment_indices(readings.iter().map(|r| r.segment)) {
            let readings: Vec<&SupplyReading> =
                readings.iter().filter(|r| r.segment == index).collect();
            let text = supply_test_text(index, kind, &label(index, kind), &readings, source);
            out.push((
                kind,
                CsvFile {
                    segment: index,
                    text,
                },
            ));
        }
    }
    out
}

/// The distinct segment indices of `segments`, in order.
fn segment_indices(segments: impl Iterator<Item = u32>) -> Vec<u32> {
    let mut v: Vec<u32> = segments.collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// The optional column `name` of a header, `,name`, where the file has
/// that column (`present`).
fn column_if(text: &mut String, present: bool, name: &str) {
    if present {
        text.push(',');
        text.push_str(name);
    }
}

/// The cell of an optional column, `,value` (`,` alone for `None`), where
/// the file has that column (`present`).
fn cell_if(text: &mut String, present: bool, v: Option<f64>) {
    if present {
        text.push(',');
        text.push_str(&cell(v));
    }
}

/// A cell of an optional column: the value, or empty where there is none.
fn cell(v: Option<f64>) -> String {
    v.map_or_else(String::new, |v| format!("{v:?}"))
}

/// A frequency as an optional value (NaN where it was not given).
fn given(frequency: f64) -> Option<f64> {
    frequency.is_finite().then_some(frequency)
}

/// One `im_no_load` or `im_locked_rotor` segment (`kind`) as the
/// contract's CSV file: `source`, where given, goes into a comment.
fn supply_test_text(
    index: u32,
    kind: SegmentKind,
    label: &str,
    readings: &[&SupplyReading],
    source: Option<&str>,
) -> String {
    let mut text = match source {
        Some(source) => preamble(index, kind, label, source),
        None => declaration(index, kind, label),
    };
    let frequency = readings.iter().any(|r| r.frequency.is_finite());
    let temperature = readings.iter().any(|r| r.winding_temperature.is_some());
    let _ = write!(
        text,
        "{COL_LINE_VOLTAGE},{COL_LINE_CURRENT},{COL_INPUT_POWER}"
    );
    column_if(&mut text, frequency, COL_FREQUENCY);
    column_if(&mut text, temperature, COL_WINDING_TEMPERATURE);
    text.push('\n');
    for r in readings {
        let _ = write!(
            text,
            "{:?},{:?},{:?}",
            r.line_voltage, r.line_current, r.input_power
        );
        cell_if(&mut text, frequency, given(r.frequency));
        cell_if(&mut text, temperature, r.winding_temperature);
        text.push('\n');
    }
    text
}

/// The contract's declaration line of a segment.
pub fn declaration(index: u32, kind: SegmentKind, label: &str) -> String {
    let label: String = label
        .chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect();
    format!("# motorbench segment {index} kind={kind} label={label}\n")
}

/// The declaration and the provenance comment.
pub(super) fn preamble(index: u32, kind: SegmentKind, label: &str, source: &str) -> String {
    format!(
        "{}# exported by {} from {source}\n",
        declaration(index, kind, label),
        crate::record::library_name()
    )
}

fn dc_text(s: &DcSegment, source: &str) -> String {
    let kind = s.kind.unwrap_or(SegmentKind::DcStep);
    let mut text = preamble(s.index, kind, &s.label, source);
    let _ = writeln!(text, "{COL_TIME},{COL_VOLTAGE},{COL_CURRENT},{COL_SPEED}");
    for k in 0..s.time.len() {
        let _ = writeln!(
            text,
            "{:?},{:?},{:?},{:?}",
            s.time[k], s.voltage[k], s.current[k], s.speed[k]
        );
    }
    text
}

fn im_text(index: u32, label: &str, points: &[&OperatingPoint], source: &str) -> String {
    let mut text = preamble(index, SegmentKind::ImSlipSweep, label, source);
    let torque = points.iter().any(|p| p.torque.is_some());
    let temperature = points.iter().any(|p| p.winding_temperature.is_some());
    let _ = write!(
        text,
        "{COL_SLIP},{COL_LINE_VOLTAGE},{COL_LINE_CURRENT},{COL_INPUT_POWER},{COL_FREQUENCY}"
    );
    column_if(&mut text, torque, COL_TORQUE);
    column_if(&mut text, temperature, COL_WINDING_TEMPERATURE);
    text.push('\n');
    for p in points {
        let _ = write!(
            text,
            "{:?},{:?},{:?},{:?},{}",
            p.slip,
            p.line_voltage,
            p.line_current,
            p.input_power,
            cell(given(p.frequency))
        );
        cell_if(&mut text, torque, p.torque);
        cell_if(&mut text, temperature, p.winding_temperature);
        text.push('\n');
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{read_dc_csv, read_im_csv, ColumnMap};

    #[test]
    fn a_dc_segment_reads_back_bit_for_bit() {
        let seg = DcSegment {
            index: 3,
            kind: Some(SegmentKind::DcCoastdown),
            label: "248 V → 0 V".into(),
            time: vec![0.1 + 0.2, 1.0 / 3.0, 7.0],
            voltage: vec![-0.0, 1e-300, 248.000_000_000_1],
            current: vec![0.001, -2.5e-17, 3.0],
            speed: vec![f64::MAX, 5e-324, 12.5],
        };
        let record = Record {
            segments: vec![seg.clone()],
            ..Record::default()
        };
        let files: Vec<CsvFile> = segment_files(&record, "r.mcap").collect();
        assert_eq!(files.len(), 1);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.csv");
        std::fs::write(&path, &files[0].text).unwrap();
        let back = read_dc_csv(&path, SegmentKind::DcStep, 0, &ColumnMap::default()).unwrap();
        assert_eq!(back.index, 3);
        assert_eq!(back.kind, Some(SegmentKind::DcCoastdown));
        assert_eq!(back.label, seg.label);
        for (a, b) in [
            (&back.time, &seg.time),
            (&back.voltage, &seg.voltage),
            (&back.current, &seg.current),
            (&back.speed, &seg.speed),
        ] {
            let a: Vec<u64> = a.iter().map(|v| v.to_bits()).collect();
            let b: Vec<u64> = b.iter().map(|v| v.to_bits()).collect();
            assert_eq!(a, b);
        }
    }

    #[test]
    fn an_im_sweep_reads_back_with_its_torque() {
        let point = |slip: f64| OperatingPoint {
            segment: 1,
            slip,
            line_voltage: 400.1,
            line_current: 7.25,
            input_power: 3100.5,
            speed: (1.0 - slip) * 157.079_632_679_489_66,
            frequency: 50.0,
            torque: Some(20.0 * slip),
            winding_temperature: None,
        };
        let record = Record {
            operating_points: vec![point(0.03), point(1.0)],
            ..Record::default()
        };
        let files: Vec<CsvFile> = segment_files(&record, "r.mcap").collect();
        assert!(files[0].text.contains("torque_Nm"), "{}", files[0].text);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.csv");
        std::fs::write(&path, &files[0].text).unwrap();
        let back = read_im_csv(&path, 0, None, Some(2), &ColumnMap::default()).unwrap();
        assert_eq!(back.index, 1);
        assert_eq!(back.label, "sweep 1");
        assert_eq!(back.points.len(), 2);
        assert_eq!(back.points[1].torque, Some(20.0));
        assert_eq!(back.points[0].slip, 0.03);
    }

    /// A sweep where only some points have a torque and a winding
    /// temperature, and one point has no frequency: every torque and
    /// temperature read is kept (the others' cells are empty)
    /// and the file reads back, the missing frequency the importer's.
    #[test]
    fn a_sweep_keeps_the_torque_of_the_points_that_have_one() {
        let point = |slip: f64, torque: Option<f64>, frequency: f64| OperatingPoint {
            segment: 0,
            slip,
            line_voltage: 400.0,
            line_current: 7.25,
            input_power: 3100.5,
            speed: f64::NAN,
            frequency,
            torque,
            winding_temperature: torque.map(|t| 40.0 + 2.0 * t),
        };
        let record = Record {
            operating_points: vec![
                point(0.03, Some(0.6), 50.0),
                point(0.5, None, f64::NAN),
                point(1.0, Some(20.0), 50.0),
            ],
            ..Record::default()
        };
        let text = &segment_files(&record, "r.mcap").next().unwrap().text;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.csv");
        std::fs::write(&path, text).unwrap();
        let back = read_im_csv(&path, 0, Some(60.0), None, &ColumnMap::default()).unwrap();
        let torques: Vec<Option<f64>> = back.points.iter().map(|p| p.torque).collect();
        assert_eq!(torques, [Some(0.6), None, Some(20.0)], "{text}");
        let temperatures: Vec<Option<f64>> =
            back.points.iter().map(|p| p.winding_temperature).collect();
        assert_eq!(
            temperatures,
            [Some(40.0 + 2.0 * 0.6), None, Some(80.0)],
            "{text}"
        );
        let frequencies: Vec<f64> = back.points.iter().map(|p| p.frequency).collect();
        assert_eq!(frequencies, [50.0, 60.0, 50.0], "{text}");
    }

    /// The standard tests read back bit for bit, the temperature and the
    /// frequency with them, where only some readings have a temperature
    /// too; a segment whose readings lack a frequency leaves the column
    /// out (the importer's `--frequency` then applies).
    #[test]
    fn standard_tests_read_back_with_their_temperatures() {
        let mut record = Record::default();
        record.standard_tests.dc_resistance = vec![DcResistanceReading {
            segment: 0,
            dc_voltage: 2.0 / 3.0,
            dc_current: 1.25,
            winding_temperature: Some(21.5),
        }];
        let reading = |segment: u32, frequency: f64| SupplyReading {
            segment,
            line_voltage: 400.0 / 3.0,
            line_current: 0.1 + 0.2,
            input_power: 123.456_789,
            frequency,
            winding_temperature: Some(40.25),
        };
        record.standard_tests.no_load = vec![reading(1, 50.0), reading(1, 50.0)];
        // A reading without a temperature keeps the others' (its cell is
        // empty).
        record.standard_tests.no_load[1].winding_temperature = None;
        record.standard_tests.locked_rotor = vec![reading(2, f64::NAN)];
        let files: Vec<CsvFile> = segment_files(&record, "r.mcap").collect();
        assert_eq!(
            files.iter().map(|f| f.segment).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        let dir = tempfile::tempdir().unwrap();
        let path = |k: usize| {
            let p = dir.path().join(format!("s{k}.csv"));
            std::fs::write(&p, &files[k].text).unwrap();
            p
        };
        let dc = crate::record::read_dc_resistance_csv(&path(0), 9, &ColumnMap::default()).unwrap();
        assert_eq!(dc.readings, record.standard_tests.dc_resistance);
        let nl = crate::record::read_supply_test_csv(
            &path(1),
            SegmentKind::ImNoLoad,
            9,
            None,
            &ColumnMap::default(),
        )
        .unwrap();
        assert_eq!(nl.readings, record.standard_tests.no_load);
        assert!(!files[2].text.contains("frequency_Hz"), "{}", files[2].text);
        let lr = crate::record::read_supply_test_csv(
            &path(2),
            SegmentKind::ImLockedRotor,
            9,
            Some(12.5),
            &ColumnMap::default(),
        )
        .unwrap();
        assert_eq!(lr.index, 2);
        assert_eq!(lr.readings[0].frequency, 12.5);
        assert_eq!(lr.readings[0].input_power, 123.456_789);
    }
}
