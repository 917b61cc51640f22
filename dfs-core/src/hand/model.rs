//! Hand model types, forward kinematics, Jacobians and joint-space inertia.

use crate::error::{DfsError, Result};
use crate::math::{skew, Isometry, Mat3, Mat6, Point, Rotation, UnitVector, Vector};
use nalgebra::SMatrix;

/// Capacity of the fixed-size joint-space storage ([`DofMatrix`], [`DofVector`],
/// [`TipJacobian`], the planners' angle arrays): a hand's DOFs plus the
/// [`FREE_BASE_DOF`] coordinates the planners add for its base position. A hand itself may
/// have at most [`MAX_HAND_DOF`].
pub const MAX_DOF: usize = MAX_HAND_DOF + FREE_BASE_DOF;
/// Largest number of generalised coordinates (DOFs) a hand may have: 32. The largest common
/// dexterous hands have up to 30 with their wrist (the Shadow hand 24, 22 of them in its
/// fingers); a hand with more is refused when it is built. Each DOF widens the
/// planners' Cholesky solves (n³) but not the DFS tick of a smaller hand.
pub const MAX_HAND_DOF: usize = 32;
/// Coordinates (and links) the planners add to a hand to move its base freely: its position
/// along world x, y and z (see [`crate::operator::with_free_base`]).
pub const FREE_BASE_DOF: usize = 3;
/// Capacity of the per-link storage ([`Kinematics`]): a hand's links plus the
/// [`FREE_BASE_DOF`] links the planners add. A hand itself may have at most
/// [`MAX_HAND_LINKS`].
pub const MAX_LINKS: usize = 64;
/// Largest number of links a hand may have: 61 ([`MAX_LINKS`] less the planners' free-base
/// links); a five-finger hand with a wrist and fixed fingertip frames has about 35.
pub const MAX_HAND_LINKS: usize = MAX_LINKS - FREE_BASE_DOF;
/// Largest number of fingertips a hand may have.
pub const MAX_TIPS: usize = 6;

/// Joint-space square matrix of fixed capacity; only the top-left `dof × dof` block is used.
pub type DofMatrix = SMatrix<f64, MAX_DOF, MAX_DOF>;
/// A joint-space vector of fixed capacity (angles, velocities, torques); only the first `dof`
/// entries are used.
pub type DofVector = nalgebra::SVector<f64, MAX_DOF>;
/// A fingertip Jacobian of fixed capacity: rows are (linear, angular) velocity of the tip point
/// in the world frame, columns the DOFs; only the first `dof` columns are used.
pub type TipJacobian = SMatrix<f64, 6, MAX_DOF>;

/// The kind of a joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointKind {
    /// Rotation about `axis`, limited.
    Revolute,
    /// Rotation about `axis`, unlimited.
    Continuous,
    /// Translation along `axis`, limited.
    Prismatic,
    /// No motion.
    Fixed,
}

/// What drives a joint's value.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointDrive {
    /// A fixed joint: no coordinate.
    Fixed,
    /// An independent joint: its value is `θ[dof]`.
    Dof(usize),
    /// A coupled joint: its value is `multiplier · θ[dof] + offset` (URDF `mimic`).
    Mimic {
        /// The driving DOF.
        dof: usize,
        /// Gear ratio.
        multiplier: f64,
        /// Offset (rad or m).
        offset: f64,
    },
}

/// Mass properties of a link, in the link frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    /// Mass (kg), ≥ 0.
    pub mass: f64,
    /// Centre of mass in the link frame (m).
    pub com: Vector,
    /// Rotational inertia about the centre of mass, link-frame axes (kg·m²).
    pub inertia: Mat3,
}

impl Inertial {
    /// The inertia tensor is diagonal: the link frame's axes are its principal axes.
    pub fn principal_in_link_frame(&self) -> bool {
        let i = &self.inertia;
        i[(0, 1)] == 0.0
            && i[(0, 2)] == 0.0
            && i[(1, 2)] == 0.0
            && i[(1, 0)] == 0.0
            && i[(2, 0)] == 0.0
            && i[(2, 1)] == 0.0
    }
}

impl Default for Inertial {
    /// No mass.
    fn default() -> Self {
        Inertial {
            mass: 0.0,
            com: Vector::zeros(),
            inertia: Mat3::zeros(),
        }
    }
}

/// A rigid link.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// Unique name.
    pub name: String,
    /// Mass properties.
    pub inertial: Inertial,
}

/// A joint between a parent and a child link.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// Unique name.
    pub name: String,
    /// Kind of motion.
    pub kind: JointKind,
    /// Index of the parent link.
    pub parent: usize,
    /// Index of the child link.
    pub child: usize,
    /// Pose of the joint frame (= child link frame at zero joint value) in the parent link frame.
    pub origin: Isometry,
    /// Axis of motion in the joint frame.
    pub axis: UnitVector,
    /// Lower joint limit (rad or m); `-inf` when unlimited.
    pub lower: f64,
    /// Upper joint limit (rad or m); `+inf` when unlimited.
    pub upper: f64,
    /// What drives the joint.
    pub drive: JointDrive,
}

/// A fingertip: a sphere on a link that can touch objects.
#[derive(Debug, Clone, PartialEq)]
pub struct Fingertip {
    /// Name (for example "index").
    pub name: String,
    /// Link the tip is attached to.
    pub link: usize,
    /// Centre of the fingertip sphere in the link frame (m).
    pub offset: Vector,
    /// Radius of the fingertip sphere (m), > 0.
    pub radius: f64,
}

/// A set of fingertips that share actuated DOFs (other than the DOFs shared by every tip,
/// such as the wrist), and those DOFs. Joint torques of a group are resolved into the
/// fingertip forces of its tips together (paper eq. 14).
#[derive(Debug, Clone, PartialEq)]
pub struct FingerGroup {
    /// Fingertip indices.
    pub tips: Vec<usize>,
    /// DOF indices.
    pub dofs: Vec<usize>,
}

/// A hand: a kinematic tree rooted at the base link, with fingertips.
#[derive(Debug, Clone, PartialEq)]
pub struct HandModel {
    /// Model name (for example "glove10").
    pub name: String,
    /// Links; index 0 need not be the root.
    pub links: Vec<Link>,
    /// Joints in topological order (a joint's parent link is the root or the child of an
    /// earlier joint).
    pub joints: Vec<Joint>,
    /// The root (base) link.
    pub root: usize,
    /// Names of the DOFs (the independent joints), in θ order.
    pub dof_names: Vec<String>,
    /// Lower limit per DOF (rad or m).
    pub dof_lower: Vec<f64>,
    /// Upper limit per DOF (rad or m).
    pub dof_upper: Vec<f64>,
    /// Torque (or force) limit per DOF (N·m or N), > 0.
    pub torque_limit: Vec<f64>,
    /// Rotor/reflected inertia added to the diagonal of M(θ) per DOF (kg·m²); keeps M positive
    /// definite for massless links.
    pub armature: Vec<f64>,
    /// Fingertips.
    pub fingertips: Vec<Fingertip>,
    /// Finger groups for resolving joint torques into tip forces.
    pub finger_groups: Vec<FingerGroup>,
    /// Whole-hand contact geometry: the palm and the phalanges as link-fixed solids
    /// ([`super::contact_geometry`]), at most [`super::MAX_CONTACT_SHAPES`]; empty for a hand
    /// that touches with its fingertips only.
    pub contact_shapes: Vec<super::ContactShape>,
}

/// Marks a link without a parent joint (the root) in [`Kinematics::parent_joint`].
pub const NO_JOINT: usize = usize::MAX;

/// Forward kinematics results of fixed capacity, reused every tick.
#[derive(Debug, Clone)]
pub struct Kinematics {
    /// Pose of every link in the world frame (only the first `links.len()` are valid).
    pub link_poses: [Isometry; MAX_LINKS],
    /// World pose of every joint frame (after applying the joint value).
    pub joint_frames: [Isometry; MAX_LINKS],
    /// Axis of every joint in the world frame (unit; only the first `joints.len()` are valid).
    pub joint_axes: [Vector; MAX_LINKS],
    /// Index of the joint whose child is each link, [`NO_JOINT`] for the root.
    pub parent_joint: [usize; MAX_LINKS],
    /// Centre of every fingertip sphere in the world frame.
    pub tip_centres: [Point; MAX_TIPS],
    /// Jacobian of every fingertip centre: (linear, angular) rows, DOF columns, world frame.
    pub tip_jacobians: [TipJacobian; MAX_TIPS],
    /// Scratch for [`HandModel::mass_matrix`]: composite spatial inertia of every subtree
    /// (only the hand's links are written).
    pub composite: [SpatialInertia; MAX_LINKS],
    /// Scratch for [`HandModel::mass_matrix`]: every driven joint's motion subspace (velocity
    /// of the body point at the world origin, angular velocity) per unit DOF value. Kept here so
    /// the 64-entry array is not zeroed on the stack every tick.
    pub joint_motion: [(Vector, Vector); MAX_LINKS],
}

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

impl Default for Kinematics {
    fn default() -> Self {
        Kinematics {
            link_poses: [Isometry::identity(); MAX_LINKS],
            joint_frames: [Isometry::identity(); MAX_LINKS],
            joint_axes: [Vector::zeros(); MAX_LINKS],
            parent_joint: [NO_JOINT; MAX_LINKS],
            tip_centres: [Point::origin(); MAX_TIPS],
            tip_jacobians: [TipJacobian::zeros(); MAX_TIPS],
            composite: [SpatialInertia::ZERO; MAX_LINKS],
            joint_motion: [(Vector::zeros(), Vector::zeros()); MAX_LINKS],
        }
    }
}

impl JointDrive {
    /// The driving DOF and the gain `∂(joint value)/∂θ[dof]` (1 for an independent joint,
    /// the multiplier for a mimic joint); `None` for a fixed joint.
    pub fn dof_and_gain(&self) -> Option<(usize, f64)> {
        match *self {
            JointDrive::Fixed => None,
            JointDrive::Dof(d) => Some((d, 1.0)),
            JointDrive::Mimic {
                dof, multiplier, ..
            } => Some((dof, multiplier)),
        }
    }

    /// The joint value (rad or m) for the DOF vector `q`; a missing DOF reads as 0.
    pub fn value(&self, q: &[f64]) -> f64 {
        let at = |d: usize| q.get(d).copied().unwrap_or(0.0);
        match *self {
            JointDrive::Fixed => 0.0,
            JointDrive::Dof(d) => at(d),
            JointDrive::Mimic {
                dof,
                multiplier,
                offset,
            } => multiplier * at(dof) + offset,
        }
    }
}

impl Joint {
    /// The motion of the joint frame for joint value `value`: a rotation about `axis` for
    /// revolute and continuous joints, a translation along `axis` for prismatic ones.
    pub fn motion(&self, value: f64) -> Isometry {
        match self.kind {
            JointKind::Revolute | JointKind::Continuous => Isometry::from_parts(
                nalgebra::Translation3::identity(),
                Rotation::from_axis_angle(&self.axis, value),
            ),
            JointKind::Prismatic => Isometry::translation(
                self.axis.x * value,
                self.axis.y * value,
                self.axis.z * value,
            ),
            JointKind::Fixed => Isometry::identity(),
        }
    }
}

impl Joint {
    /// The joint frame in its parent link's frame for joint value `value`: `origin · motion`.
    /// A rotation has no translation, so its product with the origin is only a quaternion
    /// product (no vector rotated).
    #[inline]
    pub fn placed(&self, value: f64) -> Isometry {
        match self.kind {
            JointKind::Revolute | JointKind::Continuous => {
                self.placed_rotated(value, (value / 2.0).sin_cos())
            }
            _ => self.origin * self.motion(value),
        }
    }

    /// [`placed`](Self::placed) given `(sin, cos)` of half the joint value for a rotating
    /// joint (the unit quaternion `Rotation::from_axis_angle` builds, bit for bit).
    #[inline]
    fn placed_rotated(&self, value: f64, (s, c): (f64, f64)) -> Isometry {
        match self.kind {
            JointKind::Revolute | JointKind::Continuous => Isometry::from_parts(
                self.origin.translation,
                self.origin.rotation
                    * Rotation::new_unchecked(nalgebra::Quaternion::from_parts(
                        c,
                        self.axis.into_inner() * s,
                    )),
            ),
            _ => self.origin * self.motion(value),
        }
    }
}

/// Solves `A x = b` for the symmetric positive-definite top-left `n × n` block of `a` by an
/// in-place Cholesky factorisation (entries of `x` from `n` on are zero). Allocation-free;
/// `None` when the block is not positive definite (or not finite) or `n > MAX_DOF`. Use it
/// for M(θ)⁻¹ τ.
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

/// Bit set of DOFs (`MAX_DOF` ≤ 64).
pub type DofSet = u64;

/// The bit of DOF `d` in a [`DofSet`] (none beyond its 64 bits).
fn dof_bit(d: usize) -> DofSet {
    DofSet::from(d < DofSet::BITS as usize)
        .checked_shl(d as u32)
        .unwrap_or(0)
}

const _: () = assert!(MAX_DOF <= DofSet::BITS as usize);

/// Why a hand of `n` DOFs is refused: more than [`MAX_HAND_DOF`].
pub(crate) fn too_many_dofs(n: usize) -> String {
    format!(
        "the hand has {n} DOFs (independent moving joints); at most {MAX_HAND_DOF} are \
         accepted (the largest dexterous hands have about 30 with their wrist)"
    )
}

/// True when every entry of a 3-vector is finite.
fn finite3(v: &Vector) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// True when an isometry has finite entries.
fn finite_pose(x: &Isometry) -> bool {
    finite3(&x.translation.vector) && x.rotation.coords.iter().all(|c| c.is_finite())
}

/// Checks `lower ≤ upper` with neither NaN.
fn check_limits(field: String, lower: f64, upper: f64) -> Result<()> {
    if lower.is_nan() || upper.is_nan() {
        return Err(DfsError::invalid(field, "limit is NaN"));
    }
    if lower > upper {
        return Err(DfsError::invalid(
            field,
            format!("lower {lower} > upper {upper}"),
        ));
    }
    Ok(())
}

/// Index of the first duplicate name, if any.
fn first_duplicate<'a>(names: impl Iterator<Item = &'a str> + Clone) -> Option<usize> {
    names
        .clone()
        .enumerate()
        .find(|(i, n)| names.clone().take(*i).any(|m| m == *n))
        .map(|(i, _)| i)
}

impl HandModel {
    /// Number of DOFs.
    pub fn dof(&self) -> usize {
        self.dof_names.len()
    }

    /// Checks the model: sizes within capacity, a tree (one root, no loops), valid indices,
    /// limits ordered, masses ≥ 0, radii > 0, torque limits > 0. Names the offending field.
    pub fn validate(&self) -> Result<()> {
        self.validate_sizes()?;
        self.validate_links()?;
        self.validate_dofs()?;
        self.validate_tree()?;
        self.validate_joints()?;
        self.validate_tips()?;
        self.validate_groups()?;
        super::contact_geometry::validate_contact_shapes(self, &self.contact_shapes)
    }

    /// Capacities and the lengths of the per-DOF vectors.
    fn validate_sizes(&self) -> Result<()> {
        let n = self.dof();
        if self.links.is_empty() || self.links.len() > MAX_HAND_LINKS {
            let reason = format!(
                "{} links, expected 1..={MAX_HAND_LINKS} (the largest hand accepted)",
                self.links.len()
            );
            return Err(DfsError::invalid("links", reason));
        }
        if self.joints.len() >= self.links.len() {
            let reason = format!(
                "{} joints for {} links (a tree has one fewer)",
                self.joints.len(),
                self.links.len()
            );
            return Err(DfsError::invalid("joints", reason));
        }
        if n > MAX_HAND_DOF {
            return Err(DfsError::invalid("dof_names", too_many_dofs(n)));
        }
        if self.fingertips.len() > MAX_TIPS {
            let reason = format!("{} tips > {MAX_TIPS}", self.fingertips.len());
            return Err(DfsError::invalid("fingertips", reason));
        }
        let per_dof = [
            ("dof_lower", self.dof_lower.len()),
            ("dof_upper", self.dof_upper.len()),
            ("torque_limit", self.torque_limit.len()),
            ("armature", self.armature.len()),
        ];
        for (field, len) in per_dof {
            if len != n {
                return Err(DfsError::invalid(
                    field,
                    format!("{len} entries for {n} DOFs"),
                ));
            }
        }
        if self.root >= self.links.len() {
            return Err(DfsError::invalid(
                "root",
                format!("link {} does not exist", self.root),
            ));
        }
        Ok(())
    }

    /// Link names and mass properties.
    fn validate_links(&self) -> Result<()> {
        if let Some(i) = first_duplicate(self.links.iter().map(|l| l.name.as_str())) {
            return Err(DfsError::invalid(
                format!("links[{i}].name"),
                "duplicate name",
            ));
        }
        for (i, link) in self.links.iter().enumerate() {
            let m = &link.inertial;
            if !(m.mass.is_finite() && m.mass >= 0.0) {
                let reason = format!("mass {} must be finite and ≥ 0", m.mass);
                return Err(DfsError::invalid(
                    format!("links[{i}].inertial.mass"),
                    reason,
                ));
            }
            if !finite3(&m.com) {
                return Err(DfsError::invalid(
                    format!("links[{i}].inertial.com"),
                    "not finite",
                ));
            }
            if !m.inertia.iter().all(|x| x.is_finite()) {
                let field = format!("links[{i}].inertial.inertia");
                return Err(DfsError::invalid(field, "not finite"));
            }
        }
        Ok(())
    }

    /// DOF names, limits, torque limits and armature.
    fn validate_dofs(&self) -> Result<()> {
        if let Some(i) = first_duplicate(self.dof_names.iter().map(String::as_str)) {
            return Err(DfsError::invalid(
                format!("dof_names[{i}]"),
                "duplicate name",
            ));
        }
        for i in 0..self.dof() {
            check_limits(
                format!("dof_lower[{i}]"),
                self.dof_lower[i],
                self.dof_upper[i],
            )?;
            let t = self.torque_limit[i];
            if t.is_nan() || t <= 0.0 {
                let reason = format!("torque limit {t} must be > 0");
                return Err(DfsError::invalid(format!("torque_limit[{i}]"), reason));
            }
            let a = self.armature[i];
            if !(a.is_finite() && a >= 0.0) {
                let reason = format!("armature {a} must be finite and ≥ 0");
                return Err(DfsError::invalid(format!("armature[{i}]"), reason));
            }
        }
        Ok(())
    }

    /// One root, every other link the child of exactly one joint, joints in topological
    /// order (so no loops).
    fn validate_tree(&self) -> Result<()> {
        if let Some(i) = first_duplicate(self.joints.iter().map(|j| j.name.as_str())) {
            return Err(DfsError::invalid(
                format!("joints[{i}].name"),
                "duplicate name",
            ));
        }
        let nl = self.links.len();
        let mut reached: u64 = 1 << self.root;
        for (j, joint) in self.joints.iter().enumerate() {
            if joint.parent >= nl {
                let reason = format!("link {} does not exist", joint.parent);
                return Err(DfsError::invalid(format!("joints[{j}].parent"), reason));
            }
            if joint.child >= nl {
                let reason = format!("link {} does not exist", joint.child);
                return Err(DfsError::invalid(format!("joints[{j}].child"), reason));
            }
            if reached & (1 << joint.parent) == 0 {
                let reason = "parent link is neither the root nor the child of an earlier joint \
                              (joints must be in topological order)";
                return Err(DfsError::invalid(format!("joints[{j}].parent"), reason));
            }
            if reached & (1 << joint.child) != 0 {
                let reason = "child link is the root or already has a parent (loop)";
                return Err(DfsError::invalid(format!("joints[{j}].child"), reason));
            }
            reached |= 1 << joint.child;
        }
        if let Some(i) = (0..nl).find(|&i| reached & (1 << i) == 0) {
            let reason = "link is not connected to the root (a second root)";
            return Err(DfsError::invalid(format!("links[{i}]"), reason));
        }
        Ok(())
    }

    /// Joint origins, axes, limits and drives; every DOF drives at least one joint.
    fn validate_joints(&self) -> Result<()> {
        let n = self.dof();
        let mut driven: DofSet = 0;
        for (j, joint) in self.joints.iter().enumerate() {
            if !finite_pose(&joint.origin) {
                return Err(DfsError::invalid(
                    format!("joints[{j}].origin"),
                    "not finite",
                ));
            }
            let axis = joint.axis.into_inner();
            if !finite3(&axis) || (axis.norm() - 1.0).abs() > 1e-6 {
                return Err(DfsError::invalid(
                    format!("joints[{j}].axis"),
                    "not a unit vector",
                ));
            }
            check_limits(format!("joints[{j}].lower"), joint.lower, joint.upper)?;
            let field = format!("joints[{j}].drive");
            match (joint.kind, joint.drive) {
                (JointKind::Fixed, JointDrive::Fixed) => {}
                (JointKind::Fixed, _) => {
                    return Err(DfsError::invalid(
                        field,
                        "a fixed joint must have a fixed drive",
                    ))
                }
                (_, JointDrive::Fixed) => {
                    return Err(DfsError::invalid(
                        field,
                        "a moving joint needs a DOF or a mimic",
                    ))
                }
                (
                    _,
                    JointDrive::Mimic {
                        multiplier, offset, ..
                    },
                ) if !(multiplier.is_finite() && offset.is_finite()) => {
                    return Err(DfsError::invalid(
                        field,
                        "mimic multiplier/offset not finite",
                    ))
                }
                _ => {}
            }
            if let Some((d, _)) = joint.drive.dof_and_gain() {
                if d >= n {
                    return Err(DfsError::invalid(
                        field,
                        format!("DOF {d} does not exist ({n})"),
                    ));
                }
                driven |= dof_bit(d);
            }
        }
        if let Some(d) = (0..n).find(|&d| driven & dof_bit(d) == 0) {
            return Err(DfsError::invalid(
                format!("dof_names[{d}]"),
                "drives no joint",
            ));
        }
        Ok(())
    }

    /// Fingertip links, offsets and radii.
    fn validate_tips(&self) -> Result<()> {
        if let Some(i) = first_duplicate(self.fingertips.iter().map(|t| t.name.as_str())) {
            return Err(DfsError::invalid(
                format!("fingertips[{i}].name"),
                "duplicate name",
            ));
        }
        for (k, tip) in self.fingertips.iter().enumerate() {
            if tip.link >= self.links.len() {
                let reason = format!("link {} does not exist", tip.link);
                return Err(DfsError::invalid(format!("fingertips[{k}].link"), reason));
            }
            if !finite3(&tip.offset) {
                return Err(DfsError::invalid(
                    format!("fingertips[{k}].offset"),
                    "not finite",
                ));
            }
            if !(tip.radius.is_finite() && tip.radius > 0.0) {
                let reason = format!("radius {} must be finite and > 0", tip.radius);
                return Err(DfsError::invalid(format!("fingertips[{k}].radius"), reason));
            }
        }
        Ok(())
    }

    /// Finger group indices.
    fn validate_groups(&self) -> Result<()> {
        for (g, group) in self.finger_groups.iter().enumerate() {
            if let Some(t) = group.tips.iter().find(|&&t| t >= self.fingertips.len()) {
                let reason = format!("tip {t} does not exist");
                return Err(DfsError::invalid(
                    format!("finger_groups[{g}].tips"),
                    reason,
                ));
            }
            if let Some(d) = group.dofs.iter().find(|&&d| d >= self.dof()) {
                let reason = format!("DOF {d} does not exist");
                return Err(DfsError::invalid(
                    format!("finger_groups[{g}].dofs"),
                    reason,
                ));
            }
        }
        Ok(())
    }

    /// For every DOF, the set of DOFs it shares inertia with: those driving a joint on the
    /// path from one of its joints to the root, or one below it. `M(θ)[a][b]` can be nonzero
    /// only for such pairs (and `a == b`); DOFs of different fingers never couple.
    pub fn inertia_coupling(&self) -> [DofSet; MAX_DOF] {
        let mut c = [0 as DofSet; MAX_DOF];
        for joint in &self.joints {
            let Some((b, _)) = joint.drive.dof_and_gain() else {
                continue;
            };
            if b >= MAX_DOF {
                continue;
            }
            let above = self.dofs_moving_link(joint.child);
            c[b] |= above;
            for (a, row) in c.iter_mut().enumerate() {
                if above & dof_bit(a) != 0 {
                    *row |= dof_bit(b);
                }
            }
        }
        c
    }

    /// The DOFs that move `link`, as a bit set (bit d set when DOF d moves it): those of every
    /// joint on the path from the root to it (a mimic joint counts for its source DOF). Needs
    /// a valid tree.
    pub fn dofs_moving_link(&self, link: usize) -> DofSet {
        let mut set: DofSet = 0;
        let mut current = link;
        // A valid tree has at most `joints.len()` joints on any path.
        for _ in 0..=self.joints.len() {
            let Some(joint) = self.joints.iter().find(|j| j.child == current) else {
                break;
            };
            if let Some((d, _)) = joint.drive.dof_and_gain() {
                set |= dof_bit(d);
            }
            current = joint.parent;
        }
        set
    }

    /// The path from `link` up to the root (the link first), at most [`MAX_LINKS`] long.
    fn ancestors(&self, link: usize) -> Vec<usize> {
        let mut path = vec![link];
        let mut current = link;
        for _ in 0..MAX_LINKS {
            let Some(joint) = self.joints.iter().find(|j| j.child == current) else {
                break;
            };
            current = joint.parent;
            path.push(current);
        }
        path
    }

    /// True when `ancestor` is `link` or on its path to the root. Needs a valid tree.
    pub fn is_ancestor_or_self(&self, ancestor: usize, link: usize) -> bool {
        self.ancestors(link).contains(&ancestor)
    }

    /// The deepest link that is an ancestor (or equal) of every link in `links`; `None` for
    /// no links. Needs a valid tree.
    pub fn common_ancestor(&self, links: impl IntoIterator<Item = usize>) -> Option<usize> {
        let mut links = links.into_iter();
        let mut path = self.ancestors(links.next()?);
        for l in links {
            let other = self.ancestors(l);
            path.retain(|a| other.contains(a));
        }
        path.first().copied()
    }

    /// Computes the finger groups from the tree (tips sharing non-common DOFs).
    ///
    /// The DOFs of tip k are those of the joints on the path from the root to its link.
    /// With two or more tips, the DOFs that move every tip rigidly together (the wrist: those
    /// above the tips' lowest common ancestor link) are dropped; tips whose
    /// remaining DOF sets intersect are united (transitively). A tip without DOFs forms its
    /// own group with no DOFs. Groups are ordered by their first tip; tips and DOFs ascend.
    pub fn compute_finger_groups(&mut self) {
        let nt = self.fingertips.len().min(MAX_TIPS);
        let mut sets = [0 as DofSet; MAX_TIPS];
        for (k, tip) in self.fingertips.iter().take(nt).enumerate() {
            sets[k] = self.dofs_moving_link(tip.link);
        }
        if nt >= 2 {
            // The DOFs that move every tip rigidly together (a wrist): those moving the lowest
            // common ancestor of the tips' links. A DOF below it that reaches every tip through
            // different joints (the mimic-coupled jaws of a parallel gripper) stays: it moves
            // the tips relative to each other, so it pushes on the object.
            let common = self
                .common_ancestor(self.fingertips.iter().take(nt).map(|t| t.link))
                .map(|lca| self.dofs_moving_link(lca))
                .unwrap_or(0);
            sets[..nt].iter_mut().for_each(|s| *s &= !common);
        }
        // Union-find over at most MAX_TIPS tips: label each tip with the smallest tip index
        // of its group, repeating until no label changes.
        let mut label: [usize; MAX_TIPS] = core::array::from_fn(|k| k);
        let mut changed = true;
        while changed {
            changed = false;
            for a in 0..nt {
                for b in 0..nt {
                    if sets[a] & sets[b] != 0 && label[b] > label[a] {
                        label[b] = label[a];
                        changed = true;
                    }
                }
            }
        }
        self.finger_groups = (0..nt)
            .filter(|&k| label[k] == k)
            .map(|first| {
                let tips: Vec<usize> = (0..nt).filter(|&k| label[k] == first).collect();
                let set = tips.iter().fold(0, |acc, &k| acc | sets[k]);
                let dofs = (0..self.dof().min(MAX_DOF))
                    .filter(|&d| set & dof_bit(d) != 0)
                    .collect();
                FingerGroup { tips, dofs }
            })
            .collect();
    }

    /// Checks a joint-angle vector: right length, finite, within limits (with `slack`).
    pub fn check_angles(&self, q: &[f64], slack: f64) -> Result<()> {
        if q.len() != self.dof() {
            let (got, expected) = (q.len(), self.dof());
            return Err(DfsError::WrongLength {
                what: "joint angles",
                got,
                expected,
            });
        }
        for (index, &value) in q.iter().enumerate() {
            if !value.is_finite() {
                return Err(DfsError::NotFinite {
                    what: "joint angle",
                    index,
                    value,
                });
            }
            let (lower, upper) = (self.dof_lower[index], self.dof_upper[index]);
            if value < lower - slack || value > upper + slack {
                let what = "joint angle";
                return Err(DfsError::OutOfRange {
                    what,
                    index,
                    value,
                    lower,
                    upper,
                });
            }
        }
        Ok(())
    }

    /// The range DOF `d` is swept over when a planner moves it from one end to the other: its
    /// limits, with an unlimited side (a continuous joint) read as 2 rad from the other side,
    /// or as ±1 rad when both are unlimited. Always finite, `lower ≤ upper`.
    pub fn sweep_range(&self, d: usize) -> (f64, f64) {
        let (lower, upper) = (self.dof_lower[d], self.dof_upper[d]);
        let lo = match (lower.is_finite(), upper.is_finite()) {
            (true, _) => lower,
            (false, true) => upper - 2.0,
            (false, false) => -1.0,
        };
        let hi = if upper.is_finite() { upper } else { lo + 2.0 };
        (lo, hi.max(lo))
    }

    /// Clamps `q` (the first `dof` entries) into the DOF limits; a NaN entry becomes the
    /// limit-clamped zero. Never panics on infinite limits.
    pub fn clamp_to_limits(&self, q: &mut [f64]) {
        for (i, x) in q.iter_mut().enumerate().take(self.dof()) {
            let v = if x.is_nan() { 0.0 } else { *x };
            *x = v.max(self.dof_lower[i]).min(self.dof_upper[i]);
        }
    }

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
        jac.fill(0.0);
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
    link_axes: [LinkAxes; MAX_LINKS],
}

/// How a link enters M(θ).
#[derive(Debug, Clone, Copy, PartialEq)]
enum LinkAxes {
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A symmetric positive-definite inertia with off-diagonal terms (kg·m²).
    fn inertia(scale: f64) -> Mat3 {
        Mat3::new(2.0, 0.3, -0.1, 0.3, 1.5, 0.2, -0.1, 0.2, 1.0) * scale
    }

    fn link(name: &str, mass: f64, com: [f64; 3]) -> Link {
        let inertial = Inertial {
            mass,
            com: Vector::from(com),
            inertia: inertia(mass * 1e-4),
        };
        Link {
            name: name.to_owned(),
            inertial,
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn joint(
        name: &str,
        kind: JointKind,
        parent: usize,
        child: usize,
        origin: Isometry,
        axis: Vector,
        limits: (f64, f64),
        drive: JointDrive,
    ) -> Joint {
        let axis = UnitVector::new_normalize(axis);
        let (lower, upper) = limits;
        Joint {
            name: name.to_owned(),
            kind,
            parent,
            child,
            origin,
            axis,
            lower,
            upper,
            drive,
        }
    }

    fn pose(t: [f64; 3], r: [f64; 3]) -> Isometry {
        Isometry::new(Vector::from(t), Vector::from(r))
    }

    /// A small hand exercising every joint kind: a prismatic carriage (DOF 0) carrying finger
    /// "a" (continuous DOF 1, revolute DOF 2, a fixed joint) and finger "b" (revolute DOF 3
    /// about a skew axis, then a mimic of DOF 3 with multiplier 0.7 and offset 0.1).
    pub(crate) fn test_hand() -> HandModel {
        let inf = f64::INFINITY;
        let links = vec![
            link("base", 1.0, [0.0; 3]),
            link("carriage", 0.1, [0.01, 0.0, 0.0]),
            link("a1", 0.05, [0.02, 0.001, 0.0]),
            link("a2", 0.03, [0.01, 0.0, -0.002]),
            link("a_tip", 0.01, [0.005, 0.0, 0.0]),
            link("b1", 0.04, [0.015, 0.0, 0.0]),
            link("b2", 0.02, [0.012, 0.002, 0.0]),
        ];
        let (p, c, r, f) = (
            JointKind::Prismatic,
            JointKind::Continuous,
            JointKind::Revolute,
            JointKind::Fixed,
        );
        let joints = vec![
            joint(
                "slide",
                p,
                0,
                1,
                pose([0.01, 0.0, 0.02], [0.1, 0.2, 0.3]),
                Vector::new(1.0, 0.2, 0.0),
                (-0.05, 0.05),
                JointDrive::Dof(0),
            ),
            joint(
                "a_spin",
                c,
                1,
                2,
                pose([0.03, 0.0, 0.0], [0.0, 0.0, 0.4]),
                Vector::z(),
                (-inf, inf),
                JointDrive::Dof(1),
            ),
            joint(
                "a_flex",
                r,
                2,
                3,
                pose([0.04, 0.0, 0.0], [0.2, 0.0, 0.0]),
                Vector::y(),
                (-1.0, 1.5),
                JointDrive::Dof(2),
            ),
            joint(
                "a_fixed",
                f,
                3,
                4,
                pose([0.02, 0.0, 0.005], [0.0, 0.3, 0.0]),
                Vector::x(),
                (0.0, 0.0),
                JointDrive::Fixed,
            ),
            joint(
                "b_flex",
                r,
                1,
                5,
                pose([0.0, 0.02, 0.0], [0.0; 3]),
                Vector::new(0.0, 1.0, 1.0),
                (-0.5, 1.2),
                JointDrive::Dof(3),
            ),
            joint(
                "b_coupled",
                r,
                5,
                6,
                pose([0.03, 0.0, 0.0], [0.0; 3]),
                Vector::y(),
                (-0.25, 0.94),
                JointDrive::Mimic {
                    dof: 3,
                    multiplier: 0.7,
                    offset: 0.1,
                },
            ),
        ];
        let mut hand = HandModel {
            name: "test".to_owned(),
            links,
            joints,
            root: 0,
            dof_names: ["slide", "a_spin", "a_flex", "b_flex"]
                .map(String::from)
                .to_vec(),
            dof_lower: vec![-0.05, -inf, -1.0, -0.5],
            dof_upper: vec![0.05, inf, 1.5, 1.2],
            torque_limit: vec![10.0, 1.0, 1.0, 1.0],
            armature: vec![1e-5; 4],
            fingertips: vec![
                Fingertip {
                    name: "a".into(),
                    link: 4,
                    offset: Vector::new(0.01, 0.0, 0.0),
                    radius: 0.008,
                },
                Fingertip {
                    name: "b".into(),
                    link: 6,
                    offset: Vector::new(0.025, 0.0, 0.0),
                    radius: 0.008,
                },
            ],
            finger_groups: Vec::new(),
            contact_shapes: Vec::new(),
        };
        hand.compute_finger_groups();
        hand
    }

    /// Joint angles within the limits from unit-interval samples (infinite limits → ±3).
    pub(crate) fn angles_from_unit(hand: &HandModel, u: &[f64]) -> Vec<f64> {
        (0..hand.dof())
            .map(|i| {
                let lo = hand.dof_lower[i].max(-3.0);
                let hi = hand.dof_upper[i].min(3.0);
                lo + u[i] * (hi - lo)
            })
            .collect()
    }

    fn base() -> Isometry {
        pose([0.1, -0.2, 0.3], [0.3, -0.5, 0.7])
    }

    fn fk(hand: &HandModel, q: &[f64]) -> Kinematics {
        let mut kin = Kinematics::default();
        hand.forward_kinematics(&base(), q, &mut kin);
        kin
    }

    fn invalid_field(result: Result<()>) -> String {
        match result {
            Err(DfsError::Invalid { field, .. }) => field,
            other => panic!("expected an invalid-model error, got {other:?}"),
        }
    }

    #[test]
    fn test_hand_and_glove10_are_valid() {
        test_hand().validate().unwrap();
        HandModel::glove10().validate().unwrap();
    }

    #[test]
    fn validation_names_the_offending_field() {
        type Corrupt = fn(&mut HandModel);
        let cases: Vec<(Corrupt, &str)> = vec![
            (|h| h.root = 99, "root"),
            (|h| h.joints[1].child = 0, "joints[1].child"),
            (|h| h.joints[5].child = 3, "joints[5].child"),
            (|h| h.joints[2].parent = 42, "joints[2].parent"),
            (|h| h.joints.swap(1, 2), "joints[1].parent"),
            (
                |h| {
                    h.joints[5].drive = JointDrive::Mimic {
                        dof: 7,
                        multiplier: 1.0,
                        offset: 0.0,
                    }
                },
                "joints[5].drive",
            ),
            (
                |h| h.joints[3].drive = JointDrive::Dof(0),
                "joints[3].drive",
            ),
            (|h| h.joints[2].lower = 2.0, "joints[2].lower"),
            (|h| h.dof_lower[2] = 2.0, "dof_lower[2]"),
            (
                |h| h.links[3].inertial.mass = -1.0,
                "links[3].inertial.mass",
            ),
            (
                |h| h.links[2].inertial.inertia[(0, 1)] = f64::NAN,
                "links[2].inertial.inertia",
            ),
            (|h| h.fingertips[1].radius = 0.0, "fingertips[1].radius"),
            (|h| h.fingertips[0].link = 9, "fingertips[0].link"),
            (|h| h.torque_limit[3] = 0.0, "torque_limit[3]"),
            (|h| h.armature.pop().map(drop).unwrap_or(()), "armature"),
            (|h| h.dof_names.push("extra".into()), "dof_lower"),
            (|h| h.joints.pop().map(drop).unwrap_or(()), "links[6]"),
            (|h| h.links[5].name = "a1".into(), "links[5].name"),
            (
                |h| h.finger_groups[0].dofs.push(11),
                "finger_groups[0].dofs",
            ),
        ];
        for (corrupt, field) in cases {
            let mut hand = test_hand();
            corrupt(&mut hand);
            assert_eq!(invalid_field(hand.validate()), field);
        }
    }

    #[test]
    fn validation_rejects_models_beyond_capacity() {
        let mut hand = test_hand();
        hand.fingertips = vec![hand.fingertips[0].clone(); MAX_TIPS + 1];
        assert_eq!(invalid_field(hand.validate()), "fingertips");
        let mut hand = test_hand();
        hand.dof_names = (0..=MAX_DOF).map(|i| format!("d{i}")).collect();
        assert_eq!(invalid_field(hand.validate()), "dof_names");
        // The hand's own capacity leaves room for the planners' free base.
        hand.dof_names.truncate(MAX_HAND_DOF + 1);
        let e = hand.validate().unwrap_err().to_string();
        assert!(
            e.contains("the hand has 33 DOFs") && e.contains("at most 32 are accepted"),
            "{e}"
        );
        let mut hand = test_hand();
        let link = hand.links[0].clone();
        hand.links.resize(MAX_HAND_LINKS + 1, link);
        assert_eq!(invalid_field(hand.validate()), "links");
    }

    #[test]
    fn angle_check_reports_length_non_finite_and_range() {
        let hand = test_hand();
        assert!(hand.check_angles(&[0.0, 10.0, 0.2, 0.3], 0.0).is_ok());
        assert!(matches!(
            hand.check_angles(&[0.0; 3], 0.0),
            Err(DfsError::WrongLength {
                got: 3,
                expected: 4,
                ..
            })
        ));
        let nan = hand.check_angles(&[0.0, f64::NAN, 0.0, 0.0], 0.0);
        assert!(matches!(
            nan,
            Err(DfsError::NotFinite {
                what: "joint angle",
                index: 1,
                ..
            })
        ));
        let out = hand.check_angles(&[0.0, 0.0, 1.6, 0.0], 0.05);
        assert!(matches!(out, Err(DfsError::OutOfRange { index: 2, .. })));
        assert!(hand.check_angles(&[0.0, 0.0, 1.54, 0.0], 0.05).is_ok());
    }

    #[test]
    fn finger_groups_drop_the_dofs_shared_by_every_tip() {
        let hand = test_hand();
        let expected = vec![
            FingerGroup {
                tips: vec![0],
                dofs: vec![1, 2],
            },
            FingerGroup {
                tips: vec![1],
                dofs: vec![3],
            },
        ];
        assert_eq!(hand.finger_groups, expected);
    }

    #[test]
    fn a_tip_without_dofs_forms_its_own_empty_group() {
        let mut hand = test_hand();
        hand.fingertips.push(Fingertip {
            name: "palm".into(),
            link: 0,
            offset: Vector::zeros(),
            radius: 0.01,
        });
        hand.compute_finger_groups();
        assert_eq!(hand.finger_groups.len(), 2);
        // Nothing is shared by all three tips now, so the slide DOF stays with both fingers,
        // which joins them.
        assert_eq!(
            hand.finger_groups[0],
            FingerGroup {
                tips: vec![0, 1],
                dofs: vec![0, 1, 2, 3]
            }
        );
        assert_eq!(
            hand.finger_groups[1],
            FingerGroup {
                tips: vec![2],
                dofs: vec![]
            }
        );
    }

    #[test]
    fn forward_kinematics_applies_prismatic_revolute_and_mimic_motion() {
        let hand = test_hand();
        let q0 = [0.0; 4];
        let k0 = fk(&hand, &q0);
        // The prismatic DOF translates every finger along the world slide axis.
        let k1 = fk(&hand, &[0.03, 0.0, 0.0, 0.0]);
        let axis = k0.joint_axes[0];
        for t in 0..2 {
            let d = k1.tip_centres[t] - k0.tip_centres[t];
            assert!((d - axis * 0.03).norm() < 1e-12);
        }
        // The mimic joint turns by 0.7 θ + 0.1 about its axis through its origin.
        let q = [0.0, 0.0, 0.0, 0.4];
        let k = fk(&hand, &q);
        let relative = k.link_poses[5].inverse() * k.link_poses[6];
        let angle = relative.rotation.angle();
        assert!((angle - (0.7 * 0.4 + 0.1)).abs() < 1e-12);
        // Fixed joints carry their child rigidly.
        let fixed = k.link_poses[3].inverse() * k.link_poses[4];
        assert!((fixed.to_homogeneous() - hand.joints[3].origin.to_homogeneous()).norm() < 1e-12);
        // The root sits at the base pose.
        assert_eq!(k.link_poses[0], base());
    }

    /// World angular velocity from two orientations `h` apart on either side.
    fn angular_fd(plus: &Isometry, minus: &Isometry, h: f64) -> Vector {
        (plus.rotation * minus.rotation.inverse()).scaled_axis() / (2.0 * h)
    }

    pub(crate) fn assert_jacobians_match_finite_differences(hand: &HandModel, q: &[f64]) {
        let mut kin = fk(hand, q);
        hand.tip_jacobians(&mut kin);
        let h = 1e-6;
        for d in 0..hand.dof() {
            let (mut qp, mut qm) = (q.to_vec(), q.to_vec());
            qp[d] += h;
            qm[d] -= h;
            let (kp, km) = (fk(hand, &qp), fk(hand, &qm));
            for (k, tip) in hand.fingertips.iter().enumerate() {
                let linear = (kp.tip_centres[k] - km.tip_centres[k]) / (2.0 * h);
                let angular = angular_fd(&kp.link_poses[tip.link], &km.link_poses[tip.link], h);
                let col = kin.tip_jacobians[k].column(d);
                let err_v = (col.fixed_rows::<3>(0) - linear).norm();
                let err_w = (col.fixed_rows::<3>(3) - angular).norm();
                assert!(
                    err_v < 1e-7 && err_w < 1e-6,
                    "tip {k} dof {d}: {err_v} {err_w}"
                );
            }
        }
        for col in hand.dof()..MAX_DOF {
            assert!(kin.tip_jacobians[0].column(col).iter().all(|&x| x == 0.0));
        }
    }

    /// ½ Σ_links (m |v_com|² + ωᵀ I_world ω) from central differences of the link poses along θ̇.
    fn link_energy_fd(hand: &HandModel, q: &[f64], qdot: &[f64]) -> f64 {
        let h = 1e-6;
        let qp: Vec<f64> = q.iter().zip(qdot).map(|(a, b)| a + h * b).collect();
        let qm: Vec<f64> = q.iter().zip(qdot).map(|(a, b)| a - h * b).collect();
        let (k, kp, km) = (fk(hand, q), fk(hand, &qp), fk(hand, &qm));
        let mut energy = 0.0;
        for (l, link) in hand.links.iter().enumerate() {
            let com = Point::from(link.inertial.com);
            let v = (kp.link_poses[l] * com - km.link_poses[l] * com) / (2.0 * h);
            let w = angular_fd(&kp.link_poses[l], &km.link_poses[l], h);
            let r = k.link_poses[l].rotation.to_rotation_matrix();
            let i_world = r.matrix() * link.inertial.inertia * r.matrix().transpose();
            energy += 0.5 * (link.inertial.mass * v.norm_squared() + w.dot(&(i_world * w)));
        }
        energy
    }

    pub(crate) fn assert_mass_matrix_is_consistent(hand: &HandModel, q: &[f64], qdot: &[f64]) {
        let n = hand.dof();
        let mut kin = fk(hand, q);
        let mut m = DofMatrix::identity();
        hand.mass_matrix(&mut kin, &mut m);
        assert!((m - m.transpose()).amax() < 1e-15);
        assert!(m.cholesky().is_some(), "M is not positive definite");
        let mut rest = m;
        rest.view_mut((0, 0), (n, n)).fill_with_identity();
        assert_eq!(rest, DofMatrix::identity());
        let mut qd = nalgebra::SVector::<f64, MAX_DOF>::zeros();
        qd.as_mut_slice()[..n].copy_from_slice(qdot);
        let armature: f64 = (0..n)
            .map(|i| 0.5 * hand.armature[i] * qdot[i] * qdot[i])
            .sum();
        let energy = 0.5 * qd.dot(&(m * qd)) - armature;
        let expected = link_energy_fd(hand, q, qdot);
        assert!(
            (energy - expected).abs() < 1e-9 * (1.0 + expected),
            "{energy} vs {expected}"
        );
    }

    proptest! {
        #[test]
        fn tip_jacobians_match_finite_differences_of_forward_kinematics(u in prop::collection::vec(0.0..1.0f64, 10)) {
            let hand = test_hand();
            assert_jacobians_match_finite_differences(&hand, &angles_from_unit(&hand, &u));
            let glove = HandModel::glove10();
            assert_jacobians_match_finite_differences(&glove, &angles_from_unit(&glove, &u));
        }

        #[test]
        fn the_planned_kinematics_and_inertia_equal_the_general_forms(
            u in prop::collection::vec(0.0..1.0f64, MAX_DOF),
            rpy in prop::array::uniform3(-3.0..3.0f64),
        ) {
            let base = Isometry::from_parts(
                Vector::new(0.1, -0.2, 0.3).into(),
                Rotation::from_euler_angles(rpy[0], rpy[1], rpy[2]),
            );
            for name in crate::hand::BUILTIN_HANDS {
                let hand = crate::hand::builtin_hand(name).unwrap();
                let q = angles_from_unit(&hand, &u[..hand.dof()]);
                let (mut general, mut planned) = (Kinematics::default(), Kinematics::default());
                hand.forward_kinematics(&base, &q, &mut general);
                hand.forward_kinematics_planned(&hand.fk_plan(), &base, &q, &mut planned);
                for l in 0..hand.links.len() {
                    let (a, b) = (&general.link_poses[l], &planned.link_poses[l]);
                    prop_assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
                    prop_assert!(a.rotation.angle_to(&b.rotation) < 1e-12, "{name} link {l}");
                }
                for j in 0..hand.joints.len() {
                    prop_assert!((general.joint_axes[j] - planned.joint_axes[j]).norm() < 1e-12);
                    prop_assert_eq!(general.parent_joint[hand.joints[j].child], j);
                    prop_assert_eq!(planned.parent_joint[hand.joints[j].child], j);
                }
                for k in 0..hand.fingertips.len() {
                    prop_assert!((general.tip_centres[k] - planned.tip_centres[k]).norm() < 1e-12);
                }
                // The axial form of a link's inertia against the principal-axes sums.
                let plan = hand.mass_plan();
                let mut principal = plan;
                for a in principal.link_axes.iter_mut() {
                    if matches!(a, LinkAxes::Axial { .. }) {
                        *a = LinkAxes::Principal;
                    }
                }
                let (mut m1, mut m2) = (DofMatrix::zeros(), DofMatrix::zeros());
                hand.mass_matrix_planned(&plan, &mut planned, &mut m1);
                hand.mass_matrix_planned(&principal, &mut planned, &mut m2);
                let scale = m2.amax().max(1e-12);
                prop_assert!((m1 - m2).amax() <= 1e-12 * scale, "{name}: {}", (m1 - m2).amax());
            }
            // glove10's phalanges take the axial form.
            let glove = HandModel::glove10();
            let axial = glove.mass_plan().link_axes.iter().filter(|a| matches!(a, LinkAxes::Axial { .. })).count();
            prop_assert!(axial >= 12, "{axial}");
        }

        #[test]
        fn kinetic_energy_of_the_mass_matrix_equals_the_sum_of_link_energies(
            u in prop::collection::vec(0.0..1.0f64, 10),
            qdot in prop::collection::vec(-2.0..2.0f64, 10),
        ) {
            let hand = test_hand();
            assert_mass_matrix_is_consistent(&hand, &angles_from_unit(&hand, &u), &qdot[..4]);
            let glove = HandModel::glove10();
            assert_mass_matrix_is_consistent(&glove, &angles_from_unit(&glove, &u), &qdot);
        }
    }

    #[test]
    fn a_single_pendulum_has_the_analytic_inertia() {
        let (mass, length, com) = (0.5, 0.2, 0.08);
        let izz = mass * length * length / 12.0;
        let inertial = Inertial {
            mass,
            com: Vector::new(com, 0.0, 0.0),
            inertia: Mat3::from_diagonal(&Vector::new(1e-6, izz, izz)),
        };
        let hand = HandModel {
            name: "pendulum".into(),
            links: vec![
                Link {
                    name: "base".into(),
                    inertial: Inertial::default(),
                },
                Link {
                    name: "arm".into(),
                    inertial,
                },
            ],
            joints: vec![joint(
                "pivot",
                JointKind::Revolute,
                0,
                1,
                Isometry::identity(),
                Vector::z(),
                (-3.0, 3.0),
                JointDrive::Dof(0),
            )],
            root: 0,
            dof_names: vec!["pivot".into()],
            dof_lower: vec![-3.0],
            dof_upper: vec![3.0],
            torque_limit: vec![1.0],
            armature: vec![1e-4],
            fingertips: vec![Fingertip {
                name: "tip".into(),
                link: 1,
                offset: Vector::new(length, 0.0, 0.0),
                radius: 0.01,
            }],
            finger_groups: Vec::new(),
            contact_shapes: Vec::new(),
        };
        hand.validate().unwrap();
        for angle in [-1.0, 0.0, 0.7] {
            let mut kin = fk(&hand, &[angle]);
            let mut m = DofMatrix::identity();
            hand.mass_matrix(&mut kin, &mut m);
            let expected = izz + mass * com * com + 1e-4;
            assert!((m[(0, 0)] - expected).abs() < 1e-15);
        }
    }

    #[test]
    fn the_inertia_coupling_covers_every_nonzero_of_the_mass_matrix() {
        // The implicit finger step's envelope Cholesky relies on it: an entry of M(θ) outside
        // the coupling would be silently dropped.
        let mut hands = vec![HandModel::glove10(), test_hand()];
        for name in ["allegro", "barrett", "inspire", "gripper"] {
            hands.push(crate::hand::builtin::builtin_hand(name).expect(name));
        }
        for hand in &hands {
            let n = hand.dof();
            let coupling = hand.inertia_coupling();
            for seed in 0..5 {
                let u: Vec<f64> = (0..n)
                    .map(|d| ((d * 7 + seed * 13) % 11) as f64 / 10.0)
                    .collect();
                let q = angles_from_unit(hand, &u);
                let mut kin = Kinematics::default();
                hand.forward_kinematics(&base(), &q, &mut kin);
                let mut m = DofMatrix::zeros();
                hand.mass_matrix(&mut kin, &mut m);
                for a in 0..n {
                    assert!(
                        coupling[a] & (1 << a) != 0,
                        "{}: DOF {a} not coupled to itself",
                        hand.name
                    );
                    for b in 0..n {
                        if coupling[a] & (1 << b) == 0 {
                            assert_eq!(
                                m[(a, b)],
                                0.0,
                                "{}: M[{a}][{b}] outside the coupling",
                                hand.name
                            );
                        }
                        assert_eq!(coupling[a] & (1 << b) != 0, coupling[b] & (1 << a) != 0);
                    }
                }
            }
        }
    }

    #[test]
    fn a_stretched_finger_gives_finite_jacobians_and_inertia() {
        let glove = HandModel::glove10();
        let mut kin = fk(&glove, &[0.0; 10]);
        glove.tip_jacobians(&mut kin);
        let mut m = DofMatrix::identity();
        glove.mass_matrix(&mut kin, &mut m);
        assert!(kin
            .tip_jacobians
            .iter()
            .all(|j| j.iter().all(|x| x.is_finite())));
        assert!(m.iter().all(|x| x.is_finite()));
        assert!(m.cholesky().is_some());
    }

    proptest! {
        #[test]
        fn the_dof_cholesky_solve_inverts_the_mass_matrix(
            u in prop::collection::vec(0.0..1.0f64, 10),
            b in prop::collection::vec(-1.0..1.0f64, 10),
        ) {
            let glove = HandModel::glove10();
            let mut kin = fk(&glove, &angles_from_unit(&glove, &u));
            let mut m = DofMatrix::identity();
            glove.mass_matrix(&mut kin, &mut m);
            let mut rhs = DofVector::zeros();
            rhs.as_mut_slice()[..10].copy_from_slice(&b);
            let x = solve_dof_spd(&m, &rhs, 10).unwrap();
            let reference = m.cholesky().unwrap().solve(&rhs);
            prop_assert!((x - reference).amax() <= 1e-9 * reference.amax().max(1.0));
            prop_assert!(x.as_slice()[10..].iter().all(|&v| v == 0.0));
        }
    }

    #[test]
    fn the_dof_cholesky_solve_rejects_an_indefinite_block() {
        let mut a = DofMatrix::identity();
        a[(1, 1)] = -1.0;
        assert!(solve_dof_spd(&a, &DofVector::zeros(), 3).is_none());
        assert!(solve_dof_spd(&a, &DofVector::zeros(), 1).is_some());
        assert!(solve_dof_spd(&a, &DofVector::zeros(), MAX_DOF + 1).is_none());
    }

    #[test]
    fn a_sweep_range_is_finite_with_an_unlimited_side_read_as_two_radians() {
        let mut hand = test_hand();
        hand.dof_lower[0] = f64::NEG_INFINITY;
        hand.dof_upper[0] = f64::INFINITY;
        assert_eq!(hand.sweep_range(0), (-1.0, 1.0));
        hand.dof_upper[0] = 0.5;
        assert_eq!(hand.sweep_range(0), (-1.5, 0.5));
        hand.dof_lower[0] = 0.25;
        hand.dof_upper[0] = f64::INFINITY;
        assert_eq!(hand.sweep_range(0), (0.25, 2.25));
        hand.dof_upper[0] = 0.75;
        assert_eq!(hand.sweep_range(0), (0.25, 0.75));
    }

    #[test]
    fn clamping_handles_infinite_limits_and_nan() {
        let hand = test_hand();
        let mut q = [1.0, 100.0, f64::NAN, -9.0];
        hand.clamp_to_limits(&mut q);
        assert_eq!(q, [0.05, 100.0, 0.0, -0.5]);
    }
}
