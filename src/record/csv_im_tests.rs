//! CSV import of the induction machine's standard tests besides the slip
//! sweep, one segment per file like every CSV import:
//!
//! - `im_dc_resistance`: `dc_voltage_V`, `dc_current_A` (between two line
//!   terminals), optional `winding_temperature_C`;
//! - `im_no_load` and `im_locked_rotor`: the sweep's `line_voltage_V`,
//!   `line_current_A`, `input_power_W`, optional `frequency_Hz` (else the
//!   caller's frequency) and `winding_temperature_C`.
//!
//! The file's declaration (`# motorbench segment <index> kind=<kind>
//! label=<text>`) names its kind; [`im_file_kind`] reads it so a record can
//! mix the sweep with these tests. Refused with the file, the line and the
//! column: a missing column, a field that is not a finite number, a
//! voltage, current, power or frequency that is not > 0, a temperature
//! outside −60…250 °C, a declaration of another kind, a file without rows.

use std::path::Path;

use super::columns::ColumnMap;
use super::csv::{read_text, CsvLines, CsvRow};
use super::csv_im::{COL_FREQUENCY, COL_INPUT_POWER, COL_LINE_CURRENT, COL_LINE_VOLTAGE};
use super::error::RecordError;
use super::im_tests::{implausible_temperature, DcResistanceReading, SupplyReading};
use super::types::SegmentKind;
use crate::excerpt::cut;

/// DC-voltage column of a DC-resistance file (between two line terminals).
pub const COL_DC_VOLTAGE: &str = "dc_voltage_V";
/// DC-current column of a DC-resistance file.
pub const COL_DC_CURRENT: &str = "dc_current_A";
/// Optional winding-temperature column, °C.
pub const COL_WINDING_TEMPERATURE: &str = "winding_temperature_C";

/// One imported standard-test segment.
#[derive(Debug, Clone, PartialEq)]
pub struct ImTestCsvSegment<T> {
    /// Segment index.
    pub index: u32,
    /// Label (the declaration's, or the file name).
    pub label: String,
    /// The readings in file order.
    pub readings: Vec<T>,
}

/// The kind `path` declares, else `default`.
pub fn im_file_kind(path: &Path, default: SegmentKind) -> Result<SegmentKind, RecordError> {
    let text = read_text(path)?;
    Ok(CsvLines::split(path, &text)?.decl.kind.unwrap_or(default))
}

/// The rows of a file of `kind`: per row its line, the `required` columns'
/// numbers and the `optional` columns' numbers where present.
struct Table {
    index: u32,
    label: String,
    rows: Vec<(usize, Vec<f64>, Vec<Option<f64>>)>,
}

fn read_table(
    path: &Path,
    kind: SegmentKind,
    default_index: u32,
    required: &[&str],
    optional: &[&str],
    columns: &ColumnMap,
) -> Result<Table, RecordError> {
    let text = read_text(path)?;
    let csv = CsvLines::split(path, &text)?;
    if let (Some(no), Some(declared)) = (csv.decl_line, csv.decl.kind) {
        if declared != kind {
            return Err(RecordError::csv(
                path,
                no,
                None,
                format!("the file declares kind {declared}, not {kind}"),
            ));
        }
    }
    let (header, lines) = csv.header(path, columns)?;
    let mut req = Vec::new();
    for name in required {
        let col = header.find(path, name)?.ok_or_else(|| {
            RecordError::csv(
                path,
                header.no,
                Some(name),
                format!(
                    "missing column (a {kind} file needs {}; the header names: {}; read a column \
                     of another name as one of these with --column NAME=HEADER)",
                    required.join(", "),
                    cut(&header.names.join(", "))
                ),
            )
        })?;
        req.push(col);
    }
    let opt = optional
        .iter()
        .map(|name| header.find(path, name))
        .collect::<Result<Vec<_>, _>>()?;
    let mut rows = Vec::new();
    for &(no, line) in lines {
        let row = CsvRow::split(path, &header, no, line)?;
        let values = req
            .iter()
            .map(|&c| row.number(c))
            .collect::<Result<Vec<_>, _>>()?;
        let extra = opt
            .iter()
            .map(|c| {
                c.map(|c| row.optional_number(c))
                    .transpose()
                    .map(Option::flatten)
            })
            .collect::<Result<Vec<_>, _>>()?;
        rows.push((no, values, extra));
    }
    if rows.is_empty() {
        return Err(RecordError::csv(
            path,
            header.no,
            None,
            "no data rows after the header",
        ));
    }
    Ok(Table {
        index: csv.decl.index.unwrap_or(default_index),
        label: csv.label(path),
        rows,
    })
}

/// `v` if it is > 0, else an error at `line`, `column`.
fn positive(path: &Path, line: usize, column: &str, v: f64) -> Result<f64, RecordError> {
    if v > 0.0 {
        Ok(v)
    } else {
        Err(RecordError::csv(
            path,
            line,
            Some(column),
            format!("{v} must be > 0"),
        ))
    }
}

/// A winding temperature that can be one ([`implausible_temperature`]).
pub(super) fn temperature(
    path: &Path,
    line: usize,
    t: Option<f64>,
) -> Result<Option<f64>, RecordError> {
    match t.and_then(|t| implausible_temperature(t).map(|why| (t, why))) {
        Some((t, why)) => Err(RecordError::csv(
            path,
            line,
            Some(COL_WINDING_TEMPERATURE),
            format!("{t} {why}"),
        )),
        None => Ok(t),
    }
}

/// Read one `im_dc_resistance` segment.
pub fn read_dc_resistance_csv(
    path: &Path,
    default_index: u32,
    columns: &ColumnMap,
) -> Result<ImTestCsvSegment<DcResistanceReading>, RecordError> {
    let t = read_table(
        path,
        SegmentKind::ImDcResistance,
        default_index,
        &[COL_DC_VOLTAGE, COL_DC_CURRENT],
        &[COL_WINDING_TEMPERATURE],
        columns,
    )?;
    let mut readings = Vec::new();
    for (no, v, extra) in &t.rows {
        readings.push(DcResistanceReading {
            segment: t.index,
            dc_voltage: positive(path, *no, COL_DC_VOLTAGE, v[0])?,
            dc_current: positive(path, *no, COL_DC_CURRENT, v[1])?,
            winding_temperature: temperature(path, *no, extra[0])?,
        });
    }
    Ok(ImTestCsvSegment {
        index: t.index,
        label: t.label,
        readings,
    })
}

/// Read one `im_no_load` or `im_locked_rotor` segment (`kind`);
/// `frequency` (Hz) applies where the file has no `frequency_Hz` column.
pub fn read_supply_test_csv(
    path: &Path,
    kind: SegmentKind,
    default_index: u32,
    frequency: Option<f64>,
    columns: &ColumnMap,
) -> Result<ImTestCsvSegment<SupplyReading>, RecordError> {
    let t = read_table(
        path,
        kind,
        default_index,
        &[COL_LINE_VOLTAGE, COL_LINE_CURRENT, COL_INPUT_POWER],
        &[COL_FREQUENCY, COL_WINDING_TEMPERATURE],
        columns,
    )?;
    let mut readings = Vec::new();
    for (no, v, extra) in &t.rows {
        let frequency = match extra[0] {
            Some(f) => positive(path, *no, COL_FREQUENCY, f)?,
            None => frequency.unwrap_or(f64::NAN),
        };
        readings.push(SupplyReading {
            segment: t.index,
            line_voltage: positive(path, *no, COL_LINE_VOLTAGE, v[0])?,
            line_current: positive(path, *no, COL_LINE_CURRENT, v[1])?,
            input_power: positive(path, *no, COL_INPUT_POWER, v[2])?,
            frequency,
            winding_temperature: temperature(path, *no, extra[1])?,
        });
    }
    Ok(ImTestCsvSegment {
        index: t.index,
        label: t.label,
        readings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        (dir, p)
    }

    #[test]
    fn dc_resistance_and_no_load_files_read_with_their_declarations() {
        let (_d, p) = write(
            "dc.csv",
            "# motorbench segment 4 kind=im_dc_resistance label=cold\n\
             dc_current_A,dc_voltage_V,winding_temperature_C\n2.0,3.1,21.5\n4,6.2,21.5\n",
        );
        assert_eq!(
            im_file_kind(&p, SegmentKind::ImSlipSweep).unwrap(),
            SegmentKind::ImDcResistance
        );
        let seg = read_dc_resistance_csv(&p, 0, &ColumnMap::default()).unwrap();
        assert_eq!((seg.index, seg.label.as_str()), (4, "cold"));
        assert_eq!(seg.readings[1].dc_voltage, 6.2);
        assert_eq!(seg.readings[0].winding_temperature, Some(21.5));

        let (_d, p) = write(
            "nl.csv",
            "line_voltage_V,line_current_A,input_power_W\n400,3.5,250\n",
        );
        let seg = read_supply_test_csv(
            &p,
            SegmentKind::ImNoLoad,
            2,
            Some(50.0),
            &ColumnMap::default(),
        )
        .unwrap();
        assert_eq!(seg.index, 2);
        assert_eq!(seg.readings[0].frequency, 50.0);
        assert_eq!(seg.readings[0].winding_temperature, None);
    }

    #[test]
    fn bad_input_names_file_line_and_column() {
        let cases: [(&str, SegmentKind, usize, &str, &str); 6] = [
            (
                "dc_voltage_V\n3\n",
                SegmentKind::ImDcResistance,
                1,
                "dc_current_A",
                "missing column",
            ),
            (
                "dc_voltage_V,dc_current_A\n3,-1\n",
                SegmentKind::ImDcResistance,
                2,
                "dc_current_A",
                "must be > 0",
            ),
            (
                "dc_voltage_V,dc_current_A,winding_temperature_C\n3,1,300\n",
                SegmentKind::ImDcResistance,
                2,
                "winding_temperature_C",
                "not K",
            ),
            (
                "line_voltage_V,line_current_A,input_power_W\n100,2,x\n",
                SegmentKind::ImLockedRotor,
                2,
                "input_power_W",
                "not a number",
            ),
            (
                "# motorbench segment 0 kind=im_no_load\nline_voltage_V\n",
                SegmentKind::ImLockedRotor,
                1,
                "",
                "not im_locked_rotor",
            ),
            (
                "line_voltage_V,line_current_A,input_power_W\n",
                SegmentKind::ImNoLoad,
                1,
                "",
                "no data rows",
            ),
        ];
        for (text, kind, line, column, why) in cases {
            let (_d, p) = write("test.csv", text);
            let e = match kind {
                SegmentKind::ImDcResistance => {
                    read_dc_resistance_csv(&p, 0, &ColumnMap::default()).map(|_| ())
                }
                k => read_supply_test_csv(&p, k, 0, None, &ColumnMap::default()).map(|_| ()),
            }
            .unwrap_err()
            .to_string();
            assert!(e.contains("test.csv"), "{e}");
            assert!(e.contains(&format!(":{line}")), "want line {line}: {e}");
            assert!(e.contains(column), "want column {column}: {e}");
            assert!(e.contains(why), "want {why:?}: {e}");
        }
    }
}
