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
use motorbench::identify::{
    fit_lm, identify_im, slip_grid, LmOptions, PhaseData, SlipSweep, SplitPolicy, SweepNoise,
};
use motorbench::model::{
    Connection, ImCircuit, ImModel, ImSupply, LabMachine, LabMeters, PerUnitBase,
    SEED_DOUBLE_CAGE_PU,
};
use motorbench::record::{OperatingPoint, Record};
use rand::rngs::StdRng;
use rand::SeedableRng;
use std::hint::black_box;

fn data() -> (PhaseData, ImCircuit) {
    // The seed paper's double cage on a 4 kW, 400 V star base.
    let pu = SEED_DOUBLE_CAGE_PU;
    let circuit =
        ImCircuit::from_per_unit(&pu, &PerUnitBase::from_rating(400.0, 8.3, Connection::Star));
    let mut rng = StdRng::seed_from_u64(1);
    let mut sweep: Option<SlipSweep> = None;
    for (segment, v) in [400.0, 320.0, 240.0].into_iter().enumerate() {
        let supply = ImSupply {
            line_voltage: v,
            frequency: 50.0,
            connection: Connection::Star,
            pole_pairs: 2,
        };
        let s = SlipSweep::simulate(
            &circuit,
            &supply,
            &slip_grid(50, 0.002),
            &SweepNoise::relative(0.005),
            segment as u32,
            &mut rng,
        );
        match &mut sweep {
            Some(all) => all.extend(s),
            None => sweep = Some(s),
        }
    }
    (sweep.expect("three segments").phase_data(), circuit)
}

fn bench(c: &mut Criterion) {
    let (d, truth) = data();
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
