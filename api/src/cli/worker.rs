//! `icms worker`: runs simulation and replay jobs from a data base without serving HTTP, to add
//! a machine's cores to the servers' (docs/backends.md, "Work spread over machines").

use std::sync::Arc;
use std::time::Duration;

use services::store::{Blobs, Database, Store, JOB_LEASE};
use tokio_util::sync::CancellationToken;

use super::{server_runtime, CliError};
use crate::config::{count, seconds, StoreArgs, MAX_WORKERS};
use crate::jobs::{spawn_workers, JobSignals, WorkerConfig};
use crate::startup::{shutdown_signal, trim_blob_copies};

/// Arguments of `icms worker`.
#[derive(Debug, Clone, clap::Args)]
pub struct WorkerArgs {
    /// The servers' data base and bucket (with PostgreSQL, --blobs is needed), and this
    /// worker's own data directory.
    #[command(flatten)]
    pub store: StoreArgs,
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

/// Shortest `--lease`.
const MIN_LEASE: Duration = Duration::from_secs(1);

/// Runs jobs until SIGINT or SIGTERM; then the jobs in hand are stopped and go back to the
/// queue, and the data base is closed.
pub fn run_worker(a: WorkerArgs) -> Result<(), CliError> {
    crate::telemetry::init();
    let (database, blobs, cache_bytes) = a.store.resolve()?;
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let count = count("--workers", a.workers.unwrap_or(cores), 1, MAX_WORKERS)?;
    let lease = seconds("--lease", a.lease)?;
    if lease < MIN_LEASE {
        return Err(CliError(format!(
            "--lease must be at least {} s (a claim is renewed every third of it), got {}",
            MIN_LEASE.as_secs_f64(),
            a.lease
        )));
    }
    let config = WorkerConfig {
        count,
        job_timeout: seconds("--job-timeout", a.job_timeout)?,
        lease,
    };
    if matches!(database, Database::Postgres(_)) && matches!(blobs, Blobs::Local) {
        return Err(CliError(
            "icms worker on a PostgreSQL data base needs the servers' bucket (--blobs \
             s3://bucket/prefix): the session and replay files it stores must be where every \
             server reads them, and its data directory is its own"
                .into(),
        ));
    }
    let data = &a.store.at.data;
    server_runtime()?.block_on(async {
        let store = Store::open_on(data, &database, &blobs)
            .await
            .map_err(|e| CliError(format!("{}: {e}", data.display())))?;
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
