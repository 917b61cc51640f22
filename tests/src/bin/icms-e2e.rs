//! The `icms` command line, built again inside the end-to-end test package so its tests can
//! spawn it (see `tests/Cargo.toml`). Identical to `api/src/main.rs`.

/// Counts allocations, as in the real `icms` binary.
#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

fn main() -> std::process::ExitCode {
    api::cli::run()
}
