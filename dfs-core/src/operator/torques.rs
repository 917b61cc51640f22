//! The operator's joint torques from its intention: fingertips of the grasp steered to their
//! spots and, once holding, kept where they met the object, with the squeeze and the load on
//! top; the other joints' posture impedance; and a wrap's power-grip law.

use super::power::{self, PowerGrip, Wrap};
use super::Simulation;
use crate::hand::{FingerGroup, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Vector};
use crate::scenario::Phase;

impl Simulation {
    /// The operator's joint torques `Jᵀ f` for the fingertips of the grasp, and an impedance
    /// around the intended angles for the other joints (wrist, unused fingers).
    ///
    /// Reaching and closing, a fingertip of the grasp is steered towards its spot on the object
    /// (in the object's frame, so it follows the object), `offset` out along the surface normal,
    /// with the soft [`OperatorParams::fingertip_stiffness`], like a person reaching for a spot
    /// they see; closing makes the offset zero, approaching every face head-on.
    ///
    /// Once it touches while holding, the operator keeps the fingertip where it met the object,
    /// relative to the palm (the link the finger is mounted on): a stiff, damped impedance ([`OperatorParams::hold_stiffness`],
    /// [`OperatorParams::hold_damping`]) about that spot pushed into the object by the pad's
    /// expected compression `N / k_s` (the DFS's surface stiffness), plus the squeeze `N` along
    /// the normal ([`Simulation::grip_forces`]). The set-points, fixed in the hand, fix the
    /// object's place in the hand: between opposing fingertips both springs hold it, and a
    /// squeeze that changes equally on both sides does not move it. Set-points relative to the
    /// palm rather than the forearm keep the fingers' impedance out of a loop through the
    /// wrist (fingertip forces turn the palm, which would move a forearm-fixed set-point).
    ///
    /// [`OperatorParams::fingertip_stiffness`]: super::OperatorParams::fingertip_stiffness
    /// [`OperatorParams::hold_stiffness`]: super::OperatorParams::hold_stiffness
    /// [`OperatorParams::hold_damping`]: super::OperatorParams::hold_damping
    pub(super) fn compute_torques(&mut self) {
        if let Some(wrap) = self.plan.wrap {
            self.compute_wrap_torques(&wrap);
            return;
        }
        let (mags, units, lift) = self.grip_forces();
        let hand = self.dfs.hand();
        let out = self.dfs.output();
        let kin = self.dfs.kinematics();
        let obj_pose = if self.object_held {
            self.target_state().pose
        } else {
            self.seen_object
        };
        let obj_rot = self.target_state().pose.rotation;
        let holding = matches!(
            self.phase(),
            Phase::Grasp | Phase::Lift | Phase::Hold | Phase::Transport | Phase::Place
        );
        // The operator fixes the fingertips' places only once every fingertip of the grasp is
        // on the object; until then each closes softly on its spot, so the first to touch does
        // not shove the object away from the others.
        let all_touch = (0..out.n_tips.min(MAX_TIPS))
            .filter(|&k| self.plan.tips[k] && !self.resting[k])
            .all(|k| self.target_frame(k).is_some());
        let mut in_grasp = [false; MAX_DOF];
        let mut tau = [0.0; MAX_DOF];
        for g in &hand.finger_groups {
            if !g.tips.iter().any(|&k| self.plan.tips[k]) {
                continue;
            }
            for &d in &g.dofs {
                in_grasp[d] = true;
            }
        }
        for g in &hand.finger_groups {
            for &k in g.tips.iter().filter(|&&k| self.plan.tips[k]) {
                let tip = &out.tips[k];
                let x = kin.tip_centres[k];
                let mount = kin.link_poses[self.mount[k]];
                if !holding {
                    self.hold_in_mount[k] = None;
                } else if let (true, None, Some(frame)) =
                    (all_touch, self.hold_in_mount[k], self.target_frame(k))
                {
                    // Where the fingertip met the object, with the pad just on the surface, and
                    // the inward normal there, both relative to the palm.
                    let n_in = obj_rot * frame.normal_b();
                    let spot = x - n_in * tip.penetration;
                    let inv = mount.inverse();
                    self.hold_in_mount[k] = Some(((inv * spot).coords, inv.rotation * n_in));
                }
                let j = &kin.tip_jacobians[k];
                let mut f = self.tip_force(k, &g.dofs, mags[k], &obj_pose);
                f += units[k] * mags[k];
                f += lift[k];
                for &d in &g.dofs {
                    tau[d] += j[(0, d)] * f.x + j[(1, d)] * f.y + j[(2, d)] * f.z;
                }
            }
            self.null_space_posture(g, &mut tau);
        }
        self.posture_and_limits(&in_grasp, tau);
    }

    /// Fingertip `k`'s task-space force before the squeeze and the load: with a hold spot,
    /// the stiff, damped impedance about it pushed in by the pad's expected compression
    /// `mag / k_s`; without, the soft spring towards its spot on the object (seen at
    /// `obj_pose`), `offset` out along the normal, its stretch capped at 3 cm.
    fn tip_force(&self, k: usize, dofs: &[usize], mag: Real, obj_pose: &Isometry) -> Vector {
        let kin = self.dfs.kinematics();
        let qd = &self.dfs.output().motor_qd;
        let k_s = self.dfs.params().surface_stiffness;
        let x = kin.tip_centres[k];
        let mount = kin.link_poses[self.mount[k]];
        let j = &kin.tip_jacobians[k];
        match self.hold_in_mount[k] {
            Some((spot, n_in)) => {
                let target = mount * Point::from(spot) + (mount.rotation * n_in) * (mag / k_s);
                let mut v = Vector::zeros();
                for &d in dofs {
                    v += Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]) * qd[d];
                }
                (target - x) * self.params.hold_stiffness - v * self.params.hold_damping
            }
            None => {
                let target = obj_pose
                    * Point::from(self.plan.contacts_b[k] + self.plan.normals_b[k] * self.offset);
                let mut err = target - x;
                let e = err.norm();
                if e > 0.03 {
                    err *= 0.03 / e;
                }
                err * self.params.fingertip_stiffness
            }
        }
    }

    /// A finger with more joints than its fingertip needs (the index: three joints in its
    /// flexion plane) keeps its intended posture in the null space of the fingertip task, so
    /// it neither drifts towards a stretched, singular posture nor moves the fingertip:
    /// `τ₀ − Jᵀ (J Jᵀ + λ²I)⁻¹ J τ₀` for the posture impedance `τ₀`, added to `tau` for group
    /// `g` when exactly one of its fingertips is in the grasp.
    fn null_space_posture(&self, g: &FingerGroup, tau: &mut [Real; MAX_DOF]) {
        let hand = self.dfs.hand();
        let out = self.dfs.output();
        let kin = self.dfs.kinematics();
        let q = &out.motor_q;
        let qd = &out.motor_qd;
        let mut planned = g.tips.iter().filter(|&&k| self.plan.tips[k]);
        if let (Some(&k), None) = (planned.next(), planned.next()) {
            let j = &kin.tip_jacobians[k];
            let mut t0 = [0.0; MAX_DOF];
            let mut jt0 = Vector::zeros();
            let mut jjt = nalgebra::Matrix3::<Real>::identity() * 1e-6;
            for &d in &g.dofs {
                let kp = self.params.stiffness * hand.torque_limit[d];
                t0[d] = kp * (self.q_intent[d] - q[d]) - self.params.posture_damping * qd[d];
                let c = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
                jt0 += c * t0[d];
                jjt += c * c.transpose();
            }
            if let Some(y) = jjt.cholesky().map(|ch| ch.solve(&jt0)) {
                for &d in &g.dofs {
                    let c = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
                    tau[d] += t0[d] - c.dot(&y);
                }
            }
        }
    }

    /// The posture impedance about the intended angles added to the joints outside the
    /// grasp (a varied reach's fingers of the grasp going over to it until it nears the
    /// object), then every torque limited to 1.9 times the joint's limit: the operator's torques.
    fn posture_and_limits(&mut self, in_grasp: &[bool; MAX_DOF], mut tau: [Real; MAX_DOF]) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let q = &out.motor_q;
        let qd = &out.motor_qd;
        for d in 0..n {
            let kp = self.params.stiffness * hand.torque_limit[d];
            let kd = if hand.dof_names[d].starts_with("wrist") {
                self.params.wrist_damping
            } else {
                0.0
            };
            let posture = kp * (self.q_intent[d] - q[d]) - kd * qd[d];
            if !in_grasp[d] {
                tau[d] += posture;
            } else if self.reach_path.is_some() {
                // A varied reach keeps the open hand's posture until it nears the object.
                let w = self.reach_shaping;
                tau[d] = w * tau[d] + (1.0 - w) * posture;
            }
        }
        for d in 0..n {
            let lim = 1.9 * hand.torque_limit[d];
            self.tau[d] = tau[d].clamp(-lim, lim);
        }
    }

    /// The operator's joint torques in a wrap ([`power`]): the power grip's law
    /// ([`PowerGrip::torques`]) about the intended angles, the fingers going over from their
    /// posture impedance to closing by torque as [`wrap_close`](Self::wrap_close) rises. The
    /// closing torques are scaled to the squeeze friction needs for the load the operator
    /// expects (weight plus the arm's planned acceleration) with its safety margin, for the
    /// friction it expects, through the whole hand's contacts
    /// ([`power::WRAP_NORMAL_PER_GRIP`]): `grip` ramps from the closing level
    /// ([`power::WRAP_CLOSE`]) to that squeeze, with the lift-off peak
    /// ([`OperatorParams::lift_grip_peak`]).
    ///
    /// [`OperatorParams::lift_grip_peak`]: super::OperatorParams::lift_grip_peak
    fn compute_wrap_torques(&mut self, wrap: &Wrap) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let p = &self.params;
        let mut grip = PowerGrip::closing(hand, &[], &self.q_intent[..n]);
        let w = self.wrap_close;
        for d in 0..n {
            let lim = hand.torque_limit[d];
            grip.limit[d] = 1.9 * lim;
            if wrap.closes[d] {
                grip.close[d] = power::WRAP_CLOSE * lim;
                // Going over from the posture impedance to where the fingers came to rest on
                // the object (once they have: the fixture's grip), one set-point between them.
                let open = (1.0 - w) * p.stiffness * lim;
                let (held, set) = match self.wrap_set {
                    Some(set) => (w * power::WRAP_KP_PER_LIMIT * lim, set[d]),
                    None => (0.0, 0.0),
                };
                grip.kp[d] = open + held;
                if grip.kp[d] > 0.0 {
                    grip.set[d] = (open * self.q_intent[d] + held * set) / grip.kp[d];
                }
            }
        }
        let load = ((self.base_acceleration - self.dfs.params().gravity)
            * self.target_object().mass)
            .norm();
        let squeeze = (p.grip_safety * load / (self.operator_mu * power::WRAP_NORMAL_PER_GRIP))
            .clamp(power::WRAP_CLOSE, power::WRAP_MAX_GRIP)
            * (1.0 + self.grip_boost);
        let level = w + self.grip * (squeeze / power::WRAP_CLOSE - 1.0);
        let mut tau = [0.0; MAX_DOF];
        grip.torques(level, &out.motor_q[..n], &out.motor_qd[..n], &mut tau[..n]);
        self.tau[..n].copy_from_slice(&tau[..n]);
    }
}
