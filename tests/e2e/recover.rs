//! `motorbench recover` on records cut as a killed process leaves them:
//! the Python `mcap` package's seeking (indexed) reader refuses the cut
//! file and opens the recovered one, which holds every message the cut
//! file had; motorbench replays the recovered file to the same report as
//! the cut one (the damage warning included); the cut file is kept.

use std::path::Path;
use std::process::Command;

use crate::common;

/// What the Python seeking reader makes of `file`: `None` when it does
/// not open it, else the messages it reads and the `motorbench.recovery`
/// metadata (null when absent).
fn seeking_read(file: &Path) -> Option<(u64, serde_json::Value)> {
    let code = r#"
import json, sys
from mcap.reader import SeekingReader
try:
    with open(sys.argv[1], "rb") as f:
        r = SeekingReader(f)
        if r.get_summary() is None:
            raise ValueError("no summary")
        n = sum(1 for _ in r.iter_messages(log_time_order=False))
        note = None
        for m in r.iter_metadata():
            if m.name == "motorbench.recovery":
                note = dict(m.metadata)
    print(json.dumps({"messages": n, "note": note}))
except Exception as e:
    print(json.dumps({"refused": str(e)}))
"#;
    let out = Command::new(common::python::interpreter())
        .args(["-c", code])
        .arg(file)
        .output()
        .unwrap();
    let (stdout, stderr) = common::text(&out);
    assert!(out.status.success(), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    v.get("refused")
        .is_none()
        .then(|| (v["messages"].as_u64().unwrap(), v["note"].clone()))
}

/// `motorbench replay --json --no-diagnose FILE`: exit code, report.
fn replay(file: &Path) -> (i32, String) {
    let out = common::motorbench(&["replay", "--json", "--no-diagnose", file.to_str().unwrap()]);
    (out.status.code().unwrap(), common::text(&out).0)
}

#[test]
fn a_cut_record_is_finished_for_indexed_readers_and_replays_the_same() {
    let dir = tempfile::tempdir().unwrap();
    // A short test: two levels, no coast-down.
    let config = motorbench::config::DEFAULT_CONFIG
        .replace(
            "levels_V = [60, 248, 60, 154, 248, 107, 201, 60]",
            "levels_V = [60, 248, 60]",
        )
        .replace("coastdown = true ", "coastdown = false ");
    let cfg = dir.path().join("rig.toml");
    std::fs::write(&cfg, &config).unwrap();
    let records = dir.path().join("records");
    let run = common::motorbench(&[
        "run",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        records.to_str().unwrap(),
        "--quiet",
        "--no-diagnose",
    ]);
    assert!(run.status.success(), "{}", common::text(&run).1);
    let whole = common::replay::only_mcap(&records);
    let bytes = std::fs::read(&whole).unwrap();
    let (all, note) = seeking_read(&whole).expect("a finished record opens");
    assert!(note.is_null());

    // A whole record is left as it is.
    let out = common::motorbench(&["recover", whole.to_str().unwrap()]);
    let (stdout, stderr) = common::text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("whole"), "{stdout}");
    assert_eq!(std::fs::read(&whole).unwrap(), bytes);

    // Cut where a kill would: inside the data, the summary gone.
    for share in [0.35, 0.7, 0.97] {
        let cut = dir.path().join(format!("cut-{share}.mcap"));
        let cut_bytes = &bytes[..(bytes.len() as f64 * share) as usize];
        std::fs::write(&cut, cut_bytes).unwrap();
        assert!(
            seeking_read(&cut).is_none(),
            "the seeking reader refuses a cut record"
        );
        let before = replay(&cut);
        assert!(before.0 == 0 || before.0 == 4, "{share}: {before:?}");
        assert!(before.1.contains("the record was damaged"), "{share}");

        let out = common::motorbench(&["recover", cut.to_str().unwrap()]);
        let (stdout, stderr) = common::text(&out);
        assert!(out.status.success(), "{share}: {stderr}");
        assert!(stdout.contains("finished with a summary"), "{stdout}");
        // The cut file is kept, byte for byte.
        let kept = dir.path().join(format!("cut-{share}.mcap.damaged"));
        assert_eq!(std::fs::read(&kept).unwrap(), cut_bytes);

        let (messages, note) = seeking_read(&cut).expect("the recovered record opens");
        assert!(
            messages > 0 && messages < all,
            "{share}: {messages} of {all}"
        );
        assert_eq!(note["messages"], messages.to_string(), "{note}");
        // motorbench reads the copy as it read the cut file.
        assert_eq!(replay(&cut), before, "{share}");
        // Recovering again finds it whole.
        let again = common::motorbench(&["recover", cut.to_str().unwrap()]);
        assert!(common::text(&again).0.contains("whole"));
    }

    // With --out the cut file is not touched.
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let fixed = dir.path().join("fixed.mcap");
    let out = common::motorbench(&[
        "recover",
        cut.to_str().unwrap(),
        "--out",
        fixed.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", common::text(&out).1);
    assert_eq!(std::fs::read(&cut).unwrap(), &bytes[..bytes.len() / 2]);
    assert!(seeking_read(&fixed).is_some());

    // Not a record: refused with exit 2, nothing written.
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").unwrap();
    let out = common::motorbench(&["recover", junk.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(!dir.path().join("junk.mcap.damaged").exists());
}
