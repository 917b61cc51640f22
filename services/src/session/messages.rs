//! The raw 1 kHz message types of a session, in SI units, as the rest of the code reads them,
//! and the JSON Schemas (`icms.*`) of session format 1, in which they were written as JSON.
//!
//! SI units throughout (m, rad, s, N, N·m). Vectors are `{x, y, z}`, quaternions
//! `{x, y, z, w}` (the Foxglove types are reused for them). The format 1 schemas are in
//! `services/schemas/icms.*.json`; format 2 writes these messages as protobuf
//! ([`super::proto`], from `services/proto/icms/session.proto`).

use serde::{Deserialize, Serialize};

use crate::foxglove::{Pose, Vector3};
use crate::mcap_io::JsonSchema;

/// Schema of [`GloveJointStates`] (`/glove/joint_states`).
pub const GLOVE_JOINT_STATES_SCHEMA: JsonSchema = JsonSchema::new_static(
    "icms.GloveJointStates",
    include_str!("../../schemas/icms.GloveJointStates.json"),
);
/// Schema of [`GloveFeedback`] (`/glove/feedback`).
pub const GLOVE_FEEDBACK_SCHEMA: JsonSchema = JsonSchema::new_static(
    "icms.GloveFeedback",
    include_str!("../../schemas/icms.GloveFeedback.json"),
);
/// Schema of [`Contacts`] (`/dfs/contacts`).
pub const CONTACTS_SCHEMA: JsonSchema = JsonSchema::new_static(
    "icms.Contacts",
    include_str!("../../schemas/icms.Contacts.json"),
);
/// Schema of [`ObjectState`] (`/object/state`).
pub const OBJECT_STATE_SCHEMA: JsonSchema = JsonSchema::new_static(
    "icms.ObjectState",
    include_str!("../../schemas/icms.ObjectState.json"),
);

/// Every `icms.*` schema, in topic order of [`super::RAW_TOPICS`].
pub const ICMS_SCHEMAS: [JsonSchema; 4] = [
    GLOVE_JOINT_STATES_SCHEMA,
    GLOVE_FEEDBACK_SCHEMA,
    CONTACTS_SCHEMA,
    OBJECT_STATE_SCHEMA,
];

/// `icms.GloveJointStates`: the glove sample of one tick. One entry per DOF, in `names` order.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GloveJointStates {
    /// DOF names of the hand.
    pub names: Vec<String>,
    /// Measured joint angles θ (rad; m for a prismatic DOF).
    pub positions: Vec<f64>,
    /// Joint velocities (rad/s): finite difference of consecutive measured angles, 0 at the
    /// first tick.
    pub velocities: Vec<f64>,
    /// The operator's measured joint torques τ (N·m).
    pub efforts: Vec<f64>,
}

/// Per-finger forces of [`GloveFeedback`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FingerFeedback {
    /// Fingertip name.
    pub name: String,
    /// Force of the object on the fingertip, world frame (N); left out of the message when
    /// zero (no contact).
    #[serde(default, skip_serializing_if = "is_zero_vector")]
    pub feedback_force_world: Vector3,
    /// The operator's fingertip force from τ, world frame (N).
    pub tip_force_world: Vector3,
}

/// `icms.GloveFeedback`: what the DFS sends back to the glove at one tick.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GloveFeedback {
    /// DOF names of the hand.
    pub names: Vec<String>,
    /// Glove motor position commands (rad), per DOF.
    pub motor_positions: Vec<f64>,
    /// Their velocities (rad/s).
    pub motor_velocities: Vec<f64>,
    /// Feedback joint torques the motors render (N·m).
    pub feedback_torques: Vec<f64>,
    /// Per fingertip.
    pub fingers: Vec<FingerFeedback>,
}

/// Contact intensities in the contact frame: `x`, `y` tangential force (N), `z` normal force
/// (N, positive pushes into the object), `torsion` moment about the normal (N·m).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intensity4 {
    /// Tangential force along the contact frame's x (N).
    pub x: f64,
    /// Tangential force along the contact frame's y (N).
    pub y: f64,
    /// Normal force (N), positive = pushing.
    pub z: f64,
    /// Torsional moment about the normal (N·m).
    pub torsion: f64,
}

fn is_zero_vector(v: &Vector3) -> bool {
    *v == Vector3::default()
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Intensity4 {
    fn is_zero(&self) -> bool {
        *self == Intensity4::default()
    }
}

pub use dfs_core::hand::ContactPart;

/// One contact of [`Contacts`]: a fingertip or, with whole-hand contact, a palm or phalanx
/// contact shape ([`part`](Self::part)). A fingertip away from the object (most of them, most
/// of the time) has zero point, normal, penetration and intensities; those zero fields are left
/// out of the message (a third of the session's size otherwise) and read back as zero.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FingerContact {
    /// Fingertip name, or the contact shape's (`palm`, `index_proximal`).
    pub name: String,
    /// Within the contact margin of the object's surface.
    pub touching: bool,
    /// Touching and pushing: the contact transmits force.
    pub in_contact: bool,
    /// Contact point in the object frame B (m); zero when not touching.
    #[serde(default, skip_serializing_if = "is_zero_vector")]
    pub point_b: Vector3,
    /// Unit contact normal in B, pointing into the object; zero when not touching.
    #[serde(default, skip_serializing_if = "is_zero_vector")]
    pub normal_b: Vector3,
    /// Penetration (m), negative for a gap; 0 when not touching.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub penetration: f64,
    /// The operator's intensities `c_h`.
    #[serde(default, skip_serializing_if = "Intensity4::is_zero")]
    pub intensity: Intensity4,
    /// What acts on the object (friction-limited).
    #[serde(default, skip_serializing_if = "Intensity4::is_zero")]
    pub transmitted: Intensity4,
    /// Fed back to the operator.
    #[serde(default, skip_serializing_if = "Intensity4::is_zero")]
    pub feedback: Intensity4,
    /// The requested intensities are inside the friction cone (`!slip`).
    pub in_cone: bool,
    /// The requested intensities were outside the friction cone.
    pub slip: bool,
    /// Which object of the scene it touches: its index in the `objects` list of the `session`
    /// metadata record (0 when not touching, and in a scene of one object); `point_b` and
    /// `normal_b` are in that object's frame.
    #[serde(default, skip_serializing_if = "is_zero_u32")]
    pub object: u32,
    /// Which part of the hand this is (absent: a fingertip, as in every file written before
    /// whole-hand contact). A palm or phalanx has no operator intensities of its own: its
    /// `intensity` and `feedback` are zero, `transmitted` is its spring's force.
    #[serde(default, skip_serializing_if = "ContactPart::is_fingertip")]
    pub part: ContactPart,
    /// A palm or phalanx: the name of the hand's link it is fixed to; empty for a fingertip.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub link: String,
}

fn is_zero_u32(x: &u32) -> bool {
    *x == 0
}

/// `icms.Contacts`: per-fingertip contact state at one tick, and the palm and phalanges that
/// touch an object (whole-hand contact).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Contacts {
    /// Number of transmitting contacts.
    pub n_contacts: u32,
    /// Per fingertip, in the hand's fingertip order; then each palm or phalanx contact shape
    /// that touches an object, in the hand's contact shape order (at most
    /// [`MAX_SESSION_BODY_CONTACTS`]).
    pub fingers: Vec<FingerContact>,
}

impl Contacts {
    /// How many of [`fingers`](Self::fingers) are fingertips: those before the first palm or
    /// phalanx.
    pub fn n_tips(&self) -> usize {
        self.fingers
            .iter()
            .position(|f| !f.part.is_fingertip())
            .unwrap_or(self.fingers.len())
    }
}

/// Most palm and phalanx contacts a `/dfs/contacts` message may list: a hand's contact shapes
/// ([`dfs_core::hand::MAX_CONTACT_SHAPES`]).
pub const MAX_SESSION_BODY_CONTACTS: usize = dfs_core::hand::MAX_CONTACT_SHAPES;

/// `icms.ObjectState`: the object after one tick.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectState {
    /// Pose of the object frame B (at its centre of mass) in the world.
    pub pose: Pose,
    /// Linear velocity, world frame (m/s).
    pub linear_velocity: Vector3,
    /// Angular velocity, object frame B (rad/s).
    pub angular_velocity_b: Vector3,
    /// External wrench `f_ext` in B (N, N·m): gravity, table, gyroscopic term.
    pub f_ext_b: [f64; 6],
    /// Wrench of the fingers on the object in B (N, N·m).
    pub object_force_b: [f64; 6],
    /// Wrench of the table on the object in B (N, N·m).
    pub table_force_b: [f64; 6],
    /// Pose of the object relative to the hand's base link (drift of a held object shows here).
    pub pose_in_hand: Pose,
    /// Which object of the scene the fields above describe (the one the operator grasps): its
    /// index in the `objects` list of the `session` metadata record; 0 with one object.
    #[serde(default, skip_serializing_if = "is_zero_u32")]
    pub index: u32,
    /// Every object of a scene of several, in the order of the `objects` list of the
    /// `session` metadata record; empty with one object.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub objects: Vec<SceneObjectState>,
}

/// `icms.SceneObjectState`: one object of a scene of several, after one tick.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneObjectState {
    /// Pose of the object frame B (at its centre of mass) in the world.
    pub pose: Pose,
    /// Linear velocity, world frame (m/s).
    pub linear_velocity: Vector3,
    /// Angular velocity, object frame B (rad/s).
    pub angular_velocity_b: Vector3,
}

/// One phase of the ground truth (`ground_truth` metadata, key `phases`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundTruthPhase {
    /// Phase name (`approach`, `grasp`, `lift`, ...).
    pub name: String,
    /// Start, ns since the session start.
    pub start_ns: u64,
    /// End (exclusive), ns since the session start.
    pub end_ns: u64,
}

// ---------------------------------------------------------------------------------------------
// Content checks: what a session read back must hold beyond valid JSON of the right shape.
// ---------------------------------------------------------------------------------------------

/// Most DOFs a session's messages may name (`names` of `/glove/joint_states` and
/// `/glove/feedback`): as many as a hand may have links ([`dfs_core::hand::MAX_LINKS`], one
/// joint each), well over the hands icms simulates (glove10, robot hands up to 30 DOFs).
pub const MAX_SESSION_DOFS: usize = 64;

/// Most fingertips a session's messages may list (`fingers` of `/dfs/contacts` and
/// `/glove/feedback`): a hand has 1 to [`dfs_core::hand::MAX_TIPS`] of them; this leaves room
/// for hands beyond that.
pub const MAX_SESSION_FINGERS: usize = 16;

/// How far from 1 the norm of a unit quantity may be: the orientation quaternions of
/// `/object/state`, the contact normals of `/dfs/contacts` (of fingers touching). Ours are unit
/// to 1e-6 or better; a quaternion printed to 2 decimals or through `f32` is within 1e-2, and
/// readers normalise what they read. A zero quaternion or normal, or one scaled by a factor,
/// is no rotation or direction at all and is refused (segmentation would average it into a
/// NaN normal).
pub const UNIT_NORM_TOLERANCE: f64 = 1e-2;

// Every hand icms simulates or replays onto writes sessions it can read back.
const _: () = assert!(
    MAX_SESSION_DOFS >= dfs_core::hand::MAX_DOF && MAX_SESSION_FINGERS >= dfs_core::hand::MAX_TIPS
);

/// Shortest span of each raw topic (ns): two ticks at 1 kHz. A file of one message per topic
/// lasts 0 ns: no phase, no skill, a session of nothing. Segmentation finds skills only in far
/// longer sessions (a grasp holds for tenths of a second), but a short session is a session.
pub const MIN_SESSION_NS: u64 = 1_000_000;

/// Most metadata records in a session file (ours has 2, a replay's 3).
pub const MAX_METADATA_RECORDS: usize = 64;
/// Most entries in one metadata record (our `session` record has about 15).
pub const MAX_METADATA_ENTRIES: usize = 256;
/// Longest metadata key, bytes.
pub const MAX_METADATA_KEY_BYTES: usize = 256;
/// Longest metadata value, bytes: 64 KiB. The longest ones we write grow with the scenario's
/// script: a script of 256 tasks (the most a scenario may have) with every number written to
/// full precision makes `session.scenario_json` 35 kB and `ground_truth.phases` 16 kB; a
/// built-in scenario's are under 2 kB.
pub const MAX_METADATA_VALUE_BYTES: usize = 64 * 1024;
/// Most bytes of record names, keys and values in all the metadata records of a file:
/// 256 KiB (the store keeps the `session` record and lists it with every page of sessions).
pub const MAX_METADATA_BYTES: usize = 256 * 1024;

/// The session's DOF and fingertip names, as its first messages give them: every message must
/// name the same ones, in the same order (a session records one hand).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct TickReference {
    /// DOF names of the first message that listed a valid number of them.
    pub dof_names: Option<Vec<String>>,
    /// Which message that was, for errors: "the DOF names of /glove/joint_states message 0".
    pub dof_source: String,
    /// Fingertip names of the first message that listed a valid number of them.
    pub finger_names: Option<Vec<String>>,
    /// Which message that was, for errors: "the fingertips of /dfs/contacts message 0".
    pub finger_source: String,
}

impl TickReference {
    /// Takes `names` (of a message of `topic`) as the session's DOF names if there are none
    /// yet and their number is valid (an empty list would make every other message look
    /// wrong, before the culprit's own error).
    pub(crate) fn learn_dofs(&mut self, topic: &str, names: &[String]) {
        if self.dof_names.is_none() && (1..=MAX_SESSION_DOFS).contains(&names.len()) {
            self.dof_names = Some(names.to_vec());
            self.dof_source = format!("the DOF names of {topic} message 0");
        }
    }

    /// [`Self::learn_dofs`] for the fingertip names.
    pub(crate) fn learn_fingers<'n>(
        &mut self,
        topic: &str,
        names: impl ExactSizeIterator<Item = &'n str>,
    ) {
        if self.finger_names.is_none() && (1..=MAX_SESSION_FINGERS).contains(&names.len()) {
            self.finger_names = Some(names.map(str::to_owned).collect());
            self.finger_source = format!("the fingertips of {topic} message 0");
        }
    }
}

/// A raw message whose content can be checked beyond its JSON shape. The error is the detail,
/// naming the field; the caller names the topic and the message.
pub(crate) trait TickContent {
    /// `Ok` if the message is consistent in itself and with the session's `reference`.
    fn check(&self, reference: &TickReference) -> Result<(), String>;
}

/// `names` has 1 to [`MAX_SESSION_DOFS`] entries, each array of `arrays` one per name, and the
/// names are the session's (from `/glove/joint_states` message 0).
fn check_dofs<'n>(
    names: impl ExactSizeIterator<Item = &'n str> + Clone,
    arrays: [(&str, usize); 3],
    reference: &TickReference,
) -> Result<(), String> {
    check_dofs_named(names, arrays, reference, true)
}

/// [`check_dofs`], the names compared with the reference only if `compare` (false: they are
/// those of a message that passed).
fn check_dofs_named<'n>(
    names: impl ExactSizeIterator<Item = &'n str> + Clone,
    arrays: [(&str, usize); 3],
    reference: &TickReference,
    compare: bool,
) -> Result<(), String> {
    let n = names.len();
    if n == 0 || n > MAX_SESSION_DOFS {
        return Err(format!(
            "names has {n} entries; a hand has 1 to {MAX_SESSION_DOFS} DOFs"
        ));
    }
    for (field, len) in arrays {
        if len != n {
            return Err(format!("{field} has {len} elements for {n} names"));
        }
    }
    if let Some(expected) = reference.dof_names.as_ref().filter(|_| compare) {
        same_names("names", names, expected, &reference.dof_source)?;
    }
    Ok(())
}

/// `fingers` has 1 to [`MAX_SESSION_FINGERS`] entries, named as the session's (from
/// `/dfs/contacts` message 0).
fn check_fingers<'n>(
    names: impl ExactSizeIterator<Item = &'n str> + Clone,
    reference: &TickReference,
) -> Result<(), String> {
    check_fingers_named(names, reference, true)
}

/// [`check_fingers`], the names compared with the reference only if `compare`.
fn check_fingers_named<'n>(
    names: impl ExactSizeIterator<Item = &'n str> + Clone,
    reference: &TickReference,
    compare: bool,
) -> Result<(), String> {
    let n = names.len();
    if n == 0 || n > MAX_SESSION_FINGERS {
        return Err(format!(
            "fingers has {n} entries; a hand has 1 to {MAX_SESSION_FINGERS} fingertips"
        ));
    }
    if let Some(expected) = reference.finger_names.as_ref().filter(|_| compare) {
        same_names("fingers", names, expected, &reference.finger_source)?;
    }
    Ok(())
}

/// What the checks of a `/glove/joint_states` or `/glove/feedback` message (format 2) read of
/// it, when its values are not wanted (`super::wire::glove_shape`, which converts none): its
/// DOF names, how many elements each of its three arrays has, its fingertips' names.
#[derive(Debug, Default)]
pub(crate) struct GloveShape {
    /// DOF names.
    pub names: Vec<String>,
    /// Elements of `positions`, `velocities`, `efforts` (joint states) or `motor_positions`,
    /// `motor_velocities`, `feedback_torques` (feedback).
    pub arrays: [usize; 3],
    /// Fingertip names (feedback; none in joint states).
    pub fingers: Vec<String>,
    /// Whether the names and fingertips are those of the message read into it before
    /// (compared as they were read).
    pub unchanged: bool,
    /// The bytes of the name fields the last message read began with, and how many names
    /// they hold: a message that begins with the same bytes begins with the same names.
    pub lead: Vec<u8>,
    /// Names in `lead`.
    pub lead_names: usize,
}

impl GloveShape {
    /// The checks of [`GloveJointStates`] (`feedback` false) or [`GloveFeedback`], on its
    /// shape; `names_checked`: its names are those of a message that passed them (they are
    /// not compared again).
    pub(crate) fn check(
        &self,
        feedback: bool,
        reference: &TickReference,
        names_checked: bool,
    ) -> Result<(), String> {
        let fields = if feedback {
            ["motor_positions", "motor_velocities", "feedback_torques"]
        } else {
            ["positions", "velocities", "efforts"]
        };
        check_dofs_named(
            self.names.iter().map(String::as_str),
            [
                (fields[0], self.arrays[0]),
                (fields[1], self.arrays[1]),
                (fields[2], self.arrays[2]),
            ],
            reference,
            !names_checked,
        )?;
        if feedback {
            check_fingers_named(
                self.fingers.iter().map(String::as_str),
                reference,
                !names_checked,
            )?;
        }
        Ok(())
    }
}

/// `names` (the entries of `field`) are `expected`, in order.
fn same_names<'n>(
    field: &str,
    names: impl ExactSizeIterator<Item = &'n str>,
    expected: &[String],
    what: &str,
) -> Result<(), String> {
    if names.len() != expected.len() {
        return Err(format!(
            "{field} has {} entries, {what} are {}: a session records one hand",
            names.len(),
            expected.len()
        ));
    }
    for (i, (name, want)) in names.zip(expected).enumerate() {
        if name != want {
            let entry = if field == "fingers" {
                format!("fingers[{i}].name")
            } else {
                format!("{field}[{i}]")
            };
            return Err(format!(
                "{entry} is {name:?}, not {want:?} as in {what}: a session records one hand"
            ));
        }
    }
    Ok(())
}

/// The quaternion at `field` is a rotation: its norm is within [`UNIT_NORM_TOLERANCE`]
/// of 1.
fn check_unit(q: &crate::foxglove::Quaternion, field: &str) -> Result<(), String> {
    let norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
    if (norm - 1.0).abs() > UNIT_NORM_TOLERANCE {
        return Err(format!(
            "{field} has norm {norm:.4}; an orientation is a unit quaternion (norm within \
             {UNIT_NORM_TOLERANCE} of 1)"
        ));
    }
    Ok(())
}

/// The contact normal of finger `i`, touching, is a direction: its norm is within
/// [`UNIT_NORM_TOLERANCE`] of 1.
fn check_normal(v: &Vector3, i: usize) -> Result<(), String> {
    let norm = (v.x * v.x + v.y * v.y + v.z * v.z).sqrt();
    if (norm - 1.0).abs() > UNIT_NORM_TOLERANCE {
        return Err(format!(
            "fingers[{i}].normal_b has norm {norm:.4} while the finger touches; a contact \
             normal is a unit vector (norm within {UNIT_NORM_TOLERANCE} of 1)"
        ));
    }
    Ok(())
}

impl TickContent for GloveJointStates {
    fn check(&self, reference: &TickReference) -> Result<(), String> {
        check_dofs(
            self.names.iter().map(String::as_str),
            [
                ("positions", self.positions.len()),
                ("velocities", self.velocities.len()),
                ("efforts", self.efforts.len()),
            ],
            reference,
        )
    }
}

impl TickContent for GloveFeedback {
    fn check(&self, reference: &TickReference) -> Result<(), String> {
        check_dofs(
            self.names.iter().map(String::as_str),
            [
                ("motor_positions", self.motor_positions.len()),
                ("motor_velocities", self.motor_velocities.len()),
                ("feedback_torques", self.feedback_torques.len()),
            ],
            reference,
        )?;
        check_fingers(self.fingers.iter().map(|f| f.name.as_str()), reference)
    }
}

impl TickContent for Contacts {
    fn check(&self, reference: &TickReference) -> Result<(), String> {
        let tips = self.n_tips();
        check_fingers(
            self.fingers[..tips].iter().map(|f| f.name.as_str()),
            reference,
        )?;
        let body = &self.fingers[tips..];
        if body.len() > MAX_SESSION_BODY_CONTACTS {
            return Err(format!(
                "fingers has {} palm or phalanx contacts; a hand has at most \
                 {MAX_SESSION_BODY_CONTACTS} contact shapes",
                body.len()
            ));
        }
        for (i, f) in body.iter().enumerate() {
            if f.part.is_fingertip() {
                return Err(format!(
                    "fingers[{}] is a fingertip after a palm or phalanx contact; the \
                     fingertips come first",
                    tips + i
                ));
            }
            if f.name.is_empty() || f.link.is_empty() {
                return Err(format!(
                    "fingers[{}] is a {} contact without a name or link",
                    tips + i,
                    f.part.name()
                ));
            }
        }
        for (i, f) in self.fingers.iter().enumerate() {
            if f.touching {
                check_normal(&f.normal_b, i)?;
            }
            if f.object as usize >= MAX_SESSION_OBJECTS {
                return Err(format!(
                    "fingers[{i}].object is {}; a scene holds at most {MAX_SESSION_OBJECTS} \
                     objects",
                    f.object
                ));
            }
        }
        Ok(())
    }
}

/// Most objects a session's `/object/state` may list: a scene holds 1 to
/// [`dfs_core::dfs::MAX_OBJECTS`].
pub const MAX_SESSION_OBJECTS: usize = dfs_core::dfs::MAX_OBJECTS;

impl TickContent for ObjectState {
    fn check(&self, _: &TickReference) -> Result<(), String> {
        check_unit(&self.pose.orientation, "pose.orientation")?;
        check_unit(&self.pose_in_hand.orientation, "pose_in_hand.orientation")?;
        if self.objects.len() > MAX_SESSION_OBJECTS {
            return Err(format!(
                "objects has {} entries; a scene holds at most {MAX_SESSION_OBJECTS} objects",
                self.objects.len()
            ));
        }
        if !self.objects.is_empty() && self.index as usize >= self.objects.len() {
            return Err(format!(
                "index is {}, beyond the {} objects listed",
                self.index,
                self.objects.len()
            ));
        }
        for (i, o) in self.objects.iter().enumerate() {
            check_unit(
                &o.pose.orientation,
                &format!("objects[{i}].pose.orientation"),
            )?;
        }
        Ok(())
    }
}
