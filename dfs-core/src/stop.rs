//! [`Stop`]: a flag that long computations (planning, replays, simulations) look at to end
//! early with [`crate::DfsError::Cancelled`]. dfs-core only reads it; whoever runs the work
//! (the server: a request's time limit, a client that left, shutdown) sets it.

use std::sync::atomic::{AtomicBool, Ordering};

/// A cancellation flag, set once and never cleared.
#[derive(Debug, Default)]
pub struct Stop(AtomicBool);

/// The flag of work nobody stops.
static NEVER: Stop = Stop(AtomicBool::new(false));

impl Stop {
    /// A flag not set yet.
    pub const fn new() -> Self {
        Stop(AtomicBool::new(false))
    }

    /// A flag that is never set, for work that runs to its end.
    pub fn never() -> &'static Stop {
        &NEVER
    }

    /// Asks the work to stop.
    pub fn stop(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether the work was asked to stop.
    pub fn is_stopped(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}
