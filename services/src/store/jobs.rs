//! Simulations and replays as jobs in the data base (issue 24, "work spread over machines"):
//! the typed job model and the [`Store`](super::Store) methods that submit, claim, renew and
//! settle them. The rows are `migrations/0007_jobs.sql`'s; the SQL is each backend's.
//!
//! A job is claimed by a worker (one of an `icms serve`'s own, or an `icms worker`'s) for a
//! lease it renews while the work runs ([`JOB_LEASE`]); a worker that dies stops renewing, and
//! once the lease has run out the next free worker claims the job again, at most
//! [`MAX_JOB_ATTEMPTS`] times in all. PostgreSQL claims with `FOR UPDATE SKIP LOCKED`, so
//! workers on many machines never take the same job nor wait on each other's claims; SQLite,
//! written by one process, claims in one `UPDATE`.
//!
//! A claim is the job's id with the worker's name and the attempt it is on ([`JobClaim`]):
//! only that claim may renew, settle or give back the job, so a worker whose lease ran out
//! (a stalled machine) cannot overwrite what the job's new worker does. A stalled worker can
//! still store the result it finished: the work is done at least once, and storing it twice
//! is harmless (a simulated session is content-addressed; a replay is a second report).

use std::time::Duration;

use dfs_core::scenario::Scenario;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::catalog::{NewJob as NewJobRow, SettleRow};
use super::error::StoreError;
use super::rows::JobRow;

/// How long a claim lasts without renewal: a worker renews it every third of this, and a job
/// whose worker died is claimed again this long after the worker's last renewal.
pub const JOB_LEASE: Duration = Duration::from_secs(30);

/// Claims a job gets at most: a job whose worker died this many times is failed, not tried
/// again (a job that kills its worker every time must not kill every worker in turn).
pub const MAX_JOB_ATTEMPTS: u32 = 3;

/// Largest page of [`Store::jobs`](super::Store::jobs): with requests of at most
/// [`MAX_JOB_REQUEST_BYTES`], a page holds at most 12.5 MiB of them.
pub const MAX_JOB_LIMIT: u32 = 200;

/// Largest request a job stores, bytes of its JSON: a scenario of 256 tasks and 8 objects is
/// about 15 KiB.
pub const MAX_JOB_REQUEST_BYTES: usize = 64 * 1024;

/// How long failed and cancelled jobs are kept after they ended ([`Store::prune_jobs`]):
/// a week.
///
/// [`Store::prune_jobs`]: super::Store::prune_jobs
pub const FINISHED_JOB_RETENTION: Duration = Duration::from_secs(7 * 24 * 3600);

/// What a job runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum JobRequest {
    /// Simulate a scenario through the closed 1 kHz loop, record the session and store it with
    /// its skills (`POST /api/v1/simulations`).
    Simulation {
        /// The scenario, resolved (a built-in's name is stored as its scenario, so that a
        /// worker of another version runs what was asked).
        scenario: Box<Scenario>,
        /// Simulated seconds, if not the script's length.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        duration: Option<f64>,
    },
    /// Replay a stored skill on a robot hand and store the report and its recording
    /// (`POST /api/v1/skills/{id}/replays`).
    Replay {
        /// The skill.
        skill_id: i64,
        /// The hand's name (built-in or uploaded; hands never change once stored).
        hand: String,
    },
}

impl JobRequest {
    /// Its kind.
    pub fn kind(&self) -> JobKind {
        match self {
            JobRequest::Simulation { .. } => JobKind::Simulation,
            JobRequest::Replay { .. } => JobKind::Replay,
        }
    }

    /// The request as stored (JSON) and its key: the hex SHA-256 of that JSON, which is
    /// canonical (struct fields in declaration order, no maps), so two equal requests have
    /// equal keys.
    pub fn encode(&self) -> Result<(String, String), StoreError> {
        let json = serde_json::to_string(self)?;
        let key = hex::encode(Sha256::digest(json.as_bytes()));
        Ok((json, key))
    }
}

/// The kind of a job.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobKind {
    /// A simulation of a scenario.
    Simulation,
    /// A replay of a skill on a hand.
    Replay,
}

impl JobKind {
    /// Its name in rows and URLs.
    pub fn name(self) -> &'static str {
        match self {
            JobKind::Simulation => "simulation",
            JobKind::Replay => "replay",
        }
    }

    fn from_name(s: &str) -> Option<Self> {
        match s {
            "simulation" => Some(JobKind::Simulation),
            "replay" => Some(JobKind::Replay),
            _ => None,
        }
    }
}

/// Where a job is in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    /// Waiting for a worker.
    Queued,
    /// A worker runs it.
    Running,
    /// Finished: its result is stored.
    Done,
    /// Finished without a result: its error says why.
    Failed,
    /// Cancelled before it finished.
    Cancelled,
}

impl JobState {
    /// Every state, in the order of a job's life.
    pub const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Done,
        JobState::Failed,
        JobState::Cancelled,
    ];

    /// Its name in rows, URLs and bodies.
    pub fn name(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// The state of this name.
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }

    /// Whether the job is over (done, failed or cancelled).
    pub fn is_finished(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled
        )
    }
}

/// What a finished job stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobResult {
    /// A simulation's session.
    Session {
        /// Its id.
        id: i64,
        /// Whether this job stored it (`false`: the same bytes were stored already).
        created: bool,
    },
    /// A replay.
    Replay {
        /// Its id.
        id: i64,
    },
}

/// Why a job failed: an HTTP status and a message, as the request would have been answered had
/// it waited.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct JobError {
    /// The HTTP status (422: the work cannot run as asked; 503: it was stopped, may succeed
    /// when asked again; 500: a fault of the server).
    pub status: u16,
    /// What went wrong.
    pub detail: String,
}

/// A job as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// Job id.
    pub id: i64,
    /// What it runs.
    pub request: JobRequest,
    /// Where it is in its life.
    pub state: JobState,
    /// Whether someone asked to cancel it while it ran (its worker stops it at its next
    /// renewal).
    pub cancel_requested: bool,
    /// Claims so far (1 once a worker took it; more if a worker died on it).
    pub attempts: u32,
    /// The worker of its current or last claim.
    pub worker: Option<String>,
    /// Its result, once done.
    pub result: Option<JobResult>,
    /// Why it failed, once failed.
    pub error: Option<JobError>,
    /// When it was submitted (UTC, RFC 3339).
    pub created_at: String,
    /// When its current or last claim began.
    pub started_at: Option<String>,
    /// When it finished.
    pub finished_at: Option<String>,
}

impl Job {
    /// The claim a worker holds on this job right after claiming it.
    pub fn claim(&self) -> Option<JobClaim> {
        Some(JobClaim {
            id: self.id,
            worker: self.worker.clone()?,
            attempt: self.attempts,
        })
    }
}

/// A worker's hold on a job: see the module documentation.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JobClaim {
    /// The job.
    pub id: i64,
    /// The worker's name.
    pub worker: String,
    /// The attempt the claim is (the job's `attempts` when claimed).
    pub attempt: u32,
}

/// A job submitted: the job and whether this submission made it (`false`: the same request
/// had a job waiting, running or done, which is this one).
#[derive(Debug, Clone, PartialEq)]
pub struct Submitted {
    /// The job.
    pub job: Job,
    /// Whether it is new.
    pub new: bool,
}

/// What a renewal of a claim found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Renewal {
    /// The claim holds for another lease.
    Held,
    /// The claim holds, and someone asked to cancel the job: stop it and settle it cancelled.
    CancelRequested,
    /// The claim is gone: the lease ran out and another worker took the job, or the job went
    /// with its skill or was deleted. Stop the work; the job is not this worker's.
    Lost,
}

/// How a worker ends its claim on a job.
#[derive(Debug, Clone, PartialEq)]
pub enum JobEnd {
    /// The work is done and its result stored.
    Done(JobResult),
    /// The work failed.
    Failed(JobError),
    /// The work was stopped because someone cancelled the job.
    Cancelled,
    /// The worker stops (its process shuts down) before the work finished: the job goes back
    /// to the queue, this attempt not counted.
    Released,
}

impl TryFrom<JobRow> for Job {
    type Error = StoreError;

    fn try_from(r: JobRow) -> Result<Self, StoreError> {
        let id = r.id;
        let bad = |what: &str| StoreError::Corrupt(format!("job {id}: {what}"));
        let request: JobRequest = serde_json::from_str(&r.request)
            .map_err(|e| bad(&format!("its request does not read: {e}")))?;
        let kind = JobKind::from_name(&r.kind).ok_or_else(|| bad("unknown kind"))?;
        if kind != request.kind() {
            return Err(bad("its kind is not its request's"));
        }
        let state = JobState::from_name(&r.state).ok_or_else(|| bad("unknown state"))?;
        let result = match (r.session_id, r.replay_id) {
            (Some(id), None) => Some(JobResult::Session {
                id,
                created: r.session_created.unwrap_or(false),
            }),
            (None, Some(id)) => Some(JobResult::Replay { id }),
            (None, None) => None,
            (Some(_), Some(_)) => return Err(bad("both a session and a replay")),
        };
        if state == JobState::Done && result.is_none() {
            return Err(bad("done without a result"));
        }
        let error = match (r.error_status, r.error_detail) {
            (Some(status), Some(detail)) => Some(JobError {
                status: u16::try_from(status).map_err(|_| bad("error status out of range"))?,
                detail,
            }),
            _ => None,
        };
        Ok(Job {
            id,
            request,
            state,
            cancel_requested: r.cancel_requested,
            attempts: u32::try_from(r.attempts).map_err(|_| bad("attempts out of range"))?,
            worker: r.worker,
            result,
            error,
            created_at: r.created_at,
            started_at: r.started_at,
            finished_at: r.finished_at,
        })
    }
}

/// `d` in whole milliseconds, as the lease columns count.
pub(crate) fn lease_ms(d: Duration) -> i64 {
    i64::try_from(d.as_millis()).unwrap_or(i64::MAX)
}

/// The message of a job failed because its workers died [`MAX_JOB_ATTEMPTS`] times.
pub(crate) fn exhausted_detail() -> String {
    format!(
        "the job's worker stopped before it finished {MAX_JOB_ATTEMPTS} times (killed, or its \
         machine lost); it is not tried again: ask again to run it anew"
    )
}

impl super::Store {
    /// Submits the work `request` as a job, or finds the job the same request already has
    /// (waiting, running or done: [`Submitted::new`] is `false`). Refused with
    /// [`StoreError::QueueFull`] when `max_queued` jobs wait already, and with
    /// [`StoreError::SkillNotFound`] for a replay of a skill that is not stored.
    pub async fn submit_job(
        &self,
        request: &JobRequest,
        max_queued: u64,
    ) -> Result<Submitted, StoreError> {
        let (json, key) = request.encode()?;
        if json.len() > MAX_JOB_REQUEST_BYTES {
            return Err(StoreError::InvalidInput(format!(
                "the request is {} bytes as stored, more than the {MAX_JOB_REQUEST_BYTES} a job \
                 may hold (a scenario's names or tasks too long?)",
                json.len()
            )));
        }
        let skill_id = match request {
            JobRequest::Replay { skill_id, .. } => Some(*skill_id),
            JobRequest::Simulation { .. } => None,
        };
        let catalog = &self.inner.catalog;
        // The existing job may go between the insert that found it and the read (a replay
        // job with its skill, a done job with its result): try again then.
        for _ in 0..3 {
            if let Some(row) = catalog.active_job(&key).await? {
                return Ok(Submitted {
                    job: row.try_into()?,
                    new: false,
                });
            }
            let queued = u64::try_from(catalog.queued_jobs().await?).unwrap_or(0);
            if queued >= max_queued {
                return Err(StoreError::QueueFull(queued));
            }
            let new = NewJobRow {
                kind: request.kind().name(),
                key: &key,
                request: &json,
                skill_id,
            };
            if let Some(row) = catalog.insert_job(new).await? {
                return Ok(Submitted {
                    job: row.try_into()?,
                    new: true,
                });
            }
            if let Some(id) = skill_id {
                if catalog.skill(id).await?.is_none() {
                    return Err(StoreError::SkillNotFound(id));
                }
            }
        }
        Err(StoreError::Conflict(
            "the same request's job changed three times while it was submitted; try again".into(),
        ))
    }

    /// One job.
    pub async fn job(&self, id: i64) -> Result<Job, StoreError> {
        self.inner
            .catalog
            .job(id)
            .await?
            .ok_or(StoreError::JobNotFound(id))?
            .try_into()
    }

    /// Jobs with an id below `before` (all without), in `state` if given, newest first, at
    /// most `limit` (1 to [`MAX_JOB_LIMIT`]).
    pub async fn jobs(
        &self,
        state: Option<JobState>,
        before: Option<i64>,
        limit: u32,
    ) -> Result<Vec<Job>, StoreError> {
        if !(1..=MAX_JOB_LIMIT).contains(&limit) {
            return Err(StoreError::InvalidQuery(format!(
                "limit must be 1 to {MAX_JOB_LIMIT}, not {limit}"
            )));
        }
        let rows = self
            .inner
            .catalog
            .jobs(
                state.map(JobState::name),
                before.unwrap_or(i64::MAX),
                i64::from(limit),
            )
            .await?;
        rows.into_iter().map(Job::try_from).collect()
    }

    /// Claims a job for `worker` for `lease` (see the module documentation): the oldest
    /// waiting one, or one whose worker died. Jobs whose workers died [`MAX_JOB_ATTEMPTS`]
    /// times are failed first, and jobs cancelled while their worker was away are marked so.
    /// The claim is [`Job::claim`] of the job returned.
    pub async fn claim_job(
        &self,
        worker: &str,
        lease: Duration,
    ) -> Result<Option<Job>, StoreError> {
        let catalog = &self.inner.catalog;
        let max = i64::from(MAX_JOB_ATTEMPTS);
        let ended = catalog.expire_jobs(max, &exhausted_detail()).await?;
        if ended > 0 {
            tracing::warn!(
                jobs = ended,
                "jobs whose workers stopped before they finished are over (cancelled, or \
                 failed after {MAX_JOB_ATTEMPTS} attempts)"
            );
        }
        let Some(row) = catalog.claim_job(worker, lease_ms(lease), max).await? else {
            return Ok(None);
        };
        let claim = JobClaim {
            id: row.id,
            worker: row.worker.clone().unwrap_or_default(),
            attempt: u32::try_from(row.attempts).unwrap_or(0),
        };
        match Job::try_from(row) {
            Ok(job) => Ok(Some(job)),
            // A row this worker cannot read (a newer version's request, a row changed by
            // hand): failed at once, saying why, rather than left to its lease.
            Err(e) => {
                tracing::warn!(job_id = claim.id, error = %e, "a claimed job does not read");
                let end = JobEnd::Failed(JobError {
                    status: 500,
                    detail: format!(
                        "job {} cannot be read by the worker that took it ({}): {e}",
                        claim.id, claim.worker
                    ),
                });
                self.settle_job(&claim, &end).await?;
                Ok(None)
            }
        }
    }

    /// Deletes the failed and cancelled jobs that ended more than `age` ago (the server's
    /// sweep does, with [`FINISHED_JOB_RETENTION`]); their number. Done jobs stay: each goes
    /// with its result.
    pub async fn prune_jobs(&self, age: Duration) -> Result<u64, StoreError> {
        let age_s = i64::try_from(age.as_secs()).unwrap_or(i64::MAX);
        self.inner.catalog.prune_jobs(age_s).await
    }

    /// Renews a claim for another `lease`.
    pub async fn renew_job(
        &self,
        claim: &JobClaim,
        lease: Duration,
    ) -> Result<Renewal, StoreError> {
        Ok(
            match self.inner.catalog.renew_job(claim, lease_ms(lease)).await? {
                Some(false) => Renewal::Held,
                Some(true) => Renewal::CancelRequested,
                None => Renewal::Lost,
            },
        )
    }

    /// Ends a claim; `false` when it no longer held (its lease ran out and another worker
    /// took the job, or the job is gone), and nothing was written.
    pub async fn settle_job(&self, claim: &JobClaim, end: &JobEnd) -> Result<bool, StoreError> {
        let row = |state| SettleRow {
            state,
            session_id: None,
            session_created: None,
            replay_id: None,
            error_status: None,
            error_detail: None,
        };
        let settle = match end {
            JobEnd::Released => return self.inner.catalog.release_job(claim).await,
            JobEnd::Done(JobResult::Session { id, created }) => SettleRow {
                session_id: Some(*id),
                session_created: Some(*created),
                ..row("done")
            },
            JobEnd::Done(JobResult::Replay { id }) => SettleRow {
                replay_id: Some(*id),
                ..row("done")
            },
            JobEnd::Failed(e) => SettleRow {
                error_status: Some(i64::from(e.status)),
                error_detail: Some(&e.detail),
                ..row("failed")
            },
            JobEnd::Cancelled => row("cancelled"),
        };
        self.inner.catalog.settle_job(claim, settle).await
    }

    /// Cancels a job: a waiting one at once; a running one is asked to stop (its worker
    /// stops it within a third of [`JOB_LEASE`] and marks it cancelled); a finished one stays
    /// as it is. The job after that.
    pub async fn cancel_job(&self, id: i64) -> Result<Job, StoreError> {
        self.inner
            .catalog
            .cancel_job(id)
            .await?
            .ok_or(StoreError::JobNotFound(id))?
            .try_into()
    }
}
