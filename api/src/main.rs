//! The `icms` command-line tool: static force analysis, simulation, sessions, skills, server
//! and benchmarks. Every subcommand has `--help`; `--json` prints machine-readable output.

mod cli;

/// Counts allocations so `icms bench` can report them (one relaxed atomic add per allocation).
#[global_allocator]
pub static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

fn main() -> std::process::ExitCode {
    cli::run()
}
