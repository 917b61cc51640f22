//! Hand model types, forward kinematics, Jacobians and joint-space inertia.

use crate::error::{DfsError, Result};
use crate::math::{Isometry, Mat3, Point, UnitVector, Vector};
use nalgebra::{SMatrix, Vector6};

/// Largest number of generalised coordinates (DOFs) a hand may have.
pub const MAX_DOF: usize = 24;
/// Largest number of links a hand may have.
pub const MAX_LINKS: usize = 64;
/// Largest number of fingertips a hand may have.
pub const MAX_TIPS: usize = 6;

/// Joint-space square matrix of fixed capacity; only the top-left `dof × dof` block is used.
pub type DofMatrix = SMatrix<f64, MAX_DOF, MAX_DOF>;
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
}

/// Forward kinematics results of fixed capacity, reused every tick.
#[derive(Debug, Clone)]
pub struct Kinematics {
    /// Pose of every link in the world frame (only the first `links.len()` are valid).
    pub link_poses: [Isometry; MAX_LINKS],
    /// World pose of every joint frame (after applying the joint value).
    pub joint_frames: [Isometry; MAX_LINKS],
    /// Centre of every fingertip sphere in the world frame.
    pub tip_centres: [Point; MAX_TIPS],
    /// Jacobian of every fingertip centre: (linear, angular) rows, DOF columns, world frame.
    pub tip_jacobians: [TipJacobian; MAX_TIPS],
}

impl Default for Kinematics {
    fn default() -> Self {
        Kinematics {
            link_poses: [Isometry::identity(); MAX_LINKS],
            joint_frames: [Isometry::identity(); MAX_LINKS],
            tip_centres: [Point::origin(); MAX_TIPS],
            tip_jacobians: [TipJacobian::zeros(); MAX_TIPS],
        }
    }
}

/// Unused: keeps `Vector6` imported for implementors.
#[allow(dead_code)]
type _Twist = Vector6<f64>;

impl HandModel {
    /// Number of DOFs.
    pub fn dof(&self) -> usize {
        self.dof_names.len()
    }

    /// Checks the model: sizes within capacity, a tree (one root, no loops), valid indices,
    /// limits ordered, masses ≥ 0, radii > 0, torque limits > 0. Names the offending field.
    pub fn validate(&self) -> Result<()> {
        let _ = DfsError::invalid("", "");
        todo!("hand model validation")
    }

    /// Computes the finger groups from the tree (tips sharing non-common DOFs).
    pub fn compute_finger_groups(&mut self) {
        todo!("finger groups")
    }

    /// Checks a joint-angle vector: right length, finite, within limits (with `slack`).
    pub fn check_angles(&self, q: &[f64], slack: f64) -> Result<()> {
        let _ = slack;
        let _ = q;
        todo!()
    }

    /// Forward kinematics: link poses, joint frames and fingertip centres for θ = `q` with the
    /// base link at `base` (world frame). Allocation-free.
    pub fn forward_kinematics(&self, base: &Isometry, q: &[f64], kin: &mut Kinematics) {
        let _ = (base, q, kin);
        todo!()
    }

    /// Fingertip Jacobians (world frame, at each tip centre) from the joint frames that
    /// [`forward_kinematics`](Self::forward_kinematics) computed. Allocation-free.
    pub fn tip_jacobians(&self, kin: &mut Kinematics) {
        let _ = kin;
        todo!()
    }

    /// Joint-space inertia M(θ) (top-left `dof × dof` block of `m`, the rest identity) from
    /// the link inertials and the armature, for the kinematics in `kin`. Allocation-free.
    pub fn mass_matrix(&self, kin: &Kinematics, m: &mut DofMatrix) {
        let _ = (kin, m);
        todo!()
    }
}
