//! Live glove sessions: a real operator's glove streams samples in, the Dynamic Force
//! Simulator answers each with feedback, and the session is recorded as it streams.
//!
//! This module is the session itself, with no network in it: [`LiveSession`] takes a
//! validated [`LiveConfig`] and the binary frames of `services/proto/icms/live.proto`
//! ([`proto::Sample`] in, [`proto::Feedback`] out) and records every DFS tick into a session
//! file (format v2, [`SessionRecorder`]). The WebSocket route (`GET /api/v1/live` in the `api`
//! crate) and the `icms glove` client are built on it; the protocol is described in
//! `docs/live.md`.
//!
//! # Time
//!
//! The session's time is the sample's `t_ns` less the first sample's. The DFS always steps at
//! 1 kHz of session time: a sample at session time `s` steps every tick `k` (at `k` ms) with
//! `k ms ≤ s` not yet stepped, each with the glove's input **linearly interpolated** between
//! the previous sample and this one (joint angles, torques and wrist position; the wrist's
//! orientation by slerp). A glove at 60 Hz thus drives about 17 ticks per sample, one at 1 kHz
//! one, and samples faster than 1 kHz step none until the next tick is due (they are answered
//! from the last tick). The feedback answering a sample is that of the last tick stepped, at
//! most 1 ms before the sample. Session time only advances with samples: while none comes the
//! world waits, and the feedback goes to zero force after [`STALE_AFTER`]
//! ([`LiveSession::stale_feedback`]).

use std::collections::BTreeMap;
use std::time::{Duration, SystemTime};

use dfs_core::calibration::{Calibration, DofCalibration};
use dfs_core::contact::ContactModel;
use dfs_core::dfs::{Dfs, DfsParams, GloveSample};
use dfs_core::hand::{HandModel, MAX_DOF};
use dfs_core::math::{Isometry, Rotation};
use dfs_core::operator::TICK_NS;
use dfs_core::scenario::{ScenarioObject, Scene};
use nalgebra::{Quaternion, Translation3};
use prost::Message as _;
use serde::{Deserialize, Serialize};

use crate::assist::assistant::{AssistSetup, Assistant};
use crate::assist::features::Observation;
use crate::assist::offline::OBSERVATION_PERIOD_NS;
use crate::error::{RecordingError, Result};
use crate::session::import::{interpolate_pose, GloveDrive};
use crate::session::{
    LiveView, SessionInfo, SessionOut, SessionRecorder, TickData, MAX_SESSION_NS,
};

/// The binary frames of a live session, generated from `services/proto/icms/live.proto`.
#[allow(missing_docs)]
pub mod proto {
    include!(concat!(env!("OUT_DIR"), "/icms.live.rs"));
}

/// `services/proto/icms/live.proto` compiled: a serialized `google.protobuf.FileDescriptorSet`
/// (served at `GET /api/v1/live/schema`).
pub const FILE_DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/icms_live.fds"));

/// With no sample for this long the feedback goes to zero force (a glove must never be driven
/// from stale state).
pub const STALE_AFTER: Duration = Duration::from_millis(100);

/// With no sample for this long a live session ends, stored as incomplete (the default of
/// `icms serve --live-silence`).
pub const DEFAULT_SILENCE_LIMIT: Duration = Duration::from_secs(10);

/// Largest frame a live session takes (bytes): a sample of [`MAX_DOF`] angles and torques and
/// a pose is under 1 KiB.
pub const MAX_FRAME_BYTES: usize = 64 * 1024;

/// Longest gap between two samples' times (ns): 10 s. The DFS steps through a gap tick by tick
/// (a few µs each), so the gap bounds the work one sample can ask for.
pub const MAX_SAMPLE_GAP_NS: u64 = 10_000_000_000;

/// Metadata record a live session ends with: why it ended, whether it is complete, and what
/// was accepted and refused.
pub const LIVE_METADATA: &str = "live";

/// Most stale periods whose start times the `live` record lists (all are counted).
const MAX_LISTED_STALE: usize = 32;

/// How far a wrist quaternion's norm may be from 1 before it is refused (it is normalised).
const QUATERNION_NORM_TOLERANCE: f64 = 0.01;

/// What the assistant does in a live session ([`crate::assist`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AssistMode {
    /// No assistant: the session is recorded and stored.
    #[default]
    Off,
    /// Recognise the operator's skill and send events.
    Suggest,
    /// Recognise it and apply it on a robot hand.
    Apply,
}

/// The assist settings of a `start` message.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AssistSettings {
    /// `off`, `suggest` or `apply`.
    #[serde(default)]
    pub mode: AssistMode,
    /// The robot hand a recognised skill is applied on (`apply`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<String>,
}

/// The client's first message, a JSON text frame (`"type": "start"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartMessage {
    /// The hand used as the glove model: `glove10` (default) or any stored hand's name.
    #[serde(default = "default_hand")]
    pub hand: String,
    /// The object on the table, as in a scenario file; or `objects` and `target`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<ScenarioObject>,
    /// Up to 8 objects on the table, each named (`"name": "ball"`) and placed, as a
    /// scenario's `objects`; instead of `object`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub objects: Option<Vec<ScenarioObject>>,
    /// With `objects`: the name of the object the operator is to grasp.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// A name for the session (its `scenario` in the store). Default `live`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Pose of the hand's base until a sample gives one (a glove without a tracker keeps it):
    /// `[x, y, z, qx, qy, qz, qw]` (m; unit quaternion). Default: the world origin.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wrist: Option<[f64; 7]>,
    /// The assistant's settings. Default off.
    #[serde(default)]
    pub assist: AssistSettings,
    /// The operator's calibration: `{"offsets": {DOF: rad}, "scales": {DOF: factor}}`,
    /// applied to every sample's angles (`q = scale · q_raw + offset`). Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<Calibration>,
    /// Whole-hand contact: the palm and phalanges of a hand with contact shapes touch the
    /// objects too ([`DfsParams::whole_hand`]). Default false: the fingertips alone.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub whole_hand: bool,
}

fn default_hand() -> String {
    "glove10".to_owned()
}

/// Longest session name (bytes).
pub const MAX_NAME_BYTES: usize = 256;

/// What the client sends as JSON text frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ClientMessage {
    /// Opens the session; the first message.
    Start(Box<StartMessage>),
    /// Ends the session: it is recorded up to the last sample, stored as complete and
    /// segmented; the server answers `stored` and closes.
    End,
}

impl ClientMessage {
    /// Parses a text frame. Errors name the field (`object.shape: unknown shape "torus"`),
    /// which serde's tagged enums alone do not.
    pub fn parse(text: &str) -> std::result::Result<ClientMessage, String> {
        let mut value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
        let Some(map) = value.as_object_mut() else {
            return Err("expected a JSON object {\"type\": ...}".to_owned());
        };
        let kind = match map.remove("type") {
            Some(serde_json::Value::String(k)) => k,
            Some(other) => return Err(format!("type: expected \"start\" or \"end\", got {other}")),
            None => return Err("type: missing; expected \"start\" or \"end\"".to_owned()),
        };
        match kind.as_str() {
            "start" => serde_path_to_error::deserialize::<_, StartMessage>(value)
                .map(|s| ClientMessage::Start(Box::new(s)))
                .map_err(|e| {
                    let path = e.path().to_string();
                    if path == "." {
                        format!("start: {}", e.inner())
                    } else {
                        format!("{path}: {}", e.inner())
                    }
                }),
            "end" if map.is_empty() => Ok(ClientMessage::End),
            "end" => Err(format!(
                "end takes no fields, got {}",
                map.keys().cloned().collect::<Vec<_>>().join(", ")
            )),
            other => Err(format!(
                "type: unknown message type {other:?}; expected \"start\" or \"end\""
            )),
        }
    }
}

/// Why a live session ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EndReason {
    /// The client sent `end`: the session is complete.
    Ended,
    /// The connection closed (or failed) without `end`.
    Disconnected,
    /// No sample came for the server's silence limit ([`DEFAULT_SILENCE_LIMIT`]).
    Silent,
    /// The server is shutting down.
    ServerStopping,
}

impl EndReason {
    /// Whether a session that ended so is incomplete.
    pub fn incomplete(self) -> bool {
        self != EndReason::Ended
    }

    /// The name used in the `live` metadata and events.
    pub fn name(self) -> &'static str {
        match self {
            EndReason::Ended => "ended",
            EndReason::Disconnected => "disconnected",
            EndReason::Silent => "silent",
            EndReason::ServerStopping => "server_stopping",
        }
    }
}

/// One grasp of a stored live session.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StoredSkill {
    /// The skill's id.
    pub skill_id: i64,
    /// Stored as a new skill (without the assistant every grasp is new).
    pub new: bool,
    /// The stored skill the grasp matched, when it is not new.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matched_skill_id: Option<i64>,
}

/// What the server sends as JSON text frames, besides the binary feedback.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Event {
    /// The `start` was accepted: what the samples must hold.
    Started {
        /// The hand (glove model).
        hand: String,
        /// DOF names: the order of a sample's `q` and `tau`.
        dofs: Vec<String>,
        /// Fingertip names: the order of the feedback's `fingers`.
        fingers: Vec<String>,
        /// DFS rate (Hz).
        rate_hz: u32,
        /// Milliseconds without a sample before the feedback goes to zero force.
        stale_after_ms: u64,
        /// Seconds without a sample before the session ends as incomplete.
        silence_limit_s: f64,
        /// Height of the table's top (m, world z).
        table_height: f64,
    },
    /// A frame was refused (not stepped) or the DFS failed; the session goes on.
    Error {
        /// The refused sample's `t_ns`, when it decoded.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        t_ns: Option<u64>,
        /// What is wrong.
        message: String,
    },
    /// No sample for [`STALE_AFTER`]: a zero-force feedback frame was sent.
    Stale {
        /// Session time of the last tick (ns).
        session_ns: u64,
    },
    /// Samples came again after `stale`.
    Resumed {
        /// Session time of the sample that resumed (ns).
        session_ns: u64,
    },
    /// The session ended; it is being stored.
    Ended {
        /// Why.
        reason: EndReason,
        /// Samples accepted.
        samples: u64,
        /// Samples refused.
        refused: u64,
        /// Session time of the last tick (ns).
        session_ns: u64,
    },
    /// The session is stored and segmented.
    Stored {
        /// The stored session's id.
        session_id: i64,
        /// `false` when identical bytes were already stored.
        created: bool,
        /// Stored as incomplete (ended without `end`).
        incomplete: bool,
        /// One per grasp found.
        skills: Vec<StoredSkill>,
    },
}

/// A live session's validated set-up.
#[derive(Debug, Clone)]
pub struct LiveConfig {
    /// The glove model.
    pub hand: HandModel,
    /// The URDF the hand was built from (a stored hand), for the recording's `/hand` topic.
    pub hand_urdf: Option<String>,
    /// The objects on the table (one unless `objects` were given).
    pub scene: Scene,
    /// Whether the scene was given as a list of objects (recorded as one).
    pub listed: bool,
    /// Base pose until a sample gives one.
    pub wrist: Isometry,
    /// The session's name.
    pub name: String,
    /// Wall-clock start.
    pub started_at: SystemTime,
    /// The operator's calibration, resolved for the hand.
    pub calibration: DofCalibration,
    /// It as given (recorded in the session's metadata), if any.
    pub calibration_given: Option<Calibration>,
    /// The assistant's mode (its set-up is given to [`LiveSession::start_assisted`]).
    pub assist: AssistMode,
    /// Whole-hand contact ([`DfsParams::whole_hand`]), as the start asked.
    pub whole_hand: bool,
}

impl LiveConfig {
    /// Validates a `start` message's fields but the hand, which the caller resolved (a name
    /// is looked up in the store). Errors name the field.
    pub fn from_start(
        start: &StartMessage,
        hand: HandModel,
        hand_urdf: Option<String>,
    ) -> Result<LiveConfig> {
        match (start.assist.mode, &start.assist.robot) {
            (AssistMode::Apply, None) => {
                return Err(invalid(
                    "assist.robot",
                    "assist mode \"apply\" needs the robot hand to apply the skill on (a \
                     built-in hand or one of GET /api/v1/hands)",
                ))
            }
            (AssistMode::Off | AssistMode::Suggest, Some(robot)) => {
                return Err(invalid(
                    "assist.robot",
                    format!("{robot:?} is only taken with assist mode \"apply\""),
                ))
            }
            _ => {}
        }
        let name = start.name.clone().unwrap_or_else(|| "live".to_owned());
        if name.is_empty() || name.len() > MAX_NAME_BYTES || name.chars().any(char::is_control) {
            return Err(invalid(
                "name",
                format!("must be 1 to {MAX_NAME_BYTES} bytes without control characters"),
            ));
        }
        let wrist = match start.wrist {
            None => Isometry::identity(),
            Some(w) => pose_from([w[0], w[1], w[2]], [w[3], w[4], w[5], w[6]])
                .map_err(|m| invalid("wrist", m))?,
        };
        let scene = Scene::new(
            start.object.as_ref(),
            start.objects.as_deref(),
            start.target.as_deref(),
        )
        .map_err(|e| invalid("scene", e.to_string()))?;
        let calibration = match &start.calibration {
            Some(c) => c
                .validate(&hand)
                .map_err(|e| invalid("calibration", e.to_string()))?,
            None => DofCalibration::identity(hand.dof()),
        };
        Ok(LiveConfig {
            hand,
            hand_urdf,
            scene,
            listed: start.objects.is_some(),
            wrist,
            name,
            started_at: SystemTime::now(),
            calibration,
            calibration_given: start.calibration.clone().filter(|c| !c.is_empty()),
            assist: start.assist.mode,
            whole_hand: start.whole_hand,
        })
    }
}

fn invalid(location: impl Into<String>, detail: impl Into<String>) -> RecordingError {
    RecordingError::InvalidInput {
        location: location.into(),
        detail: detail.into(),
    }
}

/// A pose from a position and an (x, y, z, w) quaternion: finite, the quaternion's norm
/// within [`QUATERNION_NORM_TOLERANCE`] of 1 (then normalised).
fn pose_from(p: [f64; 3], q: [f64; 4]) -> std::result::Result<Isometry, String> {
    if !p.iter().chain(&q).all(|v| v.is_finite()) {
        return Err(format!("must be finite, got {p:?} {q:?}"));
    }
    if p.iter().any(|v| v.abs() > 100.0) {
        return Err(format!(
            "position {p:?} m is over 100 m from the world origin"
        ));
    }
    let quat = Quaternion::new(q[3], q[0], q[1], q[2]);
    let norm = quat.norm();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(format!(
            "orientation (x, y, z, w) = {q:?} has norm {norm}; a unit quaternion is needed"
        ));
    }
    Ok(Isometry::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        Rotation::from_quaternion(quat),
    ))
}

/// Why a sample was refused: it was not stepped, and nothing accepted before it changes.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct SampleError {
    /// The sample's `t_ns`, when it decoded.
    pub t_ns: Option<u64>,
    /// What is wrong, naming the field.
    pub message: String,
}

/// The answer to an accepted sample.
#[derive(Debug)]
pub struct Answer<'a> {
    /// The encoded [`proto::Feedback`].
    pub feedback: &'a [u8],
    /// The first tick of the sample that failed, if any.
    pub failure: Option<SampleError>,
    /// The sample ended a stale period.
    pub resumed: bool,
    /// The assistant's events since the last frame, as JSON text frames.
    pub events: Vec<String>,
}

/// Counts of a live session, written to its `live` metadata record at the end.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LiveStats {
    /// Samples accepted.
    pub samples: u64,
    /// Samples refused.
    pub refused: u64,
    /// DFS ticks stepped.
    pub ticks: u64,
    /// Periods of [`STALE_AFTER`] or more without a sample.
    pub stale_periods: u64,
    /// Session times (ns) at which the first [`MAX_LISTED_STALE`] stale periods began.
    pub stale_at_ns: Vec<u64>,
    /// Ticks at which the DFS step failed (diverged); the object kept its last state.
    pub failed_ticks: u64,
    /// Session time of the first tick a fingertip transmitted force (ns).
    pub first_contact_ns: Option<u64>,
    /// The assistant's events at the end of the session (the robot's report), as JSON text
    /// frames.
    pub assist_tail: Vec<String>,
}

/// The glove's input at one sample, in session time.
#[derive(Debug, Clone, Copy)]
struct Input {
    session_ns: u64,
    q: [f64; MAX_DOF],
    tau: [f64; MAX_DOF],
    base: Isometry,
}

/// One live session: the DFS, its recorder and the frames in and out. See the module docs.
pub struct LiveSession {
    dfs: Dfs,
    recorder: Option<SessionRecorder>,
    dof: usize,
    calibration: DofCalibration,
    /// How the samples drive the DFS: decided by the first sample (with torques or of
    /// positions only); every later sample must be alike.
    drive: Option<GloveDrive>,
    /// Client time of the first sample.
    first_t_ns: Option<u64>,
    last_t_ns: u64,
    /// Index of the next tick to step.
    next_tick: u64,
    prev: Input,
    cur: Input,
    base: Isometry,
    stale: bool,
    stats: LiveStats,
    /// Reused: the sample being decoded, the feedback and its encoding.
    sample: proto::Sample,
    feedback: proto::Feedback,
    encoded: Vec<u8>,
    /// The assistant (issue 20), when the session has one, and the mode.
    assistant: Option<Assistant>,
    assist_mode: AssistMode,
    /// Index of the thumb's fingertip (for the assistant's observations).
    thumb: usize,
}

impl std::fmt::Debug for LiveSession {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveSession")
            .field("hand", &self.dfs.hand().name)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl LiveSession {
    /// Sets up the DFS and starts recording into `out` (its Foxglove topics published through
    /// `view` too, when given).
    pub fn start(
        config: &LiveConfig,
        out: SessionOut<'_>,
        view: Option<LiveView>,
    ) -> Result<LiveSession> {
        Self::start_assisted(config, out, view, None)
    }

    /// [`LiveSession::start`] with the assistant set up by `assist` (its own thread; the
    /// recording gets its topics, [`crate::session::TOPIC_ASSIST_EVENTS`] and
    /// [`crate::session::TOPIC_ASSIST_ROBOT`]).
    pub fn start_assisted(
        config: &LiveConfig,
        out: SessionOut<'_>,
        view: Option<LiveView>,
        assist: Option<AssistSetup>,
    ) -> Result<LiveSession> {
        let scene = &config.scene;
        let table_height = scene.table_height;
        let params = DfsParams {
            // Fingertip pads are soft, as the simulated operator's (`Simulation::new`).
            contact_model: ContactModel::SoftFinger,
            friction: scene.target().friction,
            table_height: Some(table_height),
            whole_hand: config.whole_hand,
            ..DfsParams::default()
        };
        let dfs = Dfs::with_objects(config.hand.clone(), &scene.dfs_objects(), params)
            .map_err(|e| invalid("hand", e.to_string()))?;
        let mut extra = BTreeMap::new();
        extra.insert(
            "contacts".to_owned(),
            if config.whole_hand {
                "whole_hand"
            } else {
                "fingertips"
            }
            .to_owned(),
        );
        if let Some(c) = &config.calibration_given {
            extra.insert(
                "calibration".to_owned(),
                serde_json::to_string(c).unwrap_or_default(),
            );
        }
        let info = SessionInfo {
            scenario: config.name.clone(),
            seed: None,
            // A scene given as a list is recorded as one (every object, the target named), as
            // a simulation records it.
            object_json: if config.listed {
                String::new()
            } else {
                serde_json::to_string(&scene.target().spec).unwrap_or_default()
            },
            source: "live".to_owned(),
            extra,
            phases: Vec::new(),
            started_at: Some(config.started_at),
            table_height: Some(table_height),
            hand_urdf: config.hand_urdf.clone(),
            scene: config.listed.then(|| scene.clone()),
            assist_topics: assist.is_some(),
        };
        let recorder =
            SessionRecorder::create_with_view(out, dfs.hand(), dfs.object(), &info, view)?;
        let dof = dfs.hand().dof();
        let n_tips = dfs.hand().fingertips.len();
        let thumb = dfs_core::hand::thumb_of(dfs.hand());
        let assistant = match assist {
            None => None,
            Some(setup) => Some(
                Assistant::start(setup)
                    .map_err(|e| RecordingError::io("starting the assistant's thread", e))?,
            ),
        };
        let input = Input {
            session_ns: 0,
            q: [0.0; MAX_DOF],
            tau: [0.0; MAX_DOF],
            base: config.wrist,
        };
        Ok(LiveSession {
            dfs,
            recorder: Some(recorder),
            dof,
            calibration: config.calibration,
            drive: None,
            first_t_ns: None,
            last_t_ns: 0,
            next_tick: 0,
            prev: input,
            cur: input,
            base: config.wrist,
            stale: false,
            stats: LiveStats::default(),
            sample: proto::Sample::default(),
            feedback: proto::Feedback {
                motor_q: Vec::with_capacity(dof),
                feedback_torque: Vec::with_capacity(dof),
                fingers: Vec::with_capacity(n_tips),
                ..Default::default()
            },
            encoded: Vec::with_capacity(1024),
            assistant,
            assist_mode: config.assist,
            thumb,
        })
    }

    /// The `started` event of this session on a server that ends sessions after `silence`
    /// without a sample.
    pub fn started_event(&self, silence: Duration) -> Event {
        let hand = self.dfs.hand();
        Event::Started {
            hand: hand.name.clone(),
            dofs: hand.dof_names.clone(),
            fingers: hand.fingertips.iter().map(|t| t.name.clone()).collect(),
            rate_hz: crate::session::RATE_HZ,
            stale_after_ms: STALE_AFTER.as_millis() as u64,
            silence_limit_s: silence.as_secs_f64(),
            table_height: self.dfs.params().table_height.unwrap_or(0.0),
        }
    }

    /// Counts so far.
    pub fn stats(&self) -> &LiveStats {
        &self.stats
    }

    /// Session time of the last tick stepped (ns; 0 before the first).
    pub fn session_ns(&self) -> u64 {
        self.next_tick.saturating_sub(1) * TICK_NS
    }

    /// Whether the feedback is at zero force for want of samples.
    pub fn is_stale(&self) -> bool {
        self.stale
    }

    /// Takes one binary frame: a [`proto::Sample`]. Steps the DFS up to the sample's time and
    /// records every tick. A refused sample (`Err`) changes nothing and is counted; an
    /// accepted one is answered with its encoded [`proto::Feedback`], and with the first
    /// failure of a tick it stepped, if one failed (the DFS diverged: the object kept its last
    /// state).
    pub fn on_frame(&mut self, frame: &[u8]) -> std::result::Result<Answer<'_>, SampleError> {
        if let Err(e) = self.accept(frame) {
            self.stats.refused += 1;
            return Err(e);
        }
        let failure = self.step_to_current();
        self.stats.samples += 1;
        let resumed = std::mem::replace(&mut self.stale, false);
        let events = self.assist_events();
        self.fill_feedback(self.sample.t_ns);
        Ok(Answer {
            feedback: &self.encoded,
            failure,
            resumed,
            events,
        })
    }

    /// The assistant's events since the last call, recorded on its topics, as JSON texts.
    fn assist_events(&mut self) -> Vec<String> {
        let Some(assistant) = &self.assistant else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for e in assistant.drain() {
            if let Some(recorder) = self.recorder.as_mut() {
                crate::assist::record::log_event(recorder, &e);
            }
            out.push(serde_json::to_string(&e).unwrap_or_default());
        }
        out
    }

    /// Decodes and validates a frame into `self.cur` (leaving `self.prev` the last accepted).
    fn accept(&mut self, frame: &[u8]) -> std::result::Result<(), SampleError> {
        self.decode(frame).map_err(|message| SampleError {
            t_ns: None,
            message,
        })?;
        let t = self.sample.t_ns;
        let at_t = |message: String| SampleError {
            t_ns: Some(t),
            message,
        };
        let (input, torques) = self.validate().map_err(at_t)?;
        if self.drive.is_none() {
            let drive = GloveDrive::new(self.dfs.hand(), self.dfs.params(), torques, None)
                .map_err(|e| at_t(format!("the glove's coupling: {e}")))?;
            self.drive = Some(drive);
        }
        if self.first_t_ns.is_none() {
            self.first_t_ns = Some(t);
            self.prev = input;
        } else {
            self.prev = self.cur;
        }
        self.cur = input;
        self.last_t_ns = t;
        self.base = input.base;
        Ok(())
    }

    /// Decodes `frame` into `self.sample`; what is wrong with it if it is not a sample.
    fn decode(&mut self, frame: &[u8]) -> std::result::Result<(), String> {
        if frame.len() > MAX_FRAME_BYTES {
            return Err(format!(
                "the frame is {} bytes; a sample frame has at most {MAX_FRAME_BYTES}",
                frame.len()
            ));
        }
        let s = &mut self.sample;
        s.clear();
        s.merge(frame)
            .map_err(|e| format!("the binary frame is not an icms.live.Sample: {e}"))
    }

    /// Checks the decoded sample against the hand, the session's glove and the previous
    /// sample: its input in session time (angles calibrated), and whether it gives torques.
    /// What is wrong with it, naming the field, if it is refused.
    fn validate(&self) -> std::result::Result<(Input, bool), String> {
        let n = self.dof;
        let torques = self.check_lengths()?;
        let q = self.calibrated_angles()?;
        self.check_torque_limits()?;
        let base = self.sample_base()?;
        let session_ns = self.sample_session_ns()?;
        let mut input = Input {
            session_ns,
            q: [0.0; MAX_DOF],
            tau: [0.0; MAX_DOF],
            base,
        };
        input.q[..n].copy_from_slice(&q[..n]);
        if torques {
            input.tau[..n].copy_from_slice(&self.sample.tau);
        }
        Ok((input, torques))
    }

    /// Checks the sample gives one angle per DOF and one torque per DOF or none, as the
    /// session's first sample did, every value finite; whether it gives torques.
    fn check_lengths(&self) -> std::result::Result<bool, String> {
        let s = &self.sample;
        let n = self.dof;
        let hand = self.dfs.hand();
        if s.q.len() != n {
            return Err(format!(
                "q has {} values; the hand {} has {n} DOFs ({})",
                s.q.len(),
                hand.name,
                hand.dof_names.join(", ")
            ));
        }
        let torques = match self.drive {
            Some(d) => d.torques(),
            None => !s.tau.is_empty(),
        };
        if s.tau.len() != if torques { n } else { 0 } {
            let kind = if self.drive.is_some() {
                "the session's first sample"
            } else {
                "a glove"
            };
            return Err(if torques {
                format!(
                    "tau has {} values; {kind} gave torques, so every sample gives one per \
                     DOF ({n} for {})",
                    s.tau.len(),
                    hand.name
                )
            } else {
                format!(
                    "tau has {} values; the session's first sample gave none (a glove of \
                     positions only), so no sample may",
                    s.tau.len()
                )
            });
        }
        for (what, values) in [("q", &s.q), ("tau", &s.tau)] {
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                return Err(format!(
                    "{what}[{i}] ({}) is {}; every value must be finite",
                    hand.dof_names[i], values[i]
                ));
            }
        }
        Ok(torques)
    }

    /// The sample's angles, calibrated, checked against the hand's joint limits (with the
    /// DFS's slack).
    fn calibrated_angles(&self) -> std::result::Result<[f64; MAX_DOF], String> {
        let n = self.dof;
        let mut q = [0.0; MAX_DOF];
        q[..n].copy_from_slice(&self.sample.q);
        self.calibration.apply(&mut q[..n]);
        let slack = self.dfs.params().angle_slack;
        if let Err(e) = self.dfs.hand().check_angles(&q[..n], slack) {
            let calibrated = if self.calibration.is_identity() {
                ""
            } else {
                " (calibrated)"
            };
            return Err(format!("q{calibrated}: {e}"));
        }
        Ok(q)
    }

    /// Checks the sample's torques are within the hand's limits (times the DFS's range).
    fn check_torque_limits(&self) -> std::result::Result<(), String> {
        let hand = self.dfs.hand();
        let range = self.dfs.params().torque_range;
        for (i, &v) in self.sample.tau.iter().enumerate() {
            let lim = hand.torque_limit[i] * range;
            if v.abs() > lim {
                return Err(format!(
                    "tau[{i}] ({}) is {v} N·m; the hand's limit there is ±{lim} \
                     ({range} × its actuator's)",
                    hand.dof_names[i]
                ));
            }
        }
        Ok(())
    }

    /// The hand base's pose at the sample: its wrist pose, else the last one.
    fn sample_base(&self) -> std::result::Result<Isometry, String> {
        match &self.sample.wrist {
            None => Ok(self.base),
            Some(w) => {
                let p = w.position.unwrap_or_default();
                let Some(o) = w.orientation else {
                    return Err("wrist.orientation is missing".to_owned());
                };
                pose_from([p.x, p.y, p.z], [o.x, o.y, o.z, o.w]).map_err(|m| format!("wrist: {m}"))
            }
        }
    }

    /// The sample's session time (ns): 0 for the first; later ones after the previous sample,
    /// at most [`MAX_SAMPLE_GAP_NS`] after it and within [`MAX_SESSION_NS`] of the first.
    fn sample_session_ns(&self) -> std::result::Result<u64, String> {
        let t = self.sample.t_ns;
        let Some(first) = self.first_t_ns else {
            return Ok(0);
        };
        if t <= self.last_t_ns {
            return Err(format!(
                "t_ns {t} is not after the previous sample's {}: samples must come in time \
                 order",
                self.last_t_ns
            ));
        }
        if t - self.last_t_ns > MAX_SAMPLE_GAP_NS {
            return Err(format!(
                "t_ns {t} is {} s after the previous sample; at most {} s may pass between \
                 samples",
                (t - self.last_t_ns) as f64 * 1e-9,
                MAX_SAMPLE_GAP_NS as f64 * 1e-9
            ));
        }
        let s = t - first;
        if s > MAX_SESSION_NS {
            return Err(format!(
                "the session would be {} s long; a live session is at most {} s: end it and \
                 start another",
                s as f64 * 1e-9,
                MAX_SESSION_NS as f64 * 1e-9
            ));
        }
        Ok(s)
    }

    /// Steps every tick due up to the current sample, interpolating its input from the
    /// previous sample's. Returns the first DFS failure (the ticks before it are recorded; the
    /// object keeps its last finite state and later ticks go on).
    fn step_to_current(&mut self) -> Option<SampleError> {
        let n = self.dof;
        let (a, b) = (self.prev, self.cur);
        let mut failure = None;
        let mut ticks = 0u32;
        while self.next_tick * TICK_NS <= b.session_ns {
            let t = self.next_tick * TICK_NS;
            let w = if b.session_ns > a.session_ns {
                (t.saturating_sub(a.session_ns)) as f64 / (b.session_ns - a.session_ns) as f64
            } else {
                1.0
            };
            let (mut q_measured, mut tau_measured) = ([0.0; MAX_DOF], [0.0; MAX_DOF]);
            for i in 0..n {
                q_measured[i] = a.q[i] + w * (b.q[i] - a.q[i]);
                tau_measured[i] = a.tau[i] + w * (b.tau[i] - a.tau[i]);
            }
            let base = interpolate_pose(&a.base, &b.base, w);
            let first = self.next_tick == 0;
            self.next_tick += 1;
            ticks += 1;
            self.stats.ticks += 1;
            let (mut q, mut tau) = ([0.0; MAX_DOF], [0.0; MAX_DOF]);
            let stepped = match &self.drive {
                Some(drive) => drive.sample(
                    self.dfs.hand(),
                    first,
                    &q_measured[..n],
                    &tau_measured[..n],
                    self.dfs.output(),
                    &mut q[..n],
                    &mut tau[..n],
                ),
                None => Err(dfs_core::DfsError::invalid("glove", "no sample yet")),
            }
            .and_then(|()| {
                self.dfs
                    .step(&GloveSample {
                        q: &q[..n],
                        tau: &tau[..n],
                        base,
                    })
                    .map(|_| ())
            });
            if let Err(e) = stepped {
                self.stats.failed_ticks += 1;
                failure.get_or_insert(SampleError {
                    t_ns: Some(self.last_t_ns),
                    message: format!(
                        "the DFS tick at session time {} s failed: {e}; the object keeps its \
                         last state",
                        t as f64 * 1e-9
                    ),
                });
                continue;
            }
            let out = self.dfs.output();
            if self.stats.first_contact_ns.is_none()
                && out.tips[..out.n_tips].iter().any(|tip| tip.in_contact)
            {
                self.stats.first_contact_ns = Some(t);
            }
            if let Some(assistant) = &self.assistant {
                if t.is_multiple_of(OBSERVATION_PERIOD_NS) {
                    assistant.offer(&Observation::of_tick(
                        t,
                        &base,
                        self.thumb,
                        out,
                        self.dfs.body_contacts(),
                    ));
                }
            }
            if let Some(recorder) = self.recorder.as_mut() {
                // As an import records: a glove with torques as measured, one of positions
                // only as stepped (its posture and the coupling's torque).
                let (q_rec, tau_rec) = if self.drive.is_some_and(|d| d.torques()) {
                    (&q_measured, &tau_measured)
                } else {
                    (&q, &tau)
                };
                let tick = TickData {
                    time_ns: t,
                    q: &q_rec[..n],
                    tau: &tau_rec[..n],
                    base: &base,
                    output: out,
                    body: self.dfs.body_contacts(),
                    kinematics: self.dfs.kinematics(),
                };
                if let Err(e) = recorder.record(&tick) {
                    failure.get_or_insert(SampleError {
                        t_ns: Some(self.last_t_ns),
                        message: format!("recording the tick at {} s failed: {e}", t as f64 * 1e-9),
                    });
                }
            }
        }
        self.feedback.ticks = ticks;
        failure
    }

    /// Fills and encodes the feedback of the last tick (zero forces while stale).
    fn fill_feedback(&mut self, t_ns: u64) {
        let out = self.dfs.output();
        let fb = &mut self.feedback;
        fb.t_ns = t_ns;
        fb.session_ns = self.next_tick.saturating_sub(1) * TICK_NS;
        fb.stale = self.stale;
        fb.motor_q.clear();
        fb.feedback_torque.clear();
        fb.fingers.clear();
        let n = self.dof;
        if self.stale {
            // Position commands where the fingers were measured last, no torque, no force.
            fb.motor_q.extend_from_slice(&self.cur.q[..n]);
            fb.feedback_torque.resize(n, 0.0);
            fb.fingers.resize(out.n_tips, proto::FingerForce::default());
            fb.ticks = 0;
        } else {
            fb.motor_q.extend_from_slice(&out.motor_q[..n]);
            fb.feedback_torque
                .extend_from_slice(&out.feedback_torque[..n]);
            for tip in &out.tips[..out.n_tips] {
                let f = tip.feedback_force_world;
                fb.fingers.push(proto::FingerForce {
                    in_contact: tip.in_contact,
                    force: Some(proto::Vector3 {
                        x: f.x,
                        y: f.y,
                        z: f.z,
                    }),
                    normal_force: if tip.in_contact {
                        tip.transmitted[2].max(0.0)
                    } else {
                        0.0
                    },
                });
            }
        }
        self.encoded.clear();
        // Encoding into a Vec cannot fail (it grows).
        let _ = fb.encode(&mut self.encoded);
    }

    /// No sample came for [`STALE_AFTER`]: the feedback frame to send, at zero force. The
    /// first call of a stale period counts it (see [`LiveStats::stale_periods`]); the next
    /// accepted sample ends it.
    pub fn stale_feedback(&mut self) -> &[u8] {
        if !self.stale {
            self.stale = true;
            self.stats.stale_periods += 1;
            if self.stats.stale_at_ns.len() < MAX_LISTED_STALE {
                self.stats.stale_at_ns.push(self.session_ns());
            }
        }
        self.fill_feedback(self.last_t_ns);
        &self.encoded
    }

    /// Ends the session: writes the `live` metadata record (why it ended, whether it is
    /// complete, the counts) and finishes the file. Every tick stepped is in it.
    pub fn finish(mut self, reason: EndReason) -> Result<LiveStats> {
        let assisted = self.assistant.take().map(Assistant::finish);
        let Some(mut recorder) = self.recorder.take() else {
            return Ok(self.stats);
        };
        let mut assist_meta = None;
        if let Some((summary, tail)) = assisted {
            for e in &tail {
                crate::assist::record::log_event(&mut recorder, e);
                self.stats
                    .assist_tail
                    .push(serde_json::to_string(e).unwrap_or_default());
            }
            assist_meta = Some(crate::assist::record::summary_metadata(
                self.assist_mode,
                &summary,
            ));
        }
        let s = &self.stats;
        let mut meta = BTreeMap::from([
            ("end_reason".to_owned(), reason.name().to_owned()),
            ("incomplete".to_owned(), reason.incomplete().to_string()),
            ("samples".to_owned(), s.samples.to_string()),
            ("refused_samples".to_owned(), s.refused.to_string()),
            ("ticks".to_owned(), s.ticks.to_string()),
            ("failed_ticks".to_owned(), s.failed_ticks.to_string()),
            ("stale_periods".to_owned(), s.stale_periods.to_string()),
            (
                "stale_at_ns".to_owned(),
                serde_json::to_string(&s.stale_at_ns).unwrap_or_default(),
            ),
            ("last_tick_ns".to_owned(), self.session_ns().to_string()),
            (
                "glove_input".to_owned(),
                match self.drive {
                    Some(d) if d.torques() => "torques",
                    Some(_) => "positions",
                    None => "none",
                }
                .to_owned(),
            ),
        ]);
        if let Some(t) = s.first_contact_ns {
            meta.insert("first_contact_ns".to_owned(), t.to_string());
        }
        if let Some(m) = assist_meta {
            meta.extend(m);
        }
        recorder.add_metadata(LIVE_METADATA, meta)?;
        recorder.finish()?;
        Ok(self.stats)
    }
}
