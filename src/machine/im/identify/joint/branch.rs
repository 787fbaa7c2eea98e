//! Which magnetising branch the joint fit keeps: the T circuit's linear
//! one, the core loss across the stator flux instead, or the saturation
//! curve (the joint module's doc says when).

use levenberg_marquardt::{LevenbergMarquardt, MinimizationReport};
use nalgebra::DVector;
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use super::problem::{Branch, CurveFit, JointProblem, Test, Q};
use super::MAX_EVALUATIONS;
use crate::identify::least_squares::{AtParams, Residuals};
use crate::machine::im::identify::standard_tests::StandardTestsReduction;
use crate::model::im_effects::{saturation, SaturatingFlux, MAIN_FLUX_EXPONENT};

/// The significance at which the saturation curve enters the fit
/// (extra-sum-of-squares F test for its one or two parameters).
pub(super) const SATURATION_P: f64 = 1e-3;

/// The least fall of `Xm` at the no-load test's highest air-gap voltage,
/// `(E/Es)^n`, for saturation to count: a better fit with less is the
/// other form's placement of the core loss (across the stator flux), not
/// saturation, and the linear fit stays.
pub(super) const MIN_SATURATION: f64 = 0.01;

/// The share by which the Γ circuit's placement of the core loss must
/// lower the T circuit's sum of squares to replace it.
const PLACEMENT_GAIN: f64 = 0.01;

/// The fewest no-load readings the saturating fit needs: with `Pfw` and
/// `Rfe` the no-load test fixes three quantities of its own.
const SATURATION_MIN_NO_LOAD: usize = 3;

/// The fewest no-load readings the fit of the curve's exponent needs
/// (with fewer it is [`MAIN_FLUX_EXPONENT`]): the no-load test then fixes
/// `Xm`, `Es`, the exponent, `Rfe` and `Pfw` with a spare reading.
const EXPONENT_MIN_NO_LOAD: usize = 6;

/// The saturating fit's starts of `Es`, times the largest air-gap voltage
/// of the no-load test (the diagnosis' starts).
const ES_STARTS: [f64; 3] = [0.9, 1.2, 2.0];

/// The Levenberg–Marquardt fit of `problem` from `x0`, bounded by
/// [`MAX_EVALUATIONS`].
fn solve(
    problem: JointProblem<'_>,
    x0: DVector<f64>,
) -> (AtParams<JointProblem<'_>>, MinimizationReport<f64>) {
    let q = problem.q();
    LevenbergMarquardt::new()
        .with_patience(MAX_EVALUATIONS / (q + 1))
        .with_tol(1e-12)
        .minimize(AtParams { problem, x: x0 })
}

/// The fit of one branch, its report and its sum of squares.
pub(super) type Fitted<'a> = (AtParams<JointProblem<'a>>, MinimizationReport<f64>, f64);

/// The fit of `problem` from `x0` and its sum of squares; `None` where it
/// ends outside the valid region.
pub(super) fn fitted<'a>(problem: JointProblem<'a>, x0: DVector<f64>) -> Option<Fitted<'a>> {
    let (fit, report) = solve(problem, x0);
    let rss = fit.residuals_at(&fit.x)?.norm_squared();
    Some((fit, report, rss))
}

/// The magnetising branch the readings ask for (the module's doc), from
/// the T circuit's linear fit `linear`, with the warnings that say what
/// was chosen. Every other branch starts from the linear fit's start `x0`
/// (the reduction, whose `Xm` is at rated voltage): a linear fit with `Rs`
/// at a bound would hold it there.
///
/// 1. The core loss across the stator flux (the Γ circuit's placement)
///    replaces the T circuit's where its sum of squares is lower by more
///    than [`PLACEMENT_GAIN`] (a tie keeps the standards' T circuit).
/// 2. The saturation curve, in both forms, from each of [`ES_STARTS`],
///    replaces that where the F test and [`MIN_SATURATION`] say so.
pub(super) fn choose_branch<'a>(
    linear: Fitted<'a>,
    reduction: &StandardTestsReduction,
    x0: &DVector<f64>,
) -> (Fitted<'a>, Vec<String>) {
    let m = linear.0.rows();
    let rms = |rss: f64| 100.0 * (rss / m as f64).sqrt();
    let e_ref = reduction
        .rated_air_gap_voltage
        .filter(|e| e.is_finite() && *e > 0.0);
    let Some(e_ref) = e_ref else {
        return (linear, Vec::new());
    };
    let curve = |flux, fit| Branch::Curve { e_ref, flux, fit };
    let mut notes = Vec::new();
    let stator = linear.0.with(curve(SaturatingFlux::Stator, CurveFit::Held));
    let base = match fitted(stator, x0.clone()) {
        Some(g) if g.2 < (1.0 - PLACEMENT_GAIN) * linear.2 => {
            notes.push(format!(
                "joint: the core loss fits these readings better across the stator flux (behind \
                 Rs alone, the Γ circuit's placement) than across the air-gap voltage: rms \
                 relative residual {:.3} % against {:.3} %; Rfe is given as the T circuit's that \
                 draws the same loss at rated voltage",
                rms(g.2),
                rms(linear.2)
            ));
            g
        }
        _ => linear,
    };
    let no_load = base
        .0
        .readings
        .iter()
        .filter(|r| r.test == Test::NoLoad)
        .count();
    let shape = if no_load >= EXPONENT_MIN_NO_LOAD {
        CurveFit::KneeAndExponent
    } else {
        CurveFit::Knee
    };
    let q = base.0.with(curve(SaturatingFlux::AirGap, shape)).q();
    if no_load < SATURATION_MIN_NO_LOAD || m <= q {
        return (base, notes);
    }
    let e_max = reduction
        .tables
        .no_load
        .iter()
        .map(|r| r.air_gap_voltage)
        .fold(e_ref, f64::max);
    let best = [SaturatingFlux::AirGap, SaturatingFlux::Stator]
        .into_iter()
        .flat_map(|flux| ES_STARTS.map(|k| (flux, k)))
        .filter_map(|(flux, k)| {
            let start = x0.clone().insert_row(Q, (k * e_max).ln());
            let knee = fitted(base.0.with(curve(flux, CurveFit::Knee)), start)?;
            if shape == CurveFit::Knee {
                return Some(knee);
            }
            // The exponent from the fit at the diagnosis' exponent, `Rs`
            // back at the DC reading (a plant of another exponent may
            // have pushed it to a bound, where its map is flat).
            let mut start = knee.0.x.clone();
            start[0] = x0[0];
            let n = f64::from(MAIN_FLUX_EXPONENT);
            let start = start.insert_row(Q + 1, JointProblem::exponent_entry(n));
            fitted(base.0.with(curve(flux, shape)), start)
        })
        .min_by(|a, b| a.2.total_cmp(&b.2));
    let Some(sat) = best else {
        return (base, notes);
    };
    let (rss0, rss1) = (base.2, sat.2);
    let (df1, df2) = ((q - Q) as f64, (m - q) as f64);
    let f = (rss0 - rss1) / df1 / (rss1 / df2);
    let p = match FisherSnedecor::new(df1, df2) {
        Ok(d) if f.is_finite() => d.sf(f.max(0.0)),
        _ if rss1 < rss0 => 0.0,
        _ => 1.0,
    };
    let fit = &sat.0;
    let (Some(es), Some((circuit, _))) = (fit.fitted_knee(&fit.x), fit.unpack(&fit.x)) else {
        return (base, notes);
    };
    let n = fit.exponent(&fit.x);
    if p >= SATURATION_P || saturation(e_max / es, n) < MIN_SATURATION {
        return (base, notes);
    }
    let xm_u = fit.unsaturated_xm(&circuit, (es, n)).unwrap_or(f64::NAN);
    let exponent = if shape == CurveFit::KneeAndExponent {
        format!("{n:.3} (saturation_exponent)")
    } else {
        format!("{n} (fixed: fewer than {EXPONENT_MIN_NO_LOAD} no-load readings)")
    };
    let form = match fit.branch {
        Branch::Curve { flux, .. } if fit.core_loss_on_stator_flux() => {
            format!("{}, the core loss across it too", flux.name())
        }
        Branch::Curve { flux, .. } => flux.name().to_string(),
        Branch::Linear => String::new(),
    };
    let note = format!(
        "joint: Xm falls with the voltage (main-flux saturation, from the {no_load} no-load \
         readings: the rms relative residual {:.3} % with one Xm, {:.3} % with the curve, F test \
         p = {p:.1e}): Xm(E) = Xm_u/(1 + (E/Es)^n) on {form}, Xm_u = {xm_u:.5} ohm \
         (Xm_unsaturated), Es = {es:.5} V per phase at rated frequency, n = {exponent}; Xm is \
         the one the no-load test shows at rated voltage, as the classical reduction takes it",
        rms(rss0),
        rms(rss1)
    );
    (sat, vec![note])
}
