//! The store's side of reprocessing (`crate::reprocess`): finding the sessions an older
//! segmentation made the skills of, reading their files back, and replacing a session's skills
//! with those of a new segmentation in one transaction.

use dfs_core::names::Named;

use super::catalog::{BlobRef, CheckedSkill, ReplacedRows, Replacement};
use super::rows::{feature_to_blob, session_version, StoredSkillRow};
use super::types::{NewSkill, ReplacedSkills, StaleSession};
use super::{blob, validate_skill, Store, StoreError};

/// A stored skill in the form its row holds it, or a new skill in the form it would be stored:
/// the row of the reprocessing query ([`StoredSkillRow`]) with its id left 0, so that two skills
/// are the same when these are equal (the numbers as numbers, stored exactly as REALs and
/// always finite; the JSON columns as the text stored).
pub(crate) type StoredForm = StoredSkillRow;

/// The new skills of a replacement in stored form, computed before its transaction begins.
pub(crate) fn new_forms(skills: &[CheckedSkill]) -> Result<Vec<StoredForm>, StoreError> {
    skills.iter().map(stored_form).collect()
}

/// Which stored skills a replacement keeps, removes and adds: the stored rows of the session
/// (`old`, as the backend's query read them) against the new skills in stored form (`new`).
/// One step of both backends' `replace_session_skills`.
pub(crate) fn plan_rows(old: Vec<StoredSkillRow>, new: &[StoredForm]) -> Plan {
    // A stored row as its id and its stored form.
    let old: Vec<(i64, StoredForm)> = old
        .into_iter()
        .map(|r| (r.id, StoredSkillRow { id: 0, ..r }))
        .collect();
    plan(&old, new)
}

/// The checks on the session version a replacement reads under its lock: `None` when the
/// session is already at `version` or newer (nothing to do), else its version. A version that
/// does not convert is [`StoreError::Corrupt`].
pub(crate) fn version_to_replace(
    session_id: i64,
    stored: i64,
    version: u32,
) -> Result<Option<u32>, StoreError> {
    let from = session_version(session_id, stored)?;
    Ok((from < version).then_some(from))
}

/// Refuses a deletion of the removed skills that deleted another number of rows than asked.
pub(crate) fn check_deleted(session_id: i64, done: u64, removed: &[i64]) -> Result<(), StoreError> {
    if done != removed.len() as u64 {
        return Err(StoreError::Corrupt(format!(
            "session {session_id}: deleted {done} of its {} replaced skills",
            removed.len()
        )));
    }
    Ok(())
}

impl Plan {
    /// What the replacement did, once the added skills were inserted with ids `added_ids` (in
    /// the order of `self.added`) and the removed replays' blobs were `replay_blobs`.
    pub(crate) fn done(
        self,
        from_version: u32,
        added_ids: Vec<i64>,
        replay_blobs: Vec<BlobRef>,
    ) -> Replacement {
        Replacement::Done(ReplacedRows {
            from_version,
            kept: self.kept,
            removed: self.removed,
            added: added_ids.into_iter().zip(self.added).collect(),
            replay_blobs,
        })
    }
}

/// What a catalog writes for the checked skill `c`, in stored form.
fn stored_form(c: &CheckedSkill) -> Result<StoredForm, StoreError> {
    let s = &c.skill;
    Ok(StoredForm {
        id: 0,
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
        feature: feature_to_blob(&c.feature),
        params: serde_json::to_string(&s.params)?,
    })
}

/// Which stored skills a replacement keeps, removes, and which new skills it adds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Plan {
    /// Kept stored skills: (stored id, index of the identical new skill).
    pub kept: Vec<(i64, usize)>,
    /// Removed stored skills' ids, in the stored order.
    pub removed: Vec<i64>,
    /// Indexes of the new skills to insert, in their order.
    pub added: Vec<usize>,
}

/// Matches the new skills (`new`, in stored form) with the stored ones (`old`: id and stored
/// form): each new skill keeps the first unclaimed identical stored skill, if any.
fn plan(old: &[(i64, StoredForm)], new: &[StoredForm]) -> Plan {
    let mut claimed = vec![false; old.len()];
    let mut kept = Vec::new();
    let mut added = Vec::new();
    for (i, form) in new.iter().enumerate() {
        match (0..old.len()).find(|&k| !claimed[k] && old[k].1 == *form) {
            Some(k) => {
                claimed[k] = true;
                kept.push((old[k].0, i));
            }
            None => added.push(i),
        }
    }
    let removed = old
        .iter()
        .zip(&claimed)
        .filter(|(_, c)| !**c)
        .map(|((id, _), _)| *id)
        .collect();
    Plan {
        kept,
        removed,
        added,
    }
}

impl Store {
    /// The sessions whose skills a segmentation older than `version` made (their
    /// `segmentation_version` is below it), by ascending id.
    pub async fn sessions_segmented_before(
        &self,
        version: u32,
    ) -> Result<Vec<StaleSession>, StoreError> {
        self.inner.catalog.sessions_segmented_before(version).await
    }

    /// Number of sessions whose skills a segmentation newer than `version` made: a newer
    /// binary reprocessed or stored them, and an older one leaves them alone.
    pub async fn sessions_segmented_after(&self, version: u32) -> Result<u64, StoreError> {
        self.inner.catalog.sessions_segmented_after(version).await
    }

    /// The MCAP bytes of session `id`, checked against the SHA-256 its row records: a blob
    /// changed on disk (bit rot, an edit behind the store's back) is [`StoreError::Corrupt`]
    /// rather than bytes to segment; a missing one is [`StoreError::Io`].
    pub async fn read_session_blob(&self, id: i64) -> Result<Vec<u8>, StoreError> {
        let BlobRef { sha256, rel } = self
            .inner
            .catalog
            .session_blob(id)
            .await?
            .ok_or(StoreError::SessionNotFound(id))?;
        let path = self.local_blob(&rel).await?;
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
            .map(|(i, s)| validate_skill(i, &s).map(|feature| CheckedSkill { skill: s, feature }))
            .collect::<Result<Vec<_>, _>>()?;

        // Exclusive, as for deletes: the removed replays' blobs are unlinked after the commit,
        // and no ingest or replay of this process may be reusing one of them meanwhile.
        let _guard = self.inner.blob_lock.write().await;
        let done = match self
            .inner
            .catalog
            .replace_session_skills(session_id, version, &checked)
            .await?
        {
            Replacement::SessionNotFound => return Err(StoreError::SessionNotFound(session_id)),
            Replacement::UpToDate => return Ok(None),
            Replacement::Done(done) => done,
        };
        {
            let mut index = self.inner.index.write().expect("index lock");
            index.remove_many(&done.removed);
            for &(id, i) in &done.added {
                index.insert(id, checked[i].feature);
            }
        }
        self.update_recognition(
            &done.removed,
            done.kept
                .iter()
                .chain(&done.added)
                .map(|&(id, i)| super::new_template(id, &checked[i])),
        );
        self.remove_unreferenced_blobs(&done.replay_blobs).await;
        let mut kept: Vec<i64> = done.kept.iter().map(|&(id, _)| id).collect();
        kept.sort_unstable();
        let added_ids: Vec<i64> = done.added.iter().map(|&(id, _)| id).collect();
        tracing::debug!(
            session_id,
            from_version = done.from_version,
            version,
            kept = kept.len(),
            removed = done.removed.len(),
            added = added_ids.len(),
            replays_removed = done.replay_blobs.len(),
            "replaced a session's skills"
        );
        Ok(Some(ReplacedSkills {
            session_id,
            from_version: done.from_version,
            to_version: version,
            kept_skill_ids: kept,
            removed_skill_ids: done.removed,
            added_skill_ids: added_ids,
            replays_removed: done.replay_blobs.len(),
        }))
    }
}
