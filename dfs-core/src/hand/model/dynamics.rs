//! The joint-space inertia M(θ) by the composite rigid-body algorithm ([`SpatialInertia`],
//! the per-hand [`MassPlan`]), and the SPD solve for M(θ)⁻¹ τ.

use super::*;

/// A rigid body's spatial inertia about the world origin, in the compact form the composite
/// rigid-body algorithm needs: mass `m`, first moment `h = m c` (c the centre of mass) and the
/// rotational inertia about the origin `I_o = I_c − m [c]×[c]×`, all in the world frame. As a
/// 6x6 matrix acting on twists (velocity of the body point at the origin, angular velocity) it
/// is `[[m 1, −[h]×], [[h]×, I_o]]`; ten numbers instead of 36, and adding two subtrees is ten
/// additions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialInertia {
    /// Mass (kg).
    pub mass: f64,
    /// First moment of mass about the origin, `m c` (kg·m).
    pub h: Vector,
    /// Rotational inertia about the origin (kg·m²), symmetric.
    pub i_o: Mat3,
}

impl SpatialInertia {
    /// No mass.
    pub const ZERO: SpatialInertia = SpatialInertia {
        mass: 0.0,
        h: Vector::new(0.0, 0.0, 0.0),
        i_o: Mat3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    };

    /// A link's inertia about the world origin for the link at `pose`.
    #[inline]
    pub fn of_link(pose: &Isometry, inertial: &Inertial) -> SpatialInertia {
        Self::of_link_with_axes(pose, inertial, inertial.principal_in_link_frame())
    }

    /// [`of_link`](Self::of_link) when it is known whether the link's inertia tensor is
    /// diagonal in its frame ([`Inertial::principal_in_link_frame`]).
    #[inline(always)]
    fn of_link_with_axes(pose: &Isometry, inertial: &Inertial, diagonal: bool) -> SpatialInertia {
        let m = inertial.mass;
        let r = pose.rotation.to_rotation_matrix();
        let r = r.matrix();
        let c = r * inertial.com + pose.translation.vector;
        // I_o = R I_c Rᵀ − m [c]×[c]× with −[c]×[c]× = |c|² 1 − c cᵀ; symmetric, so the upper
        // triangle is computed and mirrored.
        let i_c = &inertial.inertia;
        // Principal axes along the link frame (URDF and glove10 inertias mostly are): R I Rᵀ
        // is then the three scaled outer products of R's columns, the same sums as the full
        // product with its zero terms left out (bit-identical) at half the multiplications.
        let ri = if diagonal {
            let mut ri = *r;
            for k in 0..3 {
                ri.column_mut(k).scale_mut(i_c[(k, k)]);
            }
            ri
        } else {
            r * i_c
        };
        let c2 = c.norm_squared();
        let mut i_o = Mat3::zeros();
        for a in 0..3 {
            for b in a..3 {
                let rot = ri[(a, 0)] * r[(b, 0)] + ri[(a, 1)] * r[(b, 1)] + ri[(a, 2)] * r[(b, 2)];
                let shift = if a == b { c2 } else { 0.0 } - c[a] * c[b];
                i_o[(a, b)] = rot + shift * m;
                i_o[(b, a)] = i_o[(a, b)];
            }
        }
        SpatialInertia {
            mass: m,
            h: c * m,
            i_o,
        }
    }

    /// [`of_link`](Self::of_link) for a link of mass `m` whose inertia about its centre of
    /// mass is `transverse` about every axis but link axis `k`, `transverse + excess` about
    /// that one, with the centre of mass on axis `k` at `along` ([`LinkAxes::Axial`]). With
    /// `a` that axis in the world, `R I_c Rᵀ = transverse 1 + excess a aᵀ`: one column of the
    /// rotation instead of the whole product.
    #[inline(always)]
    fn of_axial_link(
        pose: &Isometry,
        m: f64,
        k: usize,
        transverse: f64,
        excess: f64,
        along: f64,
    ) -> SpatialInertia {
        let q = pose.rotation.quaternion();
        let (w, x, y, z) = (q.w, q.i, q.j, q.k);
        // Column k of the rotation matrix of the unit quaternion.
        let a = match k {
            0 => Vector::new(
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y + w * z),
                2.0 * (x * z - w * y),
            ),
            1 => Vector::new(
                2.0 * (x * y - w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z + w * x),
            ),
            _ => Vector::new(
                2.0 * (x * z + w * y),
                2.0 * (y * z - w * x),
                1.0 - 2.0 * (x * x + y * y),
            ),
        };
        let c = a * along + pose.translation.vector;
        let h = c * m;
        // I_o = transverse 1 + excess a aᵀ + m (|c|² 1 − c cᵀ), symmetric.
        let diag = transverse + h.dot(&c);
        let ea = a * excess;
        let (xy, xz, yz) = (
            ea.x * a.y - h.x * c.y,
            ea.x * a.z - h.x * c.z,
            ea.y * a.z - h.y * c.z,
        );
        let i_o = Mat3::new(
            diag + ea.x * a.x - h.x * c.x,
            xy,
            xz,
            xy,
            diag + ea.y * a.y - h.y * c.y,
            yz,
            xz,
            yz,
            diag + ea.z * a.z - h.z * c.z,
        );
        SpatialInertia { mass: m, h, i_o }
    }

    /// The spatial force `I (v, ω)` = (m v − h × ω, h × v + I_o ω) for the twist `(v, ω)`.
    #[inline]
    pub fn apply(&self, v: &Vector, w: &Vector) -> (Vector, Vector) {
        (
            v * self.mass - self.h.cross(w),
            self.h.cross(v) + self.i_o * w,
        )
    }

    /// The 6x6 matrix form.
    pub fn to_matrix(&self) -> Mat6 {
        let hx = skew(&self.h);
        let mut s = Mat6::zeros();
        s.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Mat3::identity() * self.mass));
        s.fixed_view_mut::<3, 3>(0, 3).copy_from(&-hx);
        s.fixed_view_mut::<3, 3>(3, 0).copy_from(&hx);
        s.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.i_o);
        s
    }
}

impl std::ops::AddAssign for SpatialInertia {
    fn add_assign(&mut self, o: SpatialInertia) {
        self.mass += o.mass;
        self.h += o.h;
        self.i_o += o.i_o;
    }
}

/// Solves `A x = b` for the symmetric positive-definite top-left `n × n` block of `a` by an
/// in-place Cholesky factorisation (entries of `x` from `n` on are zero). Allocation-free;
/// `None` when the block is not positive definite (or not finite) or `n > MAX_DOF`. Use it
/// for M(θ)⁻¹ τ.
///
/// Why not the tick's solver ([`crate::math::cholesky_solve_in_place`], square-root-free
/// `L D Lᵀ` over the upper triangle): the two factorisations round differently in the last
/// bits, and the inverse kinematics iterates on this solve (up to 150 steps, with accept/reject
/// decisions on the error), so replacing it changes the simulated operator's sessions bit for
/// bit — `operator::tests::without_vary_reach_a_session_is_the_one_it_was_before` pins their
/// hash, and recorded sessions and skills would no longer reproduce. Swap it only together with
/// a new pinned hash (a behaviour change of its own).
pub fn solve_dof_spd(a: &DofMatrix, b: &DofVector, n: usize) -> Option<DofVector> {
    if n > MAX_DOF {
        return None;
    }
    // Lower-triangular factor L with A = L Lᵀ, in the lower triangle of `l`.
    let mut l = *a;
    for j in 0..n {
        let mut d = l[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let d = d.sqrt();
        l[(j, j)] = d;
        for i in j + 1..n {
            let mut v = l[(i, j)];
            for k in 0..j {
                v -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = v / d;
        }
    }
    let mut x = DofVector::zeros();
    for i in 0..n {
        let mut v = b[i];
        for k in 0..i {
            v -= l[(i, k)] * x[k];
        }
        x[i] = v / l[(i, i)];
    }
    for i in (0..n).rev() {
        let mut v = x[i];
        for k in i + 1..n {
            v -= l[(k, i)] * x[k];
        }
        x[i] = v / l[(i, i)];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

impl HandModel {
    /// Joint-space inertia M(θ) into the top-left `dof × dof` block of `m` (the rest of `m` is
    /// not touched) from the link inertials and the armature, for the kinematics in `kin`.
    /// Allocation-free.
    ///
    /// M = Σ_links (J_vᵀ m J_v + J_ωᵀ R I Rᵀ J_ω) + diag(armature), with J_v the Jacobian of
    /// the link's centre of mass and J_ω its angular Jacobian (world frame), evaluated by the
    /// composite rigid-body algorithm; a mimic joint enters with its multiplier.
    pub fn mass_matrix(&self, kin: &mut Kinematics, m: &mut DofMatrix) {
        self.mass_matrix_planned(&self.mass_plan(), kin, m);
    }

    /// The structure [`mass_matrix_planned`](Self::mass_matrix_planned) walks: the driven
    /// joints, their DOFs and gains, and each one's nearest driven ancestor. It depends on the
    /// hand only, so a caller computing M(θ) every tick makes it once. Allocation-free.
    pub fn mass_plan(&self) -> MassPlan {
        let mut plan = MassPlan {
            driven: [DrivenJoint {
                joint: 0,
                child: 0,
                dof: 0,
                col: 0,
                gain: 0.0,
                prismatic: false,
                up: NO_JOINT,
            }; MAX_LINKS],
            len: 0,
            link_axes: [LinkAxes::Massless; MAX_LINKS],
        };
        for (l, link) in self.links.iter().enumerate().take(MAX_LINKS) {
            if l != self.root && link.inertial.mass > 0.0 {
                plan.link_axes[l] = LinkAxes::of(&link.inertial);
            }
        }
        // The driven-list index of the nearest driven joint at or above every link.
        let mut driven_above = [NO_JOINT; MAX_LINKS];
        let joints = &self.joints[..self.joints.len().min(MAX_LINKS)];
        // Joints come parent first (`validate`), so a joint's parent link is settled before it.
        for (j, joint) in joints.iter().enumerate() {
            let above = driven_above.get(joint.parent).copied().unwrap_or(NO_JOINT);
            let mut here = above;
            if let Some((dof, gain)) = joint.drive.dof_and_gain() {
                plan.driven[plan.len] = DrivenJoint {
                    joint: j,
                    child: joint.child,
                    dof,
                    col: dof * MAX_DOF,
                    gain,
                    prismatic: joint.kind == JointKind::Prismatic,
                    up: above,
                };
                here = plan.len;
                plan.len += 1;
            }
            if let Some(slot) = driven_above.get_mut(joint.child) {
                *slot = here;
            }
        }
        plan
    }

    /// [`mass_matrix`](Self::mass_matrix) with the hand's [`MassPlan`] made beforehand.
    pub fn mass_matrix_planned(&self, plan: &MassPlan, kin: &mut Kinematics, m: &mut DofMatrix) {
        let n = self.dof().min(MAX_DOF);
        // Only the block is written: filling all 24x24 entries every tick cost as much as the
        // algorithm itself.
        for c in 0..n {
            m.as_mut_slice()[c * MAX_DOF..c * MAX_DOF + n].fill(0.0);
        }
        // Composite rigid-body algorithm in the world frame: the spatial inertia of every
        // subtree about the world origin, then H_ij = S_jᵀ I_subtree(i) S_i for every driven
        // joint j on the path to driven joint i, the motion subspaces S scaled by the drive
        // gains (a mimic joint enters with its multiplier). The subtree inertias live in the
        // kinematics' scratch (disjoint field borrows).
        let Kinematics {
            composite,
            joint_axes,
            joint_frames,
            link_poses,
            joint_motion: motion,
            ..
        } = kin;
        for (l, link) in self.links.iter().enumerate().take(MAX_LINKS) {
            let pose = &link_poses[l];
            composite[l] = match plan.link_axes.get(l).copied() {
                None | Some(LinkAxes::Massless) => SpatialInertia::ZERO,
                Some(LinkAxes::Axial {
                    k,
                    transverse,
                    excess,
                    along,
                }) => SpatialInertia::of_axial_link(
                    pose,
                    link.inertial.mass,
                    k,
                    transverse,
                    excess,
                    along,
                ),
                Some(LinkAxes::Principal) => {
                    SpatialInertia::of_link_with_axes(pose, &link.inertial, true)
                }
                Some(LinkAxes::General) => {
                    SpatialInertia::of_link_with_axes(pose, &link.inertial, false)
                }
            };
        }
        // Children before parents; along a chain the subtree just summed is the next one's
        // child, kept at hand instead of read back from the store just made.
        let (mut last_link, mut last) = (usize::MAX, SpatialInertia::ZERO);
        for joint in self.joints[..self.joints.len().min(MAX_LINKS)].iter().rev() {
            let child = if joint.child == last_link {
                last
            } else {
                composite[joint.child]
            };
            let mut sum = composite[joint.parent];
            sum += child;
            composite[joint.parent] = sum;
            (last_link, last) = (joint.parent, sum);
        }
        let driven = &plan.driven[..plan.len.min(MAX_LINKS)];
        // Every driven joint's motion subspace once, times its gain: (velocity of the body
        // point at the origin, angular velocity) per unit DOF value.
        for (s, d) in motion.iter_mut().zip(driven) {
            let a = joint_axes[d.joint] * d.gain;
            *s = if d.prismatic {
                (a, Vector::zeros())
            } else {
                (joint_frames[d.joint].translation.vector.cross(&a), a)
            };
        }
        // Column-major storage: entry (r, c) at `c * MAX_DOF + r`, each driven joint's column
        // offset made once in the plan.
        let m = m.as_mut_slice();
        for (i, di) in driven.iter().enumerate() {
            let (v, w) = &motion[i];
            let (f, t) = composite[di.child].apply(v, w);
            m[di.col + di.dof] += v.dot(&f) + w.dot(&t);
            let mut j = di.up;
            while let (Some(dj), Some((vj, wj))) = (driven.get(j), motion.get(j)) {
                let h = vj.dot(&f) + wj.dot(&t);
                m[dj.col + di.dof] += h;
                m[di.col + dj.dof] += h;
                j = dj.up;
            }
        }
        for (i, a) in self.armature.iter().enumerate().take(n) {
            m[i * MAX_DOF + i] += a;
        }
    }
}

/// A driven (non-fixed) joint as the composite rigid-body algorithm walks it.
#[derive(Debug, Clone, Copy)]
struct DrivenJoint {
    /// Index into `HandModel::joints`.
    joint: usize,
    /// Its child link.
    child: usize,
    /// The DOF driving it.
    dof: usize,
    /// Offset of that DOF's column in the column-major [`DofMatrix`]: `dof * MAX_DOF`.
    col: usize,
    /// `∂(joint value)/∂θ[dof]`: 1, or a mimic joint's multiplier.
    gain: f64,
    prismatic: bool,
    /// Index in [`MassPlan::driven`] of the nearest driven joint above it, [`NO_JOINT`] if none.
    up: usize,
}

/// The hand structure M(θ) needs, made once per hand by [`HandModel::mass_plan`]: the driven
/// joints parent first, each with its nearest driven ancestor.
#[derive(Debug, Clone, Copy)]
pub struct MassPlan {
    driven: [DrivenJoint; MAX_LINKS],
    len: usize,
    /// Per link: no mass (or the root, which does not move), or the form of its inertia.
    pub(super) link_axes: [LinkAxes; MAX_LINKS],
}

/// How a link enters M(θ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum LinkAxes {
    Massless,
    /// Inertia tensor diagonal in the link frame with two equal moments (`transverse`), the
    /// third, about link axis `k`, `transverse + excess`; the centre of mass on that axis at
    /// `along` (a cylinder or a rod along its axis, as glove10's phalanges): only axis `k`'s
    /// world direction is needed.
    Axial {
        k: usize,
        transverse: f64,
        excess: f64,
        along: f64,
    },
    /// Inertia tensor diagonal in the link frame.
    Principal,
    General,
}

impl LinkAxes {
    /// The form of a massive link's inertia.
    fn of(inertial: &Inertial) -> LinkAxes {
        if !inertial.principal_in_link_frame() {
            return LinkAxes::General;
        }
        let (i, c) = (&inertial.inertia, &inertial.com);
        for k in 0..3 {
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            if i[(a, a)] == i[(b, b)] && c[a] == 0.0 && c[b] == 0.0 {
                return LinkAxes::Axial {
                    k,
                    transverse: i[(a, a)],
                    excess: i[(k, k)] - i[(a, a)],
                    along: c[k],
                };
            }
        }
        LinkAxes::Principal
    }
}
