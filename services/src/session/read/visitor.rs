//! What a reader asks of a read: the raw topics it decodes ([`DecodeTopics`]) and the
//! [`SessionVisitor`] its samples are handed to.

use crate::error::Result;
use crate::session::messages::*;
use crate::session::*;

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
