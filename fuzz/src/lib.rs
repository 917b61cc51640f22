//! Fuzz harnesses for every ICMS parser that takes user bytes, on stable Rust (no libFuzzer,
//! no instrumentation): deterministic, seed-based mutation with structure-aware mutators for
//! JSON, URDF and MCAP, run in child processes so that aborts are caught and bisected. See
//! `fuzz/README.md`.
//!
//! - [`driver`]: the `icms-fuzz` command, its worker processes, findings.
//! - [`targets`]: one target per parser (session, urdf, scenario, grasp, skill), and
//!   [`http`] for request bodies to the API's router.
//! - [`bytes`], [`json`], [`xml`], [`mcap`]: the mutators; [`seeds`]: the seed inputs;
//!   [`rng`]: the deterministic generator.

#![forbid(unsafe_code)]

pub mod bytes;
pub mod driver;
pub mod http;
pub mod json;
pub mod mcap;
pub mod rng;
pub mod seeds;
pub mod targets;
pub mod xml;
