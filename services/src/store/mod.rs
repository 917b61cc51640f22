//! The skill data base: recorded sessions (content-addressed MCAP blobs plus metadata) and the
//! skills found in them, in SQLite through sqlx. The only SQL of the project lives here.
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
mod error;
mod hands;
mod knn;
mod query;
mod reprocess;
mod types;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use sqlx::migrate::Migrator;
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteRow,
    SqliteSynchronous,
};
use sqlx::{Connection as _, QueryBuilder, Row as _, Sqlite, SqliteConnection};

pub use blob::{StagedBlob, StagedWriter};
pub use error::StoreError;

use crate::assist::features::TEMPLATE_DIM;
use crate::assist::index::{RecognitionIndex, StoredTemplate};
use crate::segmentation::SEGMENTATION_VERSION;
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

/// What [`Store::sweep_orphan_blobs`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct SweepReport {
    /// Blob files old enough to be looked at.
    pub examined: usize,
    /// Unreferenced ones removed.
    pub removed: usize,
    /// Their bytes.
    pub removed_bytes: u64,
}
pub use hands::MAX_HAND_NAME;
pub use query::{
    SessionQuery, SkillQuery, SortField, SortKey, SortOrder, DEFAULT_LIMIT, MAX_LIMIT,
};
pub use types::{
    Hand, HandSummary, IngestOutcome, NewSkill, ObjectShape, Page, ReplacedSkills, Replay,
    SessionMeta, SessionRecord, SkillRecord, StaleSession, FEATURE_DIM,
};

use knn::FeatureIndex;

/// Connections the store's pool opens at most.
pub const MAX_CONNECTIONS: u32 = 8;

/// Page cache of one connection, KiB: 8 MiB, so [`MAX_CONNECTIONS`] hold at most 64 MiB. The
/// caches fill as the data base is read, so their bound is the server's memory growth as the
/// data base grows (the soak of issue 17 saw 32 MiB each keep the resident set rising for its
/// ten minutes).
pub const PAGE_CACHE_KIB: u32 = 8192;

/// `PRAGMA application_id` of an ICMS database: ASCII `ICMS`.
pub const APPLICATION_ID: i32 = 0x4943_4D53;
/// File name of the database inside the data directory.
pub const DB_FILE: &str = "icms.sqlite3";
/// Largest number of sessions [`Store::list_sessions`] returns per page.
pub const MAX_SESSION_LIMIT: u32 = 1000;

/// Columns of a session row (`FROM sessions s`), its skill ids as a JSON array.
const SESSION_COLUMNS: &str = "id, sha256, size_bytes, blob_path, meta, segmentation_version, \
     created_at, \
     (SELECT json_group_array(id) FROM (SELECT id FROM skills WHERE session_id = s.id \
     ORDER BY id)) AS skill_ids, \
     (SELECT json_group_array(matched_skill_id) FROM (SELECT matched_skill_id FROM skills \
     WHERE session_id = s.id ORDER BY id)) AS matched_skill_ids";

static MIGRATOR: Migrator = sqlx::migrate!("../migrations");

/// Handle to a data directory's database and blobs. Cheap to clone (shared state).
#[derive(Clone)]
pub struct Store {
    inner: Arc<Inner>,
}

struct Inner {
    dir: PathBuf,
    pool: SqlitePool,
    index: std::sync::RwLock<FeatureIndex>,
    /// The skills as recognition sees them; a snapshot is shared by the live sessions that
    /// recognise (copied on the next change while one holds it).
    recognition: std::sync::RwLock<Arc<RecognitionIndex>>,
    /// Ingests hold it shared from blob write to index update; deletes hold it exclusively.
    blob_lock: tokio::sync::RwLock<()>,
    /// The data directory's writer lock ([`WRITER_LOCK_FILE`]), held until [`Store::close`]
    /// or the last clone is dropped; `None` for a store opened to read only.
    writer: std::sync::Mutex<Option<std::fs::File>>,
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

fn newest_known_version() -> i64 {
    MIGRATOR.iter().map(|m| m.version).max().unwrap_or(0)
}

fn is_not_a_database(e: &sqlx::Error) -> bool {
    match e {
        // SQLITE_NOTADB = 26
        sqlx::Error::Database(d) => {
            d.code().as_deref() == Some("26") || d.message().contains("not a database")
        }
        _ => false,
    }
}

/// Refuses a database that is not ours, or that a newer binary migrated.
async fn check_existing(db_path: &Path) -> Result<(), StoreError> {
    let opts = SqliteConnectOptions::new()
        .filename(db_path)
        .create_if_missing(false)
        .busy_timeout(Duration::from_secs(5));
    let not_ours = || StoreError::NotOurs(db_path.to_path_buf());
    let mut conn = match SqliteConnection::connect_with(&opts).await {
        Ok(c) => c,
        Err(e) if is_not_a_database(&e) => return Err(not_ours()),
        Err(e) => return Err(e.into()),
    };
    let result = async {
        let app_id: i32 = match sqlx::query_scalar("PRAGMA application_id")
            .fetch_one(&mut conn)
            .await
        {
            Ok(v) => v,
            Err(e) if is_not_a_database(&e) => return Err(not_ours()),
            Err(e) => return Err(e.into()),
        };
        let tables: Vec<String> = sqlx::query_scalar(
            "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%'",
        )
        .fetch_all(&mut conn)
        .await?;
        if app_id != APPLICATION_ID {
            // A fresh file, or one that sqlx began to migrate before a crash (it creates
            // `_sqlx_migrations` outside the first migration's transaction), is fine.
            if app_id != 0 || tables.iter().any(|t| t != "_sqlx_migrations") {
                return Err(not_ours());
            }
        }
        if tables.iter().any(|t| t == "_sqlx_migrations") {
            let found: Option<i64> =
                sqlx::query_scalar("SELECT MAX(version) FROM _sqlx_migrations")
                    .fetch_one(&mut conn)
                    .await?;
            let supported = newest_known_version();
            if let Some(found) = found {
                if found > supported {
                    return Err(StoreError::SchemaTooNew { found, supported });
                }
            }
        }
        Ok(())
    }
    .await;
    let _ = conn.close().await;
    result
}

fn feature_from_blob(id: i64, bytes: &[u8]) -> Result<[f32; FEATURE_DIM], StoreError> {
    if bytes.len() != FEATURE_DIM * 4 {
        return Err(StoreError::Corrupt(format!(
            "skill {id}: feature has {} bytes, expected {}",
            bytes.len(),
            FEATURE_DIM * 4
        )));
    }
    let mut f = [0.0f32; FEATURE_DIM];
    for (i, c) in bytes.chunks_exact(4).enumerate() {
        f[i] = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    }
    Ok(f)
}

fn feature_to_blob(f: &[f32; FEATURE_DIM]) -> Vec<u8> {
    f.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// An approach template from its column (`None` for NULL).
fn approach_from_blob(
    id: i64,
    bytes: Option<&[u8]>,
) -> Result<Option<[f32; TEMPLATE_DIM]>, StoreError> {
    let Some(bytes) = bytes else { return Ok(None) };
    if bytes.len() != TEMPLATE_DIM * 4 {
        return Err(StoreError::Corrupt(format!(
            "skill {id}: approach has {} bytes, expected {}",
            bytes.len(),
            TEMPLATE_DIM * 4
        )));
    }
    let mut f = [0.0f32; TEMPLATE_DIM];
    for (i, c) in bytes.chunks_exact(4).enumerate() {
        f[i] = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    }
    Ok(Some(f))
}

/// A new skill stored as `id`, as recognition sees it.
fn new_template(id: i64, s: &NewSkill, feature: &[f32; FEATURE_DIM]) -> StoredTemplate {
    stored_template(
        id,
        s.object_shape.name(),
        &s.grasp_type,
        s.object_name.clone(),
        s.approach
            .as_deref()
            .and_then(|a| <[f32; TEMPLATE_DIM]>::try_from(a).ok()),
        *feature,
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

/// The name in the TEXT column `column` of skill `id`'s row as a value of `T` (a shape, a
/// contact model): a name `T` does not know is a corrupt row, named.
fn named_column<T: Named>(row: &SqliteRow, id: i64, column: &str) -> Result<T, StoreError> {
    let text: &str = row.try_get(column)?;
    T::from_name(text).map_err(|e| StoreError::Corrupt(format!("skill {id}: {column}: {e}")))
}

fn row_to_skill(row: &SqliteRow) -> Result<SkillRecord, StoreError> {
    let id: i64 = row.try_get("id")?;
    let feature: Vec<u8> = row.try_get("feature")?;
    let phases: String = row.try_get("phase_durations")?;
    let params: String = row.try_get("params")?;
    Ok(SkillRecord {
        id,
        session_id: row.try_get("session_id")?,
        object_shape: named_column(row, id, "object_shape")?,
        object_name: row.try_get("object_name")?,
        object_mass: row.try_get("object_mass")?,
        mu: row.try_get("mu")?,
        contact_count: row.try_get("contact_count")?,
        contact_model: named_column(row, id, "contact_model")?,
        grasp_type: row.try_get("grasp_type")?,
        quality: row.try_get("quality")?,
        volume: row.try_get("volume")?,
        duration_s: row.try_get("duration_s")?,
        start_ns: row.try_get("start_ns")?,
        end_ns: row.try_get("end_ns")?,
        phase_durations: serde_json::from_str(&phases)
            .map_err(|e| StoreError::Corrupt(format!("skill {id}: phase_durations: {e}")))?,
        feature: feature_from_blob(id, &feature)?.to_vec(),
        params: serde_json::from_str(&params)?,
        approach: approach_from_blob(id, row.try_get("approach")?)?
            .map(|a| a.iter().map(|v| v.is_finite().then_some(*v)).collect()),
        matched_skill_id: row.try_get("matched_skill_id")?,
        segmentation_version: segmentation_version(row)?,
        created_at: row.try_get("created_at")?,
    })
}

/// The `segmentation_version` column of a row (a session's, or a skill's from its session).
fn segmentation_version(row: &SqliteRow) -> Result<u32, StoreError> {
    let v: i64 = row.try_get("segmentation_version")?;
    u32::try_from(v)
        .map_err(|_| StoreError::Corrupt(format!("segmentation version {v} is out of range")))
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

/// Checks a skill before insertion; returns its feature as a fixed array.
/// A session's skills with their checked feature vectors, and its duration as the store's
/// signed column: what every ingest checks before it writes anything.
#[allow(clippy::type_complexity)]
fn checked_input(
    meta: &SessionMeta,
    skills: Vec<NewSkill>,
) -> Result<(Vec<(NewSkill, [f32; FEATURE_DIM])>, i64), StoreError> {
    let checked = skills
        .into_iter()
        .enumerate()
        .map(|(i, s)| validate_skill(i, &s).map(|f| (s, f)))
        .collect::<Result<Vec<_>, _>>()?;
    finite("object_mass", meta.object_mass)?;
    finite("mu", meta.mu)?;
    let duration_ns = i64::try_from(meta.duration_ns)
        .map_err(|_| StoreError::InvalidInput("duration_ns is too large".into()))?;
    Ok((checked, duration_ns))
}

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

/// Inserts validated skills of `session_id` and their phase rows inside `tx`; returns their ids.
async fn insert_skills(
    tx: &mut sqlx::Transaction<'_, Sqlite>,
    session_id: i64,
    skills: &[(NewSkill, [f32; FEATURE_DIM])],
) -> Result<Vec<i64>, StoreError> {
    let mut ids = Vec::with_capacity(skills.len());
    // Multi-row INSERTs: 17 bound values per skill stay far below SQLite's variable limit.
    for chunk in skills.chunks(500) {
        let mut rows = Vec::with_capacity(chunk.len());
        for (s, f) in chunk {
            rows.push((
                s,
                feature_to_blob(f),
                serde_json::to_string(&s.phase_durations)?,
                serde_json::to_string(&s.params)?,
            ));
        }
        let mut b: QueryBuilder<Sqlite> = QueryBuilder::new(
            "INSERT INTO skills (session_id, object_shape, object_name, object_mass, mu, \
             contact_count, contact_model, grasp_type, quality, volume, duration_s, start_ns, \
             end_ns, phase_durations, feature, params, approach, matched_skill_id) ",
        );
        b.push_values(&rows, |mut r, (s, f, ph, p)| {
            r.push_bind(session_id)
                .push_bind(s.object_shape.name())
                .push_bind(s.object_name.as_deref())
                .push_bind(s.object_mass)
                .push_bind(s.mu)
                .push_bind(s.contact_count)
                .push_bind(s.contact_model.name())
                .push_bind(s.grasp_type.as_str())
                .push_bind(s.quality)
                .push_bind(s.volume)
                .push_bind(s.duration_s)
                .push_bind(s.start_ns)
                .push_bind(s.end_ns)
                .push_bind(ph.as_str())
                .push_bind(f.as_slice())
                .push_bind(p.as_str())
                .push_bind(
                    s.approach
                        .as_ref()
                        .map(|a| a.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>()),
                )
                .push_bind(s.matched_skill_id);
        });
        b.push(" RETURNING id");
        let mut chunk_ids: Vec<i64> = b.build_query_scalar().fetch_all(&mut **tx).await?;
        // RETURNING order is unspecified; AUTOINCREMENT ids of one statement are consecutive.
        chunk_ids.sort_unstable();
        if chunk_ids.len() != chunk.len() {
            return Err(StoreError::Corrupt(
                "skill insert returned a wrong row count".into(),
            ));
        }
        let phases: Vec<(i64, i64, &str, f64)> = chunk
            .iter()
            .zip(&chunk_ids)
            .flat_map(|((s, _), id)| {
                s.phase_durations
                    .iter()
                    .enumerate()
                    .map(move |(ord, (phase, d))| (*id, ord as i64, phase.name(), *d))
            })
            .collect();
        for pchunk in phases.chunks(2000) {
            let mut b: QueryBuilder<Sqlite> =
                QueryBuilder::new("INSERT INTO skill_phases (skill_id, ord, name, duration_s) ");
            b.push_values(pchunk, |mut r, (id, ord, name, d)| {
                r.push_bind(*id)
                    .push_bind(*ord)
                    .push_bind(*name)
                    .push_bind(*d);
            });
            b.build().execute(&mut **tx).await?;
        }
        ids.extend(chunk_ids);
    }
    Ok(ids)
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
        if create {
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
                .map_err(|e| StoreError::io(data_dir, e))?;
        }
        let db_path = data_dir.join(DB_FILE);
        let exists = match tokio::fs::metadata(&db_path).await {
            Ok(md) => md.len() > 0,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
            // A missing directory, or a file where the directory should be.
            Err(e) if !create && e.kind() == std::io::ErrorKind::NotADirectory => false,
            Err(e) => return Err(StoreError::io(&db_path, e)),
        };
        if exists {
            check_existing(&db_path).await?;
        } else if !create {
            return Err(StoreError::NoDataBase(data_dir.to_path_buf()));
        }
        let writer = if write {
            let dir = data_dir.to_path_buf();
            Some(
                tokio::task::spawn_blocking(move || lock_for_writing(&dir))
                    .await
                    .map_err(|e| StoreError::io(data_dir, std::io::Error::other(e)))??,
            )
        } else {
            None
        };
        let opts = SqliteConnectOptions::new()
            .filename(&db_path)
            .create_if_missing(create)
            .journal_mode(SqliteJournalMode::Wal)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(5))
            .synchronous(match durability {
                Durability::Full => SqliteSynchronous::Full,
                Durability::Normal => SqliteSynchronous::Normal,
            })
            .pragma("cache_size", format!("-{PAGE_CACHE_KIB}"));
        let pool = SqlitePoolOptions::new()
            .max_connections(MAX_CONNECTIONS)
            .connect_with(opts)
            .await?;
        MIGRATOR.run(&pool).await?;
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

        let rows = sqlx::query(
            "SELECT id, feature, object_shape, grasp_type, object_name, approach FROM skills",
        )
        .fetch_all(&pool)
        .await?;
        let mut entries = Vec::with_capacity(rows.len());
        let mut templates = Vec::with_capacity(rows.len());
        for row in &rows {
            let id: i64 = row.try_get(0)?;
            let bytes: &[u8] = row.try_get(1)?;
            let feature = feature_from_blob(id, bytes)?;
            entries.push((id, feature));
            templates.push(stored_template(
                id,
                row.try_get(2)?,
                row.try_get(3)?,
                row.try_get(4)?,
                approach_from_blob(id, row.try_get(5)?)?,
                feature,
            ));
        }
        drop(rows);
        Ok(Store {
            inner: Arc::new(Inner {
                dir: data_dir.to_path_buf(),
                pool,
                index: std::sync::RwLock::new(FeatureIndex::from_entries(entries)),
                recognition: std::sync::RwLock::new(Arc::new(RecognitionIndex::new(templates))),
                blob_lock: tokio::sync::RwLock::new(()),
                writer: std::sync::Mutex::new(writer),
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
        self.inner.pool.close().await;
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
        let id: Option<i64> = sqlx::query_scalar("SELECT id FROM sessions WHERE sha256 = ?")
            .bind(sha256)
            .fetch_optional(&self.inner.pool)
            .await?;
        match id {
            None => Ok(None),
            Some(session_id) => {
                let (skill_ids, matched_skill_ids) = self.skill_ids_of(session_id).await?;
                Ok(Some(IngestOutcome {
                    session_id,
                    created: false,
                    skill_ids,
                    matched_skill_ids,
                }))
            }
        }
    }

    /// A session's skill ids, ascending, and the skills they were recognised as.
    async fn skill_ids_of(
        &self,
        session_id: i64,
    ) -> Result<(Vec<i64>, Vec<Option<i64>>), StoreError> {
        let rows: Vec<(i64, Option<i64>)> = sqlx::query_as(
            "SELECT id, matched_skill_id FROM skills WHERE session_id = ? ORDER BY id",
        )
        .bind(session_id)
        .fetch_all(&self.inner.pool)
        .await?;
        Ok(rows.into_iter().unzip())
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
        self.insert_session(&sha256, size, &rel, meta, checked, duration_ns)
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
        self.insert_session(&sha256, size, &rel, meta, checked, duration_ns)
            .await
    }

    /// The rows of a session whose blob is at `rel`, in one transaction.
    async fn insert_session(
        &self,
        sha256: &str,
        size: i64,
        rel: &str,
        meta: SessionMeta,
        mut checked: Vec<(NewSkill, [f32; FEATURE_DIM])>,
        duration_ns: i64,
    ) -> Result<IngestOutcome, StoreError> {
        let meta_json = serde_json::to_string(&meta)?;
        // On-line learning: each grasp is linked to the stored skill it matches, or stored as
        // new (against the skills stored before it).
        let recognition = self.recognition_index();
        let mut scratch = crate::assist::index::Scratch::default();
        for (s, f) in &mut checked {
            if s.matched_skill_id.is_none() {
                let approach = s
                    .approach
                    .as_deref()
                    .and_then(|a| <[f32; TEMPLATE_DIM]>::try_from(a).ok());
                s.matched_skill_id = crate::assist::recognise::link_completed(
                    &recognition,
                    approach.as_ref(),
                    f,
                    &crate::assist::recognise::RecogniserParams::default(),
                    &mut scratch,
                );
            }
        }
        let mut tx = self.inner.pool.begin().await?;
        let session_id: Option<i64> = sqlx::query_scalar(
            "INSERT INTO sessions (sha256, size_bytes, blob_path, scenario, hand, object_shape, \
             duration_ns, meta, segmentation_version) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?) \
             ON CONFLICT (sha256) DO NOTHING RETURNING id",
        )
        .bind(sha256)
        .bind(size)
        .bind(rel)
        .bind(meta.scenario.as_deref())
        .bind(&meta.hand)
        .bind(meta.object_shape.name())
        .bind(duration_ns)
        .bind(&meta_json)
        .bind(i64::from(SEGMENTATION_VERSION))
        .fetch_optional(&mut *tx)
        .await?;
        let Some(session_id) = session_id else {
            // A concurrent ingest of the same bytes committed first.
            tx.rollback().await?;
            return self
                .existing(sha256)
                .await?
                .ok_or_else(|| StoreError::Corrupt("session vanished during ingest".into()));
        };
        let skill_ids = insert_skills(&mut tx, session_id, &checked).await?;
        tx.commit().await?;

        let mut index = self.inner.index.write().expect("index lock");
        for (id, (_, f)) in skill_ids.iter().zip(&checked) {
            index.insert(*id, *f);
        }
        drop(index);
        self.update_recognition(
            &[],
            skill_ids
                .iter()
                .zip(&checked)
                .map(|(id, (s, f))| new_template(*id, s, f)),
        );
        tracing::debug!(session_id, skills = skill_ids.len(), "ingested session");
        Ok(IngestOutcome {
            session_id,
            created: true,
            matched_skill_ids: checked.iter().map(|(s, _)| s.matched_skill_id).collect(),
            skill_ids,
        })
    }

    /// Bulk path of the synthetic generator: writes the blobs, then stores every session of
    /// `batch` in ONE transaction on a connection with a large page cache (random-order inserts
    /// into the filter indexes dirty one page per row and index; bigger transactions and cache
    /// write each page fewer times). Sessions whose bytes are already stored are skipped.
    pub(crate) async fn bulk_ingest(
        &self,
        batch: Vec<(Vec<u8>, SessionMeta, Vec<NewSkill>)>,
    ) -> Result<usize, StoreError> {
        let _guard = self.inner.blob_lock.read().await;
        let mut prepared = Vec::with_capacity(batch.len());
        for (bytes, meta, skills) in batch {
            let checked = skills
                .into_iter()
                .enumerate()
                .map(|(i, s)| validate_skill(i, &s).map(|f| (s, f)))
                .collect::<Result<Vec<_>, _>>()?;
            let sha256 = blob::sha256_hex(&bytes);
            let dir = self.inner.dir.clone();
            let sha = sha256.clone();
            let size = bytes.len() as i64;
            let rel = tokio::task::spawn_blocking(move || blob::write_atomic(&dir, &sha, &bytes))
                .await
                .map_err(|e| StoreError::Corrupt(format!("blob writer task failed: {e}")))??;
            prepared.push((sha256, size, rel, meta, checked));
        }
        let mut conn = self.inner.pool.acquire().await?;
        sqlx::query("PRAGMA cache_size = -1048576")
            .execute(&mut *conn)
            .await?;
        let result = async {
            let mut tx = conn.begin().await?;
            let mut inserted = Vec::new();
            for (sha256, size, rel, meta, checked) in &prepared {
                let session_id: Option<i64> = sqlx::query_scalar(
                    "INSERT INTO sessions (sha256, size_bytes, blob_path, scenario, hand, \
                     object_shape, duration_ns, meta, segmentation_version) \
                     VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?) \
                     ON CONFLICT (sha256) DO NOTHING RETURNING id",
                )
                .bind(sha256)
                .bind(size)
                .bind(rel)
                .bind(meta.scenario.as_deref())
                .bind(&meta.hand)
                .bind(meta.object_shape.name())
                .bind(i64::try_from(meta.duration_ns).unwrap_or(i64::MAX))
                .bind(serde_json::to_string(meta)?)
                .bind(i64::from(SEGMENTATION_VERSION))
                .fetch_optional(&mut *tx)
                .await?;
                if let Some(session_id) = session_id {
                    let ids = insert_skills(&mut tx, session_id, checked).await?;
                    inserted.extend(
                        ids.into_iter()
                            .zip(checked)
                            .map(|(id, (s, f))| (id, *f, new_template(id, s, f))),
                    );
                }
            }
            tx.commit().await?;
            Ok::<_, StoreError>(inserted)
        }
        .await;
        sqlx::query(&format!("PRAGMA cache_size = -{PAGE_CACHE_KIB}"))
            .execute(&mut *conn)
            .await?;
        let inserted = result?;
        let mut index = self.inner.index.write().expect("index lock");
        for (id, f, _) in &inserted {
            index.insert(*id, *f);
        }
        drop(index);
        let n = inserted.len();
        self.update_recognition(&[], inserted.into_iter().map(|(_, _, t)| t));
        Ok(n)
    }

    fn row_to_session(row: &SqliteRow) -> Result<SessionRecord, StoreError> {
        let id: i64 = row.try_get("id")?;
        let meta: String = row.try_get("meta")?;
        let skill_ids: String = row.try_get("skill_ids")?;
        let matched: String = row.try_get("matched_skill_ids")?;
        Ok(SessionRecord {
            id,
            sha256: row.try_get("sha256")?,
            size_bytes: row.try_get("size_bytes")?,
            blob_path: row.try_get("blob_path")?,
            meta: serde_json::from_str(&meta)
                .map_err(|e| StoreError::Corrupt(format!("session {id}: meta: {e}")))?,
            skill_ids: serde_json::from_str(&skill_ids)?,
            matched_skill_ids: serde_json::from_str(&matched)?,
            segmentation_version: segmentation_version(row)?,
            created_at: row.try_get("created_at")?,
        })
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
        let limit = q.limit;
        if limit == 0 || limit > MAX_SESSION_LIMIT {
            return Err(StoreError::InvalidQuery(format!(
                "limit {limit} is outside 1..={MAX_SESSION_LIMIT}"
            )));
        }
        // Ascending pages keep the tag they always had, so their cursors stay valid.
        let tag = if q.newest_first {
            "sessions-desc"
        } else {
            "sessions"
        };
        let after = match &q.cursor {
            Some(c) => match query::decode_cursor(tag, false, c)? {
                query::After::Int(id) => Some(id),
                query::After::Real(..) => return Err(StoreError::BadCursor),
            },
            None => None,
        };
        let mut sql = format!("SELECT {SESSION_COLUMNS} FROM sessions s WHERE 1");
        if after.is_some() {
            sql.push_str(if q.newest_first {
                " AND id < ?"
            } else {
                " AND id > ?"
            });
        }
        if q.scenario.is_some() {
            sql.push_str(" AND scenario = ?");
        }
        if q.hand.is_some() {
            sql.push_str(" AND hand = ?");
        }
        if q.object_shape.is_some() {
            sql.push_str(" AND object_shape = ?");
        }
        sql.push_str(if q.newest_first {
            " ORDER BY id DESC LIMIT ?"
        } else {
            " ORDER BY id LIMIT ?"
        });
        let mut stmt = sqlx::query(&sql);
        if let Some(id) = after {
            stmt = stmt.bind(id);
        }
        if let Some(s) = &q.scenario {
            stmt = stmt.bind(s);
        }
        if let Some(h) = &q.hand {
            stmt = stmt.bind(h);
        }
        if let Some(shape) = q.object_shape {
            stmt = stmt.bind(shape.name());
        }
        let rows = stmt
            .bind(i64::from(limit) + 1)
            .fetch_all(&self.inner.pool)
            .await?;
        let more = rows.len() > limit as usize;
        let items = rows
            .iter()
            .take(limit as usize)
            .map(Self::row_to_session)
            .collect::<Result<Vec<_>, _>>()?;
        let next_cursor = match (more, items.last()) {
            (true, Some(last)) => Some(query::encode_cursor(tag, query::After::Int(last.id))),
            _ => None,
        };
        Ok(Page { items, next_cursor })
    }

    /// One session with its skill ids.
    pub async fn get_session(&self, id: i64) -> Result<SessionRecord, StoreError> {
        let row = sqlx::query(&format!(
            "SELECT {SESSION_COLUMNS} FROM sessions s WHERE id = ?"
        ))
        .bind(id)
        .fetch_optional(&self.inner.pool)
        .await?
        .ok_or(StoreError::SessionNotFound(id))?;
        Self::row_to_session(&row)
    }

    /// Absolute path of a session's MCAP blob.
    pub async fn session_blob_path(&self, id: i64) -> Result<PathBuf, StoreError> {
        let rel: String = sqlx::query_scalar("SELECT blob_path FROM sessions WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.inner.pool)
            .await?
            .ok_or(StoreError::SessionNotFound(id))?;
        Ok(self.inner.dir.join(rel))
    }

    /// SQLite's `synchronous` setting on the store's connections (2 = `FULL`, 1 = `NORMAL`),
    /// as the data base reports it: what [`Durability`] became.
    pub async fn synchronous_setting(&self) -> Result<i64, StoreError> {
        Ok(sqlx::query_scalar("PRAGMA synchronous")
            .fetch_one(&self.inner.pool)
            .await?)
    }

    /// Removes blob files that no session or replay references (a blob written by an ingest
    /// whose transaction then failed, a kill between a delete's commit and its file removal)
    /// and that were last modified at least `min_age` ago.
    ///
    /// Safe beside ingests in this process: the files are listed first, then, holding the
    /// blob lock every ingest holds from its blob write to its commit, the referenced paths are
    /// read and only listed files that no row names are removed; a blob an ingest is about to
    /// reference is either not listed yet or already committed. `min_age` guards ingests of
    /// another process on the same directory (`icms ingest --data` beside a server), which
    /// commit within seconds of their blob write: the server sweeps with
    /// [`ORPHAN_BLOB_MIN_AGE`].
    pub async fn sweep_orphan_blobs(&self, min_age: Duration) -> Result<SweepReport, StoreError> {
        let dir = self.inner.dir.clone();
        let listed = tokio::task::spawn_blocking(move || blob::blobs_older_than(&dir, min_age))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob listing task failed: {e}")))?;
        let mut report = SweepReport {
            examined: listed.len(),
            ..SweepReport::default()
        };
        if listed.is_empty() {
            return Ok(report);
        }
        let _guard = self.inner.blob_lock.write().await;
        let referenced: std::collections::HashSet<String> = sqlx::query_scalar(
            "SELECT blob_path FROM sessions UNION SELECT blob_path FROM replays",
        )
        .fetch_all(&self.inner.pool)
        .await?
        .into_iter()
        .collect();
        let orphans: Vec<blob::BlobFile> = listed
            .into_iter()
            .filter(|b| !referenced.contains(&b.rel))
            .collect();
        let dir = self.inner.dir.clone();
        let removed = tokio::task::spawn_blocking(move || {
            orphans
                .into_iter()
                .filter(|b| blob::remove(&dir, &b.rel).is_ok())
                .collect::<Vec<_>>()
        })
        .await
        .map_err(|e| StoreError::Corrupt(format!("blob sweeping task failed: {e}")))?;
        report.removed = removed.len();
        report.removed_bytes = removed.iter().map(|b| b.bytes).sum();
        Ok(report)
    }

    /// Deletes a session, its skills, their phase rows and replays (one transaction), then its
    /// blob and its replays' blobs.
    pub async fn delete_session(&self, id: i64) -> Result<(), StoreError> {
        let _guard = self.inner.blob_lock.write().await;
        let mut tx = self.inner.pool.begin().await?;
        let mut blobs =
            hands::delete_replays_of(&mut tx, "SELECT id FROM skills WHERE session_id = ?", id)
                .await?;
        let skill_ids: Vec<i64> =
            sqlx::query_scalar("DELETE FROM skills WHERE session_id = ? RETURNING id")
                .bind(id)
                .fetch_all(&mut *tx)
                .await?;
        let row: Option<(String, String)> =
            sqlx::query_as("DELETE FROM sessions WHERE id = ? RETURNING sha256, blob_path")
                .bind(id)
                .fetch_optional(&mut *tx)
                .await?;
        let Some(session_blob) = row else {
            tx.rollback().await?;
            return Err(StoreError::SessionNotFound(id));
        };
        tx.commit().await?;
        blobs.push(session_blob);
        self.forget(&skill_ids, &blobs).await;
        Ok(())
    }

    /// One skill.
    pub async fn get_skill(&self, id: i64) -> Result<SkillRecord, StoreError> {
        let row = sqlx::query(&format!(
            "SELECT {} FROM skills WHERE id = ?",
            query::SKILL_COLUMNS
        ))
        .bind(id)
        .fetch_optional(&self.inner.pool)
        .await?
        .ok_or(StoreError::SkillNotFound(id))?;
        row_to_skill(&row)
    }

    /// The skills of `ids` in one query, in the order of `ids`; ids with no skill (deleted
    /// meanwhile) are left out. What `similar` answers its neighbours with, instead of one
    /// query per neighbour.
    pub async fn get_skills(&self, ids: &[i64]) -> Result<Vec<SkillRecord>, StoreError> {
        if ids.is_empty() {
            return Ok(Vec::new());
        }
        let rows = sqlx::query(&format!(
            "SELECT {} FROM skills WHERE id IN (SELECT value FROM json_each(?))",
            query::SKILL_COLUMNS
        ))
        .bind(serde_json::to_string(ids)?)
        .fetch_all(&self.inner.pool)
        .await?;
        let mut by_id = rows
            .iter()
            .map(|row| row_to_skill(row).map(|s| (s.id, s)))
            .collect::<Result<std::collections::HashMap<_, _>, _>>()?;
        Ok(ids.iter().filter_map(|id| by_id.remove(id)).collect())
    }

    /// Deletes one skill, its phase rows and its replays (one transaction; its session stays),
    /// then the replays' blobs.
    pub async fn delete_skill(&self, id: i64) -> Result<(), StoreError> {
        let _guard = self.inner.blob_lock.write().await;
        let mut tx = self.inner.pool.begin().await?;
        let blobs = hands::delete_replays_of(&mut tx, "?", id).await?;
        let done = sqlx::query("DELETE FROM skills WHERE id = ?")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        if done.rows_affected() == 0 {
            tx.rollback().await?;
            return Err(StoreError::SkillNotFound(id));
        }
        tx.commit().await?;
        self.forget(&[id], &blobs).await;
        Ok(())
    }

    /// After a delete committed: drops the skills from the similarity index and removes the
    /// blobs no row names any more (a leftover blob is harmless garbage).
    async fn forget(&self, skill_ids: &[i64], blobs: &[(String, String)]) {
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
        let mut b = query::build(q)?;
        let rows = b.build().fetch_all(&self.inner.pool).await?;
        let limit = q.limit as usize;
        let more = rows.len() > limit;
        let items = rows
            .iter()
            .take(limit)
            .map(row_to_skill)
            .collect::<Result<Vec<_>, _>>()?;
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
        let msgs: Vec<String> = sqlx::query_scalar("PRAGMA integrity_check")
            .fetch_all(&self.inner.pool)
            .await?;
        if msgs != ["ok"] {
            return Err(StoreError::Corrupt(msgs.join("; ")));
        }
        let fk = sqlx::query("PRAGMA foreign_key_check")
            .fetch_all(&self.inner.pool)
            .await?;
        if !fk.is_empty() {
            return Err(StoreError::Corrupt(format!(
                "{} dangling foreign keys",
                fk.len()
            )));
        }
        Ok(())
    }

    /// Updates SQLite's planner statistics (`PRAGMA optimize`); worth it after bulk inserts.
    pub async fn optimize(&self) -> Result<(), StoreError> {
        let mut conn = self.inner.pool.acquire().await?;
        sqlx::query("PRAGMA analysis_limit = 1000")
            .execute(&mut *conn)
            .await?;
        sqlx::query("ANALYZE").execute(&mut *conn).await?;
        Ok(())
    }
}
