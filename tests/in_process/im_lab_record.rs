//! The record a motor lab takes of a small three-phase motor (a 125-point
//! load curve at rated voltage, six locked-rotor points at reduced voltage,
//! a ten-point no-load voltage sweep with the slip not measured), imported
//! as three `im_slip_sweep` CSV segments: identification and diagnosis
//! stay bounded, say what went wrong instead of printing nonsense, and
//! give physical answers only.
//!
//! The CSV set in `tests/data/im_lab/` is written by
//! [`motorbench::model::LabMachine`]; `stored_csv_set_is_the_generators`
//! checks it and rewrites it when `MOTORBENCH_REGENERATE=1` is set.

use std::path::PathBuf;

use motorbench::model::{LabMachine, LabMeters};
use motorbench::record::{load_record_files, Record, SegmentKind};

/// Meter-noise seed of the stored set.
const SEED: u64 = 19;

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/im_lab")
}

fn files() -> Vec<PathBuf> {
    ["no_load.csv", "load.csv", "locked_rotor.csv"]
        .iter()
        .map(|f| data_dir().join(f))
        .collect()
}

fn generated() -> Vec<(String, String)> {
    let m = LabMachine::small_motor();
    m.lab_record(125, 6, 10, &LabMeters::default(), SEED)
        .iter()
        .enumerate()
        .map(|(k, s)| (format!("{}.csv", s.label), s.to_csv(k as u32, m.frequency)))
        .collect()
}

fn lab_record() -> Record {
    load_record_files(SegmentKind::ImSlipSweep, &files(), None, None).expect("the CSV set loads")
}

#[test]
fn stored_csv_set_is_the_generators() {
    let regenerate = std::env::var("MOTORBENCH_REGENERATE").is_ok_and(|v| v == "1");
    for (name, text) in generated() {
        let path = data_dir().join(&name);
        if regenerate {
            std::fs::create_dir_all(data_dir()).unwrap();
            std::fs::write(&path, &text).unwrap();
        }
        let stored = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            stored == text,
            "{} differs from the generator (MOTORBENCH_REGENERATE=1 rewrites it)",
            path.display()
        );
    }
    assert_eq!(lab_record().operating_points.len(), 141);
}
