//! The metadata half of the store as a trait, [`Catalog`]: every row the store reads or writes
//! goes through it, one implementation per data base backend (today SQLite,
//! [`super::sqlite::SqliteCatalog`]), each with its own compile-time-checked queries.
//!
//! What stays the same whatever the backend lives in [`super::Store`] around it: the blob
//! files, the in-memory k-nearest and recognition indexes, the blob lock that orders deletes
//! after ingests, and the input checks. A catalog method is one unit of work (one transaction
//! where it writes several rows) and answers `None` where a row it needs is missing, which the
//! store turns into the matching not-found error.
//!
//! `dyn Catalog` through `async-trait`, not `async fn` in the trait with the store generic
//! over it: the backend is chosen at run time (a data directory or, with the scale-out
//! issue, a `postgres://` URL), and [`super::Store`] stays one type that the HTTP state, the
//! CLI and the tests hold. The boxed future per call costs far less than the query behind it.

use std::collections::HashSet;

use super::error::StoreError;
use super::jobs::JobClaim;
use super::query::{SessionFilter, SkillFilter};
use super::rows::JobRow;
use super::types::{
    Hand, HandSummary, IngestOutcome, NewSkill, Replay, SessionMeta, SessionRecord, SkillRecord,
    StaleSession, FEATURE_DIM,
};
use crate::assist::features::TEMPLATE_DIM;
pub(crate) use store_postgres::NewReplayRow;

/// A skill checked for storing ([`super::validate_skill`]): the skill and its feature vector.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CheckedSkill {
    /// The skill as given.
    pub skill: NewSkill,
    /// Its feature vector, [`FEATURE_DIM`] finite values.
    pub feature: [f32; FEATURE_DIM],
}

/// A content-addressed blob a row names: its hex SHA-256 and its path relative to the data
/// directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct BlobRef {
    /// Hex SHA-256 of the bytes.
    pub sha256: String,
    /// Path relative to the data directory.
    pub rel: String,
}

/// A session to store whose blob is written: the rows [`Catalog::insert_session`] writes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct NewSession<'a> {
    /// Hex SHA-256 of the session's bytes.
    pub sha256: &'a str,
    /// Size of the blob, bytes.
    pub size_bytes: i64,
    /// Path of the blob relative to the data directory.
    pub blob_path: &'a str,
    /// The session's metadata.
    pub meta: &'a SessionMeta,
    /// The session's length as the signed column holds it, ns.
    pub duration_ns: i64,
    /// Version of the segmentation that made its skills.
    pub segmentation_version: u32,
    /// Its checked skills, in the order their ids are given back.
    pub skills: &'a [CheckedSkill],
}

/// What deleting a session removed: its skills' ids and the blobs of its rows (its own and
/// its skills' replays'), for the store to drop from its indexes and the disk.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct DeletedSession {
    /// Ids of the deleted skills.
    pub skill_ids: Vec<i64>,
    /// Blobs of the deleted session and replays.
    pub blobs: Vec<BlobRef>,
}

/// A stored skill as the in-memory indexes need it (loaded when the store opens).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct IndexedSkill {
    /// Skill id.
    pub id: i64,
    /// Its feature vector.
    pub feature: [f32; FEATURE_DIM],
    /// Its object shape's name.
    pub object_shape: String,
    /// Its grasp type label.
    pub grasp_type: String,
    /// The object's name in its scene, if named.
    pub object_name: Option<String>,
    /// Its approach template, if computed.
    pub approach: Option<[f32; TEMPLATE_DIM]>,
}

/// An uploaded hand whose model was built: the row [`Catalog::insert_hand`] writes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct NewHand<'a> {
    /// The hand's name (its spec's).
    pub name: &'a str,
    /// The hand spec as JSON.
    pub spec_json: &'a str,
    /// The URDF text.
    pub urdf: &'a str,
    /// What lists show of it.
    pub summary: &'a HandSummary,
}

/// The columns of a new hand's row that its summary holds in another form, as every backend
/// stores them.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct HandColumns {
    /// Its DOFs, as the signed column holds them.
    pub dof: i64,
    /// Its fingertip names, JSON.
    pub fingers: String,
    /// Its DOF names, JSON.
    pub dof_names: String,
    /// Its lowest torque limit.
    pub torque_limit_min: f64,
    /// Its highest torque limit.
    pub torque_limit_max: f64,
}

impl NewHand<'_> {
    /// The columns of its row computed from its summary; more DOFs than the column holds are
    /// [`StoreError::InvalidHand`].
    pub(crate) fn columns(&self) -> Result<HandColumns, StoreError> {
        let s = self.summary;
        let dof = i64::try_from(s.dof)
            .map_err(|_| StoreError::InvalidHand(format!("{} DOFs are too many", s.dof)))?;
        let [torque_limit_min, torque_limit_max] = s.torque_limit;
        Ok(HandColumns {
            dof,
            fingers: serde_json::to_string(&s.fingers)?,
            dof_names: serde_json::to_string(&s.dof_names)?,
            torque_limit_min,
            torque_limit_max,
        })
    }
}

/// A job to insert ([`Catalog::insert_job`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct NewJob<'a> {
    /// Its kind's name.
    pub kind: &'static str,
    /// Hex SHA-256 of its request.
    pub key: &'a str,
    /// Its request, JSON.
    pub request: &'a str,
    /// A replay's skill.
    pub skill_id: Option<i64>,
}

/// How a claim on a job ends, as the columns [`Catalog::settle_job`] writes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SettleRow<'a> {
    /// `done`, `failed` or `cancelled`.
    pub state: &'static str,
    /// A simulation's session.
    pub session_id: Option<i64>,
    /// Whether the job stored that session.
    pub session_created: Option<bool>,
    /// A replay's id.
    pub replay_id: Option<i64>,
    /// A failure's HTTP status.
    pub error_status: Option<i64>,
    /// A failure's message.
    pub error_detail: Option<&'a str>,
}

/// What [`Catalog::replace_session_skills`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Replacement {
    /// No session with this id.
    SessionNotFound,
    /// The session's version is already the one asked for or newer: nothing changed.
    UpToDate,
    /// The skills were replaced.
    Done(ReplacedRows),
}

/// The rows a replacement of a session's skills kept, removed and added.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ReplacedRows {
    /// The segmentation version the session had.
    pub from_version: u32,
    /// Kept stored skills: (stored id, index of the identical new skill).
    pub kept: Vec<(i64, usize)>,
    /// Removed stored skills' ids, ascending.
    pub removed: Vec<i64>,
    /// Added skills: (new id, index of the new skill), in the new skills' order.
    pub added: Vec<(i64, usize)>,
    /// Blobs of the replays removed with the removed skills.
    pub replay_blobs: Vec<BlobRef>,
}

/// A hold on the blobs that reaches every server on the same rows and bucket: the
/// cross-server counterpart of the store's in-process blob lock (see
/// [`Catalog::shared_blob_guard`]). Give it back with [`BlobGuard::release`]; one dropped
/// without that is still let go (PostgreSQL: its connection is closed, never returned to
/// the pool holding the lock).
#[async_trait::async_trait]
pub(crate) trait BlobGuard: Send + Sync + std::fmt::Debug {
    /// Lets go of the hold. Infallible for the caller: a failure to unlock is logged and the
    /// hold is let go another way (PostgreSQL: by closing its connection).
    async fn release(self: Box<Self>);
}

/// What [`Catalog::try_exclusive_blob_guard`] got.
#[derive(Debug)]
pub(crate) enum ExclusiveBlobGuard {
    /// The backend has no other server to order against (SQLite: one process per file).
    NotNeeded,
    /// The exclusive hold: no other server is between a blob upload and its row's commit.
    Held(Box<dyn BlobGuard>),
    /// Another server holds the shared hold (it is ingesting): try again later.
    Busy,
}

/// The store's rows in one data base backend. See the module documentation.
#[async_trait::async_trait]
pub(crate) trait Catalog: Send + Sync + std::fmt::Debug {
    /// The stored session of these bytes, with its skill ids, if any.
    async fn stored_session(&self, sha256: &str) -> Result<Option<IngestOutcome>, StoreError>;

    /// Inserts a session, its skills and their phase rows in one transaction; returns the
    /// session's id and its skills' ids (in the order of `new.skills`), or `None` when a
    /// session of the same bytes is stored already (nothing written).
    async fn insert_session(
        &self,
        new: NewSession<'_>,
    ) -> Result<Option<(i64, Vec<i64>)>, StoreError>;

    /// Inserts many sessions in one transaction, as fast as the backend can (the synthetic
    /// generator's path); per session, its skills' ids, or `None` when its bytes were stored
    /// already.
    async fn bulk_insert_sessions(
        &self,
        sessions: &[NewSession<'_>],
    ) -> Result<Vec<Option<Vec<i64>>>, StoreError>;

    /// One session.
    async fn session(&self, id: i64) -> Result<Option<SessionRecord>, StoreError>;

    /// The sessions `filter` selects, in its order, at most its `fetch` of them.
    async fn sessions(&self, filter: &SessionFilter<'_>) -> Result<Vec<SessionRecord>, StoreError>;

    /// The blob of session `id`.
    async fn session_blob(&self, id: i64) -> Result<Option<BlobRef>, StoreError>;

    /// Deletes a session, its skills, their phase rows and replays in one transaction.
    async fn delete_session(&self, id: i64) -> Result<Option<DeletedSession>, StoreError>;

    /// The blob paths some session or replay names.
    async fn referenced_blob_paths(&self) -> Result<HashSet<String>, StoreError>;

    /// Whether a session or a replay names the blob of these bytes.
    async fn blob_is_referenced(&self, sha256: &str) -> Result<bool, StoreError>;

    /// One skill.
    async fn skill(&self, id: i64) -> Result<Option<SkillRecord>, StoreError>;

    /// The skills of `ids` (in any order; missing ids left out).
    async fn skills_by_id(&self, ids: &[i64]) -> Result<Vec<SkillRecord>, StoreError>;

    /// The skills `filter` selects, in its order, at most its `fetch` of them.
    async fn skills(&self, filter: &SkillFilter<'_>) -> Result<Vec<SkillRecord>, StoreError>;

    /// Every skill as the in-memory indexes need it.
    async fn indexed_skills(&self) -> Result<Vec<IndexedSkill>, StoreError>;

    /// Deletes one skill, its phase rows and its replays in one transaction; returns the
    /// replays' blobs.
    async fn delete_skill(&self, id: i64) -> Result<Option<Vec<BlobRef>>, StoreError>;

    /// Stores an uploaded hand; returns its creation time, or `None` when the name is taken.
    async fn insert_hand(&self, hand: NewHand<'_>) -> Result<Option<String>, StoreError>;

    /// The uploaded hands, by upload.
    async fn hands(&self) -> Result<Vec<HandSummary>, StoreError>;

    /// One uploaded hand with its spec and URDF.
    async fn hand(&self, name: &str) -> Result<Option<Hand>, StoreError>;

    /// Stores a replay of an existing skill; `None` when the skill is gone.
    async fn insert_replay(&self, replay: NewReplayRow<'_>) -> Result<Option<Replay>, StoreError>;

    /// One replay.
    async fn replay(&self, id: i64) -> Result<Option<Replay>, StoreError>;

    /// The replays of one skill, by ascending id; `None` when there is no such skill.
    async fn replays_of(&self, skill_id: i64) -> Result<Option<Vec<Replay>>, StoreError>;

    /// The blob path of replay `id`.
    async fn replay_blob_path(&self, id: i64) -> Result<Option<String>, StoreError>;

    /// The sessions segmented by a version below `version`, by ascending id.
    async fn sessions_segmented_before(
        &self,
        version: u32,
    ) -> Result<Vec<StaleSession>, StoreError>;

    /// Number of sessions segmented by a version above `version`.
    async fn sessions_segmented_after(&self, version: u32) -> Result<u64, StoreError>;

    /// Replaces the skills of a session segmented again with `version` in one transaction
    /// that reads what it replaces (see [`super::Store::replace_session_skills`];
    /// [`super::reprocess::plan`] decides what is kept).
    async fn replace_session_skills(
        &self,
        session_id: i64,
        version: u32,
        skills: &[CheckedSkill],
    ) -> Result<Replacement, StoreError>;

    /// How durable a commit is, as the data base reports it (SQLite's `synchronous`: 2 for
    /// `FULL`, 1 for `NORMAL`).
    async fn synchronous_setting(&self) -> Result<i64, StoreError>;

    /// The backend's consistency checks; [`StoreError::Corrupt`] naming what failed.
    async fn integrity_check(&self) -> Result<(), StoreError>;

    /// Refreshes the query planner's statistics.
    async fn optimize(&self) -> Result<(), StoreError>;

    /// The shared cross-server blob hold, which an ingest into a shared bucket keeps from its
    /// blob upload to its row's commit; waits while another server holds the exclusive one
    /// (for a sweep or a delete's blob removal, which try it and never wait). `None`: the
    /// backend needs none (SQLite, whose file one process writes).
    async fn shared_blob_guard(&self) -> Result<Option<Box<dyn BlobGuard>>, StoreError>;

    /// The exclusive cross-server blob hold if no server holds the shared one, without
    /// waiting (see [`Catalog::shared_blob_guard`]).
    async fn try_exclusive_blob_guard(&self) -> Result<ExclusiveBlobGuard, StoreError>;

    /// Inserts a job unless the same request (`key`) has a waiting, running or done job or a
    /// replay's skill is gone: `None` then.
    async fn insert_job(&self, job: NewJob<'_>) -> Result<Option<JobRow>, StoreError>;

    /// The waiting, running or done job of the request `key`.
    async fn active_job(&self, key: &str) -> Result<Option<JobRow>, StoreError>;

    /// Number of jobs waiting for a worker.
    async fn queued_jobs(&self) -> Result<i64, StoreError>;

    /// One job.
    async fn job(&self, id: i64) -> Result<Option<JobRow>, StoreError>;

    /// Jobs with an id below `before`, in `state` if given, newest first, at most `limit`.
    async fn jobs(
        &self,
        state: Option<&str>,
        before: i64,
        limit: i64,
    ) -> Result<Vec<JobRow>, StoreError>;

    /// Ends the running jobs whose lease ran out and that may not be claimed again (cancel
    /// asked for, or `max_attempts` claims had: failed with 503 and `detail`); their number.
    async fn expire_jobs(&self, max_attempts: i64, detail: &str) -> Result<u64, StoreError>;

    /// Claims the oldest waiting job, or the oldest running one whose lease ran out with fewer
    /// than `max_attempts` claims, for `worker`, for `lease_ms`.
    async fn claim_job(
        &self,
        worker: &str,
        lease_ms: i64,
        max_attempts: i64,
    ) -> Result<Option<JobRow>, StoreError>;

    /// Renews a claim for `lease_ms`: whether a cancel was asked for; `None`: the claim is gone.
    async fn renew_job(&self, claim: &JobClaim, lease_ms: i64) -> Result<Option<bool>, StoreError>;

    /// Ends a claim; whether it still held.
    async fn settle_job(&self, claim: &JobClaim, end: SettleRow<'_>) -> Result<bool, StoreError>;

    /// Gives a claimed job back to the queue (its attempt not counted); whether it still held.
    async fn release_job(&self, claim: &JobClaim) -> Result<bool, StoreError>;

    /// Cancels a job (a running one: asks its worker to); the job after that.
    async fn cancel_job(&self, id: i64) -> Result<Option<JobRow>, StoreError>;

    /// Deletes the failed and cancelled jobs that ended more than `age_s` seconds ago.
    async fn prune_jobs(&self, age_s: i64) -> Result<u64, StoreError>;

    /// Closes the connections (waits for queries in flight; later calls fail).
    async fn close(&self);
}
