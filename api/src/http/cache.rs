//! A bounded cache of hot skills' JSON: `GET /skills/{id}` serialises a skill once and then
//! answers from memory. Deletes remove their entries, and so do the changes the store tells of
//! ([`services::store::Store::skill_changes`]: writes through any server on one PostgreSQL
//! data base, or everything when notifications were lost); an epoch counter keeps a read that
//! raced a removal from re-inserting what the removal just dropped.

use std::collections::HashMap;
use std::sync::{Arc, RwLock};

use bytes::Bytes;
use services::store::SkillsChanged;

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

    /// Forgets every skill (anything may have changed: see [`SkillCache::follow`]).
    pub fn clear(&self) {
        let mut inner = self.inner.write().unwrap_or_else(|e| e.into_inner());
        inner.epoch += 1;
        inner.map.clear();
        inner.bytes = 0;
    }

    /// Drops what `changes` tells of until their store is gone: the skills named, or
    /// everything when the store reloaded or this fell behind. Spawned on the current
    /// runtime; holds the cache, not the store.
    pub fn follow(
        self: &Arc<Self>,
        mut changes: tokio::sync::broadcast::Receiver<SkillsChanged>,
    ) -> tokio::task::JoinHandle<()> {
        use tokio::sync::broadcast::error::RecvError;
        let cache = Arc::clone(self);
        tokio::spawn(async move {
            loop {
                match changes.recv().await {
                    Ok(SkillsChanged::Skills(ids)) => cache.remove(&ids),
                    Ok(SkillsChanged::All) | Err(RecvError::Lagged(_)) => cache.clear(),
                    Err(RecvError::Closed) => return,
                }
            }
        })
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
    fn clearing_forgets_everything_and_a_read_that_raced_it_stays_out() {
        let c = SkillCache::new(1000);
        for id in 0..3 {
            c.insert(id, Bytes::from_static(b"{}"), c.get(id).unwrap_err());
        }
        let epoch = c.get(9).unwrap_err();
        c.clear();
        assert!(c.is_empty());
        assert_eq!(c.bytes(), 0);
        c.insert(9, Bytes::from_static(b"{}"), epoch);
        assert!(c.get(9).is_err(), "the stale read stays out");
    }

    /// Waits (at most 5 s) until `ok`, letting the follower run.
    async fn eventually(what: &str, ok: impl Fn() -> bool) {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
        while !ok() {
            assert!(
                std::time::Instant::now() < deadline,
                "not within 5 s: {what}"
            );
            tokio::time::sleep(std::time::Duration::from_millis(1)).await;
        }
    }

    #[tokio::test]
    async fn following_drops_the_changed_skills_and_everything_on_a_reload_or_a_lag() {
        let c = Arc::new(SkillCache::new(1000));
        let fill = |ids: &[i64]| {
            for &id in ids {
                if let Err(epoch) = c.get(id) {
                    c.insert(id, Bytes::from_static(b"{}"), epoch);
                }
            }
        };
        let (tx, rx) = tokio::sync::broadcast::channel(2);
        let task = c.follow(rx);
        fill(&[1, 2, 3]);
        tx.send(SkillsChanged::Skills(vec![2].into())).unwrap();
        eventually("skill 2 dropped", || c.get(2).is_err()).await;
        assert!(c.get(1).is_ok() && c.get(3).is_ok(), "only skill 2 dropped");
        tx.send(SkillsChanged::All).unwrap();
        eventually("everything dropped on a reload", || c.is_empty()).await;
        fill(&[1, 2, 3]);
        // More changes than the channel keeps, before the follower runs: it lagged.
        for id in [7, 8, 9] {
            tx.send(SkillsChanged::Skills(vec![id].into())).unwrap();
        }
        eventually("everything dropped on a lag", || c.is_empty()).await;
        drop(tx);
        task.await.unwrap();
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
