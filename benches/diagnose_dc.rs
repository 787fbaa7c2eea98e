//! Time of a full DC diagnosis (nominal fit, leave-one-segment-out folds,
//! seven candidates each refitted and validated on held-out segments).
//!
//! Records:
//! - the seed paper's motor on the simulated rig (the embedded default),
//!   a 60 → 248 → 107 → 201 → 60 V staircase: 5 segments at 2 kHz;
//! - a blind case (fixed seed): 5 steps from rest plus a coast-down;
//! - the embedded default's plan (what `motorbench run` records: 8 levels
//!   and a coast-down, 9 segments) at 1×, 2× and 4× its length (its
//!   levels repeated), for the cost's growth with the record's length.
//!
//! Run: `cargo bench --bench diagnose_dc`; the lengths alone:
//! `cargo bench --bench diagnose_dc -- length`.

mod common;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};

use motorbench::diagnose::blind::simulate_dc_case;
use motorbench::diagnose::{diagnose_dc, DiagnoseOptions};
use rand::rngs::StdRng;
use rand::SeedableRng;

fn bench(c: &mut Criterion) {
    let options = DiagnoseOptions::default();
    let rig = common::rig_record();
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

fn bench_length(c: &mut Criterion) {
    let options = DiagnoseOptions::default();
    let mut group = c.benchmark_group("diagnose_dc length");
    for times in [1, 2, 4] {
        let record = common::default_plan_record(times);
        let samples: usize = record.segments.iter().map(|s| s.time.len()).sum();
        eprintln!(
            "default plan x{times}: {} segments, {samples} samples at 2 kHz",
            record.segments.len()
        );
        group.bench_function(format!("{times}x ({samples} samples)"), |b| {
            b.iter(|| diagnose_dc(black_box(&record), &options).expect("diagnosis"))
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench, bench_length
}
criterion_main!(benches);
