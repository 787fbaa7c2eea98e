//! Property: identify(simulate(θ)) ≈ θ. Random DC motors run through the
//! real bench path (simulated rig, runner, record builder) with noise off
//! and fine sensors; the steady-state method must recover K, Ra, f, Tst.

use crate::common::dry_run;
use motorbench::config::{Backend, Config, Plan, Supervision};
use motorbench::identify::identify_dc;
use motorbench::model::DcParams;
use proptest::prelude::*;
use proptest::test_runner::{Config as PropConfig, RngAlgorithm, TestRng, TestRunner};

/// A plausible motor from its rating: rated voltage `v`, rated speed `w`
/// (rad/s), rated current `i`, resistive drop fraction `rho`, electrical
/// and mechanical time constants, friction and static torque fractions.
#[allow(clippy::too_many_arguments)]
fn motor(
    v: f64,
    w: f64,
    i: f64,
    rho: f64,
    tau_e: f64,
    tau_m: f64,
    visc: f64,
    stat: f64,
) -> DcParams {
    let k = v * (1.0 - rho) / w;
    let ra = rho * v / i;
    let torque = k * i;
    DcParams {
        ra,
        la: tau_e * ra,
        k,
        j: tau_m * k * k / ra,
        f: visc * torque / w,
        tst: stat * torque,
    }
}

fn run(p: DcParams, v: f64, i: f64) -> motorbench::identify::Identification {
    let mut cfg = Config::embedded_default();
    let Backend::Simulated(sim) = &mut cfg.backend else {
        unreachable!("the embedded default is the simulated rig")
    };
    sim.motor = p;
    sim.power_stage.max_voltage = 2.0 * v;
    sim.power_stage.current_limit = 1e6;
    sim.sensors.voltage_noise = 0.0;
    sim.sensors.current_noise = 0.0;
    sim.sensors.voltage_bits = 24;
    sim.sensors.current_bits = 24;
    sim.sensors.voltage_full_scale = 2.0 * v;
    sim.sensors.current_full_scale = 50.0 * i;
    sim.sensors.encoder_lines = 1 << 22;
    cfg.common.limits.max_voltage = 2.0 * v;
    cfg.common.limits.max_current = 1e6;
    cfg.common.limits.max_speed = 1e6;
    // The `[supervisor]` defaults that follow from these limits (the
    // power limit out of the way too), the winding rated at `i`.
    cfg.common.supervision = Supervision::defaults(&cfg.common.limits, i);
    cfg.plan = Plan::DcStep {
        levels: [0.3, 1.0, 0.5, 0.8, 0.4].iter().map(|f| f * v).collect(),
        coastdown: false,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .unwrap();
    identify_dc(&rt.block_on(dry_run::record(&cfg)))
}

#[test]
fn steady_state_identification_recovers_random_motors() {
    let mut runner = TestRunner::new_with_rng(
        PropConfig {
            cases: 16,
            failure_persistence: None,
            ..PropConfig::default()
        },
        TestRng::from_seed(RngAlgorithm::ChaCha, &[7; 32]),
    );
    let strategy = (
        24.0..400.0f64,
        100.0..400.0f64,
        0.5..20.0f64,
        0.03..0.15f64,
        (0.001..0.03f64, 0.02..0.15f64),
        (0.01..0.1f64, 0.02..0.1f64),
    );
    let worst = std::cell::RefCell::new([0.0f64; 4]);
    runner
        .run(&strategy, |(v, w, i, rho, (tau_e, tau_m), (visc, stat))| {
            let p = motor(v, w, i, rho, tau_e, tau_m, visc, stat);
            let id = run(p, v, i);
            let Some(params) = id.report.methods["steady_state"].params.clone() else {
                return Err(TestCaseError::fail(format!("{p:?}: {:?}", id.report)));
            };
            let rel = |key: &str, truth: f64| (params[key].value - truth).abs() / truth;
            let errors = [
                rel("K", p.k),
                rel("Ra", p.ra),
                rel("f", p.f),
                rel("Tst", p.tst),
            ];
            for (w, e) in worst.borrow_mut().iter_mut().zip(errors) {
                *w = w.max(e);
            }
            prop_assert!(
                rel("K", p.k) < 1e-4,
                "K {} vs {} ({p:?})",
                params["K"].value,
                p.k
            );
            prop_assert!(
                rel("Ra", p.ra) < 2e-3,
                "Ra {} vs {} ({p:?})",
                params["Ra"].value,
                p.ra
            );
            prop_assert!(
                rel("f", p.f) < 0.02,
                "f {} vs {} ({p:?})",
                params["f"].value,
                p.f
            );
            prop_assert!(
                rel("Tst", p.tst) < 0.02,
                "Tst {} vs {} ({p:?})",
                params["Tst"].value,
                p.tst
            );
            Ok(())
        })
        .unwrap();
    let [k, ra, f, tst] = *worst.borrow();
    println!(
        "worst relative errors over 16 motors: K {k:.2e}, Ra {ra:.2e}, f {f:.2e}, Tst {tst:.2e}"
    );
}
