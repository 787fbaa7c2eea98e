//! How many threads a diagnosis may work on, and the map that uses them.
//!
//! The DC diagnosis fits its candidates and folds on every core. Where
//! motorbench shares the machine (several tests side by side, a daemon
//! beside a rig polled on the wall clock), `MOTORBENCH_THREADS` caps that.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

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

/// Work on every core (or on `MOTORBENCH_THREADS` of them): `f` over
/// `items`, results in order. Each thread takes the next item as it
/// finishes one, so items of uneven cost share out; one worker (one core,
/// or one item) runs on the calling thread.
pub fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let workers = worker_threads().min(items.len().max(1));
    if workers <= 1 {
        return items.iter().map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<R>>> = Mutex::new((0..items.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| loop {
                let n = next.fetch_add(1, Ordering::Relaxed);
                if n >= items.len() {
                    break;
                }
                let r = f(&items[n]);
                results.lock().unwrap_or_else(|e| e.into_inner())[n] = Some(r);
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|r| r.expect("every item is processed"))
        .collect()
}

/// A positive thread count, or `None`.
fn parse_threads(v: &str) -> Option<usize> {
    v.trim().parse::<usize>().ok().filter(|&n| n > 0)
}

#[cfg(test)]
mod tests {
    use super::{par_map, parse_threads};

    #[test]
    fn the_map_keeps_the_items_order() {
        let items: Vec<u64> = (0..50).collect();
        let out = par_map(&items, |&k| {
            // Uneven work, so the threads finish out of order.
            std::thread::sleep(std::time::Duration::from_micros((50 - k) * 20));
            k * k
        });
        assert_eq!(out, items.iter().map(|k| k * k).collect::<Vec<_>>());
        assert!(par_map(&[] as &[u64], |&k| k).is_empty());
    }

    #[test]
    fn only_a_positive_whole_number_is_a_thread_count() {
        assert_eq!(parse_threads("1"), Some(1));
        assert_eq!(parse_threads(" 4\n"), Some(4));
        for bad in ["0", "-1", "two", "", "1.5"] {
            assert_eq!(parse_threads(bad), None, "{bad:?}");
        }
    }
}
