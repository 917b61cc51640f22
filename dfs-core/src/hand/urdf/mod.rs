//! Robot hands from URDF plus a hand spec: [`HandSpec`] and [`HandModel::from_urdf`].
//!
//! A URDF gives the kinematic tree and the inertials; the hand spec adds what a URDF does not
//! say: which links carry the fingertips (a contact sphere at an offset, with a radius), the
//! joint torque limits (URDF `effort` values are often placeholders: 10 N·m on the Allegro, 0 on
//! the Barrett), which fingertip is the thumb, and optionally the base link and the armature.
//!
//! # What is read, and the defaults
//!
//! * Joints `revolute` (limited), `continuous` (unlimited), `prismatic` (limited) and `fixed`;
//!   `mimic` joints become [`JointDrive::Mimic`](crate::hand::JointDrive::Mimic) of their
//!   source joint (chains of mimics are composed). `floating`, `planar` and `spherical` joints
//!   are refused: a hand is a tree of one-DOF joints. A revolute or prismatic joint whose
//!   lower and upper limits are equal is refused (URDF requires `<limit>` for them; a missing
//!   one reads as 0, 0).
//! * A DOF's limits are its joint's limits intersected with those of every joint that mimics
//!   it, mapped back through the multiplier and offset, so no mimic joint leaves its range.
//! * Inertials: mass, centre of mass and inertia (rotated by the inertial origin's rpy into the
//!   link frame). A link without `<inertial>` is massless (URDF semantics, as in Pinocchio and
//!   MuJoCo's compiler with `inertiafromgeom="false"`); the armature that every DOF gets
//!   ([`HandSpec::armature`], default [`DEFAULT_ARMATURE`]) keeps the joint-space inertia
//!   positive definite. Negative masses and inertias that are not positive semi-definite are
//!   refused, naming the link.
//! * Geometry (visual and collision meshes) is not needed and ignored.
//! * The tree: exactly one root, no link with two parents, no loops; every error names the
//!   link or joint. A spec's `base_link` makes that link's subtree the hand (the links above it
//!   are dropped).

mod joints;
mod links;
mod text;
mod tree;

pub(super) use links::pose;
pub use text::check_urdf_text;

use super::{Fingertip, HandModel, MAX_TIPS};
use crate::error::{DfsError, Result};
use crate::math::Vector;
use std::collections::BTreeMap;
use tree::Tree;

/// Armature (reflected rotor inertia, kg·m² or kg) added to every DOF when the spec gives none.
/// Small beside a geared robot finger's reflected inertia (around 10⁻³ kg·m² for the Allegro's
/// 1:369 gears), large enough to keep massless links and 1 kHz explicit control well posed.
pub const DEFAULT_ARMATURE: f64 = 1e-4;

/// Largest length in a hand (m): a joint origin's distance from its parent link, a fingertip's
/// offset and radius. Far beyond any hand, and room for a URDF that mounts its hand on an arm
/// or a stand; larger values (1e300) overflowed the kinematics into NaN.
pub const MAX_HAND_EXTENT: f64 = 10.0;

/// Largest URDF text accepted (bytes): 4 MiB. The URDFs of real hands are 10-60 kB (meshes are
/// separate files); the parser holds the text several times over, so the bound keeps a hand
/// upload's memory and parse time small.
pub const MAX_URDF_BYTES: usize = 4 << 20;

/// Deepest element nesting accepted in a URDF: 64. A real URDF nests about 5 deep
/// (`robot` > `link` > `visual` > `geometry` > `mesh`); the XML parser behind `urdf-rs` recurses
/// once per level, and a few thousand levels overflow a thread's stack (a process abort, not
/// an error), so the depth is checked before the text reaches it.
pub const MAX_URDF_DEPTH: usize = 64;

/// One fingertip of a hand spec: a contact sphere fixed to a URDF link.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "a fingertip {\"link\": ..., \"offset\": [x, y, z], \"radius\": ...}"
)]
pub struct FingertipSpec {
    /// Name of the fingertip (for example `thumb`); default the link's name.
    #[serde(default)]
    pub name: Option<String>,
    /// URDF link the contact sphere is fixed to.
    pub link: String,
    /// Centre of the contact sphere in the link frame (m).
    pub offset: [f64; 3],
    /// Radius of the contact sphere (m), > 0.
    #[cfg_attr(feature = "utoipa", schema(exclusive_minimum = 0.0))]
    pub radius: f64,
}

crate::object_only!(
    FingertipSpec,
    "a fingertip {\"link\": ..., \"offset\": [x, y, z], \"radius\": ...}",
    serialize
);
crate::object_only!(
    HandSpec,
    "a hand spec: a JSON object {\"name\": ..., \"urdf\": ..., \"fingertips\": [...], ...}",
    serialize
);

/// A hand spec: what the URDF does not say. JSON:
///
/// ```json
/// { "name": "allegro", "urdf": "allegro_hand_right.urdf",
///   "fingertips": [ { "name": "thumb", "link": "link_15.0_tip", "offset": [0, 0, -0.01],
///                     "radius": 0.012 }, ... ],
///   "thumb": "thumb", "torque_limit": 0.7, "joint_torque_limits": { "joint_12.0": 0.7 },
///   "base_link": "base_link", "armature": 0.0001 }
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "a hand spec: a JSON object {\"name\": ..., \"urdf\": ..., \"fingertips\": [...], ...}"
)]
pub struct HandSpec {
    /// Name of the hand model.
    pub name: String,
    /// The URDF file (a path relative to the spec file; for built-in hands the embedded file's
    /// name). dfs-core never opens it: callers read it and pass the text.
    pub urdf: String,
    /// The fingertips, 1 to 6 (`MAX_TIPS`).
    #[cfg_attr(feature = "utoipa", schema(min_items = 1, max_items = 6))]
    pub fingertips: Vec<FingertipSpec>,
    /// Torque (prismatic: force) limit of every DOF without its own entry (N·m or N), > 0.
    #[cfg_attr(feature = "utoipa", schema(exclusive_minimum = 0.0))]
    pub torque_limit: f64,
    /// Per-joint torque limits (N·m or N) by the name of the joint that is the DOF.
    #[serde(default)]
    pub joint_torque_limits: BTreeMap<String, f64>,
    /// The hand's base link; default the URDF's root. Links outside its subtree are dropped.
    #[serde(default)]
    pub base_link: Option<String>,
    /// Name of the fingertip that opposes the others (the thumb); default the fingertip named
    /// `thumb`, else the first fingertip.
    #[serde(default)]
    pub thumb: Option<String>,
    /// Armature added to every DOF (kg·m² or kg), ≥ 0; default 1e-4 (`DEFAULT_ARMATURE`).
    #[serde(default)]
    #[cfg_attr(feature = "utoipa", schema(minimum = 0.0))]
    pub armature: Option<f64>,
}

impl HandSpec {
    /// Index of the thumb among the fingertips (see [`HandSpec::thumb`]).
    pub fn thumb_index(&self) -> usize {
        let name_of = |t: &FingertipSpec| t.name.clone().unwrap_or_else(|| t.link.clone());
        let wanted = self.thumb.clone().unwrap_or_else(|| "thumb".to_owned());
        self.fingertips
            .iter()
            .position(|t| name_of(t) == wanted)
            .unwrap_or(0)
    }

    /// Checks the spec's own fields (not those that need the URDF); the error names the field.
    pub fn validate(&self) -> Result<()> {
        if self.name.trim().is_empty() {
            return Err(DfsError::invalid("name", "must not be empty"));
        }
        if self.fingertips.is_empty() || self.fingertips.len() > MAX_TIPS {
            let reason = format!(
                "{} fingertips, expected 1..={MAX_TIPS}",
                self.fingertips.len()
            );
            return Err(DfsError::invalid("fingertips", reason));
        }
        for (i, t) in self.fingertips.iter().enumerate() {
            let offset = Vector::from(t.offset);
            if !(offset.iter().all(|v| v.is_finite()) && offset.norm() <= MAX_HAND_EXTENT) {
                return Err(DfsError::invalid(
                    format!("fingertips[{i}].offset"),
                    format!("must be finite and within {MAX_HAND_EXTENT} m of the link"),
                ));
            }
            if !(t.radius.is_finite() && t.radius > 0.0 && t.radius <= MAX_HAND_EXTENT) {
                let reason = format!(
                    "radius {} must be a finite number in (0, {MAX_HAND_EXTENT}] m",
                    t.radius
                );
                return Err(DfsError::invalid(format!("fingertips[{i}].radius"), reason));
            }
        }
        if !(self.torque_limit.is_finite() && self.torque_limit > 0.0) {
            let reason = format!("{} must be a finite number > 0", self.torque_limit);
            return Err(DfsError::invalid("torque_limit", reason));
        }
        for (joint, &t) in &self.joint_torque_limits {
            if !(t.is_finite() && t > 0.0) {
                let reason = format!("{t} must be a finite number > 0");
                return Err(DfsError::invalid(
                    format!("joint_torque_limits.{joint}"),
                    reason,
                ));
            }
        }
        if let Some(a) = self.armature {
            if !(a.is_finite() && a >= 0.0) {
                let reason = format!("{a} must be a finite number ≥ 0");
                return Err(DfsError::invalid("armature", reason));
            }
        }
        if let Some(thumb) = &self.thumb {
            let found = self
                .fingertips
                .iter()
                .any(|t| t.name.as_ref().unwrap_or(&t.link) == thumb);
            if !found {
                return Err(DfsError::invalid(
                    "thumb",
                    format!("no fingertip named {thumb:?}"),
                ));
            }
        }
        Ok(())
    }
}

impl HandModel {
    /// Builds a hand from URDF text and a hand spec. Pure: the caller reads the files.
    ///
    /// Errors ([`DfsError::Invalid`]) name the problem: a URDF that does not parse, a
    /// kinematic loop, several roots, an unknown link or joint, an unsupported joint type,
    /// a negative mass or radius, more than [`MAX_HAND_DOF`](super::MAX_HAND_DOF) DOFs or
    /// [`MAX_HAND_LINKS`](super::MAX_HAND_LINKS) links,
    /// a text over [`MAX_URDF_BYTES`] or nesting elements deeper than [`MAX_URDF_DEPTH`].
    pub fn from_urdf(urdf: &str, spec: &HandSpec) -> Result<HandModel> {
        spec.validate()?;
        check_urdf_text(urdf)?;
        let robot = tree::parse(urdf)?;
        let tree = Tree::new(&robot, spec)?;
        let hand_links = links::hand_links(&robot, &tree)?;
        let mut dofs = joints::dofs(&robot, &tree)?;
        let hand_joints = joints::hand_joints(&robot, &tree, &mut dofs)?;
        for name in spec.joint_torque_limits.keys() {
            if !dofs.of.contains_key(name) {
                return Err(DfsError::invalid(
                    format!("joint_torque_limits.{name}"),
                    "no such independent (non-mimic, moving) joint in the hand",
                ));
            }
        }
        let torque_limit = dofs
            .names
            .iter()
            .map(|n| {
                spec.joint_torque_limits
                    .get(n)
                    .copied()
                    .unwrap_or(spec.torque_limit)
            })
            .collect();
        let armature = vec![spec.armature.unwrap_or(DEFAULT_ARMATURE); dofs.names.len()];
        let mut fingertips = Vec::with_capacity(spec.fingertips.len());
        for (i, t) in spec.fingertips.iter().enumerate() {
            let link = tree.hand_link(t.link.as_str()).ok_or_else(|| {
                DfsError::invalid(
                    format!("fingertips[{i}].link"),
                    format!("no link named {:?} in the hand", t.link),
                )
            })?;
            fingertips.push(Fingertip {
                name: t.name.clone().unwrap_or_else(|| t.link.clone()),
                link,
                offset: Vector::from(t.offset),
                radius: t.radius,
            });
        }
        let mut hand = HandModel {
            name: spec.name.clone(),
            links: hand_links,
            joints: hand_joints,
            root: 0,
            dof_names: dofs.names,
            dof_lower: dofs.lower,
            dof_upper: dofs.upper,
            torque_limit,
            armature,
            fingertips,
            finger_groups: Vec::new(),
            contact_shapes: Vec::new(),
        };
        hand.compute_finger_groups();
        hand.validate()?;
        Ok(hand)
    }
}

#[cfg(test)]
mod tests;
