//! ICMS's user-facing layer: the HTTP API ([`http`]), the `icms` command line ([`cli`]), the
//! live-session client ([`live_client`]) and the skill-filter parameters the API and the
//! command line share ([`filters`]).
//!
//! The `icms` binary is `api::cli::run()` with an allocation-counting global allocator
//! (`stats_alloc`), which `icms bench tick` reads.

pub mod cli;
pub mod config;
pub mod filters;
pub mod http;
pub mod jobs;
pub mod live_client;
pub mod memory;
pub mod startup;
pub mod telemetry;
