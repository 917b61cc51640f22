//! [`SessionWriter`]: messages into a zstd-chunked, indexed MCAP file, on protobuf channels
//! (session format 2) or on JSON channels with a JSON Schema (format 1).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::chunked::{ChunkOptions, ChunkedWriter};

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
    /// zstd level (1 = fastest; 0 = zstd's default, 3). Default 0. The recorder uses 1 (its
    /// `ZSTD_LEVEL`: the writer thread runs beside the simulation, and level 1 takes a third
    /// less of its time for files still within 12 MB a minute).
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

impl WriterOptions {
    fn to_chunked(&self) -> ChunkOptions {
        ChunkOptions {
            zstd_level: self.compress.then_some(self.compression_level as i32),
            chunk_size: usize::try_from(self.chunk_size).unwrap_or(usize::MAX),
            message_indexes: self.message_indexes,
            profile: self.profile.clone(),
            library: concat!("icms-services/", env!("CARGO_PKG_VERSION")).to_owned(),
        }
    }
}

/// What [`SessionWriter::finish`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriteSummary {
    /// The file written (for a stream, the name it was given).
    pub path: PathBuf,
    /// Bytes written.
    pub bytes: u64,
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

/// A registered topic, for [`SessionWriter::write_to`]: writing through it skips looking the
/// topic's name up (the recorder writes a few hundred thousand messages a minute).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicHandle(usize);

struct ChannelState {
    topic: String,
    id: u16,
    schema_name: String,
    sequence: u32,
    count: u64,
}

/// Writes one recording session to an MCAP file, or into any [`Write`]
/// ([`SessionWriter::to_stream`]).
///
/// One channel per topic, protobuf or JSON messages (JSON channels with a JSON Schema).
/// Chunks are zstd-compressed, about 1 MiB, with chunk indexes (message indexes unless turned
/// off) and a summary (Foxglove needs them to seek); see [`super::chunked`] for the layout and
/// why it is our own writer. The current chunk is closed and flushed whenever log time advances
/// by [`WriterOptions::flush_interval_ns`], so a process that dies mid-session leaves a file
/// that [`crate::mcap_io::salvage`] recovers up to the last flush.
///
/// Call [`finish`](Self::finish) to write the summary and footer and see any error. Dropping an
/// unfinished writer tries to finish it and ignores errors.
pub struct SessionWriter {
    inner: Option<ChunkedWriter<Sink>>,
    path: PathBuf,
    options: WriterOptions,
    channels: Vec<ChannelState>,
    topics: HashMap<String, TopicHandle>,
    last_flush_ns: Option<u64>,
    unflushed: bool,
    metadata_records: u64,
    log_time_range_ns: Option<(u64, u64)>,
    buf: Vec<u8>,
}

/// Where a [`SessionWriter`] writes: a file it syncs as it goes, or a stream of the caller's.
enum Sink {
    File {
        file: BufWriter<File>,
        /// Syncs the file in the background after each flush (see [`Syncer`]).
        syncer: Syncer,
        written: u64,
    },
    Stream {
        out: Box<dyn Write + Send>,
        written: u64,
    },
}

impl Sink {
    fn written(&self) -> u64 {
        match self {
            Sink::File { written, .. } | Sink::Stream { written, .. } => *written,
        }
    }
}

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let (n, written) = match self {
            Sink::File { file, written, .. } => (file.write(buf)?, written),
            Sink::Stream { out, written } => (out.write(buf)?, written),
        };
        *written += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Sink::File { file, syncer, .. } => {
                file.flush()?;
                syncer.request();
                Ok(())
            }
            Sink::Stream { out, .. } => out.flush(),
        }
    }
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
            .field("topics", &self.topics.keys().collect::<Vec<_>>())
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
        let sink = Sink::File {
            syncer: Syncer::new(&file),
            file: BufWriter::new(file),
            written: 0,
        };
        Self::on(sink, path, options)
    }

    /// Writes the session into `out` (which only needs [`Write`]: chunks are built in memory),
    /// naming it `name` in errors and in the [`WriteSummary`]. Nothing is synced: that is the
    /// owner of `out`'s business once [`finish`](Self::finish) returns.
    pub fn to_stream(
        out: Box<dyn Write + Send>,
        name: impl Into<PathBuf>,
        options: WriterOptions,
    ) -> Result<Self> {
        Self::on(Sink::Stream { out, written: 0 }, name.into(), options)
    }

    fn on(sink: Sink, path: PathBuf, options: WriterOptions) -> Result<Self> {
        let inner = ChunkedWriter::new(sink, options.to_chunked())
            .map_err(|e| RecordingError::io(format!("writing {}", path.display()), e))?;
        Ok(Self {
            inner: Some(inner),
            path,
            options,
            channels: Vec::new(),
            topics: HashMap::new(),
            last_flush_ns: None,
            unflushed: false,
            metadata_records: 0,
            log_time_range_ns: None,
            buf: Vec::with_capacity(4096),
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

    fn io_error(&self, e: std::io::Error) -> RecordingError {
        RecordingError::io(format!("writing {}", self.path.display()), e)
    }

    fn writer(&mut self) -> Result<&mut ChunkedWriter<Sink>> {
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
        self.register(
            topic,
            &schema.name,
            SCHEMA_ENCODING,
            schema.data.as_bytes(),
            MESSAGE_ENCODING,
        )
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
        self.register(topic, name, "protobuf", descriptor_set, "protobuf")
    }

    fn register(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_encoding: &str,
        schema: &[u8],
        message_encoding: &str,
    ) -> Result<()> {
        if let Some(&TopicHandle(i)) = self.topics.get(topic) {
            let existing = &self.channels[i];
            if existing.schema_name == schema_name {
                return Ok(());
            }
            return Err(RecordingError::TopicConflict {
                topic: topic.to_owned(),
                existing: existing.schema_name.clone(),
            });
        }
        let w = self.writer()?;
        let added = w
            .add_schema(schema_name, schema_encoding, schema)
            .and_then(|schema_id| {
                w.add_channel(schema_id, topic, message_encoding, &BTreeMap::new())
            });
        let id = added.map_err(|e| self.io_error(e))?;
        self.topics
            .insert(topic.to_owned(), TopicHandle(self.channels.len()));
        self.channels.push(ChannelState {
            topic: topic.to_owned(),
            id,
            schema_name: schema_name.to_owned(),
            sequence: 0,
            count: 0,
        });
        Ok(())
    }

    /// Whether `topic` has been registered.
    pub fn has_topic(&self, topic: &str) -> bool {
        self.topics.contains_key(topic)
    }

    /// The handle of a registered topic, for [`write_to`](Self::write_to).
    pub fn topic(&self, topic: &str) -> Result<TopicHandle> {
        self.topics
            .get(topic)
            .copied()
            .ok_or_else(|| RecordingError::UnregisteredTopic {
                topic: topic.to_owned(),
            })
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
        let handle = self.topic(topic)?;
        self.write_to(handle, log_time_ns, data)
    }

    /// [`write_raw`](Self::write_raw) on the topic of `handle` (from this writer's
    /// [`topic`](Self::topic)).
    pub fn write_to(&mut self, handle: TopicHandle, log_time_ns: u64, data: &[u8]) -> Result<()> {
        let channel = &mut self.channels[handle.0];
        let (id, sequence) = (channel.id, channel.sequence);
        channel.sequence = channel.sequence.wrapping_add(1);
        channel.count += 1;
        let written = self
            .writer()?
            .write_message(id, sequence, log_time_ns, log_time_ns, data);
        written.map_err(|e| self.io_error(e))?;
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

    /// Closes the current chunk and flushes everything written so far to the OS (and, for a
    /// file, has it synced to disk in the background).
    pub fn flush(&mut self) -> Result<()> {
        if self.unflushed {
            let flushed = self.writer()?.flush();
            flushed.map_err(|e| self.io_error(e))?;
            self.unflushed = false;
        }
        Ok(())
    }

    /// Writes an MCAP metadata record (e.g. `session` parameters, wall-clock start time).
    /// This closes the current chunk.
    pub fn add_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        let written = self.writer()?.write_metadata(name, &metadata);
        written.map_err(|e| self.io_error(e))?;
        self.metadata_records += 1;
        Ok(())
    }

    /// Writes an MCAP attachment record: a file carried in the recording (e.g. `hand.urdf`,
    /// media type `application/xml`), listed in the summary's attachment index. Its log and
    /// create times are 0, the session's start, so that a recording stays a function of its
    /// inputs byte for byte. This closes the current chunk.
    pub fn add_attachment(&mut self, name: &str, media_type: &str, data: &[u8]) -> Result<()> {
        let written = self.writer()?.attach(0, 0, name, media_type, data);
        written.map_err(|e| self.io_error(e))
    }

    /// Writes the summary section and footer, flushes (and for a file, syncs) the output, and
    /// reports what was written.
    pub fn finish(mut self) -> Result<WriteSummary> {
        let inner = self
            .inner
            .take()
            .ok_or_else(|| RecordingError::WriterClosed {
                path: self.path.clone(),
            })?;
        let (sink, chunks) = inner.finish().map_err(|e| self.io_error(e))?;
        let bytes = sink.written();
        match sink {
            Sink::File {
                file, mut syncer, ..
            } => {
                let file = file.into_inner().map_err(|e| {
                    RecordingError::io(format!("flushing {}", self.path.display()), e.into_error())
                })?;
                syncer.stop().and_then(|()| file.sync_data()).map_err(|e| {
                    RecordingError::io(format!("syncing {}", self.path.display()), e)
                })?;
            }
            Sink::Stream { mut out, .. } => out.flush().map_err(|e| self.io_error(e))?,
        }
        let messages_per_topic: BTreeMap<String, u64> = self
            .channels
            .iter()
            .map(|c| (c.topic.clone(), c.count))
            .collect();
        Ok(WriteSummary {
            path: self.path.clone(),
            bytes,
            messages: messages_per_topic.values().sum(),
            messages_per_topic,
            chunks,
            metadata_records: self.metadata_records,
            log_time_range_ns: self.log_time_range_ns,
        })
    }

    /// Gives up on the file without finishing it and returns the underlying stream: everything
    /// up to the last closed chunk is on it, followed by the first half of the current chunk
    /// (as a crash while writing it would leave it). Recover such a file with
    /// [`crate::mcap_io::salvage`].
    pub fn into_inner(mut self) -> Option<Box<dyn Write + Send>> {
        self.inner.take().map(|w| match w.abandon() {
            Sink::File { file, .. } => Box::new(file) as Box<dyn Write + Send>,
            Sink::Stream { out, .. } => out,
        })
    }
}

impl Drop for SessionWriter {
    fn drop(&mut self) {
        if let Some(inner) = self.inner.take() {
            // Best effort: a writer dropped on an error path still leaves a complete file.
            let _ = inner.finish();
        }
    }
}
