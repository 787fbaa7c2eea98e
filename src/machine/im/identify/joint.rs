//! The joint fit of the standard tests (method `joint`): the single-cage
//! circuit with core loss, and friction and windage, fitted by
//! Levenberg–Marquardt to every reading of the record at once — the load
//! test's points at their measured slip, the locked-rotor readings at
//! slip 1 (their reactances scaled to their frequency), and the no-load
//! readings at the slip where the air-gap power less the rotor copper
//! loss covers friction and windage (the slip is not measured: it follows
//! from the parameters, [`no_load_reading`]).
//!
//! - `Rs` is bounded by the DC reading (the classical reduction's `Rs`,
//!   at the locked-rotor test's temperature where the files give one):
//!   from its 95 % interval's lower end (at least 0.1 % below it: the
//!   reading's own error) to a winding [`MAX_WINDING_RISE_K`] warmer
//!   (copper's α), through a smooth map, so that the fit cannot trade the
//!   stator resistance for the core loss or the rotor resistance, as a
//!   fit of the load test alone can (the AC readings determine `Rs`
//!   weakly: with the no-load and locked-rotor tests alone it often sits
//!   on its lower bound, the DC reading, and the report says so).
//! - Where the readings carry the winding temperature and `Rs` has one
//!   (the DC reading's, corrected by the reduction), each no-load and
//!   locked-rotor reading and each load point sees `Rs` scaled to its own
//!   temperature (copper's α): the winding warms through the tests, most
//!   under load. A reading without a temperature takes `Rs` as it is.
//! - `Xs` is tied to `Xr` in the design class's leakage split (terminal
//!   readings at one frequency do not separate them), and reported with
//!   a warning that says so.
//! - `Xm`, `Rfe`, `Rr`, `Xr` and `Pfw` are fitted as logarithms: every
//!   element stays positive, the friction at least [`MIN_FRICTION_W`].
//! - Residuals are relative (`model/measured − 1`) for line current and
//!   input power; 95 % intervals from the Jacobian at the solution
//!   (Student t, `m − q` degrees of freedom), carried to each element.
//! - The solver stops after [`MAX_EVALUATIONS`] residual evaluations and
//!   says so.

use std::cell::Cell;
use std::collections::BTreeMap;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector};

use super::standard_tests::{temperature_factor, StandardTestsReduction};
use crate::contract::{MethodReport, ParamEstimate};
use crate::identify::least_squares::{AtParams, Residuals};
use crate::identify::stats::t975;
use crate::machine::im::COPPER_ALPHA;
use crate::model::{
    at_frequency, no_load_reading, Connection, ImCircuit, ImSupply, LeakageSplit, RotorCage,
};
use crate::record::{ImStandardTests, OperatingPoint};

/// The method's key in the report.
pub const JOINT: &str = "joint";

/// Why the joint fit cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JointFitError {
    /// Too few readings for the parameters.
    #[error("{readings} readings with current and power: the joint fit needs more than {min}")]
    TooFew {
        /// Readings with a current, a power and a voltage above 0.
        readings: usize,
        /// The fewest it needs, less one.
        min: usize,
    },
    /// The classical reduction gives no start.
    #[error("the classical reduction gives no usable start")]
    Start,
    /// The solver ended where the model has no value.
    #[error("the joint fit ends outside the valid region (no no-load operating point for its parameters)")]
    Invalid,
}

/// The warmest the winding may be in the AC tests above the DC reading,
/// K: the upper bound of `Rs`.
pub const MAX_WINDING_RISE_K: f64 = 60.0;

/// The least the lower bound of `Rs` lies below the DC reading, as a
/// share of it.
const RS_BELOW_DC: f64 = 0.001;

/// The least friction and windage the fit holds, W (its logarithm is
/// fitted).
pub const MIN_FRICTION_W: f64 = 1e-3;

/// Residual evaluations the solver may make (each Jacobian costs one per
/// parameter and one more).
pub const MAX_EVALUATIONS: usize = 3_000;

/// Relative step of the finite-difference Jacobian.
const STEP: f64 = 1e-6;

/// The parameters fitted: `Rs` (bounded), then `ln Xr`, `ln Xm`,
/// `ln Rfe`, `ln Rr`, `ln Pfw`.
const Q: usize = 6;

/// What a reading is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Test {
    /// A load point at its measured slip.
    Load(f64),
    /// A locked-rotor reading.
    LockedRotor,
    /// A no-load reading (slip not measured).
    NoLoad,
}

/// One reading in per-phase-independent terms.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Reading {
    test: Test,
    line_voltage: f64,
    line_current: f64,
    input_power: f64,
    frequency: f64,
    /// The reading's stator resistance over the fitted `Rs` (its winding
    /// temperature against `Rs`'s).
    rs_scale: f64,
}

/// The joint fit's result.
#[derive(Debug, Clone, PartialEq)]
pub struct JointFit {
    /// The circuit, Ω per phase at rated frequency.
    pub circuit: ImCircuit,
    /// Friction and windage, W.
    pub friction_windage: f64,
    /// The contract's parameters with their 95 % intervals.
    pub params: BTreeMap<String, ParamEstimate>,
    /// RMS of the relative residuals of current and power.
    pub rms_relative: f64,
    /// What a user should know.
    pub warnings: Vec<String>,
}

struct JointProblem<'a> {
    readings: &'a [Reading],
    connection: Connection,
    rated_frequency: f64,
    /// `Xs/Xr`.
    ratio: f64,
    rs_bounds: (f64, f64),
    evaluations: Cell<usize>,
}

impl JointProblem<'_> {
    fn rs(&self, z: f64) -> f64 {
        let (lo, hi) = self.rs_bounds;
        lo + (hi - lo) * 0.5 * (1.0 + z.tanh())
    }

    /// `d Rs / d z`.
    fn rs_slope(&self, z: f64) -> f64 {
        let (lo, hi) = self.rs_bounds;
        0.5 * (hi - lo) * (1.0 - z.tanh().powi(2))
    }

    fn unpack(&self, x: &DVector<f64>) -> Option<(ImCircuit, f64)> {
        let e = |k: usize| Some(x[k].exp()).filter(|v| v.is_finite() && *v > 0.0);
        let xr = e(1)?;
        let circuit = ImCircuit {
            rs: self.rs(x[0]),
            xs: self.ratio * xr,
            xm: e(2)?,
            rfe: Some(e(3)?),
            rotor: RotorCage::Single { rr: e(4)?, xr },
        };
        Some((circuit, e(5)?.max(MIN_FRICTION_W)))
    }

    /// Line current and input power of `r` on circuit `c` with friction
    /// `pfw`.
    fn model(&self, c: &ImCircuit, pfw: f64, r: &Reading) -> Option<(f64, f64)> {
        let mut at = at_frequency(c, r.frequency / self.rated_frequency);
        at.rs *= r.rs_scale;
        let supply = ImSupply {
            line_voltage: r.line_voltage,
            frequency: r.frequency,
            connection: self.connection,
            pole_pairs: 1,
        };
        let at_slip = |s: f64| {
            let op = at.operating_point(&supply, s);
            (op.line_current, op.input_power)
        };
        match r.test {
            Test::Load(s) => Some(at_slip(s)),
            Test::LockedRotor => Some(at_slip(1.0)),
            Test::NoLoad => no_load_reading(&at, self.connection, r.line_voltage, pfw)
                .map(|n| (n.line_current, n.input_power)),
        }
    }
}

impl Residuals for JointProblem<'_> {
    fn rows(&self) -> usize {
        2 * self.readings.len()
    }

    fn residuals_at(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
        self.evaluations.set(self.evaluations.get() + 1);
        let (c, pfw) = self.unpack(x)?;
        let mut out = DVector::zeros(2 * self.readings.len());
        for (k, r) in self.readings.iter().enumerate() {
            let (i, p) = self.model(&c, pfw, r)?;
            out[2 * k] = i / r.line_current - 1.0;
            out[2 * k + 1] = p / r.input_power - 1.0;
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    fn jacobian_at(&self, x: &DVector<f64>) -> Option<DMatrix<f64>> {
        let r0 = self.residuals_at(x)?;
        let mut jac = DMatrix::zeros(r0.len(), Q);
        for j in 0..Q {
            let h = STEP * x[j].abs().max(1.0);
            let mut xh = x.clone();
            xh[j] += h;
            let r = self.residuals_at(&xh)?;
            jac.set_column(j, &((r - &r0) / h));
        }
        Some(jac)
    }
}

/// The readings of the load test, the locked-rotor and the no-load tests;
/// a reading without a frequency takes `rated_frequency`; one with a
/// winding temperature (a load point's included) sees `Rs` (at
/// `rs_temperature`) scaled to it.
fn readings(
    points: &[OperatingPoint],
    tests: &ImStandardTests,
    rated_frequency: f64,
    rs_temperature: Option<f64>,
) -> Vec<Reading> {
    let f = |f: f64| {
        if f.is_finite() && f > 0.0 {
            f
        } else {
            rated_frequency
        }
    };
    let load = points.iter().map(|p| Reading {
        test: Test::Load(p.slip),
        line_voltage: p.line_voltage,
        line_current: p.line_current,
        input_power: p.input_power,
        frequency: f(p.frequency),
        rs_scale: temperature_factor(rs_temperature, p.winding_temperature),
    });
    let supply = |test: Test| {
        move |r: &crate::record::SupplyReading| Reading {
            test,
            line_voltage: r.line_voltage,
            line_current: r.line_current,
            input_power: r.input_power,
            frequency: f(r.frequency),
            rs_scale: temperature_factor(rs_temperature, r.winding_temperature),
        }
    };
    load.chain(tests.locked_rotor.iter().map(supply(Test::LockedRotor)))
        .chain(tests.no_load.iter().map(supply(Test::NoLoad)))
        .filter(|r| r.line_current > 0.0 && r.input_power > 0.0 && r.line_voltage > 0.0)
        .collect()
}

/// Fit the circuit to the record's load points and standard tests, from
/// the classical `reduction` (its `Rs` the DC reading), the winding
/// connected as `connection`, the leakage split `split`, reactances
/// reported at `rated_frequency`. `Err` says why the fit cannot run.
pub fn fit_joint(
    points: &[OperatingPoint],
    tests: &ImStandardTests,
    reduction: &StandardTestsReduction,
    connection: Connection,
    split: LeakageSplit,
    rated_frequency: f64,
) -> Result<JointFit, JointFitError> {
    let data = readings(points, tests, rated_frequency, reduction.rs_temperature);
    let m = 2 * data.len();
    if m <= Q {
        return Err(JointFitError::TooFew {
            readings: data.len(),
            min: Q / 2,
        });
    }
    let start = &reduction.circuit;
    let RotorCage::Single { rr, xr } = start.rotor else {
        return Err(JointFitError::Start);
    };
    let rs_dc = start.rs;
    let below = reduction
        .params
        .get("Rs")
        .and_then(|p| p.ci95)
        .map_or(0.0, |[lo, _]| rs_dc - lo)
        .max(RS_BELOW_DC * rs_dc);
    let rs_bounds = (
        rs_dc - below,
        rs_dc * (1.0 + COPPER_ALPHA * MAX_WINDING_RISE_K),
    );
    let share = split.stator_share;
    let ratio = share / (1.0 - share);
    let pfw0 = reduction
        .params
        .get("Pfw")
        .map_or(1.0, |p| p.value)
        .max(1.0);
    let rfe0 = start.rfe.unwrap_or(100.0 * start.xm);
    // Rs starts at the DC reading, inside its bounds.
    let z0 = (2.0 * (rs_dc - rs_bounds.0) / (rs_bounds.1 - rs_bounds.0) - 1.0).atanh();
    let x0 = DVector::from_vec(vec![
        z0,
        (xr.max(1e-6)).ln(),
        start.xm.ln(),
        rfe0.ln(),
        rr.ln(),
        pfw0.ln(),
    ]);
    if x0.iter().any(|v| !v.is_finite()) {
        return Err(JointFitError::Start);
    }
    let problem = AtParams {
        problem: JointProblem {
            readings: &data,
            connection,
            rated_frequency,
            ratio,
            rs_bounds,
            evaluations: Cell::new(0),
        },
        x: x0,
    };
    let solver = LevenbergMarquardt::new()
        .with_patience(MAX_EVALUATIONS / (Q + 1))
        .with_tol(1e-12);
    let (problem, report) = solver.minimize(problem);
    let x = problem.x.clone();
    let (circuit, pfw) = problem.unpack(&x).ok_or(JointFitError::Invalid)?;
    let r = problem.residuals_at(&x).ok_or(JointFitError::Invalid)?;
    let rss = r.norm_squared();
    let mut warnings = vec![format!(
        "joint: Xs = {ratio:.4} × Xr, the leakage split Xs/(Xs + Xr) = {share} of the \
         nameplate's design class (a convention: terminal readings at one frequency do not \
         separate the two leakages)"
    )];
    if let Some(t) = reduction.rs_temperature {
        let scaled: Vec<f64> = data.iter().map(|r| r.rs_scale).collect();
        let (lo, hi) = scaled
            .iter()
            .fold((1.0f64, 1.0f64), |(a, b), &k| (a.min(k), b.max(k)));
        if hi - lo > 1e-9 {
            let load = points.len();
            let load_warm = points
                .iter()
                .filter(|p| p.winding_temperature.is_some())
                .count();
            let load_note = match (load, load_warm) {
                (0, _) => String::new(),
                (n, k) if k == n => "; so does each load point".to_string(),
                (_, 0) => {
                    "; the load test's points carry no temperature and see it as it is".to_string()
                }
                (n, k) => format!(
                    "; so do {k} of the {n} load points, the others (without a temperature) see \
                     it as it is"
                ),
            };
            warnings.push(format!(
                "joint: Rs is at the winding's {t:.1} °C; each no-load and locked-rotor reading \
                 sees it scaled to its own temperature (copper, × {lo:.4} … {hi:.4}){load_note}"
            ));
        }
    }
    if report.termination == TerminationReason::LostPatience {
        warnings.push(format!(
            "joint: stopped at its bound of {MAX_EVALUATIONS} residual evaluations before \
             converging: the parameters are the last iterate"
        ));
    } else if !report.termination.was_successful() {
        warnings.push(format!(
            "joint: the solver ended with {:?}",
            report.termination
        ));
    }
    let (lo, hi) = rs_bounds;
    let at_bound = |v: f64, b: f64| (v - b).abs() <= 1e-3 * b;
    let rs_at_bound = at_bound(circuit.rs, lo) || at_bound(circuit.rs, hi);
    if rs_at_bound {
        warnings.push(format!(
            "joint: Rs = {:.5} ohm sits at its bound [{lo:.5}, {hi:.5}] ohm (the DC reading \
             {rs_dc:.5} ohm less its error, to a winding {MAX_WINDING_RISE_K} K warmer): the AC \
             readings alone would put it outside, the DC reading holds it",
            circuit.rs
        ));
    }
    // Intervals from the Jacobian at the solution; `Rs` at its bound
    // (where the map is flat) is held there and gets none.
    let dof = m - Q;
    let sigma2 = rss / dof as f64;
    let free: Vec<usize> = (usize::from(rs_at_bound)..Q).collect();
    let se: Option<Vec<f64>> = problem.jacobian().and_then(|j| {
        let j = j.select_columns(&free);
        let cov = (j.transpose() * j).try_inverse()?;
        let mut se = vec![f64::NAN; Q];
        for (a, &k) in free.iter().enumerate() {
            se[k] = Some((sigma2 * cov[(a, a)]).sqrt()).filter(|v| v.is_finite())?;
        }
        Some(se)
    });
    let t = t975(dof);
    let log_estimate = |value: f64, k: usize, unit: &str| ParamEstimate {
        value,
        ci95: se
            .as_ref()
            .map(|s| [value * (-t * s[k]).exp(), value * (t * s[k]).exp()]),
        unit: unit.into(),
    };
    let RotorCage::Single { rr, xr } = circuit.rotor else {
        unreachable!("the joint fit's circuit is a single cage")
    };
    let mut params = BTreeMap::new();
    let rs_hw = se
        .as_ref()
        .map(|s| t * problem.rs_slope(x[0]).abs() * s[0])
        .filter(|h| h.is_finite());
    params.insert(
        "Rs".to_string(),
        ParamEstimate {
            value: circuit.rs,
            ci95: rs_hw.map(|h| [(circuit.rs - h).max(lo), (circuit.rs + h).min(hi)]),
            unit: "ohm".into(),
        },
    );
    params.insert("Xr".into(), log_estimate(xr, 1, "ohm"));
    params.insert("Xs".into(), log_estimate(circuit.xs, 1, "ohm"));
    params.insert("Xm".into(), log_estimate(circuit.xm, 2, "ohm"));
    if let Some(rfe) = circuit.rfe {
        params.insert("Rfe".into(), log_estimate(rfe, 3, "ohm"));
    }
    params.insert("Rr".into(), log_estimate(rr, 4, "ohm"));
    params.insert("Pfw".into(), log_estimate(pfw, 5, "W"));
    Ok(JointFit {
        circuit,
        friction_windage: pfw,
        params,
        rms_relative: (rss / m as f64).sqrt(),
        warnings,
    })
}

/// The method's report and the warnings to add, for a record whose
/// standard tests were reduced (`reduction`); `None` without one.
pub fn joint_method(
    points: &[OperatingPoint],
    tests: &ImStandardTests,
    reduction: Option<&StandardTestsReduction>,
    connection: Connection,
    split: LeakageSplit,
    rated_frequency: f64,
) -> Option<(MethodReport, Vec<String>)> {
    let reduction = reduction?;
    Some(
        match fit_joint(points, tests, reduction, connection, split, rated_frequency) {
            Ok(fit) => {
                let mut warnings = fit.warnings;
                warnings.push(format!(
                    "joint: rms relative residual {:.3} % over {} readings of current and power",
                    100.0 * fit.rms_relative,
                    points.len() + tests.no_load.len() + tests.locked_rotor.len()
                ));
                (MethodReport::fitted(fit.params, None), warnings)
            }
            Err(why) => (MethodReport::not_applicable(why.to_string()), Vec::new()),
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{slip_grid, SlipSweep, SweepNoise};
    use crate::machine::im::assert_warned;
    use crate::machine::im::identify::reduce_standard_tests;
    use crate::machine::im::identify::StandardTestsOptions;
    use crate::model::im_fixtures::{single_cage, STAR_400V_50HZ};
    use crate::model::{locked_rotor_reading, terminal_resistance};
    use crate::record::{DcResistanceReading, SupplyReading};

    const PFW: f64 = 45.0;

    /// Star, 400 V, 50 Hz, Xs = Xr.
    fn machine() -> ImCircuit {
        single_cage(0.9, 1.8, 60.0, Some(900.0), 1.1, 1.8)
    }

    /// Noise-free standard tests of `c`, the DC reading scaled by `dc`.
    fn tests_of(c: &ImCircuit, dc: f64) -> ImStandardTests {
        let conn = Connection::Star;
        let supply = |segment, r: crate::model::StandardReading| SupplyReading {
            segment,
            line_voltage: r.line_voltage,
            line_current: r.line_current,
            input_power: r.input_power,
            frequency: 50.0,
            winding_temperature: None,
        };
        ImStandardTests {
            dc_resistance: [2.0, 4.0]
                .map(|i| DcResistanceReading {
                    segment: 0,
                    dc_voltage: dc * i * terminal_resistance(c.rs, conn),
                    dc_current: i,
                    winding_temperature: None,
                })
                .to_vec(),
            no_load: [440.0, 400.0, 320.0, 240.0, 200.0, 160.0, 120.0]
                .iter()
                .map(|&v| supply(1, no_load_reading(c, conn, v, PFW).unwrap()))
                .collect(),
            locked_rotor: [30.0, 45.0, 60.0]
                .iter()
                .map(|&v| supply(2, locked_rotor_reading(c, conn, v, 50.0, 50.0)))
                .collect(),
        }
    }

    fn load_points(c: &ImCircuit) -> Vec<OperatingPoint> {
        SlipSweep::simulate_seeded(
            c,
            &STAR_400V_50HZ,
            &slip_grid(20, 0.005),
            &SweepNoise::relative(0.0),
            1,
        )
        .operating_points(50.0)
    }

    fn fit(tests: &ImStandardTests, points: &[OperatingPoint]) -> Result<JointFit, JointFitError> {
        let opts = StandardTestsOptions {
            rated_voltage: Some(400.0),
            rated_frequency: Some(50.0),
            ..Default::default()
        };
        let reduction = reduce_standard_tests(tests, Connection::Star, &opts).unwrap();
        fit_joint(
            points,
            tests,
            &reduction,
            Connection::Star,
            LeakageSplit::default(),
            50.0,
        )
    }

    #[test]
    fn noise_free_tests_and_load_points_give_back_the_circuit_and_its_friction() {
        let c = machine();
        let f = fit(&tests_of(&c, 1.0), &load_points(&c)).unwrap();
        let RotorCage::Single { rr, xr } = f.circuit.rotor else {
            unreachable!()
        };
        for (name, got, truth) in [
            ("Rs", f.circuit.rs, c.rs),
            ("Xs", f.circuit.xs, c.xs),
            ("Xm", f.circuit.xm, c.xm),
            ("Rfe", f.circuit.rfe.unwrap(), 900.0),
            ("Rr", rr, 1.1),
            ("Xr", xr, 1.8),
            ("Pfw", f.friction_windage, PFW),
        ] {
            assert!((got / truth - 1.0).abs() < 1e-4, "{name}: {got} vs {truth}");
            let p = &f.params[name];
            assert_eq!(p.value, got);
        }
        assert!(f.rms_relative < 1e-6, "{}", f.rms_relative);
        assert!(f.warnings.iter().any(|w| w.contains("leakage split")));
        assert!(
            !f.warnings.iter().any(|w| w.contains("bound")),
            "{:?}",
            f.warnings
        );
    }

    #[test]
    fn a_dc_reading_far_above_the_ac_tests_holds_rs_at_its_bound_and_says_so() {
        // The DC reading says 30 % more than the winding has: Rs cannot
        // go below it (less 0.1 %: noise-free readings give no interval),
        // and the fit says so.
        let c = machine();
        let f = fit(&tests_of(&c, 1.3), &load_points(&c)).unwrap();
        assert!(
            (f.circuit.rs / (1.3 * 0.9 * 0.999) - 1.0).abs() < 1e-3,
            "{}",
            f.circuit.rs
        );
        assert_warned(&f.warnings, "sits at its bound");
        // Every element stays in its physical range all the same; Rs,
        // held at its bound, has no interval, the others have theirs.
        assert!(f
            .params
            .values()
            .all(|p| p.value > 0.0 && p.value.is_finite()));
        assert_eq!(f.params["Rs"].ci95, None);
        assert!(f.params["Xm"].ci95.is_some(), "{:?}", f.params);
    }

    #[test]
    fn readings_at_their_winding_temperatures_fit_with_rs_scaled_to_each() {
        // The DC reading at 20 °C, the no-load test with the winding at
        // 60 °C, the locked-rotor test at 40 °C, each reading saying so.
        let c = machine();
        let at = |t: f64| ImCircuit {
            rs: c.rs * (1.0 + COPPER_ALPHA * (t - 20.0)),
            ..c
        };
        let mut tests = tests_of(&c, 1.0);
        tests
            .dc_resistance
            .iter_mut()
            .for_each(|r| r.winding_temperature = Some(20.0));
        let with = |mut rs: Vec<SupplyReading>, t: f64| {
            rs.iter_mut().for_each(|r| r.winding_temperature = Some(t));
            rs
        };
        tests.no_load = with(tests_of(&at(60.0), 1.0).no_load, 60.0);
        tests.locked_rotor = with(tests_of(&at(40.0), 1.0).locked_rotor, 40.0);
        let f = fit(&tests, &[]).unwrap();
        let RotorCage::Single { rr, .. } = f.circuit.rotor else {
            unreachable!()
        };
        // Rs at the locked-rotor test's 40 °C.
        for (name, got, truth) in [
            ("Rs", f.circuit.rs, at(40.0).rs),
            ("Xm", f.circuit.xm, c.xm),
            ("Rfe", f.circuit.rfe.unwrap(), 900.0),
            ("Rr", rr, 1.1),
            ("Pfw", f.friction_windage, PFW),
        ] {
            assert!((got / truth - 1.0).abs() < 1e-4, "{name}: {got} vs {truth}");
        }
        assert!(f.rms_relative < 1e-6, "{}", f.rms_relative);
        assert_warned(&f.warnings, "scaled to its own temperature");
        // Without the no-load readings' temperatures they are fitted at
        // the locked-rotor test's and misfit (a little: the no-load
        // copper loss is small beside the core loss and the friction;
        // 1.4e-5 here, against under 1e-6).
        let mut unmarked = tests.clone();
        unmarked
            .no_load
            .iter_mut()
            .for_each(|r| r.winding_temperature = None);
        let g = fit(&unmarked, &[]).unwrap();
        assert!(
            g.rms_relative > 5e-6 && g.rms_relative > 10.0 * f.rms_relative,
            "{} against {}",
            g.rms_relative,
            f.rms_relative
        );
    }

    #[test]
    fn load_points_at_their_winding_temperature_see_rs_scaled_to_it() {
        // The DC reading at 20 °C, the locked-rotor and no-load tests at
        // 40 °C, then the load test with the winding warmed to 95 °C, each
        // point saying so: Rs back at 40 °C and the circuit exactly.
        let c = machine();
        let at = |t: f64| ImCircuit {
            rs: c.rs * (1.0 + COPPER_ALPHA * (t - 20.0)),
            ..c
        };
        let mut tests = tests_of(&at(40.0), 1.0);
        tests.dc_resistance = tests_of(&c, 1.0).dc_resistance;
        tests
            .dc_resistance
            .iter_mut()
            .for_each(|r| r.winding_temperature = Some(20.0));
        for r in tests.no_load.iter_mut().chain(&mut tests.locked_rotor) {
            r.winding_temperature = Some(40.0);
        }
        let mut warm = load_points(&at(95.0));
        warm.iter_mut()
            .for_each(|p| p.winding_temperature = Some(95.0));
        let f = fit(&tests, &warm).unwrap();
        let RotorCage::Single { rr, .. } = f.circuit.rotor else {
            unreachable!()
        };
        for (name, got, truth) in [
            ("Rs", f.circuit.rs, at(40.0).rs),
            ("Xm", f.circuit.xm, c.xm),
            ("Rr", rr, 1.1),
            ("Pfw", f.friction_windage, PFW),
        ] {
            assert!((got / truth - 1.0).abs() < 1e-4, "{name}: {got} vs {truth}");
        }
        assert!(f.rms_relative < 1e-6, "{}", f.rms_relative);
        assert_warned(&f.warnings, "so does each load point");
        // The same points without their temperature: fitted at 40 °C,
        // they pull Rs up (here to its bound, a winding 60 K warmer than
        // the DC reading) and misfit.
        let mut unmarked = warm.clone();
        unmarked
            .iter_mut()
            .for_each(|p| p.winding_temperature = None);
        let g = fit(&tests, &unmarked).unwrap();
        assert!(
            g.rms_relative > 10.0 * f.rms_relative.max(1e-7) && g.circuit.rs > f.circuit.rs,
            "{} against {}, Rs {} against {}",
            g.rms_relative,
            f.rms_relative,
            g.circuit.rs,
            f.circuit.rs
        );
    }

    #[test]
    fn too_few_readings_are_refused_with_a_reason() {
        let c = machine();
        let tests = tests_of(&c, 1.0);
        let opts = StandardTestsOptions::default();
        let reduction = reduce_standard_tests(&tests, Connection::Star, &opts).unwrap();
        let few = ImStandardTests {
            no_load: tests.no_load[..1].to_vec(),
            locked_rotor: tests.locked_rotor[..1].to_vec(),
            ..tests.clone()
        };
        let e = fit_joint(
            &[],
            &few,
            &reduction,
            Connection::Star,
            LeakageSplit::default(),
            50.0,
        )
        .unwrap_err();
        assert_eq!(
            e,
            JointFitError::TooFew {
                readings: 2,
                min: 3
            }
        );
        assert!(e.to_string().contains("needs more than 3"), "{e}");
    }
}
