//! How many threads a diagnosis may work on.
//!
//! The DC diagnosis fits its candidates and folds on every core. Where
//! motorbench shares the machine (several tests side by side, a daemon
//! beside a rig polled on the wall clock), `MOTORBENCH_THREADS` caps that.

/// The environment variable that caps the worker threads of an analysis.
pub const THREADS_VAR: &str = "MOTORBENCH_THREADS";

/// The worker threads an analysis may use: `MOTORBENCH_THREADS` when it
/// holds a positive whole number, else one per core. A value that is not
/// one is ignored with a warning, not fatal: the analysis still runs.
pub fn worker_threads() -> usize {
    let cores = || std::thread::available_parallelism().map_or(1, |n| n.get());
    match std::env::var(THREADS_VAR) {
        Ok(v) => parse_threads(&v).unwrap_or_else(|| {
            tracing::warn!("{THREADS_VAR}={v:?} is not a positive whole number; using every core");
            cores()
        }),
        Err(_) => cores(),
    }
}

/// A positive thread count, or `None`.
fn parse_threads(v: &str) -> Option<usize> {
    v.trim().parse::<usize>().ok().filter(|&n| n > 0)
}

#[cfg(test)]
mod tests {
    use super::parse_threads;

    #[test]
    fn only_a_positive_whole_number_is_a_thread_count() {
        assert_eq!(parse_threads("1"), Some(1));
        assert_eq!(parse_threads(" 4\n"), Some(4));
        for bad in ["0", "-1", "two", "", "1.5"] {
            assert_eq!(parse_threads(bad), None, "{bad:?}");
        }
    }
}
