//! Parameter identification from a [`Record`].
//!
//! Methods (report keys): `steady_state` (the seed paper's Eqs. 7, 9, 39
//! and 44, generalised to a least-squares fit over every settled level of
//! a staircase, with propagated uncertainty), `pasek` (Eqs. 10–20, on an
//! abacus computed from the exact response), `moments` (Eqs. 21–44),
//! `coastdown` (J and Coulomb friction from the open-armature decay),
//! `equation_error` (the model's equations on filtered data, from any
//! voltage excitation) and `output_error` (the full model simulated and
//! fitted). Channel values no motor produces are refused first
//! ([`check_plausible`]); a best `K` far from what the nameplate implies
//! is warned of (`nameplate.rs`: a speed reading scaled wrong fits as
//! well as a right one).
//! Identification is a pure function of the record, so a replayed record
//! gives the same report, bit for bit.
//!

mod abacus;
mod coastdown;
mod equation_error;
mod error;
mod friction_bound;
mod level_error;
mod levels;
mod moments;
mod nameplate;
mod output_error;
mod pasek;
mod plausibility;
#[cfg(test)]
pub(crate) mod recorded;
mod simulate;
pub(crate) mod steady_state;
mod step;
mod time_constant;
mod transient;

use std::collections::BTreeMap;

use crate::identify::nrmse;
use crate::machine::dc::join::join_short_continuations;
pub use abacus::{
    invert_delta, paper_delta, paper_t1_over_tau_e, real_pole_threshold, AbacusError, CurrentStep,
};
pub use coastdown::{fit_decay, DecayFit};
pub use equation_error::{equation_error, reading_offset_warning, EquationErrorFit};
pub use error::NotApplicable;
pub use level_error::LevelError;
pub(crate) use levels::white_noise;
pub use levels::{is_coastdown, settled_level, unsettled_channel, SettledLevel};
pub use moments::{MomentsEstimate, TransferCoefficients};
pub use output_error::{
    output_error, prepare_output_error, state_at_end, ChannelNoise, HeldOut, OutputErrorFit,
    OutputErrorOptions, PreparedFit, SegmentStart, SpeedReading, Uncertainty, PARAM_KEYS,
    PARAM_UNITS,
};
pub use pasek::{PasekEstimate, PasekReading};
pub use plausibility::{
    check_plausible, check_plausible_files, clipped_channels, ImplausibleFile, ImplausibleInput,
    MAX_CURRENT, MAX_SPEED, MAX_VOLTAGE,
};
pub use simulate::simulate_segment;
pub use steady_state::{PairEstimate, SteadyStateEstimate, SteadyStateFit};
pub(crate) use step::running_angle;
pub use step::VoltageStep;
pub use transient::TransientFit;

use crate::model::DcParams;
use crate::record::{DcSegment, Record, SegmentKind};
use crate::report::{IdentificationReport, MethodReport, ParamEstimate};

/// A model's response on one segment, for plots.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedSegment {
    /// Segment index.
    pub index: u32,
    /// Model name, e.g. `steady_state`.
    pub model: String,
    /// Current on the segment's time base, A.
    pub current: Vec<f64>,
    /// Speed on the segment's time base, rad/s.
    pub speed: Vec<f64>,
}

/// Everything identification produced: the contract report and the
/// details behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// The report per the data contract.
    pub report: IdentificationReport,
    /// The steady-state levels found, one per step segment.
    pub levels: Vec<SettledLevel>,
    /// The steady-state fit, when it applied.
    pub steady_state: Option<SteadyStateFit>,
    /// Model responses per segment, for plots.
    pub simulated: Vec<SimulatedSegment>,
    /// Pasek's method on every usable step (segment, estimate or why not).
    pub pasek_steps: Vec<(u32, Result<PasekEstimate, NotApplicable>)>,
    /// The method of moments on every usable step.
    pub moments_steps: Vec<(u32, Result<MomentsEstimate, NotApplicable>)>,
    /// The transient methods' fits (`pasek`, `moments`) that applied.
    pub transient: Vec<TransientFit>,
    /// The coast-down fit, when it applied.
    pub coastdown: Option<CoastdownFit>,
    /// The output-error fit of the full model, when it applied.
    pub output_error: Option<OutputErrorFit>,
    /// The equation-error fit of the full model, when it applied.
    pub equation_error: Option<EquationErrorFit>,
}

impl Identification {
    /// Why nothing could be identified, in terms a user can act on; `None`
    /// when a method applies. Equation error needs least of the record
    /// (any voltage that moves current and speed), so its reason says
    /// what the record lacks ("the voltage never changes", "the speed is
    /// constant"); without it, the steady state's.
    pub fn refusal(&self) -> Option<String> {
        if self.report.best.is_some() {
            return None;
        }
        let reason = |key: &str| {
            self.report
                .methods
                .get(key)
                .and_then(|m| m.reason.clone())
                .filter(|r| !r.is_empty())
        };
        let first = reason("equation_error")
            .or_else(|| reason("steady_state"))
            .unwrap_or_else(|| "the record holds no usable segment".into());
        Some(first.trim_start_matches("does not apply: ").to_string())
    }
}

/// The coast-down method's result.
#[derive(Debug, Clone, PartialEq)]
pub struct CoastdownFit {
    /// The decay fit.
    pub decay: DecayFit,
    /// J and its standard error, kg·m² (with f from the steady state).
    pub j: [f64; 2],
    /// Coulomb torque Tc and its standard error, N·m.
    pub tc: [f64; 2],
    /// Viscous friction from the steady state and its standard error.
    pub f: [f64; 2],
    /// The f interval reported (the steady state's).
    pub f_ci95: Option<[f64; 2]>,
    /// Speed NRMSE on other coast-down segments, if any.
    pub validation_nrmse: Option<f64>,
}

impl CoastdownFit {
    /// The contract's view.
    pub fn method_report(&self) -> MethodReport {
        let ci = |[v, se]: [f64; 2]| {
            (se.is_finite() && se > 0.0).then_some([v - 1.96 * se, v + 1.96 * se])
        };
        let entry = |value: f64, ci95, unit: &str| ParamEstimate {
            value,
            ci95,
            unit: unit.into(),
        };
        let params = [
            ("J".to_string(), entry(self.j[0], ci(self.j), "kg*m^2")),
            ("f".to_string(), entry(self.f[0], self.f_ci95, "N*m*s/rad")),
            ("Tc".to_string(), entry(self.tc[0], ci(self.tc), "N*m")),
        ]
        .into_iter()
        .collect();
        MethodReport::fitted(params, self.validation_nrmse)
    }
}

/// Every segment holding a coast-down (marked, or recognised from data),
/// as a coast-down.
fn coastdown_segments(record: &Record) -> Vec<DcSegment> {
    record
        .segments
        .iter()
        .filter(|s| !s.time.is_empty())
        .filter(|s| s.kind == Some(SegmentKind::DcCoastdown) || is_coastdown(s))
        .map(|s| DcSegment {
            kind: Some(SegmentKind::DcCoastdown),
            ..s.clone()
        })
        .collect()
}

fn coastdown_method(
    record: &Record,
    ss: Option<&SteadyStateFit>,
) -> Result<CoastdownFit, NotApplicable> {
    let segs = coastdown_segments(record);
    let seg = segs
        .first()
        .ok_or_else(|| NotApplicable::Missing("the record holds no coast-down segment".into()))?;
    let ss = ss.ok_or(NotApplicable::NeedsSteadyState { needs: "f" })?;
    let decay = fit_decay(seg)?;
    let (f, f_se) = (ss.estimate.f, ss.std_error[2]);
    if f.is_nan() || f <= 0.0 {
        return Err(NotApplicable::Unidentifiable(format!(
            "needs a positive f from the steady state (got {f:.3e}) to turn f/J into J"
        )));
    }
    let (j, tc) = coastdown::inertia_and_coulomb(&decay, f, f_se);
    let params = DcParams {
        ra: ss.estimate.ra,
        // The armature is open: La plays no part; any valid value will do.
        la: 1.0,
        k: ss.estimate.k,
        j: j[0],
        f,
        tst: tc[0].max(0.0),
    };
    let scores: Vec<f64> = segs[1..]
        .iter()
        .filter_map(|s| {
            let (_, w) = simulate_segment(&params, s).ok()?;
            nrmse(&s.speed, &w)
        })
        .collect();
    Ok(CoastdownFit {
        decay,
        j,
        tc,
        f: [f, f_se],
        f_ci95: ss.ci95[2],
        validation_nrmse: (!scores.is_empty())
            .then(|| scores.iter().sum::<f64>() / scores.len() as f64),
    })
}

impl CoastdownFit {
    /// The fitted decay on the coast-down segment, for plots.
    fn simulate(&self, record: &Record) -> Vec<SimulatedSegment> {
        let Some(seg) = record
            .segments
            .iter()
            .find(|s| s.index == self.decay.segment)
        else {
            return Vec::new();
        };
        let (start, _) = self.decay.range;
        let t0 = seg.time[start];
        let speed = seg
            .time
            .iter()
            .enumerate()
            .map(|(k, t)| {
                if k < start {
                    seg.speed[k]
                } else {
                    self.decay.speed(t - t0).max(0.0) * self.decay.theta[0].signum()
                }
            })
            .collect();
        vec![SimulatedSegment {
            index: seg.index,
            model: "coastdown".into(),
            current: vec![0.0; seg.time.len()],
            speed,
        }]
    }
}

/// Identify a DC motor from a `dc_step` / `dc_coastdown` record.
pub fn identify_dc(record: &Record) -> Identification {
    let mut report = IdentificationReport::new(SegmentKind::DcStep.as_str());
    if let Err(e) = check_plausible(record) {
        return implausible(report, &e);
    }
    report.warnings.extend(record.notes.iter().cloned());
    report.warnings.extend(clipped_channels(record));
    let mut levels = Vec::new();
    let mut level_notes = Vec::new();
    for seg in &record.segments {
        if seg.time.is_empty() {
            report.warnings.push(format!(
                "segment {} ({}) has no samples of armature voltage, current and speed",
                seg.index, seg.label
            ));
            continue;
        }
        if seg.kind == Some(SegmentKind::DcCoastdown) || is_coastdown(seg) {
            continue;
        }
        match settled_level(seg) {
            Some(level) if level.settled => {
                level_notes.push(format!("{} ({})", level.segment, level.label));
                levels.push(level)
            }
            Some(level) => report.warnings.push(format!(
                "segment {} ({}) had not settled at its end: {}; its level is not used",
                level.segment,
                level.label,
                unsettled_channel(seg).unwrap_or_default()
            )),
            None => report.warnings.push(format!(
                "segment {} ({}) is too short to find a level",
                seg.index, seg.label
            )),
        }
    }
    if !level_notes.is_empty() {
        report.warnings.push(format!(
            "steady_state: settled levels used: segment {}",
            crate::excerpt::listed(&level_notes)
        ));
    }
    if let Some(r) = &record.recovery {
        report.warnings.push(format!(
            "the record was damaged: {} messages recovered ({})",
            r.messages, r.reason
        ));
    }

    let fit = steady_state::fit(record, &levels);
    let (method, steady_state, mut simulated) = match fit {
        Ok(fit) => {
            report.warnings.extend(fit.warnings.iter().cloned());
            let simulated = fit.simulate(record);
            (fit.method_report(), Some(fit), simulated)
        }
        Err(reason) => (
            MethodReport::not_applicable(reason.to_string()),
            None,
            Vec::new(),
        ),
    };
    report.methods.insert("steady_state".into(), method);

    // Pasek and moments, on every usable step; fitted on the largest rise.
    // A step the supply did not follow is not the step they assume.
    let mut steps = step::voltage_steps(record, &levels);
    let spoiled = supply_limited(record, &mut report.warnings);
    steps.retain(|st| !spoiled.contains(&st.segment));
    let fit_at = step::fit_step(&steps);
    let segment = |index: u32| record.segments.iter().find(|s| s.index == index);
    let mut pasek_steps = Vec::new();
    let mut moments_steps = Vec::new();
    if let Some(ss) = &steady_state {
        for st in &steps {
            let seg = segment(st.segment).expect("a step comes from a segment");
            pasek_steps.push((st.segment, pasek::estimate(seg, st, &ss.estimate)));
            moments_steps.push((st.segment, moments::estimate(seg, st, &ss.estimate)));
        }
    }
    let mut transient = Vec::new();
    for (name, per_step) in [
        (
            "pasek",
            collect_params(&pasek_steps, |e: &PasekEstimate| e.params),
        ),
        (
            "moments",
            collect_params(&moments_steps, |e: &MomentsEstimate| e.params),
        ),
    ] {
        let outcome = match (&steady_state, fit_at) {
            (None, _) => Err(NotApplicable::NeedsSteadyState {
                needs: "K, Ra and f",
            }),
            (_, None) => Err(NotApplicable::Missing(
                "no voltage step between two settled levels at which the rotor turns the same way"
                    .into(),
            )),
            (Some(ss), Some(n)) => {
                let fit_segment = steps[n].segment;
                match per_step.iter().find(|(s, _)| *s == fit_segment) {
                    Some(_) => Ok(transient::assemble(
                        name,
                        record,
                        fit_segment,
                        per_step.clone(),
                        ss,
                    )),
                    None => {
                        let why = match name {
                            "pasek" => pasek_steps
                                .iter()
                                .find(|(s, _)| *s == fit_segment)
                                .and_then(|(_, r)| r.as_ref().err().cloned()),
                            _ => moments_steps
                                .iter()
                                .find(|(s, _)| *s == fit_segment)
                                .and_then(|(_, r)| r.as_ref().err().cloned()),
                        };
                        Err(NotApplicable::AtSegment {
                            segment: fit_segment,
                            source: Box::new(
                                why.unwrap_or_else(|| NotApplicable::Missing(String::new())),
                            ),
                        })
                    }
                }
            }
        };
        if let Some(fit) = enter_method(&mut report.methods, name, outcome, |f| f.method_report()) {
            report.warnings.extend(fit.warnings.iter().cloned());
            simulated.extend(transient::simulate_steps(&fit.params, record, name));
            transient.push(fit);
        }
    }

    let coastdown = enter_method(
        &mut report.methods,
        "coastdown",
        coastdown_method(record, steady_state.as_ref()),
        |f| f.method_report(),
    );
    if let Some(fit) = &coastdown {
        simulated.extend(fit.simulate(record));
    }

    // Equation error and output error take any excitation: short segments
    // that continue one another (a slow logger's staircase) are one driven
    // segment to them, their responses drawn on the segments as they are.
    let joined = join_short_continuations(record, "equation_error and output_error");
    let driven = joined.as_ref().map_or(record, |j| &j.record);
    report
        .warnings
        .extend(joined.as_ref().and_then(|j| j.record.notes.last().cloned()));
    let as_recorded = |sims: &[SimulatedSegment]| match &joined {
        Some(j) => j.split_back(sims.to_vec()),
        None => sims.to_vec(),
    };

    let equation_error = enter_method(
        &mut report.methods,
        "equation_error",
        equation_error(driven, SpeedReading::default()),
        |f| f.method_report(),
    );
    if let Some(fit) = &equation_error {
        report.warnings.extend(fit.warnings.iter().cloned());
        simulated.extend(as_recorded(&fit.simulated));
    }

    // The full model, fitted to every step at once, started from the
    // transient method that validated best (moments or Pasek) when one
    // applied with a motor's parameters, else from its own steady-state,
    // transient or equation-error estimates. A transient fit built on a
    // steady-state fit that a brush drop or a closed loop has pushed to a
    // negative Ra is no start: it is refused as a report value below, and
    // it would refuse output error with it.
    let score = |t: &TransientFit| t.validation_nrmse.unwrap_or(f64::INFINITY);
    let start = transient
        .iter()
        .filter(|t| t.params.validate().is_ok())
        .min_by(|a, b| score(a).total_cmp(&score(b)))
        .map(|t| t.params);
    let output_error = enter_method(
        &mut report.methods,
        "output_error",
        output_error(driven, start, &OutputErrorOptions::default()),
        |f| f.method_report(),
    );
    if let Some(fit) = &output_error {
        report.warnings.extend(fit.warnings.iter().cloned());
        simulated.extend(as_recorded(&fit.simulated));
    }

    friction_bound::refuse_friction_beyond_torque(record, &mut report);
    report.refuse_unphysical();
    let failed = report.unscore_failed_predictions();
    report.best = best_method(&report);
    let equation_error_applies = report
        .methods
        .get("equation_error")
        .is_some_and(|m| m.applies);
    if let Some(why) = prefer_equation_error(equation_error.as_ref(), output_error.as_ref()) {
        if equation_error_applies && report.best.as_deref() != Some("equation_error") {
            report.warnings.push(format!(
                "best: equation_error rather than {} (which validates best): {why}",
                report.best.as_deref().unwrap_or("none")
            ));
            report.best = Some("equation_error".into());
        }
    }
    report.warn_if_best_failed(&failed);
    if let Some(meta) = &record.meta {
        report
            .warnings
            .extend(nameplate::k_disagrees(&meta.nameplate, &report));
    }
    report
        .warnings
        .extend(time_constant::time_constant_implausible(&report));
    report
        .warnings
        .extend(time_constant::time_constant_unresolved(
            &report,
            time_constant::sample_interval(record),
        ));
    Identification {
        report,
        levels,
        steady_state,
        simulated,
        pasek_steps,
        moments_steps,
        transient,
        coastdown,
        output_error,
        equation_error,
    }
}

/// Enter method `name`'s outcome in `methods`: the fit's report (made by
/// `report_of`), or not applicable with the reason; the fit, if any.
fn enter_method<T, E: std::fmt::Display>(
    methods: &mut BTreeMap<String, MethodReport>,
    name: &str,
    outcome: Result<T, E>,
    report_of: impl FnOnce(&T) -> MethodReport,
) -> Option<T> {
    let entry = match &outcome {
        Ok(fit) => report_of(fit),
        Err(reason) => MethodReport::not_applicable(reason.to_string()),
    };
    methods.insert(name.into(), entry);
    outcome.ok()
}

/// The identification of a record whose values no motor produces: every
/// method says why it does not apply.
fn implausible(mut report: IdentificationReport, e: &ImplausibleInput) -> Identification {
    let reason = format!("the input is not physically plausible: {e}");
    for key in [
        "steady_state",
        "pasek",
        "moments",
        "coastdown",
        "equation_error",
        "output_error",
    ] {
        report
            .methods
            .insert(key.into(), MethodReport::not_applicable(reason.clone()));
    }
    report.warnings.push(reason);
    Identification {
        report,
        levels: Vec::new(),
        steady_state: None,
        simulated: Vec::new(),
        pasek_steps: Vec::new(),
        moments_steps: Vec::new(),
        transient: Vec::new(),
        coastdown: None,
        output_error: None,
        equation_error: None,
    }
}

/// The segments where the record says the supply did not follow its set
/// point (`/bench/supply_limit`), each named in a warning.
fn supply_limited(record: &Record, warnings: &mut Vec<String>) -> Vec<u32> {
    let mut out = Vec::new();
    for limit in &record.supply_limits {
        let label = record
            .segments
            .iter()
            .find(|s| s.index == limit.segment)
            .map_or("", |s| s.label.as_str());
        warnings.push(format!(
            "{}: its step is left out of the pasek and moments fits, which assume the commanded voltage step",
            limit.describe(label)
        ));
        out.push(limit.segment);
    }
    out
}

/// The per-step parameters of the steps where a method gave numbers.
fn collect_params<E>(
    steps: &[(u32, Result<E, NotApplicable>)],
    params: impl Fn(&E) -> DcParams,
) -> Vec<(u32, DcParams)> {
    steps
        .iter()
        .filter_map(|(s, r)| r.as_ref().ok().map(|e| (*s, params(e))))
        .collect()
}

/// Why the report should use equation error whatever validates best, if
/// it should: in a closed loop the voltage carries the speed reading's
/// noise back into the input, which output error takes as exact (its
/// start and its fit are then biased), while equation error's
/// instruments (simulated from the voltage) carry almost none of it; and when the full
/// model's residuals are far above the noise (an unmodelled effect),
/// output error spreads that misfit over every parameter, while the
/// electrical equation `U = La·di/dt + Ra·i + K·ω` that gives equation
/// error its K and Ra holds whatever the load and the friction do.
fn prefer_equation_error(
    ee: Option<&EquationErrorFit>,
    oe: Option<&OutputErrorFit>,
) -> Option<String> {
    let ee = ee?;
    if ee.closed_loop.is_some() {
        return Some(
            "the record is a closed loop's (the voltage follows the speed reading's noise): \
             its instrumental-variable estimate is not biased by the fed-back noise"
                .into(),
        );
    }
    oe.filter(|o| o.misfit()).map(|_| {
        "the full model's residuals are far above the noise (an unmodelled effect): output \
         error spreads that misfit over every parameter, while equation error's K and Ra \
         rest on the electrical equation, which holds whatever the load does"
            .to_string()
    })
}

/// The applying method with the lowest validation NRMSE; without any
/// NRMSE (a single segment), the first that applies of the steady state,
/// output error and equation error.
fn best_method(report: &IdentificationReport) -> Option<String> {
    report
        .methods
        .iter()
        .filter(|(_, m)| m.applies)
        .filter_map(|(k, m)| m.validation_nrmse.map(|v| (k, v)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(k, _)| k.clone())
        .or_else(|| {
            ["steady_state", "output_error", "equation_error"]
                .into_iter()
                .find(|k| report.methods.get(*k).is_some_and(|m| m.applies))
                .map(str::to_string)
        })
}
