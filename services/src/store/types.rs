//! Plain data types of the store: what goes in (sessions, skills) and what comes out.
//!
//! Shapes, contact models and phases are dfs-core's types here; the data base keeps their
//! names as TEXT, and the store converts at its edge (an unknown name in a row is
//! [`StoreError::Corrupt`](super::StoreError::Corrupt), naming the row and the column).

use dfs_core::contact::ContactModel;
use dfs_core::names::Named;
use dfs_core::object::ShapeKind;
use dfs_core::replay::FailureReason;
use dfs_core::scenario::Phase;
use serde::{Deserialize, Serialize};

/// Length of a skill's feature vector for similarity search.
pub const FEATURE_DIM: usize = 16;

/// The object shape of a stored session or skill: one of dfs-core's shapes, or `unknown` for
/// a session file that did not describe its object (stored before sessions had to; such
/// files are now refused). Named `sphere`, `box`, `cylinder` or `unknown` in the data base,
/// the API and on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ObjectShape {
    /// The object's shape.
    Known(ShapeKind),
    /// The session did not describe its object.
    Unknown,
}

impl Named for ObjectShape {
    const WHAT: &'static str = "shape";
    const ALL: &'static [Self] = &[
        ObjectShape::Known(ShapeKind::Sphere),
        ObjectShape::Known(ShapeKind::Box),
        ObjectShape::Known(ShapeKind::Cylinder),
        ObjectShape::Unknown,
    ];

    fn name(self) -> &'static str {
        match self {
            ObjectShape::Known(kind) => kind.name(),
            ObjectShape::Unknown => "unknown",
        }
    }
}

dfs_core::named_enum!(ObjectShape);

impl Serialize for ObjectShape {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl From<ShapeKind> for ObjectShape {
    fn from(kind: ShapeKind) -> Self {
        ObjectShape::Known(kind)
    }
}

/// Metadata of a recorded session, stored beside its MCAP blob.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionMeta {
    /// Name of the simulated operator scenario, if the session was simulated.
    pub scenario: Option<String>,
    /// Seed of the simulation, if simulated.
    pub seed: Option<u64>,
    /// Name of the hand (glove) that performed the session, e.g. `glove10`.
    pub hand: String,
    /// Object shape.
    pub object_shape: ObjectShape,
    /// Object mass, kg.
    pub object_mass: f64,
    /// Coulomb friction coefficient between fingertips and object (dimensionless).
    pub mu: f64,
    /// Length of the session, ns.
    pub duration_ns: u64,
    /// Wall-clock start time (RFC 3339), if known.
    pub started_at: Option<String>,
    /// Any further parameters (free-form JSON; `null` when none).
    pub extra: serde_json::Value,
}

/// A skill to insert: the hand-independent parameters of one grasp, in the object frame B.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NewSkill {
    /// Object shape.
    pub object_shape: ObjectShape,
    /// The name of the object it grasped in its session's scene, when the session names its
    /// objects (`params.object.name`); `None` for a session's one unnamed object.
    pub object_name: Option<String>,
    /// Object mass, kg.
    pub object_mass: f64,
    /// Coulomb friction coefficient (dimensionless).
    pub mu: f64,
    /// Number of fingertip contacts during the grasp.
    pub contact_count: i64,
    /// Contact model.
    pub contact_model: ContactModel,
    /// Grasp type label, e.g. `precision-2vf`, `power-3vf`.
    pub grasp_type: String,
    /// Ferrari-Canny ε grasp quality (largest disturbance wrench ball resisted; N or N·m scale).
    pub quality: f64,
    /// Volume of the grasp wrench space (GraspIt! volume metric).
    pub volume: f64,
    /// Duration of the skill, s.
    pub duration_s: f64,
    /// Start of the skill in its session, ns since the session's start.
    pub start_ns: i64,
    /// End of the skill in its session, ns since the session's start.
    pub end_ns: i64,
    /// Time spent in each phase: (phase, seconds), one per phase in alphabetical order of
    /// their names (as [`Phase`] orders), summed when a phase occurs more than once.
    pub phase_durations: Vec<(Phase, f64)>,
    /// Feature vector for similarity search, exactly [`FEATURE_DIM`] finite values.
    pub feature: Vec<f32>,
    /// The full hand-independent parameters (JSON object).
    pub params: serde_json::Value,
    /// The approach template recognition compares (`crate::assist::features`):
    /// `crate::assist::features::TEMPLATE_DIM` values, NaN where the reach did not show one;
    /// `None` when it could not be computed (the session's hand model is not known). Not in
    /// the JSON form (NaN is not JSON).
    #[serde(skip)]
    pub approach: Option<Vec<f32>>,
    /// The stored skill this one was recognised as (on-line learning links a grasp that matched
    /// a stored skill to it); `None`: stored as new.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matched_skill_id: Option<i64>,
}

/// A stored skill.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkillRecord {
    /// Skill id.
    pub id: i64,
    /// Id of the session the skill was found in.
    pub session_id: i64,
    /// Object shape.
    pub object_shape: ObjectShape,
    /// The name of the object it grasped in its session's scene, if the session names its
    /// objects (see [`NewSkill::object_name`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_name: Option<String>,
    /// Object mass, kg.
    pub object_mass: f64,
    /// Coulomb friction coefficient.
    pub mu: f64,
    /// Number of contacts.
    pub contact_count: i64,
    /// Contact model.
    pub contact_model: ContactModel,
    /// Grasp type label.
    pub grasp_type: String,
    /// Ferrari-Canny ε grasp quality.
    pub quality: f64,
    /// GWS volume metric.
    pub volume: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Start, ns since the session's start.
    pub start_ns: i64,
    /// End, ns since the session's start.
    pub end_ns: i64,
    /// Time spent in each phase: (phase, seconds), one per phase in alphabetical order of
    /// their names, summed when a phase occurs more than once.
    pub phase_durations: Vec<(Phase, f64)>,
    /// Feature vector ([`FEATURE_DIM`] values).
    pub feature: Vec<f32>,
    /// Full hand-independent parameters.
    pub params: serde_json::Value,
    /// The approach template recognition compares (`crate::assist::features`), `null` where
    /// the reach did not show a value; absent when it was not computed (stored before
    /// migration 0005 and not reprocessed, or a hand whose model is not known).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<Vec<Option<f32>>>,
    /// The stored skill this one was recognised as when it was stored; absent: stored as new.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matched_skill_id: Option<i64>,
    /// Version of the segmentation that made the skill (its session's, see
    /// [`crate::segmentation::SEGMENTATION_VERSION`]; 0: stored before versions were recorded).
    pub segmentation_version: u32,
    /// When the row was inserted (UTC, `YYYY-MM-DDTHH:MM:SS.sssZ`).
    pub created_at: String,
}

/// A stored session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionRecord {
    /// Session id.
    pub id: i64,
    /// Hex SHA-256 of the MCAP bytes.
    pub sha256: String,
    /// Size of the MCAP file, bytes.
    pub size_bytes: i64,
    /// Path of the MCAP blob relative to the data directory.
    pub blob_path: String,
    /// Session metadata.
    pub meta: SessionMeta,
    /// Ids of the session's skills, ascending.
    pub skill_ids: Vec<i64>,
    /// Per skill (in `skill_ids`' order): the stored skill it matched when it was stored
    /// (on-line learning linked it), `null` for a skill stored as new.
    #[serde(default)]
    pub matched_skill_ids: Vec<Option<i64>>,
    /// Version of the segmentation that made the session's skills
    /// ([`crate::segmentation::SEGMENTATION_VERSION`] when they were stored or last
    /// reprocessed; 0: stored before versions were recorded).
    pub segmentation_version: u32,
    /// When the row was inserted (UTC, `YYYY-MM-DDTHH:MM:SS.sssZ`).
    pub created_at: String,
}

/// Result of [`crate::store::Store::ingest`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct IngestOutcome {
    /// Id of the session (new or existing).
    pub session_id: i64,
    /// `true` if this call stored the session, `false` if the same bytes were already stored.
    pub created: bool,
    /// Ids of the session's skills, ascending.
    pub skill_ids: Vec<i64>,
    /// Per skill (in `skill_ids`' order): the stored skill it was recognised as, `None` for a
    /// skill stored as new ([`NewSkill::matched_skill_id`]).
    pub matched_skill_ids: Vec<Option<i64>>,
}

/// One page of results.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Page<T> {
    /// The items of this page.
    pub items: Vec<T>,
    /// Cursor for the next page; `None` on the last page.
    pub next_cursor: Option<String>,
}

/// A robot hand as listed: built-in (from code) or uploaded (a row of `hands`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HandSummary {
    /// Name, unique among built-in and uploaded hands; also the hand's id in URLs.
    pub name: String,
    /// `true` for the hands built into the binary.
    pub builtin: bool,
    /// Fingertip names, the thumb first.
    pub fingers: Vec<String>,
    /// Number of DOFs (independent joints).
    pub dof: usize,
    /// DOF names in θ order.
    pub dof_names: Vec<String>,
    /// Smallest and largest joint torque limit (N·m, N for prismatic DOFs).
    pub torque_limit: [f64; 2],
    /// When an uploaded hand was stored (UTC, `YYYY-MM-DDTHH:MM:SS.sssZ`); `None` if built in.
    pub created_at: Option<String>,
}

/// A robot hand with what it is made of.
#[derive(Debug, Clone, PartialEq)]
pub struct Hand {
    /// What lists show.
    pub summary: HandSummary,
    /// The hand spec (`None` for `glove10`, which is built in code without a URDF).
    pub spec: Option<dfs_core::hand::HandSpec>,
    /// The URDF text (`None` for `glove10`).
    pub urdf: Option<String>,
}

/// A stored replay of a skill on a hand.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Replay {
    /// Replay id.
    pub id: i64,
    /// The replayed skill.
    pub skill_id: i64,
    /// Name of the hand.
    pub hand: String,
    /// Whether the object was held (the report's `success`).
    pub success: bool,
    /// Why not.
    pub failure_reason: Option<FailureReason>,
    /// The replay report as JSON (dfs-core's `ReplayReport`).
    pub report: serde_json::Value,
    /// Hex SHA-256 of the replay's MCAP file.
    pub sha256: String,
    /// Size of the MCAP file, bytes.
    pub size_bytes: i64,
    /// Path of the MCAP blob relative to the data directory.
    pub blob_path: String,
    /// When the row was inserted (UTC, `YYYY-MM-DDTHH:MM:SS.sssZ`).
    pub created_at: String,
}

/// A session whose skills a segmentation older than the one asked about made (see
/// [`crate::store::Store::sessions_segmented_before`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StaleSession {
    /// Session id.
    pub id: i64,
    /// Version of the segmentation that made its skills (0: not recorded).
    pub segmentation_version: u32,
    /// Number of its skills.
    pub skill_count: usize,
}

/// What [`crate::store::Store::replace_session_skills`] did to one session's skills.
///
/// A stored skill identical to one of the new skills (every column the store keeps: the
/// indexed values, phase durations, feature and full parameters) is kept with its id, its
/// creation time and its replays; the others are removed with their replays, and the new
/// skills without an identical stored one are added.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReplacedSkills {
    /// Session id.
    pub session_id: i64,
    /// The segmentation version its skills had.
    pub from_version: u32,
    /// The version they have now.
    pub to_version: u32,
    /// Skills that came out the same: kept, ascending.
    pub kept_skill_ids: Vec<i64>,
    /// Skills that did not: removed with their phase rows and replays, ascending.
    pub removed_skill_ids: Vec<i64>,
    /// New skills, in the segmentation's (time) order.
    pub added_skill_ids: Vec<i64>,
    /// Replays removed with the removed skills (their MCAP files are deleted unless another
    /// row names the same bytes).
    pub replays_removed: usize,
}
