//! Stage 5 of the tick, [`Dfs::stage_feedback`], in named steps: per object the reaction
//! `c_o = W⁺ f_ext`, friction-limited (eq. 27), and the feedback per contact; then the finger
//! dynamics `M θ̈ = τ − Σ Jᵀ f_fb` (eq. 19-21) stepped implicitly with the contact springs: the
//! step's matrix and right-hand side, each fingertip's spring block, the solve, and the joint
//! limits.

use super::Dfs;
use crate::contact::apply_friction;
use crate::hand::{DofMatrix, MAX_DOF, MAX_TIPS};
use crate::math::{envelope_cholesky_solve, Real, Vector};

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

/// The implicit finger step's matrix without the contact springs, made in place from M(θ)
/// column by column (the storage is column-major and M symmetric): column i's product with
/// q̇ first, `rhs[i] = (M q̇)[i] + dt τ[i]`, then the joint damping `dt joint_damping` added to
/// its diagonal (a copy of M, 10 memcpy calls a tick, is not needed: M is not used after).
#[inline]
fn finger_step_matrix(
    a: &mut DofMatrix,
    qd: &[Real],
    tau: &[Real],
    dt: Real,
    joint_damping: Real,
    rhs: &mut [Real; MAX_DOF],
) {
    let ndof = qd.len();
    let a = a.as_mut_slice();
    for i in 0..ndof {
        let col = &a[i * MAX_DOF..i * MAX_DOF + ndof];
        let mut s = 0.0;
        for (&mv, &v) in col.iter().zip(qd) {
            s += mv * v;
        }
        a[i * MAX_DOF + i] += dt * joint_damping;
        rhs[i] = s + dt * tau[i];
    }
}

impl Dfs {
    /// Per object with contacts on it: the reaction `c_o = W⁺ f_ext` (eq. 27), friction-limited,
    /// distributed over its transmitting contacts, and each fingertip's feedback
    /// `c̃_h − c̃_o`.
    pub(super) fn reactions(&mut self) {
        for i in 0..self.n_objects {
            if !self.grasp_active[i] {
                continue;
            }
            let rot = &self.rots[i];
            let (start, n) = self.contact_range[i];
            let g = &self.grasps[i];
            let friction = self.objects[i].friction;
            // The reaction is distributed over the transmitting contacts only; the table's
            // share of f_ext is not the fingers' to carry.
            let f_fingers = self.out.objects[i].f_ext_b - self.out.objects[i].table_force_b;
            // Into the DFS's scratch: `distribute` writes the first `n`, and a local array of
            // MAX_CONTACTS intensities was zeroed every tick for them.
            let c_o = &mut self.reaction_scratch;
            g.distribute(&f_fingers, c_o);
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
                let rot_b = &self.frames[start + c].rot_b;
                let fb = rot_b * Vector::new(t.feedback[0], t.feedback[1], t.feedback[2]);
                t.feedback_force_world = -(rot * fb);
            }
        }
    }

    /// The implicit finger step.
    pub(super) fn integrate_fingers(&mut self, tau: &[Real]) {
        let ndof = self.hand.dof();
        let dt = self.params.dt;
        let mut rhs = [0.0; MAX_DOF];
        finger_step_matrix(
            &mut self.mass,
            &self.qd[..ndof],
            tau,
            dt,
            self.params.joint_damping,
            &mut rhs,
        );
        let mut fb_torque = [0.0; MAX_DOF];
        for k in 0..self.hand.fingertips.len() {
            self.add_tip_to_finger_step(k, &mut rhs, &mut fb_torque);
        }
        if self.body.n > 0 {
            self.body.add_to_finger_step(
                dt,
                &self.qd,
                &mut self.mass,
                &mut rhs,
                &mut fb_torque,
                &mut self.tip_cols,
            );
        }
        for d in 0..ndof {
            rhs[d] += dt * fb_torque[d];
        }
        self.out.feedback_torque[..ndof].copy_from_slice(&fb_torque[..ndof]);
        let solved = envelope_cholesky_solve(
            &self.mass,
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
    /// stiffness and damping into the step's matrix (`mass`, the solve order's lower
    /// triangle).
    #[inline]
    fn add_tip_to_finger_step(
        &mut self,
        k: usize,
        rhs: &mut [Real; MAX_DOF],
        fb_torque: &mut [Real; MAX_DOF],
    ) {
        let p = &self.params;
        let dt = p.dt;
        let a = &mut self.mass;
        let tip = &self.tips[k];
        let t = &self.out.tips[k];
        // Only the DOFs moving the tip, in solve order (the spring block below is written
        // in that order): its other Jacobian columns are zero. Their linear Jacobian columns
        // (column-major storage), read once into the DFS's scratch: the block below uses
        // each about as often as the tip has DOFs.
        let dofs = self.tip_dofs_solve[k].as_slice();
        let js = self.kin.tip_jacobians[k].as_slice();
        let cols = &mut self.tip_cols[..dofs.len()];
        // The feedback, less the passive friction part: the contact spring below carries
        // that on the finger side, implicitly.
        let f = t.feedback_force_world + tip.passive_world;
        for (c, &d) in cols.iter_mut().zip(dofs) {
            *c = Vector::new(js[6 * d], js[6 * d + 1], js[6 * d + 2]);
            fb_torque[d] += c.x * f.x + c.y * f.y + c.z * f.z;
        }
        let cols = &*cols;
        let Some(frame) = &t.frame else { return };
        let z_world = self.rots[t.object] * frame.normal_b();
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
        // The block is symmetric and the solve reads one triangle of it (row `d1`, column
        // `d2` no later than `d1` in the solve order): with the tip's DOFs in solve order,
        // only that triangle is written.
        for (p1, (&d1, &col1)) in dofs.iter().zip(cols).enumerate() {
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
            for (&d2, col2) in dofs[..=p1].iter().zip(cols) {
                a[(d1, d2)] += pc1.dot(col2);
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
