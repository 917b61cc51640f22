//! [`LiveView`]: a recording's Foxglove topics published through the Foxglove SDK's channels
//! as they are written (a live session watched in the Foxglove app).

use std::sync::Arc;

use foxglove::messages as fg;
use foxglove::Encode;

use super::ALL_TOPICS;
use crate::error::{RecordingError, Result};

/// A recording's Foxglove topics published as they are written, through the Foxglove SDK's
/// channels of `context` (whose sinks, such as its WebSocket server, send them on): `/tf`,
/// `/scene`, `/joint_states` and `/hand` under `prefix` (e.g. `/live/3/tf`), with the SDK's
/// schemas, at the topics' 50 Hz, a batch at a time (every 0.1 s of session). The channels
/// close when the recording ends.
pub struct LiveView {
    /// Per topic of [`ALL_TOPICS`] the channel it is published on (the Foxglove topics only).
    channels: Vec<Option<Arc<foxglove::RawChannel>>>,
    /// Added to a message's log time (the session's time) for the channel: the wall-clock
    /// start of the session (ns since the Unix epoch).
    epoch_ns: u64,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let topics: Vec<&str> = self.channels.iter().flatten().map(|c| c.topic()).collect();
        f.debug_struct("LiveView").field("topics", &topics).finish()
    }
}

impl LiveView {
    /// Channels under `prefix` in `context`, logging at `epoch_ns` plus the session time.
    pub fn new(context: &Arc<foxglove::Context>, prefix: &str, epoch_ns: u64) -> Result<LiveView> {
        let schemas = [
            None,
            None,
            None,
            None,
            fg::FrameTransforms::get_schema(),
            fg::SceneUpdate::get_schema(),
            fg::JointStates::get_schema(),
            fg::SceneUpdate::get_schema(),
            fg::Log::get_schema(),
            fg::SceneUpdate::get_schema(),
        ];
        let mut channels = Vec::with_capacity(ALL_TOPICS.len());
        for (topic, schema) in ALL_TOPICS.iter().zip(schemas) {
            let Some(schema) = schema else {
                channels.push(None);
                continue;
            };
            let channel = foxglove::ChannelBuilder::new(format!("{prefix}{topic}"))
                .context(context)
                .message_encoding("protobuf")
                .schema(schema)
                .build_raw()
                .map_err(|e| RecordingError::Serialize {
                    topic: format!("{prefix}{topic}"),
                    detail: format!("the live view's channel: {e}"),
                })?;
            channels.push(Some(channel));
        }
        Ok(LiveView { channels, epoch_ns })
    }

    pub(super) fn publish(&self, topic: u8, log_time: u64, bytes: &[u8]) {
        if let Some(Some(ch)) = self.channels.get(usize::from(topic)) {
            if ch.has_sinks() {
                ch.log_with_meta(
                    bytes,
                    foxglove::PartialMetadata::with_log_time(self.epoch_ns + log_time),
                );
            }
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        for ch in self.channels.iter().flatten() {
            ch.close();
        }
    }
}
