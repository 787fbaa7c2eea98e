//! Settle detection: are the signals still moving, beyond their noise?

use std::collections::VecDeque;

/// Decides when several channels have settled.
///
/// Each channel keeps its last two windows of `window` samples. A channel
/// is settled when the means of the two windows differ by no more than
/// `tolerance·max(|mean|, floor)` plus three standard errors of that
/// difference (so noise alone does not hold a level forever, and a slow
/// drift larger than the tolerance does).
#[derive(Debug, Clone)]
pub struct SettleDetector {
    window: usize,
    tolerance: f64,
    floors: Vec<f64>,
    history: Vec<VecDeque<f64>>,
}

impl SettleDetector {
    /// A detector over `floors.len()` channels; `floors[c]` is the scale
    /// below which channel `c` counts as zero (e.g. a tolerance of the
    /// channel's limit).
    pub fn new(window: usize, tolerance: f64, floors: Vec<f64>) -> SettleDetector {
        let history = floors
            .iter()
            .map(|_| VecDeque::with_capacity(2 * window))
            .collect();
        SettleDetector {
            window: window.max(2),
            tolerance,
            floors,
            history,
        }
    }

    /// Forget everything (a new level began).
    pub fn reset(&mut self) {
        self.history.iter_mut().for_each(VecDeque::clear);
    }

    /// Add one reading per channel; true when every channel is settled.
    pub fn push(&mut self, values: &[f64]) -> bool {
        let mut settled = true;
        for ((h, &v), &floor) in self.history.iter_mut().zip(values).zip(&self.floors) {
            if h.len() == 2 * self.window {
                h.pop_front();
            }
            h.push_back(v);
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
        let mut d = SettleDetector::new(100, 0.002, vec![1e-3]);
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
        let mut d = SettleDetector::new(100, 0.002, vec![1e-3]);
        // A deterministic pseudo-noise of amplitude 0.05 on a level of 1.
        let noisy = (0..400).map(|k| 1.0 + 0.05 * ((k * 7919 % 101) as f64 / 50.0 - 1.0));
        assert!(noisy.map(|v| d.push(&[v])).last().unwrap());
        let mut d = SettleDetector::new(100, 0.002, vec![1e-3]);
        assert!(!(0..1000).any(|k| d.push(&[1.0 + 1e-4 * k as f64])));
    }

    #[test]
    fn every_channel_must_settle() {
        let mut d = SettleDetector::new(10, 0.01, vec![1e-3, 1e-3]);
        assert!(!(0..100).any(|k| d.push(&[1.0, k as f64])));
    }
}
