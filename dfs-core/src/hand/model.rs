//! Hand model types, forward kinematics, Jacobians and joint-space inertia.

use crate::error::{DfsError, Result};
use crate::math::{Isometry, Mat3, Point, Rotation, UnitVector, Vector};
use nalgebra::SMatrix;

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

/// Bit set of DOFs (`MAX_DOF` ≤ 32).
type DofSet = u32;

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
        self.validate_groups()
    }

    /// Capacities and the lengths of the per-DOF vectors.
    fn validate_sizes(&self) -> Result<()> {
        let n = self.dof();
        if self.links.is_empty() || self.links.len() > MAX_LINKS {
            let reason = format!("{} links, expected 1..={MAX_LINKS}", self.links.len());
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
        if n > MAX_DOF {
            return Err(DfsError::invalid(
                "dof_names",
                format!("{n} DOFs > {MAX_DOF}"),
            ));
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
                driven |= 1 << d;
            }
        }
        if let Some(d) = (0..n).find(|&d| driven & (1 << d) == 0) {
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

    /// The DOFs that move `link`: those of every joint on the path from the root to it
    /// (mimic joints count for their source DOF). Needs a valid tree.
    pub fn dofs_moving_link(&self, link: usize) -> u32 {
        let mut set: DofSet = 0;
        let mut current = link;
        // A valid tree has at most `joints.len()` joints on any path.
        for _ in 0..=self.joints.len() {
            let Some(joint) = self.joints.iter().find(|j| j.child == current) else {
                break;
            };
            if let Some((d, _)) = joint.drive.dof_and_gain() {
                set |= 1 << d;
            }
            current = joint.parent;
        }
        set
    }

    /// Computes the finger groups from the tree (tips sharing non-common DOFs).
    ///
    /// The DOFs of tip k are those of the joints on the path from the root to its link.
    /// With two or more tips, the DOFs shared by every tip (the wrist) are dropped; tips whose
    /// remaining DOF sets intersect are united (transitively). A tip without DOFs forms its
    /// own group with no DOFs. Groups are ordered by their first tip; tips and DOFs ascend.
    pub fn compute_finger_groups(&mut self) {
        let nt = self.fingertips.len().min(MAX_TIPS);
        let mut sets = [0 as DofSet; MAX_TIPS];
        for (k, tip) in self.fingertips.iter().take(nt).enumerate() {
            sets[k] = self.dofs_moving_link(tip.link);
        }
        if nt >= 2 {
            let common = sets[..nt].iter().fold(DofSet::MAX, |acc, s| acc & s);
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
                    .filter(|&d| set & (1 << d) != 0)
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
        for (j, joint) in self.joints.iter().enumerate().take(MAX_LINKS) {
            let motion = joint.motion(joint.drive.value(q));
            let frame = kin.link_poses[joint.parent] * joint.origin * motion;
            kin.joint_frames[j] = frame;
            kin.joint_axes[j] = frame.rotation * joint.axis.into_inner();
            kin.link_poses[joint.child] = frame;
            kin.parent_joint[joint.child] = j;
        }
        for (k, tip) in self.fingertips.iter().enumerate().take(MAX_TIPS) {
            kin.tip_centres[k] = kin.link_poses[tip.link] * Point::from(tip.offset);
        }
    }

    /// Pose of fingertip `k` in the world frame: the orientation of its link, the position of
    /// the sphere centre (the fingertip frame T_k of the paper). Needs forward kinematics.
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
        let mut current = link;
        // At most one joint per link on the path to the root.
        for _ in 0..MAX_LINKS {
            let j = kin.parent_joint[current];
            if j == NO_JOINT || current == self.root {
                break;
            }
            let joint = &self.joints[j];
            if let Some((d, gain)) = joint.drive.dof_and_gain() {
                let a = kin.joint_axes[j];
                let (linear, angular) = match joint.kind {
                    JointKind::Prismatic => (a, Vector::zeros()),
                    JointKind::Fixed => (Vector::zeros(), Vector::zeros()),
                    _ => (
                        a.cross(&(point - Point::from(kin.joint_frames[j].translation.vector))),
                        a,
                    ),
                };
                let mut col = jac.column_mut(d);
                col.fixed_rows_mut::<3>(0).axpy(gain, &linear, 1.0);
                col.fixed_rows_mut::<3>(3).axpy(gain, &angular, 1.0);
            }
            current = joint.parent;
        }
    }

    /// Fingertip Jacobians (world frame, at each tip centre) from the joint frames that
    /// [`forward_kinematics`](Self::forward_kinematics) computed. Allocation-free.
    pub fn tip_jacobians(&self, kin: &mut Kinematics) {
        for (k, tip) in self.fingertips.iter().enumerate().take(MAX_TIPS) {
            let mut jac = TipJacobian::zeros();
            self.point_jacobian(kin, tip.link, &kin.tip_centres[k], &mut jac);
            kin.tip_jacobians[k] = jac;
        }
    }

    /// Joint-space inertia M(θ) (top-left `dof × dof` block of `m`, the rest identity) from
    /// the link inertials and the armature, for the kinematics in `kin`. Allocation-free.
    ///
    /// M = Σ_links (J_vᵀ m J_v + J_ωᵀ R I Rᵀ J_ω) + diag(armature), with J_v the Jacobian of
    /// the link's centre of mass and J_ω its angular Jacobian (world frame).
    pub fn mass_matrix(&self, kin: &Kinematics, m: &mut DofMatrix) {
        let n = self.dof().min(MAX_DOF);
        m.fill_with_identity();
        m.view_mut((0, 0), (n, n)).fill(0.0);
        let mut jac = TipJacobian::zeros();
        for (l, link) in self.links.iter().enumerate() {
            let inertial = &link.inertial;
            if l == self.root || (inertial.mass == 0.0 && inertial.inertia == Mat3::zeros()) {
                continue;
            }
            let pose = &kin.link_poses[l];
            let com = pose * Point::from(inertial.com);
            self.point_jacobian(kin, l, &com, &mut jac);
            let r = pose.rotation.to_rotation_matrix();
            let inertia_world = r.matrix() * inertial.inertia * r.matrix().transpose();
            add_link_inertia(&jac, inertial.mass, &inertia_world, n, m);
        }
        for (i, a) in self.armature.iter().enumerate().take(n) {
            m[(i, i)] += a;
        }
    }
}

/// Adds `J_vᵀ m J_v + J_ωᵀ I J_ω` of one link to the top-left `n × n` block of `m`.
fn add_link_inertia(
    jac: &TipJacobian,
    mass: f64,
    inertia_world: &Mat3,
    n: usize,
    m: &mut DofMatrix,
) {
    for i in 0..n {
        let vi = jac.fixed_view::<3, 1>(0, i);
        let wi = jac.fixed_view::<3, 1>(3, i);
        if vi.iter().chain(wi.iter()).all(|&x| x == 0.0) {
            continue;
        }
        let iwi = inertia_world * wi;
        for j in i..n {
            let vj = jac.fixed_view::<3, 1>(0, j);
            let wj = jac.fixed_view::<3, 1>(3, j);
            let e = mass * vi.dot(&vj) + iwi.dot(&wj);
            m[(i, j)] += e;
            if j != i {
                m[(j, i)] += e;
            }
        }
    }
}
