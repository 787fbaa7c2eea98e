//! The joint fit of the standard tests (method `joint`): the single-cage
//! circuit with core loss, and friction and windage, fitted by
//! Levenberg–Marquardt to every reading of the record at once — the load
//! test's points at their measured slip, the locked-rotor readings at
//! slip 1 (their reactances scaled to their frequency), and the no-load
//! readings at the slip where the air-gap power less the rotor copper
//! loss covers friction and windage (the slip is not measured: it follows
//! from the parameters, [`crate::model::no_load_reading`]).
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
//! - **Main-flux saturation.** A real machine's `Xm` falls with the
//!   voltage, and a no-load test from 30 % to 115 % of rated voltage sees
//!   it fall by a third or more; one constant `Xm` then misfits that test
//!   by several per cent and pushes `Rs` to a bound. With three no-load
//!   readings or more the fit is also run with the diagnosis' saturation
//!   curve, `Xm(E) = Xm_u/(1 + (E/Es)^n)`, `ln Es` one parameter more
//!   and the exponent `n` another where six no-load readings or more
//!   fix the curve's shape (else `n` = 7, the diagnosis' exponent),
//!   in both of its forms ([`crate::model::im_effects`]: the T circuit's
//!   `Xm` on the air-gap voltage, or the Γ circuit's stator inductance on
//!   the stator flux), the better fit kept. `Xm` is then reported as the
//!   no-load test shows it at rated voltage (the classical reduction's
//!   formula on the fitted model), `Xm_u` as `Xm_unsaturated`. The curve
//!   is kept where it lowers the sum of squares beyond chance
//!   (extra-sum-of-squares F test, p < [`branch::SATURATION_P`], 10⁻³) and `Xm` falls
//!   by at least [`branch::MIN_SATURATION`], 1 % within the test's voltages; a warning
//!   says so and gives `Es` and `Xm_u`.

use std::cell::Cell;
use std::collections::BTreeMap;

use levenberg_marquardt::{LeastSquaresProblem, TerminationReason};
use nalgebra::DVector;

use super::standard_tests::{temperature_factor, StandardTestsReduction};
use crate::contract::{MethodReport, ParamEstimate};
use crate::identify::least_squares::Residuals;
use crate::identify::stats::t975;
use crate::machine::im::COPPER_ALPHA;
use crate::model::{Connection, ImCircuit, LeakageSplit, RotorCage};
use crate::record::{ImStandardTests, OperatingPoint};

mod branch;
mod covariance;
mod problem;
#[cfg(test)]
mod tests;

use branch::{choose_branch, fitted};
use covariance::Covariance;
use problem::{Branch, CurveFit, JointProblem, Reading, Test, Q};

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
    let linear = JointProblem {
        readings: &data,
        connection,
        rated_frequency,
        ratio,
        rs_bounds,
        branch: Branch::Linear,
        evaluations: Cell::new(0),
    };
    let linear = fitted(linear, x0.clone()).ok_or(JointFitError::Invalid)?;
    let ((problem, report, _), branch_notes) = choose_branch(linear, reduction, &x0);
    let q = problem.q();
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
    warnings.extend(branch_notes);
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
    // Intervals from the Jacobian at the solution.
    let dof = m - q;
    let t = t975(dof);
    let cov = problem
        .jacobian()
        .and_then(|j| Covariance::of(&j, rs_at_bound, rss / dof as f64));
    let se = |k: usize| cov.as_ref().and_then(|c| c.se(k));
    let log_interval =
        |value: f64, se: Option<f64>| se.map(|s| [value * (-t * s).exp(), value * (t * s).exp()]);
    let log_estimate = |value: f64, k: usize, unit: &str| ParamEstimate {
        value,
        ci95: log_interval(value, se(k)),
        unit: unit.into(),
    };
    let RotorCage::Single { rr, xr } = circuit.rotor else {
        unreachable!("the joint fit's circuit is a single cage")
    };
    let mut params = BTreeMap::new();
    let rs_hw = se(0)
        .map(|s| t * problem.rs_slope(x[0]).abs() * s)
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
    // A saturating `Xm` is reported as the no-load test sees it at rated
    // voltage, and unsaturated beside it (each with the interval its
    // gradient carries).
    let derived = |f: &dyn Fn(&DVector<f64>) -> Option<f64>| -> Option<ParamEstimate> {
        let value = f(&x)?;
        let se = cov.as_ref().and_then(|c| c.se_of(&x, value, f));
        Some(ParamEstimate {
            value,
            ci95: log_interval(value, se),
            unit: "ohm".into(),
        })
    };
    let mut circuit = circuit;
    match problem.fitted_knee(&x) {
        Some(es) => {
            let rated = |x: &DVector<f64>| problem.rated_xm(x, reduction.rated_voltage);
            let unsaturated = |x: &DVector<f64>| {
                let (c, _) = problem.unpack(x)?;
                problem.unsaturated_xm(&c, problem.curve(x)?)
            };
            let xm = derived(&rated).ok_or(JointFitError::Invalid)?;
            circuit.xm = xm.value;
            params.insert("Xm".into(), xm);
            params.extend(derived(&unsaturated).map(|p| ("Xm_unsaturated".to_string(), p)));
            params.insert("Es".into(), log_estimate(es, Q, "V"));
            if let Branch::Curve {
                fit: CurveFit::KneeAndExponent,
                ..
            } = problem.branch
            {
                // The exponent's interval through its logistic map.
                let n = |z: f64| {
                    let mut at = x.clone();
                    at[Q + 1] = z;
                    problem.exponent(&at)
                };
                let z = x[Q + 1];
                params.insert(
                    "saturation_exponent".into(),
                    ParamEstimate {
                        value: problem.exponent(&x),
                        ci95: se(Q + 1).map(|s| [n(z - t * s), n(z + t * s)]),
                        unit: "1".into(),
                    },
                );
            }
        }
        None => {
            params.insert("Xm".into(), log_estimate(circuit.xm, 2, "ohm"));
        }
    }
    // A core loss the readings do not show runs off without limit: no
    // `Rfe`, as the classical reduction gives none without a core loss.
    let no_core_loss = cov.as_ref().is_some_and(|c| c.unmoved(3));
    match circuit.rfe {
        Some(_) if no_core_loss => warnings.push(
            "joint: the readings show no core loss (Rfe grew without limit and moves no \
             reading): no Rfe"
                .into(),
        ),
        Some(_) if problem.core_loss_on_stator_flux() => {
            let equivalent =
                |x: &DVector<f64>| problem.t_equivalent_rfe(x, reduction.rated_voltage);
            let rfe = derived(&equivalent).ok_or(JointFitError::Invalid)?;
            circuit.rfe = Some(rfe.value);
            params.insert("Rfe".into(), rfe);
        }
        Some(rfe) => {
            params.insert("Rfe".into(), log_estimate(rfe, 3, "ohm"));
        }
        None => {}
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
