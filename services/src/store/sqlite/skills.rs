//! Skills in SQLite: reading them by id, loading the in-memory indexes, deleting one (a
//! session's skills are inserted by the shared [`crate::store::skill_insert`]).

use sqlx::SqlitePool;

use crate::store::catalog::{BlobRef, IndexedSkill};
use crate::store::rows::{convert, IndexedSkillRow, SkillRow};
use crate::store::types::SkillRecord;
use crate::store::StoreError;

/// One skill.
pub(super) async fn get(pool: &SqlitePool, id: i64) -> Result<Option<SkillRecord>, StoreError> {
    sqlx::query_as!(
        SkillRow,
        r#"SELECT id AS "id!", session_id, object_shape, object_name, object_mass, mu,
               contact_count, contact_model, grasp_type, quality, volume, duration_s, start_ns,
               end_ns, phase_durations, feature, params, approach, matched_skill_id, created_at,
               (SELECT segmentation_version FROM sessions WHERE sessions.id = skills.session_id)
                   AS "segmentation_version!: i64"
           FROM skills WHERE id = ?"#,
        id
    )
    .fetch_optional(pool)
    .await?
    .map(SkillRecord::try_from)
    .transpose()
}

/// The skills of `ids` in one query (in any order; missing ids left out).
pub(super) async fn by_id(pool: &SqlitePool, ids: &[i64]) -> Result<Vec<SkillRecord>, StoreError> {
    let ids = serde_json::to_string(ids)?;
    let rows = sqlx::query_as!(
        SkillRow,
        r#"SELECT id AS "id!", session_id, object_shape, object_name, object_mass, mu,
               contact_count, contact_model, grasp_type, quality, volume, duration_s, start_ns,
               end_ns, phase_durations, feature, params, approach, matched_skill_id, created_at,
               (SELECT segmentation_version FROM sessions WHERE sessions.id = skills.session_id)
                   AS "segmentation_version!: i64"
           FROM skills WHERE id IN (SELECT value FROM json_each(?))"#,
        ids
    )
    .fetch_all(pool)
    .await?;
    convert(rows)
}

/// Every skill as the in-memory indexes need it.
pub(super) async fn indexed(pool: &SqlitePool) -> Result<Vec<IndexedSkill>, StoreError> {
    let rows = sqlx::query_as!(
        IndexedSkillRow,
        r#"SELECT id AS "id!", feature, object_shape, grasp_type, object_name, approach
           FROM skills"#
    )
    .fetch_all(pool)
    .await?;
    convert(rows)
}

/// Deletes one skill, its phase rows (cascading) and its replays in one transaction; returns
/// the replays' blobs.
pub(super) async fn delete(pool: &SqlitePool, id: i64) -> Result<Option<Vec<BlobRef>>, StoreError> {
    let mut tx = pool.begin().await?;
    let blobs = sqlx::query_as!(
        BlobRef,
        r#"DELETE FROM replays WHERE skill_id = ?
           RETURNING sha256 AS "sha256!", blob_path AS "rel!""#,
        id
    )
    .fetch_all(&mut *tx)
    .await?;
    let done = sqlx::query!("DELETE FROM skills WHERE id = ?", id)
        .execute(&mut *tx)
        .await?;
    if done.rows_affected() == 0 {
        tx.rollback().await?;
        return Ok(None);
    }
    tx.commit().await?;
    Ok(Some(blobs))
}
