//! Reading a session back: [`stream_session_file`] and [`stream_session_bytes`] check a session
//! file in one pass and hand its raw samples to a [`SessionVisitor`] as they come, holding a
//! chunk at a time whatever the file's length; [`read_session`] and its variants collect them
//! into a [`Session`].
//!
//! The parts: what a read returns ([`Session`], [`SessionHead`]: `session.rs`), what a reader
//! asks for ([`DecodeTopics`], [`SessionVisitor`]: `visitor.rs`), where it reads from and the
//! second reads ([`SessionSource`]: `source.rs`) with the messages kept for them
//! ([`KeptMessages`]: `kept.rs`); the checks, message by message (`checker.rs`), by topic
//! (`topics.rs`), of the metadata (`metadata.rs`) and of the whole file (`finish.rs`).

use std::path::Path;

use crate::error::Result;
use crate::mcap_io::ReadLimits;

mod checker;
mod finish;
mod kept;
mod metadata;
mod session;
mod source;
mod topics;
mod visitor;

pub use kept::{KeptMessages, KEPT_MESSAGES_BUDGET};
pub use session::{Session, SessionHead};
pub use source::SessionSource;
pub use visitor::{DecodeTopics, SessionVisitor};

use session::Collect;
use source::stream_source;

/// Largest raw message (bytes), in either format: ours are under 2 kB (a tick of a 30-DOF
/// hand), and the most a session may hold ([`MAX_SESSION_DOFS`] names and values,
/// [`MAX_SESSION_FINGERS`] fingertips) is far under this. Bigger messages are refused before
/// they are decoded: decoding may take a hundred times their size (an empty nested protobuf
/// message, or an empty JSON string, is 2 bytes of input and a struct or `String` in memory).
///
/// [`MAX_SESSION_DOFS`]: super::MAX_SESSION_DOFS
/// [`MAX_SESSION_FINGERS`]: super::MAX_SESSION_FINGERS
pub const MAX_RAW_MESSAGE_BYTES: usize = 256 * 1024;

/// Largest protobuf schema of a raw topic (bytes): ours is a few kB. A bigger one is refused
/// before it is decoded to be compared with ours (an empty file descriptor is 2 bytes of
/// input and hundreds in memory).
pub const MAX_RAW_SCHEMA_BYTES: usize = 64 * 1024;

/// Largest Foxglove message of format 2 that is decoded to be checked (bytes); bigger ones
/// (another tool's meshes in `/scene`, say) are for viewers and left unchecked rather than
/// decoded at a hundred times their size.
pub const MAX_CHECKED_FOXGLOVE_MESSAGE_BYTES: usize = 256 * 1024;

/// How far apart the raw topics' first (and last) log times may lie (ns): they are written
/// together, tick by tick, so a session's topics start and end within a tick of each other;
/// a file in which one stops early (a writer that lost a stream) would segment as a shorter
/// session than its glove stream says.
pub const RAW_TOPIC_SKEW_NS: u64 = 100_000_000;

/// Reads a session file with [`ReadLimits::streaming`]. See [`read_session_with_limits`].
pub fn read_session(path: impl AsRef<Path>) -> Result<Session> {
    read_session_with_limits(path, &ReadLimits::streaming())
}

/// Reads a session file safely (CRC prevalidation, record length limit, decompression bounded
/// by the file's length: [`ReadLimits::decompressed_limit`]). The four raw topics must be
/// present with their `icms.*` schemas ([`RecordingError::MissingTopic`],
/// [`RecordingError::UnknownSchema`] otherwise); Foxglove topics, if present, must carry their
/// official schema names. A malformed `ground_truth` record is [`RecordingError::InvalidInput`].
///
/// The content is checked too, each error naming the topic, the message's number and log time
/// and the field ([`RecordingError::InvalidInput`], or [`RecordingError::InvalidJson`] for a
/// message not of its type, a number beyond a finite `f64` included):
///
/// - every raw topic spans at least [`MIN_SESSION_NS`] (two ticks);
/// - `/glove/joint_states` and `/glove/feedback`: 1 to [`MAX_SESSION_DOFS`] `names`, each
///   array one element per name, the names those of `/glove/joint_states` message 0;
/// - `/dfs/contacts` and `/glove/feedback`: 1 to [`MAX_SESSION_FINGERS`] `fingers`, named as in
///   `/dfs/contacts` message 0;
/// - `/dfs/contacts`: the normal of every finger touching a unit vector, and `/object/state`:
///   `pose.orientation` and `pose_in_hand.orientation` unit quaternions (within
///   [`UNIT_NORM_TOLERANCE`]);
/// - metadata: at most one `session`, `ground_truth` and `replay` record, at most
///   [`MAX_METADATA_RECORDS`] records, [`MAX_METADATA_ENTRIES`] entries per record, keys of
///   [`MAX_METADATA_KEY_BYTES`], values of [`MAX_METADATA_VALUE_BYTES`],
///   [`MAX_METADATA_BYTES`] in all.
///
/// In format 2 (protobuf) a raw topic's schema must define its message field for field as ours
/// ([`super::proto::schema_difference`]; at most [`MAX_RAW_SCHEMA_BYTES`]), every message must
/// decode (the error names the topic and the message's index), and the Foxglove topics'
/// messages of up to [`MAX_CHECKED_FOXGLOVE_MESSAGE_BYTES`] must decode as the SDK's types. In
/// both formats a raw message holds at most [`MAX_RAW_MESSAGE_BYTES`].
///
/// Not checked, being harmless: the Foxglove topics' content beyond that (for viewers only),
/// `n_contacts` (segmentation counts the fingers in contact itself), the normal of a finger
/// not touching (segmentation ignores it).
///
/// [`RecordingError::MissingTopic`]: crate::error::RecordingError::MissingTopic
/// [`RecordingError::UnknownSchema`]: crate::error::RecordingError::UnknownSchema
/// [`RecordingError::InvalidInput`]: crate::error::RecordingError::InvalidInput
/// [`RecordingError::InvalidJson`]: crate::error::RecordingError::InvalidJson
/// [`MIN_SESSION_NS`]: super::MIN_SESSION_NS
/// [`MAX_SESSION_DOFS`]: super::MAX_SESSION_DOFS
/// [`MAX_SESSION_FINGERS`]: super::MAX_SESSION_FINGERS
/// [`UNIT_NORM_TOLERANCE`]: super::UNIT_NORM_TOLERANCE
/// [`MAX_METADATA_RECORDS`]: super::MAX_METADATA_RECORDS
/// [`MAX_METADATA_ENTRIES`]: super::MAX_METADATA_ENTRIES
/// [`MAX_METADATA_KEY_BYTES`]: super::MAX_METADATA_KEY_BYTES
/// [`MAX_METADATA_VALUE_BYTES`]: super::MAX_METADATA_VALUE_BYTES
/// [`MAX_METADATA_BYTES`]: super::MAX_METADATA_BYTES
pub fn read_session_with_limits(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<Session> {
    read_session_file_with(path, limits, DecodeTopics::ALL)
}

/// [`read_session_with_limits`] keeping only the raw topics in `topics` (the others are
/// checked and left empty).
pub fn read_session_file_with(
    path: impl AsRef<Path>,
    limits: &ReadLimits,
    topics: DecodeTopics,
) -> Result<Session> {
    let mut keep = Collect::new(topics);
    let head = stream_session_file(path, limits, &mut keep)?;
    Ok(keep.into_session(head))
}

/// Reads a session from bytes already in memory (for example an HTTP upload), with the same
/// checks as [`read_session_with_limits`]; `name` appears in error messages.
pub fn read_session_bytes(bytes: &[u8], name: &str, limits: &ReadLimits) -> Result<Session> {
    read_session_bytes_with(bytes, name, limits, DecodeTopics::ALL)
}

/// [`read_session_bytes`] keeping only the raw topics in `topics` (the others are checked and
/// left empty).
pub fn read_session_bytes_with(
    bytes: &[u8],
    name: &str,
    limits: &ReadLimits,
    topics: DecodeTopics,
) -> Result<Session> {
    let mut keep = Collect::new(topics);
    let head = stream_session_bytes(bytes, name, limits, &mut keep)?;
    Ok(keep.into_session(head))
}

/// Checks the session file at `path` in one pass, as [`read_session_with_limits`] describes,
/// handing its raw samples to `visitor` as they are read: memory is bounded by the chunk size,
/// not the file.
pub fn stream_session_file(
    path: impl AsRef<Path>,
    limits: &ReadLimits,
    visitor: &mut impl SessionVisitor,
) -> Result<SessionHead> {
    stream_source(&SessionSource::File(path.as_ref()), limits, visitor, None)
}

/// [`stream_session_file`] of bytes in memory; `name` appears in error messages.
pub fn stream_session_bytes(
    bytes: &[u8],
    name: &str,
    limits: &ReadLimits,
    visitor: &mut impl SessionVisitor,
) -> Result<SessionHead> {
    stream_source(&SessionSource::Bytes { bytes, name }, limits, visitor, None)
}
