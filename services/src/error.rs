//! The error type of the services crate.
//!
//! One enum for the crate ([`RecordingError`]) for now: every variant says what was wrong with
//! the file or the call, with enough context (topic, byte offset, field path) to act on it.

use std::path::PathBuf;

/// Everything that can go wrong when writing, reading or salvaging an MCAP session.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordingError {
    /// An operating-system I/O error, with what we were doing.
    #[error("I/O error while {context}: {source}")]
    Io {
        /// What was being done, e.g. `creating /tmp/x.mcap`.
        context: String,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },

    /// The input does not start with the MCAP magic bytes.
    #[error("not an MCAP file: the first 8 bytes are not the MCAP magic")]
    NotMcap,

    /// The input ends before the footer, or in the middle of a record.
    #[error("truncated MCAP file at byte {offset}: {detail}")]
    Truncated {
        /// Byte offset of the first record that is missing or incomplete.
        offset: u64,
        /// What was expected there.
        detail: String,
    },

    /// A chunk's stored CRC does not match its (decompressed) content.
    #[error("chunk at byte {offset} is corrupt: CRC mismatch (stored {saved:08x}, computed {calculated:08x})")]
    ChunkCrcMismatch {
        /// Byte offset of the chunk record.
        offset: u64,
        /// CRC stored in the chunk header.
        saved: u32,
        /// CRC of the data actually read.
        calculated: u32,
    },

    /// A record (or a chunk's decompressed content) is longer than the configured limit.
    #[error("record at byte {offset} (opcode {opcode:#04x}) claims {len} bytes, over the limit of {limit}")]
    RecordTooLong {
        /// Byte offset of the record (of the enclosing chunk for records inside a chunk).
        offset: u64,
        /// Record opcode.
        opcode: u8,
        /// Claimed length in bytes.
        len: u64,
        /// The limit in force ([`crate::mcap_io::ReadLimits::max_record_bytes`]).
        limit: u64,
    },

    /// A record could not be parsed, decompressed or linked (bad schema or channel reference…).
    #[error("corrupt MCAP record at byte {offset}: {detail}")]
    Corrupt {
        /// Byte offset of the record (of the enclosing chunk for records inside a chunk).
        offset: u64,
        /// What was wrong.
        detail: String,
    },

    /// The whole file decompresses to more bytes than any file may.
    #[error(
        "MCAP file decompresses to more than {limit} bytes, the most one file may hold (its \
         chunks and messages are held in memory while it is read)"
    )]
    TooMuchData {
        /// The limit in force ([`crate::mcap_io::ReadLimits::max_total_message_bytes`]).
        limit: u64,
    },

    /// The file decompresses to more than [`crate::mcap_io::ReadLimits::max_expansion`] times
    /// its size (plus a small allowance): a decompression bomb, or a chunk header that lies
    /// about its size. Refused before the chunk that crosses the limit is decompressed (the
    /// index of the messages, 40 bytes each, counts too: a file of tiny messages is refused
    /// when it is built).
    #[error(
        "MCAP file decompresses to more than {ratio}x its size ({input_len} bytes may take at \
         most {limit} bytes decompressed and indexed; up to the record at byte {offset} it \
         takes {total})"
    )]
    DecompressesTooMuch {
        /// Byte offset of the record (a chunk, usually) that crosses the limit.
        offset: u64,
        /// Length of the file, bytes.
        input_len: u64,
        /// Bytes taken up to that record: the chunks' declared sizes, messages outside chunks
        /// and the index of the messages.
        total: u64,
        /// The expansion ratio in force ([`crate::mcap_io::ReadLimits::max_expansion`]).
        ratio: u64,
        /// The decompressed bytes allowed for this file
        /// ([`crate::mcap_io::ReadLimits::decompressed_limit`]).
        limit: u64,
    },

    /// A topic the caller requires is absent from the session.
    #[error("topic {topic:?} is missing from the session")]
    MissingTopic {
        /// The topic that was required.
        topic: String,
    },

    /// A topic is present but its schema is not the one expected.
    #[error(
        "topic {topic:?} has {}, expected schema {expected:?}",
        .found.as_ref().map_or("no schema".to_owned(), |f| format!("schema {f:?}"))
    )]
    UnknownSchema {
        /// The topic.
        topic: String,
        /// The schema name that was expected.
        expected: String,
        /// The schema name found (`None`: the channel has no schema).
        found: Option<String>,
    },

    /// A topic's messages are not JSON encoded (or its schema is not a JSON Schema).
    #[error("topic {topic:?} uses encoding {encoding:?}, expected {expected:?}")]
    NonJsonEncoding {
        /// The topic.
        topic: String,
        /// The encoding found.
        encoding: String,
        /// What was expected (`json` for messages, `jsonschema` for schemas).
        expected: &'static str,
    },

    /// A message on a JSON topic is not valid JSON, or does not decode into the requested type.
    #[error(
        "message {index} on topic {topic:?} (log time {log_time_ns} ns) is not valid JSON for \
         its type{}: {source}",
        if .path.is_empty() { String::new() } else { format!(" at {}", .path) }
    )]
    InvalidJson {
        /// The topic.
        topic: String,
        /// Number of the message in its topic, from 0, in file order.
        index: usize,
        /// Log time of the message.
        log_time_ns: u64,
        /// Path of the field at fault, e.g. `positions[3]` (empty when the text is not JSON at
        /// all, or the fault is the message as a whole).
        path: String,
        /// The parse or decode error.
        #[source]
        source: serde_json::Error,
    },

    /// A message to be written holds NaN or an infinity (JSON cannot represent them).
    #[error("message on topic {topic:?} has a non-finite number ({value}) at {path}")]
    NonFiniteNumber {
        /// The topic.
        topic: String,
        /// Path of the field, e.g. `transforms[2].translation.x`.
        path: String,
        /// The offending value, printed (`NaN`, `inf`, `-inf`).
        value: String,
    },

    /// A message to be written could not be serialised.
    #[error("message on topic {topic:?} could not be serialised: {detail}")]
    Serialize {
        /// The topic.
        topic: String,
        /// The serialiser's message.
        detail: String,
    },

    /// A message was written to a topic that was never registered.
    #[error("topic {topic:?} was not registered with register_channel")]
    UnregisteredTopic {
        /// The topic.
        topic: String,
    },

    /// A topic was registered twice with different schemas.
    #[error("topic {topic:?} is already registered with schema {existing:?}")]
    TopicConflict {
        /// The topic.
        topic: String,
        /// The schema it was first registered with.
        existing: String,
    },

    /// The writer was used after it failed or finished.
    #[error("the MCAP writer for {path} was used after it failed or finished")]
    WriterClosed {
        /// The file being written.
        path: PathBuf,
    },

    /// The simulation or the DFS failed at a tick; the session file holds every tick before it.
    #[error("simulation failed at t = {:.3} s: {source}", *time_ns as f64 * 1e-9)]
    Simulation {
        /// Time of the failing tick, ns since the session start.
        time_ns: u64,
        /// The DFS error.
        #[source]
        source: dfs_core::DfsError,
    },

    /// An input to be imported or replayed is malformed; `location` names the line, message
    /// or field.
    #[error("{location}: {detail}")]
    InvalidInput {
        /// Where: e.g. `glove.csv line 7, column tau_index_mcp`.
        location: String,
        /// What is wrong.
        detail: String,
    },

    /// The file is a replay recording (`icms replay --out`, a stored replay's MCAP), not a grasp
    /// session: a robot hand driven along a skill, with no object description and no skill of
    /// its own to find. Refused by segmentation and ingest.
    #[error(
        "{name} is a replay recording{what} (written by `icms replay --out` or a stored \
         replay), not a grasp session: it holds no skills of its own; segment or ingest the \
         grasp session the skill came from"
    )]
    ReplayRecording {
        /// The file (or upload) name.
        name: String,
        /// What was replayed, e.g. ` of skill 3 on the hand allegro` (may be empty).
        what: String,
    },

    /// The writer thread died (panicked) without reporting an error.
    #[error("the session writer thread panicked")]
    WriterThreadPanicked,

    /// An error reported by the `mcap` crate while writing.
    #[error("MCAP write error: {0}")]
    Mcap(#[from] mcap::McapError),
}

impl RecordingError {
    /// An [`RecordingError::Io`] with context.
    pub(crate) fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io {
            context: context.into(),
            source,
        }
    }
}

/// Result alias for this crate.
pub type Result<T, E = RecordingError> = std::result::Result<T, E>;
