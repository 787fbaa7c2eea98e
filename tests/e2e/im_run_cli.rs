//! `motorbench run --config config/sim-im.toml`: the slip sweep on the
//! simulated rig, recorded, identified, reported; then `replay --check`
//! reproduces the recorded result exactly (with and without the
//! diagnosis); and `motorbench probe` checks that rig's wiring.

use crate::common;

use common::replay::{only_mcap, replay_identical, run_json};
use common::{motorbench, probed, text};

#[test]
fn run_sim_im_then_replay_gives_the_same_report() {
    let dir = tempfile::tempdir().unwrap();
    let v = run_json("sim-im.toml", dir.path(), &[]);
    assert_eq!(v["kind"], "im_slip_sweep");
    assert_eq!(v["best"], "lm");
    assert!(v["methods"]["lm"]["validation_nrmse"].as_f64().unwrap() < 0.01);
    // The configured machine's Rs (0.8659 ohm; 0.5 % heating at most).
    let rs = &v["methods"]["lm"]["params"]["Rs"];
    assert!(
        (rs["value"].as_f64().unwrap() / 0.8659 - 1.0).abs() < 0.01,
        "{rs}"
    );

    let mcap = only_mcap(dir.path());
    let svg_written = std::fs::read_dir(dir.path())
        .unwrap()
        .any(|e| e.unwrap().path().extension().is_some_and(|e| e == "svg"));
    assert!(svg_written);
    let r = replay_identical(&mcap, &[]);
    assert_eq!(r, v);
    assert!(v.get("diagnosis").is_some(), "a default run diagnoses");

    // Without the diagnosis the replay still matches the rest of the
    // recorded result.
    let mut r = replay_identical(&mcap, &["--no-diagnose"]);
    assert!(r.get("diagnosis").is_none(), "{r}");
    let mut v = v;
    v.as_object_mut().unwrap().remove("diagnosis");
    r.as_object_mut().unwrap().remove("diagnosis");
    assert_eq!(r, v);
}

#[test]
fn probe_reads_and_exercises_the_simulated_induction_machine_rig() {
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-im.toml");
    let out = motorbench(&["probe", "--config", config]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for q in [
        "line_voltage",
        "line_current",
        "input_power",
        "encoder_count",
    ] {
        probed(&stdout, "idle", q);
    }
    assert!(stdout.contains("supply: ") && stdout.contains("dynamometer: "));
    assert!(!stdout.contains("[cmd ]"), "nothing driven:\n{stdout}");

    let out = motorbench(&["probe", "--config", config, "--actuate"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    // The supply at 5 % of the 440 V limit, its current limit at 10 % of
    // the current limit; then the dynamometer at 5 % of the speed limit.
    for cmd in [
        "[cmd ] supply: set point 22.000: ok",
        "[cmd ] supply: output on: ok",
        "[cmd ] supply: safe state: ok",
        "[cmd ] dynamometer: set point 9.425: ok",
        "[cmd ] dynamometer: safe state: ok",
    ] {
        assert!(stdout.contains(cmd), "{cmd}:\n{stdout}");
    }
    // On: the supply's 22 V (0.5 % noise), then none with the supply safe
    // and the dynamometer on; safe: none.
    let on = probed(&stdout, "on", "line_voltage");
    assert_eq!(on.len(), 2, "{stdout}");
    assert!((on[0] / 22.0 - 1.0).abs() < 0.05, "{on:?}\n{stdout}");
    assert!(on[1].abs() < 1.0, "{on:?}\n{stdout}");
    assert!(probed(&stdout, "safe", "line_voltage")[0].abs() < 1.0);
}
