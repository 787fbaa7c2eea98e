//! The output-error fit as a least-squares problem for the
//! `levenberg-marquardt` crate: noise-weighted residuals of current and
//! speed over every fitted segment, in log-parameters, with a
//! finite-difference Jacobian.
//!
//! Parameters are `x = ln(p / p_ref)` for `p` = (Ra, La, K, J, f, Tst) and
//! a reference `p_ref` (the start): positivity holds by construction, a
//! step in `x` is a relative change, and the Jacobian columns are
//! sensitivities to relative changes, so they are comparable in size.
//!
//! The Jacobian is taken by forward differences of the simulation
//! (6 extra simulations, stepped in lockstep with the one at the point
//! itself: [`simulate_lanes`]). Sensitivity equations would be exact, but for
//! this 2-state model they mean a 14-state recursion per sample (more
//! arithmetic than the 6 simulations), and differences differentiate
//! exactly what is simulated, stiction and friction direction included.
//! The step, 1e-8 in `ln p`, balances truncation (step × curvature) against
//! rounding (about 1e-13 of residuals up to some 10³ noise levels, over
//! the step): both near 1e-5 of a noise level per residual, and the
//! optimiser's convergence test then sees no spurious gradient.

use std::cell::RefCell;
use std::rc::Rc;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector, Dyn, Matrix6, OMatrix, Owned, SMatrix, SVector, Vector6, U6, U7};

use super::simulation::{
    simulate_lanes, DrivenStep, LaneReadings, SegmentInput, SpeedReading, LANES,
};
use crate::identify::square_root::square_root_problem;
use crate::identify::vector::with_avx;
use crate::model::DcParams;

/// Number of fitted parameters.
pub const NP: usize = 6;

/// Residual of a parameter set the model refuses: large enough that the
/// optimiser always rejects the step that led there.
pub const REFUSED: f64 = 1e30;

/// Largest distance from the reference, in `ln` units (a factor e^25).
const MAX_LN: f64 = 25.0;

/// Relative reduction of the sum of squares below which the optimiser
/// stops: with some 10⁴ residuals at the noise level, a change of the sum
/// far below 1 (one standard error of a parameter moves it by 1).
const FTOL: f64 = 1e-9;

/// Forward-difference step in `ln` units.
const FD_STEP: f64 = 1e-8;

/// `p` as an array in fit order (Ra, La, K, J, f, Tst).
pub fn to_array(p: &DcParams) -> [f64; NP] {
    [p.ra, p.la, p.k, p.j, p.f, p.tst]
}

/// The inverse of [`to_array`].
pub fn from_array(a: [f64; NP]) -> DcParams {
    DcParams {
        ra: a[0],
        la: a[1],
        k: a[2],
        j: a[3],
        f: a[4],
        tst: a[5],
    }
}

/// The segments fitted, the noise weights and what the speed reads.
#[derive(Debug, Clone)]
pub struct FitData<'a> {
    /// Segments in the fit.
    pub segments: Vec<SegmentInput<'a>>,
    /// Noise standard deviation of current (A) and speed (rad/s).
    pub sigma: [f64; 2],
    /// What the speed channel reads.
    pub reading: SpeedReading,
}

impl FitData<'_> {
    /// Residuals: two per sample (current, then speed), each
    /// `(simulated − measured)/σ`.
    pub fn len(&self) -> usize {
        2 * self.segments.iter().map(SegmentInput::len).sum::<usize>()
    }

    /// Weighted residuals of `params` into `r` (of length [`Self::len`]);
    /// `false` when the model refuses the parameters.
    pub fn residuals_into(&self, params: &DcParams, r: &mut [f64]) -> bool {
        self.residuals_lanes(&[params], &mut [r])[0]
    }

    /// [`Self::residuals_into`] for several parameter sets at once, set
    /// `l` into `cols[l]`, the sets simulated in lockstep
    /// ([`simulate_lanes`]: the same values as one at a time).
    pub fn residuals_lanes(&self, params: &[&DcParams], cols: &mut [&mut [f64]]) -> Vec<bool> {
        let (wi, ww) = (1.0 / self.sigma[0], 1.0 / self.sigma[1]);
        let mut ok = vec![true; params.len()];
        let mut at = 0;
        for input in &self.segments {
            let n = input.len();
            // The sets the model accepts at this segment's interval, and
            // their rows of it.
            let mut lanes = Vec::with_capacity(params.len());
            let mut rows: Vec<&mut [f64]> = Vec::with_capacity(params.len());
            let mut sets = Vec::with_capacity(params.len());
            for (l, (p, col)) in params.iter().zip(cols.iter_mut()).enumerate() {
                if ok[l] {
                    match DrivenStep::new(p, input.dt) {
                        Ok(step) => {
                            lanes.push((*p, step));
                            rows.push(&mut col[at..at + 2 * n]);
                            sets.push(l);
                        }
                        Err(_) => ok[l] = false,
                    }
                }
            }
            let (y_i, y_w) = (&input.seg.current[..n], &input.seg.speed[..n]);
            for ((lanes, rows), sets) in lanes
                .chunks(LANES)
                .zip(rows.chunks_mut(LANES))
                .zip(sets.chunks(LANES))
            {
                let mut residuals = WeightedResiduals {
                    rows,
                    measured: [y_i, y_w],
                    weight: [wi, ww],
                    finite: [0.0; LANES],
                };
                simulate_lanes(lanes, input, self.reading, &mut residuals);
                for (j, &l) in sets.iter().enumerate() {
                    ok[l] &= residuals.finite[j] == 0.0;
                }
            }
            at += 2 * n;
        }
        ok
    }
}

/// Each lane's weighted residuals of one segment into its rows: current,
/// then speed, per sample.
struct WeightedResiduals<'r, 'y> {
    rows: &'r mut [&'y mut [f64]],
    /// Measured current and speed.
    measured: [&'y [f64]; 2],
    /// `1/σ` of current and speed.
    weight: [f64; 2],
    /// Per lane, the sum of `0·x` over its residuals `x`: zero while
    /// every one is finite, NaN from the first that is not (a check that
    /// costs a vector addition per sample, not a pass over the rows).
    finite: [f64; LANES],
}

impl LaneReadings for WeightedResiduals<'_, '_> {
    #[inline(always)]
    fn readings(&mut self, k: usize, current: &[f64; LANES], speed: &[f64; LANES]) {
        let (y_i, y_w) = (self.measured[0][k], self.measured[1][k]);
        let ri: [f64; LANES] = std::array::from_fn(|j| (current[j] - y_i) * self.weight[0]);
        let rw: [f64; LANES] = std::array::from_fn(|j| (speed[j] - y_w) * self.weight[1]);
        for j in 0..LANES {
            self.finite[j] += ri[j] * 0.0 + rw[j] * 0.0;
        }
        for (j, row) in self.rows.iter_mut().enumerate() {
            row[2 * k] = ri[j];
            row[2 * k + 1] = rw[j];
        }
    }
}

/// The linearisation of the residuals at one point, in full and reduced.
///
/// The optimiser needs `JᵀJ`, `Jᵀr` and `‖r‖` only, so it is handed the
/// problem reduced to 7 rows: `J' = [R; 0]` with `R'R = JᵀJ`, and
/// `r' = [R⁻ᵀ·Jᵀr; ‖r − projection‖]`, which has `‖r'‖ = ‖r‖` and
/// `J'ᵀr' = Jᵀr`. Its iterates are those of the full problem, without the
/// crate factorising a Jacobian of tens of thousands of rows at every
/// step. The price: every residual evaluation also takes the Jacobian.
#[derive(Debug, Clone)]
pub struct Linearisation {
    /// Where.
    pub x: Vector6<f64>,
    /// Weighted residuals (all [`REFUSED`] when the model refuses `x`).
    pub r: DVector<f64>,
    /// Their Jacobian with respect to `x` (empty when refused).
    pub jac: OMatrix<f64, Dyn, U6>,
    reduced_r: SVector<f64, 7>,
    reduced_j: SMatrix<f64, 7, 6>,
}

impl Linearisation {
    /// Whether the model refuses the parameters.
    pub fn refused(&self) -> bool {
        self.jac.nrows() == 0
    }
}

/// The problem the optimiser sees.
pub struct OutputErrorProblem<'d, 'a> {
    data: &'d FitData<'a>,
    reference: [f64; NP],
    x: Vector6<f64>,
    /// The linearisation at the last point asked for: the optimiser asks
    /// for residuals and then the Jacobian at one point.
    last: RefCell<Option<Rc<Linearisation>>>,
}

impl<'d, 'a> OutputErrorProblem<'d, 'a> {
    /// A problem over `data`, starting at (and measured from) `reference`,
    /// whose six values must be > 0.
    pub fn new(data: &'d FitData<'a>, reference: &DcParams) -> Self {
        OutputErrorProblem {
            data,
            reference: to_array(reference),
            x: Vector6::zeros(),
            last: RefCell::new(None),
        }
    }

    /// The parameters at `x`.
    pub fn params_at(&self, x: &Vector6<f64>) -> DcParams {
        from_array(std::array::from_fn(|n| self.reference[n] * x[n].exp()))
    }

    /// The weighted residuals at `x`, all [`REFUSED`] where the model
    /// refuses the parameters.
    #[cfg(test)]
    pub fn compute(&self, x: &Vector6<f64>) -> DVector<f64> {
        let mut r = DVector::zeros(self.data.len());
        self.compute_into(x, r.as_mut_slice());
        r
    }

    /// The weighted residuals at `x` into `r`, all [`REFUSED`] where the
    /// model refuses the parameters; `false` then.
    fn compute_into(&self, x: &Vector6<f64>, r: &mut [f64]) -> bool {
        let inside = x.iter().all(|v| v.abs() <= MAX_LN);
        let ok = inside && self.data.residuals_into(&self.params_at(x), r);
        if !ok {
            r.fill(REFUSED);
        }
        ok
    }

    /// The Jacobian of the residuals `r` at `x` by forward differences
    /// (backward at the edge of what the model accepts; a zero column
    /// where it accepts neither).
    #[cfg(test)]
    pub fn jacobian_from(&self, x: &Vector6<f64>, r: &DVector<f64>) -> OMatrix<f64, Dyn, U6> {
        let mut jac = OMatrix::<f64, Dyn, U6>::zeros(r.len());
        self.linearise_into(x, &mut r.clone(), &mut jac);
        jac
    }

    /// The residuals at `x` into `r` and their Jacobian into `jac` by
    /// forward differences (backward at the edge of what the model
    /// accepts; a zero column where it accepts neither); `false`, with `r`
    /// all [`REFUSED`], when the model refuses `x`. The point and its six
    /// forward steps are simulated in one lockstep pass.
    fn linearise_into(
        &self,
        x: &Vector6<f64>,
        r: &mut DVector<f64>,
        jac: &mut OMatrix<f64, Dyn, U6>,
    ) -> bool {
        let m = r.len();
        // Lane 0 is `x`, lane n + 1 its forward step in parameter n.
        let points: [Vector6<f64>; NP + 1] = std::array::from_fn(|n| {
            let mut xp = *x;
            if n > 0 {
                xp[n - 1] += FD_STEP;
            }
            xp
        });
        let inside = |x: &Vector6<f64>| x.iter().all(|v| v.abs() <= MAX_LN);
        let params: Vec<DcParams> = points.iter().map(|xp| self.params_at(xp)).collect();
        let mut ok = [false; NP + 1];
        {
            let (mut lanes, mut refs, mut cols) = (Vec::new(), Vec::new(), Vec::new());
            // Column-major storage: column n is one slice.
            let columns =
                std::iter::once(r.as_mut_slice()).chain(jac.as_mut_slice().chunks_mut(m.max(1)));
            for (n, col) in columns.enumerate() {
                if inside(&points[n]) {
                    lanes.push(n);
                    refs.push(&params[n]);
                    cols.push(col);
                }
            }
            for (&n, lane_ok) in lanes
                .iter()
                .zip(self.data.residuals_lanes(&refs, &mut cols))
            {
                ok[n] = lane_ok;
            }
        }
        if !ok[0] {
            r.fill(REFUSED);
            return false;
        }
        for (n, ok) in ok.into_iter().skip(1).enumerate() {
            let column = &mut jac.as_mut_slice()[n * m..(n + 1) * m];
            let h = if ok {
                FD_STEP
            } else {
                let mut xp = *x;
                xp[n] = x[n] - FD_STEP;
                if !self.compute_into(&xp, column) {
                    column.fill(0.0);
                    continue;
                }
                -FD_STEP
            };
            difference(column, r.as_slice(), 1.0 / h);
        }
        true
    }

    /// The linearisation at `x`.
    pub fn linearise(&self, x: &Vector6<f64>) -> Rc<Linearisation> {
        if let Some(l) = self.last.borrow().as_ref() {
            if l.x == *x {
                return Rc::clone(l);
            }
        }
        // Reuse the previous linearisation's storage when nobody holds it:
        // tens of thousands of rows, allocated anew at every evaluation.
        let m = self.data.len();
        let recycled = self
            .last
            .borrow_mut()
            .take()
            .and_then(|old| Rc::try_unwrap(old).ok())
            .filter(|old| old.r.len() == m && old.jac.nrows() == m);
        let (mut r, mut jac) = match recycled {
            Some(old) => (old.r, old.jac),
            None => (DVector::zeros(m), OMatrix::<f64, Dyn, U6>::zeros(m)),
        };
        let l = if self.linearise_into(x, &mut r, &mut jac) {
            let (reduced_r, reduced_j) = reduce(&jac, &r);
            Linearisation {
                x: *x,
                r,
                jac,
                reduced_r,
                reduced_j,
            }
        } else {
            let mut reduced_r = SVector::<f64, 7>::zeros();
            reduced_r[6] = REFUSED * (m as f64).sqrt();
            Linearisation {
                x: *x,
                r,
                jac: OMatrix::<f64, Dyn, U6>::zeros(0),
                reduced_r,
                reduced_j: SMatrix::zeros(),
            }
        };
        let l = Rc::new(l);
        *self.last.borrow_mut() = Some(Rc::clone(&l));
        l
    }
}

/// The 7-row problem equivalent to `(jac, r)` (see [`Linearisation`] and
/// [`square_root_problem`]); a non-finite linearisation is refused like a
/// refused `x`.
fn reduce(jac: &OMatrix<f64, Dyn, U6>, r: &DVector<f64>) -> (SVector<f64, 7>, SMatrix<f64, 7, 6>) {
    let (jtj, g) = normal_equations(jac, r);
    let r_norm_sq = if r.as_slice().iter().all(|v| v.is_finite()) {
        r.norm_squared()
    } else {
        f64::NAN
    };
    let dynamic = square_root_problem(
        DMatrix::from_iterator(NP, NP, jtj.iter().copied()),
        &DVector::from_iterator(NP, g.iter().copied()),
        r_norm_sq,
    );
    match dynamic {
        Some((rr, rj)) => (
            SVector::from_iterator(rr.iter().copied()),
            SMatrix::from_iterator(rj.iter().copied()),
        ),
        None => {
            let mut refused = SVector::<f64, 7>::zeros();
            refused[6] = REFUSED * (r.len() as f64).sqrt();
            (refused, SMatrix::zeros())
        }
    }
}

/// `column ← (column − base)·inv_h`: a Jacobian column from the residuals
/// at a step and at the point (vectorised, AVX where the processor has
/// it: [`with_avx`]).
fn difference(column: &mut [f64], base: &[f64], inv_h: f64) {
    with_avx(
        #[inline(always)]
        || {
            // Slices, not a vector's strided iterator, so the loop vectorises.
            for (c, b) in column.iter_mut().zip(base) {
                *c = (*c - b) * inv_h;
            }
        },
    )
}

/// `JᵀJ` and `Jᵀr`, each entry the same to the bit as nalgebra's
/// `tr_mul` gives it ([`DotSums`]), with `JᵀJ`'s lower triangle mirrored
/// from the upper (a dot product is symmetric to the bit); AVX where the
/// processor has it ([`with_avx`]).
fn normal_equations(jac: &OMatrix<f64, Dyn, U6>, r: &DVector<f64>) -> (Matrix6<f64>, Vector6<f64>) {
    with_avx(
        #[inline(always)]
        || normal_equations_kernel(jac, r),
    )
}

/// Rows per block of [`normal_equations_kernel`]: the seven columns' block
/// (28 KiB) stays in the first-level cache while its 27 products are
/// summed. A multiple of 8, so blocks hold whole blocks of [`DotSums`].
const PRODUCT_BLOCK: usize = 512;

/// The body of [`normal_equations`]: each of the 27 products summed as
/// nalgebra's `dot` sums it ([`DotSums`]), a block of rows at a time (the same sums, in the same
/// order, read from cache instead of memory).
#[inline(always)]
fn normal_equations_kernel(
    jac: &OMatrix<f64, Dyn, U6>,
    r: &DVector<f64>,
) -> (Matrix6<f64>, Vector6<f64>) {
    let m = jac.nrows();
    // Columns 0–5 of J, then r.
    let columns: [&[f64]; NP + 1] = std::array::from_fn(|n| {
        if n < NP {
            &jac.as_slice()[n * m..(n + 1) * m]
        } else {
            &r.as_slice()[..m]
        }
    });
    // The pairs (a, b), a ≤ b < NP, then (a, r).
    let pairs: Vec<(usize, usize)> = (0..NP)
        .flat_map(|a| (a..NP).map(move |b| (a, b)))
        .chain((0..NP).map(|a| (a, NP)))
        .collect();
    let mut sums = vec![DotSums::default(); pairs.len()];
    let whole = m - m % 8;
    for start in (0..whole).step_by(PRODUCT_BLOCK) {
        let end = (start + PRODUCT_BLOCK).min(whole);
        for (sum, &(a, b)) in sums.iter_mut().zip(&pairs) {
            sum.add_blocks(&columns[a][start..end], &columns[b][start..end]);
        }
    }
    let total = |p: usize| {
        let (a, b) = pairs[p];
        sums[p].total(&columns[a][whole..], &columns[b][whole..])
    };
    let mut jtj = Matrix6::zeros();
    let mut g = Vector6::zeros();
    for (p, &(a, b)) in pairs.iter().enumerate() {
        let d = total(p);
        if b < NP {
            jtj[(a, b)] = d;
            jtj[(b, a)] = d;
        } else {
            g[a] = d;
        }
    }
    (jtj, g)
}

/// The eight running sums of nalgebra's `dot` of a contiguous vector
/// (over blocks of eight), fed a block of rows at a time.
#[derive(Debug, Clone, Copy, Default)]
struct DotSums([f64; 8]);

impl DotSums {
    /// Add the products of `a` and `b`, whole blocks of eight.
    #[inline(always)]
    fn add_blocks(&mut self, a: &[f64], b: &[f64]) {
        for (x, y) in a.chunks_exact(8).zip(b.chunks_exact(8)) {
            for l in 0..8 {
                self.0[l] += x[l] * y[l];
            }
        }
    }

    /// The sum: the running sums added pairwise (0 and 4, 1 and 5, …),
    /// then the rest `a`·`b` (fewer than eight) one by one.
    #[inline(always)]
    fn total(&self, rest_a: &[f64], rest_b: &[f64]) -> f64 {
        let mut sum = 0.0;
        for l in 0..4 {
            sum += self.0[l] + self.0[l + 4];
        }
        for (x, y) in rest_a.iter().zip(rest_b) {
            sum += x * y;
        }
        sum
    }
}

/// `a·b` summed as nalgebra's `dot` sums a contiguous vector: eight
/// running sums over blocks of eight, added pairwise (0 and 4, 1 and 5,
/// …), then the rest one by one; so the same to the bit, in a loop the
/// compiler vectorises for the processor at hand.
#[cfg(test)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let b = &b[..a.len()];
    let whole = a.len() - a.len() % 8;
    let mut sums = DotSums::default();
    sums.add_blocks(&a[..whole], &b[..whole]);
    sums.total(&a[whole..], &b[whole..])
}

impl LeastSquaresProblem<f64, U7, U6> for OutputErrorProblem<'_, '_> {
    type ResidualStorage = Owned<f64, U7>;
    type JacobianStorage = Owned<f64, U7, U6>;
    type ParameterStorage = Owned<f64, U6>;

    fn set_params(&mut self, x: &Vector6<f64>) {
        self.x = *x;
    }

    fn params(&self) -> Vector6<f64> {
        self.x
    }

    fn residuals(&self) -> Option<SVector<f64, 7>> {
        Some(self.linearise(&self.x).reduced_r)
    }

    fn jacobian(&self) -> Option<SMatrix<f64, 7, 6>> {
        Some(self.linearise(&self.x).reduced_j)
    }
}

/// The result of one minimisation.
#[derive(Debug, Clone)]
pub struct Minimum {
    /// Parameters at the minimum.
    pub params: DcParams,
    /// The reference the log-parameters are measured from.
    pub reference: DcParams,
    /// The residuals and their Jacobian at the minimum.
    pub at: Rc<Linearisation>,
    /// Whether the optimiser reports convergence.
    pub converged: bool,
    /// Why it stopped, for messages.
    pub termination: String,
    /// Residual evaluations used (each with its Jacobian).
    pub evaluations: usize,
}

/// Minimise over `data` from `start` (all six values > 0).
pub fn minimise(data: &FitData, start: &DcParams) -> Minimum {
    let problem = OutputErrorProblem::new(data, start);
    let lm = LevenbergMarquardt::new()
        .with_ftol(FTOL)
        .with_xtol(1e-10)
        .with_gtol(1e-10)
        .with_patience(40);
    let (problem, report) = lm.minimize(problem);
    let converged = report.termination.was_successful()
        || matches!(
            report.termination,
            TerminationReason::NoImprovementPossible(_)
        );
    Minimum {
        params: problem.params_at(&problem.x),
        reference: *start,
        at: problem.linearise(&problem.x),
        converged,
        termination: format!("{:?}", report.termination),
        evaluations: report.number_of_evaluations,
    }
}

#[cfg(test)]
mod tests {
    use super::super::simulation::{simulate_series, SegmentStart};
    use super::*;
    use crate::record::DcSegment;

    /// A staircase simulated exactly with `p`, without noise.
    fn staircase(p: &DcParams, dt: f64) -> Vec<DcSegment> {
        let levels = [60.0, 248.0, 107.0, 201.0];
        let mut out = Vec::new();
        let mut previous = 0.0;
        for (n, &level) in levels.iter().enumerate() {
            let voltage: Vec<f64> = (0..1500)
                .map(|k| if k == 0 && n > 0 { previous } else { level })
                .collect();
            let mut seg = DcSegment {
                index: n as u32,
                time: (0..1500).map(|k| k as f64 * dt).collect(),
                voltage,
                ..Default::default()
            };
            let start = if n == 0 {
                SegmentStart::FromRest
            } else {
                SegmentStart::Settled(previous)
            };
            let input = SegmentInput::new(&seg, start);
            let (i, w) = simulate_series(p, &input, SpeedReading::IntervalMean).unwrap();
            (seg.current, seg.speed) = (i, w);
            out.push(seg);
            previous = level;
        }
        out
    }

    fn data(segs: &[DcSegment]) -> FitData<'_> {
        FitData {
            segments: segs
                .iter()
                .enumerate()
                .map(|(n, s)| {
                    let start = if n == 0 {
                        SegmentStart::FromRest
                    } else {
                        SegmentStart::Settled(s.voltage[0])
                    };
                    SegmentInput::new(s, start)
                })
                .collect(),
            sigma: [0.002, 0.5],
            reading: SpeedReading::IntervalMean,
        }
    }

    #[test]
    fn noise_free_data_is_fitted_exactly_from_a_distant_start() {
        let truth = DcParams::SEED_TABLE4_MOMENTS;
        let segs = staircase(&truth, 5e-4);
        let d = data(&segs);
        let start = DcParams {
            ra: truth.ra * 1.3,
            la: truth.la * 0.5,
            k: truth.k * 0.95,
            j: truth.j * 2.0,
            f: truth.f * 3.0,
            tst: truth.tst * 0.6,
        };
        let m = minimise(&d, &start);
        assert!(m.converged, "{}", m.termination);
        assert!(m.evaluations < 30, "{} evaluations", m.evaluations);
        let (got, want) = (to_array(&m.params), to_array(&truth));
        for n in 0..NP {
            assert!(
                ((got[n] - want[n]) / want[n]).abs() < 1e-6,
                "parameter {n}: {} vs {}",
                got[n],
                want[n]
            );
        }
        assert!(m.at.r.norm() < 1e-4);
    }

    /// `check` run on the problem of the seed motor's exact staircase,
    /// with the truth as its reference.
    fn on_seed_staircase(check: impl FnOnce(&OutputErrorProblem)) {
        let truth = DcParams::SEED_TABLE4_MOMENTS;
        let segs = staircase(&truth, 5e-4);
        let d = data(&segs);
        check(&OutputErrorProblem::new(&d, &truth));
    }

    #[test]
    fn jacobian_matches_a_central_difference() {
        on_seed_staircase(|p| {
            let x = Vector6::new(0.01, -0.02, 0.003, 0.05, -0.1, 0.02);
            let jac = p.jacobian_from(&x, &p.compute(&x));
            for n in 0..NP {
                let h = 1e-5;
                let (mut a, mut b) = (x, x);
                a[n] += h;
                b[n] -= h;
                let central = (p.compute(&a) - p.compute(&b)) / (2.0 * h);
                let err = (jac.column(n) - &central).norm() / central.norm();
                assert!(err < 1e-4, "column {n}: relative error {err}");
            }
        });
    }

    #[test]
    fn the_reduced_problem_has_the_normal_equations_and_norm_of_the_full_one() {
        let jac = OMatrix::<f64, Dyn, U6>::from_fn(50, |r, c| {
            ((r * 7 + c * 13) % 11) as f64 - 5.0 + c as f64 * 0.1 * r as f64
        });
        let r = DVector::from_fn(50, |k, _| ((k * 5) % 9) as f64 - 4.0);
        let (rr, rj) = reduce(&jac, &r);
        let jtj = jac.tr_mul(&jac);
        let jtr = jac.tr_mul(&r);
        assert!((rj.tr_mul(&rj) - jtj).norm() < 1e-9 * jtj.norm());
        assert!((rj.tr_mul(&rr) - jtr).norm() < 1e-9 * jtr.norm());
        assert!((rr.norm() - r.norm()).abs() < 1e-9 * r.norm());
    }

    #[test]
    fn a_lane_with_a_residual_that_is_not_finite_is_refused() {
        let truth = DcParams::SEED_TABLE4_MOMENTS;
        let mut segs = staircase(&truth, 5e-4);
        let other = DcParams {
            ra: truth.ra * 1.1,
            ..truth
        };
        let m = data(&segs).len();
        let lanes = |d: &FitData| {
            let (mut a, mut b) = (vec![0.0; m], vec![0.0; m]);
            d.residuals_lanes(&[&truth, &other], &mut [&mut a, &mut b])
        };
        assert_eq!(lanes(&data(&segs)), [true, true]);
        // One reading in the third segment overflows: every lane's
        // residual there is infinite.
        segs[2].current[700] = f64::INFINITY;
        assert_eq!(lanes(&data(&segs)), [false, false]);
        segs[2].current[700] = f64::NAN;
        assert_eq!(lanes(&data(&segs)), [false, false]);
    }

    #[test]
    fn normal_equations_are_nalgebras_to_the_bit() {
        // Lengths around the blocks of eight and of rows, values of every
        // magnitude and sign.
        for m in [1, 7, 8, 9, 31, 511, 512, 513, 1003, 2 * PRODUCT_BLOCK + 5] {
            let jac = OMatrix::<f64, Dyn, U6>::from_fn(m, |r, c| {
                let x = ((r * 7919 + c * 104_729) % 1009) as f64 - 504.0;
                x * 10f64.powi((r % 7) as i32 - 3) / (1.0 + c as f64)
            });
            let r = DVector::from_fn(m, |k, _| ((k * 31) % 17) as f64 * 0.37 - 3.1);
            let (jtj, g) = normal_equations(&jac, &r);
            let first = jac.column(0).into_owned();
            assert_eq!(
                dot(first.as_slice(), r.as_slice()).to_bits(),
                first.dot(&r).to_bits(),
                "dot, {m} rows"
            );
            let (want_jtj, want_g) = (jac.tr_mul(&jac), jac.tr_mul(&r));
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(jtj.as_slice()),
                bits(want_jtj.as_slice()),
                "JᵀJ, {m} rows"
            );
            assert_eq!(bits(g.as_slice()), bits(want_g.as_slice()), "Jᵀr, {m} rows");
            assert_eq!(
                bits(jtj.as_slice()),
                bits(normal_equations_kernel(&jac, &r).0.as_slice()),
                "the baseline kernel, {m} rows"
            );
        }
    }

    #[test]
    fn refused_parameters_give_a_large_finite_residual() {
        on_seed_staircase(|p| {
            let far = Vector6::new(0.0, -30.0, 0.0, 0.0, 0.0, 0.0);
            let r = p.compute(&far);
            assert!(r.iter().all(|v| *v == REFUSED));
            assert!(r.norm().is_finite());
        });
    }
}
