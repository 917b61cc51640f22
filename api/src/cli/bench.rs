//! `icms bench ...`: the figures BENCHMARKS.md quotes.

use super::CliError;

/// Benchmarks.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// One DFS tick for glove10 holding the paper's sphere on 4 contacts.
    Tick {
        /// Print JSON.
        #[arg(long)]
        json: bool,
        /// Number of timed ticks.
        #[arg(long, default_value_t = 200_000)]
        iterations: usize,
    },
}

/// Runs a benchmark.
pub fn run(c: BenchCommand) -> Result<(), CliError> {
    match c {
        BenchCommand::Tick { json, iterations } => {
            let _ = (json, iterations);
            Err(CliError("not yet available".into()))
        }
    }
}
