//! Entry points for fuzzing every parser that reads outside data.
//!
//! Each target takes arbitrary bytes and hands them to one reader of data
//! from outside the program: a contract CSV segment, a nameplate, an MCAP
//! record, a rig configuration, a Modbus device profile, a DBC file, the
//! serial DAQ's ASCII and binary framings, SLCAN lines, and the daemon's
//! start-request body. A target returns normally for any input: a reader
//! may refuse the input, but never panic, hang or hand back a non-finite
//! number, and a refusal names what it read (the file, for file readers).
//! A broken promise panics here, which is what a fuzzer reports.
//!
//! The same functions run two ways: under `cargo fuzz` (the crate in
//! `fuzz/`, one binary per target, for long coverage-guided runs), and in
//! the test suite over the checked-in corpus `fuzz/corpus/<target>/` plus
//! fixed-seed mutations of it (`tests/in_process/fuzz_corpus.rs`), so
//! every CI run exercises every target.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use motorbench_drivers::can::{decode_line, CanFrame, SignalMap, SlcanLine};
use motorbench_drivers::modbus::{DataType, DeviceProfile};
use motorbench_drivers::serial::ascii::{self, AsciiDecoder};
use motorbench_drivers::serial::binary::{self, BinaryDecoder};
use motorbench_drivers::serial::StreamRecord;

use crate::config::TestConfig;
use crate::contract::{unphysical_param, IdentificationReport};
use crate::machine::{analyse, AnalyseOptions};
use crate::model::ImModel;
use crate::record::{load_record_files, read_mcap, ColumnMap, Record, SegmentKind};

/// A fuzz target: arbitrary bytes in, a panic only for a broken promise.
pub type Target = fn(&[u8]);

/// Every target, by the name of its corpus folder and `cargo fuzz` binary.
pub const TARGETS: &[(&str, Target)] = &[
    ("csv_segment", csv_segment),
    ("identify_segment", identify_segment),
    ("nameplate", nameplate),
    ("mcap_record", mcap_record),
    ("rig_config", rig_config),
    ("device_profile", device_profile),
    ("dbc", dbc),
    ("serial_stream", serial_stream),
    ("slcan_line", slcan_line),
    ("start_request", start_request),
];

/// A contract CSV segment, read as each segment kind.
pub fn csv_segment(data: &[u8]) {
    let file = Scratch::write("segment.csv", data);
    for kind in [
        SegmentKind::DcStep,
        SegmentKind::DcCoastdown,
        SegmentKind::ImSlipSweep,
        SegmentKind::ImNoLoad,
        SegmentKind::ImLockedRotor,
        SegmentKind::ImDcResistance,
    ] {
        check_record(
            load_record_files(
                kind,
                std::slice::from_ref(&file.path),
                None,
                Some(50.0),
                &ColumnMap::default(),
            ),
            &file.path,
        );
    }
}

/// A CSV segment that reads, identified as `identify` does (without the
/// diagnosis), as a DC step and as a slip sweep: every parameter reported
/// is finite and in its physical range, every interval and validation
/// NRMSE finite. Segments over [`IDENTIFY_MAX_SAMPLES`] are passed over,
/// to keep a run's inputs many.
pub fn identify_segment(data: &[u8]) {
    let file = Scratch::write("segment.csv", data);
    for kind in [SegmentKind::DcStep, SegmentKind::ImSlipSweep] {
        let Ok(record) = load_record_files(
            kind,
            std::slice::from_ref(&file.path),
            None,
            Some(50.0),
            &ColumnMap::default(),
        ) else {
            continue;
        };
        let samples: usize = record.segments.iter().map(|s| s.time.len()).sum::<usize>()
            + record.operating_points.len();
        if samples > IDENTIFY_MAX_SAMPLES {
            continue;
        }
        let options = AnalyseOptions {
            im_model: Some(ImModel::SingleFe),
            ..AnalyseOptions::default()
        };
        let analysed = analyse(&record, kind, &options, false);
        check_report(analysed.analysis.report());
    }
}

/// Largest segment [`identify_segment`] identifies.
pub const IDENTIFY_MAX_SAMPLES: usize = 2_000;

/// Every number of an identification report is finite and physical.
fn check_report(report: &IdentificationReport) {
    for (name, method) in &report.methods {
        if let Some(params) = &method.params {
            if let Some(why) = unphysical_param(params) {
                panic!("method {name}: {why}");
            }
            for (key, p) in params {
                if let Some([lo, hi]) = p.ci95 {
                    assert!(
                        lo.is_finite() && hi.is_finite(),
                        "{name}.{key}: interval [{lo}, {hi}]"
                    );
                }
            }
        }
        if let Some(v) = method.validation_nrmse {
            assert!(v.is_finite(), "{name}: validation NRMSE {v}");
        }
    }
}

/// A nameplate (JSON) beside a valid slip-sweep segment.
pub fn nameplate(data: &[u8]) {
    let csv = Scratch::write(
        "sweep.csv",
        b"slip,line_voltage_V,line_current_A,input_power_W,frequency_Hz\n\
          0.01,400,2.1,600,50\n0.03,400,3.5,1900,50\n0.05,400,5.2,3100,50\n",
    );
    let plate = Scratch::write("nameplate.json", data);
    check_record(
        load_record_files(
            SegmentKind::ImSlipSweep,
            std::slice::from_ref(&csv.path),
            Some(&plate.path),
            None,
            &ColumnMap::default(),
        ),
        &plate.path,
    );
}

/// An MCAP record, read as `replay` and `identify` read one.
pub fn mcap_record(data: &[u8]) {
    let file = Scratch::write("record.mcap", data);
    check_record(read_mcap(&file.path), &file.path);
}

/// A rig and test configuration (TOML).
pub fn rig_config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Err(e) = TestConfig::parse("fuzz.toml", text) {
        assert_names(&e.to_string(), "fuzz.toml");
    }
}

/// A Modbus device profile (TOML), and every register it declares
/// decoded from words taken from the input.
pub fn device_profile(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match DeviceProfile::parse("fuzz.toml", text) {
        Ok(profile) => {
            let words: Vec<u16> = data
                .chunks(2)
                .map(|c| u16::from_le_bytes([c[0], *c.get(1).unwrap_or(&0)]))
                .chain(std::iter::repeat(0))
                .take(2)
                .collect();
            for register in profile.registers.values() {
                let value = register.decode(&words[..usize::from(register.data_type.width())]);
                // A float register may hold any bit pattern; an integer
                // one scaled by the profile's finite scale is finite.
                assert!(
                    register.data_type == DataType::F32 || value.is_finite(),
                    "register {} decoded to {value}",
                    register.name
                );
            }
        }
        Err(e) => assert_names(&e.to_string(), "fuzz.toml"),
    }
}

/// A DBC file, and every message it declares decoded from the input's
/// first (up to eight) bytes.
pub fn dbc(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match SignalMap::parse("fuzz.dbc", text) {
        Ok(map) => {
            let payload = &data[..data.len().min(8)];
            let ids: Vec<_> = map.message_ids().collect();
            for id in ids {
                let Ok(frame) = CanFrame::new(id, payload) else {
                    continue;
                };
                for signal in map.decode(&frame).unwrap_or_default() {
                    assert!(
                        !signal.value.is_infinite(),
                        "{} decoded to {}",
                        signal.name,
                        signal.value
                    );
                }
            }
        }
        Err(e) => assert_names(&e.to_string(), "fuzz.dbc"),
    }
}

/// The serial DAQ's two framings, fed the input in pieces whose sizes the
/// input's own bytes pick; every record decoded round-trips.
pub fn serial_stream(data: &[u8]) {
    let mut ascii = AsciiDecoder::new();
    let mut binary = BinaryDecoder::new();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut rest = data;
    let mut sizes = data.iter().cycle();
    while !rest.is_empty() {
        let n = (usize::from(*sizes.next().unwrap_or(&1)) % 64 + 1).min(rest.len());
        ascii.feed(&rest[..n], &mut a);
        binary.feed(&rest[..n], &mut b);
        rest = &rest[n..];
    }
    for r in &a {
        check_stream_record(r, Framing::Ascii);
    }
    for r in &b {
        check_stream_record(r, Framing::Binary);
    }
}

/// One SLCAN line (the adapter's reply, up to its `\r`).
pub fn slcan_line(data: &[u8]) {
    if let SlcanLine::Frame(frame, _) = decode_line(data) {
        assert!(
            frame.data().len() <= 8,
            "a classic CAN frame of {:?}",
            frame
        );
    }
}

/// The body of `POST /v1/rigs/{rig}/start`: its `test` object applied to
/// the shipped simulated DC and induction-machine configurations.
pub fn start_request(data: &[u8]) {
    let Ok(body) = serde_json::from_slice::<serde_json::Value>(data) else {
        return;
    };
    let Some(test) = body.get("test").and_then(|t| t.as_object()) else {
        return;
    };
    let dc = crate::config::TestConfig::parse("sim-dc.toml", crate::config::DEFAULT_CONFIG)
        .expect("the embedded configuration parses");
    if let Err(e) = dc.with_test(test) {
        assert_names(&e.to_string(), "sim-dc.toml");
    }
}

/// A record from a reader: refused with the file named, or every sample
/// finite.
fn check_record<E: std::fmt::Display>(result: Result<Record, E>, path: &Path) {
    match result {
        Ok(record) => {
            for seg in &record.segments {
                for v in seg.time.iter().chain(&seg.voltage).chain(&seg.current) {
                    assert!(v.is_finite(), "a non-finite reading {v} accepted");
                }
            }
        }
        Err(e) => {
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            assert_names(&e.to_string(), name);
        }
    }
}

/// A decoded record with finite values encodes to a frame that decodes
/// back to it (a value that is not finite is the sensor layer's to
/// refuse: the framing carries any IEEE 754 value).
fn check_stream_record(r: &StreamRecord, framing: Framing) {
    if r.values.is_empty() || !r.values.iter().all(|(_, v)| v.is_finite()) {
        return;
    }
    let mut again = Vec::new();
    match framing {
        Framing::Ascii => AsciiDecoder::new().feed(&ascii::encode(r), &mut again),
        Framing::Binary => {
            // A fresh decoder waits for a frame boundary before it trusts
            // a byte, as a receiver joining mid-stream must.
            let mut decoder = BinaryDecoder::new();
            decoder.feed(&[0], &mut again);
            decoder.feed(&binary::encode(r), &mut again);
        }
    }
    assert_eq!(
        again.as_slice(),
        std::slice::from_ref(r),
        "a record that does not round-trip"
    );
}

#[derive(Clone, Copy)]
enum Framing {
    Ascii,
    Binary,
}

/// A refusal says what it read.
fn assert_names(message: &str, what: &str) {
    assert!(
        message.contains(what),
        "the error does not name {what:?}: {message}"
    );
}

/// A file holding one input, removed when dropped.
struct Scratch {
    path: PathBuf,
}

impl Scratch {
    fn write(name: &str, data: &[u8]) -> Scratch {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let dir = std::env::temp_dir().join(format!(
            "motorbench-fuzz-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir).expect("a scratch directory");
        let path = dir.join(name);
        let mut f = std::fs::File::create(&path).expect("a scratch file");
        f.write_all(data).expect("the scratch file written");
        Scratch { path }
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if let Some(dir) = self.path.parent() {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}
