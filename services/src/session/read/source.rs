//! [`SessionSource`]: where a session is read from, and its reads: the first, checking read
//! (`stream_source`, keeping messages if asked) and the second reads, from the file again or
//! from the messages kept.

use std::path::Path;

use super::checker::Checker;
use crate::error::Result;
use crate::mcap_io::{stream_raw_bytes, stream_raw_file, ReadLimits};
use crate::session::*;

/// [`stream_session_file`] or [`stream_session_bytes`] of `source`, keeping the messages
/// handed to `visitor` in `keep` if given.
pub(super) fn stream_source(
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
