//! DC motor diagnosis of a staircase record (voltage steps, each held
//! until settled, usually followed by a coast-down).
//!
//! 1. The paper's model is fitted by output error to every segment at
//!    once (started from the identification's own output-error fit), then
//!    refitted without each fold of held-out data: by default interleaved
//!    blocks of 128 samples in every segment, five folds (`cv.rs`), so
//!    that every fold sees every segment's operating range; with
//!    `MOTORBENCH_DC_VALIDATION=segments` each segment in turn (the
//!    coast-down too). The held-out simulation from the measured voltage
//!    gives the nominal residual and `gap_before`.
//! 2. The residual is localised (`gap.rs`).
//! 3. Every candidate of the vocabulary (`candidates.rs`) is refitted with
//!    the nominal parameters on all segments and then on the same folds,
//!    each fold refitted in one Gauss–Newton step from the candidate's
//!    all-data optimum (`fit::one_step_refit`; iterated from there when
//!    that step is long or the residuals are not linear over it); the fits
//!    run on every core (`std::thread::scope`).
//! 4. Candidates are ranked by the held-out penalised score and tested
//!    with the paired held-out block test of `decision`; the verdict is the
//!    best significant, physically signed candidate that explains the gap,
//!    unless a higher-ranked one that explains part of it is as good on
//!    the held-out blocks (`choice.rs`); else `none`.

mod candidates;
mod choice;
mod cv;
mod fit;
mod gap;
mod lanes;
mod model;
mod windows;

use std::collections::BTreeMap;

use statrs::distribution::{ChiSquared, ContinuousCDF};

use self::candidates::{
    candidates, effect_params, extra_params, immaterial, physical, separating_plan, undetermined,
    CandidateDef, RecordScales,
};
use self::choice::{choose, Ranked, Refusal};
use self::fit::{
    fit, fit_fold, one_step_refit, refit_spec, runs_residuals, without, FitSpec, Fitted, Transform,
    Weights,
};
use self::gap::{locate, spectral_peak, HeldOutSeries, Measured};
use self::model::{AugModel, Continuation, SegmentRun, Start};
use crate::contract::{
    reportable, Candidate, Diagnosis, Gap, LookAlike, NominalFit, ParamCorrection, Verdict,
};
use crate::diagnose::decision::{
    block_sums, effective_samples, explained_share, held_out_either_sign_flip_test, held_out_test,
    median, no_baseline, partial_verdict_warning, penalised_score, residual_noise_sigma,
    unexplained_gap_warning, HeldOutTest, EXPLAINED,
};
use crate::diagnose::par_map;
use crate::diagnose::{DiagnoseError, DiagnoseOptions, DiagnosisRun, ResidualPanel, ResidualPlot};
use crate::identify::{
    is_coastdown, nrmse, output_error, OutputErrorOptions, PARAM_KEYS, PARAM_UNITS,
};
use crate::model::{DcParams, Effect};
use crate::record::{DcSegment, Record, SegmentKind, SCHEMA_VERSION};
use crate::report::ParamEstimate;

/// Fewest samples a segment needs to take part.
use crate::machine::dc::join::MIN_SAMPLES;

/// Samples per block of the held-out test: 16 ms at 2 kHz, long against
/// the encoder noise's one-sample correlation.
const BLOCK: usize = 32;

/// Smallest share of the nominal model's excess over the noise floor
/// (`gap² − floor²`, the residual power that is not noise) an effect must
/// remove to be named. Where the nominal already fits close to the floor,
/// rule (f) holds for any candidate; an effect that causes the gap
/// removes most of its excess, one that takes up a little of it with its
/// extra freedom (a fraction of a sample's lag, a voltage offset) does
/// not.
const EXPLAINED_SHARE: f64 = 0.5;

/// Share of the nominal model's excess over the noise floor above which
/// an effect is the gap's main cause even when what it leaves is more
/// than `EXPLAINED` noise floors: it removes four fifths of the residual
/// power that is not noise, and what remains is smaller than what it
/// explained by a factor of four. It is named, with a warning that the
/// rest of the gap is something else (a second effect, or the candidate's
/// shape differing from the plant's: a first-order lag for a delay).
/// Measured on the blind suites before the rule: every candidate refused
/// only for leaving more than twice the floor was the withheld effect, at
/// shares of 0.90 to 0.996 (docs/diagnosis-dc.md).
const DOMINANT_SHARE: f64 = 0.8;

/// Optimiser patience (evaluations per parameter) of an all-segment fit
/// and of a fold's refit (warm-started next to its optimum).
const PATIENCE_ALL: usize = 12;
const PATIENCE_FOLD: usize = 6;

/// The diagnosis of one model family (nominal or a candidate).
struct FamilyResult {
    all: Fitted,
    transforms: Vec<Transform>,
    folds: Vec<HeldOutSeries>,
    /// Noise-weighted squared held-out residual per block, all folds.
    blocks: Vec<f64>,
    sse: f64,
    validation: f64,
}

/// Most segments the diagnosis leaves out because the nominal model
/// refitted without them fails.
const MAX_LEFT_OUT: usize = 3;

/// Why one pass of the diagnosis ended without a result.
enum Attempt {
    /// The record cannot be diagnosed.
    Failed(DiagnoseError),
    /// The nominal model refitted without this segment (its index) fails,
    /// so the segment cannot be held out.
    FoldFailed(u32),
    /// The nominal model refitted without an interleaved fold fails.
    InterleavedFailed,
}

impl From<DiagnoseError> for Attempt {
    fn from(e: DiagnoseError) -> Attempt {
        Attempt::Failed(e)
    }
}

/// Diagnose a `dc_step` record. A segment that cannot be held out (the
/// nominal model refitted without it fails: a short part of a segment
/// cut at a gap in its time, say) is left out of the diagnosis with a
/// warning and the diagnosis repeated, up to [`MAX_LEFT_OUT`] segments
/// and while two remain, rather than refusing the record.
pub fn diagnose_dc(
    record: &Record,
    options: &DiagnoseOptions,
) -> Result<DiagnosisRun, DiagnoseError> {
    let mut left_out = Vec::new();
    // The join's note is the record's, which the report lists.
    let joined = crate::machine::dc::join::join_short_continuations(record, "the diagnosis")
        .map(|j| j.record);
    let record = joined.as_ref().unwrap_or(record);
    // A long record is read in windows (the note says so).
    let windowed = windows::windowed(record);
    let record = windowed.as_ref().unwrap_or(record);
    let mut trimmed: Option<Record> = None;
    let mut options = *options;
    loop {
        let current = trimmed.as_ref().unwrap_or(record);
        let index = match diagnose_once(current, &options) {
            Ok(mut run) => {
                left_out.append(&mut run.report.warnings);
                run.report.warnings = left_out;
                return Ok(run);
            }
            Err(Attempt::Failed(e)) => return Err(e),
            Err(Attempt::FoldFailed(index)) => index,
            // A fold of interleaved blocks the nominal model cannot be
            // refitted without (a short part of a segment after a gap):
            // hold out whole segments instead, which can leave one out
            // (and cannot fail so).
            Err(Attempt::InterleavedFailed) => {
                left_out.push(
                    "the nominal model refitted without a fold of interleaved blocks fails; \
                     whole segments are held out instead"
                        .into(),
                );
                options.dc_interleaved = Some(false);
                continue;
            }
        };
        let failed = || {
            DiagnoseError::NominalFit(format!("the nominal refit without segment {index} failed"))
        };
        if left_out.len() >= MAX_LEFT_OUT || current.segments.len() <= 2 {
            return Err(failed());
        }
        let mut next = current.clone();
        let Some(at) = next.segments.iter().position(|s| s.index == index) else {
            return Err(failed());
        };
        let seg = next.segments.remove(at);
        left_out.push(format!(
            "segment {index} ({}) is left out of the diagnosis: the nominal model refitted \
             without it fails, so it cannot be held out",
            seg.label
        ));
        trimmed = Some(next);
    }
}

/// One pass of [`diagnose_dc`] over `record` as it is.
fn diagnose_once(record: &Record, options: &DiagnoseOptions) -> Result<DiagnosisRun, Attempt> {
    let mut warnings = record.notes.clone();
    warnings.extend(crate::identify::clipped_channels(record));
    warnings.extend(crate::identify::reading_offset_warning(record));
    // Nominal: start from the identification's output-error fit, whose
    // parameters also say where a record's first segment starts when it
    // is not plainly at rest (fitted only once a segment needs it, so
    // that the record's own refusals come first).
    let oe = std::cell::OnceCell::new();
    let nominal_oe = || {
        oe.get_or_init(|| {
            output_error(
                record,
                None,
                &OutputErrorOptions {
                    validate: false,
                    correct_input_noise: false,
                    ..Default::default()
                },
            )
            .map(|fit| fit.params)
            .map_err(|e| e.to_string())
        })
        .clone()
    };
    let held = held_levels(&record.segments);
    let pieces = voltage_pieces(&record.segments);
    let NominalStart {
        runs,
        weights,
        scales: scales0,
        spec: nominal_spec,
        all: nominal_all,
    } = nominal_of_inputs(&held, pieces.as_ref(), &nominal_oe, &mut warnings)?;
    let candidate_base = floored(&nominal_all.model, scales0.dt, scales0.i_max);
    if !nominal_all.converged {
        warnings.push("the nominal fit stopped without converging".into());
    }

    // The largest spectral peak of the all-segment nominal residual in each
    // channel starts a shaft-compliance fit at that resonance. A start
    // decides nothing (the tests below do), so a peak need not be
    // significant to be tried.
    let peaks_hz = all_segment_peaks(&nominal_all.model, &runs, scales0.dt);
    let nominal_noise = residual_weights(&nominal_all.model, &runs);
    let scales = RecordScales {
        peaks_hz,
        w_noise: 1.0 / nominal_noise.speed,
        ..scales0
    };

    // Phase 1: nominal folds and candidates' all-segment fits.
    let defs = candidates(&nominal_all.model, &scales);
    enum Job<'d> {
        NominalFold(usize),
        CandidateAll(&'d CandidateDef),
    }
    // Held out: interleaved time blocks (the default, cv.rs), or whole
    // segments where `MOTORBENCH_DC_VALIDATION=segments` asks for them.
    let cv = options
        .dc_interleaved
        .unwrap_or_else(|| cv::interleaved_requested(&mut warnings));
    let nominal_jobs = if cv { 0 } else { runs.len() };
    let mut jobs: Vec<Job> = (0..nominal_jobs).map(Job::NominalFold).collect();
    jobs.extend(defs.iter().map(Job::CandidateAll));
    enum Out {
        Fold(Option<HeldOutSeries>),
        All(Option<Fitted>),
    }
    let outs = par_map(&jobs, |job| match job {
        Job::NominalFold(h) => Out::Fold(fold(&nominal_spec, &nominal_all, &runs, *h, &weights)),
        Job::CandidateAll(d) => {
            let spec = FitSpec {
                start: AugModel {
                    aug: d.aug,
                    e: d.e,
                    ..candidate_base
                },
                effect: d.transforms.clone(),
            };
            Out::All(fit(&spec, &runs, &weights, PATIENCE_ALL))
        }
    });
    let mut nominal_folds = Vec::new();
    let mut cand_all: Vec<(usize, Fitted)> = Vec::new();
    for (n, o) in outs.into_iter().enumerate() {
        match o {
            Out::Fold(Some(s)) => nominal_folds.push(s),
            Out::Fold(None) => return Err(Attempt::FoldFailed(runs[n].seg.index)),
            Out::All(Some(f)) => cand_all.push((n - nominal_jobs, f)),
            Out::All(None) => warnings.push(format!(
                "candidate {:?} could not be fitted",
                defs[n - nominal_jobs].effect
            )),
        }
    }
    if cv {
        nominal_folds =
            cv::cross_validated(&nominal_spec, &nominal_all, &runs, &weights, PATIENCE_FOLD)
                .ok_or(Attempt::InterleavedFailed)?;
    }
    // An effect fitted more than once (sensor lag on either channel, shaft
    // compliance from each resonance start): keep the fit that explains
    // the fitting data best.
    let best_of = |effect: Effect| {
        cand_all
            .iter()
            .filter(|(d, _)| defs[*d].effect == effect)
            .min_by(|a, b| a.1.sse.total_cmp(&b.1.sse))
            .map(|(d, _)| *d)
    };
    let keep: Vec<Option<usize>> = defs.iter().map(|d| best_of(d.effect)).collect();
    cand_all.retain(|(d, _)| keep[*d] == Some(*d));

    // Phase 2: candidates' folds, warm-started from their optimum.
    let jobs2: Vec<(usize, usize)> = (0..cand_all.len())
        .flat_map(|c| (0..runs.len()).map(move |h| (c, h)))
        .collect();
    let specs: Vec<FitSpec> = cand_all
        .iter()
        .map(|(d, f)| {
            refit_spec(
                &FitSpec {
                    start: f.model,
                    effect: defs[*d].transforms.clone(),
                },
                f,
            )
        })
        .collect();
    let fold_outs = if cv {
        Vec::new()
    } else {
        par_map(&jobs2, |&(c, h)| {
            fold(&specs[c], &cand_all[c].1, &runs, h, &weights)
        })
    };
    let cv_outs = if cv {
        let cs: Vec<usize> = (0..cand_all.len()).collect();
        par_map(&cs, |&c| {
            cv::cross_validated(&specs[c], &cand_all[c].1, &runs, &weights, PATIENCE_FOLD)
        })
    } else {
        Vec::new()
    };

    let w = [weights.current, weights.speed];
    // A held-out segment the nominal predicts far worse than the others (a
    // coast-down predicted from steps alone, whose friction the steps
    // barely show) would outweigh them with the size of a misfit both
    // models share rather than with evidence for or against the effect.
    // So each segment's squares are divided by the larger of the nominal's
    // mean square on it and the median of those over the segments: the
    // outlying segment counts as if it were predicted like a typical one,
    // and every other segment keeps its absolute weight.
    let fold_ms: Vec<f64> = nominal_folds
        .iter()
        .map(|s| {
            let sq = s.weighted_squares(w[0], w[1]);
            sq.iter().sum::<f64>() / sq.len().max(1) as f64
        })
        .collect();
    let median_ms = median(&mut fold_ms.clone()).unwrap_or(0.0);
    let fold_scale: Vec<f64> = fold_ms
        .iter()
        .map(|m| m.max(median_ms).max(f64::MIN_POSITIVE))
        .collect();
    let family = |all: Fitted, transforms: Vec<Transform>, folds: Vec<HeldOutSeries>| {
        let mut blocks = Vec::new();
        let mut sse = 0.0;
        for (s, scale) in folds.iter().zip(&fold_scale) {
            let sq: Vec<f64> = s
                .weighted_squares(w[0], w[1])
                .iter()
                .map(|v| v / scale)
                .collect();
            sse += sq.iter().sum::<f64>();
            blocks.extend(block_sums(&sq, BLOCK));
        }
        let validation = folds.iter().map(|s| s.nrmse).sum::<f64>() / folds.len().max(1) as f64;
        FamilyResult {
            all,
            transforms,
            folds,
            blocks,
            sse,
            validation,
        }
    };
    let nominal = family(nominal_all.clone(), Vec::new(), nominal_folds);
    let nominal_fit_nrmse = fit_nrmse(&nominal_all.model, &runs);
    if let Some(why) = no_baseline(nominal_fit_nrmse, nominal.validation) {
        return Err(DiagnoseError::NominalFit(format!(
            "{why}: no DC motor model follows these readings, and no effect can be judged \
             against it. {CHECK_THE_COLUMNS}"
        ))
        .into());
    }
    let mut families: Vec<(Effect, FamilyResult)> = Vec::new();
    for (c, (d, f)) in cand_all.iter().enumerate() {
        let folds: Option<Vec<HeldOutSeries>> = if cv {
            cv_outs[c].clone()
        } else {
            fold_outs[c * runs.len()..(c + 1) * runs.len()]
                .iter()
                .cloned()
                .collect()
        };
        match folds {
            Some(folds) => families.push((
                defs[*d].effect,
                family(f.clone(), defs[*d].transforms.clone(), folds),
            )),
            None => warnings.push(format!(
                "candidate {:?}: a held-out refit failed; left out",
                defs[*d].effect
            )),
        }
    }

    // Decision.
    let tried = 7usize;
    let n_eff = {
        let (mut ci, mut cw) = (Vec::new(), Vec::new());
        for s in &nominal.folds {
            ci.extend(s.current.iter().map(|v| v * w[0]));
            cw.extend(s.speed.iter().map(|v| v * w[1]));
        }
        effective_samples(&ci) + effective_samples(&cw)
    };
    let mut scored: Vec<(Effect, FamilyResult, HeldOutTest, f64)> = families
        .into_iter()
        .map(|(e, fam)| {
            // Held out: the paired block test of `decision`, in its
            // randomisation form: an effect that shows in a few blocks (a
            // brush drop near zero current, a coast-down's tail) gains
            // much there, which the t-test counts as variance rather than
            // evidence. On the three blind seeds' DC cases it named 4 more
            // withheld effects than the t-test and no false alarm. Each
            // block counts both by its gain and by the share of its misfit
            // the candidate removes (`held_out_either_sign_flip_test`):
            // the first sees a gain spread over many blocks, the second
            // one that one transient predicted worse would outweigh.
            let mut test = held_out_either_sign_flip_test(&nominal.blocks, &fam.blocks, tried);
            // In sample: the likelihood-ratio test of the effect's
            // parameters on all segments. Blocks of one held-out segment
            // share that fold's parameter estimates, so a candidate's
            // extra freedom that merely moves a fold's extrapolation (of a
            // coast-down from the steps, say) gains on every block of it
            // at once; an effect that is really there also lowers the
            // all-segment residual beyond what its parameters fit of the
            // noise. Both must hold; the larger p-value is reported.
            let k = extra_params(&fam.all.model);
            let lr = (nominal_all.sse - fam.all.sse) / (fam.all.s2 * fam.all.colour);
            let p_in = if lr > 0.0 {
                ChiSquared::new(k as f64).map_or(1.0, |d| 1.0 - d.cdf(lr))
            } else {
                1.0
            };
            test.p_value = test.p_value.max((p_in * tried as f64).min(1.0));
            let score = penalised_score(nominal.sse, fam.sse, n_eff, extra_params(&fam.all.model));
            (e, fam, test, score)
        })
        .collect();
    scored.sort_by(|a, b| b.3.total_cmp(&a.3));
    let noise_floor = noise_floor(&runs, &nominal_noise);
    // A candidate that passes the tests is the verdict only if its
    // parameters are determined and physical, and if it explains the gap:
    // its held-out NRMSE within `EXPLAINED` times the noise floor, or
    // `DOMINANT_SHARE` of the excess over the floor removed. One that leaves
    // more has shrunk the gap without explaining it, and naming it would be
    // a guess.
    let share_of =
        |fam: &FamilyResult| explained_share(nominal.validation, fam.validation, noise_floor);
    let refusal = |fam: &FamilyResult| -> Option<Refusal> {
        let other = |why: String| {
            Some(Refusal {
                why,
                partial: false,
            })
        };
        let partial = |why: String| Some(Refusal { why, partial: true });
        if nominal.validation <= noise_floor {
            return other(format!(
                "but the nominal model's held-out NRMSE {:.4} is already within the noise \
                 floor {:.4}: there is no gap for an effect to explain",
                nominal.validation, noise_floor
            ));
        }
        if !physical(&fam.all.model) {
            return other("only with an unphysical sign of its parameter".into());
        }
        if let Some(why) = undetermined(&fam.all.model, &scales) {
            return other(format!(
                "with a parameter the record does not determine: {why}"
            ));
        }
        if let Some(why) = immaterial(&fam.all.model) {
            return other(format!("but {why}"));
        }
        let explained = share_of(fam);
        if explained < EXPLAINED_SHARE {
            return partial(format!(
                "by {:.0} % only of its excess over the noise floor (held-out NRMSE {:.4} \
                 against {:.4}, floor {:.4}): an effect that causes the gap removes most \
                 of it",
                100.0 * explained,
                fam.validation,
                nominal.validation,
                noise_floor
            ));
        }
        if fam.validation > EXPLAINED * noise_floor && explained < DOMINANT_SHARE {
            return partial(format!(
                "but leaves a held-out NRMSE of {:.4}, {:.1} times the noise floor {:.4}: \
                 the gap is not this effect alone (another effect, or a nominal fit that \
                 missed its optimum)",
                fam.validation,
                fam.validation / noise_floor,
                noise_floor
            ));
        }
        None
    };
    let ranked: Vec<Ranked> = scored
        .iter()
        .map(|(e, fam, test, score)| Ranked {
            effect: *e,
            blocks: &fam.blocks,
            passes: test.significant() && *score > 0.0,
            refusal: refusal(fam),
        })
        .collect();
    let winner = choose(&ranked, &mut warnings);

    if let Some(wi) = winner {
        let (e, fam, _, _) = &scored[wi];
        warnings.extend(partial_verdict_warning(
            &effect_name(*e),
            nominal.validation,
            fam.validation,
            noise_floor,
        ));
    } else {
        warnings.extend(unexplained_gap_warning(
            nominal.validation,
            noise_floor,
            DC_READING_FAULTS,
        ));
    }

    let gap_before = nominal.validation;
    let location = locate(
        &nominal.folds,
        &measured_of(&runs),
        w,
        transient_seconds(&nominal_all.model.p),
        scales.dt,
    );

    let candidates_report = scored.iter().map(|(e, fam, test, score)| Candidate {
        effect: effect_name(*e),
        params: effect_params(&fam.all, &fam.transforms, &scales),
        validation_nrmse: fam.validation,
        shrink: 1.0 - fam.validation / gap_before,
        score: *score,
        p_value: test.p_value,
        nominal_params: nominal_estimates(&fam.all),
    });
    let candidates_report = reportable(candidates_report, &mut warnings);

    let verdict = match winner {
        Some(wi) => {
            let (e, fam, test, _) = &scored[wi];
            let look_alikes = scored
                .iter()
                .enumerate()
                .filter(|(n, (_, other, _, _))| {
                    *n != wi
                        && ranked[*n].passes
                        && ranked[*n].refusal.is_none()
                        && !held_out_test(&other.blocks, &fam.blocks, 1).significant()
                })
                .map(|(_, (oe, other, _, _))| LookAlike {
                    effect: effect_name(*oe),
                    validation_nrmse: other.validation,
                    plan: separating_plan(*e, *oe),
                })
                .collect();
            let corrected = PARAM_KEYS
                .iter()
                .zip(PARAM_UNITS)
                .zip(
                    to_array(&nominal_all.model.p)
                        .into_iter()
                        .zip(to_array(&fam.all.model.p)),
                )
                .map(|((k, u), (nv, cv))| {
                    (
                        (*k).to_string(),
                        ParamCorrection {
                            nominal: nv,
                            corrected: cv,
                            bias: (nv - cv) / cv,
                            unit: u.into(),
                        },
                    )
                })
                .collect();
            Verdict {
                effect: effect_name(*e),
                gap_before,
                gap_after: fam.validation,
                shrink: 1.0 - fam.validation / gap_before,
                confidence: 1.0 - test.p_value,
                look_alikes,
                corrected_params: corrected,
            }
        }
        None => Verdict {
            effect: "none".into(),
            gap_before,
            gap_after: gap_before,
            shrink: 0.0,
            confidence: scored.iter().map(|s| s.2.p_value).fold(1.0, f64::min),
            look_alikes: Vec::new(),
            corrected_params: BTreeMap::new(),
        },
    };

    let after_folds = winner.map(|wi| &scored[wi].1.folds);
    let plot = residual_plot(
        &location.regions,
        &nominal.folds,
        after_folds,
        &verdict.effect,
    );

    let report = Diagnosis {
        schema_version: SCHEMA_VERSION.into(),
        kind: "dc_step".into(),
        nominal: NominalFit {
            model: "dc_nominal".into(),
            params: nominal_estimates(&nominal_all),
            fit_nrmse: nominal_fit_nrmse,
            validation_nrmse: gap_before,
        },
        gap: Gap {
            regions: location.regions,
            channels: location.channels,
            segments: location.segments,
            evidence: location.evidence,
            noise_floor,
        },
        candidates: candidates_report,
        verdict,
        validation: if cv {
            format!(
                "interleaved blocks ({} folds of {}-sample blocks)",
                cv::CV_FOLDS,
                cv::CV_BLOCK
            )
        } else {
            format!("leave-one-segment-out ({} folds)", runs.len())
        },
        warnings,
    };
    Ok(DiagnosisRun { report, plot })
}

pub(super) fn effect_name(e: Effect) -> String {
    serde_json::to_value(e)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default()
}

fn to_array(p: &DcParams) -> [f64; 6] {
    [p.ra, p.la, p.k, p.j, p.f, p.tst]
}

/// Nominal parameters of a fit with 95 % intervals (log-normal from the
/// covariance of `ln p`).
fn nominal_estimates(f: &Fitted) -> BTreeMap<String, ParamEstimate> {
    let v = to_array(&f.model.p);
    PARAM_KEYS
        .iter()
        .enumerate()
        .map(|(n, k)| {
            let ci = f.covariance.as_ref().map(|c| {
                let sd = c[(n, n)].max(0.0).sqrt();
                [v[n] * (-1.96 * sd).exp(), v[n] * (1.96 * sd).exp()]
            });
            (
                (*k).to_string(),
                ParamEstimate {
                    value: v[n],
                    ci95: ci.filter(|c| c.iter().all(|x| x.is_finite())),
                    unit: PARAM_UNITS[n].into(),
                },
            )
        })
        .collect()
}

/// Refit `spec` without segment `h` (one step from `all`, else iterated
/// from there) and simulate it.
fn fold(
    spec: &FitSpec,
    all: &Fitted,
    runs: &[SegmentRun],
    h: usize,
    w: &Weights,
) -> Option<HeldOutSeries> {
    let train = without(runs, h);
    let model = match one_step_refit(spec, all, runs, &train, h, w) {
        Some(m) => m,
        None => fit_fold(&refit_spec(spec, all), &train, w, PATIENCE_FOLD, None)?.model,
    };
    held_out(&model, &runs[..=h])
}

/// Residuals (measured − simulated) and NRMSE of `model` on the last of
/// `runs`, simulated after the others (from which it continues where the
/// record is continuous; only their voltage is used).
fn held_out(model: &AugModel, runs: &[SegmentRun]) -> Option<HeldOutSeries> {
    let h = runs.len().checked_sub(1)?;
    let run = &runs[h];
    let (mut si, mut sw) = (Vec::with_capacity(run.len()), Vec::with_capacity(run.len()));
    if !model.simulate_runs(runs, &mut |n, i, w| {
        if n == h {
            si.push(i);
            sw.push(w);
        }
    }) {
        return None;
    }
    series_of(run, &si, &sw)
}

/// Residuals and NRMSE of `model` on every run, simulated in order.
fn all_series(model: &AugModel, runs: &[SegmentRun]) -> Option<Vec<HeldOutSeries>> {
    let mut sims: Vec<(Vec<f64>, Vec<f64>)> = runs
        .iter()
        .map(|r| (Vec::with_capacity(r.len()), Vec::with_capacity(r.len())))
        .collect();
    if !model.simulate_runs(runs, &mut |n, i, w| {
        sims[n].0.push(i);
        sims[n].1.push(w);
    }) {
        return None;
    }
    runs.iter()
        .zip(&sims)
        .map(|(r, (si, sw))| series_of(r, si, sw))
        .collect()
}

/// The held-out series of `run` from its simulated current and speed.
fn series_of(run: &SegmentRun, si: &[f64], sw: &[f64]) -> Option<HeldOutSeries> {
    let seg = run.seg;
    let t0 = seg.time[0];
    let speed_nrmse = nrmse(&seg.speed, sw)?;
    let nrmse_v = if run.coast {
        speed_nrmse
    } else {
        0.5 * (nrmse(&seg.current, si)? + speed_nrmse)
    };
    Some(HeldOutSeries {
        segment: seg.index,
        t: seg.time.iter().map(|t| t - t0).collect(),
        current: if run.coast {
            Vec::new()
        } else {
            seg.current.iter().zip(si).map(|(y, s)| y - s).collect()
        },
        speed: seg.speed.iter().zip(sw).map(|(y, s)| y - s).collect(),
        from_rest: run.start == Start::Rest,
        coast: run.coast,
        nrmse: nrmse_v,
    })
}

/// The readings' faults that leave a DC record's gap unexplained.
const DC_READING_FAULTS: &str = "an offset or a scale error of the voltage, current or speed \
     reading, a voltage read elsewhere than at the armature, a current or speed of another \
     channel";

/// What to check when no DC motor model follows a record's readings.
const CHECK_THE_COLUMNS: &str = "Check that the columns belong together: the armature voltage \
     in V, the armature current in A and the speed in rad/s at the same instants (a voltage \
     column that is a set point, or held while the motor moves; a current or speed in other \
     units, scaled, or of another channel), and that the motor's field is constant: the models \
     are a permanent-magnet or separately excited motor's, and a series or shunt winding's \
     field follows the armature current or voltage";

/// NRMSE of a model on every segment it was fitted to (mean over segments).
fn fit_nrmse(model: &AugModel, runs: &[SegmentRun]) -> f64 {
    let v: Vec<f64> = all_series(model, runs)
        .unwrap_or_default()
        .iter()
        .map(|s| s.nrmse)
        .collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn measured_of<'a>(runs: &[SegmentRun<'a>]) -> Vec<Measured<'a>> {
    runs.iter()
        .map(|r| Measured {
            voltage: &r.seg.voltage,
            current: &r.seg.current,
            speed: &r.seg.speed,
        })
        .collect()
}

/// The transient after a step: three times the electrical plus the
/// mechanical time constant.
fn transient_seconds(p: &DcParams) -> f64 {
    3.0 * (p.tau_e() + p.tau_m())
}

fn all_segment_peaks(model: &AugModel, runs: &[SegmentRun], dt: f64) -> Vec<f64> {
    let series: Vec<HeldOutSeries> = all_series(model, runs)
        .unwrap_or_default()
        .into_iter()
        .zip(runs)
        .filter(|(_, r)| !r.coast)
        .map(|(s, _)| s)
        .collect();
    let speed: Vec<&[f64]> = series.iter().map(|s| &s.speed[..]).collect();
    let current: Vec<&[f64]> = series.iter().map(|s| &s.current[..]).collect();
    let mut peaks: Vec<f64> = [speed, current]
        .iter()
        .filter_map(|pieces| spectral_peak(pieces, dt))
        .map(|p| p.hz)
        .collect();
    peaks.dedup_by(|a, b| (*a - *b).abs() <= 0.1 * b.abs());
    peaks
}

/// `m` with its electrical time constant raised to at least one sample,
/// its viscous friction to at least 0.1 % of the electrical damping
/// `K²/Ra`, and its static friction to at least 1 % of the torque at the
/// record's largest current `i_max`. A fit collapses the static friction
/// on records that reverse or stop often (closed loops): each stick or
/// breakaway moves the simulation by a whole sample, the forward
/// differences of its gradient are erratic, and once `ln Tst` has run off
/// no derivative brings it back.
fn floored(m: &AugModel, dt: f64, i_max: f64) -> AugModel {
    let mut m = *m;
    m.p.la = m.p.la.max(m.p.ra * dt);
    m.p.f = m.p.f.max(1e-3 * m.p.k * m.p.k / m.p.ra);
    m.p.tst = m.p.tst.max(1e-2 * m.p.k * i_max);
    m
}

/// The segments that take part, each with how it starts.
fn prepare_runs<'a>(
    segs: &'a [DcSegment],
    estimate: &dyn Fn() -> Option<DcParams>,
    warnings: &mut Vec<String>,
) -> Result<Vec<SegmentRun<'a>>, DiagnoseError> {
    let warnings_before = warnings.len();
    let mut runs: Vec<SegmentRun> = Vec::new();
    let mut heat = 0.0;
    for (pos, seg) in segs.iter().enumerate() {
        let n = seg.time.len();
        if let Some(prev) = pos.checked_sub(1).map(|p| &segs[p]) {
            heat += gap_heat(prev, seg);
        }
        let seg_heat = heat_of(seg);
        if n < MIN_SAMPLES {
            warnings.push(format!(
                "segment {} ({}) has {n} samples, fewer than {MIN_SAMPLES}: not used",
                seg.index, seg.label
            ));
            heat += seg_heat;
            continue;
        }
        let dt = (seg.time[n - 1] - seg.time[0]) / (n - 1) as f64;
        if !(dt.is_finite() && dt > 0.0) {
            warnings.push(format!(
                "segment {} ({}): its time does not increase; not used",
                seg.index, seg.label
            ));
            heat += seg_heat;
            continue;
        }
        let coast = seg.kind == Some(SegmentKind::DcCoastdown) || is_coastdown(seg);
        // A reading that never changes (a part of a record at rest, whose
        // encoder reads 0 throughout) has no spread to measure a misfit
        // against: the segment can be neither held out nor scored.
        let still = |y: &[f64]| y.iter().all(|v| *v == y[0]);
        let constant = if still(&seg.speed) {
            Some("speed")
        } else if !coast && still(&seg.current) {
            Some("current")
        } else {
            None
        };
        if let Some(what) = constant {
            warnings.push(format!(
                "segment {} ({}) reads the same {what} throughout: nothing to fit or hold out; \
                 not used",
                seg.index, seg.label
            ));
            heat += seg_heat;
            continue;
        }
        // The segment before, where this one follows it in time: after a
        // gap (samples the logger dropped, `machine::dc::gaps`) it starts
        // from its own first sample, as a record's first segment does.
        let prev = pos
            .checked_sub(1)
            .map(|p| &segs[p])
            .filter(|p| p.time.last().is_some_and(|&t| t >= seg.time[0] - 1.5 * dt));
        let prev_coast =
            prev.is_some_and(|p| p.kind == Some(SegmentKind::DcCoastdown) || is_coastdown(p));
        let speed_scale = seg
            .speed
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()))
            .max(1e-9);
        // At rest: the first speed reading is within 1 % of the segment's
        // largest (the current has already risen over the first interval).
        let at_rest = seg.speed[0].abs() <= 0.01 * speed_scale;
        let start = match prev {
            // A later segment at rest keeps the current it ends with (a
            // position loop holding, say): no current is an assumption only
            // the record's first segment may make.
            Some(p) if !prev_coast && p.voltage.len() >= 4 && at_rest && !coast => {
                Start::State(crate::identify::state_at_end(p).0, 0.0)
            }
            Some(p) if !prev_coast && p.voltage.len() >= 4 && !at_rest => {
                match crate::identify::settled_level(p) {
                    Some(level) if !level.settled => {
                        let (i0, w0) = crate::identify::state_at_end(p);
                        Start::State(i0, w0)
                    }
                    _ => Start::Settled(tail_mean(&p.voltage)),
                }
            }
            Some(_) if coast => {
                warnings.push(format!(
                    "coast-down segment {} does not follow a driven level; not used",
                    seg.index
                ));
                heat += seg_heat;
                continue;
            }
            None if !at_rest => first_state(seg, dt, coast, estimate()),
            _ => Start::Rest,
        };
        let continues = match (prev, runs.last()) {
            (Some(p), Some(last)) if last.seg.index == p.index => {
                continuation(p.time[p.time.len() - 1], seg.time[0], dt)
            }
            _ => None,
        };
        runs.push(SegmentRun {
            seg,
            dt,
            start,
            coast,
            heat_before: heat,
            continues,
        });
        heat += seg_heat;
    }
    if runs.len() < 2 {
        // Why the others were not used, from this pass's own warnings.
        let why: Vec<&str> = warnings[warnings_before..]
            .iter()
            .filter(|w| w.ends_with("not used"))
            .map(String::as_str)
            .collect();
        let why = if why.is_empty() {
            String::new()
        } else {
            format!(" ({})", why.join("; "))
        };
        return Err(DiagnoseError::NotEnoughData(format!(
            "{} usable segment(s) of {}{why}: the diagnosis needs at least 2; record \
             two or more segments of at least {MIN_SAMPLES} samples (one CSV file each), or one \
             segment of at least {} samples that holds voltage levels or a varied voltage to \
             cut into parts",
            runs.len(),
            segs.len(),
            2 * crate::machine::dc::split::MIN_PART
        )));
    }
    if runs.iter().all(|r| r.coast) {
        return Err(DiagnoseError::NotEnoughData(
            "no driven step segment".into(),
        ));
    }
    Ok(runs)
}

/// The start of a record's first segment (or of one after a gap in
/// time) whose first speed reading is not at rest, which no level before
/// it gives: settled at its first voltage (a record that begins on a
/// held level), in the measured state of its first sample (a closed
/// loop's first command, a file cut after a step), or at rest after all
/// (a start from rest whose first speed reading is noise, or has already
/// moved). Whichever of the three the motor `estimate` (the
/// identification's output-error fit) simulates closest to the
/// segment's readings: a rule on the first readings alone (does the
/// speed drift over them) takes a start from rest read through a noisy
/// tachometer for a settled level, and a wrong start leaves a misfit over
/// the whole first transient that the nominal parameters then bend to
/// absorb. Without an estimate (no output-error fit: the diagnosis stops
/// at its nominal fit anyway) the measured first state.
fn first_state(seg: &DcSegment, dt: f64, coast: bool, estimate: Option<DcParams>) -> Start {
    let Some(estimate) = estimate else {
        return Start::State(seg.current[0], seg.speed[0]);
    };
    let model = AugModel::nominal(estimate);
    let misfit = |start: Start| {
        let run = SegmentRun {
            seg,
            dt,
            start,
            coast,
            heat_before: 0.0,
            continues: None,
        };
        all_series(&model, &[run])
            .and_then(|s| s.first().map(|s| s.nrmse))
            .filter(|v| v.is_finite())
            .unwrap_or(f64::INFINITY)
    };
    [
        Start::Rest,
        Start::Settled(seg.voltage[0]),
        Start::State(seg.current[0], seg.speed[0]),
    ]
    .into_iter()
    .map(|start| (misfit(start), start))
    .min_by(|a, b| a.0.total_cmp(&b.0))
    .map_or(Start::Rest, |(_, start)| start)
}

/// How a segment whose first sample is at `first` (s) follows one whose
/// last is at `last`, at sample interval `dt`: sharing that sample, right
/// after it, or after a gap (`None`).
fn continuation(last: f64, first: f64, dt: f64) -> Option<Continuation> {
    let gap = first - last;
    if gap.abs() <= 0.1 * dt {
        Some(Continuation::Shared)
    } else if (gap - dt).abs() <= 0.1 * dt {
        Some(Continuation::Next)
    } else {
        None
    }
}

/// Least share of the nominal model's weighted residual that the voltage
/// as straight pieces must remove for it to replace the readings. The
/// pieces can erase excitation the motor saw (a fast controller's
/// command, a ripple), so a gain within the noise of the comparison does
/// not justify the risk; where the reading noise matters it takes far
/// more than this (its share of the residual on noisy-voltage records: a
/// half to two thirds).
const MATERIAL_NOISE: f64 = 0.05;

/// The nominal model fitted from the readings (`held`: held levels
/// denoised) or, where the reading noise is a material part of its
/// misfit, from the voltage as straight pieces (`pieces`, with its noise
/// σ), with a warning that says so. The pieces are the input where the
/// nominal model explains the current and speed better from them: the
/// readings' noise was the sensor's. Where the readings are what the motor
/// saw (a controller's command that jitters), the pieces erase part of the
/// excitation and fit worse.
fn nominal_of_inputs<'a>(
    held: &'a [DcSegment],
    pieces: Option<&'a (Vec<DcSegment>, f64)>,
    estimate: &dyn Fn() -> Result<DcParams, String>,
    warnings: &mut Vec<String>,
) -> Result<NominalStart<'a>, DiagnoseError> {
    let readings = nominal_fit(held, estimate, warnings)?;
    let Some((pieces, sigma)) = pieces else {
        return Ok(readings);
    };
    // First the start's residual from either input, which costs two
    // simulations: only where the pieces lower it materially is the
    // nominal model fitted from them too.
    let start_sse = |runs: &[SegmentRun]| {
        let mut r = Vec::new();
        runs_residuals(&readings.spec.start, runs, &readings.weights, &mut r)
            .then(|| r.iter().map(|v| v * v).sum::<f64>())
    };
    let promising = match (
        start_sse(&readings.runs),
        prepare_runs(pieces, &|| estimate().ok(), &mut Vec::new())
            .ok()
            .and_then(|runs| start_sse(&runs)),
    ) {
        (Some(from_readings), Some(from_pieces)) => {
            from_pieces < (1.0 - MATERIAL_NOISE) * from_readings
        }
        _ => false,
    };
    let mut scratch = Vec::new();
    let Some(smoothed) = promising
        .then(|| nominal_fit(pieces, estimate, &mut scratch).ok())
        .flatten()
    else {
        return Ok(readings);
    };
    let same_rows = smoothed.runs.len() == readings.runs.len()
        && smoothed
            .runs
            .iter()
            .zip(&readings.runs)
            .all(|(a, b)| a.len() == b.len());
    if !(same_rows && smoothed.all.sse < (1.0 - MATERIAL_NOISE) * readings.all.sse) {
        return Ok(readings);
    }
    warnings.extend(scratch);
    warnings.push(format!(
        "the armature voltage reading's noise (σ ≈ {sigma:.3} V) is smoothed as straight \
         pieces: the nominal model fits the current and speed better from them (weighted \
         residual {:.4e} against {:.4e} from the readings)",
        smoothed.all.sse, readings.all.sse
    ));
    Ok(smoothed)
}

/// The nominal model fitted to a record's runs, and what its fit needs.
struct NominalStart<'a> {
    runs: Vec<SegmentRun<'a>>,
    weights: Weights,
    scales: RecordScales,
    spec: FitSpec,
    all: Fitted,
}

/// The nominal model fitted on every segment of `segs`, from the
/// identification's output-error parameters, and refitted from the
/// candidates' floors when those fit better.
fn nominal_fit<'a>(
    segs: &'a [DcSegment],
    estimate: &dyn Fn() -> Result<DcParams, String>,
    warnings: &mut Vec<String>,
) -> Result<NominalStart<'a>, DiagnoseError> {
    let runs = prepare_runs(segs, &|| estimate().ok(), warnings)?;
    let weights = channel_weights(&runs, warnings);
    let scales = scales(&runs);
    let spec = FitSpec {
        start: AugModel::nominal(estimate().map_err(DiagnoseError::NominalFit)?),
        effect: Vec::new(),
    };
    let mut all = fit(&spec, &runs, &weights, 3 * PATIENCE_ALL).ok_or_else(|| {
        DiagnoseError::NominalFit("the nominal model refuses its own start values".into())
    })?;
    // A fit can collapse La or f to absorb an effect (La for a resonance
    // or a sensor lag, f for armature reaction) and then cannot leave:
    // their log is the fitted parameter, and the record is insensitive to
    // an electrical time constant far below one sample or to a viscous
    // torque far below the electrical damping. Candidates therefore start
    // from floors; so that they are compared with the best nominal fit,
    // the nominal is refitted from there too.
    let base = floored(&all.model, scales.dt, scales.i_max);
    if base != all.model {
        let from_floors = FitSpec {
            start: base,
            effect: Vec::new(),
        };
        if let Some(f) = fit(&from_floors, &runs, &weights, 3 * PATIENCE_ALL) {
            if f.sse < all.sse {
                all = f;
            }
        }
    }
    Ok(NominalStart {
        runs,
        weights,
        scales,
        spec,
        all,
    })
}

/// The segments with the armature voltage as straight pieces
/// ([`crate::identify::pieces`]), and the reading noise they remove; `None`
/// where the readings show no noise. Coast-downs keep their readings, as
/// [`held_levels`] does.
fn voltage_pieces(segments: &[DcSegment]) -> Option<(Vec<DcSegment>, f64)> {
    use crate::identify::pieces::{noise_sigma, piecewise_linear};
    let driven = |s: &&DcSegment| {
        s.voltage.len() >= MIN_SAMPLES
            && s.kind != Some(SegmentKind::DcCoastdown)
            && !is_coastdown(s)
    };
    let sigma = noise_sigma(segments.iter().filter(driven).map(|s| s.voltage.as_slice()));
    if sigma.is_nan() || sigma <= 0.0 {
        return None;
    }
    let out = segments
        .iter()
        .map(|seg| {
            let mut s = seg.clone();
            if driven(&seg) {
                s.voltage = piecewise_linear(&seg.voltage, sigma);
            }
            s
        })
        .collect();
    Some((out, sigma))
}

/// The segments with the voltage of each held level denoised: readings
/// within four noise deviations of the level (the mean over the segment's
/// last quarter) are replaced by the level, the regulated value the supply
/// held; the slew between levels, and any droop beyond the noise, stay as
/// measured. Output error simulated from a noisy input is biased (errors
/// in variables): the fit leans towards parameters that filter the
/// noise, and the biased nominal leaves a systematic residual that any
/// candidate's extra freedom would take up.
fn held_levels(segments: &[DcSegment]) -> Vec<DcSegment> {
    segments
        .iter()
        .enumerate()
        .map(|(pos, seg)| {
            let mut s = seg.clone();
            let n = s.voltage.len();
            if n < MIN_SAMPLES || s.kind == Some(SegmentKind::DcCoastdown) || is_coastdown(seg) {
                return s;
            }
            // The segment's span, from the level before it (the step into
            // it may fall between two files).
            let before = pos.checked_sub(1).and_then(|p| segments[p].voltage.last());
            let (lo, hi) = s
                .voltage
                .iter()
                .chain(before)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(*v), hi.max(*v))
                });
            let span = hi - lo;
            let level = tail_mean(&s.voltage);
            let tail = n - n / 4;
            let var = s.voltage[tail..]
                .windows(2)
                .map(|w| (w[1] - w[0]).powi(2))
                .sum::<f64>()
                / (2.0 * (n - tail - 1).max(1) as f64);
            let band = 4.0 * var.sqrt();
            if !holds_level(&s.voltage[tail..], level, var) || band > MAX_HELD_BAND * span {
                return s;
            }
            for v in s.voltage.iter_mut().skip(1) {
                if (*v - level).abs() <= band {
                    *v = level;
                }
            }
            s
        })
        .collect()
}

/// Largest share of a segment's voltage span (from the level before it)
/// that a held level's noise band (four deviations) may take for the readings in it to be replaced
/// by the level: a regulated supply's reading noise is small beside the
/// steps it is set to. A closed loop's command that jitters from sample
/// to sample (a position loop answering a coarse encoder: ±31 V a sample
/// on a segment spanning 400 V) passes the spread test of [`holds_level`]
/// like noise, yet is what the motor saw; replacing everything within
/// its band of ±125 V by the mean erased the excitation, and the nominal
/// fit went to K and Ra 25 % and 80 % off (own blind seed 7 case-11).
const MAX_HELD_BAND: f64 = 0.1;

/// Whether `tail` (mean `level`, first-difference noise variance
/// `noise_var`) is a held level: its spread about the level is the noise
/// its sample-to-sample changes show, within a factor of two. A ramp, or
/// a controller's command (a P position loop swinging between its limits,
/// a speed loop's integrator), spreads further than its changes: its
/// readings are the excitation, and replacing them by their mean would
/// feed the model a voltage the motor never saw.
fn holds_level(tail: &[f64], level: f64, noise_var: f64) -> bool {
    let spread = tail.iter().map(|v| (v - level).powi(2)).sum::<f64>() / tail.len().max(1) as f64;
    spread <= 2.0 * noise_var
}

fn tail_mean(y: &[f64]) -> f64 {
    let n = y.len();
    let tail = &y[n - (n / 4).max(1)..];
    tail.iter().sum::<f64>() / tail.len() as f64
}

/// `∫i²dt` of a segment's measured current (trapezoid), A²·s.
fn heat_of(seg: &DcSegment) -> f64 {
    seg.time
        .windows(2)
        .zip(seg.current.windows(2))
        .map(|(t, i)| 0.5 * (t[1] - t[0]) * (i[0] * i[0] + i[1] * i[1]))
        .sum()
}

/// Readings at each side of a gap in time whose `i²` stands for it.
const GAP_SIDE: usize = 32;

/// `∫i²dt` over a gap in time between `prev` and `seg` (samples a logger
/// dropped, or what a long record's windows leave out, `windows.rs`): the
/// gap's length times the mean `i²` of the readings at either side. Zero
/// where `seg` follows `prev` (on its last sample or one interval later).
fn gap_heat(prev: &DcSegment, seg: &DcSegment) -> f64 {
    let n = seg.time.len();
    let (Some(&end), true) = (prev.time.last(), n >= 2) else {
        return 0.0;
    };
    let dt = (seg.time[n - 1] - seg.time[0]) / (n - 1) as f64;
    let gap = seg.time[0] - end - dt;
    if !gap.is_finite() || gap <= 0.5 * dt {
        return 0.0;
    }
    let mean_sq = |y: &[f64]| y.iter().map(|v| v * v).sum::<f64>() / y.len().max(1) as f64;
    let before = &prev.current[prev.current.len().saturating_sub(GAP_SIDE)..];
    let after = &seg.current[..GAP_SIDE.min(n)];
    gap * 0.5 * (mean_sq(before) + mean_sq(after))
}

/// Noise of current and speed from first differences over the last
/// quarter of every step segment: `σ² = mean(Δy²)/2`.
fn channel_weights(runs: &[SegmentRun], warnings: &mut Vec<String>) -> Weights {
    let (mut sum, mut count) = ([0.0f64; 2], 0usize);
    let mut peak = [0.0f64; 2];
    for r in runs.iter().filter(|r| !r.coast) {
        let n = r.len();
        for k in n - n / 4..n {
            sum[0] += (r.seg.current[k] - r.seg.current[k - 1]).powi(2);
            sum[1] += (r.seg.speed[k] - r.seg.speed[k - 1]).powi(2);
            count += 1;
        }
        for k in 0..n {
            peak[0] = peak[0].max(r.seg.current[k].abs());
            peak[1] = peak[1].max(r.seg.speed[k].abs());
        }
    }
    let sigma: [f64; 2] = std::array::from_fn(|c| {
        let s = (sum[c] / (2.0 * count.max(1) as f64)).sqrt();
        if s > 0.0 && s.is_finite() {
            s
        } else {
            warnings.push(format!(
                "the {} reading does not vary over the settled tails; weighted by 1e-6 of its largest value",
                ["current", "speed"][c]
            ));
            1e-6 * peak[c].max(1e-9)
        }
    });
    Weights {
        current: 1.0 / sigma[0],
        speed: 1.0 / sigma[1],
    }
}

/// Noise weights `1/σ` from the residuals of `model` on every segment
/// (`decision::residual_noise_sigma`): unlike the settled tails of
/// [`channel_weights`], they exist on ramps, PRBS and closed loops too.
fn residual_weights(model: &AugModel, runs: &[SegmentRun]) -> Weights {
    let series: Vec<(HeldOutSeries, &SegmentRun)> = all_series(model, runs)
        .unwrap_or_default()
        .into_iter()
        .zip(runs)
        .collect();
    let sigma = |current: bool| {
        let (residuals, readings): (Vec<&[f64]>, Vec<&[f64]>) = series
            .iter()
            .filter(|(_, r)| !(current && r.coast))
            .map(|(s, r)| {
                if current {
                    (&s.current[..], &r.seg.current[..])
                } else {
                    (&s.speed[..], &r.seg.speed[..])
                }
            })
            .unzip();
        residual_noise_sigma(&residuals, &readings).max(f64::MIN_POSITIVE)
    };
    Weights {
        current: 1.0 / sigma(true),
        speed: 1.0 / sigma(false),
    }
}

/// The NRMSE that white noise of the estimated levels would give, the
/// contract's way (mean over channels per segment, mean over segments).
fn noise_floor(runs: &[SegmentRun], w: &Weights) -> f64 {
    let spread = |y: &[f64]| {
        let m = y.iter().sum::<f64>() / y.len() as f64;
        y.iter().map(|v| (v - m).powi(2)).sum::<f64>().sqrt()
    };
    let per: Vec<f64> = runs
        .iter()
        .map(|r| {
            let n = (r.len() as f64).sqrt();
            let sp = n / w.speed / spread(&r.seg.speed).max(1e-300);
            if r.coast {
                sp
            } else {
                0.5 * (n / w.current / spread(&r.seg.current).max(1e-300) + sp)
            }
        })
        .collect();
    per.iter().sum::<f64>() / per.len().max(1) as f64
}

fn scales(runs: &[SegmentRun]) -> RecordScales {
    let mut s = RecordScales {
        i_max: 0.0,
        i_settled: 0.0,
        u_max: 0.0,
        w_max: 0.0,
        heat_total: 0.0,
        dt: runs[0].dt,
        peaks_hz: Vec::new(),
        w_noise: 0.0,
    };
    for r in runs {
        for k in 0..r.len() {
            s.i_max = s.i_max.max(r.seg.current[k].abs());
            s.u_max = s.u_max.max(r.seg.voltage[k].abs());
            s.w_max = s.w_max.max(r.seg.speed[k].abs());
        }
        s.heat_total = s.heat_total.max(r.heat_before + heat_of(r.seg));
    }
    let mut settled: Vec<f64> = runs
        .iter()
        .filter(|r| !r.coast)
        .map(|r| tail_mean(&r.seg.current).abs())
        .collect();
    s.i_settled = median(&mut settled).unwrap_or(0.0);
    s
}

/// Panels for the largest regions: held-out residual before (nominal)
/// and after (the verdict's effect).
fn residual_plot(
    regions: &[crate::contract::GapRegion],
    before: &[HeldOutSeries],
    after: Option<&Vec<HeldOutSeries>>,
    effect: &str,
) -> ResidualPlot {
    let mut panels = Vec::new();
    for region in regions.iter().filter(|r| r.segment.is_some()).take(4) {
        let seg = region.segment.unwrap_or(0);
        let Some((n, b)) = before.iter().enumerate().find(|(_, s)| s.segment == seg) else {
            continue;
        };
        let a = after.and_then(|f| f.get(n)).unwrap_or(b);
        let current = region.channel == "armature_current";
        let pick = |s: &HeldOutSeries| {
            if current {
                s.current.clone()
            } else {
                s.speed.clone()
            }
        };
        let (rb, ra) = (pick(b), pick(a));
        let keep: Vec<usize> = (0..b.t.len())
            .filter(|&k| b.t[k] >= region.from && b.t[k] <= region.to && k < rb.len())
            .collect();
        panels.push(ResidualPanel {
            title: format!("{} · segment {seg} · {}", region.channel, region.label),
            x_label: "time in segment (s)".into(),
            unit: if current { "A" } else { "rad/s" }.into(),
            x: keep.iter().map(|&k| b.t[k]).collect(),
            before: keep.iter().map(|&k| rb[k]).collect(),
            after: keep
                .iter()
                .map(|&k| ra.get(k).copied().unwrap_or(f64::NAN))
                .collect(),
        });
    }
    ResidualPlot {
        effect: effect.into(),
        panels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::blind::simulate_dc_case;
    use rand::{rngs::StdRng, SeedableRng};

    /// A gap in time between two segments heats the winding at the `i²`
    /// of its sides; a segment that follows the one before adds nothing.
    #[test]
    fn a_gap_in_time_is_heated_at_its_sides_current() {
        let seg = |t0: f64, i: f64| DcSegment {
            index: 0,
            kind: Some(SegmentKind::DcStep),
            label: String::new(),
            time: (0..100).map(|k| t0 + k as f64 * 1e-3).collect(),
            voltage: vec![10.0; 100],
            current: vec![i; 100],
            speed: vec![5.0; 100],
        };
        let a = seg(0.0, 2.0);
        // Ends at 0.099 s; the next starts at 1.1 s: a gap of 1 s beyond
        // one interval, at i² of 4 and 16 on its sides.
        let heat = gap_heat(&a, &seg(1.1, 4.0));
        assert!((heat - 10.0).abs() < 1e-9, "{heat}");
        assert_eq!(gap_heat(&a, &seg(0.099, 4.0)), 0.0);
        assert_eq!(gap_heat(&a, &seg(0.1, 4.0)), 0.0);
    }

    /// The nominal parameters a simulated case was made with.
    fn truth_params(case: &crate::diagnose::blind::BlindRecord) -> DcParams {
        let n = &case.truth.nominal;
        DcParams {
            ra: n["Ra"],
            la: n["La"],
            k: n["K"],
            j: n["J"],
            f: n["f"],
            tst: n["Tst"],
        }
    }

    /// The generator and the diagnosis' nominal model agree: on cases
    /// without an effect, the model at the true parameters misses the
    /// readings by the noise alone (segment starts, encoder reading,
    /// coast-down included).
    #[test]
    fn the_true_nominal_model_fits_a_clean_case_to_its_noise_floor() {
        let mut rng = StdRng::seed_from_u64(5);
        for _ in 0..4 {
            let case = simulate_dc_case(None, &mut rng);
            let p = truth_params(&case);
            let held = held_levels(&case.record.segments);
            let runs = prepare_runs(&held, &|| Some(p), &mut Vec::new()).unwrap();
            assert_eq!(runs.len(), 6);
            assert_eq!(runs[0].start, Start::Rest);
            assert!(runs[5].coast);
            let v: Vec<f64> = all_series(&AugModel::nominal(p), &runs)
                .unwrap()
                .iter()
                .map(|s| s.nrmse)
                .collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            assert!(
                mean < 1.2 * case.truth.noise_floor,
                "{v:?} against a floor of {}",
                case.truth.noise_floor
            );
        }
    }

    /// A held level is replaced by its mean where the readings are its
    /// noise; a controller's command swinging between its limits (a
    /// position loop), a ramp, and a command that jitters about a steady
    /// mean by much of the segment's span are the excitation and stay as
    /// measured.
    #[test]
    fn only_a_held_level_is_denoised() {
        let noise: Vec<f64> = {
            use rand_distr::{Distribution, Normal};
            let mut rng = StdRng::seed_from_u64(3);
            let d = Normal::new(0.0, 0.2).unwrap();
            (0..400).map(|_| d.sample(&mut rng)).collect()
        };
        let seg = |voltage: Vec<f64>| DcSegment {
            index: 1,
            time: (0..400).map(|k| k as f64 * 5e-4).collect(),
            current: vec![1.0; 400],
            speed: (0..400).map(|k| 50.0 + k as f64).collect(),
            voltage,
            ..Default::default()
        };
        // A step from 60 V to a level of 100 V.
        let level = seg(noise
            .iter()
            .enumerate()
            .map(|(k, v)| if k == 0 { 60.0 } else { 100.0 } + v)
            .collect());
        let bang: Vec<f64> = (0..400)
            .map(|k| if (k / 7) % 3 == 0 { 236.0 } else { -236.0 } + noise[k])
            .collect();
        let ramp = seg((0..400).map(|k| 0.5 * k as f64 + noise[k]).collect());
        // A loop's command answering a coarse encoder: it jumps by tens of
        // volts from one sample to the next about a steady mean, which
        // the spread test takes for noise.
        let jitter: Vec<f64> = noise.iter().map(|v| 20.0 + 150.0 * v).collect();
        let out = held_levels(&[level, seg(bang.clone()), ramp.clone(), seg(jitter.clone())]);
        let held = out[0].voltage[1..]
            .iter()
            .filter(|v| out[0].voltage[1] == **v)
            .count();
        assert!(held > 390, "{held} of 399 readings replaced by the level");
        assert_eq!(out[1].voltage, bang);
        assert_eq!(out[2].voltage, ramp.voltage);
        let tail = &jitter[300..];
        let var = tail.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>()
            / (2.0 * (tail.len() - 1) as f64);
        assert!(
            holds_level(tail, tail_mean(&jitter), var),
            "the spread test alone"
        );
        assert_eq!(out[3].voltage, jitter);
    }

    #[test]
    fn one_segment_is_not_enough() {
        let mut rng = StdRng::seed_from_u64(1);
        let mut record = simulate_dc_case(None, &mut rng).record;
        record.segments.truncate(1);
        let err = diagnose_dc(&record, &DiagnoseOptions::default()).unwrap_err();
        assert!(matches!(err, DiagnoseError::NotEnoughData(_)), "{err}");
    }

    /// A record whose segments are all too short (a record decimated ten
    /// times, say) is refused saying so, segment by segment.
    #[test]
    fn segments_too_short_to_use_are_named_in_the_refusal() {
        let mut rng = StdRng::seed_from_u64(1);
        let mut record = simulate_dc_case(None, &mut rng).record;
        record.segments.truncate(3);
        for seg in &mut record.segments {
            for v in [
                &mut seg.time,
                &mut seg.voltage,
                &mut seg.current,
                &mut seg.speed,
            ] {
                v.truncate(25);
            }
        }
        let err = diagnose_dc(&record, &DiagnoseOptions::default()).unwrap_err();
        let text = err.to_string();
        assert!(text.contains("0 usable segment(s) of 3"), "{text}");
        let first = &record.segments[0];
        assert!(
            text.contains(&format!(
                "segment {} ({}) has 25 samples, fewer than 40: not used",
                first.index, first.label
            )),
            "{text}"
        );
    }

    /// A segment after a gap in time (samples a logger dropped) starts
    /// from its own first sample, not from the end of the one before it.
    #[test]
    fn a_segment_after_a_gap_starts_from_its_own_first_sample() {
        let mut rng = StdRng::seed_from_u64(1);
        let case = simulate_dc_case(None, &mut rng);
        let p = truth_params(&case);
        let mut segs = case.record.segments;
        segs.truncate(3);
        let mut warnings = Vec::new();
        let joined = prepare_runs(&segs, &|| Some(p), &mut warnings).unwrap();
        assert!(joined[1].continues.is_some());
        assert!(
            !matches!(joined[1].start, Start::State(..)),
            "{:?}",
            joined[1].start
        );
        // 20 ms of samples of segment 1 missing at its start.
        let seg = &mut segs[1];
        let dt = seg.time[1] - seg.time[0];
        let drop = (0.02 / dt) as usize;
        for ch in [
            &mut seg.time,
            &mut seg.voltage,
            &mut seg.current,
            &mut seg.speed,
        ] {
            ch.drain(..drop);
        }
        let runs = prepare_runs(&segs, &|| Some(p), &mut warnings).unwrap();
        assert_eq!(runs[1].continues, None);
        assert_eq!(
            runs[1].start,
            first_state(&segs[1], runs[1].dt, false, Some(p))
        );
    }

    /// A record that starts from rest read through a noisy tachometer:
    /// its first speed reading is well off zero and its first readings
    /// barely drift against the noise. The start is chosen by how the
    /// motor simulates from it, so the first segment still starts from
    /// rest, not settled at its first voltage or in its noisy first state.
    #[test]
    fn a_noisy_start_from_rest_is_taken_from_rest() {
        use rand_distr::{Distribution, Normal};
        let mut rng = StdRng::seed_from_u64(2);
        let case = simulate_dc_case(None, &mut rng);
        let p = truth_params(&case);
        let mut segs = case.record.segments;
        segs.truncate(3);
        let seg = &mut segs[0];
        let top = seg.speed.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let noise = Normal::new(0.0, 0.03 * top).unwrap();
        for w in &mut seg.speed {
            *w += noise.sample(&mut rng);
        }
        seg.speed[0] = 0.05 * top;
        let runs = prepare_runs(&segs, &|| Some(p), &mut Vec::new()).unwrap();
        assert_eq!(runs[0].start, Start::Rest);
    }

    /// A shaft whose ringing the current shows well above its two-mass
    /// frequency (the blind suite of seed 2024, case 26: a 46 Hz shaft
    /// ringing at 74 Hz, a 167-line encoder that shows none of it in the
    /// speed). Started at the residual's peak alone the fit shrank
    /// nothing and the verdict was `none`; the start below the peak finds
    /// the shaft.
    #[test]
    fn a_shaft_ringing_above_its_frequency_is_found() {
        let case = crate::diagnose::blind::suite_case(2024, 26, Default::default()).unwrap();
        assert_eq!(case.truth.effect, "shaft_compliance");
        let run = diagnose_dc(&case.record, &DiagnoseOptions::default()).unwrap();
        let v = &run.report.verdict;
        assert_eq!(v.effect, "shaft_compliance", "{:?}", run.report.candidates);
        let shaft = run.report.candidates.iter().find(|c| c.effect == v.effect);
        let fr = shaft.unwrap().params["fr"].value;
        let truth = case.truth.effect_params["fr"];
        assert!((fr / truth - 1.0).abs() < 0.01, "fr {fr} against {truth}");
    }

    /// Ramps read through a noisy voltage sensor (the blind suite of seed
    /// 2024, case 12: 0.13 V of noise on a 15-bit reading, a 0.68 Ω
    /// armature, so 0.2 A of simulated current noise the motor never had).
    /// From the readings the armature reaction's 1–2 A at the short's
    /// peak was lost in it and the verdict was `none`; from the voltage
    /// as straight pieces the effect is named, and Ra once it is modelled
    /// is within 1 % of the truth.
    #[test]
    fn a_noisy_voltage_reading_is_smoothed_where_the_fit_gains() {
        let case = crate::diagnose::blind::suite_case(2024, 12, Default::default()).unwrap();
        assert_eq!(case.truth.effect, "armature_reaction");
        let d = diagnose_dc(&case.record, &DiagnoseOptions::default())
            .unwrap()
            .report;
        assert!(
            d.warnings
                .iter()
                .any(|w| w.contains("smoothed as straight pieces")),
            "{:?}",
            d.warnings
        );
        assert_eq!(d.verdict.effect, "armature_reaction", "{:?}", d.candidates);
        let ra = d.verdict.corrected_params["Ra"].corrected;
        let truth = case.truth.nominal["Ra"];
        assert!((ra / truth - 1.0).abs() < 0.01, "Ra {ra} against {truth}");
    }

    /// A blind case's staircase (seed 3, no effect), whose held levels
    /// carry the voltage noise: the readings with held levels denoised
    /// stay the input.
    #[test]
    fn a_quiet_voltage_reading_stays_the_input() {
        let mut rng = StdRng::seed_from_u64(3);
        let case = simulate_dc_case(None, &mut rng);
        let d = diagnose_dc(&case.record, &DiagnoseOptions::default())
            .unwrap()
            .report;
        assert!(
            !d.warnings.iter().any(|w| w.contains("straight pieces")),
            "{:?}",
            d.warnings
        );
    }

    /// A record whose first segment's voltage column is held at its first
    /// value while the motor moves (a set point logged in place of the
    /// armature voltage; the robustness sweep's `flat_first_segment` of
    /// seed 20261121 case 42): no DC model follows it (fit NRMSE above 1),
    /// and the refusal says which columns to check instead of scoring a
    /// gap against it.
    #[test]
    fn a_record_no_motor_follows_is_refused_with_the_columns_to_check() {
        let mut case =
            crate::diagnose::blind::suite_case(20261121, 42, Default::default()).unwrap();
        let seg = &mut case.record.segments[0];
        let held = seg.voltage[0];
        seg.voltage.fill(held);
        let record = crate::machine::ready_record(case.record, SegmentKind::DcStep, false);
        let e = diagnose_dc(&record, &DiagnoseOptions::default()).unwrap_err();
        assert!(
            matches!(&e, DiagnoseError::NominalFit(m)
                if m.contains("worse than their mean")
                    && m.contains("the armature voltage in V")),
            "{e}"
        );
    }

    /// A voltage reading with an offset of a third of its largest value
    /// (no candidate's effect) leaves a gap of many noise floors that no
    /// candidate closes: the `none` verdict says so; the same record
    /// without the offset gets no such warning.
    #[test]
    fn a_gap_no_candidate_explains_is_said_to_be_unexplained() {
        let mut rng = StdRng::seed_from_u64(5);
        let case = simulate_dc_case(None, &mut rng);
        let said = |d: &crate::contract::Diagnosis| {
            d.warnings
                .iter()
                .any(|w| w.starts_with("no candidate explains the gap"))
        };
        let clean = diagnose_dc(&case.record, &DiagnoseOptions::default())
            .unwrap()
            .report;
        assert_eq!(clean.verdict.effect, "none", "{:?}", clean.candidates);
        assert!(!said(&clean), "{:?}", clean.warnings);
        let mut record = case.record.clone();
        let top = record
            .segments
            .iter()
            .flat_map(|s| s.voltage.iter())
            .fold(0.0f64, |m, v| m.max(v.abs()));
        for seg in &mut record.segments {
            seg.voltage.iter_mut().for_each(|v| *v += top / 3.0);
        }
        let d = diagnose_dc(&record, &DiagnoseOptions::default())
            .unwrap()
            .report;
        assert_eq!(d.verdict.effect, "none", "{:?}", d.candidates);
        assert!(
            d.gap.noise_floor * EXPLAINED < d.verdict.gap_before,
            "{:?}",
            d.verdict
        );
        assert!(said(&d), "{:?}", d.warnings);
    }

    /// Interleaved blocks held out: a withheld armature reaction is named
    /// and closed to the noise, the report says how it was held out.
    #[test]
    fn interleaved_blocks_name_a_withheld_effect() {
        let mut rng = StdRng::seed_from_u64(3);
        let case = simulate_dc_case(Some(Effect::ArmatureReaction), &mut rng);
        let options = DiagnoseOptions {
            dc_interleaved: Some(true),
            ..Default::default()
        };
        let d = diagnose_dc(&case.record, &options).unwrap().report;
        assert!(
            d.validation.starts_with("interleaved blocks"),
            "{}",
            d.validation
        );
        assert_eq!(d.verdict.effect, "armature_reaction", "{:?}", d.candidates);
        assert!(
            d.verdict.gap_after < 2.0 * d.gap.noise_floor,
            "{:?}",
            d.verdict
        );
        assert!(d.verdict.gap_after < d.verdict.gap_before);
    }
}
