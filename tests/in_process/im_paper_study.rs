//! The seed paper's simulation study (Sec. IV): a double-cage machine,
//! true θ = [Rr1 Rr2 Xr1 Xr2 Xs Rs Xm] = [0.0693 0.0132 0.00843 0.1162
//! 0.123 0.00778 4.3] p.u., N = 50 points, starts θ0a and θ0b; the paper's
//! recursive estimator against Levenberg–Marquardt, with l = 5 (current,
//! Rs and Xm known), l = 7 (current) and l = 7 (current + power).
//!
//! Choices the paper leaves open: slips `s_i = i/50` (i = 1…50), supply
//! 1 p.u. on the winding, power by the paper's Eq. 2 (`3V²…`, so 3 p.u. at
//! unity apparent power per phase), Gaussian noise σ = 0.005 p.u. on current
//! and power. The paper's "noise covariance = 1" cannot be meant: with it
//! `J(θ_true)` ≈ 1, ten thousand times its own stop threshold (tested).
//! Run with `--nocapture` for the tables quoted in docs/identification-im.md.

use motorbench::identify::{
    fit_lm, paper_cost, predict, recursive_estimate, Channels, Innovation, LmFit, LmOptions,
    PhaseData, RecursiveOptions, RecursiveStop, ResidualScale, SlipSweep, SweepNoise,
    THETA_DOUBLE_L5, THETA_DOUBLE_L7,
};
use motorbench::model::{
    impedance_mismatch, with_leakage_split, with_stator_leakage, Connection, ImCircuit, ImModel,
    ImParam, ImSupply, LeakageSplit, RotorCage,
};
use rand::rngs::StdRng;
use rand::SeedableRng;

/// A double cage from the paper's θ order [Rr1 Rr2 Xr1 Xr2 Xs Rs Xm].
fn theta(t: [f64; 7]) -> ImCircuit {
    ImCircuit {
        rs: t[5],
        xs: t[4],
        xm: t[6],
        rfe: None,
        rotor: RotorCage::Double {
            rr1: t[0],
            rr2: t[1],
            xr1: t[2],
            xr2: t[3],
        },
    }
}

fn paper_order(c: &ImCircuit) -> [f64; 7] {
    let g = |p| c.get(p).unwrap();
    [
        g(ImParam::Rr1),
        g(ImParam::Rr2),
        g(ImParam::Xr1),
        g(ImParam::Xr2),
        g(ImParam::Xs),
        g(ImParam::Rs),
        g(ImParam::Xm),
    ]
}

const TRUE: [f64; 7] = [0.0693, 0.0132, 0.00843, 0.1162, 0.123, 0.00778, 4.3];
const THETA0A: [f64; 7] = [0.083, 0.016, 0.01, 0.14, 0.144, 0.0078, 4.3];
const THETA0B: [f64; 7] = [0.07, 0.01, 0.009, 0.1, 0.1, 0.0078, 4.3];
/// Final vectors the paper reports for l = 7 with current only.
const THETA_NA_I: [f64; 7] = [0.064, 0.011, 0.002, 0.114, 0.094, 0.064, 4.3];
const THETA_NB_I: [f64; 7] = [0.063, 0.011, 0.0017, 0.114, 0.094, 0.064, 4.3];
/// The paper's final vector for l = 7 with current and power.
const THETA_NA_IP: [f64; 7] = [0.078, 0.0129, 0.0164, 0.121, 0.1167, 0.0073, 4.29];

fn slips() -> Vec<f64> {
    (1..=50).map(|k| f64::from(k) / 50.0).collect()
}

fn sweep(sigma: f64, seed: u64) -> PhaseData {
    // Star on √3 p.u.: 1 p.u. across the winding, and the line current
    // (where the noise goes) is the phase current.
    let supply = ImSupply {
        line_voltage: 3f64.sqrt(),
        frequency: 50.0,
        connection: Connection::Star,
        pole_pairs: 1,
    };
    let noise = SweepNoise {
        current_absolute: sigma,
        power_absolute: sigma,
        ..Default::default()
    };
    let mut rng = StdRng::seed_from_u64(seed);
    SlipSweep::simulate(&theta(TRUE), &supply, &slips(), &noise, 0, &mut rng).phase_data()
}

/// Largest relative deviation of the current and power curves from the
/// true machine's.
fn curve_error(c: &ImCircuit) -> (f64, f64) {
    let truth = theta(TRUE);
    slips().iter().fold((0.0, 0.0), |(ei, ep), &s| {
        let (i0, p0) = predict(&truth, s, 1.0);
        let (i1, p1) = predict(c, s, 1.0);
        (ei.max((i1 - i0).abs() / i0), ep.max((p1 - p0).abs() / p0))
    })
}

fn fmt(t: &[f64; 7]) -> String {
    t.iter()
        .map(|x| format!("{x:.5}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[test]
fn the_papers_noise_covariance_of_one_cannot_meet_its_own_threshold() {
    let loud = sweep(1.0, 1);
    let j = paper_cost(&loud, &theta(TRUE), Channels::Current);
    assert!(j > 0.7 && j < 1.4, "J(θ_true) = {j}");
    assert!(j > 1e3 * 1e-4);
    let quiet = sweep(0.005, 1);
    let j = paper_cost(&quiet, &theta(TRUE), Channels::CurrentAndPower);
    assert!(j < 1e-4, "J_ip(θ_true) = {j}");
}

#[test]
fn the_papers_l7_current_only_vectors_fit_the_current_but_not_the_power() {
    // Fig. 4: "the differences [in power] are significant". The paper also
    // says the current curves of θNa, θNb show "no visible difference" from
    // the true one: they differ by up to 7 %.
    for t in [THETA_NA_I, THETA_NB_I] {
        let (ei, ep) = curve_error(&theta(t));
        println!(
            "paper θN (l = 7, current): current off by {:.1} %, power by {:.0} %",
            100.0 * ei,
            100.0 * ep
        );
        assert!(ei > 0.05 && ei < 0.1, "current error {ei}");
        assert!(ep > 1.0, "power error {ep}");
    }
}

#[test]
fn the_papers_l7_current_and_power_vector_is_one_member_of_the_family() {
    // θNa with current + power differs from the true θ by up to 95 % (Xr1)
    // yet reproduces both curves: it is (within the paper's rounding) the
    // member of the true circuit's family with Xs = 0.1167.
    let paper = THETA_NA_IP;
    let member = paper_order(&with_stator_leakage(&theta(TRUE), paper[4]).unwrap());
    println!("paper θNa (l = 7, I+P):     {}", fmt(&paper));
    println!("family member at Xs=0.1167: {}", fmt(&member));
    for k in 0..7 {
        assert!(
            (paper[k] - member[k]).abs() < 0.07 * member[k],
            "component {k}"
        );
    }
    let (ei, ep) = curve_error(&theta(paper));
    assert!(
        ei < 0.01 && ep < 0.015,
        "paper θNa curves off by {ei}, {ep}"
    );
    assert!(impedance_mismatch(&theta(TRUE), &theta(member), &slips()) < 1e-10);
}

struct Case {
    name: &'static str,
    channels: Channels,
    free: &'static [ImParam],
}

const CASES: [Case; 3] = [
    Case {
        name: "l = 5, current",
        channels: Channels::Current,
        free: &THETA_DOUBLE_L5,
    },
    Case {
        name: "l = 7, current",
        channels: Channels::Current,
        free: &THETA_DOUBLE_L7,
    },
    Case {
        name: "l = 7, current + power",
        channels: Channels::CurrentAndPower,
        free: &THETA_DOUBLE_L7,
    },
];

#[test]
fn the_papers_estimator_does_not_converge_from_theta0a_or_theta0b() {
    let data = sweep(0.005, 7);
    for case in &CASES {
        for (start_name, start) in [("θ0a", THETA0A), ("θ0b", THETA0B)] {
            for innovation in [Innovation::AsPrinted, Innovation::Linearised] {
                let opts = RecursiveOptions {
                    channels: case.channels,
                    innovation,
                    ..Default::default()
                };
                let est = recursive_estimate(&data, &theta(start), case.free, &opts);
                println!(
                    "recursive {innovation:?}, {}, from {start_name}: {} passes, J {:.2e}, stop {:?}",
                    case.name, est.iterations, est.cost, est.stop
                );
                assert!(
                    !est.succeeded(),
                    "{} from {start_name} reached the threshold",
                    case.name
                );
                if innovation == Innovation::AsPrinted {
                    // Eq. 22 as printed overshoots on the first pass.
                    assert_eq!(est.iterations, 1);
                    assert!(matches!(est.stop, RecursiveStop::NonPhysical { .. }));
                }
            }
        }
    }
}

fn lm(data: &PhaseData, case: &Case, start: [f64; 7], fixed: Vec<(ImParam, f64)>) -> LmFit {
    let mut o = LmOptions::new(ImModel::Double);
    o.channels = case.channels;
    o.residual_scale = ResidualScale::Absolute;
    o.starts = vec![theta(start)];
    o.fixed = fixed;
    fit_lm(data, &o).unwrap()
}

fn covers(fit: &LmFit, truth: &ImCircuit, param: ImParam) -> bool {
    let p = fit.param(param).unwrap();
    let t = truth.get(param).unwrap();
    p.ci95.is_some_and(|[lo, hi]| lo <= t && t <= hi)
}

#[test]
fn lm_converges_from_both_starts_and_finds_the_conventional_circuit() {
    let data = sweep(0.005, 7);
    let truth = theta(TRUE);
    let j_true_i = paper_cost(&data, &truth, Channels::Current);
    let j_true_ip = paper_cost(&data, &truth, Channels::CurrentAndPower);
    let conventional = with_leakage_split(&truth, LeakageSplit::DESIGN_A).unwrap();
    println!("true θ:              {}", fmt(&TRUE));
    println!(
        "conventional (Xs = Xr(1)): {}",
        fmt(&paper_order(&conventional))
    );

    // l = 5: Rs and Xm known, current only.
    let case = &CASES[0];
    let fixed = vec![(ImParam::Rs, TRUE[5]), (ImParam::Xm, TRUE[6])];
    let a = lm(&data, case, THETA0A, fixed.clone());
    let b = lm(&data, case, THETA0B, fixed);
    let (ei, ep) = curve_error(&a.circuit);
    println!(
        "LM {}: θ {}  J {:.2e} (true {:.2e}); curves off by {:.2} % (I), {:.2} % (P); not determined {:?}",
        case.name,
        fmt(&paper_order(&a.circuit)),
        a.paper_cost,
        j_true_i,
        100.0 * ei,
        100.0 * ep,
        a.identifiability.unidentifiable
    );
    assert!(a.paper_cost <= j_true_i && (a.paper_cost - b.paper_cost).abs() < 1e-3 * a.paper_cost);
    // With the phase of the current unseen, cage 1's leakage is not pinned:
    // the fit drives it to zero and says so.
    assert!(a.identifiability.unidentifiable.contains(&ImParam::Xr1));
    assert!(a.identifiability.at_bound.contains(&ImParam::Xr1));
    assert!(ei < 0.01 && ep < 0.03);

    // l = 7: the family of equivalent circuits is found and the
    // conventional member reported, from either start.
    for case in &CASES[1..] {
        let a = lm(&data, case, THETA0A, Vec::new());
        let b = lm(&data, case, THETA0B, Vec::new());
        let j_true = if case.channels.uses_power() {
            j_true_ip
        } else {
            j_true_i
        };
        let (ei, ep) = curve_error(&a.circuit);
        println!(
            "LM {}: θ {}  J {:.2e} (true {:.2e}); curves off by {:.2} % (I), {:.2} % (P); weak before convention: {}",
            case.name,
            fmt(&paper_order(&a.circuit)),
            a.paper_cost,
            j_true,
            100.0 * ei,
            100.0 * ep,
            a.identifiability
                .weak_before_convention
                .iter()
                .map(|w| w.describe())
                .collect::<Vec<_>>()
                .join("; ")
        );
        for p in &a.params {
            println!(
                "    {:4} {:.5}  ci95 {:?}  {:?}",
                p.param.key(),
                p.value,
                p.ci95,
                p.source
            );
        }
        assert!(
            a.paper_cost <= j_true * 1.0001,
            "{} J {} vs true {}",
            case.name,
            a.paper_cost,
            j_true
        );
        assert!(a.identifiability.convention.is_some());
        assert!(a
            .identifiability
            .weak_before_convention
            .iter()
            .any(|w| w.moves(ImParam::Xr1, 0.2)));
        for (x, y) in a.circuit.values().iter().zip(b.circuit.values()) {
            assert!((x - y).abs() < 1e-4 * y, "starts disagree: {x} vs {y}");
        }
        for &p in ImModel::Double.params() {
            if a.param(p).unwrap().identifiable {
                assert!(
                    covers(&a, &conventional, p),
                    "{}: {p} misses the conventional value",
                    case.name
                );
            }
        }
        if case.channels.uses_power() {
            // With power, every element of the conventional circuit is pinned.
            assert!(a.identifiability.unidentifiable.is_empty());
            assert!(
                ep < 0.01 && ei < 0.01,
                "{}: curves off by {ei}, {ep}",
                case.name
            );
        } else {
            // The paper's Fig. 4 finding: from the current alone Xm (and with
            // it Rs) is not determined, so the power curve is not either.
            assert!(a.identifiability.unidentifiable.contains(&ImParam::Xm));
            assert!(ep > 2.0 * ei);
        }
    }
}

#[test]
fn with_xs_known_lm_recovers_the_true_circuit() {
    // Fixing Xs (instead of the split) pins the family at the true member.
    let data = sweep(0.005, 7);
    let truth = theta(TRUE);
    let fit = lm(&data, &CASES[2], THETA0B, vec![(ImParam::Xs, TRUE[4])]);
    println!("LM l = 6, Xs known: {}", fmt(&paper_order(&fit.circuit)));
    assert!(fit.identifiability.convention.is_none());
    for &p in ImModel::Double.params() {
        if p != ImParam::Xs {
            assert!(covers(&fit, &truth, p), "{p} misses the true value");
        }
    }
}
