//! A bounded cache of hot skills' JSON: `GET /skills/{id}` serialises a skill once and then
//! answers from memory. Skills never change after ingest, only disappear, so deletes remove
//! their entries; an epoch counter keeps a read that raced a delete from re-inserting what
//! the delete just removed.

use std::collections::HashMap;
use std::sync::RwLock;

use bytes::Bytes;

/// Skill id → its JSON, at most `max_bytes` of JSON in all (arbitrary entries make room when
/// full). Bounded in bytes rather than entries: a skill's JSON is 2-40 kB by its hand and
/// phases, so a count would bound memory only loosely (the soak of issue 17 saw a count-bound
/// cache grow the server's memory for as long as new skills were read).
#[derive(Debug)]
pub struct SkillCache {
    max_bytes: usize,
    inner: RwLock<Inner>,
}

#[derive(Debug, Default)]
struct Inner {
    map: HashMap<i64, Bytes>,
    /// Sum of the cached JSON's lengths.
    bytes: usize,
    /// Bumped by every removal.
    epoch: u64,
}

impl SkillCache {
    /// An empty cache holding at most `max_bytes` of JSON (0 disables it).
    pub fn new(max_bytes: usize) -> Self {
        SkillCache {
            max_bytes,
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
        if json.len() > self.max_bytes {
            return;
        }
        let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
        if inner.epoch != epoch {
            return;
        }
        if let Some(old) = inner.map.remove(&id) {
            inner.bytes -= old.len();
        }
        while inner.bytes + json.len() > self.max_bytes {
            let Some(victim) = inner.map.keys().next().copied() else {
                break;
            };
            if let Some(old) = inner.map.remove(&victim) {
                inner.bytes -= old.len();
            }
        }
        inner.bytes += json.len();
        inner.map.insert(id, json);
    }

    /// Forgets the given skills (call after they are deleted from the store).
    pub fn remove(&self, ids: &[i64]) {
        let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
        inner.epoch += 1;
        for id in ids {
            if let Some(old) = inner.map.remove(id) {
                inner.bytes -= old.len();
            }
        }
    }

    /// Bytes of JSON cached.
    pub fn bytes(&self) -> usize {
        self.inner.read().unwrap_or_else(|e| e.into_inner()).bytes
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
        let c = SkillCache::new(1000);
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
    fn the_cache_never_holds_more_bytes_than_its_bound() {
        let c = SkillCache::new(100);
        for id in 0..50 {
            let e = c.get(id).unwrap_err();
            c.insert(id, Bytes::from(vec![b' '; 10 + id as usize % 7]), e);
            assert!(c.bytes() <= 100, "{} bytes after {id}", c.bytes());
        }
        assert!(c.get(49).is_ok(), "the newest entry is kept");
        assert!(c.len() >= 6, "{} entries", c.len());
        // Re-inserting an entry replaces it without counting it twice.
        let e = c.get(1000).unwrap_err();
        c.insert(49, Bytes::from(vec![b' '; 40]), e);
        let sum: usize = (0..50)
            .filter_map(|id| c.get(id).ok())
            .map(|b| b.len())
            .sum();
        assert_eq!(c.bytes(), sum);
        // An entry larger than the whole cache is not cached; nothing is evicted for it.
        let before = c.len();
        c.insert(2000, Bytes::from(vec![b' '; 101]), e);
        assert!(c.get(2000).is_err());
        assert_eq!(c.len(), before);
        let off = SkillCache::new(0);
        off.insert(1, Bytes::from_static(b"{}"), off.get(1).unwrap_err());
        assert!(off.is_empty(), "0 disables the cache");
    }
}
