//! What a read returns: the [`Session`] with its samples, or its [`SessionHead`] when the
//! samples went to a visitor; the visitor that collects them ([`Collect`]); and whether the
//! file is a grasp session at all ([`Session::ensure_grasp_session`]).

use std::collections::BTreeMap;

use super::DecodeTopics;
use crate::error::{RecordingError, Result};
use crate::session::messages::*;
use crate::session::*;

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

/// Keeps the samples of the topics asked for.
pub(super) struct Collect {
    topics: DecodeTopics,
    joint_states: Vec<(u64, GloveJointStates)>,
    feedback: Vec<(u64, GloveFeedback)>,
    contacts: Vec<(u64, Contacts)>,
    object: Vec<(u64, messages::ObjectState)>,
}

impl Collect {
    pub(super) fn new(topics: DecodeTopics) -> Self {
        Collect {
            topics,
            joint_states: Vec::new(),
            feedback: Vec::new(),
            contacts: Vec::new(),
            object: Vec::new(),
        }
    }

    pub(super) fn into_session(self, head: SessionHead) -> Session {
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
