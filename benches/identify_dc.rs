//! Identification time of a 5-segment, 2 kHz DC step record: the whole
//! `identify_dc` (steady state and output error with its leave-one-out
//! validation), and the output-error fit alone with and without the
//! validation refits.
//!
//! The record: the seed paper's motor (the embedded default's rig) on a
//! 60 → 248 → 107 → 201 → 60 V staircase, noise and quantisation on.
//! Run: `cargo bench --bench identify_dc`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use motorbench::bench::{plan_steps, record_channels, run_test, sim_rig, NoProgress, RecordSink};
use motorbench::config::{Config, Plan};
use motorbench::identify::{identify_dc, output_error, OutputErrorOptions};
use motorbench::record::Record;
use motorbench_drivers::SensorStream;

fn record() -> Record {
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
    let record = record();
    let samples: usize = record.segments.iter().map(|s| s.time.len()).sum();
    assert_eq!(record.segments.len(), 5);
    eprintln!("record: 5 segments, {samples} samples at 2 kHz");
    c.bench_function("identify_dc (5 segments, 2 kHz)", |b| {
        b.iter(|| identify_dc(black_box(&record)))
    });
    c.bench_function("output_error with validation", |b| {
        b.iter(|| output_error(black_box(&record), None, &OutputErrorOptions::default()))
    });
    let fit_only = OutputErrorOptions {
        validate: false,
        ..OutputErrorOptions::default()
    };
    c.bench_function("output_error without validation", |b| {
        b.iter(|| output_error(black_box(&record), None, &fit_only))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
