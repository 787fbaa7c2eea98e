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
//! So the daemon holds glibc to two arenas ([`limit_arenas`], before its
//! runtime starts threads; by default glibc opens up to eight per core),
//! and after each test asks it to return the free memory of every arena
//! (`malloc_trim(0)`, which walks all arenas since glibc 2.8), off the
//! reactor. Either alone did little: trimming the eight arenas glibc had opened left most of
//! their memory in place (30–35 MB), and two arenas without a trim still
//! grew (see the soak's figures in `docs/reliability.md`). With another C
//! library both do nothing.

/// Glibc's malloc arenas the daemon allows.
pub const MALLOC_ARENAS: i32 = 2;

/// Hold the allocator to [`MALLOC_ARENAS`] arenas (glibc); call it before
/// any thread is started. `MALLOC_ARENA_MAX` in the environment, where
/// set, is left to rule.
pub fn limit_arenas() {
    if std::env::var_os("MALLOC_ARENA_MAX").is_none() {
        set_arena_max(MALLOC_ARENAS);
    }
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn set_arena_max(arenas: i32) {
    // SAFETY: `mallopt` takes two integers and sets an allocator
    // parameter under the allocator's lock.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, arenas);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn set_arena_max(_arenas: i32) {}

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
