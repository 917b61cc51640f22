//! [`Stop`]: a flag that long computations (planning, replays, simulations) look at to end
//! early with [`crate::DfsError::Cancelled`]. dfs-core only reads it; whoever runs the work
//! (the server: a request's time limit, a client that left, shutdown) sets it. Pure: no clock,
//! no I/O; a deadline is whoever sets the flag when it passes.
//!
//! The loops of [`crate::replay`] look at it often enough that a stop is honoured within about
//! 0.1 s of CPU on the largest hand accepted (every candidate pose, inverse-kinematics solve and
//! force sample of planning, every few hundred probes of the closing-motion search, every tick
//! of a replay).

use crate::error::{DfsError, Result};
use std::sync::atomic::{AtomicBool, Ordering};

/// A cancellation flag, set once and never cleared.
#[derive(Debug, Default)]
pub struct Stop(AtomicBool);

/// The flag of work nobody stops ([`Stop::never`]); [`Stop::stop`] leaves it unset.
static NEVER: Stop = Stop(AtomicBool::new(false));

impl Stop {
    /// A flag not set yet.
    pub const fn new() -> Self {
        Stop(AtomicBool::new(false))
    }

    /// A flag that is never set, for work that runs to its end. Shared by every such caller,
    /// so stopping it does nothing.
    pub fn never() -> &'static Stop {
        &NEVER
    }

    /// Asks the work to stop (a no-op on [`Stop::never`]).
    pub fn stop(&self) {
        if !std::ptr::eq(self, &NEVER) {
            self.0.store(true, Ordering::Relaxed);
        }
    }

    /// Whether the work was asked to stop.
    pub fn is_stopped(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    /// `Err(`[`DfsError::Cancelled`]`)` once the work was asked to stop: `stop.check()?` in a
    /// loop.
    pub fn check(&self) -> Result<()> {
        if self.is_stopped() {
            Err(DfsError::Cancelled)
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stop_is_seen_once_set_and_the_never_flag_cannot_be_set() {
        let stop = Stop::new();
        assert!(!stop.is_stopped());
        assert_eq!(stop.check(), Ok(()));
        stop.stop();
        assert!(stop.is_stopped());
        assert_eq!(stop.check(), Err(DfsError::Cancelled));
        Stop::never().stop();
        assert!(!Stop::never().is_stopped());
        assert!(Stop::never().check().is_ok());
    }
}
