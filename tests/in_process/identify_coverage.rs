//! Coverage of the output-error fit's 95 % intervals: random motors from
//! 100 W to 2 kW (see `tests/common/rated_motor.rs` for the generator), each
//! run through the default staircase on the simulated rig with noise and
//! quantisation on, identified from the record. The truth must lie inside
//! the reported interval in at least 90 % of the cases, for every
//! parameter and overall. The seed is fixed; the test prints the coverage.

use crate::common::rated_motor;

use crate::common::dry_run;
use motorbench::identify::{output_error, OutputErrorOptions, PARAM_KEYS};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rated_motor::{config_for, random_motor, DEFAULT_STAIRCASE};

/// Motors simulated.
const MOTORS: usize = 60;

/// Generator seed.
const SEED: u64 = 20_261_121;

fn values(p: &motorbench::model::DcParams) -> [f64; 6] {
    [p.ra, p.la, p.k, p.j, p.f, p.tst]
}

#[tokio::test(flavor = "current_thread")]
async fn output_error_intervals_cover_the_truth_for_random_motors() {
    let mut rng = StdRng::seed_from_u64(SEED);
    let mut inside = [0usize; 6];
    let mut inside_classic = [0usize; 6];
    println!(
        "{:>3} {:>7} {:>6} {:>6} {:>7} {:>7} {:>6}  z-scores (ln p̂ − ln p)/σ: {}",
        "#",
        "P [W]",
        "U [V]",
        "r/min",
        "τe [ms]",
        "τm [ms]",
        "s",
        PARAM_KEYS.join(" ")
    );
    for n in 0..MOTORS {
        let motor = random_motor(&mut rng);
        let cfg = config_for(&motor, &DEFAULT_STAIRCASE, 1000 + n as u64, &mut rng);
        let record = dry_run::record(&cfg).await;
        let options = OutputErrorOptions {
            validate: false,
            ..OutputErrorOptions::default()
        };
        let fit = output_error(&record, None, &options)
            .unwrap_or_else(|e| panic!("motor {n} ({}): {e}", cfg.common.motor_id));
        let truth = values(&motor.params);
        let got = values(&fit.params);
        let u = &fit.uncertainty;
        let mut z = Vec::new();
        for p in 0..6 {
            let covered = u.ci95[p].is_some_and(|[lo, hi]| lo <= truth[p] && truth[p] <= hi);
            inside[p] += usize::from(covered);
            let zc = (got[p] / truth[p]).ln() / u.std_ln_classic[p];
            inside_classic[p] += usize::from(zc.abs() <= 1.96);
            z.push(format!(
                "{:+5.1}{}",
                (got[p] / truth[p]).ln() / u.std_ln[p],
                if covered { " " } else { "*" }
            ));
        }
        let mp = &motor.params;
        println!(
            "{n:>3} {:>7.0} {:>6.1} {:>6.0} {:>7.2} {:>7.1} {:>6.2}  {}",
            motor.power,
            motor.voltage,
            motor.speed_rpm,
            1e3 * mp.tau_e(),
            1e3 * mp.tau_m(),
            u.residual_variance.sqrt(),
            z.join(" ")
        );
    }
    let total: usize = inside.iter().sum();
    let overall = total as f64 / (6 * MOTORS) as f64;
    println!("\ncoverage of the 95 % intervals over {MOTORS} motors:");
    for p in 0..6 {
        println!(
            "  {:<4} {:>5.1} %   (classic s²(JᵀJ)⁻¹: {:>5.1} %)",
            PARAM_KEYS[p],
            100.0 * inside[p] as f64 / MOTORS as f64,
            100.0 * inside_classic[p] as f64 / MOTORS as f64
        );
    }
    let classic: usize = inside_classic.iter().sum();
    println!(
        "  all  {:>5.1} %   (classic: {:>5.1} %)",
        100.0 * overall,
        100.0 * classic as f64 / (6 * MOTORS) as f64
    );
    for p in 0..6 {
        assert!(
            inside[p] as f64 >= 0.9 * MOTORS as f64,
            "{} covered in {} of {MOTORS}",
            PARAM_KEYS[p],
            inside[p]
        );
    }
    assert!(overall >= 0.9, "overall coverage {overall}");
}
