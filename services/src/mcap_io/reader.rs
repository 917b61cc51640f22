//! Reading untrusted MCAP files: [`read_session_bytes`], [`read_session_file`] and the record
//! scanner that [`crate::mcap_io::salvage`] shares.
//!
//! The scanner frames top-level records itself (so it knows every record's byte offset and never
//! allocates more than [`ReadLimits::max_record_bytes`], nor more than the bytes actually left in
//! the input) and hands each complete record to the `mcap` crate's sans-I/O linear reader with
//! chunk CRC prevalidation and a record length limit: a chunk's records are released only after
//! the whole chunk decompressed and matched its CRC. The data section and summary CRCs are
//! checked too, the zstd window is capped at 16 MiB, and reserved opcodes are refused (the spec's
//! "skip unknown records" would turn a damaged chunk opcode into a silently missing chunk).
//!
//! Decompression is bounded by the input's length ([`ReadLimits::decompressed_limit`]): each
//! chunk's declared `uncompressed_size` counts against the budget before the chunk is
//! decompressed, and no chunk decompresses past its declared size, so a small file that
//! expands to gigabytes (a decompression bomb, a header that lies) is refused having allocated
//! no more than its budget.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use mcap::records::{op, ChunkHeader, MessageHeader, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::McapError;
use serde::de::DeserializeOwned;
use serde::Deserialize;

use super::bounded_zstd::{BoundedZstd, MAX_WINDOW_LOG};
use super::json_check;
use super::par::{par_map, MESSAGES_PER_JOB};
use super::pool::CHUNK_BUFFERS;
use super::writer::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use crate::error::{RecordingError, Result};

/// Bounds on what a reader accepts from an untrusted file.
///
/// # Memory
///
/// What a read holds is bounded by the input's length `N`. The decompressed chunks, the
/// messages outside chunks and the index of every message (40 bytes each) together take at most
/// [`decompressed_limit(N)`](Self::decompressed_limit): `128 N + 1 MiB` with the defaults, and
/// never more than 4 GiB. Each chunk counts with the size its header declares before it is
/// decompressed, and none decompresses past that size. On top of that: the compressed records
/// (about `N`, plus two buffers of the largest record) and, for
/// [`crate::session::read_session`], the typed samples of the raw topics it keeps (about as
/// much again as their JSON).
///
/// Measured (peak resident set of `icms segment`): a 60 s session of 31 MB, 325 MB; a 1 MB
/// file of 2-byte messages up to its budget, 145 MB, refused (293 MB before the index counted);
/// a 34 kB file of zstd chunks claiming 1 GiB, 8 MB, refused (1 GiB before these limits).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    /// Longest record accepted, in bytes, and the largest decompressed chunk. Default 64 MiB
    /// (our writer's chunks are about 1 MiB).
    pub max_record_bytes: u64,
    /// Most bytes one file may decompress to, whatever its size (chunk contents and messages
    /// outside chunks). Default 4 GiB: about 30 minutes of a 1 kHz session.
    pub max_total_message_bytes: u64,
    /// Most bytes a file may decompress to per byte of its own length: see
    /// [`DEFAULT_MAX_EXPANSION`]. A file that expands more is a decompression bomb (or a chunk
    /// header that lies about its size) and is refused before the chunk that crosses the line
    /// is decompressed.
    pub max_expansion: u64,
    /// Decompressed bytes allowed on top of `max_expansion` times the length, so that tiny
    /// files (a few messages, where compression barely pays) are not refused. Default 1 MiB.
    pub expansion_allowance: u64,
}

/// Default [`ReadLimits::max_expansion`]: 128, about twice the most compressible session
/// measured. Chunks decompress to this many times the file's length:
///
/// | session                                   | ours (zstd) | `mcap` Rust / Python, zstd | lz4 |
/// |-------------------------------------------|-------------|----------------------------|-----|
/// | built-in scenarios, 60 s of `two-grasps`  | 4.7-5.9     | 4.4-5.6 (6.4 with no message indexes) | 2.7-3.8 |
/// | a glove import that never moves (60 s)    | 22.3        | 21.8-22.6 (66-72 with no message indexes) | 14.8-27.5 |
///
/// A chunk of zeros expands about 30 000x in zstd and 250x in lz4.
pub const DEFAULT_MAX_EXPANSION: u64 = 128;

impl Default for ReadLimits {
    fn default() -> Self {
        Self {
            max_record_bytes: 64 * 1024 * 1024,
            max_total_message_bytes: 4 * 1024 * 1024 * 1024,
            max_expansion: DEFAULT_MAX_EXPANSION,
            expansion_allowance: 1024 * 1024,
        }
    }
}

/// [`ReadLimits::max_total_message_bytes`] of [`ReadLimits::streaming`]: 64 GiB, about 40 hours
/// of a format 2 session (1.6 GB of messages an hour).
pub const STREAMING_MAX_TOTAL_MESSAGE_BYTES: u64 = 64 << 30;

impl ReadLimits {
    /// The limits of a streamed read (the session readers of [`crate::session`]): the
    /// defaults, with [`STREAMING_MAX_TOTAL_MESSAGE_BYTES`] in all. A streamed read holds a
    /// chunk at a time, so the total bounds work, not memory; a file's own length still
    /// bounds what it may decompress to ([`Self::max_expansion`]).
    pub fn streaming() -> Self {
        Self {
            max_total_message_bytes: STREAMING_MAX_TOTAL_MESSAGE_BYTES,
            ..Self::default()
        }
    }

    /// Most bytes a file of `input_len` bytes may decompress to: `max_expansion × input_len +
    /// expansion_allowance`, and never more than `max_total_message_bytes`. The readers apply
    /// it with the length of what they read (the bytes given, the file's size), whatever
    /// limits the caller passes.
    pub fn decompressed_limit(&self, input_len: u64) -> u64 {
        self.max_expansion
            .saturating_mul(input_len)
            .saturating_add(self.expansion_allowance)
            .min(self.max_total_message_bytes)
    }

    /// The error for a file of `input_len` bytes (`None`: unknown) whose chunks, up to and
    /// including the one at `offset`, decompress to `total` bytes: over the expansion limit or
    /// over the absolute one, whichever is in force.
    fn over_limit(&self, input_len: Option<u64>, offset: u64, total: u64) -> RecordingError {
        match input_len {
            Some(len) if self.decompressed_limit(len) < self.max_total_message_bytes => {
                RecordingError::DecompressesTooMuch {
                    offset,
                    input_len: len,
                    total,
                    ratio: self.max_expansion,
                    limit: self.decompressed_limit(len),
                }
            }
            _ => RecordingError::TooMuchData {
                limit: self.max_total_message_bytes,
            },
        }
    }

    /// The decompressed bytes a file of `input_len` bytes may hold (`None`: unknown length,
    /// only the absolute limit applies).
    fn budget(&self, input_len: Option<u64>) -> u64 {
        input_len.map_or(self.max_total_message_bytes, |len| {
            self.decompressed_limit(len)
        })
    }
}

/// Schema record of a channel, as read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SchemaInfo {
    /// Schema name, e.g. `foxglove.SceneUpdate`.
    pub name: String,
    /// Schema encoding, e.g. `jsonschema`.
    pub encoding: String,
    /// Schema document.
    pub data: Vec<u8>,
}

/// One message as read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordedMessage {
    /// Log time, ns since the session start.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// Channel sequence number.
    pub sequence: u32,
    /// Message payload (JSON text on `json` topics, checked at read time; protobuf bytes on
    /// `protobuf` topics, decoded by the session reader).
    pub data: Vec<u8>,
}

/// All messages of one topic, in file order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicRecording {
    /// Topic name.
    pub topic: String,
    /// Message encoding of the topic's channel (`protobuf` for ours since format 2, `json`
    /// before).
    pub message_encoding: String,
    /// The channel's schema, `None` for a schemaless channel.
    pub schema: Option<SchemaInfo>,
    /// The messages in file order.
    pub messages: Vec<RecordedMessage>,
}

impl TopicRecording {
    /// Schema name, if the channel has a schema.
    pub fn schema_name(&self) -> Option<&str> {
        self.schema.as_ref().map(|s| s.name.as_str())
    }

    /// Checks that every message is valid JSON (without building anything).
    pub fn check_json(&self) -> Result<()> {
        self.check_json_encoding()?;
        for (i, m) in self.messages.iter().enumerate() {
            check_message(&self.topic, i, m.log_time_ns, &m.data)?;
        }
        Ok(())
    }

    /// The messages parsed as JSON values, with their log times.
    pub fn json_values(&self) -> Result<Vec<(u64, serde_json::Value)>> {
        self.decode()
    }

    /// The messages decoded into `T`, with their log times.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<Vec<(u64, T)>> {
        self.check_json_encoding()?;
        self.messages
            .iter()
            .enumerate()
            .map(|(i, m)| decode_message(&self.topic, i, m.log_time_ns, &m.data))
            .collect()
    }

    fn check_json_encoding(&self) -> Result<()> {
        check_json_encoding(&self.topic, &self.message_encoding)
    }
}

/// One metadata record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MetadataRecord {
    /// Record name, e.g. `session`.
    pub name: String,
    /// Key-value pairs.
    pub entries: BTreeMap<String, String>,
}

/// A whole MCAP session read into memory: topics, schemas, metadata.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecordedSession {
    /// Header `profile` field.
    pub profile: String,
    /// Header `library` field (which writer made the file).
    pub library: String,
    /// Topics by name.
    pub topics: BTreeMap<String, TopicRecording>,
    /// Metadata records in file order (names may repeat).
    pub metadata: Vec<MetadataRecord>,
}

impl RecordedSession {
    /// The topic, which must exist and have the schema named `schema_name`: JSON messages with
    /// a `jsonschema` schema, or protobuf messages with a `protobuf` schema.
    pub fn require_topic(&self, topic: &str, schema_name: &str) -> Result<&TopicRecording> {
        let t = self
            .topics
            .get(topic)
            .ok_or_else(|| RecordingError::MissingTopic {
                topic: topic.to_owned(),
            })?;
        check_topic(topic, &t.message_encoding, t.schema.as_ref(), schema_name)?;
        Ok(t)
    }

    /// [`require_topic`](Self::require_topic), then decode every message into `T`.
    pub fn decode_topic<T: DeserializeOwned>(
        &self,
        topic: &str,
        schema_name: &str,
    ) -> Result<Vec<(u64, T)>> {
        self.require_topic(topic, schema_name)?.decode()
    }

    /// The first metadata record named `name`.
    pub fn metadata(&self, name: &str) -> Option<&BTreeMap<String, String>> {
        self.metadata
            .iter()
            .find(|m| m.name == name)
            .map(|m| &m.entries)
    }

    /// Messages per topic.
    pub fn message_counts(&self) -> BTreeMap<String, usize> {
        self.topics
            .iter()
            .map(|(k, t)| (k.clone(), t.messages.len()))
            .collect()
    }
}

/// Reads a whole MCAP session from memory. See [`read_session_file`].
pub fn read_session_bytes(bytes: &[u8], limits: &ReadLimits) -> Result<RecordedSession> {
    read_session_from(bytes, Some(bytes.len() as u64), limits, &[])
}

/// [`read_session_bytes`] for a caller that decodes the messages of `decoded_topics` itself
/// (which validates their JSON): those are not parsed a second time here. Every other `json`
/// topic is still checked to hold valid JSON.
pub fn read_session_bytes_decoding(
    bytes: &[u8],
    limits: &ReadLimits,
    decoded_topics: &[&str],
) -> Result<RecordedSession> {
    read_session_from(bytes, Some(bytes.len() as u64), limits, decoded_topics)
}

/// Reads a whole MCAP session from a file, safely for untrusted input: checks the magic,
/// validates every chunk's CRC before using its records, refuses records longer than
/// [`ReadLimits::max_record_bytes`], and requires the footer (a file without one is
/// [`RecordingError::Truncated`]: [`crate::mcap_io::salvage`] it). Messages on `json` topics
/// are checked to be valid JSON.
pub fn read_session_file(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<RecordedSession> {
    read_session_file_decoding(path, limits, &[])
}

/// [`read_session_file`] for a caller that decodes the messages of `decoded_topics` itself;
/// see [`read_session_bytes_decoding`].
pub fn read_session_file_decoding(
    path: impl AsRef<Path>,
    limits: &ReadLimits,
    decoded_topics: &[&str],
) -> Result<RecordedSession> {
    let path = path.as_ref();
    let (file, len) = open_with_len(path)?;
    read_session_from(file, Some(len), limits, decoded_topics)
}

/// The file at `path`, buffered for reading, and its length.
fn open_with_len(path: &Path) -> Result<(BufReader<File>, u64)> {
    let file = File::open(path)
        .map_err(|e| RecordingError::io(format!("opening {}", path.display()), e))?;
    let len = file
        .metadata()
        .map_err(|e| RecordingError::io(format!("reading {}", path.display()), e))?
        .len();
    Ok((BufReader::with_capacity(1 << 16, file), len))
}

fn read_session_from<R: Read>(
    src: R,
    total_len: Option<u64>,
    limits: &ReadLimits,
    decoded_topics: &[&str],
) -> Result<RecordedSession> {
    let raw = read_raw(src, total_len, limits)?;
    let skip: Vec<&str> = decoded_topics.to_vec();
    raw.check_json(|topic| !skip.contains(&topic))?;
    Ok(raw.into_recorded())
}

/// Where a message's payload lies: `buffers[buffer][start..end]` of a [`RawSession`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MessageRef {
    /// Log time, ns.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// Channel sequence number.
    pub sequence: u32,
    buffer: u32,
    start: usize,
    end: usize,
}

/// One topic of a [`RawSession`]: like [`TopicRecording`], with the payloads left in place.
#[derive(Debug, Clone)]
pub(crate) struct RawTopic {
    pub topic: String,
    pub message_encoding: String,
    pub schema: Option<SchemaInfo>,
    pub messages: Vec<MessageRef>,
}

impl RawTopic {
    /// Same checks as [`RecordedSession::require_topic`].
    pub(crate) fn require(&self, schema_name: &str) -> Result<()> {
        check_topic(
            &self.topic,
            &self.message_encoding,
            self.schema.as_ref(),
            schema_name,
        )
    }

    /// Whether the topic carries JSON messages.
    pub(crate) fn is_json(&self) -> bool {
        self.message_encoding == MESSAGE_ENCODING
    }

    /// Whether the topic carries protobuf messages.
    pub(crate) fn is_protobuf(&self) -> bool {
        self.message_encoding == PROTOBUF
    }
}

/// A session read and checked structurally (CRCs, limits, links between records) but with
/// every message payload still inside its decompressed chunk: no copy per message. Messages
/// are not yet checked to be JSON: [`RawSession::check_json`] or a decoder does that.
#[derive(Debug, Default)]
pub(crate) struct RawSession {
    pub profile: String,
    pub library: String,
    pub topics: BTreeMap<String, RawTopic>,
    pub metadata: Vec<MetadataRecord>,
    /// Decompressed chunk contents, then the payloads of messages outside chunks.
    buffers: Vec<Vec<u8>>,
}

impl RawSession {
    /// The payload of `m`.
    pub(crate) fn data(&self, m: &MessageRef) -> &[u8] {
        &self.buffers[m.buffer as usize][m.start..m.end]
    }

    /// Checks that every message of every `json` topic `check(topic)` selects is valid JSON,
    /// in parallel; the first invalid message in topic and file order is the error.
    pub(crate) fn check_json(&self, check: impl Fn(&str) -> bool) -> Result<()> {
        let jobs: Vec<(&RawTopic, usize, &[MessageRef])> = self
            .topics
            .values()
            .filter(|t| t.is_json() && check(&t.topic))
            .flat_map(|t| {
                t.messages
                    .chunks(MESSAGES_PER_JOB)
                    .enumerate()
                    .map(move |(k, m)| (t, k * MESSAGES_PER_JOB, m))
            })
            .collect();
        par_map(jobs.len(), |i| {
            let (t, first, messages) = jobs[i];
            self.check_json_of(t, first, messages)
        })
        .into_iter()
        .collect()
    }

    /// Checks that each of `messages` (of topic `t`, the first of them its message number
    /// `first`) is valid JSON.
    pub(crate) fn check_json_of(
        &self,
        t: &RawTopic,
        first: usize,
        messages: &[MessageRef],
    ) -> Result<()> {
        for (i, m) in messages.iter().enumerate() {
            check_message(&t.topic, first + i, m.log_time_ns, self.data(m))?;
        }
        Ok(())
    }

    /// The owned form: one `Vec` per message.
    fn into_recorded(self) -> RecordedSession {
        let topics = self
            .topics
            .values()
            .map(|t| {
                let messages = t
                    .messages
                    .iter()
                    .map(|m| RecordedMessage {
                        log_time_ns: m.log_time_ns,
                        publish_time_ns: m.publish_time_ns,
                        sequence: m.sequence,
                        data: self.data(m).to_vec(),
                    })
                    .collect();
                (
                    t.topic.clone(),
                    TopicRecording {
                        topic: t.topic.clone(),
                        message_encoding: t.message_encoding.clone(),
                        schema: t.schema.clone(),
                        messages,
                    },
                )
            })
            .collect();
        RecordedSession {
            profile: self.profile,
            library: self.library,
            topics,
            metadata: self.metadata,
        }
    }
}

/// Message `index` of `topic`, checked to be JSON; the error names its topic, number and log
/// time.
pub(crate) fn check_message(
    topic: &str,
    index: usize,
    log_time_ns: u64,
    data: &[u8],
) -> Result<()> {
    json_check::validate(data).map_err(|source| RecordingError::InvalidJson {
        topic: topic.to_owned(),
        index,
        log_time_ns,
        path: String::new(),
        source,
    })
}

/// Message `index` of `topic` decoded into `T`, with its log time; the error names its topic,
/// number, log time and field.
fn decode_message<T: DeserializeOwned>(
    topic: &str,
    index: usize,
    log_time_ns: u64,
    data: &[u8],
) -> Result<(u64, T)> {
    serde_json::from_slice(data)
        .map(|v| (log_time_ns, v))
        .map_err(|source| json_error::<T>(topic, index, log_time_ns, data, source))
}

/// The error of message `index` of `topic`, whose payload `data` does not decode into `T`
/// (`source`): with the path of the field at fault, found by decoding it again (only on this
/// error path: tracking the path on every message would slow reading down).
pub(crate) fn json_error<'de, T: Deserialize<'de>>(
    topic: &str,
    index: usize,
    log_time_ns: u64,
    data: &'de [u8],
    source: serde_json::Error,
) -> RecordingError {
    let mut de = serde_json::Deserializer::from_slice(data);
    let path = match serde_path_to_error::deserialize::<_, T>(&mut de) {
        Err(e) => e.path().to_string(),
        Ok(_) => String::new(),
    };
    RecordingError::InvalidJson {
        topic: topic.to_owned(),
        index,
        log_time_ns,
        path: if path == "." { String::new() } else { path },
        source,
    }
}

/// Message and schema encoding of session format 2.
const PROTOBUF: &str = "protobuf";

/// How errors name a message: `topic T message I (log time N ns)`.
pub(crate) fn message_location(topic: &str, index: usize, log_time_ns: u64) -> String {
    format!("topic {topic} message {index} (log time {log_time_ns} ns)")
}

/// A topic's schema is the one named `schema_name`, and its messages are JSON with a
/// `jsonschema` schema (session format 1) or protobuf with a `protobuf` schema (format 2).
fn check_topic(
    topic: &str,
    message_encoding: &str,
    schema: Option<&SchemaInfo>,
    schema_name: &str,
) -> Result<()> {
    let schema_encoding = if message_encoding == PROTOBUF {
        PROTOBUF
    } else {
        check_json_encoding(topic, message_encoding)?;
        SCHEMA_ENCODING
    };
    match schema {
        Some(s) if s.name == schema_name => {
            if s.encoding != schema_encoding {
                return Err(RecordingError::NonJsonEncoding {
                    topic: topic.to_owned(),
                    encoding: s.encoding.clone(),
                    expected: schema_encoding,
                });
            }
            Ok(())
        }
        other => Err(RecordingError::UnknownSchema {
            topic: topic.to_owned(),
            expected: schema_name.to_owned(),
            found: other.map(|s| s.name.clone()),
        }),
    }
}

fn check_json_encoding(topic: &str, encoding: &str) -> Result<()> {
    if encoding != MESSAGE_ENCODING {
        return Err(RecordingError::NonJsonEncoding {
            topic: topic.to_owned(),
            encoding: encoding.to_owned(),
            expected: MESSAGE_ENCODING,
        });
    }
    Ok(())
}

/// Reads a whole MCAP session safely (see [`read_session_file`]) without checking its JSON.
///
/// Three steps. The scanner frames the top-level records and checks the data and summary
/// section CRCs, keeping chunks compressed. Then every chunk is decompressed, checked against
/// its CRC and split into records, in parallel (each chunk is independent). Then, in file
/// order, schemas and channels are linked and each message is filed under its topic by
/// reference into its chunk. Errors are reported in file order: the first bad record wins.
fn read_raw<R: Read>(src: R, total_len: Option<u64>, limits: &ReadLimits) -> Result<RawSession> {
    let mut batches: Vec<Batch> = Vec::new();
    // Every decompressed chunk is held until the session is read: `scan` bounds their declared
    // sizes together, and `unpack_chunk` decompresses none past its declared size.
    let outcome = scan(src, total_len, limits, true, |batch| {
        batches.push(batch);
        Ok(())
    })?;
    // Over the budget: refused at once, without decompressing the chunks before it (an error
    // in those would otherwise come first, in file order).
    if let Some(
        e @ (RecordingError::DecompressesTooMuch { .. } | RecordingError::TooMuchData { .. }),
    ) = outcome.error
    {
        return Err(e);
    }
    let chunks: Vec<(u64, &ChunkHeader, &[u8])> = batches
        .iter()
        .flat_map(|b| {
            b.records.iter().filter_map(move |r| match r {
                Record::Chunk { header, data } => Some((b.offset, header, &data[..])),
                _ => None,
            })
        })
        .collect();
    let unpacked = par_map(chunks.len(), |i| {
        let (offset, header, data) = chunks[i];
        unpack_chunk(offset, header, data, limits, &mut None, None)
    });
    let loose_buffer = u32::try_from(chunks.len()).map_err(|_| RecordingError::Corrupt {
        offset: 0,
        detail: "more than 2^32 chunks".into(),
    })?;
    let mut builder = SessionBuilder::new(*limits, total_len, loose_buffer);
    // The chunks are decompressed (to their declared sizes, checked): what messages outside
    // chunks and the index of every message add counts against the same budget.
    builder.held = batches
        .iter()
        .flat_map(|b| &b.records)
        .map(|r| match r {
            Record::Chunk { header, .. } => header.uncompressed_size,
            _ => 0,
        })
        .fold(0u64, u64::saturating_add);
    drop(chunks);
    let mut unpacked = unpacked.into_iter();
    for batch in batches {
        let offset = batch.offset;
        for record in batch.records {
            match record {
                Record::Chunk { .. } => {
                    let content = unpacked.next().expect("one result per chunk")?;
                    let buffer = builder.session.buffers.len() as u32;
                    // The chunk's records again, in order: messages are framed from its data
                    // (checked by `unpack_chunk`), the others were parsed there.
                    let mut others = content.others.into_iter();
                    let mut pos = 0;
                    while let Some((opcode, start, end)) =
                        next_chunk_record(&content.data, pos, offset, limits)?
                    {
                        if opcode == op::MESSAGE {
                            let header = message_header(&content.data[start..end]);
                            let payload = start + MESSAGE_HEADER_LEN;
                            builder.message(offset, &header, buffer, payload, end)?;
                        } else if let Some(r) = others.next() {
                            builder.apply(offset, r)?;
                        }
                        pos = end;
                    }
                    builder.session.buffers.push(content.data);
                }
                Record::Message { header, data } => {
                    builder.loose_message(offset, &header, &data)?
                }
                other => builder.apply(offset, other)?,
            }
        }
    }
    outcome.into_result()?;
    let mut session = builder.session;
    session.buffers.push(builder.loose);
    session.topics = builder
        .topics
        .into_iter()
        .map(|t| (t.topic.clone(), t))
        .collect();
    Ok(session)
}

/// What [`stream_raw`] hands on, record by record in file order.
pub(crate) trait RawVisitor {
    /// Message `index` (counted per topic from 0) of `topic`, the `topic_index`th topic
    /// announced by [`RawVisitor::topic`], its payload borrowed from its chunk. An error stops
    /// the read and is its result.
    fn message(
        &mut self,
        topic_index: usize,
        topic: &RawTopic,
        index: usize,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<()>;

    /// A topic seen for the first time (its first channel record), before any of its messages.
    fn topic(&mut self, _topic: &RawTopic) -> Result<()> {
        Ok(())
    }

    /// A metadata record, as it comes.
    fn metadata(&mut self, _record: &MetadataRecord) -> Result<()> {
        Ok(())
    }

    /// Asked of [`stream_raw`]'s `early` visitor once a topic was announced: whether it takes
    /// that topic's messages on the reading thread (the main visitor then never sees them).
    fn claims(&self, _topic_index: usize) -> bool {
        false
    }
}

/// A visitor that takes nothing.
impl RawVisitor for () {
    fn message(&mut self, _: usize, _: &RawTopic, _: usize, _: u64, _: &[u8]) -> Result<()> {
        Ok(())
    }
}

/// What a streamed read leaves once every message went to the visitor: the topics (with no
/// message list) and how many messages each had, and the metadata records.
#[derive(Debug, Default)]
pub(crate) struct StreamedRaw {
    /// Topics in order of first appearance, each with its message count.
    pub topics: Vec<(RawTopic, usize)>,
    pub metadata: Vec<MetadataRecord>,
}

impl StreamedRaw {
    /// The topic named `topic` and its message count.
    pub(crate) fn topic(&self, topic: &str) -> Option<&(RawTopic, usize)> {
        self.topics.iter().find(|(t, _)| t.topic == topic)
    }
}

/// Most metadata records a streamed read keeps before refusing the file (the session reader
/// allows far fewer and says so at the end; this bounds what a file of nothing but metadata
/// can make it hold).
const STREAM_MAX_METADATA_RECORDS: usize = 4096;

/// [`stream_raw`] of bytes in memory.
pub(crate) fn stream_raw_bytes(
    bytes: &[u8],
    limits: &ReadLimits,
    early: &mut (impl RawVisitor + Send),
    visitor: &mut impl RawVisitor,
) -> Result<StreamedRaw> {
    stream_raw(bytes, Some(bytes.len() as u64), limits, early, visitor)
}

/// [`stream_raw`] of a file.
pub(crate) fn stream_raw_file(
    path: &Path,
    limits: &ReadLimits,
    early: &mut (impl RawVisitor + Send),
    visitor: &mut impl RawVisitor,
) -> Result<StreamedRaw> {
    let (file, len) = open_with_len(path)?;
    stream_raw(file, Some(len), limits, early, visitor)
}

/// Reads an MCAP file in one pass with the checks of [`read_raw`], handing every message to a
/// visitor as its chunk is decompressed and checked, in file order, then dropping the chunk:
/// what it holds is a few chunks (each at most [`ReadLimits::max_record_bytes`]) whatever the
/// file's length. Decompression is bounded as in [`read_raw`] (the chunks' declared sizes
/// against [`ReadLimits::decompressed_limit`] of the input's length), which here bounds work,
/// not memory.
///
/// Two threads: the reading thread reads, checks, decompresses and files the records, and
/// hands the messages of the topics `early` [claims](RawVisitor::claims) to it; the calling
/// thread hands the others to `visitor`, a few chunks behind. Both see every topic and
/// metadata record announced, each in file order.
///
/// The visitors see messages before the end of the file is checked: a file truncated or
/// damaged later (a data section CRC, a missing footer) is an error at the end, after the
/// messages before the damage went by. Callers keep nothing of a read that failed.
pub(crate) fn stream_raw<R: Read + Send>(
    src: R,
    total_len: Option<u64>,
    limits: &ReadLimits,
    early: &mut (impl RawVisitor + Send),
    visitor: &mut impl RawVisitor,
) -> Result<StreamedRaw> {
    std::thread::scope(|scope| -> Result<StreamedRaw> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Filed>(STREAM_CHUNKS_AHEAD);
        // Decompressed chunks go back to the reading thread to be filled again: a fresh buffer
        // for every chunk cost a page fault (and the kernel's zeroing) per 4 kB of it.
        let (recycle, recycled) = std::sync::mpsc::sync_channel::<Vec<u8>>(RECYCLED_BUFFERS);
        let reader = scope.spawn(move || -> Result<StreamedRaw> {
            let mut filer = Filer::new(total_len, limits, early);
            filer.recycled = Some(recycled);
            let outcome = scan(src, total_len, limits, true, |batch| {
                let filed = filer.file(batch)?;
                // The calling thread stopped (an error there): stop reading.
                tx.send(filed).map_err(|_| RecordingError::WriterClosed {
                    path: std::path::PathBuf::from("the session stream"),
                })
            })?;
            outcome.into_result()?;
            Ok(filer.streamed())
        });
        let mut topics: Vec<RawTopic> = Vec::new();
        let mut failed = None;
        for filed in rx.iter() {
            match deliver(filed, &mut topics, visitor) {
                Ok(buffers) => {
                    for buffer in buffers {
                        // Full (the reader has enough) or gone: to the pool.
                        if let Err(e) = recycle.try_send(buffer) {
                            let (std::sync::mpsc::TrySendError::Full(b)
                            | std::sync::mpsc::TrySendError::Disconnected(b)) = e;
                            CHUNK_BUFFERS.give(b);
                        }
                    }
                }
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        drop(rx);
        let read = reader
            .join()
            .map_err(|_| RecordingError::WriterThreadPanicked)?;
        match failed {
            Some(e) => Err(e),
            None => read,
        }
    })
}

/// Hands the events of `filed` to `visitor` in order (`topics`: those announced so far);
/// returns its buffers, to be filled again.
fn deliver(
    filed: Filed,
    topics: &mut Vec<RawTopic>,
    visitor: &mut impl RawVisitor,
) -> Result<Vec<Vec<u8>>> {
    for event in filed.events {
        match event {
            Event::Topic(t) => {
                let r = visitor.topic(&t);
                topics.push(*t);
                r?
            }
            Event::Metadata(m) => visitor.metadata(&m)?,
            Event::Message {
                topic,
                index,
                log_time_ns,
                buffer,
                start,
                end,
            } => visitor.message(
                topic,
                &topics[topic],
                index,
                log_time_ns,
                &filed.buffers[buffer][start..end],
            )?,
        }
    }
    Ok(filed.buffers)
}

/// What the reading thread of [`stream_raw`] hands on for one top-level record: the records'
/// events in file order, and the buffers the messages lie in (a decompressed chunk, or a
/// message outside chunks).
struct Filed {
    buffers: Vec<Vec<u8>>,
    events: Vec<Event>,
}

/// One thing the calling thread of [`stream_raw`] hands its visitor.
enum Event {
    Topic(Box<RawTopic>),
    Metadata(MetadataRecord),
    Message {
        topic: usize,
        index: usize,
        log_time_ns: u64,
        buffer: usize,
        start: usize,
        end: usize,
    },
}

/// The reading thread's filing of records: schemas, channels and topics, message counts, and
/// the messages of claimed topics handed to the early visitor.
struct Filer<'a, E: RawVisitor> {
    builder: SessionBuilder,
    counts: Vec<usize>,
    claimed: Vec<bool>,
    limits: &'a ReadLimits,
    early: &'a mut E,
    /// The zstd context, reused from chunk to chunk.
    dctx: Option<zstd::zstd_safe::DCtx<'static>>,
    /// Chunk buffers the calling thread is done with, to decompress into again.
    recycled: Option<std::sync::mpsc::Receiver<Vec<u8>>>,
}

impl<'a, E: RawVisitor> Filer<'a, E> {
    fn new(total_len: Option<u64>, limits: &'a ReadLimits, early: &'a mut E) -> Self {
        Filer {
            builder: SessionBuilder::new(*limits, total_len, 0),
            counts: Vec::new(),
            claimed: Vec::new(),
            limits,
            early,
            dctx: None,
            recycled: None,
        }
    }

    /// What the read found, once every record was filed.
    fn streamed(&mut self) -> StreamedRaw {
        let topics = std::mem::take(&mut self.builder.topics);
        let counts = std::mem::take(&mut self.counts);
        StreamedRaw {
            topics: topics.into_iter().zip(counts).collect(),
            metadata: std::mem::take(&mut self.builder.session.metadata),
        }
    }

    fn file(&mut self, batch: Batch) -> Result<Filed> {
        let offset = batch.offset;
        let mut filed = Filed {
            buffers: Vec::new(),
            events: Vec::new(),
        };
        for record in batch.records {
            match record {
                Record::Chunk { header, data } => {
                    let reuse = self.recycled.as_ref().and_then(|r| r.try_recv().ok());
                    let content =
                        unpack_chunk(offset, &header, &data, self.limits, &mut self.dctx, reuse)?;
                    if let Cow::Owned(compressed) = data {
                        CHUNK_BUFFERS.give(compressed);
                    }
                    let buffer = filed.buffers.len();
                    let mut others = content.others.into_iter();
                    let mut pos = 0;
                    while let Some((opcode, start, end)) =
                        next_chunk_record(&content.data, pos, offset, self.limits)?
                    {
                        if opcode == op::MESSAGE {
                            let header = message_header(&content.data[start..end]);
                            let payload = (start + MESSAGE_HEADER_LEN, end);
                            self.message(
                                offset,
                                &header,
                                &content.data,
                                buffer,
                                payload,
                                &mut filed,
                            )?;
                        } else if let Some(r) = others.next() {
                            self.other(offset, r, &mut filed)?;
                        }
                        pos = end;
                    }
                    filed.buffers.push(content.data);
                }
                Record::Message { header, data } => {
                    let buffer = filed.buffers.len();
                    let data = data.into_owned();
                    self.message(offset, &header, &data, buffer, (0, data.len()), &mut filed)?;
                    filed.buffers.push(data);
                }
                other => self.other(offset, other, &mut filed)?,
            }
        }
        Ok(filed)
    }

    /// A message whose payload is `data[start..end]` (`data` to be `filed.buffers[buffer]`).
    fn message(
        &mut self,
        offset: u64,
        header: &MessageHeader,
        data: &[u8],
        buffer: usize,
        (start, end): (usize, usize),
        filed: &mut Filed,
    ) -> Result<()> {
        let topic = self.builder.channel_topic(offset, header.channel_id)?;
        self.builder.count_message((end - start) as u64)?;
        let index = self.counts[topic];
        self.counts[topic] += 1;
        if self.claimed[topic] {
            let t = &self.builder.topics[topic];
            return self
                .early
                .message(topic, t, index, header.log_time, &data[start..end]);
        }
        filed.events.push(Event::Message {
            topic,
            index,
            log_time_ns: header.log_time,
            buffer,
            start,
            end,
        });
        Ok(())
    }

    /// A record other than a message: filed, new topics and metadata announced to both.
    fn other(&mut self, offset: u64, record: Record<'static>, filed: &mut Filed) -> Result<()> {
        let is_metadata = matches!(record, Record::Metadata(_));
        self.builder.apply(offset, record)?;
        while self.counts.len() < self.builder.topics.len() {
            let index = self.counts.len();
            let t = &self.builder.topics[index];
            self.early.topic(t)?;
            self.claimed.push(self.early.claims(index));
            self.counts.push(0);
            filed.events.push(Event::Topic(Box::new(t.clone())));
        }
        if is_metadata {
            self.builder.metadata_added(offset, self.early)?;
            if let Some(m) = self.builder.session.metadata.last() {
                filed.events.push(Event::Metadata(m.clone()));
            }
        }
        Ok(())
    }
}

impl<E: RawVisitor> Drop for Filer<'_, E> {
    fn drop(&mut self) {
        if let Some(recycled) = &self.recycled {
            while let Ok(buffer) = recycled.try_recv() {
                CHUNK_BUFFERS.give(buffer);
            }
        }
    }
}

/// Chunks read and decompressed ahead of the one being filed by [`stream_raw`].
const STREAM_CHUNKS_AHEAD: usize = 2;

/// Decompressed chunk buffers [`stream_raw`]'s calling thread hands back for reuse, at most
/// (with those in flight, the buffers it holds stay a few chunks' worth).
const RECYCLED_BUFFERS: usize = 2;

/// Most topics a file may have (ours has nine).
const MAX_TOPICS: usize = 1024;

/// A chunk decompressed, checked and split into records: its content, and its records other
/// than messages, parsed, in order (messages, most of a chunk, are framed again from `data`
/// when the session is built: a list of them for every chunk at once would hold 48 bytes per
/// message on top of the data).
struct ChunkContent {
    data: Vec<u8>,
    others: Vec<Record<'static>>,
}

/// zstd's name for the error of an output buffer too small for the frame (stable across zstd
/// versions; were it to change, such a chunk would still be refused, as "zstd: <name>").
const ZSTD_DST_TOO_SMALL: &str = "Destination buffer is too small";

/// Length of a message record's header: channel id, sequence, log time, publish time.
const MESSAGE_HEADER_LEN: usize = 2 + 4 + 8 + 8;

/// Decompresses the chunk at `offset` into a buffer of its declared size (at most
/// [`ReadLimits::max_record_bytes`]; single-pass zstd decoding allocates nothing more, so no
/// window can be forced on us, and an lz4 frame is read to one byte past that size at most),
/// checks its CRC, and frames its records. Compressions: zstd, lz4, none.
fn unpack_chunk(
    offset: u64,
    header: &ChunkHeader,
    compressed: &[u8],
    limits: &ReadLimits,
    dctx: &mut Option<zstd::zstd_safe::DCtx<'static>>,
    reuse: Option<Vec<u8>>,
) -> Result<ChunkContent> {
    let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
    if header.uncompressed_size > limits.max_record_bytes {
        return Err(RecordingError::RecordTooLong {
            offset,
            opcode: op::CHUNK,
            len: header.uncompressed_size,
            limit: limits.max_record_bytes,
        });
    }
    let size = header.uncompressed_size as usize;
    // A header that declares less than the content holds: decompression stops at the declared
    // size (which the reader counted against its budget), never past it.
    let overflows = || {
        corrupt(format!(
            "chunk decompresses to more than the {size} bytes its header declares"
        ))
    };
    let data = match header.compression.as_str() {
        "" => {
            let mut out = reuse.unwrap_or_default();
            out.clear();
            out.extend_from_slice(compressed);
            out
        }
        "zstd" => {
            // Single-pass decoding into exactly the declared size: zstd fails rather than
            // write past it. The context is the caller's, reused from chunk to chunk (its
            // window limit is a sticky parameter; each frame starts afresh), and the buffer is
            // one handed back or pooled if one is big enough (its pages already mapped; the
            // size was checked against the limit above).
            let mut out = match reuse {
                Some(buffer) if buffer.capacity() >= size => buffer,
                Some(small) => {
                    CHUNK_BUFFERS.give(small);
                    CHUNK_BUFFERS.take(size)
                }
                None => CHUNK_BUFFERS.take(size),
            };
            let dctx = match dctx {
                Some(d) => d,
                None => {
                    let mut d = zstd::zstd_safe::DCtx::create();
                    d.set_parameter(zstd::zstd_safe::DParameter::WindowLogMax(MAX_WINDOW_LOG))
                        .map_err(|code| {
                            corrupt(format!("zstd: {}", zstd::zstd_safe::get_error_name(code)))
                        })?;
                    dctx.insert(d)
                }
            };
            let written = if out.capacity() == size {
                // Into its spare capacity, exactly the declared size: nothing to zero first.
                out.clear();
                dctx.decompress(&mut out, compressed)
            } else {
                // A bigger buffer: into its first `size` bytes (only what its previous content
                // lacks of them is zeroed).
                out.resize(size, 0);
                dctx.decompress(&mut out[..], compressed)
            }
            .map_err(|code| match zstd::zstd_safe::get_error_name(code) {
                ZSTD_DST_TOO_SMALL => overflows(),
                name => corrupt(format!("zstd: {name}")),
            })?;
            out.truncate(written);
            out
        }
        "lz4" => {
            // An LZ4 frame, read to at most one byte past the declared size: a chunk that
            // decodes to more is refused there, before it can grow without bound.
            let mut out = reuse.unwrap_or_default();
            out.clear();
            lz4::Decoder::new(compressed)
                .and_then(|d| d.take(size as u64 + 1).read_to_end(&mut out))
                .map_err(|e| corrupt(format!("lz4: {e}")))?;
            if out.len() > size {
                return Err(overflows());
            }
            out
        }
        other => {
            return Err(corrupt(format!(
                "unsupported compression {other:?} (supported: zstd, lz4, none)"
            )))
        }
    };
    if data.len() != size {
        return Err(corrupt(format!(
            "chunk content is {} bytes, its header says {size}",
            data.len()
        )));
    }
    if header.uncompressed_crc != 0 {
        let calculated = crc32fast::hash(&data);
        if calculated != header.uncompressed_crc {
            return Err(RecordingError::ChunkCrcMismatch {
                offset,
                saved: header.uncompressed_crc,
                calculated,
            });
        }
    }
    let mut others = Vec::new();
    let mut pos = 0usize;
    while let Some((opcode, start, end)) = next_chunk_record(&data, pos, offset, limits)? {
        let body = &data[start..end];
        if opcode == op::MESSAGE {
            if body.len() < MESSAGE_HEADER_LEN {
                return Err(corrupt("message record shorter than its header".into()));
            }
        } else {
            super::lengths::check(opcode, body).map_err(corrupt)?;
            match mcap::parse_record(opcode, body) {
                Ok(Record::Unknown { opcode, .. }) if !known_or_private(opcode) => {
                    return Err(corrupt(format!(
                        "reserved record opcode {opcode:#04x} in a chunk"
                    )));
                }
                Ok(Record::Chunk { .. }) => {
                    return Err(corrupt("a chunk inside a chunk".into()));
                }
                Ok(r) => others.push(r.into_owned()),
                Err(e) => return Err(map_mcap_error(e, offset, limits)),
            }
        }
        pos = end;
    }
    Ok(ChunkContent { data, others })
}

/// The record of chunk content `data` that starts at `pos`: its opcode and where its body lies
/// (`None` at the end). The errors name the chunk at `offset`.
fn next_chunk_record(
    data: &[u8],
    pos: usize,
    offset: u64,
    limits: &ReadLimits,
) -> Result<Option<(u8, usize, usize)>> {
    let Some(rest) = data.get(pos..).filter(|r| !r.is_empty()) else {
        return Ok(None);
    };
    let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
    if rest.len() < OPCODE_LEN_SIZE as usize {
        return Err(corrupt("chunk content ends inside a record header".into()));
    }
    let opcode = rest[0];
    let len = u64::from_le_bytes(rest[1..9].try_into().expect("8 bytes"));
    if len > limits.max_record_bytes {
        return Err(RecordingError::RecordTooLong {
            offset,
            opcode,
            len,
            limit: limits.max_record_bytes,
        });
    }
    let available = (rest.len() - OPCODE_LEN_SIZE as usize) as u64;
    if len > available {
        return Err(corrupt(format!(
            "record (opcode {opcode:#04x}) in a chunk claims {len} bytes but only {available} \
             remain"
        )));
    }
    let start = pos + OPCODE_LEN_SIZE as usize;
    Ok(Some((opcode, start, start + len as usize)))
}

/// The header of a message record whose body (at least [`MESSAGE_HEADER_LEN`] bytes) is
/// `body`.
fn message_header(body: &[u8]) -> MessageHeader {
    let u16_at = |i: usize| u16::from_le_bytes(body[i..i + 2].try_into().expect("2 bytes"));
    let u32_at = |i: usize| u32::from_le_bytes(body[i..i + 4].try_into().expect("4 bytes"));
    let u64_at = |i: usize| u64::from_le_bytes(body[i..i + 8].try_into().expect("8 bytes"));
    MessageHeader {
        channel_id: u16_at(0),
        sequence: u32_at(2),
        log_time: u64_at(6),
        publish_time: u64_at(14),
    }
}

struct SessionBuilder {
    /// Schemas, metadata and buffers (topics are in `topics` until the end).
    session: RawSession,
    /// Topics in order of first appearance.
    topics: Vec<RawTopic>,
    /// Topic name -> index in `topics`.
    topic_index: HashMap<String, usize>,
    schemas: HashMap<u16, SchemaInfo>,
    /// Channel id -> (topic name, index in `topics`).
    channels: HashMap<u16, (String, usize)>,
    /// The same lookup by the message's channel id, as an index (`u32::MAX`: none): hashing
    /// the id of every message cost more than filing it.
    channel_topics: Vec<u32>,
    total_bytes: u64,
    limits: ReadLimits,
    /// Length of the input, if known.
    input_len: Option<u64>,
    /// Bytes held against [`ReadLimits::decompressed_limit`]: the decompressed chunks, the
    /// payloads of messages outside chunks, and [`MessageRef`]s.
    held: u64,
    /// Payloads of messages outside chunks.
    loose: Vec<u8>,
    /// Index `loose` will have in the session's buffers.
    loose_buffer: u32,
}

impl SessionBuilder {
    fn new(limits: ReadLimits, input_len: Option<u64>, loose_buffer: u32) -> Self {
        SessionBuilder {
            session: RawSession::default(),
            topics: Vec::new(),
            topic_index: HashMap::new(),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            channel_topics: Vec::new(),
            total_bytes: 0,
            limits,
            input_len,
            held: 0,
            loose: Vec::new(),
            loose_buffer,
        }
    }

    /// The index in `topics` of the channel `channel_id` of a message at `offset`.
    fn channel_topic(&self, offset: u64, channel_id: u16) -> Result<usize> {
        self.channel_topics
            .get(usize::from(channel_id))
            .filter(|&&topic| topic != u32::MAX)
            .map(|&topic| topic as usize)
            .ok_or_else(|| RecordingError::Corrupt {
                offset,
                detail: format!("message refers to unknown channel id {channel_id}"),
            })
    }

    /// Counts a message's payload against [`ReadLimits::max_total_message_bytes`].
    fn count_message(&mut self, bytes: u64) -> Result<()> {
        self.total_bytes += bytes;
        if self.total_bytes > self.limits.max_total_message_bytes {
            return Err(RecordingError::TooMuchData {
                limit: self.limits.max_total_message_bytes,
            });
        }
        Ok(())
    }

    /// The metadata record just applied, handed to `visitor`; too many records are refused.
    fn metadata_added(&mut self, offset: u64, visitor: &mut impl RawVisitor) -> Result<()> {
        // Kept to the end of the read (and copied for the calling thread): counted against
        // the input's budget like the chunks of a whole-file read.
        let bytes = self.session.metadata.last().map_or(0, |m| {
            m.name.len()
                + m.entries
                    .iter()
                    .map(|(k, v)| k.len() + v.len())
                    .sum::<usize>()
        });
        self.hold(offset, 2 * bytes as u64)?;
        let records = &self.session.metadata;
        if records.len() > STREAM_MAX_METADATA_RECORDS {
            return Err(RecordingError::Corrupt {
                offset,
                detail: format!("more than {STREAM_MAX_METADATA_RECORDS} metadata records"),
            });
        }
        match records.last() {
            Some(record) => visitor.metadata(record),
            None => Ok(()),
        }
    }

    /// Counts `bytes` more against the budget of the input's length.
    fn hold(&mut self, offset: u64, bytes: u64) -> Result<()> {
        self.held = self.held.saturating_add(bytes);
        if self.held > self.limits.budget(self.input_len) {
            return Err(self.limits.over_limit(self.input_len, offset, self.held));
        }
        Ok(())
    }

    /// A message outside chunks: its payload copied into `loose` and filed.
    fn loose_message(&mut self, offset: u64, header: &MessageHeader, data: &[u8]) -> Result<()> {
        self.hold(offset, data.len() as u64)?;
        let start = self.loose.len();
        self.loose.extend_from_slice(data);
        let end = self.loose.len();
        self.message(offset, header, self.loose_buffer, start, end)
    }

    fn message(
        &mut self,
        offset: u64,
        header: &MessageHeader,
        buffer: u32,
        start: usize,
        end: usize,
    ) -> Result<()> {
        let topic = self.channel_topic(offset, header.channel_id)?;
        self.count_message((end - start) as u64)?;
        // A message's index entry is held too: for a file of tiny messages it outweighs them.
        self.hold(offset, std::mem::size_of::<MessageRef>() as u64)?;
        self.topics[topic].messages.push(MessageRef {
            log_time_ns: header.log_time,
            publish_time_ns: header.publish_time,
            sequence: header.sequence,
            buffer,
            start,
            end,
        });
        Ok(())
    }

    fn apply(&mut self, offset: u64, record: Record<'static>) -> Result<()> {
        let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
        match record {
            Record::Header(h) => {
                self.session.profile = h.profile;
                self.session.library = h.library;
            }
            Record::Schema { header, data } => {
                if header.id == 0 {
                    return Err(corrupt("schema with id 0".into()));
                }
                let info = SchemaInfo {
                    name: header.name,
                    encoding: header.encoding,
                    data: data.into_owned(),
                };
                if let Some(old) = self.schemas.get(&header.id) {
                    if *old != info {
                        return Err(corrupt(format!(
                            "schema id {} redefined with different content",
                            header.id
                        )));
                    }
                } else {
                    self.schemas.insert(header.id, info);
                }
            }
            Record::Channel(c) => {
                let schema = if c.schema_id == 0 {
                    None
                } else {
                    Some(self.schemas.get(&c.schema_id).cloned().ok_or_else(|| {
                        corrupt(format!(
                            "channel {:?} refers to unknown schema id {}",
                            c.topic, c.schema_id
                        ))
                    })?)
                };
                if let Some((old_topic, _)) = self.channels.get(&c.id) {
                    if *old_topic != c.topic {
                        return Err(corrupt(format!(
                            "channel id {} redefined with topic {:?}",
                            c.id, c.topic
                        )));
                    }
                }
                let index = match self.topic_index.get(&c.topic) {
                    Some(&index) => {
                        let t = &self.topics[index];
                        if t.schema != schema || t.message_encoding != c.message_encoding {
                            return Err(corrupt(format!(
                                "topic {:?} has two channels with different schemas or \
                                 encodings",
                                c.topic
                            )));
                        }
                        index
                    }
                    None => {
                        // Each topic holds its own copy of its schema: a file of many topics
                        // sharing one large schema would otherwise hold copies without bound.
                        if self.topics.len() >= MAX_TOPICS {
                            return Err(corrupt(format!(
                                "more than {MAX_TOPICS} topics (a session has about ten)"
                            )));
                        }
                        let copy = schema.as_ref().map_or(0, |s| s.data.len()) + c.topic.len();
                        self.hold(offset, 2 * copy as u64)?;
                        self.topics.push(RawTopic {
                            topic: c.topic.clone(),
                            message_encoding: c.message_encoding.clone(),
                            schema,
                            messages: Vec::new(),
                        });
                        self.topic_index
                            .insert(c.topic.clone(), self.topics.len() - 1);
                        self.topics.len() - 1
                    }
                };
                let id = usize::from(c.id);
                if self.channel_topics.len() <= id {
                    self.channel_topics.resize(id + 1, u32::MAX);
                }
                // At most MAX_TOPICS topics.
                self.channel_topics[id] = index as u32;
                self.channels.insert(c.id, (c.topic, index));
            }
            Record::Message { header, data } => self.loose_message(offset, &header, &data)?,
            Record::Metadata(m) => self.session.metadata.push(MetadataRecord {
                name: m.name,
                entries: m.metadata,
            }),
            _ => {}
        }
        Ok(())
    }
}

/// The records that came out of one top-level record (one, or a chunk's content).
pub(crate) struct Batch {
    /// Byte offset of the top-level record.
    pub offset: u64,
    /// Whether the top-level record was a chunk.
    pub is_chunk: bool,
    /// The records, owned.
    pub records: Vec<Record<'static>>,
}

/// How a scan ended.
pub(crate) struct ScanOutcome {
    /// Footer and end magic were read.
    pub complete: bool,
    /// Offset just past the last top-level record whose batch was accepted.
    pub committed_offset: u64,
    /// Why the scan stopped early (bad record, truncation, or an error from the callback).
    pub error: Option<RecordingError>,
}

impl ScanOutcome {
    /// `Ok` for a scan that read the whole file to its footer; its error, or
    /// [`RecordingError::Truncated`] for a file that ends without one.
    fn into_result(self) -> Result<()> {
        if let Some(err) = self.error {
            return Err(err);
        }
        if !self.complete {
            return Err(RecordingError::Truncated {
                offset: self.committed_offset,
                detail: "no footer".into(),
            });
        }
        Ok(())
    }
}

const OPCODE_LEN_SIZE: u64 = 9;

/// Where a chunk record's `uncompressed_size` lies: after the opcode, the length and the
/// start and end times.
const CHUNK_SIZE_AT: usize = OPCODE_LEN_SIZE as usize + 16;

/// Reads `src` record by record, calling `on_batch` with the records of each complete
/// top-level record. With `emit_chunks`, a chunk is handed over whole and still compressed (its
/// bytes are covered by the data section CRC; the caller decompresses it and checks its own
/// CRC); otherwise its records are, after its CRC matched. Stops at the first bad record or callback error and reports it in the
/// outcome; only a bad magic (or an I/O error on the first bytes) is returned as `Err`.
pub(crate) fn scan<R: Read>(
    mut src: R,
    total_len: Option<u64>,
    limits: &ReadLimits,
    emit_chunks: bool,
    mut on_batch: impl FnMut(Batch) -> Result<()>,
) -> Result<ScanOutcome> {
    let mut magic = [0u8; 8];
    let got = read_up_to(&mut src, &mut magic)
        .map_err(|e| RecordingError::io("reading the MCAP magic", e))?;
    if got < magic.len() || magic != *mcap::MAGIC {
        return Err(RecordingError::NotMcap);
    }
    let record_limit = usize::try_from(limits.max_record_bytes).unwrap_or(usize::MAX);
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_prevalidate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(record_limit)
            .with_emit_chunks(emit_chunks),
    );
    // Replaces the built-in zstd decoder: same decoding, window capped at 16 MiB.
    reader.add_decompressor(BoundedZstd::default())?;
    // The data section CRC covers the magic too.
    reader.insert(magic.len()).copy_from_slice(&magic);
    reader.notify_read(magic.len());
    let mut offset = 8u64;
    let mut outcome = ScanOutcome {
        complete: false,
        committed_offset: offset,
        error: None,
    };
    // Decompressed bytes the chunks so far declare, against what the input's length allows.
    let budget = limits.budget(total_len);
    let mut declared = 0u64;
    // The record being read, in a buffer reused from one read to the next.
    let mut record = PooledBuffer(CHUNK_BUFFERS.take(0));
    let record = &mut record.0;
    loop {
        // Frame the next top-level record.
        let mut head = [0u8; OPCODE_LEN_SIZE as usize];
        let got = match read_up_to(&mut src, &mut head) {
            Ok(n) => n,
            Err(e) => {
                outcome.error = Some(RecordingError::io(format!("reading at byte {offset}"), e));
                return Ok(outcome);
            }
        };
        if got == 0 {
            // Clean end of input between records, but no footer: truncated.
            outcome.error = Some(RecordingError::Truncated {
                offset,
                detail: "file ends without a footer (the writer did not finish)".into(),
            });
            return Ok(outcome);
        }
        if got < head.len() {
            outcome.error = Some(RecordingError::Truncated {
                offset,
                detail: "file ends inside a record header".into(),
            });
            return Ok(outcome);
        }
        let opcode = head[0];
        let len = u64::from_le_bytes(head[1..].try_into().expect("8 bytes"));
        if !known_or_private(opcode) {
            outcome.error = Some(RecordingError::Corrupt {
                offset,
                detail: format!("reserved record opcode {opcode:#04x}"),
            });
            return Ok(outcome);
        }
        let remaining = total_len.map(|t| t.saturating_sub(offset + OPCODE_LEN_SIZE));
        if let Some(remaining) = remaining {
            if len > remaining {
                outcome.error = Some(RecordingError::Truncated {
                    offset,
                    detail: format!(
                        "record (opcode {opcode:#04x}) claims {len} bytes but only {remaining} remain"
                    ),
                });
                return Ok(outcome);
            }
        }
        if len > limits.max_record_bytes {
            outcome.error = Some(RecordingError::RecordTooLong {
                offset,
                opcode,
                len,
                limit: limits.max_record_bytes,
            });
            return Ok(outcome);
        }
        record.clear();
        if total_len.is_some() {
            // Its length is within what the input holds (checked above) and the record
            // limit: room for it at once, not grown by doubling.
            record.reserve(head.len() + len as usize);
        }
        record.extend_from_slice(&head);
        // `take` + `read_to_end` grows the buffer with the data actually present, so a bogus
        // length on a stream of unknown size cannot force a large allocation.
        if let Err(e) = (&mut src).take(len).read_to_end(record) {
            outcome.error = Some(RecordingError::io(format!("reading at byte {offset}"), e));
            return Ok(outcome);
        }
        if (record.len() as u64) < OPCODE_LEN_SIZE + len {
            outcome.error = Some(RecordingError::Truncated {
                offset,
                detail: format!("file ends inside a record (opcode {opcode:#04x})"),
            });
            return Ok(outcome);
        }

        // A chunk counts against the decompression budget with the size its header declares,
        // before anything decompresses it; none decompresses past that size.
        if opcode == op::CHUNK {
            if let Some(size) = record.get(CHUNK_SIZE_AT..CHUNK_SIZE_AT + 8) {
                let size = u64::from_le_bytes(size.try_into().expect("8 bytes"));
                declared = declared.saturating_add(size);
                if declared > budget {
                    outcome.error = Some(limits.over_limit(total_len, offset, declared));
                    return Ok(outcome);
                }
            }
        }

        // Its length-prefixed fields must fit in it: the parser allocates what they declare.
        if let Err(detail) = super::lengths::check(opcode, &record[OPCODE_LEN_SIZE as usize..]) {
            outcome.error = Some(RecordingError::Corrupt { offset, detail });
            return Ok(outcome);
        }

        // Hand the whole record to the sans-I/O reader and drain what it yields.
        reader.insert(record.len()).copy_from_slice(record);
        reader.notify_read(record.len());
        let mut batch = Batch {
            offset,
            is_chunk: opcode == op::CHUNK,
            records: Vec::new(),
        };
        let mut is_footer = false;
        let mut failure = None;
        while let Some(event) = reader.next_event() {
            match event {
                Ok(LinearReadEvent::ReadRequest(_)) => break,
                Ok(LinearReadEvent::Record { data, opcode }) => {
                    // A record from inside a chunk: its fields too must fit in it.
                    if let Err(detail) = super::lengths::check(opcode, data) {
                        failure = Some(RecordingError::Corrupt { offset, detail });
                        break;
                    }
                    match mcap::parse_record(opcode, data) {
                        Ok(Record::Unknown { opcode, .. }) if !known_or_private(opcode) => {
                            failure = Some(RecordingError::Corrupt {
                                offset,
                                detail: format!("reserved record opcode {opcode:#04x} in a chunk"),
                            });
                            break;
                        }
                        Ok(Record::Chunk { header, data }) => {
                            // Its compressed bytes into a pooled buffer (the reader of the
                            // batch gives it back).
                            let mut owned = CHUNK_BUFFERS.take(data.len());
                            owned.clear();
                            owned.extend_from_slice(&data);
                            batch.records.push(Record::Chunk {
                                header,
                                data: Cow::Owned(owned),
                            });
                        }
                        Ok(r) => {
                            is_footer |= matches!(r, Record::Footer(_));
                            batch.records.push(r.into_owned());
                        }
                        Err(e) => {
                            failure = Some(map_mcap_error(e, offset, limits));
                            break;
                        }
                    }
                }
                Err(e) => {
                    failure = Some(map_mcap_error(e, offset, limits));
                    break;
                }
            }
        }
        if let Some(err) = failure {
            outcome.error = Some(err);
            return Ok(outcome);
        }
        if let Err(err) = on_batch(batch) {
            outcome.error = Some(err);
            return Ok(outcome);
        }
        offset += OPCODE_LEN_SIZE + len;
        outcome.committed_offset = offset;
        if is_footer {
            let mut end = [0u8; 8];
            let got = read_up_to(&mut src, &mut end).unwrap_or(0);
            if got == end.len() && end == *mcap::MAGIC {
                outcome.complete = true;
            } else {
                outcome.error = Some(RecordingError::Truncated {
                    offset,
                    detail: "footer is not followed by the MCAP magic".into(),
                });
            }
            return Ok(outcome);
        }
    }
}

/// A buffer given back to [`CHUNK_BUFFERS`] when dropped.
struct PooledBuffer(Vec<u8>);

impl Drop for PooledBuffer {
    fn drop(&mut self) {
        CHUNK_BUFFERS.give(std::mem::take(&mut self.0));
    }
}

/// Opcodes defined by the MCAP spec (0x01..=0x0f) or private (>= 0x80). Anything else is
/// reserved: in a file we read, it means a damaged opcode byte, and skipping the record (as the
/// spec allows for unknown records) would silently drop a whole chunk.
fn known_or_private(opcode: u8) -> bool {
    (0x01..=0x0f).contains(&opcode) || opcode >= 0x80
}

fn map_mcap_error(e: McapError, offset: u64, limits: &ReadLimits) -> RecordingError {
    match e {
        McapError::BadChunkCrc { saved, calculated } => RecordingError::ChunkCrcMismatch {
            offset,
            saved,
            calculated,
        },
        McapError::RecordTooLarge { opcode, len } => RecordingError::RecordTooLong {
            offset,
            opcode,
            len,
            limit: limits.max_record_bytes,
        },
        McapError::ChunkTooLarge(len) => RecordingError::RecordTooLong {
            offset,
            opcode: op::CHUNK,
            len,
            limit: limits.max_record_bytes,
        },
        McapError::BadDataCrc { saved, calculated } => RecordingError::Corrupt {
            offset,
            detail: format!(
                "data section CRC mismatch (stored {saved:08x}, computed {calculated:08x})"
            ),
        },
        McapError::BadSummaryCrc { saved, calculated } => RecordingError::Corrupt {
            offset,
            detail: format!(
                "summary section CRC mismatch (stored {saved:08x}, computed {calculated:08x})"
            ),
        },
        McapError::UnexpectedEof => RecordingError::Truncated {
            offset,
            detail: "record ends early".into(),
        },
        other => RecordingError::Corrupt {
            offset,
            detail: other.to_string(),
        },
    }
}

/// Reads until `buf` is full or the input ends; returns the bytes read.
fn read_up_to<R: Read>(src: &mut R, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match src.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}
