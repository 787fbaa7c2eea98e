//! End to end through several links at once: the simulated rig's supply
//! behind Modbus TCP, its armature voltage and current streaming over a
//! serial pseudo-terminal, and its speed and position from the simulated
//! CANopen (CiA 406) encoder over SLCAN on another pseudo-terminal, merged
//! into one sample stream (`config/sim-modbus-can-dc.toml`): the full DC
//! test against the direct simulated rig, `probe` over every link, and a
//! pulled CAN cable mid-test; and a Modbus DAQ whose channels are polled
//! at their own configured rates.
//!
//! These tests run on the wall clock, one at a time (a shared lock).

use crate::common;

use std::path::Path;

use motorbench::bench::{NoProgress, Outcome, RecordSink};
use motorbench::config::{Backend, Config};
use motorbench::machine::dc::{build_rig, plan_steps, record_channels, run_test};
use motorbench::report::IdentificationReport;
use motorbench::session::Commissioned;

static REALTIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

fn config_path(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name)
}

fn param(r: &IdentificationReport, key: &str) -> (f64, f64) {
    let p = &r.methods["steady_state"].params.as_ref().unwrap()[key];
    let [lo, hi] = p.ci95.expect("steady state gives intervals");
    (p.value, (hi - lo) / 2.0)
}

async fn run(cfg: &Config) -> (tempfile::TempDir, Commissioned) {
    common::dry_run::commission(cfg).await
}

/// The final statistics event of `quantity`.
fn stats_of<'a>(done: &'a Commissioned, quantity: &str) -> &'a str {
    let prefix = format!("sampling statistics, {quantity}: ");
    done.record
        .events
        .iter()
        .map(|(_, e)| e.message.as_str())
        .find(|m| m.starts_with(&prefix))
        .unwrap_or_else(|| panic!("no statistics for {quantity}: {:?}", done.record.events))
}

/// The number of readings a statistics event says were received.
fn received(stats: &str) -> u64 {
    let after = stats.split(": ").nth(1).unwrap();
    after.split(' ').next().unwrap().parse().unwrap()
}

/// Runs `cfg` on its served rig and on the in-process rig with the same
/// motor, plan and limits; both estimates agree within their intervals
/// and lie near the truth.
async fn matches_the_direct_rig(cfg: &Config) -> Commissioned {
    let sim = cfg.backend.simulated().unwrap().clone();
    let truth = sim.motor;
    let (dir, served) = run(cfg).await;
    assert_eq!(
        served.outcome,
        Outcome::Completed,
        "{:?}",
        served.record.events
    );
    let mut direct_cfg = cfg.clone();
    direct_cfg.backend = Backend::Simulated(sim);
    let (_direct_dir, direct) = run(&direct_cfg).await;
    assert_eq!(direct.outcome, Outcome::Completed);
    let (a, b) = (&served.analysis.report(), &direct.analysis.report());
    for (key, t, tol) in [("K", truth.k, 0.01), ("Ra", truth.ra, 0.05)] {
        let ((va, ha), (vb, hb)) = (param(a, key), param(b, key));
        eprintln!("{key}: served {va:.5} ± {ha:.5}, direct {vb:.5} ± {hb:.5}, truth {t}");
        assert!(
            (va - vb).abs() <= ha + hb,
            "{key}: served {va} ± {ha}, direct {vb} ± {hb}"
        );
        // Near the truth: within a fixed tolerance, or within 1.5 times
        // the 95 % half-width (about 3 σ) where a slow channel leaves
        // fewer readings per level and so a wider interval.
        assert!(
            (va - t).abs() < (tol * t).max(1.5 * ha),
            "{key}: served {va} ± {ha}, truth {t}"
        );
    }
    // The statistics are in the MCAP file too.
    let replayed = motorbench::record::read_mcap(&served.mcap_path).unwrap();
    assert_eq!(replayed.events, served.record.events);
    drop(dir);
    served
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn modbus_supply_serial_daq_and_can_encoder_identify_the_motor() {
    let _one_at_a_time = REALTIME.lock().await;
    let cfg = Config::load(&config_path("sim-modbus-can-dc.toml")).unwrap();
    let Backend::Modbus { rig, .. } = &cfg.backend else {
        panic!("a modbus backend")
    };
    assert!(rig.can.is_some(), "the config selects the CAN encoder");
    let served = matches_the_direct_rig(&cfg).await;

    // Each channel kept its own source and configured rate.
    let encoder = stats_of(&served, "encoder_count");
    assert!(encoder.contains("(nominal 2.000 ms)"), "{encoder}");
    let current = stats_of(&served, "armature_current");
    assert!(current.contains("(nominal 1.000 ms)"), "{current}");
    // Both links delivered throughout the test (several seconds).
    assert!(received(encoder) > 1000, "{encoder}");
    assert!(received(current) > 1000, "{current}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn modbus_channels_are_polled_at_their_configured_rates() {
    let _one_at_a_time = REALTIME.lock().await;
    let path = config_path("sim-modbus-dc.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let line = "channels = { armature_voltage = \"armature_voltage\", armature_current = \"armature_current\", encoder_count = \"encoder_count\" }";
    assert!(text.contains(line), "the shipped config changed");
    let text = text.replace(
        line,
        "channels = { armature_voltage = { register = \"armature_voltage\", rate_Hz = 100 }, armature_current = \"armature_current\", encoder_count = \"encoder_count\" }",
    );
    let cfg = Config::parse(&path.display().to_string(), &text).unwrap();
    let served = matches_the_direct_rig(&cfg).await;

    let voltage = stats_of(&served, "armature_voltage");
    assert!(voltage.contains("(nominal 10.000 ms)"), "{voltage}");
    let current = stats_of(&served, "armature_current");
    assert!(current.contains("(nominal 5.000 ms)"), "{current}");
    // Polled at half the current's rate: about half the readings.
    assert!(
        3 * received(voltage) < 2 * received(current),
        "{voltage}\n{current}"
    );
}

#[test]
fn probe_reads_every_channel_of_every_link() {
    let _one_at_a_time = REALTIME.blocking_lock();
    let cfg = config_path("sim-modbus-can-dc.toml");
    let out = common::motorbench(&["probe", "--config", cfg.to_str().unwrap()]);
    let (stdout, stderr) = common::text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for (q, source) in [
        ("armature_voltage", "(serial:"),
        ("armature_current", "(serial:"),
        ("encoder_count", "(slcan:"),
    ] {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&format!("[idle] {q} ")))
            .unwrap_or_else(|| panic!("no {q} in:\n{stdout}"));
        assert!(!line.contains("FAILED"), "{line}");
        assert!(line.contains(source), "{line}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pulled_can_cable_ends_the_test_with_the_stage_commanded_safe() {
    let _one_at_a_time = REALTIME.lock().await;
    let cfg = Config::load(&config_path("sim-modbus-can-dc.toml")).unwrap();
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
        // Mid-test, with the output on, the encoder's adapter goes away;
        // the serial DAQ goes on streaming.
        tokio::select! {
            o = &mut test => panic!("the test ended before the cable was pulled: {o:?}"),
            _ = tokio::time::sleep(std::time::Duration::from_millis(1500)) => {
                assert!(served.stage_output_enabled(), "the output is on mid-test");
                served.pull_can_cable();
                test.await.unwrap()
            }
        }
    };
    let Outcome::Aborted { reason } = outcome else {
        panic!("the test went on without its encoder: {outcome:?}");
    };
    assert!(
        reason.contains("power stage commanded to its safe state"),
        "{reason}"
    );
    assert!(reason.contains("sensor fault"), "{reason}");
    assert!(!served.stage_output_enabled());
    assert_eq!(served.stage_setpoint(), 0.0);
    eprintln!("abort reason: {reason}");
}
