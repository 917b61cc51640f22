//! A bounded cache of hot skills' JSON: `GET /skills/{id}` serialises a skill once and then
//! answers from memory. Skills never change after ingest, only disappear, so deletes remove
//! their entries; an epoch counter keeps a read that raced a delete from re-inserting what
//! the delete just removed.

use std::collections::HashMap;
use std::sync::RwLock;

use bytes::Bytes;

/// Skill id → its JSON, at most `capacity` entries (an arbitrary entry makes room when full).
#[derive(Debug)]
pub struct SkillCache {
    capacity: usize,
    inner: RwLock<Inner>,
}

#[derive(Debug, Default)]
struct Inner {
    map: HashMap<i64, Bytes>,
    /// Bumped by every removal.
    epoch: u64,
}

impl SkillCache {
    /// An empty cache holding at most `capacity` skills (0 disables it).
    pub fn new(capacity: usize) -> Self {
        SkillCache {
            capacity,
            inner: RwLock::new(Inner::default()),
        }
    }

    /// The cached JSON of skill `id`, and the epoch to pass to [`SkillCache::insert`] if it
    /// was not cached.
    pub fn get(&self, id: i64) -> Result<Bytes, u64> {
        let inner = self.inner.read().unwrap_or_else(|e| e.into_inner());
        inner.map.get(&id).cloned().ok_or(inner.epoch)
    }

    /// Caches the JSON of skill `id`, read from the store after [`SkillCache::get`] returned
    /// `epoch`; skipped if anything was removed since (the skill may be the removed one).
    pub fn insert(&self, id: i64, json: Bytes, epoch: u64) {
        if self.capacity == 0 {
            return;
        }
        let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
        if inner.epoch != epoch {
            return;
        }
        if inner.map.len() >= self.capacity && !inner.map.contains_key(&id) {
            if let Some(victim) = inner.map.keys().next().copied() {
                inner.map.remove(&victim);
            }
        }
        inner.map.insert(id, json);
    }

    /// Forgets the given skills (call after they are deleted from the store).
    pub fn remove(&self, ids: &[i64]) {
        let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
        inner.epoch += 1;
        for id in ids {
            inner.map.remove(id);
        }
    }

    /// Number of cached skills.
    pub fn len(&self) -> usize {
        self.inner
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .map
            .len()
    }

    /// Whether nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_read_that_raced_a_delete_is_not_cached() {
        let c = SkillCache::new(10);
        let epoch = c.get(1).unwrap_err();
        c.remove(&[1]);
        c.insert(1, Bytes::from_static(b"{}"), epoch);
        assert!(c.get(1).is_err(), "the stale read stays out");
        let epoch = c.get(1).unwrap_err();
        c.insert(1, Bytes::from_static(b"{}"), epoch);
        assert_eq!(c.get(1).unwrap(), Bytes::from_static(b"{}"));
        c.remove(&[1]);
        assert!(c.get(1).is_err(), "deleted skills leave the cache");
    }

    #[test]
    fn the_cache_never_grows_past_its_capacity() {
        let c = SkillCache::new(3);
        for id in 0..10 {
            let e = c.get(id).unwrap_err();
            c.insert(id, Bytes::from_static(b"{}"), e);
        }
        assert_eq!(c.len(), 3);
        assert!(c.get(9).is_ok(), "the newest entry is kept");
    }
}
