//! Levenberg–Marquardt fit of the nominal model or an augmented one to a
//! subset of a sweep's points (current and power, noise-weighted), the
//! held-out residuals of a model over folds, and linearised 95 %
//! intervals of a fit.

use levenberg_marquardt::LevenbergMarquardt;
use nalgebra::{DMatrix, DVector};

use super::data::SweepSet;
use super::effects::{ImAugmentation, Terminal};
use crate::diagnose::decision::negligible_ftol;
use crate::identify::least_squares::{AtParams, Residuals};
use crate::identify::PRACTICAL_LIMIT;

/// A fitted model.
#[derive(Debug, Clone, PartialEq)]
pub struct AugmentedFit {
    /// The fitted vector.
    pub x: Vec<f64>,
    /// Sum of squared weighted residuals on the fitted points.
    pub cost: f64,
    /// Residual evaluations the solver took, over all starts.
    pub evaluations: usize,
}

/// Weighted residuals of `model` at point `k`: current and power, each
/// divided by its noise scale, and the shaft torque's (0 where the point
/// has no torque). `None` outside the physical region.
pub fn weighted_residual(
    model: &ImAugmentation,
    x: &[f64],
    data: &SweepSet,
    k: usize,
) -> Option<(f64, f64, f64)> {
    let t = model.terminal(x, &data.inputs[k])?;
    Some(weighted_of(model, x, data, k, &t))
}

/// [`weighted_residual`] from the model's terminal values `t` at point `k`.
fn weighted_of(
    model: &ImAugmentation,
    x: &[f64],
    data: &SweepSet,
    k: usize,
    t: &Terminal,
) -> (f64, f64, f64) {
    let torque =
        torque_misfit(model, x, data, k, t).map_or(0.0, |d| d / (data.sigma_t * data.scale_t[k]));
    (
        (data.current[k] - t.current) / (data.sigma_i * data.scale_i[k]),
        (data.power[k] - t.power) / (data.sigma_p * data.scale_p[k]),
        torque,
    )
}

/// Measured less modelled shaft torque at point `k`, N·m, from the
/// model's terminal values `t` (the air-gap power over the synchronous
/// speed, less `Tfw·(1 − s)`); `None` where the point has no torque.
pub fn torque_misfit(
    model: &ImAugmentation,
    x: &[f64],
    data: &SweepSet,
    k: usize,
    t: &Terminal,
) -> Option<f64> {
    let measured = data.torque[k]?;
    let predicted = t.rotor_power / data.sync_speed[k]
        - model.torque_shortfall(x) * (1.0 - data.inputs[k].slip);
    Some(measured - predicted)
}

struct Problem<'a> {
    model: ImAugmentation,
    data: &'a SweepSet,
    idx: &'a [usize],
}

impl Problem<'_> {
    fn residuals_of(&self, x: &[f64]) -> Option<DVector<f64>> {
        let n = self.idx.len();
        let mut r = DVector::zeros(self.rows());
        for (j, &k) in self.idx.iter().enumerate() {
            let (a, b, c) = weighted_residual(&self.model, x, self.data, k)?;
            r[j] = a;
            r[n + j] = b;
            if self.model.torque {
                r[2 * n + j] = c;
            }
        }
        Some(r)
    }
}

impl Residuals for Problem<'_> {
    fn rows(&self) -> usize {
        (2 + usize::from(self.model.torque)) * self.idx.len()
    }

    fn residuals_at(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
        self.residuals_of(x.as_slice())
    }

    fn jacobian_at(&self, x: &DVector<f64>) -> Option<DMatrix<f64>> {
        jacobian(self.model, self.data, self.idx, x.as_slice())
    }
}

/// Central-difference Jacobian of the weighted residuals.
fn jacobian(
    model: ImAugmentation,
    data: &SweepSet,
    idx: &[usize],
    x: &[f64],
) -> Option<DMatrix<f64>> {
    let p = Problem { model, data, idx };
    let mut jac = DMatrix::zeros(p.rows(), x.len());
    let mut xp = x.to_vec();
    for j in 0..x.len() {
        let h = 1e-6 * (1.0 + x[j].abs());
        xp[j] = x[j] + h;
        let up = p.residuals_of(&xp)?;
        xp[j] = x[j] - h;
        let dn = p.residuals_of(&xp)?;
        xp[j] = x[j];
        jac.set_column(j, &((up - dn) / (2.0 * h)));
    }
    jac.iter().all(|v| v.is_finite()).then_some(jac)
}

/// Fit `model` to the points `idx` from each of `starts`; the lowest cost
/// wins. `None` when no start gives a finite fit.
pub fn fit(
    model: ImAugmentation,
    data: &SweepSet,
    idx: &[usize],
    starts: &[Vec<f64>],
) -> Option<AugmentedFit> {
    let mut best: Option<AugmentedFit> = None;
    let mut evaluations = 0;
    for s in starts {
        if s.len() != model.len() {
            continue;
        }
        let problem = AtParams {
            problem: Problem { model, data, idx },
            x: DVector::from_column_slice(s),
        };
        if problem
            .residuals_of(s)
            .is_none_or(|r| !r.iter().all(|v| v.is_finite()))
        {
            continue;
        }
        // The statistical stopping rule: a candidate whose effect fits as
        // nothing stops where it starts to crawl.
        let lm = LevenbergMarquardt::new()
            .with_patience(100)
            .with_tol(1e-10)
            .with_ftol(negligible_ftol(problem.problem.rows()));
        let (p, report) = lm.minimize(problem);
        evaluations += report.number_of_evaluations;
        let x: Vec<f64> = p.x.iter().copied().collect();
        let Some(r) = p.residuals_of(&x) else {
            continue;
        };
        let cost = r.norm_squared();
        if cost.is_finite() && best.as_ref().is_none_or(|b| cost < b.cost) {
            best = Some(AugmentedFit {
                x,
                cost,
                evaluations: 0,
            });
        }
    }
    best.map(|b| AugmentedFit { evaluations, ..b })
}

/// Starting vectors of `model` from a fitted nominal vector: the nominal
/// part with each of the effect's starts, plus `extra` full vectors.
pub fn starts_from(
    model: &ImAugmentation,
    nominal: &[f64],
    data: &SweepSet,
    extra: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    let (v, i) = data.maxima();
    // The friction and the torque's shortfall, where the model carries
    // them, as the nominal fit has them.
    let nuisance = &nominal[4.min(nominal.len())..];
    let mut out: Vec<Vec<f64>> = model
        .effect_starts(nominal, v, i)
        .into_iter()
        .map(|e| {
            nominal[..4]
                .iter()
                .copied()
                .chain(e)
                .chain(nuisance.iter().copied())
                .collect()
        })
        .collect();
    out.extend(extra.iter().filter(|x| x.len() == model.len()).cloned());
    out
}

/// Held-out residuals of `model` over `folds`: each fold fitted on the
/// other points, its own points predicted. Per point: the weighted
/// (current, power) residual, and the fold fits.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOut {
    /// Weighted held-out residual per point (current, power).
    pub weighted: Vec<(f64, f64)>,
    /// Weighted held-out residual of the shaft torque per point (0 where
    /// the point has none).
    pub weighted_torque: Vec<f64>,
    /// Predicted phase current and power per point (held out).
    pub predicted: Vec<(f64, f64)>,
    /// The vector fitted for each fold.
    pub fold_x: Vec<Vec<f64>>,
}

/// Cross-validate `model`: `start` is the model's fit on all points (the
/// folds start from it and from the fold's nominal fit `fold_nominal`).
pub fn held_out(
    model: ImAugmentation,
    data: &SweepSet,
    folds: &[Vec<usize>],
    start: &[f64],
    fold_nominal: &[Vec<f64>],
) -> Option<HeldOut> {
    let n = data.len();
    let mut weighted = vec![(f64::NAN, f64::NAN); n];
    let mut weighted_torque = vec![0.0; n];
    let mut predicted = vec![(f64::NAN, f64::NAN); n];
    let mut fold_x = Vec::with_capacity(folds.len());
    for (f, out) in folds.iter().enumerate() {
        let train: Vec<usize> = (0..n).filter(|k| !out.contains(k)).collect();
        let mut starts = vec![start.to_vec()];
        if let Some(nom) = fold_nominal.get(f) {
            starts.extend(starts_from(&model, nom, data, &[]));
        }
        let fitted = fit(model, data, &train, &starts)?;
        for &k in out {
            let t = model.terminal(&fitted.x, &data.inputs[k])?;
            predicted[k] = (t.current, t.power);
            let (a, b, c) = weighted_of(&model, &fitted.x, data, k, &t);
            weighted[k] = (a, b);
            weighted_torque[k] = c;
        }
        fold_x.push(fitted.x);
    }
    Some(HeldOut {
        weighted,
        weighted_torque,
        predicted,
        fold_x,
    })
}

/// A fitted vector entry with its 95 % interval on the vector's scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    /// Value on the vector's scale.
    pub x: f64,
    /// Half-width of the 95 % interval on the vector's scale (`None`:
    /// not determined by the data).
    pub half_width: Option<f64>,
}

/// Linearised 95 % intervals of a fit on the points `idx`
/// (`σ² = cost/(m − q)`, Student t). An entry whose standard error on
/// the log scale exceeds [`PRACTICAL_LIMIT`] (or whose direction the data
/// do not see) gets no interval.
pub fn intervals(
    model: ImAugmentation,
    data: &SweepSet,
    idx: &[usize],
    fit: &AugmentedFit,
) -> Vec<Interval> {
    let q = fit.x.len();
    let none = || {
        fit.x
            .iter()
            .map(|&x| Interval {
                x,
                half_width: None,
            })
            .collect()
    };
    let Some(jac) = jacobian(model, data, idx, &fit.x) else {
        return none();
    };
    let m = jac.nrows();
    if m <= q {
        return none();
    }
    let s2 = fit.cost / (m - q) as f64;
    // The SVD panics on a NaN.
    if !jac.iter().all(|v| v.is_finite()) {
        return none();
    }
    // Bounded: an SVD that does not converge gives no intervals rather
    // than an endless loop.
    let Some(svd) = jac.try_svd(
        false,
        true,
        f64::EPSILON,
        crate::identify::SVD_MAX_ITERATIONS,
    ) else {
        return none();
    };
    let Some(v_t) = svd.v_t else {
        return none();
    };
    let sv = svd.singular_values;
    let smax = sv.max();
    let mut cov = DMatrix::zeros(q, q);
    let mut undetermined = vec![0.0; q];
    for k in 0..q {
        let vk = v_t.row(k).transpose();
        if sv[k] > smax * 1e-9 {
            cov += &vk * vk.transpose() * (s2 / (sv[k] * sv[k]));
        } else {
            for j in 0..q {
                undetermined[j] += vk[j] * vk[j];
            }
        }
    }
    let t = t975(m - q);
    let log_entries = log_mask(&model);
    (0..q)
        .map(|j| {
            let sd = cov[(j, j)].max(0.0).sqrt();
            let weak = undetermined[j] > 1e-4 || (log_entries[j] && sd > PRACTICAL_LIMIT);
            Interval {
                x: fit.x[j],
                half_width: (!weak && sd.is_finite()).then_some(t * sd),
            }
        })
        .collect()
}

/// The 97.5 % quantile of Student's t (at least one degree of freedom).
fn t975(dof: usize) -> f64 {
    crate::identify::stats::t975(dof.max(1))
}

/// Which entries of the vector are logarithms.
pub fn log_mask(model: &ImAugmentation) -> Vec<bool> {
    let mut m = vec![true; 4];
    m.extend(
        model
            .effect_params()
            .iter()
            .map(|p| p.transform == super::effects::Transform::Log),
    );
    if model.iron {
        m.push(true);
    }
    if model.friction {
        m.push(true);
    }
    if model.torque {
        m.push(true);
    }
    m
}
