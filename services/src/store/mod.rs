//! The skill data base: recorded sessions (content-addressed MCAP blobs plus metadata) and the
//! skills found in them, in SQLite through sqlx. The only SQL of the project lives here, in
//! the backend [`sqlite`] behind the [`catalog::Catalog`] trait; the blob files, the
//! in-memory indexes and the locks that order deletes after ingests are [`Store`]'s, the
//! same for every backend.
//!
//! Layout of a data directory: `DIR/icms.sqlite3` (WAL mode) and `DIR/blobs/sha256/ab/cdef….mcap`.
//! A blob is written and fsynced before the row that names it commits, and a session's row, its
//! skills and their phases commit in one transaction, so a process killed at any point leaves
//! either the whole session or none (at worst an unreferenced blob, which a later ingest of the
//! same file reuses). Replays of skills on robot hands are stored the same way (see `hands`),
//! and go with their skill. One process per data directory: deletes and ingests are ordered by an
//! in-process lock so that a delete never unlinks a blob that a concurrent ingest has just reused.
//!
//! Every session records the version of the segmentation that made its skills
//! ([`crate::segmentation::SEGMENTATION_VERSION`] at ingest); `reprocess` replaces the skills
//! of a session segmented again ([`Store::replace_session_skills`], one transaction).
//!
//! This file holds the [`Store`] handle, its shared state and its settings; `open.rs` opens
//! a store, `ingest.rs` stores sessions, `records.rs` reads and deletes them and their skills,
//! `blob_access.rs` reaches the blobs behind the rows, and `sweep.rs` keeps the blob files
//! bounded.

pub mod bench;
mod blob;
mod blob_access;
mod catalog;
mod error;
mod hands;
mod ingest;
mod jobs;
mod knn;
mod open;
mod postgres;
mod query;
mod records;
mod remote;
mod reprocess;
mod rows;
mod skill_filter;
mod skill_insert;
mod sqlite;
mod sweep;
mod types;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

pub use blob::{StagedBlob, StagedWriter};
pub use error::StoreError;
pub use hands::MAX_HAND_NAME;
pub use jobs::{
    Job, JobClaim, JobEnd, JobError, JobKind, JobRequest, JobResult, JobState, Renewal, Submitted,
    FINISHED_JOB_RETENTION, JOB_LEASE, MAX_JOB_ATTEMPTS, MAX_JOB_LIMIT, MAX_JOB_REQUEST_BYTES,
};
pub use open::WRITER_LOCK_FILE;
pub use postgres::{
    is_postgres_url, redact_url, SkillsChanged, BLOB_LOCK_CLASS, PG_CONNECT_TIMEOUT,
    PG_MAX_CONNECTIONS,
};
pub use query::{
    SessionQuery, SkillQuery, SortField, SortKey, SortOrder, DEFAULT_LIMIT, MAX_LIMIT,
};
pub use remote::{Blobs, S3Bucket, BUCKET_CONNECT_TIMEOUT};
pub use sqlite::{APPLICATION_ID, DB_FILE, MAX_CONNECTIONS, PAGE_CACHE_KIB};
pub use sweep::{SweepReport, TrimReport};
pub use types::{
    Hand, HandSummary, IngestOutcome, NewSkill, ObjectShape, Page, ReplacedSkills, Replay,
    SessionMeta, SessionRecord, SkillRecord, StaleSession, FEATURE_DIM,
};

use crate::assist::index::{RecognitionIndex, StoredTemplate};
use catalog::{BlobGuard, Catalog};
use ingest::{new_template, stored_template, validate_skill};
use knn::FeatureIndex;

/// Youngest unreferenced blob the server's sweep removes (see [`Store::sweep_orphan_blobs`]):
/// ten minutes, far longer than any ingest takes from its blob write to its commit.
pub const ORPHAN_BLOB_MIN_AGE: Duration = Duration::from_secs(600);

/// When a commit counts as done (SQLite's `synchronous` in WAL mode).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Durability {
    /// `synchronous=FULL`: the WAL is fsynced at every commit, so an acknowledged write
    /// survives a power cut. The default of every store the server and the CLI open.
    #[default]
    Full,
    /// `synchronous=NORMAL`: fsync only at checkpoints; a power cut may roll back the last
    /// commits (never corrupts). For benchmarks and throwaway data bases.
    Normal,
}

/// Where a store keeps its rows (its blobs are files in the data directory either way).
#[derive(Clone, Default, PartialEq, Eq)]
pub enum Database {
    /// The SQLite file `DIR/icms.sqlite3` in the data directory: the default, nothing to set
    /// up.
    #[default]
    Sqlite,
    /// A PostgreSQL data base, by its `postgres://` URL (`icms serve --database-url`).
    Postgres(String),
}

impl Database {
    /// The backend a `--database-url` (or `DATABASE_URL`) names: none or an empty one is the
    /// data directory's SQLite file, a `postgres://` (or `postgresql://`) URL is PostgreSQL,
    /// anything else is refused naming what is accepted.
    pub fn from_url(url: Option<&str>) -> Result<Database, StoreError> {
        match url.map(str::trim) {
            None | Some("") => Ok(Database::Sqlite),
            Some(u) if is_postgres_url(u) => Ok(Database::Postgres(u.to_owned())),
            Some(u) => Err(StoreError::InvalidInput(format!(
                "database URL {} is not a postgres:// URL: --database-url (or DATABASE_URL) \
                 names a PostgreSQL data base; without it the store is the SQLite file in the \
                 data directory",
                redact_url(u)
            ))),
        }
    }

    /// What logs and messages show of it (a URL's password hidden).
    pub fn describe(&self) -> String {
        match self {
            Database::Sqlite => format!("SQLite ({DB_FILE} in the data directory)"),
            Database::Postgres(url) => format!("PostgreSQL at {}", redact_url(url)),
        }
    }
}

impl std::fmt::Debug for Database {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

/// Largest number of sessions [`Store::list_sessions`] returns per page.
pub const MAX_SESSION_LIMIT: u32 = 1000;

/// Handle to a data directory's database and blobs. Cheap to clone (shared state).
#[derive(Clone)]
pub struct Store {
    inner: Arc<Inner>,
}

struct Inner {
    dir: PathBuf,
    /// The rows, in the data base backend the store was opened on.
    catalog: Box<dyn Catalog>,
    /// The bucket the blobs live in (`--blobs s3://…`), the data directory then keeping
    /// copies; `None`: the data directory's files are the blobs.
    remote: Option<remote::RemoteBlobs>,
    index: std::sync::RwLock<FeatureIndex>,
    /// The skills as recognition sees them; a snapshot is shared by the live sessions that
    /// recognise (copied on the next change while one holds it).
    recognition: std::sync::RwLock<Arc<RecognitionIndex>>,
    /// Ingests hold it shared from blob write to index update; deletes hold it exclusively.
    /// With a bucket and a PostgreSQL catalog, its counterpart across servers is the
    /// catalog's blob guard ([`Store::shared_blob_hold`]), taken inside it.
    blob_lock: tokio::sync::RwLock<()>,
    /// The data directory's writer lock ([`WRITER_LOCK_FILE`]), held until [`Store::close`]
    /// or the last clone is dropped; `None` for a store opened to read only.
    writer: std::sync::Mutex<Option<std::fs::File>>,
    /// Following other servers' writes (PostgreSQL) and telling [`Store::skill_changes`].
    follow: postgres::follow::Follow,
}

/// The cross-server blob hold an ingest keeps from its blob upload to its row's commit (see
/// [`Store::sweep_orphan_blobs`]): empty where none is needed (no bucket, or SQLite). Give it
/// back with [`CrossServerBlobHold::release`]; dropped, it is let go all the same (its
/// connection closed).
#[doc(hidden)]
#[derive(Debug)]
#[must_use = "the hold lasts until released"]
pub struct CrossServerBlobHold(Option<Box<dyn BlobGuard>>);

impl CrossServerBlobHold {
    /// Whether a cross-server lock is held (a bucket and a PostgreSQL catalog).
    pub fn is_held(&self) -> bool {
        self.0.is_some()
    }

    /// Lets go of the hold.
    pub async fn release(self) {
        if let Some(g) = self.0 {
            g.release().await;
        }
    }
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Store")
            .field("dir", &self.inner.dir)
            .finish_non_exhaustive()
    }
}

impl Store {
    /// The stored skills as recognition sees them (a snapshot: skills stored later are in
    /// the next one).
    pub fn recognition_index(&self) -> Arc<RecognitionIndex> {
        Arc::clone(&self.inner.recognition.read().expect("recognition lock"))
    }

    /// Removes `removed` from the recognition index and adds (or replaces) `added`.
    pub(crate) fn update_recognition(
        &self,
        removed: &[i64],
        added: impl IntoIterator<Item = StoredTemplate>,
    ) {
        let mut guard = self.inner.recognition.write().expect("recognition lock");
        let index = Arc::make_mut(&mut guard);
        index.remove(removed);
        for t in added {
            index.insert(t);
        }
    }

    /// The data directory.
    pub fn data_dir(&self) -> &Path {
        &self.inner.dir
    }

    /// Closes the connection pool (waits for in-flight queries; later calls fail) and releases
    /// the data directory's writer lock.
    pub async fn close(&self) {
        self.inner.follow.stop();
        self.inner.catalog.close().await;
        // The next writer may come in now, even while clones of this store live on.
        if let Ok(mut writer) = self.inner.writer.lock() {
            writer.take();
        }
    }

    /// Number of skills in the feature index (equal to the skills table).
    pub fn skill_count(&self) -> usize {
        self.inner.index.read().expect("index lock").len()
    }

    /// SQLite's `synchronous` setting on the store's connections (2 = `FULL`, 1 = `NORMAL`),
    /// as the data base reports it: what [`Durability`] became.
    pub async fn synchronous_setting(&self) -> Result<i64, StoreError> {
        self.inner.catalog.synchronous_setting().await
    }

    /// Runs SQLite's `integrity_check` and `foreign_key_check`; `Corrupt` if either complains.
    pub async fn integrity_check(&self) -> Result<(), StoreError> {
        self.inner.catalog.integrity_check().await
    }

    /// Updates SQLite's planner statistics (`PRAGMA optimize`); worth it after bulk inserts.
    pub async fn optimize(&self) -> Result<(), StoreError> {
        self.inner.catalog.optimize().await
    }
}
