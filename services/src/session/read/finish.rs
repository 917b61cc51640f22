//! The checks that need the whole file, once every message was read: the topics name one hand,
//! every raw topic is there and spans the session ([`check_spans`]), the metadata.

use super::checker::{Checker, Times};
use super::metadata::{check_metadata, check_session_object};
use crate::error::{RecordingError, Result};
use crate::mcap_io::StreamedRaw;
use crate::replay::REPLAY_METADATA;
use crate::session::*;

impl<V: SessionVisitor> Checker<'_, V> {
    /// The checks that need the whole file: every raw topic there and spanning the session,
    /// the metadata.
    pub(super) fn finish(
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
        for (k, v) in find(OVERLAPS_METADATA).unwrap_or_default() {
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
