//! Keeping a long-running server's resident memory from creeping up (glibc's allocator).
//!
//! glibc gives each thread that contends for the allocator an arena of its own, up to 8 per
//! core, and returns an arena's free pages to the system only from the top of its heap. A
//! server whose requests allocate and free tens of MiB at a time (reading and segmenting an
//! upload, planning a replay) on whichever worker or blocking thread runs them leaves free but
//! resident pages scattered over many arenas: the 10-minute soak of issue 17 saw 15 arenas of
//! 10-40 MiB each and the resident set rise from 206 to 310 MiB with no leak (every allocation
//! freed, the figures in BENCHMARKS.md "Availability under load"). Two measures, both glibc's
//! own: at most one arena per core (`M_ARENA_MAX`), and `malloc_trim(0)` every
//! [`TRIM_INTERVAL`], which hands every whole free page of every arena back (`MADV_DONTNEED`).
//! Elsewhere (musl, other systems) these are no-ops.
//!
//! The workspace denies `unsafe`; this module allows it for exactly these two calls into libc,
//! which take plain integers and have no memory-safety preconditions.
#![allow(unsafe_code)]

use std::time::Duration;

/// How often [`trim_periodically`] returns free memory to the system.
pub const TRIM_INTERVAL: Duration = Duration::from_secs(10);

/// Caps glibc's arenas at one per core. Call before the runtime starts its threads (an arena
/// already made stays).
pub fn limit_arenas() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
        let arenas = libc::c_int::try_from(cores.max(2)).unwrap_or(libc::c_int::MAX);
        // SAFETY: mallopt only sets an allocator parameter; M_ARENA_MAX takes any positive value.
        unsafe {
            libc::mallopt(libc::M_ARENA_MAX, arenas);
        }
    }
}

/// Returns free memory to the system now; true if any was returned.
pub fn trim() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: malloc_trim takes the allocator's own locks; any thread may call it.
        unsafe { libc::malloc_trim(0) != 0 }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

/// Calls [`trim`] every [`TRIM_INTERVAL`] on a blocking thread, for ever (spawn it and let the
/// runtime's shutdown end it).
pub async fn trim_periodically() {
    let mut tick = tokio::time::interval(TRIM_INTERVAL);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        let _ = tokio::task::spawn_blocking(trim).await;
    }
}

#[cfg(test)]
mod tests {
    /// Resident memory of this process (kB), from `/proc/self/status`.
    fn rss_kb() -> u64 {
        std::fs::read_to_string("/proc/self/status")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("VmRSS:"))
                    .and_then(|l| l.split_whitespace().nth(1))
                    .and_then(|v| v.parse().ok())
            })
            .unwrap_or(0)
    }

    #[test]
    fn trimming_returns_free_pages_from_the_middle_of_the_heap() {
        if !cfg!(all(target_os = "linux", target_env = "gnu")) {
            return;
        }
        super::limit_arenas();
        // 80 MB of 4 kB blocks, then all but every 64th freed: 250 kB runs of free pages held
        // between live blocks, which only malloc_trim hands back (the heap's top is in use).
        let mut blocks: Vec<Vec<u8>> = (0..20_000).map(|_| vec![1u8; 4000]).collect();
        let mut i = 0;
        blocks.retain(|_| {
            i += 1;
            i % 64 == 0
        });
        std::hint::black_box(&blocks);
        let before = rss_kb();
        super::trim();
        let after = rss_kb();
        assert!(
            after + 30_000 < before,
            "RSS {before} kB before trimming, {after} kB after"
        );
        drop(blocks);
    }
}
