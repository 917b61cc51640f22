//! What a recording is told and what it reports: [`SessionInfo`] (the `session` record's
//! parameters), [`TickData`] (one tick of the closed loop), [`RecordSummary`], and the
//! assistant's topics ([`AssistTopic`]).

use std::collections::BTreeMap;

use dfs_core::dfs::{BodyContact, TickOutput};
use dfs_core::hand::Kinematics;
use dfs_core::math::Isometry;
use dfs_core::scenario::Scene;

use crate::mcap_io::WriteSummary;
use crate::session::*;

/// The assistant's events in a live session (`foxglove.Log`, one per event: its JSON as the
/// message, `icms.assist` as the name), shown by Foxglove's Log panel.
pub const TOPIC_ASSIST_EVENTS: &str = "/assist/events";
/// The robot hand the assistant applies a skill on (`foxglove.SceneUpdate`: its fingertips and
/// its object, drawn beside the operator's scene), at [`ASSIST_ROBOT_RATE_HZ`].
pub const TOPIC_ASSIST_ROBOT: &str = "/assist/robot";
/// Rate of [`TOPIC_ASSIST_ROBOT`] (Hz).
pub const ASSIST_ROBOT_RATE_HZ: u64 = 20;

/// A topic of the assistant, for [`SessionRecorder::log_assist`].
///
/// [`SessionRecorder::log_assist`]: super::SessionRecorder::log_assist
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AssistTopic {
    /// [`TOPIC_ASSIST_EVENTS`].
    Events,
    /// [`TOPIC_ASSIST_ROBOT`].
    Robot,
}

/// Descriptive parameters of a session, written to the `session` metadata record.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionInfo {
    /// Scenario name (or the imported file's name).
    pub scenario: String,
    /// Seed of the operator's noise (empty for imports).
    pub seed: Option<u64>,
    /// The object as JSON (the scenario file's `object`).
    pub object_json: String,
    /// Where the session comes from: `simulation` or `import-glove`.
    pub source: String,
    /// More key-value pairs for the `session` record (e.g. the whole scenario as JSON).
    pub extra: BTreeMap<String, String>,
    /// Ground-truth phases (empty when unknown).
    pub phases: Vec<GroundTruthPhase>,
    /// Wall-clock start written as `started_at`. `None` (the default): the Unix epoch, so that
    /// a simulation, a replay or an import is a pure function of its inputs and the simulator
    /// version, byte for byte (a repeated request finds the session already stored); a live
    /// recording passes the time it started.
    pub started_at: Option<std::time::SystemTime>,
    /// Height of the table's top in the world (m), shown in `/scene`; `None`: no table.
    pub table_height: Option<f64>,
    /// The URDF text the hand was built from, if any: its primitive link shapes are kept in
    /// the `hand.urdf` attachment and on `/hand` (see [`super::hand_scene`]). `None`: a
    /// built-in hand's own URDF, else shapes generated from the joints.
    ///
    /// [`super::hand_scene`]: crate::session::hand_scene
    pub hand_urdf: Option<String>,
    /// The scene, when it was given as a list of objects (a scenario's `objects`, a live
    /// session's): the `session` record then lists them (`objects`, a JSON list as a
    /// scenario's, each named, and `target`, the name of the one grasped), `/object/state`
    /// holds every object's state (its main fields the target's) and `/scene` and `/tf` show
    /// each object; at the end an [`OVERLAPS_METADATA`] record says whether and when two
    /// objects overlapped. The DFS's object indices are the scene's. `None`: one object, as
    /// the recorder's `object` and `object_json` describe it.
    pub scene: Option<Scene>,
    /// Registers the assistant's topics ([`TOPIC_ASSIST_EVENTS`], [`TOPIC_ASSIST_ROBOT`]) for
    /// [`SessionRecorder::log_assist`]: a live session with the assistant on.
    ///
    /// [`SessionRecorder::log_assist`]: super::SessionRecorder::log_assist
    pub assist_topics: bool,
}

/// Metadata record written at the end of a session of several objects (see
/// [`SessionInfo::scene`]): `overlap_ticks`, the number of ticks after which two objects
/// overlapped (objects do not act on each other, so one passed into another), and, if any,
/// `first_overlap_ns` (the session time of the first such tick) and `first_overlap` (the two
/// objects' names, comma-separated). Reading a session merges its entries into the
/// `session` record's.
pub const OVERLAPS_METADATA: &str = "overlaps";

/// One tick of the closed loop, as the recorder needs it.
#[derive(Debug, Clone, Copy)]
pub struct TickData<'a> {
    /// Tick time, ns since the session start (the messages' log time).
    pub time_ns: u64,
    /// Measured joint angles θ, one per DOF.
    pub q: &'a [f64],
    /// Operator joint torques τ, one per DOF.
    pub tau: &'a [f64],
    /// Pose of the hand's base link in the world.
    pub base: &'a Isometry,
    /// The DFS output of the tick.
    pub output: &'a TickOutput,
    /// The tick's whole-hand contacts, one per contact shape of the hand
    /// ([`Dfs::body_contacts`](dfs_core::dfs::Dfs::body_contacts)): empty without whole-hand
    /// contact. Those touching an object are recorded on `/dfs/contacts` after the fingertips.
    pub body: &'a [BodyContact],
    /// The DFS kinematics of the tick (link poses for `/tf`).
    pub kinematics: &'a Kinematics,
}

/// What a recording wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordSummary {
    /// Ticks recorded.
    pub ticks: u64,
    /// Size of the finished file (bytes).
    pub file_bytes: u64,
    /// What the MCAP writer wrote (messages per topic, chunks, ...).
    pub write: WriteSummary,
}
