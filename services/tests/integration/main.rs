//! Every integration test of `services` in one test binary: one build and one link for all
//! of them instead of one each (most of the clean-clone CI time was compiling and linking
//! 28 binaries that each instantiate the same generic code). A file is a module here:
//! `cargo test --release -p services --test integration -- FILE::` runs one file's tests.
//! Tests that count the process's allocations keep a binary of their own beside this one.

mod common;
#[macro_use]
mod store_common;
#[path = "../../../tests/python/interpreter.rs"]
mod interpreter;
mod s3_server;
mod tcp_relay;

mod assist_phase;
mod decompression_bombs;
mod foxglove_schemas;
mod glove_import;
mod hand_in_session;
mod hostile_sessions;
mod mcap_io;
mod python_reader;
mod recognition;
mod replay;
mod reprocess;
mod segmentation;
mod segmentation_odd;
mod segmentation_stream;
mod session;
mod session_v1;
mod several_objects;
mod sqlx_offline_data;
mod sqlx_offline_data_postgres;
mod store_follow;
mod store_hands_replays;
mod store_ingest;
mod store_jobs;
mod store_kill;
mod store_query;
mod store_s3;
mod store_sweep;
mod varied_reach;
