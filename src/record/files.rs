//! Load a record from the files a user names on the command line: one
//! MCAP file, or any number of CSV files (one segment each) with an
//! optional nameplate (JSON). Shared by `identify`, `diagnose` and the
//! blind benchmark's scorer.

use std::path::{Path, PathBuf};

use super::{read_dc_csv, read_im_csv, read_mcap, Record, SegmentKind, TestMeta, SCHEMA_VERSION};

/// Read `files` as a record of `kind`. An IM record takes its supply
/// frequency from `frequency`, else the nameplate's `frequency_Hz`, and
/// its pole pairs from the nameplate's `poles`. Errors name the file (and
/// line and field where there is one).
pub fn load_record_files(
    kind: SegmentKind,
    files: &[PathBuf],
    nameplate: Option<&Path>,
    frequency: Option<f64>,
) -> Result<Record, String> {
    let plate = nameplate.map(read_nameplate).transpose()?;
    let is_mcap = |p: &PathBuf| {
        p.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
    };
    match files.iter().filter(|p| is_mcap(p)).count() {
        0 => {}
        1 if files.len() == 1 => return read_mcap(&files[0]).map_err(|e| e.to_string()),
        _ => return Err("give either one MCAP file or any number of CSV files".into()),
    }
    let mut record = Record::default();
    let mut seen: Vec<(u32, usize)> = Vec::new();
    let mut claim = |index: u32, n: usize| -> Result<(), String> {
        if let Some((_, other)) = seen.iter().find(|(i, _)| *i == index) {
            return Err(format!(
                "{}: segment index {index} is already used by {}",
                files[n].display(),
                files[*other].display()
            ));
        }
        seen.push((index, n));
        Ok(())
    };
    if kind == SegmentKind::ImSlipSweep {
        let number = |key: &str| {
            plate
                .as_ref()
                .and_then(|p| p.get(key))
                .and_then(|v| v.as_f64())
        };
        let frequency = frequency.or_else(|| number("frequency_Hz"));
        let pole_pairs = number("poles").map(|p| (p / 2.0).round() as u32);
        for (n, path) in files.iter().enumerate() {
            let seg =
                read_im_csv(path, n as u32, frequency, pole_pairs).map_err(|e| e.to_string())?;
            claim(seg.index, n)?;
            record.operating_points.extend(seg.points);
        }
        record.meta = plate.map(|nameplate| TestMeta {
            schema_version: SCHEMA_VERSION.to_string(),
            kind,
            motor_id: String::new(),
            started_at: String::new(),
            nameplate,
            config: String::new(),
        });
        return Ok(record);
    }
    for (n, path) in files.iter().enumerate() {
        let seg = read_dc_csv(path, kind, n as u32).map_err(|e| e.to_string())?;
        claim(seg.index, n)?;
        record.segments.push(seg);
    }
    record.segments.sort_by_key(|s| s.index);
    Ok(record)
}

/// Read a nameplate: a JSON object with the contract's keys.
fn read_nameplate(path: &Path) -> Result<serde_json::Value, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("{}:{}: {e}", path.display(), e.line()))?;
    if !v.is_object() {
        return Err(format!(
            "{}: a nameplate must be a JSON object",
            path.display()
        ));
    }
    Ok(v)
}
