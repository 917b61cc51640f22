//! The job workers: the tasks that claim simulations and replays from the store's job table
//! (`services::store::jobs`), run them on the blocking pool and store their results. Every
//! `icms serve` runs `--max-simulations` of them; `icms worker` runs them without serving HTTP,
//! on the same data base and bucket as the servers (PostgreSQL), to add machines to the work.
//!
//! A worker renews its claim every third of the lease, at least every [`CANCEL_POLL`], while
//! the work runs. The work is given a
//! [`Stop`] that is set when the job runs over `--job-timeout` (the job fails, 503, nothing
//! stored), when someone cancels it (`DELETE /api/v1/jobs/{id}`: the job ends cancelled), when
//! the claim is lost (another worker has the job now: this one lets go of it) and when the
//! process shuts down (the job goes back to the queue for the next worker: accepted work is
//! not lost). A worker killed outright stops renewing; its job is claimed again once the lease
//! has run out.

use std::sync::Arc;
use std::time::Duration;

use dfs_core::replay::{ReplayParams, ReplayReport, SkillSpec};
use dfs_core::scenario::Scenario;
use dfs_core::Stop;
use services::replay::{replay_skill_until, skill_spec_from_json, ReplaySource};
use services::session::{SessionOut, SessionSource};
use services::store::{
    Hand, Job, JobClaim, JobEnd, JobError, JobRequest, JobResult, NewSkill, Renewal, SessionMeta,
    StagedBlob, Store, StoreError,
};
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;

use crate::http::error::Problem;

/// How long an idle worker sleeps before it looks for work again, unless woken sooner (a job
/// submitted through its own server wakes it at once; one submitted through another server
/// waits at most this).
pub const IDLE_POLL: Duration = Duration::from_millis(250);

/// Longest a running job's worker takes to hear of a cancel asked for through another
/// process: it renews its claim (and reads the cancel flag) at least this often.
pub const CANCEL_POLL: Duration = Duration::from_secs(1);

/// Longest pause after the data base failed to answer a claim, doubling from a quarter second.
const MAX_BACKOFF: Duration = Duration::from_secs(5);

/// The settings of the workers.
#[derive(Debug, Clone)]
pub struct WorkerConfig {
    /// Workers, each running one job at a time.
    pub count: usize,
    /// Longest a job may run before it is stopped and failed.
    pub job_timeout: Duration,
    /// How long a claim lasts without renewal ([`services::store::JOB_LEASE`]).
    pub lease: Duration,
}

/// What the workers and the requests that wait for them tell each other within one process.
#[derive(Debug, Default)]
pub struct JobSignals {
    /// A job was submitted: one idle worker looks for it at once.
    wake: Notify,
    /// A job ended here: the requests waiting for a job look at theirs.
    settled: Notify,
    /// A cancel was asked for here: the workers look whether it is their job's at once.
    cancels: Notify,
}

impl JobSignals {
    /// Tells one idle worker of this process that a job waits.
    pub fn job_submitted(&self) {
        self.wake.notify_one();
    }

    /// Tells this process's workers that a cancel was asked for (they check their jobs at
    /// once; a worker elsewhere hears of it within [`CANCEL_POLL`]).
    pub fn cancel_asked(&self) {
        self.cancels.notify_waiters();
    }

    /// Resolves when a worker of this process ends a job (or never: wait with a timeout, for
    /// jobs other processes end).
    pub async fn job_settled(&self) {
        self.settled.notified().await;
    }
}

/// This machine's name and this process's id: the prefix of its workers' names, which the
/// jobs they claim show.
pub fn worker_prefix() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_owned())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into());
    format!("{host}:{}", std::process::id())
}

/// Starts `config.count` workers on `store`; they run until `stop` is cancelled, then stop
/// the work in flight and give its jobs back (see the module documentation). Wait for the
/// returned tasks before closing the store.
pub fn spawn_workers(
    store: &Store,
    config: &WorkerConfig,
    signals: &Arc<JobSignals>,
    stop: &CancellationToken,
) -> tokio::task::JoinSet<()> {
    let mut set = tokio::task::JoinSet::new();
    let prefix = worker_prefix();
    for k in 0..config.count {
        let worker = Worker {
            store: store.clone(),
            name: format!("{prefix}:{k}"),
            config: config.clone(),
            signals: Arc::clone(signals),
            stop: stop.clone(),
        };
        set.spawn(async move { worker.run().await });
    }
    set
}

/// One worker.
struct Worker {
    store: Store,
    name: String,
    config: WorkerConfig,
    signals: Arc<JobSignals>,
    stop: CancellationToken,
}

/// Why a job's work was told to stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum StopReason {
    Deadline,
    Cancelled,
    Lost,
    Shutdown,
}

/// What a job's blocking work made, for storing.
enum Made {
    Session(StagedBlob, SessionMeta, Vec<NewSkill>),
    Replay {
        report: ReplayReport,
        mcap: StagedBlob,
        skill_id: i64,
        hand: String,
    },
}

/// A job's blocking work.
type Work = Box<dyn FnOnce(&Stop) -> Result<Made, Problem> + Send>;

impl Worker {
    async fn run(self) {
        let mut backoff = Duration::from_millis(250);
        while !self.stop.is_cancelled() {
            match self.store.claim_job(&self.name, self.config.lease).await {
                Ok(Some(job)) => {
                    backoff = Duration::from_millis(250);
                    self.run_job(job).await;
                    self.signals.settled.notify_waiters();
                }
                Ok(None) => {
                    tokio::select! {
                        () = self.signals.wake.notified() => {}
                        () = tokio::time::sleep(IDLE_POLL) => {}
                        () = self.stop.cancelled() => {}
                    }
                }
                Err(e) => {
                    tracing::warn!(worker = %self.name, error = %e,
                        "could not look for jobs; trying again");
                    tokio::select! {
                        () = tokio::time::sleep(backoff) => {}
                        () = self.stop.cancelled() => {}
                    }
                    backoff = (backoff * 2).min(MAX_BACKOFF);
                }
            }
        }
    }

    async fn run_job(&self, job: Job) {
        let Some(claim) = job.claim() else {
            return;
        };
        tracing::info!(job_id = job.id, kind = job.request.kind().name(), attempt = claim.attempt,
            worker = %self.name, "job claimed");
        let end = match self.prepare(&job.request).await {
            Ok(work) => match self.execute(&claim, work).await {
                Some(end) => end,
                None => {
                    tracing::info!(
                        job_id = job.id,
                        "the job's claim is gone (it ran out and another worker took the job, \
                         or the job went with its skill): left to it"
                    );
                    return;
                }
            },
            Err(p) => failed(&p),
        };
        self.settle(&claim, end).await;
    }

    /// Records the end of the job of `claim`, trying again on a failure: a done job whose
    /// result cannot be named (it was deleted as it was stored) is recorded failed, and a job
    /// whose end cannot be recorded at all is given back to the queue rather than left to
    /// its lease.
    async fn settle(&self, claim: &JobClaim, mut end: JobEnd) {
        for attempt in 1..=3 {
            match self.store.settle_job(claim, &end).await {
                Ok(true) => {
                    tracing::info!(job_id = claim.id, end = ?end, "job ended");
                    return;
                }
                Ok(false) => {
                    tracing::info!(
                        job_id = claim.id,
                        "the job's claim was gone when it ended: another worker has it, or \
                         it is gone"
                    );
                    return;
                }
                Err(e) => {
                    tracing::warn!(job_id = claim.id, attempt, error = %e,
                        "could not record the job's end");
                    if attempt == 2 && matches!(end, JobEnd::Done(_)) {
                        end = failed(&Problem::conflict(format!(
                            "the job's result was stored but could not be recorded as its \
                             result ({e}); it may have been deleted meanwhile: ask again"
                        )));
                    }
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        }
        match self.store.settle_job(claim, &JobEnd::Released).await {
            Ok(_) => tracing::warn!(
                job_id = claim.id,
                "the job's end could not be recorded: it is back in the queue"
            ),
            Err(e) => tracing::warn!(job_id = claim.id, error = %e,
                "the job's end could not be recorded; it will be claimed again when its lease \
                 runs out"),
        }
    }

    /// The blocking work of a request, once what it needs is read from the store.
    async fn prepare(&self, request: &JobRequest) -> Result<Work, Problem> {
        let store = self.store.clone();
        match request {
            JobRequest::Simulation { scenario, duration } => {
                let scenario: Scenario = (**scenario).clone();
                let duration = *duration;
                Ok(Box::new(move |stop: &Stop| {
                    let (staged, meta, skills) =
                        simulate_blocking(&store, &scenario, duration, stop)?;
                    Ok(Made::Session(staged, meta, skills))
                }))
            }
            JobRequest::Replay { skill_id, hand } => {
                let skill_id = *skill_id;
                let skill = self.store.get_skill(skill_id).await?;
                let hand = match self.store.get_hand(hand).await {
                    Ok(h) => h,
                    Err(StoreError::HandNotFound(name)) => {
                        return Err(Problem::unprocessable(format!(
                            "hand: no hand named {name:?} (GET /api/v1/hands lists them)"
                        )))
                    }
                    Err(e) => return Err(e.into()),
                };
                let source = ReplaySource {
                    skill_id: Some(skill_id),
                    skill_name: format!("skill {skill_id}"),
                };
                let spec =
                    skill_spec_from_json(&skill.params, &source.skill_name).map_err(|e| {
                        Problem::unprocessable(format!("skill {skill_id} cannot be replayed: {e}"))
                    })?;
                Ok(Box::new(move |stop: &Stop| {
                    let (report, mcap) = replay_blocking(&store, &hand, &spec, &source, stop)?;
                    Ok(Made::Replay {
                        report,
                        mcap,
                        skill_id,
                        hand: hand.summary.name.clone(),
                    })
                }))
            }
        }
    }

    /// Runs `work` on the blocking pool, renewing the claim meanwhile, and stores what it made;
    /// `None` when the claim was lost.
    async fn execute(&self, claim: &JobClaim, work: Work) -> Option<JobEnd> {
        let stop = Arc::new(Stop::new());
        let handle = tokio::task::spawn_blocking({
            let stop = Arc::clone(&stop);
            move || work(&stop)
        });
        tokio::pin!(handle);
        let deadline = tokio::time::sleep(self.config.job_timeout);
        tokio::pin!(deadline);
        let period = (self.config.lease / 3).clamp(Duration::from_millis(50), CANCEL_POLL);
        let mut renewals = tokio::time::interval_at(tokio::time::Instant::now() + period, period);
        let mut why: Option<StopReason> = None;
        // The first reason stands, but a cancel outranks the deadline (the user asked; the job
        // ends cancelled, not failed) and a lost claim outranks everything (the job is not
        // this worker's to end).
        let halt = |reason: StopReason, why: &mut Option<StopReason>| {
            let replace = match *why {
                None => true,
                Some(StopReason::Deadline) => reason == StopReason::Cancelled,
                Some(StopReason::Lost) => false,
                Some(_) => reason == StopReason::Lost,
            };
            if replace {
                *why = Some(reason);
                stop.stop();
            }
        };
        let joined = loop {
            tokio::select! {
                j = &mut handle => break j,
                () = &mut deadline, if why.is_none() => halt(StopReason::Deadline, &mut why),
                () = self.stop.cancelled(), if why.is_none() => {
                    halt(StopReason::Shutdown, &mut why);
                }
                () = async {
                    tokio::select! {
                        _ = renewals.tick() => {}
                        () = self.signals.cancels.notified() => {}
                    }
                } => match self.store.renew_job(claim, self.config.lease).await {
                    Ok(Renewal::Held) => {}
                    Ok(Renewal::CancelRequested) => halt(StopReason::Cancelled, &mut why),
                    Ok(Renewal::Lost) => halt(StopReason::Lost, &mut why),
                    // The lease may run out; the end finds out whether the claim held.
                    Err(e) => tracing::warn!(job_id = claim.id, error = %e,
                        "could not renew the job's claim"),
                },
            }
        };
        let made = match joined {
            Ok(made) => made,
            Err(e) => Err(Problem::internal(&format!("the job's work panicked: {e}"))),
        };
        match (why, made) {
            (Some(StopReason::Lost), _) => None,
            (Some(StopReason::Cancelled), _) => Some(JobEnd::Cancelled),
            (Some(StopReason::Shutdown), Err(_)) => {
                tracing::info!(
                    job_id = claim.id,
                    "work stopped by shutdown; the job goes back to the queue"
                );
                Some(JobEnd::Released)
            }
            (Some(StopReason::Deadline), Err(_)) => {
                tracing::info!(
                    job_id = claim.id,
                    "work stopped before it finished: over its time limit"
                );
                Some(failed(&Problem::unavailable(format!(
                    "the job ran over the server's time limit of {} s (--job-timeout) and was \
                     stopped; nothing was stored",
                    self.config.job_timeout.as_secs_f64()
                ))))
            }
            (_, Err(p)) => Some(failed(&p)),
            // Finished as it was told to stop: what it made is kept. Storing it (a bucket upload,
            // the rows) may outlast a lease: the claim is renewed meanwhile.
            (_, Ok(made)) => {
                let keep = self.keep(made);
                tokio::pin!(keep);
                let kept = loop {
                    tokio::select! {
                        r = &mut keep => break r,
                        _ = renewals.tick() => {
                            if let Err(e) = self.store.renew_job(claim, self.config.lease).await {
                                tracing::warn!(job_id = claim.id, error = %e,
                                    "could not renew the job's claim");
                            }
                        }
                    }
                };
                Some(match kept {
                    Ok(result) => JobEnd::Done(result),
                    Err(p) => failed(&p),
                })
            }
        }
    }

    /// Stores what a job made.
    async fn keep(&self, made: Made) -> Result<JobResult, Problem> {
        match made {
            Made::Session(staged, meta, skills) => {
                let out = self.store.ingest_staged(staged, meta, skills).await?;
                tracing::info!(
                    session_id = out.session_id,
                    skills = out.skill_ids.len(),
                    created = out.created,
                    "simulated session stored"
                );
                Ok(JobResult::Session {
                    id: out.session_id,
                    created: out.created,
                })
            }
            Made::Replay {
                report,
                mcap,
                skill_id,
                hand,
            } => {
                let replay = self
                    .store
                    .insert_replay_staged(skill_id, &hand, &report, mcap)
                    .await?;
                tracing::info!(replay_id = replay.id, skill_id, hand = %hand,
                    success = replay.success,
                    failure_reason = replay.failure_reason.map_or("", |r| r.name()),
                    "replay stored");
                Ok(JobResult::Replay { id: replay.id })
            }
        }
    }
}

/// A job's failure as the problem its request would have been answered with.
fn failed(p: &Problem) -> JobEnd {
    JobEnd::Failed(JobError {
        status: p.status.as_u16(),
        detail: p.detail.clone(),
    })
}

/// Simulates `scenario` straight into a staged blob of the store (`blobs/sha256/staging/`),
/// hashed as the recorder writes it, and segments it from the file in two streamed passes:
/// all blocking work, for the blocking pool. The file is never read into memory; storing it
/// is a rename.
pub fn simulate_blocking(
    store: &Store,
    scenario: &Scenario,
    duration: Option<f64>,
    stop: &Stop,
) -> Result<(StagedBlob, SessionMeta, Vec<NewSkill>), Problem> {
    let mut staged = store.stage_upload().map_err(|e| Problem::internal(&e))?;
    let out = SessionOut::Stream {
        out: Box::new(staged.writer().map_err(|e| Problem::internal(&e))?),
        name: staged.path().to_path_buf(),
    };
    services::session::record_simulation_until(scenario, duration, out, |_, _| {}, stop).map_err(
        |e| match e {
            services::RecordingError::InvalidInput { .. }
            | services::RecordingError::Simulation { .. } => {
                Problem::unprocessable(format!("the simulation failed: {e}"))
            }
            other => Problem::internal(&other),
        },
    )?;
    staged.finish().map_err(|e| Problem::internal(&e))?;
    let (meta, skills) = services::ingest::analyse_source(&SessionSource::File(staged.path()))
        .map_err(|e| Problem::internal(&format!("a simulated session did not read back: {e}")))?;
    Ok((staged, meta, skills))
}

/// Replays `skill` on `hand` straight into a staged blob of the store, hashed as the recorder
/// writes it: blocking work, for the blocking pool. Returns the report and the staged file,
/// which storing moves into place (never read into memory).
fn replay_blocking(
    store: &Store,
    hand: &Hand,
    skill: &SkillSpec,
    source: &ReplaySource,
    stop: &Stop,
) -> Result<(ReplayReport, StagedBlob), Problem> {
    let loaded = hand.load()?;
    let mut staged = store.stage_upload().map_err(|e| Problem::internal(&e))?;
    let out = SessionOut::Stream {
        out: Box::new(staged.writer().map_err(|e| Problem::internal(&e))?),
        name: staged.path().to_path_buf(),
    };
    let report = replay_skill_until(
        &loaded,
        skill,
        &ReplayParams::default(),
        source,
        Some(out),
        stop,
    )
    .map_err(|e| match e {
        services::RecordingError::InvalidInput { .. } => {
            Problem::unprocessable(format!("the replay could not run: {e}"))
        }
        other => Problem::internal(&other),
    })?;
    staged.finish().map_err(|e| Problem::internal(&e))?;
    Ok((report, staged))
}
