//! A full induction-machine diagnosis (nominal fit, six candidates each
//! cross-validated on interleaved folds, gap localisation, verdict) of a
//! blind case: the deep-bar case of a fixed seed, and a case without an
//! effect; and of a motor lab's record of a small motor
//! (`tests/data/im_lab`: no-load sweep with the slip not measured, load
//! curve, locked rotor; 141 points).
//!
//! `cargo bench --bench diagnose_im`

use criterion::{criterion_group, criterion_main, Criterion};
use motorbench::diagnose::blind::simulate_im_case;
use motorbench::diagnose::{diagnose_im, DiagnoseOptions};
use motorbench::model::{Connection, Effect};
use motorbench::record::{load_record_files, ColumnMap, SegmentKind};
use rand::rngs::StdRng;
use rand::SeedableRng;
use std::hint::black_box;
use std::path::PathBuf;

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("diagnose_im");
    group.sample_size(10);
    for (name, effect) in [("deep_bar", Some(Effect::DeepBar)), ("none", None)] {
        let case = simulate_im_case(effect, &mut StdRng::seed_from_u64(5));
        let points = case.record.operating_points.len();
        group.bench_function(format!("{name} ({points} points)"), |b| {
            b.iter(|| diagnose_im(black_box(&case.record), &DiagnoseOptions::default()).unwrap())
        });
    }
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/im_lab");
    let files: Vec<PathBuf> = ["no_load.csv", "load.csv", "locked_rotor.csv"]
        .iter()
        .map(|f| dir.join(f))
        .collect();
    let lab = load_record_files(
        SegmentKind::ImSlipSweep,
        &files,
        None,
        None,
        &ColumnMap::default(),
    )
    .expect("lab record");
    let star = DiagnoseOptions {
        connection: Some(Connection::Star),
        ..Default::default()
    };
    let points = lab.operating_points.len();
    group.bench_function(format!("lab record ({points} points)"), |b| {
        b.iter(|| diagnose_im(black_box(&lab), &star).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
