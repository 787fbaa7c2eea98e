//! Coast-down: J and the Coulomb friction from the speed decay with the
//! armature open.
//!
//! With no current, `J·dω/dt = −f·ω − Tc` (for ω > 0), so
//!
//! ```text
//! ω(t) = ω0·e^(−r·t) − g·(1 − e^(−r·t))/r,   r = f/J,  g = Tc/J
//! ```
//!
//! (the exponential of viscous friction plus the linear decay of Coulomb
//! friction; as r → 0 it becomes `ω0 − g·t`). `[ω0, r, g]` are fitted by
//! Levenberg–Marquardt (the `levenberg-marquardt` crate) to the samples
//! between the armature opening and the speed falling under 2 % of its
//! start, started from a linearisation (`ω[k+1] = a·ω[k] + b`, linear
//! least squares). Their covariance is `s²·(JᵀJ)⁻¹` at the optimum.
//!
//! The decay gives f/J and Tc/J only; with f from the steady state,
//! J = f/r and Tc = g·J. On the simulated rig the static torque Tst is a
//! friction opposing motion, so a coast-down there sees Tc = Tst.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned, Vector3, U3};

use super::error::NotApplicable;
use crate::record::DcSegment;

/// The decay fit.
#[derive(Debug, Clone, PartialEq)]
pub struct DecayFit {
    /// Segment index.
    pub segment: u32,
    /// First and one-past-last sample fitted.
    pub range: (usize, usize),
    /// `[ω0 (rad/s), r = f/J (1/s), g = Tc/J (rad/s²)]`.
    pub theta: [f64; 3],
    /// Covariance of `theta`.
    pub covariance: [[f64; 3]; 3],
    /// Residual standard deviation, rad/s.
    pub residual_sd: f64,
}

impl DecayFit {
    /// The fitted speed at `t` seconds after the first fitted sample.
    pub fn speed(&self, t: f64) -> f64 {
        decay(&self.theta, t).0
    }
}

/// `φ(r, t) = (1 − e^(−r·t))/r` and `∂φ/∂r`, stable as r → 0.
fn phi(r: f64, t: f64) -> (f64, f64) {
    let x = r * t;
    if x.abs() < 1e-5 {
        (
            t * (1.0 - x / 2.0 + x * x / 6.0),
            -t * t / 2.0 + r * t.powi(3) / 3.0,
        )
    } else {
        let p = -(-x).exp_m1() / r;
        (p, (t * (-x).exp() - p) / r)
    }
}

/// The model and its gradient `[∂/∂ω0, ∂/∂r, ∂/∂g]` at `t`.
fn decay(theta: &[f64; 3], t: f64) -> (f64, [f64; 3]) {
    let [w0, r, g] = *theta;
    let e = (-r * t).exp();
    let (p, dp) = phi(r, t);
    (w0 * e - g * p, [e, -t * w0 * e - g * dp, -p])
}

struct DecayProblem<'a> {
    t: &'a [f64],
    w: &'a [f64],
    theta: Vector3<f64>,
}

impl LeastSquaresProblem<f64, Dyn, U3> for DecayProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U3>;
    type ParameterStorage = Owned<f64, U3>;

    fn set_params(&mut self, x: &Vector3<f64>) {
        self.theta = *x;
    }

    fn params(&self) -> Vector3<f64> {
        self.theta
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let th = [self.theta[0], self.theta[1], self.theta[2]];
        Some(DVector::from_iterator(
            self.t.len(),
            self.t.iter().zip(self.w).map(|(t, w)| decay(&th, *t).0 - w),
        ))
    }

    fn jacobian(&self) -> Option<nalgebra::OMatrix<f64, Dyn, U3>> {
        let th = [self.theta[0], self.theta[1], self.theta[2]];
        let mut j = nalgebra::OMatrix::<f64, Dyn, U3>::zeros(self.t.len());
        for (row, t) in self.t.iter().enumerate() {
            let (_, g) = decay(&th, *t);
            for c in 0..3 {
                j[(row, c)] = g[c];
            }
        }
        Some(j)
    }
}

/// Fit the decay of `seg` (a coast-down: armature open after its first
/// samples), or say why not.
pub fn fit_decay(seg: &DcSegment) -> Result<DecayFit, NotApplicable> {
    let n = seg.time.len();
    if n < 20 {
        return Err(NotApplicable::Missing(format!(
            "segment {} has too few samples",
            seg.index
        )));
    }
    // The armature is open from the first of 3 samples with current under
    // a tenth of the segment's largest (or 1 mA).
    let peak = seg.current.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let open = (0.1 * peak).max(1e-3);
    let start = (0..n.saturating_sub(3))
        .find(|&k| seg.current[k..k + 3].iter().all(|i| i.abs() <= open))
        .ok_or_else(|| {
            NotApplicable::Missing("the armature current never falls to zero: no coast-down".into())
        })?;
    let w_start = seg.speed[start];
    if w_start == 0.0 {
        return Err(NotApplicable::Missing(
            "the rotor is at rest when the armature opens".into(),
        ));
    }
    let s = w_start.signum();
    let end = (start..n)
        .find(|&k| s * seg.speed[k] < 0.02 * w_start.abs())
        .unwrap_or(n);
    if end - start < 20 {
        return Err(NotApplicable::Missing(format!(
            "only {} samples between the armature opening and rest",
            end - start
        )));
    }
    let t: Vec<f64> = seg.time[start..end]
        .iter()
        .map(|t| t - seg.time[start])
        .collect();
    let w: Vec<f64> = seg.speed[start..end].iter().map(|w| s * w).collect();

    // Start: ω[k+1] = a·ω[k] + b by linear least squares.
    let m = w.len() - 1;
    let a_mat = DMatrix::from_fn(m, 2, |r, c| if c == 0 { w[r] } else { 1.0 });
    let b_vec = DVector::from_fn(m, |r, _| w[r + 1]);
    let dt = t[m] / m as f64;
    let (r0, g0) = match crate::identify::stats::least_squares(&a_mat, &b_vec) {
        Some(ls) if ls.x[0] > 0.0 && ls.x[0] < 1.0 => {
            let r = -ls.x[0].ln() / dt;
            (r, -ls.x[1] / phi(r, dt).0)
        }
        _ => (1e-3 / t[m], (w[0] - w[m]) / t[m]),
    };
    let problem = DecayProblem {
        t: &t,
        w: &w,
        theta: Vector3::new(w[0], r0, g0),
    };
    let (problem, report) = LevenbergMarquardt::new().minimize(problem);
    if !report.termination.was_successful() {
        return Err(NotApplicable::Unidentifiable(format!(
            "the decay fit did not converge ({:?})",
            report.termination
        )));
    }
    let theta = [problem.theta[0], problem.theta[1], problem.theta[2]];
    let res = problem.residuals().expect("finite residuals");
    let jac = problem.jacobian().expect("finite jacobian");
    let dof = (t.len() - 3) as f64;
    let s2 = res.norm_squared() / dof;
    let cov = (jac.transpose() * &jac).try_inverse().ok_or_else(|| {
        NotApplicable::Unidentifiable(
            "the decay does not separate f/J from Tc/J (too short or too straight)".into(),
        )
    })? * s2;
    Ok(DecayFit {
        segment: seg.index,
        range: (start, end),
        theta: [s * theta[0], theta[1], theta[2]],
        covariance: std::array::from_fn(|r| std::array::from_fn(|c| cov[(r, c)])),
        residual_sd: s2.sqrt(),
    })
}

/// J and Tc (and their standard errors) from a decay fit and f with its
/// standard error: `J = f/r`, `Tc = g·f/r`.
pub fn inertia_and_coulomb(fit: &DecayFit, f: f64, f_se: f64) -> ([f64; 2], [f64; 2]) {
    let [_, r, g] = fit.theta;
    let c = &fit.covariance;
    let j = f / r;
    let tc = g * j;
    let rel_f = (f_se / f).powi(2);
    let rel_r = c[1][1] / (r * r);
    let rel_g = c[2][2] / (g * g);
    let rel_rg = c[1][2] / (r * g);
    let j_se = j.abs() * (rel_f + rel_r).sqrt();
    let tc_se = tc.abs() * (rel_f + rel_r + rel_g - 2.0 * rel_rg).max(0.0).sqrt();
    ([j, j_se], [tc, tc_se])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{DcMotor, DcParams, Terminal};

    fn coast(p: &DcParams, w0: f64, dt: f64, quantum: f64) -> DcSegment {
        let motor = DcMotor::new(*p, dt).unwrap();
        let mut x = p.steady_state(p.k * w0);
        let mut seg = DcSegment::default();
        let mut k = 0;
        while k < 20_000 {
            if k > 0 {
                x = motor.step(&x, Terminal::Open);
            }
            // Speed quantised like an encoder's count difference.
            let speed = if quantum > 0.0 {
                (x.speed / quantum).round() * quantum
            } else {
                x.speed
            };
            let current = if k == 0 { x.current } else { 0.0 };
            seg.push_sample(k as f64 * dt, p.k * x.speed, current, speed);
            if x.speed == 0.0 {
                break;
            }
            k += 1;
        }
        seg
    }

    #[test]
    fn decay_gives_j_over_f_and_the_coulomb_torque() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let seg = coast(&p, 180.0, 5e-4, 0.05);
        let fit = fit_decay(&seg).unwrap();
        let [_, r, g] = fit.theta;
        assert!(((r - p.f / p.j) / (p.f / p.j)).abs() < 0.01, "f/J {r}");
        assert!(
            ((g - p.tst / p.j) / (p.tst / p.j)).abs() < 0.005,
            "Tc/J {g}"
        );
        let (j, tc) = inertia_and_coulomb(&fit, p.f, 0.0);
        assert!(((j[0] - p.j) / p.j).abs() < 0.01, "J {j:?}");
        assert!(((tc[0] - p.tst) / p.tst).abs() < 0.01, "Tc {tc:?}");
        // The intervals are of the error's size (1.96 σ covers it).
        assert!((j[0] - p.j).abs() < 1.96 * j[1] * 3.0 && j[1] / j[0] < 0.02);
    }

    #[test]
    fn pure_coulomb_decay_is_a_line() {
        // No viscous friction: r → 0 and the model stays finite.
        let p = DcParams {
            f: 0.0,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        let seg = coast(&p, 100.0, 1e-3, 0.0);
        let fit = fit_decay(&seg).unwrap();
        assert!(fit.theta[1].abs() < 1e-6, "r = {}", fit.theta[1]);
        assert!(((fit.theta[2] - p.tst / p.j) / (p.tst / p.j)).abs() < 1e-6);
    }

    #[test]
    fn a_driven_segment_is_no_coastdown() {
        let seg = DcSegment::held(100, 1e-3, 60.0, 0.11, 40.0);
        assert!(fit_decay(&seg)
            .unwrap_err()
            .to_string()
            .contains("never falls"));
    }
}
