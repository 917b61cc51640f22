//! The operator's intention along a phase, tick by tick: the arm (hand base) along its
//! minimum-jerk path (a varied approach's bent one), the fingers towards their targets, the
//! grip's ramp and lift-off peak, the share of the load the fingertips carry, and the tremor
//! on top.

use super::reach::{min_jerk, reach_point};
use super::{Simulation, REACH_SHAPE_FROM};
use crate::hand::MAX_DOF;
use crate::math::{Isometry, Real, Vector};
use crate::scenario::Phase;

impl Simulation {
    /// Moves the intention to time `t` (ns) of the current phase: the base pose and its
    /// planned acceleration, the intended joint angles, the grip, the carried share of the
    /// load, the grip's boost, the wrap's closing and the fingertip offset.
    pub(super) fn update_intention(&mut self, t: u64) {
        let span = self.span_now().span;
        let dur = (span.end_ns - span.start_ns) as Real * 1e-9;
        let s = ((t - span.start_ns) as Real * 1e-9 / dur).clamp(0.0, 1.0);
        let (m, m2) = min_jerk(s);
        // Fingers and grip: in `grasp` the fingers close first and the grip ramps up after; in
        // `release` the grip ramps down first and the fingers open after.
        let (sq, sg) = match span.phase {
            Phase::Grasp => ((s / 0.6).min(1.0), ((s - 0.5) / 0.5).max(0.0)),
            Phase::Release => (((s - 0.4) / 0.6).max(0.0), (s / 0.4).min(1.0)),
            _ => (s, s),
        };
        let (mut mq, _) = min_jerk(sq);
        let (mg, _) = min_jerk(sg);
        // A wrap: the fingers close from 20 % to 50 % of `grasp`, and in `release` open after
        // the grip has gone (40 % on).
        self.wrap_close = match span.phase {
            Phase::Grasp => min_jerk((s - 0.2) / 0.3).0,
            Phase::Lift | Phase::Hold | Phase::Transport | Phase::Place => 1.0,
            Phase::Release => 1.0 - min_jerk((s - 0.4) / 0.6).0,
            _ => 0.0,
        };
        let dp = self.to_base.translation.vector - self.from_base.translation.vector;
        let (p, r, acceleration) = match &self.reach_path {
            None => (
                self.from_base.translation.vector + dp * m,
                self.from_base.rotation.slerp(&self.to_base.rotation, m),
                dp * (m2 / (dur * dur)),
            ),
            // A varied approach: along its bent path, pausing if it does; the fingers follow
            // the same progress.
            Some(path) => {
                let (u, du, ddu) = path.reach.progress((t - span.start_ns) as Real * 1e-9);
                let (sin, cos) = (std::f64::consts::PI * u).sin_cos();
                let pi = std::f64::consts::PI;
                mq = u;
                self.reach_shaping =
                    crate::min_jerk::progress((u - REACH_SHAPE_FROM) / (1.0 - REACH_SHAPE_FROM));
                (
                    reach_point(&self.from_base.translation.vector, &dp, &path.bend, u),
                    self.from_base.rotation.slerp(&self.to_base.rotation, u),
                    (dp + path.bend * (pi * cos)) * ddu - path.bend * (pi * pi * sin * du * du),
                )
            }
        };
        let time = t as Real * 1e-9;
        let mut tremor = Vector::zeros();
        for (k, c) in tremor.iter_mut().enumerate() {
            let i = MAX_DOF + k;
            *c = self.params.tremor_arm
                * (std::f64::consts::TAU * self.tremor_freq[i] * time + self.tremor_phase[i]).sin();
        }
        let new_base = Isometry::from_parts((p + tremor).into(), r);
        self.base_acceleration = acceleration;
        self.base = new_base;
        let n = self.dfs.hand().dof();
        for d in 0..n {
            let tr = self.params.tremor_joint
                * (std::f64::consts::TAU * self.tremor_freq[d] * time + self.tremor_phase[d]).sin();
            self.q_intent[d] = self.from_q[d] + (self.to_q[d] - self.from_q[d]) * mq + tr;
        }
        self.grip = self.from_grip + (self.to_grip - self.from_grip) * mg;
        // The load force: the fingertips take over the object's weight from the table early in
        // the lift (the loading phase, before the object moves: Johansson & Westling 1984) and
        // hand it back late in the place.
        self.carry = match span.phase {
            Phase::Lift => min_jerk(s / 0.3).0,
            Phase::Hold | Phase::Transport => 1.0,
            Phase::Place => 1.0 - min_jerk((s - 0.6) / 0.4).0,
            _ => 0.0,
        };
        // The grip peaks as the load comes on at lift-off and relaxes to its static level by
        // the end of the lift.
        self.grip_boost = match span.phase {
            Phase::Lift => {
                self.params.lift_grip_peak
                    * min_jerk(s / 0.3).0
                    * (1.0 - min_jerk((s - 0.3) / 0.7).0)
            }
            _ => 0.0,
        };
        self.offset = self.from_offset + (self.to_offset - self.from_offset) * mq;
    }
}
