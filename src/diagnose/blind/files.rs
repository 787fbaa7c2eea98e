//! A blind case on disk: the record as contract CSV files (one per
//! segment, each with its segment declaration; an induction machine's
//! no-load and locked-rotor tests too) and the nameplate, in a directory
//! of its own. The truth never goes there.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::SuiteError;
use crate::record::export::csv::{declaration, supply_test_files};
use crate::record::{Record, SegmentKind};

/// Write `record` into `dir` (created if missing) as CSV files, plus
/// `nameplate.json` when the record has a nameplate. Returns the CSV
/// files and the nameplate path, as `diagnose` takes them.
pub fn write_case_files(
    record: &Record,
    dir: &Path,
) -> Result<(Vec<PathBuf>, Option<PathBuf>), SuiteError> {
    std::fs::create_dir_all(dir).map_err(SuiteError::io(dir))?;
    let write = |name: String, text: String| -> Result<PathBuf, SuiteError> {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(SuiteError::io(&path))?;
        Ok(path)
    };
    let mut files = Vec::new();
    for seg in &record.segments {
        let kind = seg.kind.unwrap_or(SegmentKind::DcStep);
        let mut text = declaration(seg.index, kind, &seg.label);
        text.push_str("time_s,armature_voltage_V,armature_current_A,speed_rad_s\n");
        for k in 0..seg.time.len() {
            let _ = writeln!(
                text,
                "{},{},{},{}",
                seg.time[k], seg.voltage[k], seg.current[k], seg.speed[k]
            );
        }
        files.push(write(format!("segment-{}.csv", seg.index), text)?);
    }
    let mut sweeps: Vec<u32> = record.operating_points.iter().map(|p| p.segment).collect();
    sweeps.dedup();
    sweeps.sort_unstable();
    sweeps.dedup();
    for sweep in sweeps {
        let mut text = declaration(sweep, SegmentKind::ImSlipSweep, &format!("sweep {sweep}"));
        text.push_str("slip,line_voltage_V,line_current_A,input_power_W,frequency_Hz\n");
        for p in record
            .operating_points
            .iter()
            .filter(|p| p.segment == sweep)
        {
            let _ = writeln!(
                text,
                "{},{},{},{},{}",
                p.slip, p.line_voltage, p.line_current, p.input_power, p.frequency
            );
        }
        files.push(write(format!("sweep-{sweep}.csv"), text)?);
    }
    for (kind, file) in
        supply_test_files(&record.standard_tests, |_, kind| kind.as_str().into(), None)
    {
        files.push(write(
            format!("{}-{}.csv", kind.as_str(), file.segment),
            file.text,
        )?);
    }
    let nameplate = match &record.meta {
        Some(meta) if meta.nameplate.is_object() => Some(write(
            "nameplate.json".into(),
            serde_json::to_string_pretty(&meta.nameplate).expect("JSON serialises"),
        )?),
        _ => None,
    };
    Ok((files, nameplate))
}
