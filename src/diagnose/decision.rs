//! The statistics that turn held-out residuals into a verdict: a paired
//! one-sided test of "the candidate shrinks the held-out gap", corrected
//! for the number of candidates tried, a penalised ranking score, and a
//! noise-level estimate for the noise floor.
//!
//! Why a paired block test: the held-out residuals of the nominal and the
//! augmented model are computed on the same samples, so their difference
//! per block cancels the noise both share. Blocks (a few tens of
//! milliseconds of a DC record, or one operating point of a sweep) make
//! the differences close to independent even when the noise is coloured,
//! so the test's false-alarm rate holds without a noise model. The
//! Bonferroni correction over candidates keeps the family-wise false-alarm
//! rate of a diagnosis at [`FALSE_ALARM_RATE`].

use statrs::distribution::{ContinuousCDF, StudentsT};

pub use crate::identify::stats::median;

/// Family-wise false-alarm rate of one diagnosis: the probability of
/// naming an effect on data that has none. A false alarm costs an
/// engineer a day, so 1 %.
pub const FALSE_ALARM_RATE: f64 = 0.01;

/// Largest held-out NRMSE, in noise floors, of a model that explains the
/// record: at twice the floor three quarters of the residual's power is
/// already structure the model misses.
pub const EXPLAINED: f64 = 2.0;

/// Share of the nominal model's excess over the noise floor (`gap² −
/// floor²`, the residual power that is not noise) that a model with the
/// held-out NRMSE `gap_after` removes.
pub fn explained_share(gap_before: f64, gap_after: f64, noise_floor: f64) -> f64 {
    let excess = |g: f64| g * g - noise_floor * noise_floor;
    1.0 - excess(gap_after) / excess(gap_before)
}

/// The warning for a verdict that leaves more than [`EXPLAINED`] noise
/// floors of held-out NRMSE: what it removed, and that the rest is
/// something else. `None` when it leaves less.
pub fn partial_verdict_warning(
    effect: &str,
    gap_before: f64,
    gap_after: f64,
    noise_floor: f64,
) -> Option<String> {
    (gap_after > EXPLAINED * noise_floor).then(|| {
        format!(
            "{effect}: named as the verdict, though it leaves a held-out NRMSE of {gap_after:.4}, \
             {:.1} times the noise floor {noise_floor:.4}: it removes {:.0} % of the gap's excess \
             over the floor, and the rest is something else (a second effect, or the plant's \
             form of this one differing from the candidate's)",
            gap_after / noise_floor,
            100.0 * explained_share(gap_before, gap_after, noise_floor)
        )
    })
}

/// The warning for a `none` verdict on a gap of more than [`EXPLAINED`]
/// noise floors: no candidate explains it, so the record holds something
/// the model and every candidate lack — an effect outside the list, or a
/// reading at fault (`faults`: the machine's usual suspects). `None` when
/// the gap is within that.
pub fn unexplained_gap_warning(gap_before: f64, noise_floor: f64, faults: &str) -> Option<String> {
    (gap_before > EXPLAINED * noise_floor).then(|| {
        format!(
            "no candidate explains the gap: the nominal model's held-out NRMSE {gap_before:.4} \
             is {:.1} times the noise floor {noise_floor:.4}, so the record holds something \
             the model and its candidates lack: an effect outside the list, or a reading at \
             fault ({faults})",
            gap_before / noise_floor
        )
    })
}

/// Why a nominal model is no baseline to judge effects against, if it is
/// not: it predicts the readings worse than their own mean (a fit NRMSE
/// above 1, which the mean scores), or, fitted without them, the held-out
/// readings. A shrink of such a gap measures nothing about an effect.
pub fn no_baseline(fit_nrmse: f64, held_out_nrmse: f64) -> Option<String> {
    let worse = |v: f64| v.is_nan() || v > 1.0;
    if worse(fit_nrmse) {
        Some(format!(
            "the nominal fit predicts the readings worse than their mean (fit NRMSE {fit_nrmse:.3})"
        ))
    } else if worse(held_out_nrmse) {
        Some(format!(
            "the nominal model, fitted without them, predicts the held-out readings worse than \
             their mean (held-out NRMSE {held_out_nrmse:.3})"
        ))
    } else {
        None
    }
}

/// A diagnosis fit stops when an iteration lowers its sum of squared,
/// noise-weighted residuals by less than this fraction of one row's mean
/// square: far below any difference the held-out decision can see.
/// Without it a candidate whose effect fits as nothing crawls along the
/// flat valley of its shape parameters until the optimiser's patience runs
/// out: on the DC default record 2e-3 of 53 558 an iteration for 108
/// simulations (two thirds of its diagnosis once the folds stepped), on an
/// induction machine's 117 points the leakage knee a billionth of the sum
/// an iteration for 300 evaluations (two thirds of a 3 s diagnosis).
pub const NEGLIGIBLE_DECREASE: f64 = 0.01;

/// The optimiser's relative `ftol` for a diagnosis fit of `rows`
/// residuals: [`NEGLIGIBLE_DECREASE`] over the rows, never below 1e-8.
pub fn negligible_ftol(rows: usize) -> f64 {
    (NEGLIGIBLE_DECREASE / rows.max(1) as f64).max(1e-8)
}

/// The result of comparing a candidate with the nominal model on held-out
/// data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldOutTest {
    /// Mean gain per block (nominal minus candidate squared residual).
    pub mean_gain: f64,
    /// Blocks compared.
    pub blocks: usize,
    /// One-sided p-value of "no gain", Bonferroni-corrected for the
    /// candidates tried, at most 1.
    pub p_value: f64,
}

impl HeldOutTest {
    /// Whether the gain is significant at [`FALSE_ALARM_RATE`].
    pub fn significant(&self) -> bool {
        self.p_value < FALSE_ALARM_RATE
    }
}

/// Paired one-sided t-test on per-block squared held-out residuals of the
/// nominal model and a candidate (same blocks, same order), corrected for
/// `candidates_tried` candidates.
///
/// Fewer than three blocks, or blocks that do not differ at all, give
/// p = 1: no evidence.
pub fn held_out_test(nominal: &[f64], candidate: &[f64], candidates_tried: usize) -> HeldOutTest {
    let n = nominal.len().min(candidate.len());
    let gains: Vec<f64> = (0..n).map(|b| nominal[b] - candidate[b]).collect();
    let mean = if n > 0 {
        gains.iter().sum::<f64>() / n as f64
    } else {
        0.0
    };
    let mut test = HeldOutTest {
        mean_gain: mean,
        blocks: n,
        p_value: 1.0,
    };
    if n < 3 {
        return test;
    }
    let var = gains.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let se = (var / n as f64).sqrt();
    if se.is_nan() || se <= 0.0 || !mean.is_finite() {
        return test;
    }
    let t = mean / se;
    let dist = StudentsT::new(0.0, 1.0, (n - 1) as f64).expect("n ≥ 3 gives a valid t");
    let p = 1.0 - dist.cdf(t);
    test.p_value = (p * candidates_tried.max(1) as f64).min(1.0);
    test
}

/// Sign-flip (Fisher randomisation) version of [`held_out_test`]: the
/// one-sided p-value of the summed gain under "each block's gain is as
/// likely negative as positive", from `SIGN_FLIPS` random sign patterns
/// (fixed seed, so a diagnosis is reproducible), Bonferroni-corrected.
///
/// The t-test is this test's large-sample approximation, and it loses
/// its power when the gain sits in a few blocks (an effect seen only near
/// synchronous speed, say): its variance then comes from the effect
/// itself, so t ≈ √(blocks that gain) however large the gain. The
/// randomisation test uses the gains' sizes and keeps its false-alarm
/// rate exactly for independent, symmetric blocks.
pub fn held_out_sign_flip_test(
    nominal: &[f64],
    candidate: &[f64],
    candidates_tried: usize,
) -> HeldOutTest {
    let gains = gains(nominal, candidate);
    sign_flip(&gains, &gains, candidates_tried)
}

/// Each block's gain, nominal minus candidate, over the blocks both have.
fn gains(nominal: &[f64], candidate: &[f64]) -> Vec<f64> {
    nominal.iter().zip(candidate).map(|(n, c)| n - c).collect()
}

/// [`held_out_sign_flip_test`] on each block's gain relative to its size,
/// `(nominal − candidate) / (nominal + candidate)`, in [−1, 1]: every
/// block counts by the share of its squared residual the candidate
/// removes (or adds), not by the size of that residual. Its false-alarm
/// rate holds on the same terms (each block's relative gain is as likely
/// negative as positive when the two models are equally wrong).
///
/// Why, for the DC diagnosis's blocks of a few tens of samples: the
/// nominal model's largest misfits lie in a few transients, and there the
/// absolute gains are large both ways; a candidate that removes a share of
/// the misfit in most blocks can be outweighed by one transient block it
/// predicts worse. On the blind DC suites (three seeds) it named three
/// more withheld effects and lost one (own cases 60/75 either way,
/// gym-electric-motor 41/45 → 43/45), no false alarm. Not for the IM
/// sweep, whose blocks are operating points: there it lost six of 99 verdicts.
/// Both forms with the smaller p-value doubled gave own cases 59/75,
/// gym-electric-motor 43/45 (docs/diagnosis-dc.md).
pub fn held_out_relative_sign_flip_test(
    nominal: &[f64],
    candidate: &[f64],
    candidates_tried: usize,
) -> HeldOutTest {
    let gains = gains(nominal, candidate);
    let relative: Vec<f64> = gains
        .iter()
        .zip(nominal.iter().zip(candidate))
        .map(|(g, (n, c))| if n + c > 0.0 { g / (n + c) } else { 0.0 })
        .collect();
    sign_flip(&gains, &relative, candidates_tried)
}

/// The smaller p-value of [`held_out_sign_flip_test`] and
/// [`held_out_relative_sign_flip_test`], doubled (Bonferroni over the
/// two), with that test's mean gain: its false-alarm rate holds on the
/// same terms as each alone. The absolute form has the power where a
/// candidate gains a little in many blocks and loses a little in the
/// rest (a thermal drift or a brush drop over a PRBS or a speed loop: the
/// shares of the blocks it loses weigh as much as those it wins); the
/// relative form where it gains in most blocks and loses much in a few.
/// On the blind DC suites (three seeds, once the voltage could be taken
/// as straight pieces) it named one more withheld effect than the
/// relative form alone (own seed 20261121 case-38, a brush drop under a
/// PRBS: absolute p 0.00035, relative 0.015, both with the seven
/// candidates counted) and lost none, no false alarm
/// (docs/diagnosis-dc.md). Before the straight pieces it had lost one.
/// Not for the induction machine's sweep: there it lost two of 99
/// verdicts (motulator seed 7 mot-07, an iron loss, and seed 2024 mot-10,
/// main-flux saturation: `none` once the absolute form's p-value is
/// doubled), and the absolute form alone stays.
pub fn held_out_either_sign_flip_test(
    nominal: &[f64],
    candidate: &[f64],
    candidates_tried: usize,
) -> HeldOutTest {
    let absolute = held_out_sign_flip_test(nominal, candidate, candidates_tried);
    let relative = held_out_relative_sign_flip_test(nominal, candidate, candidates_tried);
    let mut test = if absolute.p_value < relative.p_value {
        absolute
    } else {
        relative
    };
    test.p_value = (2.0 * test.p_value).min(1.0);
    test
}

/// The sign-flip test of `tested` (one value per block), reporting the
/// mean of `gains` (the absolute gain per block).
fn sign_flip(gains: &[f64], tested: &[f64], candidates_tried: usize) -> HeldOutTest {
    let n = tested.len();
    let sum: f64 = tested.iter().sum();
    let mut test = HeldOutTest {
        mean_gain: if n > 0 {
            gains.iter().sum::<f64>() / n as f64
        } else {
            0.0
        },
        blocks: n,
        p_value: 1.0,
    };
    if n < 3 || !sum.is_finite() || sum <= 0.0 {
        return test;
    }
    // Each pattern's sign flips are done on the sign bit (no branch on a
    // coin toss to mispredict); the patterns are drawn once per block
    // count (`sign_patterns`).
    let exceed = super::sign_patterns::count_at_or_above(tested, sum, SIGN_FLIPS);
    let p = (1 + exceed) as f64 / (1 + SIGN_FLIPS) as f64;
    test.p_value = (p * candidates_tried.max(1) as f64).min(1.0);
    test
}

/// Random sign patterns of [`held_out_sign_flip_test`].
pub const SIGN_FLIPS: usize = 20_000;

/// Sums of `squared` over consecutive blocks of `block` samples (the last
/// block may be shorter; it is kept when it has at least half a block).
pub fn block_sums(squared: &[f64], block: usize) -> Vec<f64> {
    let block = block.max(1);
    squared
        .chunks(block)
        .filter(|c| 2 * c.len() >= block)
        .map(|c| c.iter().sum())
        .collect()
}

/// Ranking score of a candidate on held-out data: the held-out BIC
/// difference, `n/2·ln(SSE_nominal/SSE_candidate) − k/2·ln(n)`, with `n`
/// held-out (effective) samples and `k` extra parameters. Positive when
/// the gain outweighs the parameters.
pub fn penalised_score(sse_nominal: f64, sse_candidate: f64, n: f64, extra_params: usize) -> f64 {
    if !(sse_nominal > 0.0 && sse_candidate > 0.0 && n > 1.0) {
        return f64::NEG_INFINITY;
    }
    0.5 * n * (sse_nominal / sse_candidate).ln() - 0.5 * extra_params as f64 * n.ln()
}

/// Effective number of independent samples in a residual series with
/// lag-one autocorrelation ρ: `n·(1−ρ)/(1+ρ)` (ρ clamped to [0, 0.99]).
pub fn effective_samples(residual: &[f64]) -> f64 {
    let n = residual.len();
    if n < 3 {
        return n as f64;
    }
    let mean = residual.iter().sum::<f64>() / n as f64;
    let var: f64 = residual.iter().map(|r| (r - mean).powi(2)).sum();
    if var <= 0.0 {
        return n as f64;
    }
    let cov: f64 = residual
        .windows(2)
        .map(|w| (w[0] - mean) * (w[1] - mean))
        .sum();
    let rho = (cov / var).clamp(0.0, 0.99);
    n as f64 * (1.0 - rho) / (1.0 + rho)
}

/// Standard deviation of white measurement noise on a smooth signal, from
/// the median absolute first difference (robust to steps and outliers):
/// `median|Δy| / (√2 · 0.6745)`.
pub fn noise_sigma(y: &[f64]) -> f64 {
    let mut d: Vec<f64> = y.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    median(&mut d).map_or(0.0, |m| m / (std::f64::consts::SQRT_2 * 0.674_489_75))
}

/// Differences of a residual beyond this many times its rms are a
/// misfit's jumps, not noise ([`residual_noise_sigma`]).
const CLIP_SIGMAS: f64 = 4.0;

/// Standard deviation of the measurement noise in residuals (measured
/// minus simulated), pooled over `residuals` (one slice per segment), from
/// the first differences `Δr`, which the misfit's slow part does not
/// reach: `σ² = mean(Δr²) + mean(Δr_k·Δr_(k−1))`, exact for noise
/// correlated over one sample at most, and never below the quantisation
/// noise `q/√12` of `readings`, `q` their smallest nonzero step. White
/// noise gives `mean(Δr²)/2`; a speed from differenced encoder counts
/// (its quantisation error `(e_k − e_(k−1))/dt`, anticorrelated) would be
/// overestimated by √1.5 by that, and a reading through a filter of about
/// a sample (correlated) underestimated, so that a nominal model at the
/// noise floor would seem to miss it, or one that misses it to be at it.
/// Mean squares rather than medians: a reading quantised near its noise
/// level has first differences of 0 or one step, whose median says
/// nothing of σ.
///
/// Differencing the residual rather than the reading removes what the
/// model follows, so the estimate holds on ramps, PRBS and closed loops,
/// where the reading itself never settles. What differencing does not
/// remove is a misfit that jumps: a sensor delay or a fast current the
/// model lags leaves one large difference at every step of the voltage.
/// Differences beyond [`CLIP_SIGMAS`] times the estimate are left out
/// (sigma clipping, repeated until the estimate holds still): on a
/// blind record of a PRBS through a 0.5 ms delay (one sample) with an
/// armature time constant of a sample, the floor came out 6.4 times the
/// true one without it and the delay's verdict was refused as "within
/// the noise floor"; over the four blind seeds' 160 DC records the median
/// estimate moved from 1.05 to 1.02 times the truth, and no other verdict
/// changed (docs/diagnosis-dc.md).
pub fn residual_noise_sigma(residuals: &[&[f64]], readings: &[&[f64]]) -> f64 {
    let diffs: Vec<Vec<f64>> = residuals
        .iter()
        .map(|r| r.windows(2).map(|w| w[1] - w[0]).collect())
        .collect();
    // Over every segment: V0 = mean(Δr²), V1 = mean(Δr_k·Δr_(k−1)), of
    // the differences within `clip` (both of a pair for V1).
    let moments = |clip: f64| {
        let kept = |x: f64| x.is_finite() && x.abs() <= clip;
        let (mut v0, mut v1, mut n0, mut n1) = (0.0, 0.0, 0usize, 0usize);
        for d in &diffs {
            for (k, &x) in d.iter().enumerate().filter(|(_, x)| kept(**x)) {
                v0 += x * x;
                n0 += 1;
                if let Some(&p) = k.checked_sub(1).map(|p| &d[p]).filter(|p| kept(**p)) {
                    v1 += x * p;
                    n1 += 1;
                }
            }
        }
        let v0 = v0 / n0.max(1) as f64;
        (v0, if n1 > 0 { v1 / n1 as f64 } else { -0.5 * v0 })
    };
    // A misfit that jumps (a delay across a step, a spike the model
    // misses) leaves a few large differences the noise does not: they are
    // clipped at CLIP_SIGMAS times the estimate, repeated until it holds
    // still (Gaussian noise loses 6e-5 of its samples at 4 σ).
    let (mut v0, mut v1) = moments(f64::INFINITY);
    for _ in 0..8 {
        let (c0, c1) = moments(CLIP_SIGMAS * v0.sqrt());
        let settled = c0 >= 0.999 * v0;
        (v0, v1) = (c0, c1);
        if settled {
            break;
        }
    }
    // Noise correlated over one sample at most (white, or an encoder's
    // differenced quantisation, or a filter of about a sample):
    // γ0 = V0 + V1; a one-lag correlation cannot make it less than V0/3
    // (differenced white noise), which bounds the estimate where a
    // misfit's changes anticorrelate.
    let rms = (v0 + v1).max(v0 / 3.0).sqrt();
    let step = readings
        .iter()
        .flat_map(|y| y.windows(2).map(|w| (w[1] - w[0]).abs()))
        .filter(|v| *v > 0.0 && v.is_finite())
        .fold(f64::INFINITY, f64::min);
    let quantisation = if step.is_finite() {
        step / 12f64.sqrt()
    } else {
        0.0
    };
    rms.max(quantisation)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The unexplained gap's warning: above twice the floor, with the
    /// ratio and the faults named; none within it.
    #[test]
    fn a_gap_beyond_twice_the_floor_is_unexplained() {
        assert_eq!(unexplained_gap_warning(0.02, 0.01, "x"), None);
        let w = unexplained_gap_warning(0.05, 0.01, "a meter's offset").unwrap();
        assert!(w.contains("5.0 times the noise floor 0.0100"), "{w}");
        assert!(w.ends_with("(a meter's offset)"), "{w}");
    }
    use rand::{rngs::StdRng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// A nominal model worse than the readings' mean, in the fit or held
    /// out, is no baseline, and the reason names which NRMSE; a NaN is no
    /// baseline either; within 1 both is.
    #[test]
    fn a_model_worse_than_the_mean_is_no_baseline() {
        assert_eq!(no_baseline(0.2, 0.9), None);
        assert!(no_baseline(2.206, 2.5).unwrap().contains("fit NRMSE 2.206"));
        assert!(no_baseline(0.6, 1.036)
            .unwrap()
            .contains("held-out NRMSE 1.036"));
        assert!(no_baseline(f64::NAN, 0.1).is_some());
    }

    #[test]
    fn a_verdict_that_leaves_the_gap_says_what_it_removed() {
        // Gap 0.05 → 0.03 against a floor of 0.01: 2/3 of the excess.
        let w = partial_verdict_warning("iron_loss", 0.05, 0.03, 0.01).unwrap();
        assert!(w.starts_with("iron_loss: named as the verdict"), "{w}");
        assert!(w.contains("3.0 times the noise floor 0.0100"), "{w}");
        assert!(w.contains("removes 67 %"), "{w}");
        assert_eq!(partial_verdict_warning("iron_loss", 0.05, 0.02, 0.01), None);
    }

    /// `n` draws of unit Gaussian noise from a generator seeded `seed`.
    pub(crate) fn noise(seed: u64, n: usize) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let d = Normal::new(0.0, 1.0).unwrap();
        (0..n).map(|_| d.sample(&mut rng)).collect()
    }

    /// How many of `trials` pairs of independent squared-noise draws (40
    /// points each) `significant` calls a gain: two models equally wrong.
    fn false_alarms(trials: u64, significant: impl Fn(&[f64], &[f64]) -> bool) -> usize {
        (0..trials)
            .filter(|&s| {
                let a: Vec<f64> = noise(2 * s, 40).iter().map(|x| x * x).collect();
                let b: Vec<f64> = noise(2 * s + 1, 40).iter().map(|x| x * x).collect();
                significant(&a, &b)
            })
            .count()
    }

    #[test]
    fn pure_noise_gains_are_rarely_significant() {
        // Two independent noise draws stand in for two models that are
        // equally wrong: the test must alarm at about its nominal rate.
        let trials = 400;
        let alarms = false_alarms(trials, |a, b| held_out_test(a, b, 1).significant());
        // 1 % nominal: 4 of 400 expected; 12 would be p < 0.001 binomially.
        assert!(alarms <= 12, "{alarms} false alarms in {trials}");
    }

    #[test]
    fn a_real_gain_is_significant_and_bonferroni_weakens_it() {
        let nominal: Vec<f64> = noise(7, 60).iter().map(|x| 2.0 + x * x).collect();
        let candidate: Vec<f64> = noise(7, 60).iter().map(|x| x * x).collect();
        let one = held_out_test(&nominal, &candidate, 1);
        assert!(one.significant());
        assert!((one.mean_gain - 2.0).abs() < 1e-12);
        let weak_n: Vec<f64> = noise(9, 8).iter().map(|x| 0.3 + x * x).collect();
        let weak_c: Vec<f64> = noise(10, 8).iter().map(|x| x * x).collect();
        let single = held_out_test(&weak_n, &weak_c, 1);
        let many = held_out_test(&weak_n, &weak_c, 7);
        assert!(many.p_value >= single.p_value);
        assert!(held_out_test(&[1.0, 2.0], &[0.0, 0.0], 1).p_value == 1.0);
    }

    /// The flips on the sign bit are the coin tosses of
    /// `rng.random::<bool>()`, word for word: the p-value is the same to
    /// the bit as the branching loop's.
    #[test]
    fn sign_flips_are_the_coin_tosses_they_replace() {
        use rand::{rngs::StdRng, RngExt, SeedableRng};
        let tested: Vec<f64> = noise(13, 40).iter().map(|x| x + 0.3).collect();
        let sum: f64 = tested.iter().sum();
        let mut rng = StdRng::seed_from_u64(0x5eed);
        let exceed = (0..SIGN_FLIPS)
            .filter(|_| {
                let flipped: f64 = tested
                    .iter()
                    .map(|g| if rng.random::<bool>() { *g } else { -*g })
                    .sum();
                flipped >= sum
            })
            .count();
        let p = (1 + exceed) as f64 / (1 + SIGN_FLIPS) as f64;
        let test = sign_flip(&tested, &tested, 1);
        assert!(p > 1e-4 && p < 0.5, "{p}");
        assert_eq!(test.p_value.to_bits(), p.to_bits());
    }

    #[test]
    fn sign_flip_tests_hold_their_rate_and_see_a_localised_gain() {
        let trials = 200;
        type BlockTest = fn(&[f64], &[f64], usize) -> HeldOutTest;
        let tests: [BlockTest; 3] = [
            held_out_sign_flip_test,
            held_out_relative_sign_flip_test,
            held_out_either_sign_flip_test,
        ];
        for test in tests {
            let alarms = false_alarms(trials, |a, b| test(a, b, 1).significant());
            // 1 % nominal: 2 of 200 expected; 8 would be p < 0.001 binomially.
            assert!(alarms <= 8, "{alarms} false alarms in {trials}");
        }
        // Eight blocks of 60 points gain a lot, the rest nothing: the t
        // approximation misses it, the randomisation test does not.
        let nominal: Vec<f64> = noise(11, 60)
            .iter()
            .enumerate()
            .map(|(k, x)| x * x + if k < 8 { 50.0 * (1.0 + k as f64) } else { 0.0 })
            .collect();
        let candidate: Vec<f64> = noise(12, 60).iter().map(|x| x * x).collect();
        assert!(!held_out_test(&nominal, &candidate, 6).significant());
        assert!(held_out_sign_flip_test(&nominal, &candidate, 6).significant());
        assert_eq!(
            held_out_sign_flip_test(&candidate, &candidate, 1).p_value,
            1.0
        );
    }

    /// A gain of 2 in thirty blocks of large misfit, a loss of 0.3 in
    /// thirty of small misfit: the relative form sees more blocks lost by
    /// their share than won and finds nothing; the absolute form, and so
    /// the pair, finds the gain, at twice the absolute form's p-value.
    #[test]
    fn either_sign_flip_test_takes_the_form_that_sees_the_gain() {
        let nominal: Vec<f64> = noise(15, 60)
            .iter()
            .enumerate()
            .map(|(k, x)| x * x + if k < 30 { 20.0 } else { 0.0 })
            .collect();
        let candidate: Vec<f64> = nominal
            .iter()
            .enumerate()
            .map(|(k, n)| if k < 30 { n - 2.0 } else { n + 0.3 })
            .collect();
        let relative = held_out_relative_sign_flip_test(&nominal, &candidate, 6);
        let absolute = held_out_sign_flip_test(&nominal, &candidate, 6);
        let either = held_out_either_sign_flip_test(&nominal, &candidate, 6);
        assert!(!relative.significant(), "{relative:?}");
        assert!(either.significant(), "{either:?}");
        assert_eq!(either.p_value, 2.0 * absolute.p_value);
        assert_eq!(either.mean_gain, absolute.mean_gain);
    }

    #[test]
    fn the_relative_sign_flip_test_is_not_outweighed_by_one_block() {
        // Half of 60 blocks carry a misfit the candidate removes; one
        // block (a transient it extrapolates badly) it predicts far worse.
        let nominal: Vec<f64> = noise(13, 60)
            .iter()
            .enumerate()
            .map(|(k, x)| x * x + if k < 30 { 4.0 } else { 0.0 })
            .collect();
        let mut candidate: Vec<f64> = noise(14, 60).iter().map(|x| x * x).collect();
        candidate[59] += 400.0;
        assert!(!held_out_sign_flip_test(&nominal, &candidate, 6).significant());
        let relative = held_out_relative_sign_flip_test(&nominal, &candidate, 6);
        assert!(relative.significant(), "{relative:?}");
        // The mean gain it reports is the absolute one.
        let absolute = held_out_sign_flip_test(&nominal, &candidate, 6);
        assert_eq!(relative.mean_gain, absolute.mean_gain);
        assert_eq!(
            held_out_relative_sign_flip_test(&candidate, &candidate, 1).p_value,
            1.0
        );
    }

    #[test]
    fn residual_noise_ignores_a_slow_misfit_and_keeps_the_quantisation_floor() {
        let white = noise(21, 4000);
        let residual: Vec<f64> = white
            .iter()
            .enumerate()
            .map(|(k, v)| 0.05 * v + 0.3 * (k as f64 * 0.002).sin())
            .collect();
        let s = residual_noise_sigma(&[&residual], &[&white]);
        assert!((s - 0.05).abs() < 0.003, "sigma {s}");
        // A speed from encoder counts: its noise is the difference of two
        // quantisation errors, σ = √2·σe; the first differences alone
        // (mean(Δr²)/2) would say √3·σe.
        let e = noise(22, 8001);
        let encoder: Vec<f64> = e.windows(2).map(|w| 0.1 * (w[1] - w[0])).collect();
        let s = residual_noise_sigma(&[&encoder], &[&white]);
        let want = 0.1 * 2f64.sqrt();
        assert!((s - want).abs() < 0.03 * want, "sigma {s}, want {want}");
        // A reading in steps of 0.5 with a residual that never moves:
        // the quantisation noise 0.5/sqrt(12) remains.
        let coarse: Vec<f64> = (0..100).map(|k| 0.5 * (k / 10) as f64).collect();
        let flat = vec![0.0; 100];
        let q = residual_noise_sigma(&[&flat], &[&coarse]);
        assert!((q - 0.5 / 12f64.sqrt()).abs() < 1e-12, "{q}");
    }

    #[test]
    fn residual_noise_leaves_out_a_misfit_that_jumps() {
        // White noise of 0.05 and, every 100 samples, a jump of 2 the
        // model misses for one sample (a delay across a voltage step).
        let white = noise(23, 4000);
        let residual: Vec<f64> = white
            .iter()
            .enumerate()
            .map(|(k, v)| 0.05 * v + if k % 100 == 50 { 2.0 } else { 0.0 })
            .collect();
        let s = residual_noise_sigma(&[&residual], &[&white]);
        // Unclipped, the jumps' 80 differences of ±2 alone would give
        // √(80·4/3999/2) ≈ 0.2: four times the noise.
        assert!((s - 0.05).abs() < 0.003, "sigma {s}");
    }

    #[test]
    fn score_penalises_parameters() {
        assert!(penalised_score(2.0, 1.0, 100.0, 1) > 0.0);
        assert!(penalised_score(1.0, 1.0, 100.0, 1) < 0.0);
        assert!(penalised_score(2.0, 1.0, 100.0, 1) > penalised_score(2.0, 1.0, 100.0, 3));
    }

    #[test]
    fn noise_sigma_ignores_steps_and_effective_samples_see_colour() {
        let mut y = noise(3, 4000);
        for (k, v) in y.iter_mut().enumerate() {
            *v = 0.1 * *v + if k > 2000 { 5.0 } else { 0.0 } + k as f64 * 1e-5;
        }
        let s = noise_sigma(&y);
        assert!((s - 0.1).abs() < 0.01, "sigma {s}");
        let white = noise(4, 4000);
        assert!(effective_samples(&white) > 3500.0);
        let coloured: Vec<f64> = white.windows(8).map(|w| w.iter().sum()).collect();
        assert!(effective_samples(&coloured) < 1000.0);
        assert_eq!(block_sums(&[1.0; 10], 4), vec![4.0, 4.0, 2.0]);
    }
}
