//! The state every handler shares: the store, the configured token, limits, the simulation
//! semaphore and the hot-skill cache. One `Clone` handle (an `Arc`).

use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use bytes::Bytes;

use services::store::Store;
use tokio::sync::Semaphore;

use super::cache::SkillCache;
use super::error::Problem;

/// What the handlers need besides the request. Cheap to clone.
#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    store: Store,
    token: Option<String>,
    max_body: usize,
    simulations: Arc<Semaphore>,
    cache: SkillCache,
    scratch: PathBuf,
    openapi: OnceLock<Bytes>,
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
    /// Largest request body, bytes.
    pub max_body: usize,
    /// Simulations that may run at once; more wait for a turn.
    pub max_simulations: usize,
    /// Skills whose JSON is kept in memory.
    pub cache_capacity: usize,
}

impl AppState {
    /// State over an open store.
    pub fn new(store: Store, config: &StateConfig) -> Self {
        let scratch = store.data_dir().join("tmp");
        AppState {
            inner: Arc::new(Inner {
                store,
                token: config.token.clone(),
                max_body: config.max_body,
                simulations: Arc::new(Semaphore::new(config.max_simulations.max(1))),
                cache: SkillCache::new(config.cache_capacity),
                scratch,
                openapi: OnceLock::new(),
            }),
        }
    }

    /// The skill store.
    pub fn store(&self) -> &Store {
        &self.inner.store
    }

    /// The bearer token writes need, if one is configured.
    pub fn token(&self) -> Option<&str> {
        self.inner.token.as_deref()
    }

    /// Largest request body, bytes.
    pub fn max_body(&self) -> usize {
        self.inner.max_body
    }

    /// Runs `work` (a simulation or a replay) on the blocking pool once one of the
    /// simulation permits is free; the work holds its permit until it ends, even if the
    /// request is dropped meanwhile.
    pub async fn run_limited<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> Result<T, Problem> + Send + 'static,
    ) -> Result<T, Problem> {
        let permit = Arc::clone(&self.inner.simulations)
            .acquire_owned()
            .await
            .map_err(|_| Problem::unavailable("the server is shutting down"))?;
        tokio::task::spawn_blocking(move || {
            let _permit = permit;
            work()
        })
        .await
        .map_err(|e| Problem::internal(&e))?
    }

    /// The hot-skill cache.
    pub fn cache(&self) -> &SkillCache {
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
