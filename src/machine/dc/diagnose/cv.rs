//! Interleaved time-block cross-validation of a DC fit.
//!
//! Each segment's samples are cut into blocks of [`CV_BLOCK`] samples
//! from its start, and block `b` of the segment at position `s` belongs
//! to fold `(b + s) mod CV_FOLDS`: the transient after each step (its
//! first block) goes to a different fold from one segment to the next,
//! so no fold holds out every transient and leaves the parameters only
//! transients determine (La, J) to the settled rest. Each fold refits the model without its blocks' rows
//! and simulates the whole record with the refit; each sample's held-out
//! residual is the one of the fold that left it out. Every fold sees every
//! segment's operating range, so an effect that shows only at the largest
//! current is not judged by an extrapolation from smaller ones (which
//! leave-one-segment-out does), and every sample is predicted once.
//!
//! The default since 2026-12-05 (`MOTORBENCH_DC_VALIDATION=segments`
//! leaves one segment out instead): on the blind suites it names more
//! withheld effects than leaving one segment out (own records 60/75
//! against 54/75, gym-electric-motor's 40/45 against 39/45, no false
//! alarm on either; docs/diagnosis-dc.md, Status). Its two false alarms
//! on third-party `none` records were sensor lags of 0.30 and 0.39 samples,
//! below what a record resolves from its own sampling
//! (`candidates::MIN_LAG_SAMPLES`).

use super::fit::{
    fit_fold, gauss_newton_step, refit_spec, runs_residuals, segment_rows, step_landed, FitSpec,
    Fitted, Weights,
};
use super::gap::HeldOutSeries;
use super::model::{AugModel, SegmentRun};

/// Folds of the interleaved cross-validation.
pub const CV_FOLDS: usize = 5;

/// Samples per block of the interleaving: longer than the residuals'
/// correlation at the rates DC records are taken (the decision's blocks
/// are 32 samples), so that a held-out block is not predicted by the
/// noise of the blocks beside it.
pub const CV_BLOCK: usize = 128;

/// The environment variable that picks the DC diagnosis's held-out
/// scheme: `interleaved` (this module, the default) or `segments` (leave
/// one segment out).
pub const VALIDATION_VAR: &str = "MOTORBENCH_DC_VALIDATION";

/// Whether interleaved blocks are held out: unless [`VALIDATION_VAR`]
/// asks for segments; a value that names no scheme is warned of and the
/// default kept.
pub fn interleaved_requested(warnings: &mut Vec<String>) -> bool {
    match std::env::var(VALIDATION_VAR).as_deref() {
        Ok("interleaved") | Err(_) => true,
        Ok("segments") => false,
        Ok(other) => {
            warnings.push(format!(
                "{VALIDATION_VAR}={other:?} names no held-out scheme (segments or \
                 interleaved); holding out interleaved blocks"
            ));
            true
        }
    }
}

/// The fold of sample `k` of the segment at position `s` of the record:
/// blocks counted from the segment's start, the first in fold `s`.
fn fold_of(s: usize, k: usize) -> usize {
    (k / CV_BLOCK + s) % CV_FOLDS
}

/// Per row of the record's residual vector ([`runs_residuals`] order):
/// the fold that holds it out.
pub(super) fn row_folds(runs: &[SegmentRun]) -> Vec<usize> {
    let mut out = Vec::with_capacity(runs.iter().map(segment_rows).sum());
    for (s, run) in runs.iter().enumerate() {
        for k in 0..run.len() {
            let f = fold_of(s, k);
            out.push(f);
            if !run.coast {
                out.push(f);
            }
        }
    }
    out
}

/// The model refit without fold `f`'s rows: one Gauss–Newton step from
/// `all`'s optimum when it is short and the linearisation predicts its
/// decrease (the tests of the leave-one-segment-out refit,
/// [`super::fit::one_step_refit`]), else an iterated fit from `all` with
/// those rows masked.
fn refit_fold(
    spec: &FitSpec,
    all: &Fitted,
    runs: &[SegmentRun],
    rows: &[usize],
    f: usize,
    w: &Weights,
    patience: usize,
) -> Option<AugModel> {
    let refit = refit_spec(spec, all);
    let at = &all.at;
    let np = refit.len();
    if at.np == np && at.rows == rows.len() && f < at.by_fold.len() {
        let held = &at.by_fold[f];
        let normal = &at.whole.normal - &held.normal;
        let gradient = &at.whole.gradient - &held.gradient;
        let sse0 = at.whole.sse - held.sse;
        if let Some(step) = gauss_newton_step(&normal, &gradient) {
            let model = refit.model_at(&step);
            let mut r = Vec::new();
            if runs_residuals(&model, runs, w, &mut r) && r.len() == rows.len() {
                let sse1: f64 = r
                    .iter()
                    .zip(rows)
                    .filter(|(_, k)| **k != f)
                    .map(|(v, _)| v * v)
                    .sum();
                if step_landed(&normal, &gradient, &step, sse0, sse1) {
                    return Some(model);
                }
            }
        }
    }
    let mask: Vec<bool> = rows.iter().map(|k| *k == f).collect();
    fit_fold(&refit, runs, w, patience, Some(&mask)).map(|m| m.model)
}

/// The cross-validated residual series of every run: each sample
/// predicted by the fold that left it out. `None` when a fold's refit or
/// simulation fails.
pub fn cross_validated(
    spec: &FitSpec,
    all: &Fitted,
    runs: &[SegmentRun],
    w: &Weights,
    patience: usize,
) -> Option<Vec<HeldOutSeries>> {
    let rows = row_folds(runs);
    let mut sims: Vec<(Vec<f64>, Vec<f64>)> = runs
        .iter()
        .map(|r| (vec![0.0; r.len()], vec![0.0; r.len()]))
        .collect();
    for f in 0..CV_FOLDS {
        let model = refit_fold(spec, all, runs, &rows, f, w, patience)?;
        let mut counts = vec![0usize; runs.len()];
        let ok = model.simulate_runs(runs, &mut |n, i, s| {
            let k = counts[n];
            if k < runs[n].len() && fold_of(n, k) == f {
                sims[n].0[k] = i;
                sims[n].1[k] = s;
            }
            counts[n] += 1;
        });
        if !ok {
            return None;
        }
    }
    runs.iter()
        .zip(&sims)
        .map(|(r, (si, sw))| super::series_of(r, si, sw))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fold_holds_out_a_fifth_of_the_blocks_in_turn() {
        let folds: Vec<usize> = (0..CV_BLOCK * CV_FOLDS * 2)
            .map(|k| fold_of(0, k))
            .collect();
        for f in 0..CV_FOLDS {
            let n = folds.iter().filter(|k| **k == f).count();
            assert_eq!(n, 2 * CV_BLOCK, "fold {f}");
        }
        assert_eq!(fold_of(0, CV_BLOCK - 1), 0);
        assert_eq!(fold_of(0, CV_BLOCK), 1);
        assert_eq!(fold_of(0, CV_BLOCK * CV_FOLDS), 0);
    }

    /// Segments of one length (a staircase's equal holds): their first
    /// blocks, the transients after the steps, fall in every fold in
    /// turn, not all in one.
    #[test]
    fn the_steps_transients_are_spread_over_the_folds() {
        let len = CV_BLOCK * CV_FOLDS;
        let first: Vec<usize> = (0..CV_FOLDS).map(|s| fold_of(s, 0)).collect();
        assert_eq!(first, [0, 1, 2, 3, 4]);
        for s in 0..CV_FOLDS {
            assert_eq!(fold_of(s, len), fold_of(s, 0), "segment {s}");
        }
    }
}
