//! `/api/v1/jobs`: the simulations and replays the server was asked for, as jobs in the data
//! base that any server's workers or an `icms worker` run (see [`crate::jobs`]).
//!
//! `POST /api/v1/simulations` and `POST /api/v1/skills/{id}/replays` submit a job and wait up
//! to `--job-wait` seconds for it: finished by then, they answer its result as before (201 with
//! the stored session or replay); otherwise `202 Accepted` with the job and its URL in
//! `Location`, which `GET /api/v1/jobs/{id}` reads until the job is `done` (its `result_url`
//! names the session or replay) or `failed` (its `error` says why, as the request would have
//! been answered). The same request while its job waits or runs answers with that job, and once
//! it is done with its result (200). `DELETE /api/v1/jobs/{id}` cancels one.

use std::time::Duration;

use axum::extract::State;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use services::store::{Job, JobKind, JobRequest, JobResult, JobState};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{Problem, ProblemBody};
use super::extract::{Id, Query, WriteAccess};
use super::state::AppState;

/// How often a request waiting for its job looks at it, besides when a worker of this server
/// ends a job (a worker elsewhere is seen within this).
const WAIT_POLL: Duration = Duration::from_millis(100);

/// Default page of `GET /api/v1/jobs`.
const DEFAULT_JOB_LIMIT: u32 = 50;

/// A job, as `GET /api/v1/jobs/{id}` shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobBody {
    /// Job id.
    pub job_id: i64,
    /// `simulation` or `replay`.
    #[schema(value_type = String, example = "simulation")]
    pub kind: JobKind,
    /// `queued` (waiting for a worker), `running`, `done`, `failed` or `cancelled`.
    #[schema(value_type = String, example = "running")]
    pub state: JobState,
    /// What the job runs: `{"kind": "simulation", "scenario": {...}, "duration": ...}` (the
    /// scenario resolved) or `{"kind": "replay", "skill_id": ..., "hand": ...}`.
    pub request: serde_json::Value,
    /// Claims by workers so far: 1 once one took it, more if a worker died on it (a job is
    /// failed after 3).
    pub attempts: u32,
    /// Whether a cancel was asked for while it ran (its worker stops it within seconds).
    pub cancel_requested: bool,
    /// The worker of its current or last claim (`host:pid:n`).
    pub worker: Option<String>,
    /// Once done: the stored session (`/api/v1/sessions/{id}`) or replay (`/api/v1/replays/{id}`).
    pub result_url: Option<String>,
    /// Once failed: why, as the request would have been answered had it waited (`status`,
    /// `detail`).
    pub error: Option<ProblemBody>,
    /// This job's URL.
    pub url: String,
    /// When it was submitted (UTC, RFC 3339).
    pub created_at: String,
    /// When its current or last claim began.
    pub started_at: Option<String>,
    /// When it ended.
    pub finished_at: Option<String>,
}

impl JobBody {
    /// The body of `job`.
    pub fn of(job: &Job) -> JobBody {
        JobBody {
            job_id: job.id,
            kind: job.request.kind(),
            state: job.state,
            request: serde_json::to_value(&job.request).unwrap_or_default(),
            attempts: job.attempts,
            cancel_requested: job.cancel_requested,
            worker: job.worker.clone(),
            result_url: job.result.map(|r| match r {
                JobResult::Session { id, .. } => format!("/api/v1/sessions/{id}"),
                JobResult::Replay { id } => format!("/api/v1/replays/{id}"),
            }),
            error: job.error.as_ref().map(|e| {
                Problem::new(
                    StatusCode::from_u16(e.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR),
                    e.detail.clone(),
                )
                .body()
            }),
            url: job_url(job.id),
            created_at: job.created_at.clone(),
            started_at: job.started_at.clone(),
            finished_at: job.finished_at.clone(),
        }
    }
}

/// A page of jobs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobPage {
    /// Newest first.
    pub items: Vec<JobBody>,
    /// Pass as `before` for the next page; absent on the last.
    pub next_before: Option<i64>,
}

/// The filters of `GET /api/v1/jobs`.
#[derive(Debug, Clone, Default, Deserialize, IntoParams)]
#[serde(default, deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct JobParams {
    /// Only jobs in this state: queued, running, done, failed or cancelled.
    pub state: Option<String>,
    /// Only jobs with an id below this (the previous page's `next_before`).
    pub before: Option<i64>,
    /// Page size, 1 to 200. Default 50.
    #[param(minimum = 1, maximum = 200)]
    pub limit: Option<u32>,
}

/// The URL of job `id`.
pub fn job_url(id: i64) -> String {
    format!("/api/v1/jobs/{id}")
}

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_jobs))
        .routes(routes!(get_job, cancel_job))
}

/// What [`submit`] found once it stopped waiting.
#[derive(Debug)]
pub enum Waited {
    /// The job finished (done, failed or cancelled); `new`: this request submitted it.
    Finished {
        /// The job.
        job: Job,
        /// Whether this request submitted it.
        new: bool,
    },
    /// The job still waits or runs: answered 202 (see [`accepted`]).
    Pending(Job),
}

/// Submits `request` as a job (or finds the same request's job) and waits for it up to the
/// server's job wait, stopping at the latest a quarter of the job wait (5 ms at least) before
/// the request's time limit (`deadline`, from [`super::RequestDeadline`]), so that a slow body
/// or data base does not turn the 202 into the time limit's 503.
pub async fn submit(
    st: &AppState,
    request: &JobRequest,
    deadline: Option<super::RequestDeadline>,
) -> Result<Waited, Problem> {
    let started = tokio::time::Instant::now();
    let submitted = st.store().submit_job(request, st.max_queued_jobs()).await?;
    let new = submitted.new;
    let mut job = submitted.job;
    if new {
        tracing::info!(
            job_id = job.id,
            kind = job.request.kind().name(),
            "job submitted"
        );
        st.jobs().job_submitted();
    }
    // job_wait is at most 80 % of the time limit: the margin it leaves is kept from the
    // request's end.
    let mut until = started + st.job_wait();
    if let Some(super::RequestDeadline(end)) = deadline {
        let margin = st.job_wait().mul_f64(0.25).max(Duration::from_millis(5));
        until = until.min(end.checked_sub(margin).unwrap_or(started));
    }
    while !job.state.is_finished() {
        let now = tokio::time::Instant::now();
        if now >= until || st.shutdown_token().is_cancelled() {
            return Ok(Waited::Pending(job));
        }
        tokio::select! {
            () = st.jobs().job_settled() => {}
            () = tokio::time::sleep(WAIT_POLL.min(until - now)) => {}
            () = st.shutdown_token().cancelled() => {}
        }
        job = match st.store().job(job.id).await {
            Ok(j) => j,
            Err(services::store::StoreError::JobNotFound(id)) => {
                return Err(Problem::conflict(format!(
                    "job {id} went while it ran: its skill or its result was deleted \
                     meanwhile; ask again to run it anew"
                )))
            }
            Err(e) => return Err(e.into()),
        };
    }
    Ok(Waited::Finished { job, new })
}

/// `202 Accepted` with the job and `Location` naming it.
pub fn accepted(job: &Job) -> Response {
    let mut r = (StatusCode::ACCEPTED, axum::Json(JobBody::of(job))).into_response();
    if let Ok(v) = HeaderValue::from_str(&job_url(job.id)) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    r.headers_mut()
        .insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
    r
}

/// The problem a finished job without a result answers (`None` for a done job).
pub fn problem_of(job: &Job) -> Option<Problem> {
    match job.state {
        JobState::Failed => Some(match &job.error {
            Some(e) => Problem::new(
                StatusCode::from_u16(e.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR),
                format!("{} (job {})", e.detail, job.id),
            ),
            None => Problem::internal(&format!("job {} failed without an error", job.id)),
        }),
        JobState::Cancelled => Some(Problem::conflict(format!(
            "job {} was cancelled before it finished; nothing was stored (ask again to run it)",
            job.id
        ))),
        _ => None,
    }
}

/// Jobs, newest first, one page at a time.
#[utoipa::path(get, path = "/jobs", tag = "jobs",
    params(JobParams),
    responses(
        (status = 200, description = "One page of jobs, newest first", body = JobPage),
        (status = 400, description = "An unknown state, a limit out of range, or an unknown parameter", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn list_jobs(
    State(st): State<AppState>,
    Query(p): Query<JobParams>,
) -> Result<axum::Json<JobPage>, Problem> {
    let state = match p.state.as_deref() {
        None => None,
        Some(s) => Some(JobState::from_name(s).ok_or_else(|| {
            Problem::bad_request(format!(
                "state {s:?} is not one of {}",
                JobState::ALL.map(JobState::name).join(", ")
            ))
        })?),
    };
    let limit = p.limit.unwrap_or(DEFAULT_JOB_LIMIT);
    let jobs = st.store().jobs(state, p.before, limit).await?;
    let next_before = (jobs.len() == limit as usize)
        .then(|| jobs.last().map(|j| j.id))
        .flatten();
    Ok(axum::Json(JobPage {
        items: jobs.iter().map(JobBody::of).collect(),
        next_before,
    }))
}

/// One job: its state, and once done its result's URL, once failed its error.
#[utoipa::path(get, path = "/jobs/{id}", tag = "jobs",
    params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job", body = JobBody),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No job with this id (a job goes with its result and a replay job with its skill)", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn get_job(State(st): State<AppState>, Id(id): Id) -> Result<axum::Json<JobBody>, Problem> {
    Ok(axum::Json(JobBody::of(&st.store().job(id).await?)))
}

/// Cancels a job: a queued one at once (`cancelled`); a running one is stopped by its worker
/// within seconds (`cancel_requested` until then); nothing of a cancelled job is stored.
#[utoipa::path(delete, path = "/jobs/{id}", tag = "jobs",
    params(("id" = i64, Path, description = "Job id")),
    security((), ("bearer" = [])),
    responses(
        (status = 200, description = "The job after the cancel: `cancelled`, or `running` with `cancel_requested`", body = JobBody),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No job with this id", body = ProblemBody, content_type = "application/problem+json"),
        (status = 409, description = "The job had finished (done or failed) already", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn cancel_job(
    _: WriteAccess,
    State(st): State<AppState>,
    Id(id): Id,
) -> Result<axum::Json<JobBody>, Problem> {
    let job = st.store().cancel_job(id).await?;
    // A cancelled job cancelled again is answered as it is (200): cancelling is idempotent.
    if matches!(job.state, JobState::Done | JobState::Failed) {
        return Err(Problem::conflict(format!(
            "job {id} is {} already: there is nothing to cancel",
            job.state.name()
        )));
    }
    st.jobs().cancel_asked();
    tracing::info!(
        job_id = id,
        state = job.state.name(),
        "job cancel asked for"
    );
    Ok(axum::Json(JobBody::of(&job)))
}
