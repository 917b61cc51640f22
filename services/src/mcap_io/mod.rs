//! MCAP session files: writing ([`SessionWriter`]), reading untrusted files
//! ([`read_session_file`], [`read_session_bytes`]) and recovering files whose writer died
//! ([`salvage`]).
//!
//! Layout of the files we write: one channel per topic, protobuf messages with a `protobuf`
//! schema (session format 2; [`SessionWriter::register_protobuf_channel`]) or JSON messages
//! with a `jsonschema` schema (format 1, still read and still writable for tests and tools),
//! zstd chunks of about 1 MiB closed at least every second of log time, chunk indexes (message
//! indexes unless [`WriterOptions::message_indexes`] is off, as the recorder has it), a
//! summary, metadata records for session parameters. No NaN or infinity is ever written.
//!
//! The session-specific message types live elsewhere; this module takes serialised messages,
//! or `serde::Serialize` ones for JSON channels.

mod bounded_zstd;
mod chunked;
mod finite;
mod json_check;
mod lengths;
mod par;
pub(crate) mod pool;
mod reader;
mod salvage;
pub mod schemas;
mod writer;

pub(crate) use reader::{
    check_message, json_error, message_location, stream_raw_bytes, stream_raw_file, RawTopic,
    RawVisitor, StreamedRaw,
};
pub use reader::{
    read_session_bytes, read_session_bytes_decoding, read_session_file, read_session_file_decoding,
    MetadataRecord, ReadLimits, RecordedMessage, RecordedSession, SchemaInfo, TopicRecording,
    DEFAULT_MAX_EXPANSION, STREAMING_MAX_TOTAL_MESSAGE_BYTES,
};
pub use salvage::{salvage, SalvageReport};
pub use schemas::JsonSchema;
pub use writer::{
    SessionWriter, TopicHandle, WriteSummary, WriterOptions, MESSAGE_ENCODING, SCHEMA_ENCODING,
};

#[cfg(test)]
mod tests {
    /// The recorder runs the writer on its own thread and hands sessions between threads.
    #[test]
    fn writer_and_session_types_can_move_between_threads() {
        fn assert_send<T: Send>() {}
        fn assert_send_sync<T: Send + Sync>() {}
        assert_send::<super::SessionWriter>();
        assert_send_sync::<super::RecordedSession>();
        assert_send_sync::<crate::RecordingError>();
    }
}
