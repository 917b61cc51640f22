//! [`SessionRecorder`]: ticks of the closed loop into a session file, with the serialising and
//! the writing on threads of their own; [`record_simulation`]: a scenario run and recorded.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;

use dfs_core::dfs::{BodyContact, TickOutput};
use dfs_core::hand::{HandModel, Kinematics};
use dfs_core::math::{Isometry, Point, Rotation, Vector};
use dfs_core::object::{RigidObject, Shape};
use dfs_core::operator::Simulation;
use dfs_core::scenario::{Scenario, Scene};
use dfs_core::Stop;

use foxglove::messages as fg;
use foxglove::Encode;

use super::messages::*;
use super::proto::{GloveJointStatesProto, Quantiser, FILE_DESCRIPTOR_SET, FORMAT_VERSION};
use super::*;
use crate::error::{RecordingError, Result};
use crate::foxglove::{Pose, Quaternion, Vector3};
use crate::mcap_io::{SessionWriter, WriteSummary, WriterOptions};

/// Ticks per batch handed from the simulation thread to the serialiser thread, and from it to
/// the writer thread (a multiple of the Foxglove period).
const BATCH_TICKS: usize = 5 * FOXGLOVE_DECIMATION as usize;
/// zstd level of session files: 1. Measured on a 60 s `sphere-lift` (2026-11-26, `perf` by
/// thread, chunks compressed whole by `mcap_io::chunked`): level 3 made a 10.75 MB file with
/// 0.14 s of the writer thread's CPU, level 1 an 11.42 MB one with 0.10 s. Beside a simulation
/// of 0.15 s on the other core, a third of the writer's work is what recording's time over
/// the simulation's comes down to (BENCHMARKS.md, "Recording"); both sizes are within 12 MB
/// per minute.
const ZSTD_LEVEL: u32 = 1;
/// Batches in flight on each of the two channels (simulation → serialiser → writer).
const CHANNEL_BOUND: usize = 4;

/// Topic indices used inside batches: the raw topics, then the Foxglove topics, then the
/// assistant's (registered only when [`SessionInfo::assist_topics`]).
const ALL_TOPICS: [&str; 10] = [
    TOPIC_GLOVE_JOINT_STATES,
    TOPIC_GLOVE_FEEDBACK,
    TOPIC_CONTACTS,
    TOPIC_OBJECT_STATE,
    TOPIC_TF,
    TOPIC_SCENE,
    TOPIC_JOINT_STATES,
    TOPIC_HAND,
    TOPIC_ASSIST_EVENTS,
    TOPIC_ASSIST_ROBOT,
];

/// The assistant's events in a live session (`foxglove.Log`, one per event: its JSON as the
/// message, `icms.assist` as the name), shown by Foxglove's Log panel.
pub const TOPIC_ASSIST_EVENTS: &str = "/assist/events";
/// The robot hand the assistant applies a skill on (`foxglove.SceneUpdate`: its fingertips and
/// its object, drawn beside the operator's scene), at [`ASSIST_ROBOT_RATE_HZ`].
pub const TOPIC_ASSIST_ROBOT: &str = "/assist/robot";
/// Rate of [`TOPIC_ASSIST_ROBOT`] (Hz).
pub const ASSIST_ROBOT_RATE_HZ: u64 = 20;

/// A topic of the assistant, for [`SessionRecorder::log_assist`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AssistTopic {
    /// [`TOPIC_ASSIST_EVENTS`].
    Events,
    /// [`TOPIC_ASSIST_ROBOT`].
    Robot,
}

/// Serialised messages of several ticks: protobuf bytes back to back, and per message its
/// topic index, log time and byte range.
#[derive(Default)]
struct Batch {
    data: Vec<u8>,
    items: Vec<(u8, u64, usize, usize)>,
    /// Metadata records to write after the batch's messages.
    metadata: Vec<(String, BTreeMap<String, String>)>,
}

/// What the simulation thread keeps of one tick for the serialiser thread (besides its joint
/// values and link poses, which [`Inputs`] holds in flat arrays).
#[derive(Clone, Copy)]
struct TickInput {
    /// The tick's index among the ticks `record` accepted (0 for the first): it decides the
    /// Foxglove ticks and the `/hand` ticks.
    index: u64,
    time_ns: u64,
    /// How many values of q and of τ the tick gave (at most the DOF count; the rest of their
    /// slots is 0).
    q_len: usize,
    tau_len: usize,
    base: Isometry,
    /// How many whole-hand contacts the tick gave ([`TickData::body`]; at most the hand's
    /// contact shapes).
    body_len: usize,
}

/// The inputs of several ticks, copied on the simulation thread: nothing is computed from them
/// there. Reused: cleared and sent back by the serialiser thread.
#[derive(Default)]
struct Inputs {
    ticks: Vec<TickInput>,
    /// The DFS output of each tick (apart from [`TickInput`] so that it is copied once, with
    /// one `memcpy`, straight from the simulation's).
    outputs: Vec<TickOutput>,
    /// Per tick, `dof` slots of q then `dof` of τ.
    joints: Vec<f64>,
    /// The whole-hand contacts of each tick ([`TickInput::body_len`] each), in tick order.
    bodies: Vec<BodyContact>,
    /// The link poses of the Foxglove ticks (`links` per such tick), in tick order.
    link_poses: Vec<Isometry>,
    /// Metadata records to write after the ticks.
    metadata: Vec<(String, BTreeMap<String, String>)>,
    /// Messages encoded by the caller (the assistant's): topic index, log time, bytes.
    extras: Vec<(u8, u64, Vec<u8>)>,
}

impl Inputs {
    fn with_capacity(hand: &HandFrames) -> Self {
        Self {
            ticks: Vec::with_capacity(BATCH_TICKS),
            outputs: Vec::with_capacity(BATCH_TICKS),
            joints: Vec::with_capacity(BATCH_TICKS * 2 * hand.dof),
            bodies: Vec::with_capacity(BATCH_TICKS * hand.n_shapes),
            link_poses: Vec::with_capacity(
                BATCH_TICKS.div_ceil(FOXGLOVE_DECIMATION as usize) * hand.links,
            ),
            metadata: Vec::new(),
            extras: Vec::new(),
        }
    }

    fn is_empty(&self) -> bool {
        self.ticks.is_empty() && self.metadata.is_empty() && self.extras.is_empty()
    }

    fn clear(&mut self) {
        self.ticks.clear();
        self.outputs.clear();
        self.joints.clear();
        self.bodies.clear();
        self.link_poses.clear();
        self.metadata.clear();
        self.extras.clear();
    }
}

/// One tick as the serialisation reads it: either borrowed from the caller's [`TickData`] or
/// rebuilt from [`Inputs`] on the serialiser thread.
struct Tick<'a> {
    index: u64,
    time_ns: u64,
    q: &'a [f64],
    tau: &'a [f64],
    base: &'a Isometry,
    output: &'a TickOutput,
    /// The whole-hand contacts (empty without).
    body: &'a [BodyContact],
    /// Pose of every link (only read on Foxglove ticks; may be empty on others).
    link_poses: &'a [Isometry],
}

impl Tick<'_> {
    fn is_foxglove(&self) -> bool {
        self.index.is_multiple_of(FOXGLOVE_DECIMATION)
    }
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
    pub assist_topics: bool,
}

/// Metadata record written at the end of a session of several objects (see
/// [`SessionInfo::scene`]): `overlap_ticks`, the number of ticks after which two objects
/// overlapped (objects do not act on each other, so one passed into another), and, if any,
/// `first_overlap_ns` (the session time of the first such tick) and `first_overlap` (the two
/// objects' names, comma-separated). Reading a session merges its entries into the
/// `session` record's.
pub const OVERLAPS_METADATA: &str = "overlaps";

/// Overlaps of objects seen so far in a recording.
#[derive(Debug, Clone, Default)]
struct OverlapCount {
    ticks: u64,
    first: Option<(u64, usize, usize)>,
}

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

/// Hand structure needed for `/tf` and the per-finger messages.
#[derive(Clone)]
struct HandFrames {
    dof: usize,
    n_tips: usize,
    /// Number of contact shapes (whole-hand contacts recorded per tick, at most).
    n_shapes: usize,
    /// Number of links (link poses copied per Foxglove tick).
    links: usize,
    root: usize,
    /// Per joint: (parent link, child link).
    joints: Vec<(usize, usize)>,
}

/// Reused message instances: filled in place every tick, so that serialising the raw topics
/// allocates nothing once warm. The raw topics are filled in SI units, then quantised and
/// encoded as protobuf ([`super::proto`]); the Foxglove topics are the SDK's own types.
struct Messages {
    /// `/glove/joint_states` without its DOF names (see `names_pb`).
    joints: GloveJointStates,
    /// `/glove/feedback` without its DOF names (see `names_pb`).
    feedback: GloveFeedback,
    contacts: Contacts,
    object: messages::ObjectState,
    /// Which object fills `object`'s main fields, and whether it lists every object.
    primary: usize,
    listed: bool,
    quantiser: Quantiser,
    /// The DOF names as protobuf (`repeated string names = 1`), encoded once: the first bytes
    /// of every `/glove/joint_states` and `/glove/feedback` message (field 1 of both, so
    /// written first), the same every tick; the rest is encoded from SI messages without names.
    names_pb: Vec<u8>,
    tf: fg::FrameTransforms,
    scene: fg::SceneUpdate,
    /// The entities of the objects other than the grasped one, moved into `scene` after the
    /// table's with the first update.
    other_entities: Vec<fg::SceneEntity>,
    fox_joints: fg::JointStates,
    prev_q: Vec<f64>,
    prev_time_ns: Option<u64>,
}

/// The objects as `/scene` and `/object/state` show them.
#[derive(Clone)]
struct SceneObjects {
    /// Per object: its entity id in `/scene` and frame id in `/tf` (the grasped one's is
    /// [`OBJECT_FRAME`], the others' `object/NAME`), and its shape.
    objects: Vec<(String, Shape)>,
    /// Index of the object whose state fills `/object/state`'s main fields.
    primary: usize,
    /// Whether `/object/state` lists every object (a scene given as a list of objects).
    listed: bool,
}

impl SceneObjects {
    fn new(object: &RigidObject, scene: Option<&Scene>) -> Self {
        match scene {
            None => SceneObjects {
                objects: vec![(OBJECT_FRAME.to_owned(), object.shape)],
                primary: 0,
                listed: false,
            },
            Some(scene) => SceneObjects {
                objects: scene
                    .objects
                    .iter()
                    .enumerate()
                    .map(|(i, o)| {
                        let id = if i == scene.target {
                            OBJECT_FRAME.to_owned()
                        } else {
                            format!("{OBJECT_FRAME}/{}", o.name)
                        };
                        (id, o.object.shape)
                    })
                    .collect(),
                primary: scene.target,
                listed: true,
            },
        }
    }
}

/// The serialiser thread's state: the hand, the scene and the reused messages.
struct Serialiser {
    hand: HandFrames,
    scene: SceneObjects,
    table_height: Option<f64>,
    hand_scene: super::hand_scene::HandScene,
    msgs: Messages,
}

/// What the serialiser thread reports when its input ends.
#[derive(Default)]
struct SerialiserReport {
    /// Ticks it left out (a value too large for its field).
    refused: u64,
    /// The first of those refusals.
    first_refusal: Option<RecordingError>,
}

/// Records ticks into a session file.
///
/// Three threads share the work. The caller's thread ([`record`](Self::record)) only checks
/// that the tick's numbers are finite and copies its inputs (q, τ, the base pose, the
/// [`TickOutput`], and on Foxglove ticks the link poses) into a reused batch; a serialiser
/// thread turns batches of ticks into messages (SI messages, fixed-point quantisation,
/// protobuf) and a writer thread compresses and writes them (zstd, file I/O). Both hand-overs
/// go through bounded channels and their buffers come back for reuse, so memory is bounded and
/// nothing is allocated per tick once warm. Call [`finish`](Self::finish) to close the file and
/// see any error. Dropping an unfinished recorder finishes the file and ignores errors.
pub struct SessionRecorder {
    tx: Option<SyncSender<Inputs>>,
    recycled: Receiver<Inputs>,
    serialiser: Option<JoinHandle<SerialiserReport>>,
    writer: Option<JoinHandle<Result<WriteSummary>>>,
    inputs: Inputs,
    path: PathBuf,
    hand: HandFrames,
    /// Messages for naming the field of a tick that holds a non-finite number, on this thread:
    /// their velocities follow the ticks accepted here.
    check: Messages,
    ticks: u64,
    /// The scene's object names, when it was given as a list ([`SessionInfo::scene`]): the
    /// [`OVERLAPS_METADATA`] record is written at the end.
    object_names: Option<Vec<String>>,
    overlaps: OverlapCount,
}

impl std::fmt::Debug for SessionRecorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SessionRecorder")
            .field("path", &self.path)
            .field("ticks", &self.ticks)
            .finish_non_exhaustive()
    }
}

fn v3(v: &Vector) -> Vector3 {
    Vector3::new(v.x, v.y, v.z)
}

fn quat(r: &Rotation) -> Quaternion {
    let q = r.quaternion();
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

fn pose(iso: &Isometry) -> Pose {
    Pose {
        position: v3(&iso.translation.vector),
        orientation: quat(&iso.rotation),
    }
}

fn intensity(c: &dfs_core::contact::Intensity) -> Intensity4 {
    Intensity4 {
        x: c[0],
        y: c[1],
        z: c[2],
        torsion: c[3],
    }
}

fn wrench6(w: &dfs_core::math::Wrench) -> [f64; 6] {
    [w[0], w[1], w[2], w[3], w[4], w[5]]
}

/// Whether every number of the tick that the raw topics are computed from is finite: q, τ, the
/// base pose, and of the output those [`Messages::fill_raw`] reads (the fingertips' contact
/// frames and penetrations even when not touching, so this may say no to a tick whose
/// messages are all finite: the caller then runs the quantiser to be sure). Cheap: no
/// branch per value, no division.
fn inputs_finite(hand: &HandFrames, tick: &TickData<'_>) -> bool {
    #[inline]
    fn all(xs: &[f64]) -> bool {
        xs.iter().fold(true, |ok, x| ok & x.is_finite())
    }
    fn iso(i: &Isometry) -> bool {
        all(i.translation.vector.as_slice()) & all(i.rotation.coords.as_slice())
    }
    let n = hand.dof;
    let out = tick.output;
    for o in &out.objects[..out.n_objects.min(out.objects.len())] {
        let s = &o.state;
        if !(iso(&s.pose)
            & all(s.linear_velocity.as_slice())
            & all(s.angular_velocity_b.as_slice()))
        {
            return false;
        }
    }
    let mut ok = all(&tick.q[..tick.q.len().min(n)])
        & all(&tick.tau[..tick.tau.len().min(n)])
        & iso(tick.base)
        & all(&out.motor_q[..n])
        & all(&out.motor_qd[..n])
        & all(&out.feedback_torque[..n])
        & iso(&out.object.pose)
        & all(out.object.linear_velocity.as_slice())
        & all(out.object.angular_velocity_b.as_slice())
        & all(out.f_ext_b.as_slice())
        & all(out.object_force_b.as_slice())
        & all(out.table_force_b.as_slice());
    for tip in &out.tips[..hand.n_tips] {
        ok &= all(tip.feedback_force_world.as_slice())
            & all(tip.tip_force_world.as_slice())
            & tip.penetration.is_finite()
            & all(tip.intensity.as_slice())
            & all(tip.transmitted.as_slice())
            & all(tip.feedback.as_slice());
        if let Some(frame) = &tip.frame {
            ok &= all(frame.p_b.as_slice()) & all(frame.rot_b.matrix().as_slice());
        }
    }
    ok
}

/// A recording's Foxglove topics published as they are written, through the Foxglove SDK's
/// channels of `context` (whose sinks, such as its WebSocket server, send them on): `/tf`,
/// `/scene`, `/joint_states` and `/hand` under `prefix` (e.g. `/live/3/tf`), with the SDK's
/// schemas, at the topics' 50 Hz, a batch at a time (every 0.1 s of session). The channels
/// close when the recording ends.
pub struct LiveView {
    /// Per topic of [`ALL_TOPICS`] the channel it is published on (the Foxglove topics only).
    channels: Vec<Option<Arc<foxglove::RawChannel>>>,
    /// Added to a message's log time (the session's time) for the channel: the wall-clock
    /// start of the session (ns since the Unix epoch).
    epoch_ns: u64,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let topics: Vec<&str> = self.channels.iter().flatten().map(|c| c.topic()).collect();
        f.debug_struct("LiveView").field("topics", &topics).finish()
    }
}

impl LiveView {
    /// Channels under `prefix` in `context`, logging at `epoch_ns` plus the session time.
    pub fn new(context: &Arc<foxglove::Context>, prefix: &str, epoch_ns: u64) -> Result<LiveView> {
        let schemas = [
            None,
            None,
            None,
            None,
            fg::FrameTransforms::get_schema(),
            fg::SceneUpdate::get_schema(),
            fg::JointStates::get_schema(),
            fg::SceneUpdate::get_schema(),
            fg::Log::get_schema(),
            fg::SceneUpdate::get_schema(),
        ];
        let mut channels = Vec::with_capacity(ALL_TOPICS.len());
        for (topic, schema) in ALL_TOPICS.iter().zip(schemas) {
            let Some(schema) = schema else {
                channels.push(None);
                continue;
            };
            let channel = foxglove::ChannelBuilder::new(format!("{prefix}{topic}"))
                .context(context)
                .message_encoding("protobuf")
                .schema(schema)
                .build_raw()
                .map_err(|e| RecordingError::Serialize {
                    topic: format!("{prefix}{topic}"),
                    detail: format!("the live view's channel: {e}"),
                })?;
            channels.push(Some(channel));
        }
        Ok(LiveView { channels, epoch_ns })
    }

    fn publish(&self, topic: u8, log_time: u64, bytes: &[u8]) {
        if let Some(Some(ch)) = self.channels.get(usize::from(topic)) {
            if ch.has_sinks() {
                ch.log_with_meta(
                    bytes,
                    foxglove::PartialMetadata::with_log_time(self.epoch_ns + log_time),
                );
            }
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        for ch in self.channels.iter().flatten() {
            ch.close();
        }
    }
}

/// Where a recording goes.
pub enum SessionOut<'a> {
    /// A file, created (truncated), synced as it is written and when finished.
    File(&'a Path),
    /// Any writer, written front to back (never read or seeked); `name` names it in errors
    /// and summaries. Syncing it is its owner's business.
    Stream {
        /// The writer.
        out: Box<dyn std::io::Write + Send>,
        /// What to call it.
        name: PathBuf,
    },
}

impl<'a> From<&'a Path> for SessionOut<'a> {
    fn from(path: &'a Path) -> Self {
        SessionOut::File(path)
    }
}

impl<'a> From<&'a PathBuf> for SessionOut<'a> {
    fn from(path: &'a PathBuf) -> Self {
        SessionOut::File(path)
    }
}

impl std::fmt::Debug for SessionOut<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SessionOut::File(path) => f.debug_tuple("File").field(path).finish(),
            SessionOut::Stream { name, .. } => {
                f.debug_struct("Stream").field("name", name).finish()
            }
        }
    }
}

impl SessionRecorder {
    /// The writer's options: zstd at [`ZSTD_LEVEL`], no message indexes.
    fn writer_options() -> WriterOptions {
        WriterOptions {
            compression_level: ZSTD_LEVEL,
            message_indexes: false,
            ..WriterOptions::default()
        }
    }

    /// Creates `out` (truncating it), writes the `session` and `ground_truth` metadata and the
    /// channels, and starts the serialiser and writer threads. The file is synced as it is
    /// written (each second of session) and at [`finish`](Self::finish).
    pub fn create(
        out: impl AsRef<Path>,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
    ) -> Result<Self> {
        let path = out.as_ref().to_path_buf();
        let writer = SessionWriter::create_with_options(&path, Self::writer_options())?;
        Self::start(writer, hand, object, info)
    }

    /// [`create`](Self::create) into a file or any [`Write`](std::io::Write) (a socket, a
    /// pipe, a store's staging file, memory): the session is written front to back, each chunk
    /// whole, and nothing is ever read back or seeked.
    pub fn create_to(
        out: SessionOut<'_>,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
    ) -> Result<Self> {
        Self::create_with_view(out, hand, object, info, None)
    }

    /// [`create_to`](Self::create_to), publishing the Foxglove topics as they are written
    /// through `view` too (a live session watched in the Foxglove app).
    pub fn create_with_view(
        out: SessionOut<'_>,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
        view: Option<LiveView>,
    ) -> Result<Self> {
        let writer = match out {
            SessionOut::File(path) => {
                SessionWriter::create_with_options(path, Self::writer_options())?
            }
            SessionOut::Stream { out, name } => {
                SessionWriter::to_stream(out, name, Self::writer_options())?
            }
        };
        Self::start_viewed(writer, hand, object, info, view)
    }

    fn start(
        writer: SessionWriter,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
    ) -> Result<Self> {
        Self::start_viewed(writer, hand, object, info, None)
    }

    fn start_viewed(
        mut writer: SessionWriter,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
        view: Option<LiveView>,
    ) -> Result<Self> {
        let path = writer.path().to_path_buf();
        let mut meta = BTreeMap::new();
        meta.insert("scenario".to_owned(), info.scenario.clone());
        meta.insert(
            "seed".to_owned(),
            info.seed.map(|s| s.to_string()).unwrap_or_default(),
        );
        meta.insert("hand".to_owned(), hand.name.clone());
        meta.insert("object".to_owned(), info.object_json.clone());
        meta.insert("rate_hz".to_owned(), RATE_HZ.to_string());
        meta.insert(
            "software_version".to_owned(),
            env!("CARGO_PKG_VERSION").to_owned(),
        );
        meta.insert(
            "started_at".to_owned(),
            rfc3339_utc(info.started_at.unwrap_or(std::time::UNIX_EPOCH)),
        );
        meta.insert("source".to_owned(), info.source.clone());
        meta.insert("format_version".to_owned(), FORMAT_VERSION.to_string());
        meta.insert(
            "foxglove_rate_hz".to_owned(),
            (u64::from(RATE_HZ) / FOXGLOVE_DECIMATION).to_string(),
        );
        if let Some(scene) = &info.scene {
            let named: Vec<_> = scene
                .objects
                .iter()
                .map(|o| dfs_core::scenario::ScenarioObject {
                    name: Some(o.name.clone()),
                    ..o.spec.clone()
                })
                .collect();
            let json = |e: serde_json::Error| RecordingError::Serialize {
                topic: SESSION_METADATA.to_owned(),
                detail: e.to_string(),
            };
            meta.insert(
                "objects".to_owned(),
                serde_json::to_string(&named).map_err(json)?,
            );
            meta.insert("target".to_owned(), scene.target().name.clone());
            if info.object_json.is_empty() {
                meta.insert(
                    "object".to_owned(),
                    serde_json::to_string(&named[scene.target]).map_err(json)?,
                );
            }
        }
        for (k, v) in &info.extra {
            meta.entry(k.clone()).or_insert_with(|| v.clone());
        }
        writer.add_metadata(SESSION_METADATA, meta)?;
        let phases =
            serde_json::to_string(&info.phases).map_err(|e| RecordingError::Serialize {
                topic: GROUND_TRUTH_METADATA.to_owned(),
                detail: e.to_string(),
            })?;
        writer.add_metadata(
            GROUND_TRUTH_METADATA,
            BTreeMap::from([("phases".to_owned(), phases)]),
        )?;
        for (topic, schema) in RAW_TOPICS.iter().zip(RAW_SCHEMA_NAMES) {
            writer.register_protobuf_channel(topic, schema, FILE_DESCRIPTOR_SET)?;
        }
        register_foxglove::<fg::FrameTransforms>(&mut writer, TOPIC_TF)?;
        register_foxglove::<fg::SceneUpdate>(&mut writer, TOPIC_SCENE)?;
        register_foxglove::<fg::JointStates>(&mut writer, TOPIC_JOINT_STATES)?;
        if info.assist_topics {
            register_foxglove::<fg::Log>(&mut writer, TOPIC_ASSIST_EVENTS)?;
            register_foxglove::<fg::SceneUpdate>(&mut writer, TOPIC_ASSIST_ROBOT)?;
        }
        let hand_scene =
            super::hand_scene::HandScene::create(&mut writer, hand, info.hand_urdf.as_deref())?;

        let frames = HandFrames {
            dof: hand.dof(),
            n_tips: hand.fingertips.len(),
            n_shapes: hand.contact_shapes.len(),
            links: hand.links.len(),
            root: hand.root,
            joints: hand.joints.iter().map(|j| (j.parent, j.child)).collect(),
        };
        let scene = SceneObjects::new(object, info.scene.as_ref());
        let serialiser = Serialiser {
            hand: frames.clone(),
            table_height: info.table_height,
            hand_scene,
            msgs: Messages::new(hand, &scene),
            scene: scene.clone(),
        };

        // Emptied buffers go back on channels of their own, bounded too (they hold at most
        // the buffers in flight, and a bounded channel allocates nothing per message).
        let (batch_tx, batch_rx) = sync_channel::<Batch>(CHANNEL_BOUND);
        let (batch_recycle_tx, batch_recycled) = sync_channel::<Batch>(CHANNEL_BOUND + 2);
        let writer = std::thread::Builder::new()
            .name("icms-session-writer".into())
            .spawn(move || writer_thread(writer, batch_rx, batch_recycle_tx, view))
            .map_err(|e| RecordingError::io("starting the session writer thread", e))?;
        let (tx, rx) = sync_channel::<Inputs>(CHANNEL_BOUND);
        let (recycle_tx, recycled) = sync_channel::<Inputs>(CHANNEL_BOUND + 2);
        let serialiser = match std::thread::Builder::new()
            .name("icms-session-serialiser".into())
            .spawn(move || serialiser.run(rx, recycle_tx, batch_tx, batch_recycled))
        {
            Ok(handle) => handle,
            Err(e) => {
                // The writer thread sees its channel closed and finishes the file.
                let _ = writer.join();
                return Err(RecordingError::io(
                    "starting the session serialiser thread",
                    e,
                ));
            }
        };

        Ok(Self {
            tx: Some(tx),
            recycled,
            serialiser: Some(serialiser),
            writer: Some(writer),
            inputs: Inputs::with_capacity(&frames),
            path,
            check: Messages::new(hand, &scene),
            hand: frames,
            ticks: 0,
            object_names: info
                .scene
                .as_ref()
                .map(|s| s.objects.iter().map(|o| o.name.clone()).collect()),
            overlaps: OverlapCount::default(),
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Ticks recorded so far (accepted by [`record`](Self::record)).
    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    /// Records one tick: the raw topics always, the Foxglove topics when the tick index is a
    /// multiple of [`FOXGLOVE_DECIMATION`].
    ///
    /// Fails with [`RecordingError::NonFiniteNumber`], naming the topic and field, if a value
    /// is NaN or infinite: nothing of the tick is written then, its velocities are not taken
    /// as the next tick's reference, and the recorder goes on with the next tick. Fails with
    /// the writer thread's error if it failed.
    ///
    /// This thread only checks and copies the tick; its messages are made on the serialiser
    /// thread. A finite value too large for its fixed-point field (beyond ±2³¹ steps: a force
    /// over 2.1·10⁶ N, a moment over 2147 N·m, a penetration over 2.1 m, a joint velocity over
    /// 2.1·10⁷ rad/s, ...) is found there: that tick is left out just the same (nothing of it is
    /// written, the next velocities are taken from the tick before it), the recording goes on,
    /// and [`finish`](Self::finish) reports the first such refusal as
    /// [`RecordingError::NonFiniteNumber`] (value "… (beyond the field's range)") after
    /// finishing the file.
    pub fn record(&mut self, tick: &TickData<'_>) -> Result<()> {
        let n = self.hand.dof;
        let (q, tau) = (
            &tick.q[..tick.q.len().min(n)],
            &tick.tau[..tick.tau.len().min(n)],
        );
        let view = Tick {
            index: self.ticks,
            time_ns: tick.time_ns,
            q,
            tau,
            base: tick.base,
            output: tick.output,
            body: &tick.body[..tick.body.len().min(self.hand.n_shapes)],
            link_poses: &tick.kinematics.link_poses[..self.hand.links],
        };
        if !inputs_finite(&self.hand, tick) {
            // Name the field as the serialisation would (if none is refused, the non-finite
            // number is one no message carries, and the tick is recorded).
            self.check.raw_topics(&self.hand, &view, None)?;
        }
        let foxglove = view.is_foxglove();
        if foxglove {
            timestamp(tick.time_ns)?;
        }
        self.check.advance(&view);

        let inputs = &mut self.inputs;
        inputs.ticks.push(TickInput {
            index: self.ticks,
            time_ns: tick.time_ns,
            q_len: q.len(),
            tau_len: tau.len(),
            base: *tick.base,
            body_len: view.body.len(),
        });
        inputs.bodies.extend_from_slice(view.body);
        inputs
            .outputs
            .extend_from_slice(std::slice::from_ref(tick.output));
        inputs.joints.extend_from_slice(q);
        inputs
            .joints
            .resize(inputs.joints.len() + (n - q.len()), 0.0);
        inputs.joints.extend_from_slice(tau);
        inputs
            .joints
            .resize(inputs.joints.len() + (n - tau.len()), 0.0);
        if foxglove {
            inputs.link_poses.extend_from_slice(view.link_poses);
        }
        if let Some((i, j)) = tick.output.overlap {
            self.overlaps.ticks += 1;
            self.overlaps.first.get_or_insert((tick.time_ns, i, j));
        }
        self.ticks += 1;
        if self.inputs.ticks.len() >= BATCH_TICKS {
            self.send_inputs()?;
        }
        Ok(())
    }

    /// Logs a message of the assistant's `topic` at session time `t_ns` (written with the
    /// ticks recorded so far; ignored unless the session was created with
    /// [`SessionInfo::assist_topics`]).
    pub fn log_assist(&mut self, topic: AssistTopic, t_ns: u64, msg: &impl prost::Message) {
        let index = match topic {
            AssistTopic::Events => 8,
            AssistTopic::Robot => 9,
        };
        self.inputs.extras.push((index, t_ns, msg.encode_to_vec()));
    }

    /// Adds a metadata record (written after the ticks recorded so far), for records only
    /// known at the end such as a replay's report.
    pub fn add_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        self.inputs.metadata.push((name.to_owned(), metadata));
        self.send_inputs()
    }

    fn send_inputs(&mut self) -> Result<()> {
        if self.inputs.is_empty() {
            return Ok(());
        }
        let next = match self.recycled.try_recv() {
            Ok(inputs) => inputs,
            Err(_) => Inputs::with_capacity(&self.hand),
        };
        let full = std::mem::replace(&mut self.inputs, next);
        let sent = match &self.tx {
            Some(tx) => tx.send(full).is_ok(),
            None => false,
        };
        if !sent {
            // A thread stopped: report why.
            return Err(self.join().err().unwrap_or(RecordingError::WriterClosed {
                path: self.path.clone(),
            }));
        }
        Ok(())
    }

    /// Closes the channel to the serialiser thread and waits for both threads: the writer's
    /// error first, then the first tick the serialiser refused.
    fn join(&mut self) -> Result<WriteSummary> {
        self.tx = None;
        let report = match self.serialiser.take() {
            Some(handle) => handle.join().ok(),
            None => Some(SerialiserReport::default()),
        };
        let written = match self.writer.take() {
            Some(handle) => handle
                .join()
                .unwrap_or(Err(RecordingError::WriterThreadPanicked)),
            None => Err(RecordingError::WriterClosed {
                path: self.path.clone(),
            }),
        };
        let report = report.ok_or(RecordingError::WriterThreadPanicked)?;
        let write = written?;
        self.ticks -= report.refused;
        match report.first_refusal {
            Some(e) => Err(e),
            None => Ok(write),
        }
    }

    /// Writes the remaining ticks, finishes the file (summary, footer, sync) on the writer
    /// thread and reports what was written. If the serialiser thread left out a tick (a value
    /// beyond its field's range, see [`record`](Self::record)), the file is finished all the
    /// same, without that tick, and the error is the first such refusal.
    pub fn finish(mut self) -> Result<RecordSummary> {
        if let Some(names) = self.object_names.take() {
            let o = &self.overlaps;
            let mut record = BTreeMap::from([("overlap_ticks".to_owned(), o.ticks.to_string())]);
            if let Some((t, i, j)) = o.first {
                let name = |k: usize| names.get(k).cloned().unwrap_or_else(|| k.to_string());
                record.insert("first_overlap_ns".to_owned(), t.to_string());
                record.insert(
                    "first_overlap".to_owned(),
                    format!("{},{}", name(i), name(j)),
                );
            }
            self.inputs
                .metadata
                .push((OVERLAPS_METADATA.to_owned(), record));
        }
        self.send_inputs()?;
        let write = self.join()?;
        Ok(RecordSummary {
            ticks: self.ticks,
            file_bytes: write.bytes,
            write,
        })
    }
}

impl Drop for SessionRecorder {
    fn drop(&mut self) {
        if self.serialiser.is_some() || self.writer.is_some() {
            let _ = self.send_inputs();
            let _ = self.join();
        }
    }
}

impl Serialiser {
    /// Turns batches of tick inputs into batches of messages for the writer thread, until the
    /// input channel closes or the writer thread stops.
    fn run(
        mut self,
        rx: Receiver<Inputs>,
        recycle: SyncSender<Inputs>,
        tx: SyncSender<Batch>,
        recycled: Receiver<Batch>,
    ) -> SerialiserReport {
        let mut report = SerialiserReport::default();
        let (n, links) = (self.hand.dof, self.hand.links);
        for mut inputs in rx {
            let mut batch = recycled.try_recv().unwrap_or_else(|_| Batch {
                data: Vec::with_capacity(256 * 1024),
                items: Vec::with_capacity(BATCH_TICKS * (RAW_TOPICS.len() + 1)),
                metadata: Vec::new(),
            });
            let (mut poses, mut bodies) = (0, 0);
            for (k, (input, output)) in inputs.ticks.iter().zip(&inputs.outputs).enumerate() {
                let joints = &inputs.joints[2 * n * k..2 * n * (k + 1)];
                let mut tick = Tick {
                    index: input.index,
                    time_ns: input.time_ns,
                    q: &joints[..input.q_len],
                    tau: &joints[n..n + input.tau_len],
                    base: &input.base,
                    output,
                    body: &inputs.bodies[bodies..bodies + input.body_len],
                    link_poses: &[],
                };
                bodies += input.body_len;
                if tick.is_foxglove() {
                    tick.link_poses = &inputs.link_poses[poses..poses + links];
                    poses += links;
                }
                let (start_items, start_data) = (batch.items.len(), batch.data.len());
                if let Err(e) = self.serialise_tick(&tick, &mut batch) {
                    batch.items.truncate(start_items);
                    batch.data.truncate(start_data);
                    report.refused += 1;
                    report.first_refusal.get_or_insert(e);
                }
            }
            for (topic, t, bytes) in inputs.extras.drain(..) {
                let start = batch.data.len();
                batch.data.extend_from_slice(&bytes);
                batch.items.push((topic, t, start, batch.data.len()));
            }
            batch.metadata.append(&mut inputs.metadata);
            inputs.clear();
            let _ = recycle.try_send(inputs);
            if tx.send(batch).is_err() {
                // The writer thread stopped: its own result says why.
                break;
            }
        }
        report
    }

    /// All the messages of one tick at the end of `batch`; on an error, the batch holds part of
    /// them (the caller cuts them off) and the velocities' reference is left as it was.
    fn serialise_tick(&mut self, tick: &Tick<'_>, batch: &mut Batch) -> Result<()> {
        let t = tick.time_ns;
        let m = &mut self.msgs;
        m.raw_topics(&self.hand, tick, Some(batch))?;
        if tick.is_foxglove() {
            m.fill_foxglove(&self.hand, &self.scene, self.table_height, tick)?;
            push(batch, 4, t, &m.tf);
            push(batch, 5, t, &m.scene);
            push(batch, 6, t, &m.fox_joints);
            if let Some(hand) = self.hand_scene.due(tick.index, t) {
                push(batch, 7, t, hand);
            }
        }
        m.advance(tick);
        Ok(())
    }
}

/// Encodes `msg` (protobuf) at the end of the batch.
fn push<M: prost::Message>(batch: &mut Batch, topic: u8, t: u64, msg: &M) {
    let start = batch.data.len();
    msg.encode_raw(&mut batch.data);
    batch.items.push((topic, t, start, batch.data.len()));
}

/// The quantiser's refusal as the recorder's error: a value of raw topic `topic` that is not
/// finite or too large for its field (nothing of the tick is written then).
fn refused(q: &Quantiser, topic: u8) -> Result<()> {
    match &q.refused {
        None => Ok(()),
        Some((field, value)) => Err(RecordingError::NonFiniteNumber {
            topic: ALL_TOPICS[topic as usize].to_owned(),
            path: field.clone(),
            value: if value.is_finite() {
                format!("{value} (beyond the field's range)")
            } else {
                value.to_string()
            },
        }),
    }
}

/// Registers a Foxglove topic with the SDK's schema of `T` (a `FileDescriptorSet` of the
/// official `.proto`).
fn register_foxglove<T: Encode>(writer: &mut SessionWriter, topic: &str) -> Result<()> {
    let schema = T::get_schema().ok_or_else(|| RecordingError::Serialize {
        topic: topic.to_owned(),
        detail: "the Foxglove SDK has no schema for it".to_owned(),
    })?;
    writer.register_protobuf_channel(topic, &schema.name, &schema.data)
}

fn writer_thread(
    mut writer: SessionWriter,
    rx: Receiver<Batch>,
    recycle: SyncSender<Batch>,
    view: Option<LiveView>,
) -> Result<WriteSummary> {
    // The assistant's topics are registered only in sessions that have them.
    let handles: Vec<_> = ALL_TOPICS.iter().map(|t| writer.topic(t).ok()).collect();
    for mut batch in rx {
        for &(topic, t, start, end) in &batch.items {
            let Some(handle) = handles[topic as usize] else {
                continue;
            };
            writer.write_to(handle, t, &batch.data[start..end])?;
            if let Some(view) = &view {
                view.publish(topic, t, &batch.data[start..end]);
            }
        }
        for (name, metadata) in batch.metadata.drain(..) {
            writer.add_metadata(&name, metadata)?;
        }
        batch.data.clear();
        batch.items.clear();
        let _ = recycle.try_send(batch);
    }
    writer.finish()
}

impl Messages {
    fn new(hand: &HandModel, scene: &SceneObjects) -> Self {
        let n = hand.dof();
        let names = hand.dof_names.clone();
        let tip_names: Vec<String> = hand.fingertips.iter().map(|t| t.name.clone()).collect();
        let joints = GloveJointStates {
            names: names.clone(),
            positions: vec![0.0; n],
            velocities: vec![0.0; n],
            efforts: vec![0.0; n],
        };
        let feedback = GloveFeedback {
            names: names.clone(),
            motor_positions: vec![0.0; n],
            motor_velocities: vec![0.0; n],
            feedback_torques: vec![0.0; n],
            fingers: tip_names
                .iter()
                .map(|name| FingerFeedback {
                    name: name.clone(),
                    ..FingerFeedback::default()
                })
                .collect(),
        };
        // The fingertips, then one entry per contact shape (encoded only while it touches).
        let contacts = Contacts {
            n_contacts: 0,
            fingers: tip_names
                .iter()
                .map(|name| FingerContact {
                    name: name.clone(),
                    ..FingerContact::default()
                })
                .chain(hand.contact_shapes.iter().map(|s| {
                    FingerContact {
                        name: s.name.clone(),
                        part: ContactPart::of_body(s.part),
                        link: hand
                            .links
                            .get(s.link)
                            .map(|l| l.name.clone())
                            .unwrap_or_default(),
                        ..FingerContact::default()
                    }
                }))
                .collect(),
        };
        let root_name = hand.links[hand.root].name.clone();
        let transform = |parent: &str, child: &str| fg::FrameTransform {
            parent_frame_id: parent.to_owned(),
            child_frame_id: child.to_owned(),
            ..fg::FrameTransform::default()
        };
        let mut transforms = vec![transform(WORLD_FRAME, &root_name)];
        transforms.extend(
            hand.joints
                .iter()
                .map(|j| transform(&hand.links[j.parent].name, &hand.links[j.child].name)),
        );
        transforms.push(transform(WORLD_FRAME, OBJECT_FRAME));
        for (i, (id, _)) in scene.objects.iter().enumerate() {
            if i != scene.primary {
                transforms.push(transform(WORLD_FRAME, id));
            }
        }
        let entity = |id: &str| fg::SceneEntity {
            frame_id: WORLD_FRAME.to_owned(),
            id: id.to_owned(),
            frame_locked: false,
            ..fg::SceneEntity::default()
        };
        // The grasped object (with the contact forces) first, then the table (added with the
        // first update, see `fill_foxglove`) and the other objects.
        let entities = vec![entity(OBJECT_FRAME)];
        let others: Vec<fg::SceneEntity> = scene
            .objects
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != scene.primary)
            .map(|(_, (id, _))| entity(id))
            .collect();
        let fox_joints = fg::JointStates {
            timestamp: None,
            joints: names
                .iter()
                .map(|name| fg::JointState {
                    name: name.clone(),
                    position: Some(0.0),
                    velocity: Some(0.0),
                    acceleration: None,
                    effort: Some(0.0),
                })
                .collect(),
        };
        // The DOF names encoded once, and left out of the SI messages.
        let names_pb = prost::Message::encode_to_vec(&GloveJointStatesProto {
            names: joints.names.clone(),
            ..GloveJointStatesProto::default()
        });
        let (mut joints, mut feedback) = (joints, feedback);
        joints.names.clear();
        feedback.names.clear();
        Self {
            quantiser: Quantiser::default(),
            names_pb,
            joints,
            feedback,
            contacts,
            object: messages::ObjectState {
                objects: if scene.listed {
                    vec![messages::SceneObjectState::default(); scene.objects.len()]
                } else {
                    Vec::new()
                },
                index: scene.primary as u32,
                ..messages::ObjectState::default()
            },
            primary: scene.primary,
            listed: scene.listed,
            other_entities: others,
            tf: fg::FrameTransforms { transforms },
            scene: fg::SceneUpdate {
                deletions: Vec::new(),
                entities,
            },
            fox_joints,
            prev_q: vec![0.0; n],
            prev_time_ns: None,
        }
    }

    /// Fills the raw topics of `tick` and quantises them, encoding each at the end of `batch`
    /// if one is given; the first value the quantiser refuses is the error (the batch then
    /// holds the topics before its own).
    fn raw_topics(
        &mut self,
        hand: &HandFrames,
        tick: &Tick<'_>,
        batch: Option<&mut Batch>,
    ) -> Result<()> {
        let t = tick.time_ns;
        self.fill_raw(hand, tick);
        let q = &mut self.quantiser;
        q.refused = None;
        // Without a batch (naming a refused field), the messages go to a buffer of their own.
        let mut spare = Vec::new();
        let (data, mut items) = match batch {
            Some(b) => (&mut b.data, Some(&mut b.items)),
            None => (&mut spare, None),
        };
        for topic in 0..RAW_TOPICS.len() as u8 {
            let start = data.len();
            match topic {
                0 => {
                    data.extend_from_slice(&self.names_pb);
                    q.encode_joint_states(&self.joints, data);
                }
                1 => {
                    data.extend_from_slice(&self.names_pb);
                    q.encode_feedback(&self.feedback, data);
                }
                2 => q.encode_contacts(&self.contacts, data),
                _ => q.encode_object(&self.object, data),
            }
            refused(q, topic)?;
            if let Some(items) = items.as_deref_mut() {
                items.push((topic, t, start, data.len()));
            }
        }
        Ok(())
    }

    fn fill_raw(&mut self, hand: &HandFrames, tick: &Tick<'_>) {
        let n = hand.dof;
        let out = tick.output;
        let dt = match self.prev_time_ns {
            Some(prev) if tick.time_ns > prev => (tick.time_ns - prev) as f64 * 1e-9,
            _ => 0.0,
        };
        for i in 0..n {
            let q = tick.q.get(i).copied().unwrap_or(0.0);
            self.joints.positions[i] = q;
            self.joints.velocities[i] = if dt > 0.0 {
                (q - self.prev_q[i]) / dt
            } else {
                0.0
            };
            self.joints.efforts[i] = tick.tau.get(i).copied().unwrap_or(0.0);
            self.feedback.motor_positions[i] = out.motor_q[i];
            self.feedback.motor_velocities[i] = out.motor_qd[i];
            self.feedback.feedback_torques[i] = out.feedback_torque[i];
        }
        self.contacts.n_contacts = out.n_contacts as u32;
        for k in 0..hand.n_tips {
            let tip = &out.tips[k];
            let fb = &mut self.feedback.fingers[k];
            fb.feedback_force_world = v3(&tip.feedback_force_world);
            fb.tip_force_world = v3(&tip.tip_force_world);
            let c = &mut self.contacts.fingers[k];
            c.touching = tip.touching;
            c.in_contact = tip.in_contact;
            match (&tip.frame, tip.touching) {
                (Some(frame), true) => {
                    c.point_b = v3(&frame.p_b);
                    c.normal_b = v3(&frame.normal_b());
                    c.penetration = tip.penetration;
                }
                _ => {
                    c.point_b = Vector3::default();
                    c.normal_b = Vector3::default();
                    c.penetration = 0.0;
                }
            }
            c.intensity = intensity(&tip.intensity);
            c.transmitted = intensity(&tip.transmitted);
            c.feedback = intensity(&tip.feedback);
            c.slip = tip.slip;
            c.in_cone = !tip.slip;
            c.object = if tip.touching { tip.object as u32 } else { 0 };
        }
        // Whole-hand contacts: a palm or phalanx pushes with its spring, so its intensity is
        // what it transmits; it has no feedback of its own (the hand feels it through Jᵀ).
        let none = BodyContact::default();
        for s in 0..hand.n_shapes {
            let b = tick.body.get(s).unwrap_or(&none);
            let c = &mut self.contacts.fingers[hand.n_tips + s];
            c.touching = b.touching;
            c.in_contact = b.in_contact;
            match (&b.frame, b.touching) {
                (Some(frame), true) => {
                    c.point_b = v3(&frame.p_b);
                    c.normal_b = v3(&frame.normal_b());
                    c.penetration = b.penetration;
                }
                _ => {
                    c.point_b = Vector3::default();
                    c.normal_b = Vector3::default();
                    c.penetration = 0.0;
                }
            }
            c.intensity = intensity(&b.transmitted);
            c.transmitted = intensity(&b.transmitted);
            c.slip = b.slip;
            c.in_cone = !b.slip;
            c.object = if b.touching { b.object as u32 } else { 0 };
        }
        let o = &mut self.object;
        let main = &out.objects[self.primary];
        o.pose = pose(&main.state.pose);
        o.linear_velocity = v3(&main.state.linear_velocity);
        o.angular_velocity_b = v3(&main.state.angular_velocity_b);
        o.f_ext_b = wrench6(&main.f_ext_b);
        o.object_force_b = wrench6(&main.object_force_b);
        o.table_force_b = wrench6(&main.table_force_b);
        o.pose_in_hand = pose(&(tick.base.inverse() * main.state.pose));
        if self.listed {
            for (entry, each) in o.objects.iter_mut().zip(&out.objects) {
                entry.pose = pose(&each.state.pose);
                entry.linear_velocity = v3(&each.state.linear_velocity);
                entry.angular_velocity_b = v3(&each.state.angular_velocity_b);
            }
        }
    }

    /// The tick just recorded becomes the one the next velocities are taken from (not called
    /// for a refused tick, which records nothing).
    fn advance(&mut self, tick: &Tick<'_>) {
        for (prev, &q) in self.prev_q.iter_mut().zip(tick.q) {
            *prev = q;
        }
        self.prev_time_ns = Some(tick.time_ns);
    }

    fn fill_foxglove(
        &mut self,
        hand: &HandFrames,
        scene: &SceneObjects,
        table_height: Option<f64>,
        tick: &Tick<'_>,
    ) -> Result<()> {
        let stamp = Some(timestamp(tick.time_ns)?);
        let link_poses = tick.link_poses;
        let out = tick.output;
        let tfs = &mut self.tf.transforms;
        let set = |tf: &mut fg::FrameTransform, iso: &Isometry| {
            tf.timestamp = stamp;
            tf.translation = Some(fg_vector(&iso.translation.vector));
            tf.rotation = Some(fg_quaternion(&iso.rotation));
        };
        set(&mut tfs[0], &link_poses[hand.root]);
        for (j, &(parent, child)) in hand.joints.iter().enumerate() {
            let rel = link_poses[parent].inverse() * link_poses[child];
            set(&mut tfs[1 + j], &rel);
        }
        // The grasped object's frame, then the others' in the scene's order.
        let first = 1 + hand.joints.len();
        set(&mut tfs[first], &out.objects[scene.primary].state.pose);
        let others = (0..scene.objects.len()).filter(|&i| i != scene.primary);
        for (k, i) in others.enumerate() {
            set(&mut tfs[first + 1 + k], &out.objects[i].state.pose);
        }

        // The table: a slab of TABLE_SIZE_M square under the world origin, its top at the
        // table's height (in every update, so that a viewer opening the file mid-way sees it).
        // Entities: the grasped object, the table, the other objects.
        let size = |x: f64, y: f64, z: f64| Some(fg::Vector3 { x, y, z });
        if self.scene.entities.len() == 1 {
            if table_height.is_some() {
                self.scene.entities.push(fg::SceneEntity {
                    frame_id: WORLD_FRAME.to_owned(),
                    id: TABLE_ENTITY.to_owned(),
                    ..fg::SceneEntity::default()
                });
            }
            self.scene.entities.append(&mut self.other_entities);
        }
        if let Some(h) = table_height {
            let table = &mut self.scene.entities[1];
            table.timestamp = stamp;
            table.cubes.clear();
            table.cubes.push(fg::CubePrimitive {
                pose: Some(fg_pose(&Isometry::translation(
                    0.0,
                    0.0,
                    h - 0.5 * TABLE_THICKNESS_M,
                ))),
                size: size(TABLE_SIZE_M, TABLE_SIZE_M, TABLE_THICKNESS_M),
                color: Some(rgba(0.55, 0.45, 0.35, 1.0)),
            });
        }
        let others_from = if table_height.is_some() { 2 } else { 1 };
        let others = (0..scene.objects.len()).filter(|&i| i != scene.primary);
        for (e, i) in std::iter::once((0, scene.primary))
            .chain(others.enumerate().map(|(k, i)| (others_from + k, i)))
        {
            let entity = &mut self.scene.entities[e];
            entity.timestamp = stamp;
            entity.spheres.clear();
            entity.cubes.clear();
            entity.cylinders.clear();
            entity.arrows.clear();
            let p = Some(fg_pose(&out.objects[i].state.pose));
            // The grasped object blue, the others grey.
            let colour = Some(if i == scene.primary {
                rgba(0.25, 0.5, 0.85, 0.8)
            } else {
                rgba(0.6, 0.6, 0.6, 0.8)
            });
            match scene.objects[i].1 {
                Shape::Sphere { radius } => entity.spheres.push(fg::SpherePrimitive {
                    pose: p,
                    size: size(2.0 * radius, 2.0 * radius, 2.0 * radius),
                    color: colour,
                }),
                Shape::Box { half_extents: h } => entity.cubes.push(fg::CubePrimitive {
                    pose: p,
                    size: size(2.0 * h[0], 2.0 * h[1], 2.0 * h[2]),
                    color: colour,
                }),
                Shape::Cylinder {
                    radius,
                    half_height,
                } => entity.cylinders.push(fg::CylinderPrimitive {
                    pose: p,
                    size: size(2.0 * radius, 2.0 * radius, 2.0 * half_height),
                    bottom_scale: 1.0,
                    top_scale: 1.0,
                    color: colour,
                }),
            }
        }
        // The contact forces, on whichever object each fingertip pushes.
        let entity = &mut self.scene.entities[0];
        for tip in out.tips.iter().take(hand.n_tips) {
            let Some(frame) = tip.frame.filter(|_| tip.in_contact) else {
                continue;
            };
            let object_pose = &out.objects[tip.object.min(out.objects.len() - 1)]
                .state
                .pose;
            let t = &tip.transmitted;
            let f_world = object_pose.rotation * (frame.rot_b * Vector::new(t[0], t[1], t[2]));
            let magnitude = f_world.norm();
            if magnitude.is_nan() || magnitude <= 1e-9 {
                continue;
            }
            let point_world = object_pose * Point::from(frame.p_b);
            let rotation =
                Rotation::rotation_between(&Vector::x(), &f_world).unwrap_or_else(|| {
                    // Antiparallel to +x: half a turn about z.
                    Rotation::from_axis_angle(&Vector::z_axis(), std::f64::consts::PI)
                });
            let length = ARROW_M_PER_N * magnitude;
            let head = (0.25 * length).min(0.01);
            entity.arrows.push(fg::ArrowPrimitive {
                pose: Some(fg::Pose {
                    position: Some(fg_vector(&point_world.coords)),
                    orientation: Some(fg_quaternion(&rotation)),
                }),
                shaft_length: length - head,
                shaft_diameter: 0.003,
                head_length: head,
                head_diameter: 0.007,
                color: Some(if tip.slip {
                    rgba(1.0, 0.6, 0.0, 1.0)
                } else {
                    rgba(0.9, 0.1, 0.1, 1.0)
                }),
            });
        }

        self.fox_joints.timestamp = stamp;
        for (i, j) in self.fox_joints.joints.iter_mut().enumerate() {
            j.position = Some(f32p(self.joints.positions[i]));
            j.velocity = Some(f32p(self.joints.velocities[i]));
            j.effort = Some(f32p(self.joints.efforts[i]));
        }
        Ok(())
    }
}

/// Id of the table's entity in `/scene`.
pub const TABLE_ENTITY: &str = "table";
/// Side of the table shown in `/scene` (m).
const TABLE_SIZE_M: f64 = 1.0;
/// Thickness of the table shown in `/scene` (m).
const TABLE_THICKNESS_M: f64 = 0.02;

/// A Foxglove timestamp of `ns` since the session's start.
fn timestamp(ns: u64) -> Result<fg::Timestamp> {
    let sec = u32::try_from(ns / 1_000_000_000).map_err(|_| RecordingError::Serialize {
        topic: TOPIC_TF.to_owned(),
        detail: format!("log time {ns} ns is past what a Foxglove timestamp holds"),
    })?;
    Ok(fg::Timestamp::new(sec, (ns % 1_000_000_000) as u32))
}

/// A Foxglove topic's number: `x` at `f32` precision, kept as the schema's `double`.
///
/// The Foxglove topics draw what the raw topics record, and `f32` (a relative 6e-8: 60 nm at a
/// metre, 1e-7 of a unit quaternion) is far finer than the raw topics' steps (1e-6 m, 1e-6,
/// 1e-5 rad). A `double` that holds an `f32` ends in 29 zero bits, which zstd takes for
/// almost nothing: `/tf`, `/scene` and `/joint_states` come out a third smaller (0.73 MB of a
/// minute's 11.48 MB). A value beyond `f32`'s range (no real pose or angle) stays as it is,
/// never infinite.
fn f32p(x: f64) -> f64 {
    let y = x as f32;
    if y.is_finite() {
        f64::from(y)
    } else {
        x
    }
}

pub(super) fn fg_vector(v: &Vector) -> fg::Vector3 {
    fg::Vector3 {
        x: f32p(v.x),
        y: f32p(v.y),
        z: f32p(v.z),
    }
}

fn fg_quaternion(r: &Rotation) -> fg::Quaternion {
    let q = r.quaternion();
    fg::Quaternion {
        x: f32p(q.i),
        y: f32p(q.j),
        z: f32p(q.k),
        w: f32p(q.w),
    }
}

pub(super) fn fg_pose(iso: &Isometry) -> fg::Pose {
    fg::Pose {
        position: Some(fg_vector(&iso.translation.vector)),
        orientation: Some(fg_quaternion(&iso.rotation)),
    }
}

fn rgba(r: f64, g: f64, b: f64, a: f64) -> fg::Color {
    fg::Color { r, g, b, a }
}

/// Runs `scenario` (glove10, 1 kHz) for its script's length or `duration` seconds and records
/// every tick into `out`. `progress(done, total)` is called every 100 ticks and at the end.
///
/// A scenario that cannot be set up is [`RecordingError::InvalidInput`] (naming the field) and
/// writes no file. If the simulation fails midway, the file is finished with every tick before the failure
/// (it reads) and [`RecordingError::Simulation`] is returned with the failing tick's time.
pub fn record_simulation<'a>(
    scenario: &Scenario,
    duration: Option<f64>,
    out: impl Into<SessionOut<'a>>,
    progress: impl FnMut(u64, u64),
) -> Result<RecordSummary> {
    record_simulation_until(scenario, duration, out, progress, Stop::never())
}

/// [`record_simulation`] that ends early when `stop` is set: the file is finished with the
/// ticks recorded so far and the error is [`RecordingError::Simulation`] with
/// [`dfs_core::DfsError::Cancelled`]. `stop` is looked at every 100 simulated milliseconds
/// (well under a millisecond of CPU).
pub fn record_simulation_until<'a>(
    scenario: &Scenario,
    duration: Option<f64>,
    out: impl Into<SessionOut<'a>>,
    progress: impl FnMut(u64, u64),
    stop: &Stop,
) -> Result<RecordSummary> {
    // Set-up errors (a bad field, an unreachable object, a bad duration) come before any file.
    let mut sim = Simulation::new(scenario, HandModel::glove10(), duration).map_err(|e| {
        RecordingError::InvalidInput {
            location: format!("scenario {:?}", scenario.name),
            detail: e.to_string(),
        }
    })?;
    // A scene given as a list of objects is recorded as one (every object, the target named);
    // a scenario's one `object` as before.
    let scene = scenario.objects.as_ref().map(|_| sim.scene().clone());
    let object_json = match &scene {
        Some(_) => String::new(),
        None => serde_json::to_string(&scenario.object).unwrap_or_default(),
    };
    let scenario_json = serde_json::to_string(scenario).unwrap_or_default();
    let info = SessionInfo {
        scenario: scenario.name.clone(),
        seed: Some(scenario.seed),
        object_json,
        source: "simulation".to_owned(),
        extra: BTreeMap::from([
            ("scenario_json".to_owned(), scenario_json),
            (
                "duration_s".to_owned(),
                (sim.total_ticks() as f64 * 1e-3).to_string(),
            ),
            (
                "grasp_style".to_owned(),
                dfs_core::names::Named::name(sim.style()).to_owned(),
            ),
            // What touches the object, as imports and live sessions record it: a power
            // grasp's session is exported for import with the whole hand.
            (
                "contacts".to_owned(),
                if sim.dfs().params().whole_hand {
                    "whole_hand"
                } else {
                    "fingertips"
                }
                .to_owned(),
            ),
        ]),
        phases: sim
            .phases()
            .iter()
            .map(|s| GroundTruthPhase {
                name: s.phase.name().to_owned(),
                start_ns: s.start_ns,
                end_ns: s.end_ns,
            })
            .collect(),
        started_at: None,
        table_height: Some(sim.table_height()),
        hand_urdf: None,
        scene,
        assist_topics: false,
    };
    let dfs = sim.dfs();
    let recorder = SessionRecorder::create_to(out.into(), dfs.hand(), dfs.object(), &info)?;
    record_ticks_until(&mut sim, recorder, progress, stop)
}

/// Steps `sim` to its end, recording every tick with `recorder`, then finishes the file.
/// `progress(done, total)` is called every 100 ticks and at the end. If the simulation or a
/// write fails midway, the file is still finished with every tick recorded before it. A tick
/// with a value beyond its field's range is left out of the file and reported at the end (see
/// [`SessionRecorder::record`]).
pub fn record_ticks(
    sim: &mut Simulation,
    recorder: SessionRecorder,
    progress: impl FnMut(u64, u64),
) -> Result<RecordSummary> {
    record_ticks_until(sim, recorder, progress, Stop::never())
}

/// [`record_ticks`] that ends early when `stop` is set (looked at every 100 ticks): the file is
/// finished with the ticks recorded so far and the error is [`RecordingError::Simulation`]
/// with [`dfs_core::DfsError::Cancelled`].
pub fn record_ticks_until(
    sim: &mut Simulation,
    mut recorder: SessionRecorder,
    mut progress: impl FnMut(u64, u64),
    stop: &Stop,
) -> Result<RecordSummary> {
    let total = sim.total_ticks();
    loop {
        let next_time = sim.ticks() * dfs_core::operator::TICK_NS;
        let step = if sim.ticks().is_multiple_of(100) && stop.is_stopped() {
            Err(dfs_core::DfsError::Cancelled)
        } else {
            sim.step()
        };
        match step {
            Ok(true) => {}
            Ok(false) => break,
            Err(source) => {
                // Keep what was recorded: finish the file, then report the failure.
                recorder.finish()?;
                return Err(RecordingError::Simulation {
                    time_ns: next_time,
                    source,
                });
            }
        }
        let (q, tau, base) = sim.sample();
        let tick = TickData {
            time_ns: sim.time_ns(),
            q,
            tau,
            base,
            output: sim.output(),
            body: sim.dfs().body_contacts(),
            kinematics: sim.dfs().kinematics(),
        };
        if let Err(e) = recorder.record(&tick) {
            let _ = recorder.finish();
            return Err(e);
        }
        let done = sim.ticks();
        if done.is_multiple_of(100) || done == total {
            progress(done, total);
        }
    }
    recorder.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recording_into_any_writer_is_the_file_byte_for_byte() {
        /// A writer that cannot seek, whose bytes the test keeps.
        struct Shared(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);
        impl std::io::Write for Shared {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                self.0.lock().unwrap().extend_from_slice(buf);
                Ok(buf.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let scenario = Scenario::builtin("sphere-lift", 3).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.mcap");
        let file = record_simulation(&scenario, Some(2.5), path.as_path(), |_, _| {}).unwrap();
        let bytes = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let out = SessionOut::Stream {
            out: Box::new(Shared(bytes.clone())),
            name: "memory".into(),
        };
        let streamed = record_simulation(&scenario, Some(2.5), out, |_, _| {}).unwrap();
        let bytes = bytes.lock().unwrap().clone();
        assert_eq!(std::fs::read(&path).unwrap(), bytes);
        assert_eq!(
            (file.file_bytes, streamed.file_bytes),
            (bytes.len() as u64, bytes.len() as u64)
        );
        assert_eq!(streamed.write.path, PathBuf::from("memory"));
        assert_eq!(streamed.ticks, 2500);
    }

    /// What [`record_with`] recorded: per tick its `record` result, time and q.
    struct Recorded {
        results: Vec<Result<()>>,
        times: Vec<u64>,
        q: Vec<Vec<f64>>,
        finished: Result<RecordSummary>,
    }

    /// Records `seconds` of `sphere-lift` into `path`, with `edit(tick position, τ)` applied to
    /// each tick's τ (0 for the first tick).
    fn record_with(path: &Path, seconds: f64, edit: impl Fn(usize, &mut [f64])) -> Recorded {
        let scenario = Scenario::builtin("sphere-lift", 3).unwrap();
        let mut sim = Simulation::new(&scenario, HandModel::glove10(), Some(seconds)).unwrap();
        let dfs = sim.dfs();
        let mut rec =
            SessionRecorder::create(path, dfs.hand(), dfs.object(), &SessionInfo::default())
                .unwrap();
        let (mut results, mut times, mut qs) = (Vec::new(), Vec::new(), Vec::new());
        while sim.step().unwrap() {
            let (q, tau, base) = sim.sample();
            let mut tau = tau.to_vec();
            edit(results.len(), &mut tau);
            let tick = TickData {
                time_ns: sim.time_ns(),
                q,
                tau: &tau,
                base,
                output: sim.output(),
                body: sim.dfs().body_contacts(),
                kinematics: sim.dfs().kinematics(),
            };
            results.push(rec.record(&tick));
            times.push(sim.time_ns());
            qs.push(q.to_vec());
        }
        Recorded {
            results,
            times,
            q: qs,
            finished: rec.finish(),
        }
    }

    #[test]
    fn a_value_beyond_its_field_leaves_its_tick_out_and_finish_reports_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.mcap");
        // τ₃ of 10⁵ N·m is 10¹⁰ steps of 10⁻⁵: finite, but beyond an sint32. Ticks 29, 30
        // and 40 (counted from 0; 40 is a Foxglove tick).
        let r = record_with(&path, 0.1, |tick, tau| {
            if [29, 30, 40].contains(&tick) {
                tau[3] = 1e5;
            }
        });
        assert_eq!(r.results.len(), 100);
        assert!(r.results.iter().all(Result::is_ok));
        match r.finished.unwrap_err() {
            RecordingError::NonFiniteNumber { topic, path, value } => {
                assert_eq!(topic, TOPIC_GLOVE_JOINT_STATES);
                assert_eq!(path, "efforts[3]");
                assert!(value.contains("beyond the field's range"), "{value}");
            }
            e => panic!("{e}"),
        }
        // The file is finished without those ticks.
        let session = read_session(&path).unwrap();
        assert_eq!(session.ticks(), 97);
        for topic in RAW_TOPICS {
            assert_eq!(session.message_counts[topic], 97, "{topic}");
        }
        // The Foxglove ticks 0, 20, 60 and 80: not 40.
        assert_eq!(session.message_counts[TOPIC_TF], 4);
        let times: Vec<u64> = session.joint_states.iter().map(|(t, _)| *t).collect();
        for k in [29, 30, 40] {
            assert!(!times.contains(&r.times[k]), "{k}");
        }
        // Velocities after the gap are taken from the last tick recorded before it (28).
        let after = &session.joint_states[times.iter().position(|&t| t == r.times[31]).unwrap()];
        let dt = (r.times[31] - r.times[28]) as f64 * 1e-9;
        for (i, v) in after.1.velocities.iter().enumerate() {
            let expected = (r.q[31][i] - r.q[28][i]) / dt;
            assert!(
                (v - expected).abs() <= 0.0051,
                "{i}: {v} against {expected}"
            );
        }
    }

    #[test]
    fn a_non_finite_value_is_refused_at_once_naming_its_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("inf.mcap");
        let r = record_with(&path, 0.05, |tick, tau| {
            if tick == 20 {
                tau[4] = f64::NEG_INFINITY;
            }
        });
        let refused: Vec<_> = r
            .results
            .iter()
            .enumerate()
            .filter_map(|(i, r)| r.as_ref().err().map(|e| (i, e.to_string())))
            .collect();
        assert_eq!(refused.len(), 1, "{refused:?}");
        assert_eq!(refused[0].0, 20);
        assert!(refused[0].1.contains("efforts[4]"), "{}", refused[0].1);
        assert_eq!(r.finished.unwrap().ticks, 49);
        assert_eq!(read_session(&path).unwrap().ticks(), 49);
    }

    #[test]
    fn each_raw_message_is_the_one_prost_writes_for_its_decoding() {
        for (name, seconds) in [("cylinder-power-grasp", 3.0), ("table-three", 3.5)] {
            let scenario = Scenario::builtin(name, 5).unwrap();
            let mut sim = Simulation::new(&scenario, HandModel::glove10(), Some(seconds)).unwrap();
            let scene = scenario.objects.as_ref().map(|_| sim.scene().clone());
            raw_messages_are_canonical(&mut sim, scene.as_ref());
        }
    }

    /// Records `sim` to its end into messages, each checked to be prost's own encoding.
    fn raw_messages_are_canonical(sim: &mut Simulation, scene: Option<&Scene>) {
        use super::super::proto::{ContactsProto, GloveFeedbackProto, ObjectStateProto};
        use prost::Message;
        /// `bytes` decoded as `M`, checked to be prost's own encoding of it.
        fn canonical<M: Message + Default>(bytes: &[u8]) -> M {
            let m = M::decode(bytes).unwrap();
            assert_eq!(m.encode_to_vec(), bytes);
            m
        }
        let hand = sim.dfs().hand().clone();
        let frames = HandFrames {
            dof: hand.dof(),
            n_tips: hand.fingertips.len(),
            n_shapes: hand.contact_shapes.len(),
            links: hand.links.len(),
            root: hand.root,
            joints: hand.joints.iter().map(|j| (j.parent, j.child)).collect(),
        };
        let mut m = Messages::new(&hand, &SceneObjects::new(sim.dfs().object(), scene));
        let mut batch = Batch::default();
        let mut touching = 0;
        while sim.step().unwrap() {
            let (q, tau, base) = sim.sample();
            let tick = Tick {
                index: sim.ticks(),
                time_ns: sim.time_ns(),
                q,
                tau,
                base,
                output: sim.output(),
                body: sim.dfs().body_contacts(),
                link_poses: &[],
            };
            batch.data.clear();
            batch.items.clear();
            m.raw_topics(&frames, &tick, Some(&mut batch)).unwrap();
            m.advance(&tick);
            let bytes = |k: usize| &batch.data[batch.items[k].2..batch.items[k].3];
            let joints: GloveJointStatesProto = canonical(bytes(0));
            assert_eq!(joints.names, hand.dof_names);
            assert_eq!(joints.positions_e5.len(), hand.dof());
            let feedback: GloveFeedbackProto = canonical(bytes(1));
            assert_eq!(feedback.names, hand.dof_names);
            let contacts: ContactsProto = canonical(bytes(2));
            touching += contacts.fingers.iter().filter(|f| f.touching).count();
            let object = canonical::<ObjectStateProto>(bytes(3));
            if let Some(scene) = scene {
                assert_eq!(object.index as usize, scene.target);
                assert_eq!(object.objects.len(), scene.objects.len());
                assert_eq!(object.objects[scene.target].pose, object.pose);
                for f in contacts.fingers.iter().filter(|f| f.touching) {
                    assert_eq!(f.object as usize, scene.target);
                }
            } else {
                assert!(object.objects.is_empty() && object.index == 0);
            }
        }
        assert!(touching > 1000, "{touching}");
    }
}
