//! Forward kinematics, fingertip poses and Jacobians, with the per-hand plan
//! ([`FkPlan`]) that the DFS makes once and reuses every tick.

use super::*;

impl HandModel {
    /// Forward kinematics: link poses, joint frames and fingertip centres for θ = `q` with the
    /// base link at `base` (world frame). Allocation-free.
    ///
    /// The model must be valid ([`validate`](Self::validate)); `q` should have `dof` entries
    /// (a missing one reads as 0) and be finite ([`check_angles`](Self::check_angles)).
    pub fn forward_kinematics(&self, base: &Isometry, q: &[f64], kin: &mut Kinematics) {
        kin.link_poses[self.root] = *base;
        kin.parent_joint[self.root] = NO_JOINT;
        let mut half_angles = HalfAngles::default();
        for (j, joint) in self.joints.iter().enumerate().take(MAX_LINKS) {
            let value = joint.drive.value(q);
            let placed = match joint.kind {
                JointKind::Revolute | JointKind::Continuous => {
                    let sc = half_angles.sin_cos(value, f64::sin_cos);
                    joint.placed_rotated(value, sc)
                }
                _ => joint.placed(value),
            };
            let frame = kin.link_poses[joint.parent] * placed;
            kin.joint_frames[j] = frame;
            kin.joint_axes[j] = frame.rotation * joint.axis.into_inner();
            kin.link_poses[joint.child] = frame;
            kin.parent_joint[joint.child] = j;
        }
        for (k, tip) in self.fingertips.iter().enumerate().take(MAX_TIPS) {
            kin.tip_centres[k] = kin.link_poses[tip.link] * Point::from(tip.offset);
        }
    }

    /// The per-joint constants [`forward_kinematics_planned`](Self::forward_kinematics_planned)
    /// uses; they depend on the hand only, so a caller running forward kinematics every tick
    /// makes them once. Allocation-free.
    pub fn fk_plan(&self) -> FkPlan {
        let mut plan = FkPlan {
            joints: [FkJoint {
                rotating: false,
                q0: nalgebra::Quaternion::identity(),
                p: nalgebra::Quaternion::identity(),
                axis_parent: Vector::zeros(),
            }; MAX_LINKS],
        };
        for (fj, joint) in plan.joints.iter_mut().zip(&self.joints) {
            let q0 = *joint.origin.rotation.quaternion();
            let axis = joint.axis.into_inner();
            *fj = FkJoint {
                rotating: matches!(joint.kind, JointKind::Revolute | JointKind::Continuous),
                q0,
                p: q0 * nalgebra::Quaternion::from_parts(0.0, axis),
                axis_parent: joint.origin.rotation * axis,
            };
        }
        plan
    }

    /// [`forward_kinematics`](Self::forward_kinematics) with the hand's [`FkPlan`] made
    /// beforehand: a rotating joint's frame in its parent is `cos(θ/2) q₀ + sin(θ/2) q₀ (0, a)`
    /// (`q₀` the origin's rotation, `a` the axis), four products and sums instead of a
    /// quaternion product, and its world axis is its parent's rotation of `q₀ a`, which the
    /// joint's own rotation leaves alone. The same poses to round-off.
    pub fn forward_kinematics_planned(
        &self,
        plan: &FkPlan,
        base: &Isometry,
        q: &[f64],
        kin: &mut Kinematics,
    ) {
        kin.link_poses[self.root] = *base;
        kin.parent_joint[self.root] = NO_JOINT;
        let mut half_angles = HalfAngles::default();
        // The last frame computed, kept at hand: along a finger each joint's parent is the
        // previous joint's child, and reading that pose back from memory right after writing
        // it stalls on the store.
        let (mut last_link, mut last_frame) = (self.root, *base);
        for (j, (joint, fj)) in self.joints.iter().zip(&plan.joints).enumerate() {
            let value = joint.drive.value(q);
            let parent = if joint.parent == last_link {
                last_frame
            } else {
                kin.link_poses[joint.parent]
            };
            let frame = if fj.rotating {
                let (s, c) = half_angles.sin_cos(value, crate::math::sin_cos);
                let local = Rotation::new_unchecked(nalgebra::Quaternion::from(
                    fj.q0.coords * c + fj.p.coords * s,
                ));
                Isometry::from_parts(
                    (parent.translation.vector + parent.rotation * joint.origin.translation.vector)
                        .into(),
                    parent.rotation * local,
                )
            } else {
                parent * joint.placed(value)
            };
            kin.joint_frames[j] = frame;
            kin.joint_axes[j] = parent.rotation * fj.axis_parent;
            kin.link_poses[joint.child] = frame;
            kin.parent_joint[joint.child] = j;
            (last_link, last_frame) = (joint.child, frame);
        }
        for (k, tip) in self.fingertips.iter().enumerate().take(MAX_TIPS) {
            kin.tip_centres[k] = kin.link_poses[tip.link] * Point::from(tip.offset);
        }
    }

    /// Pose of fingertip `k` in the world frame: the orientation of its link, the position of
    /// the sphere centre (the fingertip frame T_k of the paper). Needs forward kinematics and
    /// `k < fingertips.len()`.
    pub fn tip_pose(&self, kin: &Kinematics, k: usize) -> Isometry {
        let rotation = kin.link_poses[self.fingertips[k].link].rotation;
        Isometry::from_parts(kin.tip_centres[k].coords.into(), rotation)
    }

    /// Jacobian of a world point rigidly attached to `link` (rows: linear velocity of the
    /// point, angular velocity of the link; world frame; DOF columns), from the joint frames
    /// of [`forward_kinematics`](Self::forward_kinematics). Allocation-free.
    pub fn point_jacobian(
        &self,
        kin: &Kinematics,
        link: usize,
        point: &Point,
        jac: &mut TipJacobian,
    ) {
        // As a slice: one memset, where nalgebra's `fill` steps element by element (11 000
        // instructions a tick in the power grasp's ten touching shapes, callgrind).
        jac.as_mut_slice().fill(0.0);
        self.add_chain_jacobian(
            &kin.parent_joint,
            &kin.joint_axes,
            &kin.joint_frames,
            link,
            point,
            jac,
        );
    }

    /// Adds the Jacobian columns of the joints on the path from `link` to the root for a world
    /// point on `link` (the caller zeroes `jac`). Takes the kinematics' fields separately so a
    /// caller can write into `Kinematics::tip_jacobians` while reading the rest.
    fn add_chain_jacobian(
        &self,
        parent_joint: &[usize; MAX_LINKS],
        joint_axes: &[Vector; MAX_LINKS],
        joint_frames: &[Isometry; MAX_LINKS],
        link: usize,
        point: &Point,
        jac: &mut TipJacobian,
    ) {
        let mut current = link;
        // At most one joint per link on the path to the root.
        for _ in 0..MAX_LINKS {
            let j = parent_joint[current];
            if j == NO_JOINT || current == self.root {
                break;
            }
            let joint = &self.joints[j];
            if let Some((d, gain)) = joint.drive.dof_and_gain() {
                let a = joint_axes[j];
                let (linear, angular) = match joint.kind {
                    JointKind::Prismatic => (a, Vector::zeros()),
                    JointKind::Fixed => (Vector::zeros(), Vector::zeros()),
                    _ => (
                        a.cross(&(point - Point::from(joint_frames[j].translation.vector))),
                        a,
                    ),
                };
                // Column d of the column-major 6 x MAX_DOF storage.
                let col = &mut jac.as_mut_slice()[6 * d..6 * d + 6];
                for r in 0..3 {
                    col[r] += gain * linear[r];
                    col[3 + r] += gain * angular[r];
                }
            }
            current = joint.parent;
        }
    }

    /// Fingertip Jacobians (world frame, at each tip centre) from the joint frames that
    /// [`forward_kinematics`](Self::forward_kinematics) computed. Allocation-free.
    pub fn tip_jacobians(&self, kin: &mut Kinematics) {
        let n = self.dof().min(MAX_DOF);
        let Kinematics {
            parent_joint,
            joint_axes,
            joint_frames,
            tip_centres,
            tip_jacobians,
            ..
        } = kin;
        for (k, tip) in self.fingertips.iter().enumerate().take(MAX_TIPS) {
            let jac = &mut tip_jacobians[k];
            // Column-major: the first n columns are the first 6n entries (a slice fill is a
            // memset; the column view's element iterator cost a fifth of the glove stage).
            jac.as_mut_slice()[..6 * n].fill(0.0);
            self.add_chain_jacobian(
                parent_joint,
                joint_axes,
                joint_frames,
                tip.link,
                &tip_centres[k],
                jac,
            );
        }
    }
}

/// The half-angle `(sin, cos)` of the last few joint values forward kinematics met: a mimic
/// joint copying a DOF (glove10's ring and little fingers, a thumb IP following its MCP)
/// reuses them instead of another `sin_cos` (a fifth of forward kinematics). Keyed by the
/// exact bits, so the poses are bit-identical. Separate arrays, not (sin, cos) pairs: a
/// 16-byte read of a pair just stored as two 8-byte writes stalls until they retire.
#[derive(Default)]
struct HalfAngles {
    bits: [u64; 4],
    sin: [f64; 4],
    cos: [f64; 4],
    next: usize,
    filled: usize,
}

impl HalfAngles {
    /// `f(value / 2)`, from the cache when `value` was met lately.
    #[inline(always)]
    fn sin_cos(&mut self, value: f64, f: impl Fn(f64) -> (f64, f64)) -> (f64, f64) {
        let bits = value.to_bits();
        if let Some(r) = self.bits[..self.filled].iter().position(|&b| b == bits) {
            return (self.sin[r], self.cos[r]);
        }
        let (s, c) = f(value / 2.0);
        let k = self.next;
        (self.bits[k], self.sin[k], self.cos[k]) = (bits, s, c);
        self.next = (k + 1) % self.bits.len();
        self.filled = (self.filled + 1).min(self.bits.len());
        (s, c)
    }
}

/// The per-joint constants of [`HandModel::forward_kinematics_planned`], made once per hand
/// by [`HandModel::fk_plan`].
#[derive(Debug, Clone, Copy)]
pub struct FkPlan {
    joints: [FkJoint; MAX_LINKS],
}

#[derive(Debug, Clone, Copy)]
struct FkJoint {
    /// Revolute or continuous.
    rotating: bool,
    /// The origin's rotation.
    q0: nalgebra::Quaternion<f64>,
    /// `q0 (0, axis)`: the joint's rotation in its parent is `cos(θ/2) q0 + sin(θ/2) p`.
    p: nalgebra::Quaternion<f64>,
    /// The axis in the parent link's frame.
    axis_parent: Vector,
}
