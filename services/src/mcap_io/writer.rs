//! [`SessionWriter`]: messages into a zstd-chunked, indexed MCAP file, on protobuf channels
//! (session format 2) or on JSON channels with a JSON Schema (format 1).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};
use serde::Serialize;

use super::finite::find_non_finite;
use super::schemas::JsonSchema;
use crate::error::{RecordingError, Result};

/// Message encoding of every channel this crate writes.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every schema this crate writes.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// How a [`SessionWriter`] lays out the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriterOptions {
    /// Compress chunks with zstd. Default `true`; `false` is for tests and debugging.
    pub compress: bool,
    /// Target uncompressed chunk size in bytes: a chunk is closed once it grows past this.
    /// Default 1 MiB.
    pub chunk_size: u64,
    /// Close the current chunk (and flush it to the OS) whenever log time has advanced by at
    /// least this much since the last flush, so that a crash loses at most about this much
    /// recording. Nanoseconds; default 1 s. `0` flushes after every message.
    pub flush_interval_ns: u64,
    /// MCAP header `profile` field. Default empty (no ROS profile: plain JSON).
    pub profile: String,
    /// zstd level (1 = fastest; 0 = zstd's default, 3). Default 0. The recorder uses 3 (its
    /// `ZSTD_LEVEL`: the smallest files at a cost the writer thread carries beside the
    /// simulation).
    pub compression_level: u32,
    /// Write a message index after each chunk (16 bytes per message, uncompressed). Default
    /// `true`. Readers (ours, Foxglove, the Python `mcap` reader) find chunks by the chunk
    /// index and read a chunk whole; the per-message index only helps reading one topic of a
    /// chunk, and at 1 kHz it is a fifth of a session file, so the recorder leaves it out.
    pub message_indexes: bool,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            compress: true,
            chunk_size: 1024 * 1024,
            flush_interval_ns: 1_000_000_000,
            profile: String::new(),
            compression_level: 0,
            message_indexes: true,
        }
    }
}

impl WriterOptions {
    /// The `mcap` crate's options for these settings: message indexes, chunk indexes, metadata
    /// indexes, statistics and summary all on; single-threaded zstd.
    pub(crate) fn to_mcap(&self) -> mcap::WriteOptions {
        let compression = if self.compress {
            Some(mcap::Compression::Zstd)
        } else {
            None
        };
        mcap::WriteOptions::new()
            .compression(compression)
            .compression_level(self.compression_level)
            .compression_threads(0)
            .chunk_size(Some(self.chunk_size))
            .use_chunks(true)
            .emit_message_indexes(self.message_indexes)
            .emit_chunk_indexes(true)
            .emit_metadata_indexes(true)
            .emit_statistics(true)
            .emit_summary_offsets(true)
            .emit_summary_records(true)
            .profile(self.profile.clone())
            .library(concat!("icms-services/", env!("CARGO_PKG_VERSION")))
    }
}

/// What [`SessionWriter::finish`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriteSummary {
    /// The file written.
    pub path: PathBuf,
    /// Messages written, all topics.
    pub messages: u64,
    /// Messages written per topic.
    pub messages_per_topic: BTreeMap<String, u64>,
    /// Chunks in the file.
    pub chunks: u64,
    /// Metadata records written.
    pub metadata_records: u64,
    /// Smallest and largest message log time (ns), if any message was written.
    pub log_time_range_ns: Option<(u64, u64)>,
}

/// The hasher of [`SessionWriter`]'s topic map, FxHash-like: 8 bytes per multiplication. Each
/// message looks its topic up, and a session writes a few hundred thousand of them; the
/// default SipHash made that lookup a few per cent of the recorder's writer thread. The keys
/// are our own topic names, so there is no hash flooding to defend against.
#[derive(Clone, Copy, Default)]
struct TopicHasher(u64);

impl TopicHasher {
    fn add(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
}

impl std::hash::Hasher for TopicHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for chunk in &mut chunks {
            let mut word = [0; 8];
            word.copy_from_slice(chunk);
            self.add(u64::from_le_bytes(word));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut word = [0; 8];
            word[..rest.len()].copy_from_slice(rest);
            self.add(u64::from_le_bytes(word) ^ ((rest.len() as u64) << 59));
        }
    }
}

struct ChannelState {
    id: u16,
    schema_name: String,
    sequence: u32,
    count: u64,
}

/// Writes one recording session to an MCAP file.
///
/// Messages are JSON (`serde_json`), one channel per topic, each channel with a JSON Schema.
/// Chunks are zstd-compressed, about 1 MiB, with message indexes, chunk indexes and a summary
/// (Foxglove needs them to seek). The current chunk is closed and flushed whenever log time
/// advances by [`WriterOptions::flush_interval_ns`], so a process that dies mid-session leaves a
/// file that [`crate::mcap_io::salvage`] recovers up to the last flush.
///
/// Call [`finish`](Self::finish) to write the summary and footer and see any error. Dropping an
/// unfinished writer tries to finish it and ignores errors.
pub struct SessionWriter {
    inner: Option<mcap::Writer<BufWriter<File>>>,
    path: PathBuf,
    options: WriterOptions,
    channels: HashMap<String, ChannelState, std::hash::BuildHasherDefault<TopicHasher>>,
    last_flush_ns: Option<u64>,
    unflushed: bool,
    metadata_records: u64,
    log_time_range_ns: Option<(u64, u64)>,
    buf: Vec<u8>,
    /// Syncs the file in the background after each flush (see [`Syncer`]).
    syncer: Syncer,
}

/// Syncs the file to disk on a thread of its own after each [`SessionWriter::flush`], on a
/// second handle of the file, while writing goes on: at [`SessionWriter::finish`] only the
/// last flush interval is left to sync. (The recorder writes a 60 s session in well under a
/// second; syncing its 11 MB at the end took 8 to 17 ms of that, the last second's data takes
/// about 1 ms.) Its first error is reported by `finish`, which then syncs the rest.
struct Syncer {
    /// A handle on the file, until the thread starts.
    file: Option<File>,
    requests: Option<std::sync::mpsc::SyncSender<()>>,
    thread: Option<std::thread::JoinHandle<std::io::Result<()>>>,
}

impl Syncer {
    fn new(file: &File) -> Self {
        Self {
            file: file.try_clone().ok(),
            requests: None,
            thread: None,
        }
    }

    /// Asks for a sync of what was written so far (none if one is already waiting).
    fn request(&mut self) {
        if self.requests.is_none() {
            let Some(file) = self.file.take() else {
                return;
            };
            let (tx, rx) = std::sync::mpsc::sync_channel::<()>(1);
            let spawned = std::thread::Builder::new()
                .name("icms-mcap-sync".into())
                .spawn(move || rx.iter().try_for_each(|()| file.sync_data()));
            match spawned {
                Ok(thread) => (self.requests, self.thread) = (Some(tx), Some(thread)),
                Err(_) => return,
            }
        }
        if let Some(tx) = &self.requests {
            let _ = tx.try_send(());
        }
    }

    /// Stops the thread once its last sync is done, and reports its first error.
    fn stop(&mut self) -> std::io::Result<()> {
        self.requests = None;
        match self.thread.take() {
            Some(thread) => thread
                .join()
                .unwrap_or_else(|_| Err(std::io::Error::other("the sync thread panicked"))),
            None => Ok(()),
        }
    }
}

impl std::fmt::Debug for SessionWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SessionWriter")
            .field("path", &self.path)
            .field("options", &self.options)
            .field("topics", &self.channels.keys().collect::<Vec<_>>())
            .field("open", &self.inner.is_some())
            .finish()
    }
}

impl SessionWriter {
    /// Creates (truncates) `path` and writes the MCAP header, with default options.
    pub fn create(path: impl AsRef<Path>) -> Result<Self> {
        Self::create_with_options(path, WriterOptions::default())
    }

    /// Creates (truncates) `path` and writes the MCAP header.
    pub fn create_with_options(path: impl AsRef<Path>, options: WriterOptions) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let file = File::create(&path)
            .map_err(|e| RecordingError::io(format!("creating {}", path.display()), e))?;
        let syncer = Syncer::new(&file);
        let inner = options.to_mcap().create(BufWriter::new(file))?;
        Ok(Self {
            inner: Some(inner),
            path,
            options,
            channels: HashMap::default(),
            last_flush_ns: None,
            unflushed: false,
            metadata_records: 0,
            log_time_range_ns: None,
            buf: Vec::with_capacity(4096),
            syncer,
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The options in force.
    pub fn options(&self) -> &WriterOptions {
        &self.options
    }

    fn writer(&mut self) -> Result<&mut mcap::Writer<BufWriter<File>>> {
        match self.inner.as_mut() {
            Some(w) => Ok(w),
            None => Err(RecordingError::WriterClosed {
                path: self.path.clone(),
            }),
        }
    }

    /// Registers `topic` with a JSON Schema. Registering the same topic again with the same
    /// schema name is a no-op; with another schema name it is an error.
    pub fn register_channel(&mut self, topic: &str, schema: &JsonSchema) -> Result<()> {
        if let Some(existing) = self.channels.get(topic) {
            if existing.schema_name == schema.name {
                return Ok(());
            }
            return Err(RecordingError::TopicConflict {
                topic: topic.to_owned(),
                existing: existing.schema_name.clone(),
            });
        }
        let w = self.writer()?;
        let schema_id = w.add_schema(&schema.name, SCHEMA_ENCODING, schema.data.as_bytes())?;
        let id = w.add_channel(schema_id, topic, MESSAGE_ENCODING, &BTreeMap::new())?;
        self.channels.insert(
            topic.to_owned(),
            ChannelState {
                id,
                schema_name: schema.name.to_string(),
                sequence: 0,
                count: 0,
            },
        );
        Ok(())
    }

    /// Registers `topic` with a protobuf schema: `name` is the message's full name (e.g.
    /// `icms.Contacts`), `descriptor_set` a serialised `FileDescriptorSet` that defines it. The
    /// channel's messages are then protobuf ([`SessionWriter::write_raw`]). Registering the same
    /// topic again with the same schema name is a no-op; with another one it is an error.
    pub fn register_protobuf_channel(
        &mut self,
        topic: &str,
        name: &str,
        descriptor_set: &[u8],
    ) -> Result<()> {
        if let Some(existing) = self.channels.get(topic) {
            if existing.schema_name == name {
                return Ok(());
            }
            return Err(RecordingError::TopicConflict {
                topic: topic.to_owned(),
                existing: existing.schema_name.clone(),
            });
        }
        let w = self.writer()?;
        let schema_id = w.add_schema(name, "protobuf", descriptor_set)?;
        let id = w.add_channel(schema_id, topic, "protobuf", &BTreeMap::new())?;
        self.channels.insert(
            topic.to_owned(),
            ChannelState {
                id,
                schema_name: name.to_owned(),
                sequence: 0,
                count: 0,
            },
        );
        Ok(())
    }

    /// Whether `topic` has been registered.
    pub fn has_topic(&self, topic: &str) -> bool {
        self.channels.contains_key(topic)
    }

    /// Serialises `msg` as JSON and writes it on `topic` at `log_time_ns` (nanoseconds since the
    /// session start; also used as publish time).
    ///
    /// Fails with [`RecordingError::NonFiniteNumber`] (naming the field) if `msg` holds NaN or an
    /// infinity: nothing is written then, and the writer stays usable. Fails with
    /// [`RecordingError::UnregisteredTopic`] if `topic` was not registered.
    pub fn write<T: Serialize + ?Sized>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> Result<()> {
        match find_non_finite(msg) {
            Ok(None) => {}
            Ok(Some(found)) => {
                return Err(RecordingError::NonFiniteNumber {
                    topic: topic.to_owned(),
                    path: if found.path.is_empty() {
                        "(top level)".to_owned()
                    } else {
                        found.path
                    },
                    value: found.value.to_string(),
                })
            }
            Err(detail) => {
                return Err(RecordingError::Serialize {
                    topic: topic.to_owned(),
                    detail,
                })
            }
        }
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        let serialised = serde_json::to_writer(&mut buf, msg);
        let result = match serialised {
            Ok(()) => self.write_raw(topic, log_time_ns, &buf),
            Err(e) => Err(RecordingError::Serialize {
                topic: topic.to_owned(),
                detail: e.to_string(),
            }),
        };
        self.buf = buf;
        result
    }

    /// Writes an already-serialised message (JSON or protobuf, as the topic's channel says).
    /// The caller vouches that it matches the topic's schema (no check is made).
    pub fn write_raw(&mut self, topic: &str, log_time_ns: u64, data: &[u8]) -> Result<()> {
        let Some(channel) = self.channels.get_mut(topic) else {
            return Err(RecordingError::UnregisteredTopic {
                topic: topic.to_owned(),
            });
        };
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        channel.sequence = channel.sequence.wrapping_add(1);
        channel.count += 1;
        self.writer()?.write_to_known_channel(&header, data)?;
        self.unflushed = true;
        self.log_time_range_ns = Some(match self.log_time_range_ns {
            None => (log_time_ns, log_time_ns),
            Some((lo, hi)) => (lo.min(log_time_ns), hi.max(log_time_ns)),
        });
        let last = *self.last_flush_ns.get_or_insert(log_time_ns);
        if log_time_ns.saturating_sub(last) >= self.options.flush_interval_ns {
            self.flush()?;
            self.last_flush_ns = Some(log_time_ns);
        }
        Ok(())
    }

    /// Closes the current chunk and flushes everything written so far to the OS (and has it
    /// synced to disk in the background).
    pub fn flush(&mut self) -> Result<()> {
        if self.unflushed {
            self.writer()?.flush()?;
            self.unflushed = false;
            self.syncer.request();
        }
        Ok(())
    }

    /// Writes an MCAP metadata record (e.g. `session` parameters, wall-clock start time).
    /// This closes the current chunk.
    pub fn add_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        let record = Metadata {
            name: name.to_owned(),
            metadata,
        };
        self.writer()?.write_metadata(&record)?;
        self.metadata_records += 1;
        Ok(())
    }

    /// Writes an MCAP attachment record: a file carried in the recording (e.g. `hand.urdf`,
    /// media type `application/xml`), listed in the summary's attachment index. Its log and
    /// create times are 0, the session's start, so that a recording stays a function of its
    /// inputs byte for byte. This closes the current chunk.
    pub fn add_attachment(&mut self, name: &str, media_type: &str, data: &[u8]) -> Result<()> {
        self.writer()?.attach(&mcap::Attachment {
            log_time: 0,
            create_time: 0,
            name: name.to_owned(),
            media_type: media_type.to_owned(),
            data: std::borrow::Cow::Borrowed(data),
        })?;
        Ok(())
    }

    /// Writes the summary section and footer, flushes and syncs the file, and reports what was
    /// written.
    pub fn finish(mut self) -> Result<WriteSummary> {
        let mut inner = self
            .inner
            .take()
            .ok_or_else(|| RecordingError::WriterClosed {
                path: self.path.clone(),
            })?;
        let summary = inner.finish()?;
        let buffered = inner.into_inner();
        let file = buffered.into_inner().map_err(|e| {
            RecordingError::io(format!("flushing {}", self.path.display()), e.into_error())
        })?;
        self.syncer
            .stop()
            .and_then(|()| file.sync_data())
            .map_err(|e| RecordingError::io(format!("syncing {}", self.path.display()), e))?;
        let messages_per_topic: BTreeMap<String, u64> = self
            .channels
            .iter()
            .map(|(topic, c)| (topic.clone(), c.count))
            .collect();
        Ok(WriteSummary {
            path: self.path.clone(),
            messages: messages_per_topic.values().sum(),
            messages_per_topic,
            chunks: summary.chunk_indexes.len() as u64,
            metadata_records: self.metadata_records,
            log_time_range_ns: self.log_time_range_ns,
        })
    }

    /// Gives up on the file without finishing it and returns the underlying stream: everything
    /// up to the last closed chunk is on it, followed by the current chunk left incomplete (as a
    /// crash would leave it). Recover such a file with [`crate::mcap_io::salvage`].
    pub fn into_inner(mut self) -> Option<BufWriter<File>> {
        self.inner.take().map(mcap::Writer::into_inner)
    }
}

impl Drop for SessionWriter {
    fn drop(&mut self) {
        if let Some(mut inner) = self.inner.take() {
            // Best effort: a writer dropped on an error path still leaves a complete file.
            let _ = inner.finish();
            let mut buffered = inner.into_inner();
            let _ = buffered.flush();
        }
    }
}
