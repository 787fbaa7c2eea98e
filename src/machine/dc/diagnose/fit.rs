//! Output-error fit of a nominal or augmented DC model on a set of
//! segments, by the `levenberg-marquardt` crate on noise-weighted
//! residuals of current and speed, and the held-out simulation of one
//! segment.
//!
//! Parameters are transformed so that the optimiser works unconstrained:
//! the six nominal parameters as `ln(p/p_ref)`, an effect parameter
//! linearly (a zero effect lies inside the search space, so a fit on data
//! without the effect finds it at zero), logarithmically or as a logit
//! where physics bounds it. The Jacobian is taken by forward differences
//! (what is simulated is what is differentiated, stiction included), and
//! the crate sees the problem reduced to `P+1` rows (`R` of a QR of the
//! Jacobian and the residual's norm), so it never factorises the tall
//! Jacobian itself.
//!
//! A held-out refit starts from the all-segment fit's linearisation, kept
//! with the fit ([`AtOptimum`]): one Gauss–Newton step on its normal
//! equations less the held-out rows ([`one_step_refit`]) where that step is
//! short and the residuals are linear over it, which costs one segment's
//! linearisation instead of an iterated fit of all the others. The fit
//! keeps the normal equations of each segment's rows and of each
//! interleaved fold's, not the tall Jacobian itself: a Jacobian is rows ×
//! parameters (17 MB for a minute at 2 kHz with a three-parameter effect),
//! and every candidate's fit lives until the verdict.

use std::cell::{Cell, RefCell};
use std::sync::Arc;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

use super::lanes;
use super::model::{AugModel, SegmentRun};
use crate::diagnose::decision::negligible_ftol;
use crate::identify::square_root::square_root_problem;
use crate::model::DcParams;

/// How one fitted parameter maps to its physical value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Transform {
    /// `v = reference·e^x`.
    Log,
    /// `v = reference + scale·x`.
    Linear(f64),
    /// `v = 1/(1 + e^−(x + logit(reference)))`, in (0, 1).
    Logit,
}

impl Transform {
    fn apply(self, reference: f64, x: f64) -> f64 {
        match self {
            Transform::Log => reference * x.exp(),
            Transform::Linear(scale) => reference + scale * x,
            Transform::Logit => {
                let z = x + (reference / (1.0 - reference)).ln();
                1.0 / (1.0 + (-z).exp())
            }
        }
    }
}

/// Noise weights `1/σ` of current and speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weights {
    /// 1/σ of the current, 1/A.
    pub current: f64,
    /// 1/σ of the speed, s/rad.
    pub speed: f64,
}

/// What is fitted: the model's form, where it starts and how each
/// parameter is transformed.
#[derive(Debug, Clone, PartialEq)]
pub struct FitSpec {
    /// The start (and reference of the transforms).
    pub start: AugModel,
    /// Transforms of the effect's parameters (0 to 3 of them).
    pub effect: Vec<Transform>,
}

impl FitSpec {
    /// Parameters fitted.
    pub fn len(&self) -> usize {
        6 + self.effect.len()
    }

    /// The model at `x`.
    pub fn model_at(&self, x: &DVector<f64>) -> AugModel {
        let r = &self.start.p;
        let p = DcParams {
            ra: r.ra * x[0].exp(),
            la: r.la * x[1].exp(),
            k: r.k * x[2].exp(),
            j: r.j * x[3].exp(),
            f: r.f * x[4].exp(),
            tst: r.tst * x[5].exp(),
        };
        let mut e = self.start.e;
        for (n, t) in self.effect.iter().enumerate() {
            e[n] = t.apply(self.start.e[n], x[6 + n]);
        }
        AugModel { p, e, ..self.start }
    }
}

/// Weighted residuals of the segments `runs`, simulated in order (each
/// continuing the one before where the record does): current then speed
/// per sample (speed only for a coast-down, whose current is zero by
/// construction), appended to `out`.
pub fn runs_residuals(
    model: &AugModel,
    runs: &[SegmentRun],
    w: &Weights,
    out: &mut Vec<f64>,
) -> bool {
    let rows: usize = runs.iter().map(segment_rows).sum();
    let from = out.len();
    out.resize(from + rows, 0.0);
    let col = &mut out[from..];
    runs_residuals_lanes(
        std::slice::from_ref(model),
        &[true],
        runs,
        w,
        &mut [col],
        |_, _, _| {},
    )[0]
}

/// [`runs_residuals`] of each model of `models` whose `live` is set, the
/// models simulated in lockstep ([`lanes::simulate_runs`]), lane `l`'s
/// rows into `cols[l]` (as many as the runs have); `seen(l, n, readings)`
/// with the simulated readings of run `n` in lane `l` where a caller
/// needs them too. Whether each lane's rows are all there.
pub(super) fn runs_residuals_lanes(
    models: &[AugModel],
    live: &[bool],
    runs: &[SegmentRun],
    w: &Weights,
    cols: &mut [&mut [f64]],
    mut seen: impl FnMut(usize, usize, &[(f64, f64)]),
) -> Vec<bool> {
    // Where each run's rows begin, the same in every lane; a lane's
    // readings of run `n` at `counts[l * runs.len() + n]`.
    let starts: Vec<usize> = runs
        .iter()
        .scan(0, |at, run| {
            let start = *at;
            *at += segment_rows(run);
            Some(start)
        })
        .collect();
    let mut counts = vec![0usize; models.len() * runs.len()];
    let ok = lanes::simulate_runs(models, live, runs, |l, n, readings| {
        seen(l, n, readings);
        let run = &runs[n];
        counts[l * runs.len() + n] += readings.len();
        let readings = &readings[..readings.len().min(run.len())];
        let (current, speed) = (
            &run.seg.current[..readings.len()],
            &run.seg.speed[..readings.len()],
        );
        let rows = &mut cols[l][starts[n]..starts[n] + segment_rows(run)];
        if run.coast {
            for ((row, (_, s)), m) in rows.iter_mut().zip(readings).zip(speed) {
                *row = (s - m) * w.speed;
            }
        } else {
            for (((row, (i, s)), mi), ms) in rows
                .chunks_exact_mut(2)
                .zip(readings)
                .zip(current)
                .zip(speed)
            {
                row[0] = (i - mi) * w.current;
                row[1] = (s - ms) * w.speed;
            }
        }
    });
    ok.iter()
        .zip(counts.chunks(runs.len().max(1)))
        .map(|(ok, counts)| *ok && counts.iter().zip(runs).all(|(k, r)| *k == r.len()))
        .collect()
}

/// Rows of one segment's residuals.
pub fn segment_rows(run: &SegmentRun) -> usize {
    if run.coast {
        run.len()
    } else {
        2 * run.len()
    }
}

/// Residual value standing for a model the simulation refuses.
const REFUSED: f64 = 1e15;

/// Forward-difference step in the transformed parameters.
const FD_STEP: f64 = 1e-7;

struct Linearisation {
    x: DVector<f64>,
    r: DVector<f64>,
    jac: DMatrix<f64>,
    reduced_r: DVector<f64>,
    reduced_j: DMatrix<f64>,
}

struct FitProblem<'a> {
    spec: &'a FitSpec,
    runs: &'a [SegmentRun<'a>],
    w: Weights,
    /// Rows left out of the fit (their residuals count as zero).
    mask: Option<&'a [bool]>,
    rows: usize,
    x: DVector<f64>,
    last: RefCell<Option<Linearisation>>,
    /// The squared norm of the reduced residuals at the solver's current
    /// point (where it last took the Jacobian): a trial point whose sum
    /// of squares is not below it is rejected whatever its Jacobian.
    reference: Cell<f64>,
    /// A trial point's residuals simulated alone, for the linearisation
    /// there to reuse.
    trial: RefCell<Option<(DVector<f64>, DVector<f64>)>>,
}

impl FitProblem<'_> {
    /// The residuals at each of `xs` into the matching column of `cols`
    /// (each of [`Self::rows`]), the models simulated in lockstep; whether
    /// the model accepts each `x` and every residual of it is finite.
    fn residuals_lanes(&self, xs: &[DVector<f64>], cols: &mut [&mut [f64]]) -> Vec<bool> {
        let live: Vec<bool> = xs
            .iter()
            .map(|x| x.iter().all(|v| v.is_finite() && v.abs() < 30.0))
            .collect();
        let models: Vec<AugModel> = xs.iter().map(|x| self.spec.model_at(x)).collect();
        let ok = runs_residuals_lanes(&models, &live, self.runs, &self.w, cols, |_, _, _| {});
        ok.into_iter()
            .zip(cols.iter_mut())
            .map(|(ok, col)| {
                if let (true, Some(mask)) = (ok, self.mask) {
                    for (v, out) in col.iter_mut().zip(mask) {
                        if *out {
                            *v = 0.0;
                        }
                    }
                }
                // A fold, not `all`: without the early exit the check
                // vectorises (a pass over tens of thousands of rows).
                ok && col.iter().fold(true, |all, v| all & v.is_finite())
            })
            .collect()
    }

    /// The reduced residuals the solver rejects the trial point `x` by,
    /// if it must reject it; `None` where it may accept it (then the
    /// point's residuals, simulated here, wait in [`Self::trial`] for its
    /// linearisation) or where this does not apply.
    ///
    /// The solver (MINPACK's `lmder`) accepts a trial only if it lowers
    /// the sum of squares, and on a rejection it reads nothing of the
    /// trial but the residuals' norm. So a trial whose sum of squares is
    /// not below the current point's needs no Jacobian: its residuals
    /// alone, as `[0, …, 0, ‖r‖]` (their norm: the reduced form's, up to
    /// rounding). Only for the models that are not rigid (a sensor lag,
    /// shaft compliance): in lockstep ([`lanes::simulate_runs`]) the point
    /// alone and then its steps cost more than all together. Sensor lags
    /// have gone in lockstep too since this was written, and for them it
    /// now costs about what it saves (5 of their 66 trials on the default
    /// record are rejected); it stays, because dropping it would move
    /// their fits in the last bits.
    fn rejected_trial(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
        let reference = self.reference.get();
        if self.spec.start.is_rigid()
            || !reference.is_finite()
            || self.last.borrow().as_ref().is_some_and(|l| l.x == *x)
        {
            return None;
        }
        let mut r = DVector::<f64>::zeros(self.rows);
        if !self.residuals_lanes(std::slice::from_ref(x), &mut [r.as_mut_slice()])[0] {
            return None;
        }
        let sse = r.norm_squared();
        if sse < reference {
            *self.trial.borrow_mut() = Some((x.clone(), r));
            return None;
        }
        let mut reduced = DVector::zeros(x.len() + 1);
        reduced[x.len()] = sse.sqrt();
        Some(reduced)
    }

    fn linearise(&self, x: &DVector<f64>) {
        if let Some(l) = self.last.borrow().as_ref() {
            if l.x == *x {
                return;
            }
        }
        // The residuals at `x` where a trial has simulated them already.
        let known = self
            .trial
            .borrow_mut()
            .take()
            .filter(|(at, _)| at == x)
            .map(|(_, r)| r);
        // The previous linearisation goes before the next is built: two
        // tall Jacobians at once would double the fit's peak memory. Its
        // buffers are reused as they are: every row of every column is
        // written below (a lane whose simulation fails is stepped
        // backward or zeroed), and a fresh tall matrix would cost a zeroing
        // pass and the page faults of megabytes per evaluation.
        let np = x.len();
        let (mut r, mut jac) = match self.last.borrow_mut().take() {
            Some(l) if l.r.len() == self.rows && l.jac.shape() == (self.rows, np) => (l.r, l.jac),
            _ => (
                DVector::<f64>::zeros(self.rows),
                DMatrix::<f64>::zeros(self.rows, np),
            ),
        };
        // The residuals at `x` (unless known) and at a forward step in
        // every parameter, all in one lockstep simulation; a column whose
        // step the model refuses steps backward alone, and stays zero
        // where it refuses both.
        let steps = (0..np).map(|n| {
            let mut xp = x.clone();
            xp[n] += FD_STEP;
            xp
        });
        let ok = if let Some(known) = known {
            r = known;
            let lanes: Vec<DVector<f64>> = steps.collect();
            let mut cols: Vec<&mut [f64]> =
                jac.as_mut_slice().chunks_mut(self.rows.max(1)).collect();
            let mut ok = vec![true];
            ok.extend(self.residuals_lanes(&lanes, &mut cols));
            ok
        } else {
            let lanes: Vec<DVector<f64>> = std::iter::once(x.clone()).chain(steps).collect();
            let mut cols: Vec<&mut [f64]> = std::iter::once(r.as_mut_slice())
                .chain(jac.as_mut_slice().chunks_mut(self.rows.max(1)))
                .collect();
            self.residuals_lanes(&lanes, &mut cols)
        };
        let l = if ok[0] {
            for (n, ok) in ok.into_iter().skip(1).enumerate() {
                // Column-major storage: column n is one slice.
                let col = &mut jac.as_mut_slice()[n * self.rows..(n + 1) * self.rows];
                let h = if ok {
                    FD_STEP
                } else {
                    let mut xp = x.clone();
                    xp[n] += -FD_STEP;
                    if !self.residuals_lanes(std::slice::from_ref(&xp), &mut [&mut *col])[0] {
                        col.fill(0.0);
                        continue;
                    }
                    -FD_STEP
                };
                // Slices, not the vector's strided iterator: this loop
                // runs over every row of every column and vectorises.
                for (c, a) in col.iter_mut().zip(r.as_slice()) {
                    *c = (*c - a) / h;
                }
            }
            let (reduced_r, reduced_j) = reduce(&jac, &r);
            Linearisation {
                x: x.clone(),
                r,
                jac,
                reduced_r,
                reduced_j,
            }
        } else {
            let mut reduced_r = DVector::zeros(np + 1);
            reduced_r[np] = REFUSED;
            Linearisation {
                x: x.clone(),
                r: DVector::zeros(0),
                jac: DMatrix::zeros(0, np),
                reduced_r,
                reduced_j: DMatrix::zeros(np + 1, np),
            }
        };
        *self.last.borrow_mut() = Some(l);
    }
}

/// The `P+1`-row problem equivalent to `(jac, r)`
/// ([`square_root_problem`]); a non-finite linearisation is refused like a
/// refused `x`.
fn reduce(jac: &DMatrix<f64>, r: &DVector<f64>) -> (DVector<f64>, DMatrix<f64>) {
    let np = jac.ncols();
    let r_norm_sq = if r.as_slice().iter().all(|v| v.is_finite()) {
        r.norm_squared()
    } else {
        f64::NAN
    };
    square_root_problem(gram(jac), &jac.tr_mul(r), r_norm_sq).unwrap_or_else(|| {
        let mut refused = DVector::zeros(np + 1);
        refused[np] = REFUSED;
        (refused, DMatrix::zeros(np + 1, np))
    })
}

/// `JᵀJ`, each entry the dot product of two columns as `tr_mul` takes it
/// (the same value to the last bit), the lower triangle mirrored from the
/// upper: half the work on a Jacobian of tens of thousands of rows.
fn gram(jac: &DMatrix<f64>) -> DMatrix<f64> {
    let np = jac.ncols();
    let mut out = DMatrix::zeros(np, np);
    for a in 0..np {
        for b in a..np {
            let v = jac.column(a).dot(&jac.column(b));
            out[(a, b)] = v;
            out[(b, a)] = v;
        }
    }
    out
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for FitProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x = x.clone();
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        if let Some(rejected) = self.rejected_trial(&self.x) {
            return Some(rejected);
        }
        self.linearise(&self.x);
        self.last.borrow().as_ref().map(|l| l.reduced_r.clone())
    }

    /// Also marks `x` as the solver's current point (it takes the
    /// Jacobian nowhere else).
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.linearise(&self.x);
        let last = self.last.borrow();
        self.reference.set(
            last.as_ref()
                .map_or(f64::NAN, |l| l.reduced_r.norm_squared()),
        );
        last.as_ref().map(|l| l.reduced_j.clone())
    }
}

/// Sums over a set of rows of a linearisation `(J, r)`.
#[derive(Debug, Clone)]
pub struct RowSums {
    /// `JᵀJ` of the rows.
    pub normal: DMatrix<f64>,
    /// `Jᵀr` of the rows.
    pub gradient: DVector<f64>,
    /// `rᵀr` of the rows.
    pub sse: f64,
}

impl RowSums {
    /// Over the `rows` rows of `(jac, r)` from `from`, computed as the
    /// one-step refit always took them (the same value to the last bit).
    fn of_block(jac: &DMatrix<f64>, r: &DVector<f64>, from: usize, rows: usize) -> RowSums {
        let j = jac.rows(from, rows);
        let rr = r.rows(from, rows);
        RowSums {
            normal: j.tr_mul(&j),
            gradient: j.tr_mul(&rr),
            sse: rr.norm_squared(),
        }
    }

    /// Over the rows `take` marks, a contiguous run of them at a time.
    fn of_rows(jac: &DMatrix<f64>, r: &DVector<f64>, take: impl Fn(usize) -> bool) -> RowSums {
        let np = jac.ncols();
        let mut s = RowSums {
            normal: DMatrix::zeros(np, np),
            gradient: DVector::zeros(np),
            sse: 0.0,
        };
        let mut row = 0;
        while row < r.len() {
            if !take(row) {
                row += 1;
                continue;
            }
            let from = row;
            while row < r.len() && take(row) {
                row += 1;
            }
            let b = RowSums::of_block(jac, r, from, row - from);
            s.normal += b.normal;
            s.gradient += b.gradient;
            s.sse += b.sse;
        }
        s
    }
}

/// The normal equations of a fit's linearisation at its optimum, whole
/// and per block of rows: what a held-out refit steps from.
#[derive(Debug)]
pub struct AtOptimum {
    /// Residual rows, of every run in order ([`segment_rows`] each).
    pub rows: usize,
    /// Transformed parameters (the Jacobian's columns).
    pub np: usize,
    /// Over every row: `JᵀJ`, `Jᵀr`, `rᵀr`.
    pub whole: RowSums,
    /// Over each run's rows, in the runs' order (empty on a fold's own
    /// fit, which no refit steps from).
    pub by_run: Vec<RowSums>,
    /// Over each interleaved fold's rows ([`super::cv`]); empty as
    /// `by_run`.
    pub by_fold: Vec<RowSums>,
}

impl AtOptimum {
    /// The sums of `(jac, r)`, the linearisation of `runs`; per run and
    /// per fold only when `blocks`.
    fn new(jac: &DMatrix<f64>, r: &DVector<f64>, runs: &[SegmentRun], blocks: bool) -> AtOptimum {
        let whole = RowSums {
            normal: gram(jac),
            gradient: jac.tr_mul(r),
            sse: r.norm_squared(),
        };
        let (by_run, by_fold) = if blocks {
            let mut from = 0;
            let by_run = runs
                .iter()
                .map(|run| {
                    let rows = segment_rows(run);
                    let s = RowSums::of_block(jac, r, from, rows);
                    from += rows;
                    s
                })
                .collect();
            let folds = super::cv::row_folds(runs);
            let by_fold = (0..super::cv::CV_FOLDS)
                .map(|f| RowSums::of_rows(jac, r, |row| folds[row] == f))
                .collect();
            (by_run, by_fold)
        } else {
            (Vec::new(), Vec::new())
        };
        AtOptimum {
            rows: r.len(),
            np: jac.ncols(),
            whole,
            by_run,
            by_fold,
        }
    }
}

/// A fitted model.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The model at the optimum.
    pub model: AugModel,
    /// Sum of squared weighted residuals.
    pub sse: f64,
    /// Covariance of the transformed parameters (`s²·(JᵀJ)⁻¹`, inflated
    /// by the residuals' colour); `None` when singular.
    pub covariance: Option<DMatrix<f64>>,
    /// Whether the optimiser reports convergence.
    pub converged: bool,
    /// Residual variance per degree of freedom, `SSE/(rows − P)`.
    pub s2: f64,
    /// Colour of the residuals: rows per effective independent sample.
    pub colour: f64,
    /// The linearisation at the optimum (what a held-out refit steps
    /// from, [`one_step_refit`]).
    pub at: Arc<AtOptimum>,
}

/// Fit `spec` to `runs` weighted by `w`, at most `patience` (×P)
/// evaluations, keeping what a held-out refit steps from. `None` when the
/// start itself is refused.
pub fn fit(spec: &FitSpec, runs: &[SegmentRun], w: &Weights, patience: usize) -> Option<Fitted> {
    fit_masked(spec, runs, w, patience, None, true)
}

/// A cross-validation fold's refit: [`fit`] without the rows `mask` marks,
/// keeping no per-block sums (no refit steps from a fold's).
pub fn fit_fold(
    spec: &FitSpec,
    runs: &[SegmentRun],
    w: &Weights,
    patience: usize,
    mask: Option<&[bool]>,
) -> Option<Fitted> {
    fit_masked(spec, runs, w, patience, mask, false)
}

fn fit_masked(
    spec: &FitSpec,
    runs: &[SegmentRun],
    w: &Weights,
    patience: usize,
    mask: Option<&[bool]>,
    blocks: bool,
) -> Option<Fitted> {
    let rows: usize = runs.iter().map(segment_rows).sum();
    let np = spec.len();
    let problem = FitProblem {
        spec,
        runs,
        w: *w,
        mask,
        rows,
        x: DVector::zeros(np),
        last: RefCell::new(None),
        reference: Cell::new(f64::NAN),
        trial: RefCell::new(None),
    };
    let lm = LevenbergMarquardt::new()
        .with_ftol(negligible_ftol(rows))
        .with_xtol(1e-9)
        .with_gtol(1e-9)
        .with_patience(patience);
    let (problem, report) = lm.minimize(problem);
    problem.linearise(&problem.x);
    let last = problem.last.into_inner()?;
    if last.r.is_empty() {
        return None;
    }
    let sse = last.r.norm_squared();
    let dof = (rows as f64 - np as f64).max(1.0);
    let s2 = sse / dof;
    let colour =
        rows as f64 / crate::diagnose::decision::effective_samples(last.r.as_slice()).max(1.0);
    let at = AtOptimum::new(&last.jac, &last.r, runs, blocks);
    let model = spec.model_at(&last.x);
    drop(last);
    let covariance = at
        .whole
        .normal
        .clone()
        .try_inverse()
        .map(|m| m * s2 * colour.max(1.0));
    Some(Fitted {
        model,
        sse,
        covariance,
        converged: report.termination.was_successful(),
        s2,
        colour: colour.max(1.0),
        at: Arc::new(at),
    })
}

/// Largest change of any transformed parameter a one-step refit takes
/// (a factor e^0.05 of a log-transformed one): leaving one segment out
/// moves a parameter the others determine by a fraction of its standard
/// error, far less. A longer step (a direction the training segments
/// leave flat, or a misspecified model whose optimum moves with every
/// segment) is left to the iterated refit.
const ONE_STEP_LIMIT: f64 = 0.05;

/// The refit of `all` (fitted on every run of `runs`) without run `h`
/// (`train`: the others), in one Gauss–Newton step from `all`'s optimum:
/// the normal equations of the all-run linearisation less the rows of run
/// `h`; the run after `h`, which in the fold starts from its own start
/// instead of continuing `h`, linearised anew on its own. The fold's
/// optimum lies next to `all`'s (one segment of several left out), where
/// the residuals are close to linear in the parameters, so one step lands
/// on it up to the curvature's second-order term, at the cost of one
/// segment's linearisation and one simulation of `train` instead of an
/// iterated fit of it. The step is taken only if it moves no parameter by
/// more than [`ONE_STEP_LIMIT`] and lowers the fold's sum of squares by
/// what the linearisation predicts (within [`ONE_STEP_AGREEMENT`]);
/// `None` otherwise (the caller then iterates).
pub fn one_step_refit(
    spec: &FitSpec,
    all: &Fitted,
    runs: &[SegmentRun],
    train: &[SegmentRun],
    h: usize,
    w: &Weights,
) -> Option<AugModel> {
    // Measured from `all`'s optimum: x = 0 there, and the Jacobian with
    // respect to this spec's parameters is the all-run one (every
    // transform's derivative at a point does not depend on its reference).
    let refit = refit_spec(spec, all);
    let np = refit.len();
    let at = &all.at;
    if at.np != np
        || at.by_run.len() != runs.len()
        || at.rows != runs.iter().map(segment_rows).sum::<usize>()
    {
        return None;
    }
    let mut normal = at.whole.normal.clone();
    let mut gradient = at.whole.gradient.clone();
    let mut sse0 = at.whole.sse;
    let mut add = |s: &RowSums, sign: f64| {
        normal += &s.normal * sign;
        gradient += &s.gradient * sign;
        sse0 += s.sse * sign;
    };
    add(&at.by_run[h], -1.0);
    let next = h + 1;
    let next_continues = next < runs.len()
        && runs[next].continues.is_some()
        && runs[next].seg.index == runs[h].seg.index + 1;
    if next_continues {
        let rows = segment_rows(&runs[next]);
        add(&at.by_run[next], -1.0);
        let alone = FitProblem {
            spec: &refit,
            runs: std::slice::from_ref(&runs[next]),
            w: *w,
            mask: None,
            rows,
            x: DVector::zeros(np),
            last: RefCell::new(None),
            reference: Cell::new(f64::NAN),
            trial: RefCell::new(None),
        };
        alone.linearise(&alone.x);
        let l = alone.last.into_inner()?;
        if l.r.is_empty() {
            return None;
        }
        add(&RowSums::of_block(&l.jac, &l.r, 0, rows), 1.0);
    }
    let step = gauss_newton_step(&normal, &gradient)?;
    let model = refit.model_at(&step);
    let mut r = Vec::new();
    if !runs_residuals(&model, train, w, &mut r) {
        return None;
    }
    let sse1: f64 = r.iter().map(|v| v * v).sum();
    step_landed(&normal, &gradient, &step, sse0, sse1).then_some(model)
}

/// Whether a Gauss–Newton `step` on the problem `(normal, gradient)`
/// landed where the linearisation said: the sum of squares fell from
/// `sse0` to `sse1` by what it predicts, ‖r‖² − ‖r + JΔ‖², within
/// [`ONE_STEP_AGREEMENT`].
pub fn step_landed(
    normal: &DMatrix<f64>,
    gradient: &DVector<f64>,
    step: &DVector<f64>,
    sse0: f64,
    sse1: f64,
) -> bool {
    let predicted = -(2.0 * gradient.dot(step) + step.dot(&(normal * step)));
    let actual = sse0 - sse1;
    let linear = if predicted <= 1e-9 * sse0 {
        actual >= -1e-9 * sse0
    } else {
        (ONE_STEP_AGREEMENT.0..=ONE_STEP_AGREEMENT.1).contains(&(actual / predicted))
    };
    sse1.is_finite() && linear
}

/// Range of the ratio of the actual to the predicted decrease of the
/// fold's sum of squares within which the residuals count as linear over
/// the step, so that the step lands where an iterated refit converges.
const ONE_STEP_AGREEMENT: (f64, f64) = (0.8, 1.25);

/// Directions of the parameters whose curvature `JᵀJ` is below this
/// fraction of the largest are ones the data do not determine: a
/// candidate's shape parameters where its size fits as nothing (on the
/// default record, eigenvalues of 1e-4 to 3 against 7e9; every determined
/// direction there is above 2e-4 of the largest).
const UNDETERMINED: f64 = 1e-6;

/// The Gauss–Newton step `−(JᵀJ)⁻¹Jᵀr`, if every component is within
/// [`ONE_STEP_LIMIT`]. A longer step is not shortened: a step cut short
/// stays next to the all-segment optimum, which was fitted with the
/// held-out segment, and would predict that segment with what it was
/// fitted to (a misspecified nominal model then looks better held out than
/// it is).
///
/// Directions the data do not determine ([`UNDETERMINED`]) are left where
/// the all-segment optimum has them instead: the held-out rows carry no
/// more information on them than the rest, so the fold's refit cannot
/// learn them from the held-out data, and a step along them (tens of
/// units of a log-transformed parameter) is the linearisation's artefact,
/// not the fold's optimum. Without this, every fold of a candidate whose
/// effect fits as nothing was refitted by iterating (two thirds of the
/// default record's diagnosis).
pub fn gauss_newton_step(normal: &DMatrix<f64>, gradient: &DVector<f64>) -> Option<DVector<f64>> {
    let eigen = normal.clone().symmetric_eigen();
    let largest = eigen.eigenvalues.max();
    if !(largest.is_finite() && largest > 0.0) {
        return None;
    }
    let floor = UNDETERMINED * largest;
    let step = if eigen.eigenvalues.iter().all(|&l| l > floor) {
        normal.clone().cholesky()?.solve(&(-gradient))
    } else {
        let mut step = DVector::zeros(gradient.len());
        for (k, &l) in eigen.eigenvalues.iter().enumerate() {
            if l > floor {
                let v = eigen.eigenvectors.column(k);
                step -= v * (v.dot(gradient) / l);
            }
        }
        step
    };
    step.iter()
        .all(|v| v.is_finite() && v.abs() <= ONE_STEP_LIMIT)
        .then_some(step)
}

/// `runs` without run `h`: a fold's training runs.
pub fn without<'a>(runs: &[SegmentRun<'a>], h: usize) -> Vec<SegmentRun<'a>> {
    runs.iter()
        .enumerate()
        .filter(|(n, _)| *n != h)
        .map(|(_, r)| *r)
        .collect()
}

/// The spec that refits `fitted` itself (a fold's start).
pub fn refit_spec(spec: &FitSpec, fitted: &Fitted) -> FitSpec {
    FitSpec {
        start: fitted.model,
        effect: spec.effect.clone(),
    }
}

#[cfg(test)]
pub(super) mod tests {
    use proptest::prelude::*;

    use super::super::candidates::{candidates, RecordScales};
    use super::super::model::{Augment, Continuation, LagChannel, Start};
    use super::*;
    use crate::record::DcSegment;

    pub(in crate::machine::dc::diagnose) const DT: f64 = 5e-4;
    const LEVELS: [f64; 2] = [120.0, 200.0];

    /// Two noise-free segments of the seed motor with augmentation `aug`
    /// at `e`: a start from rest at 120 V, then a step to 200 V from there.
    fn record(aug: Augment, e: [f64; 3]) -> Vec<DcSegment> {
        let m = AugModel {
            aug,
            e,
            ..AugModel::nominal(DcParams::SEED_TABLE4_MOMENTS)
        };
        let n = 1200;
        let mut heat = 0.0;
        let mut out = Vec::new();
        for (k, &u) in LEVELS.iter().enumerate() {
            let input = DcSegment {
                index: k as u32,
                time: (0..n).map(|j| j as f64 * DT).collect(),
                voltage: vec![u; n],
                ..Default::default()
            };
            let run = SegmentRun {
                seg: &input,
                dt: DT,
                start: start(k),
                coast: false,
                heat_before: heat,
                continues: None,
            };
            let (mut i, mut w) = (Vec::new(), Vec::new());
            assert!(m.simulate(&run, &mut |a, b| {
                i.push(a);
                w.push(b);
            }));
            heat += i.iter().map(|v| v * v * DT).sum::<f64>();
            out.push(DcSegment {
                current: i,
                speed: w,
                ..input
            });
        }
        out
    }

    fn start(k: usize) -> Start {
        if k == 0 {
            Start::Rest
        } else {
            Start::Settled(LEVELS[k - 1])
        }
    }

    /// `segs` as the runs a fit takes, each from its own start; the heat
    /// of them all.
    fn runs_of(segs: &[DcSegment]) -> (Vec<SegmentRun<'_>>, f64) {
        let mut heat = 0.0;
        let runs = segs
            .iter()
            .enumerate()
            .map(|(k, seg)| {
                let r = SegmentRun {
                    seg,
                    dt: DT,
                    start: start(k),
                    coast: false,
                    heat_before: heat,
                    continues: None,
                };
                heat += seg.current.iter().map(|v| v * v * DT).sum::<f64>();
                r
            })
            .collect();
        (runs, heat)
    }

    /// Noise weights of the noise-free test records, and the noise of
    /// [`noisy_steps`]: 10 mA, 0.1 rad/s.
    pub(in crate::machine::dc::diagnose) const WEIGHTS: Weights = Weights {
        current: 1.0 / 0.01,
        speed: 1.0 / 0.1,
    };

    /// A trial the solver must reject (its sum of squares above the
    /// current point's) gets its residuals' norm alone, and the
    /// linearisation stays at the current point; a trial it may accept is
    /// linearised, the same to the bit as from scratch. Only where lanes
    /// go one after another (a sensor lag), not in lockstep.
    #[test]
    fn a_trial_that_cannot_be_accepted_is_not_linearised() {
        let segs = record(
            Augment::SensorLag(LagChannel::Current),
            [2.0 * DT, 0.0, 0.0],
        );
        let (runs, _) = runs_of(&segs);
        let nominal = AugModel::nominal(DcParams::SEED_TABLE4_MOMENTS);
        let spec = |aug, effect| FitSpec {
            start: AugModel {
                aug,
                e: [DT, 0.0, 0.0],
                ..nominal
            },
            effect,
        };
        let (lag_spec, thermal_spec) = (
            spec(
                Augment::SensorLag(LagChannel::Current),
                vec![Transform::Linear(DT)],
            ),
            spec(Augment::ThermalDrift, vec![Transform::Linear(1.0)]),
        );
        let problem_of = |spec| FitProblem {
            spec,
            runs: &runs,
            w: WEIGHTS,
            mask: None,
            rows: runs.iter().map(segment_rows).sum(),
            x: DVector::zeros(7),
            last: RefCell::new(None),
            reference: Cell::new(f64::NAN),
            trial: RefCell::new(None),
        };
        let at = |x6: f64| DVector::from_fn(7, |k, _| if k == 6 { x6 } else { 0.0 });
        let sse = |p: &FitProblem, x: &DVector<f64>| {
            let mut r = Vec::new();
            assert!(runs_residuals(&p.spec.model_at(x), &runs, &WEIGHTS, &mut r));
            r.iter().map(|v| v * v).sum::<f64>()
        };

        let mut lag = problem_of(&lag_spec);
        lag.jacobian().unwrap();
        // Twenty samples of lag against the record's two: far worse.
        let far = at(19.0);
        assert!(sse(&lag, &far) > sse(&lag, &at(0.0)));
        lag.set_params(&far);
        let rejected = lag.residuals().unwrap();
        assert!(rejected.rows(0, 7).iter().all(|v| *v == 0.0));
        assert!((rejected[7] - sse(&lag, &far).sqrt()).abs() <= 1e-12 * rejected[7]);
        assert_eq!(lag.last.borrow().as_ref().unwrap().x, at(0.0));
        // The record's own lag: better, linearised there.
        let near = at(1.0);
        lag.set_params(&near);
        let reduced = lag.residuals().unwrap();
        assert_eq!(lag.last.borrow().as_ref().unwrap().x, near);
        let fresh = problem_of(&lag_spec);
        fresh.linearise(&near);
        let fresh = fresh.last.into_inner().unwrap();
        assert_eq!(reduced, fresh.reduced_r);
        assert_eq!(lag.jacobian().unwrap(), fresh.reduced_j);

        // A rigid model's trial is linearised whatever its sum of squares.
        let mut thermal = problem_of(&thermal_spec);
        thermal.jacobian().unwrap();
        thermal.set_params(&far);
        thermal.residuals().unwrap();
        assert_eq!(thermal.last.borrow().as_ref().unwrap().x, far);
    }

    /// Fit `aug` to `segs` from the nominal parameters and the candidate's
    /// own start values; the fitted model.
    fn refit(aug: Augment, segs: &[DcSegment]) -> AugModel {
        let (runs, heat) = runs_of(segs);
        let all = |f: fn(&DcSegment) -> &Vec<f64>| {
            segs.iter().flat_map(f).fold(0.0f64, |m, v| m.max(v.abs()))
        };
        let settled: Vec<f64> = segs
            .iter()
            .map(|s| s.current[s.current.len() - 1])
            .collect();
        let scales = RecordScales {
            i_max: all(|s| &s.current),
            i_settled: settled.iter().sum::<f64>() / settled.len() as f64,
            u_max: all(|s| &s.voltage),
            w_max: all(|s| &s.speed),
            heat_total: heat,
            dt: DT,
            peaks_hz: Vec::new(),
            w_noise: 0.0,
        };
        let nominal = AugModel::nominal(DcParams::SEED_TABLE4_MOMENTS);
        let w = WEIGHTS;
        // Every start of that augmentation; the best fit stands, as in the
        // diagnosis.
        candidates(&nominal, &scales)
            .into_iter()
            .filter(|d| d.aug == aug)
            .map(|d| {
                let spec = FitSpec {
                    start: AugModel {
                        aug,
                        e: d.e,
                        ..nominal
                    },
                    effect: d.transforms,
                };
                fit(&spec, &runs, &w, 40).expect("the start is simulated")
            })
            .min_by(|a, b| a.sse.total_cmp(&b.sse))
            .expect("a candidate of that augmentation")
            .model
    }

    /// Three noisy steps of the seed motor, each from the level before it
    /// (settled), as runs.
    pub(in crate::machine::dc::diagnose) fn noisy_steps(levels: &[f64]) -> Vec<DcSegment> {
        let m = AugModel::nominal(DcParams::SEED_TABLE4_MOMENTS);
        let mut x = 0.412_345_678f64;
        let mut noise = move || {
            x = (x * 7.123_456_789 + 0.271_828).fract();
            (x - 0.5) * 3.0f64.sqrt() * 2.0
        };
        let n = 1200;
        levels
            .windows(2)
            .enumerate()
            .map(|(k, pair)| {
                let input = DcSegment {
                    index: k as u32,
                    time: (0..n).map(|j| j as f64 * DT).collect(),
                    voltage: vec![pair[1]; n],
                    ..Default::default()
                };
                let run = SegmentRun {
                    seg: &input,
                    dt: DT,
                    start: Start::Settled(pair[0]),
                    coast: false,
                    heat_before: 0.0,
                    continues: None,
                };
                let (mut i, mut w) = (Vec::new(), Vec::new());
                assert!(m.simulate(&run, &mut |a, b| {
                    i.push(a + 0.01 * noise());
                    w.push(b + 0.1 * noise());
                }));
                DcSegment {
                    current: i,
                    speed: w,
                    ..input
                }
            })
            .collect()
    }

    /// `segs` as runs [`DT`] apart, none coasting or heated before, each
    /// starting and continuing the one before as `start` says of its
    /// index.
    pub(in crate::machine::dc::diagnose) fn unheated_runs(
        segs: &[DcSegment],
        start: impl Fn(usize) -> (Start, Option<Continuation>),
    ) -> Vec<SegmentRun<'_>> {
        segs.iter()
            .enumerate()
            .map(|(k, seg)| {
                let (start, continues) = start(k);
                SegmentRun {
                    seg,
                    dt: DT,
                    start,
                    coast: false,
                    heat_before: 0.0,
                    continues,
                }
            })
            .collect()
    }

    /// The seed motor with its resistance 10 % high and its constant 3 %
    /// low: a fit's start off the truth of [`noisy_steps`].
    pub(in crate::machine::dc::diagnose) fn off_seed() -> AugModel {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        AugModel::nominal(DcParams {
            ra: p.ra * 1.1,
            k: p.k * 0.97,
            ..p
        })
    }

    /// A held-out refit in one step predicts the held-out segment as the
    /// refit iterated to convergence does: the same held-out sum of
    /// squares to 1e-4, for every fold.
    #[test]
    fn one_step_refit_predicts_as_the_converged_refit() {
        let levels = [60.0, 120.0, 200.0, 90.0];
        let segs = noisy_steps(&levels);
        let runs = unheated_runs(&segs, |k| (Start::Settled(levels[k]), None));
        let w = WEIGHTS;
        let spec = FitSpec {
            start: off_seed(),
            effect: Vec::new(),
        };
        let all = fit(&spec, &runs, &w, 40).expect("the all-segment fit");
        let held_sse = |m: &AugModel, h: usize| {
            let mut r = Vec::new();
            assert!(runs_residuals(m, &runs[h..=h], &w, &mut r));
            r.iter().map(|v| v * v).sum::<f64>()
        };
        for h in 0..runs.len() {
            let train = without(&runs, h);
            let one = one_step_refit(&spec, &all, &runs, &train, h, &w).expect("a step");
            let full = fit(&refit_spec(&spec, &all), &train, &w, 40)
                .expect("the fold's fit")
                .model;
            let (a, b) = (held_sse(&one, h), held_sse(&full, h));
            assert!((a / b - 1.0).abs() < 1e-4, "fold {h}: {a} against {b}");
            // And not merely the all-segment model again.
            assert_ne!(one, all.model, "fold {h}");
        }

        // What the fit keeps instead of its Jacobian: the segments' sums,
        // and the interleaved folds', each add up to the whole.
        let at = &all.at;
        assert_eq!((at.by_run.len(), at.by_fold.len()), (runs.len(), 5));
        for blocks in [&at.by_run, &at.by_fold] {
            let normal = blocks
                .iter()
                .fold(DMatrix::zeros(at.np, at.np), |m, b| m + &b.normal);
            let gradient = blocks
                .iter()
                .fold(DVector::zeros(at.np), |g, b| g + &b.gradient);
            let sse: f64 = blocks.iter().map(|b| b.sse).sum();
            assert!((normal - &at.whole.normal).norm() <= 1e-9 * at.whole.normal.norm());
            assert!((gradient - &at.whole.gradient).norm() <= 1e-9 * at.whole.normal.norm());
            assert!((sse / at.whole.sse - 1.0).abs() < 1e-12);
        }
        // A fold's own fit keeps no blocks: no refit steps from it.
        let fold = fit_fold(&refit_spec(&spec, &all), &without(&runs, 0), &w, 40, None)
            .expect("the fold's fit");
        assert!(fold.at.by_run.is_empty() && fold.at.by_fold.is_empty());
        assert!(one_step_refit(&spec, &fold, &runs, &without(&runs, 0), 0, &w).is_none());
    }

    /// A direction the data do not determine is left where it is; the
    /// determined ones take the Gauss–Newton step, and a full-rank problem
    /// is solved as before (Cholesky).
    #[test]
    fn an_undetermined_direction_takes_no_step() {
        // Curvature 4 and 9 along x and y; along z, 1e-9 of that (a
        // candidate's shape where its size is nothing).
        let normal = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 9.0, 9e-9]));
        let gradient = DVector::from_vec(vec![-0.04, 0.09, 0.5]);
        let step = gauss_newton_step(&normal, &gradient).expect("a step");
        assert!((step[0] - 0.01).abs() < 1e-15, "{step}");
        assert!((step[1] + 0.01).abs() < 1e-15, "{step}");
        assert_eq!(step[2], 0.0, "{step}");
        // Determined in every direction: the Cholesky solution exactly.
        let full = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.0, 1.0, 9.0, 0.5, 0.0, 0.5, 2.0]);
        let g = DVector::from_vec(vec![0.01, -0.02, 0.03]);
        let want = full.clone().cholesky().unwrap().solve(&(-&g));
        assert_eq!(gauss_newton_step(&full, &g), Some(want));
        // Too long a step along a determined direction is still refused.
        let far = DVector::from_vec(vec![-4.0, 0.0, 0.0]);
        assert_eq!(gauss_newton_step(&normal, &far), None);
    }

    /// The Gram matrix is `tr_mul`'s to the last bit, so the fits (and
    /// every verdict) are those before it replaced `tr_mul`.
    #[test]
    fn gram_is_tr_mul_exactly() {
        let mut x = 0.123_456_789f64;
        let jac = DMatrix::<f64>::from_fn(3001, 9, |_, _| {
            x = (x * 3.987_654_321 + 0.314_159).fract();
            (x - 0.5) * 1e3_f64.powf(x)
        });
        assert_eq!(gram(&jac), jac.tr_mul(&jac));
    }

    fn close(got: f64, want: f64, tol: f64) -> bool {
        (got / want - 1.0).abs() < tol
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 24,
            // A fixed seed: CI runs the same cases every time.
            rng_seed: proptest::test_runner::RngSeed::Fixed(24),
            ..ProptestConfig::default()
        })]

        /// identify(simulate(θ)) ≈ θ for every augmentation with a zero
        /// effect inside its search space, from the starts the diagnosis
        /// uses: the effect's parameters within 2 %, K and Ra within 0.5 %.
        #[test]
        fn an_augmented_fit_recovers_the_effect_it_was_simulated_with(
            which in 0usize..6,
            a in 0.0f64..1.0,
            b in 0.0f64..1.0,
        ) {
            let (aug, e, n) = match which {
                // 2–6 V above a knee of 0.1–0.4 A (steady currents ~0.15 A).
                0 => (Augment::BrushDrop, [2.0 + 4.0 * a, 0.1 + 0.3 * b, 0.0], 2),
                // K down 3–10 % at the 6.5 A start-up peak.
                1 => (Augment::ArmatureReaction, [(0.03 + 0.07 * a) / 42.0, 0.0, 0.0], 1),
                // La halved at 2.5–8 A.
                2 => (Augment::InductanceSaturation, [1.0 / (2.5 + 5.5 * a).powi(2), 0.0, 0.0], 1),
                // La falling to a floor of 30–50 % past a knee at 1.5–4 A.
                5 => (
                    Augment::InductanceSaturation,
                    [1.0 / (1.5 + 2.5 * a).powi(2), 0.3 + 0.2 * b, 0.0],
                    2,
                ),
                // Ra up 0.5–2 % per A²·s.
                3 => (Augment::ThermalDrift, [0.005 + 0.015 * a, 0.0, 0.0], 1),
                // A 1–4 sample lag on the current reading.
                _ => (Augment::SensorLag(LagChannel::Current), [DT * (1.0 + 3.0 * a), 0.0, 0.0], 1),
            };
            let m = refit(aug, &record(aug, e));
            for k in 0..n {
                prop_assert!(close(m.e[k], e[k], 0.02), "{aug:?} e {:?} vs {:?}, {:?}", m.e, e, m.p);
            }
            let p = DcParams::SEED_TABLE4_MOMENTS;
            prop_assert!(close(m.p.k, p.k, 5e-3) && close(m.p.ra, p.ra, 5e-3), "{aug:?}: {:?}", m.p);
        }
    }
}
