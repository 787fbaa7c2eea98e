//! How a simulated sensor stream delivers its batches, for every
//! simulated rig: on a virtual clock, as fast as the CPU allows (yielding
//! now and then so that signal handlers and the recorder's queue run), or
//! paced at the wall clock, each batch delivered when the wall-clock time
//! since the start reaches its data time, as on a real rig.

use std::time::Duration;

use tokio::time::Instant;

/// Plant steps between two yields on the virtual clock.
const YIELD_EVERY: u64 = 1024;

/// A simulated stream's clock; see the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Pacing {
    /// As fast as the CPU allows.
    Virtual,
    /// At the wall clock from `start`, or from the first batch when
    /// `None`.
    Wall {
        /// The wall-clock instant of data time zero.
        start: Option<Instant>,
    },
}

impl Pacing {
    /// At the wall clock from now.
    pub(crate) fn wall_from_now() -> Pacing {
        Pacing::Wall {
            start: Some(Instant::now()),
        }
    }

    /// At the wall clock from the first batch.
    pub(crate) fn wall_from_first_batch() -> Pacing {
        Pacing::Wall { start: None }
    }

    /// Whether the stream runs on the virtual clock.
    pub(crate) fn is_virtual(&self) -> bool {
        *self == Pacing::Virtual
    }

    /// Start the wall clock now if it has not started (before the first
    /// batch is sampled, so that its data time counts from here).
    pub(crate) fn start(&mut self) {
        if let Pacing::Wall { start } = self {
            start.get_or_insert_with(Instant::now);
        }
    }

    /// Wait until the batch of data time `t_ns`, the plant's step `step`,
    /// is due.
    pub(crate) async fn wait(&mut self, t_ns: u64, step: u64) {
        match self {
            Pacing::Wall { start } => {
                let start = *start.get_or_insert_with(Instant::now);
                tokio::time::sleep_until(start + Duration::from_nanos(t_ns)).await;
            }
            Pacing::Virtual => {
                if step % YIELD_EVERY == 0 {
                    tokio::task::yield_now().await;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn wall_pacing_waits_for_the_data_time_from_its_start() {
        let mut p = Pacing::wall_from_first_batch();
        assert!(!p.is_virtual());
        let t0 = Instant::now();
        p.wait(0, 0).await;
        p.wait(250_000_000, 1).await;
        assert_eq!(Instant::now() - t0, Duration::from_millis(250));
    }

    #[tokio::test(start_paused = true)]
    async fn virtual_pacing_does_not_wait() {
        let mut p = Pacing::Virtual;
        assert!(p.is_virtual());
        let t0 = Instant::now();
        for step in 0..3000 {
            p.wait(step * 1_000_000_000, step).await;
        }
        assert_eq!(Instant::now(), t0);
    }
}
