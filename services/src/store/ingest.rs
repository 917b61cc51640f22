//! Storing sessions: each skill checked, the MCAP bytes written as a content-addressed blob
//! (and uploaded to the bucket), the rows inserted in one transaction with each grasp linked
//! to the stored skill it matches, and the in-memory indexes updated; the synthetic
//! generator's bulk path.

use super::catalog::{CheckedSkill, NewSession};
use super::{
    blob, IngestOutcome, NewSkill, SessionMeta, StagedBlob, Store, StoreError, FEATURE_DIM,
};
use crate::assist::features::{template_of, TEMPLATE_DIM};
use crate::assist::index::StoredTemplate;
use crate::segmentation::SEGMENTATION_VERSION;
use dfs_core::names::Named;

/// A new skill stored as `id`, as recognition sees it.
pub(super) fn new_template(id: i64, c: &CheckedSkill) -> StoredTemplate {
    let s = &c.skill;
    stored_template(
        id,
        s.object_shape.name(),
        &s.grasp_type,
        s.object_name.clone(),
        s.approach.as_deref().and_then(template_of),
        c.feature,
    )
}

/// A skill as recognition sees it ([`RecognitionIndex`](crate::assist::index::RecognitionIndex)).
pub(super) fn stored_template(
    id: i64,
    shape: &str,
    grasp_type: &str,
    object_name: Option<String>,
    approach: Option<[f32; TEMPLATE_DIM]>,
    feature: [f32; FEATURE_DIM],
) -> StoredTemplate {
    StoredTemplate {
        skill_id: id,
        kind: format!("{shape}/{grasp_type}"),
        object_name,
        template: approach.unwrap_or([f32::NAN; TEMPLATE_DIM]),
        feature,
    }
}

fn finite(what: &str, v: f64) -> Result<(), StoreError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(StoreError::InvalidInput(format!(
            "{what} must be finite, got {v}"
        )))
    }
}

/// Checks each skill before insertion ([`validate_skill`]).
fn checked_skills(skills: Vec<NewSkill>) -> Result<Vec<CheckedSkill>, StoreError> {
    skills
        .into_iter()
        .enumerate()
        .map(|(i, skill)| validate_skill(i, &skill).map(|feature| CheckedSkill { skill, feature }))
        .collect()
}

/// A session's skills with their checked feature vectors, and its duration as the store's
/// signed column: what every ingest checks before it writes anything.
fn checked_input(
    meta: &SessionMeta,
    skills: Vec<NewSkill>,
) -> Result<(Vec<CheckedSkill>, i64), StoreError> {
    let checked = checked_skills(skills)?;
    finite("object_mass", meta.object_mass)?;
    finite("mu", meta.mu)?;
    let duration_ns = i64::try_from(meta.duration_ns)
        .map_err(|_| StoreError::InvalidInput("duration_ns is too large".into()))?;
    Ok((checked, duration_ns))
}

/// Checks skill number `i` before insertion; returns its feature as a fixed array.
pub(super) fn validate_skill(i: usize, s: &NewSkill) -> Result<[f32; FEATURE_DIM], StoreError> {
    let ctx = |field: &str| format!("skill {i}: {field}");
    if let Some(name) = &s.object_name {
        let max = dfs_core::scenario::MAX_OBJECT_NAME_CHARS;
        if name.is_empty() || name.chars().count() > max || name.chars().any(char::is_control) {
            return Err(StoreError::InvalidInput(format!(
                "{}: must be 1 to {max} characters, none a control character",
                ctx("object_name")
            )));
        }
    }
    finite(&ctx("object_mass"), s.object_mass)?;
    finite(&ctx("mu"), s.mu)?;
    finite(&ctx("quality"), s.quality)?;
    finite(&ctx("volume"), s.volume)?;
    finite(&ctx("duration_s"), s.duration_s)?;
    for (name, d) in &s.phase_durations {
        finite(&ctx(&format!("phase {name} duration")), *d)?;
    }
    let feature: [f32; FEATURE_DIM] = s.feature.as_slice().try_into().map_err(|_| {
        StoreError::InvalidInput(format!(
            "{}: feature has {} values, expected {FEATURE_DIM}",
            ctx("feature"),
            s.feature.len()
        ))
    })?;
    if feature.iter().any(|x| !x.is_finite()) {
        return Err(StoreError::InvalidInput(format!(
            "{} must be finite",
            ctx("feature")
        )));
    }
    if let Some(a) = &s.approach {
        // Exactly the current template: one of segmentation version 2 (read back from old
        // rows) is not written again, as `icms reprocess` would not come back to it.
        if a.len() != TEMPLATE_DIM || a.iter().any(|x| x.is_infinite()) {
            return Err(StoreError::InvalidInput(format!(
                "{}: needs {TEMPLATE_DIM} values, finite or NaN (not seen); got {}",
                ctx("approach"),
                a.len()
            )));
        }
    }
    Ok(feature)
}

impl Store {
    async fn existing(&self, sha256: &str) -> Result<Option<IngestOutcome>, StoreError> {
        self.inner.catalog.stored_session(sha256).await
    }

    /// Runs `write` (a blob write into the data directory, blocking) on a blocking thread: how
    /// every session and replay blob is written.
    pub(super) async fn write_blob<T: Send + 'static>(
        &self,
        write: impl FnOnce(&std::path::Path) -> Result<T, StoreError> + Send + 'static,
    ) -> Result<T, StoreError> {
        let dir = self.inner.dir.clone();
        tokio::task::spawn_blocking(move || write(&dir))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob writer task failed: {e}")))?
    }

    /// Stores a session: its MCAP bytes as a content-addressed blob, its metadata and skills.
    ///
    /// Idempotent: bytes already stored (same SHA-256) return the existing session with
    /// `created: false`, also when concurrent ingests of the same file race. The blob is
    /// written atomically and fsynced before one transaction inserts the session, skills and
    /// phases; any error (full disk, bad input) leaves no rows.
    pub async fn ingest(
        &self,
        mcap: &[u8],
        meta: SessionMeta,
        skills: Vec<NewSkill>,
    ) -> Result<IngestOutcome, StoreError> {
        let (checked, duration_ns) = checked_input(&meta, skills)?;

        let bytes = mcap.to_vec();
        let sha256 = tokio::task::spawn_blocking(move || (blob::sha256_hex(&bytes), bytes))
            .await
            .map_err(|e| StoreError::Corrupt(format!("hashing task failed: {e}")));
        let (sha256, bytes) = sha256?;
        if let Some(found) = self.existing(&sha256).await? {
            return Ok(found);
        }

        let _guard = self.inner.blob_lock.read().await;
        let sha = sha256.clone();
        let size = bytes.len() as i64;
        let rel = self
            .write_blob(move |dir| blob::write_atomic(dir, &sha, &bytes))
            .await?;
        self.publish_and_insert_session(&sha256, size, &rel, meta, checked, duration_ns)
            .await
    }

    /// A new [`StagedBlob`] in the data directory, for an upload to stream into. Blocking.
    pub fn stage_upload(&self) -> Result<StagedBlob, StoreError> {
        StagedBlob::create(&self.inner.dir)
    }

    /// [`Store::ingest`] of an upload already written to disk and hashed ([`StagedBlob`]):
    /// the file is moved to its content address (or dropped, if those bytes are stored
    /// already), never read into memory.
    pub async fn ingest_staged(
        &self,
        staged: StagedBlob,
        meta: SessionMeta,
        skills: Vec<NewSkill>,
    ) -> Result<IngestOutcome, StoreError> {
        let (checked, duration_ns) = checked_input(&meta, skills)?;
        let sha256 = staged.sha256().to_owned();
        if let Some(found) = self.existing(&sha256).await? {
            return Ok(found);
        }
        let _guard = self.inner.blob_lock.read().await;
        let size = staged.len() as i64;
        let rel = self.write_blob(move |dir| staged.commit(dir)).await?;
        self.publish_and_insert_session(&sha256, size, &rel, meta, checked, duration_ns)
            .await
    }

    /// Uploads the blob at `rel` to the bucket (if any) and inserts the session's rows,
    /// holding the cross-server blob lock shared throughout (see
    /// [`Store::sweep_orphan_blobs`]). Call under the in-process blob lock, shared.
    async fn publish_and_insert_session(
        &self,
        sha256: &str,
        size: i64,
        rel: &str,
        meta: SessionMeta,
        checked: Vec<CheckedSkill>,
        duration_ns: i64,
    ) -> Result<IngestOutcome, StoreError> {
        let hold = self.shared_blob_hold().await?;
        let done = async {
            self.publish(rel).await?;
            self.insert_session(sha256, size, rel, meta, checked, duration_ns)
                .await
        }
        .await;
        hold.release().await;
        done
    }

    /// The rows of a session whose blob is at `rel`, in one transaction.
    async fn insert_session(
        &self,
        sha256: &str,
        size: i64,
        rel: &str,
        meta: SessionMeta,
        mut checked: Vec<CheckedSkill>,
        duration_ns: i64,
    ) -> Result<IngestOutcome, StoreError> {
        // On-line learning: each grasp is linked to the stored skill it matches, or stored as
        // new (against the skills stored before it).
        let recognition = self.recognition_index();
        let mut scratch = crate::assist::index::Scratch::default();
        for CheckedSkill { skill: s, feature } in &mut checked {
            if s.matched_skill_id.is_none() {
                let approach = s.approach.as_deref().and_then(template_of);
                s.matched_skill_id = crate::assist::recognise::link_completed(
                    &recognition,
                    approach.as_ref(),
                    feature,
                    &crate::assist::recognise::RecogniserParams::default(),
                    &mut scratch,
                );
            }
        }
        let inserted = self
            .inner
            .catalog
            .insert_session(NewSession {
                sha256,
                size_bytes: size,
                blob_path: rel,
                meta: &meta,
                duration_ns,
                segmentation_version: SEGMENTATION_VERSION,
                skills: &checked,
            })
            .await?;
        let Some((session_id, skill_ids)) = inserted else {
            // A concurrent ingest of the same bytes committed first.
            return self
                .existing(sha256)
                .await?
                .ok_or_else(|| StoreError::Corrupt("session vanished during ingest".into()));
        };

        let mut index = self.inner.index.write().expect("index lock");
        for (id, c) in skill_ids.iter().zip(&checked) {
            index.insert(*id, c.feature);
        }
        drop(index);
        self.update_recognition(
            &[],
            skill_ids
                .iter()
                .zip(&checked)
                .map(|(id, c)| new_template(*id, c)),
        );
        tracing::debug!(session_id, skills = skill_ids.len(), "ingested session");
        Ok(IngestOutcome {
            session_id,
            created: true,
            matched_skill_ids: checked.iter().map(|c| c.skill.matched_skill_id).collect(),
            skill_ids,
        })
    }

    /// Bulk path of the synthetic generator: writes the blobs, then stores every session of
    /// `batch` in ONE transaction, as fast as the backend can. Sessions whose bytes are already
    /// stored are skipped.
    pub(crate) async fn bulk_ingest(
        &self,
        batch: Vec<(Vec<u8>, SessionMeta, Vec<NewSkill>)>,
    ) -> Result<usize, StoreError> {
        let _guard = self.inner.blob_lock.read().await;
        let hold = self.shared_blob_hold().await?;
        let inserted = self.bulk_publish_and_insert(batch).await;
        hold.release().await;
        let (inserted, sessions) = inserted?;
        let stored = || {
            inserted
                .iter()
                .zip(&sessions)
                .flat_map(|(ids, (_, checked))| ids.iter().flatten().zip(checked))
        };
        let mut index = self.inner.index.write().expect("index lock");
        for (id, c) in stored() {
            index.insert(*id, c.feature);
        }
        drop(index);
        self.update_recognition(&[], stored().map(|(id, c)| new_template(*id, c)));
        Ok(stored().count())
    }

    /// [`Store::bulk_ingest`]'s blob writes, uploads and transaction; per session, its skills'
    /// ids (or `None`, stored already), and its (SHA-256, checked skills).
    #[allow(clippy::type_complexity)]
    async fn bulk_publish_and_insert(
        &self,
        batch: Vec<(Vec<u8>, SessionMeta, Vec<NewSkill>)>,
    ) -> Result<(Vec<Option<Vec<i64>>>, Vec<(String, Vec<CheckedSkill>)>), StoreError> {
        let mut prepared = Vec::with_capacity(batch.len());
        for (bytes, meta, skills) in batch {
            let checked = checked_skills(skills)?;
            let sha256 = blob::sha256_hex(&bytes);
            let sha = sha256.clone();
            let size = bytes.len() as i64;
            let rel = self
                .write_blob(move |dir| blob::write_atomic(dir, &sha, &bytes))
                .await?;
            self.publish(&rel).await?;
            let duration_ns = i64::try_from(meta.duration_ns).unwrap_or(i64::MAX);
            prepared.push((sha256, size, rel, meta, checked, duration_ns));
        }
        let sessions: Vec<NewSession<'_>> = prepared
            .iter()
            .map(
                |(sha256, size, rel, meta, checked, duration_ns)| NewSession {
                    sha256,
                    size_bytes: *size,
                    blob_path: rel,
                    meta,
                    duration_ns: *duration_ns,
                    segmentation_version: SEGMENTATION_VERSION,
                    skills: checked,
                },
            )
            .collect();
        let inserted = self.inner.catalog.bulk_insert_sessions(&sessions).await?;
        drop(sessions);
        let sessions = prepared
            .into_iter()
            .map(|(sha256, _, _, _, checked, _)| (sha256, checked))
            .collect();
        Ok((inserted, sessions))
    }
}
