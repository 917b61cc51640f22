//! ICMS's user-facing layer: the `icms` command line ([`cli`]) and the skill-filter parameters
//! it shares with the HTTP API ([`filters`]).
//!
//! The `icms` binary is `api::cli::run()` with an allocation-counting global allocator
//! (`stats_alloc`), which `icms bench tick` reads.

pub mod cli;
pub mod filters;
