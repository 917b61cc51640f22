//! [`Checker`]: the checks of a session read in one pass, message by message, in front of a
//! [`SessionVisitor`]: each raw message's log time, size and content, decoded into reused
//! messages and handed on.

use super::topics::Kind;
use crate::error::{RecordingError, Result};
use crate::mcap_io::{json_error, message_location};
use crate::session::messages::*;
use crate::session::wire;
use crate::session::*;

/// Per raw topic: what its log times were so far.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Times {
    pub(super) first: Option<u64>,
    pub(super) last: u64,
    pub(super) count: usize,
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
pub(super) struct Checker<'v, V: SessionVisitor> {
    pub(super) visitor: &'v mut V,
    pub(super) kinds: Vec<Kind>,
    pub(super) times: [Times; 4],
    /// The first raw log time seen so far.
    t0: Option<u64>,
    /// Per raw topic, its DOF and fingertip names as its message 0 lists them: each message is
    /// checked against its own topic's (whichever thread checks it); the topics against each
    /// other at the end.
    pub(super) references: [TickReference; 4],
    scratch: Scratch,
    /// A second read of a file read and checked before: only these raw topics are decoded
    /// (and checked as they are), the others and the file-wide checks skipped.
    pub(super) again: Option<DecodeTopics>,
    /// A second read stopped because the visitor was done (the error that stopped the
    /// reader is not one).
    pub(super) stopped: bool,
    /// The checker of the reading thread, for a visitor that takes these raw topics: it
    /// claims the others, and the Foxglove and other JSON topics.
    pub(super) early_for: Option<DecodeTopics>,
    /// Where the raw messages handed to the visitor are kept for a second read.
    pub(super) keep: Option<&'v mut KeptMessages>,
    /// The raw topics the visitor takes.
    wants: DecodeTopics,
    /// The messages were read and checked before, these very bytes ([`KeptMessages`]): they
    /// are only decoded.
    pub(super) checked_before: bool,
    /// With `checked_before`: contacts and object states are decoded only as far as the
    /// visitor reads them ([`SessionVisitor::segmentation_fields_only`]).
    pub(super) lean: bool,
}

impl<'v, V: SessionVisitor> Checker<'v, V> {
    pub(super) fn new(visitor: &'v mut V) -> Self {
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
    pub(super) fn early(nothing: &'v mut (), wants: DecodeTopics) -> Self {
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
    pub(super) fn raw_message(
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
