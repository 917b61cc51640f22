//! Starting a recording: where it goes ([`SessionOut`]), the [`SessionRecorder`]'s
//! constructors, the metadata records and channels written first, and the serialiser and
//! writer threads started.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::sync_channel;

use dfs_core::hand::HandModel;
use dfs_core::object::RigidObject;

use foxglove::messages as fg;
use foxglove::Encode;

use super::foxglove_topics::SceneObjects;
use super::inputs::{Batch, HandFrames, Inputs};
use super::live_view::LiveView;
use super::raw::Messages;
use super::record::OverlapCount;
use super::threads::{writer_thread, Serialiser};
use super::{
    SessionInfo, SessionRecorder, CHANNEL_BOUND, TOPIC_ASSIST_EVENTS, TOPIC_ASSIST_ROBOT,
    ZSTD_LEVEL,
};
use crate::error::{RecordingError, Result};
use crate::mcap_io::{SessionWriter, WriterOptions};
use crate::session::hand_scene::HandScene;
use crate::session::proto::{FILE_DESCRIPTOR_SET, FORMAT_VERSION};
use crate::session::*;

/// Where a recording goes.
pub enum SessionOut<'a> {
    /// A file, created (truncated), synced as it is written and when finished.
    File(&'a Path),
    /// Any writer, written front to back (never read or seeked); `name` names it in errors
    /// and summaries. Syncing it is its owner's business.
    Stream {
        /// The writer.
        out: Box<dyn std::io::Write + Send>,
        /// What to call it.
        name: PathBuf,
    },
}

impl<'a> From<&'a Path> for SessionOut<'a> {
    fn from(path: &'a Path) -> Self {
        SessionOut::File(path)
    }
}

impl<'a> From<&'a PathBuf> for SessionOut<'a> {
    fn from(path: &'a PathBuf) -> Self {
        SessionOut::File(path)
    }
}

impl std::fmt::Debug for SessionOut<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SessionOut::File(path) => f.debug_tuple("File").field(path).finish(),
            SessionOut::Stream { name, .. } => {
                f.debug_struct("Stream").field("name", name).finish()
            }
        }
    }
}

impl SessionRecorder {
    /// The writer's options: zstd at [`ZSTD_LEVEL`], no message indexes.
    fn writer_options() -> WriterOptions {
        WriterOptions {
            compression_level: ZSTD_LEVEL,
            message_indexes: false,
            ..WriterOptions::default()
        }
    }

    /// Creates `out` (truncating it), writes the `session` and `ground_truth` metadata and the
    /// channels, and starts the serialiser and writer threads. The file is synced as it is
    /// written (each second of session) and at [`finish`](Self::finish).
    pub fn create(
        out: impl AsRef<Path>,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
    ) -> Result<Self> {
        let path = out.as_ref().to_path_buf();
        let writer = SessionWriter::create_with_options(&path, Self::writer_options())?;
        Self::start(writer, hand, object, info)
    }

    /// [`create`](Self::create) into a file or any [`Write`](std::io::Write) (a socket, a
    /// pipe, a store's staging file, memory): the session is written front to back, each chunk
    /// whole, and nothing is ever read back or seeked.
    pub fn create_to(
        out: SessionOut<'_>,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
    ) -> Result<Self> {
        Self::create_with_view(out, hand, object, info, None)
    }

    /// [`create_to`](Self::create_to), publishing the Foxglove topics as they are written
    /// through `view` too (a live session watched in the Foxglove app).
    pub fn create_with_view(
        out: SessionOut<'_>,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
        view: Option<LiveView>,
    ) -> Result<Self> {
        let writer = match out {
            SessionOut::File(path) => {
                SessionWriter::create_with_options(path, Self::writer_options())?
            }
            SessionOut::Stream { out, name } => {
                SessionWriter::to_stream(out, name, Self::writer_options())?
            }
        };
        Self::start_viewed(writer, hand, object, info, view)
    }

    fn start(
        writer: SessionWriter,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
    ) -> Result<Self> {
        Self::start_viewed(writer, hand, object, info, None)
    }

    fn start_viewed(
        mut writer: SessionWriter,
        hand: &HandModel,
        object: &RigidObject,
        info: &SessionInfo,
        view: Option<LiveView>,
    ) -> Result<Self> {
        let path = writer.path().to_path_buf();
        write_metadata(&mut writer, hand, info)?;
        register_channels(&mut writer, info)?;
        let hand_scene = HandScene::create(&mut writer, hand, info.hand_urdf.as_deref())?;

        let frames = HandFrames::of(hand);
        let scene = SceneObjects::new(object, info.scene.as_ref());
        let serialiser = Serialiser {
            hand: frames.clone(),
            table_height: info.table_height,
            hand_scene,
            msgs: Messages::new(hand, &scene),
            scene: scene.clone(),
        };

        // Emptied buffers go back on channels of their own, bounded too (they hold at most
        // the buffers in flight, and a bounded channel allocates nothing per message).
        let (batch_tx, batch_rx) = sync_channel::<Batch>(CHANNEL_BOUND);
        let (batch_recycle_tx, batch_recycled) = sync_channel::<Batch>(CHANNEL_BOUND + 2);
        let writer = std::thread::Builder::new()
            .name("icms-session-writer".into())
            .spawn(move || writer_thread(writer, batch_rx, batch_recycle_tx, view))
            .map_err(|e| RecordingError::io("starting the session writer thread", e))?;
        let (tx, rx) = sync_channel::<Inputs>(CHANNEL_BOUND);
        let (recycle_tx, recycled) = sync_channel::<Inputs>(CHANNEL_BOUND + 2);
        let serialiser = match std::thread::Builder::new()
            .name("icms-session-serialiser".into())
            .spawn(move || serialiser.run(rx, recycle_tx, batch_tx, batch_recycled))
        {
            Ok(handle) => handle,
            Err(e) => {
                // The writer thread sees its channel closed and finishes the file.
                let _ = writer.join();
                return Err(RecordingError::io(
                    "starting the session serialiser thread",
                    e,
                ));
            }
        };

        Ok(Self {
            tx: Some(tx),
            recycled,
            serialiser: Some(serialiser),
            writer: Some(writer),
            inputs: Inputs::with_capacity(&frames),
            path,
            check: Messages::new(hand, &scene),
            hand: frames,
            ticks: 0,
            object_names: info
                .scene
                .as_ref()
                .map(|s| s.objects.iter().map(|o| o.name.clone()).collect()),
            overlaps: OverlapCount::default(),
        })
    }
}

/// The `session` metadata record of a recording of `hand` described by `info`.
fn session_record(hand: &HandModel, info: &SessionInfo) -> Result<BTreeMap<String, String>> {
    let mut meta = BTreeMap::new();
    meta.insert("scenario".to_owned(), info.scenario.clone());
    meta.insert(
        "seed".to_owned(),
        info.seed.map(|s| s.to_string()).unwrap_or_default(),
    );
    meta.insert("hand".to_owned(), hand.name.clone());
    meta.insert("object".to_owned(), info.object_json.clone());
    meta.insert("rate_hz".to_owned(), RATE_HZ.to_string());
    meta.insert(
        "software_version".to_owned(),
        env!("CARGO_PKG_VERSION").to_owned(),
    );
    meta.insert(
        "started_at".to_owned(),
        rfc3339_utc(info.started_at.unwrap_or(std::time::UNIX_EPOCH)),
    );
    meta.insert("source".to_owned(), info.source.clone());
    meta.insert("format_version".to_owned(), FORMAT_VERSION.to_string());
    meta.insert(
        "foxglove_rate_hz".to_owned(),
        (u64::from(RATE_HZ) / FOXGLOVE_DECIMATION).to_string(),
    );
    if let Some(scene) = &info.scene {
        let named: Vec<_> = scene
            .objects
            .iter()
            .map(|o| dfs_core::scenario::ScenarioObject {
                name: Some(o.name.clone()),
                ..o.spec.clone()
            })
            .collect();
        let json = |e: serde_json::Error| RecordingError::Serialize {
            topic: SESSION_METADATA.to_owned(),
            detail: e.to_string(),
        };
        meta.insert(
            "objects".to_owned(),
            serde_json::to_string(&named).map_err(json)?,
        );
        meta.insert("target".to_owned(), scene.target().name.clone());
        if info.object_json.is_empty() {
            meta.insert(
                "object".to_owned(),
                serde_json::to_string(&named[scene.target]).map_err(json)?,
            );
        }
    }
    for (k, v) in &info.extra {
        meta.entry(k.clone()).or_insert_with(|| v.clone());
    }
    Ok(meta)
}

/// Writes the `session` and `ground_truth` metadata records.
fn write_metadata(writer: &mut SessionWriter, hand: &HandModel, info: &SessionInfo) -> Result<()> {
    writer.add_metadata(SESSION_METADATA, session_record(hand, info)?)?;
    let phases = serde_json::to_string(&info.phases).map_err(|e| RecordingError::Serialize {
        topic: GROUND_TRUTH_METADATA.to_owned(),
        detail: e.to_string(),
    })?;
    writer.add_metadata(
        GROUND_TRUTH_METADATA,
        BTreeMap::from([("phases".to_owned(), phases)]),
    )?;
    Ok(())
}

/// Registers the raw topics (protobuf, our schemas), the Foxglove topics and, if
/// [`SessionInfo::assist_topics`], the assistant's.
fn register_channels(writer: &mut SessionWriter, info: &SessionInfo) -> Result<()> {
    for (topic, schema) in RAW_TOPICS.iter().zip(RAW_SCHEMA_NAMES) {
        writer.register_protobuf_channel(topic, schema, FILE_DESCRIPTOR_SET)?;
    }
    register_foxglove::<fg::FrameTransforms>(writer, TOPIC_TF)?;
    register_foxglove::<fg::SceneUpdate>(writer, TOPIC_SCENE)?;
    register_foxglove::<fg::JointStates>(writer, TOPIC_JOINT_STATES)?;
    if info.assist_topics {
        register_foxglove::<fg::Log>(writer, TOPIC_ASSIST_EVENTS)?;
        register_foxglove::<fg::SceneUpdate>(writer, TOPIC_ASSIST_ROBOT)?;
    }
    Ok(())
}

/// Registers a Foxglove topic with the SDK's schema of `T` (a `FileDescriptorSet` of the
/// official `.proto`).
fn register_foxglove<T: Encode>(writer: &mut SessionWriter, topic: &str) -> Result<()> {
    let schema = T::get_schema().ok_or_else(|| RecordingError::Serialize {
        topic: topic.to_owned(),
        detail: "the Foxglove SDK has no schema for it".to_owned(),
    })?;
    writer.register_protobuf_channel(topic, &schema.name, &schema.data)
}
