//! The progress bar `motorbench run` shows on stderr while a test runs.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

use crate::bench::Progress;

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub(crate) struct Bar {
    bar: ProgressBar,
    last_tick_ms: AtomicU64,
}

impl Bar {
    /// A bar, hidden when `quiet`.
    pub(crate) fn new(quiet: bool) -> Bar {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(0)
        };
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] test time {prefix} {bar:24} segment {pos}/{len} {msg}",
            )
            .expect("valid template"),
        );
        bar.enable_steady_tick(Duration::from_millis(120));
        Bar {
            bar,
            last_tick_ms: AtomicU64::new(0),
        }
    }
}

impl Progress for Bar {
    fn segment(&self, index: usize, total: usize, label: &str) {
        self.bar.set_length(total as u64);
        self.bar.set_position(index as u64 + 1);
        self.bar.set_message(label.to_string());
    }

    fn tick(&self, t_s: f64) {
        let ms = (t_s * 1e3) as u64;
        if ms >= self.last_tick_ms.load(Ordering::Relaxed) + 100 {
            self.last_tick_ms.store(ms, Ordering::Relaxed);
            self.bar.set_prefix(format!("{t_s:.1} s"));
        }
    }

    fn done(&self, message: &str) {
        self.bar.finish_and_clear();
        if !self.bar.is_hidden() {
            eprintln!("{message}");
        }
    }
}
