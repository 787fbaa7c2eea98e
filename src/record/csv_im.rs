//! CSV import of one `im_slip_sweep` segment (the contract's "CSV import"):
//! columns `slip`, `line_voltage_V`, `line_current_A`, `input_power_W`,
//! optional `torque_Nm`, `frequency_Hz` and `winding_temperature_C` (°C,
//! motorbench's addition), in any order, unknown columns
//! ignored, `#` comment lines, and the optional declaration
//! `# motorbench segment <index> kind=im_slip_sweep label=<text>`.
//!
//! Refused with the file, the line and the column: a missing column, a
//! field that is not a finite number, a slip outside [0, 1], a voltage or
//! current that is not > 0, a row of the wrong width, a declaration of
//! another kind, a file without rows.
//!
//! In place of `slip`, a file may give the measured shaft speed,
//! `speed_rpm` or `speed_rad_s` (motorbench's addition: a lab measures
//! speed); the slip is then `1 − ω·p/(2π·f)` with the nameplate's pole
//! pairs and the supply frequency, and a file without them is refused
//! saying so. Otherwise the speed is computed from slip, frequency and
//! the pole pairs where both are known, and NaN (unknown) otherwise.

use std::path::Path;

use super::columns::ColumnMap;
use super::csv::{missing_column, read_text, CsvLines, CsvRow};
use super::csv_im_tests::{temperature, COL_WINDING_TEMPERATURE};
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
/// Shaft speed in r/min, in place of `slip` (motorbench's addition).
pub const COL_SPEED_RPM: &str = "speed_rpm";
/// Shaft speed in rad/s, in place of `slip` (motorbench's addition).
pub const COL_SPEED_RAD_S: &str = "speed_rad_s";

/// Where a row's slip comes from.
#[derive(Debug, Clone, Copy)]
enum SlipSource {
    /// The `slip` column.
    Slip(usize),
    /// A speed column, its name and its factor to rad/s.
    Speed(usize, &'static str, f64),
}

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
    columns: &ColumnMap,
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
    let (header_row, lines) = csv.header(path, columns)?;
    let find = |name: &str| header_row.find(path, name);
    let header_no = header_row.no;
    let header = &header_row.names;
    let required = |name: &str| -> Result<usize, RecordError> {
        find(name)?.ok_or_else(|| err(header_no, Some(name), missing_column("", header)))
    };
    // The slip, or the shaft speed it is computed from (a lab measures
    // speed): s = 1 − ω·p/(2π·f).
    let slip_source = match (
        find(COL_SLIP)?,
        find(COL_SPEED_RPM)?,
        find(COL_SPEED_RAD_S)?,
    ) {
        (Some(c), _, _) => SlipSource::Slip(c),
        (None, Some(c), _) => SlipSource::Speed(c, COL_SPEED_RPM, std::f64::consts::TAU / 60.0),
        (None, None, Some(c)) => SlipSource::Speed(c, COL_SPEED_RAD_S, 1.0),
        (None, None, None) => {
            return Err(err(
                header_no,
                Some(COL_SLIP),
                format!(
                    "missing column (or {COL_SPEED_RPM} or {COL_SPEED_RAD_S}, with the nameplate's \
                     poles; the header names: {}; read a column of another name as one of these \
                     with --column NAME=HEADER)",
                    cut(&header.join(", "))
                ),
            ))
        }
    };
    let v_col = required(COL_LINE_VOLTAGE)?;
    let i_col = required(COL_LINE_CURRENT)?;
    let p_col = required(COL_INPUT_POWER)?;
    let t_col = find(COL_TORQUE)?;
    let f_col = find(COL_FREQUENCY)?;
    let temperature_col = find(COL_WINDING_TEMPERATURE)?;
    let index = csv.decl.index.unwrap_or(default_index);
    let mut points = Vec::new();
    for &(no, line) in lines {
        let row = CsvRow::split(path, &header_row, no, line)?;
        let number = |col: usize| row.number(col);
        let positive = |col: usize| -> Result<f64, RecordError> {
            let v = number(col)?;
            if v <= 0.0 {
                return Err(err(no, Some(header[col]), format!("{v} must be > 0")));
            }
            Ok(v)
        };
        // An empty cell of an optional column: not measured at this point.
        let f = match f_col.filter(|&c| !row.is_empty(c)) {
            Some(c) => positive(c)?,
            None => frequency.unwrap_or(f64::NAN),
        };
        let (slip, slip_column, from_speed) = match slip_source {
            SlipSource::Slip(c) => (number(c)?, COL_SLIP, String::new()),
            SlipSource::Speed(c, name, to_rad_s) => {
                let p =
                    match pole_pairs {
                        Some(p) if p > 0 && f.is_finite() => f64::from(p),
                        _ => return Err(err(
                            no,
                            Some(name),
                            "the slip is computed from the speed with the machine's poles and the \
                             supply frequency: give --nameplate with poles and frequency_Hz (or a \
                             frequency_Hz column)"
                                .into(),
                        )),
                    };
                let w = number(c)? * to_rad_s;
                let s = 1.0 - w * p / (std::f64::consts::TAU * f);
                (
                    s,
                    name,
                    format!(" (computed from the speed {w:.4} rad/s, {p} pole pairs, {f} Hz)"),
                )
            }
        };
        if !(0.0..=1.0).contains(&slip) {
            return Err(err(
                no,
                Some(slip_column),
                format!("slip {slip} is outside [0, 1]{from_speed}"),
            ));
        }
        let line_voltage = positive(v_col)?;
        let line_current = positive(i_col)?;
        let input_power = number(p_col)?;
        let torque = t_col.map(|c| row.optional_number(c)).transpose()?.flatten();
        let winding_temperature = temperature(
            path,
            no,
            temperature_col
                .map(|c| row.optional_number(c))
                .transpose()?
                .flatten(),
        )?;
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
            winding_temperature,
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
        read_with(text, Some(2))
    }

    /// `text` as `sweep.csv` at 50 Hz with `pole_pairs`.
    fn read_with(text: &str, pole_pairs: Option<u32>) -> Result<ImCsvSegment, RecordError> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sweep.csv");
        std::fs::write(&p, text).unwrap();
        read_im_csv(&p, 3, Some(50.0), pole_pairs, &ColumnMap::default())
    }

    /// A lab's own names, mapped: the same points as under the contract's.
    #[test]
    fn a_mapped_header_reads_as_the_contracts() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sweep.csv");
        std::fs::write(&p, "n [rpm],U [V],I [A],P1 [W]\n1470,400,3.1,310.5\n").unwrap();
        let map = ColumnMap::parse(&[
            "speed_rpm=n [rpm]",
            "line_voltage_V=U [V]",
            "line_current_A=I [A]",
            "input_power_W=P1 [W]",
        ])
        .unwrap();
        let mapped = read_im_csv(&p, 3, Some(50.0), Some(2), &map).unwrap();
        let contract =
            read("speed_rpm,line_voltage_V,line_current_A,input_power_W\n1470,400,3.1,310.5\n")
                .unwrap();
        assert_eq!(mapped.points, contract.points);
        let e = read_im_csv(&p, 0, Some(50.0), Some(2), &ColumnMap::default()).unwrap_err();
        assert!(e.to_string().contains("--column NAME=HEADER"), "{e}");
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
        assert_eq!(p.winding_temperature, None);
    }

    #[test]
    fn a_winding_temperature_column_is_read_per_point() {
        let seg = read(
            "slip,line_voltage_V,line_current_A,input_power_W,winding_temperature_C\n\
             0.01,400,4,900,41.5\n0.02,400,5,1500,\n0.03,400,6,2100,44\n",
        )
        .unwrap();
        let t: Vec<Option<f64>> = seg.points.iter().map(|p| p.winding_temperature).collect();
        assert_eq!(t, [Some(41.5), None, Some(44.0)]);
    }

    #[test]
    fn a_winding_temperature_in_kelvin_is_refused_naming_line_and_column() {
        let e = read(
            "slip,line_voltage_V,line_current_A,input_power_W,winding_temperature_C\n\
             0.01,400,4,900,41.5\n0.02,400,5,1500,318.15\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("sweep.csv:3") && e.contains("winding_temperature_C"),
            "{e}"
        );
        assert!(e.contains("not K"), "{e}");
    }

    #[test]
    fn a_measured_speed_gives_the_slip_with_the_poles_and_the_frequency() {
        // 4 poles at 50 Hz: 1500 r/min synchronous; 1455 r/min is slip 0.03.
        let seg = read(
            "speed_rpm,line_voltage_V,line_current_A,input_power_W\n1455,400,10,6000\n1500,400,4,300\n",
        )
        .unwrap();
        assert!(
            (seg.points[0].slip - 0.03).abs() < 1e-12,
            "{}",
            seg.points[0].slip
        );
        assert!(seg.points[1].slip.abs() < 1e-12);
        let w = 1455.0 * std::f64::consts::TAU / 60.0;
        assert!((seg.points[0].speed - w).abs() < 1e-9);
        // The same in rad/s, and the slip column winning over a speed.
        let seg = read(&format!(
            "speed_rad_s,line_voltage_V,line_current_A,input_power_W\n{w},400,10,6000\n"
        ))
        .unwrap();
        assert!((seg.points[0].slip - 0.03).abs() < 1e-12);
        let seg = read(
            "slip,speed_rpm,line_voltage_V,line_current_A,input_power_W\n0.05,1455,400,10,6000\n",
        )
        .unwrap();
        assert_eq!(seg.points[0].slip, 0.05);
        // Without the poles the slip cannot be had: say what to give.
        let e = read_with(
            "speed_rpm,line_voltage_V,line_current_A,input_power_W\n1455,400,10,6000\n",
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("sweep.csv:2: column speed_rpm") && e.contains("poles"),
            "{e}"
        );
        // A speed above synchronous (a generator, or the wrong poles).
        let e = read("speed_rpm,line_voltage_V,line_current_A,input_power_W\n1600,400,10,6000\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("outside [0, 1] (computed from the speed"), "{e}");
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
        let seg = read_im_csv(&p, 0, None, Some(2), &ColumnMap::default()).unwrap();
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
