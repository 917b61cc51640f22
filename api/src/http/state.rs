//! The state every handler shares: the store, the configured token, limits, the signals of the
//! job workers and the hot-skill cache. One `Clone` handle (an `Arc`).

use std::path::PathBuf;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use bytes::Bytes;

use services::store::Store;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio_util::sync::CancellationToken;

use super::cache::SkillCache;
use super::error::Problem;
use super::live::LiveHub;
use crate::jobs::JobSignals;

/// What the handlers need besides the request. Cheap to clone.
#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    store: Store,
    token: Option<String>,
    max_body: usize,
    max_upload: usize,
    ingests: Arc<Semaphore>,
    jobs: Arc<JobSignals>,
    job_wait: Duration,
    max_queued_jobs: u64,
    queue_wait: Duration,
    shutdown: CancellationToken,
    cache: Arc<SkillCache>,
    scratch: PathBuf,
    openapi: OnceLock<Bytes>,
    live: LiveHub,
}

impl std::fmt::Debug for AppState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AppState")
            .field("store", &self.inner.store)
            .field("token", &self.inner.token.as_ref().map(|_| "***"))
            .field("max_body", &self.inner.max_body)
            .finish_non_exhaustive()
    }
}

/// The settings of [`AppState`].
#[derive(Debug, Clone)]
pub struct StateConfig {
    /// Bearer token required by write endpoints; `None`: writes are open.
    pub token: Option<String>,
    /// Largest request body, bytes, but for session uploads.
    pub max_body: usize,
    /// Largest session upload (`POST /api/v1/sessions`), bytes: streamed to disk, so memory
    /// does not grow with it.
    pub max_upload: usize,
    /// Longest a simulation or replay request waits for its job before 202 with the job.
    pub job_wait: Duration,
    /// Jobs that may wait for a worker; more are refused 503 with `Retry-After`.
    pub max_queued_jobs: u64,
    /// Session uploads that may be read and segmented at once; more wait for a turn.
    pub max_ingests: usize,
    /// Longest wait of an upload for a turn before 503 with `Retry-After`.
    pub queue_wait: Duration,
    /// Bytes of skill JSON kept in memory.
    pub cache_bytes: usize,
    /// Live glove sessions at once.
    pub max_live: usize,
    /// Threads stepping the live sessions.
    pub live_threads: usize,
    /// A live session ends after this long without a sample.
    pub live_silence: Duration,
}

impl AppState {
    /// State over an open store. Fails only if the live stepping threads cannot start.
    pub fn new(store: Store, config: &StateConfig) -> std::io::Result<Self> {
        let scratch = store.data_dir().join("tmp");
        let live = LiveHub::new(config.max_live, config.live_threads, config.live_silence)?;
        Ok(AppState {
            inner: Arc::new(Inner {
                store,
                token: config.token.clone(),
                max_body: config.max_body,
                max_upload: config.max_upload,
                ingests: Arc::new(Semaphore::new(config.max_ingests.max(1))),
                jobs: Arc::new(JobSignals::default()),
                job_wait: config.job_wait,
                max_queued_jobs: config.max_queued_jobs,
                queue_wait: config.queue_wait,
                shutdown: CancellationToken::new(),
                cache: Arc::new(SkillCache::new(config.cache_bytes)),
                scratch,
                openapi: OnceLock::new(),
                live,
            }),
        })
    }

    /// The live sessions: their stepping pool and slots.
    pub fn live(&self) -> &LiveHub {
        &self.inner.live
    }

    /// The skill store.
    pub fn store(&self) -> &Store {
        &self.inner.store
    }

    /// The bearer token writes need, if one is configured.
    pub fn token(&self) -> Option<&str> {
        self.inner.token.as_deref()
    }

    /// Largest request body, bytes, but for session uploads.
    pub fn max_body(&self) -> usize {
        self.inner.max_body
    }

    /// Largest session upload, bytes.
    pub fn max_upload(&self) -> usize {
        self.inner.max_upload
    }

    /// What this server's job workers and the requests waiting for jobs tell each other.
    pub fn jobs(&self) -> &Arc<JobSignals> {
        &self.inner.jobs
    }

    /// Longest a simulation or replay request waits for its job.
    pub fn job_wait(&self) -> Duration {
        self.inner.job_wait
    }

    /// Jobs that may wait for a worker at once.
    pub fn max_queued_jobs(&self) -> u64 {
        self.inner.max_queued_jobs
    }

    /// A turn to read and segment an uploaded session: waits at most the queue wait for one of
    /// the ingest permits, then 503 with `Retry-After`.
    pub async fn ingest_turn(&self) -> Result<OwnedSemaphorePermit, Problem> {
        self.turn(&self.inner.ingests, "session uploads").await
    }

    async fn turn(
        &self,
        slots: &Arc<Semaphore>,
        what: &str,
    ) -> Result<OwnedSemaphorePermit, Problem> {
        let wait = self.inner.queue_wait;
        // Biased: a free turn is taken even once shutdown began (a request already in flight
        // finishes, as graceful shutdown promises); only waiting ends at shutdown.
        tokio::select! {
            biased;
            p = tokio::time::timeout(wait, Arc::clone(slots).acquire_owned()) => match p {
                Ok(Ok(p)) => Ok(p),
                Ok(Err(_)) => Err(Problem::unavailable("the server is shutting down")),
                Err(_) => Err(Problem::busy(
                    format!(
                        "the server is busy: every turn for {what} is taken and none came free \
                         within {} s; try again",
                        wait.as_secs_f64()
                    ),
                    wait.as_secs().clamp(1, 60) as u32,
                )),
            },
            () = self.inner.shutdown.cancelled() => {
                Err(Problem::unavailable("the server is shutting down"))
            }
        }
    }

    /// Tells the work in flight to stop (shutdown): the job workers give their jobs back, the
    /// live sessions end, requests waiting for a turn or a job are answered.
    pub fn stop_work(&self) {
        self.inner.shutdown.cancel();
    }

    /// Whether the server is shutting down.
    pub fn shutdown_token(&self) -> &CancellationToken {
        &self.inner.shutdown
    }

    /// The hot-skill cache.
    pub fn cache(&self) -> &Arc<SkillCache> {
        &self.inner.cache
    }

    /// Directory for temporary files (simulated sessions before ingest), in the data directory.
    pub fn scratch_dir(&self) -> &std::path::Path {
        &self.inner.scratch
    }

    /// The OpenAPI document as JSON (empty until [`AppState::set_openapi_json`]).
    pub fn openapi_json(&self) -> Bytes {
        self.inner.openapi.get().cloned().unwrap_or_default()
    }

    /// Sets the OpenAPI document, once, when the router is built.
    pub fn set_openapi_json(&self, json: Bytes) {
        let _ = self.inner.openapi.set(json);
    }
}
