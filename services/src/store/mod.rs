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

pub mod bench;
mod blob;
mod catalog;
mod error;
mod hands;
mod jobs;
mod knn;
mod postgres;
mod query;
mod remote;
mod reprocess;
mod rows;
mod sqlite;
mod types;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

pub use blob::{StagedBlob, StagedWriter};
pub use error::StoreError;
pub use postgres::{
    is_postgres_url, redact_url, SkillsChanged, BLOB_LOCK_CLASS, PG_CONNECT_TIMEOUT,
    PG_MAX_CONNECTIONS,
};
pub use remote::{Blobs, S3Bucket, BUCKET_CONNECT_TIMEOUT};
pub use sqlite::{APPLICATION_ID, DB_FILE, MAX_CONNECTIONS, PAGE_CACHE_KIB};

use crate::assist::features::TEMPLATE_DIM;
use crate::assist::index::{RecognitionIndex, StoredTemplate};
use crate::segmentation::SEGMENTATION_VERSION;
use catalog::{
    BlobGuard, BlobRef, Catalog, CheckedSkill, ExclusiveBlobGuard, IndexedSkill, NewSession,
};
use dfs_core::names::Named;

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

/// What [`Store::trim_blob_copies`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct TrimReport {
    /// Copies found.
    pub copies: usize,
    /// Their bytes, before.
    pub bytes: u64,
    /// Copies removed.
    pub removed: usize,
    /// Their bytes.
    pub removed_bytes: u64,
}

/// [`Store::trim_blob_copies`]'s work, blocking.
fn trim_copies(dir: &Path, max_bytes: u64, min_age: Duration) -> TrimReport {
    let mut files = blob::blob_files(dir);
    let mut report = TrimReport {
        copies: files.len(),
        bytes: files.iter().map(|(f, _)| f.bytes).sum(),
        ..TrimReport::default()
    };
    let mut left = report.bytes;
    // Least recently used first.
    files.sort_by_key(|(_, modified)| *modified);
    for (f, _) in files {
        if left <= max_bytes {
            break;
        }
        let path = dir.join(&f.rel);
        // Read again: a copy used since the listing is young again.
        let old = std::fs::metadata(&path)
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age >= min_age);
        if !old {
            continue;
        }
        if blob::remove(dir, &f.rel).is_ok() {
            report.removed += 1;
            report.removed_bytes += f.bytes;
            left -= f.bytes;
        }
    }
    report
}

/// What [`Store::sweep_orphan_blobs`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct SweepReport {
    /// Blob files old enough to be looked at.
    pub examined: usize,
    /// Unreferenced ones removed.
    pub removed: usize,
    /// Their bytes.
    pub removed_bytes: u64,
    /// Nothing was removed because another server on the same data base and bucket was
    /// ingesting (it held the cross-server blob lock shared): the next sweep tries again.
    pub skipped_busy: bool,
}
pub use hands::MAX_HAND_NAME;
pub use jobs::{
    Job, JobClaim, JobEnd, JobError, JobKind, JobRequest, JobResult, JobState, Renewal, Submitted,
    FINISHED_JOB_RETENTION, JOB_LEASE, MAX_JOB_ATTEMPTS, MAX_JOB_LIMIT, MAX_JOB_REQUEST_BYTES,
};
pub use query::{
    SessionQuery, SkillQuery, SortField, SortKey, SortOrder, DEFAULT_LIMIT, MAX_LIMIT,
};
pub use types::{
    Hand, HandSummary, IngestOutcome, NewSkill, ObjectShape, Page, ReplacedSkills, Replay,
    SessionMeta, SessionRecord, SkillRecord, StaleSession, FEATURE_DIM,
};

use knn::FeatureIndex;

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

/// The file in the data directory whose lock says a process writes it (`flock`, released by
/// the kernel when the process ends, however it ends). It holds the writer's pid and command
/// line, for the message another process gets.
pub const WRITER_LOCK_FILE: &str = "icms.lock";

/// Takes the data directory's writer lock, or says who holds it.
fn lock_for_writing(data_dir: &Path) -> Result<std::fs::File, StoreError> {
    use std::io::{Read, Seek, Write};
    let path = data_dir.join(WRITER_LOCK_FILE);
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(|e| StoreError::io(&path, e))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut holder = String::new();
            let _ = Read::by_ref(&mut file)
                .take(512)
                .read_to_string(&mut holder);
            let holder = holder.trim();
            return Err(StoreError::InUse {
                dir: data_dir.to_path_buf(),
                holder: if holder.is_empty() {
                    "it did not say which".to_owned()
                } else {
                    holder.to_owned()
                },
            });
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(StoreError::io(&path, e)),
    }
    let command: Vec<String> = std::env::args().collect();
    let mut me = format!("pid {}: {}", std::process::id(), command.join(" "));
    if let Some((end, _)) = me.char_indices().nth(400) {
        me.truncate(end);
    }
    // Who holds it is only a courtesy to the next one: the lock itself is what counts.
    let _ = file
        .set_len(0)
        .and_then(|()| file.rewind())
        .and_then(|()| file.write_all(me.as_bytes()));
    Ok(file)
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Store")
            .field("dir", &self.inner.dir)
            .finish_non_exhaustive()
    }
}

/// A new skill stored as `id`, as recognition sees it.
fn new_template(id: i64, c: &CheckedSkill) -> StoredTemplate {
    let s = &c.skill;
    stored_template(
        id,
        s.object_shape.name(),
        &s.grasp_type,
        s.object_name.clone(),
        s.approach
            .as_deref()
            .and_then(|a| <[f32; TEMPLATE_DIM]>::try_from(a).ok()),
        c.feature,
    )
}

/// A skill as recognition sees it ([`RecognitionIndex`]).
fn stored_template(
    id: i64,
    shape: &str,
    grasp_type: &str,
    object_name: Option<String>,
    approach: Option<[f32; TEMPLATE_DIM]>,
    feature: [f32; FEATURE_DIM],
) -> StoredTemplate {
    StoredTemplate {
        skill_id: id,
        kind: format!("{shape}/{grasp_type}"),
        object_name,
        template: approach.unwrap_or([f32::NAN; TEMPLATE_DIM]),
        feature,
    }
}

fn finite(what: &str, v: f64) -> Result<(), StoreError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(StoreError::InvalidInput(format!(
            "{what} must be finite, got {v}"
        )))
    }
}

/// Checks each skill before insertion ([`validate_skill`]).
fn checked_skills(skills: Vec<NewSkill>) -> Result<Vec<CheckedSkill>, StoreError> {
    skills
        .into_iter()
        .enumerate()
        .map(|(i, skill)| validate_skill(i, &skill).map(|feature| CheckedSkill { skill, feature }))
        .collect()
}

/// A session's skills with their checked feature vectors, and its duration as the store's
/// signed column: what every ingest checks before it writes anything.
fn checked_input(
    meta: &SessionMeta,
    skills: Vec<NewSkill>,
) -> Result<(Vec<CheckedSkill>, i64), StoreError> {
    let checked = checked_skills(skills)?;
    finite("object_mass", meta.object_mass)?;
    finite("mu", meta.mu)?;
    let duration_ns = i64::try_from(meta.duration_ns)
        .map_err(|_| StoreError::InvalidInput("duration_ns is too large".into()))?;
    Ok((checked, duration_ns))
}

/// Checks skill number `i` before insertion; returns its feature as a fixed array.
fn validate_skill(i: usize, s: &NewSkill) -> Result<[f32; FEATURE_DIM], StoreError> {
    let ctx = |field: &str| format!("skill {i}: {field}");
    if let Some(name) = &s.object_name {
        let max = dfs_core::scenario::MAX_OBJECT_NAME_CHARS;
        if name.is_empty() || name.chars().count() > max || name.chars().any(char::is_control) {
            return Err(StoreError::InvalidInput(format!(
                "{}: must be 1 to {max} characters, none a control character",
                ctx("object_name")
            )));
        }
    }
    finite(&ctx("object_mass"), s.object_mass)?;
    finite(&ctx("mu"), s.mu)?;
    finite(&ctx("quality"), s.quality)?;
    finite(&ctx("volume"), s.volume)?;
    finite(&ctx("duration_s"), s.duration_s)?;
    for (name, d) in &s.phase_durations {
        finite(&ctx(&format!("phase {name} duration")), *d)?;
    }
    let feature: [f32; FEATURE_DIM] = s.feature.as_slice().try_into().map_err(|_| {
        StoreError::InvalidInput(format!(
            "{}: feature has {} values, expected {FEATURE_DIM}",
            ctx("feature"),
            s.feature.len()
        ))
    })?;
    if feature.iter().any(|x| !x.is_finite()) {
        return Err(StoreError::InvalidInput(format!(
            "{} must be finite",
            ctx("feature")
        )));
    }
    if let Some(a) = &s.approach {
        if a.len() != TEMPLATE_DIM || a.iter().any(|x| x.is_infinite()) {
            return Err(StoreError::InvalidInput(format!(
                "{}: needs {TEMPLATE_DIM} values, finite or NaN (not seen); got {}",
                ctx("approach"),
                a.len()
            )));
        }
    }
    Ok(feature)
}

impl Store {
    /// Opens (creating and migrating if needed) the store in `data_dir`.
    ///
    /// Refuses a database that is not ours ([`StoreError::NotOurs`]) or that a newer binary
    /// migrated ([`StoreError::SchemaTooNew`]) before touching it. Settings: WAL journal,
    /// `foreign_keys=ON`, busy timeout 5 s, `synchronous=FULL` (a commit is on disk before it returns: an
    /// acknowledged write survives a power cut; the cost is in BENCHMARKS.md). Loads the feature
    /// index.
    ///
    /// Takes the data directory's writer lock ([`WRITER_LOCK_FILE`]): while this store is
    /// open, another process's open to write fails with [`StoreError::InUse`] naming it (two
    /// `icms serve` on one directory would each answer from caches the other's writes leave
    /// stale). Stores opened to read ([`Store::open_existing`]) take no lock.
    pub async fn open(data_dir: &Path) -> Result<Store, StoreError> {
        Self::open_with(data_dir, true, Durability::Full, true).await
    }

    /// [`Store::open`] with another [`Durability`]: `icms bench ingest` measures what
    /// `synchronous=FULL` costs against `NORMAL` with it.
    pub async fn open_with_durability(
        data_dir: &Path,
        durability: Durability,
    ) -> Result<Store, StoreError> {
        Self::open_with(data_dir, true, durability, true).await
    }

    /// Opens the store in `data_dir` like [`Store::open`], but only if a data base is already
    /// there: without one (no database file, or an empty file) it fails with
    /// [`StoreError::NoDataBase`] and creates nothing, neither the directory nor a file. For
    /// commands that only read (`icms skills`, `icms hands --data`): a mistyped directory must
    /// not leave an empty data base behind and answer as if it held no skills. An existing data
    /// base of an older schema is still migrated. It takes no writer lock, so it reads beside
    /// a running `icms serve`.
    pub async fn open_existing(data_dir: &Path) -> Result<Store, StoreError> {
        Self::open_with(data_dir, false, Durability::Full, false).await
    }

    /// [`Store::open_existing`] for a command that writes (`icms reprocess`, `icms replay
    /// --data`): it takes the writer lock as [`Store::open`] does.
    pub async fn open_existing_to_write(data_dir: &Path) -> Result<Store, StoreError> {
        Self::open_with(data_dir, false, Durability::Full, true).await
    }

    async fn open_with(
        data_dir: &Path,
        create: bool,
        durability: Durability,
        write: bool,
    ) -> Result<Store, StoreError> {
        Self::open_sqlite(data_dir, create, durability, write, None).await
    }

    async fn open_sqlite(
        data_dir: &Path,
        create: bool,
        durability: Durability,
        write: bool,
        remote: Option<remote::RemoteBlobs>,
    ) -> Result<Store, StoreError> {
        if create {
            Self::create_data_dir(data_dir).await?;
        }
        let db_path = sqlite::locate(data_dir, create).await?;
        let writer = if write {
            Some(Self::take_writer_lock(data_dir).await?)
        } else {
            None
        };
        let catalog = sqlite::SqliteCatalog::open(&db_path, create, durability).await?;
        Self::assemble(data_dir, Box::new(catalog), writer, remote).await
    }

    /// Opens the store of `data_dir` with its rows in `database`: [`Store::open`] for
    /// [`Database::Sqlite`]; for [`Database::Postgres`], the data directory (created if
    /// missing) holds the blobs and its writer lock is taken as [`Store::open`] takes it,
    /// and the data base is connected to (within [`PG_CONNECT_TIMEOUT`], else
    /// [`StoreError::Unreachable`] naming it) and migrated.
    ///
    /// A PostgreSQL store follows the writes made through every other server on the same
    /// data base (`LISTEN/NOTIFY`): its k-nearest and recognition indexes take them in as
    /// their notifications arrive, and [`Store::skill_changes`] tells whoever caches skills.
    /// A lost listening connection is made again and both indexes reloaded, so staleness is
    /// bounded by how long the data base is out of reach, plus one reload (details in
    /// `postgres/follow.rs` and docs/backends.md).
    pub async fn open_in(data_dir: &Path, database: &Database) -> Result<Store, StoreError> {
        Self::open_on(data_dir, database, &Blobs::Local).await
    }

    /// [`Store::open_in`] with the blobs in `blobs`: for [`Blobs::S3`], the bucket is
    /// connected to first (configured from the environment, see [`Blobs`]) and must answer a
    /// listing within [`BUCKET_CONNECT_TIMEOUT`], else [`StoreError::ObjectStore`] naming it;
    /// the data directory then keeps copies of the blobs this process writes or reads.
    pub async fn open_on(
        data_dir: &Path,
        database: &Database,
        blobs: &Blobs,
    ) -> Result<Store, StoreError> {
        let remote = match blobs {
            Blobs::Local => None,
            Blobs::S3(bucket) => {
                Some(remote::RemoteBlobs::connect(bucket, BUCKET_CONNECT_TIMEOUT).await?)
            }
        };
        let url = match database {
            Database::Sqlite => {
                return Self::open_sqlite(data_dir, true, Durability::Full, true, remote).await
            }
            Database::Postgres(url) => url,
        };
        Self::create_data_dir(data_dir).await?;
        let writer = Self::take_writer_lock(data_dir).await?;
        let catalog = postgres::PgCatalog::connect(url, PG_CONNECT_TIMEOUT).await?;
        // Listening before the indexes load: no write committed after the load is missed.
        let listener = postgres::follow::Listener::connect(&catalog, url).await?;
        let store = Self::assemble(data_dir, Box::new(catalog), Some(writer), remote).await?;
        listener.follow(&store);
        Ok(store)
    }

    /// Creates the data directory if missing, refusing a file in its place.
    async fn create_data_dir(data_dir: &Path) -> Result<(), StoreError> {
        // create_dir_all on a file says only "File exists".
        if tokio::fs::metadata(data_dir)
            .await
            .is_ok_and(|m| !m.is_dir())
        {
            return Err(StoreError::io(
                data_dir,
                std::io::Error::new(
                    std::io::ErrorKind::NotADirectory,
                    "it is a file, not a directory (the data directory holds the data base \
                     and the session files)",
                ),
            ));
        }
        tokio::fs::create_dir_all(data_dir)
            .await
            .map_err(|e| StoreError::io(data_dir, e))
    }

    async fn take_writer_lock(data_dir: &Path) -> Result<std::fs::File, StoreError> {
        let dir = data_dir.to_path_buf();
        tokio::task::spawn_blocking(move || lock_for_writing(&dir))
            .await
            .map_err(|e| StoreError::io(data_dir, std::io::Error::other(e)))?
    }

    /// The store around an opened catalog: leftover temporary blobs removed, the in-memory
    /// indexes loaded.
    async fn assemble(
        data_dir: &Path,
        catalog: Box<dyn Catalog>,
        writer: Option<std::fs::File>,
        remote: Option<remote::RemoteBlobs>,
    ) -> Result<Store, StoreError> {
        let dir = data_dir.to_path_buf();
        let swept = tokio::task::spawn_blocking(move || blob::sweep_temp_files(&dir))
            .await
            .unwrap_or(0);
        if swept > 0 {
            tracing::info!(
                swept,
                "removed temporary blob files left by interrupted ingests"
            );
        }

        let skills = catalog.indexed_skills().await?;
        let mut entries = Vec::with_capacity(skills.len());
        let mut templates = Vec::with_capacity(skills.len());
        for s in skills {
            let IndexedSkill {
                id,
                feature,
                object_shape,
                grasp_type,
                object_name,
                approach,
            } = s;
            entries.push((id, feature));
            templates.push(stored_template(
                id,
                &object_shape,
                &grasp_type,
                object_name,
                approach,
                feature,
            ));
        }
        Ok(Store {
            inner: Arc::new(Inner {
                dir: data_dir.to_path_buf(),
                catalog,
                remote,
                index: std::sync::RwLock::new(FeatureIndex::from_entries(entries)),
                recognition: std::sync::RwLock::new(Arc::new(RecognitionIndex::new(templates))),
                blob_lock: tokio::sync::RwLock::new(()),
                writer: std::sync::Mutex::new(writer),
                follow: postgres::follow::Follow::new(),
            }),
        })
    }

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

    async fn existing(&self, sha256: &str) -> Result<Option<IngestOutcome>, StoreError> {
        self.inner.catalog.stored_session(sha256).await
    }

    /// Stores a session: its MCAP bytes as a content-addressed blob, its metadata and skills.
    ///
    /// Idempotent: bytes already stored (same SHA-256) return the existing session with
    /// `created: false`, also when concurrent ingests of the same file race. The blob is
    /// written atomically and fsynced before one transaction inserts the session, skills and
    /// phases; any error (full disk, bad input) leaves no rows.
    pub async fn ingest(
        &self,
        mcap: &[u8],
        meta: SessionMeta,
        skills: Vec<NewSkill>,
    ) -> Result<IngestOutcome, StoreError> {
        let (checked, duration_ns) = checked_input(&meta, skills)?;

        let bytes = mcap.to_vec();
        let sha256 = tokio::task::spawn_blocking(move || (blob::sha256_hex(&bytes), bytes))
            .await
            .map_err(|e| StoreError::Corrupt(format!("hashing task failed: {e}")));
        let (sha256, bytes) = sha256?;
        if let Some(found) = self.existing(&sha256).await? {
            return Ok(found);
        }

        let _guard = self.inner.blob_lock.read().await;
        let dir = self.inner.dir.clone();
        let sha = sha256.clone();
        let size = bytes.len() as i64;
        let rel = tokio::task::spawn_blocking(move || blob::write_atomic(&dir, &sha, &bytes))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob writer task failed: {e}")))??;
        self.publish_and_insert_session(&sha256, size, &rel, meta, checked, duration_ns)
            .await
    }

    /// A new [`StagedBlob`] in the data directory, for an upload to stream into. Blocking.
    pub fn stage_upload(&self) -> Result<StagedBlob, StoreError> {
        StagedBlob::create(&self.inner.dir)
    }

    /// [`Store::ingest`] of an upload already written to disk and hashed ([`StagedBlob`]):
    /// the file is moved to its content address (or dropped, if those bytes are stored
    /// already), never read into memory.
    pub async fn ingest_staged(
        &self,
        staged: StagedBlob,
        meta: SessionMeta,
        skills: Vec<NewSkill>,
    ) -> Result<IngestOutcome, StoreError> {
        let (checked, duration_ns) = checked_input(&meta, skills)?;
        let sha256 = staged.sha256().to_owned();
        if let Some(found) = self.existing(&sha256).await? {
            return Ok(found);
        }
        let _guard = self.inner.blob_lock.read().await;
        let dir = self.inner.dir.clone();
        let size = staged.len() as i64;
        let rel = tokio::task::spawn_blocking(move || staged.commit(&dir))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob writer task failed: {e}")))??;
        self.publish_and_insert_session(&sha256, size, &rel, meta, checked, duration_ns)
            .await
    }

    /// Uploads the blob at `rel` to the bucket (if any) and inserts the session's rows,
    /// holding the cross-server blob lock shared throughout (see
    /// [`Store::sweep_orphan_blobs`]). Call under the in-process blob lock, shared.
    async fn publish_and_insert_session(
        &self,
        sha256: &str,
        size: i64,
        rel: &str,
        meta: SessionMeta,
        checked: Vec<CheckedSkill>,
        duration_ns: i64,
    ) -> Result<IngestOutcome, StoreError> {
        let hold = self.shared_blob_hold().await?;
        let done = async {
            self.publish(rel).await?;
            self.insert_session(sha256, size, rel, meta, checked, duration_ns)
                .await
        }
        .await;
        hold.release().await;
        done
    }

    /// The cross-server blob lock, shared: held by an ingest from its blob upload to its
    /// row's commit, so that no other server's sweep or delete removes the object meanwhile.
    /// Needed only with a bucket (the data directory is one process's) and a catalog that
    /// several servers share (PostgreSQL); empty otherwise. Waits only while another server
    /// holds it exclusively, which it does briefly and never waiting itself.
    pub(crate) async fn shared_blob_hold(&self) -> Result<CrossServerBlobHold, StoreError> {
        if self.inner.remote.is_none() {
            return Ok(CrossServerBlobHold(None));
        }
        Ok(CrossServerBlobHold(
            self.inner.catalog.shared_blob_guard().await?,
        ))
    }

    /// Test hook: takes [`Store::shared_blob_hold`] as an ingest does, for a test to hold it
    /// across another store's sweep.
    #[doc(hidden)]
    pub async fn hold_shared_blob_lock(&self) -> Result<CrossServerBlobHold, StoreError> {
        self.shared_blob_hold().await
    }

    /// The cross-server blob lock, exclusive, if no other server holds it (see
    /// [`Store::shared_blob_hold`]); [`ExclusiveBlobGuard::NotNeeded`] without a bucket or
    /// with SQLite. Never waits.
    pub(crate) async fn try_exclusive_blob_hold(&self) -> Result<ExclusiveBlobGuard, StoreError> {
        if self.inner.remote.is_none() {
            return Ok(ExclusiveBlobGuard::NotNeeded);
        }
        self.inner.catalog.try_exclusive_blob_guard().await
    }

    /// The rows of a session whose blob is at `rel`, in one transaction.
    async fn insert_session(
        &self,
        sha256: &str,
        size: i64,
        rel: &str,
        meta: SessionMeta,
        mut checked: Vec<CheckedSkill>,
        duration_ns: i64,
    ) -> Result<IngestOutcome, StoreError> {
        // On-line learning: each grasp is linked to the stored skill it matches, or stored as
        // new (against the skills stored before it).
        let recognition = self.recognition_index();
        let mut scratch = crate::assist::index::Scratch::default();
        for CheckedSkill { skill: s, feature } in &mut checked {
            if s.matched_skill_id.is_none() {
                let approach = s
                    .approach
                    .as_deref()
                    .and_then(|a| <[f32; TEMPLATE_DIM]>::try_from(a).ok());
                s.matched_skill_id = crate::assist::recognise::link_completed(
                    &recognition,
                    approach.as_ref(),
                    feature,
                    &crate::assist::recognise::RecogniserParams::default(),
                    &mut scratch,
                );
            }
        }
        let inserted = self
            .inner
            .catalog
            .insert_session(NewSession {
                sha256,
                size_bytes: size,
                blob_path: rel,
                meta: &meta,
                duration_ns,
                segmentation_version: SEGMENTATION_VERSION,
                skills: &checked,
            })
            .await?;
        let Some((session_id, skill_ids)) = inserted else {
            // A concurrent ingest of the same bytes committed first.
            return self
                .existing(sha256)
                .await?
                .ok_or_else(|| StoreError::Corrupt("session vanished during ingest".into()));
        };

        let mut index = self.inner.index.write().expect("index lock");
        for (id, c) in skill_ids.iter().zip(&checked) {
            index.insert(*id, c.feature);
        }
        drop(index);
        self.update_recognition(
            &[],
            skill_ids
                .iter()
                .zip(&checked)
                .map(|(id, c)| new_template(*id, c)),
        );
        tracing::debug!(session_id, skills = skill_ids.len(), "ingested session");
        Ok(IngestOutcome {
            session_id,
            created: true,
            matched_skill_ids: checked.iter().map(|c| c.skill.matched_skill_id).collect(),
            skill_ids,
        })
    }

    /// Bulk path of the synthetic generator: writes the blobs, then stores every session of
    /// `batch` in ONE transaction, as fast as the backend can. Sessions whose bytes are already
    /// stored are skipped.
    pub(crate) async fn bulk_ingest(
        &self,
        batch: Vec<(Vec<u8>, SessionMeta, Vec<NewSkill>)>,
    ) -> Result<usize, StoreError> {
        let _guard = self.inner.blob_lock.read().await;
        let hold = self.shared_blob_hold().await?;
        let inserted = self.bulk_publish_and_insert(batch).await;
        hold.release().await;
        let (inserted, sessions) = inserted?;
        let stored = || {
            inserted
                .iter()
                .zip(&sessions)
                .flat_map(|(ids, (_, checked))| ids.iter().flatten().zip(checked))
        };
        let mut index = self.inner.index.write().expect("index lock");
        for (id, c) in stored() {
            index.insert(*id, c.feature);
        }
        drop(index);
        self.update_recognition(&[], stored().map(|(id, c)| new_template(*id, c)));
        Ok(stored().count())
    }

    /// [`Store::bulk_ingest`]'s blob writes, uploads and transaction; per session, its skills'
    /// ids (or `None`, stored already), and its (SHA-256, checked skills).
    #[allow(clippy::type_complexity)]
    async fn bulk_publish_and_insert(
        &self,
        batch: Vec<(Vec<u8>, SessionMeta, Vec<NewSkill>)>,
    ) -> Result<(Vec<Option<Vec<i64>>>, Vec<(String, Vec<CheckedSkill>)>), StoreError> {
        let mut prepared = Vec::with_capacity(batch.len());
        for (bytes, meta, skills) in batch {
            let checked = checked_skills(skills)?;
            let sha256 = blob::sha256_hex(&bytes);
            let dir = self.inner.dir.clone();
            let sha = sha256.clone();
            let size = bytes.len() as i64;
            let rel = tokio::task::spawn_blocking(move || blob::write_atomic(&dir, &sha, &bytes))
                .await
                .map_err(|e| StoreError::Corrupt(format!("blob writer task failed: {e}")))??;
            self.publish(&rel).await?;
            let duration_ns = i64::try_from(meta.duration_ns).unwrap_or(i64::MAX);
            prepared.push((sha256, size, rel, meta, checked, duration_ns));
        }
        let sessions: Vec<NewSession<'_>> = prepared
            .iter()
            .map(
                |(sha256, size, rel, meta, checked, duration_ns)| NewSession {
                    sha256,
                    size_bytes: *size,
                    blob_path: rel,
                    meta,
                    duration_ns: *duration_ns,
                    segmentation_version: SEGMENTATION_VERSION,
                    skills: checked,
                },
            )
            .collect();
        let inserted = self.inner.catalog.bulk_insert_sessions(&sessions).await?;
        drop(sessions);
        let sessions = prepared
            .into_iter()
            .map(|(sha256, _, _, _, checked, _)| (sha256, checked))
            .collect();
        Ok((inserted, sessions))
    }

    /// Sessions by ascending id, `limit` (1..=1000) per page, after `cursor`.
    pub async fn list_sessions(
        &self,
        limit: u32,
        cursor: Option<&str>,
    ) -> Result<Page<SessionRecord>, StoreError> {
        self.query_sessions(&SessionQuery {
            limit,
            cursor: cursor.map(str::to_owned),
            ..SessionQuery::default()
        })
        .await
    }

    /// Sessions matching every filter of `q`, by id (ascending, or newest first), `q.limit`
    /// (1..=1000) per page, after `q.cursor`. A cursor belongs to its order: one of the other
    /// order is [`StoreError::BadCursor`].
    pub async fn query_sessions(
        &self,
        q: &SessionQuery,
    ) -> Result<Page<SessionRecord>, StoreError> {
        let filter = query::session_filter(q, MAX_SESSION_LIMIT)?;
        let mut items = self.inner.catalog.sessions(&filter).await?;
        let more = items.len() > q.limit as usize;
        items.truncate(q.limit as usize);
        let next_cursor = match (more, items.last()) {
            (true, Some(last)) => Some(query::encode_cursor(
                query::session_tag(q.newest_first),
                query::After::Int(last.id),
            )),
            _ => None,
        };
        Ok(Page { items, next_cursor })
    }

    /// One session with its skill ids.
    pub async fn get_session(&self, id: i64) -> Result<SessionRecord, StoreError> {
        self.inner
            .catalog
            .session(id)
            .await?
            .ok_or(StoreError::SessionNotFound(id))
    }

    /// Absolute path of a session's MCAP blob (downloaded first from the bucket, if the store
    /// has one and the data directory has no copy).
    pub async fn session_blob_path(&self, id: i64) -> Result<PathBuf, StoreError> {
        let BlobRef { rel, .. } = self
            .inner
            .catalog
            .session_blob(id)
            .await?
            .ok_or(StoreError::SessionNotFound(id))?;
        self.local_blob(&rel).await
    }

    /// Uploads the blob at `rel`, just written to the data directory, to the store's bucket
    /// (if it has one), before any row names it.
    async fn publish(&self, rel: &str) -> Result<(), StoreError> {
        match &self.inner.remote {
            Some(remote) => remote.upload(&self.inner.dir.join(rel), rel).await,
            None => Ok(()),
        }
    }

    /// The path of the blob at `rel` in the data directory; with a bucket, a missing copy is
    /// downloaded first (checked against the hash its path names).
    pub(crate) async fn local_blob(&self, rel: &str) -> Result<PathBuf, StoreError> {
        let path = self.inner.dir.join(rel);
        let Some(remote) = &self.inner.remote else {
            return Ok(path);
        };
        if tokio::fs::metadata(&path).await.is_ok_and(|m| m.is_file()) {
            // Used now: trimming the copies keeps it a while (Store::trim_blob_copies).
            let touched = path.clone();
            let _ = tokio::task::spawn_blocking(move || blob::touch(&touched)).await;
            return Ok(path);
        }
        let sha256 = blob::sha256_of(rel)
            .ok_or_else(|| StoreError::Corrupt(format!("{rel:?} is not a blob path")))?;
        remote.download(rel, &sha256, &path).await?;
        Ok(path)
    }

    /// Removes the blob at `rel`: its file, and its object if the store has a bucket. Call
    /// once no row names it.
    pub(crate) async fn remove_blob(&self, rel: &str) -> Result<(), StoreError> {
        let dir = self.inner.dir.clone();
        let owned = rel.to_owned();
        tokio::task::spawn_blocking(move || blob::remove(&dir, &owned))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob removal task failed: {e}")))??;
        match &self.inner.remote {
            Some(remote) => remote.delete(rel).await,
            None => Ok(()),
        }
    }

    /// Bounds the data directory's copies of a bucket's blobs to `max_bytes`: while they hold
    /// more, removes the least recently used copy (by its modification time, which writing,
    /// downloading and each read through [`Store::local_blob`] set) that was last used at least
    /// `min_age` ago. The objects stay in the bucket; a removed copy is downloaded again when
    /// next read. Without a bucket the files are the blobs themselves: nothing is removed.
    ///
    /// It holds the blob lock that ingests hold from their copy's write to their commit, so no
    /// copy an ingest is uploading goes; a copy just downloaded or read is younger than
    /// `min_age` (the server uses [`ORPHAN_BLOB_MIN_AGE`]) and stays, and each candidate's
    /// time is read again just before its removal, so one read since the listing stays too.
    pub async fn trim_blob_copies(
        &self,
        max_bytes: u64,
        min_age: Duration,
    ) -> Result<TrimReport, StoreError> {
        if self.inner.remote.is_none() {
            return Ok(TrimReport::default());
        }
        // No ingest of this process is between its copy's write and its upload and commit
        // (they hold the lock shared), so no copy is removed from under an upload.
        let _no_ingest = self.inner.blob_lock.write().await;
        let dir = self.inner.dir.clone();
        tokio::task::spawn_blocking(move || trim_copies(&dir, max_bytes, min_age))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob copy trimming task failed: {e}")))
    }

    /// SQLite's `synchronous` setting on the store's connections (2 = `FULL`, 1 = `NORMAL`),
    /// as the data base reports it: what [`Durability`] became.
    pub async fn synchronous_setting(&self) -> Result<i64, StoreError> {
        self.inner.catalog.synchronous_setting().await
    }

    /// Removes blob files that no session or replay references (a blob written by an ingest
    /// whose transaction then failed, a kill between a delete's commit and its file removal)
    /// and that were last modified at least `min_age` ago; with a bucket, its objects too.
    ///
    /// Safe beside ingests in this process: the files are listed first, then, holding the
    /// blob lock every ingest holds from its blob write to its commit, the referenced paths are
    /// read and only listed files that no row names are removed; a blob an ingest is about to
    /// reference is either not listed yet or already committed. `min_age` guards ingests of
    /// another process on the same directory (`icms ingest --data` beside a server), which
    /// commit within seconds of their blob write: the server sweeps with
    /// [`ORPHAN_BLOB_MIN_AGE`].
    ///
    /// With a bucket shared by several servers on one PostgreSQL data base, another server's
    /// ingest is not under this lock but under its cross-server counterpart, an advisory lock
    /// of the data base ([`BLOB_LOCK_CLASS`]): every ingest holds it shared from its blob
    /// upload to its row's commit, and the sweep, holding the in-process lock, tries it
    /// exclusively before reading the referenced paths and keeps it until its last removal.
    /// While another server is ingesting the sweep does not wait: it removes nothing this
    /// round, logs it and says so ([`SweepReport::skipped_busy`]). So no removal runs while
    /// any server is between an upload and its commit, and a blob committed before the lock
    /// was taken is among the referenced paths: the window the former look-up-then-remove
    /// check left (another server uploading the same bytes again and committing between the
    /// two) is closed. Each candidate's object is still looked up again just before its
    /// removal, so an object written since the listing, or within `min_age`, is left alone
    /// (docs/backends.md).
    pub async fn sweep_orphan_blobs(&self, min_age: Duration) -> Result<SweepReport, StoreError> {
        let dir = self.inner.dir.clone();
        let mut listed = tokio::task::spawn_blocking(move || blob::blobs_older_than(&dir, min_age))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob listing task failed: {e}")))?;
        if let Some(remote) = &self.inner.remote {
            // A copy in the data directory and its object are one blob.
            let local: std::collections::HashSet<String> =
                listed.iter().map(|b| b.rel.clone()).collect();
            let objects = remote.blobs_older_than(min_age).await?;
            listed.extend(objects.into_iter().filter(|b| !local.contains(&b.rel)));
        }
        let mut report = SweepReport {
            examined: listed.len(),
            ..SweepReport::default()
        };
        if listed.is_empty() {
            return Ok(report);
        }
        let _guard = self.inner.blob_lock.write().await;
        let exclusive = match self.try_exclusive_blob_hold().await? {
            ExclusiveBlobGuard::Busy => {
                tracing::info!(
                    examined = report.examined,
                    "another server is ingesting into the bucket: unreferenced blobs are left \
                     for the next sweep"
                );
                report.skipped_busy = true;
                return Ok(report);
            }
            ExclusiveBlobGuard::Held(g) => Some(g),
            ExclusiveBlobGuard::NotNeeded => None,
        };
        let done = self.remove_orphans(listed, min_age, &mut report).await;
        if let Some(g) = exclusive {
            g.release().await;
        }
        done.map(|()| report)
    }

    /// The sweep's removals of the `listed` blobs that no row names, under the blob locks.
    async fn remove_orphans(
        &self,
        listed: Vec<blob::BlobFile>,
        min_age: Duration,
        report: &mut SweepReport,
    ) -> Result<(), StoreError> {
        let referenced = self.inner.catalog.referenced_blob_paths().await?;
        for orphan in listed.into_iter().filter(|b| !referenced.contains(&b.rel)) {
            if let Some(remote) = &self.inner.remote {
                let young = remote
                    .modified(&orphan.rel)
                    .await?
                    .is_some_and(|t| t.elapsed().map_or(true, |age| age < min_age));
                if young {
                    continue;
                }
            }
            match self.remove_blob(&orphan.rel).await {
                Ok(()) => {
                    report.removed += 1;
                    report.removed_bytes += orphan.bytes;
                }
                Err(e) => {
                    tracing::warn!(error = %e, blob = %orphan.rel, "could not remove an orphan blob")
                }
            }
        }
        Ok(())
    }

    /// Deletes a session, its skills, their phase rows and replays (one transaction), then its
    /// blob and its replays' blobs.
    pub async fn delete_session(&self, id: i64) -> Result<(), StoreError> {
        let _guard = self.inner.blob_lock.write().await;
        let deleted = self
            .inner
            .catalog
            .delete_session(id)
            .await?
            .ok_or(StoreError::SessionNotFound(id))?;
        self.forget(&deleted.skill_ids, &deleted.blobs).await;
        Ok(())
    }

    /// One skill.
    pub async fn get_skill(&self, id: i64) -> Result<SkillRecord, StoreError> {
        self.inner
            .catalog
            .skill(id)
            .await?
            .ok_or(StoreError::SkillNotFound(id))
    }

    /// The skills of `ids` in one query, in the order of `ids`; ids with no skill (deleted
    /// meanwhile) are left out. What `similar` answers its neighbours with, instead of one
    /// query per neighbour.
    pub async fn get_skills(&self, ids: &[i64]) -> Result<Vec<SkillRecord>, StoreError> {
        if ids.is_empty() {
            return Ok(Vec::new());
        }
        let mut by_id = self
            .inner
            .catalog
            .skills_by_id(ids)
            .await?
            .into_iter()
            .map(|s| (s.id, s))
            .collect::<std::collections::HashMap<_, _>>();
        Ok(ids.iter().filter_map(|id| by_id.remove(id)).collect())
    }

    /// Deletes one skill, its phase rows and its replays (one transaction; its session stays),
    /// then the replays' blobs.
    pub async fn delete_skill(&self, id: i64) -> Result<(), StoreError> {
        let _guard = self.inner.blob_lock.write().await;
        let blobs = self
            .inner
            .catalog
            .delete_skill(id)
            .await?
            .ok_or(StoreError::SkillNotFound(id))?;
        self.forget(&[id], &blobs).await;
        Ok(())
    }

    /// After a delete committed: drops the skills from the similarity index and removes the
    /// blobs no row names any more (a leftover blob is harmless garbage).
    async fn forget(&self, skill_ids: &[i64], blobs: &[BlobRef]) {
        self.inner
            .index
            .write()
            .expect("index lock")
            .remove_many(skill_ids);
        self.update_recognition(skill_ids, []);
        self.remove_unreferenced_blobs(blobs).await;
    }

    /// Skills matching the filters of `q`, sorted by `q.sort`, one page after `q.cursor`.
    pub async fn query_skills(&self, q: &SkillQuery) -> Result<Page<SkillRecord>, StoreError> {
        let filter = query::skill_filter(q)?;
        let mut items = self.inner.catalog.skills(&filter).await?;
        let limit = q.limit as usize;
        let more = items.len() > limit;
        items.truncate(limit);
        let next_cursor = match (more, items.last()) {
            (true, Some(last)) => Some(query::cursor_after(q.sort, last)),
            _ => None,
        };
        Ok(Page { items, next_cursor })
    }

    /// The `k` skills nearest to `feature` (Euclidean distance in feature space, nearest
    /// first, ties by id) as (skill id, distance). CPU only: about 1 ms per 100 000 skills.
    pub fn nearest(&self, feature: &[f32], k: usize) -> Result<Vec<(i64, f32)>, StoreError> {
        let q: [f32; FEATURE_DIM] = feature.try_into().map_err(|_| {
            StoreError::InvalidQuery(format!(
                "feature has {} values, expected {FEATURE_DIM}",
                feature.len()
            ))
        })?;
        if q.iter().any(|x| !x.is_finite()) {
            return Err(StoreError::InvalidQuery("feature must be finite".into()));
        }
        Ok(self
            .inner
            .index
            .read()
            .expect("index lock")
            .nearest(&q, k, None))
    }

    /// The `k` skills nearest to skill `id`, leaving out the skill itself.
    pub fn nearest_to_skill(&self, id: i64, k: usize) -> Result<Vec<(i64, f32)>, StoreError> {
        let index = self.inner.index.read().expect("index lock");
        let q = index.get(id).ok_or(StoreError::SkillNotFound(id))?;
        Ok(index.nearest(&q, k, Some(id)))
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
