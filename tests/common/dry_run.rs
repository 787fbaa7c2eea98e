//! Dry runs: a configuration's test on its rig (simulated, or simulated
//! behind its protocols), not paced at the wall clock, to a record. The
//! one place the tests turn a configuration into a record, so a change to
//! how a test is run is made here and not in every test file.
//!
//! - [`commission`] goes the way `motorbench run` goes (the one session:
//!   rig, sequencer, recorder, identification, report files) into a
//!   fresh temporary directory, without the diagnosis;
//! - [`record`] runs a DC configuration's plan on its simulated rig to an
//!   in-memory record only (no files, no identification), for tests that
//!   run many motors.

use motorbench::bench::{NoProgress, Outcome, RecordSink};
use motorbench::config::{Backend, Config};
use motorbench::machine::dc::{plan_steps, record_channels, run_test, sim_rig};
use motorbench::machine::Machine;
use motorbench::record::Record;
use motorbench::session::{CommissionOptions, Commissioned};
use motorbench_drivers::{PowerStage, SensorStream};
use tempfile::TempDir;

/// Options for a dry run into `dir`: not paced, not diagnosed.
fn options(dir: &TempDir) -> CommissionOptions {
    CommissionOptions {
        out_dir: dir.path().to_path_buf(),
        realtime: false,
        diagnose: false,
    }
}

/// Commission `machine`'s test (a [`Config`] or a
/// [`motorbench::machine::im::ImRunConfig`]) into
/// a fresh temporary directory, kept alive by the returned handle; the
/// outcome is the caller's to check.
pub async fn commission<M: Machine + Clone + 'static>(machine: &M) -> (TempDir, Commissioned) {
    let dir = tempfile::tempdir().unwrap();
    let (_tx, rx) = tokio::sync::watch::channel(false);
    let done = motorbench::session::commission(
        Box::new(machine.clone()),
        &options(&dir),
        &NoProgress,
        &rx,
    )
    .await
    .unwrap();
    (dir, done)
}

/// Run `cfg`'s plan on its simulated rig and return the record; panics
/// when `cfg` is not a simulated rig or its test does not complete.
pub async fn record(cfg: &Config) -> Record {
    let Backend::Simulated(sim) = &cfg.backend else {
        panic!(
            "{}: a dry run to a record needs a simulated rig",
            cfg.common.motor_id
        )
    };
    let (mut stage, mut sensors) =
        sim_rig(sim, cfg.common.sample_rate_hz, false).expect("a valid motor");
    let mut sink = RecordSink::new(None, None, record_channels(sensors.channels(), stage.id()));
    let (_tx, rx) = tokio::sync::watch::channel(false);
    let counts_per_rev = f64::from(sim.sensors.encoder_lines) * 4.0;
    let outcome = run_test(
        cfg,
        &plan_steps(&cfg.plan),
        &mut stage,
        &mut sensors,
        counts_per_rev,
        &mut sink,
        &NoProgress,
        &rx,
    )
    .await
    .expect("the record is written");
    assert_eq!(outcome, Outcome::Completed, "{}", cfg.common.motor_id);
    sink.into_parts().1
}
