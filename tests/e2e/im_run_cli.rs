//! `motorbench run --config config/sim-im.toml`: the slip sweep on the
//! simulated rig, recorded, identified, reported; then `replay --check`
//! reproduces the recorded result exactly.

use crate::common;

use common::{motorbench, text};

#[test]
fn run_sim_im_then_replay_gives_the_same_report() {
    let dir = tempfile::tempdir().unwrap();
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-im.toml");
    let out = motorbench(&[
        "run",
        "--config",
        config,
        "--out",
        dir.path().to_str().unwrap(),
        "--json",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["kind"], "im_slip_sweep");
    assert_eq!(v["best"], "lm");
    assert!(v["methods"]["lm"]["validation_nrmse"].as_f64().unwrap() < 0.01);
    // The configured machine's Rs (0.8659 ohm; 0.5 % heating at most).
    let rs = &v["methods"]["lm"]["params"]["Rs"];
    assert!(
        (rs["value"].as_f64().unwrap() / 0.8659 - 1.0).abs() < 0.01,
        "{rs}"
    );

    let mcap: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    assert_eq!(mcap.len(), 1);
    let svg_written = std::fs::read_dir(dir.path())
        .unwrap()
        .any(|e| e.unwrap().path().extension().is_some_and(|e| e == "svg"));
    assert!(svg_written);
    let replay = motorbench(&["replay", mcap[0].to_str().unwrap(), "--check", "--json"]);
    let (rstdout, rstderr) = text(&replay);
    assert!(replay.status.success(), "{rstderr}");
    assert!(
        rstderr.contains("identical to the recorded /bench/result"),
        "{rstderr}"
    );
    let r: serde_json::Value = serde_json::from_str(&rstdout).unwrap();
    assert_eq!(r, v);
}
