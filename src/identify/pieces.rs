//! A noisy input as straight pieces: the least-squares piecewise-linear
//! approximation of a sampled signal, with as many pieces as the noise
//! justifies.
//!
//! Output-error models are simulated from the measured input. A reading
//! with sensor noise feeds that noise through the model, which then
//! carries a residual the plant never had (errors in variables); where the
//! input is really a few steps, ramps and holds (a supply's staircase, a
//! ramp generator, a PRBS between two levels), the pieces are what the
//! plant saw and the noise is gone. A piece of one sample is allowed, so a
//! step that falls between two samples keeps its reading.
//!
//! The pieces are chosen by optimal partitioning (Jackson et al. 2005)
//! with the pruning of PELT (Killick, Fearnhead and Eckley 2012): the cost
//! of a piece is its least-squares line's residual in units of the noise
//! variance, plus a penalty of `3·ln n` for each piece (its two
//! coefficients and its start, as the Bayesian information criterion
//! counts them). A piece is at most [`MAX_PIECE`] samples long, so the work
//! is linear in the length of the signal however long a level is held.
//!
//! Whether the pieces are the input or erase part of it (a controller's
//! command that jitters from sample to sample is what the motor saw, not
//! noise) is for the caller to decide, from how well its model explains
//! the outputs from each.

/// Longest piece, samples: long enough that a held level's noise is
/// averaged down by a factor above 10, short enough to bound the work.
pub const MAX_PIECE: usize = 256;

/// Noise standard deviation of a sampled signal from its second
/// differences, `σ = 1.4826·median|Δ²y|/√6`: a line (a hold or a ramp) has
/// none, a step changes only two of them, so the median sees the noise
/// alone. Zero for a signal without noise (or one quantised more coarsely
/// than its noise).
pub fn noise_sigma<'a>(signals: impl IntoIterator<Item = &'a [f64]>) -> f64 {
    let mut d2: Vec<f64> = signals
        .into_iter()
        .flat_map(|y| y.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).abs()))
        .filter(|d| d.is_finite())
        .collect();
    if d2.is_empty() {
        return 0.0;
    }
    let mid = d2.len() / 2;
    let (_, median, _) = d2.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *median / 6f64.sqrt()
}

/// Running sums from which any piece's least-squares line and residual
/// follow in constant time. The abscissa is the sample index from the
/// signal's start and the ordinate is taken about the signal's mean, so
/// the differences stay well conditioned.
struct Sums {
    /// Prefix sums of `1, k, k², y, k·y, y²`; row `m` holds the first `m`
    /// samples.
    prefix: Vec<[f64; 6]>,
}

impl Sums {
    fn new(y: &[f64], mean: f64) -> Sums {
        let mut prefix = Vec::with_capacity(y.len() + 1);
        let mut acc = [0.0f64; 6];
        prefix.push(acc);
        for (k, v) in y.iter().enumerate() {
            let (k, v) = (k as f64, v - mean);
            for (a, term) in acc.iter_mut().zip([1.0, k, k * k, v, k * v, v * v]) {
                *a += term;
            }
            prefix.push(acc);
        }
        Sums { prefix }
    }

    /// Residual sum of squares of the least-squares line through samples
    /// `a..b`, without a division: `1/n` and `1/Σ(k − k̄)²` depend on the
    /// length alone and come from `inv` (see [`Inverses`]).
    fn sse(&self, a: usize, b: usize, inv: &Inverses) -> f64 {
        let (p, q) = (&self.prefix[a], &self.prefix[b]);
        let (s1, sy, sky, syy) = (q[1] - p[1], q[3] - p[3], q[4] - p[4], q[5] - p[5]);
        let (inv_n, inv_skk) = inv.of[b - a];
        let cross = sky - s1 * sy * inv_n;
        syy - sy * sy * inv_n - cross * cross * inv_skk
    }

    /// Intercept (at `k = 0`), slope and residual sum of squares of the
    /// least-squares line through samples `a..b`.
    fn line(&self, a: usize, b: usize) -> (f64, f64, f64) {
        let (p, q) = (&self.prefix[a], &self.prefix[b]);
        let s: [f64; 6] = std::array::from_fn(|j| q[j] - p[j]);
        let n = s[0];
        let (mk, my) = (s[1] / n, s[3] / n);
        let skk = s[2] - s[1] * mk;
        let sky = s[4] - s[1] * my;
        let syy = s[5] - s[3] * my;
        if skk <= 0.0 {
            // One sample: the line is its value.
            return (my, 0.0, 0.0);
        }
        let slope = sky / skk;
        (my - slope * mk, slope, (syy - slope * sky).max(0.0))
    }
}

/// `1/n` and `1/Σ(k − k̄)² = 12/(n(n² − 1))` for every piece length `n`
/// up to [`MAX_PIECE`] (zero for one sample, whose line has no slope).
struct Inverses {
    of: Vec<(f64, f64)>,
}

impl Inverses {
    fn new() -> Inverses {
        let of = (0..=MAX_PIECE)
            .map(|n| {
                let m = n as f64;
                let skk = m * (m * m - 1.0) / 12.0;
                (
                    if n > 0 { 1.0 / m } else { 0.0 },
                    if n > 1 { 1.0 / skk } else { 0.0 },
                )
            })
            .collect();
        Inverses { of }
    }
}

/// The least-squares piecewise-linear approximation of `y`, whose
/// readings carry white noise of standard deviation `sigma` (see the
/// module docs). A signal with no noise (`sigma` zero or not finite), or
/// with fewer than three samples, comes back as it is.
pub fn piecewise_linear(y: &[f64], sigma: f64) -> Vec<f64> {
    let n = y.len();
    if !(sigma.is_finite() && sigma > 0.0) || n < 3 || y.iter().any(|v| !v.is_finite()) {
        return y.to_vec();
    }
    let mean = y.iter().sum::<f64>() / n as f64;
    let sums = Sums::new(y, mean);
    let inv = Inverses::new();
    let var = sigma * sigma;
    let penalty = 3.0 * (n as f64).ln();
    // best[t]: least cost of the first t samples; start[t]: where the
    // last of its pieces starts.
    let mut best = vec![0.0f64; n + 1];
    let mut start = vec![0usize; n + 1];
    best[0] = -penalty;
    let mut open: Vec<usize> = vec![0];
    let mut costs: Vec<f64> = Vec::new();
    for t in 1..=n {
        open.retain(|&s| t - s <= MAX_PIECE);
        costs.clear();
        costs.extend(
            open.iter()
                .map(|&s| best[s] + sums.sse(s, t, &inv).max(0.0) / var),
        );
        let (mut cost, mut from) = (f64::INFINITY, t - 1);
        for (&s, &c) in open.iter().zip(&costs) {
            if c + penalty < cost {
                (cost, from) = (c + penalty, s);
            }
        }
        best[t] = cost;
        start[t] = from;
        // PELT: a start whose cost up to `t` (its piece's penalty left
        // out) already exceeds the best partition's cost at `t` can never
        // be the best start of a later piece (the residual of a piece only
        // grows as it is lengthened).
        let mut kept = costs.iter();
        open.retain(|_| kept.next().is_some_and(|&c| c <= cost));
        open.push(t);
    }
    let mut out = vec![0.0; n];
    let mut t = n;
    while t > 0 {
        let s = start[t];
        let (c0, c1, _) = sums.line(s, t);
        for (k, o) in out.iter_mut().enumerate().take(t).skip(s) {
            *o = mean + c0 + c1 * k as f64;
        }
        t = s;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn noisy(clean: &[f64], sigma: f64, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        clean.iter().map(|v| v + noise.sample(&mut rng)).collect()
    }

    fn rms(a: &[f64], b: &[f64]) -> f64 {
        (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
    }

    /// A step, a ramp and a hold: the pieces recover the clean signal far
    /// below the noise, and the step stays sharp.
    #[test]
    fn steps_ramps_and_holds_come_back_clean() {
        let clean: Vec<f64> = (0..1500)
            .map(|k| match k {
                0..300 => 10.0,
                300..700 => 40.0,
                700..1100 => 40.0 - 25.0 * (k - 700) as f64 / 400.0,
                _ => 15.0,
            })
            .collect();
        let y = noisy(&clean, 0.3, 1);
        let sigma = noise_sigma([y.as_slice()]);
        assert!((sigma / 0.3 - 1.0).abs() < 0.1, "σ estimated {sigma}");
        let fit = piecewise_linear(&y, sigma);
        let err = rms(&fit, &clean);
        assert!(err < 0.05, "rms error {err} against noise 0.3");
        assert!((fit[299] - 10.0).abs() < 0.2 && (fit[300] - 40.0).abs() < 0.2);
    }

    /// A curve is followed by as many pieces as it needs: what is left is
    /// no more than the noise, and the error against the curve is less.
    #[test]
    fn a_curve_is_followed_within_the_noise() {
        let clean: Vec<f64> = (0..2000)
            .map(|k| 20.0 * (k as f64 * std::f64::consts::TAU / 700.0).sin())
            .collect();
        let y = noisy(&clean, 0.2, 2);
        let fit = piecewise_linear(&y, noise_sigma([y.as_slice()]));
        let err = rms(&fit, &clean);
        assert!(err < 0.1, "rms error {err} against noise 0.2");
    }

    #[test]
    fn a_signal_without_noise_is_left_as_it_is() {
        let y: Vec<f64> = (0..100).map(|k| ((k / 10) as f64).powi(2)).collect();
        assert_eq!(noise_sigma([y.as_slice()]), 0.0);
        assert_eq!(piecewise_linear(&y, 0.0), y);
        assert_eq!(piecewise_linear(&y[..2], 1.0), y[..2]);
    }

    /// The division-free residual is the line's, for every piece of a
    /// signal far from the origin.
    #[test]
    fn the_fast_residual_is_the_lines() {
        let y = noisy(
            &(0..600).map(|k| 300.0 + 0.1 * k as f64).collect::<Vec<_>>(),
            0.5,
            4,
        );
        let sums = Sums::new(&y, y.iter().sum::<f64>() / y.len() as f64);
        let inv = Inverses::new();
        for (a, b) in [(0, 1), (0, 2), (10, 13), (100, 356), (344, 600)] {
            let (fast, line) = (sums.sse(a, b, &inv), sums.line(a, b).2);
            assert!(
                (fast - line).abs() <= 1e-9 * (1.0 + line),
                "{a}..{b}: {fast} vs {line}"
            );
        }
    }

    /// A hold far longer than the longest piece is split, not refused, and
    /// still averaged down.
    #[test]
    fn a_long_hold_is_cut_into_pieces() {
        let clean = vec![5.0; 5000];
        let y = noisy(&clean, 1.0, 3);
        let fit = piecewise_linear(&y, 1.0);
        assert!(rms(&fit, &clean) < 0.15);
    }
}
