//! The raw 1 kHz message types of a session and their JSON Schemas (`icms.*`).
//!
//! SI units throughout (m, rad, s, N, N·m). Vectors are `{x, y, z}`, quaternions
//! `{x, y, z, w}` (the Foxglove types are reused for them). The schemas are hand-written in
//! `services/schemas/icms.*.json` and embedded.

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

/// One fingertip of [`Contacts`]. A fingertip away from the object (most of them, most of
/// the time) has zero point, normal, penetration and intensities; those zero fields are left
/// out of the message (a third of the session's size otherwise) and read back as zero.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FingerContact {
    /// Fingertip name.
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
}

/// `icms.Contacts`: per-fingertip contact state at one tick.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Contacts {
    /// Number of transmitting contacts.
    pub n_contacts: u32,
    /// Per fingertip, in the hand's fingertip order.
    pub fingers: Vec<FingerContact>,
}

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
