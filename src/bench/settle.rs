//! Settle detection: are the signals still moving, beyond their noise?

use std::collections::VecDeque;

/// Decides when several channels have settled.
///
/// Each channel keeps its last two windows of `window` samples. A channel
/// is settled when the means of the two windows differ by no more than
/// `tolerance·max(|mean|, peak/1000)` plus three standard errors of that
/// difference, `peak` being the largest magnitude the channel reached
/// since the last reset. The noise term keeps noise alone from holding a
/// level forever; the peak term lets a signal settle towards zero; a slow
/// drift larger than the tolerance holds it. The criterion is scale-free:
/// it needs no knowledge of the channel's range.
#[derive(Debug, Clone)]
pub struct SettleDetector {
    window: usize,
    tolerance: f64,
    peaks: Vec<f64>,
    history: Vec<VecDeque<f64>>,
}

/// Fraction of a channel's peak below which its level counts as near zero.
const PEAK_FLOOR: f64 = 1e-3;

impl SettleDetector {
    /// A detector over `channels` channels.
    pub fn new(window: usize, tolerance: f64, channels: usize) -> SettleDetector {
        let history = (0..channels)
            .map(|_| VecDeque::with_capacity(2 * window))
            .collect();
        SettleDetector {
            window: window.max(2),
            tolerance,
            peaks: vec![0.0; channels],
            history,
        }
    }

    /// Forget everything (a new level began).
    pub fn reset(&mut self) {
        self.history.iter_mut().for_each(VecDeque::clear);
        self.peaks.iter_mut().for_each(|p| *p = 0.0);
    }

    /// Add one reading per channel; true when every channel is settled.
    pub fn push(&mut self, values: &[f64]) -> bool {
        let mut settled = true;
        for ((h, &v), peak) in self.history.iter_mut().zip(values).zip(&mut self.peaks) {
            if h.len() == 2 * self.window {
                h.pop_front();
            }
            h.push_back(v);
            *peak = peak.max(v.abs());
            let floor = PEAK_FLOOR * *peak;
            settled &= h.len() == 2 * self.window
                && Self::channel_settled(h, self.window, self.tolerance, floor);
        }
        settled
    }

    fn channel_settled(h: &VecDeque<f64>, w: usize, tolerance: f64, floor: f64) -> bool {
        let (older, newer): (Vec<f64>, Vec<f64>) = (
            h.iter().take(w).copied().collect(),
            h.iter().skip(w).copied().collect(),
        );
        let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
        let var = |x: &[f64], m: f64| {
            x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64
        };
        let (m1, m2) = (mean(&older), mean(&newer));
        // Noise from the newer window only: the older one may still hold the transient.
        let stderr = (2.0 * var(&newer, m2) / w as f64).sqrt();
        (m2 - m1).abs() <= tolerance * m2.abs().max(floor) + 3.0 * stderr
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponential_settles_only_after_its_tail_flattens() {
        let mut d = SettleDetector::new(100, 0.002, 1);
        let tau = 50.0; // samples
        let settled_at = (0..5000)
            .position(|k| d.push(&[1.0 - (-(k as f64) / tau).exp()]))
            .unwrap();
        // The newer window's mean of e^(−k/τ) is 50·(e² − 1)/100·e^(−k/τ) and the
        // older one's e² times that, so the means differ by 20.4·e^(−k/τ):
        // ≤ 0.002 from k = τ·ln(20.4/0.002) ≈ 461.
        assert!((455..=465).contains(&settled_at), "settled at {settled_at}");
    }

    #[test]
    fn noise_alone_settles_and_a_ramp_does_not() {
        let mut d = SettleDetector::new(100, 0.002, 1);
        // A deterministic pseudo-noise of amplitude 0.05 on a level of 1.
        let noisy = (0..400).map(|k| 1.0 + 0.05 * ((k * 7919 % 101) as f64 / 50.0 - 1.0));
        assert!(noisy.map(|v| d.push(&[v])).last().unwrap());
        let mut d = SettleDetector::new(100, 0.002, 1);
        assert!(!(0..1000).any(|k| d.push(&[1.0 + 1e-4 * k as f64])));
    }

    #[test]
    fn a_decay_to_zero_settles_relative_to_its_peak() {
        let mut d = SettleDetector::new(100, 0.002, 1);
        let settled_at = (0..5000)
            .position(|k| d.push(&[5.0 * (-(k as f64) / 50.0).exp()]))
            .unwrap();
        // 5·20.4·e^(−k/50) ≤ 0.002·0.005 → k ≈ 50·ln(1.02e7) ≈ 807.
        assert!((800..=815).contains(&settled_at), "settled at {settled_at}");
    }

    #[test]
    fn every_channel_must_settle() {
        let mut d = SettleDetector::new(10, 0.01, 2);
        assert!(!(0..100).any(|k| d.push(&[1.0, k as f64])));
    }
}
