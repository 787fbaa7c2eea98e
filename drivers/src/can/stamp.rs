//! [`PeriodicStamp`]: send times of a periodic CAN message, estimated from
//! its arrival times on the host.
//!
//! A CAN frame carries no time of its own, and an adapter behind USB or a
//! serial line hands frames over in bursts: two frames sent 2 ms apart may
//! reach the host 10 µs apart. Stamping each on arrival would make a speed
//! derived from consecutive positions jump by orders of magnitude. A
//! periodic message (a CANopen TPDO on its event timer) is sent on a grid
//! `t = phase + n · period`; its arrival is never earlier than its send, so
//! the least-delayed arrivals pin the grid's phase (a minimum filter), and
//! every frame is stamped on the grid, never later than its own arrival:
//!
//! - The next frame is the next slot (`n + 1`) unless it comes more than
//!   `resync_periods` after the previous stamp: then frames were lost, and
//!   the index jumps to the slot nearest its arrival.
//! - The phase creeps later by `period / 1000` per frame, so the grid
//!   follows a device clock up to 0.1 % slower than nominal (a faster
//!   one pulls the phase earlier by itself) and recovers from a loss taken
//!   for a delay.
//!
//! Losses shorter than `resync_periods` periods are first taken for delays
//! (CAN itself retransmits; on a healthy bus a late frame is far more
//! common than a lost one). A delay leaves a backlog that drains in a
//! burst, each frame's lag behind the grid a period less than the last;
//! frames after a loss come at the grid's pace instead, at a steady lag.
//! So when [`LAG_FRAMES`] frames in a row lag the grid by more than
//! [`LAG_PERIODS`] periods, each within half a period of the lag before,
//! the frames were lost: the index jumps to the slot nearest the arrival
//! and the slots skipped count as lost (a few periods after the frames
//! resume, where the stamps would otherwise have lagged until the creep
//! caught up, for as many thousand frames as were lost).

/// Estimates send times of one periodic message. See the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicStamp {
    period_ns: f64,
    resync_periods: f64,
    phase_ns: f64,
    last: Option<(i64, f64)>,
    /// The last frame's lag behind the grid, ns.
    last_lag: Option<f64>,
    /// Frames in a row at a steady lag of more than [`LAG_PERIODS`].
    paced: u32,
}

/// A lag behind the grid, in periods, beyond which frames that keep the
/// grid's pace are taken for frames after a loss (a least-delayed frame
/// pins the lag at 0; a healthy link's bursts stay within a few periods).
pub const LAG_PERIODS: f64 = 4.0;

/// Frames in a row at a steady lag beyond [`LAG_PERIODS`] that make a loss.
pub const LAG_FRAMES: u32 = 3;

/// What [`PeriodicStamp::arrived`] decided for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stamped {
    /// Estimated send time, ns (never after the arrival).
    pub t_ns: u64,
    /// Frames taken as lost before this one.
    pub lost: u64,
    /// Where the frame stands in a run of frames at a steady lag (the
    /// frames after a loss, until [`LAG_FRAMES`] of them make it one).
    pub run: LagRun,
}

/// A frame's place in a run of frames at a steady lag of more than
/// [`LAG_PERIODS`] behind the grid. Until the run is long enough to be
/// taken for a loss, its frames are stamped on the old grid, behind the
/// message's true time; a consumer that can wait a few periods holds them
/// and restamps them once the loss is known.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LagRun {
    /// Not in such a run: any frames held for one keep their stamps.
    None,
    /// The `n`-th frame of a run not yet taken for a loss: the `n − 1`
    /// frames before it are the run's, any held before those are not.
    Open(u32),
    /// The run is a loss: this frame is stamped on the grid after it, and
    /// the run's `LAG_FRAMES − 1` frames before it were sent one, two, …
    /// periods before it.
    Loss,
}

impl PeriodicStamp {
    /// A message sent every `1 / rate_hz` s; a silence longer than
    /// `resync_periods` periods is taken as lost frames.
    pub fn new(rate_hz: f64, resync_periods: f64) -> PeriodicStamp {
        PeriodicStamp {
            period_ns: 1e9 / rate_hz,
            resync_periods,
            phase_ns: 0.0,
            last: None,
            last_lag: None,
            paced: 0,
        }
    }

    /// A frame arrived at `arrival_ns`.
    pub fn arrived(&mut self, arrival_ns: u64) -> Stamped {
        let a = arrival_ns as f64;
        let p = self.period_ns;
        let (mut n, mut lost) = match self.last {
            None => {
                self.phase_ns = a;
                (0, 0)
            }
            Some((n_last, t_last)) => {
                self.phase_ns += p * 1e-3;
                if a - t_last > self.resync_periods * p {
                    let n = (((a - self.phase_ns) / p).round() as i64).max(n_last + 1);
                    (n, (n - n_last - 1) as u64)
                } else {
                    (n_last + 1, 0)
                }
            }
        };
        let mut t = self.phase_ns + n as f64 * p;
        let lag = a - t;
        let run = if self.lags_after_a_loss(lag) {
            let skipped = (lag / p).round() as i64;
            n += skipped;
            lost += skipped as u64;
            t = self.phase_ns + n as f64 * p;
            LagRun::Loss
        } else if lag > LAG_PERIODS * p {
            LagRun::Open(self.paced + 1)
        } else {
            LagRun::None
        };
        if t > a {
            // Sent no later than it arrived: this frame is the least
            // delayed so far, and pins the phase.
            self.phase_ns = a - n as f64 * p;
            t = a;
        }
        if let Some((_, t_last)) = self.last {
            t = t.max(t_last);
        }
        self.last = Some((n, t));
        Stamped {
            t_ns: t.max(0.0).round() as u64,
            lost,
            run,
        }
    }

    /// The message's period, ns.
    pub fn period_ns(&self) -> f64 {
        self.period_ns
    }

    /// Whether a frame lagging the grid by `lag` ns completes a run of
    /// [`LAG_FRAMES`] at a steady lag beyond [`LAG_PERIODS`] (see the
    /// module docs); the run starts again after it.
    fn lags_after_a_loss(&mut self, lag: f64) -> bool {
        let p = self.period_ns;
        let far = LAG_PERIODS * p;
        let steady = lag > far && self.last_lag.is_some_and(|l| l > far && l - lag < p / 2.0);
        self.paced = if steady { self.paced + 1 } else { 0 };
        self.last_lag = Some(lag);
        if self.paced + 1 >= LAG_FRAMES {
            self.paced = 0;
            self.last_lag = None;
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_burst_after_a_delay_is_spread_back_onto_the_grid() {
        let mut s = PeriodicStamp::new(500.0, 10.0);
        // Sent at 0, 2, 4, 6, 8 ms; the frames of 2 and 4 ms are held
        // until 4.9 ms and arrive together.
        let arrivals = [0, 4_900_000, 4_910_000, 6 * MS, 8 * MS];
        let t: Vec<u64> = arrivals.iter().map(|&a| s.arrived(a).t_ns).collect();
        // On the grid, within the phase's creep (period / 1000 per frame).
        for (k, (&t, sent)) in t
            .iter()
            .zip([0, 2 * MS, 4 * MS, 6 * MS, 8 * MS])
            .enumerate()
        {
            assert!(
                t.abs_diff(sent) <= k as u64 * 2_000,
                "frame {k}: {t} ns, sent {sent} ns"
            );
        }
    }

    #[test]
    fn a_long_silence_counts_lost_frames() {
        let mut s = PeriodicStamp::new(1000.0, 10.0);
        assert_eq!(s.arrived(0).lost, 0);
        assert_eq!(s.arrived(MS).lost, 0);
        let after = s.arrived(31 * MS);
        assert_eq!(after.lost, 29);
        assert!(after.t_ns <= 31 * MS && after.t_ns >= 30 * MS, "{after:?}");
    }

    /// Frames at 500 Hz, the ones of `sent` (slot numbers) only, each
    /// arriving 0.3 ms after its send plus `extra` (by slot); the stamps
    /// and the losses counted.
    fn stamp(sent: &[u64], extra: impl Fn(u64) -> u64) -> (Vec<u64>, u64) {
        let mut s = PeriodicStamp::new(500.0, 125.0);
        let mut lost = 0;
        let t = sent
            .iter()
            .map(|&k| {
                let st = s.arrived(k * 2 * MS + 300_000 + extra(k));
                lost += st.lost;
                st.t_ns
            })
            .collect();
        (t, lost)
    }

    #[test]
    fn a_short_loss_is_counted_once_the_frames_after_it_keep_their_pace() {
        // 100 ms of a 500 Hz message lost (slots 100 to 149), far less
        // than the resynchronising silence of 125 periods.
        let sent: Vec<u64> = (0..100).chain(150..300).collect();
        let (t, lost) = stamp(&sent, |_| 0);
        assert_eq!(lost, 50);
        // A few frames after the loss, back on the send grid.
        for (&k, &t) in sent.iter().zip(&t).skip(100 + LAG_FRAMES as usize) {
            assert!(t.abs_diff(k * 2 * MS) <= MS, "slot {k}: {t} ns");
        }
    }

    /// The frames after a short loss form a run that ends in a loss: the
    /// first open, the last taken for the loss; a healthy stream has none.
    #[test]
    fn the_frames_after_a_short_loss_are_a_run_ending_in_the_loss() {
        let mut s = PeriodicStamp::new(500.0, 125.0);
        let runs: Vec<LagRun> = (0..100)
            .chain(150..155)
            .map(|k| s.arrived(k * 2 * MS + 300_000).run)
            .collect();
        assert!(runs[..100].iter().all(|r| *r == LagRun::None));
        assert_eq!(
            runs[100..],
            [
                LagRun::Open(1),
                LagRun::Open(2),
                LagRun::Loss,
                LagRun::None,
                LagRun::None
            ]
        );
    }

    #[test]
    fn a_backlog_draining_in_a_burst_is_a_delay_not_a_loss() {
        // Slots 100 to 149 held up for 100 ms, then sent back to back
        // (0.2 ms apart) ahead of slot 150: nothing is lost.
        let sent: Vec<u64> = (0..300).collect();
        let (t, lost) = stamp(&sent, |k| match k {
            100..=149 => (150 - k) * 2 * MS - (150 - k) * 200_000,
            _ => 0,
        });
        assert_eq!(lost, 0);
        for (&k, &t) in sent.iter().zip(&t) {
            assert!(t.abs_diff(k * 2 * MS) <= MS, "slot {k}: {t} ns");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, rng_seed: proptest::test_runner::RngSeed::Fixed(406), ..ProptestConfig::default() })]
        /// Stamps never pass the arrival, never go back, and after delays
        /// of up to 2.5 periods stay within the least recent delay (plus
        /// the phase's creep) of the true send times.
        #[test]
        fn stamps_follow_the_send_grid(delays in proptest::collection::vec(0u64..5_000_000, 200)) {
            let period = 2 * MS;
            let creep = period / 1000;
            let window = 100usize;
            let mut s = PeriodicStamp::new(500.0, 10.0);
            let mut last_t = 0;
            let mut last_arrival = 0;
            let mut effective = Vec::new();
            for (k, d) in delays.iter().enumerate() {
                let sent = 1_000 * MS + k as u64 * period;
                // Arrivals keep their order (one link).
                let arrival = (sent + d).max(last_arrival);
                last_arrival = arrival;
                effective.push(arrival - sent);
                let st = s.arrived(arrival);
                prop_assert!(st.t_ns <= arrival);
                prop_assert!(st.t_ns >= last_t);
                prop_assert_eq!(st.lost, 0);
                last_t = st.t_ns;
                if k >= window {
                    // The phase sits no later than the least delay of the
                    // last `window` frames plus its creep since.
                    let least = effective[k - window..=k].iter().min().copied().unwrap_or(0);
                    let bound = least + window as u64 * creep + 1_000;
                    prop_assert!(
                        st.t_ns.abs_diff(sent) <= bound,
                        "frame {}: error {} ns, bound {} ns", k, st.t_ns.abs_diff(sent), bound
                    );
                }
            }
        }
    }
}
