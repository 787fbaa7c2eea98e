//! The progress bar `motorbench run` shows on stderr while a test runs,
//! and the plan's warnings as they come (the record holds them all).

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

use crate::bench::Progress;
use crate::record::EventLevel;

/// Warnings printed on stderr while a test runs; the rest are counted
/// once (every one is in the record's `/bench/event`).
const PRINTED_WARNINGS: usize = 20;

/// A progress bar on stderr (hidden when stderr is not a terminal), and
/// the plan's warnings printed as they come unless quiet.
pub(crate) struct Bar {
    bar: ProgressBar,
    last_tick_ms: AtomicU64,
    quiet: bool,
    warnings: AtomicUsize,
}

impl Bar {
    /// A bar, hidden when `quiet` (and no warnings printed).
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
            quiet,
            warnings: AtomicUsize::new(0),
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

    fn event(&self, t_s: f64, level: EventLevel, message: &str) {
        if self.quiet || level != EventLevel::Warn {
            return;
        }
        let n = self.warnings.fetch_add(1, Ordering::Relaxed);
        self.bar.suspend(|| match n {
            n if n < PRINTED_WARNINGS => {
                eprintln!("motorbench: warning at test time {t_s:.3} s: {message}")
            }
            PRINTED_WARNINGS => eprintln!(
                "motorbench: more warnings follow; the record's /bench/event holds every one"
            ),
            _ => {}
        });
    }

    fn done(&self, message: &str) {
        self.bar.finish_and_clear();
        if !self.bar.is_hidden() {
            eprintln!("{message}");
        }
    }
}
