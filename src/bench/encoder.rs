//! Speed from quadrature-encoder counts.

/// Differentiates encoder counts into speed, rad/s.
///
/// Each estimate is the count change since the previous reading over the
/// time between them: unbiased, with a quantisation noise of one count per
/// interval that averages out over a window (the count telescopes).
///
/// With a baseline ([`SpeedFromEncoder::with_baseline`]) each estimate
/// spans at least that long, readings in between repeating the last one:
/// polled counts carry their poll's timestamp jitter, which over one short
/// interval can be a large part of it.
#[derive(Debug, Clone)]
pub struct SpeedFromEncoder {
    rad_per_count: f64,
    last: Option<(u64, f64)>,
    baseline_ns: u64,
    estimate: Option<f64>,
    fresh: u64,
}

impl SpeedFromEncoder {
    /// An estimator for an encoder with `counts_per_rev` counts per turn.
    pub fn new(counts_per_rev: f64) -> SpeedFromEncoder {
        SpeedFromEncoder {
            rad_per_count: std::f64::consts::TAU / counts_per_rev,
            last: None,
            baseline_ns: 0,
            estimate: None,
            fresh: 0,
        }
    }

    /// An estimator whose estimates each span at least `baseline_ns`.
    pub fn with_baseline(counts_per_rev: f64, baseline_ns: u64) -> SpeedFromEncoder {
        SpeedFromEncoder {
            baseline_ns,
            ..SpeedFromEncoder::new(counts_per_rev)
        }
    }

    /// Feed a reading; the speed since the previous one (`None` at first,
    /// or when time did not advance).
    pub fn update(&mut self, t_ns: u64, count: f64) -> Option<f64> {
        let Some((t0, c0)) = self.last else {
            self.last = Some((t_ns, count));
            return None;
        };
        if t_ns <= t0 {
            self.last = Some((t_ns, count));
            return None;
        }
        if t_ns - t0 < self.baseline_ns {
            return self.estimate;
        }
        self.last = Some((t_ns, count));
        let w = (count - c0) * self.rad_per_count / ((t_ns - t0) as f64 * 1e-9);
        self.estimate = Some(w);
        self.fresh += 1;
        Some(w)
    }

    /// How many new estimates (not repeats within the baseline) were made.
    pub fn estimates(&self) -> u64 {
        self.fresh
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_turn_per_second_is_tau_rad_per_s() {
        let mut e = SpeedFromEncoder::new(10_000.0);
        assert_eq!(e.update(0, 0.0), None);
        let w = e.update(500_000, 5.0).unwrap();
        assert!((w - std::f64::consts::TAU).abs() < 1e-12);
        assert_eq!(e.update(500_000, 6.0), None, "no time elapsed");
    }

    #[test]
    fn a_baseline_spans_jittered_intervals() {
        // 1000 counts/rev at 1 rev/s, read every 5 ms with the timestamps
        // off by +1 ms and -1 ms in turn: single intervals are off by up to
        // 40 %, estimates over a 20 ms baseline by 5 % at most.
        let mut plain = SpeedFromEncoder::new(1000.0);
        let mut based = SpeedFromEncoder::with_baseline(1000.0, 20_000_000);
        let tau = std::f64::consts::TAU;
        let (mut worst_plain, mut worst_based) = (0.0f64, 0.0f64);
        for k in 0..200u64 {
            let t_true = k * 5_000_000;
            let count = (t_true as f64 * 1e-9 * 1000.0).floor();
            let t = if k % 2 == 0 {
                t_true + 1_000_000
            } else {
                t_true - 1_000_000
            };
            if let Some(w) = plain.update(t, count) {
                worst_plain = worst_plain.max((w / tau - 1.0).abs());
            }
            if let Some(w) = based.update(t, count) {
                worst_based = worst_based.max((w / tau - 1.0).abs());
            }
        }
        assert!(worst_plain > 0.3, "{worst_plain}");
        assert!(worst_based < 0.11, "{worst_based}");
    }
}
