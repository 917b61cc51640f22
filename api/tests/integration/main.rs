//! Every integration test of `api` in one test binary: one build and one link for all
//! of them instead of one each (most of the clean-clone CI time was compiling and linking
//! 16 binaries that each instantiate the same generic code). A file is a module here:
//! `cargo test --release -p api --test integration -- FILE::` runs one file's tests.
//! Tests that count the process's allocations keep a binary of their own beside this one.

mod common;
#[path = "../../../services/tests/integration/s3_server/mod.rs"]
mod s3_server;
#[path = "../../../services/tests/integration/tcp_relay/mod.rs"]
mod tcp_relay;

mod cli_bench;
mod cli_bench_store;
mod cli_dfs_static;
mod cli_full_disk;
mod cli_postgres;
mod cli_recognise;
mod cli_replay;
mod cli_reprocess;
mod cli_segment;
mod cli_serve_blobs;
mod cli_serve_database;
mod cli_serve_database_outage;
mod cli_serve_follow;
mod cli_sessions;
mod cli_skills;
mod cli_worker;
