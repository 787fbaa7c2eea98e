//! CSV import of one `im_slip_sweep` segment (the contract's "CSV import"):
//! columns `slip`, `line_voltage_V`, `line_current_A`, `input_power_W`,
//! optional `torque_Nm` and `frequency_Hz`, in any order, unknown columns
//! ignored, `#` comment lines, and the optional declaration
//! `# motorbench segment <index> kind=im_slip_sweep label=<text>`.
//!
//! Refused with the file, the line and the column: a missing column, a
//! field that is not a finite number, a slip outside [0, 1], a voltage or
//! current that is not > 0, a row of the wrong width, a declaration of
//! another kind, a file without rows.
//!
//! Speed is not a CSV column; it is computed from slip, frequency and the
//! pole pairs where both are known, and NaN (unknown) otherwise.

use std::path::Path;

use super::csv::{read_text, CsvLines, CsvRow};
use super::error::RecordError;
use super::types::{OperatingPoint, SegmentKind};
use crate::excerpt::cut;

/// Slip column.
pub const COL_SLIP: &str = "slip";
/// Line-voltage column (RMS, line to line).
pub const COL_LINE_VOLTAGE: &str = "line_voltage_V";
/// Line-current column (RMS).
pub const COL_LINE_CURRENT: &str = "line_current_A";
/// Three-phase input-power column.
pub const COL_INPUT_POWER: &str = "input_power_W";
/// Optional shaft-torque column.
pub const COL_TORQUE: &str = "torque_Nm";
/// Optional supply-frequency column.
pub const COL_FREQUENCY: &str = "frequency_Hz";

/// One imported sweep segment.
#[derive(Debug, Clone, PartialEq)]
pub struct ImCsvSegment {
    /// Segment index.
    pub index: u32,
    /// Label (the declaration's, or the file name).
    pub label: String,
    /// The operating points in file order.
    pub points: Vec<OperatingPoint>,
}

/// Read one `im_slip_sweep` segment. `frequency` (Hz) applies where the
/// file has no `frequency_Hz` column; `pole_pairs` gives the speed.
pub fn read_im_csv(
    path: &Path,
    default_index: u32,
    frequency: Option<f64>,
    pole_pairs: Option<u32>,
) -> Result<ImCsvSegment, RecordError> {
    let text = read_text(path)?;
    let csv = CsvLines::split(path, &text)?;
    let err = |line: usize, column: Option<&str>, reason: String| {
        RecordError::csv(path, line, column, reason)
    };
    if let (Some(no), Some(kind)) = (csv.decl_line, csv.decl.kind) {
        if kind != SegmentKind::ImSlipSweep {
            return Err(err(
                no,
                None,
                format!("the file declares kind {kind}, not im_slip_sweep"),
            ));
        }
    }
    let (header, lines) = csv.header(path)?;
    let find = |name: &str| header.find(path, name);
    let header_no = header.no;
    let header = &header.names;
    let required = |name: &str| -> Result<usize, RecordError> {
        find(name)?.ok_or_else(|| {
            err(
                header_no,
                Some(name),
                format!(
                    "missing column (the header names: {})",
                    cut(&header.join(", "))
                ),
            )
        })
    };
    let slip_col = required(COL_SLIP)?;
    let v_col = required(COL_LINE_VOLTAGE)?;
    let i_col = required(COL_LINE_CURRENT)?;
    let p_col = required(COL_INPUT_POWER)?;
    let t_col = find(COL_TORQUE)?;
    let f_col = find(COL_FREQUENCY)?;
    let index = csv.decl.index.unwrap_or(default_index);
    let mut points = Vec::new();
    for &(no, line) in lines {
        let row = CsvRow::split(path, header, no, line)?;
        let number = |col: usize| row.number(col);
        let slip = number(slip_col)?;
        if !(0.0..=1.0).contains(&slip) {
            return Err(err(
                no,
                Some(COL_SLIP),
                format!("slip {slip} is outside [0, 1]"),
            ));
        }
        let positive = |col: usize| -> Result<f64, RecordError> {
            let v = number(col)?;
            if v <= 0.0 {
                return Err(err(no, Some(header[col]), format!("{v} must be > 0")));
            }
            Ok(v)
        };
        let line_voltage = positive(v_col)?;
        let line_current = positive(i_col)?;
        let input_power = number(p_col)?;
        let torque = t_col.map(number).transpose()?;
        let f = match f_col {
            Some(c) => positive(c)?,
            None => frequency.unwrap_or(f64::NAN),
        };
        let speed = match pole_pairs {
            Some(p) if p > 0 => (1.0 - slip) * std::f64::consts::TAU * f / f64::from(p),
            _ => f64::NAN,
        };
        points.push(OperatingPoint {
            segment: index,
            slip,
            line_voltage,
            line_current,
            input_power,
            speed,
            frequency: f,
            torque,
        });
    }
    if points.is_empty() {
        return Err(err(header_no, None, "no data rows after the header".into()));
    }
    Ok(ImCsvSegment {
        index,
        label: csv.label(path),
        points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<ImCsvSegment, RecordError> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sweep.csv");
        std::fs::write(&p, text).unwrap();
        read_im_csv(&p, 3, Some(50.0), Some(2))
    }

    #[test]
    fn any_column_order_optional_columns_and_declaration() {
        let seg = read(
            "# motorbench segment 1 kind=im_slip_sweep label=400 V\n# a note\n\
             input_power_W, note, line_current_A,slip,line_voltage_V,torque_Nm\n\
             310.5,x,3.1,0.002,400,0.4\n9000,y,40,1,399,30\n",
        )
        .unwrap();
        assert_eq!(seg.index, 1);
        assert_eq!(seg.label, "400 V");
        assert_eq!(seg.points.len(), 2);
        let p = seg.points[0];
        assert_eq!(
            (
                p.slip,
                p.line_voltage,
                p.line_current,
                p.input_power,
                p.torque
            ),
            (0.002, 400.0, 3.1, 310.5, Some(0.4))
        );
        assert_eq!(p.frequency, 50.0);
        assert!((p.speed - 0.998 * std::f64::consts::PI * 50.0).abs() < 1e-9);
        assert_eq!(seg.points[1].segment, 1);
    }

    #[test]
    fn without_frequency_the_speed_is_unknown() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.csv");
        std::fs::write(
            &p,
            "slip,line_voltage_V,line_current_A,input_power_W\n0.5,400,10,2000\n",
        )
        .unwrap();
        let seg = read_im_csv(&p, 0, None, Some(2)).unwrap();
        assert!(seg.points[0].frequency.is_nan() && seg.points[0].speed.is_nan());
        assert_eq!(seg.points[0].non_finite_field().map(|f| f.0), Some("speed"));
        assert_eq!(seg.label, "s.csv");
        assert_eq!(seg.index, 0);
    }

    #[test]
    fn bad_input_names_file_line_and_column() {
        let cases = [
            (
                "slip,line_voltage_V,line_current_A\n0.1,400,3\n",
                1,
                "input_power_W",
                "missing column",
            ),
            (
                "slip,line_voltage_V,line_current_A,input_power_W\n1.5,400,3,100\n",
                2,
                "slip",
                "outside [0, 1]",
            ),
            (
                "slip,line_voltage_V,line_current_A,input_power_W\n0.1,400,abc,100\n",
                2,
                "line_current_A",
                "not a number",
            ),
            (
                "slip,line_voltage_V,line_current_A,input_power_W\n0.1,0,3,100\n",
                2,
                "line_voltage_V",
                "must be > 0",
            ),
            (
                "slip,line_voltage_V,line_current_A,input_power_W\n0.1,400,3,NaN\n",
                2,
                "input_power_W",
                "not a finite",
            ),
            (
                "slip,line_voltage_V,line_current_A,input_power_W\n0.1,400,3\n",
                2,
                "input_power_W",
                "fields",
            ),
            (
                "slip,line_voltage_V,line_current_A,input_power_W\n",
                1,
                "",
                "no data rows",
            ),
            (
                "# motorbench segment 0 kind=dc_step\nslip\n",
                1,
                "",
                "not im_slip_sweep",
            ),
        ];
        for (text, line, column, why) in cases {
            let e = read(text).unwrap_err().to_string();
            assert!(e.contains("sweep.csv"), "{e}");
            assert!(e.contains(&format!(":{line}")), "want line {line}: {e}");
            assert!(e.contains(column), "want column {column}: {e}");
            assert!(e.contains(why), "want {why:?}: {e}");
        }
    }
}
