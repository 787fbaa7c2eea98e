//! Load a record from the files a user names on the command line: one
//! MCAP file, or any number of CSV files (one segment each) with an
//! optional nameplate (JSON). Shared by `identify`, `diagnose` and the
//! blind benchmark's scorer.

use std::path::{Path, PathBuf};

use super::{
    im_file_kind, read_dc_csv, read_dc_resistance_csv, read_im_csv, read_mcap,
    read_supply_test_csv, ColumnMap, LoadError, Record, SegmentKind, TestMeta, SCHEMA_VERSION,
};

/// Read `files` as a record of `kind`. An IM record (any IM kind) reads
/// each file as the kind it declares, else `kind`: the slip sweep and the
/// standard tests (DC resistance, no load, locked rotor) may be mixed. It
/// takes its supply frequency from `frequency`, else the nameplate's
/// `frequency_Hz`, and its pole pairs from the nameplate's `poles`. Errors name the file (and
/// line and field where there is one). `columns` reads CSV header cells of
/// other names as the contract's columns.
pub fn load_record_files(
    kind: SegmentKind,
    files: &[PathBuf],
    nameplate: Option<&Path>,
    frequency: Option<f64>,
    columns: &ColumnMap,
) -> Result<Record, LoadError> {
    let plate = nameplate.map(read_nameplate).transpose()?;
    let is_mcap = |p: &PathBuf| {
        p.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
    };
    match files.iter().filter(|p| is_mcap(p)).count() {
        0 => {}
        1 if files.len() == 1 => return Ok(read_mcap(&files[0])?),
        _ => return Err(LoadError::MixedFiles),
    }
    let mut record = Record::default();
    let mut seen: Vec<(u32, usize)> = Vec::new();
    let mut claim = |index: u32, n: usize| -> Result<(), LoadError> {
        if let Some((_, other)) = seen.iter().find(|(i, _)| *i == index) {
            return Err(LoadError::DuplicateSegment {
                path: files[n].clone(),
                index,
                other: files[*other].clone(),
            });
        }
        seen.push((index, n));
        Ok(())
    };
    if kind.is_im() {
        let number = |key: &str| {
            plate
                .as_ref()
                .and_then(|p| p.get(key))
                .and_then(|v| v.as_f64())
        };
        let frequency = frequency.or_else(|| number("frequency_Hz"));
        let pole_pairs = number("poles").map(|p| (p / 2.0).round() as u32);
        for (n, path) in files.iter().enumerate() {
            let tests = &mut record.standard_tests;
            match im_file_kind(path, kind)? {
                SegmentKind::ImDcResistance => {
                    let seg = read_dc_resistance_csv(path, n as u32, columns)?;
                    claim(seg.index, n)?;
                    tests.dc_resistance.extend(seg.readings);
                }
                k @ (SegmentKind::ImNoLoad | SegmentKind::ImLockedRotor) => {
                    let seg = read_supply_test_csv(path, k, n as u32, frequency, columns)?;
                    claim(seg.index, n)?;
                    if k == SegmentKind::ImNoLoad {
                        tests.no_load.extend(seg.readings);
                    } else {
                        tests.locked_rotor.extend(seg.readings);
                    }
                }
                _ => {
                    let seg = read_im_csv(path, n as u32, frequency, pole_pairs, columns)?;
                    claim(seg.index, n)?;
                    record.operating_points.extend(seg.points);
                }
            }
        }
    } else {
        for (n, path) in files.iter().enumerate() {
            let seg = read_dc_csv(path, kind, n as u32, columns)?;
            claim(seg.index, n)?;
            record.segments.push(seg);
        }
        record.segments.sort_by_key(|s| s.index);
    }
    // The nameplate goes with the record either way: the IM reduction
    // takes its rating from it, the DC identification checks its K
    // against it.
    record.meta = plate.map(|nameplate| TestMeta {
        schema_version: SCHEMA_VERSION.to_string(),
        kind,
        motor_id: String::new(),
        started_at: String::new(),
        nameplate,
        config: String::new(),
    });
    Ok(record)
}

/// Read a nameplate: a JSON object with the contract's keys.
fn read_nameplate(path: &Path) -> Result<serde_json::Value, LoadError> {
    let text = std::fs::read_to_string(path).map_err(|source| LoadError::NameplateIo {
        path: path.to_path_buf(),
        source,
    })?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|source| LoadError::NameplateJson {
            path: path.to_path_buf(),
            source,
        })?;
    if !v.is_object() {
        return Err(LoadError::NameplateNotObject {
            path: path.to_path_buf(),
        });
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::RecordError;

    #[test]
    fn a_caller_tells_a_bad_choice_of_files_from_a_file_that_does_not_read() {
        let dir = tempfile::tempdir().unwrap();
        let mcap = dir.path().join("a.mcap");
        let csv = dir.path().join("b.csv");
        let e = load_record_files(
            SegmentKind::DcStep,
            &[mcap, csv.clone()],
            None,
            None,
            &ColumnMap::default(),
        )
        .unwrap_err();
        assert!(matches!(e, LoadError::MixedFiles), "{e:?}");
        assert_eq!(
            e.to_string(),
            "give either one MCAP file or any number of CSV files"
        );
        let e = load_record_files(
            SegmentKind::DcStep,
            std::slice::from_ref(&csv),
            None,
            None,
            &ColumnMap::default(),
        )
        .unwrap_err();
        assert!(
            matches!(&e, LoadError::Record(RecordError::Io { .. })),
            "{e:?}"
        );
        assert!(e.to_string().starts_with(&format!("{}: ", csv.display())));
        let plate = dir.path().join("plate.json");
        std::fs::write(&plate, "[1]").unwrap();
        let e = load_record_files(
            SegmentKind::DcStep,
            &[csv],
            Some(&plate),
            None,
            &ColumnMap::default(),
        )
        .unwrap_err();
        assert!(matches!(e, LoadError::NameplateNotObject { .. }), "{e:?}");
    }
}
