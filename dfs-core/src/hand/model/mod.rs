//! The hand model: its types (links, joints, fingertips, finger groups) and the fixed-size
//! joint-space storage, here; validation ([`validate`](HandModel::validate)) in `validate`;
//! the tree's topology (which DOFs move what, finger groups, joint limits) in `topology`;
//! forward kinematics and Jacobians with their per-hand plan in `kinematics`; the
//! joint-space inertia M(θ) by the composite rigid-body algorithm, with its plan, in
//! `dynamics`.

use crate::error::{DfsError, Result};
use crate::math::{skew, Isometry, Mat3, Mat6, Point, Rotation, UnitVector, Vector};
use nalgebra::SMatrix;

mod dynamics;
mod kinematics;
mod topology;
mod validate;

pub use dynamics::{solve_dof_spd, MassPlan, SpatialInertia};
pub use kinematics::FkPlan;

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

impl HandModel {
    /// Number of DOFs.
    pub fn dof(&self) -> usize {
        self.dof_names.len()
    }
}

#[cfg(test)]
pub(crate) mod tests;
