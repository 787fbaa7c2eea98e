//! Time of a full DC diagnosis (nominal fit, leave-one-segment-out folds,
//! seven candidates each refitted and validated on held-out segments).
//!
//! Records:
//! - the seed paper's motor on the simulated rig (the embedded default),
//!   a 60 → 248 → 107 → 201 → 60 V staircase: 5 segments at 2 kHz;
//! - a blind case (fixed seed): 5 steps from rest plus a coast-down.
//!
//! Run: `cargo bench --bench diagnose_dc`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use motorbench::bench::{plan_steps, record_channels, run_test, sim_rig, NoProgress, RecordSink};
use motorbench::config::{Config, Plan};
use motorbench::diagnose::blind::simulate_dc_case;
use motorbench::diagnose::{diagnose_dc, DiagnoseOptions};
use motorbench::record::Record;
use motorbench_drivers::SensorStream;
use rand::rngs::StdRng;
use rand::SeedableRng;

fn rig_record() -> Record {
    let mut cfg = Config::embedded_default();
    cfg.plan = Plan::DcStep {
        levels: vec![60.0, 248.0, 107.0, 201.0, 60.0],
        coastdown: false,
    };
    let sim = cfg
        .backend
        .simulated()
        .expect("the embedded default is the simulated rig");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .expect("a runtime");
    runtime.block_on(async {
        let (mut stage, mut sensors) = sim_rig(sim, cfg.sample_rate_hz, false).expect("the rig");
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

fn bench(c: &mut Criterion) {
    let options = DiagnoseOptions::default();
    let rig = rig_record();
    let samples: usize = rig.segments.iter().map(|s| s.time.len()).sum();
    assert_eq!(rig.segments.len(), 5);
    eprintln!("rig record: 5 segments, {samples} samples at 2 kHz");
    c.bench_function("diagnose_dc (rig, 5 segments, 2 kHz)", |b| {
        b.iter(|| diagnose_dc(black_box(&rig), &options).expect("diagnosis"))
    });
    let blind = simulate_dc_case(None, &mut StdRng::seed_from_u64(11)).record;
    let samples: usize = blind.segments.iter().map(|s| s.time.len()).sum();
    eprintln!("blind record: 5 steps + coast-down, {samples} samples at 2 kHz");
    c.bench_function("diagnose_dc (blind case, 5 steps + coast-down)", |b| {
        b.iter(|| diagnose_dc(black_box(&blind), &options).expect("diagnosis"))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
