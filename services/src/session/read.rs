//! [`read_session`]: a session file back into typed samples.

use std::collections::BTreeMap;
use std::path::Path;

use super::messages::*;
use super::*;
use crate::error::{RecordingError, Result};
use crate::foxglove::{FRAME_TRANSFORMS_SCHEMA, JOINT_STATES_SCHEMA, SCENE_UPDATE_SCHEMA};
use crate::mcap_io::{read_session_file, JsonSchema, ReadLimits, RecordedSession};

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
    /// Number of ticks (messages on `/glove/joint_states`).
    pub fn ticks(&self) -> usize {
        self.joint_states.len()
    }

    /// The scenario name from the `session` record.
    pub fn scenario(&self) -> Option<&str> {
        self.metadata.get("scenario").map(String::as_str)
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
    let recorded = read_session_file(path, limits)?;
    from_recorded(&recorded, &path.display().to_string())
}

/// Reads a session from bytes already in memory (for example an HTTP upload), with the same
/// checks as [`read_session_with_limits`]; `name` appears in error messages.
pub fn read_session_bytes(bytes: &[u8], name: &str, limits: &ReadLimits) -> Result<Session> {
    let recorded = crate::mcap_io::read_session_bytes(bytes, limits)?;
    from_recorded(&recorded, name)
}

fn from_recorded(recorded: &RecordedSession, name: &str) -> Result<Session> {
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
    Ok(Session {
        metadata,
        phases,
        joint_states: recorded
            .decode_topic(TOPIC_GLOVE_JOINT_STATES, &GLOVE_JOINT_STATES_SCHEMA.name)?,
        feedback: recorded.decode_topic(TOPIC_GLOVE_FEEDBACK, &GLOVE_FEEDBACK_SCHEMA.name)?,
        contacts: recorded.decode_topic(TOPIC_CONTACTS, &CONTACTS_SCHEMA.name)?,
        object: recorded.decode_topic(TOPIC_OBJECT_STATE, &OBJECT_STATE_SCHEMA.name)?,
        message_counts: recorded.message_counts(),
    })
}
