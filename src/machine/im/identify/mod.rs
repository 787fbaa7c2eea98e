//! Induction-machine identification of a record: the operating points of
//! its `im_slip_sweep` segments in, the contract report (methods
//! `recursive` and `lm`) out; and, when the record holds the standard
//! tests (`im_dc_resistance`, `im_no_load`, `im_locked_rotor`), their
//! classical reduction, method `standard_tests` ([`reduce_standard_tests`]).
//!
//! - `lm` ([`fit_lm`]): parameters in Ω with 95 % intervals; an element the
//!   data do not determine is left out of `params` and named in the
//!   warnings; `Xs` under the leakage-split convention is reported with a
//!   warning that says so. `validation_nrmse` is the mean, over segments, of
//!   the NRMSE of current and power on a segment left out of the fit (it
//!   needs two segments, e.g. sweeps at two voltages).
//! - `recursive` ([`recursive_estimate`]): the seed paper's estimator as
//!   printed, run in per unit (the paper's threshold `J < 10⁻⁴` only means
//!   something there) from the first classical start; it applies when it
//!   ends with physical parameters; no intervals.

mod classical;
mod error;
mod identifiability;
mod joint;
mod lm;
mod lm_solver;
mod plausibility;
mod recursive;
mod standard_tests;
mod sweep;

pub use classical::{classical_single, classical_starts};
pub use error::{ImFitError, SweepError};
pub use identifiability::{weak_directions, Identifiability, WeakDirection, STRUCTURAL_LIMIT};
pub use joint::{
    fit_joint, joint_method, JointFit, JointFitError, JOINT, MAX_EVALUATIONS, MAX_WINDING_RISE_K,
    MIN_FRICTION_W,
};
pub use lm::{
    evaluation_bound, fit_lm, FittedParam, LmFit, LmOptions, ParamSource, ResidualScale,
    SplitPolicy, PRACTICAL_LIMIT, SOLVE_POINT_EVALUATIONS, SVD_MAX_ITERATIONS,
};
pub use plausibility::{check_input_power, ImplausiblePower};
pub use recursive::{
    paper_cost, recursive_estimate, recursive_pass, Innovation, RecursiveEstimate,
    RecursiveOptions, RecursiveStop, THETA_DOUBLE_L5, THETA_DOUBLE_L7, THETA_SINGLE_FE_L6,
    THETA_SINGLE_L4,
};
pub use standard_tests::{
    no_load_friction, reduce_standard_tests, standard_tests_method, NoLoadFriction,
    StandardTestsError, StandardTestsOptions, StandardTestsReduction, FRICTION_VOLTAGE_SHARE,
    STANDARD_TESTS,
};
pub use sweep::{
    predict, predict_gradient, predict_gradient_into, slip_grid, Channels, PhaseData, SlipSweep,
    SweepNoise, SweepPoint, MAX_PARAMS,
};

use crate::identify::nrmse;
use crate::model::{Connection, ImCircuit, ImModel, LeakageSplit, PerUnitBase};
use crate::record::{Record, SegmentKind};
use crate::report::{IdentificationReport, MethodReport, ParamEstimate};

/// Everything induction-machine identification produced.
#[derive(Debug, Clone, PartialEq)]
pub struct ImIdentification {
    /// The report per the data contract.
    pub report: IdentificationReport,
    /// The sweep the fits used.
    pub sweep: SlipSweep,
    /// The per-unit base used for the recursive estimator and the text
    /// report (rated values from the nameplate, else from the data).
    pub base: Option<PerUnitBase>,
    /// The Levenberg–Marquardt fit, when it ran.
    pub lm: Option<LmFit>,
    /// The recursive estimate, when it ran (circuit in Ω).
    pub recursive: Option<RecursiveEstimate>,
}

/// The nameplate's number under `key`, where the record has one.
pub(crate) fn nameplate_number(record: &Record, key: &str) -> Option<f64> {
    record.meta.as_ref()?.nameplate.get(key)?.as_f64()
}

/// The standard tests' options from the nameplate: rated voltage and
/// frequency, and the leakage split from its NEMA design class
/// (`"design"`: `A`–`D`, `wound`, or a share such as `0.45`).
fn standard_tests_options(record: &Record, warnings: &mut Vec<String>) -> StandardTestsOptions {
    let design = record
        .meta
        .as_ref()
        .and_then(|m| m.nameplate.get("design"))
        .and_then(|v| v.as_str());
    let split = match design.map(|d| (d, LeakageSplit::parse(d))) {
        Some((_, Some(split))) => split,
        Some((d, None)) if !record.standard_tests.is_empty() => {
            warnings.push(format!(
                "standard_tests: the nameplate's design {d:?} is not a NEMA class (A, B, C, D,                  wound) nor a share in (0, 1): the 0.5/0.5 leakage split is used"
            ));
            LeakageSplit::default()
        }
        _ => LeakageSplit::default(),
    };
    StandardTestsOptions {
        split,
        rated_voltage: nameplate_number(record, "voltage_V"),
        rated_frequency: nameplate_number(record, "frequency_Hz"),
    }
}

/// The connection to use: the caller's, else the nameplate's.
fn connection_of(
    record: &Record,
    given: Option<Connection>,
    warnings: &mut Vec<String>,
) -> Connection {
    if let Some(c) = given {
        return c;
    }
    let from_plate = record
        .meta
        .as_ref()
        .and_then(|m| m.nameplate.get("connection"))
        .and_then(|v| v.as_str())
        .and_then(Connection::parse);
    from_plate.unwrap_or_else(|| {
        warnings.push(
            "no winding connection given (--connection or the nameplate's \"connection\"): star assumed; \
             per-phase impedances scale by 3 between star and delta"
                .into(),
        );
        Connection::Star
    })
}

/// The sweep of `record`'s operating points.
pub fn sweep_of(record: &Record, connection: Connection) -> SlipSweep {
    let points: Vec<SweepPoint> = record
        .operating_points
        .iter()
        .map(|p| SweepPoint {
            segment: p.segment,
            slip: p.slip,
            line_voltage: p.line_voltage,
            line_current: p.line_current,
            input_power: p.input_power,
            torque: p.torque,
            winding_temperature: p.winding_temperature,
        })
        .collect();
    let frequency = record
        .operating_points
        .iter()
        .map(|p| p.frequency)
        .find(|f| f.is_finite());
    SlipSweep {
        connection,
        frequency,
        reference_temperature: SlipSweep::first_temperature(&points),
        points,
    }
}

fn params_of(
    values: &[(String, f64, Option<[f64; 2]>)],
) -> std::collections::BTreeMap<String, ParamEstimate> {
    values
        .iter()
        .map(|(k, v, ci)| {
            (
                k.clone(),
                ParamEstimate {
                    value: *v,
                    ci95: *ci,
                    unit: "ohm".into(),
                },
            )
        })
        .collect()
}

/// Mean NRMSE of current and power of `c` on `points`.
fn sweep_nrmse(c: &ImCircuit, sweep: &SlipSweep, segment: u32) -> Option<f64> {
    let part = SlipSweep {
        points: sweep
            .points
            .iter()
            .copied()
            .filter(|p| p.segment == segment)
            .collect(),
        ..sweep.clone()
    };
    let d = part.phase_data();
    let (mut i, mut p) = (Vec::new(), Vec::new());
    for k in 0..d.len() {
        let (ik, pk) = d.predict(c, k);
        i.push(ik);
        p.push(pk);
    }
    let parts: Vec<f64> = [nrmse(&d.current, &i), nrmse(&d.power, &p)]
        .into_iter()
        .flatten()
        .collect();
    (!parts.is_empty()).then(|| parts.iter().sum::<f64>() / parts.len() as f64)
}

/// Folds of interleaved points when no segment can be held out: within
/// each segment the points ranked by slip (recording order among equal
/// slips) go to fold `rank mod k`.
const INTERLEAVED_FOLDS: usize = 5;

/// A noise-to-misfit ratio above which the circuit is said to misfit the
/// data: the rms residual exceeds three times the scatter between
/// neighbouring points (a correct model leaves a ratio near 1; a smooth
/// misfit raises the rms but hardly the scatter between neighbours).
const MISFIT_RATIO: f64 = 3.0;

/// Relative noise of `residual` (one segment after another, each ordered
/// by slip) from its first differences: `σ² ≈ mean((r_k − r_{k−1})²)/2`.
fn neighbour_noise(sweep: &SlipSweep, residual: &[f64]) -> Option<f64> {
    let segments: std::collections::BTreeSet<u32> =
        sweep.points.iter().map(|p| p.segment).collect();
    let (mut sum, mut count) = (0.0, 0usize);
    for seg in segments {
        let mut idx: Vec<usize> = (0..sweep.points.len())
            .filter(|&k| sweep.points[k].segment == seg)
            .collect();
        idx.sort_by(|&a, &b| sweep.points[a].slip.total_cmp(&sweep.points[b].slip));
        for w in idx.windows(2) {
            let d = residual[w[1]] - residual[w[0]];
            if d.is_finite() {
                sum += d * d;
                count += 1;
            }
        }
    }
    (count >= 3).then(|| (sum / (2.0 * count as f64)).sqrt())
}

/// The relative residuals of current and power of `c` on `sweep`.
fn relative_residuals(c: &ImCircuit, sweep: &SlipSweep) -> (Vec<f64>, Vec<f64>) {
    let d = sweep.phase_data();
    (0..d.len())
        .map(|k| {
            let (i, p) = d.predict(c, k);
            (
                (i - d.current[k]) / d.current[k].abs().max(f64::MIN_POSITIVE),
                (p - d.power[k]) / d.power[k].abs().max(f64::MIN_POSITIVE),
            )
        })
        .unzip()
}

/// A warning when `c` misfits `sweep` well beyond its noise.
fn misfit_warning(c: &ImCircuit, sweep: &SlipSweep, model: ImModel) -> Option<String> {
    let (ri, rp) = relative_residuals(c, sweep);
    // A floor of 0.01 % (below any meter) keeps noise-free data from
    // calling round-off a misfit.
    let noise = |r: &[f64]| neighbour_noise(sweep, r).map(|s| s.max(1e-4));
    let (ni, np) = (noise(&ri)?, noise(&rp)?);
    let (ei, ep) = (rms(&ri), rms(&rp));
    (ei > MISFIT_RATIO * ni || ep > MISFIT_RATIO * np).then(|| {
        format!(
            "lm: the {model} circuit misfits these data: rms relative residual {:.2} % (current), \
             {:.2} % (power), against a scatter of about {:.2} % and {:.2} % between neighbouring \
             points; its elements are biased by what the circuit lacks (a loss, saturation, or a \
             slip recorded as 0 where it was not measured), and its intervals do not cover that bias \
             (`diagnose` locates the misfit)",
            100.0 * ei,
            100.0 * ep,
            100.0 * ni,
            100.0 * np
        )
    })
}

/// What to check when no circuit follows a record's readings at all.
pub const CHECK_THE_COLUMNS: &str = "Check that the columns belong together: the line current \
     in A and the three-phase total input power in W at the same instants, with the slip \
     measured there (one phase's power, or one of two wattmeters, is a fraction of the total; a \
     scaled sensor reads a multiple); readings that jump from point to point do not follow slip \
     as a machine's do";

/// Whether the circuit `c` predicts almost nothing of the measured
/// current or power (an rms relative residual of 90 % or more, below or
/// above the readings): relative residuals
/// give every prediction of zero a cost of one per point, so a fit to
/// readings that no circuit of its kind follows (an input power of half
/// the machine's, current and power that jump from point to point) can
/// end there.
fn collapsed(c: &ImCircuit, sweep: &SlipSweep) -> bool {
    let (ri, rp) = relative_residuals(c, sweep);
    rms(&rp) >= 0.9 || rms(&ri) >= 0.9
}

/// Root mean square of `r` (0 when empty).
fn rms(r: &[f64]) -> f64 {
    (r.iter().map(|v| v * v).sum::<f64>() / r.len().max(1) as f64).sqrt()
}

/// Mean over current and power of the NRMSE of `pred` against `sweep`.
fn pooled_nrmse(sweep: &SlipSweep, pred: &[(f64, f64)]) -> Option<f64> {
    let d = sweep.phase_data();
    mean_nrmse(&d.current, &d.power, pred)
}

/// Mean over current and power of the NRMSE of `pred`, `(current,
/// power)` per point, against the measured `current` and `power` (phase
/// values; the NRMSE is the same for line values); `None` when neither
/// channel has one.
pub(crate) fn mean_nrmse(current: &[f64], power: &[f64], pred: &[(f64, f64)]) -> Option<f64> {
    let i: Vec<f64> = pred.iter().map(|p| p.0).collect();
    let p: Vec<f64> = pred.iter().map(|p| p.1).collect();
    let parts: Vec<f64> = [nrmse(current, &i), nrmse(power, &p)]
        .into_iter()
        .flatten()
        .collect();
    (!parts.is_empty()).then(|| parts.iter().sum::<f64>() / parts.len() as f64)
}

/// The segments whose slip range the other segments cover: holding one
/// out then asks the fit to interpolate, not to extrapolate.
fn covered_segments(sweep: &SlipSweep) -> Vec<u32> {
    let segments: std::collections::BTreeSet<u32> =
        sweep.points.iter().map(|p| p.segment).collect();
    let range = |keep: &dyn Fn(u32) -> bool| {
        sweep
            .points
            .iter()
            .filter(|p| keep(p.segment))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.slip), hi.max(p.slip))
            })
    };
    segments
        .iter()
        .copied()
        .filter(|&s| {
            let (lo, hi) = range(&|t| t == s);
            let (rlo, rhi) = range(&|t| t != s);
            // Within the others' range, give or take a tenth of it.
            let tol = 0.1 * (rhi - rlo).max(0.0);
            lo >= rlo - tol && hi <= rhi + tol
        })
        .collect()
}

/// Held-out validation of the fit `full`: leave one segment out where the
/// other segments cover its slip range (sweeps at several voltages), else
/// interleaved points. Each held-out fit starts from `full` alone. Returns
/// the NRMSE and how it was taken.
fn validate(
    sweep: &SlipSweep,
    opts: &LmOptions,
    full: &LmFit,
    warnings: &mut Vec<String>,
) -> Option<f64> {
    let opts = LmOptions {
        starts: vec![full.circuit],
        ..opts.clone()
    };
    let segments: std::collections::BTreeSet<u32> =
        sweep.points.iter().map(|p| p.segment).collect();
    let covered = covered_segments(sweep);
    let subset = |keep: &dyn Fn(usize) -> bool| SlipSweep {
        points: sweep
            .points
            .iter()
            .enumerate()
            .filter(|(k, _)| keep(*k))
            .map(|(_, p)| *p)
            .collect(),
        ..sweep.clone()
    };
    if segments.len() >= 2 && covered.len() == segments.len() {
        let mut scores = Vec::new();
        for &held in &segments {
            let rest = subset(&|k| sweep.points[k].segment != held);
            if let Ok(f) = fit_lm(&rest.phase_data(), &opts) {
                scores.extend(sweep_nrmse(&f.circuit, sweep, held));
            }
        }
        return (!scores.is_empty()).then(|| scores.iter().sum::<f64>() / scores.len() as f64);
    }
    // Interleaved folds, stratified by segment.
    let n = sweep.points.len();
    let mut fold = vec![0usize; n];
    for &seg in &segments {
        let mut idx: Vec<usize> = (0..n).filter(|&k| sweep.points[k].segment == seg).collect();
        idx.sort_by(|&a, &b| sweep.points[a].slip.total_cmp(&sweep.points[b].slip));
        for (rank, &k) in idx.iter().enumerate() {
            fold[k] = rank % INTERLEAVED_FOLDS;
        }
    }
    let mut pred = vec![(f64::NAN, f64::NAN); n];
    for f in 0..INTERLEAVED_FOLDS {
        if !fold.contains(&f) {
            continue;
        }
        let train = subset(&|k| fold[k] != f);
        let fitted = match fit_lm(&train.phase_data(), &opts) {
            Ok(fitted) => fitted,
            Err(e) => {
                warnings.push(format!(
                    "lm: no held-out validation: the fit without fold {} of {INTERLEAVED_FOLDS} failed ({e})",
                    f + 1
                ));
                return None;
            }
        };
        let d = sweep.phase_data();
        for k in (0..n).filter(|&k| fold[k] == f) {
            pred[k] = d.predict(&fitted.circuit, k);
        }
    }
    if segments.len() >= 2 {
        warnings.push(format!(
            "lm: held-out validation on interleaved points ({INTERLEAVED_FOLDS} folds): no segment \
             can be held out whole, the others do not cover its slip range"
        ));
    }
    pooled_nrmse(sweep, &pred)
}

fn lm_method(
    sweep: &SlipSweep,
    model: ImModel,
    warnings: &mut Vec<String>,
) -> (MethodReport, Option<LmFit>) {
    let data = sweep.phase_data();
    let opts = LmOptions::new(model);
    let fit = match fit_lm(&data, &opts) {
        Ok(f) => f,
        Err(reason) => return (MethodReport::not_applicable(reason.to_string()), None),
    };
    let mut values = Vec::new();
    for p in &fit.params {
        if p.identifiable {
            values.push((p.param.key().to_string(), p.value, p.ci95));
        }
    }
    let at_bound = &fit.identifiability.at_bound;
    if !at_bound.is_empty() {
        let names: Vec<&str> = at_bound.iter().map(|p| p.key()).collect();
        warnings.push(format!(
            "lm: the fit drove {} towards 0 (below 10⁻³·|Z(s=1)|): these data ask for less than \
             the {model} circuit holds; a simpler circuit may fit as well",
            names.join(", ")
        ));
    }
    let weak: Vec<&str> = fit
        .identifiability
        .unidentifiable
        .iter()
        .filter(|p| !at_bound.contains(p))
        .map(|p| p.key())
        .collect();
    if !weak.is_empty() {
        let advice = if opts.channels.uses_power() {
            "fixing an element measured otherwise (Rs from a DC test) removes a degree of freedom"
        } else {
            "record input power, or fix Rs (DC test) and Xm"
        };
        warnings.push(format!(
            "lm: {} not determined by these data (left out of the parameters: relative standard \
             error above 50 %, or on a direction the data do not see); {advice}",
            weak.join(", ")
        ));
    }
    for w in &fit.identifiability.weak_before_convention {
        warnings.push(format!(
            "lm: weak direction with every element free: {}",
            w.describe()
        ));
    }
    if let Some(c) = &fit.identifiability.convention {
        warnings.push(format!(
            "lm: the leakage split is a convention, not a measurement: {c}"
        ));
    }
    warnings.extend(fit.warnings.iter().map(|w| format!("lm: {w}")));
    warnings.extend(misfit_warning(&fit.circuit, sweep, model));
    // A collapsed fit is no circuit to report even where an element looks
    // determined; nor is one with every element left out (the warnings
    // above say why). Neither is validated or diagnosed against.
    let collapse = collapsed(&fit.circuit, sweep);
    if collapse || values.is_empty() {
        return (
            MethodReport::not_applicable(if collapse {
                format!(
                    "the fit of the {model} circuit collapsed to elements of zero or without \
                     bound, predicting almost nothing of the measured current and power: no \
                     {model} circuit follows these readings. {CHECK_THE_COLUMNS}"
                )
            } else {
                format!(
                    "the fit of the {model} circuit determined none of its elements (see the \
                     warnings): readings that do not follow slip as a machine's do, or more \
                     elements than these data pin (fit a simpler circuit, or fix Rs from a DC \
                     test)"
                )
            }),
            None,
        );
    }

    let segments: std::collections::BTreeSet<u32> =
        sweep.points.iter().map(|p| p.segment).collect();
    if segments.len() < 2 {
        warnings.push(
            "lm: one sweep only, so no held-out validation (sweep at a second voltage for one)"
                .into(),
        );
    }
    // A held-out NRMSE of 1 or more is no score
    // (`IdentificationReport::unscore_failed_predictions`).
    let validation_nrmse = if segments.len() >= 2 {
        validate(sweep, &opts, &fit, warnings)
    } else {
        None
    };
    let report = MethodReport {
        applies: true,
        params: Some(params_of(&values)),
        validation_nrmse,
        reason: None,
    };
    (report, Some(fit))
}

fn recursive_method(
    sweep: &SlipSweep,
    model: ImModel,
    base: &PerUnitBase,
    warnings: &mut Vec<String>,
) -> (MethodReport, Option<RecursiveEstimate>) {
    let data = sweep.phase_data();
    let start = match classical_starts(&data, model, Default::default(), None) {
        Ok(s) => s[0],
        Err(reason) => return (MethodReport::not_applicable(reason.to_string()), None),
    };
    let pu = data.per_unit(base.phase_voltage, base.phase_current);
    let start_pu = start.to_per_unit(base);
    let mut est = recursive_estimate(&pu, &start_pu, model.params(), &RecursiveOptions::default());
    est.circuit = ImCircuit::from_per_unit(&est.circuit, base);
    let report = match est.stop {
        RecursiveStop::NonPhysical { param, value } => MethodReport::not_applicable(format!(
            "the paper's estimator stopped at its step 8 on pass {}: {param} went to {value:.4} p.u. (non-physical)",
            est.iterations
        )),
        RecursiveStop::Numerical => MethodReport::not_applicable("the paper's estimator produced a non-finite value"),
        RecursiveStop::Threshold | RecursiveStop::MaxIterations => {
            if est.stop == RecursiveStop::MaxIterations {
                warnings.push(format!(
                    "recursive: J = {:.3e} p.u.² after {} passes, above the paper's threshold 1e-4",
                    est.cost, est.iterations
                ));
            }
            let values: Vec<(String, f64, Option<[f64; 2]>)> = model
                .params()
                .iter()
                .map(|&p| (p.key().to_string(), est.circuit.get(p).unwrap_or(f64::NAN), None))
                .collect();
            MethodReport { applies: true, params: Some(params_of(&values)), validation_nrmse: None, reason: None }
        }
    };
    (report, Some(est))
}

/// A winding that warmed by more than this over the load test's points
/// (the thermometer's readings), K, is worth a warning: copper's
/// resistance then changed by about 2 %, as much as the slip-sweep fits'
/// `Rs` is typically determined to.
const WARMING_NOTE_K: f64 = 5.0;

/// What the slip-sweep fits make of the winding thermometer over the
/// sweep's points: where every point has a temperature, each point's `Rs`
/// is scaled to it ([`SlipSweep::rs_scale`]) and the note says at which
/// temperature `Rs` is given; where only some have one and the winding
/// warmed by more than [`WARMING_NOTE_K`] over them, that these fits
/// take one `Rs` for every point.
fn warming_note(sweep: &SlipSweep) -> Option<String> {
    let (first, [lo, hi], count) = sweep.thermometer()?;
    if count == sweep.points.len() {
        return Some(format!(
            "lm, recursive: Rs is given at the first point's winding temperature {first:.1} °C; \
             each point's Rs is scaled to its own (the thermometer read {lo:.1} to {hi:.1} °C; \
             copper's α)"
        ));
    }
    (hi - lo > WARMING_NOTE_K).then(|| {
        let rise = standard_tests::temperature_factor(Some(lo), Some(hi)) - 1.0;
        format!(
            "lm, recursive: the winding thermometer read {lo:.1} to {hi:.1} °C over the load \
             test's points, so Rs rose by {:.1} % (copper) during the sweep; with a temperature \
             on {} of the {} points these fits take one Rs for every point (the joint fit, \
             given the standard tests, scales it to each point that has one)",
            100.0 * rise,
            count,
            sweep.points.len()
        )
    })
}

/// Close `report`: refuse unphysical values, the first method of
/// `preference` that applies as the best, `warnings`, and the methods
/// whose predictions failed unscored (with a warning where the best is
/// one of them).
fn conclude(report: &mut IdentificationReport, preference: &[&str], warnings: Vec<String>) {
    report.refuse_unphysical();
    report.best = preference
        .iter()
        .find(|m| report.methods.get(**m).is_some_and(|r| r.applies))
        .map(|m| m.to_string());
    report.warnings = warnings;
    let failed = report.unscore_failed_predictions();
    report.warn_if_best_failed(&failed);
}

/// Identify an induction machine from `record`'s operating points.
/// `connection` overrides the nameplate's.
pub fn identify_im(
    record: &Record,
    connection: Option<Connection>,
    model: ImModel,
) -> ImIdentification {
    let mut report = IdentificationReport::new(SegmentKind::ImSlipSweep.as_str());
    let mut warnings = Vec::new();
    let conn = connection_of(record, connection, &mut warnings);
    let sweep = sweep_of(record, conn);
    if let Some(r) = &record.recovery {
        warnings.push(format!(
            "the record was damaged: {} messages recovered ({})",
            r.messages, r.reason
        ));
    }
    let opts = standard_tests_options(record, &mut warnings);
    let standard = standard_tests_method(&record.standard_tests, conn, &opts);
    if let Some((method, reduction)) = standard {
        report.methods.insert(STANDARD_TESTS.into(), method);
        // The joint fit starts from the reduction; the reactances at the
        // nameplate's frequency, else the readings'.
        let rated_frequency = opts
            .rated_frequency
            .or_else(|| {
                let tests = &record.standard_tests;
                tests
                    .no_load
                    .iter()
                    .chain(&tests.locked_rotor)
                    .map(|r| r.frequency)
                    .find(|f| f.is_finite() && *f > 0.0)
            })
            .unwrap_or(50.0);
        if let Some((method, notes)) = joint_method(
            &record.operating_points,
            &record.standard_tests,
            reduction.as_ref(),
            conn,
            opts.split,
            rated_frequency,
        ) {
            report.methods.insert(JOINT.into(), method);
            warnings.extend(notes);
        }
        if let Some(r) = reduction {
            warnings.extend(r.warnings);
            report.standard_tests = Some(r.tables);
        }
    }
    if let Err(reason) = sweep.validate() {
        for key in ["lm", "recursive"] {
            report
                .methods
                .insert(key.into(), MethodReport::not_applicable(reason.to_string()));
        }
        conclude(&mut report, &[JOINT, STANDARD_TESTS], warnings);
        return ImIdentification {
            report,
            sweep,
            base: None,
            lm: None,
            recursive: None,
        };
    }
    let data = sweep.phase_data();
    let base = match (
        nameplate_number(record, "voltage_V"),
        nameplate_number(record, "current_A"),
    ) {
        (Some(v), Some(i)) if v > 0.0 && i > 0.0 => PerUnitBase::from_rating(v, i, conn),
        _ => {
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let mut sorted = data.current.clone();
            sorted.sort_by(f64::total_cmp);
            warnings.push(
                "per-unit base from the data (mean voltage, median current): the nameplate has no voltage_V and current_A"
                    .into(),
            );
            PerUnitBase {
                phase_voltage: mean(&data.voltage),
                phase_current: sorted[sorted.len() / 2],
            }
        }
    };
    let (lm_report, lm) = lm_method(&sweep, model, &mut warnings);
    warnings.extend(warming_note(&sweep));
    let (rec_report, recursive) = recursive_method(&sweep, model, &base, &mut warnings);
    report.methods.insert("lm".into(), lm_report);
    report.methods.insert("recursive".into(), rec_report);
    conclude(
        &mut report,
        &[JOINT, "lm", "recursive", STANDARD_TESTS],
        warnings,
    );
    ImIdentification {
        report,
        sweep,
        base: Some(base),
        lm,
        recursive,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{slip_grid, SweepNoise};
    use crate::machine::im::assert_warned;
    use crate::model::{ImSupply, RotorCage};
    use crate::record::OperatingPoint;
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    fn record(circuit: &ImCircuit, voltages: &[f64], noise: f64) -> Record {
        let mut rng = StdRng::seed_from_u64(11);
        let mut points = Vec::new();
        for (seg, &v) in voltages.iter().enumerate() {
            let supply = ImSupply {
                line_voltage: v,
                frequency: 50.0,
                connection: Connection::Delta,
                pole_pairs: 2,
            };
            let sw = SlipSweep::simulate(
                circuit,
                &supply,
                &slip_grid(40, 0.002),
                &SweepNoise::relative(noise),
                seg as u32,
                &mut rng,
            );
            points.extend(sw.points.iter().map(|p| OperatingPoint {
                segment: p.segment,
                slip: p.slip,
                line_voltage: p.line_voltage,
                line_current: p.line_current,
                input_power: p.input_power,
                speed: (1.0 - p.slip) * std::f64::consts::PI * 50.0,
                frequency: 50.0,
                torque: p.torque,
                winding_temperature: None,
            }));
        }
        Record {
            operating_points: points,
            ..Record::default()
        }
    }

    fn machine() -> ImCircuit {
        ImCircuit {
            rs: 1.5,
            xs: 3.0,
            xm: 90.0,
            rfe: None,
            rotor: RotorCage::Single { rr: 1.6, xr: 3.0 },
        }
    }

    #[test]
    fn a_sweep_whose_winding_warmed_says_so_and_one_that_did_not_is_quiet() {
        let mut r = record(&machine(), &[400.0], 0.002);
        let n = r.operating_points.len() as f64;
        for (k, p) in r.operating_points.iter_mut().enumerate() {
            p.winding_temperature = Some(30.0 + 20.0 * k as f64 / (n - 1.0));
        }
        // A thermometer on some points only: one Rs for all.
        r.operating_points[5].winding_temperature = None;
        let id = identify_im(&r, Some(Connection::Delta), ImModel::Single);
        assert_warned(&id.report.warnings, "read 30.0 to 50.0 °C");
        // (1 + α·30 K)/(1 + α·10 K), α = 0.393 %/K.
        assert_warned(&id.report.warnings, "Rs rose by 7.6 %");
        assert_warned(&id.report.warnings, "on 39 of the 40 points");
        for p in r.operating_points.iter_mut() {
            p.winding_temperature = p.winding_temperature.map(|t| 30.0 + (t - 30.0) / 5.0);
        }
        let id = identify_im(&r, Some(Connection::Delta), ImModel::Single);
        assert!(
            !id.report.warnings.iter().any(|w| w.contains("thermometer")),
            "{:?}",
            id.report.warnings
        );
    }

    /// A sweep whose stator warms from 30 to 90 °C point by point (its Rs
    /// by 21 %): with each point's temperature the LM fit gives Rs at the
    /// first point's; without, one Rs for a warming winding. (The paper's
    /// recursive estimator stops non-physical on this machine either way;
    /// its use of the scale is tested in `recursive.rs`.)
    #[test]
    fn the_sweep_fits_scale_rs_to_each_point_temperature() {
        use crate::machine::im::COPPER_ALPHA;
        let cold = machine();
        let supply = ImSupply {
            line_voltage: 400.0,
            frequency: 50.0,
            connection: Connection::Delta,
            pole_pairs: 2,
        };
        let mut rng = StdRng::seed_from_u64(5);
        let slips = slip_grid(40, 0.002);
        let points: Vec<OperatingPoint> = slips
            .iter()
            .enumerate()
            .map(|(k, &s)| {
                let t = 30.0 + 60.0 * k as f64 / 39.0;
                let warm = ImCircuit {
                    rs: cold.rs * (1.0 + COPPER_ALPHA * (t - 20.0)) / (1.0 + COPPER_ALPHA * 10.0),
                    ..cold
                };
                let noise = SweepNoise::relative(0.002);
                let p = SlipSweep::simulate(&warm, &supply, &[s], &noise, 0, &mut rng).points[0];
                OperatingPoint {
                    segment: 0,
                    slip: s,
                    line_voltage: p.line_voltage,
                    line_current: p.line_current,
                    input_power: p.input_power,
                    speed: (1.0 - s) * std::f64::consts::PI * 50.0,
                    frequency: 50.0,
                    torque: None,
                    winding_temperature: Some(t),
                }
            })
            .collect();
        let mut r = Record {
            operating_points: points,
            ..Record::default()
        };
        let rs = |r: &Record| {
            let id = identify_im(r, Some(Connection::Delta), ImModel::Single);
            let lm = &id.report.methods["lm"];
            let params = lm.params.as_ref().expect("lm applies");
            (
                params["Rs"].value,
                params["Rs"].ci95.unwrap(),
                id.report.warnings,
            )
        };
        let (with, [lo, hi], warnings) = rs(&r);
        assert_warned(
            &warnings,
            "Rs is given at the first point's winding temperature 30.0 °C",
        );
        for p in r.operating_points.iter_mut() {
            p.winding_temperature = None;
        }
        let (without, _, _) = rs(&r);
        println!(
            "lm Rs with each point's temperature {with:.5} [{lo:.5}, {hi:.5}], one Rs for all \
             {without:.5}; truth {} at 30 °C",
            cold.rs
        );
        assert!(lo <= cold.rs && cold.rs <= hi, "Rs {with} [{lo}, {hi}]");
        assert!((without / cold.rs - 1.0).abs() > 3.0 * (with / cold.rs - 1.0).abs());
    }

    #[test]
    fn a_fit_that_determines_no_element_does_not_apply() {
        // Current and power that jump up and down from point to point,
        // as no machine's do along slip: the single-fe circuit's fit
        // leaves every element out.
        let points = (0..16)
            .map(|k| {
                let slip = 0.004 + 0.996 * f64::from(k) / 15.0;
                let jump = if k % 2 == 0 { 1.0 } else { -1.0 };
                OperatingPoint {
                    segment: 0,
                    slip,
                    line_voltage: 400.0,
                    line_current: 10.0 + 5.0 * jump,
                    input_power: 5000.0 - 2000.0 * jump,
                    speed: (1.0 - slip) * std::f64::consts::PI * 50.0,
                    frequency: 50.0,
                    torque: None,
                    winding_temperature: None,
                }
            })
            .collect();
        let record = Record {
            operating_points: points,
            ..Record::default()
        };
        let id = identify_im(&record, Some(Connection::Star), ImModel::SingleFe);
        let lm = &id.report.methods["lm"];
        assert!(!lm.applies, "{lm:?}");
        assert!(
            lm.reason
                .as_deref()
                .unwrap()
                .contains("collapsed to elements of zero or without bound"),
            "{lm:?}"
        );
        assert!(id.lm.is_none());
        assert_ne!(id.report.best.as_deref(), Some("lm"));
        // Whatever still applies reports finite values (a NaN would reach
        // the JSON as null).
        for (name, m) in &id.report.methods {
            for (key, p) in m.params.iter().flatten() {
                assert!(p.value.is_finite(), "{name} {key}: {p:?}");
            }
        }
    }

    /// An input power of half what the machine took (one wattmeter of
    /// two read as the total): the single circuit's fit collapses to
    /// zero elements, and the reason says which columns to check.
    #[test]
    fn a_collapsed_fit_names_the_channel_to_check() {
        let mut r = record(&machine(), &[400.0], 0.002);
        for p in &mut r.operating_points {
            p.input_power *= 0.5;
        }
        let id = identify_im(&r, Some(Connection::Delta), ImModel::Single);
        let lm = &id.report.methods["lm"];
        assert!(!lm.applies, "{lm:?}");
        let reason = lm.reason.as_deref().unwrap();
        assert!(
            reason.contains("collapsed to elements of zero or without bound")
                && reason.contains("three-phase total input power in W"),
            "{reason}"
        );
        let sound = identify_im(
            &record(&machine(), &[400.0], 0.002),
            Some(Connection::Delta),
            ImModel::Single,
        );
        assert!(sound.report.methods["lm"].applies);
    }

    #[test]
    fn report_has_both_methods_and_validates_on_held_out_segments() {
        let id = identify_im(
            &record(&machine(), &[230.0, 180.0], 0.002),
            Some(Connection::Delta),
            ImModel::Single,
        );
        let json: serde_json::Value = serde_json::from_str(&id.report.to_json_pretty()).unwrap();
        assert_eq!(json["kind"], "im_slip_sweep");
        assert_eq!(json["best"], "lm");
        let lm = &json["methods"]["lm"];
        assert_eq!(lm["applies"], true);
        let rs = &lm["params"]["Rs"];
        assert_eq!(rs["unit"], "ohm");
        let [lo, hi] = [
            rs["ci95"][0].as_f64().unwrap(),
            rs["ci95"][1].as_f64().unwrap(),
        ];
        assert!(lo <= 1.5 && 1.5 <= hi, "Rs interval [{lo}, {hi}]");
        assert!(lm["validation_nrmse"].as_f64().unwrap() < 0.05);
        assert!(json["methods"]["recursive"].is_object());
        assert_warned(&id.report.warnings, "convention");
    }

    #[test]
    fn connection_comes_from_the_nameplate_or_is_assumed_with_a_warning() {
        let mut r = record(&machine(), &[230.0], 0.002);
        let id = identify_im(&r, None, ImModel::Single);
        assert_eq!(id.sweep.connection, Connection::Star);
        assert!(id
            .report
            .warnings
            .iter()
            .any(|w| w.contains("star assumed")));
        r.meta = Some(crate::record::TestMeta {
            schema_version: "1".into(),
            kind: SegmentKind::ImSlipSweep,
            motor_id: "m".into(),
            started_at: String::new(),
            nameplate: serde_json::json!({"connection": "delta", "voltage_V": 230.0, "current_A": 4.0}),
            config: String::new(),
        });
        let id = identify_im(&r, None, ImModel::Single);
        assert_eq!(id.sweep.connection, Connection::Delta);
        assert_eq!(id.base.unwrap().phase_current, 4.0 / 3f64.sqrt());
    }

    #[test]
    fn an_empty_record_is_not_applicable() {
        let id = identify_im(&Record::default(), Some(Connection::Star), ImModel::Double);
        assert!(id.report.best.is_none());
        assert!(!id.report.methods["lm"].applies);
        assert!(id.report.methods["lm"]
            .reason
            .as_deref()
            .unwrap()
            .contains("no operating points"));
    }
}
