//! Stage 5 of the tick, [`Dfs::stage_feedback`], in named steps: per object the reaction
//! `c_o = W⁺ f_ext`, friction-limited (eq. 27), and the feedback per contact; then the finger
//! dynamics `M θ̈ = τ − Σ Jᵀ f_fb` (eq. 19-21) stepped implicitly with the contact springs: the
//! step's matrix and right-hand side, each fingertip's spring block, the solve, and the joint
//! limits.

use super::{Dfs, MAX_OBJECTS};
use crate::contact::{apply_friction, Intensity};
use crate::grasp::MAX_CONTACTS;
use crate::hand::{DofMatrix, MAX_DOF, MAX_TIPS};
use crate::math::{envelope_cholesky_solve, Real, Vector};
use nalgebra::Rotation3;

/// How a touching fingertip's contact spring-damper acts on the finger in the implicit step.
#[derive(Clone, Copy)]
enum Spring {
    /// Sliding: along the normal only.
    Normal,
    /// Sticking, damped alike in every direction.
    Isotropic,
    /// Sticking, damped less across the normal (the object's step limits it).
    StiffNormal,
}

/// The implicit finger step's matrix without the contact springs, column by column (the
/// storage is column-major and M symmetric): `a`'s column i is M's plus the joint damping
/// `dt joint_damping` on the diagonal; `rhs[i] = (M q̇)[i] + dt τ[i]`.
#[inline]
fn finger_step_matrix(
    a: &mut DofMatrix,
    mass: &DofMatrix,
    qd: &[Real],
    tau: &[Real],
    dt: Real,
    joint_damping: Real,
    rhs: &mut [Real; MAX_DOF],
) {
    let ndof = qd.len();
    let (a, m) = (a.as_mut_slice(), mass.as_slice());
    for i in 0..ndof {
        let col = &m[i * MAX_DOF..i * MAX_DOF + ndof];
        let to = &mut a[i * MAX_DOF..i * MAX_DOF + ndof];
        // One pass copies the column and forms the product (no memcpy call per column).
        let mut s = 0.0;
        for ((t, &mv), &v) in to.iter_mut().zip(col).zip(qd) {
            *t = mv;
            s += mv * v;
        }
        a[i * MAX_DOF + i] += dt * joint_damping;
        rhs[i] = s + dt * tau[i];
    }
}

impl Dfs {
    /// Per object with contacts on it: the reaction `c_o = W⁺ f_ext` (eq. 27), friction-limited,
    /// distributed over its transmitting contacts, and each fingertip's feedback
    /// `c̃_h − c̃_o`; `rots` holds each object's orientation as a matrix.
    pub(super) fn reactions(&mut self, rots: &[Rotation3<Real>; MAX_OBJECTS]) {
        for (i, rot) in rots.iter().enumerate().take(self.n_objects) {
            if !self.grasp_active[i] {
                continue;
            }
            let (start, n) = self.contact_range[i];
            let g = &self.grasps[i];
            let friction = self.objects[i].friction;
            // The reaction is distributed over the transmitting contacts only; the table's
            // share of f_ext is not the fingers' to carry.
            let f_fingers = self.out.objects[i].f_ext_b - self.out.objects[i].table_force_b;
            let mut c_o = [Intensity::zeros(); MAX_CONTACTS];
            g.distribute(&f_fingers, &mut c_o);
            for (c, ci) in c_o.iter().enumerate().take(n) {
                let k = self.contact_tip[start + c];
                if k >= MAX_TIPS {
                    self.body_out[k - MAX_TIPS].reaction =
                        apply_friction(self.params.contact_model, &friction, ci).transmitted;
                    continue;
                }
                let t = &mut self.out.tips[k];
                t.reaction = apply_friction(self.params.contact_model, &friction, ci).transmitted;
                t.feedback = t.transmitted - t.reaction;
                let frame = self.frames[start + c];
                let fb = frame.rot_b * Vector::new(t.feedback[0], t.feedback[1], t.feedback[2]);
                t.feedback_force_world = -(rot * fb);
            }
        }
    }

    /// The implicit finger step; `rots` holds each object's orientation as a matrix.
    pub(super) fn integrate_fingers(
        &mut self,
        tau: &[Real],
        rots: &[Rotation3<Real>; MAX_OBJECTS],
    ) {
        let ndof = self.hand.dof();
        let dt = self.params.dt;
        let mut rhs = [0.0; MAX_DOF];
        finger_step_matrix(
            &mut self.scratch,
            &self.mass,
            &self.qd[..ndof],
            tau,
            dt,
            self.params.joint_damping,
            &mut rhs,
        );
        let mut fb_torque = [0.0; MAX_DOF];
        for k in 0..self.hand.fingertips.len() {
            self.add_tip_to_finger_step(k, rots, &mut rhs, &mut fb_torque);
        }
        if self.body.n > 0 {
            self.body
                .add_to_finger_step(dt, &self.qd, &mut self.scratch, &mut rhs, &mut fb_torque);
        }
        for d in 0..ndof {
            rhs[d] += dt * fb_torque[d];
        }
        self.out.feedback_torque[..ndof].copy_from_slice(&fb_torque[..ndof]);
        let solved = envelope_cholesky_solve(
            &self.scratch,
            &self.solve_order[..ndof],
            &self.solve_first[..ndof],
            &mut self.factor,
            &mut rhs,
        );
        if solved {
            self.step_joints(&rhs);
        }
        self.out.motor_q[..ndof].copy_from_slice(&self.q[..ndof]);
        self.out.motor_qd[..ndof].copy_from_slice(&self.qd[..ndof]);
    }

    /// Fingertip `k` in the implicit finger step: its feedback force into the feedback torques
    /// `fb_torque` (`Jᵀ f`), and, touching, its contact spring-damper's force into `rhs` and its
    /// stiffness and damping into the step's matrix (`scratch`, the solve order's lower
    /// triangle).
    #[inline]
    fn add_tip_to_finger_step(
        &mut self,
        k: usize,
        rots: &[Rotation3<Real>; MAX_OBJECTS],
        rhs: &mut [Real; MAX_DOF],
        fb_torque: &mut [Real; MAX_DOF],
    ) {
        let p = &self.params;
        let dt = p.dt;
        let a = &mut self.scratch;
        let tip = &self.tips[k];
        let t = &self.out.tips[k];
        let j = &self.kin.tip_jacobians[k];
        // The feedback, less the passive friction part: the contact spring below carries
        // that on the finger side, implicitly.
        let f = t.feedback_force_world + tip.passive_world;
        // Only the DOFs moving the tip, in solve order (the spring block below is written
        // in that order): its other Jacobian columns are zero.
        let dofs = self.tip_dofs_solve[k].as_slice();
        for &d in dofs {
            fb_torque[d] += j[(0, d)] * f.x + j[(1, d)] * f.y + j[(2, d)] * f.z;
        }
        let Some(frame) = t.frame else { return };
        let z_world = rots[t.object] * frame.normal_b();
        let stick = tip.stick;
        let v = tip.spring_vel;
        // A sticking tip is damped across the normal as the object is (`damping`), along it
        // by the surface damping; a sliding one along the normal only.
        let damping = tip.tangential_damping;
        let extra_normal = p.surface_damping - damping;
        // How each tip is sprung: along the normal only (sliding), alike in every direction
        // (sticking, the tangential damping not limited) or more along the normal.
        let spring = match (stick, extra_normal == 0.0) {
            (false, _) => Spring::Normal,
            (true, true) => Spring::Isotropic,
            (true, false) => Spring::StiffNormal,
        };
        let f = -tip.spring_err * p.surface_stiffness
            - match spring {
                Spring::Normal => z_world * v.dot(&z_world) * p.surface_damping,
                Spring::Isotropic => v * damping,
                Spring::StiffNormal => v * damping + z_world * (v.dot(&z_world) * extra_normal),
            };
        let c = dt * p.surface_damping + dt * dt * p.surface_stiffness;
        let c_stick = dt * damping + dt * dt * p.surface_stiffness;
        // A pad on the contact ramp: the operator's push it does not pass on draws the
        // fingertip in, stiffly (its normal intensity over the ramp's depth), so that
        // stiffness is in the implicit step too (its force is already in `f`, the feedback
        // holding only what was passed on).
        let ramp = dt * dt * tip.ramp_stiffness;
        // The tip's linear Jacobian column of DOF d (column-major storage).
        let js = j.as_slice();
        let col = |d: usize| Vector::new(js[6 * d], js[6 * d + 1], js[6 * d + 2]);
        // The block is symmetric and the solve reads one triangle of it (row `d1`, column
        // `d2` no later than `d1` in the solve order): with the tip's DOFs in solve order,
        // only that triangle is written.
        for (p1, &d1) in dofs.iter().enumerate() {
            let col1 = col(d1);
            if col1 == Vector::zeros() {
                continue;
            }
            rhs[d1] += dt * col1.dot(&f);
            let mut pc1 = match spring {
                Spring::Normal => z_world * z_world.dot(&col1) * c,
                Spring::Isotropic => col1 * c_stick,
                Spring::StiffNormal => {
                    col1 * c_stick + z_world * (z_world.dot(&col1) * (dt * extra_normal))
                }
            };
            if ramp != 0.0 {
                pc1 += z_world * (z_world.dot(&col1) * ramp);
            }
            for &d2 in &dofs[..=p1] {
                a[(d1, d2)] += pc1.dot(&col(d2));
            }
        }
    }

    /// The joint velocities `qd_new` the implicit step solved for, integrated to the joint
    /// angles and stopped at the joints' limits.
    #[inline]
    fn step_joints(&mut self, qd_new: &[Real; MAX_DOF]) {
        let dt = self.params.dt;
        for d in 0..self.hand.dof() {
            let mut v = qd_new[d];
            let mut q = self.q[d] + dt * v;
            let (lo, hi) = (self.hand.dof_lower[d], self.hand.dof_upper[d]);
            if q < lo {
                q = lo;
                v = v.max(0.0);
            } else if q > hi {
                q = hi;
                v = v.min(0.0);
            }
            self.q[d] = q;
            self.qd[d] = v;
        }
    }
}
