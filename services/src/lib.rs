//! ICMS services: recording, segmentation, store.
//!
//! - [`mcap_io`]: MCAP session files (write, read untrusted, salvage).
//! - [`foxglove`]: serde types for the Foxglove schemas we record.
//! - [`session`]: grasp sessions: topics, recorder, reader, glove import.
//! - [`store`]: the skill data base (SQLite via sqlx, content-addressed MCAP blobs).
//! - [`segmentation`]: sessions into skills (one per grasp) and their parameters.
//! - [`ingest`]: a session file read, segmented and stored in one step.
//! - [`reprocess`]: stored sessions segmented again when the segmentation changed.
//! - [`error`]: the crate's error type.

pub mod assist;
pub mod error;
pub mod foxglove;
pub mod ingest;
pub mod live;
pub mod mcap_io;
pub mod replay;
pub mod reprocess;
pub mod segmentation;
pub mod session;
pub mod store;

pub use error::RecordingError;
