//! Speed from quadrature-encoder counts.

/// Differentiates encoder counts into speed, rad/s.
///
/// Each estimate is the count change since the previous reading over the
/// time between them: unbiased, with a quantisation noise of one count per
/// interval that averages out over a window (the count telescopes).
#[derive(Debug, Clone)]
pub struct SpeedFromEncoder {
    rad_per_count: f64,
    last: Option<(u64, f64)>,
}

impl SpeedFromEncoder {
    /// An estimator for an encoder with `counts_per_rev` counts per turn.
    pub fn new(counts_per_rev: f64) -> SpeedFromEncoder {
        SpeedFromEncoder {
            rad_per_count: std::f64::consts::TAU / counts_per_rev,
            last: None,
        }
    }

    /// Feed a reading; the speed since the previous one (`None` at first,
    /// or when time did not advance).
    pub fn update(&mut self, t_ns: u64, count: f64) -> Option<f64> {
        let previous = self.last.replace((t_ns, count));
        let (t0, c0) = previous?;
        if t_ns <= t0 {
            return None;
        }
        Some((count - c0) * self.rad_per_count / ((t_ns - t0) as f64 * 1e-9))
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
}
