//! `motorbench identify --kind dc_step` on CSV files gives the same report
//! as on the MCAP of the same data.

mod common;

use std::fmt::Write;

use motorbench::bench::{commission, CommissionOptions, NoProgress, Outcome};
use motorbench::config::Config;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn csv_files_identify_like_the_mcap_they_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let (_tx, rx) = tokio::sync::watch::channel(false);
    let opts = CommissionOptions {
        out_dir: dir.path().to_path_buf(),
        realtime: false,
        diagnose: false,
    };
    let done = commission(&Config::embedded_default(), &opts, &NoProgress, &rx)
        .await
        .unwrap();
    assert_eq!(done.outcome, Outcome::Completed);

    // One CSV per segment, floats written in full (shortest round-trip)
    // precision, each declaring its index, kind and label.
    let mut files = Vec::new();
    for seg in &done.record.segments {
        let mut text = format!(
            "# motorbench segment {} kind={} label={}\n",
            seg.index,
            seg.kind.unwrap().as_str(),
            seg.label
        );
        text.push_str("time_s,armature_voltage_V,armature_current_A,speed_rad_s\n");
        for k in 0..seg.time.len() {
            writeln!(
                text,
                "{:?},{:?},{:?},{:?}",
                seg.time[k], seg.voltage[k], seg.current[k], seg.speed[k]
            )
            .unwrap();
        }
        let path = dir.path().join(format!("segment-{}.csv", seg.index));
        std::fs::write(&path, text).unwrap();
        files.push(path.to_str().unwrap().to_string());
    }

    let mcap = done.mcap_path.to_str().unwrap();
    let from_mcap = common::motorbench(&["identify", "--kind", "dc_step", "--json", mcap]);
    let (mcap_json, stderr) = common::text(&from_mcap);
    assert!(from_mcap.status.success(), "{stderr}");
    let mut args = vec!["identify", "--kind", "dc_step", "--json"];
    args.extend(files.iter().map(String::as_str));
    let from_csv = common::motorbench(&args);
    let (csv_json, stderr) = common::text(&from_csv);
    assert!(from_csv.status.success(), "{stderr}");

    // The same report to the last digit, with every method in it.
    assert_eq!(csv_json, mcap_json);
    let v: serde_json::Value = serde_json::from_str(&csv_json).unwrap();
    for method in ["steady_state", "pasek", "moments", "coastdown"] {
        assert!(v["methods"].get(method).is_some(), "{method} missing");
    }
    assert_eq!(v["methods"]["moments"]["applies"], true);
}
