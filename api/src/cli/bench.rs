//! `icms bench ...`: the figures BENCHMARKS.md quotes. Timings are wall-clock on this machine;
//! compare ratios against peers run in the same session, not absolute numbers.

use super::{print_json, CliError};
use dfs_core::dfs::GloveSample;
use dfs_core::fixtures::glove10_holding_paper_sphere;
use serde::Serialize;
use std::hint::black_box;
use std::time::Instant;

/// Benchmarks.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// One DFS tick for glove10 holding the paper's sphere on 4 contacts.
    Tick {
        /// Print JSON: `{"median_ns", "p99_ns", "allocations_per_tick"}`.
        #[arg(long)]
        json: bool,
        /// Number of timed ticks.
        #[arg(long, default_value_t = 200_000)]
        iterations: usize,
    },
}

/// Result of `icms bench tick`.
#[derive(Debug, Serialize)]
pub struct TickBench {
    /// Median time of one tick (ns).
    pub median_ns: f64,
    /// 99th percentile (ns).
    pub p99_ns: f64,
    /// Mean time of one tick (ns).
    pub mean_ns: f64,
    /// Heap allocations per tick (counted by the global allocator).
    pub allocations_per_tick: f64,
    /// Ticks timed.
    pub iterations: usize,
    /// Transmitting contacts in the tick.
    pub contacts: usize,
}

/// Runs a benchmark.
pub fn run(c: BenchCommand) -> Result<(), CliError> {
    match c {
        BenchCommand::Tick { json, iterations } => {
            let r = bench_tick(iterations.max(1000))?;
            if json {
                print_json(&r)
            } else {
                println!(
                    "DFS tick (glove10, paper sphere, {} contacts): median {:.0} ns, p99 {:.0} ns, mean {:.0} ns, {} allocations/tick over {} ticks",
                    r.contacts, r.median_ns, r.p99_ns, r.mean_ns, r.allocations_per_tick, r.iterations
                );
                Ok(())
            }
        }
    }
}

fn bench_tick(iterations: usize) -> Result<TickBench, CliError> {
    let (mut dfs, q, tau, base) = glove10_holding_paper_sphere()?;
    let start = *dfs.object_state();
    let sample = GloveSample {
        q: &q,
        tau: &tau,
        base,
    };
    for _ in 0..iterations / 10 {
        dfs.set_object_state(start);
        black_box(dfs.step(&sample)?);
    }
    let contacts = dfs.output().n_contacts;
    let mut times = vec![0u32; iterations];
    let region = stats_alloc::Region::new(crate::GLOBAL);
    let total = Instant::now();
    for t in times.iter_mut() {
        let t0 = Instant::now();
        dfs.set_object_state(start);
        black_box(dfs.step(black_box(&sample))?);
        *t = t0.elapsed().as_nanos().min(u32::MAX as u128) as u32;
    }
    let total = total.elapsed();
    let allocs = region.change().allocations;
    times.sort_unstable();
    Ok(TickBench {
        median_ns: times[iterations / 2] as f64,
        p99_ns: times[iterations * 99 / 100] as f64,
        mean_ns: total.as_nanos() as f64 / iterations as f64,
        allocations_per_tick: allocs as f64 / iterations as f64,
        iterations,
        contacts,
    })
}
