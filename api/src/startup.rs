//! Starting and stopping the server: open (create, migrate) the store, bind, serve until a
//! shutdown signal, seed an empty data base in the background, and on shutdown let in-flight
//! requests finish and close the database cleanly.

use std::future::Future;
use std::net::SocketAddr;

use axum::Router;
use dfs_core::scenario::Scenario;
use services::store::{JobRequest, Store, StoreError};
use tokio::net::TcpListener;
use tokio_util::sync::CancellationToken;

use crate::config::ServeConfig;
use crate::http::server::ConnectionLimits;
use crate::http::{self, AppState};
use crate::jobs::{self, WorkerConfig};

/// Why the server could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum StartupError {
    /// The store could not be opened (not ours, too new, unreadable ...).
    #[error("{path}: {source}")]
    Store {
        /// The data directory.
        path: String,
        /// Why.
        #[source]
        source: StoreError,
    },
    /// The address could not be bound, or serving failed.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

/// A bound, ready server. [`Application::run_until`] serves it.
pub struct Application {
    listener: TcpListener,
    addr: SocketAddr,
    router: Router,
    state: AppState,
    demo: bool,
    connections: ConnectionLimits,
    workers: WorkerConfig,
    blob_cache_bytes: u64,
    foxglove: Option<foxglove::WebSocketServerHandle>,
}

/// Longest wait at shutdown for the live sessions to be finished and stored.
pub const LIVE_STORE_GRACE: std::time::Duration = std::time::Duration::from_secs(30);

/// How often the server and `icms worker` trim the copies of a bucket's blobs.
pub const TRIM_INTERVAL: std::time::Duration = std::time::Duration::from_secs(60);

/// How often the server sweeps unreferenced blobs (besides once at start-up).
pub const SWEEP_INTERVAL: std::time::Duration = std::time::Duration::from_secs(3600);

impl std::fmt::Debug for Application {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Application")
            .field("addr", &self.addr)
            .field("state", &self.state)
            .finish_non_exhaustive()
    }
}

impl Application {
    /// Opens the store in `config.data` (creating and migrating it), builds the router and
    /// binds `config.addr` (port 0: a free port, see [`Application::local_addr`]).
    pub async fn build(config: ServeConfig) -> Result<Application, StartupError> {
        let store = Store::open_on(&config.data, &config.database, &config.blobs)
            .await
            .map_err(|source| StartupError::Store {
                path: config.data.display().to_string(),
                source,
            })?;
        tracing::info!(database = %config.database.describe(), blobs = %config.blobs.describe(),
            "store opened");
        let state = AppState::new(store, &config.state).map_err(|source| StartupError::Io {
            context: "starting the live stepping threads".into(),
            source,
        })?;
        // Skills changed through any server on the same data base leave the cache (a
        // PostgreSQL store tells them; see SkillCache::follow).
        state.cache().follow(state.store().skill_changes());
        clear_scratch(state.scratch_dir()).await;
        let foxglove = match config.foxglove {
            None => None,
            Some(addr) => {
                let context = foxglove::Context::new();
                let server = foxglove::WebSocketServer::new()
                    .name("icms live sessions")
                    .bind(addr.ip().to_string(), addr.port())
                    .context(&context)
                    .start()
                    .await
                    .map_err(|e| StartupError::Io {
                        context: format!("starting the Foxglove WebSocket server on {addr}"),
                        source: std::io::Error::other(e.to_string()),
                    })?;
                tracing::info!(addr = %addr, port = server.port(),
                    "publishing live sessions to Foxglove (Open connection → Foxglove WebSocket)");
                state.live().publish_to(context);
                Some(server)
            }
        };
        let router = http::app(state.clone(), &config.layers);
        let listener = TcpListener::bind(config.addr)
            .await
            .map_err(|source| StartupError::Io {
                context: format!("binding {}", config.addr),
                source,
            })?;
        let addr = listener.local_addr().map_err(|source| StartupError::Io {
            context: "reading the bound address".into(),
            source,
        })?;
        Ok(Application {
            listener,
            addr,
            router,
            state,
            demo: config.demo,
            connections: config.connections,
            workers: config.workers,
            blob_cache_bytes: config.blob_cache_bytes,
            foxglove,
        })
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The port of the Foxglove WebSocket server (`--foxglove`), if one runs.
    pub fn foxglove_port(&self) -> Option<u16> {
        self.foxglove.as_ref().map(|s| s.port())
    }

    /// The handlers' state (its store is the server's).
    pub fn state(&self) -> &AppState {
        &self.state
    }

    /// Serves until `shutdown` completes, then stops accepting, tells the job workers to stop
    /// (their running simulations and replays end within a fraction of a second and go back to
    /// the queue, for the next server or worker), waits at most the shutdown grace for open
    /// connections, and closes the database.
    pub async fn run_until(
        self,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> Result<(), StartupError> {
        let stopping = self.state.shutdown_token().clone();
        let mut workers = jobs::spawn_workers(
            self.state.store(),
            &self.workers,
            self.state.jobs(),
            &stopping,
        );
        tracing::info!(
            workers = self.workers.count,
            job_timeout_s = self.workers.job_timeout.as_secs_f64(),
            "job workers started"
        );
        let seeding = if self.demo {
            let state = self.state.clone();
            let stop = stopping.clone();
            Some(tokio::spawn(
                async move { seed_if_empty(&state, &stop).await },
            ))
        } else {
            None
        };
        let sweeping = {
            let state = self.state.clone();
            let stop = stopping.clone();
            tokio::spawn(async move { sweep_blobs(&state, &stop).await })
        };
        let trimming = {
            let store = self.state.store().clone();
            let stop = stopping.clone();
            let max = self.blob_cache_bytes;
            tokio::spawn(async move { trim_blob_copies(&store, max, &stop).await })
        };
        tracing::info!(addr = %self.addr, data = %self.state.store().data_dir().display(),
            writes_need_token = self.state.token().is_some(),
            max_connections = self.connections.max_connections,
            header_timeout_s = self.connections.header_timeout.as_secs_f64(),
            keep_alive_timeout_s = self.connections.keep_alive_timeout.as_secs_f64(),
            "serving the ICMS API");
        let state = self.state.clone();
        let served =
            http::server::serve(self.listener, self.router, self.connections, async move {
                shutdown.await;
                tracing::info!("shutting down: stopping work in flight, finishing open requests");
                state.stop_work();
            })
            .await;
        self.state.stop_work();
        // Live sessions end on stop_work; each is finished and stored before the store closes.
        if !self.state.live().wait_stored(LIVE_STORE_GRACE).await {
            tracing::warn!(
                grace_s = LIVE_STORE_GRACE.as_secs_f64(),
                "live sessions were still being stored after the grace; their recordings stay \
                 in the staging area"
            );
        }
        if let Some(server) = self.foxglove {
            server.stop().wait().await;
        }
        if let Some(task) = seeding {
            let _ = task.await;
        }
        // Each worker stops its job within a fraction of a second and gives it back (or stores
        // what it finished).
        while workers.join_next().await.is_some() {}
        let _ = sweeping.await;
        let _ = trimming.await;
        self.state.store().close().await;
        tracing::info!("database closed; stopped");
        served.map_err(|source| StartupError::Io {
            context: "serving".into(),
            source,
        })
    }
}

/// Resolves on SIGINT (Ctrl-C) or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}

/// Removes simulation files a killed server left in the scratch directory (one server per
/// data directory, so none is in use now).
async fn clear_scratch(dir: &std::path::Path) {
    let Ok(mut entries) = tokio::fs::read_dir(dir).await else {
        return;
    };
    while let Ok(Some(e)) = entries.next_entry().await {
        let _ = tokio::fs::remove_file(e.path()).await;
    }
}

/// Sweeps unreferenced blobs and deletes week-old failed and cancelled jobs, now and every
/// [`SWEEP_INTERVAL`] until `stop`, logging what went.
async fn sweep_blobs(state: &AppState, stop: &CancellationToken) {
    loop {
        match state
            .store()
            .sweep_orphan_blobs(services::store::ORPHAN_BLOB_MIN_AGE)
            .await
        {
            Ok(r) if r.removed > 0 => tracing::info!(
                examined = r.examined,
                removed = r.removed,
                removed_bytes = r.removed_bytes,
                "removed blobs that no session or replay references"
            ),
            Ok(r) if r.skipped_busy => tracing::info!(
                examined = r.examined,
                "another server was ingesting into the bucket: unreferenced blobs are left \
                 for the next sweep"
            ),
            Ok(r) => tracing::debug!(examined = r.examined, "no unreferenced blobs"),
            Err(e) => tracing::warn!(error = %e, "sweeping unreferenced blobs failed"),
        }
        match state
            .store()
            .prune_jobs(services::store::FINISHED_JOB_RETENTION)
            .await
        {
            Ok(0) => {}
            Ok(n) => tracing::info!(jobs = n, "deleted failed and cancelled jobs a week old"),
            Err(e) => tracing::warn!(error = %e, "deleting old jobs failed"),
        }
        tokio::select! {
            () = tokio::time::sleep(SWEEP_INTERVAL) => {}
            () = stop.cancelled() => return,
        }
    }
}

/// Keeps the data directory's copies of a bucket's blobs within `max_bytes`: trims them now
/// and every [`TRIM_INTERVAL`] until `stop` (nothing to do without a bucket).
pub async fn trim_blob_copies(store: &Store, max_bytes: u64, stop: &CancellationToken) {
    loop {
        match store
            .trim_blob_copies(max_bytes, services::store::ORPHAN_BLOB_MIN_AGE)
            .await
        {
            Ok(r) if r.removed > 0 => tracing::info!(
                copies = r.copies,
                bytes = r.bytes,
                removed = r.removed,
                removed_bytes = r.removed_bytes,
                "removed the least recently used copies of the bucket's files (--blob-cache-mib)"
            ),
            Ok(_) => {}
            Err(e) => {
                tracing::warn!(error = %e, "trimming the copies of the bucket's files failed")
            }
        }
        tokio::select! {
            () = tokio::time::sleep(TRIM_INTERVAL) => {}
            () = stop.cancelled() => return,
        }
    }
}

/// Seeds an empty data base with one simulated session of every built-in scenario (seed 0),
/// so that a newcomer sees skills at once: one job each, which the workers run (the same
/// requests as `POST /api/v1/simulations {"scenario": NAME}`, so a seeding interrupted and
/// started again queues nothing twice).
async fn seed_if_empty(state: &AppState, stop: &CancellationToken) {
    match state.store().list_sessions(1, None).await {
        Ok(page) if page.items.is_empty() => {}
        Ok(_) => return,
        Err(e) => {
            tracing::warn!(error = %e, "could not check whether the data base is empty");
            return;
        }
    }
    tracing::info!(
        scenarios = Scenario::BUILTINS.len(),
        "empty data base: seeding it with simulated sessions of the built-in scenarios \
         (--no-demo skips this)"
    );
    let mut queued = 0;
    for name in Scenario::BUILTINS {
        if stop.is_cancelled() {
            tracing::info!("seeding stopped by shutdown");
            return;
        }
        let Some(scenario) = Scenario::builtin(name, 0) else {
            continue;
        };
        let request = JobRequest::Simulation {
            scenario: Box::new(scenario),
            duration: None,
        };
        match state.store().submit_job(&request, u64::MAX).await {
            Ok(s) => {
                queued += usize::from(s.new);
                state.jobs().job_submitted();
            }
            Err(e) => tracing::warn!(scenario = name, error = %e, "seeding failed"),
        }
    }
    tracing::info!(
        jobs = queued,
        "seeding queued; the sessions appear as the workers finish them"
    );
}
