//! [`read_session`]: a session file back into typed samples.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use super::messages::*;
use super::proto::{self, schema_difference};
use super::*;
use crate::error::{RecordingError, Result};
use crate::foxglove::{FRAME_TRANSFORMS_SCHEMA, JOINT_STATES_SCHEMA, SCENE_UPDATE_SCHEMA};
use crate::mcap_io::{
    message_location, par_map, read_raw_bytes, read_raw_file, JsonSchema, MessageRef, RawSession,
    RawTopic, ReadLimits, MESSAGES_PER_JOB,
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
        if !self.is_replay() {
            if self
                .metadata
                .get("object")
                .is_none_or(|o| o.trim().is_empty())
            {
                let record = if self.metadata.is_empty() {
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
        let get = |key: &str| {
            self.replay
                .as_ref()
                .and_then(|r| r.get(key))
                .filter(|v| !v.is_empty())
        };
        let hand = get("hand")
            .or_else(|| self.metadata.get("replay_hand"))
            .or_else(|| self.metadata.get("hand"));
        let skill = get("skill").or_else(|| self.metadata.get("scenario"));
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
    /// What [`crate::segmentation::segment`] reads: contacts and object state.
    pub const SEGMENTATION: DecodeTopics = DecodeTopics {
        joint_states: false,
        feedback: false,
        contacts: true,
        object: true,
    };
}

impl Default for DecodeTopics {
    fn default() -> Self {
        DecodeTopics::ALL
    }
}

/// Reads a session file with default [`ReadLimits`]. See [`read_session_with_limits`].
pub fn read_session(path: impl AsRef<Path>) -> Result<Session> {
    read_session_with_limits(path, &ReadLimits::default())
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

/// [`read_session_with_limits`] decoding only the raw topics in `topics` (the others are
/// checked and left empty).
pub fn read_session_file_with(
    path: impl AsRef<Path>,
    limits: &ReadLimits,
    topics: DecodeTopics,
) -> Result<Session> {
    let path = path.as_ref();
    let raw = read_raw_file(path, limits)?;
    from_raw(&raw, &path.display().to_string(), topics)
}

/// Reads a session from bytes already in memory (for example an HTTP upload), with the same
/// checks as [`read_session_with_limits`]; `name` appears in error messages.
pub fn read_session_bytes(bytes: &[u8], name: &str, limits: &ReadLimits) -> Result<Session> {
    read_session_bytes_with(bytes, name, limits, DecodeTopics::ALL)
}

/// [`read_session_bytes`] decoding only the raw topics in `topics` (the others are checked and
/// left empty).
pub fn read_session_bytes_with(
    bytes: &[u8],
    name: &str,
    limits: &ReadLimits,
    topics: DecodeTopics,
) -> Result<Session> {
    let raw = read_raw_bytes(bytes, limits)?;
    from_raw(&raw, name, topics)
}

/// One job of [`from_raw`]: a block of one topic's messages, checked or decoded.
enum Decoded {
    Checked,
    JointStates(Vec<(u64, GloveJointStates)>),
    Feedback(Vec<(u64, GloveFeedback)>),
    Contacts(Vec<(u64, Contacts)>),
    Object(Vec<(u64, messages::ObjectState)>),
}

/// The `session` metadata's `object` (when there is one, not empty) must describe a real object: a known
/// shape with positive finite sizes and mass, μ and torsional μ finite and ≥ 0. Skills carry
/// it into the store's filters and onto robot hands, so an impossible one is refused here, at
/// the boundary, naming the field.
fn check_session_object(metadata: &BTreeMap<String, String>, name: &str) -> Result<()> {
    let Some(text) = metadata.get("object").filter(|t| !t.trim().is_empty()) else {
        return Ok(());
    };
    let invalid = |detail: String| RecordingError::InvalidInput {
        location: format!("{name}: metadata session.object"),
        detail,
    };
    let o: dfs_core::scenario::ScenarioObject =
        serde_json::from_str(text).map_err(|e| invalid(e.to_string()))?;
    o.to_object().map_err(|e| invalid(e.to_string()))?;
    Ok(())
}

/// What a job does with its block: checks a topic's JSON, or decodes a raw topic's messages
/// and checks their content, keeping the samples (`true`) or not.
#[derive(Clone, Copy)]
enum Job {
    Check,
    JointStates(bool),
    Feedback(bool),
    Contacts(bool),
    Object(bool),
}

/// The metadata records are few and small, and name the session once: at most
/// [`MAX_METADATA_RECORDS`] records of at most [`MAX_METADATA_ENTRIES`] entries, keys of at
/// most [`MAX_METADATA_KEY_BYTES`], values of at most [`MAX_METADATA_VALUE_BYTES`], at most
/// [`MAX_METADATA_BYTES`] in all, and one record at most named `session`, `ground_truth` or
/// `replay` (a second one would be ignored: which one describes the session?). The store keeps
/// the `session` record with the session and lists it with every page of sessions.
fn check_metadata(raw: &RawSession, name: &str) -> Result<()> {
    let invalid = |location: String, detail: String| RecordingError::InvalidInput {
        location: format!("{name}: metadata {location}"),
        detail,
    };
    let records = &raw.metadata;
    if records.len() > MAX_METADATA_RECORDS {
        return Err(invalid(
            "records".into(),
            format!(
                "the file has {} metadata records; a session has at most {MAX_METADATA_RECORDS}",
                records.len()
            ),
        ));
    }
    for unique in [SESSION_METADATA, GROUND_TRUTH_METADATA, REPLAY_METADATA] {
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

/// The session's DOF and fingertip names, from the first message of `/glove/joint_states` and
/// of `/dfs/contacts` (`None` where that message does not decode: its own check reports it).
fn tick_reference(raw: &RawSession) -> TickReference {
    // (Not decoded when over the size limit: its own check refuses it.)
    let first = |topic: &str| {
        raw.topics
            .get(topic)
            .and_then(|t| t.messages.first())
            .map(|m| raw.data(m))
            .filter(|d| d.len() <= MAX_RAW_MESSAGE_BYTES)
    };
    // Only a list that passes its own check is a reference (an empty one would make every
    // other message's list look wrong, before the culprit's own error).
    let protobuf = |topic: &str| raw.topics.get(topic).is_some_and(|t| t.is_protobuf());
    let dof_names = if protobuf(TOPIC_GLOVE_JOINT_STATES) {
        first(TOPIC_GLOVE_JOINT_STATES)
            .and_then(|d| <proto::GloveJointStatesProto as prost::Message>::decode(d).ok())
            .map(|m| m.names)
    } else {
        first(TOPIC_GLOVE_JOINT_STATES)
            .and_then(|d| serde_json::from_slice::<GloveJointStatesShape>(d).ok())
            .map(|m| m.names())
    };
    let finger_names = if protobuf(TOPIC_CONTACTS) {
        first(TOPIC_CONTACTS)
            .and_then(|d| <proto::ContactsProto as prost::Message>::decode(d).ok())
            .map(|m| m.fingers.into_iter().map(|f| f.name).collect::<Vec<_>>())
    } else {
        first(TOPIC_CONTACTS)
            .and_then(|d| serde_json::from_slice::<Contacts>(d).ok())
            .map(|m| m.fingers.into_iter().map(|f| f.name).collect::<Vec<_>>())
    };
    TickReference {
        dof_names: dof_names.filter(|n| (1..=MAX_SESSION_DOFS).contains(&n.len())),
        finger_names: finger_names.filter(|n| (1..=MAX_SESSION_FINGERS).contains(&n.len())),
    }
}

/// Decodes a block of a raw topic's messages (`first`: the index of its first message in the
/// topic) and checks each one's content against `reference`, keeping the samples if `keep`.
/// The error names the topic, the message's index and log time, and the field.
fn raw_block<'s, T: Deserialize<'s> + TickContent>(
    raw: &'s RawSession,
    t: &RawTopic,
    first: usize,
    messages: &[MessageRef],
    reference: &TickReference,
    keep: bool,
) -> Result<Vec<(u64, T)>> {
    refuse_oversized(raw, t, first, messages)?;
    let mut out = Vec::with_capacity(if keep { messages.len() } else { 0 });
    raw.decode_each(t, first, messages, |i, time, message: T| {
        message
            .check(reference)
            .map_err(|detail| RecordingError::InvalidInput {
                location: message_location(&t.topic, i, time),
                detail,
            })?;
        if keep {
            out.push((time, message));
        }
        Ok(())
    })?;
    Ok(out)
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

/// A raw message over [`MAX_RAW_MESSAGE_BYTES`] is [`RecordingError::InvalidInput`] naming it.
fn refuse_oversized(
    raw: &RawSession,
    t: &RawTopic,
    first: usize,
    messages: &[MessageRef],
) -> Result<()> {
    match messages
        .iter()
        .enumerate()
        .find(|(_, m)| raw.data(m).len() > MAX_RAW_MESSAGE_BYTES)
    {
        None => Ok(()),
        Some((i, m)) => Err(RecordingError::InvalidInput {
            location: message_location(&t.topic, first + i, m.log_time_ns),
            detail: format!(
                "the message is {} bytes; a message of this topic holds at most \
                 {MAX_RAW_MESSAGE_BYTES}",
                raw.data(m).len()
            ),
        }),
    }
}

/// Largest Foxglove message of format 2 that is decoded to be checked (bytes); bigger ones
/// (another tool's meshes in `/scene`, say) are for viewers and left unchecked rather than
/// decoded at a hundred times their size.
pub const MAX_CHECKED_FOXGLOVE_MESSAGE_BYTES: usize = 256 * 1024;

/// [`raw_block`] for a protobuf (format 2) raw topic: each message decoded as `P`, converted
/// to its SI form by `convert`, checked, and kept if `keep`.
fn raw_block_protobuf<P: prost::Message + Default, T: TickContent>(
    raw: &RawSession,
    t: &RawTopic,
    first: usize,
    messages: &[MessageRef],
    reference: &TickReference,
    keep: bool,
    convert: fn(P) -> T,
) -> Result<Vec<(u64, T)>> {
    let mut out = Vec::with_capacity(if keep { messages.len() } else { 0 });
    refuse_oversized(raw, t, first, messages)?;
    raw.decode_each_protobuf(t, first, messages, usize::MAX, |i, time, message: P| {
        let message = convert(message);
        message
            .check(reference)
            .map_err(|detail| RecordingError::InvalidInput {
                location: message_location(&t.topic, i, time),
                detail,
            })?;
        if keep {
            out.push((time, message));
        }
        Ok(())
    })?;
    Ok(out)
}

/// Checks that every message of a protobuf Foxglove topic decodes as its official schema (the
/// SDK's types); other protobuf topics are not ours to check.
fn check_foxglove_protobuf(
    raw: &RawSession,
    t: &RawTopic,
    first: usize,
    messages: &[MessageRef],
) -> Result<()> {
    use foxglove::messages as fg;
    let ok = |_: usize, _: u64, _: ()| Ok(());
    let limit = MAX_CHECKED_FOXGLOVE_MESSAGE_BYTES;
    match t.schema.as_ref().map(|s| s.name.as_str()) {
        Some("foxglove.FrameTransforms") => {
            raw.decode_each_protobuf(t, first, messages, limit, |i, l, _: fg::FrameTransforms| {
                ok(i, l, ())
            })
        }
        Some("foxglove.SceneUpdate") => {
            raw.decode_each_protobuf(t, first, messages, limit, |i, l, _: fg::SceneUpdate| {
                ok(i, l, ())
            })
        }
        Some("foxglove.JointStates") => {
            raw.decode_each_protobuf(t, first, messages, limit, |i, l, _: fg::JointStates| {
                ok(i, l, ())
            })
        }
        _ => Ok(()),
    }
}

fn from_raw(raw: &RawSession, name: &str, topics: DecodeTopics) -> Result<Session> {
    let expected: [(&str, &JsonSchema); 3] = [
        (TOPIC_TF, &FRAME_TRANSFORMS_SCHEMA),
        (TOPIC_SCENE, &SCENE_UPDATE_SCHEMA),
        (TOPIC_JOINT_STATES, &JOINT_STATES_SCHEMA),
    ];
    for (topic, schema) in expected {
        if raw.topics.contains_key(topic) {
            raw.require_topic(topic, &schema.name)?;
        }
    }
    check_metadata(raw, name)?;
    let metadata = raw.metadata(SESSION_METADATA).cloned().unwrap_or_default();
    if raw.metadata(REPLAY_METADATA).is_none()
        && metadata.get("source").is_none_or(|s| s != "replay")
    {
        check_session_object(&metadata, name)?;
    }
    let phases = match raw
        .metadata(GROUND_TRUTH_METADATA)
        .and_then(|m| m.get("phases"))
    {
        None => Vec::new(),
        Some(text) => serde_json::from_str(text).map_err(|e| RecordingError::InvalidInput {
            location: format!("{name}: metadata ground_truth.phases"),
            detail: e.to_string(),
        })?,
    };
    let t = topics;
    // The raw topics must be there with their schemas; their messages are decoded and their
    // content checked whether they are kept or not (a topic not kept is read into borrowed
    // shapes, at a fraction of the cost).
    let raw_topics = [
        (
            TOPIC_GLOVE_JOINT_STATES,
            &GLOVE_JOINT_STATES_SCHEMA,
            Job::JointStates(t.joint_states),
        ),
        (
            TOPIC_GLOVE_FEEDBACK,
            &GLOVE_FEEDBACK_SCHEMA,
            Job::Feedback(t.feedback),
        ),
        (TOPIC_CONTACTS, &CONTACTS_SCHEMA, Job::Contacts(t.contacts)),
        (
            TOPIC_OBJECT_STATE,
            &OBJECT_STATE_SCHEMA,
            Job::Object(t.object),
        ),
    ];
    for (topic, schema, _) in &raw_topics {
        let t = raw.require_topic(topic, &schema.name)?;
        // A protobuf raw topic must be laid out as ours: another layout would decode into
        // wrong numbers rather than fail.
        if t.is_protobuf() {
            let data = t.schema.as_ref().map_or(&[][..], |s| &s.data[..]);
            if data.len() > MAX_RAW_SCHEMA_BYTES {
                return Err(RecordingError::InvalidInput {
                    location: format!("{name}: topic {topic} schema {}", schema.name),
                    detail: format!(
                        "the schema is {} bytes; a raw topic's schema holds at most \
                         {MAX_RAW_SCHEMA_BYTES} (ours is a few kB)",
                        data.len()
                    ),
                });
            }
            if let Some(detail) = schema_difference(data, &schema.name) {
                return Err(RecordingError::InvalidInput {
                    location: format!("{name}: topic {topic} schema {}", schema.name),
                    detail: format!("differs from ours: {detail}"),
                });
            }
        }
    }
    check_raw_log_times(raw)?;
    let reference = tick_reference(raw);
    // Every JSON message is checked or decoded, in blocks spread over the cores: the other
    // topics first (their errors come first, as in file order they would), then the raw ones.
    let mut plan: Vec<(&RawTopic, Job)> = raw
        .topics
        .values()
        .filter(|t| (t.is_json() || t.is_protobuf()) && !RAW_TOPICS.contains(&t.topic.as_str()))
        .map(|t| (t, Job::Check))
        .collect();
    for (topic, _, job) in raw_topics {
        plan.push((&raw.topics[topic], job));
    }
    let jobs: Vec<(&RawTopic, usize, &[MessageRef], Job)> = plan
        .iter()
        .flat_map(|&(t, job)| {
            t.messages
                .chunks(MESSAGES_PER_JOB)
                .enumerate()
                .map(move |(k, m)| (t, k * MESSAGES_PER_JOB, m, job))
        })
        .collect();
    let r = &reference;
    let done = par_map(jobs.len(), |i| -> Result<Decoded> {
        let (t, first, m, job) = jobs[i];
        if t.is_protobuf() {
            return Ok(match job {
                Job::Check => {
                    check_foxglove_protobuf(raw, t, first, m)?;
                    Decoded::Checked
                }
                Job::JointStates(keep) => kept(
                    keep,
                    raw_block_protobuf(raw, t, first, m, r, keep, proto::joint_states_from_proto)?,
                    Decoded::JointStates,
                ),
                Job::Feedback(keep) => kept(
                    keep,
                    raw_block_protobuf(raw, t, first, m, r, keep, proto::feedback_from_proto)?,
                    Decoded::Feedback,
                ),
                Job::Contacts(keep) => kept(
                    keep,
                    raw_block_protobuf(raw, t, first, m, r, keep, proto::contacts_from_proto)?,
                    Decoded::Contacts,
                ),
                Job::Object(keep) => kept(
                    keep,
                    raw_block_protobuf(raw, t, first, m, r, keep, proto::object_from_proto)?,
                    Decoded::Object,
                ),
            });
        }
        Ok(match job {
            Job::Check => {
                raw.check_json_of(t, first, m)?;
                Decoded::Checked
            }
            Job::JointStates(true) => Decoded::JointStates(raw_block(raw, t, first, m, r, true)?),
            Job::JointStates(false) => {
                raw_block::<GloveJointStatesShape>(raw, t, first, m, r, false)?;
                Decoded::Checked
            }
            Job::Feedback(true) => Decoded::Feedback(raw_block(raw, t, first, m, r, true)?),
            Job::Feedback(false) => {
                raw_block::<GloveFeedbackShape>(raw, t, first, m, r, false)?;
                Decoded::Checked
            }
            Job::Contacts(keep) => kept(
                keep,
                raw_block(raw, t, first, m, r, keep)?,
                Decoded::Contacts,
            ),
            Job::Object(keep) => kept(keep, raw_block(raw, t, first, m, r, keep)?, Decoded::Object),
        })
    });
    let mut session = Session {
        metadata,
        phases,
        joint_states: Vec::new(),
        feedback: Vec::new(),
        contacts: Vec::new(),
        object: Vec::new(),
        message_counts: raw.message_counts(),
        replay: raw.metadata(REPLAY_METADATA).cloned(),
    };
    for d in done {
        match d? {
            Decoded::Checked => {}
            Decoded::JointStates(v) => append(&mut session.joint_states, v),
            Decoded::Feedback(v) => append(&mut session.feedback, v),
            Decoded::Contacts(v) => append(&mut session.contacts, v),
            Decoded::Object(v) => append(&mut session.object, v),
        }
    }
    Ok(session)
}

/// How far apart the raw topics' first (and last) log times may lie (ns): they are written
/// together, tick by tick, so a session's topics start and end within a tick of each other;
/// a file in which one stops early (a writer that lost a stream) would segment as a shorter
/// session than its glove stream says.
pub const RAW_TOPIC_SKEW_NS: u64 = 100_000_000;

/// The raw topics are tick streams recorded together: each has messages, is in time order,
/// advances (more than one message do not share one log time), spans at least
/// [`MIN_SESSION_NS`] (two ticks), starts and ends within
/// [`RAW_TOPIC_SKEW_NS`] of the others, and lies within [`MAX_SESSION_NS`] of the session's
/// first raw message; every log time fits the store's signed 64-bit columns. The error names
/// the topic, the message and its log time (callers add the file's name).
fn check_raw_log_times(raw: &RawSession) -> Result<()> {
    let invalid =
        |location: String, detail: String| RecordingError::InvalidInput { location, detail };
    for topic in RAW_TOPICS {
        if raw.topics[topic].messages.is_empty() {
            return Err(invalid(
                format!("topic {topic}"),
                "has no messages: a session records every raw topic at every tick".into(),
            ));
        }
    }
    let span = |topic: &str| {
        let m = &raw.topics[topic].messages;
        (m[0].log_time_ns, m[m.len() - 1].log_time_ns)
    };
    let t0 = RAW_TOPICS.iter().map(|t| span(t).0).min().unwrap_or(0);
    for topic in RAW_TOPICS {
        let mut prev = t0;
        for (i, m) in raw.topics[topic].messages.iter().enumerate() {
            let t = m.log_time_ns;
            let problem = if t > i64::MAX as u64 {
                Some("the log time is beyond 2^63 ns".to_owned())
            } else if t < prev {
                Some(format!(
                    "the log time goes back before the previous message's ({prev} ns): a raw \
                     topic must be in time order"
                ))
            } else if t - t0 > MAX_SESSION_NS {
                Some(format!(
                    "the log time is {:.1} s after the session's first message; a session \
                     spans at most {} s",
                    (t - t0) as f64 * 1e-9,
                    MAX_SESSION_NS / 1_000_000_000
                ))
            } else {
                None
            };
            if let Some(detail) = problem {
                return Err(invalid(
                    format!("topic {topic} message {i} (log time {t} ns)"),
                    detail,
                ));
            }
            prev = t;
        }
    }
    let t1 = RAW_TOPICS.iter().map(|t| span(t).1).max().unwrap_or(0);
    let s = |ns: u64| (ns - t0) as f64 * 1e-9;
    for topic in RAW_TOPICS {
        let (first, last) = span(topic);
        let n = raw.topics[topic].messages.len();
        let detail = if n == 1 {
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
        return Err(invalid(format!("topic {topic}"), detail));
    }
    Ok(())
}

/// The decoded samples if they are kept, else only [`Decoded::Checked`].
fn kept<T>(keep: bool, v: Vec<(u64, T)>, decoded: fn(Vec<(u64, T)>) -> Decoded) -> Decoded {
    if keep {
        decoded(v)
    } else {
        Decoded::Checked
    }
}

/// `out.extend(v)`, taking `v` itself when `out` is empty.
fn append<T>(out: &mut Vec<T>, mut v: Vec<T>) {
    if out.is_empty() {
        *out = v;
    } else {
        out.append(&mut v);
    }
}
