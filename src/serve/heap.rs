//! Handing the memory a finished test freed back to the system.
//!
//! A test's analysis (identification and diagnosis) allocates about
//! 13 MB on the runtime's blocking-pool threads and frees it when the
//! test ends. glibc's malloc keeps freed memory in its per-thread arenas
//! for reuse rather than returning it, so a daemon that runs test after
//! test sees its resident size climb by the arenas' slack while its live
//! heap does not: a heap profile of 400 soak tests (heaptrack, see
//! `docs/reliability.md`) found the live heap between tests at 1–2 MB (the
//! records index, about 1 kB a test by design, and the last 100 tests'
//! statuses), its peak at 15 MB, and 64 kB not freed at exit, while the
//! anonymous resident memory grew from 11 to 44 MB.
//!
//! After each test the daemon asks glibc to return the free memory of
//! every arena (`malloc_trim(0)`, which walks all arenas since glibc 2.8),
//! off the reactor. With another C library it does nothing.

/// Return the memory freed by a finished test to the system, where the
/// allocator can (glibc); `true` when some was returned.
pub async fn release_freed_memory() -> bool {
    tokio::task::spawn_blocking(trim).await.unwrap_or(false)
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn trim() -> bool {
    // SAFETY: `malloc_trim` takes no pointer and only works on the
    // allocator's own free lists, under each arena's lock; any thread may
    // call it at any time.
    unsafe { libc::malloc_trim(0) != 0 }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn trim() -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Memory freed below a block still in use (which `free` alone does
    /// not return: it trims only the top of a heap) is handed back.
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[tokio::test]
    async fn memory_freed_below_a_live_block_is_returned() {
        let blocks: Vec<Vec<u8>> = (0..64 * 1024).map(|i| vec![i as u8; 1000]).collect();
        let live = vec![1u8; 1000];
        drop(blocks);
        assert!(release_freed_memory().await);
        assert_eq!(live.iter().map(|&b| usize::from(b)).sum::<usize>(), 1000);
    }
}
