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
//!   `mimic` joints become [`JointDrive::Mimic`] of their source joint (chains of mimics are
//!   composed). `floating`, `planar` and `spherical` joints are refused: a hand is a tree of
//!   one-DOF joints. A revolute or prismatic joint whose lower and upper limits are equal is
//!   refused (URDF requires `<limit>` for them; a missing one reads as 0, 0).
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

use std::collections::BTreeMap;

use super::{Fingertip, HandModel, Inertial, Joint, JointDrive, JointKind, Link};
use super::{MAX_HAND_DOF, MAX_HAND_LINKS, MAX_TIPS};
use crate::error::{DfsError, Result};
use crate::math::{Isometry, Mat3, Rotation, UnitVector, Vector};

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

/// Checks a URDF text's size ([`MAX_URDF_BYTES`]) and element nesting ([`MAX_URDF_DEPTH`])
/// before it is parsed, in one pass over the bytes with no recursion. The scan follows the
/// XML tokenizer of `urdf-rs` (RustyXML): comments end at the first `-->`, CDATA at the first
/// `]]>`, processing instructions at the first `>` after a `?`, a `<!DOCTYPE` and an end tag at
/// their first `>`, and a start tag at its first `>` outside an attribute value (a value is
/// quoted after `=`); a start tag ending `/>` is empty. Where it may end a construct earlier
/// than that parser, it only counts more depth. A malformed text within the bounds is left
/// to the parser to report.
pub fn check_urdf_text(urdf: &str) -> Result<()> {
    if urdf.len() > MAX_URDF_BYTES {
        return Err(DfsError::invalid(
            "urdf",
            format!(
                "the URDF is {} bytes; at most {MAX_URDF_BYTES} ({} MiB) are accepted",
                urdf.len(),
                MAX_URDF_BYTES >> 20
            ),
        ));
    }
    let deepest = nesting_depth(urdf.as_bytes());
    if deepest > MAX_URDF_DEPTH {
        return Err(DfsError::invalid(
            "urdf",
            format!(
                "the URDF nests elements {deepest} deep; at most {MAX_URDF_DEPTH} are accepted"
            ),
        ));
    }
    Ok(())
}

/// The deepest element nesting of an XML text, scanned as [`check_urdf_text`] describes.
fn nesting_depth(b: &[u8]) -> usize {
    // Index of the first occurrence of `pat` at or after `from` (the end when there is none).
    let find = |from: usize, pat: &[u8]| -> usize {
        b.get(from..)
            .and_then(|rest| rest.windows(pat.len()).position(|w| w == pat))
            .map_or(b.len(), |p| from + p)
    };
    let mut depth = 0usize;
    // The deepest nesting, reported whole when it is over the limit.
    let mut deepest = 0usize;
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        let rest = &b[i..];
        if rest.starts_with(b"<!--") {
            i = find(i + 4, b"-->") + 3;
        } else if rest.starts_with(b"<![CDATA[") {
            i = find(i + 9, b"]]>") + 3;
        } else if rest.starts_with(b"<?") {
            let q = find(i + 2, b"?");
            i = find(q, b">") + 1;
        } else if rest.starts_with(b"<!") || rest.starts_with(b"</") {
            if rest.starts_with(b"</") {
                depth = depth.saturating_sub(1);
            }
            i = find(i + 2, b">") + 1;
        } else {
            // A start tag: its name, then attributes `name = "value"`, until `>` or `/>`.
            depth += 1;
            deepest = deepest.max(depth);
            let (end, empty) = start_tag_end(b, i + 1);
            if empty {
                depth -= 1;
            }
            i = end + 1;
        }
    }
    deepest
}

/// Where the start tag whose name begins at `from` ends (the index of its `>`, or the text's
/// end) and whether it is empty (`/>`): the states of RustyXML's tokenizer, in which a quote
/// opens an attribute value only after an attribute name and `=`.
fn start_tag_end(b: &[u8], from: usize) -> (usize, bool) {
    #[derive(PartialEq)]
    enum State {
        Name,
        InTag,
        AttrName,
        ExpectValue,
    }
    let mut state = State::Name;
    let mut j = from;
    while j < b.len() {
        let c = b[j];
        match (&state, c) {
            (State::Name | State::InTag, b'>') => return (j, false),
            (State::Name | State::InTag, b'/') if b.get(j + 1) == Some(&b'>') => {
                return (j + 1, true)
            }
            (State::Name, c) if c.is_ascii_whitespace() => state = State::InTag,
            (State::InTag, c) if !c.is_ascii_whitespace() && c != b'/' => state = State::AttrName,
            (State::AttrName, b'=') => state = State::ExpectValue,
            (State::ExpectValue, b'"' | b'\'') => {
                // The value runs to the same quote.
                j = b[j + 1..]
                    .iter()
                    .position(|&q| q == c)
                    .map_or(b.len(), |p| j + 1 + p);
                state = State::InTag;
            }
            (State::ExpectValue, c) if !c.is_ascii_whitespace() => {
                // Malformed (the parser refuses it): read on as a tag.
                state = State::InTag;
                continue;
            }
            (State::AttrName, b'>') => return (j, false),
            _ => {}
        }
        j += 1;
    }
    (b.len(), false)
}

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

/// An isometry from a URDF origin (xyz, fixed-axis roll-pitch-yaw).
pub(super) fn pose(p: &urdf_rs::Pose) -> Isometry {
    let [x, y, z] = p.xyz.0;
    let [r, pi, ya] = p.rpy.0;
    Isometry::from_parts(
        Vector::new(x, y, z).into(),
        Rotation::from_euler_angles(r, pi, ya),
    )
}

/// The link's mass properties in the link frame; the field name of an error names the link.
fn inertial(link: &urdf_rs::Link) -> Result<Inertial> {
    let field = || format!("urdf link {:?} inertial", link.name);
    let m = link.inertial.mass.value;
    // A hand's link, not a building: the grasp file's object bound (10⁴ kg) is far above any.
    let max = crate::spec::MASS_RANGE.1;
    if !(m.is_finite() && (0.0..=max).contains(&m)) {
        return Err(DfsError::invalid(
            field(),
            format!("mass {m} kg must be finite, ≥ 0 and at most {max} kg"),
        ));
    }
    let i = &link.inertial.inertia;
    let local = Mat3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    if !local.iter().all(|v| v.is_finite()) {
        return Err(DfsError::invalid(field(), "inertia is not finite"));
    }
    let eig = local.symmetric_eigenvalues();
    let scale = eig.iter().fold(0.0_f64, |a, b| a.max(b.abs()));
    if eig.iter().any(|&e| e < -1e-9 * scale.max(1e-12)) {
        return Err(DfsError::invalid(
            field(),
            format!(
                "inertia is not positive semi-definite (eigenvalues {:.3e}, {:.3e}, {:.3e})",
                eig[0], eig[1], eig[2]
            ),
        ));
    }
    let origin = pose(&link.inertial.origin);
    let r = origin.rotation.to_rotation_matrix();
    Ok(Inertial {
        mass: m,
        com: origin.translation.vector,
        inertia: r.matrix() * local * r.matrix().transpose(),
    })
}

/// The source DOF joint of a (possibly chained) mimic: (source joint name, multiplier, offset).
fn resolve_mimic(
    by_name: &BTreeMap<&str, &urdf_rs::Joint>,
    joint: &urdf_rs::Joint,
) -> Result<(String, f64, f64)> {
    let (mut mult, mut off) = (1.0, 0.0);
    let mut current = joint;
    for _ in 0..=by_name.len() {
        let Some(m) = &current.mimic else {
            return Ok((current.name.clone(), mult, off));
        };
        let Some(source) = by_name.get(m.joint.as_str()) else {
            return Err(DfsError::invalid(
                format!("urdf joint {:?} mimic", joint.name),
                format!("mimics joint {:?}, which does not exist", m.joint),
            ));
        };
        // value = a (b θ + c) + d
        let (a, d) = (m.multiplier.unwrap_or(1.0), m.offset.unwrap_or(0.0));
        if !(a.is_finite() && d.is_finite()) {
            return Err(DfsError::invalid(
                format!("urdf joint {:?} mimic", joint.name),
                "multiplier and offset must be finite",
            ));
        }
        off = a * off + d;
        mult *= a;
        if matches!(source.joint_type, urdf_rs::JointType::Fixed) {
            return Err(DfsError::invalid(
                format!("urdf joint {:?} mimic", joint.name),
                format!("mimics the fixed joint {:?}", source.name),
            ));
        }
        current = source;
    }
    Err(DfsError::invalid(
        format!("urdf joint {:?} mimic", joint.name),
        "mimic joints form a cycle",
    ))
}

impl HandModel {
    /// Builds a hand from URDF text and a hand spec. Pure: the caller reads the files.
    ///
    /// Errors ([`DfsError::Invalid`]) name the problem: a URDF that does not parse, a
    /// kinematic loop, several roots, an unknown link or joint, an unsupported joint type,
    /// a negative mass or radius, more than [`MAX_HAND_DOF`] DOFs or [`MAX_HAND_LINKS`] links,
    /// a text over [`MAX_URDF_BYTES`] or nesting elements deeper than [`MAX_URDF_DEPTH`].
    pub fn from_urdf(urdf: &str, spec: &HandSpec) -> Result<HandModel> {
        spec.validate()?;
        check_urdf_text(urdf)?;
        let robot = urdf_rs::read_from_string(urdf).map_err(|e| {
            let e = e.to_string();
            let e = e.strip_prefix("custom: ").unwrap_or(&e);
            // urdf-rs names the missing attribute but not the element: say where it belongs.
            let hint = if e.contains("`velocity`") || e.contains("`effort`") {
                " (every joint <limit> needs both effort and velocity, as URDF requires)"
            } else {
                ""
            };
            DfsError::invalid("urdf", format!("does not parse: {e}{hint}"))
        })?;
        let links = &robot.links;
        if links.is_empty() {
            return Err(DfsError::invalid(
                "urdf",
                format!(
                    "robot {:?} has no links: a hand needs at least its base link",
                    robot.name
                ),
            ));
        }
        let mut link_index: BTreeMap<&str, usize> = BTreeMap::new();
        for (i, l) in links.iter().enumerate() {
            if link_index.insert(l.name.as_str(), i).is_some() {
                return Err(DfsError::invalid(
                    format!("urdf link {:?}", l.name),
                    "duplicate link name",
                ));
            }
        }
        let mut by_name: BTreeMap<&str, &urdf_rs::Joint> = BTreeMap::new();
        // Per link: the joint whose child it is.
        let mut parent_of: Vec<Option<usize>> = vec![None; links.len()];
        for (j, joint) in robot.joints.iter().enumerate() {
            if by_name.insert(joint.name.as_str(), joint).is_some() {
                return Err(DfsError::invalid(
                    format!("urdf joint {:?}", joint.name),
                    "duplicate joint name",
                ));
            }
            let field = || format!("urdf joint {:?}", joint.name);
            match joint.joint_type {
                urdf_rs::JointType::Revolute
                | urdf_rs::JointType::Continuous
                | urdf_rs::JointType::Prismatic
                | urdf_rs::JointType::Fixed => {}
                ref other => {
                    return Err(DfsError::invalid(
                        field(),
                        format!(
                            "type {other:?} is not supported (a hand is a tree of revolute, \
                             continuous, prismatic and fixed joints)"
                        ),
                    ))
                }
            }
            let lookup = |name: &str, role: &str| {
                link_index.get(name).copied().ok_or_else(|| {
                    DfsError::invalid(field(), format!("{role} link {name:?} does not exist"))
                })
            };
            lookup(&joint.parent.link, "parent")?;
            let child = lookup(&joint.child.link, "child")?;
            if let Some(other) = parent_of[child] {
                return Err(DfsError::invalid(
                    format!("urdf link {:?}", joint.child.link),
                    format!(
                        "is the child of two joints ({:?} and {:?}): a kinematic loop",
                        robot.joints[other].name, joint.name
                    ),
                ));
            }
            parent_of[child] = Some(j);
        }
        let roots: Vec<&str> = (0..links.len())
            .filter(|&l| parent_of[l].is_none())
            .map(|l| links[l].name.as_str())
            .collect();
        if roots.is_empty() {
            return Err(DfsError::invalid(
                "urdf",
                "every link has a parent joint: the joints form a kinematic loop",
            ));
        }
        if roots.len() > 1 {
            return Err(DfsError::invalid(
                "urdf",
                format!(
                    "several root links ({}): a hand is one tree",
                    roots.join(", ")
                ),
            ));
        }
        // Links reached from the root; a link with a parent that is not reached is on a loop.
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); links.len()];
        for (j, joint) in robot.joints.iter().enumerate() {
            children[link_index[joint.parent.link.as_str()]].push(j);
        }
        let root = link_index[roots[0]];
        let base = match &spec.base_link {
            Some(name) => *link_index.get(name.as_str()).ok_or_else(|| {
                DfsError::invalid("base_link", format!("no link named {name:?} in the URDF"))
            })?,
            None => root,
        };
        let mut reached = vec![false; links.len()];
        let mut stack = vec![root];
        while let Some(l) = stack.pop() {
            reached[l] = true;
            stack.extend(
                children[l]
                    .iter()
                    .map(|&j| link_index[robot.joints[j].child.link.as_str()]),
            );
        }
        if let Some(l) = (0..links.len()).find(|&l| !reached[l]) {
            return Err(DfsError::invalid(
                format!("urdf link {:?}", links[l].name),
                "is not connected to the root: its joints form a kinematic loop",
            ));
        }
        // Breadth-first order of the base's subtree: links and joints.
        let mut order_links = vec![base];
        let mut order_joints: Vec<usize> = Vec::new();
        let mut head = 0;
        while head < order_links.len() {
            let l = order_links[head];
            head += 1;
            for &j in &children[l] {
                order_joints.push(j);
                order_links.push(link_index[robot.joints[j].child.link.as_str()]);
            }
        }
        if order_links.len() > MAX_HAND_LINKS {
            let reason = format!(
                "the hand has {} links; at most {MAX_HAND_LINKS} are accepted",
                order_links.len()
            );
            return Err(DfsError::invalid("urdf", reason));
        }
        let new_index: BTreeMap<usize, usize> = order_links
            .iter()
            .enumerate()
            .map(|(new, &old)| (old, new))
            .collect();
        let mut hand_links = Vec::with_capacity(order_links.len());
        for &l in &order_links {
            hand_links.push(Link {
                name: links[l].name.clone(),
                inertial: inertial(&links[l])?,
            });
        }
        // DOFs: the moving joints that mimic nothing, in tree order.
        let mut dof_of: BTreeMap<String, usize> = BTreeMap::new();
        let mut dof_names = Vec::new();
        let mut dof_lower = Vec::new();
        let mut dof_upper = Vec::new();
        let limits = |joint: &urdf_rs::Joint| -> Result<(f64, f64)> {
            match joint.joint_type {
                urdf_rs::JointType::Continuous => Ok((f64::NEG_INFINITY, f64::INFINITY)),
                urdf_rs::JointType::Fixed => Ok((0.0, 0.0)),
                _ => {
                    let (lo, hi) = (joint.limit.lower, joint.limit.upper);
                    if !(lo.is_finite() && hi.is_finite()) || lo >= hi {
                        return Err(DfsError::invalid(
                            format!("urdf joint {:?} limit", joint.name),
                            format!(
                                "lower {lo} must be below upper {hi} (a revolute or prismatic \
                                 joint needs <limit lower upper>)"
                            ),
                        ));
                    }
                    Ok((lo, hi))
                }
            }
        };
        for &j in &order_joints {
            let joint = &robot.joints[j];
            if joint.mimic.is_none() && !matches!(joint.joint_type, urdf_rs::JointType::Fixed) {
                let (lo, hi) = limits(joint)?;
                dof_of.insert(joint.name.clone(), dof_names.len());
                dof_names.push(joint.name.clone());
                dof_lower.push(lo);
                dof_upper.push(hi);
            }
        }
        if dof_names.len() > MAX_HAND_DOF {
            let reason = super::model::too_many_dofs(dof_names.len());
            return Err(DfsError::invalid("urdf", reason));
        }
        if dof_names.is_empty() {
            // Joints that mimic each other leave no DOF: name that cycle first.
            for &j in &order_joints {
                let joint = &robot.joints[j];
                if joint.mimic.is_some() && !matches!(joint.joint_type, urdf_rs::JointType::Fixed) {
                    resolve_mimic(&by_name, joint)?;
                }
            }
            return Err(DfsError::invalid(
                "urdf",
                "the hand has no actuated joint (every joint of the hand's tree is fixed or \
                 mimics another): it cannot close on an object",
            ));
        }
        let mut hand_joints = Vec::with_capacity(order_joints.len());
        for &j in &order_joints {
            let joint = &robot.joints[j];
            let field = || format!("urdf joint {:?}", joint.name);
            let kind = match joint.joint_type {
                urdf_rs::JointType::Revolute => JointKind::Revolute,
                urdf_rs::JointType::Continuous => JointKind::Continuous,
                urdf_rs::JointType::Prismatic => JointKind::Prismatic,
                _ => JointKind::Fixed,
            };
            let (lower, upper) = limits(joint)?;
            let drive = if kind == JointKind::Fixed {
                JointDrive::Fixed
            } else if joint.mimic.is_some() {
                let (source, multiplier, offset) = resolve_mimic(&by_name, joint)?;
                let Some(&dof) = dof_of.get(&source) else {
                    return Err(DfsError::invalid(
                        field(),
                        format!("mimics joint {source:?}, which is not in the hand's subtree"),
                    ));
                };
                if multiplier == 0.0 {
                    return Err(DfsError::invalid(field(), "mimic multiplier is 0"));
                }
                // Keep the mimic joint inside its own limits: narrow the source DOF's range.
                if lower.is_finite() || upper.is_finite() {
                    let a = (lower - offset) / multiplier;
                    let b = (upper - offset) / multiplier;
                    dof_lower[dof] = dof_lower[dof].max(a.min(b));
                    dof_upper[dof] = dof_upper[dof].min(a.max(b));
                    if dof_lower[dof] > dof_upper[dof] {
                        return Err(DfsError::invalid(
                            field(),
                            format!("its limits and those of {source:?} leave no common range"),
                        ));
                    }
                }
                JointDrive::Mimic {
                    dof,
                    multiplier,
                    offset,
                }
            } else {
                JointDrive::Dof(dof_of[&joint.name])
            };
            // The axis is a direction, normalised as URDF readers do: scaled by its largest
            // component first, so that (0, 1e200, 0) does not overflow the norm.
            let raw = Vector::from(joint.axis.xyz.0);
            let largest = raw.amax();
            let axis = if raw.iter().all(|v| v.is_finite()) && largest > 0.0 {
                UnitVector::new_normalize(raw / largest)
            } else if kind == JointKind::Fixed {
                Vector::x_axis()
            } else {
                return Err(DfsError::invalid(
                    field(),
                    "axis must be a finite, non-zero vector",
                ));
            };
            let origin = pose(&joint.origin);
            let xyz = origin.translation.vector;
            if !(xyz.iter().all(|v| v.is_finite()) && xyz.norm() <= MAX_HAND_EXTENT) {
                return Err(DfsError::invalid(
                    field(),
                    format!("origin must be finite and within {MAX_HAND_EXTENT} m of its parent"),
                ));
            }
            hand_joints.push(Joint {
                name: joint.name.clone(),
                kind,
                parent: new_index[&link_index[joint.parent.link.as_str()]],
                child: new_index[&link_index[joint.child.link.as_str()]],
                origin,
                axis,
                lower: if kind == JointKind::Fixed { 0.0 } else { lower },
                upper: if kind == JointKind::Fixed { 0.0 } else { upper },
                drive,
            });
        }
        for name in spec.joint_torque_limits.keys() {
            if !dof_of.contains_key(name) {
                return Err(DfsError::invalid(
                    format!("joint_torque_limits.{name}"),
                    "no such independent (non-mimic, moving) joint in the hand",
                ));
            }
        }
        let torque_limit = dof_names
            .iter()
            .map(|n| {
                spec.joint_torque_limits
                    .get(n)
                    .copied()
                    .unwrap_or(spec.torque_limit)
            })
            .collect();
        let armature = vec![spec.armature.unwrap_or(DEFAULT_ARMATURE); dof_names.len()];
        let mut fingertips = Vec::with_capacity(spec.fingertips.len());
        for (i, t) in spec.fingertips.iter().enumerate() {
            let link = link_index
                .get(t.link.as_str())
                .and_then(|old| new_index.get(old))
                .copied()
                .ok_or_else(|| {
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
            dof_names,
            dof_lower,
            dof_upper,
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
mod tests {
    use super::*;
    use crate::hand::builtin::{builtin_hand, builtin_spec, GRIPPER_URDF};
    use crate::hand::model::tests::{
        angles_from_unit, assert_jacobians_match_finite_differences,
        assert_mass_matrix_is_consistent,
    };
    use crate::hand::{FingerGroup, Kinematics, BUILTIN_HANDS};

    fn error_of(result: Result<HandModel>) -> (String, String) {
        match result {
            Err(DfsError::Invalid { field, reason }) => (field, reason),
            Err(other) => panic!("expected an invalid-model error, got {other:?}"),
            Ok(h) => panic!("expected an error, got a hand with {} DOFs", h.dof()),
        }
    }

    fn gripper_spec() -> HandSpec {
        builtin_spec("gripper").unwrap().0
    }

    #[test]
    fn every_builtin_hand_loads_with_its_fingers_and_dofs() {
        let expected = [
            ("glove10", 5, 10),
            ("allegro", 4, 16),
            ("barrett", 3, 8),
            ("inspire", 5, 6),
            ("gripper", 2, 2),
        ];
        assert_eq!(BUILTIN_HANDS.len(), expected.len());
        for (name, tips, dofs) in expected {
            let hand = builtin_hand(name).unwrap();
            assert_eq!(hand.name, name);
            assert_eq!(hand.fingertips.len(), tips, "{name} fingertips");
            assert_eq!(hand.dof(), dofs, "{name} DOFs");
            hand.validate().unwrap();
        }
    }

    #[test]
    fn inspire_mimic_joints_follow_their_source_within_their_own_limits() {
        let hand = builtin_hand("inspire").unwrap();
        let mimics: Vec<&Joint> = hand
            .joints
            .iter()
            .filter(|j| matches!(j.drive, JointDrive::Mimic { .. }))
            .collect();
        // Four finger intermediates and two thumb joints.
        assert_eq!(mimics.len(), 6);
        let j = hand
            .joints
            .iter()
            .find(|j| j.name == "index_intermediate_joint")
            .unwrap();
        let JointDrive::Mimic {
            dof,
            multiplier,
            offset,
        } = j.drive
        else {
            panic!("not a mimic");
        };
        assert_eq!(hand.dof_names[dof], "index_proximal_joint");
        assert_eq!((multiplier, offset), (1.06399, -0.04545));
        // The thumb's pitch DOF is narrowed so its intermediate joint (×1.334, ≤ 0.8) stays in.
        let pitch = hand
            .dof_names
            .iter()
            .position(|n| n == "thumb_proximal_pitch_joint")
            .unwrap();
        assert!((hand.dof_upper[pitch] - 0.8 / 1.334).abs() < 1e-12);
        for m in mimics {
            let (d, gain) = m.drive.dof_and_gain().unwrap();
            for q in [hand.dof_lower[d], hand.dof_upper[d]] {
                let mut theta = vec![0.0; hand.dof()];
                theta[d] = q;
                let v = m.drive.value(&theta);
                assert!(
                    v >= m.lower - 1e-9 && v <= m.upper + 1e-9,
                    "{} = {v}",
                    m.name
                );
                assert!(gain != 0.0);
            }
        }
    }

    #[test]
    fn the_gripper_jaws_share_one_dof_and_form_one_finger_group() {
        let hand = builtin_hand("gripper").unwrap();
        let jaw = hand
            .dof_names
            .iter()
            .position(|n| n == "right_finger_joint")
            .unwrap();
        assert_eq!(
            hand.finger_groups,
            vec![FingerGroup {
                tips: vec![0, 1],
                dofs: vec![jaw]
            }]
        );
        // Opening the jaw DOF moves the two pads apart symmetrically.
        let mut kin = Kinematics::default();
        let mut q = vec![0.0; 2];
        q[jaw] = 0.03;
        hand.forward_kinematics(&Isometry::identity(), &q, &mut kin);
        let gap = (kin.tip_centres[0] - kin.tip_centres[1]).norm();
        assert!((gap - (0.06 + 0.02)).abs() < 1e-12, "{gap}");
    }

    #[test]
    fn allegro_jacobians_and_inertia_match_finite_differences() {
        let hand = builtin_hand("allegro").unwrap();
        let mut u = 0.137;
        for _ in 0..5 {
            let samples: Vec<f64> = (0..hand.dof())
                .map(|_| {
                    u = (u * 7.31 + 0.123) % 1.0;
                    u
                })
                .collect();
            let q = angles_from_unit(&hand, &samples);
            assert_jacobians_match_finite_differences(&hand, &q);
            let qdot: Vec<f64> = samples.iter().map(|s| 2.0 * s - 1.0).collect();
            assert_mass_matrix_is_consistent(&hand, &q, &qdot);
        }
        let inspire = builtin_hand("inspire").unwrap();
        let q = angles_from_unit(&inspire, &[0.3, 0.5, 0.7, 0.2, 0.9, 0.4]);
        assert_jacobians_match_finite_differences(&inspire, &q);
    }

    /// The gripper URDF with `from` replaced by `to` (which must occur).
    fn edited(from: &str, to: &str) -> String {
        assert!(GRIPPER_URDF.contains(from), "{from}");
        GRIPPER_URDF.replacen(from, to, 1)
    }

    #[test]
    fn bad_urdfs_and_specs_are_refused_naming_the_problem() {
        let spec = gripper_spec();
        let cases: Vec<(String, HandSpec, &str, &str)> = vec![
            (
                "<robot name=\"x\"><link name=".into(),
                spec.clone(),
                "urdf",
                "does not parse",
            ),
            (
                // A loop: the palm becomes the child of a finger as well.
                edited(
                    "</robot>",
                    "<joint name=\"loop\" type=\"fixed\"><parent link=\"left_finger\"/>\
                     <child link=\"palm\"/></joint></robot>",
                ),
                spec.clone(),
                "urdf link \"palm\"",
                "kinematic loop",
            ),
            (
                edited("</robot>", "<link name=\"stray\"/></robot>"),
                spec.clone(),
                "urdf",
                "several root links (base_link, stray)",
            ),
            (
                GRIPPER_URDF.into(),
                HandSpec {
                    fingertips: vec![FingertipSpec {
                        name: None,
                        link: "nail".into(),
                        offset: [0.0; 3],
                        radius: 0.01,
                    }],
                    thumb: None,
                    ..spec.clone()
                },
                "fingertips[0].link",
                "no link named \"nail\"",
            ),
            (
                // Every joint fixed: a hand that cannot move a finger was accepted.
                GRIPPER_URDF
                    .replace("type=\"revolute\"", "type=\"fixed\"")
                    .replace("type=\"prismatic\"", "type=\"fixed\"")
                    .replace(
                        "<mimic joint=\"right_finger_joint\" multiplier=\"1\" offset=\"0\"/>",
                        "",
                    ),
                spec.clone(),
                "urdf",
                "the hand has no actuated joint",
            ),
            (
                // Two joints mimicking each other were reported as a hand with no actuated
                // joint, not as the cycle they are.
                GRIPPER_URDF
                    .replace("type=\"revolute\"", "type=\"fixed\"")
                    .replace(
                        "<child link=\"right_finger\"/>",
                        "<child link=\"right_finger\"/><mimic joint=\"left_finger_joint\"/>",
                    ),
                spec.clone(),
                "urdf joint \"right_finger_joint\" mimic",
                "mimic joints form a cycle",
            ),
            (
                edited("<mass value=\"0.05\"/>", "<mass value=\"1e30\"/>"),
                spec.clone(),
                "urdf link \"right_finger\" inertial",
                "at most 10000 kg",
            ),
            (
                edited("<mass value=\"0.05\"/>", "<mass value=\"-0.05\"/>"),
                spec.clone(),
                "urdf link \"right_finger\" inertial",
                "mass -0.05",
            ),
            (
                edited("ixx=\"3.5e-5\"", "ixx=\"-3.5e-5\""),
                spec.clone(),
                "urdf link \"right_finger\" inertial",
                "not positive semi-definite",
            ),
            (
                GRIPPER_URDF.into(),
                {
                    let mut s = spec.clone();
                    s.fingertips[1].radius = -0.01;
                    s
                },
                "fingertips[1].radius",
                "radius -0.01",
            ),
            (
                edited("type=\"revolute\"", "type=\"floating\""),
                spec.clone(),
                "urdf joint \"wrist_roll\"",
                "Floating is not supported",
            ),
            (
                edited("joint=\"right_finger_joint\"", "joint=\"thumb_joint\""),
                spec.clone(),
                "urdf joint \"left_finger_joint\" mimic",
                "\"thumb_joint\", which does not exist",
            ),
            (
                edited("<child link=\"palm\"/>", "<child link=\"hand\"/>"),
                spec.clone(),
                "urdf joint \"wrist_roll\"",
                "child link \"hand\" does not exist",
            ),
            (
                edited(
                    "<limit lower=\"-3.14\" upper=\"3.14\" effort=\"5\" velocity=\"3\"/>",
                    "",
                ),
                spec.clone(),
                "urdf joint \"wrist_roll\" limit",
                "needs <limit",
            ),
            (
                GRIPPER_URDF.into(),
                HandSpec {
                    torque_limit: 0.0,
                    ..spec.clone()
                },
                "torque_limit",
                "> 0",
            ),
            (
                GRIPPER_URDF.into(),
                {
                    let mut s = spec.clone();
                    s.joint_torque_limits
                        .insert("left_finger_joint".into(), 5.0);
                    s
                },
                "joint_torque_limits.left_finger_joint",
                "no such independent",
            ),
            (
                GRIPPER_URDF.into(),
                HandSpec {
                    base_link: Some("forearm".into()),
                    ..spec.clone()
                },
                "base_link",
                "no link named \"forearm\"",
            ),
            (
                "<robot name=\"x\"></robot>".into(),
                spec.clone(),
                "urdf",
                "robot \"x\" has no links",
            ),
            (
                edited("effort=\"5\" velocity=\"3\"", "effort=\"5\""),
                spec.clone(),
                "urdf",
                "missing field `velocity` (every joint <limit> needs both effort and velocity",
            ),
            (
                edited("<axis xyz=\"0 0 1\"/>", "<axis xyz=\"0 0 0\"/>"),
                spec.clone(),
                "urdf joint \"wrist_roll\"",
                "axis must be a finite, non-zero vector",
            ),
        ];
        for (urdf, spec, field, reason) in cases {
            let (f, r) = error_of(HandModel::from_urdf(&urdf, &spec));
            assert_eq!(f, field, "{r}");
            assert!(r.contains(reason), "{field}: {r:?} lacks {reason:?}");
        }
    }

    #[test]
    fn lengths_far_beyond_a_hand_are_refused_naming_the_field() {
        let spec = gripper_spec();
        let mut far_tip = spec.clone();
        far_tip.fingertips[0].offset = [1e300, 0.0, 0.0];
        let (f, r) = error_of(HandModel::from_urdf(GRIPPER_URDF, &far_tip));
        assert_eq!(f, "fingertips[0].offset", "{r}");
        let mut huge_tip = spec.clone();
        huge_tip.fingertips[1].radius = 20.0;
        let (f, r) = error_of(HandModel::from_urdf(GRIPPER_URDF, &huge_tip));
        assert_eq!(f, "fingertips[1].radius", "{r}");
        let far_joint = edited(
            "<origin xyz=\"0 0 0.04\" rpy=\"0 0 0\"/>",
            "<origin xyz=\"1e300 0 0.04\" rpy=\"0 0 0\"/>",
        );
        let (f, r) = error_of(HandModel::from_urdf(&far_joint, &spec));
        assert!(
            f.starts_with("urdf joint") && r.contains("within 10 m"),
            "{f}: {r}"
        );
    }

    #[test]
    fn too_many_dofs_are_refused_naming_the_limit() {
        // 33 revolute joints in a chain.
        let mut urdf = String::from("<robot name=\"snake\"><link name=\"l0\"/>");
        for i in 1..=33 {
            urdf.push_str(&format!(
                "<link name=\"l{i}\"/><joint name=\"j{i}\" type=\"revolute\">\
                 <parent link=\"l{}\"/><child link=\"l{i}\"/><axis xyz=\"0 0 1\"/>\
                 <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>",
                i - 1
            ));
        }
        urdf.push_str("</robot>");
        let spec = HandSpec {
            fingertips: vec![FingertipSpec {
                name: None,
                link: "l33".into(),
                offset: [0.0; 3],
                radius: 0.01,
            }],
            thumb: None,
            joint_torque_limits: BTreeMap::new(),
            ..gripper_spec()
        };
        let (field, reason) = error_of(HandModel::from_urdf(&urdf, &spec));
        assert_eq!(field, "urdf");
        assert!(
            reason.starts_with(
                "the hand has 33 DOFs (independent moving joints); at most 32 are accepted"
            ),
            "{reason}"
        );
        // One fewer is a hand.
        let urdf = urdf.replace(
            "type=\"revolute\"><parent link=\"l32\"",
            "type=\"fixed\"><parent link=\"l32\"",
        );
        assert_eq!(
            HandModel::from_urdf(&urdf, &spec).unwrap().dof(),
            MAX_HAND_DOF
        );
    }

    #[test]
    fn an_axis_is_a_direction_whatever_its_length() {
        let spec = gripper_spec();
        let unit = HandModel::from_urdf(GRIPPER_URDF, &spec).unwrap();
        for axis in ["0 0 1e200", "0 0 1e-200", "0 0 7"] {
            let urdf = edited("<axis xyz=\"0 0 1\"/>", &format!("<axis xyz=\"{axis}\"/>"));
            let hand = HandModel::from_urdf(&urdf, &spec).unwrap();
            assert_eq!(hand.joints, unit.joints, "axis {axis}");
        }
    }

    #[test]
    fn a_base_link_drops_the_links_above_it_and_continuous_joints_are_unlimited() {
        let urdf = edited("type=\"revolute\"", "type=\"continuous\"");
        let spec = HandSpec {
            base_link: Some("palm".into()),
            joint_torque_limits: BTreeMap::new(),
            ..gripper_spec()
        };
        let hand = HandModel::from_urdf(&urdf, &spec).unwrap();
        assert_eq!(hand.links[hand.root].name, "palm");
        assert_eq!(hand.dof(), 1);
        let full = HandModel::from_urdf(
            &urdf,
            &HandSpec {
                joint_torque_limits: BTreeMap::new(),
                ..gripper_spec()
            },
        )
        .unwrap();
        assert_eq!(full.dof_lower[0], f64::NEG_INFINITY);
        assert_eq!(full.dof_upper[0], f64::INFINITY);
        // A massless link reads as massless; the armature keeps M positive definite.
        assert!(full.armature.iter().all(|&a| a == DEFAULT_ARMATURE));
    }

    /// The gripper's URDF with `inner` inserted just inside `<robot>`.
    fn gripper_with(inner: &str) -> String {
        let at = GRIPPER_URDF.find("<link").unwrap();
        format!("{}{inner}{}", &GRIPPER_URDF[..at], &GRIPPER_URDF[at..])
    }

    /// `depth` unknown elements, each inside the last.
    fn nest(depth: usize) -> String {
        format!("{}{}", "<junk>".repeat(depth), "</junk>".repeat(depth))
    }

    /// Loads `urdf` on a thread with a 2 MiB stack (a tokio worker's and Rust's default):
    /// before the depth check, 3000 levels overflowed it inside the XML parser.
    fn load_on_small_stack(urdf: String) -> Result<HandModel> {
        std::thread::Builder::new()
            .stack_size(2 << 20)
            .spawn(move || HandModel::from_urdf(&urdf, &gripper_spec()))
            .unwrap()
            .join()
            .unwrap()
    }

    #[test]
    fn a_urdf_nesting_elements_thousands_deep_is_refused_naming_the_limit() {
        for depth in [3000, 100_000] {
            // `<robot>` is the first level.
            let (field, reason) = error_of(load_on_small_stack(gripper_with(&nest(depth - 1))));
            assert_eq!(field, "urdf");
            assert_eq!(
                reason,
                format!("the URDF nests elements {depth} deep; at most 64 are accepted")
            );
        }
        // At the limit an unknown element is ignored as before; one more is refused.
        load_on_small_stack(gripper_with(&nest(MAX_URDF_DEPTH - 1))).unwrap();
        let (_, reason) = error_of(load_on_small_stack(gripper_with(&nest(MAX_URDF_DEPTH))));
        assert!(reason.contains("65 deep; at most 64"), "{reason}");
    }

    #[test]
    fn a_urdf_over_4_mib_is_refused_naming_the_limit() {
        let padding = " ".repeat(MAX_URDF_BYTES);
        let (field, reason) = error_of(HandModel::from_urdf(
            &gripper_with(&padding),
            &gripper_spec(),
        ));
        assert_eq!(field, "urdf");
        assert!(
            reason.starts_with("the URDF is 41")
                && reason.ends_with("bytes; at most 4194304 (4 MiB) are accepted"),
            "{reason}"
        );
    }

    #[test]
    fn comments_cdata_instructions_and_attribute_values_do_not_count_as_nesting() {
        let depth = |s: &str| nesting_depth(s.as_bytes());
        assert_eq!(depth("<a><b/><c x=\"1\"></c></a>"), 2);
        assert_eq!(depth("<a><!-- <b><b><b> --></a>"), 1);
        assert_eq!(depth("<a><![CDATA[<b><b><b>]]></a>"), 1);
        assert_eq!(depth("<?xml version=\"1.0\"?><!DOCTYPE robot><a/>"), 1);
        assert_eq!(depth("<a x=\"<b><b>\" y='/>' z = \"<c>\"><d/></a>"), 2);
        // A quote opens a value only after `=`, as in the parser: here the tag ends at `>`
        // and the elements after it count.
        assert_eq!(depth("<a\"><b><c>"), 3);
        assert_eq!(depth("<a b\"><b><c>"), 3);
        // Unclosed constructs end the scan (the parser refuses them).
        assert_eq!(depth("<a><!-- <b><b>"), 1);
        assert_eq!(depth("<a x=\"<b><b>"), 1);
        // A processing instruction ends at the first `>` after a `?`, as the parser's does.
        assert_eq!(depth("<?p ? ><a><b>"), 2);
        // A comment full of elements in a real URDF loads.
        let hand = HandModel::from_urdf(
            &gripper_with(&format!("<!-- {} -->", nest(5000))),
            &gripper_spec(),
        )
        .unwrap();
        assert_eq!(hand.dof(), 2);
    }

    #[test]
    fn every_built_in_urdf_nests_less_than_ten_deep() {
        for name in BUILTIN_HANDS.iter().filter(|&&n| n != "glove10") {
            let (_, urdf) = builtin_spec(name).unwrap();
            check_urdf_text(urdf).unwrap();
            let depth = nesting_depth(urdf.as_bytes());
            assert!((3..10).contains(&depth), "{name}: {depth}");
        }
    }
}
