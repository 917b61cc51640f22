//! `icms bench jobs`: replay jobs run by one worker, then by two (issue 24: "100 replay jobs
//! finish ≥ 1.7× faster with two workers than with one").
//!
//! Each round gets a store of its own (a fresh schema of the PostgreSQL data base given, or a
//! temporary SQLite data directory) seeded the same way: the built-in scenarios simulated
//! (seeds 0, 1, … until there are skills enough; not timed) and their skills stored. Then `--jobs` replay jobs (skill × built-in
//! hand, in order) are submitted and the round's workers (the same code `icms worker` and
//! `icms serve` run, in this process, each on its own thread of the blocking pool) started;
//! the time is from their start until every job has ended.

use std::sync::Arc;
use std::time::{Duration, Instant};

use dfs_core::scenario::Scenario;
use serde::Serialize;
use services::store::{Blobs, Database, JobRequest, JobState, Store, JOB_LEASE};
use sqlx::Connection as _;
use tokio_util::sync::CancellationToken;

use services::replay::skill_spec_from_json;

use crate::cli::CliError;
use crate::jobs::{simulate_blocking, spawn_workers, JobSignals, WorkerConfig};

/// One round: `workers` workers on the jobs.
#[derive(Debug, Serialize)]
pub struct Round {
    /// Workers.
    pub workers: usize,
    /// Seconds from the workers' start to the last job's end.
    pub seconds: f64,
    /// Jobs per second.
    pub jobs_per_second: f64,
    /// Jobs that ended done (the others failed: none should).
    pub done: usize,
    /// CPU time this process used during the round over its wall time: how many cores the
    /// workers kept busy (a replay records through a pipeline of threads, so one worker keeps
    /// more than one busy). `None` without `/proc`.
    pub cores_busy: Option<f64>,
}

/// The figures of `icms bench jobs`.
#[derive(Debug, Serialize)]
pub struct JobsBench {
    /// Replay jobs per round.
    pub jobs: usize,
    /// The backend: `SQLite` or `PostgreSQL`.
    pub backend: String,
    /// The rounds, one worker then two.
    pub rounds: Vec<Round>,
    /// Time with one worker over time with two.
    pub speedup: f64,
    /// The most two workers could gain over one on this machine's cores: its cores over the
    /// cores one worker kept busy (at most 2).
    pub ceiling: Option<f64>,
    /// Cores of this machine.
    pub cores: usize,
}

/// Runs the bench: `jobs` replay jobs, one worker then two, on `database` (an empty PostgreSQL
/// data base, in schemas the bench makes and drops; `None`: temporary SQLite data directories).
pub fn bench_jobs(jobs: usize, database_url: Option<&str>) -> Result<JobsBench, CliError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("tokio: {e}")))?;
    rt.block_on(async {
        let mut rounds = Vec::new();
        for workers in [1, 2] {
            let tmp = tempfile::tempdir()?;
            let (database, schema) = match database_url {
                None => (Database::Sqlite, None),
                Some(url) => {
                    let schema = format!("icms_bench_jobs_{}_{workers}", std::process::id());
                    (
                        Database::Postgres(in_schema(url, &schema).await?),
                        Some(schema),
                    )
                }
            };
            let store = Store::open_on(tmp.path(), &database, &Blobs::Local).await?;
            let round = round(&store, jobs, workers).await;
            store.close().await;
            if let (Some(url), Some(schema)) = (database_url, schema) {
                let mut conn = sqlx::PgConnection::connect(url).await?;
                sqlx::query(&format!("DROP SCHEMA {schema} CASCADE"))
                    .execute(&mut conn)
                    .await?;
                conn.close().await?;
            }
            rounds.push(round?);
        }
        let speedup = rounds[0].seconds / rounds[1].seconds;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let ceiling = rounds[0]
            .cores_busy
            .map(|busy| (cores as f64 / busy).min(2.0));
        Ok(JobsBench {
            jobs,
            backend: match database_url {
                None => "SQLite".into(),
                Some(_) => "PostgreSQL".into(),
            },
            rounds,
            speedup,
            ceiling,
            cores,
        })
    })
}

/// `url` with a fresh schema `schema` as its search path.
async fn in_schema(url: &str, schema: &str) -> Result<String, CliError> {
    let mut conn = sqlx::PgConnection::connect(url).await?;
    for q in [
        format!("DROP SCHEMA IF EXISTS {schema} CASCADE"),
        format!("CREATE SCHEMA {schema}"),
    ] {
        sqlx::query(&q).execute(&mut conn).await?;
    }
    conn.close().await?;
    let sep = if url.contains('?') { '&' } else { '?' };
    Ok(format!("{url}{sep}options=-c%20search_path%3D{schema}"))
}

/// Seeds `store`, submits `jobs` replay jobs and times `workers` workers on them.
async fn round(store: &Store, jobs: usize, workers: usize) -> Result<Round, CliError> {
    let hands = dfs_core::hand::BUILTIN_HANDS;
    let mut skills = Vec::new();
    // Seeds 0, 1, … of every built-in scenario until there are skills enough.
    'seeding: for seed in 0..100 {
        for name in Scenario::BUILTINS {
            if skills.len() * hands.len() >= jobs {
                break 'seeding;
            }
            let scenario = Scenario::builtin(name, seed).expect("a built-in scenario");
            let s = store.clone();
            let (staged, meta, new) = tokio::task::spawn_blocking(move || {
                simulate_blocking(&s, &scenario, None, &dfs_core::Stop::new())
            })
            .await?
            .map_err(|p| CliError(p.detail))?;
            for id in store.ingest_staged(staged, meta, new).await?.skill_ids {
                // Whole-hand skills do not replay on robot hands yet (issue 21): left out.
                let params = store.get_skill(id).await?.params;
                if skill_spec_from_json(&params, "skill").is_ok() {
                    skills.push(id);
                }
            }
        }
    }
    let requests: Vec<JobRequest> = skills
        .iter()
        .flat_map(|&skill_id| {
            hands.iter().map(move |h| JobRequest::Replay {
                skill_id,
                hand: (*h).to_owned(),
            })
        })
        .take(jobs)
        .collect();
    for r in &requests {
        store.submit_job(r, u64::MAX).await?;
    }
    let config = WorkerConfig {
        count: workers,
        job_timeout: Duration::from_secs(600),
        lease: JOB_LEASE,
    };
    let stop = CancellationToken::new();
    let cpu_before = cpu_seconds();
    let start = Instant::now();
    let mut set = spawn_workers(store, &config, &Arc::new(JobSignals::default()), &stop);
    loop {
        let open = store.jobs(Some(JobState::Queued), None, 1).await?.len()
            + store.jobs(Some(JobState::Running), None, 1).await?.len();
        if open == 0 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let seconds = start.elapsed().as_secs_f64();
    let cores_busy = cpu_seconds()
        .zip(cpu_before)
        .map(|(b, a)| (b - a) / seconds);
    stop.cancel();
    while set.join_next().await.is_some() {}
    let mut done = 0;
    let mut before = None;
    loop {
        let page = store.jobs(Some(JobState::Done), before, 200).await?;
        done += page.len();
        match page.last() {
            Some(j) if page.len() == 200 => before = Some(j.id),
            _ => break,
        }
    }
    for j in store.jobs(Some(JobState::Failed), None, 3).await? {
        eprintln!("  failed: {:?}: {:?}", j.request, j.error);
    }
    eprintln!("  {workers} worker(s): {jobs} replay jobs in {seconds:.2} s ({done} done)");
    Ok(Round {
        workers,
        seconds,
        jobs_per_second: jobs as f64 / seconds,
        done,
        cores_busy,
    })
}

/// CPU time this process used so far (user and system), seconds, from `/proc/self/stat`
/// (`None` where there is none). In clock ticks of 1/100 s, the kernel's USER_HZ on Linux.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name, which is in parentheses and may hold spaces.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split(' ').collect();
    // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name.
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// Prints the figures.
pub fn print(r: &JobsBench) {
    for round in &r.rounds {
        println!(
            "{} replay jobs on {}, {} worker(s): {:.2} s, {:.1} jobs/s ({} done), {} cores busy",
            r.jobs,
            r.backend,
            round.workers,
            round.seconds,
            round.jobs_per_second,
            round.done,
            round
                .cores_busy
                .map_or_else(|| "?".to_owned(), |c| format!("{c:.2}"))
        );
    }
    println!(
        "two workers finish {:.2}x faster than one (target >= 1.7x); on {} cores, with one \
         worker keeping {} busy, two can gain at most {}",
        r.speedup,
        r.cores,
        r.rounds[0]
            .cores_busy
            .map_or_else(|| "?".to_owned(), |c| format!("{c:.2}")),
        r.ceiling
            .map_or_else(|| "?".to_owned(), |c| format!("{c:.2}x"))
    );
}
