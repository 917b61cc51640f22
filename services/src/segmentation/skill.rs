//! The result of segmentation: a skill's phases and its hand-independent parameters (the
//! public types, their JSON), and the meaning of each dimension of its feature vector.

use std::collections::BTreeMap;

use dfs_core::contact::ContactModel;
use dfs_core::object::{Shape, ShapeKind};
use dfs_core::scenario::Phase;
use dfs_core::DfsError;
use serde::{Deserialize, Serialize};

use crate::session::ContactPart;
// A phase found by `segment`: dfs-core's one phase-span type (`{"name", "start_ns", "end_ns"}`
// in JSON), still at this path.
pub use dfs_core::scenario::PhaseSpan;

/// The result of [`segment`](super::segment): one skill per grasp, in time order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Segmentation {
    /// The skills.
    pub skills: Vec<Skill>,
}

/// One grasp of a session: its phases and its hand-independent parameters.
///
/// Its JSON is what `icms segment --json` prints in `skills`, what the store keeps as a skill's
/// `params` and what `icms replay --skill FILE` reads. Read back ([`Skill::from_json`]), a skill
/// may leave out what replay does not use (a skill file written by hand): every parameter but
/// `phases`, `contact_model` and `contacts` has a default (empty, zero, or absent), and so
/// have a contact's `finger`, `mean_intensity` and `grip_profile` and the object's `inertia`
/// and `mu_torsion`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skill {
    /// Phases, in time order, never overlapping (nor the phases of other skills), inside the
    /// session; contiguous except where odd data leaves a gap.
    pub phases: Vec<PhaseSpan>,
    /// The skill's parameters (flattened into the skill's JSON).
    #[serde(flatten)]
    pub parameters: SkillParameters,
}

impl Skill {
    /// A skill from its JSON (see [`Skill`]); an error names the path of the field that is
    /// wrong (`object.shape`, `phases[2].name`: serde's flattening loses the path of the
    /// parameters' fields, so they are read on their own).
    pub fn from_json(
        value: &serde_json::Value,
    ) -> Result<Skill, serde_path_to_error::Error<serde_json::Error>> {
        /// The one field of a skill that is not a parameter.
        #[derive(Deserialize)]
        struct Phases {
            phases: Vec<PhaseSpan>,
        }
        let Phases { phases } = serde_path_to_error::deserialize(value)?;
        let parameters = serde_path_to_error::deserialize(value)?;
        Ok(Skill { phases, parameters })
    }
}

/// The object as the session's metadata describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectParams {
    /// Its name in the session's scene, when the session names its objects (a scene of
    /// several: the `objects` of the `session` metadata record; or a named `object`): the
    /// object the skill grasped, the one its contacts pushed. Absent for a session's one
    /// unnamed object.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// `sphere`, `box` or `cylinder`.
    pub shape: ShapeKind,
    /// Size (m): `[radius]` (sphere), half extents (box), `[radius, half_height]` (cylinder),
    /// as [`Shape::sizes`] lists them.
    pub size: Vec<f64>,
    /// Mass (kg).
    pub mass: f64,
    /// Principal moments of inertia about B's axes (kg·m²), solid body of uniform density
    /// ([`Shape::principal_inertia`]). Zero when a skill file leaves it out (replay takes the
    /// inertia from the shape and mass).
    #[serde(default)]
    pub inertia: [f64; 3],
    /// Coulomb friction coefficient.
    pub mu: f64,
    /// Torsional friction coefficient (m). Default 0.
    #[serde(default)]
    pub mu_torsion: f64,
}

impl ObjectParams {
    /// The shape with its sizes, validated; an error names `object.size` when the list does
    /// not fit the shape, the size (`object.radius`, ...) when one is not a length > 0.
    pub fn to_shape(&self) -> Result<Shape, DfsError> {
        Shape::from_sizes(self.shape, &self.size, "object.size")
    }
}

/// One contact of a skill, in the object frame B.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContactParams {
    /// Fingertip of the recording hand, or its palm or phalanx contact shape (provenance
    /// only; the skill does not depend on it).
    #[serde(default)]
    pub finger: String,
    /// Which part of the hand held the object there: a fingertip (absent: as every skill
    /// before whole-hand contact), the palm or a phalanx.
    #[serde(default, skip_serializing_if = "ContactPart::is_fingertip")]
    pub part: ContactPart,
    /// Mean contact point in B over the held part of the grasp (m).
    pub position_b: [f64; 3],
    /// Mean unit normal in B, pointing into the object.
    pub normal_b: [f64; 3],
    /// Mean intensities `[x, y, normal, torsion]` (N, N·m) per phase, while touching.
    #[serde(default)]
    pub mean_intensity: BTreeMap<Phase, [f64; 4]>,
    /// Normal force (N) resampled to [`SegmentParams::profile_points`] points over the span from
    /// the start of `grasp` to the end of `release` (or of the last phase in contact).
    ///
    /// [`SegmentParams::profile_points`]: super::SegmentParams::profile_points
    #[serde(default)]
    pub grip_profile: Vec<f64>,
}

/// A slip of one contact.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlipEvent {
    /// Start, s since the start of `grasp`.
    pub time_s: f64,
    /// Fingertip.
    pub finger: String,
    /// Duration (s).
    pub duration_s: f64,
}

/// A key pose of the object relative to its pose at the start of the grasp (frame B₀).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyPose {
    /// Time since the start of `grasp` (s).
    pub time_s: f64,
    /// Position of B in B₀ (m).
    pub position: [f64; 3],
    /// Rotation of B relative to B₀ as a rotation vector (rad).
    pub rotation: [f64; 3],
}

/// Grasp quality (GraspIt!): Ferrari-Canny ε and the volume of the grasp wrench space with
/// 8-edge linearised friction cones, on the mean contacts with the object's μ and μ_t and the
/// recording's contact model (soft finger: with point contacts with friction a two-finger pinch
/// is never force closure), torques divided by the object's half diagonal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QualityParamsOut {
    /// Ferrari-Canny ε (0 when not force closure).
    pub epsilon: f64,
    /// Volume of the grasp wrench space.
    pub volume: f64,
    /// The grasp is force closure.
    pub force_closure: bool,
}

/// Grasp type label.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GraspType {
    /// `power` when the palm holds the object (whole-hand contact); otherwise, as for every
    /// fingertip grasp, `precision` with ≤ 3 contacts and `power` with more.
    pub label: String,
    /// Number of virtual fingers: the palm's contacts as one, and the other contacts in groups
    /// of similar normals (within 60°); 2 for a pinch. 0 without contacts.
    pub opposing_virtual_fingers: usize,
}

/// Where a skill comes from.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SkillSource {
    /// Scenario (or imported file) name.
    pub scenario: String,
    /// Seed, if simulated.
    pub seed: Option<u64>,
    /// The session's `hand` and `source` metadata.
    pub metadata: BTreeMap<String, String>,
    /// Start of the skill's first phase (ns since the session start).
    pub start_ns: u64,
    /// End of the skill's last phase (ns since the session start).
    pub end_ns: u64,
}

/// The parameters of a skill, in the object frame B and independent of the hand. Read back,
/// every field but `contact_model` and `contacts` may be left out (see [`Skill`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkillParameters {
    /// The object (absent when the metadata does not describe it).
    #[serde(default)]
    pub object: Option<ObjectParams>,
    /// Contact model of the recording (`soft_finger`: point contact with friction and torsion).
    pub contact_model: ContactModel,
    /// Number of contacts.
    #[serde(default)]
    pub contact_count: usize,
    /// The contacts.
    pub contacts: Vec<ContactParams>,
    /// Mean sum of the normal forces while the object is held (N).
    #[serde(default)]
    pub internal_force_n: f64,
    /// Smallest `μ c_n − |c_t|` over the held part of the grasp (`lift` to `place`, or the
    /// whole grasp if the object was never lifted), on contacts pushing with more than 0.05 N
    /// (N); negative when a contact left its cone.
    #[serde(default)]
    pub friction_margin_n: f64,
    /// The same as a ratio `(μ c_n − |c_t|) / (μ c_n)` (1 = pure normal force, ≤ 0 = slip).
    #[serde(default)]
    pub friction_margin_ratio: f64,
    /// The object's motion relative to its pose at the start of `grasp`: key poses at every
    /// phase boundary and every [`SegmentParams::keyframe_s`] in between.
    ///
    /// [`SegmentParams::keyframe_s`]: super::SegmentParams::keyframe_s
    #[serde(default)]
    pub motion: Vec<KeyPose>,
    /// Duration of each phase (s; summed when a phase repeats), by phase name.
    #[serde(default)]
    pub phase_durations: BTreeMap<Phase, f64>,
    /// Slip events: runs of ≥ 2 ms in which a touching contact's requested intensities were
    /// outside its friction cone, merged per finger when less than 20 ms apart.
    #[serde(default)]
    pub slip_events: Vec<SlipEvent>,
    /// Grasp quality on the mean contacts (absent without contacts or μ).
    #[serde(default)]
    pub quality: Option<QualityParamsOut>,
    /// Grasp type.
    #[serde(default)]
    pub grasp_type: GraspType,
    /// Source session and span.
    #[serde(default)]
    pub source: SkillSource,
    /// Feature vector for similarity search, see [`FEATURE_DIMENSIONS`].
    #[serde(default)]
    pub feature: [f32; 16],
}

/// Meaning of each dimension of [`SkillParameters::feature`].
pub const FEATURE_DIMENSIONS: [&str; 16] = [
    "ln(mass / 1 kg)",
    "mu",
    "contact count",
    "Ferrari-Canny epsilon",
    "grasp wrench space volume^(1/6)",
    "internal force / weight",
    "hold duration (s)",
    "lift height of the object (m)",
    "horizontal transport distance of the object (m)",
    "largest rotation of the object (rad)",
    "mean |normal_b.x| of the contacts",
    "mean |normal_b.y| of the contacts",
    "mean |normal_b.z| of the contacts",
    "shape is sphere (0/1)",
    "shape is box (0/1)",
    "shape is cylinder (0/1)",
];
