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
        /// Number of timed ticks, at least 1000 (a percentile of fewer says little).
        #[arg(long, default_value_t = 200_000, value_parser = clap::value_parser!(u64).range(1000..=100_000_000))]
        iterations: u64,
    },
    /// A scenario simulated alone, then simulated and recorded into an MCAP session (written
    /// to a temporary file, deleted afterwards).
    Session {
        /// Print JSON: `{"seconds", "realtime_factor", "file_bytes", "bytes_per_minute", ...}`.
        #[arg(long)]
        json: bool,
        /// Simulated seconds.
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
        /// Built-in scenario.
        #[arg(long, default_value = "sphere-lift")]
        scenario: String,
    },
    /// Replay of the sphere-lift skill (recorded with glove10, segmented) on Allegro: the
    /// time to retarget and simulate it, per 5 s of skill (5 000 DFS ticks), and one
    /// retargeting step (warm-started IK plus the force distribution with torque limits).
    Replay {
        /// Print JSON: `{"retarget_ms", "simulate_ms", "per_5s_ms", "retarget_step_us", ...}`.
        #[arg(long)]
        json: bool,
        /// Hand.
        #[arg(long, default_value = "allegro")]
        hand: String,
    },
    /// Segmentation of every built-in scenario × seeds scored against the ground truth, and
    /// the time to segment a long sphere-lift session.
    Segmentation {
        /// Print JSON: `{"overall": {"median_boundary_error_ms", "phases_found_fraction", ...},
        /// "per_scenario": {...}, "segment_60s_ms", ...}`.
        #[arg(long)]
        json: bool,
        /// Seeds per scenario (0..N).
        #[arg(long, default_value_t = 20)]
        seeds: u64,
        /// Simulated seconds of the session whose segmentation is timed.
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
    },
    /// Ingest (read and validate, segment, store) of simulated sessions held in memory; the
    /// simulation that makes them is not timed.
    Ingest {
        /// Print JSON: `{"sessions_per_second", "analyse_ms", "store_ms", ...}`.
        #[arg(long)]
        json: bool,
        /// Number of sessions (sphere-lift, seeds 0..N).
        #[arg(long, default_value_t = 20)]
        sessions: u64,
        /// Simulated seconds per session.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Built-in scenario.
        #[arg(long, default_value = "sphere-lift")]
        scenario: String,
    },
}

/// Result of `icms bench ingest`.
#[derive(Debug, Serialize)]
pub struct IngestBench {
    /// Sessions ingested per wall-clock second, as `icms ingest FILE...` does: files on disk
    /// into a fresh data base, one after the other.
    pub sessions_per_second: f64,
    /// Median time to ingest one session file (copy into the store while hashed, read and
    /// check, segment, store), ms.
    pub ingest_ms: f64,
    /// Median time to read, check and segment one session file (two streamed passes), ms,
    /// timed apart.
    pub analyse_ms: f64,
    /// `ingest_ms - analyse_ms`: copying, hashing and the transaction (ms).
    pub store_ms: f64,
    /// Median size of one session file (bytes).
    pub file_bytes: u64,
    /// `store_ms` with `synchronous=NORMAL` instead of the store's `FULL` (the cost of
    /// durable commits), ms.
    pub store_ms_synchronous_normal: f64,
    /// Sessions ingested.
    pub sessions: u64,
    /// Simulated seconds per session.
    pub duration: f64,
    /// Scenario.
    pub scenario: String,
}

/// Result of `icms bench session`.
#[derive(Debug, Serialize)]
pub struct SessionBench {
    /// Wall-clock seconds to simulate and record the session.
    pub seconds: f64,
    /// Simulated seconds per wall-clock second, simulating and recording.
    pub realtime_factor: f64,
    /// Size of the session file (bytes).
    pub file_bytes: u64,
    /// File size per simulated minute (bytes).
    pub bytes_per_minute: f64,
    /// Wall-clock seconds to simulate alone (no recording).
    pub simulation_seconds: f64,
    /// Simulated seconds per wall-clock second, simulating alone.
    pub simulation_realtime_factor: f64,
    /// Extra wall-clock seconds that recording adds to the simulation.
    pub recording_overhead_seconds: f64,
    /// Messages written.
    pub messages: u64,
    /// Ticks simulated.
    pub ticks: u64,
    /// Scenario.
    pub scenario: String,
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
        BenchCommand::Replay { json, hand } => super::replay::bench_replay(&hand, json),
        BenchCommand::Segmentation {
            json,
            seeds,
            duration,
        } => super::segment::bench_segmentation(seeds, duration, json),
        BenchCommand::Ingest {
            json,
            sessions,
            duration,
            scenario,
        } => {
            let r = bench_ingest(&scenario, sessions.max(1), duration)?;
            if json {
                print_json(&r)
            } else {
                println!(
                    "ingest of {} {} s {} sessions ({} bytes each): {:.1} sessions/s; per session: read + segment {:.1} ms, store {:.1} ms (synchronous=FULL; NORMAL: {:.1} ms) (medians)",
                    r.sessions, r.duration, r.scenario, r.file_bytes, r.sessions_per_second,
                    r.analyse_ms, r.store_ms, r.store_ms_synchronous_normal
                );
                Ok(())
            }
        }
        BenchCommand::Tick { json, iterations } => {
            let r = bench_tick(iterations as usize)?;
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
        BenchCommand::Session {
            json,
            duration,
            scenario,
        } => {
            let r = bench_session(&scenario, duration)?;
            if json {
                print_json(&r)
            } else {
                println!(
                    "{} s of {}: simulate + record {:.3} s ({:.0}× real time), simulate alone {:.3} s ({:.0}×); {} bytes ({:.0} bytes/min), {} messages",
                    duration, r.scenario, r.seconds, r.realtime_factor, r.simulation_seconds,
                    r.simulation_realtime_factor, r.file_bytes, r.bytes_per_minute, r.messages
                );
                Ok(())
            }
        }
    }
}

fn bench_session(name: &str, duration: f64) -> Result<SessionBench, CliError> {
    let scenario = dfs_core::scenario::Scenario::builtin(name, 0)
        .ok_or_else(|| CliError(format!("no built-in scenario {name:?}")))?;
    let t0 = Instant::now();
    let mut sim = dfs_core::operator::Simulation::new(
        &scenario,
        dfs_core::hand::HandModel::glove10(),
        Some(duration),
    )?;
    while sim.step()? {
        black_box(sim.output());
    }
    let simulation_seconds = t0.elapsed().as_secs_f64();
    let ticks = sim.ticks();
    let path = std::env::temp_dir().join(format!("icms-bench-session-{}.mcap", std::process::id()));
    let t0 = Instant::now();
    let result = services::session::record_simulation(&scenario, Some(duration), &path, |_, _| {});
    let seconds = t0.elapsed().as_secs_f64();
    let _ = std::fs::remove_file(&path);
    let summary = result?;
    let simulated = summary.ticks as f64 * 1e-3;
    Ok(SessionBench {
        seconds,
        realtime_factor: simulated / seconds,
        file_bytes: summary.file_bytes,
        bytes_per_minute: summary.file_bytes as f64 * 60.0 / simulated,
        simulation_seconds,
        simulation_realtime_factor: simulated / simulation_seconds,
        recording_overhead_seconds: seconds - simulation_seconds,
        messages: summary.write.messages,
        ticks,
        scenario: scenario.name,
    })
}

fn bench_ingest(name: &str, sessions: u64, duration: f64) -> Result<IngestBench, CliError> {
    let dir = tempfile::tempdir().map_err(|e| CliError(format!("temporary directory: {e}")))?;
    let mut files = Vec::new();
    for seed in 0..sessions {
        let scenario = dfs_core::scenario::Scenario::builtin(name, seed)
            .ok_or_else(|| CliError(format!("no built-in scenario {name:?}")))?;
        let path = dir.path().join(format!("{seed}.mcap"));
        services::session::record_simulation(&scenario, Some(duration), &path, |_, _| {})?;
        files.push(path);
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("starting the async runtime: {e}")))?;
    let data = dir.path().join("data");
    let normal_data = dir.path().join("data-normal");
    // The analysis alone (read, check, segment: two streamed passes over the file), timed
    // apart first.
    let mut analyse = Vec::new();
    for path in &files {
        let t0 = Instant::now();
        services::ingest::analyse_source(&services::session::SessionSource::File(path))?;
        analyse.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    let (mut ingest_t, total, mut store_normal) = rt.block_on(async {
        let store = services::store::Store::open(&data).await?;
        let normal = services::store::Store::open_with_durability(
            &normal_data,
            services::store::Durability::Normal,
        )
        .await?;
        let (mut s, mut n) = (Vec::new(), Vec::new());
        // What `icms ingest FILE...` does for each file, into a fresh data base.
        let t_all = Instant::now();
        for (i, path) in files.iter().enumerate() {
            let t0 = Instant::now();
            services::ingest::ingest_file(&store, path.clone(), format!("session {i}")).await?;
            s.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        let total = t_all.elapsed().as_secs_f64();
        // The same files stored again into a synchronous=NORMAL data base, right after, for
        // the cost of durable commits measured in one run.
        for (i, path) in files.iter().enumerate() {
            let t0 = Instant::now();
            services::ingest::ingest_file(&normal, path.clone(), format!("session {i}")).await?;
            n.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        store.close().await;
        normal.close().await;
        Ok::<_, CliError>((s, total, n))
    })?;
    let mut sizes: Vec<u64> = files
        .iter()
        .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0))
        .collect();
    sizes.sort_unstable();
    let analyse_ms = services::segmentation::median(&mut analyse);
    let ingest_ms = services::segmentation::median(&mut ingest_t);
    Ok(IngestBench {
        sessions_per_second: sessions as f64 / total,
        analyse_ms,
        store_ms: (ingest_ms - analyse_ms).max(0.0),
        ingest_ms,
        store_ms_synchronous_normal: (services::segmentation::median(&mut store_normal)
            - analyse_ms)
            .max(0.0),
        file_bytes: sizes[sizes.len() / 2],
        sessions,
        duration,
        scenario: name.to_string(),
    })
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
    let region = stats_alloc::Region::new(&stats_alloc::INSTRUMENTED_SYSTEM);
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
