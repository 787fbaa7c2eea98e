//! Levenberg–Marquardt identification of a double-cage induction machine
//! (l = 7, current + power) on three sweeps of 50 points at 100 %, 80 %
//! and 60 % of rated voltage: the whole `fit_lm` (classical starts,
//! whitening, identifiability, leakage-split convention) and one
//! Levenberg–Marquardt run from a single start.
//!
//! And the whole `identify_im` (the `lm` fit, its held-out validation and
//! the paper's recursive estimator) of a motor lab's record of a small
//! motor (`model::LabMachine`: no-load sweep with the slip not measured,
//! load curve, locked rotor; saturation, core loss, friction and windage)
//! for every circuit: the 141-point record of `tests/data/im_lab`, and the
//! same shape with a 400-point load curve (416 points).
//!
//! `cargo bench --bench identify_im`

use criterion::{criterion_group, criterion_main, Criterion};
use motorbench::identify::{fit_lm, identify_im, LmOptions, SplitPolicy};
use motorbench::model::{Connection, ImModel, LabMachine, LabMeters};
use motorbench::record::{OperatingPoint, Record};
use std::hint::black_box;

#[path = "common/im_sweeps.rs"]
mod im_sweeps;

fn bench(c: &mut Criterion) {
    let (d, truth) = im_sweeps::double_cage_sweeps();
    let opts = LmOptions::new(ImModel::Double);
    let fit = fit_lm(&d, &opts).expect("fit");
    println!(
        "fit_lm on {} points: {} starts ({} at the best cost), {} evaluations",
        d.len(),
        fit.starts.0,
        fit.starts.1,
        fit.evaluations
    );
    c.bench_function("fit_lm double l=7, 3x50 points, classical starts", |b| {
        b.iter(|| fit_lm(black_box(&d), black_box(&opts)).expect("fit"))
    });
    let mut one = LmOptions::new(ImModel::Double);
    one.starts = vec![truth];
    one.split_policy = SplitPolicy::Never;
    c.bench_function("fit_lm double l=7, 3x50 points, one start", |b| {
        b.iter(|| fit_lm(black_box(&d), black_box(&one)).expect("fit"))
    });
}

/// The lab record with a load curve of `load_points` readings.
fn lab_record(load_points: usize) -> Record {
    let m = LabMachine::small_motor();
    let mut record = Record::default();
    for (k, seg) in m
        .lab_record(load_points, 6, 10, &LabMeters::default(), 19)
        .iter()
        .enumerate()
    {
        record
            .operating_points
            .extend(seg.points.iter().map(|p| OperatingPoint {
                segment: k as u32,
                slip: p.slip,
                line_voltage: p.line_voltage,
                line_current: p.line_current,
                input_power: p.input_power,
                speed: f64::NAN,
                frequency: m.frequency,
                torque: p.torque,
                winding_temperature: None,
            }));
    }
    record
}

fn bench_lab(c: &mut Criterion) {
    let mut group = c.benchmark_group("identify_im lab record");
    group.sample_size(10);
    for load_points in [125, 400] {
        let record = lab_record(load_points);
        let n = record.operating_points.len();
        for model in [
            ImModel::Single,
            ImModel::SingleFe,
            ImModel::Double,
            ImModel::DoubleFe,
        ] {
            let id = identify_im(&record, Some(Connection::Star), model);
            println!(
                "identify_im {model} on {n} points: {} evaluations in the final fit_lm{}",
                id.lm.as_ref().map_or(0, |f| f.evaluations),
                if id.lm.as_ref().is_some_and(|f| f.stopped_at_bound) {
                    " (stopped at its bound)"
                } else {
                    ""
                }
            );
            group.bench_function(format!("{model}, {n} points"), |b| {
                b.iter(|| identify_im(black_box(&record), Some(Connection::Star), model))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench, bench_lab);
criterion_main!(benches);
