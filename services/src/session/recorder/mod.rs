//! [`SessionRecorder`]: ticks of the closed loop into a session file, with the serialising and
//! the writing on threads of their own; [`record_simulation`]: a scenario run and recorded.
//!
//! The parts: what a recording is told and reports ([`SessionInfo`], [`TickData`]: `info.rs`),
//! its start ([`SessionOut`], the constructors, the first records: `create.rs`), the recording
//! thread's side ([`SessionRecorder::record`], [`SessionRecorder::finish`]: `record.rs`), what
//! goes between the threads (`inputs.rs`), the serialiser and writer threads (`threads.rs`),
//! the raw topics' messages (`raw.rs`) and the Foxglove topics' (`foxglove_topics.rs`), the
//! live view ([`LiveView`]: `live_view.rs`) and a simulation recorded ([`record_simulation`]:
//! `simulate.rs`).

use super::*;

mod create;
mod foxglove_topics;
mod info;
mod inputs;
mod live_view;
mod raw;
mod record;
mod simulate;
#[cfg(test)]
mod tests;
mod threads;

pub use create::SessionOut;
pub use foxglove_topics::TABLE_ENTITY;
pub(super) use foxglove_topics::{fg_pose, fg_vector};
pub use info::{
    AssistTopic, RecordSummary, SessionInfo, TickData, ASSIST_ROBOT_RATE_HZ, OVERLAPS_METADATA,
    TOPIC_ASSIST_EVENTS, TOPIC_ASSIST_ROBOT,
};
pub use live_view::LiveView;
pub use record::SessionRecorder;
pub use simulate::{record_simulation, record_simulation_until, record_ticks, record_ticks_until};

/// Ticks per batch handed from the simulation thread to the serialiser thread, and from it to
/// the writer thread (a multiple of the Foxglove period).
const BATCH_TICKS: usize = 5 * FOXGLOVE_DECIMATION as usize;
/// zstd level of session files: 1. Measured on a 60 s `sphere-lift` (2026-11-26, `perf` by
/// thread, chunks compressed whole by `mcap_io::chunked`): level 3 made a 10.75 MB file with
/// 0.14 s of the writer thread's CPU, level 1 an 11.42 MB one with 0.10 s. Beside a simulation
/// of 0.15 s on the other core, a third of the writer's work is what recording's time over
/// the simulation's comes down to (BENCHMARKS.md, "Recording"); both sizes are within 12 MB
/// per minute.
const ZSTD_LEVEL: u32 = 1;
/// Batches in flight on each of the two channels (simulation → serialiser → writer).
const CHANNEL_BOUND: usize = 4;

/// Topic indices used inside batches: the raw topics, then the Foxglove topics, then the
/// assistant's (registered only when [`SessionInfo::assist_topics`]).
const ALL_TOPICS: [&str; 10] = [
    TOPIC_GLOVE_JOINT_STATES,
    TOPIC_GLOVE_FEEDBACK,
    TOPIC_CONTACTS,
    TOPIC_OBJECT_STATE,
    TOPIC_TF,
    TOPIC_SCENE,
    TOPIC_JOINT_STATES,
    TOPIC_HAND,
    TOPIC_ASSIST_EVENTS,
    TOPIC_ASSIST_ROBOT,
];
