//! Skills in SQLite: inserting a session's skills with their phase rows, reading them by id,
//! loading the in-memory indexes, deleting one.

use dfs_core::names::Named;
use sqlx::{QueryBuilder, Sqlite, SqliteConnection, SqlitePool};

use crate::store::catalog::{BlobRef, CheckedSkill, IndexedSkill};
use crate::store::rows::{approach_to_blob, convert, feature_to_blob, IndexedSkillRow, SkillRow};
use crate::store::types::SkillRecord;
use crate::store::StoreError;

/// Inserts checked skills of `session_id` and their phase rows on `tx` (a connection inside a
/// transaction); returns their ids in the order of `skills`.
///
/// Built at run time like the skill filter, from typed parts (`push_values` binding every
/// value), because a statement inserts many rows: one checked statement per row, tried,
/// made `icms bench store`'s generation of 100 000 skills 3.4 times slower (29 s → 100 s,
/// six statements per skill, each a round trip to the connection's thread), and a session's
/// ingest slower with it. The columns are the ones the checked queries read back, so a
/// renamed column fails every store test at once.
pub(super) async fn insert_skills<'a>(
    tx: &mut SqliteConnection,
    session_id: i64,
    skills: impl Iterator<Item = &'a CheckedSkill> + Send,
) -> Result<Vec<i64>, StoreError> {
    let skills: Vec<&CheckedSkill> = skills.collect();
    let mut ids = Vec::with_capacity(skills.len());
    // Multi-row INSERTs: 18 bound values per skill stay far below SQLite's variable limit.
    for chunk in skills.chunks(500) {
        let mut rows = Vec::with_capacity(chunk.len());
        for c in chunk {
            let s = &c.skill;
            rows.push((
                s,
                feature_to_blob(&c.feature),
                serde_json::to_string(&s.phase_durations)?,
                serde_json::to_string(&s.params)?,
                s.approach.as_deref().map(approach_to_blob),
            ));
        }
        let mut b: QueryBuilder<Sqlite> = QueryBuilder::new(
            "INSERT INTO skills (session_id, object_shape, object_name, object_mass, mu, \
             contact_count, contact_model, grasp_type, quality, volume, duration_s, start_ns, \
             end_ns, phase_durations, feature, params, approach, matched_skill_id) ",
        );
        b.push_values(&rows, |mut r, (s, feature, phases, params, approach)| {
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
                .push_bind(phases.as_str())
                .push_bind(feature.as_slice())
                .push_bind(params.as_str())
                .push_bind(approach.as_deref())
                .push_bind(s.matched_skill_id);
        });
        b.push(" RETURNING id");
        let mut chunk_ids: Vec<i64> = b.build_query_scalar().fetch_all(&mut *tx).await?;
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
            .flat_map(|(c, id)| {
                c.skill
                    .phase_durations
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
            b.build().execute(&mut *tx).await?;
        }
        ids.extend(chunk_ids);
    }
    Ok(ids)
}

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
