//! The store's error type: every way an open, ingest or query can fail.

use std::path::PathBuf;

/// An error from the skill store ([`crate::store::Store`]).
///
/// Messages say what was wrong without leaking SQL; the API maps each variant to a status.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The database file belongs to something else: another application id, tables without the
    /// ICMS marker, or not a SQLite database at all.
    #[error(
        "{0} is not an ICMS database (another application's SQLite file or not SQLite at all); \
         refusing to touch it — choose another data directory"
    )]
    NotOurs(PathBuf),
    /// [`crate::store::Store::open_existing`] found no data base in this directory (no
    /// database file, or an empty one); nothing was created.
    #[error("no ICMS data base at {0}")]
    NoDataBase(PathBuf),
    /// Another process writes this data directory (an `icms serve`, an `icms ingest`, ...): one
    /// writer at a time, or the other's caches would answer wrongly.
    #[error(
        "the data directory {dir} is in use by another icms process ({holder}); one process at a \
         time may write it: stop that one, or send the work to its HTTP API"
    )]
    InUse {
        /// The data directory.
        dir: PathBuf,
        /// Who holds it, as it wrote itself into the lock file (pid and command line).
        holder: String,
    },
    /// The database was migrated by a newer binary than this one.
    #[error(
        "the database schema is version {found}, newer than this binary supports ({supported}); \
         upgrade icms"
    )]
    SchemaTooNew {
        /// Newest migration version applied to the database.
        found: i64,
        /// Newest migration version this binary knows.
        supported: i64,
    },
    /// The PostgreSQL data base of `--database-url` could not be reached or refused the
    /// connection (wrong address, server down, wrong password, no such data base).
    #[error(
        "cannot connect to the PostgreSQL data base {url}: {reason} (check --database-url or \
         DATABASE_URL, and that the server runs and accepts this user)"
    )]
    Unreachable {
        /// The data base URL, its password hidden.
        url: String,
        /// What failed.
        reason: String,
    },
    /// The bucket of `--blobs` could not be reached, refused a request, or failed one (wrong
    /// endpoint, no such bucket, wrong credentials, a server that does not answer).
    #[error(
        "the object store {bucket} failed: {reason} (check --blobs, AWS_ENDPOINT_URL and the \
         credentials in AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY)"
    )]
    ObjectStore {
        /// The bucket, its prefix and endpoint.
        bucket: String,
        /// What failed.
        reason: String,
    },
    /// A pagination cursor that this store did not produce, or one from another sort order.
    #[error("malformed pagination cursor (pass back next_cursor unchanged, with the same sort)")]
    BadCursor,
    /// A query parameter out of range (limit, a min above its max, a non-finite bound, ...).
    #[error("invalid query: {0}")]
    InvalidQuery(String),
    /// Ingest input that cannot be stored (wrong feature length, non-finite numbers, ...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// No session with this id.
    #[error("no session with id {0}")]
    SessionNotFound(i64),
    /// No skill with this id.
    #[error("no skill with id {0}")]
    SkillNotFound(i64),
    /// No robot hand (built-in or uploaded) with this name.
    #[error("no hand named {0:?}")]
    HandNotFound(String),
    /// No replay with this id.
    #[error("no replay with id {0}")]
    ReplayNotFound(i64),
    /// No job with this id.
    #[error("no job with id {0}")]
    JobNotFound(i64),
    /// Too many jobs wait for a worker already (their number): the work was not accepted.
    #[error("{0} simulations and replays wait for a worker already; try again when fewer do")]
    QueueFull(u64),
    /// A hand that cannot be built: its URDF or spec is invalid (the message names the problem).
    #[error("the hand is invalid: {0}")]
    InvalidHand(String),
    /// A name already taken (a hand named like a built-in or a stored hand).
    #[error("{0}")]
    Conflict(String),
    /// A row or blob failed a consistency check.
    #[error("store is corrupt: {0}")]
    Corrupt(String),
    /// A file system operation failed (full disk, permissions, ...).
    #[error("I/O error on {path}: {source}")]
    Io {
        /// The file or directory involved.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The database failed.
    #[error("database error: {0}")]
    Db(#[from] sqlx::Error),
    /// Running the migrations failed.
    #[error("database migration failed: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// A JSON column could not be encoded or decoded.
    #[error("JSON column error: {0}")]
    Json(#[from] serde_json::Error),
}

impl StoreError {
    /// Whether the data base was too busy to answer in time: another connection held the
    /// write lock past the busy timeout (`SQLITE_BUSY`, `SQLITE_LOCKED` and their extended
    /// codes), or no pooled connection came free in time. Nothing was written; the same call
    /// may succeed later.
    pub fn is_busy(&self) -> bool {
        match self {
            StoreError::Db(sqlx::Error::PoolTimedOut) => true,
            // PostgreSQL: serialization failure, deadlock, lock not available.
            StoreError::Db(sqlx::Error::Database(d))
                if d.try_downcast_ref::<sqlx::postgres::PgDatabaseError>()
                    .is_some() =>
            {
                matches!(d.code().as_deref(), Some("40001" | "40P01" | "55P03"))
            }
            StoreError::Db(sqlx::Error::Database(d)) => d
                .code()
                .and_then(|c| c.parse::<i32>().ok())
                // The primary result code is the low byte of an extended one.
                .is_some_and(|c| matches!(c & 0xff, 5 | 6)),
            _ => false,
        }
    }

    /// Whether the data base could not be reached: its connection broke or could not be made
    /// (the server down, restarting or unreachable; PostgreSQL's connection-exception and
    /// shutdown codes). Nothing was written by the call; the pool connects again by itself, so
    /// the same call succeeds once the data base is back.
    pub fn is_unreachable(&self) -> bool {
        match self {
            StoreError::Db(sqlx::Error::Io(_) | sqlx::Error::Tls(_)) => true,
            StoreError::Db(sqlx::Error::Database(d))
                if d.try_downcast_ref::<sqlx::postgres::PgDatabaseError>()
                    .is_some() =>
            {
                d.code().is_some_and(|c| {
                    c.starts_with("08") || matches!(c.as_ref(), "57P01" | "57P02" | "57P03")
                })
            }
            _ => false,
        }
    }

    /// Wraps an I/O error with the path it happened on.
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        StoreError::Io {
            path: path.into(),
            source,
        }
    }
}
