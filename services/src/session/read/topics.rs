//! The topics of a session file as the [`Checker`] meets them ([`RawVisitor`]): which are raw
//! topics and with which schema, which Foxglove topics, and each message checked by its kind.

use super::checker::Checker;
use crate::error::{RecordingError, Result};
use crate::foxglove::{FRAME_TRANSFORMS_SCHEMA, JOINT_STATES_SCHEMA, SCENE_UPDATE_SCHEMA};
use crate::mcap_io::{check_message, message_location, RawTopic, RawVisitor};
use crate::session::proto::schema_difference;
use crate::session::wire;
use crate::session::*;

/// What a topic is to the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
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
pub(super) enum FoxgloveType {
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
