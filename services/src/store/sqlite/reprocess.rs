//! Reprocessing in SQLite: the sessions an older segmentation made, and replacing a session's
//! skills in one transaction.

use sqlx::{Sqlite, SqlitePool};

use crate::store::catalog::{BlobRef, CheckedSkill, Replacement};
use crate::store::reprocess::{check_deleted, new_forms, plan_rows, version_to_replace};
use crate::store::rows::{approach_to_blob, convert, StaleSessionRow, StoredSkillRow};
use crate::store::skill_insert::insert_skills;
use crate::store::types::StaleSession;
use crate::store::StoreError;

/// The sessions segmented by a version below `version`, by ascending id.
pub(super) async fn segmented_before(
    pool: &SqlitePool,
    version: u32,
) -> Result<Vec<StaleSession>, StoreError> {
    let version = i64::from(version);
    let rows = sqlx::query_as!(
        StaleSessionRow,
        r#"SELECT id AS "id!", segmentation_version,
               (SELECT count(*) FROM skills WHERE session_id = s.id) AS "skill_count!: i64"
           FROM sessions s WHERE segmentation_version < ? ORDER BY id"#,
        version
    )
    .fetch_all(pool)
    .await?;
    convert(rows)
}

/// Number of sessions segmented by a version above `version`.
pub(super) async fn segmented_after(pool: &SqlitePool, version: u32) -> Result<u64, StoreError> {
    let version = i64::from(version);
    let n = sqlx::query_scalar!(
        r#"SELECT count(*) AS "n!: i64" FROM sessions WHERE segmentation_version > ?"#,
        version
    )
    .fetch_one(pool)
    .await?;
    Ok(u64::try_from(n).unwrap_or(0))
}

/// Replaces the skills of session `session_id` with `skills` (segmentation `version`) in one
/// transaction that holds the write lock from its start, so that what it reads is what its
/// writes replace.
pub(super) async fn replace(
    pool: &SqlitePool,
    session_id: i64,
    version: u32,
    skills: &[CheckedSkill],
) -> Result<Replacement, StoreError> {
    let new_forms = new_forms(skills)?;
    // IMMEDIATE: the write lock from the start (a deferred transaction that reads first cannot
    // write after another connection's commit).
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let from = sqlx::query_scalar!(
        "SELECT segmentation_version FROM sessions WHERE id = ?",
        session_id
    )
    .fetch_optional(&mut *tx)
    .await?;
    let Some(from) = from else {
        tx.rollback().await?;
        return Ok(Replacement::SessionNotFound);
    };
    let Some(from_version) = version_to_replace(session_id, from, version)? else {
        tx.rollback().await?;
        return Ok(Replacement::UpToDate);
    };

    let old = sqlx::query_as!(
        StoredSkillRow,
        r#"SELECT id AS "id!", object_shape, object_name, object_mass, mu, contact_count,
               contact_model, grasp_type, quality, volume, duration_s, start_ns, end_ns,
               phase_durations, feature, params
           FROM skills WHERE session_id = ? ORDER BY id"#,
        session_id
    )
    .fetch_all(&mut *tx)
    .await?;
    let plan = plan_rows(old, &new_forms);

    // A kept skill takes the new approach template (derived data, not the skill's identity:
    // a skill stored before templates were gets one without losing its id).
    for &(id, i) in &plan.kept {
        let approach = skills[i].skill.approach.as_deref().map(approach_to_blob);
        sqlx::query!("UPDATE skills SET approach = ? WHERE id = ?", approach, id)
            .execute(&mut *tx)
            .await?;
    }
    let mut replay_blobs = Vec::new();
    if !plan.removed.is_empty() {
        let ids = serde_json::to_string(&plan.removed)?;
        replay_blobs = sqlx::query_as!(
            BlobRef,
            r#"DELETE FROM replays WHERE skill_id IN (SELECT value FROM json_each(?))
               RETURNING sha256 AS "sha256!", blob_path AS "rel!""#,
            ids
        )
        .fetch_all(&mut *tx)
        .await?;
        let done = sqlx::query!(
            "DELETE FROM skills WHERE id IN (SELECT value FROM json_each(?))",
            ids
        )
        .execute(&mut *tx)
        .await?;
        check_deleted(session_id, done.rows_affected(), &plan.removed)?;
    }
    let added = plan.added.iter().map(|&i| &skills[i]);
    let added_ids = insert_skills::<Sqlite>(&mut tx, session_id, added).await?;
    let version_column = i64::from(version);
    sqlx::query!(
        "UPDATE sessions SET segmentation_version = ? WHERE id = ?",
        version_column,
        session_id
    )
    .execute(&mut *tx)
    .await?;
    tx.commit().await?;
    Ok(plan.done(from_version, added_ids, replay_blobs))
}
