//! `icms bench store`: the skill data base alone, on synthetic data in a fresh data directory
//! (no simulation, no segmentation): storing sessions, generating a large store, filtered
//! queries, k-nearest search and opening the store again.

use std::path::PathBuf;
use std::time::Instant;

use serde::Serialize;
use services::store::bench::{
    generate_synthetic, synthetic_blob, synthetic_skill, time_filtered_queries, time_nearest,
    SplitMix64, Timing,
};
use services::store::{Database, NewSkill, SessionMeta, Store};

use crate::cli::CliError;

/// Sessions stored one by one for the ingest figures, for each of the two blob sizes.
const INGESTED_SESSIONS: u64 = 50;
/// Blob sizes of the ingest figures: a short session and a long one (bytes).
const BLOB_SIZES: [(&str, usize); 2] = [("200 KiB", 200 * 1024), ("2 MiB", 2 * 1024 * 1024)];
/// Filtered queries timed.
const QUERIES: usize = 1000;
/// k-nearest searches timed, and their k.
const NEAREST: (usize, usize) = (200, 10);

/// Store ingest of one blob size.
#[derive(Debug, Serialize)]
pub struct IngestFigure {
    /// The blob size, as printed (`200 KiB`).
    pub label: &'static str,
    /// Bytes of each blob.
    pub blob_bytes: usize,
    /// Sessions (2 skills each) stored one after the other, one transaction each, per second.
    pub sessions_per_second: f64,
}

/// Result of `icms bench store`.
#[derive(Debug, Serialize)]
pub struct StoreBench {
    /// Where the rows were (`SQLite (...)` or `PostgreSQL at postgres://...`, password hidden).
    pub database: String,
    /// Storing 50 sessions of 2 skills, for each blob size (the store's part of an ingest:
    /// blob written and synced, rows committed; no reading or segmentation).
    pub ingest: Vec<IngestFigure>,
    /// Synthetic skills generated into the store.
    pub skills: usize,
    /// Seconds to generate them (bulk transactions).
    pub generate_seconds: f64,
    /// Random filtered queries (shape, a mass window, a minimum quality, best first, 50 a
    /// page) over the whole store.
    pub filtered_query: Timing,
    /// k-nearest searches (k = 10) for random feature vectors.
    pub nearest: Timing,
    /// Seconds to open the store again, loading its k-nearest index.
    pub reopen_seconds: f64,
}

/// Runs the benchmark with `skills` synthetic skills in a temporary directory under `dir`
/// (the system's temporary directory by default), kept afterwards when `keep`, with the rows
/// in `database` (a PostgreSQL data base must be empty: the bench fills it).
pub fn bench_store(
    skills: usize,
    dir: Option<PathBuf>,
    keep: bool,
    database: &Database,
) -> Result<StoreBench, CliError> {
    let parent = dir.unwrap_or_else(std::env::temp_dir);
    let tmp = tempfile::tempdir_in(&parent).map_err(|e| {
        CliError(format!(
            "a temporary directory in {}: {e}",
            parent.display()
        ))
    })?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("starting the async runtime: {e}")))?;
    let result = rt.block_on(async {
        let store = Store::open_in(tmp.path(), database).await?;
        if store.skill_count() > 0 {
            store.close().await;
            return Err(CliError(format!(
                "{} already holds {} skills: the bench needs an empty data base",
                database.describe(),
                store.skill_count()
            )));
        }
        let mut ingest = Vec::new();
        for (k, &(label, size)) in BLOB_SIZES.iter().enumerate() {
            let files: Vec<Vec<u8>> = (0..INGESTED_SESSIONS)
                .map(|i| synthetic_blob(k as u64 * 1_000_000 + i, size))
                .collect();
            let t = Instant::now();
            for (i, f) in files.iter().enumerate() {
                let seed = k as u64 * 1_000_000 + i as u64;
                store
                    .ingest(f, session_meta(seed), two_skills(seed))
                    .await?;
            }
            ingest.push(IngestFigure {
                label,
                blob_bytes: size,
                sessions_per_second: INGESTED_SESSIONS as f64 / t.elapsed().as_secs_f64(),
            });
        }
        let generated = generate_synthetic(&store, skills, 1).await?;
        let filtered_query = time_filtered_queries(&store, QUERIES, 2).await?;
        let nearest = time_nearest(&store, NEAREST.0, NEAREST.1, 3)?;
        drop(store);
        let t = Instant::now();
        let store = Store::open_in(tmp.path(), database).await?;
        let reopen_seconds = t.elapsed().as_secs_f64();
        store.close().await;
        Ok::<_, CliError>(StoreBench {
            database: database.describe(),
            ingest,
            skills: generated.skills,
            generate_seconds: generated.elapsed_s,
            filtered_query,
            nearest,
            reopen_seconds,
        })
    });
    if keep {
        let kept = tmp.keep();
        eprintln!("kept the data directory {}", kept.display());
    }
    result
}

/// Prints `r` for people.
pub fn print(r: &StoreBench) {
    println!("store: {}", r.database);
    for i in &r.ingest {
        println!(
            "store ingest: {INGESTED_SESSIONS} sessions of {} with 2 skills each: {:.0} sessions/s",
            i.label, i.sessions_per_second
        );
    }
    println!(
        "generate: {} skills in {:.1} s ({:.0} skills/s)",
        r.skills,
        r.generate_seconds,
        r.skills as f64 / r.generate_seconds
    );
    let line = |what: &str, t: &Timing| {
        println!(
            "{what} over {} skills: p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms ({} timed)",
            r.skills, t.p50_ms, t.p99_ms, t.max_ms, t.n
        );
    };
    line("filtered query", &r.filtered_query);
    line(&format!("nearest k={}", NEAREST.1), &r.nearest);
    println!("reopen with index load: {:.3} s", r.reopen_seconds);
}

fn session_meta(seed: u64) -> SessionMeta {
    SessionMeta {
        scenario: Some("bench-store".into()),
        seed: Some(seed),
        hand: "glove10".into(),
        object_shape: dfs_core::object::ShapeKind::Sphere.into(),
        object_mass: 0.5,
        mu: 0.8,
        duration_ns: 10_000_000_000,
        started_at: None,
        extra: serde_json::Value::Null,
    }
}

fn two_skills(seed: u64) -> Vec<NewSkill> {
    let mut rng = SplitMix64::new(seed);
    (0..2).map(|_| synthetic_skill(&mut rng)).collect()
}
