//! End to end through the real driver code: the simulated rig served as
//! Modbus devices (TCP on loopback, RTU on pseudo-terminals), commissioned
//! by the bench over the Modbus client, bus task, power stage and poller;
//! and a pulled cable mid-test.
//!
//! These tests run on the wall clock (a served rig cannot run faster than
//! real time): about 7 s each, one at a time (a shared lock), so that they
//! do not compete for the CPU and disturb each other's sampling.

use crate::common;

use std::path::Path;

use motorbench::bench::{NoProgress, Outcome, RecordSink};
use motorbench::config::{Backend, Config};
use motorbench::machine::dc::{build_rig, plan_steps, record_channels, run_test};
use motorbench::record::EventLevel;
use motorbench::report::IdentificationReport;

/// Held by every wall-clock test: they run one after the other.
static REALTIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

fn config(name: &str) -> Config {
    Config::load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("config")
            .join(name),
    )
    .unwrap()
}

fn param(r: &IdentificationReport, key: &str) -> (f64, f64) {
    let p = &r.methods["steady_state"].params.as_ref().unwrap()[key];
    let [lo, hi] = p.ci95.expect("steady state gives intervals");
    (p.value, (hi - lo) / 2.0)
}

async fn run(cfg: &Config) -> (tempfile::TempDir, motorbench::session::Commissioned) {
    common::dry_run::commission(cfg).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn modbus_tcp_run_matches_the_direct_simulated_rig_within_noise() {
    let _one_at_a_time = REALTIME.lock().await;
    let cfg = config("sim-modbus-dc.toml");
    let sim = cfg.backend.simulated().unwrap().clone();
    let truth = sim.motor;
    let (_dir, served) = run(&cfg).await;
    assert_eq!(served.outcome, Outcome::Completed);

    // The same motor, plan and limits on the in-process rig, polled at the
    // same rate.
    let mut direct_cfg = cfg.clone();
    direct_cfg.backend = Backend::Simulated(sim);
    let (_direct_dir, direct) = run(&direct_cfg).await;
    assert_eq!(direct.outcome, Outcome::Completed);

    let (a, b) = (&served.analysis.report(), &direct.analysis.report());
    // Within noise: the two estimates differ by less than their 95 %
    // intervals together allow; and each is near the truth (a 95 %
    // interval misses the truth in one run of twenty by design, so the
    // truth check uses fixed tolerances instead).
    for (key, t, tol) in [
        ("K", truth.k, 0.01),
        ("Ra", truth.ra, 0.05),
        ("Tst", truth.tst, 0.02),
        ("f", truth.f, 0.10),
    ] {
        let ((va, ha), (vb, hb)) = (param(a, key), param(b, key));
        assert!(
            (va - vb).abs() <= ha + hb,
            "{key}: Modbus {va} ± {ha}, direct {vb} ± {hb}"
        );
        assert!(((va - t) / t).abs() < tol, "{key}: Modbus {va}, truth {t}");
    }

    // The record carries the sampling statistics of every polled channel.
    let stats: Vec<_> = served
        .record
        .events
        .iter()
        .filter(|(_, e)| e.message.starts_with("sampling statistics"))
        .collect();
    assert_eq!(stats.len(), 3, "{:?}", served.record.events);
    for q in ["armature_voltage", "armature_current", "encoder_count"] {
        assert!(stats.iter().any(|(_, e)| e.message.contains(q)), "{q}");
    }
    // They are in the MCAP file too.
    let replayed = motorbench::record::read_mcap(&served.mcap_path).unwrap();
    assert_eq!(replayed.events, served.record.events);
}

#[test]
fn modbus_rtu_run_through_the_cli_identifies_the_motor() {
    let _one_at_a_time = REALTIME.blocking_lock();
    let dir = tempfile::tempdir().unwrap();
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim-modbus-rtu-dc.toml");
    let out = common::motorbench(&[
        "run",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
        "--json",
        "--no-diagnose",
    ]);
    let (stdout, stderr) = common::text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let report: IdentificationReport = serde_json::from_str(&stdout).unwrap();
    let truth = config("sim-modbus-rtu-dc.toml")
        .backend
        .simulated()
        .unwrap()
        .motor;
    for (key, t, tol) in [
        ("K", truth.k, 0.03),
        ("Ra", truth.ra, 0.10),
        ("Tst", truth.tst, 0.03),
    ] {
        let (v, _) = param(&report, key);
        assert!(((v - t) / t).abs() < tol, "{key}: {v}, truth {t}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pulled_sensor_cable_ends_the_test_with_the_stage_commanded_safe() {
    let _one_at_a_time = REALTIME.lock().await;
    let cfg = config("sim-modbus-dc.toml");
    let mut rig = build_rig(&cfg, false).await.unwrap();
    let channels = record_channels(rig.sensors.channels(), rig.stage.id());
    let mut sink = RecordSink::new(None, None, channels);
    let steps = plan_steps(&cfg.plan);
    let (_tx, rx) = tokio::sync::watch::channel(false);
    let mut served = rig.served.take().expect("a served rig");
    let outcome = {
        let test = run_test(
            &cfg,
            &steps,
            rig.stage.as_mut(),
            rig.sensors.as_mut(),
            rig.counts_per_rev,
            &mut sink,
            &NoProgress,
            &rx,
        );
        tokio::pin!(test);
        // Let the test reach its second level with the output on, then pull
        // the DAQ's cable (its server and connection go away).
        tokio::select! {
            o = &mut test => panic!("the test ended before the cable was pulled: {o:?}"),
            _ = tokio::time::sleep(std::time::Duration::from_millis(1500)) => {
                assert!(served.stage_output_enabled(), "the output is on mid-test");
                served.pull_sensor_cable();
                test.await.unwrap()
            }
        }
    };
    let Outcome::Aborted { reason } = outcome else {
        panic!("the test went on without its sensors: {outcome:?}");
    };
    assert!(
        reason.contains("power stage commanded to its safe state"),
        "{reason}"
    );
    assert!(reason.contains("sensor"), "{reason}");
    // The supply really is safe: the plant sees it off at 0 V, and so do
    // its registers.
    assert!(!served.stage_output_enabled());
    assert_eq!(served.stage_setpoint(), 0.0);
    let p = match &cfg.backend {
        Backend::Modbus { rig, .. } => rig.power_stage.profile.clone(),
        _ => unreachable!(),
    };
    assert_eq!(
        served.stage_register(p.register("output_enable").unwrap()),
        0.0
    );
    assert_eq!(
        served.stage_register(p.register("voltage_set").unwrap()),
        0.0
    );
    // And the record says so.
    let (_, record) = sink.into_parts();
    let abort: Vec<_> = record
        .events
        .iter()
        .filter(|(_, e)| e.level == EventLevel::Abort)
        .collect();
    assert_eq!(abort.len(), 1, "{:?}", record.events);
    assert!(
        abort[0].1.message.contains("safe state"),
        "{}",
        abort[0].1.message
    );
}

#[test]
fn probe_reads_every_channel_and_actuates_only_when_asked() {
    let _one_at_a_time = REALTIME.blocking_lock();
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim-modbus-dc.toml");
    let cfg = cfg.to_str().unwrap();
    let value = |stdout: &str, step: &str, quantity: &str| -> f64 {
        let prefix = format!("[{step:>4}] {quantity} ");
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&prefix))
            .unwrap_or_else(|| panic!("no {step} {quantity} in:\n{stdout}"));
        line[prefix.len()..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };

    let out = common::motorbench(&["probe", "--config", cfg]);
    let (stdout, stderr) = common::text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for q in ["armature_voltage", "armature_current", "encoder_count"] {
        value(&stdout, "idle", q);
    }
    assert!(
        !stdout.contains("[cmd ]"),
        "nothing is driven without --actuate:\n{stdout}"
    );

    let out = common::motorbench(&["probe", "--config", cfg, "--actuate"]);
    let (stdout, stderr) = common::text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    // 5 % of the 60 V limit, measured through the served DAQ (12-bit ADC
    // over ±400 V: 0.2 V steps, 0.1 V noise).
    let on = value(&stdout, "on", "armature_voltage");
    assert!((on - 3.0).abs() < 0.6, "{on}\n{stdout}");
    assert!(stdout.contains("[cmd ] safe state: ok"), "{stdout}");
    let safe = value(&stdout, "safe", "armature_voltage");
    assert!(
        safe.abs() < 0.6,
        "the output is off after the probe: {safe}\n{stdout}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn streaming_serial_daq_run_identifies_the_motor() {
    let _one_at_a_time = REALTIME.lock().await;
    let cfg = config("sim-modbus-serial-dc.toml");
    let truth = cfg.backend.simulated().unwrap().motor;
    let (_dir, done) = run(&cfg).await;
    assert_eq!(done.outcome, Outcome::Completed);
    let r = &done.analysis.report();
    // Device timestamps: no host jitter in the intervals, so the steady
    // state is as sharp as on the in-process rig.
    for (key, t, tol) in [
        ("K", truth.k, 0.005),
        ("Ra", truth.ra, 0.02),
        ("Tst", truth.tst, 0.01),
        ("f", truth.f, 0.05),
    ] {
        let (v, _) = param(r, key);
        assert!(((v - t) / t).abs() < tol, "{key}: {v}, truth {t}");
    }
    let sources: Vec<_> = done
        .record
        .events
        .iter()
        .filter(|(_, e)| e.message.starts_with("sampling statistics"))
        .collect();
    assert_eq!(sources.len(), 3);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pulled_stage_cable_is_reported_as_a_failed_safe_state() {
    let _one_at_a_time = REALTIME.lock().await;
    let cfg = config("sim-modbus-dc.toml");
    let mut rig = build_rig(&cfg, false).await.unwrap();
    let channels = record_channels(rig.sensors.channels(), rig.stage.id());
    let mut sink = RecordSink::new(None, None, channels);
    let steps = plan_steps(&cfg.plan);
    let (_tx, rx) = tokio::sync::watch::channel(false);
    let mut served = rig.served.take().expect("a served rig");
    let outcome = {
        let test = run_test(
            &cfg,
            &steps,
            rig.stage.as_mut(),
            rig.sensors.as_mut(),
            rig.counts_per_rev,
            &mut sink,
            &NoProgress,
            &rx,
        );
        tokio::pin!(test);
        tokio::select! {
            o = &mut test => panic!("the test ended before the cable was pulled: {o:?}"),
            _ = tokio::time::sleep(std::time::Duration::from_millis(500)) => {
                served.pull_stage_cable();
                test.await.unwrap()
            }
        }
    };
    // The next set point cannot be delivered: the test stops, and the
    // record says plainly that the safe state could not be commanded (the
    // supply, which has no watchdog, keeps its last set point).
    let Outcome::Aborted { reason } = outcome else {
        panic!("the test went on without its power stage: {outcome:?}");
    };
    assert!(reason.contains("power stage fault"), "{reason}");
    assert!(reason.contains("SAFE-STATE COMMAND FAILED"), "{reason}");
    assert!(served.stage_output_enabled(), "nothing reached the supply");
}
