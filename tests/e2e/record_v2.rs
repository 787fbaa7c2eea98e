//! Contract version 2 (docs/data-contract.md): a new record's `log_time`
//! is the wall clock, its events are `foxglove.Log`; a version 1 record
//! (the checked-in `tests/mcap_corpus/seed.mcap`) still reads and replays
//! to the report its data gives under version 2, bit for bit.

use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use crate::common;

use motorbench::machine::analyse_record;
use motorbench::record::{read_entries, read_mcap, Entry, Recorder};

fn unix_ns_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
}

fn seed_path() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mcap_corpus/seed.mcap")
}

/// `(t_ns, channel, value bits)` of every sample and the other entries as
/// text, so that -0.0 and 0.0 differ.
fn exact(entries: &[Entry]) -> Vec<String> {
    entries
        .iter()
        .map(|e| match e {
            Entry::Samples { t_ns, values } => format!(
                "{t_ns} {:?}",
                values
                    .iter()
                    .map(|(c, v)| (*c, v.to_bits()))
                    .collect::<Vec<_>>()
            ),
            other => format!("{other:?}"),
        })
        .collect()
}

#[test]
fn a_v2_record_s_log_time_is_the_wall_clock_at_its_start() {
    let dir = tempfile::tempdir().unwrap();
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mcap_corpus/seed.toml");
    let before = unix_ns_now();
    let run = common::motorbench(&[
        "run",
        "--config",
        config.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
        "--quiet",
        "--no-diagnose",
    ]);
    let after = unix_ns_now();
    assert!(run.status.success(), "{}", common::text(&run).1);
    let mcap_path = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("run wrote an MCAP");
    let bytes = std::fs::read(&mcap_path).unwrap();

    let mut start_ns = None;
    for r in mcap::read::LinearReader::new(&bytes).unwrap() {
        if let mcap::records::Record::Metadata(m) = r.unwrap() {
            assert_eq!(m.metadata["schema_version"], "2");
            start_ns = Some(m.metadata["start_time_ns"].parse::<u64>().unwrap());
        }
    }
    let start_ns = start_ns.expect("the motorbench.test metadata");
    assert!(
        (before..=after).contains(&start_ns),
        "start {start_ns} not within the run [{before}, {after}]"
    );
    let mut first = u64::MAX;
    let mut events = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        first = first.min(m.log_time);
        if m.channel.topic == "/bench/event" {
            events += 1;
            assert_eq!(m.channel.schema.as_ref().unwrap().name, "foxglove.Log");
        }
    }
    assert!(events > 0, "the run logs at least its start");
    assert!(first >= start_ns, "a message before the start");
    assert!(
        first.abs_diff(before) < 1_000_000_000,
        "first log_time {first} is not within a second of the wall clock {before}"
    );

    // The reader gives times since the start, as identification wants,
    // and an independent reader accepts the file as version 2.
    let record = read_mcap(&mcap_path).unwrap();
    assert!(
        record.segments[0].time[0] < 1.0,
        "{}",
        record.segments[0].time[0]
    );
    common::python_check_mcap(&mcap_path, &[]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_v1_fixture_replays_bit_identically_to_its_v2_copy() {
    // The fixture was written under version 1: log_time from 0.
    let (meta, channels, entries, recovery) = read_entries(&seed_path()).unwrap();
    assert_eq!(meta.schema_version, "1");
    assert!(recovery.is_none());
    let last = entries.iter().map(Entry::t_ns).max().unwrap();
    assert!(last < 10_000_000_000, "times since the start: {last}");

    // The same entries written by this build: version 2, wall clock.
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("seed-v2.mcap");
    let mut meta2 = meta.clone();
    meta2.schema_version = "2".into();
    let recorder = Recorder::start(&copy, &meta2, &channels, 64).unwrap();
    for e in &entries {
        recorder.send(e.clone()).await.unwrap();
    }
    recorder.finish().await.unwrap();
    let (meta_back, channels_back, entries_back, _) = read_entries(&copy).unwrap();
    assert_eq!(meta_back, meta2);
    assert_eq!(channels_back, channels);
    assert_eq!(exact(&entries_back), exact(&entries));

    // Both replay to the same report, to the last digit.
    let v1 = read_mcap(&seed_path()).unwrap();
    let v2 = read_mcap(&copy).unwrap();
    let report =
        |r| serde_json::to_string(analyse_record(r, false).analysis.report()).expect("serialises");
    assert_eq!(report(&v1), report(&v2));

    // The CLI replays the fixture; the Python reader accepts it as v1.
    let replay = common::motorbench(&[
        "replay",
        "--json",
        "--no-diagnose",
        seed_path().to_str().unwrap(),
    ]);
    assert!(replay.status.success(), "{}", common::text(&replay).1);
    let v: serde_json::Value = serde_json::from_slice(&replay.stdout).unwrap();
    assert_eq!(v["kind"], "dc_step");
    let counts = common::python_check_mcap(&seed_path(), &[]);
    assert_eq!(counts["/bench/event"], 1);
}

/// The contract checker can fail: the seed record with five sample
/// payloads forged (a boolean, an extra key, no value, NaN, a string) is
/// refused, each forgery named.
#[test]
fn the_contract_checker_refuses_forged_sample_payloads() {
    let dir = tempfile::tempdir().unwrap();
    let forged = dir.path().join("forged.mcap");
    let script = |name: &str| {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/python")
            .join(name)
    };
    let python = common::python::interpreter();
    let out = std::process::Command::new(python)
        .arg(script("forge_samples.py"))
        .arg(seed_path())
        .arg(&forged)
        .output()
        .unwrap();
    let (_, stderr) = common::text(&out);
    assert!(out.status.success(), "forge_samples.py: {stderr}");
    let out = std::process::Command::new(python)
        .arg(script("check_mcap.py"))
        .arg(&forged)
        .output()
        .unwrap();
    let (_, stderr) = common::text(&out);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    for want in [
        "value True is not a number",
        "keys ['unit', 'value'], want ['value']",
        "keys [], want ['value']",
        "payload is not JSON: NaN is not JSON",
        "value '7' is not a number",
    ] {
        assert!(stderr.contains(want), "{want}: {stderr}");
    }
    // The record it was forged from passes.
    common::python_check_mcap(&seed_path(), &[]);
}
