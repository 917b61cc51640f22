//! `icms bench ...`: the figures BENCHMARKS.md quotes. Timings are wall-clock on this machine;
//! compare ratios against peers run in the same session, not absolute numbers.

use super::{print_json, CliError};
use serde::Serialize;
use std::hint::black_box;
use std::time::Instant;

pub mod jobs;
pub mod store;
pub mod tick;

/// Benchmarks.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// The DFS tick on a held-object scene that evolves (`fingertips`: glove10 holding a ball
    /// on four fingertips, the grip swinging), timed as the MuJoCo peer of the same scene
    /// (`benches/peers/mujoco_peer.py`) times its step: the median over batches of 100 ticks
    /// of the time per tick.
    Tick {
        /// Print JSON: `{"median_ns", "p99_ns", "allocations_per_tick", "median_tick_ns", ...}`.
        #[arg(long)]
        json: bool,
        /// The scene: `fingertips` (four fingertips hold a ball), `power-grasp` (whole-hand
        /// contact: the fingers press a cylinder into the palm) or `frozen` (the benchmark before
        /// issue 21).
        #[arg(long, value_enum, default_value_t = tick::TickScene::Fingertips)]
        scene: tick::TickScene,
        /// Number of timed ticks, at least 1000 (a percentile of fewer says little); at most
        /// 2 000 000 for a held scene, whose glove samples are made beforehand.
        #[arg(long, default_value_t = 200_000, value_parser = clap::value_parser!(u64).range(1000..=100_000_000))]
        iterations: u64,
        /// Print the scene (hand pose, ball, the operator's set posture, torques and gains) as
        /// JSON instead of timing it: what the MuJoCo peer builds its scene from
        /// (`benches/peers/fingertips_scene.json`).
        #[arg(long, conflicts_with_all = ["json", "iterations"])]
        describe: bool,
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
    /// Early recognition (issue 20): skills of every built-in grasp kind stored from training
    /// seeds, held-out seeds recognised as they stream (anticipation 200 ms before the first
    /// contact, the nearest stored skill by 1 s after it, each kind left out for the open set),
    /// and the cost per observation with 10 000 stored skills.
    Recognition {
        /// Print JSON: `{"anticipated_fraction", "nearest_fraction", "unknown_fraction",
        /// "stored_as_new_fraction", "median_decided_fraction", "cost", "sessions", ...}`.
        #[arg(long)]
        json: bool,
        /// Training seeds per grasp kind.
        #[arg(long, default_value_t = 5)]
        train: u64,
        /// Held-out seeds per grasp kind.
        #[arg(long, default_value_t = 5)]
        test: u64,
        /// Stored skills the cost is measured with.
        #[arg(long, default_value_t = 10_000)]
        stored: usize,
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
    /// Ingest (read and validate, segment, store) of simulated session files into a fresh data
    /// base, as `icms ingest FILE...` does it; the simulation that makes them is not timed.
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
    /// Live glove sessions (`GET /api/v1/live`) at once against the real server, started
    /// in-process on an ephemeral port with a fresh data directory, each streaming the
    /// simulated operator of a scenario (different seeds) at its sample times: the round trip
    /// of each sample to its feedback over loopback. The simulation that makes the samples is
    /// done before and not timed.
    Live {
        /// Print JSON: `{"p50_us", "p99_us", "dropped", "load_before", ...}`.
        #[arg(long)]
        json: bool,
        /// Concurrent sessions.
        #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u64).range(1..=64))]
        sessions: u64,
        /// Seconds each session streams.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// Samples per second per session, 60 to 1000.
        #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(60..=1000))]
        rate: u32,
        /// Built-in scenario.
        #[arg(long, default_value = "sphere-lift")]
        scenario: String,
        /// With the assistant on (`suggest`), recognising against three stored sessions of the
        /// scenario (seeds 100-102).
        #[arg(long)]
        assist: bool,
    },
    /// The skill data base alone on synthetic data in a fresh data directory: storing 50
    /// sessions of 200 KiB and of 2 MiB, generating `--skills` skills, random filtered queries
    /// and k-nearest searches over them, opening the store again.
    Store {
        /// Print JSON: `{"ingest", "filtered_query": {"p50_ms", "p99_ms", ...}, "nearest", ...}`.
        #[arg(long)]
        json: bool,
        /// Synthetic skills in the store, 1 000 to 10 000 000 (the filtered-query target is set
        /// at 1 000 000).
        #[arg(long, default_value_t = 100_000, value_parser = clap::value_parser!(u64).range(1000..=10_000_000))]
        skills: u64,
        /// Where the temporary data directory goes (default: the system's temporary
        /// directory; a million skills take about 2 GB).
        #[arg(long)]
        dir: Option<std::path::PathBuf>,
        /// Keep the data directory afterwards (its path is printed on stderr).
        #[arg(long)]
        keep: bool,
        /// An empty PostgreSQL data base to bench instead of SQLite (postgres://…); the bench
        /// fills it. See docs/backends.md.
        #[arg(long, value_name = "URL")]
        database_url: Option<String>,
    },
    /// Replay jobs (skill x built-in hand, from the built-in scenarios' skills) run by one
    /// worker, then by two, each round on a fresh store seeded alike (not timed): the time
    /// until every job has ended, and the ratio.
    Jobs {
        /// Print JSON: `{"rounds": [{"workers", "seconds", ...}], "speedup", ...}`.
        #[arg(long)]
        json: bool,
        /// Replay jobs per round.
        #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..=1000))]
        jobs: u64,
        /// An empty PostgreSQL data base to run the jobs on (postgres://…; the bench makes and
        /// drops a schema per round). Default: temporary SQLite data directories.
        #[arg(long, value_name = "URL")]
        database_url: Option<String>,
    },
    /// Uploads of simulated session files (`POST /api/v1/sessions`, each a distinct file) over
    /// HTTP on loopback to the real server, started in-process on an ephemeral port with a
    /// fresh data directory: the time from connecting to the end of the 201 reply (the body
    /// streamed to disk and hashed, read and segmented, stored). The simulation that makes
    /// the files and reading them into memory are not timed.
    Upload {
        /// Print JSON: `{"median_ms", "min_ms", "max_ms", "uploads_ms", ...}`.
        #[arg(long)]
        json: bool,
        /// Number of uploads (sessions of seeds 1..=N).
        #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=1000))]
        uploads: u64,
        /// Simulated seconds per session.
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
        /// Built-in scenario.
        #[arg(long, default_value = "sphere-lift")]
        scenario: String,
    },
}

/// Result of `icms bench live`.
#[derive(Debug, Serialize)]
pub struct LiveBench {
    /// Round trip sample → feedback over loopback, all sessions together, µs: median.
    pub p50_us: f64,
    /// 90th percentile.
    pub p90_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// 99.9th percentile.
    pub p999_us: f64,
    /// Slowest.
    pub max_us: f64,
    /// Samples sent, all sessions.
    pub samples: u64,
    /// Samples without an answer (sent less answered less refused).
    pub dropped: u64,
    /// Samples the server refused.
    pub refused: u64,
    /// Concurrent live sessions.
    pub sessions: usize,
    /// Samples per second per session.
    pub rate_hz: u32,
    /// Seconds streamed per session.
    pub seconds: f64,
    /// The sessions' samples were sent at their times (`true`), not as fast as answered.
    pub realtime: bool,
    /// The assistant was on (`suggest`, against three stored sessions).
    pub assist: bool,
    /// Threads stepping the live sessions (`--live-threads`).
    pub live_threads: usize,
    /// Cores of this machine.
    pub cores: usize,
    /// The 1-minute load average before the run (from /proc/loadavg; -1 if unknown): how
    /// quiet the machine was.
    pub load_before: f64,
    /// The 1-minute load average after the run.
    pub load_after: f64,
    /// Every session was stored.
    pub stored: usize,
}

/// Result of `icms bench upload`.
#[derive(Debug, Serialize)]
pub struct UploadBench {
    /// Median time of one upload, from connecting to the end of the reply, ms.
    pub median_ms: f64,
    /// Fastest upload, ms.
    pub min_ms: f64,
    /// Slowest upload, ms.
    pub max_ms: f64,
    /// Every upload's time, in order, ms.
    pub uploads_ms: Vec<f64>,
    /// Median time to read, check and segment one of the files alone (no HTTP, no store),
    /// timed after the uploads: the share of an upload that is analysis, ms.
    pub analyse_ms: f64,
    /// Median size of one session file (bytes).
    pub file_bytes: u64,
    /// Uploads.
    pub uploads: u64,
    /// Simulated seconds per session.
    pub duration: f64,
    /// Scenario.
    pub scenario: String,
}

/// Result of `icms bench ingest`.
#[derive(Debug, Serialize)]
pub struct IngestBench {
    /// Sessions ingested per wall-clock second, as `icms ingest FILE...` does: files on disk
    /// into a fresh data base, `in_flight` analysed at once ahead of the commits (one
    /// transaction per session, in order).
    pub sessions_per_second: f64,
    /// The same files one after the other (each staged, analysed and committed before the
    /// next starts: `icms ingest` before it overlapped them), into another fresh data base,
    /// sessions per second.
    pub sessions_per_second_one_at_a_time: f64,
    /// Files `icms ingest` analyses at once.
    pub in_flight: usize,
    /// Median time to ingest one session file alone (copy into the store while hashed, read
    /// and check, segment, store), ms.
    pub ingest_ms: f64,
    /// Median time to read, check and segment one session file (two streamed passes), ms,
    /// timed apart.
    pub analyse_ms: f64,
    /// `ingest_ms - analyse_ms`: copying, hashing and the transaction (ms).
    pub store_ms: f64,
    /// Median size of one session file (bytes).
    pub file_bytes: u64,
    /// `store_ms` with `synchronous=NORMAL` instead of the store's `FULL` (the cost of
    /// durable commits), one file at a time, ms.
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
        } => run_ingest(json, sessions, duration, &scenario),
        BenchCommand::Store {
            json,
            skills,
            dir,
            keep,
            database_url,
        } => run_store(json, skills, dir, keep, database_url.as_deref()),
        BenchCommand::Jobs {
            json,
            jobs: n,
            database_url,
        } => run_jobs(json, n, database_url.as_deref()),
        BenchCommand::Upload {
            json,
            uploads,
            duration,
            scenario,
        } => run_upload(json, uploads, duration, &scenario),
        BenchCommand::Recognition {
            json,
            train,
            test,
            stored,
        } => run_recognition(json, train, test, stored),
        BenchCommand::Live {
            json,
            sessions,
            seconds,
            rate,
            scenario,
            assist,
        } => run_live(json, sessions, seconds, rate, &scenario, assist),
        BenchCommand::Tick {
            json,
            scene,
            iterations,
            describe,
        } => run_tick(json, scene, iterations, describe),
        BenchCommand::Session {
            json,
            duration,
            scenario,
        } => run_session(json, duration, &scenario),
    }
}

/// `icms bench ingest`: runs it and prints the result.
fn run_ingest(json: bool, sessions: u64, duration: f64, scenario: &str) -> Result<(), CliError> {
    let r = bench_ingest(scenario, sessions.max(1), duration)?;
    if json {
        print_json(&r)
    } else {
        println!(
            "ingest of {} {} s {} sessions ({} bytes each): {:.1} sessions/s ({} files at once; one at a time {:.1}/s); per session alone: read + segment {:.1} ms, store {:.1} ms (synchronous=FULL; NORMAL: {:.1} ms) (medians)",
            r.sessions, r.duration, r.scenario, r.file_bytes, r.sessions_per_second,
            r.in_flight, r.sessions_per_second_one_at_a_time,
            r.analyse_ms, r.store_ms, r.store_ms_synchronous_normal
        );
        Ok(())
    }
}

/// `icms bench store`: runs it and prints the result.
fn run_store(
    json: bool,
    skills: u64,
    dir: Option<std::path::PathBuf>,
    keep: bool,
    database_url: Option<&str>,
) -> Result<(), CliError> {
    let database = services::store::Database::from_url(database_url)?;
    let r = store::bench_store(skills as usize, dir, keep, &database)?;
    if json {
        print_json(&r)
    } else {
        store::print(&r);
        Ok(())
    }
}

/// `icms bench jobs`: runs it and prints the result.
fn run_jobs(json: bool, n: u64, database_url: Option<&str>) -> Result<(), CliError> {
    let r = jobs::bench_jobs(n as usize, database_url)?;
    if json {
        print_json(&r)
    } else {
        jobs::print(&r);
        Ok(())
    }
}

/// `icms bench upload`: runs it and prints the result.
fn run_upload(json: bool, uploads: u64, duration: f64, scenario: &str) -> Result<(), CliError> {
    let r = bench_upload(scenario, uploads, duration)?;
    if json {
        print_json(&r)
    } else {
        println!(
            "upload of {} {} s {} sessions ({} bytes each) over HTTP on loopback: median {:.1} ms, min {:.1} ms, max {:.1} ms (read + segment alone: {:.1} ms)",
            r.uploads, r.duration, r.scenario, r.file_bytes, r.median_ms, r.min_ms,
            r.max_ms, r.analyse_ms
        );
        Ok(())
    }
}

/// `icms bench recognition`: runs it and prints the result.
fn run_recognition(json: bool, train: u64, test: u64, stored: usize) -> Result<(), CliError> {
    let r = bench_recognition(train, test, stored)?;
    if json {
        print_json(&r)
    } else {
        let c = r.cost.as_ref();
        println!(
            "recognition over {} held-out sessions ({:?} stored): target and kind named 200 ms before first contact {:.0} %, median decision at {:.0} % of the reach ({:.0} ms before contact); nearest stored skill named by 1 s after contact {:.0} % (exact knowledge of what is known then: {:.0} %); kind left out: unknown {:.0} %, stored as new {:.0} %; cost per call (an observation, or a slice of work between two) with {} skills: mean {:.2} µs, p99 {:.2} µs, max {:.0} µs (least of {} runs per call: mean {:.2} µs, p99 {:.2} µs, max {:.0} µs); an approach-decision call mean {:.0} µs (max {:.0} µs), a decision's calls together {:.0} µs; a grasp-stage call mean {:.0} µs (max {:.0} µs), {:.1} observation periods per grasp-stage decision",
            r.sessions.len(), r.stored_per_kind, 100.0 * r.anticipated_fraction,
            100.0 * r.median_decided_fraction, r.median_lead_ms,
            100.0 * r.nearest_fraction, 100.0 * r.nearest_bound_fraction,
            100.0 * r.unknown_fraction,
            100.0 * r.stored_as_new_fraction, c.map_or(0, |c| c.stored_skills),
            c.map_or(0.0, |c| c.mean_us), c.map_or(0.0, |c| c.p99_us),
            c.map_or(0.0, |c| c.max_us),
            services::assist::evaluate::COST_REPEATS,
            c.map_or(0.0, |c| c.least_mean_us), c.map_or(0.0, |c| c.least_p99_us),
            c.map_or(0.0, |c| c.least_max_us),
            c.map_or(0.0, |c| c.approach_decision_mean_us),
            c.map_or(0.0, |c| c.approach_decision_max_us),
            c.map_or(0.0, |c| c.approach_decision_total_us),
            c.map_or(0.0, |c| c.grasp_step_mean_us),
            c.map_or(0.0, |c| c.grasp_step_max_us),
            c.map_or(0.0, |c| c.grasp_steps_per_decision)
        );
        Ok(())
    }
}

/// `icms bench live`: runs it and prints the result.
fn run_live(
    json: bool,
    sessions: u64,
    seconds: f64,
    rate: u32,
    scenario: &str,
    assist: bool,
) -> Result<(), CliError> {
    let r = bench_live(scenario, sessions as usize, seconds, rate, assist)?;
    if json {
        print_json(&r)
    } else {
        println!(
            "{} live sessions × {} s at {} Hz over loopback ({} stepping threads, {} cores, load {:.2} before): round trip p50 {:.0} µs, p90 {:.0} µs, p99 {:.0} µs, p99.9 {:.0} µs, max {:.0} µs; {} samples, {} dropped, {} refused; {} of {} stored",
            r.sessions, r.seconds, r.rate_hz, r.live_threads, r.cores, r.load_before,
            r.p50_us, r.p90_us, r.p99_us, r.p999_us, r.max_us, r.samples, r.dropped,
            r.refused, r.stored, r.sessions
        );
        Ok(())
    }
}

/// `icms bench tick`: describes the scene, or runs it and prints the result.
fn run_tick(
    json: bool,
    scene: tick::TickScene,
    iterations: u64,
    describe: bool,
) -> Result<(), CliError> {
    if describe {
        return print_json(&tick::describe(scene)?);
    }
    let r = tick::bench_tick(scene, iterations as usize)?;
    if json {
        print_json(&r)
    } else {
        println!(
            "DFS tick, scene {:?} ({} contacts at the end, at least {}): median {:.0} ns per tick (batches of {}), p99 {:.0} ns, median of single ticks {:.0} ns, {} allocations/tick over {} ticks",
            scene, r.contacts, r.min_contacts, r.median_ns, r.batch_ticks, r.p99_ns,
            r.median_tick_ns, r.allocations_per_tick, r.iterations
        );
        Ok(())
    }
}

/// `icms bench session`: runs it and prints the result.
fn run_session(json: bool, duration: f64, scenario: &str) -> Result<(), CliError> {
    let r = bench_session(scenario, duration)?;
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
    // The analysis alone (read, check, segment: two streamed passes over the file), timed
    // apart first.
    let mut analyse = Vec::new();
    for path in &files {
        let t0 = Instant::now();
        services::ingest::analyse_source(&services::session::SessionSource::File(path))?;
        analyse.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    let (total, mut one_t, one_total, mut store_normal) = rt.block_on(async {
        // What `icms ingest FILE...` does, into a fresh data base.
        let store = services::store::Store::open(&dir.path().join("data")).await?;
        let mut failed = None;
        let t_all = Instant::now();
        super::skills::ingest_paths(&store, &files, |f, outcome| {
            if let Err(e) = outcome {
                failed.get_or_insert_with(|| format!("{}: {e}", f.display()));
            }
        })
        .await;
        let total = t_all.elapsed().as_secs_f64();
        store.close().await;
        if let Some(e) = failed {
            return Err(CliError(e));
        }
        // The same files one at a time into fresh data bases: with the store's
        // synchronous=FULL, then NORMAL (the cost of durable commits), measured in one run.
        let mut per_file = Vec::new();
        let mut one_total = 0.0;
        for durability in [
            services::store::Durability::Full,
            services::store::Durability::Normal,
        ] {
            let data = dir.path().join(format!("data-{durability:?}"));
            let store = services::store::Store::open_with_durability(&data, durability).await?;
            let mut times = Vec::new();
            let t_all = Instant::now();
            for (i, path) in files.iter().enumerate() {
                let t0 = Instant::now();
                services::ingest::ingest_file(&store, path.clone(), format!("session {i}")).await?;
                times.push(t0.elapsed().as_secs_f64() * 1e3);
            }
            if durability == services::store::Durability::Full {
                one_total = t_all.elapsed().as_secs_f64();
            }
            store.close().await;
            per_file.push(times);
        }
        let normal = per_file.pop().unwrap_or_default();
        let full = per_file.pop().unwrap_or_default();
        Ok::<_, CliError>((total, full, one_total, normal))
    })?;
    let mut sizes: Vec<u64> = files
        .iter()
        .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0))
        .collect();
    sizes.sort_unstable();
    let analyse_ms = services::segmentation::median(&mut analyse);
    let ingest_ms = services::segmentation::median(&mut one_t);
    Ok(IngestBench {
        sessions_per_second: sessions as f64 / total,
        sessions_per_second_one_at_a_time: sessions as f64 / one_total,
        in_flight: services::ingest::INGEST_FILES_IN_FLIGHT,
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

/// The 1-minute load average (-1 where /proc/loadavg is not there).
fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|t| t.split_whitespace().next()?.parse().ok())
        .unwrap_or(-1.0)
}

/// `icms bench live` (see [`BenchCommand::Live`]): `sessions` clients streaming `name`'s
/// simulated operator at `rate` Hz for `seconds` to the server started in-process.
fn bench_live(
    name: &str,
    sessions: usize,
    seconds: f64,
    rate: u32,
    assist: bool,
) -> Result<LiveBench, CliError> {
    if !(seconds.is_finite() && (0.1..=600.0).contains(&seconds)) {
        return Err(CliError(format!(
            "--seconds must be 0.1 to 600, got {seconds}"
        )));
    }
    let every = u64::from((1000 / rate).max(1));
    let streams = live_streams(name, sessions, seconds, every, assist)?;
    let dir = tempfile::tempdir().map_err(|e| CliError(format!("temporary directory: {e}")))?;
    crate::memory::limit_arenas();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let server_rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("starting the async runtime: {e}")))?;
    let args = crate::config::ServeArgs {
        addr: std::net::SocketAddr::from(([127, 0, 0, 1], 0)),
        store: crate::config::StoreArgs::in_dir(dir.path().join("data")),
        no_demo: true,
        ..crate::config::ServeArgs::default()
    };
    if assist {
        store_live_skills(dir.path(), name)?;
    }
    let config = args.into_config()?;
    let live_threads = config.state.live_threads;
    let app = server_rt.block_on(crate::startup::Application::build(config))?;
    let url = format!("ws://{}/api/v1/live", app.local_addr());
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = server_rt.spawn(app.run_until(async move {
        let _ = stopped.await;
    }));
    // The clients on a runtime of their own, as a glove's driver would be a process of its
    // own.
    let client_rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("starting the client runtime: {e}")))?;
    let load_before = load_average();
    let results = client_rt.block_on(stream_live(&url, streams));
    let load_after = load_average();
    let _ = stop.send(());
    server_rt
        .block_on(server)
        .map_err(|e| CliError(format!("the server task: {e}")))??;
    let totals = LiveTotals::of(results)?;
    let all = &totals.round_trips_us;
    let p = |q| crate::live_client::percentile(all, q);
    Ok(LiveBench {
        p50_us: p(0.5),
        p90_us: p(0.9),
        p99_us: p(0.99),
        p999_us: p(0.999),
        max_us: all.last().copied().unwrap_or(0.0),
        samples: totals.samples,
        dropped: totals.samples - totals.answered - totals.refused,
        refused: totals.refused,
        sessions,
        rate_hz: rate,
        seconds,
        realtime: true,
        assist,
        live_threads,
        cores,
        load_before,
        load_after,
        stored: totals.stored,
    })
}

/// The start message and the simulated glove frames (a sample every `every` ms for `seconds`)
/// of each of `sessions` live sessions of scenario `name`, seeds 0 on.
fn live_streams(
    name: &str,
    sessions: usize,
    seconds: f64,
    every: u64,
    assist: bool,
) -> Result<Vec<LiveStream>, CliError> {
    let mut streams = Vec::new();
    for seed in 0..sessions as u64 {
        let scenario = dfs_core::scenario::Scenario::builtin(name, seed)
            .ok_or_else(|| CliError(format!("no built-in scenario {name:?}")))?;
        let frames = crate::live_client::simulated_frames(&scenario, Some(seconds), every)
            .map_err(|e| CliError(e.0))?;
        let start = services::live::StartMessage {
            hand: "glove10".to_owned(),
            object: scenario.object.clone(),
            objects: scenario.objects.clone(),
            target: scenario.target.clone(),
            name: Some(format!("bench-live-{seed}")),
            wrist: None,
            assist: services::live::AssistSettings {
                mode: if assist {
                    services::live::AssistMode::Suggest
                } else {
                    services::live::AssistMode::Off
                },
                robot: None,
            },
            calibration: None,
            whole_hand: false,
        };
        streams.push((start, frames));
    }
    Ok(streams)
}

/// Skills for the assistant to recognise: three sessions of scenario `name` (seeds 100-102)
/// stored in the data directory under `dir`, before the server starts.
fn store_live_skills(dir: &std::path::Path, name: &str) -> Result<(), CliError> {
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let store = services::store::Store::open(&dir.join("data")).await?;
        for seed in 100..103 {
            let scenario = dfs_core::scenario::Scenario::builtin(name, seed)
                .ok_or_else(|| CliError(format!("no built-in scenario {name:?}")))?;
            let path = dir.join(format!("stored-{seed}.mcap"));
            services::session::record_simulation(&scenario, None, path.as_path(), |_, _| {})?;
            services::ingest::ingest_file(&store, path, format!("stored-{seed}")).await?;
        }
        store.close().await;
        Ok::<_, CliError>(())
    })
}

/// Streams every session to the live route at `url` at once, one task each, in real time;
/// each task's outcome, in order.
async fn stream_live(url: &str, streams: Vec<LiveStream>) -> Vec<ClientOutcome> {
    let mut tasks = Vec::new();
    for (start, frames) in streams {
        let url = url.to_owned();
        tasks.push(tokio::spawn(async move {
            let options = crate::live_client::ClientOptions {
                token: None,
                realtime: true,
            };
            crate::live_client::run(&url, &start, frames, &options, |_| {}).await
        }));
    }
    let mut out = Vec::new();
    for t in tasks {
        out.push(t.await);
    }
    out
}

/// The live sessions' counts, all together.
struct LiveTotals {
    /// Samples sent.
    samples: u64,
    /// Feedback frames received.
    answered: u64,
    /// Samples refused.
    refused: u64,
    /// Sessions stored.
    stored: usize,
    /// Every round trip (µs), sorted.
    round_trips_us: Vec<f64>,
}

impl LiveTotals {
    /// Adds up the clients' summaries; the first failed client is the error.
    fn of(results: Vec<ClientOutcome>) -> Result<LiveTotals, CliError> {
        let mut all = Vec::new();
        let (mut samples, mut answered, mut refused, mut stored) = (0, 0, 0, 0);
        for r in results {
            let s = r
                .map_err(|e| CliError(format!("a live client task: {e}")))?
                .map_err(|e| CliError(e.0))?;
            samples += s.samples_sent;
            answered += s.feedback_received;
            refused += s.refused;
            stored += usize::from(s.session_id.is_some());
            all.extend(s.round_trips_us);
        }
        all.sort_by(f64::total_cmp);
        Ok(LiveTotals {
            samples,
            answered,
            refused,
            stored,
            round_trips_us: all,
        })
    }
}

/// A live session to stream: its start message and its glove frames.
type LiveStream = (services::live::StartMessage, Vec<crate::live_client::Frame>);

/// How a live client's task ended.
type ClientOutcome = Result<
    Result<crate::live_client::ClientSummary, crate::live_client::ClientError>,
    tokio::task::JoinError,
>;

fn bench_upload(name: &str, uploads: u64, duration: f64) -> Result<UploadBench, CliError> {
    let dir = tempfile::tempdir().map_err(|e| CliError(format!("temporary directory: {e}")))?;
    let mut files = Vec::new();
    for seed in 1..=uploads {
        let scenario = dfs_core::scenario::Scenario::builtin(name, seed)
            .ok_or_else(|| CliError(format!("no built-in scenario {name:?}")))?;
        let path = dir.path().join(format!("{seed}.mcap"));
        services::session::record_simulation(&scenario, Some(duration), &path, |_, _| {})?;
        files.push(path);
    }
    // As `icms serve` runs: its allocator setting, a multi-threaded runtime.
    crate::memory::limit_arenas();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("starting the async runtime: {e}")))?;
    let mut times = rt.block_on(async {
        let config = crate::config::ServeArgs {
            addr: std::net::SocketAddr::from(([127, 0, 0, 1], 0)),
            store: crate::config::StoreArgs::in_dir(dir.path().join("data")),
            no_demo: true,
            ..crate::config::ServeArgs::default()
        }
        .into_config()?;
        let app = crate::startup::Application::build(config).await?;
        let addr = app.local_addr();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let server = tokio::spawn(app.run_until(async move {
            let _ = stopped.await;
        }));
        let mut times = Vec::new();
        let mut failed = None;
        for path in &files {
            let body = bytes::Bytes::from(
                tokio::fs::read(path)
                    .await
                    .map_err(|e| CliError(format!("{}: {e}", path.display())))?,
            );
            let t0 = Instant::now();
            let reply = post_session(addr, body).await;
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            match reply {
                Ok((201, _)) => times.push(ms),
                Ok((status, body)) => {
                    failed = Some(format!(
                        "{}: the upload got {status}: {}",
                        path.display(),
                        String::from_utf8_lossy(&body)
                    ));
                    break;
                }
                Err(e) => {
                    failed = Some(format!("{}: {}", path.display(), e.0));
                    break;
                }
            }
        }
        let _ = stop.send(());
        server
            .await
            .map_err(|e| CliError(format!("the server task: {e}")))??;
        match failed {
            Some(e) => Err(CliError(e)),
            None => Ok(times),
        }
    })?;
    let uploads_ms = times.clone();
    let mut analyse = Vec::new();
    for path in &files {
        let t0 = Instant::now();
        services::ingest::analyse_source(&services::session::SessionSource::File(path))?;
        analyse.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    let mut sizes: Vec<u64> = files
        .iter()
        .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0))
        .collect();
    sizes.sort_unstable();
    Ok(UploadBench {
        median_ms: services::segmentation::median(&mut times),
        min_ms: uploads_ms.iter().copied().fold(f64::INFINITY, f64::min),
        max_ms: uploads_ms.iter().copied().fold(0.0, f64::max),
        uploads_ms,
        analyse_ms: services::segmentation::median(&mut analyse),
        file_bytes: sizes[sizes.len() / 2],
        uploads,
        duration,
        scenario: name.to_string(),
    })
}

/// `POST /api/v1/sessions` of `body` to the server at `addr` on a new connection, as
/// `curl --data-binary @FILE -H 'content-type: application/x-mcap'` sends it: the reply's
/// status and body.
async fn post_session(
    addr: std::net::SocketAddr,
    body: bytes::Bytes,
) -> Result<(u16, bytes::Bytes), CliError> {
    use axum::http::{header, Request};
    use http_body_util::{BodyExt, Full};
    let stream = tokio::net::TcpStream::connect(addr)
        .await
        .map_err(|e| CliError(format!("connecting to {addr}: {e}")))?;
    stream
        .set_nodelay(true)
        .map_err(|e| CliError(format!("TCP_NODELAY: {e}")))?;
    let (mut sender, connection) =
        hyper::client::conn::http1::handshake(hyper_util::rt::TokioIo::new(stream))
            .await
            .map_err(|e| CliError(format!("HTTP handshake with {addr}: {e}")))?;
    let connection = tokio::spawn(connection);
    let request = Request::post("/api/v1/sessions")
        .header(header::HOST, addr.to_string())
        .header(header::CONTENT_TYPE, crate::http::sessions::MCAP)
        .body(Full::new(body))
        .map_err(|e| CliError(format!("building the request: {e}")))?;
    let reply = sender
        .send_request(request)
        .await
        .map_err(|e| CliError(format!("uploading: {e}")))?;
    let status = reply.status().as_u16();
    let body = reply
        .into_body()
        .collect()
        .await
        .map_err(|e| CliError(format!("reading the reply: {e}")))?
        .to_bytes();
    drop(sender);
    let _ = connection.await;
    Ok((status, body))
}

/// The grasp kinds `icms bench recognition` stores and recognises: the built-in scenarios of
/// one grasp each (a scene of three objects among them).
const RECOGNITION_KINDS: [&str; 4] = [
    "sphere-lift",
    "box-pinch-lift",
    "cylinder-power-grasp",
    "table-three",
];

fn bench_recognition(
    train: u64,
    test: u64,
    stored: usize,
) -> Result<services::assist::evaluate::Evaluation, CliError> {
    use dfs_core::scenario::Scenario;
    let dir = tempfile::tempdir()?;
    let scenarios = |seeds: std::ops::Range<u64>| -> Vec<Scenario> {
        RECOGNITION_KINDS
            .iter()
            .flat_map(|k| {
                seeds
                    .clone()
                    .filter_map(move |s| recognition_scenario(k, s))
            })
            .collect()
    };
    let mut progress = |done: usize, total: usize| {
        eprint!("\rsessions recorded: {done}/{total}");
        if done == total {
            eprintln!();
        }
    };
    Ok(services::assist::evaluate::evaluate(
        services::assist::evaluate::EvalSetup {
            train: scenarios(1..1 + train),
            // Held-out seeds: never among the training ones.
            test: scenarios(1000..1000 + test),
            dir: dir.path(),
            params: services::assist::recognise::RecogniserParams::default(),
            cost_skills: Some(stored),
            progress: &mut progress,
        },
    )?)
}

/// The scenario of a grasp kind for a seed: the built-in scenario's variant (object size,
/// mass and μ perturbed, the target of `table-three` drawn, a varied reach: see
/// `dfs_core::scenario::Scenario::variant`), so that no two sessions are alike.
fn recognition_scenario(kind: &str, seed: u64) -> Option<dfs_core::scenario::Scenario> {
    dfs_core::scenario::Scenario::variant(kind, seed)
}
