//! Jobs in PostgreSQL: the queries of services' `store::jobs` (see migrations/postgres/0007_jobs.sql).
//!
//! A claim takes the oldest claimable row `FOR UPDATE SKIP LOCKED`: two workers claiming at
//! once each get a different job and never wait for the other's transaction. Times are the
//! data base server's (`clock_timestamp()`), so workers on machines whose clocks disagree
//! still agree on whose lease ran out.

use sqlx::PgExecutor;

use crate::rows::JobRow;
use crate::Result;

/// Inserts a job (kind, request key, request JSON, a replay's skill) unless the same request
/// has a waiting, running or done job, or the skill is gone: `None` then.
pub async fn insert<'e>(
    e: impl PgExecutor<'e>,
    kind: &str,
    key: &str,
    request: &str,
    skill_id: Option<i64>,
) -> Result<Option<JobRow>> {
    sqlx::query_as!(
        JobRow,
        r#"INSERT INTO jobs (kind, request_key, request, skill_id)
           SELECT $1, $2, $3, $4
           WHERE $4::bigint IS NULL OR EXISTS (SELECT 1 FROM skills WHERE id = $4)
           ON CONFLICT (request_key) WHERE state IN ('queued', 'running', 'done') DO NOTHING
           RETURNING id, kind, request, state, cancel_requested, attempts, worker, session_id,
               session_created, replay_id, error_status, error_detail, created_at, started_at,
               finished_at"#,
        kind,
        key,
        request,
        skill_id,
    )
    .fetch_optional(e)
    .await
}

/// The waiting, running or done job of a request.
pub async fn active<'e>(e: impl PgExecutor<'e>, key: &str) -> Result<Option<JobRow>> {
    sqlx::query_as!(
        JobRow,
        r#"SELECT id, kind, request, state, cancel_requested, attempts, worker, session_id,
               session_created, replay_id, error_status, error_detail, created_at, started_at,
               finished_at
           FROM jobs WHERE request_key = $1 AND state IN ('queued', 'running', 'done')"#,
        key
    )
    .fetch_optional(e)
    .await
}

/// Number of jobs waiting for a worker.
pub async fn queued<'e>(e: impl PgExecutor<'e>) -> Result<i64> {
    sqlx::query_scalar!(r#"SELECT COUNT(*) AS "n!" FROM jobs WHERE state = 'queued'"#)
        .fetch_one(e)
        .await
}

/// One job.
pub async fn get<'e>(e: impl PgExecutor<'e>, id: i64) -> Result<Option<JobRow>> {
    sqlx::query_as!(
        JobRow,
        r#"SELECT id, kind, request, state, cancel_requested, attempts, worker, session_id,
               session_created, replay_id, error_status, error_detail, created_at, started_at,
               finished_at
           FROM jobs WHERE id = $1"#,
        id
    )
    .fetch_optional(e)
    .await
}

/// Jobs with an id below `before`, in `state` if given, newest first, at most `limit`.
pub async fn list<'e>(
    e: impl PgExecutor<'e>,
    state: Option<&str>,
    before: i64,
    limit: i64,
) -> Result<Vec<JobRow>> {
    sqlx::query_as!(
        JobRow,
        r#"SELECT id, kind, request, state, cancel_requested, attempts, worker, session_id,
               session_created, replay_id, error_status, error_detail, created_at, started_at,
               finished_at
           FROM jobs WHERE ($1::text IS NULL OR state = $1) AND id < $2
           ORDER BY id DESC LIMIT $3"#,
        state,
        before,
        limit,
    )
    .fetch_all(e)
    .await
}

/// Ends the running jobs whose lease ran out and that may not be claimed again: cancelled if
/// someone asked, failed with 503 and `detail` after `max_attempts` claims. Their number.
pub async fn expire<'e>(e: impl PgExecutor<'e>, max_attempts: i64, detail: &str) -> Result<u64> {
    Ok(sqlx::query!(
        r#"UPDATE jobs SET
               state = CASE WHEN cancel_requested THEN 'cancelled' ELSE 'failed' END,
               error_status = CASE WHEN cancel_requested THEN NULL ELSE 503 END,
               error_detail = CASE WHEN cancel_requested THEN NULL ELSE $2 END,
               finished_at = to_char(now() AT TIME ZONE 'UTC', 'YYYY-MM-DD"T"HH24:MI:SS.MS"Z"'),
               lease_until_ms = NULL
           WHERE state = 'running'
               AND lease_until_ms < (extract(epoch FROM clock_timestamp()) * 1000)::bigint
               AND (cancel_requested OR attempts >= $1)"#,
        max_attempts,
        detail,
    )
    .execute(e)
    .await?
    .rows_affected())
}

/// Claims the oldest waiting job, or the oldest running one whose lease ran out with fewer
/// than `max_attempts` claims, skipping rows another claim has locked.
pub async fn claim<'e>(
    e: impl PgExecutor<'e>,
    worker: &str,
    lease_ms: i64,
    max_attempts: i64,
) -> Result<Option<JobRow>> {
    sqlx::query_as!(
        JobRow,
        r#"UPDATE jobs SET state = 'running', worker = $1, attempts = attempts + 1,
               lease_until_ms = (extract(epoch FROM clock_timestamp()) * 1000)::bigint + $2,
               started_at = to_char(now() AT TIME ZONE 'UTC', 'YYYY-MM-DD"T"HH24:MI:SS.MS"Z"')
           WHERE id = (SELECT id FROM jobs
               WHERE state = 'queued'
                   OR (state = 'running' AND NOT cancel_requested AND attempts < $3
                       AND lease_until_ms
                           < (extract(epoch FROM clock_timestamp()) * 1000)::bigint)
               ORDER BY id LIMIT 1 FOR UPDATE SKIP LOCKED)
           RETURNING id, kind, request, state, cancel_requested, attempts, worker, session_id,
               session_created, replay_id, error_status, error_detail, created_at, started_at,
               finished_at"#,
        worker,
        lease_ms,
        max_attempts,
    )
    .fetch_optional(e)
    .await
}

/// Renews the claim (job, worker, attempt) for `lease_ms`: whether a cancel was asked for, or
/// `None` when the claim is gone.
pub async fn renew<'e>(
    e: impl PgExecutor<'e>,
    id: i64,
    worker: &str,
    attempt: i64,
    lease_ms: i64,
) -> Result<Option<bool>> {
    sqlx::query_scalar!(
        r#"UPDATE jobs
           SET lease_until_ms = (extract(epoch FROM clock_timestamp()) * 1000)::bigint + $4
           WHERE id = $1 AND worker = $2 AND attempts = $3 AND state = 'running'
           RETURNING cancel_requested"#,
        id,
        worker,
        attempt,
        lease_ms,
    )
    .fetch_optional(e)
    .await
}

/// The columns a claim's end writes.
#[derive(Debug, Clone, Copy)]
pub struct Settle<'a> {
    /// `done`, `failed` or `cancelled`.
    pub state: &'a str,
    /// A simulation's session.
    pub session_id: Option<i64>,
    /// Whether the job stored that session.
    pub session_created: Option<bool>,
    /// A replay's id.
    pub replay_id: Option<i64>,
    /// A failure's HTTP status.
    pub error_status: Option<i64>,
    /// A failure's message.
    pub error_detail: Option<&'a str>,
}

/// Ends the claim (job, worker, attempt); whether it still held.
pub async fn settle<'e>(
    e: impl PgExecutor<'e>,
    id: i64,
    worker: &str,
    attempt: i64,
    s: Settle<'_>,
) -> Result<bool> {
    Ok(sqlx::query!(
        r#"UPDATE jobs SET state = $4, session_id = $5, session_created = $6, replay_id = $7,
               error_status = $8, error_detail = $9,
               finished_at = to_char(now() AT TIME ZONE 'UTC', 'YYYY-MM-DD"T"HH24:MI:SS.MS"Z"'),
               lease_until_ms = NULL
           WHERE id = $1 AND worker = $2 AND attempts = $3 AND state = 'running'"#,
        id,
        worker,
        attempt,
        s.state,
        s.session_id,
        s.session_created,
        s.replay_id,
        s.error_status,
        s.error_detail,
    )
    .execute(e)
    .await?
    .rows_affected()
        == 1)
}

/// Gives the claimed job back to the queue, its attempt not counted (cancelled instead if
/// someone asked); whether the claim still held.
pub async fn release<'e>(
    e: impl PgExecutor<'e>,
    id: i64,
    worker: &str,
    attempt: i64,
) -> Result<bool> {
    Ok(sqlx::query!(
        r#"UPDATE jobs SET
               state = CASE WHEN cancel_requested THEN 'cancelled' ELSE 'queued' END,
               finished_at = CASE WHEN cancel_requested THEN
                   to_char(now() AT TIME ZONE 'UTC', 'YYYY-MM-DD"T"HH24:MI:SS.MS"Z"') END,
               worker = NULL, lease_until_ms = NULL, started_at = NULL,
               attempts = attempts - 1
           WHERE id = $1 AND worker = $2 AND attempts = $3 AND state = 'running'"#,
        id,
        worker,
        attempt,
    )
    .execute(e)
    .await?
    .rows_affected()
        == 1)
}

/// Cancels a job: a waiting one at once, a running one at its worker's next renewal (asked
/// for here); a finished one stays. The job after that.
pub async fn cancel<'e>(e: impl PgExecutor<'e>, id: i64) -> Result<Option<JobRow>> {
    sqlx::query_as!(
        JobRow,
        r#"UPDATE jobs SET
               state = CASE WHEN state = 'queued' THEN 'cancelled' ELSE state END,
               finished_at = CASE WHEN state = 'queued' THEN
                   to_char(now() AT TIME ZONE 'UTC', 'YYYY-MM-DD"T"HH24:MI:SS.MS"Z"')
                   ELSE finished_at END,
               cancel_requested = (state = 'running') OR cancel_requested
           WHERE id = $1
           RETURNING id, kind, request, state, cancel_requested, attempts, worker, session_id,
               session_created, replay_id, error_status, error_detail, created_at, started_at,
               finished_at"#,
        id
    )
    .fetch_optional(e)
    .await
}

/// Deletes the failed and cancelled jobs that ended more than `age_s` seconds ago; their
/// number.
pub async fn prune<'e>(e: impl PgExecutor<'e>, age_s: f64) -> Result<u64> {
    Ok(sqlx::query!(
        r#"DELETE FROM jobs WHERE state IN ('failed', 'cancelled')
           AND finished_at < to_char((now() - make_interval(secs => $1)) AT TIME ZONE 'UTC',
               'YYYY-MM-DD"T"HH24:MI:SS.MS"Z"')"#,
        age_s
    )
    .execute(e)
    .await?
    .rows_affected())
}
