//! Jobs in SQLite (see `store::jobs`). One process writes a SQLite file, and SQLite runs one
//! write at a time, so a claim is one `UPDATE` of the oldest claimable row.
//!
//! Times: `lease_until_ms` counts the data base's clock in ms since 1970
//! (`(julianday('now') - 2440587.5) * 86400000`), the text columns are RFC 3339 UTC.

use sqlx::SqlitePool;

use crate::store::catalog::{NewJob, SettleRow};
use crate::store::jobs::JobClaim;
use crate::store::rows::JobRow;
use crate::store::StoreError;

/// Inserts a job unless the same request has a waiting, running or done job, or its skill is
/// gone: `None` then.
pub(super) async fn insert(pool: &SqlitePool, j: NewJob<'_>) -> Result<Option<JobRow>, StoreError> {
    Ok(sqlx::query_as!(
        JobRow,
        r#"INSERT INTO jobs (kind, request_key, request, skill_id)
           SELECT ?1, ?2, ?3, ?4
           WHERE ?4 IS NULL OR EXISTS (SELECT 1 FROM skills WHERE id = ?4)
           ON CONFLICT (request_key) WHERE state IN ('queued', 'running', 'done') DO NOTHING
           RETURNING id AS "id!", kind AS "kind!", request AS "request!", state AS "state!",
               cancel_requested AS "cancel_requested!: bool", attempts AS "attempts!", worker,
               session_id, session_created AS "session_created: bool", replay_id,
               error_status, error_detail, created_at AS "created_at!", started_at,
               finished_at"#,
        j.kind,
        j.key,
        j.request,
        j.skill_id,
    )
    .fetch_optional(pool)
    .await?)
}

/// The waiting, running or done job of a request.
pub(super) async fn active(pool: &SqlitePool, key: &str) -> Result<Option<JobRow>, StoreError> {
    Ok(sqlx::query_as!(
        JobRow,
        r#"SELECT id AS "id!", kind, request, state,
               cancel_requested AS "cancel_requested: bool", attempts, worker, session_id,
               session_created AS "session_created: bool", replay_id, error_status,
               error_detail, created_at, started_at, finished_at
           FROM jobs WHERE request_key = ? AND state IN ('queued', 'running', 'done')"#,
        key
    )
    .fetch_optional(pool)
    .await?)
}

/// Number of jobs waiting for a worker.
pub(super) async fn queued(pool: &SqlitePool) -> Result<i64, StoreError> {
    Ok(
        sqlx::query_scalar!(r#"SELECT COUNT(*) AS "n!: i64" FROM jobs WHERE state = 'queued'"#)
            .fetch_one(pool)
            .await?,
    )
}

/// One job.
pub(super) async fn get(pool: &SqlitePool, id: i64) -> Result<Option<JobRow>, StoreError> {
    Ok(sqlx::query_as!(
        JobRow,
        r#"SELECT id AS "id!", kind, request, state,
               cancel_requested AS "cancel_requested: bool", attempts, worker, session_id,
               session_created AS "session_created: bool", replay_id, error_status,
               error_detail, created_at, started_at, finished_at
           FROM jobs WHERE id = ?"#,
        id
    )
    .fetch_optional(pool)
    .await?)
}

/// Jobs with an id below `before`, in `state` if given, newest first, at most `limit`.
pub(super) async fn list(
    pool: &SqlitePool,
    state: Option<&str>,
    before: i64,
    limit: i64,
) -> Result<Vec<JobRow>, StoreError> {
    Ok(sqlx::query_as!(
        JobRow,
        r#"SELECT id AS "id!", kind, request, state,
               cancel_requested AS "cancel_requested: bool", attempts, worker, session_id,
               session_created AS "session_created: bool", replay_id, error_status,
               error_detail, created_at, started_at, finished_at
           FROM jobs WHERE (?1 IS NULL OR state = ?1) AND id < ?2 ORDER BY id DESC LIMIT ?3"#,
        state,
        before,
        limit,
    )
    .fetch_all(pool)
    .await?)
}

/// Ends the running jobs whose lease ran out and that may not be claimed again: cancelled if
/// someone asked, failed with `detail` if they had `max_attempts` claims. Their number.
pub(super) async fn expire(
    pool: &SqlitePool,
    max_attempts: i64,
    detail: &str,
) -> Result<u64, StoreError> {
    Ok(sqlx::query!(
        r#"UPDATE jobs SET
               state = CASE WHEN cancel_requested THEN 'cancelled' ELSE 'failed' END,
               error_status = CASE WHEN cancel_requested THEN NULL ELSE 503 END,
               error_detail = CASE WHEN cancel_requested THEN NULL ELSE ?2 END,
               finished_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now'), lease_until_ms = NULL
           WHERE state = 'running'
               AND lease_until_ms < CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER)
               AND (cancel_requested OR attempts >= ?1)"#,
        max_attempts,
        detail,
    )
    .execute(pool)
    .await?
    .rows_affected())
}

/// Claims the oldest waiting job, or the oldest running one whose lease ran out (its worker
/// died) and that had fewer than `max_attempts` claims.
pub(super) async fn claim(
    pool: &SqlitePool,
    worker: &str,
    lease_ms: i64,
    max_attempts: i64,
) -> Result<Option<JobRow>, StoreError> {
    Ok(sqlx::query_as!(
        JobRow,
        r#"UPDATE jobs SET state = 'running', worker = ?1, attempts = attempts + 1,
               lease_until_ms =
                   CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER) + ?2,
               started_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
           WHERE id = (SELECT id FROM jobs
               WHERE state = 'queued'
                   OR (state = 'running' AND NOT cancel_requested AND attempts < ?3
                       AND lease_until_ms
                           < CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER))
               ORDER BY id LIMIT 1)
           RETURNING id AS "id!", kind AS "kind!", request AS "request!", state AS "state!",
               cancel_requested AS "cancel_requested!: bool", attempts AS "attempts!", worker,
               session_id, session_created AS "session_created: bool", replay_id,
               error_status, error_detail, created_at AS "created_at!", started_at,
               finished_at"#,
        worker,
        lease_ms,
        max_attempts,
    )
    .fetch_optional(pool)
    .await?)
}

/// Renews a claim for `lease_ms`: whether someone asked to cancel the job, or `None` when the
/// claim is gone.
pub(super) async fn renew(
    pool: &SqlitePool,
    c: &JobClaim,
    lease_ms: i64,
) -> Result<Option<bool>, StoreError> {
    let attempt = i64::from(c.attempt);
    Ok(sqlx::query_scalar!(
        r#"UPDATE jobs SET lease_until_ms =
               CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER) + ?4
           WHERE id = ?1 AND worker = ?2 AND attempts = ?3 AND state = 'running'
           RETURNING cancel_requested AS "cancel_requested!: bool""#,
        c.id,
        c.worker,
        attempt,
        lease_ms,
    )
    .fetch_optional(pool)
    .await?)
}

/// Ends a claim with `end`; whether the claim still held.
pub(super) async fn settle(
    pool: &SqlitePool,
    c: &JobClaim,
    end: SettleRow<'_>,
) -> Result<bool, StoreError> {
    let attempt = i64::from(c.attempt);
    Ok(sqlx::query!(
        r#"UPDATE jobs SET state = ?4, session_id = ?5, session_created = ?6, replay_id = ?7,
               error_status = ?8, error_detail = ?9,
               finished_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now'), lease_until_ms = NULL
           WHERE id = ?1 AND worker = ?2 AND attempts = ?3 AND state = 'running'"#,
        c.id,
        c.worker,
        attempt,
        end.state,
        end.session_id,
        end.session_created,
        end.replay_id,
        end.error_status,
        end.error_detail,
    )
    .execute(pool)
    .await?
    .rows_affected()
        == 1)
}

/// Gives a claimed job back to the queue, this attempt not counted (cancelled instead if
/// someone asked); whether the claim still held.
pub(super) async fn release(pool: &SqlitePool, c: &JobClaim) -> Result<bool, StoreError> {
    let attempt = i64::from(c.attempt);
    Ok(sqlx::query!(
        r#"UPDATE jobs SET
               state = CASE WHEN cancel_requested THEN 'cancelled' ELSE 'queued' END,
               finished_at = CASE WHEN cancel_requested
                   THEN strftime('%Y-%m-%dT%H:%M:%fZ', 'now') END,
               worker = NULL, lease_until_ms = NULL, started_at = NULL,
               attempts = attempts - 1
           WHERE id = ?1 AND worker = ?2 AND attempts = ?3 AND state = 'running'"#,
        c.id,
        c.worker,
        attempt,
    )
    .execute(pool)
    .await?
    .rows_affected()
        == 1)
}

/// Cancels a job: a waiting one at once, a running one at its worker's next renewal (asked
/// for here); a finished one stays as it is. The job after that, or `None` without it.
pub(super) async fn cancel(pool: &SqlitePool, id: i64) -> Result<Option<JobRow>, StoreError> {
    Ok(sqlx::query_as!(
        JobRow,
        r#"UPDATE jobs SET
               state = CASE WHEN state = 'queued' THEN 'cancelled' ELSE state END,
               finished_at = CASE WHEN state = 'queued'
                   THEN strftime('%Y-%m-%dT%H:%M:%fZ', 'now') ELSE finished_at END,
               cancel_requested = CASE WHEN state = 'running' THEN 1 ELSE cancel_requested END
           WHERE id = ?1
           RETURNING id AS "id!", kind AS "kind!", request AS "request!", state AS "state!",
               cancel_requested AS "cancel_requested!: bool", attempts AS "attempts!", worker,
               session_id, session_created AS "session_created: bool", replay_id,
               error_status, error_detail, created_at AS "created_at!", started_at,
               finished_at"#,
        id
    )
    .fetch_optional(pool)
    .await?)
}

/// Deletes the failed and cancelled jobs that ended more than `age_s` seconds ago; their
/// number.
pub(super) async fn prune(pool: &SqlitePool, age_s: i64) -> Result<u64, StoreError> {
    let modifier = format!("-{age_s} seconds");
    Ok(sqlx::query!(
        r#"DELETE FROM jobs WHERE state IN ('failed', 'cancelled')
           AND finished_at < strftime('%Y-%m-%dT%H:%M:%fZ', 'now', ?)"#,
        modifier
    )
    .execute(pool)
    .await?
    .rows_affected())
}
