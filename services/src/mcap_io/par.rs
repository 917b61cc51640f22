//! A small parallel map for reading sessions: chunks are decompressed, and blocks of messages
//! validated or decoded, on every core (the work items are independent and of similar size).

use std::sync::atomic::{AtomicUsize, Ordering};

/// Most worker threads one call uses.
const MAX_WORKERS: usize = 8;

/// Messages per validation or decoding job: large enough that handing out jobs costs nothing,
/// small enough that the cores finish together.
pub(crate) const MESSAGES_PER_JOB: usize = 1024;

/// `f(0), f(1), ..., f(n - 1)`, computed on up to [`MAX_WORKERS`] threads (the calling thread is
/// one of them), returned in index order. A panic in `f` is resumed on the caller.
pub(crate) fn par_map<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let workers = std::thread::available_parallelism()
        .map_or(1, |p| p.get())
        .min(MAX_WORKERS)
        .min(n);
    if workers <= 1 {
        return (0..n).map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let work = || {
        let mut done = Vec::new();
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            if i >= n {
                return done;
            }
            done.push((i, f(i)));
        }
    };
    let mut parts = std::thread::scope(|scope| {
        let helpers: Vec<_> = (1..workers).map(|_| scope.spawn(work)).collect();
        let mut parts = vec![work()];
        for h in helpers {
            parts.push(h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
        }
        parts
    });
    let mut slots: Vec<Option<T>> = (0..n).map(|_| None).collect();
    for (i, v) in parts.drain(..).flatten() {
        slots[i] = Some(v);
    }
    slots
        .into_iter()
        .map(|v| v.expect("every index was computed"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_index_order() {
        let v = par_map(1000, |i| i * 2);
        assert_eq!(v, (0..1000).map(|i| i * 2).collect::<Vec<_>>());
        assert!(par_map(0, |i| i).is_empty());
    }
}
