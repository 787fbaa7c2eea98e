//! Identification time of a 5-segment, 2 kHz DC step record: the whole
//! `identify_dc` (steady state and output error with its leave-one-out
//! validation), and the output-error fit alone with and without the
//! validation refits.
//!
//! The record: the seed paper's motor (the embedded default's rig) on a
//! 60 → 248 → 107 → 201 → 60 V staircase, noise and quantisation on.
//! Run: `cargo bench --bench identify_dc`.

mod common;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};

use motorbench::identify::{identify_dc, output_error, OutputErrorOptions};

fn bench(c: &mut Criterion) {
    let record = common::rig_record();
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
