//! The store's side of reprocessing (`crate::reprocess`): finding the sessions an older
//! segmentation made the skills of, reading their files back, and replacing a session's skills
//! with those of a new segmentation in one transaction.

use dfs_core::names::Named;
use sqlx::Row as _;

use super::types::{NewSkill, ReplacedSkills, StaleSession};
use super::{blob, feature_to_blob, insert_skills, validate_skill, Store, StoreError, FEATURE_DIM};

/// A stored skill in the form its row holds it, or a new skill in the form it would be stored:
/// two skills are the same when these are equal (the numbers as numbers, stored exactly as
/// SQLite REALs and always finite; the JSON columns as the text stored).
#[derive(Debug, PartialEq, sqlx::FromRow)]
struct StoredForm {
    object_shape: String,
    object_name: Option<String>,
    object_mass: f64,
    mu: f64,
    contact_count: i64,
    contact_model: String,
    grasp_type: String,
    quality: f64,
    volume: f64,
    duration_s: f64,
    start_ns: i64,
    end_ns: i64,
    phase_durations: String,
    feature: Vec<u8>,
    params: String,
}

impl StoredForm {
    /// What `insert_skills` writes for `s` (its checked feature `f`).
    fn of_new(s: &NewSkill, f: &[f32; FEATURE_DIM]) -> Result<Self, StoreError> {
        Ok(StoredForm {
            object_shape: s.object_shape.name().to_owned(),
            object_name: s.object_name.clone(),
            object_mass: s.object_mass,
            mu: s.mu,
            contact_count: s.contact_count,
            contact_model: s.contact_model.name().to_owned(),
            grasp_type: s.grasp_type.clone(),
            quality: s.quality,
            volume: s.volume,
            duration_s: s.duration_s,
            start_ns: s.start_ns,
            end_ns: s.end_ns,
            phase_durations: serde_json::to_string(&s.phase_durations)?,
            feature: feature_to_blob(f),
            params: serde_json::to_string(&s.params)?,
        })
    }
}

/// The columns a [`StoredForm`] is read from (`sqlx::FromRow`, by name), after `id`.
const STORED_FORM_COLUMNS: &str = "id, object_shape, object_name, object_mass, mu, contact_count, \
     contact_model, grasp_type, quality, volume, duration_s, start_ns, end_ns, phase_durations, \
     feature, params";

impl Store {
    /// The sessions whose skills a segmentation older than `version` made (their
    /// `segmentation_version` is below it), by ascending id.
    pub async fn sessions_segmented_before(
        &self,
        version: u32,
    ) -> Result<Vec<StaleSession>, StoreError> {
        let rows = sqlx::query(
            "SELECT id, segmentation_version, \
             (SELECT count(*) FROM skills WHERE session_id = s.id) AS skill_count \
             FROM sessions s WHERE segmentation_version < ? ORDER BY id",
        )
        .bind(i64::from(version))
        .fetch_all(&self.inner.pool)
        .await?;
        rows.iter()
            .map(|row| {
                let count: i64 = row.try_get("skill_count")?;
                Ok(StaleSession {
                    id: row.try_get("id")?,
                    segmentation_version: super::segmentation_version(row)?,
                    skill_count: usize::try_from(count).unwrap_or(0),
                })
            })
            .collect()
    }

    /// Number of sessions whose skills a segmentation newer than `version` made: a newer
    /// binary reprocessed or stored them, and an older one leaves them alone.
    pub async fn sessions_segmented_after(&self, version: u32) -> Result<u64, StoreError> {
        let n: i64 =
            sqlx::query_scalar("SELECT count(*) FROM sessions WHERE segmentation_version > ?")
                .bind(i64::from(version))
                .fetch_one(&self.inner.pool)
                .await?;
        Ok(u64::try_from(n).unwrap_or(0))
    }

    /// The MCAP bytes of session `id`, checked against the SHA-256 its row records: a blob
    /// changed on disk (bit rot, an edit behind the store's back) is [`StoreError::Corrupt`]
    /// rather than bytes to segment; a missing one is [`StoreError::Io`].
    pub async fn read_session_blob(&self, id: i64) -> Result<Vec<u8>, StoreError> {
        let (sha256, rel): (String, String) =
            sqlx::query_as("SELECT sha256, blob_path FROM sessions WHERE id = ?")
                .bind(id)
                .fetch_optional(&self.inner.pool)
                .await?
                .ok_or(StoreError::SessionNotFound(id))?;
        let path = self.inner.dir.join(&rel);
        tokio::task::spawn_blocking(move || {
            let bytes = std::fs::read(&path).map_err(|e| StoreError::io(&path, e))?;
            let found = blob::sha256_hex(&bytes);
            if found != sha256 {
                return Err(StoreError::Corrupt(format!(
                    "session {id}: its file {rel} has SHA-256 {found}, not the {sha256} it was \
                     stored with (changed on disk)"
                )));
            }
            Ok(bytes)
        })
        .await
        .map_err(|e| StoreError::Corrupt(format!("blob reader task failed: {e}")))?
    }

    /// Replaces the skills of session `session_id` with `skills`, the result of segmenting its
    /// file with segmentation `version`, and records that version; in one transaction, so a
    /// failure or a kill at any point leaves the session as it was.
    ///
    /// A stored skill identical to a new one (see [`ReplacedSkills`]) is kept with its id and
    /// replays; every other stored skill is deleted with its phase rows and replays (a replay
    /// retargeted parameters that no longer exist), and the remaining new skills are inserted
    /// as [`Store::ingest`] inserts them. The in-memory similarity index follows after the
    /// commit, and the removed replays' MCAP files are deleted unless another row names them.
    ///
    /// `Ok(None)` when the session's version is already `version` or newer (another process
    /// reprocessed it meanwhile): nothing is changed. [`StoreError::SessionNotFound`] when it
    /// was deleted.
    ///
    /// A caller that caches skill JSON (the server's hot-skill cache) must drop every skill of
    /// the session: the removed ones are gone, and the kept ones report the new version.
    pub async fn replace_session_skills(
        &self,
        session_id: i64,
        skills: Vec<NewSkill>,
        version: u32,
    ) -> Result<Option<ReplacedSkills>, StoreError> {
        let checked = skills
            .into_iter()
            .enumerate()
            .map(|(i, s)| validate_skill(i, &s).map(|f| (s, f)))
            .collect::<Result<Vec<_>, _>>()?;
        let new_forms = checked
            .iter()
            .map(|(s, f)| StoredForm::of_new(s, f))
            .collect::<Result<Vec<_>, _>>()?;

        // Exclusive, as for deletes: the removed replays' blobs are unlinked after the commit,
        // and no ingest or replay of this process may be reusing one of them meanwhile.
        let _guard = self.inner.blob_lock.write().await;
        // IMMEDIATE: the write lock from the start, so that what is read below is what the
        // writes replace (a deferred transaction that reads first cannot write after another
        // connection's commit).
        let mut tx = self.inner.pool.begin_with("BEGIN IMMEDIATE").await?;
        let from: Option<i64> =
            sqlx::query_scalar("SELECT segmentation_version FROM sessions WHERE id = ?")
                .bind(session_id)
                .fetch_optional(&mut *tx)
                .await?;
        let Some(from) = from else {
            tx.rollback().await?;
            return Err(StoreError::SessionNotFound(session_id));
        };
        let from_version = u32::try_from(from).map_err(|_| {
            StoreError::Corrupt(format!(
                "session {session_id}: segmentation version {from} is out of range"
            ))
        })?;
        if from_version >= version {
            tx.rollback().await?;
            return Ok(None);
        }

        let rows = sqlx::query(&format!(
            "SELECT {STORED_FORM_COLUMNS} FROM skills WHERE session_id = ? ORDER BY id"
        ))
        .bind(session_id)
        .fetch_all(&mut *tx)
        .await?;
        let mut old = Vec::with_capacity(rows.len());
        for row in &rows {
            let id: i64 = row.try_get("id")?;
            old.push((id, <StoredForm as sqlx::FromRow<_>>::from_row(row)?));
        }
        drop(rows);

        // Each new skill keeps the first unclaimed identical stored skill, if any.
        // A kept skill takes the new approach template (derived data, not the skill's
        // identity: a skill stored before templates were gets one without losing its id).
        let mut claimed = vec![false; old.len()];
        let mut kept = Vec::new();
        let mut kept_templates = Vec::new();
        let mut added = Vec::new();
        for (new, form) in checked.into_iter().zip(&new_forms) {
            match (0..old.len()).find(|&i| !claimed[i] && old[i].1 == *form) {
                Some(i) => {
                    claimed[i] = true;
                    kept.push(old[i].0);
                    kept_templates.push(super::new_template(old[i].0, &new.0, &new.1));
                    sqlx::query("UPDATE skills SET approach = ? WHERE id = ?")
                        .bind(
                            new.0.approach.as_ref().map(|a| {
                                a.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>()
                            }),
                        )
                        .bind(old[i].0)
                        .execute(&mut *tx)
                        .await?;
                }
                None => added.push(new),
            }
        }
        let removed: Vec<i64> = old
            .iter()
            .zip(&claimed)
            .filter(|(_, c)| !**c)
            .map(|((id, _), _)| *id)
            .collect();

        let mut replay_blobs = Vec::new();
        if !removed.is_empty() {
            let ids = serde_json::to_string(&removed)?;
            let rows = sqlx::query(
                "DELETE FROM replays WHERE skill_id IN (SELECT value FROM json_each(?)) \
                 RETURNING sha256, blob_path",
            )
            .bind(&ids)
            .fetch_all(&mut *tx)
            .await?;
            for row in &rows {
                replay_blobs.push((row.try_get(0)?, row.try_get(1)?));
            }
            let done =
                sqlx::query("DELETE FROM skills WHERE id IN (SELECT value FROM json_each(?))")
                    .bind(&ids)
                    .execute(&mut *tx)
                    .await?;
            if done.rows_affected() != removed.len() as u64 {
                return Err(StoreError::Corrupt(format!(
                    "session {session_id}: deleted {} of its {} replaced skills",
                    done.rows_affected(),
                    removed.len()
                )));
            }
        }
        let added_ids = insert_skills(&mut tx, session_id, &added).await?;
        sqlx::query("UPDATE sessions SET segmentation_version = ? WHERE id = ?")
            .bind(i64::from(version))
            .bind(session_id)
            .execute(&mut *tx)
            .await?;
        tx.commit().await?;

        {
            let mut index = self.inner.index.write().expect("index lock");
            index.remove_many(&removed);
            for (id, (_, f)) in added_ids.iter().zip(&added) {
                index.insert(*id, *f);
            }
        }
        self.update_recognition(
            &removed,
            kept_templates.into_iter().chain(
                added_ids
                    .iter()
                    .zip(&added)
                    .map(|(id, (s, f))| super::new_template(*id, s, f)),
            ),
        );
        self.remove_unreferenced_blobs(&replay_blobs).await;
        kept.sort_unstable();
        tracing::debug!(
            session_id,
            from_version,
            version,
            kept = kept.len(),
            removed = removed.len(),
            added = added_ids.len(),
            replays_removed = replay_blobs.len(),
            "replaced a session's skills"
        );
        Ok(Some(ReplacedSkills {
            session_id,
            from_version,
            to_version: version,
            kept_skill_ids: kept,
            removed_skill_ids: removed,
            added_skill_ids: added_ids,
            replays_removed: replay_blobs.len(),
        }))
    }
}
