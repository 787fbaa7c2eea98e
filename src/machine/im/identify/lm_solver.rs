//! The Levenberg–Marquardt solver of the slip-sweep fit ([`super::lm`]):
//! the algorithm of the `levenberg-marquardt` crate (version 0.15, itself
//! a port of MINPACK's `lmder`: a column-pivoted Householder QR of the
//! Jacobian, Moré's iteration for the trust-region parameter, the same
//! acceptance and stopping tests), operation for operation, so that a fit
//! reaches the same parameters as the crate's `minimize` to the last bit
//! (the tests below and in [`super::lm`] run both). A different order of
//! the same sums would not do: the double cage's fit moves along a family
//! of equivalent circuits, and a change in the last bit of one Jacobian
//! entry already ends it elsewhere on the family. What it saves, on a
//! problem of a few hundred residuals and at most [`MAX_COLS`]
//! parameters, is the crate's overhead around that arithmetic:
//!
//! - every buffer is allocated once per run, none per evaluation;
//! - the Jacobian is held row by row (`[f64; MAX_COLS]` per residual), so
//!   that one pass over the rows takes the dot products of every
//!   remaining column with a Householder vector (independent chains, each
//!   summed in the crate's order, interleaved instead of one after the
//!   other), and one more pass applies the reflection to them, two
//!   columns at a time and only to the columns it changes;
//! - `Qᵀ·r` is formed in those passes (the residuals reflected as one more
//!   column), not in a second sweep over the factor;
//! - a column norm the factorisation needs next (the next pivot's, or one
//!   to recompute) is summed during the reflection that precedes it, and
//!   MINPACK's `enorm` takes a plain sum of squares wherever every
//!   component is of ordinary size ([`Squares`]), which is what it does
//!   then too;
//! - the trust-region subproblem works on the `n × n` triangle only, and
//!   its Givens rotations run an anti-diagonal at a time
//!   ([`Factored::eliminate_diag`]).
//!
//! The crate's `minimize` is the reference: where this file and the crate
//! differ in anything but speed, the crate is right. Its loops index as
//! the crate's (and MINPACK's) do, so that the two read side by side.
#![allow(clippy::needless_range_loop)]

use levenberg_marquardt::TerminationReason;

/// Most parameters a problem may have (the largest circuit, the double
/// cage with iron loss, has eight elements).
pub(super) const MAX_COLS: usize = 8;

/// The residual answered outside the valid region, as
/// `crate::identify::least_squares` answers it to the crate: large and
/// finite, so that the trial step is rejected and the trust region
/// shrinks.
pub(super) use crate::identify::least_squares::OUTSIDE;

/// A row of the Jacobian: one residual's derivatives, in its first `n`
/// columns.
pub(super) type Row = [f64; MAX_COLS];

/// A least-squares problem as the solver sees it.
pub(super) trait Problem {
    /// Number of residuals.
    fn rows(&self) -> usize;
    /// The residuals at `x` into `out` (`rows()` long); `false` outside
    /// the valid region (then `out` is not used).
    fn residuals(&mut self, x: &[f64], out: &mut [f64]) -> bool;
    /// The Jacobian at `x` into the first `x.len()` columns of `out`
    /// (`rows()` rows; the solver never reads the others); `false` where
    /// it is not defined or not finite.
    fn jacobian(&mut self, x: &[f64], out: &mut [Row]) -> bool;
}

/// The crate's settings that the fits use: `LevenbergMarquardt::new()`
/// with `with_tol(tol)` and `with_patience(patience)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Settings {
    ftol: f64,
    xtol: f64,
    gtol: f64,
    stepbound: f64,
    patience: usize,
}

impl Settings {
    /// `ftol = xtol = tol`, `gtol = 0`, the step bound 100, and at most
    /// `patience·(n + 1)` residual evaluations.
    pub(super) fn new(tol: f64, patience: usize) -> Settings {
        assert!(tol > 0.0, "tol must > 0");
        assert!(patience > 0, "patience must be > 0");
        Settings {
            ftol: tol,
            xtol: tol,
            gtol: 0.0,
            stepbound: 100.0,
            patience,
        }
    }

    /// The same with MINPACK's `factor`, the first trust region's radius
    /// over `‖D·x‖`, at `factor` instead of 100.
    pub(super) fn with_step_bound(self, factor: f64) -> Settings {
        assert!(factor > 0.0, "the step bound must be > 0");
        Settings {
            stepbound: factor,
            ..self
        }
    }
}

/// How a run ended.
#[derive(Debug, PartialEq)]
pub(super) struct Outcome {
    /// The parameters the problem was left at (the crate's
    /// `problem.params()` after `minimize`).
    pub x: Vec<f64>,
    /// Why the run stopped.
    pub termination: TerminationReason,
    /// Residual evaluations, the first included.
    pub evaluations: usize,
    /// The residuals at `x` where the run knows them (it does unless it
    /// stopped on a numerical failure right after a rejected step).
    pub residuals: Option<Vec<f64>>,
}

/// `eps` of the crate's tests (`f64::EPSILON`).
const EPSMCH: f64 = f64::EPSILON;
/// The crate's smallest positive magnitude (`f64::MIN_POSITIVE`).
const DWARF: f64 = f64::MIN_POSITIVE;

/// The Euclidean norm as MINPACK's `enorm` (and the crate's) computes it:
/// sums of squares for small, intermediate and large components kept
/// apart, so that it neither overflows nor underflows; `NaN` if any
/// component is.
pub(super) fn enorm(v: impl ExactSizeIterator<Item = f64>) -> f64 {
    let agiant = f64::MAX.sqrt() / v.len() as f64;
    let rdwarf = DWARF.sqrt();
    let (mut s1, mut s2, mut s3) = (0.0f64, 0.0f64, 0.0f64);
    let (mut x1max, mut x3max) = (0.0f64, 0.0f64);
    for xi in v {
        let xabs = xi.abs();
        if xabs.is_nan() {
            return xabs;
        }
        if xabs >= agiant || xabs <= rdwarf {
            if xabs > rdwarf {
                // Large components.
                if xabs > x1max {
                    s1 = 1.0 + s1 * (x1max / xabs).powi(2);
                    x1max = xabs;
                } else {
                    s1 += (xabs / x1max).powi(2);
                }
            } else if xabs > x3max {
                // Small components.
                s3 = 1.0 + s3 * (x3max / xabs).powi(2);
                x3max = xabs;
            } else if xabs != 0.0 {
                s3 += (xabs / x3max).powi(2);
            }
        } else {
            s2 += xabs * xabs;
        }
    }
    if s1 != 0.0 {
        x1max * (s1 + (s2 / x1max) / x1max).sqrt()
    } else if s2 != 0.0 {
        (if s2 >= x3max {
            s2 * (1.0 + (x3max / s2) * (x3max * s3))
        } else {
            x3max * ((s2 / x3max) + (x3max * s3))
        })
        .sqrt()
    } else {
        x3max * s3.sqrt()
    }
}

/// [`enorm`] of a slice (by [`Squares`] where it can).
fn enorm_of(v: &[f64]) -> f64 {
    let mut squares = Squares::NEW;
    for &x in v {
        squares.add(x);
    }
    squares
        .norm(v.len())
        .unwrap_or_else(|| enorm(v.iter().copied()))
}

/// [`enorm`] of column `col` of `rows` (by [`Squares`] where it can).
fn column_enorm(rows: &[Row], col: usize) -> f64 {
    let mut squares = Squares::NEW;
    for row in rows {
        squares.add(row[col]);
    }
    squares
        .norm(rows.len())
        .unwrap_or_else(|| enorm(rows.iter().map(|r| r[col])))
}

/// The factored linear least-squares problem of one iteration: `J·P =
/// Q·R` and `Qᵀ·r`, with the crate's working vectors
/// (`LinearLeastSquaresDiagonalProblem`).
struct Factored {
    n: usize,
    /// `min(m, n)`: the columns the factorisation reduced.
    reduced: usize,
    /// `R` (row, column) in the upper triangle and on the diagonal; the
    /// strict lower triangle holds `L` after [`Factored::eliminate_diag`].
    upper_r: [[f64; MAX_COLS]; MAX_COLS],
    qt_b: [f64; MAX_COLS],
    l_diag: [f64; MAX_COLS],
    permutation: [usize; MAX_COLS],
    /// Norms of the Jacobian's columns, in their original order.
    column_norms: [f64; MAX_COLS],
    work: [f64; MAX_COLS],
}

impl Factored {
    fn new(n: usize) -> Factored {
        Factored {
            n,
            reduced: n,
            upper_r: [[0.0; MAX_COLS]; MAX_COLS],
            qt_b: [0.0; MAX_COLS],
            l_diag: [0.0; MAX_COLS],
            permutation: [0; MAX_COLS],
            column_norms: [0.0; MAX_COLS],
            work: [0.0; MAX_COLS],
        }
    }

    /// Factor `a` (`m` rows, its first `n` columns) and reflect `b` with
    /// it (`PivotedQR::new` followed by
    /// `into_least_squares_diagonal_problem`). `a` and `b` are
    /// overwritten; `w` (`m` long) holds each reflection vector in turn.
    fn factor(&mut self, a: &mut [Row], b: &mut [f64], w: &mut [f64]) {
        let n = self.n;
        let m = a.len();
        let k_end = m.min(n);
        self.column_norms = column_enorms(a, n);
        let mut r_diag = self.column_norms;
        let mut work = self.column_norms;
        for (j, p) in self.permutation[..n].iter_mut().enumerate() {
            *p = j;
        }
        for j in 0..n {
            self.qt_b[j] = if j < m { b[j] } else { 0.0 };
        }
        // The norm of the next pivot column below the rows reduced so
        // far, where the previous reflection computed it on its way.
        let mut next: Option<(usize, f64)> = None;
        for j in 0..k_end {
            let kmax = pivot(&r_diag, j, n);
            let known = if j == 0 {
                Some(self.column_norms[kmax])
            } else {
                next.filter(|&(k, _)| k == kmax).map(|(_, norm)| norm)
            };
            if kmax != j {
                for row in a.iter_mut() {
                    row.swap(j, kmax);
                }
                self.permutation.swap(j, kmax);
                r_diag[kmax] = r_diag[j];
                work[kmax] = work[j];
            }
            let lower = &mut a[j..];
            let mut aj_norm = known.unwrap_or_else(|| column_enorm(lower, j));
            next = None;
            if aj_norm == 0.0 {
                r_diag[j] = 0.0;
                self.qt_b[j] = b[j];
                continue;
            }
            if lower[0][j].is_sign_negative() {
                aj_norm = -aj_norm;
            }
            r_diag[j] = -aj_norm;
            let w = &mut w[..lower.len()];
            let (dots, b_dot) = reflection(lower, &b[j..], j, aj_norm, w);
            // c ← c − (c·w/w₀)·w for the columns right of j and for b;
            // the columns left of j and j itself (no longer read below
            // row j) and the zero columns past n get a coefficient 0.
            let mut coef = [0.0; MAX_COLS];
            for k in j + 1..n {
                coef[k] = -(dots[k] / w[0]);
            }
            let b_coef = -b_dot / w[0];
            reflect_rows(
                &mut lower[..1],
                &mut b[j..=j],
                &w[..1],
                j,
                &coef,
                b_coef,
                Norms::None,
            );
            self.qt_b[j] = b[j];
            // Update the norms of the remaining columns (LAPACK Working
            // Note 176); one that lost too many digits is recomputed once
            // the reflection is done.
            let mut recompute = [false; MAX_COLS];
            for k in j + 1..n {
                if r_diag[k] == 0.0 {
                    continue;
                }
                let temp = (lower[0][k] / r_diag[k]).powi(2);
                r_diag[k] *= (1.0 - temp).max(0.0).sqrt();
                recompute[k] = 0.05 * (r_diag[k] / work[k]).powi(2) <= EPSMCH;
            }
            // The rest of the reflection takes on its way the norms to
            // recompute, or, without any, the norm of the next pivot
            // (known now).
            let norms = if recompute.contains(&true) {
                Norms::All
            } else if j + 1 < k_end {
                Norms::Column(pivot(&r_diag, j + 1, n))
            } else {
                Norms::None
            };
            let found = reflect_rows(
                &mut lower[1..],
                &mut b[j + 1..],
                &w[1..],
                j,
                &coef,
                b_coef,
                norms,
            );
            for k in j + 1..n {
                if recompute[k] {
                    r_diag[k] = found[k].unwrap_or_else(|| column_enorm(&lower[1..], k));
                    work[k] = r_diag[k];
                }
            }
            next = (j + 1 < k_end)
                .then(|| pivot(&r_diag, j + 1, n))
                .and_then(|k| found[k].map(|norm| (k, norm)));
        }
        for (i, row) in self.upper_r[..n].iter_mut().enumerate() {
            *row = if i < m { a[i] } else { [0.0; MAX_COLS] };
        }
        for j in 0..k_end {
            self.upper_r[j][j] = r_diag[j];
        }
        self.reduced = k_end;
        self.l_diag = r_diag;
        self.work = work;
    }

    /// The largest `|(Jᵀ·r)_j|/(‖J_j‖·‖r‖)` (`max_a_t_b_scaled`); `None` if
    /// it is not a number.
    fn max_a_t_b_scaled(&mut self, b_norm: f64) -> Option<f64> {
        let n = self.n;
        for j in 0..n {
            self.work[j] = self.qt_b[j] / b_norm;
        }
        let mut max = 0.0f64;
        for j in 0..n {
            let scale = self.column_norms[self.permutation[j]];
            if scale == 0.0 {
                continue;
            }
            let mut sum = 0.0;
            for i in 0..=j {
                sum += self.upper_r[i][j] * self.work[i];
            }
            let temp = (sum / scale).abs();
            if temp.is_nan() {
                return None;
            }
            max = max.max(temp);
        }
        Some(max)
    }

    /// `‖J·x‖` from the factor (`a_x_norm`).
    fn a_x_norm(&mut self, x: &[f64; MAX_COLS]) -> f64 {
        let n = self.n;
        self.work = [0.0; MAX_COLS];
        for i in 0..n {
            let xi = x[self.permutation[i]];
            for k in 0..=i {
                self.work[k] += xi * self.upper_r[k][i];
            }
        }
        enorm_of(&self.work[..n])
    }

    fn is_non_singular(&self) -> bool {
        self.reduced == self.n && (0..self.n).all(|j| self.upper_r[j][j] != 0.0)
    }

    /// The Gauss–Newton step (`solve_with_zero_diagonal`); the factor to
    /// solve with afterwards is `R` ([`Triangle::Upper`]).
    fn solve_with_zero_diagonal(&mut self, x: &mut [f64; MAX_COLS]) {
        let n = self.n;
        self.work = self.qt_b;
        let rank = (0..self.reduced)
            .position(|i| self.upper_r[i][i] == 0.0)
            .unwrap_or(self.reduced);
        for w in &mut self.work[rank..n] {
            *w = 0.0;
        }
        // nalgebra's `solve_upper_triangular_mut` on the leading block.
        for i in (0..rank).rev() {
            let coeff = self.work[i] / self.upper_r[i][i];
            self.work[i] = coeff;
            for k in 0..i {
                self.work[k] += -coeff * self.upper_r[k][i];
            }
        }
        *x = [0.0; MAX_COLS];
        for j in 0..n {
            x[self.permutation[j]] = self.work[j];
        }
    }

    /// The step for the diagonal `diag` (`solve_with_diagonal`); the
    /// factor to solve with afterwards is `L` ([`Triangle::Lower`]).
    fn solve_with_diagonal(&mut self, diag: &[f64; MAX_COLS], x: &mut [f64; MAX_COLS]) {
        let n = self.n;
        let mut rhs = self.qt_b;
        self.eliminate_diag(diag, &mut rhs);
        let rank = self.l_diag[..n].iter().position(|&d| d == 0.0).unwrap_or(n);
        for r in &mut rhs[rank..n] {
            *r = 0.0;
        }
        // Solve Lᵀ·x = rhs.
        for j in (0..rank).rev() {
            let mut sum = 0.0;
            for i in j + 1..rank {
                sum += self.upper_r[i][j] * rhs[i];
            }
            rhs[j] = (rhs[j] - sum) / self.l_diag[j];
        }
        for j in 0..n {
            x[self.permutation[j]] = rhs[j];
        }
        self.work = rhs;
    }

    /// Givens rotations that eliminate `diag` from `[R; D]`, leaving `L`
    /// in the strict lower triangle and `l_diag`, `R` restored
    /// (`eliminate_diag`).
    ///
    /// The crate rotates row `j` of `D` into `R` column by column, `k =
    /// j..n`, one row after the other. Rotation `(j, k)` depends only on
    /// `(j, k − 1)` (the row being rotated) and `(j − 1, k)` (column `k`
    /// of `R` and `rhs[k]`), so the rotations of one anti-diagonal
    /// `j + k = t` are independent: done together, in `2n − 1` rounds,
    /// the processor overlaps their long chains (a division, a square
    /// root and a division each); every rotation is the crate's, with
    /// the same operands.
    fn eliminate_diag(&mut self, diag: &[f64; MAX_COLS], rhs: &mut [f64; MAX_COLS]) {
        let n = self.n;
        let r = &mut self.upper_r;
        for j in 0..n {
            for i in j + 1..n {
                r[i][j] = r[j][i];
            }
            self.work[j] = r[j][j];
        }
        // Row j of D as it is rotated (the crate's l_diag while it
        // works on j), and its share of Qᵀb.
        let mut rows = [[0.0; MAX_COLS]; MAX_COLS];
        let mut qtbp = [0.0; MAX_COLS];
        for t in 0..(2 * n).saturating_sub(1) {
            for j in (t + 1).saturating_sub(n)..=t / 2 {
                let k = t - j;
                if k == j {
                    rows[j][j] = diag[self.permutation[j]];
                }
                if rows[j][k] != 0.0 {
                    givens(r, &mut rows[j], &mut qtbp[j], rhs, k, n);
                }
                if k == j {
                    self.l_diag[j] = r[j][j];
                    r[j][j] = self.work[j];
                }
            }
        }
    }

    /// Solve `Rᵀ·R·x = rhs` or `Lᵀ·L`… as the crate's `CholeskyFactor::solve`
    /// does: the permuted right-hand side through the triangle.
    fn solve(&mut self, triangle: Triangle, rhs: &mut [f64; MAX_COLS]) {
        let n = self.n;
        for i in 0..n {
            self.work[i] = rhs[self.permutation[i]];
        }
        match triangle {
            Triangle::Lower => {
                for j in 0..n {
                    self.work[j] /= self.l_diag[j];
                    let x = self.work[j];
                    for i in j + 1..n {
                        self.work[i] += -x * self.upper_r[i][j];
                    }
                }
            }
            Triangle::Upper => {
                for j in 0..n {
                    let mut sum = 0.0;
                    for i in 0..j {
                        sum += self.work[i] * self.upper_r[i][j];
                    }
                    self.work[j] = (self.work[j] - sum) / self.upper_r[j][j];
                }
            }
        }
        std::mem::swap(&mut self.work, rhs);
    }

    /// `(triangle)·Qᵀb` in the permuted order (`mul_qt_b`).
    fn mul_qt_b(&self, triangle: Triangle, out: &mut [f64; MAX_COLS]) {
        let n = self.n;
        *out = [0.0; MAX_COLS];
        match triangle {
            Triangle::Lower => {
                for i in 0..n {
                    for k in i + 1..n {
                        out[k] += self.qt_b[i] * self.upper_r[k][i];
                    }
                    out[i] += self.qt_b[i] * self.l_diag[i];
                }
            }
            Triangle::Upper => {
                for i in 0..n {
                    let mut sum = 0.0;
                    for k in 0..=i {
                        sum += self.qt_b[k] * self.upper_r[k][i];
                    }
                    out[i] = sum;
                }
            }
        }
    }
}

/// The crate's Givens rotation of `row` (rotated into `R` from column
/// `k` on) against column `k` of `r`: `r[k][k]`, `rhs[k]` and the
/// row's share `qtbp` of `Qᵀb` rotated, then the rest of column `k` of
/// `L` (below the diagonal of `r`) and of the row.
#[inline(always)]
fn givens(
    r: &mut [[f64; MAX_COLS]; MAX_COLS],
    row: &mut [f64; MAX_COLS],
    qtbp: &mut f64,
    rhs: &mut [f64; MAX_COLS],
    k: usize,
    n: usize,
) {
    let r_kk = r[k][k];
    let (sin, cos) = if r_kk.abs() < row[k].abs() {
        let cot = r_kk / row[k];
        let sin = 0.5 / (0.25 + 0.25 * (cot * cot)).sqrt();
        (sin, sin * cot)
    } else {
        let tan = row[k] / r_kk;
        let cos = 0.5 / (0.25 + 0.25 * (tan * tan)).sqrt();
        (cos * tan, cos)
    };
    r[k][k] = cos * r_kk + sin * row[k];
    let temp = cos * rhs[k] + sin * *qtbp;
    *qtbp = -sin * rhs[k] + cos * *qtbp;
    rhs[k] = temp;
    for i in k + 1..n {
        let r_ik = r[i][k];
        let temp = cos * r_ik + sin * row[i];
        row[i] = -sin * r_ik + cos * row[i];
        r[i][k] = temp;
    }
}

/// Which factor the crate's `CholeskyFactor` holds: `R` after
/// `solve_with_zero_diagonal`, `L` after `solve_with_diagonal`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Triangle {
    Upper,
    Lower,
}

/// The largest remaining column norm from column `j` on (the first of
/// equals), as the crate pivots.
fn pivot(r_diag: &[f64; MAX_COLS], j: usize, n: usize) -> usize {
    let mut kmax = j;
    for k in j + 1..n {
        if r_diag[k] > r_diag[kmax] {
            kmax = k;
        }
    }
    kmax
}

/// The first column a reflection of column `j` changes, rounded down to
/// a pair of columns: the reflections below work on columns
/// `first_pair(j)..` only, two at a time, and leave the columns left of
/// them alone (those below row `j` are no longer read).
fn first_pair(j: usize) -> usize {
    (j + 1) & !1
}

/// The Householder vector of column `j` of `rows` (rows `j..` of the
/// matrix) into `w`: the column over its signed norm `aj_norm`, plus 1 in
/// its first element. Returns the dot products of the columns right of
/// `j` and of `b` with it, each summed from the first row on as the
/// crate sums them one column at a time, here all in one pass.
fn reflection(rows: &[Row], b: &[f64], j: usize, aj_norm: f64, w: &mut [f64]) -> (Row, f64) {
    match first_pair(j) {
        0 => reflection_from::<0>(rows, b, j, aj_norm, w),
        2 => reflection_from::<2>(rows, b, j, aj_norm, w),
        4 => reflection_from::<4>(rows, b, j, aj_norm, w),
        6 => reflection_from::<6>(rows, b, j, aj_norm, w),
        _ => reflection_from::<MAX_COLS>(rows, b, j, aj_norm, w),
    }
}

/// [`reflection`] on the columns `F..`. The divisions go two rows at a
/// time (one vector division), the sums one row after the other.
fn reflection_from<const F: usize>(
    rows: &[Row],
    b: &[f64],
    j: usize,
    aj_norm: f64,
    w: &mut [f64],
) -> (Row, f64) {
    let mut dots = [0.0; MAX_COLS];
    let mut b_dot = 0.0;
    let mut add = |row: &Row, bi: f64, wi: f64| {
        for k in F..MAX_COLS {
            dots[k] += row[k] * wi;
        }
        b_dot += bi * wi;
    };
    w[0] = rows[0][j] / aj_norm + 1.0;
    add(&rows[0], b[0], w[0]);
    let (rows, b, w) = (&rows[1..], &b[1..], &mut w[1..]);
    let pairs = rows
        .chunks_exact(2)
        .zip(b.chunks_exact(2))
        .zip(w.chunks_exact_mut(2));
    for ((r, b), w) in pairs {
        let pair = [r[0][j] / aj_norm, r[1][j] / aj_norm];
        w.copy_from_slice(&pair);
        add(&r[0], b[0], pair[0]);
        add(&r[1], b[1], pair[1]);
    }
    if rows.len() % 2 == 1 {
        let last = rows.len() - 1;
        w[last] = rows[last][j] / aj_norm;
        add(&rows[last], b[last], w[last]);
    }
    (dots, b_dot)
}

/// `row ← coef·w + row` on the columns `F..` (the crate's `axpy`).
#[inline(always)]
fn reflect_row<const F: usize>(row: &mut Row, w: f64, coef: &Row) {
    for k in F..MAX_COLS {
        row[k] += coef[k] * w;
    }
}

/// Which column norms [`reflect_rows`] takes on its way, over the rows
/// it reflects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Norms {
    None,
    Column(usize),
    /// Every column it changes.
    All,
}

/// `row ← coef·w + row` for every row from column `first_pair(j)` on,
/// and `b ← b_coef·w + b`; also the [`enorm`] of the columns `norms`
/// names after the reflection, where [`Squares::norm`] has it.
fn reflect_rows(
    rows: &mut [Row],
    b: &mut [f64],
    w: &[f64],
    j: usize,
    coef: &Row,
    b_coef: f64,
    norms: Norms,
) -> [Option<f64>; MAX_COLS] {
    match first_pair(j) {
        0 => reflect_rows_from::<0>(rows, b, w, coef, b_coef, norms),
        2 => reflect_rows_from::<2>(rows, b, w, coef, b_coef, norms),
        4 => reflect_rows_from::<4>(rows, b, w, coef, b_coef, norms),
        6 => reflect_rows_from::<6>(rows, b, w, coef, b_coef, norms),
        _ => reflect_rows_from::<MAX_COLS>(rows, b, w, coef, b_coef, norms),
    }
}

/// [`reflect_rows`] on the columns `F..`.
fn reflect_rows_from<const F: usize>(
    rows: &mut [Row],
    b: &mut [f64],
    w: &[f64],
    coef: &Row,
    b_coef: f64,
    norms: Norms,
) -> [Option<f64>; MAX_COLS] {
    let len = rows.len();
    let rows_b_w = rows.iter_mut().zip(b.iter_mut()).zip(w);
    let mut found = [None; MAX_COLS];
    match norms {
        Norms::None => {
            for ((row, bi), &wi) in rows_b_w {
                reflect_row::<F>(row, wi, coef);
                *bi += b_coef * wi;
            }
        }
        Norms::Column(k) => {
            let mut squares = Squares::NEW;
            for ((row, bi), &wi) in rows_b_w {
                reflect_row::<F>(row, wi, coef);
                *bi += b_coef * wi;
                (squares.sum, squares.smallest) =
                    Squares::step(squares.sum, squares.smallest, row[k]);
            }
            found[k] = squares.norm(len);
        }
        Norms::All => {
            // Each field a row of its own, so that the pass vectorises.
            let mut sum = [0.0; MAX_COLS];
            let mut smallest = [f64::INFINITY; MAX_COLS];
            for ((row, bi), &wi) in rows_b_w {
                reflect_row::<F>(row, wi, coef);
                *bi += b_coef * wi;
                for k in F..MAX_COLS {
                    (sum[k], smallest[k]) =
                        Squares::step_skipping_zeros(sum[k], smallest[k], row[k]);
                }
            }
            for k in F..MAX_COLS {
                found[k] = Squares {
                    sum: sum[k],
                    smallest: smallest[k],
                }
                .norm(len);
            }
        }
    }
    found
}

/// The sum of squares of a vector as [`enorm`] forms it for components
/// of intermediate size, with what it takes to tell whether every
/// component was of that size or zero (which `enorm` skips, and which
/// adds nothing here): then `enorm` is the square root of that sum, to
/// the bit.
#[derive(Debug, Clone, Copy)]
struct Squares {
    sum: f64,
    /// The smallest `|x|` ([`Squares::step`]), or the smallest non-zero
    /// one ([`Squares::step_skipping_zeros`]).
    smallest: f64,
}

impl Squares {
    const NEW: Squares = Squares {
        sum: 0.0,
        smallest: f64::INFINITY,
    };

    /// Add `x` ([`Squares::step_skipping_zeros`]).
    #[inline(always)]
    fn add(&mut self, x: f64) {
        (self.sum, self.smallest) = Squares::step_skipping_zeros(self.sum, self.smallest, x);
    }

    /// `sum` and `smallest` with `x` added, without branches (so that a
    /// loop of these vectorises). A zero counts as a smallest component
    /// too small for the plain sum: the cheapest step, for vectors that
    /// seldom hold a zero.
    #[inline(always)]
    fn step(sum: f64, smallest: f64, x: f64) -> (f64, f64) {
        let a = x.abs();
        (sum + a * a, if a < smallest { a } else { smallest })
    }

    /// [`Squares::step`], a zero skipped: for vectors that may hold zeros
    /// (the columns that the factorisation has nearly eliminated).
    #[inline(always)]
    fn step_skipping_zeros(sum: f64, smallest: f64, x: f64) -> (f64, f64) {
        let a = x.abs();
        let non_zero = if a == 0.0 { f64::INFINITY } else { a };
        (
            sum + a * a,
            if non_zero < smallest {
                non_zero
            } else {
                smallest
            },
        )
    }

    /// [`enorm`] of the `len` components added, unless one may have been
    /// too large or too small (but not zero) for `enorm`'s plain sum, or
    /// not a number: then `None`. A component of `|x| ≥ agiant` would make the
    /// sum at least `agiant²` (rounding is monotonic), so a smaller sum
    /// rules it out.
    fn norm(&self, len: usize) -> Option<f64> {
        let agiant = f64::MAX.sqrt() / len as f64;
        // With s1 = s3 = x3max = 0, enorm's result is sqrt(s2·(1 + 0)).
        (self.sum < agiant * agiant && self.smallest > DWARF.sqrt()).then(|| {
            if self.sum == 0.0 {
                0.0
            } else {
                self.sum.sqrt()
            }
        })
    }
}

/// [`enorm`] of each of the first `n` columns of `rows`, in one pass
/// where every component is of intermediate size, else column by column.
fn column_enorms(rows: &[Row], n: usize) -> Row {
    // Each field a row of its own, so that the pass vectorises.
    let mut sum = [0.0; MAX_COLS];
    let mut smallest = [f64::INFINITY; MAX_COLS];
    for row in rows {
        for k in 0..MAX_COLS {
            (sum[k], smallest[k]) = Squares::step(sum[k], smallest[k], row[k]);
        }
    }
    let mut norms = [0.0; MAX_COLS];
    for k in 0..n {
        let s = Squares {
            sum: sum[k],
            smallest: smallest[k],
        };
        norms[k] = s.norm(rows.len()).unwrap_or_else(|| column_enorm(rows, k));
    }
    norms
}

/// The trust-region parameter `λ` and the step for the radius `delta`
/// (`determine_lambda_and_parameter_update`): the step, `λ` and `‖D·p‖`.
fn lambda_and_step(
    lls: &mut Factored,
    diag: &[f64; MAX_COLS],
    delta: f64,
    initial_lambda: f64,
    p: &mut [f64; MAX_COLS],
) -> (f64, f64) {
    const P1: f64 = 0.1;
    let n = lls.n;
    let scaled = |p: &[f64; MAX_COLS]| {
        let mut d = [0.0; MAX_COLS];
        for j in 0..n {
            d[j] = p[j] * diag[j];
        }
        d
    };
    let is_non_singular = lls.is_non_singular();
    lls.solve_with_zero_diagonal(p);
    let mut diag_p = scaled(p);
    let mut diag_p_norm = enorm_of(&diag_p[..n]);
    let mut fp = diag_p_norm - delta;
    if fp <= delta * P1 {
        // A feasible step with λ = 0.
        return (0.0, diag_p_norm);
    }
    // A λ > 0 with ‖D·p‖ = delta, by Newton's iteration.
    let newton = |lls: &mut Factored,
                  triangle: Triangle,
                  p: &mut [f64; MAX_COLS],
                  diag_p: &[f64; MAX_COLS],
                  diag_p_norm: f64,
                  fp: f64| {
        for j in 0..n {
            p[j] = diag_p[j] / diag_p_norm;
            p[j] *= diag[j];
        }
        lls.solve(triangle, p);
        let norm = enorm_of(&p[..n]);
        ((fp / delta) / norm) / norm
    };
    let mut lambda_lower = if is_non_singular {
        newton(lls, Triangle::Upper, p, &diag_p, diag_p_norm, fp)
    } else {
        0.0
    };
    // The upper bound ‖(J·D⁻¹)ᵀ·r‖/delta.
    lls.mul_qt_b(Triangle::Upper, p);
    for j in 0..n {
        p[j] /= diag[lls.permutation[j]];
    }
    let gnorm = enorm_of(&p[..n]);
    let mut lambda_upper = {
        let upper = gnorm / delta;
        if upper == 0.0 {
            DWARF / delta.min(P1)
        } else {
            upper
        }
    };
    let mut lambda = initial_lambda.max(lambda_lower).min(lambda_upper);
    if lambda == 0.0 {
        lambda = gnorm / diag_p_norm;
    }
    for iteration in 1.. {
        if lambda == 0.0 {
            lambda = DWARF.max(lambda_upper * 0.001);
        }
        let l_sqrt = lambda.sqrt();
        for j in 0..n {
            diag_p[j] = l_sqrt * diag[j];
        }
        lls.solve_with_diagonal(&diag_p, p);
        diag_p = scaled(p);
        diag_p_norm = enorm_of(&diag_p[..n]);
        if iteration == 10 {
            break;
        }
        let fp_old = fp;
        fp = diag_p_norm - delta;
        if fp.abs() <= delta * P1
            || (lambda_lower == 0.0 && fp <= fp_old && fp_old.is_sign_negative())
        {
            break;
        }
        let correction = newton(lls, Triangle::Lower, p, &diag_p, diag_p_norm, fp);
        if fp.is_sign_positive() {
            lambda_lower = lambda_lower.max(lambda);
        } else {
            lambda_upper = lambda_upper.min(lambda);
        }
        lambda = lambda_lower.max(lambda + correction);
    }
    (lambda, diag_p_norm)
}

/// The residuals at `x` into `out`, [`OUTSIDE`] where the problem has none
/// or they are not finite (what `AtParams::residuals` answers the crate),
/// and their [`enorm`].
fn evaluate<P: Problem>(problem: &mut P, x: &[f64], out: &mut [f64]) -> f64 {
    if problem.residuals(x, out) {
        let mut squares = Squares::NEW;
        for &r in out.iter() {
            (squares.sum, squares.smallest) = Squares::step(squares.sum, squares.smallest, r);
        }
        // A finite sum of squares has finite terms.
        if squares.sum.is_finite() || out.iter().all(|v| v.is_finite()) {
            return squares
                .norm(out.len())
                .unwrap_or_else(|| enorm(out.iter().copied()));
        }
    }
    out.fill(OUTSIDE);
    enorm_of(out)
}

/// The state of one run (the crate's `LM`).
struct Run<'s, P> {
    settings: &'s Settings,
    problem: P,
    n: usize,
    x: [f64; MAX_COLS],
    /// The trial point.
    tmp: [f64; MAX_COLS],
    /// Where the problem was last evaluated or reset to (the crate's
    /// `target.params()`).
    at: [f64; MAX_COLS],
    /// Whether `at` is `x`.
    at_x: bool,
    /// The residuals at `x`.
    residuals: Vec<f64>,
    trial: Vec<f64>,
    evaluations: usize,
    delta: f64,
    lambda: f64,
    xnorm: f64,
    gnorm: f64,
    residuals_norm: f64,
    diag: [f64; MAX_COLS],
    first_trust_region_iteration: bool,
    first_update: bool,
    max_fev: usize,
}

/// What one trust-region iteration decided.
enum Step {
    /// The step was taken: factor the new Jacobian.
    Taken,
    /// The step was rejected: try a shorter one.
    Rejected,
}

impl<P: Problem> Run<'_, P> {
    /// `update_diag`.
    fn update_diag(&mut self, lls: &mut Factored) -> Result<(), TerminationReason> {
        let n = self.n;
        self.gnorm = lls
            .max_a_t_b_scaled(self.residuals_norm)
            .ok_or(TerminationReason::Numerical("jacobian"))?;
        if self.gnorm <= self.settings.gtol {
            return Err(TerminationReason::Orthogonal);
        }
        if self.first_update {
            for j in 0..n {
                let norm = lls.column_norms[j];
                self.diag[j] = if norm == 0.0 { 1.0 } else { norm };
            }
            self.xnorm = self.scaled_x_norm();
            if !self.xnorm.is_finite() {
                return Err(TerminationReason::Numerical("subproblem x"));
            }
            self.delta = if self.xnorm == 0.0 {
                self.settings.stepbound
            } else {
                self.settings.stepbound * self.xnorm
            };
            self.first_update = false;
        } else {
            for j in 0..n {
                self.diag[j] = lls.column_norms[j].max(self.diag[j]);
            }
        }
        Ok(())
    }

    /// `‖D·x‖`.
    fn scaled_x_norm(&mut self) -> f64 {
        for j in 0..self.n {
            self.tmp[j] = self.diag[j] * self.x[j];
        }
        enorm_of(&self.tmp[..self.n])
    }

    /// `trust_region_iteration`.
    fn trust_region_iteration(
        &mut self,
        lls: &mut Factored,
        step: &[f64; MAX_COLS],
        lambda: f64,
        pnorm: f64,
    ) -> Result<Step, TerminationReason> {
        const P1: f64 = 0.1;
        const P0001: f64 = 1.0e-4;
        let n = self.n;
        self.lambda = lambda;
        if !pnorm.is_finite() {
            return Err(TerminationReason::Numerical("subproblem ||Dp||"));
        }
        let temp1 = (lls.a_x_norm(step) / self.residuals_norm).powi(2);
        if !temp1.is_finite() {
            return Err(TerminationReason::Numerical("trust-region reduction"));
        }
        let temp2 = ((self.lambda.sqrt() * pnorm) / self.residuals_norm).powi(2);
        if !temp2.is_finite() {
            return Err(TerminationReason::Numerical("trust-region reduction"));
        }
        let predicted_reduction = temp1 + temp2 / 0.5;
        let dir_der = -(temp1 + temp2);
        if self.first_trust_region_iteration && pnorm < self.delta {
            self.delta = pnorm;
        }
        self.first_trust_region_iteration = false;

        for j in 0..n {
            self.tmp[j] = -step[j] + self.x[j];
        }
        self.at = self.tmp;
        self.at_x = false;
        self.evaluations += 1;
        let new_residuals_norm = evaluate(&mut self.problem, &self.tmp[..n], &mut self.trial);

        let actual_reduction = if new_residuals_norm * P1 < self.residuals_norm {
            1.0 - (new_residuals_norm / self.residuals_norm).powi(2)
        } else {
            -1.0
        };
        let ratio = if predicted_reduction == 0.0 {
            0.0
        } else {
            actual_reduction / predicted_reduction
        };
        if ratio <= 0.25 {
            let mut temp = if actual_reduction.is_sign_positive() {
                0.5
            } else {
                0.5 * dir_der / (dir_der + 0.5 * actual_reduction)
            };
            if new_residuals_norm * P1 >= self.residuals_norm || temp < P1 {
                temp = P1;
            }
            self.delta = temp * self.delta.min(pnorm * 10.0);
            self.lambda /= temp;
        } else if self.lambda == 0.0 || ratio >= 0.75 {
            self.delta = pnorm / 0.5;
            self.lambda *= 0.5;
        }

        let good = ratio >= P0001;
        if good {
            std::mem::swap(&mut self.x, &mut self.tmp);
            std::mem::swap(&mut self.residuals, &mut self.trial);
            self.at_x = true;
            self.xnorm = self.scaled_x_norm();
            if !self.xnorm.is_finite() {
                return Err(TerminationReason::Numerical("new x"));
            }
            self.residuals_norm = new_residuals_norm;
        }

        // Convergence.
        if self.residuals_norm <= f64::MIN_POSITIVE {
            self.reset_if(!good);
            return Err(TerminationReason::ResidualsZero);
        }
        let ftol_check = actual_reduction.abs() <= self.settings.ftol
            && predicted_reduction <= self.settings.ftol
            && ratio * 0.5 <= 1.0;
        let xtol_check = self.delta <= self.settings.xtol * self.xnorm;
        if ftol_check || xtol_check {
            self.reset_if(!good);
            return Err(TerminationReason::Converged {
                ftol: ftol_check,
                xtol: xtol_check,
            });
        }
        // Termination.
        if self.evaluations >= self.max_fev {
            self.reset_if(!good);
            return Err(TerminationReason::LostPatience);
        }
        if actual_reduction.abs() <= EPSMCH && predicted_reduction <= EPSMCH && ratio * 0.5 <= 1.0 {
            self.reset_if(!good);
            return Err(TerminationReason::NoImprovementPossible("ftol"));
        }
        if self.delta <= EPSMCH * self.xnorm {
            self.reset_if(!good);
            return Err(TerminationReason::NoImprovementPossible("xtol"));
        }
        if self.gnorm <= EPSMCH {
            self.reset_if(!good);
            return Err(TerminationReason::NoImprovementPossible("gtol"));
        }
        Ok(if good { Step::Taken } else { Step::Rejected })
    }

    /// Put the problem back at `x` after a rejected last step.
    fn reset_if(&mut self, reset: bool) {
        if reset {
            self.at = self.x;
            self.at_x = true;
        }
    }

    fn finish(self, termination: TerminationReason) -> Outcome {
        let n = self.n;
        Outcome {
            x: self.at[..n].to_vec(),
            termination,
            evaluations: self.evaluations,
            residuals: self.at_x.then_some(self.residuals),
        }
    }
}

/// Minimise `‖r(x)‖²` from `x0` (at most [`MAX_COLS`] parameters) as the
/// crate's `LevenbergMarquardt::minimize` does with `settings`.
pub(super) fn minimize<P: Problem>(problem: P, x0: &[f64], settings: &Settings) -> Outcome {
    let n = x0.len();
    assert!(n <= MAX_COLS, "{n} parameters, at most {MAX_COLS}");
    let m = problem.rows();
    let mut x = [0.0; MAX_COLS];
    x[..n].copy_from_slice(x0);
    let mut run = Run {
        settings,
        problem,
        n,
        x,
        tmp: x,
        at: x,
        at_x: true,
        residuals: vec![0.0; m],
        trial: vec![0.0; m],
        evaluations: 1,
        delta: 0.0,
        lambda: 0.0,
        xnorm: 0.0,
        gnorm: 0.0,
        residuals_norm: 0.0,
        diag: [1.0; MAX_COLS],
        first_trust_region_iteration: true,
        first_update: true,
        max_fev: settings.patience * (n + 1),
    };
    run.residuals_norm = evaluate(&mut run.problem, x0, &mut run.residuals);
    if n == 0 {
        return run.finish(TerminationReason::NoParameters);
    }
    if m == 0 {
        return run.finish(TerminationReason::NoResiduals);
    }
    if !run.residuals_norm.is_finite() {
        return run.finish(TerminationReason::Numerical("residuals norm"));
    }
    if run.residuals_norm <= f64::MIN_POSITIVE {
        return run.finish(TerminationReason::ResidualsZero);
    }
    // The columns past n are never read (the reflections may leave
    // anything in them).
    let mut jacobian = vec![[0.0; MAX_COLS]; m];
    let mut qt_r = vec![0.0; m];
    let mut w = vec![0.0; m];
    let mut lls = Factored::new(n);
    let mut step = [0.0; MAX_COLS];
    loop {
        if !run.problem.jacobian(&run.x[..n], &mut jacobian) {
            return run.finish(TerminationReason::User("jacobian"));
        }
        qt_r.copy_from_slice(&run.residuals);
        lls.factor(&mut jacobian, &mut qt_r, &mut w);
        if let Err(reason) = run.update_diag(&mut lls) {
            return run.finish(reason);
        }
        loop {
            let (lambda, pnorm) =
                lambda_and_step(&mut lls, &run.diag, run.delta, run.lambda, &mut step);
            match run.trust_region_iteration(&mut lls, &step, lambda, pnorm) {
                Ok(Step::Taken) => break,
                Ok(Step::Rejected) => {}
                Err(reason) => return run.finish(reason),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::least_squares::{AtParams, Residuals};
    use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
    use nalgebra::{DMatrix, DVector};

    type Residual = fn(&[f64], &[f64]) -> Option<f64>;
    type Gradient = fn(&[f64], &[f64]) -> Vec<f64>;

    /// A test problem: one residual per sample `t`, and its gradient.
    struct Samples {
        t: Vec<Vec<f64>>,
        residual: Residual,
        gradient: Gradient,
    }

    impl Samples {
        fn residuals(&self, x: &[f64]) -> Option<Vec<f64>> {
            self.t.iter().map(|t| (self.residual)(x, t)).collect()
        }

        fn jacobian(&self, x: &[f64]) -> Option<Vec<Vec<f64>>> {
            let rows: Vec<Vec<f64>> = self.t.iter().map(|t| (self.gradient)(x, t)).collect();
            rows.iter()
                .all(|r| r.iter().all(|v| v.is_finite()))
                .then_some(rows)
        }
    }

    impl Problem for &Samples {
        fn rows(&self) -> usize {
            self.t.len()
        }

        fn residuals(&mut self, x: &[f64], out: &mut [f64]) -> bool {
            Samples::residuals(self, x).is_some_and(|r| {
                out.copy_from_slice(&r);
                true
            })
        }

        fn jacobian(&mut self, x: &[f64], out: &mut [Row]) -> bool {
            Samples::jacobian(self, x).is_some_and(|rows| {
                for (o, r) in out.iter_mut().zip(rows) {
                    o[..r.len()].copy_from_slice(&r);
                }
                true
            })
        }
    }

    /// The same problem as the crate sees it, through the adapter every
    /// other dynamic fit uses.
    impl Residuals for &Samples {
        fn rows(&self) -> usize {
            self.t.len()
        }

        fn residuals_at(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
            self.residuals(x.as_slice()).map(DVector::from_vec)
        }

        fn jacobian_at(&self, x: &DVector<f64>) -> Option<DMatrix<f64>> {
            let rows = self.jacobian(x.as_slice())?;
            Some(DMatrix::from_fn(rows.len(), x.len(), |i, j| rows[i][j]))
        }
    }

    /// Both solvers from `x0`: the same parameters to the bit, the same
    /// termination and evaluations, and the residuals reported at them.
    fn agree(problem: &Samples, x0: &[f64], tol: f64, patience: usize) {
        let ours = minimize(problem, x0, &Settings::new(tol, patience));
        let (theirs, report) = LevenbergMarquardt::new()
            .with_patience(patience)
            .with_tol(tol)
            .minimize(AtParams {
                problem,
                x: DVector::from_column_slice(x0),
            });
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&ours.x), bits(theirs.x.as_slice()), "{ours:?}");
        assert_eq!(ours.termination, report.termination);
        assert_eq!(ours.evaluations, report.number_of_evaluations);
        if let Some(r) = &ours.residuals {
            assert_eq!(bits(r), bits(theirs.residuals().unwrap().as_slice()));
        }
    }

    fn grid(m: usize) -> Vec<Vec<f64>> {
        (0..m)
            .map(|i| {
                let t = i as f64 / m as f64;
                vec![t, (7.0 * t).sin() * 0.01]
            })
            .collect()
    }

    fn decay() -> Samples {
        Samples {
            t: grid(40),
            residual: |x, t| {
                Some(x[0] * (-x[1] * t[0]).exp() + x[2] - 2.0 * (-3.0 * t[0]).exp() - 0.5 - t[1])
            },
            gradient: |x, t| {
                let e = (-x[1] * t[0]).exp();
                vec![e, -x[0] * t[0] * e, 1.0]
            },
        }
    }

    #[test]
    fn the_solver_matches_the_crate_on_a_curve_fit() {
        for x0 in [
            [1.0, 1.0, 0.0],
            [10.0, 0.1, -3.0],
            [-2.0, 8.0, 1.0],
            [0.0, 0.0, 0.0],
        ] {
            for (tol, patience) in [(1e-8, 100), (1e-12, 100), (1e-12, 3), (1e-15, 1)] {
                agree(&decay(), &x0, tol, patience);
            }
        }
    }

    #[test]
    fn the_solver_matches_the_crate_on_degenerate_problems() {
        // A parameter without effect (a zero column), and two with the
        // same effect (rank deficiency).
        let idle = Samples {
            t: grid(12),
            residual: |x, t| Some(x[0] * t[0] - 1.0 + t[1] + 0.0 * x[1]),
            gradient: |_, t| vec![t[0], 0.0],
        };
        let twins = Samples {
            t: grid(12),
            residual: |x, t| Some((x[0] + x[1]) * t[0] - 1.0 + t[1]),
            gradient: |_, t| vec![t[0], t[0]],
        };
        // Fewer residuals than parameters.
        let wide = Samples {
            t: grid(2),
            residual: |x, t| Some(x[0] * t[0] + x[1] * x[1] - x[2] + (x[3] - 1.0).powi(3) - 2.0),
            gradient: |x, t| vec![t[0], 2.0 * x[1], -1.0, 3.0 * (x[3] - 1.0).powi(2)],
        };
        // Rosenbrock's valley, square.
        let valley = Samples {
            t: vec![vec![0.0], vec![1.0]],
            residual: |x, t| {
                Some(if t[0] == 0.0 {
                    10.0 * (x[1] - x[0] * x[0])
                } else {
                    1.0 - x[0]
                })
            },
            gradient: |x, t| {
                if t[0] == 0.0 {
                    vec![-20.0 * x[0], 10.0]
                } else {
                    vec![-1.0, 0.0]
                }
            },
        };
        for (p, x0) in [
            (&idle, vec![3.0, 1.0]),
            (&twins, vec![3.0, -1.0]),
            (&wide, vec![0.5, 2.0, 1.0, 3.0]),
            (&valley, vec![-1.2, 1.0]),
        ] {
            for tol in [1e-8, 1e-12] {
                agree(p, &x0, tol, 100);
            }
        }
    }

    #[test]
    fn the_solver_matches_the_crate_at_the_edges_of_the_norm_and_the_region() {
        // Residuals near overflow and underflow (enorm's other sums), and
        // a region outside which there are none.
        let huge = Samples {
            t: grid(30),
            residual: |x, t| Some(1e160 * (x[0] * t[0] + x[1] - 1.0 - t[1])),
            gradient: |_, t| vec![1e160 * t[0], 1e160],
        };
        let tiny = Samples {
            t: grid(30),
            residual: |x, t| Some(1e-160 * (x[0] * t[0] + x[1] * x[1] - 1.0 - t[1])),
            gradient: |x, t| vec![1e-160 * t[0], 2e-160 * x[1]],
        };
        let bounded = Samples {
            t: grid(25),
            residual: |x, t| (x[0] > 0.0).then(|| x[0].ln() * t[0] + x[1] - 2.0 * t[0] - t[1]),
            gradient: |x, t| vec![t[0] / x[0], 1.0],
        };
        for (p, x0) in [
            (&huge, vec![0.0, 0.0]),
            (&tiny, vec![3.0, 2.0]),
            (&bounded, vec![0.01, 0.0]),
            (&bounded, vec![-1.0, 0.0]),
        ] {
            for tol in [1e-8, 1e-12] {
                agree(p, &x0, tol, 100);
            }
        }
    }

    #[test]
    fn enorm_keeps_tiny_and_huge_components() {
        let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-15;
        assert_eq!(enorm_of(&[3.0, 4.0]), 5.0);
        assert!(close(enorm_of(&[3e200, 4e200]), 5e200));
        assert!(close(enorm_of(&[3e-200, 4e-200]), 5e-200));
        assert!(enorm_of(&[1.0, f64::NAN]).is_nan());
        assert_eq!(enorm_of(&[0.0, 0.0]), 0.0);
    }
}
