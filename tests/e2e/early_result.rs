//! The identification is in the record before the diagnosis runs: a run
//! records it as a first `/bench/result` (marked `diagnosis_pending`) as
//! soon as it exists, then the whole report as the last one. Readers take
//! the last; a record whose run died during the diagnosis (its last result
//! the pending one) replays and checks against its identification.

use crate::common;

use motorbench::record::{read_entries, read_mcap, Entry, Recorder};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_identification_is_recorded_before_the_diagnosis_and_replays_alone() {
    let dir = tempfile::tempdir().unwrap();
    let run = common::motorbench(&[
        "run",
        "--out",
        dir.path().to_str().unwrap(),
        "--json",
        "--quiet",
    ]);
    let (stdout, stderr) = common::text(&run);
    assert!(run.status.success(), "{stderr}");
    let printed: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let mcap = common::replay::only_mcap(dir.path());

    // Two results: the identification first, then the whole report.
    let (meta, channels, entries, recovery) = read_entries(&mcap).unwrap();
    assert!(recovery.is_none());
    let results: Vec<(usize, &serde_json::Value)> = entries
        .iter()
        .enumerate()
        .filter_map(|(i, e)| match e {
            Entry::Result { report, .. } => Some((i, report)),
            _ => None,
        })
        .collect();
    assert_eq!(results.len(), 2, "{results:?}");
    let (first_at, first) = results[0];
    let (_, last) = results[1];
    assert_eq!(first["diagnosis_pending"], true);
    assert!(first.get("diagnosis").is_none(), "{first}");
    assert_eq!(
        first["provenance"]["files"],
        serde_json::json!([]),
        "no file is written with the identification alone"
    );
    assert_eq!(first["methods"], last["methods"]);
    assert_eq!(first["best"], last["best"]);
    assert_eq!(*last, printed, "the last result is the report printed");
    assert!(last.get("diagnosis_pending").is_none(), "{last}");
    assert!(last.get("diagnosis").is_some(), "{last}");
    // The reader takes the last. (That a replay reproduces it, the
    // printed report, to the last digit is
    // `dc_step::cli_run_then_replay_prints_the_same_json_to_the_last_digit`,
    // on the same default run: not diagnosed a third time here.)
    let record = read_mcap(&mcap).unwrap();
    assert_eq!(record.recorded_result.as_ref(), Some(last));

    // The record as a run killed during its diagnosis leaves it: every
    // entry up to the identification, not the whole report.
    let cut = dir.path().join("killed-in-diagnosis.mcap");
    let recorder = Recorder::start(&cut, &meta, &channels, 64).unwrap();
    for e in &entries[..=first_at] {
        recorder.send(e.clone()).await.unwrap();
    }
    recorder.finish().await.unwrap();
    assert_eq!(
        read_mcap(&cut).unwrap().recorded_result.as_ref(),
        Some(first)
    );
    for extra in [&[][..], &["--no-diagnose"][..]] {
        let mut args = vec!["replay", cut.to_str().unwrap(), "--check", "--json"];
        args.extend(extra);
        let out = common::motorbench(&args);
        let (stdout, stderr) = common::text(&out);
        assert!(out.status.success(), "{extra:?}: {stderr}");
        assert!(
            stderr.contains("identical to the recorded /bench/result (the identification;"),
            "{extra:?}: {stderr}"
        );
        let replayed: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(replayed["methods"], first["methods"]);
    }
}
