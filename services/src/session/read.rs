//! Reading a session back: [`stream_session_file`] and [`stream_session_bytes`] check a session
//! file in one pass and hand its raw samples to a [`SessionVisitor`] as they come, holding a
//! chunk at a time whatever the file's length; [`read_session`] and its variants collect them
//! into a [`Session`].

use std::collections::BTreeMap;
use std::path::Path;

use super::messages::*;
use super::proto::schema_difference;
use super::wire;
use super::*;
use crate::error::{RecordingError, Result};
use crate::foxglove::{FRAME_TRANSFORMS_SCHEMA, JOINT_STATES_SCHEMA, SCENE_UPDATE_SCHEMA};
use crate::mcap_io::pool::Pool;
use crate::mcap_io::{
    check_message, json_error, message_location, stream_raw_bytes, stream_raw_file, MetadataRecord,
    RawTopic, RawVisitor, ReadLimits, StreamedRaw,
};
use crate::replay::REPLAY_METADATA;

/// A session read back: metadata, ground truth and the raw topics tick by tick. Every sample
/// is `(log_time_ns, message)` in file order.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    /// The `session` metadata record (empty if absent).
    pub metadata: BTreeMap<String, String>,
    /// Ground-truth phases (`ground_truth` record; empty if absent, e.g. for imports).
    pub phases: Vec<GroundTruthPhase>,
    /// `/glove/joint_states`.
    pub joint_states: Vec<(u64, GloveJointStates)>,
    /// `/glove/feedback`.
    pub feedback: Vec<(u64, GloveFeedback)>,
    /// `/dfs/contacts`.
    pub contacts: Vec<(u64, Contacts)>,
    /// `/object/state`.
    pub object: Vec<(u64, messages::ObjectState)>,
    /// Messages per topic, all topics of the file.
    pub message_counts: BTreeMap<String, usize>,
    /// The `replay` metadata record ([`crate::replay::REPLAY_METADATA`]): present only in a
    /// replay recording (`icms replay --out`, a stored replay's MCAP), `None` in a grasp session.
    pub replay: Option<BTreeMap<String, String>>,
}

impl Session {
    /// Number of ticks (messages on `/glove/joint_states`; 0 if that topic was not decoded,
    /// see [`DecodeTopics`]).
    pub fn ticks(&self) -> usize {
        self.joint_states.len()
    }

    /// The scenario name from the `session` record.
    pub fn scenario(&self) -> Option<&str> {
        self.metadata.get("scenario").map(String::as_str)
    }

    /// Whether this is a replay recording rather than a grasp session: it has a `replay`
    /// metadata record, or its `session` record says `source: replay` (both written by
    /// [`crate::replay::replay_skill`]). A replay records a robot hand driven along a skill,
    /// with no object description in its `session` record: segmenting it would find a skill of
    /// shape `unknown` with no parameters, a copy of a copy.
    pub fn is_replay(&self) -> bool {
        self.replay.is_some() || self.metadata.get("source").is_some_and(|s| s == "replay")
    }

    /// `Ok` for a grasp session; [`RecordingError::ReplayRecording`] (naming `name`, the
    /// replayed skill and the hand) for a replay recording, which has no skills to find;
    /// [`RecordingError::InvalidInput`] for a file whose `session` metadata does not name its
    /// object (the reader has checked an object that is there). For everything that segments
    /// or stores a file as a session.
    pub fn ensure_grasp_session(&self, name: &str) -> Result<()> {
        ensure_grasp_session(&self.metadata, self.replay.as_ref(), name)
    }
}

/// [`Session::ensure_grasp_session`] of a session's `session` and `replay` metadata records.
fn ensure_grasp_session(
    metadata: &BTreeMap<String, String>,
    replay: Option<&BTreeMap<String, String>>,
    name: &str,
) -> Result<()> {
    if !(replay.is_some() || metadata.get("source").is_some_and(|s| s == "replay")) {
        if metadata.get("object").is_none_or(|o| o.trim().is_empty()) {
            let record = if metadata.is_empty() {
                format!("has no `{SESSION_METADATA}` metadata record")
            } else {
                format!("has no `object` in its `{SESSION_METADATA}` metadata record")
            };
            return Err(RecordingError::InvalidInput {
                location: name.to_owned(),
                detail: format!(
                    "{record}: a grasp session names the object grasped (shape, sizes, \
             mass, mu, as a scenario file's `object`), which its skills carry into \
             the data base and onto robot hands"
                ),
            });
        }
        return Ok(());
    }
    let get = |key: &str| replay.and_then(|r| r.get(key)).filter(|v| !v.is_empty());
    let hand = get("hand")
        .or_else(|| metadata.get("replay_hand"))
        .or_else(|| metadata.get("hand"));
    let skill = get("skill").or_else(|| metadata.get("scenario"));
    let what = match (skill, hand) {
        (Some(s), Some(h)) => format!(" of {s} on the hand {h}"),
        (None, Some(h)) => format!(" on the hand {h}"),
        (Some(s), None) => format!(" of {s}"),
        (None, None) => String::new(),
    };
    Err(RecordingError::ReplayRecording {
        name: name.to_owned(),
        what,
    })
}

/// Which raw topics a read decodes into the [`Session`]. A topic left out is checked as one
/// kept (present, with its schema, every message of its type, its content consistent: the same
/// files are refused either way) but its list stays empty: segmentation needs only contacts and
/// object state, and keeping all four topics is most of the cost of reading a session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecodeTopics {
    /// `/glove/joint_states`.
    pub joint_states: bool,
    /// `/glove/feedback`.
    pub feedback: bool,
    /// `/dfs/contacts`.
    pub contacts: bool,
    /// `/object/state`.
    pub object: bool,
}

impl DecodeTopics {
    /// Every raw topic.
    pub const ALL: DecodeTopics = DecodeTopics {
        joint_states: true,
        feedback: true,
        contacts: true,
        object: true,
    };
    /// No raw topic.
    pub const NONE: DecodeTopics = DecodeTopics {
        joint_states: false,
        feedback: false,
        contacts: false,
        object: false,
    };
    /// What [`crate::segmentation::segment`] reads: contacts and object state.
    pub const SEGMENTATION: DecodeTopics = DecodeTopics {
        joint_states: false,
        feedback: false,
        contacts: true,
        object: true,
    };
}

impl DecodeTopics {
    /// The raw topics in either.
    pub const fn union(self, other: DecodeTopics) -> DecodeTopics {
        DecodeTopics {
            joint_states: self.joint_states || other.joint_states,
            feedback: self.feedback || other.feedback,
            contacts: self.contacts || other.contacts,
            object: self.object || other.object,
        }
    }

    /// Whether raw topic `RAW_TOPICS[i]` is among these.
    pub fn has(&self, i: usize) -> bool {
        match i {
            0 => self.joint_states,
            1 => self.feedback,
            2 => self.contacts,
            _ => self.object,
        }
    }
}

impl Default for DecodeTopics {
    fn default() -> Self {
        DecodeTopics::ALL
    }
}

/// What a session holds besides its samples: what [`stream_session_file`] returns once every
/// sample went to the visitor.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionHead {
    /// The `session` metadata record (empty if absent).
    pub metadata: BTreeMap<String, String>,
    /// Ground-truth phases (`ground_truth` record; empty if absent).
    pub phases: Vec<GroundTruthPhase>,
    /// Messages per topic, all topics of the file.
    pub message_counts: BTreeMap<String, usize>,
    /// The `replay` metadata record, present only in a replay recording.
    pub replay: Option<BTreeMap<String, String>>,
    /// The `live` metadata record ([`crate::live::LIVE_METADATA`]), present only in a live
    /// session: how it ended and whether it is complete.
    pub live: Option<BTreeMap<String, String>>,
    /// Log times of the first and last `/object/state` message (ns).
    pub object_span_ns: (u64, u64),
}

impl SessionHead {
    /// [`Session::ensure_grasp_session`] of this session.
    pub fn ensure_grasp_session(&self, name: &str) -> Result<()> {
        ensure_grasp_session(&self.metadata, self.replay.as_ref(), name)
    }

    /// The session without samples, to fill.
    fn into_session(self) -> Session {
        Session {
            metadata: self.metadata,
            phases: self.phases,
            joint_states: Vec::new(),
            feedback: Vec::new(),
            contacts: Vec::new(),
            object: Vec::new(),
            message_counts: self.message_counts,
            replay: self.replay,
        }
    }
}

/// Receives a session's raw samples, checked, in file order (each topic in time order; the
/// topics interleaved as written, tick by tick in our files). Each message is lent: copy
/// what you keep. An error stops the read and is its result.
///
/// The samples come before the end of the file is checked: a read can still fail after the
/// last one (a truncated file, a topic missing, metadata out of bounds). Keep nothing of a
/// read that failed.
pub trait SessionVisitor {
    /// A `/glove/joint_states` sample.
    fn joint_states(&mut self, _log_time_ns: u64, _m: &GloveJointStates) -> Result<()> {
        Ok(())
    }
    /// A `/glove/feedback` sample.
    fn feedback(&mut self, _log_time_ns: u64, _m: &GloveFeedback) -> Result<()> {
        Ok(())
    }
    /// A `/dfs/contacts` sample.
    fn contacts(&mut self, _log_time_ns: u64, _m: &Contacts) -> Result<()> {
        Ok(())
    }
    /// An `/object/state` sample.
    fn object(&mut self, _log_time_ns: u64, _m: &messages::ObjectState) -> Result<()> {
        Ok(())
    }
    /// The raw topics whose samples it takes: the others are checked on the reading thread,
    /// beside decompression, and never handed to it. Default: all four.
    fn wants(&self) -> DecodeTopics {
        DecodeTopics::ALL
    }
    /// Whether no sample to come can matter: a second read
    /// ([`SessionSource::stream_again`]) stops there. A first read checks the whole file
    /// whatever this says.
    fn done(&self) -> bool {
        false
    }
    /// Whether it reads of contacts and object states only what segmentation reads: each
    /// fingertip's name, `touching`, `in_contact`, `slip`, `point_b`, `normal_b` and
    /// `intensity`, and the object's `pose` and `pose_in_hand`. A second read from kept
    /// messages ([`SessionSource::stream_again_kept`]) then decodes only those, the other
    /// fields left zero. Default: false.
    fn segmentation_fields_only(&self) -> bool {
        false
    }
}

/// A visitor that keeps nothing: [`stream_session_file`] with it only checks the file.
impl SessionVisitor for () {
    fn wants(&self) -> DecodeTopics {
        DecodeTopics::NONE
    }
}

/// Reads a session file with [`ReadLimits::streaming`]. See [`read_session_with_limits`].
pub fn read_session(path: impl AsRef<Path>) -> Result<Session> {
    read_session_with_limits(path, &ReadLimits::streaming())
}

/// Reads a session file safely (CRC prevalidation, record length limit, decompression bounded
/// by the file's length: [`ReadLimits::decompressed_limit`]). The four raw topics must be
/// present with their `icms.*` schemas ([`RecordingError::MissingTopic`],
/// [`RecordingError::UnknownSchema`] otherwise); Foxglove topics, if present, must carry their
/// official schema names. A malformed `ground_truth` record is [`RecordingError::InvalidInput`].
///
/// The content is checked too, each error naming the topic, the message's number and log time
/// and the field ([`RecordingError::InvalidInput`], or [`RecordingError::InvalidJson`] for a
/// message not of its type, a number beyond a finite `f64` included):
///
/// - every raw topic spans at least [`MIN_SESSION_NS`] (two ticks);
/// - `/glove/joint_states` and `/glove/feedback`: 1 to [`MAX_SESSION_DOFS`] `names`, each
///   array one element per name, the names those of `/glove/joint_states` message 0;
/// - `/dfs/contacts` and `/glove/feedback`: 1 to [`MAX_SESSION_FINGERS`] `fingers`, named as in
///   `/dfs/contacts` message 0;
/// - `/dfs/contacts`: the normal of every finger touching a unit vector, and `/object/state`:
///   `pose.orientation` and `pose_in_hand.orientation` unit quaternions (within
///   [`UNIT_NORM_TOLERANCE`]);
/// - metadata: at most one `session`, `ground_truth` and `replay` record, at most
///   [`MAX_METADATA_RECORDS`] records, [`MAX_METADATA_ENTRIES`] entries per record, keys of
///   [`MAX_METADATA_KEY_BYTES`], values of [`MAX_METADATA_VALUE_BYTES`],
///   [`MAX_METADATA_BYTES`] in all.
///
/// In format 2 (protobuf) a raw topic's schema must define its message field for field as ours
/// ([`super::proto::schema_difference`]; at most [`MAX_RAW_SCHEMA_BYTES`]), every message must
/// decode (the error names the topic and the message's index), and the Foxglove topics'
/// messages of up to [`MAX_CHECKED_FOXGLOVE_MESSAGE_BYTES`] must decode as the SDK's types. In
/// both formats a raw message holds at most [`MAX_RAW_MESSAGE_BYTES`].
///
/// Not checked, being harmless: the Foxglove topics' content beyond that (for viewers only),
/// `n_contacts` (segmentation counts the fingers in contact itself), the normal of a finger
/// not touching (segmentation ignores it).
pub fn read_session_with_limits(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<Session> {
    read_session_file_with(path, limits, DecodeTopics::ALL)
}

/// [`read_session_with_limits`] keeping only the raw topics in `topics` (the others are
/// checked and left empty).
pub fn read_session_file_with(
    path: impl AsRef<Path>,
    limits: &ReadLimits,
    topics: DecodeTopics,
) -> Result<Session> {
    let mut keep = Collect::new(topics);
    let head = stream_session_file(path, limits, &mut keep)?;
    Ok(keep.into_session(head))
}

/// Reads a session from bytes already in memory (for example an HTTP upload), with the same
/// checks as [`read_session_with_limits`]; `name` appears in error messages.
pub fn read_session_bytes(bytes: &[u8], name: &str, limits: &ReadLimits) -> Result<Session> {
    read_session_bytes_with(bytes, name, limits, DecodeTopics::ALL)
}

/// [`read_session_bytes`] keeping only the raw topics in `topics` (the others are checked and
/// left empty).
pub fn read_session_bytes_with(
    bytes: &[u8],
    name: &str,
    limits: &ReadLimits,
    topics: DecodeTopics,
) -> Result<Session> {
    let mut keep = Collect::new(topics);
    let head = stream_session_bytes(bytes, name, limits, &mut keep)?;
    Ok(keep.into_session(head))
}

/// Checks the session file at `path` in one pass, as [`read_session_with_limits`] describes,
/// handing its raw samples to `visitor` as they are read: memory is bounded by the chunk size,
/// not the file.
pub fn stream_session_file(
    path: impl AsRef<Path>,
    limits: &ReadLimits,
    visitor: &mut impl SessionVisitor,
) -> Result<SessionHead> {
    stream_source(&SessionSource::File(path.as_ref()), limits, visitor, None)
}

/// [`stream_session_file`] of bytes in memory; `name` appears in error messages.
pub fn stream_session_bytes(
    bytes: &[u8],
    name: &str,
    limits: &ReadLimits,
    visitor: &mut impl SessionVisitor,
) -> Result<SessionHead> {
    stream_source(&SessionSource::Bytes { bytes, name }, limits, visitor, None)
}

/// [`stream_session_file`] or [`stream_session_bytes`] of `source`, keeping the messages
/// handed to `visitor` in `keep` if given.
fn stream_source(
    source: &SessionSource<'_>,
    limits: &ReadLimits,
    visitor: &mut impl SessionVisitor,
    keep: Option<&mut KeptMessages>,
) -> Result<SessionHead> {
    let mut nothing = ();
    // The reading thread checks the raw topics neither the visitor takes nor `keep` keeps;
    // the others come to this one. A thread finds a file's faults in file order, so the two
    // glove topics are checked on one thread: a file whose joint states and feedback are both
    // broken is refused naming the same message by every read.
    let kept_also = keep.as_ref().map_or(DecodeTopics::NONE, |k| k.also);
    let mut here = visitor.wants().union(kept_also);
    if here.joint_states || here.feedback {
        here.joint_states = true;
        here.feedback = true;
    }
    let mut early = Checker::early(&mut nothing, here);
    let mut checker = Checker::new(visitor);
    let len = match source {
        SessionSource::File(path) => {
            std::fs::metadata(path).map_or(0, |m| usize::try_from(m.len()).unwrap_or(usize::MAX))
        }
        SessionSource::Bytes { bytes, .. } => bytes.len(),
    };
    checker.keep = keep.map(|k| k.start(checker.visitor.wants(), len));
    let (raw, name) = match source {
        SessionSource::File(path) => (
            stream_raw_file(path, limits, &mut early, &mut checker)?,
            path.display().to_string(),
        ),
        SessionSource::Bytes { bytes, name } => (
            stream_raw_bytes(bytes, limits, &mut early, &mut checker)?,
            (*name).to_owned(),
        ),
    };
    checker.finish(raw, early, &name)
}

/// Default budget of [`KeptMessages`]: 32 MiB, the contacts and object states of about two
/// minutes of session (190 to 240 bytes a millisecond, and 48 of index).
pub const KEPT_MESSAGES_BUDGET: usize = 32 << 20;

/// The raw messages a first read ([`SessionSource::stream_keeping`]) handed its visitor, as
/// they were in the file, for a second read ([`SessionSource::stream_again_kept`]) that then
/// reads no file: no decompression, no CRC, no framing, and no checks (these very bytes were
/// checked). Up to a budget of bytes: a read that would keep more drops them all and keeps
/// nothing further (the second read then reads the file again), so memory stays bounded
/// whatever the session's length.
#[derive(Debug)]
pub struct KeptMessages {
    budget: usize,
    /// Raw topics kept besides those the first read's visitor takes ([`KeptMessages::also`]).
    also: DecodeTopics,
    /// The raw topics kept: those the first read's visitor took, and `also`.
    topics: DecodeTopics,
    /// Whether every message of `topics` the read handed on is here (false once over budget,
    /// or before a read).
    complete: bool,
    messages: Vec<KeptMessage>,
    bytes: Vec<u8>,
}

/// One kept message: where its payload lies in [`KeptMessages::bytes`], what it was.
#[derive(Debug, Clone, Copy)]
struct KeptMessage {
    log_time_ns: u64,
    start: u32,
    len: u32,
    index: u32,
    raw: u8,
    protobuf: bool,
}

/// The payloads of kept messages, reused from one segmentation to the next (16 MiB: a
/// minute of session, or a few short ones analysed side by side).
static KEPT_BYTES: Pool<u8> = Pool::new(16 << 20, 1);
/// Their index, likewise (a minute's is 3 MB).
static KEPT_INDEX: Pool<KeptMessage> = Pool::new(6 << 20, 1);

impl KeptMessages {
    /// Keeps at most `budget` bytes (payloads and their index).
    pub fn new(budget: usize) -> Self {
        KeptMessages {
            budget,
            also: DecodeTopics::NONE,
            topics: DecodeTopics::NONE,
            complete: false,
            messages: Vec::new(),
            bytes: Vec::new(),
        }
    }

    /// Keeps the messages of `topics` as well as those the first read's visitor takes, for a
    /// later reader of other topics (ingest's approach templates read the joint angles after
    /// segmentation, which reads contacts and object states).
    pub fn also(mut self, topics: DecodeTopics) -> Self {
        self.also = topics;
        self
    }

    /// Empty, ready to keep the messages of `topics` of a new read of a file of `len` bytes
    /// (their room taken at once: the contacts and object states are 85 to 100 % of one of
    /// our session files' length, one message per 95 to 120 bytes of it).
    fn start(&mut self, topics: DecodeTopics, len: usize) -> &mut Self {
        self.release();
        let room = len.min(self.budget);
        self.bytes = KEPT_BYTES.take(room);
        self.bytes.clear();
        self.messages = KEPT_INDEX.take(room / 90);
        self.messages.clear();
        self.topics = topics.union(self.also);
        self.complete = true;
        self
    }

    /// Gives the buffers back to their pools.
    fn release(&mut self) {
        KEPT_BYTES.give(std::mem::take(&mut self.bytes));
        KEPT_INDEX.give(std::mem::take(&mut self.messages));
    }

    /// Whether it holds every message of `topics` of the read (none dropped for the budget).
    pub fn covers(&self, topics: DecodeTopics) -> bool {
        self.complete && (0..RAW_TOPICS.len()).all(|i| !topics.has(i) || self.topics.has(i))
    }

    /// Bytes held (payloads and index).
    pub fn held_bytes(&self) -> usize {
        self.bytes.len() + self.messages.len() * std::mem::size_of::<KeptMessage>()
    }

    /// Keeps a message; over the budget (or past what the index can say), drops everything.
    fn keep(&mut self, raw: usize, protobuf: bool, index: usize, t: u64, data: &[u8]) {
        if !self.complete || !self.topics.has(raw) {
            return;
        }
        let entry = (
            u32::try_from(self.bytes.len()),
            u32::try_from(data.len()),
            u32::try_from(index),
        );
        let over =
            self.held_bytes() + data.len() + std::mem::size_of::<KeptMessage>() > self.budget;
        match entry {
            (Ok(start), Ok(len), Ok(index)) if !over => {
                self.bytes.extend_from_slice(data);
                self.messages.push(KeptMessage {
                    log_time_ns: t,
                    start,
                    len,
                    index,
                    raw: raw as u8,
                    protobuf,
                });
            }
            _ => {
                self.complete = false;
                self.release();
            }
        }
    }
}

impl Drop for KeptMessages {
    fn drop(&mut self) {
        self.release();
    }
}

/// Where a session is read from, as many times as a reader needs (segmentation reads twice).
#[derive(Debug, Clone, Copy)]
pub enum SessionSource<'a> {
    /// A file.
    File(&'a Path),
    /// Bytes in memory, and the name errors give them.
    Bytes {
        /// The file's bytes.
        bytes: &'a [u8],
        /// What errors call them (an upload's name).
        name: &'a str,
    },
}

impl SessionSource<'_> {
    /// What errors call the session: the file's path or the bytes' name.
    pub fn name(&self) -> String {
        match self {
            SessionSource::File(path) => path.display().to_string(),
            SessionSource::Bytes { name, .. } => (*name).to_owned(),
        }
    }

    /// A second read of a source that [`SessionSource::stream`] read without error: only the
    /// raw topics the visitor [wants](SessionVisitor::wants) are decoded (and checked as they
    /// are) and handed to it, the rest of the file is only framed and its CRCs checked; the
    /// read stops as soon as the visitor is [`done`](SessionVisitor::done). For readers that
    /// need two passes (segmentation).
    pub fn stream_again(
        &self,
        limits: &ReadLimits,
        visitor: &mut impl SessionVisitor,
    ) -> Result<()> {
        let topics = visitor.wants();
        let mut checker = Checker::new(visitor);
        checker.again = Some(topics);
        let read = match *self {
            SessionSource::File(path) => {
                stream_raw_file(path, limits, &mut (), &mut checker).map(drop)
            }
            SessionSource::Bytes { bytes, .. } => {
                stream_raw_bytes(bytes, limits, &mut (), &mut checker).map(drop)
            }
        };
        match read {
            Err(_) if checker.stopped => Ok(()),
            other => other,
        }
    }

    /// [`stream_session_file`] or [`stream_session_bytes`] of the source.
    pub fn stream(
        &self,
        limits: &ReadLimits,
        visitor: &mut impl SessionVisitor,
    ) -> Result<SessionHead> {
        self.stream_with(limits, visitor, None)
    }

    /// [`SessionSource::stream`] keeping the raw messages handed to `visitor` in `keep`
    /// (within its budget), for [`SessionSource::stream_again_kept`].
    pub fn stream_keeping(
        &self,
        limits: &ReadLimits,
        visitor: &mut impl SessionVisitor,
        keep: &mut KeptMessages,
    ) -> Result<SessionHead> {
        let head = self.stream_with(limits, visitor, Some(&mut *keep));
        if head.is_err() {
            // Nothing of a read that failed is to be used.
            keep.complete = false;
            keep.release();
        }
        head
    }

    fn stream_with(
        &self,
        limits: &ReadLimits,
        visitor: &mut impl SessionVisitor,
        keep: Option<&mut KeptMessages>,
    ) -> Result<SessionHead> {
        stream_source(self, limits, visitor, keep)
    }

    /// [`SessionSource::stream_again`] from the messages `kept` by a first read of the source
    /// ([`SessionSource::stream_keeping`], without error) if it holds all the visitor
    /// [wants](SessionVisitor::wants): they are decoded and handed on, in file order, until
    /// the visitor is [`done`](SessionVisitor::done), and no file is read. Otherwise the
    /// source is read again as [`SessionSource::stream_again`] does.
    pub fn stream_again_kept(
        &self,
        limits: &ReadLimits,
        visitor: &mut impl SessionVisitor,
        kept: &KeptMessages,
    ) -> Result<()> {
        let topics = visitor.wants();
        if !kept.covers(topics) {
            return self.stream_again(limits, visitor);
        }
        let lean = visitor.segmentation_fields_only();
        let mut checker = Checker::new(visitor);
        checker.again = Some(topics);
        checker.checked_before = true;
        checker.lean = lean;
        for m in &kept.messages {
            let raw = usize::from(m.raw);
            if !topics.has(raw) {
                continue;
            }
            let start = m.start as usize;
            let data = &kept.bytes[start..start + m.len as usize];
            checker.raw_message(
                raw,
                m.protobuf,
                RAW_TOPICS[raw],
                m.index as usize,
                m.log_time_ns,
                data,
            )?;
            if checker.visitor.done() {
                break;
            }
        }
        Ok(())
    }
}

/// Keeps the samples of the topics asked for.
struct Collect {
    topics: DecodeTopics,
    joint_states: Vec<(u64, GloveJointStates)>,
    feedback: Vec<(u64, GloveFeedback)>,
    contacts: Vec<(u64, Contacts)>,
    object: Vec<(u64, messages::ObjectState)>,
}

impl Collect {
    fn new(topics: DecodeTopics) -> Self {
        Collect {
            topics,
            joint_states: Vec::new(),
            feedback: Vec::new(),
            contacts: Vec::new(),
            object: Vec::new(),
        }
    }

    fn into_session(self, head: SessionHead) -> Session {
        Session {
            joint_states: self.joint_states,
            feedback: self.feedback,
            contacts: self.contacts,
            object: self.object,
            ..head.into_session()
        }
    }
}

impl SessionVisitor for Collect {
    fn wants(&self) -> DecodeTopics {
        self.topics
    }
    fn joint_states(&mut self, t: u64, m: &GloveJointStates) -> Result<()> {
        if self.topics.joint_states {
            self.joint_states.push((t, m.clone()));
        }
        Ok(())
    }
    fn feedback(&mut self, t: u64, m: &GloveFeedback) -> Result<()> {
        if self.topics.feedback {
            self.feedback.push((t, m.clone()));
        }
        Ok(())
    }
    fn contacts(&mut self, t: u64, m: &Contacts) -> Result<()> {
        if self.topics.contacts {
            self.contacts.push((t, m.clone()));
        }
        Ok(())
    }
    fn object(&mut self, t: u64, m: &messages::ObjectState) -> Result<()> {
        if self.topics.object {
            self.object.push((t, m.clone()));
        }
        Ok(())
    }
}

/// The `session` metadata's `object` (when there is one, not empty) must describe a real object: a known
/// shape with positive finite sizes and mass, μ and torsional μ finite and ≥ 0. Skills carry
/// it into the store's filters and onto robot hands, so an impossible one is refused here, at
/// the boundary, naming the field.
fn check_session_object(metadata: &BTreeMap<String, String>, name: &str) -> Result<()> {
    let Some(text) = metadata.get("object").filter(|t| !t.trim().is_empty()) else {
        return check_session_objects(metadata, name);
    };
    let invalid = |detail: String| RecordingError::InvalidInput {
        location: format!("{name}: metadata session.object"),
        detail,
    };
    // With the path of a field that does not parse (`object.shape: unknown shape ...`).
    let mut de = serde_json::Deserializer::from_str(text);
    let o: dfs_core::scenario::ScenarioObject =
        serde_path_to_error::deserialize(&mut de).map_err(|e| {
            match e.path().to_string().as_str() {
                "." => invalid(e.inner().to_string()),
                path => invalid(format!("object.{path}: {}", e.inner())),
            }
        })?;
    de.end().map_err(|e| invalid(e.to_string()))?;
    o.to_object().map_err(|e| invalid(e.to_string()))?;
    check_session_objects(metadata, name)
}

/// The `objects` and `target` of a session's `session` metadata record (a scene of several
/// objects), if it has them: a JSON list of 1 to 8 objects as a scenario file's, each named
/// (1 to 64 characters, unique) and a valid object, and the name of one of them. Errors name
/// the field.
fn check_session_objects(metadata: &BTreeMap<String, String>, name: &str) -> Result<()> {
    use dfs_core::scenario::{ScenarioObject, MAX_OBJECTS, MAX_OBJECT_NAME_CHARS};
    let invalid = |field: String, detail: String| RecordingError::InvalidInput {
        location: format!("{name}: metadata session.{field}"),
        detail,
    };
    let (objects, target) = match (metadata.get("objects"), metadata.get("target")) {
        (None, None) => return Ok(()),
        (Some(o), Some(t)) => (o, t),
        (None, Some(_)) => {
            return Err(invalid(
                "objects".into(),
                "missing: `target` names one of the scene's `objects`".into(),
            ))
        }
        (Some(_), None) => {
            return Err(invalid(
                "target".into(),
                "missing: which of the `objects` is grasped".into(),
            ))
        }
    };
    let mut de = serde_json::Deserializer::from_str(objects);
    let list: Vec<ScenarioObject> = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        invalid(
            format!("objects{}", path_suffix(&e.path().to_string())),
            e.inner().to_string(),
        )
    })?;
    if !(1..=MAX_OBJECTS).contains(&list.len()) {
        return Err(invalid(
            "objects".into(),
            format!("{} objects; a scene holds 1 to {MAX_OBJECTS}", list.len()),
        ));
    }
    let mut names: Vec<&str> = Vec::with_capacity(list.len());
    for (i, o) in list.iter().enumerate() {
        let n = o.name.as_deref().unwrap_or("");
        let chars = n.chars().count();
        if !(1..=MAX_OBJECT_NAME_CHARS).contains(&chars) || n.chars().any(char::is_control) {
            return Err(invalid(
                format!("objects[{i}].name"),
                format!(
                    "must be 1 to {MAX_OBJECT_NAME_CHARS} characters, none a control character"
                ),
            ));
        }
        if names.contains(&n) {
            return Err(invalid(
                format!("objects[{i}].name"),
                format!("{n:?} names two objects"),
            ));
        }
        names.push(n);
        o.to_object()
            .map_err(|e| invalid(format!("objects[{i}]"), e.to_string()))?;
    }
    if !names.contains(&target.as_str()) {
        return Err(invalid(
            "target".into(),
            format!("{target:?} names none of the `objects`"),
        ));
    }
    Ok(())
}

/// A `serde_path_to_error` path as a suffix of a field (`[2].mass`; empty for the root).
fn path_suffix(path: &str) -> String {
    match path {
        "." => String::new(),
        p if p.starts_with('[') => p.to_owned(),
        p => format!(".{p}"),
    }
}

/// The metadata records are few and small, and name the session once: at most
/// [`MAX_METADATA_RECORDS`] records of at most [`MAX_METADATA_ENTRIES`] entries, keys of at
/// most [`MAX_METADATA_KEY_BYTES`], values of at most [`MAX_METADATA_VALUE_BYTES`], at most
/// [`MAX_METADATA_BYTES`] in all, and one record at most named `session`, `ground_truth` or
/// `replay` (a second one would be ignored: which one describes the session?). The store keeps
/// the `session` record with the session and lists it with every page of sessions.
fn check_metadata(records: &[MetadataRecord], name: &str) -> Result<()> {
    let invalid = |location: String, detail: String| RecordingError::InvalidInput {
        location: format!("{name}: metadata {location}"),
        detail,
    };
    if records.len() > MAX_METADATA_RECORDS {
        return Err(invalid(
            "records".into(),
            format!(
                "the file has {} metadata records; a session has at most {MAX_METADATA_RECORDS}",
                records.len()
            ),
        ));
    }
    for unique in [
        SESSION_METADATA,
        GROUND_TRUTH_METADATA,
        REPLAY_METADATA,
        crate::live::LIVE_METADATA,
        super::recorder::OVERLAPS_METADATA,
    ] {
        let n = records.iter().filter(|r| r.name == unique).count();
        if n > 1 {
            return Err(invalid(
                unique.to_owned(),
                format!(
                    "the file has {n} `{unique}` metadata records; a session has one at most \
                     (which would describe it?)"
                ),
            ));
        }
    }
    let mut total = 0usize;
    for record in records {
        let r = &record.name;
        if record.entries.len() > MAX_METADATA_ENTRIES {
            return Err(invalid(
                r.clone(),
                format!(
                    "has {} entries; a metadata record has at most {MAX_METADATA_ENTRIES}",
                    record.entries.len()
                ),
            ));
        }
        total += r.len();
        for (key, value) in &record.entries {
            if key.len() > MAX_METADATA_KEY_BYTES {
                let shown: String = key.chars().take(40).collect();
                return Err(invalid(
                    format!("{r}.{shown}…"),
                    format!(
                        "the key is {} bytes long; a key has at most {MAX_METADATA_KEY_BYTES}",
                        key.len()
                    ),
                ));
            }
            if value.len() > MAX_METADATA_VALUE_BYTES {
                return Err(invalid(
                    format!("{r}.{key}"),
                    format!(
                        "the value is {} bytes long; a metadata value has at most {} bytes",
                        value.len(),
                        MAX_METADATA_VALUE_BYTES
                    ),
                ));
            }
            total += key.len() + value.len();
        }
        if total > MAX_METADATA_BYTES {
            return Err(invalid(
                r.clone(),
                format!(
                    "the metadata records hold more than {MAX_METADATA_BYTES} bytes of names, \
                     keys and values; a session's metadata holds at most that"
                ),
            ));
        }
    }
    Ok(())
}

/// Largest raw message (bytes), in either format: ours are under 2 kB (a tick of a 30-DOF
/// hand), and the most a session may hold ([`MAX_SESSION_DOFS`] names and values,
/// [`MAX_SESSION_FINGERS`] fingertips) is far under this. Bigger messages are refused before
/// they are decoded: decoding may take a hundred times their size (an empty nested protobuf
/// message, or an empty JSON string, is 2 bytes of input and a struct or `String` in memory).
pub const MAX_RAW_MESSAGE_BYTES: usize = 256 * 1024;

/// Largest protobuf schema of a raw topic (bytes): ours is a few kB. A bigger one is refused
/// before it is decoded to be compared with ours (an empty file descriptor is 2 bytes of
/// input and hundreds in memory).
pub const MAX_RAW_SCHEMA_BYTES: usize = 64 * 1024;

/// Largest Foxglove message of format 2 that is decoded to be checked (bytes); bigger ones
/// (another tool's meshes in `/scene`, say) are for viewers and left unchecked rather than
/// decoded at a hundred times their size.
pub const MAX_CHECKED_FOXGLOVE_MESSAGE_BYTES: usize = 256 * 1024;

/// How far apart the raw topics' first (and last) log times may lie (ns): they are written
/// together, tick by tick, so a session's topics start and end within a tick of each other;
/// a file in which one stops early (a writer that lost a stream) would segment as a shorter
/// session than its glove stream says.
pub const RAW_TOPIC_SKEW_NS: u64 = 100_000_000;

/// What a topic is to the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// Raw topic `RAW_TOPICS[i]`, protobuf (format 2) or JSON (format 1).
    Raw(usize, bool),
    /// A Foxglove topic of ours, protobuf: decoded as the SDK's type to be checked.
    Foxglove(FoxgloveType),
    /// Another JSON topic: checked to be JSON.
    Json,
    /// Another topic: not ours to check.
    Other,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FoxgloveType {
    FrameTransforms,
    SceneUpdate,
    JointStates,
}

/// The check of a Foxglove type's messages, made once from the SDK's schema (`None` if it
/// could not be: prost decodes them then).
fn foxglove_check(which: FoxgloveType) -> Option<&'static wire::MessageCheck> {
    use foxglove::messages as fg;
    use foxglove::Encode;
    static CHECKS: std::sync::OnceLock<[Option<wire::MessageCheck>; 3]> =
        std::sync::OnceLock::new();
    let checks = CHECKS.get_or_init(|| {
        let make = |schema: Option<foxglove::Schema>| {
            schema.and_then(|s| wire::MessageCheck::new(&s.data, &s.name))
        };
        [
            make(fg::FrameTransforms::get_schema()),
            make(fg::SceneUpdate::get_schema()),
            make(fg::JointStates::get_schema()),
        ]
    });
    let i = match which {
        FoxgloveType::FrameTransforms => 0,
        FoxgloveType::SceneUpdate => 1,
        FoxgloveType::JointStates => 2,
    };
    checks[i].as_ref()
}

/// Per raw topic: what its log times were so far.
#[derive(Debug, Clone, Copy, Default)]
struct Times {
    first: Option<u64>,
    last: u64,
    count: usize,
}

/// The messages decoded, reused from one to the next.
#[derive(Default)]
struct Scratch {
    joint_states: GloveJointStates,
    feedback: GloveFeedback,
    contacts: Contacts,
    object: messages::ObjectState,
    /// `/glove/joint_states` and `/glove/feedback` read for their checks alone.
    shapes: [GloveShape; 2],
    /// Per glove topic: its last message passed the checks of its names.
    names_checked: [bool; 2],
}

/// The checks of a session read in one pass, in front of a [`SessionVisitor`].
struct Checker<'v, V: SessionVisitor> {
    visitor: &'v mut V,
    kinds: Vec<Kind>,
    times: [Times; 4],
    /// The first raw log time seen so far.
    t0: Option<u64>,
    /// Per raw topic, its DOF and fingertip names as its message 0 lists them: each message is
    /// checked against its own topic's (whichever thread checks it); the topics against each
    /// other at the end.
    references: [TickReference; 4],
    scratch: Scratch,
    /// A second read of a file read and checked before: only these raw topics are decoded
    /// (and checked as they are), the others and the file-wide checks skipped.
    again: Option<DecodeTopics>,
    /// A second read stopped because the visitor was done (the error that stopped the
    /// reader is not one).
    stopped: bool,
    /// The checker of the reading thread, for a visitor that takes these raw topics: it
    /// claims the others, and the Foxglove and other JSON topics.
    early_for: Option<DecodeTopics>,
    /// Where the raw messages handed to the visitor are kept for a second read.
    keep: Option<&'v mut KeptMessages>,
    /// The raw topics the visitor takes.
    wants: DecodeTopics,
    /// The messages were read and checked before, these very bytes ([`KeptMessages`]): they
    /// are only decoded.
    checked_before: bool,
    /// With `checked_before`: contacts and object states are decoded only as far as the
    /// visitor reads them ([`SessionVisitor::segmentation_fields_only`]).
    lean: bool,
}

impl<'v, V: SessionVisitor> Checker<'v, V> {
    fn new(visitor: &'v mut V) -> Self {
        Checker {
            wants: visitor.wants(),
            visitor,
            kinds: Vec::new(),
            times: [Times::default(); 4],
            t0: None,
            references: Default::default(),
            scratch: Scratch::default(),
            again: None,
            stopped: false,
            early_for: None,
            keep: None,
            checked_before: false,
            lean: false,
        }
    }
}

impl<'v> Checker<'v, ()> {
    /// The checker of the reading thread for a visitor that takes `wants`.
    fn early(nothing: &'v mut (), wants: DecodeTopics) -> Self {
        let mut checker = Checker::new(nothing);
        checker.early_for = Some(wants);
        checker
    }
}

impl<'v, V: SessionVisitor> Checker<'v, V> {
    /// A raw message's log time: in its topic's time order, within 2^63 ns and
    /// [`MAX_SESSION_NS`] of the first raw message seen.
    fn check_time(&mut self, raw: usize, topic: &str, index: usize, t: u64) -> Result<()> {
        let times = &mut self.times[raw];
        let t0 = *self.t0.get_or_insert(t);
        let prev = if times.count == 0 {
            t0.min(t)
        } else {
            times.last
        };
        let problem = if t > i64::MAX as u64 {
            Some("the log time is beyond 2^63 ns".to_owned())
        } else if t < prev {
            Some(format!(
                "the log time goes back before the previous message's ({prev} ns): a raw topic \
                 must be in time order"
            ))
        } else if t.saturating_sub(t0) > MAX_SESSION_NS {
            Some(format!(
                "the log time is {:.1} s after the session's first message; a session spans at \
                 most {} s",
                (t - t0) as f64 * 1e-9,
                MAX_SESSION_NS / 1_000_000_000
            ))
        } else {
            None
        };
        if let Some(detail) = problem {
            return Err(RecordingError::InvalidInput {
                location: format!("topic {topic} message {index} (log time {t} ns)"),
                detail,
            });
        }
        times.first.get_or_insert(t);
        times.last = t;
        times.count += 1;
        self.t0 = Some(t0.min(t));
        Ok(())
    }

    /// Decodes raw message `index` of `topic` (raw topic `raw`) into the scratch message,
    /// checks it and hands it on.
    fn raw_message(
        &mut self,
        raw: usize,
        protobuf: bool,
        name: &str,
        index: usize,
        t: u64,
        data: &[u8],
    ) -> Result<()> {
        if self.checked_before {
            // These bytes passed every check in a first read: decoded only.
            if self.lean && protobuf && raw >= 2 {
                let s = &mut self.scratch;
                let lean = if raw == 2 {
                    wire::contacts_lean(data, &mut s.contacts)
                } else {
                    wire::object_lean(data, &mut s.object)
                };
                lean.map_err(|e| undecodable(raw, name, index, t, e))?;
            } else {
                self.decode(raw, protobuf, name, index, t, data)?;
            }
            let s = &self.scratch;
            return match raw {
                0 => self.visitor.joint_states(t, &s.joint_states),
                1 => self.visitor.feedback(t, &s.feedback),
                2 => self.visitor.contacts(t, &s.contacts),
                _ => self.visitor.object(t, &s.object),
            };
        }
        if data.len() > MAX_RAW_MESSAGE_BYTES {
            return Err(RecordingError::InvalidInput {
                location: message_location(name, index, t),
                detail: format!(
                    "the message is {} bytes; a message of this topic holds at most \
                     {MAX_RAW_MESSAGE_BYTES}",
                    data.len()
                ),
            });
        }
        self.check_time(raw, name, index, t)?;
        let invalid = |detail: String| RecordingError::InvalidInput {
            location: message_location(name, index, t),
            detail,
        };
        if protobuf && raw < 2 && !self.wants.has(raw) {
            // A glove topic no one takes: read only as far as its checks need (no value
            // converted), its names compared with the reference only when they changed.
            let shape = &mut self.scratch.shapes[raw];
            wire::glove_shape(data, raw == 1, shape)
                .map_err(|e| undecodable(raw, name, index, t, e))?;
            let r = &mut self.references[raw];
            r.learn_dofs(name, &shape.names);
            if raw == 1 {
                r.learn_fingers(name, shape.fingers.iter().map(String::as_str));
            }
            let checked = shape.unchanged && self.scratch.names_checked[raw];
            shape.check(raw == 1, r, checked).map_err(invalid)?;
            self.scratch.names_checked[raw] = true;
            return Ok(());
        }
        self.decode(raw, protobuf, name, index, t, data)?;
        let s = &mut self.scratch;
        let r = &mut self.references[raw];
        match raw {
            0 => {
                r.learn_dofs(name, &s.joint_states.names);
                s.joint_states.check(r).map_err(invalid)?;
                self.visitor.joint_states(t, &s.joint_states)
            }
            1 => {
                r.learn_dofs(name, &s.feedback.names);
                r.learn_fingers(name, s.feedback.fingers.iter().map(|f| f.name.as_str()));
                s.feedback.check(r).map_err(invalid)?;
                self.visitor.feedback(t, &s.feedback)
            }
            2 => {
                r.learn_fingers(name, s.contacts.fingers.iter().map(|f| f.name.as_str()));
                s.contacts.check(r).map_err(invalid)?;
                self.visitor.contacts(t, &s.contacts)
            }
            _ => {
                s.object.check(r).map_err(invalid)?;
                self.visitor.object(t, &s.object)
            }
        }
    }

    /// Decodes raw message `index` of `name` (raw topic `raw`) into the scratch message.
    fn decode(
        &mut self,
        raw: usize,
        protobuf: bool,
        name: &str,
        index: usize,
        t: u64,
        data: &[u8],
    ) -> Result<()> {
        let s = &mut self.scratch;
        let undecodable = |e: wire::DecodeError| undecodable(raw, name, index, t, e);
        fn json<T: serde::de::DeserializeOwned>(
            topic: &str,
            index: usize,
            t: u64,
            data: &[u8],
        ) -> Result<T> {
            serde_json::from_slice(data).map_err(|e| json_error::<T>(topic, index, t, data, e))
        }
        match (raw, protobuf) {
            (0, true) => wire::joint_states(data, &mut s.joint_states).map_err(undecodable)?,
            (0, false) => s.joint_states = json(name, index, t, data)?,
            (1, true) => wire::feedback(data, &mut s.feedback).map_err(undecodable)?,
            (1, false) => s.feedback = json(name, index, t, data)?,
            (2, true) => wire::contacts(data, &mut s.contacts).map_err(undecodable)?,
            (2, false) => s.contacts = json(name, index, t, data)?,
            (_, true) => wire::object(data, &mut s.object).map_err(undecodable)?,
            (_, false) => s.object = json(name, index, t, data)?,
        }
        Ok(())
    }

    /// The checks that need the whole file: every raw topic there and spanning the session,
    /// the metadata.
    fn finish(
        mut self,
        raw: StreamedRaw,
        early: Checker<'_, ()>,
        name: &str,
    ) -> Result<SessionHead> {
        if self.again.is_some() {
            return Ok(SessionHead::default());
        }
        // The raw topics the reading thread checked.
        for ((mine, theirs), (my_ref, their_ref)) in self
            .times
            .iter_mut()
            .zip(early.times)
            .zip(self.references.iter_mut().zip(early.references))
        {
            if mine.count == 0 {
                *mine = theirs;
                *my_ref = their_ref;
            }
        }
        // The topics name the same hand: /glove/feedback the DOFs of /glove/joint_states and
        // the fingertips of /dfs/contacts.
        let [joints, feedback, contacts, _] = &self.references;
        for (what, a, b) in [
            ("DOF names", &joints.dof_names, &feedback.dof_names),
            ("fingertips", &contacts.finger_names, &feedback.finger_names),
        ] {
            if let (Some(a), Some(b)) = (a, b) {
                if a != b {
                    let (source_a, source_b) = if what == "DOF names" {
                        (&joints.dof_source, &feedback.dof_source)
                    } else {
                        (&contacts.finger_source, &feedback.finger_source)
                    };
                    return Err(RecordingError::InvalidInput {
                        location: format!("{name}: topic {TOPIC_GLOVE_FEEDBACK}"),
                        detail: format!(
                            "{source_b} are {b:?}, {source_a} {a:?}: a session records one \
                             hand, with the same {what} on every topic"
                        ),
                    });
                }
            }
        }
        // (Schemas were checked as each topic appeared; a raw topic may be missing.)
        for topic in RAW_TOPICS {
            if raw.topic(topic).is_none() {
                return Err(RecordingError::MissingTopic {
                    topic: topic.to_owned(),
                });
            }
        }
        check_metadata(&raw.metadata, name)?;
        let find = |record: &str| {
            raw.metadata
                .iter()
                .find(|m| m.name == record)
                .map(|m| m.entries.clone())
        };
        let mut metadata = find(SESSION_METADATA).unwrap_or_default();
        // A scene of several objects says at its end whether they overlapped: with the
        // session's parameters (never in place of one).
        for (k, v) in find(super::recorder::OVERLAPS_METADATA).unwrap_or_default() {
            metadata.entry(k).or_insert(v);
        }
        let replay = find(REPLAY_METADATA);
        if replay.is_none() && metadata.get("source").is_none_or(|s| s != "replay") {
            check_session_object(&metadata, name)?;
        }
        let phases = match find(GROUND_TRUTH_METADATA)
            .as_ref()
            .and_then(|m| m.get("phases"))
        {
            None => Vec::new(),
            Some(text) => serde_json::from_str(text).map_err(|e| RecordingError::InvalidInput {
                location: format!("{name}: metadata ground_truth.phases"),
                detail: e.to_string(),
            })?,
        };
        check_spans(&self.times)?;
        let object = &self.times[3];
        Ok(SessionHead {
            metadata,
            phases,
            message_counts: raw
                .topics
                .iter()
                .map(|(t, n)| (t.topic.clone(), *n))
                .collect(),
            replay,
            live: find(crate::live::LIVE_METADATA),
            object_span_ns: (object.first.unwrap_or(0), object.last),
        })
    }
}

impl<V: SessionVisitor> RawVisitor for Checker<'_, V> {
    fn claims(&self, topic_index: usize) -> bool {
        let Some(wants) = self.early_for else {
            return false;
        };
        // Everything but the raw topics the visitor takes: the others are checked (or, not
        // ours, passed over) on the reading thread and never queued for the calling one.
        match self.kinds.get(topic_index) {
            Some(Kind::Raw(raw, _)) => !wants.has(*raw),
            Some(Kind::Foxglove(_)) if wants != DecodeTopics::NONE => false,
            _ => true,
        }
    }

    fn topic(&mut self, topic: &RawTopic) -> Result<()> {
        let name = topic.topic.as_str();
        let kind = if let Some(raw) = RAW_TOPICS.iter().position(|t| *t == name) {
            let schema_name = RAW_SCHEMA_NAMES[raw];
            topic.require(schema_name)?;
            if topic.is_protobuf() {
                // A protobuf raw topic must be laid out as ours: another layout would decode
                // into wrong numbers rather than fail.
                let data = topic.schema.as_ref().map_or(&[][..], |s| &s.data[..]);
                let location = format!("topic {name} schema {schema_name}");
                if data.len() > MAX_RAW_SCHEMA_BYTES {
                    return Err(RecordingError::InvalidInput {
                        location,
                        detail: format!(
                            "the schema is {} bytes; a raw topic's schema holds at most \
                             {MAX_RAW_SCHEMA_BYTES} (ours is a few kB)",
                            data.len()
                        ),
                    });
                }
                if let Some(detail) = schema_difference(data, schema_name) {
                    return Err(RecordingError::InvalidInput {
                        location,
                        detail: format!("differs from ours: {detail}"),
                    });
                }
            }
            Kind::Raw(raw, topic.is_protobuf())
        } else {
            let foxglove = [
                (
                    TOPIC_TF,
                    &FRAME_TRANSFORMS_SCHEMA.name,
                    FoxgloveType::FrameTransforms,
                ),
                (
                    TOPIC_SCENE,
                    &SCENE_UPDATE_SCHEMA.name,
                    FoxgloveType::SceneUpdate,
                ),
                (
                    TOPIC_JOINT_STATES,
                    &JOINT_STATES_SCHEMA.name,
                    FoxgloveType::JointStates,
                ),
                (
                    TOPIC_HAND,
                    &SCENE_UPDATE_SCHEMA.name,
                    FoxgloveType::SceneUpdate,
                ),
            ];
            match foxglove.iter().find(|(t, _, _)| *t == name) {
                Some((_, schema, which)) => {
                    topic.require(schema)?;
                    if topic.is_protobuf() {
                        Kind::Foxglove(*which)
                    } else {
                        Kind::Json
                    }
                }
                None if topic.is_json() => Kind::Json,
                None => Kind::Other,
            }
        };
        self.kinds.push(kind);
        Ok(())
    }

    fn message(
        &mut self,
        topic_index: usize,
        topic: &RawTopic,
        index: usize,
        t: u64,
        data: &[u8],
    ) -> Result<()> {
        let kind = self.kinds.get(topic_index).copied().unwrap_or(Kind::Other);
        if let Some(topics) = self.again {
            let wanted = match kind {
                Kind::Raw(0, _) => topics.joint_states,
                Kind::Raw(1, _) => topics.feedback,
                Kind::Raw(2, _) => topics.contacts,
                Kind::Raw(_, _) => topics.object,
                _ => false,
            };
            if !wanted {
                return Ok(());
            }
        }
        match kind {
            Kind::Raw(raw, protobuf) => {
                self.raw_message(raw, protobuf, &topic.topic, index, t, data)?;
                if let Some(keep) = self.keep.as_deref_mut() {
                    keep.keep(raw, protobuf, index, t, data);
                }
                if self.again.is_some() && self.visitor.done() {
                    self.stopped = true;
                    return Err(RecordingError::InvalidInput {
                        location: topic.topic.clone(),
                        detail: "the reader needs no more samples".into(),
                    });
                }
                Ok(())
            }
            Kind::Json => check_message(&topic.topic, index, t, data),
            Kind::Foxglove(_) if data.len() > MAX_CHECKED_FOXGLOVE_MESSAGE_BYTES => Ok(()),
            Kind::Foxglove(which) => {
                use foxglove::messages as fg;
                use prost::Message;
                // Checked as prost decodes it, without building it (`wire::MessageCheck`);
                // decoded by prost if the SDK's schema could not make the check.
                let decoded = match (foxglove_check(which), which) {
                    (Some(check), _) => check
                        .check(data)
                        .map_err(|e| format!("failed to decode Protobuf message: {e}")),
                    (None, FoxgloveType::FrameTransforms) => fg::FrameTransforms::decode(data)
                        .map(drop)
                        .map_err(|e| e.to_string()),
                    (None, FoxgloveType::SceneUpdate) => fg::SceneUpdate::decode(data)
                        .map(drop)
                        .map_err(|e| e.to_string()),
                    (None, FoxgloveType::JointStates) => fg::JointStates::decode(data)
                        .map(drop)
                        .map_err(|e| e.to_string()),
                };
                decoded.map_err(|e| RecordingError::InvalidInput {
                    location: message_location(&topic.topic, index, t),
                    detail: format!(
                        "does not decode as {}: {e}",
                        topic
                            .schema
                            .as_ref()
                            .map_or("its schema", |s| s.name.as_str())
                    ),
                })
            }
            Kind::Other => Ok(()),
        }
    }
}

/// The error of raw message `index` (log time `t`) of `name` (raw topic `raw`) that does not
/// decode.
fn undecodable(
    raw: usize,
    name: &str,
    index: usize,
    t: u64,
    e: wire::DecodeError,
) -> RecordingError {
    RecordingError::InvalidInput {
        location: message_location(name, index, t),
        detail: format!(
            "does not decode as {}: failed to decode Protobuf message: {e}",
            RAW_SCHEMA_NAMES[raw]
        ),
    }
}

/// The raw topics are tick streams recorded together: each has messages, spans at least
/// [`MIN_SESSION_NS`] (two ticks), starts and ends within [`RAW_TOPIC_SKEW_NS`] of the others
/// and lies within [`MAX_SESSION_NS`] of the session's first raw message (their order and
/// range message by message were checked as they came: [`Checker::check_time`]).
fn check_spans(times: &[Times; 4]) -> Result<()> {
    let invalid = |topic: &str, detail: String| RecordingError::InvalidInput {
        location: format!("topic {topic}"),
        detail,
    };
    for (topic, t) in RAW_TOPICS.iter().zip(times) {
        if t.count == 0 {
            return Err(invalid(
                topic,
                "has no messages: a session records every raw topic at every tick".into(),
            ));
        }
    }
    let first = |t: &Times| t.first.unwrap_or(0);
    let t0 = times.iter().map(first).min().unwrap_or(0);
    let t1 = times.iter().map(|t| t.last).max().unwrap_or(0);
    let s = |ns: u64| (ns - t0) as f64 * 1e-9;
    for (topic, t) in RAW_TOPICS.iter().zip(times) {
        let (first, last, n) = (first(t), t.last, t.count);
        let detail = if last - t0 > MAX_SESSION_NS {
            format!(
                "ends {:.1} s after the session's first message; a session spans at most {} s",
                s(last),
                MAX_SESSION_NS / 1_000_000_000
            )
        } else if n == 1 {
            format!(
                "has one message: a session lasts at least {} ms (two ticks at 1 kHz) on every \
                 raw topic",
                MIN_SESSION_NS / 1_000_000
            )
        } else if first == last {
            format!(
                "all {n} messages have the same log time ({first} ns): a raw topic is a tick \
                 stream, one message per 1 ms tick"
            )
        } else if last - first < MIN_SESSION_NS {
            format!(
                "spans {} ns: a session lasts at least {} ms (two ticks at 1 kHz) on every raw \
                 topic",
                last - first,
                MIN_SESSION_NS / 1_000_000
            )
        } else if first - t0 > RAW_TOPIC_SKEW_NS {
            format!(
                "starts at {:.3} s, after the session's first raw message: the raw topics are \
                 recorded together, tick by tick",
                s(first)
            )
        } else if t1 - last > RAW_TOPIC_SKEW_NS {
            format!(
                "ends at {:.3} s, {:.3} s before the session's last raw message: the raw topics \
                 are recorded together, tick by tick",
                s(last),
                (t1 - last) as f64 * 1e-9
            )
        } else {
            continue;
        };
        return Err(invalid(topic, detail));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metadata(objects: &str, target: &str) -> BTreeMap<String, String> {
        BTreeMap::from([
            ("objects".to_owned(), objects.to_owned()),
            ("target".to_owned(), target.to_owned()),
        ])
    }

    #[test]
    fn the_objects_of_a_session_are_checked_naming_the_field() {
        let ball = r#"{"name": "ball", "shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8}"#;
        let cup = r#"{"name": "cup", "shape": "cylinder", "radius": 0.04, "half_height": 0.05, "mass": 0.3, "mu": 0.8}"#;
        let good = format!("[{ball}, {cup}]");
        check_session_objects(&metadata(&good, "cup"), "f").unwrap();
        check_session_objects(&BTreeMap::new(), "f").unwrap();
        let error =
            |m: BTreeMap<String, String>| check_session_objects(&m, "f").unwrap_err().to_string();
        let e = error(metadata(&good, "mug"));
        assert!(e.contains("session.target") && e.contains("\"mug\""), "{e}");
        let e = error(metadata(&format!("[{ball}, {ball}]"), "ball"));
        assert!(e.contains("session.objects[1].name"), "{e}");
        let e = error(metadata(&good.replace("0.05", "-1"), "cup"));
        assert!(
            e.contains("session.objects[1]") && e.contains("half_height"),
            "{e}"
        );
        let e = error(metadata(&good.replace("\"sphere\"", "\"torus\""), "cup"));
        assert!(e.contains("session.objects[0].shape"), "{e}");
        let e = error(metadata("[]", "cup"));
        assert!(e.contains("0 objects"), "{e}");
        let mut m = metadata(&good, "cup");
        m.remove("target");
        assert!(error(m).contains("session.target"));
    }
}
