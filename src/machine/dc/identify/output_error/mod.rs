//! Output-error identification: the full DC model (Ra, La, K, J, f, Tst)
//! fitted by Levenberg–Marquardt to the armature current and the speed of
//! every step segment at once, simulated exactly from the measured
//! voltage.
//!
//! - Residuals are weighted by each channel's noise level, estimated from
//!   the first differences over the settled tails, so current and speed
//!   count by their information, not their units.
//! - Parameters are fitted as logarithms, with a finite-difference
//!   Jacobian, and handed to the `levenberg-marquardt` crate reduced to
//!   seven rows (see [`problem`]).
//! - Each segment starts from the model's own steady state at the mean
//!   voltage over the settled tail of the level before it (the bench holds
//!   every level until it settles), at its first voltage reading when no
//!   level precedes it, or from rest when the speed there is zero although
//!   that steady state would turn the rotor. Only the measured input and
//!   the model set the start, so a held-out segment is a true simulation:
//!   nothing of its outputs is fitted. A segment after a level that had
//!   not settled has no known start and is left out, with a warning.
//! - Intervals come from a sandwich covariance at the optimum: the
//!   residuals' own scatter plus what the noise of the measured voltage
//!   adds (see [`uncertainty`] and [`input_noise`]); the bias that voltage
//!   noise causes is removed from the estimate.
//! - Validation: each segment in turn is held out, the model refitted on
//!   the others and simulated on it; the report gives the mean NRMSE. A
//!   refit starts one Gauss–Newton step from the all-segment optimum (with
//!   the held-out rows removed) and converges to its own optimum; the
//!   start only saves evaluations.

mod input_noise;
mod multi_start;
mod problem;
mod simulation;
mod start;
mod uncertainty;

use std::fmt::Write;

use super::error::NotApplicable;
use super::{is_coastdown, nrmse, settled_level, SimulatedSegment};
use crate::model::DcParams;
use crate::record::{DcSegment, Record, SegmentKind};
use crate::report::{MethodReport, ParamEstimate};
use nalgebra::{Matrix6, Vector6};
use problem::{minimise, to_array, FitData, OutputErrorProblem, NP};

pub(crate) use simulation::{simulate_series, SegmentInput};
pub use simulation::{SegmentStart, SpeedReading};
pub use uncertainty::{Uncertainty, PARAM_KEYS};

/// Units of the parameters, in [`PARAM_KEYS`] order, as the contract
/// spells them.
pub const PARAM_UNITS: [&str; NP] = ["ohm", "H", "V*s/rad", "kg*m^2", "N*m*s/rad", "N*m"];

/// Fewest samples a step segment needs to enter the fit.
const MIN_SAMPLES: usize = 20;

/// Samples per block of the residual part of the covariance (see
/// [`uncertainty`]): 16 ms at 2 kHz, long against the encoder noise's
/// one-sample correlation and most electrical time constants.
const SCORE_BLOCK: usize = 32;

/// Weighted residual variance above which the model is reported as not
/// describing the data to its noise level.
const MISFIT_VARIANCE: f64 = 4.0;

/// Largest voltage-noise bias correction, in standard errors of the
/// parameter it moves, that is applied. On the three blind seeds' 120 DC
/// records the corrections beyond it (4.3, 5.8 and 42 standard errors,
/// all position loops) each took La or K away from the truth (La −7.6,
/// −53 and −97 % against +0.5, +6.2 and +12 % uncorrected); every one
/// within it was under two.
const MAX_BIAS_SIGMAS: f64 = 3.0;

/// How to run the fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputErrorOptions {
    /// What the record's speed channel reads.
    pub speed_reading: SpeedReading,
    /// Hold out each segment in turn for the validation NRMSE (one refit
    /// per segment).
    pub validate: bool,
    /// Remove the bias the noise of the voltage reading causes: the fit
    /// simulates from the measured voltage and leans towards parameters
    /// that filter its noise more (one Newton step on the expected noise
    /// energy undoes it). Turn off when the voltage varies over the
    /// settled tails for real (supply ripple), not by measurement noise.
    pub correct_input_noise: bool,
}

impl Default for OutputErrorOptions {
    fn default() -> Self {
        OutputErrorOptions {
            speed_reading: SpeedReading::IntervalMean,
            validate: true,
            correct_input_noise: true,
        }
    }
}

/// Noise standard deviation of the measured channels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelNoise {
    /// Armature voltage, V.
    pub voltage: f64,
    /// Armature current, A.
    pub current: f64,
    /// Speed, rad/s.
    pub speed: f64,
}

/// One held-out segment of the validation.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOut {
    /// The segment held out.
    pub segment: u32,
    /// Parameters fitted without it.
    pub params: DcParams,
    /// NRMSE on it (mean of current and speed).
    pub nrmse: f64,
}

/// The output-error fit and everything behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputErrorFit {
    /// The estimate from every fitted segment.
    pub params: DcParams,
    /// Intervals, correlation, singular values, residual variance.
    pub uncertainty: Uncertainty,
    /// The correction for the voltage-noise bias applied to the least-
    /// squares optimum, as a change of `ln p` per parameter.
    pub input_noise_shift: [f64; NP],
    /// Noise levels the residuals were weighted by.
    pub noise: ChannelNoise,
    /// Where the optimiser started.
    pub start: DcParams,
    /// Segments fitted, with how each starts.
    pub segments: Vec<(u32, SegmentStart)>,
    /// Whether the optimiser reports convergence.
    pub converged: bool,
    /// Residual evaluations of the all-segment fit.
    pub evaluations: usize,
    /// The leave-one-segment-out refits.
    pub held_out: Vec<HeldOut>,
    /// Mean NRMSE over the held-out segments.
    pub validation_nrmse: Option<f64>,
    /// Findings worth a user's attention (each starts `output_error:`).
    pub warnings: Vec<String>,
    /// The fitted model on every fitted segment, for plots.
    pub simulated: Vec<SimulatedSegment>,
}

/// Fit the full DC model to every step segment of `record`.
///
/// `start` is where the optimiser begins (e.g. the moments or Pasek
/// estimate); without it, K, Ra, f, Tst come from the steady-state fit and
/// La, J from the integrated model equations over the transients.
pub fn output_error(
    record: &Record,
    start: Option<DcParams>,
    options: &OutputErrorOptions,
) -> Result<OutputErrorFit, NotApplicable> {
    let PreparedFit {
        candidates,
        noise,
        data,
        start,
        poorly_conditioned,
        mut warnings,
    } = prepare_output_error(record, start, options)?;

    let best = if poorly_conditioned {
        let (best, tried) = multi_start::best_of(&data, &start);
        warnings.push(format!(
            "output_error: the equation-error start is poorly conditioned, so the fit ran from \
             {tried} starts (La and J scaled by 1/4 and 4) and kept the lowest residual"
        ));
        best
    } else {
        minimise(&data, &start)
    };
    if best.at.refused() {
        return Err(NotApplicable::Unidentifiable(format!(
            "the fit ended at parameters the model refuses ({})",
            best.termination
        )));
    }
    if !best.converged {
        warnings.push(format!(
            "output_error: the optimiser stopped without converging ({}) after {} evaluations",
            best.termination, best.evaluations
        ));
    }
    let jac = &best.at.jac;
    let segment_rows: Vec<usize> = data.segments.iter().map(|s| 2 * s.len()).collect();
    let input_scores = if noise.voltage > 0.0 {
        input_noise::voltage_score_matrix(jac, &data, &best.params)
            .map_or(Matrix6::zeros(), |m| m * noise.voltage.powi(2))
    } else {
        Matrix6::zeros()
    };
    let mut unc = uncertainty::uncertainty(
        jac,
        &best.at.r,
        &best.params,
        &segment_rows,
        2 * SCORE_BLOCK,
        &input_scores,
    );
    warnings.extend(unc.warnings.iter().map(|w| format!("output_error: {w}")));
    let problem = OutputErrorProblem::new(&data, &best.reference);
    let shift = if options.correct_input_noise {
        let shift = input_noise::bias_shift(
            &problem,
            &data,
            &best.at.x,
            jac,
            &unc.poorly_determined,
            noise.voltage,
        );
        // The correction is a first-order one, for a bias of a few tenths
        // of a standard error; one of several is outside its reach (a
        // closed loop, whose voltage "noise" is the controller's answer to
        // the sensors' and no measurement error of the input).
        match (0..NP).find(|&n| shift[n].abs() > MAX_BIAS_SIGMAS * unc.std_ln[n]) {
            Some(n) => {
                warnings.push(format!(
                    "output_error: the voltage-noise bias correction was not applied: it would \
                     move {} by {:.1} standard errors ({:+.1} %), beyond the first-order \
                     correction's reach (a voltage whose variation is not measurement noise, \
                     as a closed loop's command)",
                    PARAM_KEYS[n],
                    shift[n].abs() / unc.std_ln[n],
                    100.0 * shift[n].exp_m1()
                ));
                [0.0; NP]
            }
            None => shift,
        }
    } else {
        [0.0; NP]
    };
    let params = problem.params_at(&(best.at.x + Vector6::from(shift)));
    physical(&params, candidates.iter().map(|(_, s)| *s))?;
    unc.ci95 = uncertainty::intervals(&params, &unc.std_ln, unc.dof);
    if unc.residual_variance > MISFIT_VARIANCE {
        warnings.push(format!(
            "output_error: the residuals are {:.1} times the noise level of the settled tails: \
             the model does not describe everything in the data (an unmodelled effect?); \
             the intervals include that scatter but assume the model's form",
            unc.residual_variance.sqrt()
        ));
    }
    let longest = data
        .segments
        .iter()
        .map(|s| s.dt * (s.len() - 1) as f64)
        .fold(0.0, f64::max);
    let tau_m = params.tau_m();
    let mechanical_doubt = unc.flagged[3] || unc.flagged[4] || unc.flagged[5];
    if longest < 3.0 * tau_m && mechanical_doubt {
        warnings.push(format!(
            "output_error: the longest segment lasts {longest:.3} s, less than 3 mechanical time constants \
             (3·τm = {:.3} s): the speed does not settle, so the record cannot tell J, f and Tst apart well; \
             hold each level longer",
            3.0 * tau_m
        ));
    }

    let held_out = if options.validate && data.segments.len() >= 2 {
        held_out_refits(&data, &problem, &best)
    } else {
        if options.validate {
            warnings
                .push("output_error: a single segment fitted, so no held-out validation".into());
        }
        Vec::new()
    };
    let validation_nrmse = (!held_out.is_empty())
        .then(|| held_out.iter().map(|h| h.nrmse).sum::<f64>() / held_out.len() as f64);

    let simulated = data
        .segments
        .iter()
        .filter_map(|input| {
            let (current, speed) = simulate_series(&params, input, options.speed_reading).ok()?;
            Some(SimulatedSegment {
                index: input.seg.index,
                model: "output_error".into(),
                current,
                speed,
            })
        })
        .collect();

    Ok(OutputErrorFit {
        params,
        uncertainty: unc,
        input_noise_shift: shift,
        noise,
        start,
        segments: data
            .segments
            .iter()
            .map(|s| (s.seg.index, s.start))
            .collect(),
        converged: best.converged,
        evaluations: best.evaluations,
        held_out,
        validation_nrmse,
        warnings,
        simulated,
    })
}

/// The least-squares problem [`output_error`] minimises, ready for its
/// optimiser: the segments fitted with their starts, the noise weights
/// and the start values. [`PreparedFit::minimise`] runs the optimiser
/// alone, which is what a comparison with another least-squares solver
/// on the same problem times.
pub struct PreparedFit<'a> {
    /// The record's step segments (position in the record, segment).
    candidates: Vec<(usize, &'a DcSegment)>,
    noise: ChannelNoise,
    data: FitData<'a>,
    start: DcParams,
    /// The start came from an equation-error fit that flags La, Ra, K
    /// or J as poorly determined: the fit runs from several starts.
    poorly_conditioned: bool,
    warnings: Vec<String>,
}

impl PreparedFit<'_> {
    /// The optimiser from the start values alone: the parameters at the
    /// least-squares optimum and the residual evaluations it took (each
    /// with its Jacobian). One start, even where [`output_error`] would
    /// run from several (a poorly conditioned equation-error start); no
    /// intervals, no bias correction, no validation: [`output_error`]
    /// adds those.
    pub fn minimise(&self) -> (DcParams, usize) {
        let best = minimise(&self.data, &self.start);
        (best.params, best.evaluations)
    }

    /// Where the optimiser starts.
    pub fn start(&self) -> DcParams {
        self.start
    }

    /// The segments fitted, with how each starts.
    pub fn segments(&self) -> Vec<(u32, SegmentStart)> {
        self.data
            .segments
            .iter()
            .map(|s| (s.seg.index, s.start))
            .collect()
    }

    /// The noise levels the residuals are weighted by.
    pub fn noise(&self) -> ChannelNoise {
        self.noise
    }
}

/// [`output_error`]'s problem on `record` before its minimisation: the
/// step segments, their noise and starts, and the start values (`start`,
/// or as [`output_error`] finds them).
pub fn prepare_output_error<'a>(
    record: &'a Record,
    start: Option<DcParams>,
    options: &OutputErrorOptions,
) -> Result<PreparedFit<'a>, NotApplicable> {
    let mut warnings = Vec::new();

    let candidates: Vec<(usize, &DcSegment)> = record
        .segments
        .iter()
        .enumerate()
        .filter(|(_, s)| {
            s.time.len() >= MIN_SAMPLES
                && s.kind != Some(SegmentKind::DcCoastdown)
                && !is_coastdown(s)
        })
        .collect();
    if candidates.is_empty() {
        return Err(NotApplicable::Missing(format!(
            "needs at least one step segment of {MIN_SAMPLES} samples or more"
        )));
    }
    let segments: Vec<&DcSegment> = candidates.iter().map(|(_, s)| *s).collect();
    super::equation_error::excites(&segments)?;
    let noise = channel_noise(segments.iter().copied(), &mut warnings);
    let sigma = [noise.current, noise.speed];

    let mut ee_start = None;
    let mut poorly_conditioned = false;
    let statics = match start {
        Some(p) => {
            p.validate().map_err(|e| {
                NotApplicable::Unidentifiable(format!("the start values are not a motor: {e}"))
            })?;
            p
        }
        None => match steady_state_start(record) {
            Ok(p) => p,
            Err(why) => {
                let ee = super::equation_error(record, options.speed_reading).map_err(|e| {
                    NotApplicable::Missing(format!(
                        "no start values: {why}; the equation-error fit {e}"
                    ))
                })?;
                warnings.push(format!(
                    "output_error: started from the equation-error estimate ({why})"
                ));
                poorly_conditioned = ["La", "Ra", "K", "J"].iter().any(|key| {
                    ee.warnings.iter().any(|w| {
                        w.starts_with(&format!("equation_error: {key} is poorly determined"))
                    })
                });
                ee_start = Some(ee.params);
                ee.params
            }
        },
    };
    let statics = with_positive_friction(statics, &candidates);

    let mut inputs = Vec::new();
    for &(pos, seg) in &candidates {
        match segment_start(record, pos, &statics, noise.speed) {
            Ok((start, level_before)) => inputs.push(SegmentInput {
                level_before,
                ..SegmentInput::new(seg, start)
            }),
            Err(why) => warnings.push(format!(
                "output_error: segment {} ({}) is not fitted: {why}",
                seg.index, seg.label
            )),
        }
    }
    if inputs.is_empty() {
        return Err(NotApplicable::Missing(
            "no step segment starts from a known state".into(),
        ));
    }
    let data = FitData {
        segments: inputs,
        sigma,
        reading: options.speed_reading,
    };
    let start = match start.or(ee_start) {
        Some(p) => p,
        None => {
            let (p, from_data) =
                start::crude_start(&statics, &data.segments, sigma, options.speed_reading);
            for (name, ok) in ["La", "J"].iter().zip(from_data) {
                if !ok {
                    warnings.push(format!(
                        "output_error: no step changed the signals enough to estimate {name} for a start; \
                         a generic start was used"
                    ));
                }
            }
            p
        }
    };

    Ok(PreparedFit {
        candidates,
        noise,
        data,
        start,
        poorly_conditioned,
        warnings,
    })
}

/// Noise of voltage, current and speed from the first differences over
/// the last quarter of each segment: `σ² = mean(Δy²)/2` for white noise,
/// and slow drift of a not quite settled tail hardly adds to it.
fn channel_noise<'a>(
    segments: impl Iterator<Item = &'a DcSegment>,
    warnings: &mut Vec<String>,
) -> ChannelNoise {
    let mut diffs: [Vec<f64>; 3] = Default::default();
    let mut peak = [0.0f64; 3];
    for s in segments {
        let n = s.time.len();
        let channels = [&s.voltage, &s.current, &s.speed];
        let tail = (n / 4).max(MIN_SAMPLES / 2).min(n - 1);
        for (c, y) in channels.iter().enumerate() {
            diffs[c].extend((n - tail..n).map(|k| y[k] - y[k - 1]));
            peak[c] = y.iter().fold(peak[c], |m, v| m.max(v.abs()));
        }
    }
    let sigma: [f64; 3] = std::array::from_fn(|c| difference_noise(&diffs[c]));
    let mut weight = [sigma[1], sigma[2]];
    for (c, name) in ["current", "speed"].iter().enumerate() {
        if weight[c].is_nan() || weight[c] <= 0.0 {
            weight[c] = 1e-6 * peak[c + 1].max(1e-9);
            warnings.push(format!(
                "output_error: the {name} reading does not vary over the settled tails (noise below its \
                 resolution); its residuals are weighted by 1e-6 of its largest value"
            ));
        }
    }
    ChannelNoise {
        voltage: sigma[0],
        current: weight[0],
        speed: weight[1],
    }
}

/// Refuse an optimum no turning motor has, judged by the record alone:
/// a static torque above the largest electromagnetic torque the record
/// shows (`K·|i|max`: the rotor would never have turned), or an inertia
/// whose kinetic energy at the record's top speed exceeds all the
/// electrical energy the armature took in. Such an optimum is a local one
/// the start led to; the other methods still report.
fn physical<'a>(
    p: &DcParams,
    segments: impl Iterator<Item = &'a DcSegment> + Clone,
) -> Result<(), NotApplicable> {
    let i_max = segments
        .clone()
        .flat_map(|s| s.current.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    if p.tst > p.k * i_max {
        return Err(NotApplicable::Unidentifiable(format!(
            "the fit ends at Tst = {:.4e} N*m, more than the largest torque the record shows \
             (K·|i|max = {:.4e} N*m): a rotor that turns cannot have it, so this optimum is \
             not physical",
            p.tst,
            p.k * i_max
        )));
    }
    let mut energy = 0.0;
    let (mut w_first, mut w_max) = (None, 0.0f64);
    for s in segments {
        for k in 1..s.time.len() {
            energy += (s.voltage[k] * s.current[k]).max(0.0) * (s.time[k] - s.time[k - 1]);
        }
        w_first.get_or_insert(s.speed.first().map_or(0.0, |w| w.abs()));
        w_max = s.speed.iter().fold(w_max, |m, w| m.max(w.abs()));
    }
    let gained = 0.5 * p.j * (w_max.powi(2) - w_first.unwrap_or(0.0).powi(2));
    if gained > energy {
        return Err(NotApplicable::Unidentifiable(format!(
            "the fit ends at J = {:.4e} kg*m^2, whose kinetic energy at the record's top speed \
             ({gained:.4e} J) exceeds all the electrical energy the armature took in \
             ({energy:.4e} J), so this optimum is not physical",
            p.j
        )));
    }
    Ok(())
}

/// `σ = √(mean(Δy²)/2)` over the first differences `d`, leaving out a
/// difference beyond [`JUMP`] times their median magnitude: a step inside
/// a tail that is too short to settle (a level held a few samples) is not
/// noise. Noise never reaches that far (for Gaussian noise the median is
/// 0.67 of the differences' deviation), so a settled tail keeps every
/// difference; readings below their resolution (median zero) keep them
/// all too.
fn difference_noise(d: &[f64]) -> f64 {
    let mut magnitudes: Vec<f64> = d.iter().map(|v| v.abs()).collect();
    let limit = match crate::identify::stats::median(&mut magnitudes) {
        Some(m) if m > 0.0 => JUMP * m,
        _ => f64::INFINITY,
    };
    let (sum, count) = d
        .iter()
        .filter(|v| v.abs() <= limit)
        .fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    (sum / (2.0 * count.max(1) as f64)).sqrt()
}

/// Differences beyond this many times their median magnitude are steps,
/// not noise (see [`difference_noise`]).
const JUMP: f64 = 12.0;

/// K, Ra, f, Tst from the steady-state fit (La and J placeholders).
fn steady_state_start(record: &Record) -> Result<DcParams, NotApplicable> {
    let levels: Vec<_> = record
        .segments
        .iter()
        .filter(|s| s.kind != Some(SegmentKind::DcCoastdown) && !is_coastdown(s))
        .filter_map(settled_level)
        .filter(|l| l.settled)
        .collect();
    let fit = super::steady_state::fit(record, &levels).map_err(|e| {
        NotApplicable::Missing(format!(
            "no start values: the steady-state fit does not apply ({e})"
        ))
    })?;
    let e = fit.estimate;
    if !(e.k > 0.0 && e.ra > 0.0) {
        return Err(NotApplicable::Unidentifiable(format!(
            "no start values: the steady-state fit gives K = {:.4}, Ra = {:.4}",
            e.k, e.ra
        )));
    }
    Ok(DcParams {
        ra: e.ra,
        la: 1.0,
        k: e.k,
        j: 1.0,
        f: e.f,
        tst: e.tst,
    })
}

/// f and Tst raised to a small positive value where a start has them at
/// (or below) zero: the fit works on their logarithms.
fn with_positive_friction(p: DcParams, segments: &[(usize, &DcSegment)]) -> DcParams {
    let i_max = segments
        .iter()
        .flat_map(|(_, s)| s.current.iter())
        .fold(0.0f64, |m, i| m.max(i.abs()));
    DcParams {
        f: if p.f > 0.0 {
            p.f
        } else {
            1e-3 * p.k * p.k / p.ra
        },
        tst: if p.tst > 0.0 {
            p.tst
        } else {
            1e-3 * p.k * i_max.max(1e-6)
        },
        ..p
    }
}

/// How the segment at `pos` in `record` starts, and where its start
/// voltage was averaged (see [`SegmentInput::level_before`]); `Err` when
/// it follows a level that had not settled (its start is then unknown).
///
/// Settled at the mean voltage of the settled tail of the level before
/// when that level is the previous segment of the record, else at the
/// segment's first voltage reading; from rest when the first speed
/// reading is zero within its noise although that steady state would turn
/// the rotor.
fn segment_start(
    record: &Record,
    pos: usize,
    params: &DcParams,
    speed_noise: f64,
) -> Result<(SegmentStart, Option<(u32, usize)>), NotApplicable> {
    let seg = &record.segments[pos];
    let mut u0 = seg.voltage[0];
    let mut level_before = None;
    if pos > 0 {
        let prev = &record.segments[pos - 1];
        let dt = (seg.time[seg.time.len() - 1] - seg.time[0]) / (seg.time.len() - 1) as f64;
        let adjacent = prev
            .time
            .last()
            .is_some_and(|&t| t >= seg.time[0] - 1.5 * dt);
        let is_step = prev.kind != Some(SegmentKind::DcCoastdown) && !is_coastdown(prev);
        if adjacent && is_step {
            match settled_level(prev) {
                Some(level) if level.settled => {
                    u0 = level.voltage;
                    level_before = Some((prev.index, level.samples));
                }
                Some(_) => return Ok((state_at_end_start(prev), None)),
                None => {
                    return Err(NotApplicable::Missing(format!(
                        "the segment before it ({}) is too short to give its start",
                        prev.index
                    )))
                }
            }
        } else if !is_step || !adjacent {
            return Ok((first_state(seg, params, speed_noise), None));
        }
    } else {
        return Ok((first_state(seg, params, speed_noise), None));
    }
    let at_rest = seg.speed[0].abs() <= 3.0 * speed_noise;
    let would_turn = params.steady_state(u0).speed.abs() > 6.0 * speed_noise;
    Ok(if at_rest && would_turn {
        (SegmentStart::FromRest, None)
    } else {
        (SegmentStart::Settled(u0), level_before)
    })
}

/// The start of a segment after `prev`, a level that had not settled:
/// the state at `prev`'s last instant (the next segment's first sample).
fn state_at_end_start(prev: &DcSegment) -> SegmentStart {
    let (current, speed) = state_at_end(prev);
    SegmentStart::State { current, speed }
}

/// Current and speed at the end of `prev` from a straight line through
/// its last readings (up to 16, a quarter of the segment at most).
pub fn state_at_end(prev: &DcSegment) -> (f64, f64) {
    let n = prev.time.len();
    let m = (n / 4).clamp(2, 16);
    let t = &prev.time[n - m..];
    let at_end = |y: &[f64]| {
        let tm = t.iter().sum::<f64>() / m as f64;
        let ym = y.iter().sum::<f64>() / m as f64;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for (ti, yi) in t.iter().zip(y) {
            sxy += (ti - tm) * (yi - ym);
            sxx += (ti - tm).powi(2);
        }
        let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
        ym + slope * (t[m - 1] - tm)
    };
    (at_end(&prev.current[n - m..]), at_end(&prev.speed[n - m..]))
}

/// How a segment with no settled level before it starts: from rest when
/// its first speed reading is zero within the noise and the steady state
/// of its first voltage would turn the rotor; settled at its first voltage
/// when its first readings are that steady state; else in the measured
/// state of its first readings (a record that starts in motion).
fn first_state(seg: &DcSegment, params: &DcParams, speed_noise: f64) -> SegmentStart {
    let u0 = seg.voltage[0];
    let ss = params.steady_state(u0);
    let at_rest = seg.speed[0].abs() <= 3.0 * speed_noise;
    if at_rest && ss.speed.abs() > 6.0 * speed_noise {
        return SegmentStart::FromRest;
    }
    let near = (ss.speed - seg.speed[0]).abs() <= (6.0 * speed_noise).max(0.02 * ss.speed.abs());
    if near || at_rest {
        SegmentStart::Settled(u0)
    } else {
        SegmentStart::State {
            current: seg.current[0],
            speed: seg.speed[0],
        }
    }
}

/// Each segment of `data` held out in turn: the fit on the others from
/// the all-segment optimum `best`, and its NRMSE on the held-out segment.
fn held_out_refits(
    data: &FitData,
    problem: &OutputErrorProblem,
    best: &problem::Minimum,
) -> Vec<HeldOut> {
    let mut held_out = Vec::new();
    let mut row0 = 0;
    for n in 0..data.segments.len() {
        let rows = row0..row0 + 2 * data.segments[n].len();
        row0 = rows.end;
        let rest = FitData {
            segments: data
                .segments
                .iter()
                .enumerate()
                .filter(|(m, _)| *m != n)
                .map(|(_, s)| *s)
                .collect(),
            ..data.clone()
        };
        let fold = minimise(&rest, &one_step_without(problem, best, rows));
        let input = &data.segments[n];
        if let Some(nrmse) = segment_nrmse(&fold.params, input, data.reading) {
            held_out.push(HeldOut {
                segment: input.seg.index,
                params: fold.params,
                nrmse,
            });
        }
    }
    held_out
}

/// A start for the fit without the residual rows `rows` (one segment):
/// one Gauss–Newton step from the all-segment optimum using its own
/// Jacobian with those rows removed. The refit then needs few
/// evaluations; it converges to its own optimum whatever the start.
fn one_step_without(
    problem: &OutputErrorProblem,
    best: &problem::Minimum,
    rows: std::ops::Range<usize>,
) -> DcParams {
    let (jac, r) = (&best.at.jac, &best.at.r);
    let held_j = jac.rows(rows.start, rows.len());
    let held_r = r.rows(rows.start, rows.len());
    let g = jac.tr_mul(r) - held_j.tr_mul(&held_r);
    let h = jac.tr_mul(jac) - held_j.tr_mul(&held_j);
    let step = h
        .try_inverse()
        .map(|inv| -(inv * g))
        .filter(|s| s.iter().all(|v| v.is_finite() && v.abs() < 1.0))
        .unwrap_or_else(Vector6::zeros);
    problem.params_at(&(best.at.x + step))
}

/// Mean NRMSE of current and speed of `params` on `input`.
fn segment_nrmse(params: &DcParams, input: &SegmentInput, reading: SpeedReading) -> Option<f64> {
    let (i, w) = simulate_series(params, input, reading).ok()?;
    let parts: Vec<f64> = [nrmse(&input.seg.current, &i), nrmse(&input.seg.speed, &w)]
        .into_iter()
        .flatten()
        .collect();
    (!parts.is_empty()).then(|| parts.iter().sum::<f64>() / parts.len() as f64)
}

impl OutputErrorFit {
    /// Whether the residuals exceed the noise level of the settled tails
    /// enough to say the model does not describe the data (the warning
    /// "the residuals are … times the noise level").
    pub fn misfit(&self) -> bool {
        self.uncertainty.residual_variance > MISFIT_VARIANCE
    }

    /// The contract's view of this fit.
    pub fn method_report(&self) -> MethodReport {
        let values = to_array(&self.params);
        let params = (0..NP)
            .map(|n| {
                (
                    PARAM_KEYS[n].to_string(),
                    ParamEstimate {
                        value: values[n],
                        ci95: self.uncertainty.ci95[n],
                        unit: PARAM_UNITS[n].to_string(),
                    },
                )
            })
            .collect();
        MethodReport::fitted(params, self.validation_nrmse)
    }

    /// The 95 % interval of the parameter with contract key `key` (`None`
    /// for an unknown key or where the record does not determine it).
    pub fn ci95_of(&self, key: &str) -> Option<[f64; 2]> {
        let n = PARAM_KEYS.iter().position(|k| *k == key)?;
        self.uncertainty.ci95[n]
    }

    /// Details for the text report: noise levels, residual level, the
    /// correlation matrix, the Jacobian's singular values, the held-out
    /// scores.
    pub fn render_details(&self) -> String {
        let mut out = String::new();
        let u = &self.uncertainty;
        let _ = writeln!(
            out,
            "  noise (settled tails): voltage {:.3e} V, current {:.3e} A, speed {:.3e} rad/s; residual level {:.2}× noise ({} dof)",
            self.noise.voltage,
            self.noise.current,
            self.noise.speed,
            u.residual_variance.sqrt(),
            u.dof
        );
        let s = to_array(&self.start);
        let _ = writeln!(
            out,
            "  started at Ra {:.4e}, La {:.4e}, K {:.4e}, J {:.4e}, f {:.4e}, Tst {:.4e}; {} evaluations{}",
            s[0],
            s[1],
            s[2],
            s[3],
            s[4],
            s[5],
            self.evaluations,
            if self.converged { "" } else { " (not converged)" }
        );
        let shift: Vec<String> = (0..NP)
            .map(|n| {
                format!(
                    "{} {:+.2}σ",
                    PARAM_KEYS[n],
                    self.input_noise_shift[n] / u.std_ln[n]
                )
            })
            .collect();
        let _ = writeln!(
            out,
            "  voltage-noise bias removed from the least-squares optimum: {}",
            shift.join(", ")
        );
        let _ = writeln!(out, "  correlation of the estimates:");
        let _ = write!(out, "  {:>5}", "");
        for key in PARAM_KEYS {
            let _ = write!(out, " {key:>7}");
        }
        let _ = writeln!(out);
        for (a, row) in u.correlation.iter().enumerate() {
            let _ = write!(out, "  {:>5}", PARAM_KEYS[a]);
            for &c in row {
                let _ = write!(out, " {}", correlation_cell(c));
            }
            let _ = writeln!(out);
        }
        let sv: Vec<String> = u
            .relative_singular_values
            .iter()
            .map(|v| format!("{v:.2e}"))
            .collect();
        let _ = writeln!(
            out,
            "  singular values of the scaled Jacobian (relative): {}",
            sv.join(", ")
        );
        if !self.held_out.is_empty() {
            let scores: Vec<String> = self
                .held_out
                .iter()
                .map(|h| format!("{}: {:.4}", h.segment, h.nrmse))
                .collect();
            let _ = writeln!(out, "  held-out NRMSE by segment: {}", scores.join(", "));
        }
        out
    }
}

/// One cell of the printed correlation matrix, 7 characters wide: a
/// parameter held at its bound (Tst at 0) has no variance and no
/// correlation (0/0), printed as a dash, never as NaN.
fn correlation_cell(c: f64) -> String {
    if c.is_finite() {
        format!("{c:>+7.3}")
    } else {
        format!("{:>7}", "—")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// The white noise of every reading of the test records, drawn from a
    /// generator seeded with `seed`: the generator and the distributions
    /// of the voltage (0.1 V), current (2 mA) and speed (0.3 rad/s) noise.
    fn reading_noise(seed: u64) -> (StdRng, [Normal<f64>; 3]) {
        (
            StdRng::seed_from_u64(seed),
            [
                Normal::new(0.0, 0.1).unwrap(),
                Normal::new(0.0, 0.002).unwrap(),
                Normal::new(0.0, 0.3).unwrap(),
            ],
        )
    }

    /// A staircase of `levels` (from rest), each held `seconds`, simulated
    /// exactly with `p` at 2 kHz, with white noise on every reading.
    fn record(p: &DcParams, levels: &[f64], seconds: f64, seed: u64) -> Record {
        let dt = 5e-4;
        let n = (seconds / dt) as usize;
        let (mut rng, [nu, ni, nw]) = reading_noise(seed);
        let mut segments = Vec::new();
        let mut t0 = 0.0;
        for (s, &level) in levels.iter().enumerate() {
            let before = if s == 0 { None } else { Some(levels[s - 1]) };
            let mut seg = DcSegment {
                index: s as u32,
                kind: Some(SegmentKind::DcStep),
                label: format!("{level} V"),
                time: (0..n).map(|k| t0 + k as f64 * dt).collect(),
                voltage: (0..n)
                    .map(|k| {
                        if k == 0 {
                            before.unwrap_or(level)
                        } else {
                            level
                        }
                    })
                    .collect(),
                ..Default::default()
            };
            let start = before.map_or(SegmentStart::FromRest, SegmentStart::Settled);
            let input = SegmentInput::new(&seg, start);
            let (i, w) = simulate_series(p, &input, SpeedReading::IntervalMean).unwrap();
            seg.current = i.iter().map(|v| v + ni.sample(&mut rng)).collect();
            seg.speed = w.iter().map(|v| v + nw.sample(&mut rng)).collect();
            for v in &mut seg.voltage {
                *v += nu.sample(&mut rng);
            }
            t0 = seg.time[n - 1];
            segments.push(seg);
        }
        Record {
            segments,
            ..Default::default()
        }
    }

    #[test]
    fn an_optimum_no_turning_motor_has_is_refused() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let rec = record(&p, &[60.0, 248.0], 0.6, 1);
        let segs = || rec.segments.iter();
        assert!(physical(&p, segs()).is_ok());
        let stuck = DcParams { tst: 1e3, ..p };
        let e = physical(&stuck, segs()).unwrap_err().to_string();
        assert!(e.contains("Tst") && e.contains("not physical"), "{e}");
        let heavy = DcParams { j: 1e4, ..p };
        let e = physical(&heavy, segs()).unwrap_err().to_string();
        assert!(e.contains("kinetic energy"), "{e}");
    }

    #[test]
    fn recovers_a_simulated_staircase_within_its_intervals() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let rec = record(&p, &[60.0, 248.0, 107.0, 201.0], 0.6, 1);
        let fit = output_error(&rec, None, &OutputErrorOptions::default()).unwrap();
        assert!(fit.converged);
        assert_eq!(fit.segments[0], (0, SegmentStart::FromRest));
        assert!(matches!(fit.segments[1].1, SegmentStart::Settled(u) if (u - 60.0).abs() < 0.05));
        let truth = to_array(&p);
        let got = to_array(&fit.params);
        for n in 0..NP {
            let [lo, hi] = fit.uncertainty.ci95[n].unwrap();
            assert!(
                lo <= truth[n] && truth[n] <= hi,
                "{}: {} not in [{lo}, {hi}]",
                PARAM_KEYS[n],
                truth[n]
            );
            assert!(
                ((got[n] - truth[n]) / truth[n]).abs() < 0.02,
                "{}",
                PARAM_KEYS[n]
            );
        }
        // White noise at the levels the weights assume: s² near 1.
        assert!((fit.uncertainty.residual_variance - 1.0).abs() < 0.1);
        assert!((fit.noise.current - 0.002).abs() < 2e-4 && (fit.noise.speed - 0.3).abs() < 0.03);
        assert_eq!(fit.held_out.len(), 4);
        let v = fit.validation_nrmse.unwrap();
        assert!(v > 0.0 && v < 0.05, "validation NRMSE {v}");
        assert_eq!(fit.simulated.len(), 4);
        assert!(fit.warnings.is_empty(), "{:?}", fit.warnings);
        let report = fit.method_report();
        let params = report.params.unwrap();
        assert_eq!(params.len(), 6);
        assert_eq!(params["La"].unit, "H");
        assert_eq!(params["J"].unit, "kg*m^2");
        assert_eq!(params["Ra"].ci95, fit.ci95_of("Ra"));
        assert_eq!(report.validation_nrmse, fit.validation_nrmse);
        assert!(fit
            .render_details()
            .contains("correlation of the estimates"));
    }

    #[test]
    fn a_correlation_without_variance_prints_as_a_dash_not_nan() {
        assert_eq!(correlation_cell(-0.379), " -0.379");
        assert_eq!(correlation_cell(f64::NAN), "      —");
        assert_eq!(correlation_cell(f64::INFINITY), "      —");
    }

    #[test]
    fn a_record_shorter_than_the_mechanical_time_constant_warns_about_the_friction() {
        // One step from rest lasting a third of τm ≈ 54 ms: the speed is
        // nowhere near settled. The initial acceleration K·i/J still gives
        // J; the viscous friction, which shows only as the speed levels
        // off, is not determined.
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let rec = record(&p, &[248.0], 0.02, 2);
        let fit = output_error(&rec, Some(p), &OutputErrorOptions::default()).unwrap();
        let text = fit.warnings.join("\n");
        assert!(fit.uncertainty.flagged[4], "{text}");
        assert!(
            text.contains("output_error: f is poorly determined"),
            "{text}"
        );
        assert!(text.contains("3 mechanical time constants"), "{text}");
        assert!(text.contains("no held-out validation"), "{text}");
    }

    /// A staircase of `levels` (from rest), `per` samples each, simulated
    /// as one continuous run at 2 kHz (each segment starts where the one
    /// before ended, settled or not), with white noise on every reading.
    fn continuous(p: &DcParams, levels: &[f64], per: usize, seed: u64) -> Record {
        use crate::model::{DcMotor, DcState, Terminal};
        let dt = 5e-4;
        let motor = DcMotor::new(*p, dt).unwrap();
        let (mut rng, [nu, ni, nw]) = reading_noise(seed);
        let n = levels.len() * per + 1;
        let mut x = DcState::default();
        let mut all = Vec::new();
        for k in 0..n {
            let u = levels[(k.saturating_sub(1) / per).min(levels.len() - 1)];
            let before = x.angle;
            x = motor.step(&x, Terminal::Driven(u));
            all.push((
                u + nu.sample(&mut rng),
                x.current + ni.sample(&mut rng),
                (x.angle - before) / dt + nw.sample(&mut rng),
            ));
        }
        let segments = (0..levels.len())
            .map(|s| {
                let r = s * per..=(s + 1) * per;
                DcSegment {
                    index: s as u32,
                    kind: Some(SegmentKind::DcStep),
                    label: format!("{} V", levels[s]),
                    time: r.clone().map(|k| k as f64 * dt).collect(),
                    voltage: all[r.clone()].iter().map(|v| v.0).collect(),
                    current: all[r.clone()].iter().map(|v| v.1).collect(),
                    speed: all[r].iter().map(|v| v.2).collect(),
                }
            })
            .collect();
        Record {
            segments,
            ..Default::default()
        }
    }

    #[test]
    fn a_segment_after_an_unsettled_level_starts_from_the_state_at_its_end() {
        // Levels held 80 ms (1.5 mechanical time constants): none settles.
        // Each segment starts where the one before ended (a line through
        // its last readings), and the fit still finds the motor.
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let rec = continuous(&p, &[60.0, 248.0, 107.0], 160, 3);
        let fit = output_error(&rec, None, &OutputErrorOptions::default()).unwrap();
        let fitted: Vec<u32> = fit.segments.iter().map(|s| s.0).collect();
        assert_eq!(fitted, [0, 1, 2]);
        for (n, (_, start)) in fit.segments.iter().enumerate().skip(1) {
            let prev = &rec.segments[n - 1];
            let (i_end, w_end) = (*prev.current.last().unwrap(), *prev.speed.last().unwrap());
            match start {
                SegmentStart::State { current, speed } => {
                    assert!((current - i_end).abs() < 0.01, "{current} vs {i_end}");
                    assert!((speed - w_end).abs() < 1.0, "{speed} vs {w_end}");
                }
                other => panic!("segment {n} starts {other:?}"),
            }
        }
        assert!(fit
            .warnings
            .iter()
            .any(|w| w.contains("started from the equation-error estimate")));
        for (got, want, name) in [(fit.params.k, p.k, "K"), (fit.params.ra, p.ra, "Ra")] {
            assert!(((got - want) / want).abs() < 0.01, "{name} {got}");
        }
    }

    #[test]
    fn no_step_segment_is_an_error() {
        let err =
            output_error(&Record::default(), None, &OutputErrorOptions::default()).unwrap_err();
        assert!(err.to_string().contains("step segment"), "{err}");
    }
}
