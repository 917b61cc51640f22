//! Uploaded hands and replays in SQLite.

use sqlx::SqlitePool;

use crate::store::catalog::{NewHand, NewReplayRow};
use crate::store::rows::{convert, HandRow, HandSummaryRow, ReplayRow};
use crate::store::types::{Hand, HandSummary, Replay};
use crate::store::StoreError;

/// Stores an uploaded hand; its creation time, or `None` when the name is taken.
pub(super) async fn insert_hand(
    pool: &SqlitePool,
    h: NewHand<'_>,
) -> Result<Option<String>, StoreError> {
    let c = h.columns()?;
    Ok(sqlx::query_scalar!(
        r#"INSERT INTO hands (name, spec, urdf, dof, fingers, dof_names, torque_limit_min,
               torque_limit_max) VALUES (?, ?, ?, ?, ?, ?, ?, ?)
           ON CONFLICT (name) DO NOTHING RETURNING created_at AS "created_at!""#,
        h.name,
        h.spec_json,
        h.urdf,
        c.dof,
        c.fingers,
        c.dof_names,
        c.torque_limit_min,
        c.torque_limit_max,
    )
    .fetch_optional(pool)
    .await?)
}

/// The uploaded hands, by upload.
pub(super) async fn hands(pool: &SqlitePool) -> Result<Vec<HandSummary>, StoreError> {
    let rows = sqlx::query_as!(
        HandSummaryRow,
        "SELECT name, dof, fingers, dof_names, torque_limit_min, torque_limit_max, created_at
         FROM hands ORDER BY id"
    )
    .fetch_all(pool)
    .await?;
    convert(rows)
}

/// One uploaded hand with its spec and URDF.
pub(super) async fn hand(pool: &SqlitePool, name: &str) -> Result<Option<Hand>, StoreError> {
    sqlx::query_as!(
        HandRow,
        "SELECT name, spec, urdf, dof, fingers, dof_names, torque_limit_min, torque_limit_max,
             created_at
         FROM hands WHERE name = ?",
        name
    )
    .fetch_optional(pool)
    .await?
    .map(Hand::try_from)
    .transpose()
}

/// Stores a replay of skill `r.skill_id` if that skill exists.
pub(super) async fn insert_replay(
    pool: &SqlitePool,
    r: NewReplayRow<'_>,
) -> Result<Option<Replay>, StoreError> {
    sqlx::query_as!(
        ReplayRow,
        r#"INSERT INTO replays (skill_id, hand, success, failure_reason, report, sha256,
               size_bytes, blob_path)
           SELECT ?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8 WHERE EXISTS (SELECT 1 FROM skills WHERE id = ?1)
           RETURNING id AS "id!", skill_id AS "skill_id!", hand AS "hand!",
               success AS "success!: bool", failure_reason, report AS "report!",
               sha256 AS "sha256!", size_bytes AS "size_bytes!", blob_path AS "blob_path!",
               created_at AS "created_at!""#,
        r.skill_id,
        r.hand,
        r.success,
        r.failure_reason,
        r.report,
        r.sha256,
        r.size_bytes,
        r.blob_path,
    )
    .fetch_optional(pool)
    .await?
    .map(Replay::try_from)
    .transpose()
}

/// One replay.
pub(super) async fn replay(pool: &SqlitePool, id: i64) -> Result<Option<Replay>, StoreError> {
    sqlx::query_as!(
        ReplayRow,
        r#"SELECT id AS "id!", skill_id, hand, success AS "success: bool", failure_reason,
               report, sha256, size_bytes, blob_path, created_at
           FROM replays WHERE id = ?"#,
        id
    )
    .fetch_optional(pool)
    .await?
    .map(Replay::try_from)
    .transpose()
}

/// The replays of one skill by ascending id, or `None` without that skill (one read
/// transaction, so a skill deleted meanwhile is not answered with an empty list).
pub(super) async fn replays_of(
    pool: &SqlitePool,
    skill_id: i64,
) -> Result<Option<Vec<Replay>>, StoreError> {
    let mut tx = pool.begin().await?;
    let exists = sqlx::query_scalar!(r#"SELECT id AS "id!" FROM skills WHERE id = ?"#, skill_id)
        .fetch_optional(&mut *tx)
        .await?;
    if exists.is_none() {
        return Ok(None);
    }
    let rows = sqlx::query_as!(
        ReplayRow,
        r#"SELECT id AS "id!", skill_id, hand, success AS "success: bool", failure_reason,
               report, sha256, size_bytes, blob_path, created_at
           FROM replays WHERE skill_id = ? ORDER BY id"#,
        skill_id
    )
    .fetch_all(&mut *tx)
    .await?;
    tx.commit().await?;
    convert(rows).map(Some)
}

/// The blob path of replay `id`.
pub(super) async fn replay_blob_path(
    pool: &SqlitePool,
    id: i64,
) -> Result<Option<String>, StoreError> {
    Ok(
        sqlx::query_scalar!("SELECT blob_path FROM replays WHERE id = ?", id)
            .fetch_optional(pool)
            .await?,
    )
}
