//! The IM diagnosis on blind cases of its own generator: verdict accuracy,
//! no false alarm on `none`, gap_after near the noise floor.

use motorbench::diagnose::blind::simulate_im_case;
use motorbench::diagnose::{diagnose_im, DiagnoseOptions};
use motorbench::model::Effect;
use rand::rngs::StdRng;
use rand::SeedableRng;

const EFFECTS: [Option<Effect>; 7] = [
    None,
    Some(Effect::IronLoss),
    Some(Effect::DeepBar),
    Some(Effect::MainFluxSaturation),
    Some(Effect::LeakageSaturation),
    Some(Effect::StrayLoadLoss),
    Some(Effect::ThermalDrift),
];

#[test]
#[ignore]
fn explore() {
    let n: usize = std::env::var("CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(2);
    let seed: u64 = std::env::var("SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    let mut rng = StdRng::seed_from_u64(seed);
    for round in 0..n {
        for e in EFFECTS {
            let case = simulate_im_case(e, &mut rng);
            let t = std::time::Instant::now();
            let run = diagnose_im(&case.record, &DiagnoseOptions::default()).unwrap();
            let v = &run.report.verdict;
            let cands: Vec<String> = run
                .report
                .candidates
                .iter()
                .map(|c| format!("{}:{:.1}/p{:.2e}", c.effect, c.score, c.p_value))
                .collect();
            println!(
                "{round} truth {:24} verdict {:24} before {:.4} after {:.4} floor {:.4} est {:.4} [{}] {:?} {:.2}s",
                case.truth.effect,
                v.effect,
                v.gap_before,
                v.gap_after,
                case.truth.noise_floor,
                run.report.gap.noise_floor,
                cands.join(" "),
                case.truth.effect_params.values().map(|x| format!("{x:.3}")).collect::<Vec<_>>(),
                t.elapsed().as_secs_f64()
            );
        }
    }
}

#[test]
#[ignore]
fn one() {
    let seed: u64 = std::env::var("SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    let skip: usize = std::env::var("SKIP").ok().and_then(|v| v.parse().ok()).unwrap_or(0);
    let mut rng = StdRng::seed_from_u64(seed);
    let mut k = 0;
    loop {
        for e in EFFECTS {
            let case = simulate_im_case(e, &mut rng);
            if k == skip {
                println!("truth {} {:?}", case.truth.effect, case.truth.effect_params);
                for p in &case.record.operating_points {
                    println!("seg {} s {:.4} V {:.1} I {:.3} P {:.1}", p.segment, p.slip, p.line_voltage, p.line_current, p.input_power);
                }
                let run = diagnose_im(&case.record, &DiagnoseOptions::default()).unwrap();
                println!("{}", serde_json::to_string_pretty(&run.report.nominal).unwrap());
                println!("{}", serde_json::to_string_pretty(&run.report.verdict).unwrap());
                println!("{:?}", case.truth);
                return;
            }
            k += 1;
        }
    }
}
