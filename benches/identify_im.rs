//! Levenberg–Marquardt identification of a double-cage induction machine
//! (l = 7, current + power) on three sweeps of 50 points at 100 %, 80 %
//! and 60 % of rated voltage: the whole `fit_lm` (classical starts,
//! whitening, identifiability, leakage-split convention) and one
//! Levenberg–Marquardt run from a single start.
//!
//! `cargo bench --bench identify_im`

use criterion::{criterion_group, criterion_main, Criterion};
use motorbench::identify::{
    fit_lm, slip_grid, LmOptions, PhaseData, SlipSweep, SplitPolicy, SweepNoise,
};
use motorbench::model::{
    Connection, ImCircuit, ImModel, ImSupply, PerUnitBase, SEED_DOUBLE_CAGE_PU,
};
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

criterion_group!(benches, bench);
criterion_main!(benches);
