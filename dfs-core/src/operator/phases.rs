//! The targets of each phase of the script, set as it begins: for an `approach` the grasp
//! planned where the object lies and the reach's path, then where the hand, fingers, grip
//! and fingertip offset go in each phase; and the poses the hand waits and rises at.

use super::plan::tip_index;
use super::reach::{bend_vector, ReachCheck, BEND_TRIES};
use super::{plan_operator_grasp, power, GraspPlan, Reach, ReachPath, Simulation, REACH_BEND};
use crate::error::Result;
use crate::hand::{HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Real, Rotation, Vector};
use crate::object::{RigidObject, Shape};
use crate::scenario::Phase;
use rand::Rng;

impl Simulation {
    /// Sets the targets of the phase that starts now, from where the hand and object are.
    pub(super) fn begin_phase(&mut self) -> Result<()> {
        let task = self.span_now().task;
        self.from_base = self.to_base;
        self.from_q = self.to_q;
        self.from_grip = self.to_grip;
        self.from_offset = self.to_offset;
        self.seen_object = self.target_state().pose;
        self.reach_path = None;
        match task.phase {
            Phase::Approach => self.begin_approach()?,
            Phase::Preshape => {
                // A wrap slides the open hand down beside the object and onto it: the palm
                // touches as the preshape ends, and the grasp only closes the fingers.
                self.to_base = self.plan.wrap.map_or(self.plan.base, |w| w.base);
                self.to_q = self.plan.q_pre;
                self.to_offset = 0.015;
            }
            Phase::Grasp => {
                self.to_q = self.closing_target();
                self.to_grip = 1.0;
                // Aim a little inside the surface, as a person presses on what they hold.
                self.to_offset = -0.002;
            }
            Phase::Lift => {
                self.to_base = raise(&self.from_base, task.height);
            }
            Phase::Hold => {}
            Phase::Transport => {
                let centre = self.target_state().pose.translation.vector;
                let turn = Rotation::from_euler_angles(0.0, 0.0, task.turn);
                let b = self.from_base;
                let p = centre + turn * (b.translation.vector - centre) + Vector::from(task.offset);
                self.to_base = Isometry::from_parts(p.into(), turn * b.rotation);
            }
            Phase::Place => {
                let obj = self.target_state().pose;
                let depth = self.target_object().shape.support_depth(&obj.rotation);
                let dz = self.table_height + depth - obj.translation.z - 0.002;
                self.to_base = raise(&self.from_base, dz);
            }
            Phase::Release => {
                self.to_q = self.plan.q_pre;
                self.to_grip = 0.0;
                self.to_offset = 0.015;
                self.let_go_where_held();
            }
            Phase::Retreat => {
                self.to_base = match self.plan.wrap {
                    // The open hand backs off the object and slides up off it, the way it came.
                    Some(wrap) => {
                        let rise = self.target_object().shape.bounding_radius() + 0.06;
                        let mut x = raise(&self.from_base, rise);
                        x.translation.vector += wrap.out * (2.0 * power::WRAP_STANDOFF);
                        x
                    }
                    None => raise(&self.from_base, 0.10),
                };
                self.to_q = self.plan.q_open;
                self.to_grip = 0.0;
                self.to_offset = 0.03;
            }
        }
        Ok(())
    }

    /// The targets of an `approach`: the grasp planned on the object where it lies now (the
    /// other objects as obstacles), the fingertips that only rest on it, the open hand beside
    /// it, and a varied reach's path.
    fn begin_approach(&mut self) -> Result<()> {
        let pose = self.target_state().pose;
        let obstacles: Vec<(RigidObject, Isometry)> = self
            .dfs
            .objects()
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != self.target)
            .map(|(_, o)| (o.object, o.state.pose))
            .collect();
        self.plan = plan_operator_grasp(
            self.dfs.hand(),
            self.target_object(),
            &pose,
            self.style,
            &obstacles,
        )?;
        self.resting = resting_tips(
            &self.plan,
            self.dfs.hand(),
            self.operator_mu,
            self.params.grip_safety,
        );
        self.to_base = approach_pose(&self.plan.base, &self.target_object().shape);
        self.to_q = self.plan.q_open;
        self.to_grip = 0.0;
        self.to_offset = 0.03;
        self.object_held = false;
        if let Some(reach) = self.reaches.get(self.span).copied().flatten() {
            self.reach_path = Some(self.bend_reach(reach));
        }
        Ok(())
    }

    /// The fingers' target in `grasp`: the planned grasp, past it by the operator's overshoot
    /// of the preshape-to-grasp motion ([`OperatorParams::close_overshoot`]), within the
    /// joints' limits.
    ///
    /// [`OperatorParams::close_overshoot`]: super::OperatorParams::close_overshoot
    fn closing_target(&self) -> [Real; MAX_DOF] {
        let n = self.dfs.hand().dof();
        let mut q = self.plan.q_grasp;
        for d in 0..n {
            let delta = self.plan.q_grasp[d] - self.plan.q_pre[d];
            let hand = self.dfs.hand();
            q[d] = (q[d] + self.params.close_overshoot * delta)
                .clamp(hand.dof_lower[d], hand.dof_upper[d]);
        }
        q
    }

    /// Let go from where each fingertip holds the object, not from where the plan put it: an
    /// object that turned or slid in the hand (set down on a tilted edge, say) would otherwise
    /// be dragged back by fingertips steering to their planned spots as they open. Moves the
    /// plan's spots and normals of the fingertips of the grasp that touch the object there.
    fn let_go_where_held(&mut self) {
        let out = self.dfs.output();
        for k in 0..out.n_tips.min(MAX_TIPS) {
            if let (true, Some(frame)) = (self.plan.tips[k], self.target_frame(k)) {
                let n_out = -frame.normal_b();
                let r = self.dfs.hand().fingertips[k].radius;
                self.plan.contacts_b[k] = frame.p_b + n_out * r;
                self.plan.normals_b[k] = n_out;
            }
        }
    }

    /// The path of a varied approach from `from_base` to `to_base`: its first bend, or
    /// smaller ones drawn from the reach stream, the first that keeps clear of the table and
    /// the objects ([`ReachCheck::is_clear`]), else the straight line.
    fn bend_reach(&mut self, reach: Reach) -> ReachPath {
        let n = self.dfs.hand().dof();
        let check = ReachCheck {
            hand: self.dfs.hand(),
            q_from: &self.from_q[..n],
            q_to: &self.to_q[..n],
            from: &self.from_base,
            to: &self.to_base,
            objects: self.dfs.objects(),
            table_height: self.table_height,
        };
        let dp = self.to_base.translation.vector - self.from_base.translation.vector;
        let mut kin = Kinematics::default();
        let (mut fraction, mut angle) = (reach.bend, reach.bend_angle);
        for attempt in 1..=BEND_TRIES {
            let bend = bend_vector(&dp, fraction, angle);
            if check.is_clear(&bend, &mut kin) {
                return ReachPath { reach, bend };
            }
            let Some(rng) = self.reach_rng.as_mut() else {
                break;
            };
            let shrink = 1.0 - attempt as Real / BEND_TRIES as Real;
            fraction = rng.random_range(0.0..=REACH_BEND) * shrink;
            angle = rng.random_range(0.0..=std::f64::consts::PI);
        }
        ReachPath {
            reach,
            bend: Vector::zeros(),
        }
    }
}

/// The fingertips of `plan` that rest on the object instead of squeezing it: those beside the
/// squeezing pair (thumb and index) that cannot push within the friction cone the operator
/// expects with its safety margin even before any load, i.e. whose push direction nearest the
/// contact normal ([`GraspPlan::normal_alignment`], cos θ) leans off it by tan θ > μ / safety.
/// Pressing harder with such a finger only makes it slide on the surface (a finger whose
/// flexion plane passes beside a cylinder's axis meets a surface turned away from the plane);
/// it closes until it touches and presses with the least force.
pub(super) fn resting_tips(
    plan: &GraspPlan,
    hand: &HandModel,
    mu: Real,
    safety: Real,
) -> [bool; MAX_TIPS] {
    let mut out = [false; MAX_TIPS];
    let pair = [tip_index(hand, "thumb"), tip_index(hand, "index")];
    for (k, rest) in out.iter_mut().enumerate().take(hand.fingertips.len()) {
        if !plan.tips[k] || pair.contains(&Some(k)) {
            continue;
        }
        let c = plan.normal_alignment[k].clamp(1e-6, 1.0);
        let tan = (1.0 - c * c).sqrt() / c;
        *rest = tan * safety > mu;
    }
    out
}

/// Where the hand waits before closing in: beside the grasp pose along the palm's y axis (the
/// fingertips close in the palm's x-z plane, so sliding along y brings them around the
/// object without touching it), by the object's size plus 5 cm, and 1 cm higher.
pub(super) fn approach_pose(grasp_base: &Isometry, shape: &Shape) -> Isometry {
    let side = grasp_base.rotation * Vector::y() * (shape.bounding_radius() + 0.05);
    let mut x = *grasp_base;
    x.translation.vector += side + Vector::z() * 0.01;
    x
}

/// The pose raised by `dz` (m) along world z.
pub(super) fn raise(x: &Isometry, dz: Real) -> Isometry {
    let mut y = *x;
    y.translation.vector.z += dz;
    y
}
