//! Grasp sessions in MCAP files: the topics and metadata of a session ([`messages`]), the
//! recorder ([`SessionRecorder`], [`record_simulation`]), reading a session back
//! ([`read_session`]), importing a real glove recording ([`import`]) and exporting a session's
//! glove samples in the same format ([`export`]).
//!
//! # Layout of a session file
//!
//! Raw topics, one message per 1 kHz tick (log time = tick time, ns since the session start):
//!
//! | topic                 | schema                  | content                                  |
//! |-----------------------|-------------------------|------------------------------------------|
//! | `/glove/joint_states` | `icms.GloveJointStates` | θ measured, velocities, operator τ       |
//! | `/glove/feedback`     | `icms.GloveFeedback`    | motor commands, feedback torques, forces |
//! | `/dfs/contacts`       | `icms.Contacts`         | per finger: contact, point/normal in B, intensities, slip |
//! | `/object/state`       | `icms.ObjectState`      | pose, twist, wrenches, pose in the hand  |
//!
//! Every topic is protobuf (session format 2; [`proto`] for the raw topics; format 1, JSON,
//! is still read). Foxglove topics every [`FOXGLOVE_DECIMATION`]th tick (50 Hz), in the
//! official schemas of the Foxglove SDK: `/tf` (`foxglove.FrameTransforms`: world → hand base link, parent link → every link,
//! world → `object`), `/scene` (`foxglove.SceneUpdate`: one entity `object` in `world` with the
//! object's shape and one arrow per transmitting contact, from the contact point along the
//! force on the object, [`ARROW_M_PER_N`] m per N; and the entity [`TABLE_ENTITY`], a slab
//! whose top is the table), `/joint_states` (`foxglove.JointStates`). And once a second
//! ([`HAND_SCENE_PERIOD_TICKS`]) `/hand` (`foxglove.SceneUpdate`: one frame-locked entity per
//! link, in the link's frame, with its shapes; see [`hand_scene`]).
//!
//! Attachment: `hand.urdf` ([`HAND_URDF_ATTACHMENT`], `application/xml`), the hand's URDF with
//! the same link geometry; its link and joint names are the frame ids of `/tf`.
//!
//! Metadata records: `session` (keys `scenario`, `seed`, `hand`, `object` (JSON), `rate_hz`,
//! `software_version`, `format_version`, `started_at` (RFC 3339, UTC), `source`, and more)
//! and `ground_truth` (key `phases`: a JSON list of `{"name", "start_ns", "end_ns"}`; empty
//! for imports).
//!
//! # Scenes of several objects
//!
//! A session of a scene given as a list of objects ([`SessionInfo::scene`]) lists them in
//! its `session` record: `objects` (a JSON list, as a scenario file's, each object named) and
//! `target` (the name of the one the operator grasps, which `object` describes). Each
//! fingertip of `/dfs/contacts` says which object it touches (`object`, an index in that
//! list); `/object/state`'s main fields are the target's (`index`) and `objects` holds every
//! object's pose and velocities; `/tf` has a frame and `/scene` an entity per object (the
//! target `object`, the others `object/NAME`). At its end an [`OVERLAPS_METADATA`] record
//! counts the ticks after which two objects overlapped (`overlap_ticks`) and names the first
//! (`first_overlap_ns`, `first_overlap`); reading the session merges it into the `session`
//! record's entries.
//!
//! # Writing
//!
//! Three threads. The simulation thread only checks that a tick's numbers are finite and
//! copies its inputs (joint values, the DFS output, the base pose, on Foxglove ticks the link
//! poses) into a reused batch; a serialiser thread quantises them and writes the protobuf
//! bytes (no per-message allocation once warm); a writer thread owns the
//! [`SessionWriter`](crate::mcap_io::SessionWriter) (zstd compression and file I/O). Batches
//! of 100 ticks go through bounded channels and come back emptied for reuse.
//! [`SessionRecorder::finish`] closes the channels, joins the threads and finishes the file.
//! If anything fails midway, the file is still finished with every tick written before the
//! failure.
//!
//! # Reading
//!
//! [`stream_session_file`] and [`stream_session_bytes`] check a session in one pass and hand
//! its raw samples to a [`SessionVisitor`] as they come, holding a few decompressed chunks
//! whatever the file's length. Two threads share the work: the reading thread reads, checks
//! the CRCs, decompresses and files the records, and checks the raw topics the visitor does
//! not take (for segmentation the glove topics, read only as far as their checks need: names
//! and array lengths); the calling thread decodes and checks the ones it takes and hands them
//! on, and checks the Foxglove topics (a visitor that takes no raw topic leaves everything to
//! the reading thread). The raw topics of format 2 are decoded by a decoder of our own
//! (`session/wire/`, held to prost's by property tests) into reused SI messages: no
//! allocation per message; the Foxglove topics' messages are checked against the SDK's
//! schemas as prost would decode them, without building them (`wire::MessageCheck`, held to
//! prost likewise). [`read_session`] collects the samples into a [`Session`] for callers that
//! want them all; segmentation streams twice instead
//! ([`crate::segmentation::segment_source`]), the second time from the messages it kept from
//! the first when the session is two minutes or so at most ([`KeptMessages`]): an hour of
//! session is checked and segmented in about 4 s in 220 MB.

pub mod export;
pub mod hand_scene;
pub mod import;
pub mod messages;
pub mod proto;
mod read;
mod recorder;
mod time;
mod wire;

pub use hand_scene::{
    hand_scene_update, hand_shapes, session_hand_urdf, HAND_SCENE_PERIOD_TICKS,
    HAND_URDF_ATTACHMENT, HAND_URDF_MEDIA_TYPE, TOPIC_HAND,
};
pub use messages::*;
pub use read::{
    read_session, read_session_bytes, read_session_bytes_with, read_session_file_with,
    read_session_with_limits, stream_session_bytes, stream_session_file, DecodeTopics,
    KeptMessages, Session, SessionHead, SessionSource, SessionVisitor, KEPT_MESSAGES_BUDGET,
    MAX_CHECKED_FOXGLOVE_MESSAGE_BYTES, MAX_RAW_MESSAGE_BYTES, MAX_RAW_SCHEMA_BYTES,
    RAW_TOPIC_SKEW_NS,
};
pub use recorder::{
    record_simulation, record_simulation_until, record_ticks, record_ticks_until, AssistTopic,
    LiveView, RecordSummary, SessionInfo, SessionOut, SessionRecorder, TickData,
    ASSIST_ROBOT_RATE_HZ, OVERLAPS_METADATA, TABLE_ENTITY, TOPIC_ASSIST_EVENTS, TOPIC_ASSIST_ROBOT,
};
pub use time::rfc3339_utc;

/// Raw tick topic: glove joint states.
pub const TOPIC_GLOVE_JOINT_STATES: &str = "/glove/joint_states";
/// Raw tick topic: glove feedback.
pub const TOPIC_GLOVE_FEEDBACK: &str = "/glove/feedback";
/// Raw tick topic: contacts.
pub const TOPIC_CONTACTS: &str = "/dfs/contacts";
/// Raw tick topic: object state.
pub const TOPIC_OBJECT_STATE: &str = "/object/state";
/// Foxglove topic: frame transforms.
pub const TOPIC_TF: &str = "/tf";
/// Foxglove topic: scene (object and contact force arrows).
pub const TOPIC_SCENE: &str = "/scene";
/// Foxglove topic: joint states.
pub const TOPIC_JOINT_STATES: &str = "/joint_states";

/// The raw topics, written every tick.
pub const RAW_TOPICS: [&str; 4] = [
    TOPIC_GLOVE_JOINT_STATES,
    TOPIC_GLOVE_FEEDBACK,
    TOPIC_CONTACTS,
    TOPIC_OBJECT_STATE,
];
/// Schema names of the raw topics, in [`RAW_TOPICS`] order (the same in both formats).
pub const RAW_SCHEMA_NAMES: [&str; 4] = [
    "icms.GloveJointStates",
    "icms.GloveFeedback",
    "icms.Contacts",
    "icms.ObjectState",
];
/// The Foxglove topics, written every [`FOXGLOVE_DECIMATION`]th tick.
pub const FOXGLOVE_TOPICS: [&str; 3] = [TOPIC_TF, TOPIC_SCENE, TOPIC_JOINT_STATES];

/// Longest span of log times a session read back may cover on its raw topics (ns): two hours
/// and a minute. The longest session icms writes is an hour (`simulate --duration` and
/// scenario scripts ≤ 3600 s, glove imports ≤ 1 h; a replay adds a few seconds); files from
/// other recorders may run to two hours (the default upload limit holds three). Segmentation
/// resamples a session onto a 1 ms grid (41 bytes a millisecond: 300 MB for two hours), so an
/// unbounded span (one message with a far-future log time) would ask for terabytes.
pub const MAX_SESSION_NS: u64 = 7_260_000_000_000;

/// Foxglove topics are written on ticks whose index is a multiple of this (50 Hz at 1 kHz).
pub const FOXGLOVE_DECIMATION: u64 = 20;
/// Length of a contact force arrow in `/scene` per newton of force (m/N).
pub const ARROW_M_PER_N: f64 = 0.02;
/// Tick rate of a session (Hz).
pub const RATE_HZ: u32 = 1000;
/// Frame id of the world in `/tf` and `/scene`.
pub const WORLD_FRAME: &str = "world";
/// Frame id of the object in `/tf`.
pub const OBJECT_FRAME: &str = "object";
/// Metadata record of the session parameters.
pub const SESSION_METADATA: &str = "session";
/// Metadata record of the ground truth (`phases`).
pub const GROUND_TRUTH_METADATA: &str = "ground_truth";
