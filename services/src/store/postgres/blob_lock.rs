//! The cross-server blob lock of stores that share one PostgreSQL data base and one bucket: a
//! session-level advisory lock, the counterpart across servers of the store's in-process blob
//! lock. An ingest holds it shared from its blob upload to its row's commit; the orphan sweep
//! and a delete's blob removal try it exclusively and, if another server is ingesting, leave
//! their removals for later (see `Store::sweep_orphan_blobs`).
//!
//! The lock is the two-key advisory lock ([`BLOB_LOCK_CLASS`], `hashtext(current_schema())`):
//! the first key is the project's, fixed; the second is (a hash of) the schema the rows are
//! in, the first of the connection's search path, so that stores on other schemas of the same
//! data base (another deployment, or the tests, each in a schema of its own) never wait for one
//! another. It is held on a connection taken from the
//! pool for the guard's life and let go by [`BlobGuard::release`]; a guard dropped without
//! that, or whose unlock failed, closes its connection (PostgreSQL ends the session and its
//! locks with it) instead of giving it back to the pool still holding the lock. At most half
//! the pool's connections are guards' at once (further ingests wait for a place), so that an
//! ingest holding its guard always finds a connection for its rows.
//!
//! Plain `sqlx::query`, not checked queries of `store-postgres`: these touch no table, so a
//! check against the schema has nothing to catch, and they are the only statements whose
//! connection matters (an advisory lock belongs to its session).

use std::sync::Arc;

use sqlx::pool::PoolConnection;
use sqlx::{Connection as _, PgPool, Postgres};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::super::catalog::{BlobGuard, ExclusiveBlobGuard};
use super::super::StoreError;

/// The first key of the blob lock (`pg_advisory_lock_shared(BLOB_LOCK_CLASS,
/// hashtext(current_schema()))`), fixed for the project: "ICMS blob" as 32 bits, 0x1C35_B10B.
/// Any other use of advisory locks on the same data base must not take this class.
pub const BLOB_LOCK_CLASS: i32 = 0x1C35_B10B;

const LOCK_SHARED: &str =
    "SELECT pg_advisory_lock_shared($1, hashtext(coalesce(current_schema(), '')))";
const TRY_LOCK_EXCLUSIVE: &str =
    "SELECT pg_try_advisory_lock($1, hashtext(coalesce(current_schema(), '')))";
const UNLOCK_SHARED: &str =
    "SELECT pg_advisory_unlock_shared($1, hashtext(coalesce(current_schema(), '')))";
const UNLOCK_EXCLUSIVE: &str =
    "SELECT pg_advisory_unlock($1, hashtext(coalesce(current_schema(), '')))";

/// The blob lock held (or being taken) on one pooled connection.
#[derive(Debug)]
struct PgBlobGuard {
    /// `None` once given back to the pool, unlocked.
    conn: Option<PoolConnection<Postgres>>,
    exclusive: bool,
    /// The guard's place among those that may hold a connection at once (at most half the
    /// pool: an ingest holding its guard needs another connection for its rows, and a pool
    /// all of whose connections guards held would leave every such ingest waiting).
    _permit: OwnedSemaphorePermit,
}

impl PgBlobGuard {
    async fn new(
        pool: &PgPool,
        permits: &Arc<Semaphore>,
        exclusive: bool,
    ) -> Result<PgBlobGuard, StoreError> {
        let permit = Arc::clone(permits)
            .acquire_owned()
            .await
            .map_err(|_| StoreError::Corrupt("blob lock permits closed".into()))?;
        Ok(PgBlobGuard {
            conn: Some(pool.acquire().await?),
            exclusive,
            _permit: permit,
        })
    }

    /// Runs one of the lock statements on the guard's connection. The guard owns the
    /// connection throughout, so a future cancelled while the lock is being granted drops
    /// the guard, which closes the connection.
    async fn run(&mut self, sql: &'static str) -> Result<Option<bool>, StoreError> {
        let conn = self
            .conn
            .as_mut()
            .ok_or_else(|| StoreError::Corrupt("blob lock connection already released".into()))?;
        // pg_advisory_lock_shared returns void, which sqlx cannot decode: read nothing then.
        if sql == LOCK_SHARED {
            sqlx::query(sql)
                .bind(BLOB_LOCK_CLASS)
                .execute(&mut **conn)
                .await?;
            return Ok(None);
        }
        let held: bool = sqlx::query_scalar(sql)
            .bind(BLOB_LOCK_CLASS)
            .fetch_one(&mut **conn)
            .await?;
        Ok(Some(held))
    }
}

/// Waits for the shared blob lock.
pub(super) async fn shared(
    pool: &PgPool,
    permits: &Arc<Semaphore>,
) -> Result<Box<dyn BlobGuard>, StoreError> {
    let mut guard = PgBlobGuard::new(pool, permits, false).await?;
    guard.run(LOCK_SHARED).await?;
    Ok(Box::new(guard))
}

/// The exclusive blob lock if no session holds the lock, without waiting.
pub(super) async fn try_exclusive(
    pool: &PgPool,
    permits: &Arc<Semaphore>,
) -> Result<ExclusiveBlobGuard, StoreError> {
    let mut guard = PgBlobGuard::new(pool, permits, true).await?;
    if guard.run(TRY_LOCK_EXCLUSIVE).await? == Some(true) {
        Ok(ExclusiveBlobGuard::Held(Box::new(guard)))
    } else {
        // Not locked: the connection goes back to the pool as it came.
        guard.conn.take();
        Ok(ExclusiveBlobGuard::Busy)
    }
}

#[async_trait::async_trait]
impl BlobGuard for PgBlobGuard {
    async fn release(mut self: Box<Self>) {
        let sql = if self.exclusive {
            UNLOCK_EXCLUSIVE
        } else {
            UNLOCK_SHARED
        };
        match self.run(sql).await {
            // Unlocked: the connection goes back to the pool.
            Ok(Some(true)) => drop(self.conn.take()),
            Ok(_) => tracing::warn!("the blob lock was not held at its release"),
            Err(e) => tracing::warn!(error = %e, "could not release the blob lock"),
        }
        // Otherwise dropping the guard closes its connection, which ends the lock.
    }
}

impl Drop for PgBlobGuard {
    fn drop(&mut self) {
        let Some(conn) = self.conn.take() else {
            return;
        };
        // Still (perhaps) locked: never back to the pool. Closing the session lets the lock go.
        let conn = conn.detach();
        match tokio::runtime::Handle::try_current() {
            Ok(rt) => {
                rt.spawn(async move {
                    let _ = conn.close().await;
                });
            }
            // No runtime: dropping the socket ends the session all the same.
            Err(_) => drop(conn),
        }
    }
}
