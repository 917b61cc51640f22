//! Every integration test of `tests` in one test binary: one build and one link for all
//! of them instead of one each (most of the clean-clone CI time was compiling and linking
//! 14 binaries that each instantiate the same generic code). A file is a module here:
//! `cargo test --release -p tests --test integration -- FILE::` runs one file's tests.
//! Tests that count the process's allocations keep a binary of their own beside this one.

#[path = "../../python/interpreter.rs"]
mod interpreter;

mod assist;
mod generated_client;
mod hostile_server;
mod http_errors;
mod http_flow;
mod http_hands_replays;
mod http_jobs;
mod http_openapi;
mod http_uploads;
mod http_web;
mod live;
mod readme_commands;
mod server_process;
mod web_page;
