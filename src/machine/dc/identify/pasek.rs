//! Pasek's method (the seed paper's Eqs. 10–20): La and J from the peak of
//! the armature current after a voltage step.
//!
//! From one step: t1, the time of the current peak after the (equivalent)
//! step instant; δ = Δi(2·t1)/Δi(t1) (Eq. 16); λ = τm/τe and t1/τe from
//! the abacus ([`super::abacus`], computed from the exact response rather
//! than the paper's closed forms); then τe = t1/(t1/τe), τm = λ·τe,
//! La = Ra·τe, J = τm·(K² + Ra·f)/Ra. Ra, K and the f in μ come from the
//! steady-state fit; the reported f is Eq. 19 on this step's current gain
//! and Tst is Eq. 20 (with K, not the current gain: see `steady_state`).
//!
//! The method needs real poles (λ ≥ λ*(μ) ≈ 4). The data shows complex
//! poles as a current that undershoots its final value after the peak
//! (impossible with real poles: the response then approaches its final
//! value from above, a sum of two exponentials with one sign change at
//! most), or as a δ below the abacus's range. Either way the method says
//! it does not apply, with the reason, instead of giving numbers.

use super::abacus::{invert_delta, real_pole_threshold};
use super::error::NotApplicable;
use super::step::VoltageStep;
use super::SteadyStateEstimate;
use crate::model::DcParams;
use crate::record::DcSegment;

/// What the current trace of one step gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PasekReading {
    /// Time of the current peak after the equivalent step instant, s.
    pub t1: f64,
    /// Δi(t1), A (signed like ΔU).
    pub di_t1: f64,
    /// Δi(2·t1), A.
    pub di_2t1: f64,
    /// δ = Δi(2·t1)/Δi(t1).
    pub delta: f64,
}

/// Pasek's estimate from one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PasekEstimate {
    /// Segment of the step.
    pub segment: u32,
    /// The current trace's reading.
    pub reading: PasekReading,
    /// μ = Ra·f/(K² + Ra·f) from the steady-state fit.
    pub mu: f64,
    /// λ = τm/τe from the abacus.
    pub lambda: f64,
    /// t1/τe from the abacus.
    pub x1: f64,
    /// τe, s.
    pub tau_e: f64,
    /// τm, s.
    pub tau_m: f64,
    /// The full parameter set: Ra, K from the steady state; La, J from
    /// the abacus; f from Eq. 19; Tst from Eq. 20.
    pub params: DcParams,
}

/// The coefficients of the least-squares cubic through `(x, y)`,
/// `c0 + c1·x + c2·x² + c3·x³`, with x centred on `x0` by the caller.
fn cubic_fit(x: &[f64], y: &[f64]) -> Option<[f64; 4]> {
    if x.len() < 6 {
        return None;
    }
    let a = nalgebra::DMatrix::from_fn(x.len(), 4, |r, c| x[r].powi(c as i32));
    let b = nalgebra::DVector::from_column_slice(y);
    let ls = crate::identify::stats::least_squares(&a, &b)?;
    Some([ls.x[0], ls.x[1], ls.x[2], ls.x[3]])
}

fn cubic(c: &[f64; 4], x: f64) -> f64 {
    c[0] + x * (c[1] + x * (c[2] + x * c[3]))
}

/// Samples of `z` (time `tau`) within `h` of `centre`, centred.
fn window(tau: &[f64], z: &[f64], centre: f64, h: f64) -> (Vec<f64>, Vec<f64>) {
    tau.iter()
        .zip(z)
        .filter(|(t, _)| (**t - centre).abs() <= h)
        .map(|(t, v)| (t - centre, *v))
        .unzip()
}

/// Read t1, Δi(t1), Δi(2·t1) off the current of `step` on `seg`.
///
/// The peak is located roughly on a 5-sample moving average, then refined
/// by a least-squares cubic over ±30 % of t1 (its stationary point: a
/// parabola's vertex would be biased by the peak's asymmetry); Δi(2·t1)
/// is the same kind of cubic evaluated at 2·t1. Errors say why the trace
/// gives no reading, complex poles included.
pub fn read_current_peak(
    seg: &DcSegment,
    step: &VoltageStep,
) -> Result<PasekReading, NotApplicable> {
    let s = step.du().signum();
    let i0 = step.before.current;
    let z_final = s * step.di_final();
    let (tau, z): (Vec<f64>, Vec<f64>) = (0..step.tail_start)
        .filter(|&k| seg.time[k] > step.t_step)
        .map(|k| (seg.time[k] - step.t_step, s * (seg.current[k] - i0)))
        .unzip();
    let w = 5usize;
    if z.len() < 4 * w {
        return Err(NotApplicable::Missing(
            "too few samples between the step and the settled tail".into(),
        ));
    }
    let smooth: Vec<f64> = (0..=z.len() - w)
        .map(|k| z[k..k + w].iter().sum::<f64>() / w as f64)
        .collect();
    let (kmax, zmax) = smooth
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(k, v)| (k, *v))
        .expect("non-empty");
    let noise = step.current_noise / (w as f64).sqrt();
    let hump = zmax - z_final;
    if kmax + 1 >= smooth.len() || hump <= 5.0 * noise {
        return Err(NotApplicable::Missing(format!(
            "the current shows no peak above its final value (hump {:.3e} A, noise {:.1e} A): \
             no transient to read",
            hump, step.current_noise
        )));
    }
    // Complex poles: the current undershoots its final value after the peak.
    let undershoot = z_final - smooth[kmax..].iter().fold(f64::INFINITY, |m, v| m.min(*v));
    if undershoot > 4.0 * noise + 0.01 * hump {
        return Err(NotApplicable::Unidentifiable(format!(
            "the current undershoots its final value by {:.3e} A after its peak \
             ({:.1} % of the peak's rise above it): the poles are complex, and Pasek's \
             method needs real ones",
            undershoot,
            100.0 * undershoot / hump
        )));
    }
    let rough = tau[kmax + w / 2];
    let dt = tau[1] - tau[0];
    let h = (0.3 * rough).max(4.0 * dt);
    let (x, y) = window(&tau, &z, rough, h);
    let c = cubic_fit(&x, &y)
        .ok_or_else(|| NotApplicable::Missing("too few samples around the current peak".into()))?;
    // Stationary points of the cubic: c1 + 2c2·u + 3c3·u² = 0, nearest 0.
    let (qa, qb, qc) = (3.0 * c[3], 2.0 * c[2], c[1]);
    let u = if qa.abs() < 1e-300 {
        -qc / qb
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 {
            return Err(NotApplicable::Unidentifiable(
                "the current peak could not be located".into(),
            ));
        }
        let r = disc.sqrt();
        let (u1, u2) = ((-qb + r) / (2.0 * qa), (-qb - r) / (2.0 * qa));
        if u1.abs() < u2.abs() {
            u1
        } else {
            u2
        }
    };
    if u.abs() > h {
        return Err(NotApplicable::Unidentifiable(
            "the current peak could not be located".into(),
        ));
    }
    let t1 = rough + u;
    let di_t1 = cubic(&c, u);
    let last = tau[tau.len() - 1];
    if 2.0 * t1 + h > last {
        return Err(NotApplicable::Missing(format!(
            "2·t1 = {:.4} s is too close to the settled tail (it starts {:.4} s after the step)",
            2.0 * t1,
            last
        )));
    }
    let (x, y) = window(&tau, &z, 2.0 * t1, h);
    let c2 = cubic_fit(&x, &y)
        .ok_or_else(|| NotApplicable::Missing("too few samples around 2·t1".into()))?;
    let di_2t1 = cubic(&c2, 0.0);
    Ok(PasekReading {
        t1,
        di_t1: s * di_t1,
        di_2t1: s * di_2t1,
        delta: di_2t1 / di_t1,
    })
}

/// μ = Ra·f/(K² + Ra·f).
pub fn mu(ss: &SteadyStateEstimate) -> f64 {
    ss.ra * ss.f / (ss.k * ss.k + ss.ra * ss.f)
}

/// The parameters from an abacus reading `(λ, t1/τe)` and t1, with K, Ra
/// and f (for J) from the steady state, f from Eq. 19 on the step's
/// current gain `di_final` (for a step `du`) and Tst from Eq. 20 at the
/// pre-step level `(i0, ω0)`.
#[allow(clippy::too_many_arguments)]
pub fn params_from_abacus(
    t1: f64,
    lambda: f64,
    x1: f64,
    ss: &SteadyStateEstimate,
    du: f64,
    di_final: f64,
    i0: f64,
    w0: f64,
) -> (f64, f64, DcParams) {
    let tau_e = t1 / x1;
    let tau_m = lambda * tau_e;
    let d = ss.k * ss.k + ss.ra * ss.f;
    // Eq. 19: f = K²·Ki/(ΔU − Ra·Ki).
    let f = ss.k * ss.k * di_final / (du - ss.ra * di_final);
    let params = DcParams {
        ra: ss.ra,
        la: ss.ra * tau_e,
        k: ss.k,
        j: tau_m * d / ss.ra,
        f,
        // Eq. 20 (Eq. 44): Tst = K·i0 − f·ω0, signed for the direction of turning.
        tst: (ss.k * i0 - f * w0) * w0.signum(),
    };
    (tau_e, tau_m, params)
}

/// Pasek's estimate from one step, or why the method does not apply.
pub fn estimate(
    seg: &DcSegment,
    step: &VoltageStep,
    ss: &SteadyStateEstimate,
) -> Result<PasekEstimate, NotApplicable> {
    let mu = mu(ss);
    if !(0.0..1.0).contains(&mu) {
        return Err(NotApplicable::Unidentifiable(format!(
            "μ = {mu:.4} from the steady-state fit is outside [0, 1)"
        )));
    }
    let reading = read_current_peak(seg, step)?;
    let (lambda, x1) = invert_delta(reading.delta, mu).map_err(|e| {
        NotApplicable::Unidentifiable(format!(
            "{e} (real poles need λ = τm/τe ≥ {:.3} at μ = {mu:.4}); Pasek's method does not apply",
            real_pole_threshold(mu)
        ))
    })?;
    let (tau_e, tau_m, params) = params_from_abacus(
        reading.t1,
        lambda,
        x1,
        ss,
        step.du(),
        step.di_final(),
        step.before.current,
        step.before.speed,
    );
    Ok(PasekEstimate {
        segment: step.segment,
        reading,
        mu,
        lambda,
        x1,
        tau_e,
        tau_m,
        params,
    })
}

#[cfg(test)]
mod tests {
    use super::super::abacus::{paper_delta, paper_t1_over_tau_e, CurrentStep};
    use super::super::recorded::recorded;
    use super::*;
    use crate::identify::SettledLevel;
    use crate::model::DcParams;

    /// The paper's Table 2 and Table 4 numbers.
    const RA: f64 = 30.9;
    const K: f64 = 1.323;
    const F: f64 = 0.0005;
    const T1: f64 = 0.026;

    fn seed_ss() -> SteadyStateEstimate {
        SteadyStateEstimate {
            k: K,
            ra: RA,
            f: F,
            tst: 0.128,
        }
    }

    #[test]
    fn paper_fig4_readings_against_its_own_model() {
        let mu = mu(&seed_ss());
        assert!((mu - 0.00874).abs() < 1e-4, "the paper's μ: {mu}");
        // The exact response at the paper's λ = 4.5 gives neither its δ nor
        // its t1/τe.
        let c = CurrentStep::new(4.5, mu).unwrap();
        let (d_exact, x_exact) = (c.delta().unwrap(), c.peak().unwrap());
        assert!((d_exact - 0.79).abs() > 0.03, "δ(4.5) = {d_exact}");
        assert!((x_exact - 1.82).abs() > 0.2, "t1/τe(4.5) = {x_exact}");
        // Inverted exactly, δ = 0.79 means λ ≈ 6.3 and t1/τe ≈ 2.3.
        let (lambda, x1) = invert_delta(0.79, mu).unwrap();
        assert!(lambda > 6.0 && lambda < 6.6, "λ = {lambda}");
        assert!(x1 > 2.2 && x1 < 2.4, "t1/τe = {x1}");
        // No real-pole response peaks before t1/τe = 2: the abacus's
        // minimum is at the threshold, so the reading 1.82 cannot come
        // from real poles at all.
        let x_min = CurrentStep::new(real_pole_threshold(mu) * (1.0 + 1e-9), mu)
            .unwrap()
            .peak()
            .unwrap();
        assert!(x_min > 1.99 && x_min < 2.02, "x1 at the threshold: {x_min}");
        // The printed closed forms agree with neither: Eq. 15 gives 1.96
        // at λ = 4.5, and Eq. 17 (with the appendix's L2) gives δ = 0.52.
        let x15 = paper_t1_over_tau_e(4.5, mu).unwrap();
        let d17 = paper_delta(4.5, mu).unwrap();
        assert!(
            (x15 - 1.82).abs() > 0.1 && (x15 - x_exact).abs() > 0.1,
            "Eq. 15: {x15}"
        );
        assert!(
            (d17 - 0.79).abs() > 0.2 && (d17 - d_exact).abs() > 0.2,
            "Eq. 17: {d17}"
        );
    }

    #[test]
    fn closed_forms_hold_for_mu_zero_only() {
        // Pasek's original (μ = 0): Eqs. 15 and 17 are the exact abacus.
        for lambda in [4.1, 4.5, 6.0, 10.0, 50.0] {
            let c = CurrentStep::new(lambda, 0.0).unwrap();
            let x15 = paper_t1_over_tau_e(lambda, 0.0).unwrap();
            let d17 = paper_delta(lambda, 0.0).unwrap();
            assert!((x15 - c.peak().unwrap()).abs() < 1e-9, "λ {lambda}");
            assert!((d17 - c.delta().unwrap()).abs() < 1e-9, "λ {lambda}");
        }
        // With friction (μ > 0) Eq. 15 misplaces the peak by several percent
        // and Eq. 17 (its L2 carries r^(+1/a) where L1 has r^(−1/a)) is not
        // even monotone: it falls through zero as λ grows.
        let mu = 0.00874;
        for lambda in [4.5, 6.0, 10.0] {
            let c = CurrentStep::new(lambda, mu).unwrap();
            let x15 = paper_t1_over_tau_e(lambda, mu).unwrap();
            let rel = (x15 - c.peak().unwrap()) / c.peak().unwrap();
            assert!(rel < -0.03, "λ {lambda}: Eq. 15 off by {rel}");
        }
        assert!(paper_delta(4.5, mu).unwrap() > paper_delta(6.0, mu).unwrap());
        assert!(paper_delta(10.0, mu).unwrap() < 0.0);
    }

    #[test]
    fn paper_table4_pasek_column_from_its_readings() {
        let ss = seed_ss();
        let (i0, w0) = (0.113, 400.0 * std::f64::consts::TAU / 60.0);
        let (du, di) = (188.0, 0.167 - 0.113);
        // The paper's readings λ = 4.5, t1/τe = 1.82 with t1 = 0.026 s.
        let (_, _, p) = params_from_abacus(T1, 4.5, 1.82, &ss, du, di, i0, w0);
        // Table 4: La 0.438 H, J 0.0036 (t1 is printed to two digits:
        // 0.0258 s would give 0.438 exactly).
        assert!(((p.la - 0.438) / 0.438).abs() < 0.01, "La = {}", p.la);
        assert!(((p.j - 0.0036) / 0.0036).abs() < 0.025, "J = {}", p.j);
        // f from Eq. 19 is Table 4's 0.0005; Tst from Eq. 20 its 0.128.
        assert!((p.f - 0.0005).abs() < 0.00002, "f = {}", p.f);
        assert!((p.tst - 0.128).abs() < 0.002, "Tst = {}", p.tst);
        // The exact abacus from the same δ = 0.79 and t1: La 0.35 H and
        // J 0.0040, still far from the moments column (0.803 H, 0.0031):
        // the paper's own conclusion is that its poles are complex, where
        // no reading of the abacus is meaningful.
        let (lambda, x1) = invert_delta(0.79, mu(&ss)).unwrap();
        let (_, _, e) = params_from_abacus(T1, lambda, x1, &ss, du, di, i0, w0);
        assert!((e.la - 0.3456).abs() < 0.005, "La = {}", e.la);
        assert!((e.j - 0.00403).abs() < 0.0001, "J = {}", e.j);
        let moments = DcParams::SEED_TABLE4_MOMENTS;
        let lambda_m = moments.tau_m() / moments.tau_e();
        assert!(lambda_m < real_pole_threshold(mu(&ss)), "λ = {lambda_m}");
    }

    /// A noisy step record of `p` from `u0` to `u1`, dt, `n` samples.
    fn step_segment(p: &DcParams, u0: f64, u1: f64, dt: f64, n: usize, noise: f64) -> DcSegment {
        let (mut seg, _) = recorded(
            p,
            dt,
            p.steady_state(u0),
            n,
            |k| if k == 0 { u0 } else { u1 },
        );
        seg.index = 1;
        let mut seed = 0x2545f4914f6cdd1du64;
        let mut gauss = || {
            // Sum of 12 uniforms: close enough to normal for a test.
            (0..12)
                .map(|_| {
                    seed ^= seed << 13;
                    seed ^= seed >> 7;
                    seed ^= seed << 17;
                    (seed >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        for current in &mut seg.current {
            *current += noise * gauss();
        }
        seg
    }

    fn levels(p: &DcParams, u0: f64, u1: f64, samples: usize) -> (SettledLevel, SettledLevel) {
        (
            SettledLevel::exact(p, u0, 0, samples),
            SettledLevel::exact(p, u1, 1, samples),
        )
    }

    #[test]
    fn recovers_la_and_j_with_real_poles() {
        // La 0.1 H: λ ≈ 17.
        let p = DcParams {
            la: 0.1,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        let seg = step_segment(&p, 60.0, 150.0, 2e-4, 8000, 0.002);
        let (b, a) = levels(&p, 60.0, 150.0, 2000);
        let step = super::super::step::voltage_step(&seg, &b, &a).unwrap();
        let ss = SteadyStateEstimate::of(&p);
        let e = estimate(&seg, &step, &ss).unwrap();
        let lambda = p.tau_m() / p.tau_e();
        assert!(
            ((e.lambda - lambda) / lambda).abs() < 0.05,
            "λ {} vs {lambda}",
            e.lambda
        );
        assert!(
            ((e.params.la - p.la) / p.la).abs() < 0.03,
            "La {}",
            e.params.la
        );
        assert!(((e.params.j - p.j) / p.j).abs() < 0.03, "J {}", e.params.j);
    }

    #[test]
    fn complex_poles_are_refused_with_a_reason() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let seg = step_segment(&p, 60.0, 248.0, 5e-4, 3000, 0.002);
        let (b, a) = levels(&p, 60.0, 248.0, 750);
        let step = super::super::step::voltage_step(&seg, &b, &a).unwrap();
        let ss = seed_ss();
        let err = estimate(&seg, &step, &ss).unwrap_err();
        assert!(matches!(err, NotApplicable::Unidentifiable(_)), "{err:?}");
        assert!(err.to_string().contains("complex"), "{err}");
    }
}
