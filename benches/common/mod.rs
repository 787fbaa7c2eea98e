//! The records the DC benches time: the seed paper's motor on the
//! simulated rig (the embedded default), a 60 → 248 → 107 → 201 → 60 V
//! staircase, 5 segments at 2 kHz; and the embedded default's own plan
//! (8 levels and a coast-down) repeated to make longer records.

use motorbench::bench::{NoProgress, RecordSink};
use motorbench::config::{Config, Plan};
use motorbench::machine::dc::{plan_steps, record_channels, run_test, sim_rig};
use motorbench::record::Record;
use motorbench_drivers::SensorStream;

/// Run the staircase on the simulated rig and return its record.
#[allow(dead_code)] // not every bench uses both records
pub fn rig_record() -> Record {
    record_of(vec![60.0, 248.0, 107.0, 201.0, 60.0], false)
}

/// First level of each repeat of the default plan in
/// [`default_plan_record`] (as in `benches/diagnosis_cpu.sh`).
pub const REPEAT_FIRST_V: f64 = 107.0;

/// The embedded default's plan with its levels repeated `times` times and
/// its coast-down at the end: `times` = 1 is the default run's record
/// (9 segments), 2 and 4 are about twice and four times as long.
#[allow(dead_code)]
pub fn default_plan_record(times: usize) -> Record {
    let Plan::DcStep { levels, coastdown } = Config::embedded_default().plan else {
        panic!("the embedded default is a DC step plan");
    };
    let mut repeated = levels.clone();
    for _ in 1..times {
        // A repeat's first level is 107 V: the plan ends on the level it
        // starts with, and a level may not repeat the one before it.
        repeated.push(REPEAT_FIRST_V);
        repeated.extend_from_slice(&levels[1..]);
    }
    record_of(repeated, coastdown)
}

fn record_of(levels: Vec<f64>, coastdown: bool) -> Record {
    let mut cfg = Config::embedded_default();
    cfg.plan = Plan::DcStep { levels, coastdown };
    let sim = cfg
        .backend
        .simulated()
        .expect("the embedded default is the simulated rig");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .expect("a runtime");
    runtime.block_on(async {
        let (mut stage, mut sensors) =
            sim_rig(sim, cfg.common.sample_rate_hz, false).expect("the rig");
        let mut sink = RecordSink::new(
            None,
            None,
            record_channels(sensors.channels(), "sim-supply"),
        );
        let (_tx, rx) = tokio::sync::watch::channel(false);
        let counts = f64::from(sim.sensors.encoder_lines) * 4.0;
        run_test(
            &cfg,
            &plan_steps(&cfg.plan),
            &mut stage,
            &mut sensors,
            counts,
            &mut sink,
            &NoProgress,
            &rx,
        )
        .await
        .expect("the test runs");
        sink.into_parts().1
    })
}
