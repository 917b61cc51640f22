//! The `icms` command-line tool: static force analysis, simulation, sessions, skills, server
//! and benchmarks. Every subcommand has `--help`; `--json` prints machine-readable output.

mod cli;

fn main() -> std::process::ExitCode {
    cli::run()
}
