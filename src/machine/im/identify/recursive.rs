//! The seed paper's recursive estimator (Eqs. 22–24, the ten steps of
//! Sec. III, and the current + power version of Eqs. 25–27).
//!
//! One iteration is one pass over the data. Within a pass every prediction
//! and derivative is taken at the pass's start `θ0` (Eqs. 22 and 24):
//!
//! ```text
//! W_i = W_{i−1} − W_{i−1}·G_i·G_iᵀ·W_{i−1} / (1 + G_iᵀ·W_{i−1}·G_i)     (23)
//! θ_i = θ_{i−1} + W_i·G_i·[y_i − Y(s_i, θ0)]                            (22)
//! ```
//!
//! After the pass (steps 8–10): stop if a component of `θ_N` is negative;
//! stop successfully if `J(θ_N)` is below the threshold; otherwise keep `θ0`
//! and halve `W0` when `J(θ_N) > J(θ0)`, or take `θ0 = θ_N`, `W0 = W_N`.
//! With power data the pass runs over the N current points, then the N
//! power points with `G_i = ∂P/∂θ` (Eqs. 26–27); the cost is Eq. 25.
//!
//! Eq. 22 as printed uses the innovation `y_i − Y(s_i, θ0)` at every step
//! although `θ` has already moved within the pass. Recursive least squares
//! on the model linearised at `θ0` would use
//! `y_i − Y(s_i, θ0) − G_iᵀ·(θ_{i−1} − θ0)`, and then `θ_N` is the
//! Gauss–Newton step regularised by `W0⁻¹`. [`Innovation`] selects either;
//! the paper's form is the default. The derivatives are analytic (the
//! appendix's for the single cage, and through the complex impedance for
//! every model: [`super::sweep::predict_gradient`]).

use nalgebra::{DMatrix, DVector};

use super::sweep::{Channels, PhaseData};
use crate::model::{ImCircuit, ImParam};

/// The paper's θ of Eq. 17, single cage with iron loss, l = 6.
pub const THETA_SINGLE_FE_L6: [ImParam; 6] = [
    ImParam::Rr,
    ImParam::Xr,
    ImParam::Xs,
    ImParam::Rs,
    ImParam::Xm,
    ImParam::Rfe,
];
/// The paper's θ of Eq. 18, single cage, `Rs` and `Rfe` known, l = 4.
pub const THETA_SINGLE_L4: [ImParam; 4] = [ImParam::Rr, ImParam::Xr, ImParam::Xs, ImParam::Xm];
/// The paper's θ of Eq. 19, double cage, `Rs` and `Xm` known, l = 5.
pub const THETA_DOUBLE_L5: [ImParam; 5] = [
    ImParam::Rr1,
    ImParam::Rr2,
    ImParam::Xr1,
    ImParam::Xr2,
    ImParam::Xs,
];
/// The paper's θ of Eq. 20, double cage, l = 7.
pub const THETA_DOUBLE_L7: [ImParam; 7] = [
    ImParam::Rr1,
    ImParam::Rr2,
    ImParam::Xr1,
    ImParam::Xr2,
    ImParam::Xs,
    ImParam::Rs,
    ImParam::Xm,
];

/// Which innovation drives the update within a pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Innovation {
    /// Eq. 22 as printed: `y_i − Y(s_i, θ0)`.
    AsPrinted,
    /// Recursive least squares on the model linearised at `θ0`:
    /// `y_i − Y(s_i, θ0) − G_iᵀ·(θ_{i−1} − θ0)`.
    Linearised,
}

/// Settings of the recursive estimator; the defaults are the paper's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecursiveOptions {
    /// `W0 = w0·I` (step 2: 10³).
    pub w0: f64,
    /// Successful stop when `J` falls below this (step 9: 10⁻⁴).
    pub j_threshold: f64,
    /// Most passes (the paper reports 10 in simulation, 50 on its machine).
    pub max_iterations: usize,
    /// Current only (Eq. 15) or current and power (Eq. 25).
    pub channels: Channels,
    /// The innovation of Eq. 22.
    pub innovation: Innovation,
}

impl Default for RecursiveOptions {
    fn default() -> Self {
        RecursiveOptions {
            w0: 1e3,
            j_threshold: 1e-4,
            max_iterations: 50,
            channels: Channels::CurrentAndPower,
            innovation: Innovation::AsPrinted,
        }
    }
}

/// Why the estimator stopped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RecursiveStop {
    /// Step 9: `J` fell below the threshold.
    Threshold,
    /// Step 8: a pass proposed a negative (non-physical) parameter.
    NonPhysical {
        /// The first negative parameter.
        param: ImParam,
        /// Its proposed value.
        value: f64,
    },
    /// The iteration limit was reached.
    MaxIterations,
    /// A pass produced a non-finite value.
    Numerical,
}

/// The estimator's result.
#[derive(Debug, Clone, PartialEq)]
pub struct RecursiveEstimate {
    /// The last accepted parameters (θ0 of the last pass, or θ_N on a
    /// successful stop).
    pub circuit: ImCircuit,
    /// The parameters estimated, in the order used.
    pub free: Vec<ImParam>,
    /// Passes run.
    pub iterations: usize,
    /// `J` of [`RecursiveEstimate::circuit`] (Eq. 15 or 25).
    pub cost: f64,
    /// `J(θ0)` at the start of every pass, then the final cost.
    pub cost_history: Vec<f64>,
    /// Why it stopped.
    pub stop: RecursiveStop,
}

impl RecursiveEstimate {
    /// Whether the paper's own success test (step 9) was met.
    pub fn succeeded(&self) -> bool {
        self.stop == RecursiveStop::Threshold
    }
}

/// The paper's cost: Eq. 15 with the current (`J`), or Eq. 25 (`J_ip`),
/// the mean squared current error plus the mean squared power error, in
/// the units of `data`.
pub fn paper_cost(data: &PhaseData, circuit: &ImCircuit, channels: Channels) -> f64 {
    let n = data.len() as f64;
    let (mut ji, mut jp) = (0.0, 0.0);
    for k in 0..data.len() {
        let (i, p) = data.predict(circuit, k);
        ji += (data.current[k] - i).powi(2);
        jp += (data.power[k] - p).powi(2);
    }
    if channels.uses_power() {
        (ji + jp) / n
    } else {
        ji / n
    }
}

fn with_values(start: &ImCircuit, free: &[ImParam], theta: &DVector<f64>) -> Option<ImCircuit> {
    let mut c = *start;
    for (k, &p) in free.iter().enumerate() {
        c.set(p, theta[k]).ok()?;
    }
    Some(c)
}

/// Steps 3–7: one pass of Eqs. 22–23 (and 26–27) over the data from
/// `circuit0` (θ0) with weighting matrix `w0`; returns `θ_N` (in the order
/// of `free`) and `W_N`.
pub fn recursive_pass(
    data: &PhaseData,
    circuit0: &ImCircuit,
    free: &[ImParam],
    w0: &DMatrix<f64>,
    channels: Channels,
    innovation: Innovation,
) -> (DVector<f64>, DMatrix<f64>) {
    let theta0 = DVector::from_iterator(
        free.len(),
        free.iter().map(|&p| circuit0.get(p).unwrap_or(f64::NAN)),
    );
    let mut theta = theta0.clone();
    let mut w = w0.clone();
    let channel_count = if channels.uses_power() { 2 } else { 1 };
    for channel in 0..channel_count {
        for k in 0..data.len() {
            let (i, p, di, dp) = data.predict_gradient(circuit0, k, free);
            let (y, model, grad) = if channel == 0 {
                (data.current[k], i, di)
            } else {
                (data.power[k], p, dp)
            };
            let g = DVector::from_vec(grad);
            let wg = &w * &g;
            let denom = 1.0 + g.dot(&wg);
            w -= &wg * wg.transpose() / denom;
            let mut e = y - model;
            if innovation == Innovation::Linearised {
                e -= g.dot(&(&theta - &theta0));
            }
            theta += &w * &g * e;
        }
    }
    (theta, w)
}

/// Run the recursive estimator from `start`, adjusting `free` (the other
/// elements stay at their `start` values).
pub fn recursive_estimate(
    data: &PhaseData,
    start: &ImCircuit,
    free: &[ImParam],
    opts: &RecursiveOptions,
) -> RecursiveEstimate {
    let l = free.len();
    let mut circuit0 = *start;
    let mut w0 = DMatrix::<f64>::identity(l, l) * opts.w0;
    let mut j0 = paper_cost(data, &circuit0, opts.channels);
    let mut history = Vec::new();
    let finish = |circuit: ImCircuit, iterations, cost, mut history: Vec<f64>, stop| {
        history.push(cost);
        RecursiveEstimate {
            circuit,
            free: free.to_vec(),
            iterations,
            cost,
            cost_history: history,
            stop,
        }
    };
    if j0 < opts.j_threshold {
        return finish(circuit0, 0, j0, history, RecursiveStop::Threshold);
    }
    for iteration in 1..=opts.max_iterations {
        history.push(j0);
        // Steps 3–7: one pass over the data, everything evaluated at θ0.
        let (theta, w) = recursive_pass(data, &circuit0, free, &w0, opts.channels, opts.innovation);
        if theta.iter().any(|x| !x.is_finite()) {
            return finish(circuit0, iteration, j0, history, RecursiveStop::Numerical);
        }
        // Step 8: a negative component has no physical meaning.
        if let Some(k) = (0..l).find(|&k| theta[k] <= 0.0) {
            let stop = RecursiveStop::NonPhysical {
                param: free[k],
                value: theta[k],
            };
            return finish(circuit0, iteration, j0, history, stop);
        }
        let Some(circuit_n) = with_values(start, free, &theta) else {
            return finish(circuit0, iteration, j0, history, RecursiveStop::Numerical);
        };
        let jn = paper_cost(data, &circuit_n, opts.channels);
        // Step 9.
        if jn < opts.j_threshold {
            return finish(circuit_n, iteration, jn, history, RecursiveStop::Threshold);
        }
        // Step 10.
        if jn > j0 {
            w0 /= 2.0;
        } else {
            circuit0 = circuit_n;
            w0 = w;
            j0 = jn;
        }
    }
    finish(
        circuit0,
        opts.max_iterations,
        j0,
        history,
        RecursiveStop::MaxIterations,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{slip_grid, SlipSweep, SweepNoise};
    use crate::model::im_fixtures::supply;
    use crate::model::{Connection, RotorCage};

    fn machine() -> ImCircuit {
        ImCircuit {
            rs: 0.03,
            xs: 0.08,
            xm: 2.5,
            rfe: None,
            rotor: RotorCage::Single { rr: 0.03, xr: 0.09 },
        }
    }

    fn data(c: &ImCircuit) -> PhaseData {
        SlipSweep::simulate_seeded(
            c,
            &supply(1.0, 50.0, Connection::Delta, 2),
            &slip_grid(40, 0.002),
            &SweepNoise::default(),
            3,
        )
        .phase_data()
    }

    /// A start near `c` for Rr, Xr and Xm: its Xm times `xm_factor`, its
    /// single cage `rr`, `xr`.
    fn near(c: ImCircuit, xm_factor: f64, rr: f64, xr: f64) -> ImCircuit {
        let mut start = c;
        start.xm *= xm_factor;
        start.rotor = RotorCage::Single { rr, xr };
        start
    }

    #[test]
    fn exact_start_stops_at_once_on_the_threshold() {
        let c = machine();
        let est = recursive_estimate(
            &data(&c),
            &c,
            &THETA_SINGLE_L4,
            &RecursiveOptions::default(),
        );
        assert_eq!(est.stop, RecursiveStop::Threshold);
        assert_eq!(est.iterations, 0);
    }

    /// Readings of a winding whose Rs rose point by point: with each
    /// point's scale the true circuit is already the answer (the cost is
    /// zero at once); read as one Rs it is not.
    #[test]
    fn each_point_sees_rs_at_its_own_scale() {
        let c = machine();
        let mut d = data(&c);
        d.rs_scale = (0..d.len()).map(|k| 1.0 + 0.005 * k as f64).collect();
        for k in 0..d.len() {
            (d.current[k], d.power[k]) = d.predict(&c, k);
        }
        let est = recursive_estimate(&d, &c, &THETA_SINGLE_L4, &RecursiveOptions::default());
        assert_eq!((est.stop, est.iterations), (RecursiveStop::Threshold, 0));
        assert_eq!(est.cost, 0.0);
        let one_rs = PhaseData {
            rs_scale: Vec::new(),
            ..d
        };
        assert!(paper_cost(&one_rs, &c, Channels::CurrentAndPower) > 0.0);
    }

    #[test]
    fn linearised_pass_is_the_regularised_gauss_newton_step() {
        // Recursive least squares on the linearised model equals the batch
        // solution θ0 + (W0⁻¹ + ΣGGᵀ)⁻¹·ΣG·r (matrix inversion lemma).
        let c = machine();
        let d = data(&c);
        let start = near(c, 1.03, 0.031, 0.088);
        let free = [ImParam::Rr, ImParam::Xr, ImParam::Xm];
        let w0 = DMatrix::identity(3, 3) * 1e3;
        let mut info = DMatrix::identity(3, 3) * 1e-3;
        let mut rhs = DVector::zeros(3);
        for k in 0..d.len() {
            let (i, p, di, dp) = d.predict_gradient(&start, k, &free);
            for (g, r) in [(di, d.current[k] - i), (dp, d.power[k] - p)] {
                let g = DVector::from_vec(g);
                info += &g * g.transpose();
                rhs += &g * r;
            }
        }
        let step = info.clone().try_inverse().unwrap() * &rhs;
        let theta0 = DVector::from_vec(vec![0.031, 0.088, start.xm]);
        let (lin, w) = recursive_pass(
            &d,
            &start,
            &free,
            &w0,
            Channels::CurrentAndPower,
            Innovation::Linearised,
        );
        assert!(
            (&lin - (&theta0 + &step)).norm() < 1e-9 * step.norm(),
            "{lin} vs {}",
            &theta0 + &step
        );
        assert!((w - info.try_inverse().unwrap()).norm() < 1e-9);
        // Eq. 22 as printed takes the same information but re-uses the full
        // innovation at every point: it overshoots the Gauss–Newton step.
        let (printed, _) = recursive_pass(
            &d,
            &start,
            &free,
            &w0,
            Channels::CurrentAndPower,
            Innovation::AsPrinted,
        );
        assert!(
            (&printed - &theta0).norm() > 1.5 * step.norm(),
            "{printed} vs GN {}",
            &theta0 + &step
        );
    }

    #[test]
    fn linearised_estimator_converges_from_a_near_start() {
        let c = machine();
        let start = near(c, 1.05, 0.033, 0.085);
        let free = [ImParam::Rr, ImParam::Xr, ImParam::Xm];
        let opts = RecursiveOptions {
            j_threshold: 1e-8,
            max_iterations: 200,
            innovation: Innovation::Linearised,
            ..Default::default()
        };
        let est = recursive_estimate(&data(&c), &start, &free, &opts);
        assert_eq!(est.stop, RecursiveStop::Threshold, "{est:?}");
        assert!(est.cost_history.windows(2).all(|w| w[1] <= w[0]));
        // Step 10 carries W_N into the next pass, so the gain shrinks like
        // 1/pass: the first pass does most of the work, the tail is slow.
        assert!(est.cost_history[1] < 1e-3 * est.cost_history[0]);
        assert!(est.iterations > 20, "{} passes", est.iterations);
    }

    #[test]
    fn a_pass_that_goes_negative_stops_as_non_physical() {
        let c = machine();
        let mut start = c;
        start.rotor = RotorCage::Single { rr: 0.3, xr: 0.9 };
        start.xs = 0.01;
        let opts = RecursiveOptions {
            w0: 1e6,
            ..Default::default()
        };
        let est = recursive_estimate(&data(&c), &start, &THETA_SINGLE_L4, &opts);
        assert!(
            matches!(est.stop, RecursiveStop::NonPhysical { .. }),
            "{:?}",
            est.stop
        );
        assert_eq!(est.circuit, start);
    }

    #[test]
    fn w0_halves_when_the_cost_grows() {
        // From Xm 20 % high the printed update overshoots: passes that raise
        // J are rejected (θ0 kept, W0 halved) until one lowers it.
        let c = machine();
        let mut start = c;
        start.xm = 3.0;
        let opts = RecursiveOptions {
            max_iterations: 40,
            ..Default::default()
        };
        let est = recursive_estimate(&data(&c), &start, &[ImParam::Xm], &opts);
        assert_eq!(est.stop, RecursiveStop::Threshold);
        let rejected = est.cost_history.windows(2).filter(|w| w[1] == w[0]).count();
        assert!(rejected >= 1, "no rejected pass: {:?}", est.cost_history);
        assert!(est.cost_history.windows(2).all(|w| w[1] <= w[0]));
        assert!(
            (est.circuit.xm - 2.5).abs() < 0.025,
            "Xm = {}",
            est.circuit.xm
        );
    }
}
