//! Reading and deleting what the store holds: pages of sessions and skills by their filters
//! and cursors, one session or skill, a session's blob, the nearest skills in feature space,
//! and deletes with the indexes and blobs they leave behind.

use std::path::PathBuf;

use super::catalog::BlobRef;
use super::{
    query, Page, SessionQuery, SessionRecord, SkillQuery, SkillRecord, Store, StoreError,
    FEATURE_DIM, MAX_SESSION_LIMIT,
};

impl Store {
    /// Sessions by ascending id, `limit` (1..=1000) per page, after `cursor`.
    pub async fn list_sessions(
        &self,
        limit: u32,
        cursor: Option<&str>,
    ) -> Result<Page<SessionRecord>, StoreError> {
        self.query_sessions(&SessionQuery {
            limit,
            cursor: cursor.map(str::to_owned),
            ..SessionQuery::default()
        })
        .await
    }

    /// Sessions matching every filter of `q`, by id (ascending, or newest first), `q.limit`
    /// (1..=1000) per page, after `q.cursor`. A cursor belongs to its order: one of the other
    /// order is [`StoreError::BadCursor`].
    pub async fn query_sessions(
        &self,
        q: &SessionQuery,
    ) -> Result<Page<SessionRecord>, StoreError> {
        let filter = query::session_filter(q, MAX_SESSION_LIMIT)?;
        let mut items = self.inner.catalog.sessions(&filter).await?;
        let more = items.len() > q.limit as usize;
        items.truncate(q.limit as usize);
        let next_cursor = match (more, items.last()) {
            (true, Some(last)) => Some(query::encode_cursor(
                query::session_tag(q.newest_first),
                query::After::Int(last.id),
            )),
            _ => None,
        };
        Ok(Page { items, next_cursor })
    }

    /// One session with its skill ids.
    pub async fn get_session(&self, id: i64) -> Result<SessionRecord, StoreError> {
        self.inner
            .catalog
            .session(id)
            .await?
            .ok_or(StoreError::SessionNotFound(id))
    }

    /// Absolute path of a session's MCAP blob (downloaded first from the bucket, if the store
    /// has one and the data directory has no copy).
    pub async fn session_blob_path(&self, id: i64) -> Result<PathBuf, StoreError> {
        let BlobRef { rel, .. } = self
            .inner
            .catalog
            .session_blob(id)
            .await?
            .ok_or(StoreError::SessionNotFound(id))?;
        self.local_blob(&rel).await
    }

    /// Deletes a session, its skills, their phase rows and replays (one transaction), then its
    /// blob and its replays' blobs.
    pub async fn delete_session(&self, id: i64) -> Result<(), StoreError> {
        let _guard = self.inner.blob_lock.write().await;
        let deleted = self
            .inner
            .catalog
            .delete_session(id)
            .await?
            .ok_or(StoreError::SessionNotFound(id))?;
        self.forget(&deleted.skill_ids, &deleted.blobs).await;
        Ok(())
    }

    /// One skill.
    pub async fn get_skill(&self, id: i64) -> Result<SkillRecord, StoreError> {
        self.inner
            .catalog
            .skill(id)
            .await?
            .ok_or(StoreError::SkillNotFound(id))
    }

    /// The skills of `ids` in one query, in the order of `ids`; ids with no skill (deleted
    /// meanwhile) are left out. What `similar` answers its neighbours with, instead of one
    /// query per neighbour.
    pub async fn get_skills(&self, ids: &[i64]) -> Result<Vec<SkillRecord>, StoreError> {
        if ids.is_empty() {
            return Ok(Vec::new());
        }
        let mut by_id = self
            .inner
            .catalog
            .skills_by_id(ids)
            .await?
            .into_iter()
            .map(|s| (s.id, s))
            .collect::<std::collections::HashMap<_, _>>();
        Ok(ids.iter().filter_map(|id| by_id.remove(id)).collect())
    }

    /// Deletes one skill, its phase rows and its replays (one transaction; its session stays),
    /// then the replays' blobs.
    pub async fn delete_skill(&self, id: i64) -> Result<(), StoreError> {
        let _guard = self.inner.blob_lock.write().await;
        let blobs = self
            .inner
            .catalog
            .delete_skill(id)
            .await?
            .ok_or(StoreError::SkillNotFound(id))?;
        self.forget(&[id], &blobs).await;
        Ok(())
    }

    /// After a delete committed: drops the skills from the similarity index and removes the
    /// blobs no row names any more (a leftover blob is harmless garbage).
    async fn forget(&self, skill_ids: &[i64], blobs: &[BlobRef]) {
        self.inner
            .index
            .write()
            .expect("index lock")
            .remove_many(skill_ids);
        self.update_recognition(skill_ids, []);
        self.remove_unreferenced_blobs(blobs).await;
    }

    /// Skills matching the filters of `q`, sorted by `q.sort`, one page after `q.cursor`.
    pub async fn query_skills(&self, q: &SkillQuery) -> Result<Page<SkillRecord>, StoreError> {
        let filter = query::skill_filter(q)?;
        let mut items = self.inner.catalog.skills(&filter).await?;
        let limit = q.limit as usize;
        let more = items.len() > limit;
        items.truncate(limit);
        let next_cursor = match (more, items.last()) {
            (true, Some(last)) => Some(query::cursor_after(q.sort, last)),
            _ => None,
        };
        Ok(Page { items, next_cursor })
    }

    /// The `k` skills nearest to `feature` (Euclidean distance in feature space, nearest
    /// first, ties by id) as (skill id, distance). CPU only: about 1 ms per 100 000 skills.
    pub fn nearest(&self, feature: &[f32], k: usize) -> Result<Vec<(i64, f32)>, StoreError> {
        let q: [f32; FEATURE_DIM] = feature.try_into().map_err(|_| {
            StoreError::InvalidQuery(format!(
                "feature has {} values, expected {FEATURE_DIM}",
                feature.len()
            ))
        })?;
        if q.iter().any(|x| !x.is_finite()) {
            return Err(StoreError::InvalidQuery("feature must be finite".into()));
        }
        Ok(self
            .inner
            .index
            .read()
            .expect("index lock")
            .nearest(&q, k, None))
    }

    /// The `k` skills nearest to skill `id`, leaving out the skill itself.
    pub fn nearest_to_skill(&self, id: i64, k: usize) -> Result<Vec<(i64, f32)>, StoreError> {
        let index = self.inner.index.read().expect("index lock");
        let q = index.get(id).ok_or(StoreError::SkillNotFound(id))?;
        Ok(index.nearest(&q, k, Some(id)))
    }
}
