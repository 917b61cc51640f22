//! [`read_session`]: a session file back into typed samples.

use std::collections::BTreeMap;
use std::path::Path;

use super::messages::*;
use super::*;
use crate::error::{RecordingError, Result};
use crate::foxglove::{FRAME_TRANSFORMS_SCHEMA, JOINT_STATES_SCHEMA, SCENE_UPDATE_SCHEMA};
use crate::mcap_io::{read_session_file_decoding, JsonSchema, ReadLimits, RecordedSession};

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
}

/// Which raw topics a read decodes into the [`Session`]. A topic left out is still checked
/// (present, with its schema, every message valid JSON) but its list stays empty: segmentation
/// needs only contacts and object state, and decoding all four topics is most of the cost of
/// reading a session.
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

/// Reads a session file safely (CRC prevalidation, record length limit). The four raw topics
/// must be present with their `icms.*` schemas ([`RecordingError::MissingTopic`],
/// [`RecordingError::UnknownSchema`] otherwise); Foxglove topics, if present, must carry their
/// official schema names. A malformed `ground_truth` record is [`RecordingError::InvalidInput`].
pub fn read_session_with_limits(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<Session> {
    let path = path.as_ref();
    let recorded = read_session_file_decoding(path, limits, &RAW_TOPICS)?;
    from_recorded(&recorded, &path.display().to_string(), DecodeTopics::ALL)
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
    let recorded = crate::mcap_io::read_session_bytes_decoding(bytes, limits, &RAW_TOPICS)?;
    from_recorded(&recorded, name, topics)
}

fn from_recorded(recorded: &RecordedSession, name: &str, topics: DecodeTopics) -> Result<Session> {
    let expected: [(&str, &JsonSchema); 3] = [
        (TOPIC_TF, &FRAME_TRANSFORMS_SCHEMA),
        (TOPIC_SCENE, &SCENE_UPDATE_SCHEMA),
        (TOPIC_JOINT_STATES, &JOINT_STATES_SCHEMA),
    ];
    for (topic, schema) in expected {
        if recorded.topics.contains_key(topic) {
            recorded.require_topic(topic, &schema.name)?;
        }
    }
    let metadata = recorded
        .metadata(SESSION_METADATA)
        .cloned()
        .unwrap_or_default();
    let phases = match recorded
        .metadata(GROUND_TRUTH_METADATA)
        .and_then(|m| m.get("phases"))
    {
        None => Vec::new(),
        Some(text) => serde_json::from_str(text).map_err(|e| RecordingError::InvalidInput {
            location: format!("{name}: metadata ground_truth.phases"),
            detail: e.to_string(),
        })?,
    };
    // The four raw topics are most of the work of reading a session: decode them on two
    // threads (contacts and feedback are the larger pair).
    // A topic not decoded is still required with its schema and checked to hold valid JSON.
    fn decode<T: serde::de::DeserializeOwned>(
        recorded: &RecordedSession,
        on: bool,
        topic: &str,
        schema: &JsonSchema,
    ) -> Result<Vec<(u64, T)>> {
        if on {
            recorded.decode_topic(topic, &schema.name)
        } else {
            recorded.require_topic(topic, &schema.name)?.check_json()?;
            Ok(Vec::new())
        }
    }
    let t = topics;
    let (contacts, feedback, joint_states, object) = std::thread::scope(|scope| {
        let other = scope.spawn(|| {
            let contacts = decode(recorded, t.contacts, TOPIC_CONTACTS, &CONTACTS_SCHEMA);
            let feedback = decode(
                recorded,
                t.feedback,
                TOPIC_GLOVE_FEEDBACK,
                &GLOVE_FEEDBACK_SCHEMA,
            );
            (contacts, feedback)
        });
        let joint_states = decode(
            recorded,
            t.joint_states,
            TOPIC_GLOVE_JOINT_STATES,
            &GLOVE_JOINT_STATES_SCHEMA,
        );
        let object = decode(recorded, t.object, TOPIC_OBJECT_STATE, &OBJECT_STATE_SCHEMA);
        let (contacts, feedback) = other.join().unwrap_or_else(|panic| {
            std::panic::resume_unwind(panic);
        });
        (contacts, feedback, joint_states, object)
    });
    Ok(Session {
        metadata,
        phases,
        joint_states: joint_states?,
        feedback: feedback?,
        contacts: contacts?,
        object: object?,
        message_counts: recorded.message_counts(),
    })
}
