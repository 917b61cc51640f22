//! Reading untrusted MCAP files: [`read_session_bytes`], [`read_session_file`] and the record
//! scanner that [`crate::mcap_io::salvage`] shares.
//!
//! The scanner frames top-level records itself (so it knows every record's byte offset and never
//! allocates more than [`ReadLimits::max_record_bytes`], nor more than the bytes actually left in
//! the input) and hands each complete record to the `mcap` crate's sans-I/O linear reader with
//! chunk CRC prevalidation and a record length limit: a chunk's records are released only after
//! the whole chunk decompressed and matched its CRC. The data section and summary CRCs are
//! checked too, the zstd window is capped at 16 MiB, and reserved opcodes are refused (the spec's "skip unknown records" would turn a
//! damaged chunk opcode into a silently missing chunk).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::McapError;
use serde::de::DeserializeOwned;

use super::bounded_zstd::BoundedZstd;
use super::writer::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use crate::error::{RecordingError, Result};

/// Bounds on what a reader accepts from an untrusted file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    /// Longest record accepted, in bytes, and the largest decompressed chunk. Default 64 MiB
    /// (our writer's chunks are about 1 MiB).
    pub max_record_bytes: u64,
    /// Most message payload bytes accepted in one file (all topics, decompressed).
    /// Default 4 GiB.
    pub max_total_message_bytes: u64,
}

impl Default for ReadLimits {
    fn default() -> Self {
        Self {
            max_record_bytes: 64 * 1024 * 1024,
            max_total_message_bytes: 4 * 1024 * 1024 * 1024,
        }
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
    /// Message payload (JSON text on `json` topics, checked at read time).
    pub data: Vec<u8>,
}

/// All messages of one topic, in file order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicRecording {
    /// Topic name.
    pub topic: String,
    /// Message encoding of the topic's channel (`json` for ours).
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
        for m in &self.messages {
            serde_json::from_slice::<serde::de::IgnoredAny>(&m.data).map_err(|source| {
                RecordingError::InvalidJson {
                    topic: self.topic.clone(),
                    log_time_ns: m.log_time_ns,
                    source,
                }
            })?;
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
            .map(|m| {
                serde_json::from_slice(&m.data)
                    .map(|v| (m.log_time_ns, v))
                    .map_err(|source| RecordingError::InvalidJson {
                        topic: self.topic.clone(),
                        log_time_ns: m.log_time_ns,
                        source,
                    })
            })
            .collect()
    }

    fn check_json_encoding(&self) -> Result<()> {
        if self.message_encoding != MESSAGE_ENCODING {
            return Err(RecordingError::NonJsonEncoding {
                topic: self.topic.clone(),
                encoding: self.message_encoding.clone(),
                expected: MESSAGE_ENCODING,
            });
        }
        Ok(())
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
    /// The topic, which must exist, carry JSON messages, and have a `jsonschema` schema named
    /// `schema_name`.
    pub fn require_topic(&self, topic: &str, schema_name: &str) -> Result<&TopicRecording> {
        let t = self
            .topics
            .get(topic)
            .ok_or_else(|| RecordingError::MissingTopic {
                topic: topic.to_owned(),
            })?;
        t.check_json_encoding()?;
        match &t.schema {
            Some(s) if s.name == schema_name => {
                if s.encoding != SCHEMA_ENCODING {
                    return Err(RecordingError::NonJsonEncoding {
                        topic: topic.to_owned(),
                        encoding: s.encoding.clone(),
                        expected: SCHEMA_ENCODING,
                    });
                }
                Ok(t)
            }
            other => Err(RecordingError::UnknownSchema {
                topic: topic.to_owned(),
                expected: schema_name.to_owned(),
                found: other.as_ref().map(|s| s.name.clone()),
            }),
        }
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
    let file = File::open(path)
        .map_err(|e| RecordingError::io(format!("opening {}", path.display()), e))?;
    let len = file
        .metadata()
        .map_err(|e| RecordingError::io(format!("reading {}", path.display()), e))?
        .len();
    read_session_from(
        BufReader::with_capacity(1 << 16, file),
        Some(len),
        limits,
        decoded_topics,
    )
}

fn read_session_from<R: Read>(
    src: R,
    total_len: Option<u64>,
    limits: &ReadLimits,
    decoded_topics: &[&str],
) -> Result<RecordedSession> {
    let mut builder = SessionBuilder {
        session: RecordedSession::default(),
        schemas: HashMap::new(),
        channels: HashMap::new(),
        total_bytes: 0,
        limits: *limits,
        decoded_topics,
    };
    let outcome = scan(src, total_len, limits, |batch| builder.apply(batch))?;
    if let Some(err) = outcome.error {
        return Err(err);
    }
    if !outcome.complete {
        return Err(RecordingError::Truncated {
            offset: outcome.committed_offset,
            detail: "no footer".into(),
        });
    }
    Ok(builder.session)
}

struct SessionBuilder<'a> {
    session: RecordedSession,
    schemas: HashMap<u16, SchemaInfo>,
    channels: HashMap<u16, String>,
    total_bytes: u64,
    limits: ReadLimits,
    /// Topics whose JSON the caller validates by decoding them.
    decoded_topics: &'a [&'a str],
}

impl SessionBuilder<'_> {
    fn apply(&mut self, batch: Batch) -> Result<()> {
        let offset = batch.offset;
        let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
        for record in batch.records {
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
                    if let Some(old_topic) = self.channels.get(&c.id) {
                        if *old_topic != c.topic {
                            return Err(corrupt(format!(
                                "channel id {} redefined with topic {:?}",
                                c.id, c.topic
                            )));
                        }
                    }
                    match self.session.topics.get(&c.topic) {
                        Some(t) => {
                            if t.schema != schema || t.message_encoding != c.message_encoding {
                                return Err(corrupt(format!(
                                    "topic {:?} has two channels with different schemas or \
                                     encodings",
                                    c.topic
                                )));
                            }
                        }
                        None => {
                            self.session.topics.insert(
                                c.topic.clone(),
                                TopicRecording {
                                    topic: c.topic.clone(),
                                    message_encoding: c.message_encoding.clone(),
                                    schema,
                                    messages: Vec::new(),
                                },
                            );
                        }
                    }
                    self.channels.insert(c.id, c.topic);
                }
                Record::Message { header, data } => {
                    let topic = self.channels.get(&header.channel_id).ok_or_else(|| {
                        corrupt(format!(
                            "message refers to unknown channel id {}",
                            header.channel_id
                        ))
                    })?;
                    self.total_bytes += data.len() as u64;
                    if self.total_bytes > self.limits.max_total_message_bytes {
                        return Err(RecordingError::TooMuchData {
                            limit: self.limits.max_total_message_bytes,
                        });
                    }
                    let t = self
                        .session
                        .topics
                        .get_mut(topic)
                        .expect("every channel has a topic entry");
                    if t.message_encoding == MESSAGE_ENCODING
                        && !self.decoded_topics.contains(&topic.as_str())
                    {
                        if let Err(source) = serde_json::from_slice::<serde::de::IgnoredAny>(&data)
                        {
                            return Err(RecordingError::InvalidJson {
                                topic: topic.clone(),
                                log_time_ns: header.log_time,
                                source,
                            });
                        }
                    }
                    t.messages.push(RecordedMessage {
                        log_time_ns: header.log_time,
                        publish_time_ns: header.publish_time,
                        sequence: header.sequence,
                        data: data.into_owned(),
                    });
                }
                Record::Metadata(m) => self.session.metadata.push(MetadataRecord {
                    name: m.name,
                    entries: m.metadata,
                }),
                _ => {}
            }
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

const OPCODE_LEN_SIZE: u64 = 9;

/// Reads `src` record by record, calling `on_batch` with the records of each complete
/// top-level record. Stops at the first bad record or callback error and reports it in the
/// outcome; only a bad magic (or an I/O error on the first bytes) is returned as `Err`.
pub(crate) fn scan<R: Read>(
    mut src: R,
    total_len: Option<u64>,
    limits: &ReadLimits,
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
            .with_record_length_limit(record_limit),
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
    let mut record = Vec::new();
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
        record.extend_from_slice(&head);
        // `take` + `read_to_end` grows the buffer with the data actually present, so a bogus
        // length on a stream of unknown size cannot force a large allocation.
        if let Err(e) = (&mut src).take(len).read_to_end(&mut record) {
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

        // Hand the whole record to the sans-I/O reader and drain what it yields.
        reader.insert(record.len()).copy_from_slice(&record);
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
                    match mcap::parse_record(opcode, data) {
                        Ok(Record::Unknown { opcode, .. }) if !known_or_private(opcode) => {
                            failure = Some(RecordingError::Corrupt {
                                offset,
                                detail: format!("reserved record opcode {opcode:#04x} in a chunk"),
                            });
                            break;
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
