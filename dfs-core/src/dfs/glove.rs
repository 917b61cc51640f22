//! Stage 1 of the tick, [`Dfs::stage_glove`]: a glove sample is checked before anything
//! changes (its lengths, its angles within the hand's limits and slack, its torques finite and
//! within the glove's range, the base pose finite).

use super::{Dfs, GloveSample};
use crate::error::{DfsError, Result};

impl Dfs {
    /// Refuses a sample the tick cannot take; the error names what is wrong with it.
    pub(super) fn check_sample(&self, s: &GloveSample<'_>) -> Result<()> {
        let n = self.hand.dof();
        if s.tau.len() != n {
            return Err(DfsError::WrongLength {
                what: "joint torques",
                got: s.tau.len(),
                expected: n,
            });
        }
        self.hand.check_angles(s.q, self.params.angle_slack)?;
        for (i, &t) in s.tau.iter().enumerate() {
            if !t.is_finite() {
                return Err(DfsError::NotFinite {
                    what: "joint torque",
                    index: i,
                    value: t,
                });
            }
            let lim = self.hand.torque_limit[i] * self.params.torque_range;
            if t.abs() > lim {
                return Err(DfsError::OutOfRange {
                    what: "joint torque",
                    index: i,
                    value: t,
                    lower: -lim,
                    upper: lim,
                });
            }
        }
        let b = &s.base;
        if !(b.translation.vector.iter().all(|v| v.is_finite())
            && b.rotation.coords.iter().all(|v| v.is_finite()))
        {
            return Err(DfsError::invalid("base", "hand base pose is not finite"));
        }
        Ok(())
    }
}
