//! CSV import per the contract's "CSV import" section: one file is one
//! segment, for data taken elsewhere (a scope, a spreadsheet).
//!
//! DC kinds (`dc_step`, `dc_coastdown`) need the columns `time_s`,
//! `armature_voltage_V`, `armature_current_A` and `speed_rad_s`; in place
//! of each but the voltage, one in another unit is converted to SI:
//! `time_ms` (×10⁻³), `armature_current_mA` (×10⁻³), `speed_rpm` (×2π/60).
//! Where both are present the SI column is used. The header row names the columns, in any order, optionally in
//! quotes; unknown columns are ignored (and not parsed). Fields are plain
//! numbers with optional surrounding whitespace (and optional quotes),
//! separated by commas — or, as a spreadsheet in a decimal-comma locale or
//! a logger exports them, by semicolons or tabs (motorbench's addition to
//! the contract): the header row's most frequent of the three is the
//! file's delimiter, and where it is not the comma a field's comma is its
//! decimal point (`0,25` is 0.25). Blank lines and lines starting with `#`
//! are skipped.
//!
//! The file may open with a declaration comment,
//! `# motorbench segment <index> kind=<kind> label=<free text>`
//! (`kind=` and `label=` optional); without it the segment takes the
//! caller's kind and index, and the file name as its label.
//!
//! Refused with the file, the line and (where there is one) the column: a
//! missing column, a field that is not a number, NaN or infinity, time not
//! strictly increasing, a time beyond ±10¹⁰ s, a step between rows outside
//! 1 µs to 10 s (see [`crate::bounds`]), a row whose number of fields differs from the
//! header's, a malformed declaration, a file without a header or data rows.
//! `im_slip_sweep` files are read by [`super::read_im_csv`].

use std::path::Path;

use super::columns::ColumnMap;
use super::error::{DeclarationError, RecordError, TimeError};
use super::types::{DcSegment, SegmentKind};
use crate::bounds::{MAX_CSV_STEP_S, MAX_CSV_TIME_S, MIN_CSV_STEP_S};
use crate::excerpt::{cut, quoted};

/// Time column.
pub const COL_TIME: &str = "time_s";
/// Armature-voltage column.
pub const COL_VOLTAGE: &str = "armature_voltage_V";
/// Armature-current column.
pub const COL_CURRENT: &str = "armature_current_A";
/// Speed column in rad/s.
pub const COL_SPEED: &str = "speed_rad_s";
/// Speed column in rpm, accepted instead of [`COL_SPEED`].
pub const COL_SPEED_RPM: &str = "speed_rpm";
/// Time column in ms, accepted instead of [`COL_TIME`] (motorbench's
/// addition: scopes and loggers often write milliseconds).
pub const COL_TIME_MS: &str = "time_ms";
/// Armature-current column in mA, accepted instead of [`COL_CURRENT`]
/// (motorbench's addition, for small motors' shunt readings).
pub const COL_CURRENT_MA: &str = "armature_current_mA";

/// Prefix of the declaration comment, after `#` and blanks.
const DECLARATION: &str = "motorbench segment";

/// rpm → rad/s.
const RPM_TO_RAD_S: f64 = 2.0 * std::f64::consts::PI / 60.0;

/// What the declaration comment says.
#[derive(Debug, Default)]
pub(super) struct Declaration {
    pub(super) index: Option<u32>,
    pub(super) kind: Option<SegmentKind>,
    pub(super) label: Option<String>,
}

/// Reads one DC segment from a CSV file. `default_kind` and
/// `default_index` apply unless the file declares its own.
pub fn read_dc_csv(
    path: &Path,
    default_kind: SegmentKind,
    default_index: u32,
    columns: &ColumnMap,
) -> Result<DcSegment, RecordError> {
    let text = read_text(path)?;
    let csv = CsvLines::split(path, &text)?;
    let err = |line: usize, column: Option<&str>, reason: String| {
        RecordError::csv(path, line, column, reason)
    };

    let kind = csv.decl.kind.unwrap_or(default_kind);
    if kind.is_im() {
        return Err(RecordError::Unsupported {
            path: path.to_path_buf(),
            reason: format!("an {kind} file holds induction-machine readings, not DC samples (give --kind {kind})"),
        });
    }

    let (header_row, lines) = csv.header(path, columns)?;
    let find = |name: &str| header_row.find(path, name);
    let header_no = header_row.no;
    let header = &header_row.names;
    let missing =
        |name: &str, extra: &str| err(header_no, Some(name), missing_column(extra, header));
    // Each quantity from its SI column, else from the first of its other
    // units the file has: (column, factor to SI, name).
    let column =
        |units: &[(&'static str, f64)]| -> Result<(usize, f64, &'static str), RecordError> {
            for &(name, scale) in units {
                if let Some(c) = find(name)? {
                    return Ok((c, scale, name));
                }
            }
            let others: Vec<&str> = units[1..].iter().map(|(n, _)| *n).collect();
            let extra = if others.is_empty() {
                String::new()
            } else {
                format!(" (or {})", others.join(" or "))
            };
            Err(missing(units[0].0, &extra))
        };
    let time = column(&[(COL_TIME, 1.0), (COL_TIME_MS, 1e-3)])?;
    let voltage = column(&[(COL_VOLTAGE, 1.0)])?;
    let current = column(&[(COL_CURRENT, 1.0), (COL_CURRENT_MA, 1e-3)])?;
    let speed = column(&[(COL_SPEED, 1.0), (COL_SPEED_RPM, RPM_TO_RAD_S)])?;

    let mut seg = DcSegment {
        index: csv.decl.index.unwrap_or(default_index),
        kind: Some(kind),
        label: csv.label(path),
        ..DcSegment::default()
    };
    let mut previous_time: Option<(f64, usize)> = None;
    for &(no, line) in lines {
        let row = CsvRow::split(path, &header_row, no, line)?;
        // In SI: times the unit's factor (1 for an SI column).
        let si = |(col, scale, _): (usize, f64, &str)| -> Result<f64, RecordError> {
            Ok(row.number(col)? * scale)
        };
        let t = si(time)?;
        check_time(t, previous_time).map_err(|why| err(no, Some(time.2), why.to_string()))?;
        previous_time = Some((t, no));
        seg.time.push(t);
        seg.voltage.push(si(voltage)?);
        seg.current.push(si(current)?);
        seg.speed.push(si(speed)?);
    }
    if seg.time.is_empty() {
        return Err(err(header_no, None, "no data rows after the header".into()));
    }
    Ok(seg)
}

/// The line (from 1) of each data row of the CSV file at `path`, in
/// order: where an error found in a segment's samples stands in the file.
pub fn data_lines(path: &Path) -> Result<Vec<usize>, RecordError> {
    let text = read_text(path)?;
    let csv = CsvLines::split(path, &text)?;
    let (_, rows) = csv.header(path, &ColumnMap::default())?;
    Ok(rows.iter().map(|(no, _)| *no).collect())
}

/// Why a header lacks a column: what it names instead, and how to map a
/// column of another name (`extra`: the other units' names, if any).
pub(super) fn missing_column(extra: &str, header: &[&str]) -> String {
    format!(
        "missing column{extra} (the header names: {}; read a column of another name as this \
         one with --column NAME=HEADER)",
        cut(&header.join(", "))
    )
}

/// Time `t` of a row, after `previous` (the previous row's time and line):
/// within ±[`MAX_CSV_TIME_S`] and a step of [`MIN_CSV_STEP_S`] to
/// [`MAX_CSV_STEP_S`] after the previous row's.
fn check_time(t: f64, previous: Option<(f64, usize)>) -> Result<(), TimeError> {
    if t.abs() > MAX_CSV_TIME_S {
        return Err(TimeError::OutOfRange { t });
    }
    let Some((prev, prev_no)) = previous else {
        return Ok(());
    };
    if t <= prev {
        return Err(TimeError::NotIncreasing {
            t,
            previous: prev,
            previous_line: prev_no,
        });
    }
    let step = t - prev;
    if !(MIN_CSV_STEP_S..=MAX_CSV_STEP_S).contains(&step) {
        return Err(TimeError::Step {
            step,
            previous_line: prev_no,
        });
    }
    Ok(())
}

/// The file's text, without a leading byte-order mark.
pub(super) fn read_text(path: &Path) -> Result<String, RecordError> {
    let text = std::fs::read_to_string(path).map_err(|e| RecordError::io(path, e))?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// A CSV file split the contract's way: the optional declaration on the
/// first non-blank line, then the header and data lines, blank and `#`
/// comment lines skipped.
pub(super) struct CsvLines<'a> {
    /// The declaration (empty when the file has none).
    pub decl: Declaration,
    /// The line of the declaration, when the file has one.
    pub decl_line: Option<usize>,
    lines: Vec<NumberedLine<'a>>,
    last_line: usize,
}

/// A 1-based line number and the line's text.
pub(super) type NumberedLine<'a> = (usize, &'a str);

/// The header row: its line number, column names and delimiter.
pub(super) struct CsvHeader<'a> {
    /// 1-based line number.
    pub no: usize,
    /// Column names, quotes removed.
    pub names: Vec<&'a str>,
    /// What separates the fields, in this row and every data row.
    pub delimiter: Delimiter,
}

/// A CSV file's field separator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Delimiter {
    /// `,` (the contract's), with a decimal point.
    Comma,
    /// `;`, a decimal-comma locale's spreadsheet export: a field's comma
    /// is its decimal point.
    Semicolon,
    /// A tab, as loggers write: a field's comma is its decimal point.
    Tab,
}

impl Delimiter {
    /// The most frequent separator of the header `line` (the comma where
    /// none is more frequent).
    fn of_header(line: &str) -> Delimiter {
        let count = |c: char| line.matches(c).count();
        let (commas, semicolons, tabs) = (count(','), count(';'), count('\t'));
        if semicolons > commas && semicolons >= tabs {
            Delimiter::Semicolon
        } else if tabs > commas && tabs > semicolons {
            Delimiter::Tab
        } else {
            Delimiter::Comma
        }
    }

    /// The separator itself.
    fn char(self) -> char {
        match self {
            Delimiter::Comma => ',',
            Delimiter::Semicolon => ';',
            Delimiter::Tab => '\t',
        }
    }

    /// `field` as a number: with a decimal comma where the delimiter is
    /// not the comma (`"0,25"` is 0.25; `"1,000.5"`, a thousands
    /// separator, is not a number).
    fn parse(self, field: &str) -> Option<f64> {
        if self == Delimiter::Comma || !field.contains(',') {
            return field.parse().ok();
        }
        field.replacen(',', ".", 1).parse().ok()
    }
}

impl<'a> CsvLines<'a> {
    /// Split `text` (of `path`); a malformed declaration is an error.
    pub(super) fn split(path: &Path, text: &'a str) -> Result<CsvLines<'a>, RecordError> {
        let mut lines = text
            .split('\n')
            .enumerate()
            .map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l)))
            .filter(|(_, l)| !l.trim().is_empty())
            .peekable();
        let mut decl = Declaration::default();
        let mut decl_line = None;
        if let Some(&(no, line)) = lines.peek() {
            if let Some(rest) = declaration_text(line) {
                decl = parse_declaration(rest)
                    .map_err(|r| RecordError::csv(path, no, None, r.to_string()))?;
                decl_line = Some(no);
                lines.next();
            }
        }
        Ok(CsvLines {
            decl,
            decl_line,
            lines: lines
                .filter(|(_, l)| !l.trim_start().starts_with('#'))
                .collect(),
            last_line: text.lines().count().max(1),
        })
    }

    /// The header row (its cells renamed by `columns`) and the data lines
    /// after it.
    pub(super) fn header(
        &self,
        path: &Path,
        columns: &ColumnMap,
    ) -> Result<(CsvHeader<'a>, &[NumberedLine<'a>]), RecordError> {
        let Some((&(no, line), rows)) = self.lines.split_first() else {
            let reason = "no header row (the file is empty)";
            return Err(RecordError::csv(path, self.last_line, None, reason));
        };
        let delimiter = Delimiter::of_header(line);
        let mut names: Vec<&str> = line.split(delimiter.char()).map(unquote).collect();
        if names.iter().all(|n| delimiter.parse(n.trim()).is_some()) {
            let reason = format!(
                "no header row: the first line that is not a '#' comment holds numbers ({}); \
                 the file's first row must name its columns (the data contract's names: \
                 time_s,armature_voltage_V,armature_current_A,speed_rad_s for a DC segment, \
                 slip,line_voltage_V,line_current_A,input_power_W for an induction machine's)",
                cut(line)
            );
            return Err(RecordError::csv(path, no, None, reason));
        }
        columns.rename(&mut names);
        Ok((
            CsvHeader {
                no,
                names,
                delimiter,
            },
            rows,
        ))
    }

    /// The declared label, or the file name.
    pub(super) fn label(&self, path: &Path) -> String {
        self.decl.label.clone().unwrap_or_else(|| {
            path.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        })
    }
}

impl CsvHeader<'_> {
    /// The index of column `name`, if present; a column named twice is an
    /// error naming it.
    pub(super) fn find(&self, path: &Path, name: &str) -> Result<Option<usize>, RecordError> {
        let mut hits = self.names.iter().enumerate().filter(|(_, h)| **h == name);
        let first = hits.next().map(|(i, _)| i);
        if hits.next().is_some() {
            return Err(RecordError::csv(
                path,
                self.no,
                Some(name),
                "column appears twice",
            ));
        }
        Ok(first)
    }
}

/// The text after `# motorbench segment`, if `line` is a declaration.
pub(super) fn declaration_text(line: &str) -> Option<&str> {
    let rest = line.trim().strip_prefix('#')?.trim_start();
    let rest = rest.strip_prefix(DECLARATION)?;
    if rest.is_empty() || rest.starts_with(char::is_whitespace) {
        Some(rest.trim())
    } else {
        None
    }
}

/// Parses `<index> kind=<kind> label=<free text>`.
pub(super) fn parse_declaration(text: &str) -> Result<Declaration, DeclarationError> {
    let mut decl = Declaration::default();
    let (index, mut rest) = split_word(text);
    if index.is_empty() {
        return Err(DeclarationError::NoIndex);
    }
    decl.index = Some(index.parse().map_err(|_| DeclarationError::BadIndex {
        quoted: quoted(index),
    })?);
    if let Some(after) = rest.strip_prefix("kind=") {
        let (kind, tail) = split_word(after);
        decl.kind = Some(
            SegmentKind::parse(kind).ok_or_else(|| DeclarationError::BadKind {
                quoted: quoted(kind),
            })?,
        );
        rest = tail;
    }
    if let Some(label) = rest.strip_prefix("label=") {
        decl.label = Some(label.trim().to_string());
    } else if !rest.is_empty() {
        return Err(DeclarationError::Unexpected {
            quoted: quoted(rest),
        });
    }
    Ok(decl)
}

/// The first whitespace-separated word and the trimmed rest.
fn split_word(s: &str) -> (&str, &str) {
    let s = s.trim_start();
    match s.find(char::is_whitespace) {
        Some(i) => (&s[..i], s[i..].trim()),
        None => (s, ""),
    }
}

/// Trims blanks and one pair of surrounding quotes.
/// One data row, split into fields and checked against the header.
pub(super) struct CsvRow<'a> {
    path: &'a Path,
    header: &'a [&'a str],
    delimiter: Delimiter,
    no: usize,
    fields: Vec<&'a str>,
}

impl<'a> CsvRow<'a> {
    /// Split line `no` of `path`; refuse a field count other than the
    /// header's (naming the first missing column, if any).
    pub(super) fn split(
        path: &'a Path,
        header: &'a CsvHeader<'a>,
        no: usize,
        line: &'a str,
    ) -> Result<CsvRow<'a>, RecordError> {
        let (delimiter, header) = (header.delimiter, &header.names[..]);
        let fields: Vec<&str> = line.split(delimiter.char()).collect();
        if fields.len() != header.len() {
            let column = header.get(fields.len()).copied();
            let reason = format!(
                "the row has {} fields, the header has {}",
                fields.len(),
                header.len()
            );
            return Err(RecordError::csv(path, no, column, reason));
        }
        Ok(CsvRow {
            path,
            header,
            delimiter,
            no,
            fields,
        })
    }

    /// Field `col` as a finite number; the error names file, line, column.
    pub(super) fn number(&self, col: usize) -> Result<f64, RecordError> {
        let name = self.header[col];
        let raw = unquote(self.fields[col]);
        let bad = |what: &str| {
            RecordError::csv(
                self.path,
                self.no,
                Some(name),
                format!("{} is not {what}", quoted(raw)),
            )
        };
        let v = self.delimiter.parse(raw).ok_or_else(|| bad("a number"))?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(bad("a finite number"))
        }
    }

    /// Field `col` of an optional column: `None` where the cell is empty
    /// (not measured at this row), else as [`CsvRow::number`].
    pub(super) fn optional_number(&self, col: usize) -> Result<Option<f64>, RecordError> {
        if self.is_empty(col) {
            Ok(None)
        } else {
            self.number(col).map(Some)
        }
    }

    /// Whether field `col` is empty (blank or an empty quote).
    pub(super) fn is_empty(&self, col: usize) -> bool {
        unquote(self.fields[col]).is_empty()
    }
}

pub(super) fn unquote(s: &str) -> &str {
    let s = s.trim();
    for q in ['"', '\''] {
        if let Some(inner) = s.strip_prefix(q).and_then(|r| r.strip_suffix(q)) {
            return inner.trim();
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn read(text: &str) -> Result<DcSegment, RecordError> {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "data.csv", text);
        read_dc_csv(&p, SegmentKind::DcStep, 3, &ColumnMap::default())
    }

    /// The error text, checked to name the file, the line and the column.
    fn error(text: &str, line: usize, column: Option<&str>) -> String {
        let e = read(text).unwrap_err();
        let s = e.to_string();
        assert!(matches!(e, RecordError::Csv { .. }), "{s}");
        assert!(s.contains("data.csv"), "{s}");
        assert!(s.contains(&format!("data.csv:{line}: ")), "{s}");
        if let Some(c) = column {
            assert!(s.contains(&format!("column {c}: ")), "{s}");
        }
        assert!(!s.contains('\n'), "{s}");
        s
    }

    #[test]
    fn times_the_numerics_cannot_take_are_refused_with_line_and_column() {
        let header = "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n";
        let rows = |times: &[&str]| {
            let mut s = header.to_string();
            for t in times {
                s += &format!("{t},60,0.1,40\n");
            }
            s
        };
        let e = error(&rows(&["0", "1e-300", "2e-300"]), 3, Some(COL_TIME));
        assert!(e.contains("1e-6"), "{e}");
        let e = error(&rows(&["1e300", "1.0000001e300"]), 2, Some(COL_TIME));
        assert!(e.contains("1e300 s is beyond"), "{e}");
        let e = error(&rows(&["0", "0.001", "1e308"]), 4, Some(COL_TIME));
        assert!(e.contains("1e308"), "{e}");
        let e = error(&rows(&["0", "0.001", "60"]), 4, Some(COL_TIME));
        assert!(e.contains("10 s"), "{e}");
        // A Unix time at 1 kHz is fine.
        let seg = read(&rows(&["1764547200.000", "1764547200.001"])).unwrap();
        assert_eq!(seg.time.len(), 2);
    }

    #[test]
    fn a_long_bad_field_is_cut_in_the_message() {
        let field = "7".repeat(100_000) + "x";
        let text =
            format!("time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,60,{field},40\n");
        let e = error(&text, 2, Some(COL_CURRENT));
        assert!(e.len() < 200, "{} bytes", e.len());
        assert!(e.contains("…(100001 bytes) is not a number"), "{e}");
    }

    #[test]
    fn happy_path_any_order_unknown_columns_comments() {
        let seg = read(
            "# scope export\n\
             \"speed_rad_s\", time_s ,armature_current_A,note,armature_voltage_V\r\n\
             10.5, 0.0, 1.25, x, 24\r\n\
             \n\
             # a comment between rows\n\
             11.0,0.001,1.5,y,24.0\n",
        )
        .unwrap();
        assert_eq!(seg.index, 3);
        assert_eq!(seg.kind, Some(SegmentKind::DcStep));
        assert_eq!(seg.label, "data.csv");
        assert_eq!(seg.time, vec![0.0, 0.001]);
        assert_eq!(seg.voltage, vec![24.0, 24.0]);
        assert_eq!(seg.current, vec![1.25, 1.5]);
        assert_eq!(seg.speed, vec![10.5, 11.0]);
    }

    #[test]
    fn semicolon_and_tab_separated_files_read_a_decimal_comma() {
        let comma = read(
            "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,60,0.25,40\n0.5,60,1.5,41\n",
        )
        .unwrap();
        for text in [
            "time_s;armature_voltage_V;armature_current_A;speed_rad_s\n0;60;0,25;40\n0,5;60;1,5;41\n",
            "\"time_s\";\"armature_voltage_V\";\"armature_current_A\";\"speed_rad_s\"\n0;60;\"0,25\";40\n0,5;60;1.5;41\n",
            "time_s\tarmature_voltage_V\tarmature_current_A\tspeed_rad_s\n0\t60\t0,25\t40\n0.5\t60\t1,5\t41\n",
        ] {
            let seg = read(text).unwrap();
            assert_eq!(
                (&seg.time, &seg.voltage, &seg.current, &seg.speed),
                (&comma.time, &comma.voltage, &comma.current, &comma.speed),
                "{text}"
            );
        }
        // A thousands separator is not a decimal comma.
        let e = error(
            "time_s;armature_voltage_V;armature_current_A;speed_rad_s\n0;1,000.5;0,25;40\n",
            2,
            Some("armature_voltage_V"),
        );
        assert!(e.contains("\"1,000.5\" is not a number"), "{e}");
        // A comma-separated row under a semicolon header is one field.
        let e = error(
            "time_s;armature_voltage_V;armature_current_A;speed_rad_s\n0,60,0.25,40\n",
            2,
            Some("armature_voltage_V"),
        );
        assert!(e.contains("the row has 1 fields, the header has 4"), "{e}");
        // A comma-separated file keeps its decimal point: a decimal
        // comma there is a field more.
        let e = error(
            "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,60,0,25,40\n",
            2,
            None,
        );
        assert!(e.contains("the row has 5 fields, the header has 4"), "{e}");
    }

    #[test]
    fn rpm_is_converted() {
        let seg =
            read("time_s,armature_voltage_V,armature_current_A,speed_rpm\n0,1,2,60\n1,1,2,3000\n")
                .unwrap();
        assert_eq!(seg.speed[0], 2.0 * std::f64::consts::PI / 60.0 * 60.0);
        assert!((seg.speed[0] - 2.0 * std::f64::consts::PI).abs() < 1e-12);
        assert!((seg.speed[1] - 314.159_265_358_979_3).abs() < 1e-9);
    }

    #[test]
    fn milliseconds_and_milliamperes_are_read_in_si() {
        let seg = read(
            "time_ms,armature_voltage_V,armature_current_mA,speed_rad_s\n0,1,250,3\n0.5,1,500,4\n",
        )
        .unwrap();
        assert_eq!(seg.time, vec![0.0, 0.5e-3]);
        assert_eq!(seg.current, vec![0.25, 0.5]);
        // The SI column wins where both are present.
        let seg =
            read("time_s,time_ms,armature_voltage_V,armature_current_A,speed_rad_s\n0,7,1,2,3\n")
                .unwrap();
        assert_eq!(seg.time, vec![0.0]);
        // A time in ms checked as seconds: a step of 20 s is refused
        // naming the column the file has.
        let s = error(
            "time_ms,armature_voltage_V,armature_current_A,speed_rad_s\n0,1,2,3\n20000,1,2,3\n",
            3,
            Some(COL_TIME_MS),
        );
        assert!(s.contains("step"), "{s}");
        let s = error(
            "armature_voltage_V,armature_current_A,speed_rad_s\n1,2,3\n",
            1,
            Some(COL_TIME),
        );
        assert!(s.contains("(or time_ms)"), "{s}");
    }

    #[test]
    fn rad_s_wins_over_rpm() {
        let seg = read(
            "time_s,armature_voltage_V,armature_current_A,speed_rpm,speed_rad_s\n0,1,2,60,7\n",
        )
        .unwrap();
        assert_eq!(seg.speed, vec![7.0]);
    }

    #[test]
    fn declaration_comment() {
        let seg = read(
            "# motorbench segment 4 kind=dc_coastdown label=coast from 1500 rpm, hot\n\
             time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,0,0,150\n0.5,0,0,100\n",
        )
        .unwrap();
        assert_eq!(seg.index, 4);
        assert_eq!(seg.kind, Some(SegmentKind::DcCoastdown));
        assert_eq!(seg.label, "coast from 1500 rpm, hot");
        let seg = read(
            "  # motorbench segment 7\n\
             time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,0,0,150\n",
        )
        .unwrap();
        assert_eq!((seg.index, seg.kind), (7, Some(SegmentKind::DcStep)));
        assert_eq!(seg.label, "data.csv");
    }

    #[test]
    fn im_slip_sweep_is_not_a_dc_file() {
        let e = read("# motorbench segment 0 kind=im_slip_sweep label=sweep\nslip\n").unwrap_err();
        assert!(matches!(e, RecordError::Unsupported { .. }), "{e}");
        assert!(e.to_string().contains("--kind im_slip_sweep"), "{e}");
        let e = read("# motorbench segment 0 kind=im_no_load\nline_voltage_V\n").unwrap_err();
        assert!(e.to_string().contains("an im_no_load file"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "s.csv", "slip\n0.1\n");
        let e = read_dc_csv(&p, SegmentKind::ImSlipSweep, 0, &ColumnMap::default()).unwrap_err();
        assert!(e.to_string().contains("s.csv"), "{e}");
    }

    /// Every refusal of a bad DC CSV text: the line, the column where
    /// there is one, and what the message says.
    #[test]
    fn bad_files_name_line_column_and_cause() {
        const HEAD: &str = "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n";
        let with_head = |rows: &str| format!("{HEAD}{rows}");
        let cases: Vec<(String, usize, Option<&str>, &str)> = vec![
            // The declaration comment.
            (
                "# motorbench segment x kind=dc_step label=a\ntime_s\n".into(),
                1,
                None,
                "segment index",
            ),
            ("# motorbench segment 1 kind=ac\n".into(), 1, None, "\"ac\""),
            // The header row.
            ("".into(), 1, None, "no header"),
            ("# only a comment\n\n".into(), 2, None, "no header"),
            (
                "# c\n0,1.5,2,3e2\n1,1.5,2,3e2\n".into(),
                2,
                None,
                "no header row",
            ),
            (
                "# c\n0,1.5,2,3e2\n1,1.5,2,3e2\n".into(),
                2,
                None,
                "0,1.5,2,3e2",
            ),
            (
                "# c\ntime_s,armature_voltage_V,speed_rad_s\n0,1,2\n".into(),
                2,
                Some(COL_CURRENT),
                "missing column",
            ),
            (
                "time_s,armature_voltage_V,armature_current_A\n0,1,2\n".into(),
                1,
                Some(COL_SPEED),
                "speed_rpm",
            ),
            (format!("time_s,{HEAD}"), 1, Some(COL_TIME), "time_s"),
            (format!("# c\n{HEAD}# nothing\n"), 2, None, "no data rows"),
            // The rows.
            (
                with_head("0,1,2,3\n0.1,1,abc,3\n"),
                3,
                Some(COL_CURRENT),
                "\"abc\" is not a number",
            ),
            (
                with_head("0,,2,3\n"),
                2,
                Some(COL_VOLTAGE),
                "\"\" is not a number",
            ),
            (
                with_head("0,1,2,3\n0.5,1,2,3\n0.5,1,2,3\n"),
                4,
                Some(COL_TIME),
                "line 3",
            ),
            (
                with_head("0,1,2,3\n# x\n-1,1,2,3\n"),
                4,
                Some(COL_TIME),
                "data.csv:4",
            ),
            (
                with_head("0,1,2\n"),
                2,
                Some(COL_SPEED),
                "3 fields, the header has 4",
            ),
            (with_head("0,1,2,3,4\n"), 2, None, "5 fields"),
        ];
        for (text, line, column, says) in &cases {
            let s = error(text, *line, *column);
            assert!(s.contains(says), "{text:?}: {s}");
        }
        let s = error(&with_head("0,1,2,3\n0.1,1,abc,3\n"), 3, Some(COL_CURRENT));
        assert!(s.ends_with("\"abc\" is not a number"), "{s}");
        for bad in ["NaN", "nan", "inf", "-infinity"] {
            let s = error(
                &with_head(&format!("0,1,2,3\n1,1,2,{bad}\n")),
                3,
                Some(COL_SPEED),
            );
            assert!(s.contains("not a finite number"), "{s}");
        }
    }

    #[test]
    fn missing_file() {
        let dir = tempfile::tempdir().unwrap();
        let e = read_dc_csv(
            &dir.path().join("nope.csv"),
            SegmentKind::DcStep,
            0,
            &ColumnMap::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("nope.csv"), "{e}");
    }
}
