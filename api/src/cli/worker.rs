//! `icms worker`: runs simulation and replay jobs from a data base without serving HTTP, to add
//! a machine's cores to the servers' (docs/backends.md, "Work spread over machines").

use std::path::PathBuf;
use std::sync::Arc;

use services::store::{Blobs, Database, Store, JOB_LEASE};
use tokio_util::sync::CancellationToken;

use super::CliError;
use crate::config::{blob_cache_bytes, DEFAULT_BLOB_CACHE_MIB, MAX_WORKERS};
use crate::jobs::{spawn_workers, JobSignals, WorkerConfig};
use crate::startup::{shutdown_signal, trim_blob_copies};

/// Arguments of `icms worker`.
#[derive(Debug, Clone, clap::Args)]
pub struct WorkerArgs {
    /// Data directory: with --database-url it holds the MCAP blobs (with --blobs, copies of
    /// them); without, its SQLite data base, which no `icms serve` may have open.
    #[arg(long, default_value = "icms-data")]
    pub data: PathBuf,
    /// The servers' PostgreSQL data base (postgres://user:password@host:port/dbname).
    #[arg(long, env = "DATABASE_URL", hide_env_values = true, value_name = "URL")]
    pub database_url: Option<String>,
    /// The servers' bucket (s3://bucket/prefix); endpoint and credentials from AWS_ENDPOINT_URL,
    /// AWS_REGION, AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY.
    #[arg(long, env = "ICMS_BLOBS", value_name = "URL")]
    pub blobs: Option<String>,
    /// MiB of the data directory the copies of the bucket's files may take: past it, the
    /// least recently used copies (unused for 10 minutes) are removed.
    #[arg(long, default_value_t = DEFAULT_BLOB_CACHE_MIB)]
    pub blob_cache_mib: u64,
    /// Jobs run at once. Default: the number of cores.
    #[arg(long)]
    pub workers: Option<usize>,
    /// Longest a job may run, seconds: then it is stopped and failed (503), nothing stored.
    #[arg(long, default_value_t = 600.0)]
    pub job_timeout: f64,
    /// Seconds a claim on a job lasts without renewal (renewed every third of it, at least
    /// every second): a job whose worker died is taken by another this long after.
    #[arg(long, default_value_t = JOB_LEASE.as_secs_f64())]
    pub lease: f64,
}

/// Runs jobs until SIGINT or SIGTERM; then the jobs in hand are stopped and go back to the
/// queue, and the data base is closed.
pub fn run_worker(a: WorkerArgs) -> Result<(), CliError> {
    crate::telemetry::init();
    let database = Database::from_url(a.database_url.as_deref())?;
    let blobs = Blobs::from_arg(a.blobs.as_deref())?;
    let cache_bytes = blob_cache_bytes(a.blob_cache_mib)?;
    let count = a
        .workers
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()));
    if !(1..=MAX_WORKERS).contains(&count) {
        return Err(CliError(format!(
            "--workers must be in 1..={MAX_WORKERS}, got {count}"
        )));
    }
    let seconds = |option: &str, v: f64, min: f64| {
        if v.is_finite() && v >= min && v <= 86_400.0 {
            Ok(std::time::Duration::from_secs_f64(v))
        } else {
            Err(CliError(format!(
                "{option} must be a number of seconds in [{min}, 86400], got {v}"
            )))
        }
    };
    let config = WorkerConfig {
        count,
        job_timeout: seconds("--job-timeout", a.job_timeout, 0.001)?,
        lease: seconds("--lease", a.lease, 1.0)?,
    };
    if matches!(database, Database::Postgres(_)) && matches!(blobs, Blobs::Local) {
        return Err(CliError(
            "icms worker on a PostgreSQL data base needs the servers' bucket (--blobs \
             s3://bucket/prefix): the session and replay files it stores must be where every \
             server reads them, and its data directory is its own"
                .into(),
        ));
    }
    crate::memory::limit_arenas();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("tokio: {e}")))?;
    rt.block_on(async {
        let store = Store::open_on(&a.data, &database, &blobs)
            .await
            .map_err(|e| CliError(format!("{}: {e}", a.data.display())))?;
        tracing::info!(database = %database.describe(), blobs = %blobs.describe(), workers = count,
            "icms worker: running jobs; Ctrl-C stops");
        eprintln!(
            "icms worker: running up to {count} jobs at once from {}; Ctrl-C stops",
            database.describe()
        );
        let stop = CancellationToken::new();
        let mut workers = spawn_workers(&store, &config, &Arc::new(JobSignals::default()), &stop);
        let trimming = {
            let store = store.clone();
            let stop = stop.clone();
            tokio::spawn(async move { trim_blob_copies(&store, cache_bytes, &stop).await })
        };
        shutdown_signal().await;
        tracing::info!("shutting down: the jobs in hand go back to the queue");
        stop.cancel();
        while workers.join_next().await.is_some() {}
        let _ = trimming.await;
        store.close().await;
        tracing::info!("database closed; stopped");
        Ok(())
    })
}
