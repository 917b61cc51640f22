//! Following the writes of every server on one PostgreSQL data base (issue 24): each store
//! keeps the k-nearest index and the recognition index in memory, and the HTTP server a cache
//! of skills' JSON; this keeps them in step with writes made through any other server.
//!
//! - **What is sent.** A trigger on `skills` (migrations/postgres/0006_skill_notify.sql)
//!   notifies channel [`SKILLS_CHANNEL`] at the commit of every statement that changes skills,
//!   naming the ids (at most 300 a message) and the schema. NOTIFY is transactional: nothing
//!   for a rolled-back write, and messages arrive in commit order.
//! - **What is done with it.** A task per store ([`Listener::follow`]) `LISTEN`s on its own
//!   connection (`application_name` `icms-follow <pid> #<n>`, see
//!   [`Store::follower_application_name`]). Ids inserted or updated are read again from the
//!   data base and put in both indexes (those no longer there are removed: a later delete
//!   committed first); deleted ids are removed. Then the ids go to the subscribers of
//!   [`Store::skill_changes`] (the HTTP server drops them from its cache). The store's own
//!   writes come back too: every step replaces or removes by id, so the echo changes nothing.
//!   Messages of another schema are ignored; one that does not parse is logged and answered
//!   with a reload.
//! - **Lost notifications.** PostgreSQL keeps no notification for a listener that is not
//!   connected. When the connection ends (the data base restarted, the backend was
//!   terminated, the network cut it) or stops answering the ping sent after
//!   [`PING_AFTER`] without a message (within [`PING_TIMEOUT`]), the task connects again,
//!   `LISTEN`s, and only then reloads both indexes from the data base and tells subscribers
//!   [`SkillsChanged::All`]: whatever it missed is in what it reloads, and whatever commits
//!   after the `LISTEN` is notified. A failed attempt is retried after [`RETRY_FIRST`],
//!   doubling up to [`RETRY_MAX`].
//!
//! So a write through another server shows here once its notification arrives (milliseconds
//! after its commit), and at worst, when the connection was lost, once the data base answers
//! again plus one reload; a connection cut silently is noticed within [`PING_AFTER`] +
//! [`PING_TIMEOUT`].

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::Duration;

use sqlx::postgres::{PgConnectOptions, PgListener, PgPool, PgPoolOptions};
use store_postgres::SKILLS_CHANNEL;
use tokio::sync::broadcast;

use super::super::catalog::IndexedSkill;
use super::super::knn::FeatureIndex;
use super::super::rows::convert;
use super::super::{stored_template, Inner, Store, StoreError};
use super::{redact_url, PgCatalog, PG_CONNECT_TIMEOUT};
use crate::assist::index::RecognitionIndex;

/// A quiet listening connection is pinged after this long without a message.
pub const PING_AFTER: Duration = Duration::from_secs(30);

/// A ping not answered within this long counts as a lost connection.
pub const PING_TIMEOUT: Duration = Duration::from_secs(10);

/// Wait after a failed attempt to listen again (or to reload); doubled at each further
/// failure up to [`RETRY_MAX`]. The first attempt after a lost connection is at once.
pub const RETRY_FIRST: Duration = Duration::from_millis(250);

/// Longest wait between two attempts to listen again.
pub const RETRY_MAX: Duration = Duration::from_secs(30);

/// Notifications handled together at most (one query for all their skills).
const MAX_BATCH: usize = 256;

/// Changes kept for a subscriber that does not keep up; one that falls further behind is
/// told [`SkillsChanged::All`] (as a `Lagged` error of its receiver).
const CHANNEL_CAPACITY: usize = 1024;

/// What changed in a store's skills, as [`Store::skill_changes`] tells its subscribers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SkillsChanged {
    /// These skills were stored, changed or deleted (through any server on the data base,
    /// this one's own writes included): a cached copy of any of them is stale.
    Skills(Arc<[i64]>),
    /// Anything may have changed (notifications were lost, or one was not understood): the
    /// indexes were reloaded, and every cached skill is suspect.
    All,
}

/// The following side of a store: the channel to its subscribers, and for a PostgreSQL store
/// the task that listens (stopped when the store closes or the last clone is dropped).
pub(crate) struct Follow {
    changes: broadcast::Sender<SkillsChanged>,
    task: Mutex<Option<Task>>,
}

struct Task {
    handle: tokio::task::JoinHandle<()>,
    application_name: String,
}

impl Follow {
    /// A store that follows nothing yet (SQLite's always: one process writes its directory).
    pub(crate) fn new() -> Follow {
        Follow {
            changes: broadcast::channel(CHANNEL_CAPACITY).0,
            task: Mutex::new(None),
        }
    }

    /// Stops the listening task, if one runs.
    pub(crate) fn stop(&self) {
        let task = self.task.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(t) = task {
            t.handle.abort();
        }
    }

    fn publish(&self, change: SkillsChanged) {
        // No subscriber is no error.
        let _ = self.changes.send(change);
    }
}

impl Drop for Follow {
    fn drop(&mut self) {
        self.stop();
    }
}

impl Store {
    /// The changes to the stored skills made through any server on the same PostgreSQL data
    /// base (this one's own writes included, after their commit), for whoever caches skills:
    /// see [`SkillsChanged`]. A receiver that falls more than 1024 changes behind gets a
    /// `Lagged` error: it must then treat everything as changed. A SQLite store sends
    /// nothing: one process writes its data directory, and its writes are its caller's.
    pub fn skill_changes(&self) -> broadcast::Receiver<SkillsChanged> {
        self.inner.follow.changes.subscribe()
    }

    /// The `application_name` of the connection on which a PostgreSQL store listens for the
    /// other servers' writes (`icms-follow <pid> #<n>`, as `pg_stat_activity` shows it);
    /// `None` for a SQLite store, or once closed.
    pub fn follower_application_name(&self) -> Option<String> {
        let task = self
            .inner
            .follow
            .task
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        task.as_ref().map(|t| t.application_name.clone())
    }
}

/// A store's listening connection, made before its indexes load: nothing committed after the
/// load goes unnotified.
pub(crate) struct Listener {
    listener: PgListener,
    ctx: Ctx,
}

/// What the listening task needs besides the store.
struct Ctx {
    options: PgConnectOptions,
    /// The store's pool, for reading changed skills.
    pool: PgPool,
    /// The schema of the store's tables, as notifications name it.
    schema: String,
    application_name: String,
}

impl Listener {
    /// Connects (within [`PG_CONNECT_TIMEOUT`]) to the data base of `catalog`, at `url`, and
    /// listens on [`SKILLS_CHANNEL`].
    pub(crate) async fn connect(catalog: &PgCatalog, url: &str) -> Result<Listener, StoreError> {
        static STORES: AtomicU64 = AtomicU64::new(0);
        let unreachable = |reason: String| StoreError::Unreachable {
            url: redact_url(url),
            reason,
        };
        let options: PgConnectOptions = url
            .parse()
            .map_err(|e| unreachable(format!("not a PostgreSQL URL: {e}")))?;
        let pool = catalog.pool().clone();
        let schema = store_postgres::skills_schema(&pool).await?;
        let application_name = format!(
            "icms-follow {} #{}",
            std::process::id(),
            STORES.fetch_add(1, Ordering::Relaxed)
        );
        let ctx = Ctx {
            options,
            pool,
            schema,
            application_name,
        };
        let listener = listen(&ctx)
            .await
            .map_err(|e| unreachable(format!("listening for other servers' writes: {e}")))?;
        Ok(Listener { listener, ctx })
    }

    /// Starts the task that keeps `store`'s indexes in step with the notifications.
    pub(crate) fn follow(self, store: &Store) {
        let application_name = self.ctx.application_name.clone();
        let handle = tokio::spawn(run(Arc::downgrade(&store.inner), self.listener, self.ctx));
        let old = store
            .inner
            .follow
            .task
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .replace(Task {
                handle,
                application_name,
            });
        if let Some(old) = old {
            old.handle.abort();
        }
    }
}

/// A new listening connection, in a pool of its own (one that stops answering must not hold
/// up the next).
async fn listen(ctx: &Ctx) -> Result<PgListener, String> {
    let attempt = async {
        let pool = PgPoolOptions::new()
            .max_connections(1)
            .min_connections(0)
            .max_lifetime(None)
            .idle_timeout(None)
            .acquire_timeout(PG_CONNECT_TIMEOUT)
            .connect_lazy_with(ctx.options.clone().application_name(&ctx.application_name));
        let mut listener = PgListener::connect_with(&pool).await?;
        // A lost connection ends this listener: the task makes a new one and reloads.
        listener.eager_reconnect(false);
        listener.listen(SKILLS_CHANNEL).await?;
        Ok::<_, sqlx::Error>(listener)
    };
    match tokio::time::timeout(PG_CONNECT_TIMEOUT * 2, attempt).await {
        Ok(Ok(listener)) => Ok(listener),
        Ok(Err(e)) => Err(e.to_string()),
        Err(_) => Err(format!(
            "no answer within {} s",
            (PG_CONNECT_TIMEOUT * 2).as_secs_f64()
        )),
    }
}

/// The listening task: until the store is gone, receive; when the connection is lost, listen
/// again and reload.
async fn run(store: Weak<Inner>, first: PgListener, ctx: Ctx) {
    let mut first = Some(first);
    let mut retry = RETRY_FIRST;
    loop {
        let mut listener = match first.take() {
            Some(listener) => listener,
            None => {
                let listener = match listen(&ctx).await {
                    Ok(l) => l,
                    Err(e) => {
                        tracing::warn!(error = %e, retry_in_s = retry.as_secs_f64(),
                            "cannot listen for other servers' writes to the skills");
                        tokio::time::sleep(retry).await;
                        retry = (retry * 2).min(RETRY_MAX);
                        continue;
                    }
                };
                // Listening again: what changed meanwhile is in what this reads.
                let Some(inner) = store.upgrade() else { return };
                let reloaded = reload(&Store { inner }, &ctx).await;
                if let Err(e) = reloaded {
                    tracing::warn!(error = %e, retry_in_s = retry.as_secs_f64(),
                        "cannot reload the skill indexes after listening again");
                    drop(listener);
                    tokio::time::sleep(retry).await;
                    retry = (retry * 2).min(RETRY_MAX);
                    continue;
                }
                tracing::info!("listening again for other servers' writes; indexes reloaded");
                listener
            }
        };
        retry = RETRY_FIRST;
        match receive(&store, &ctx, &mut listener).await {
            None => return,
            Some(why) => tracing::warn!(reason = %why,
                "lost the connection that listens for other servers' writes: listening again, \
                 then reloading the skill indexes"),
        }
    }
}

/// Receives and applies notifications until the connection is lost (why) or the store is gone
/// (`None`).
async fn receive(store: &Weak<Inner>, ctx: &Ctx, listener: &mut PgListener) -> Option<String> {
    loop {
        let first = match tokio::time::timeout(PING_AFTER, listener.try_recv()).await {
            Ok(Ok(Some(n))) => n,
            Ok(Ok(None)) => return Some("the data base closed it".into()),
            Ok(Err(e)) => return Some(e.to_string()),
            Err(_) => {
                // Quiet for a while: does the connection still answer?
                let ping = sqlx::query("SELECT 1").execute(&mut *listener);
                match tokio::time::timeout(PING_TIMEOUT, ping).await {
                    Ok(Ok(_)) => continue,
                    Ok(Err(e)) => return Some(format!("ping: {e}")),
                    Err(_) => {
                        return Some(format!(
                            "no answer to a ping within {} s",
                            PING_TIMEOUT.as_secs_f64()
                        ))
                    }
                }
            }
        };
        let mut batch = Batch::default();
        batch.add(&ctx.schema, first.payload());
        // Whatever else has arrived already goes with it.
        let mut lost = None;
        for _ in 1..MAX_BATCH {
            match tokio::time::timeout(Duration::ZERO, listener.try_recv()).await {
                Ok(Ok(Some(n))) => batch.add(&ctx.schema, n.payload()),
                Ok(Ok(None)) => {
                    lost = Some("the data base closed it".to_owned());
                    break;
                }
                Ok(Err(e)) => {
                    lost = Some(e.to_string());
                    break;
                }
                // Nothing more has arrived.
                Err(_) => break,
            }
        }
        let inner = store.upgrade()?;
        if let Err(e) = batch.apply(&Store { inner }, ctx).await {
            // The data base did not answer: listening again reloads everything.
            return Some(format!("reading changed skills: {e}"));
        }
        if lost.is_some() {
            return lost;
        }
    }
}

/// One notification, as migrations/postgres/0006_skill_notify.sql sends it.
#[derive(Debug, serde::Deserialize)]
struct Message {
    schema: String,
    op: Op,
    #[serde(default)]
    ids: Vec<i64>,
}

#[derive(Debug, Clone, Copy, serde::Deserialize)]
#[serde(rename_all = "UPPERCASE")]
enum Op {
    Insert,
    Update,
    Delete,
    Truncate,
}

/// The notifications handled together.
#[derive(Debug, Default, PartialEq, Eq)]
struct Batch {
    /// Inserted or updated: read again.
    changed: BTreeSet<i64>,
    /// Deleted (ids are never reused: a delete wins over an insert of the same batch).
    removed: BTreeSet<i64>,
    /// Everything is to be read again.
    reload: bool,
}

impl Batch {
    /// Adds the notification `payload` for a store whose tables are in `schema`.
    fn add(&mut self, schema: &str, payload: &str) {
        match serde_json::from_str::<Message>(payload) {
            Ok(m) if m.schema != schema => {}
            Ok(Message {
                op: Op::Insert | Op::Update,
                ids,
                ..
            }) => self.changed.extend(ids),
            Ok(Message {
                op: Op::Delete,
                ids,
                ..
            }) => self.removed.extend(ids),
            Ok(Message {
                op: Op::Truncate, ..
            }) => self.reload = true,
            Err(e) => {
                let shown: String = payload.chars().take(200).collect();
                tracing::warn!(payload = %shown, error = %e,
                    "a notification of a change to the skills that is not understood: \
                     reloading the skill indexes");
                self.reload = true;
            }
        }
    }

    /// Brings `store`'s indexes up to date with the batch and tells its subscribers.
    async fn apply(self, store: &Store, ctx: &Ctx) -> Result<(), StoreError> {
        if self.reload {
            return reload(store, ctx).await;
        }
        let load: Vec<i64> = self.changed.difference(&self.removed).copied().collect();
        let found: Vec<IndexedSkill> = if load.is_empty() {
            Vec::new()
        } else {
            convert(store_postgres::indexed_skills_by_id(&ctx.pool, &load).await?)?
        };
        let found_ids: BTreeSet<i64> = found.iter().map(|s| s.id).collect();
        // Changed and gone since: a delete that committed later, whose message follows.
        let removed: Vec<i64> = self
            .removed
            .iter()
            .chain(load.iter().filter(|id| !found_ids.contains(id)))
            .copied()
            .collect();
        if removed.is_empty() && found.is_empty() {
            return Ok(());
        }
        {
            let mut index = store.inner.index.write().expect("index lock");
            index.remove_many(&removed);
            for s in &found {
                index.insert(s.id, s.feature);
            }
        }
        store.update_recognition(&removed, found.into_iter().map(template));
        let mut ids: Vec<i64> = removed;
        ids.extend(found_ids);
        ids.sort_unstable();
        store
            .inner
            .follow
            .publish(SkillsChanged::Skills(ids.into()));
        Ok(())
    }
}

fn template(s: IndexedSkill) -> crate::assist::index::StoredTemplate {
    stored_template(
        s.id,
        &s.object_shape,
        &s.grasp_type,
        s.object_name,
        s.approach,
        s.feature,
    )
}

/// Replaces both indexes with what the data base holds now and tells subscribers
/// [`SkillsChanged::All`].
async fn reload(store: &Store, ctx: &Ctx) -> Result<(), StoreError> {
    let skills: Vec<IndexedSkill> = convert(store_postgres::indexed_skills(&ctx.pool).await?)?;
    let entries = skills.iter().map(|s| (s.id, s.feature)).collect();
    let index = FeatureIndex::from_entries(entries);
    let recognition = RecognitionIndex::new(skills.into_iter().map(template));
    *store.inner.index.write().expect("index lock") = index;
    *store.inner.recognition.write().expect("recognition lock") = Arc::new(recognition);
    store.inner.follow.publish(SkillsChanged::All);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_reads_inserts_and_updates_again_and_removes_deletes() {
        let mut b = Batch::default();
        b.add("s", r#"{"schema": "s", "op": "INSERT", "ids": [3, 1]}"#);
        b.add("s", r#"{"schema": "s", "op": "UPDATE", "ids": [7]}"#);
        b.add("s", r#"{"schema": "s", "op": "DELETE", "ids": [1]}"#);
        b.add("s", r#"{"schema": "other", "op": "DELETE", "ids": [3]}"#);
        assert_eq!(
            b,
            Batch {
                changed: [1, 3, 7].into(),
                removed: [1].into(),
                reload: false,
            }
        );
    }

    #[test]
    fn a_payload_not_understood_or_a_truncate_asks_for_a_reload() {
        for payload in [
            "",
            "not json",
            r#"{"schema": "s", "op": "MERGE", "ids": [1]}"#,
            r#"{"schema": "s", "op": "INSERT", "ids": ["x"]}"#,
            r#"{"op": "INSERT", "ids": [1]}"#,
            r#"{"schema": "s", "op": "TRUNCATE"}"#,
        ] {
            let mut b = Batch::default();
            b.add("s", payload);
            assert!(b.reload, "{payload:?}");
        }
    }
}
