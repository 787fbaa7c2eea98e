//! The wall clock a served simulated plant runs on: the plant steps in
//! its own sample period from the instant it was started, and every
//! request first advances it to "now". The DC and the induction-machine
//! served rigs share this so both count their steps the same way.

use std::time::Instant;

/// A plant's steps on the wall clock: how many it has taken, and which
/// are due by now or by an instant.
#[derive(Debug, Clone)]
pub(crate) struct WallClock {
    start: Instant,
    period_s: f64,
    steps: u64,
}

impl WallClock {
    /// A clock starting now, stepping at `rate_hz`, no step taken yet.
    pub(crate) fn start(rate_hz: f64) -> WallClock {
        WallClock {
            start: Instant::now(),
            period_s: 1.0 / rate_hz,
            steps: 0,
        }
    }

    /// The plant's sample period, seconds.
    pub(crate) fn period_s(&self) -> f64 {
        self.period_s
    }

    /// Take every step due by now: `step` runs once per step, with the
    /// index of the step it takes, oldest first.
    pub(crate) fn catch_up(&mut self, mut step: impl FnMut(u64)) {
        let due = (self.start.elapsed().as_secs_f64() / self.period_s) as u64;
        while self.steps < due {
            step(self.steps);
            self.steps += 1;
        }
    }

    /// The index of the step at the instant `at` (0 before the start).
    pub(crate) fn step_at(&self, at: Instant) -> u64 {
        (at.saturating_duration_since(self.start).as_secs_f64() / self.period_s) as u64
    }

    /// Seconds from the end of the steps taken to now.
    pub(crate) fn since_steps(&self) -> f64 {
        self.start.elapsed().as_secs_f64() - self.steps as f64 * self.period_s
    }
}
