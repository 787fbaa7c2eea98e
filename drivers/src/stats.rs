//! Sampling statistics per channel: how many readings arrived, how many
//! were lost, and how far the intervals between readings strayed from the
//! nominal period (jitter).

/// Statistics of one channel over a stream's life so far.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelStats {
    /// Index of the channel in [`crate::SensorStream::channels`].
    pub channel: usize,
    /// Readings delivered.
    pub received: u64,
    /// Readings known to be lost (a failed poll, a sequence gap).
    pub lost: u64,
    /// Nominal period, s (1 / the configured rate).
    pub nominal_period_s: f64,
    /// Intervals measured (between consecutive readings with no loss
    /// between them).
    pub intervals: u64,
    /// Mean interval, s (NaN with no interval).
    pub mean_interval_s: f64,
    /// RMS of (interval − nominal period), s (NaN with no interval).
    pub jitter_rms_s: f64,
    /// Largest |interval − nominal period|, s (NaN with no interval).
    pub jitter_max_s: f64,
}

impl ChannelStats {
    /// Lost readings as a fraction of those expected (0 when none were).
    pub fn loss_fraction(&self) -> f64 {
        let expected = self.received + self.lost;
        if expected == 0 {
            0.0
        } else {
            self.lost as f64 / expected as f64
        }
    }
}

impl std::fmt::Display for ChannelStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} received, {} lost ({:.3} %), mean interval {:.3} ms (nominal {:.3} ms), jitter rms {:.3} ms, max {:.3} ms",
            self.received,
            self.lost,
            100.0 * self.loss_fraction(),
            self.mean_interval_s * 1e3,
            self.nominal_period_s * 1e3,
            self.jitter_rms_s * 1e3,
            self.jitter_max_s * 1e3
        )
    }
}

/// Accumulates [`ChannelStats`] reading by reading.
#[derive(Debug, Clone, PartialEq)]
pub struct IntervalStats {
    channel: usize,
    nominal_s: f64,
    last_t_ns: Option<u64>,
    received: u64,
    lost: u64,
    intervals: u64,
    sum_interval: f64,
    sum_dev2: f64,
    max_dev: f64,
}

impl IntervalStats {
    /// An accumulator for `channel`, sampled at `rate_hz`.
    pub fn new(channel: usize, rate_hz: f64) -> IntervalStats {
        IntervalStats {
            channel,
            nominal_s: 1.0 / rate_hz,
            last_t_ns: None,
            received: 0,
            lost: 0,
            intervals: 0,
            sum_interval: 0.0,
            sum_dev2: 0.0,
            max_dev: 0.0,
        }
    }

    /// A reading arrived at `t_ns`.
    pub fn received(&mut self, t_ns: u64) {
        self.received += 1;
        if let Some(last) = self.last_t_ns {
            let dt = t_ns.saturating_sub(last) as f64 * 1e-9;
            let dev = dt - self.nominal_s;
            self.intervals += 1;
            self.sum_interval += dt;
            self.sum_dev2 += dev * dev;
            self.max_dev = self.max_dev.max(dev.abs());
        }
        self.last_t_ns = Some(t_ns);
    }

    /// `n` readings were lost; the next interval is not measured across
    /// the gap.
    pub fn lost(&mut self, n: u64) {
        self.lost += n;
        self.last_t_ns = None;
    }

    /// Readings lost so far.
    pub fn lost_count(&self) -> u64 {
        self.lost
    }

    /// The statistics so far.
    pub fn summary(&self) -> ChannelStats {
        let n = self.intervals as f64;
        let (mean, rms, max) = if self.intervals == 0 {
            (f64::NAN, f64::NAN, f64::NAN)
        } else {
            (
                self.sum_interval / n,
                (self.sum_dev2 / n).sqrt(),
                self.max_dev,
            )
        };
        ChannelStats {
            channel: self.channel,
            received: self.received,
            lost: self.lost,
            nominal_period_s: self.nominal_s,
            intervals: self.intervals,
            mean_interval_s: mean,
            jitter_rms_s: rms,
            jitter_max_s: max,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jitter_and_loss_by_hand() {
        let mut s = IntervalStats::new(2, 1000.0);
        for t in [0u64, 1_000_000, 2_200_000, 3_000_000] {
            s.received(t);
        }
        s.lost(2);
        s.received(10_000_000); // no interval across the gap
        s.received(11_000_000);
        let c = s.summary();
        assert_eq!((c.channel, c.received, c.lost, c.intervals), (2, 6, 2, 4));
        // Deviations: 0, +0.2 ms, -0.2 ms, 0.
        assert!((c.jitter_rms_s - (0.08e-6f64 / 4.0).sqrt()).abs() < 1e-12);
        assert!((c.jitter_max_s - 0.2e-3).abs() < 1e-12);
        assert!((c.mean_interval_s - 1e-3).abs() < 1e-12);
        assert!((c.loss_fraction() - 0.25).abs() < 1e-12);
    }

    #[test]
    fn no_interval_gives_nan_not_zero() {
        let mut s = IntervalStats::new(0, 10.0);
        s.received(5);
        assert!(s.summary().jitter_rms_s.is_nan());
    }
}
