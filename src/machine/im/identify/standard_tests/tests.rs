//! The reduction against a circuit with known elements: the standard
//! tests simulated from the crate's equivalent circuit (core loss and a
//! friction-and-windage load included), with and without meter noise, at
//! rated and at reduced locked-rotor frequency, with a hot winding; and
//! the reasons it gives for missing tests and bad data.

use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::*;
use crate::machine::im::{assert_warned, COPPER_ALPHA};
use crate::model::{locked_rotor_reading, no_load_reading, terminal_resistance};
use crate::record::{DcResistanceReading, SupplyReading};

/// The true machine: delta, 400 V, 50 Hz, Xs = Xr (design A's split).
fn machine() -> ImCircuit {
    ImCircuit {
        rs: 1.5,
        xs: 3.0,
        xm: 90.0,
        rfe: Some(1500.0),
        rotor: RotorCage::Single { rr: 1.6, xr: 3.0 },
    }
}

const PFW: f64 = 60.0;
const NO_LOAD_V: [f64; 9] = [440.0, 400.0, 360.0, 300.0, 240.0, 200.0, 160.0, 120.0, 80.0];
const LOCKED_V: [f64; 4] = [40.0, 60.0, 80.0, 100.0];

/// Relative Gaussian meter errors of σ `sigma`.
struct Meter {
    rng: StdRng,
    normal: Normal<f64>,
}

impl Meter {
    fn new(sigma: f64, seed: u64) -> Meter {
        Meter {
            rng: StdRng::seed_from_u64(seed),
            normal: Normal::new(0.0, sigma.max(f64::MIN_POSITIVE)).unwrap(),
        }
    }

    fn read(&mut self, v: f64) -> f64 {
        v * (1.0 + self.normal.sample(&mut self.rng))
    }
}

/// The tests of `c` with its winding at `hot_c` °C during the AC tests
/// (the DC reading at 20 °C, `c.rs` being the resistance at 20 °C), the
/// locked-rotor test at `f_lr` Hz.
fn tests_of(c: &ImCircuit, sigma: f64, f_lr: f64, hot_c: Option<f64>) -> ImStandardTests {
    seeded_tests_of(c, sigma, 7, f_lr, hot_c)
}

/// [`tests_of`] with the meters' errors drawn from `seed`.
fn seeded_tests_of(
    c: &ImCircuit,
    sigma: f64,
    seed: u64,
    f_lr: f64,
    hot_c: Option<f64>,
) -> ImStandardTests {
    let mut m = Meter::new(sigma, seed);
    let conn = Connection::Delta;
    let hot = ImCircuit {
        rs: c.rs * (1.0 + COPPER_ALPHA * (hot_c.unwrap_or(20.0) - 20.0)),
        ..*c
    };
    let r_ll = terminal_resistance(c.rs, conn);
    let dc_resistance = [1.0, 1.5, 2.0, 2.5, 3.0]
        .iter()
        .map(|&i| DcResistanceReading {
            segment: 0,
            dc_voltage: m.read(r_ll * i),
            dc_current: i,
            winding_temperature: hot_c.map(|_| 20.0),
        })
        .collect();
    let mut supply = |segment, r: crate::model::StandardReading, f| SupplyReading {
        segment,
        line_voltage: m.read(r.line_voltage),
        line_current: m.read(r.line_current),
        input_power: m.read(r.input_power),
        frequency: f,
        winding_temperature: hot_c,
    };
    let no_load = NO_LOAD_V
        .iter()
        .map(|&v| supply(1, no_load_reading(&hot, conn, v, PFW).unwrap(), 50.0))
        .collect();
    let locked_rotor = LOCKED_V
        .iter()
        .map(|&v| {
            let v = v * f_lr / 50.0;
            supply(2, locked_rotor_reading(&hot, conn, v, f_lr, 50.0), f_lr)
        })
        .collect();
    ImStandardTests {
        dc_resistance,
        no_load,
        locked_rotor,
    }
}

fn opts() -> StandardTestsOptions {
    StandardTestsOptions {
        rated_voltage: Some(400.0),
        rated_frequency: Some(50.0),
        ..Default::default()
    }
}

fn reduce(tests: &ImStandardTests) -> StandardTestsReduction {
    reduce_standard_tests(tests, Connection::Delta, &opts()).unwrap()
}

/// The true value of each reported key.
fn truth(c: &ImCircuit) -> Vec<(&'static str, f64)> {
    let RotorCage::Single { rr, xr } = c.rotor else {
        unreachable!()
    };
    vec![
        ("Rs", c.rs),
        ("Xs", c.xs),
        ("Xr", xr),
        ("Rr", rr),
        ("Xm", c.xm),
        ("Rfe", c.rfe.unwrap()),
        ("Pfw", PFW),
    ]
}

/// The relative error the method itself leaves on noise-free data: the
/// classical reduction takes the uncoupled rotor's air-gap power for
/// friction and windage, so `Pfw` comes out `Pfw·s/(1 − s)` high (0.25 %
/// here, the lowest no-load voltage running at the largest slip); the
/// rest only the bisection's and the curve's round-off.
fn tolerance(key: &str) -> f64 {
    if key == "Pfw" {
        5e-3
    } else {
        1e-3
    }
}

fn value<'a>(r: &'a StandardTestsReduction, key: &str) -> &'a ParamEstimate {
    &r.params[key]
}

#[test]
fn noise_free_tests_give_back_the_circuit() {
    let r = reduce(&tests_of(&machine(), 0.0, 50.0, None));
    for (key, t) in truth(&machine()) {
        let v = value(&r, key).value;
        eprintln!("noise-free {key}: {v:.6} (true {t})");
        assert!((v - t).abs() < tolerance(key) * t, "{key}: {v} against {t}");
    }
    // The core loss at rated voltage is 3·E²/Rfe.
    let row = r
        .tables
        .no_load
        .iter()
        .find(|x| x.line_voltage == 400.0)
        .unwrap();
    let pfe = 3.0 * row.air_gap_voltage.powi(2) / 1500.0;
    assert!((value(&r, "Pfe").value - pfe).abs() < 1e-3 * pfe);
    assert_eq!(r.tables.no_load.len(), 9);
    assert!(r.tables.no_load[0].line_voltage < r.tables.no_load[8].line_voltage);
    assert_eq!(r.tables.locked_rotor.len(), 4);
    let curve = r.tables.xm_curve.as_ref().unwrap();
    let at_rated: f64 = (curve.coefficients.iter().enumerate())
        .map(|(k, a)| a * 400f64.powi(k as i32))
        .sum();
    assert!((at_rated - 90.0).abs() < 0.1, "{curve:?}");
    assert!(r.warnings.iter().any(|w| w.contains("convention")));
}

#[test]
fn noisy_tests_cover_every_element_with_their_intervals() {
    // Over many draws of 0.2 % meter errors each 95 % interval covers its
    // truth nearly always (a few misses are the interval's 5 %).
    let draws = 40;
    let mut covered = std::collections::BTreeMap::new();
    for seed in 0..draws {
        let r = reduce(&seeded_tests_of(&machine(), 0.002, seed, 50.0, None));
        for (key, t) in truth(&machine()) {
            let p = value(&r, key);
            let [lo, hi] = p.ci95.unwrap_or_else(|| panic!("{key} has no interval"));
            assert!(hi - lo < 0.2 * t, "{key}: interval [{lo}, {hi}] too wide");
            *covered.entry(key).or_insert(0) += usize::from(lo <= t && t <= hi);
        }
    }
    eprintln!("coverage over {draws} draws: {covered:?}");
    for (key, n) in &covered {
        assert!(
            *n >= draws as usize * 85 / 100,
            "{key}: covered in {n} of {draws} draws"
        );
    }
    let r = reduce(&tests_of(&machine(), 0.002, 50.0, None));
    for (key, t) in truth(&machine()) {
        let p = value(&r, key);
        let [lo, hi] = p.ci95.unwrap();
        eprintln!(
            "0.2 % noise {key}: {:.4} [{lo:.4}, {hi:.4}] (true {t})",
            p.value
        );
        assert!(
            (p.value - t).abs() < 0.02 * t,
            "{key}: {} against {t}",
            p.value
        );
    }
    let c = &r.circuit;
    let RotorCage::Single { xr, .. } = c.rotor else {
        unreachable!()
    };
    let (lo_s, hi_s) = (r.params["Xs"].ci95.unwrap(), r.params["Xr"].ci95.unwrap());
    assert!(
        lo_s[0] + hi_s[0] <= 6.0 && 6.0 <= lo_s[1] + hi_s[1],
        "Xs + Xr = {}",
        c.xs + xr
    );
}

#[test]
fn a_reduced_frequency_locked_rotor_test_scales_to_rated_frequency() {
    let r = reduce(&tests_of(&machine(), 0.0, 12.5, None));
    for (key, t) in truth(&machine()) {
        let v = value(&r, key).value;
        assert!((v - t).abs() < tolerance(key) * t, "{key}: {v} against {t}");
    }
    assert_warned(&r.warnings, "12.5 Hz");
    assert_eq!(r.tables.locked_rotor[0].frequency, Some(12.5));
}

#[test]
fn a_hot_winding_gets_the_dc_resistance_corrected_to_its_temperature() {
    let r = reduce(&tests_of(&machine(), 0.0, 50.0, Some(75.0)));
    let hot = 1.5 * (1.0 + COPPER_ALPHA * 55.0);
    let rs = value(&r, "Rs").value;
    assert!((rs - hot).abs() < 1e-3 * hot, "Rs {rs} against {hot}");
    let rr = value(&r, "Rr").value;
    assert!((rr - 1.6).abs() < 2e-3 * 1.6, "Rr {rr}");
    // Uncorrected, the copper the DC reading misses would land in Rr.
    let mut cold = tests_of(&machine(), 0.0, 50.0, Some(75.0));
    for d in &mut cold.dc_resistance {
        d.winding_temperature = None;
    }
    let wrong = reduce(&cold);
    assert!(value(&wrong, "Rr").value > 1.6 + 0.5 * (hot - 1.5));
    assert!(wrong.warnings.iter().any(|w| w.contains("not corrected")));
}

#[test]
fn the_design_class_sets_the_leakage_split() {
    let mut c = machine();
    c.xs = 2.4;
    c.rotor = RotorCage::Single { rr: 1.6, xr: 3.6 };
    let tests = tests_of(&c, 0.0, 50.0, None);
    let design_b = StandardTestsOptions {
        split: LeakageSplit::DESIGN_B,
        ..opts()
    };
    let r = reduce_standard_tests(&tests, Connection::Delta, &design_b).unwrap();
    assert!((value(&r, "Xs").value - 2.4).abs() < 5e-3, "{:?}", r.params);
    assert!((value(&r, "Xr").value - 3.6).abs() < 5e-3);
    assert!(r.warnings.iter().any(|w| w.contains("= 0.4")));
}

#[test]
fn missing_tests_and_bad_data_give_reasons_not_nans() {
    let full = tests_of(&machine(), 0.0, 50.0, None);
    let no_nl = ImStandardTests {
        no_load: vec![],
        ..full.clone()
    };
    let e = reduce_standard_tests(&no_nl, Connection::Delta, &opts()).unwrap_err();
    assert!(e.to_string().contains("no im_no_load segment"), "{e}");
    assert!(matches!(e, StandardTestsError::Missing(_)), "{e:?}");
    let (m, _) = standard_tests_method(&no_nl, Connection::Delta, &opts()).unwrap();
    assert!(!m.applies);
    assert!(
        standard_tests_method(&ImStandardTests::default(), Connection::Delta, &opts()).is_none()
    );

    // One no-load voltage cannot separate friction from core loss.
    let one = ImStandardTests {
        no_load: full.no_load[..1].to_vec(),
        ..full.clone()
    };
    let e = reduce_standard_tests(&one, Connection::Delta, &opts()).unwrap_err();
    assert!(
        e.to_string().contains("fewer than two distinct voltages"),
        "{e}"
    );

    // A DC reading far above the locked-rotor resistance.
    let mut high = full.clone();
    for d in &mut high.dc_resistance {
        d.dc_voltage *= 5.0;
    }
    let e = reduce_standard_tests(&high, Connection::Delta, &opts()).unwrap_err();
    assert!(e.to_string().contains("no physical rotor branch"), "{e}");
    assert!(
        matches!(e, StandardTestsError::NoRotorBranch { .. }),
        "{e:?}"
    );

    // A power factor above 1.
    let mut bad = full;
    bad.locked_rotor[1].input_power *= 10.0;
    let e = reduce_standard_tests(&bad, Connection::Delta, &opts()).unwrap_err();
    assert!(e.to_string().contains("not below"), "{e}");
}

#[test]
fn a_negative_friction_intercept_is_held_at_zero_with_a_reason() {
    let mut t = tests_of(&machine(), 0.0, 50.0, None);
    // A wattmeter reading 100 W low everywhere.
    for r in &mut t.no_load {
        r.input_power -= 100.0;
    }
    let r = reduce(&t);
    let p = value(&r, "Pfw");
    assert_eq!(p.value, 0.0);
    assert_warned(&r.warnings, "taken as 0 W");
    for p in r.params.values() {
        assert!(p.value.is_finite() && p.value >= 0.0, "{p:?}");
    }
}

#[test]
fn locked_rotor_tests_at_two_frequencies_give_the_circuit_the_reduced_ones_rotor() {
    // A rotor whose resistance at 50 Hz slip frequency is 20 % above its
    // resistance at 12.5 Hz (a deep bar's): the circuit takes the 12.5 Hz
    // test's, the 50 Hz test's is reported beside it.
    let deep = ImCircuit {
        rotor: RotorCage::Single { rr: 1.92, xr: 3.0 },
        ..machine()
    };
    let mut tests = tests_of(&machine(), 0.0, 12.5, None);
    let mut rated = tests_of(&deep, 0.0, 50.0, None).locked_rotor;
    for r in &mut rated {
        r.segment = 3;
    }
    tests.locked_rotor.extend(rated);
    let r = reduce(&tests);
    for (key, t) in truth(&machine()) {
        let v = value(&r, key).value;
        assert!((v - t).abs() < tolerance(key) * t, "{key}: {v} against {t}");
    }
    let rr50 = value(&r, "Rr_rated_frequency").value;
    assert!((rr50 / 1.92 - 1.0).abs() < 1e-3, "{rr50}");
    let xr50 = value(&r, "Xr_rated_frequency").value;
    assert!((xr50 / 3.0 - 1.0).abs() < 1e-3, "{xr50}");
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("12.5 Hz and 50 Hz") && w.contains("+20.0 %")),
        "{:?}",
        r.warnings
    );
    let frequencies: Vec<Option<f64>> = r.tables.locked_rotor.iter().map(|l| l.frequency).collect();
    assert_eq!(frequencies.iter().filter(|f| **f == Some(12.5)).count(), 4);
    assert_eq!(frequencies.iter().filter(|f| **f == Some(50.0)).count(), 4);
}
