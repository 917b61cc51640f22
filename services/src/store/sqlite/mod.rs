//! The SQLite backend of the store's [`Catalog`]: the data base file `DIR/icms.sqlite3` (WAL
//! mode), its migrations (`migrations/`), and every query the store runs on it.
//!
//! Every fixed query is one of sqlx's compile-time-checked macros (`query!`, `query_as!`,
//! `query_scalar!`), checked against the migrated schema: with a data base at `DATABASE_URL`
//! while developing, from the query data committed in `.sqlx/` otherwise (regenerate it with
//! `scripts/sqlx-prepare` after changing a query or a migration). Built at run time, from
//! typed parts with every value bound, and shared with the PostgreSQL backend: the skill
//! filter ([`skill_filter`]) and the multi-row skill inserts ([`super::skill_insert`]).

mod hands;
mod jobs;
mod reprocess;
mod sessions;
mod skill_filter;
mod skills;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Duration;

use sqlx::migrate::Migrator;
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};
use sqlx::{Connection as _, SqliteConnection};

use super::catalog::{
    BlobGuard, BlobRef, Catalog, CheckedSkill, DeletedSession, ExclusiveBlobGuard, IndexedSkill,
    NewHand, NewJob, NewReplayRow, NewSession, Replacement, SettleRow,
};
use super::jobs::JobClaim;
use super::query::{SessionFilter, SkillFilter};
use super::rows::JobRow;
use super::types::{
    Hand, HandSummary, IngestOutcome, Replay, SessionRecord, SkillRecord, StaleSession,
};
use super::{Durability, StoreError};

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

static MIGRATOR: Migrator = sqlx::migrate!("../migrations");

/// The store's rows in a SQLite file. See the module documentation.
#[derive(Debug, Clone)]
pub(crate) struct SqliteCatalog {
    pool: SqlitePool,
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

/// Where the data base of `data_dir` is, after checking that what is there is ours: a file
/// of another application, or one a newer binary migrated, is refused before anything is
/// written. Without a data base (no file, or an empty one) it is
/// [`StoreError::NoDataBase`] unless `create`.
pub(crate) async fn locate(data_dir: &Path, create: bool) -> Result<PathBuf, StoreError> {
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
    Ok(db_path)
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
        // `+ 0`: an expression, whose type sqlx takes from the override; a bare pragma column
        // sends it looking for a table column of that name, which a pragma's is not.
        let app_id = match sqlx::query_scalar!(
            r#"SELECT application_id + 0 AS "id!: i32" FROM pragma_application_id()"#
        )
        .fetch_one(&mut conn)
        .await
        {
            Ok(v) => v,
            Err(e) if is_not_a_database(&e) => return Err(not_ours()),
            Err(e) => return Err(e.into()),
        };
        let tables = sqlx::query_scalar!(
            r#"SELECT name AS "name!: String" FROM sqlite_master
               WHERE type = 'table' AND name NOT LIKE 'sqlite_%'"#
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
            let found =
                sqlx::query_scalar!(r#"SELECT MAX(version) AS "v?: i64" FROM _sqlx_migrations"#)
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

impl SqliteCatalog {
    /// Opens the data base at `db_path` (found by [`locate`]), creating it if `create`, and
    /// migrates it. Settings: WAL journal, `foreign_keys=ON`, busy timeout 5 s, `synchronous`
    /// as `durability` says, a page cache of [`PAGE_CACHE_KIB`] per connection.
    pub(crate) async fn open(
        db_path: &Path,
        create: bool,
        durability: Durability,
    ) -> Result<SqliteCatalog, StoreError> {
        let opts = SqliteConnectOptions::new()
            .filename(db_path)
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
        Ok(SqliteCatalog { pool })
    }
}

#[async_trait::async_trait]
impl Catalog for SqliteCatalog {
    async fn stored_session(&self, sha256: &str) -> Result<Option<IngestOutcome>, StoreError> {
        sessions::stored(&self.pool, sha256).await
    }

    async fn insert_session(
        &self,
        new: NewSession<'_>,
    ) -> Result<Option<(i64, Vec<i64>)>, StoreError> {
        sessions::insert(&self.pool, new).await
    }

    async fn bulk_insert_sessions(
        &self,
        sessions: &[NewSession<'_>],
    ) -> Result<Vec<Option<Vec<i64>>>, StoreError> {
        sessions::bulk_insert(&self.pool, sessions).await
    }

    async fn session(&self, id: i64) -> Result<Option<SessionRecord>, StoreError> {
        sessions::get(&self.pool, id).await
    }

    async fn sessions(&self, filter: &SessionFilter<'_>) -> Result<Vec<SessionRecord>, StoreError> {
        sessions::list(&self.pool, filter).await
    }

    async fn session_blob(&self, id: i64) -> Result<Option<BlobRef>, StoreError> {
        sessions::blob(&self.pool, id).await
    }

    async fn delete_session(&self, id: i64) -> Result<Option<DeletedSession>, StoreError> {
        sessions::delete(&self.pool, id).await
    }

    async fn referenced_blob_paths(&self) -> Result<HashSet<String>, StoreError> {
        sessions::referenced_blob_paths(&self.pool).await
    }

    async fn blob_is_referenced(&self, sha256: &str) -> Result<bool, StoreError> {
        sessions::blob_is_referenced(&self.pool, sha256).await
    }

    async fn skill(&self, id: i64) -> Result<Option<SkillRecord>, StoreError> {
        skills::get(&self.pool, id).await
    }

    async fn skills_by_id(&self, ids: &[i64]) -> Result<Vec<SkillRecord>, StoreError> {
        skills::by_id(&self.pool, ids).await
    }

    async fn skills(&self, filter: &SkillFilter<'_>) -> Result<Vec<SkillRecord>, StoreError> {
        skill_filter::fetch(&self.pool, filter).await
    }

    async fn indexed_skills(&self) -> Result<Vec<IndexedSkill>, StoreError> {
        skills::indexed(&self.pool).await
    }

    async fn delete_skill(&self, id: i64) -> Result<Option<Vec<BlobRef>>, StoreError> {
        skills::delete(&self.pool, id).await
    }

    async fn insert_hand(&self, hand: NewHand<'_>) -> Result<Option<String>, StoreError> {
        hands::insert_hand(&self.pool, hand).await
    }

    async fn hands(&self) -> Result<Vec<HandSummary>, StoreError> {
        hands::hands(&self.pool).await
    }

    async fn hand(&self, name: &str) -> Result<Option<Hand>, StoreError> {
        hands::hand(&self.pool, name).await
    }

    async fn insert_replay(&self, replay: NewReplayRow<'_>) -> Result<Option<Replay>, StoreError> {
        hands::insert_replay(&self.pool, replay).await
    }

    async fn replay(&self, id: i64) -> Result<Option<Replay>, StoreError> {
        hands::replay(&self.pool, id).await
    }

    async fn replays_of(&self, skill_id: i64) -> Result<Option<Vec<Replay>>, StoreError> {
        hands::replays_of(&self.pool, skill_id).await
    }

    async fn replay_blob_path(&self, id: i64) -> Result<Option<String>, StoreError> {
        hands::replay_blob_path(&self.pool, id).await
    }

    async fn sessions_segmented_before(
        &self,
        version: u32,
    ) -> Result<Vec<StaleSession>, StoreError> {
        reprocess::segmented_before(&self.pool, version).await
    }

    async fn sessions_segmented_after(&self, version: u32) -> Result<u64, StoreError> {
        reprocess::segmented_after(&self.pool, version).await
    }

    async fn replace_session_skills(
        &self,
        session_id: i64,
        version: u32,
        skills: &[CheckedSkill],
    ) -> Result<Replacement, StoreError> {
        reprocess::replace(&self.pool, session_id, version, skills).await
    }

    async fn synchronous_setting(&self) -> Result<i64, StoreError> {
        Ok(sqlx::query_scalar!(
            r#"SELECT synchronous + 0 AS "synchronous!: i64" FROM pragma_synchronous()"#
        )
        .fetch_one(&self.pool)
        .await?)
    }

    async fn integrity_check(&self) -> Result<(), StoreError> {
        let messages = sqlx::query_scalar!(
            r#"SELECT group_concat(integrity_check, '; ') AS "messages!: String"
               FROM pragma_integrity_check()"#
        )
        .fetch_one(&self.pool)
        .await?;
        if messages != "ok" {
            return Err(StoreError::Corrupt(messages));
        }
        let dangling =
            sqlx::query_scalar!(r#"SELECT count(*) AS "n!: i64" FROM pragma_foreign_key_check()"#)
                .fetch_one(&self.pool)
                .await?;
        if dangling > 0 {
            return Err(StoreError::Corrupt(format!(
                "{dangling} dangling foreign keys"
            )));
        }
        Ok(())
    }

    async fn optimize(&self) -> Result<(), StoreError> {
        let mut conn = self.pool.acquire().await?;
        // It answers the limit set, which is of no interest.
        sqlx::query!("PRAGMA analysis_limit = 1000")
            .fetch_all(&mut *conn)
            .await?;
        sqlx::query!("ANALYZE").execute(&mut *conn).await?;
        Ok(())
    }

    async fn shared_blob_guard(&self) -> Result<Option<Box<dyn BlobGuard>>, StoreError> {
        // One process writes a SQLite file: the store's in-process blob lock is enough.
        Ok(None)
    }

    async fn try_exclusive_blob_guard(&self) -> Result<ExclusiveBlobGuard, StoreError> {
        Ok(ExclusiveBlobGuard::NotNeeded)
    }

    async fn insert_job(&self, job: NewJob<'_>) -> Result<Option<JobRow>, StoreError> {
        jobs::insert(&self.pool, job).await
    }

    async fn active_job(&self, key: &str) -> Result<Option<JobRow>, StoreError> {
        jobs::active(&self.pool, key).await
    }

    async fn queued_jobs(&self) -> Result<i64, StoreError> {
        jobs::queued(&self.pool).await
    }

    async fn job(&self, id: i64) -> Result<Option<JobRow>, StoreError> {
        jobs::get(&self.pool, id).await
    }

    async fn jobs(
        &self,
        state: Option<&str>,
        before: i64,
        limit: i64,
    ) -> Result<Vec<JobRow>, StoreError> {
        jobs::list(&self.pool, state, before, limit).await
    }

    async fn expire_jobs(&self, max_attempts: i64, detail: &str) -> Result<u64, StoreError> {
        jobs::expire(&self.pool, max_attempts, detail).await
    }

    async fn claim_job(
        &self,
        worker: &str,
        lease_ms: i64,
        max_attempts: i64,
    ) -> Result<Option<JobRow>, StoreError> {
        jobs::claim(&self.pool, worker, lease_ms, max_attempts).await
    }

    async fn renew_job(&self, claim: &JobClaim, lease_ms: i64) -> Result<Option<bool>, StoreError> {
        jobs::renew(&self.pool, claim, lease_ms).await
    }

    async fn settle_job(&self, claim: &JobClaim, end: SettleRow<'_>) -> Result<bool, StoreError> {
        jobs::settle(&self.pool, claim, end).await
    }

    async fn release_job(&self, claim: &JobClaim) -> Result<bool, StoreError> {
        jobs::release(&self.pool, claim).await
    }

    async fn cancel_job(&self, id: i64) -> Result<Option<JobRow>, StoreError> {
        jobs::cancel(&self.pool, id).await
    }

    async fn prune_jobs(&self, age_s: i64) -> Result<u64, StoreError> {
        jobs::prune(&self.pool, age_s).await
    }

    async fn close(&self) {
        self.pool.close().await;
    }
}
