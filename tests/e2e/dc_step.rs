//! End to end on the simulated rig: the embedded default DC step test,
//! recorded to MCAP, read by the Python `mcap` reader, identified, and
//! replayed to the same result.

use crate::common;

use motorbench::bench::Outcome;
use motorbench::config::Config;
use motorbench::identify::identify_dc;
use motorbench::record::{read_mcap, EventLevel, SegmentKind, SupplyLimitKind};

fn param(report: &motorbench::report::IdentificationReport, key: &str) -> f64 {
    report.methods["steady_state"].params.as_ref().unwrap()[key].value
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn default_run_identifies_the_seed_motor_and_replays_identically() {
    let cfg = Config::embedded_default();
    let sim = cfg.backend.simulated().expect("a simulated rig");
    let truth = sim.motor;
    let (_dir, done) = common::dry_run::commission(&cfg).await;
    assert_eq!(done.outcome, Outcome::Completed);

    // The acceptance: K within 1 %, Ra within 3 %.
    let r = &done.analysis.report();
    let (k, ra) = (param(r, "K"), param(r, "Ra"));
    assert!(((k - truth.k) / truth.k).abs() < 0.01, "K = {k}");
    assert!(((ra - truth.ra) / truth.ra).abs() < 0.03, "Ra = {ra}");
    // Viscous friction and static torque too, within 5 %.
    assert!(((param(r, "f") - truth.f) / truth.f).abs() < 0.05);
    assert!(((param(r, "Tst") - truth.tst) / truth.tst).abs() < 0.05);
    // Every interval given covers the truth.
    for (key, t) in [
        ("K", truth.k),
        ("Ra", truth.ra),
        ("f", truth.f),
        ("Tst", truth.tst),
    ] {
        let p = &r.methods["steady_state"].params.as_ref().unwrap()[key];
        let [lo, hi] = p.ci95.unwrap();
        assert!(lo <= t && t <= hi, "{key}: {t} outside [{lo}, {hi}]");
    }

    // The output-error fit covers all six parameters, the truth inside
    // each interval, and validates best on held-out segments.
    let oe = r.methods["output_error"].params.as_ref().unwrap();
    for (key, t) in [
        ("Ra", truth.ra),
        ("La", truth.la),
        ("K", truth.k),
        ("J", truth.j),
        ("f", truth.f),
        ("Tst", truth.tst),
    ] {
        let [lo, hi] = oe[key].ci95.unwrap();
        assert!(
            lo <= t && t <= hi,
            "output_error {key}: {t} outside [{lo}, {hi}]"
        );
    }
    assert_eq!(r.best.as_deref(), Some("output_error"));

    // Segments: every level of the staircase plus the coast-down.
    let kinds: Vec<_> = done.record.segments.iter().map(|s| s.kind).collect();
    assert_eq!(kinds.len(), 9);
    assert_eq!(kinds[8], Some(SegmentKind::DcCoastdown));
    let coast = &done.record.segments[8];
    // Its first sample is the boundary reading (the last one at the level).
    assert!(
        coast.current[1..].iter().all(|i| i.abs() < 0.02),
        "open armature carries no current"
    );
    assert_eq!(
        *coast.speed.last().unwrap(),
        0.0,
        "the coast-down runs to rest"
    );

    // The file replays to the same record and the same identification.
    let replayed = read_mcap(&done.mcap_path).unwrap();
    assert!(replayed.recovery.is_none());
    assert_eq!(
        replayed.segments, done.record.segments,
        "replay sees exactly the samples the bench saw"
    );
    let again = identify_dc(&replayed);
    let mut live = done.analysis.report().clone();
    let provenance = live
        .provenance
        .take()
        .expect("a run's report says where it came from");
    assert_eq!(again.report, live);
    // Where it came from: the motor, the start, the record and every file
    // written beside it, the version.
    assert_eq!(provenance.motor_id, cfg.common.motor_id);
    let meta = replayed.meta.as_ref().unwrap();
    assert_eq!(provenance.started_at, meta.started_at);
    let dir = done.mcap_path.parent().unwrap();
    assert_eq!(
        dir.join(&provenance.record),
        done.mcap_path,
        "the record's file name"
    );
    let mut written: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| *n != provenance.record)
        .collect();
    written.sort();
    let mut named = provenance.files.clone();
    named.sort();
    assert_eq!(
        named, written,
        "every file written is named, and only those"
    );
    assert_eq!(provenance.motorbench_version, env!("CARGO_PKG_VERSION"));
    let recorded = replayed
        .recorded_result
        .expect("the report is in the record");
    assert_eq!(
        recorded,
        serde_json::to_value(done.analysis.report()).unwrap()
    );

    // Nothing was dropped: one message per sample per channel.
    let samples = done
        .record
        .segments
        .iter()
        .map(|s| s.time.len())
        .sum::<usize>();
    assert!(samples > 10_000);
    assert_eq!(done.stats.per_topic["/bench/segment"], 18);
    assert_eq!(done.stats.per_topic["/bench/result"], 1);
    let sensor = done.stats.per_topic["/sensor/armature_current"];
    assert_eq!(done.stats.per_topic["/sensor/armature_voltage"], sensor);
    assert_eq!(done.stats.per_topic["/sensor/encoder_count"], sensor);
    assert_eq!(
        done.stats.per_topic["/sensor/speed"],
        sensor - 1,
        "speed starts at the second encoder reading"
    );

    // The Python reader accepts the file and counts the same messages.
    let expect: Vec<String> = done
        .stats
        .per_topic
        .iter()
        .map(|(t, n)| format!("{t}={n}"))
        .collect();
    let counts = common::python_check_mcap(&done.mcap_path, &expect);
    assert_eq!(counts["/sensor/armature_current"], sensor);

    // The report files exist and hold what was printed.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&done.files.report).unwrap()).unwrap();
    assert_eq!(json, recorded);
    let svg = std::fs::read_to_string(&done.files.svg).unwrap();
    assert!(
        svg.contains("<svg")
            && svg.contains("segment 1: 60 V → 248 V")
            && svg.contains("steady_state")
    );
}

#[test]
fn cli_run_then_replay_prints_the_same_json_to_the_last_digit() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    // `run` and `replay` both diagnose the record (dozens of model fits;
    // the test profile optimises motorbench's own crates, see Cargo.toml).
    let run = common::motorbench(&["run", "--out", out, "--json", "--quiet"]);
    let (run_json, stderr) = common::text(&run);
    assert!(run.status.success(), "{stderr}");
    let mcap = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("run wrote an MCAP");
    let replay = common::motorbench(&["replay", "--json", "--check", mcap.to_str().unwrap()]);
    let (replay_json, stderr) = common::text(&replay);
    assert!(replay.status.success(), "{stderr}");
    assert!(stderr.contains("identical to the recorded"), "{stderr}");
    assert_eq!(run_json, replay_json);
    // Without the diagnosis: the rest of the recorded result still matches.
    let replay = common::motorbench(&[
        "replay",
        "--json",
        "--check",
        "--no-diagnose",
        mcap.to_str().unwrap(),
    ]);
    let (_, stderr) = common::text(&replay);
    assert!(replay.status.success(), "{stderr}");
    assert!(stderr.contains("identical to the recorded"), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&run_json).unwrap();
    assert_eq!(v["schema_version"], "2");
    // The seed motor has complex poles: Pasek does not apply; the full
    // model fitted to every step validates best.
    assert_eq!(v["methods"]["pasek"]["applies"], false);
    assert_eq!(
        v["best"], "output_error",
        "the fit with the lowest validation NRMSE"
    );
    // The diagnosis rides in the same report, replayed to the last digit
    // too; the simulated rig has no unmodelled effect.
    assert_eq!(v["diagnosis"]["kind"], "dc_step", "{run_json}");
    assert_eq!(v["diagnosis"]["verdict"]["effect"], "none", "{run_json}");
}

#[test]
fn cli_text_report_shows_the_truth_beside_the_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let run = common::motorbench(&["run", "--out", dir.path().to_str().unwrap(), "--quiet"]);
    let (stdout, stderr) = common::text(&run);
    assert!(run.status.success(), "{stderr}");
    assert!(stdout.contains("method steady_state"), "{stdout}");
    assert!(stdout.contains("sim-to-real diagnosis"), "{stdout}");
    assert!(stdout.contains("gap:    "), "{stdout}");
    assert!(stdout.contains("simulated 1.32300"), "{stdout}");
    assert!(stdout.contains("record: "), "{stdout}");
}

#[test]
fn a_supply_current_limit_below_the_steps_peak_is_recorded_reported_and_named() {
    // The 60 V → 248 V step peaks at about 4.1 A. With `max_current_A` 2
    // (0.5) the supply is set to 1.8 A (0.45 A) and holds the step's
    // current there: the record, the report and identification say so.
    for (limit, spoiled) in [("2", vec![1u32]), ("0.5", vec![0, 1])] {
        let dir = tempfile::tempdir().unwrap();
        let config = motorbench::config::DEFAULT_CONFIG
            .replace("max_current_A = 6 ", &format!("max_current_A = {limit} "))
            .replace(
                "levels_V = [60, 248, 60, 154, 248, 107, 201, 60]",
                "levels_V = [60, 248]",
            )
            .replace("coastdown = true ", "coastdown = false ");
        let path = dir.path().join("rig.toml");
        std::fs::write(&path, &config).unwrap();
        let out = dir.path().join("records");
        let run = common::motorbench(&[
            "run",
            "--config",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--json",
            "--quiet",
            "--no-diagnose",
        ]);
        let (json, stderr) = common::text(&run);
        assert!(run.status.success(), "{stderr}");
        let report: serde_json::Value = serde_json::from_str(&json).unwrap();

        // The record: one /bench/supply_limit stretch and one warning per
        // limited segment.
        let mcap = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|e| e == "mcap"))
            .expect("run wrote an MCAP");
        let rec = read_mcap(&mcap).unwrap();
        let segments: Vec<u32> = rec.supply_limits.iter().map(|l| l.segment).collect();
        assert_eq!(
            segments, spoiled,
            "limit {limit} A: {:?}",
            rec.supply_limits
        );
        let set = 0.9 * limit.parse::<f64>().unwrap();
        for l in &rec.supply_limits {
            assert_eq!(l.kind, SupplyLimitKind::CurrentLimit);
            assert_eq!(l.current_limit, Some(set));
            assert!(l.to > l.from && (l.peak_current - set).abs() < 0.02 * set + 0.01);
            // The supply lowered its voltage to hold the current.
            assert!(l.measured_voltage < 0.9 * l.commanded_voltage, "{l:?}");
            let said = format!("current-limiting (held at its {set:.3} A limit");
            assert!(
                rec.events.iter().any(|(_, e)| e.level == EventLevel::Warn
                    && e.message.contains(&said)
                    && e.message.contains(&format!("in segment {}", l.segment))),
                "{:?}",
                rec.events
            );
        }

        // The report names each segment; the step fits leave them out.
        let warnings = report["warnings"].as_array().unwrap();
        for s in &spoiled {
            assert!(
                warnings.iter().any(|w| {
                    let w = w.as_str().unwrap();
                    w.contains("current-limiting") && w.contains(&format!("in segment {s} "))
                }),
                "limit {limit} A: {warnings:?}"
            );
        }
        for method in ["pasek", "moments"] {
            assert_eq!(report["methods"][method]["applies"], false, "{method}");
        }
        // The fit driven by the measured voltage is not misled.
        let best = report["best"].as_str().unwrap();
        let ra = report["methods"][best]["params"]["Ra"]["value"]
            .as_f64()
            .unwrap();
        assert!(
            (ra / 30.9 - 1.0).abs() < 0.05,
            "limit {limit} A: {best} Ra {ra}"
        );
        // A replay reads the stretches back and gives the same report.
        let replay = common::motorbench(&[
            "replay",
            "--json",
            "--check",
            "--no-diagnose",
            mcap.to_str().unwrap(),
        ]);
        let (replayed, stderr) = common::text(&replay);
        assert!(replay.status.success(), "{stderr}");
        assert_eq!(replayed, json);
    }
}

#[test]
fn sigint_during_run_aborts_through_the_supervisor_and_keeps_the_record() {
    // Paced at the wall clock, the default test runs for several seconds:
    // SIGINT one second in is an operator abort through the supervisor
    // (exit code 3), the stage is commanded safe, and the record is
    // finished and replays up to the stop.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("records");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_motorbench"))
        .args(["run", "--realtime", "--quiet", "--no-diagnose", "--out"])
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(1));
    let kill = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let done = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert_eq!(done.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("stopped by the safety supervisor: operator abort"),
        "{stderr}"
    );
    let mcap = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("the record is written");
    let record = read_mcap(&mcap).unwrap();
    assert!(record
        .events
        .iter()
        .any(|(_, e)| e.message.starts_with("safety supervisor: operator abort")));
    let t_end = record
        .segments
        .iter()
        .filter_map(|s| s.time.last())
        .fold(0.0_f64, |a, &b| a.max(b));
    assert!(t_end > 0.0 && t_end < 5.0, "recorded up to {t_end} s");
}
