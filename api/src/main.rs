//! The `icms` command-line tool: static force analysis, simulation, sessions, skills, server
//! and benchmarks. Every subcommand has `--help`; `--json` prints machine-readable output.

/// Counts allocations so `icms bench tick` can report them (one relaxed atomic add per
/// allocation).
#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

fn main() -> std::process::ExitCode {
    api::cli::run()
}
