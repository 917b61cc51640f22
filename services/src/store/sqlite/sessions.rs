//! Sessions in SQLite: storing one (its skills in the same transaction), many at once,
//! reading, listing and deleting them, and which blobs their rows name.

use std::collections::HashSet;

use dfs_core::names::Named;
use sqlx::{Sqlite, SqlitePool};

use crate::store::catalog::{BlobRef, DeletedSession, NewSession};
use crate::store::query::SessionFilter;
use crate::store::rows::{convert, SessionRow};
use crate::store::skill_insert::insert_skills;
use crate::store::types::{IngestOutcome, SessionRecord};
use crate::store::StoreError;

/// The stored session of these bytes, with its skill ids.
pub(super) async fn stored(
    pool: &SqlitePool,
    sha256: &str,
) -> Result<Option<IngestOutcome>, StoreError> {
    let Some(session_id) = sqlx::query_scalar!(
        r#"SELECT id AS "id!" FROM sessions WHERE sha256 = ?"#,
        sha256
    )
    .fetch_optional(pool)
    .await?
    else {
        return Ok(None);
    };
    let rows = sqlx::query!(
        r#"SELECT id AS "id!", matched_skill_id FROM skills WHERE session_id = ? ORDER BY id"#,
        session_id
    )
    .fetch_all(pool)
    .await?;
    let (skill_ids, matched_skill_ids) =
        rows.into_iter().map(|r| (r.id, r.matched_skill_id)).unzip();
    Ok(Some(IngestOutcome {
        session_id,
        created: false,
        skill_ids,
        matched_skill_ids,
    }))
}

/// Inserts the session row of `new` in `tx`; `None` when its bytes are stored already.
async fn insert_row(
    tx: &mut sqlx::SqliteConnection,
    new: &NewSession<'_>,
) -> Result<Option<i64>, StoreError> {
    let meta_json = serde_json::to_string(new.meta)?;
    let shape = new.meta.object_shape.name();
    let version = i64::from(new.segmentation_version);
    Ok(sqlx::query_scalar!(
        r#"INSERT INTO sessions (sha256, size_bytes, blob_path, scenario, hand, object_shape,
               duration_ns, meta, segmentation_version)
           VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)
           ON CONFLICT (sha256) DO NOTHING RETURNING id AS "id!""#,
        new.sha256,
        new.size_bytes,
        new.blob_path,
        new.meta.scenario,
        new.meta.hand,
        shape,
        new.duration_ns,
        meta_json,
        version,
    )
    .fetch_optional(&mut *tx)
    .await?)
}

/// Inserts a session, its skills and their phases in one transaction.
pub(super) async fn insert(
    pool: &SqlitePool,
    new: NewSession<'_>,
) -> Result<Option<(i64, Vec<i64>)>, StoreError> {
    let mut tx = pool.begin().await?;
    let Some(session_id) = insert_row(&mut tx, &new).await? else {
        tx.rollback().await?;
        return Ok(None);
    };
    let skill_ids = insert_skills::<Sqlite>(&mut tx, session_id, new.skills.iter()).await?;
    tx.commit().await?;
    Ok(Some((session_id, skill_ids)))
}

/// Inserts many sessions in ONE transaction on a connection with a large page cache, closed
/// afterwards.
pub(super) async fn bulk_insert(
    pool: &SqlitePool,
    sessions: &[NewSession<'_>],
) -> Result<Vec<Option<Vec<i64>>>, StoreError> {
    let mut conn = pool.acquire().await?;
    // A page cache of 1 GiB: random-order inserts into the filter indexes dirty one page per
    // row and index, and a bigger cache writes each page fewer times. The connection is closed
    // after use (the pool opens a fresh one in its place), so the others keep their small one.
    conn.close_on_drop();
    sqlx::query!("PRAGMA cache_size = -1048576")
        .execute(&mut *conn)
        .await?;
    let mut tx = sqlx::Connection::begin(&mut *conn).await?;
    let mut out = Vec::with_capacity(sessions.len());
    for new in sessions {
        out.push(match insert_row(&mut tx, new).await? {
            Some(session_id) => {
                Some(insert_skills::<Sqlite>(&mut tx, session_id, new.skills.iter()).await?)
            }
            None => None,
        });
    }
    tx.commit().await?;
    Ok(out)
}

/// One session with its skill ids.
pub(super) async fn get(pool: &SqlitePool, id: i64) -> Result<Option<SessionRecord>, StoreError> {
    sqlx::query_as!(
        SessionRow,
        r#"SELECT id AS "id!", sha256, size_bytes, blob_path, meta, segmentation_version, created_at,
               (SELECT json_group_array(id) FROM (SELECT id FROM skills
                   WHERE session_id = s.id ORDER BY id)) AS "skill_ids!: String",
               (SELECT json_group_array(matched_skill_id) FROM (SELECT matched_skill_id
                   FROM skills WHERE session_id = s.id ORDER BY id))
                   AS "matched_skill_ids!: String"
           FROM sessions s WHERE id = ?"#,
        id
    )
    .fetch_optional(pool)
    .await?
    .map(SessionRecord::try_from)
    .transpose()
}

/// The sessions `f` selects: ids after its cursor, every filter given, in its order.
///
/// Two fixed queries (the order cannot be bound): an absent filter binds NULL and matches
/// every row, an absent cursor binds the end of the id range.
pub(super) async fn list(
    pool: &SqlitePool,
    f: &SessionFilter<'_>,
) -> Result<Vec<SessionRecord>, StoreError> {
    let shape = f.object_shape.map(Named::name);
    let rows = if f.newest_first {
        let before = f.after.unwrap_or(i64::MAX);
        sqlx::query_as!(
            SessionRow,
            r#"SELECT id AS "id!", sha256, size_bytes, blob_path, meta, segmentation_version,
                   created_at,
                   (SELECT json_group_array(id) FROM (SELECT id FROM skills
                       WHERE session_id = s.id ORDER BY id)) AS "skill_ids!: String",
                   (SELECT json_group_array(matched_skill_id) FROM (SELECT matched_skill_id
                       FROM skills WHERE session_id = s.id ORDER BY id))
                       AS "matched_skill_ids!: String"
               FROM sessions s
               WHERE id < ?1 AND (?2 IS NULL OR scenario = ?2) AND (?3 IS NULL OR hand = ?3)
                   AND (?4 IS NULL OR object_shape = ?4)
               ORDER BY id DESC LIMIT ?5"#,
            before,
            f.scenario,
            f.hand,
            shape,
            f.fetch,
        )
        .fetch_all(pool)
        .await?
    } else {
        let after = f.after.unwrap_or(i64::MIN);
        sqlx::query_as!(
            SessionRow,
            r#"SELECT id AS "id!", sha256, size_bytes, blob_path, meta, segmentation_version,
                   created_at,
                   (SELECT json_group_array(id) FROM (SELECT id FROM skills
                       WHERE session_id = s.id ORDER BY id)) AS "skill_ids!: String",
                   (SELECT json_group_array(matched_skill_id) FROM (SELECT matched_skill_id
                       FROM skills WHERE session_id = s.id ORDER BY id))
                       AS "matched_skill_ids!: String"
               FROM sessions s
               WHERE id > ?1 AND (?2 IS NULL OR scenario = ?2) AND (?3 IS NULL OR hand = ?3)
                   AND (?4 IS NULL OR object_shape = ?4)
               ORDER BY id LIMIT ?5"#,
            after,
            f.scenario,
            f.hand,
            shape,
            f.fetch,
        )
        .fetch_all(pool)
        .await?
    };
    convert(rows)
}

/// The blob of session `id`.
pub(super) async fn blob(pool: &SqlitePool, id: i64) -> Result<Option<BlobRef>, StoreError> {
    Ok(sqlx::query_as!(
        BlobRef,
        r#"SELECT sha256, blob_path AS rel FROM sessions WHERE id = ?"#,
        id
    )
    .fetch_optional(pool)
    .await?)
}

/// Deletes a session, its skills, their phase rows (cascading) and replays in one
/// transaction.
pub(super) async fn delete(
    pool: &SqlitePool,
    id: i64,
) -> Result<Option<DeletedSession>, StoreError> {
    let mut tx = pool.begin().await?;
    let mut blobs = sqlx::query_as!(
        BlobRef,
        r#"DELETE FROM replays WHERE skill_id IN (SELECT id FROM skills WHERE session_id = ?)
           RETURNING sha256 AS "sha256!", blob_path AS "rel!""#,
        id
    )
    .fetch_all(&mut *tx)
    .await?;
    let skill_ids = sqlx::query_scalar!(
        r#"DELETE FROM skills WHERE session_id = ? RETURNING id AS "id!""#,
        id
    )
    .fetch_all(&mut *tx)
    .await?;
    let session_blob = sqlx::query_as!(
        BlobRef,
        r#"DELETE FROM sessions WHERE id = ? RETURNING sha256 AS "sha256!", blob_path AS "rel!""#,
        id
    )
    .fetch_optional(&mut *tx)
    .await?;
    let Some(session_blob) = session_blob else {
        tx.rollback().await?;
        return Ok(None);
    };
    tx.commit().await?;
    blobs.push(session_blob);
    Ok(Some(DeletedSession { skill_ids, blobs }))
}

/// Every blob path a session or a replay names.
pub(super) async fn referenced_blob_paths(
    pool: &SqlitePool,
) -> Result<HashSet<String>, StoreError> {
    Ok(sqlx::query_scalar!(
        r#"SELECT blob_path AS "blob_path!" FROM sessions UNION SELECT blob_path FROM replays"#
    )
    .fetch_all(pool)
    .await?
    .into_iter()
    .collect())
}

/// Whether a session or a replay names the blob of these bytes.
pub(super) async fn blob_is_referenced(
    pool: &SqlitePool,
    sha256: &str,
) -> Result<bool, StoreError> {
    let found = sqlx::query_scalar!(
        r#"SELECT 1 AS "one!: i64" FROM sessions WHERE sha256 = ?1
           UNION ALL SELECT 1 FROM replays WHERE sha256 = ?1 LIMIT 1"#,
        sha256
    )
    .fetch_optional(pool)
    .await?;
    Ok(found.is_some())
}
