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
//!
//! Layout: this module holds the limits, the public types and the whole-file readers;
//! [`scan`] frames top-level records, `chunk` unpacks one chunk, `session` indexes a session
//! read whole, and `stream` hands a session's records to a visitor chunk by chunk.

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

use super::bounded_zstd::{bounded_dctx, BoundedZstd};
use super::json_check;
use super::par::{par_map, MESSAGES_PER_JOB};
use super::pool::CHUNK_BUFFERS;
use super::writer::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use crate::error::{RecordingError, Result};

mod chunk;
mod scan;
mod session;
mod stream;

use chunk::*;
use scan::*;
pub(crate) use scan::{scan, Batch};
pub(crate) use session::*;
pub(crate) use stream::*;

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

    /// Refuses a record (or a chunk's decompressed content) of opcode `opcode` at `offset`
    /// that claims `len` bytes, more than [`Self::max_record_bytes`].
    pub(super) fn check_record_len(&self, offset: u64, opcode: u8, len: u64) -> Result<()> {
        if len > self.max_record_bytes {
            return Err(RecordingError::RecordTooLong {
                offset,
                opcode,
                len,
                limit: self.max_record_bytes,
            });
        }
        Ok(())
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
