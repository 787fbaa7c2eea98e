//! What of a long hold the analysis reads: a test's memory does not grow
//! with its length.
//!
//! The record file keeps every sample. What identification and the
//! diagnosis read (the [`super::Record`] the live bench and the reader
//! build at [`Resolution::Analysis`]) keeps, of each step segment and each
//! series (voltage, current, speed):
//!
//! - its head: the step and its transient, where the motor's dynamics
//!   show, and as long again. The current readings are taken in windows
//!   of [`WINDOW`]; the motor has settled at the first window whose mean
//!   agrees with the window's before it ([`agree`]). The head holds twice
//!   the readings up to there, at least [`HEAD_SAMPLES`] and at most
//!   [`HEAD_MAX`]: what is left of the transient at its end is the square
//!   of what was left when the motor settled, so a method that integrates
//!   the response (the moments) still sees all of it. Voltage and speed
//!   readings up to the head's last current reading belong to it;
//! - its last [`TAIL_SAMPLES`] samples: the settled level the plan held.
//!
//! What lies between is more of the same level, and would cost memory and
//! analysis time in proportion to the hold's length. Where the head ends
//! on the level the tail holds ([`splices`]), the tail follows the head
//! one sample interval later: the analysis' clock leaves out what lies
//! between (times after the head, in this segment and the ones after it,
//! read that much earlier), so every segment stays evenly sampled and
//! still follows the one before it. Every DC model is simulated one
//! sample interval at a time, and under a constant voltage a settled
//! motor's state at the head's end is its state at the tail's start.
//! Where it does not (a drift), the segment is its head alone.
//!
//! A segment of up to [`PAST_HEAD`] samples past its head is read whole
//! (cutting it would save little and perturb the methods that integrate a
//! whole segment), as is a coast-down (it lasts as long as the rotor takes
//! to stop, whatever the plan's holds).
//!
//! Samples are assigned to segments after [`PENDING`] later samples of
//! their series have arrived (or when the record is finished), so a
//! segment marker may arrive that much after its first samples.

use std::collections::VecDeque;

/// Fewest current readings of a step segment's head (1.02 s at 2 kHz).
pub const HEAD_SAMPLES: usize = 2048;
/// Most current readings of a step segment's head (8.2 s at 2 kHz).
pub const HEAD_MAX: usize = 16_384;
/// Current readings per window of the head's settling test.
pub const WINDOW: usize = 256;
/// Samples at a long step segment's end the analysis reads.
pub const TAIL_SAMPLES: usize = 2048;
/// Samples past a step segment's head held while it is recorded: a
/// segment with no more is read whole.
pub const PAST_HEAD: usize = 8192;
/// Samples of a series held unassigned before the oldest are assigned to
/// their segments.
pub const PENDING: usize = 1 << 15;
/// Samples at each side of the splice whose means are compared.
const SIDE: usize = WINDOW;
/// Share of the level the means may differ by (beside their noise).
const LEVEL_SHARE: f64 = 0.01;
/// Standard errors of the difference of the means they may differ by.
const STANDARD_ERRORS: f64 = 4.0;

/// What a record keeps of its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Resolution {
    /// A long step segment's head and tail (this module's rule): for
    /// analysis.
    Analysis,
    /// Every sample (an export).
    Full,
}

/// One series' samples of one segment past its head.
#[derive(Debug, Clone, Default)]
pub(crate) struct SpanSeries {
    /// Samples of the segment seen so far.
    pub seen: usize,
    /// The last [`PAST_HEAD`] samples past the head, `(t_ns, value)`.
    pub tail: VecDeque<(u64, f64)>,
    /// Samples the tail forgot.
    pub dropped: usize,
}

impl SpanSeries {
    /// Counts a sample of the segment's head.
    pub fn head(&mut self) {
        self.seen += 1;
    }

    /// Takes a sample past the segment's head into the tail, which forgets
    /// its oldest sample once full.
    pub fn tail(&mut self, t_ns: u64, value: f64) {
        self.seen += 1;
        if self.tail.len() == PAST_HEAD {
            self.tail.pop_front();
            self.dropped += 1;
        }
        self.tail.push_back((t_ns, value));
    }

    /// Whether samples were left out between the head and the tail.
    pub fn is_cut(&self) -> bool {
        self.dropped > 0
    }

    /// The tail of a cut segment: its last [`TAIL_SAMPLES`].
    pub fn last(&mut self) -> impl Iterator<Item = (u64, f64)> + '_ {
        let skip = self.tail.len().saturating_sub(TAIL_SAMPLES);
        self.tail.drain(skip..)
    }
}

/// Where a step segment's head ends: the settling test on its current
/// readings.
#[derive(Debug, Clone, Default)]
pub(crate) struct Head {
    /// Current readings in the head so far.
    readings: usize,
    /// The running window's count, sum and sum of squares.
    window: (usize, f64, f64),
    /// The last whole window's mean and squared standard error.
    previous: Option<(f64, f64)>,
    /// Readings up to the end of the first window that agreed with the
    /// one before it.
    settled_at: Option<usize>,
    /// The head's last current reading, ns, once it has ended.
    pub end: Option<u64>,
}

impl Head {
    /// Takes the next current reading of the head (the head has not
    /// ended); ends the head at it once it holds twice the readings the
    /// motor took to settle (at least [`HEAD_SAMPLES`]), or [`HEAD_MAX`].
    pub fn reading(&mut self, t_ns: u64, value: f64) {
        self.readings += 1;
        let (n, sum, squares) = &mut self.window;
        *n += 1;
        *sum += value;
        *squares += value * value;
        if *n == WINDOW {
            let m = WINDOW as f64;
            let mean = *sum / m;
            let var = ((*squares - m * mean * mean) / (m - 1.0)).max(0.0);
            let this = (mean, var / m);
            if self.settled_at.is_none() && self.previous.is_some_and(|p| agree(p, this)) {
                self.settled_at = Some(self.readings);
            }
            self.previous = Some(this);
            self.window = (0, 0.0, 0.0);
        }
        let enough = self
            .settled_at
            .is_some_and(|k| self.readings >= (2 * k).max(HEAD_SAMPLES));
        if enough || self.readings >= HEAD_MAX {
            self.end = Some(t_ns);
        }
    }
}

/// Whether two means, each with its squared standard error, agree within
/// 1 % of the level plus four standard errors of their difference.
fn agree((a, va): (f64, f64), (b, vb): (f64, f64)) -> bool {
    let allowed = LEVEL_SHARE * a.abs().max(b.abs()) + STANDARD_ERRORS * (va + vb).sqrt();
    (a - b).abs() <= allowed
}

/// Whether `tail` continues `head` at one level: the means of the last
/// [`SIDE`] samples of `head` and the first of `tail` [`agree`] (each
/// side's standard error from the spread of its samples).
pub fn splices(head: &[f64], tail: &[f64]) -> bool {
    let m = SIDE.min(head.len()).min(tail.len());
    if m < 2 {
        return false;
    }
    let stats = |x: &[f64]| {
        let n = x.len() as f64;
        let mean = x.iter().sum::<f64>() / n;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var / n)
    };
    agree(stats(&head[head.len() - m..]), stats(&tail[..m]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tail_keeps_the_last_samples() {
        let mut s = SpanSeries::default();
        let n = PAST_HEAD + 10;
        for k in 0..n {
            s.tail(k as u64, k as f64);
        }
        assert_eq!(s.tail.len(), PAST_HEAD);
        assert_eq!(s.tail.front(), Some(&(10, 10.0)));
        assert!(s.is_cut());
        let last: Vec<(u64, f64)> = s.last().collect();
        assert_eq!(last.len(), TAIL_SAMPLES);
        assert_eq!(last[0].0 as usize, n - TAIL_SAMPLES);
        assert_eq!(last[TAIL_SAMPLES - 1].0 as usize, n - 1);
        let mut whole = SpanSeries::default();
        for k in 0..PAST_HEAD {
            whole.tail(k as u64, 0.0);
        }
        assert!(!whole.is_cut());
    }

    #[test]
    fn the_head_holds_twice_the_settling_or_at_its_most() {
        // A first-order decay of time constant `tau` readings to 1.0 with
        // ±0.001 alternating noise: the readings in the head.
        let end = |tau: f64| {
            let mut head = Head::default();
            let mut k = 0u64;
            while head.end.is_none() {
                let noise = if k % 2 == 0 { 1e-3 } else { -1e-3 };
                head.reading(k, 1.0 + (-(k as f64) / tau).exp() + noise);
                k += 1;
            }
            (head.end.unwrap() as usize + 1, head.settled_at)
        };
        assert_eq!(end(100.0).0, HEAD_SAMPLES);
        // τ = 2000 readings: two windows agree within 1 % once the decay's
        // change over a window, 256/2000·e^(−k/2000), is below about
        // 0.01: after 5120 readings; the head holds twice that.
        let (slow, settled) = end(2000.0);
        assert_eq!(settled, Some(5120));
        assert_eq!(slow, 10_240);
        assert_eq!(
            end(1e9),
            (HEAD_SAMPLES, Some(2 * WINDOW)),
            "a level that hardly moves"
        );
        let mut ramp = Head::default();
        for k in 0..HEAD_MAX as u64 {
            assert!(ramp.end.is_none());
            ramp.reading(k, k as f64 * k as f64);
        }
        assert_eq!(ramp.end, Some(HEAD_MAX as u64 - 1));
    }

    #[test]
    fn a_level_splices_and_a_motor_still_moving_does_not() {
        // Noise of ±0.05 about 2.0 on both sides.
        let noisy = |base: f64| -> Vec<f64> {
            (0..400)
                .map(|k| base + if k % 2 == 0 { 0.05 } else { -0.05 })
                .collect()
        };
        assert!(splices(&noisy(2.0), &noisy(2.0)));
        // Within 1 % of the level.
        assert!(splices(&noisy(2.0), &noisy(2.015)));
        // 5 % apart: still moving.
        assert!(!splices(&noisy(2.0), &noisy(2.1)));
        // A quantised reading that does not move at all.
        assert!(splices(&[7.0; 300], &[7.0; 300]));
        assert!(!splices(&[7.0; 300], &[7.5; 300]));
        assert!(!splices(&[1.0], &[1.0]));
    }
}
