//! Replays of stored skills on robot hands: `POST /api/v1/skills/{id}/replays` retargets the
//! skill onto a hand and simulates it (a job, as simulations are: see [`super::jobs`]), stores
//! the report and the replay's MCAP, and answers 201 with the report —
//! also when the replay failed (`success: false` with a `failure_reason`): a failed replay is a
//! result, not an error. `GET /api/v1/skills/{id}/replays`, `GET /api/v1/replays/{id}` and
//! `GET /api/v1/replays/{id}/mcap` read them back. Replays go with their skill.

use axum::extract::State;
use axum::response::{IntoResponse, Response};
use axum::Extension;
use dfs_core::replay::{FailureReason, ReplayReport};
use serde::{Deserialize, Serialize};
use services::replay::skill_spec_from_json;
use services::store::{JobRequest, JobResult, Replay, StoreError};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::created;
use super::error::{Problem, ProblemBody};
use super::extract::{Id, Json, WriteAccess};
use super::jobs::{self, JobBody, Waited};
use super::sessions::{send_mcap, McapFile};
use super::state::AppState;
use super::RequestDeadline;

/// A replay to run.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(
    remote = "Self",
    deny_unknown_fields,
    expecting = "a replay request: a JSON object {\"hand\": ...}"
)]
pub struct ReplayRequest {
    /// Name of the hand: built-in or uploaded (see `GET /api/v1/hands`).
    pub hand: String,
}

// Only a JSON object: serde would also take the fields in a JSON array.
dfs_core::object_only!(
    ReplayRequest,
    "a replay request: a JSON object {\"hand\": ...}"
);

/// A stored replay.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ReplayBody {
    /// Replay id.
    pub replay_id: i64,
    /// The replayed skill.
    pub skill_id: i64,
    /// Name of the hand.
    pub hand: String,
    /// Whether the object was held (the report's `success`).
    pub success: bool,
    /// Why not: unreachable, torque_limit, slip or no_force_closure.
    pub failure_reason: Option<FailureReason>,
    /// The full report (dfs-core's `ReplayReport`).
    #[schema(value_type = ReplayReport)]
    pub report: serde_json::Value,
    /// Hex SHA-256 of the replay's MCAP file.
    pub sha256: String,
    /// Size of the MCAP file, bytes.
    pub size_bytes: i64,
    /// Where to download the MCAP file (viewable in Foxglove like a session).
    pub mcap_url: String,
    /// When the replay was stored (UTC, RFC 3339).
    pub created_at: String,
}

impl From<Replay> for ReplayBody {
    fn from(r: Replay) -> Self {
        ReplayBody {
            mcap_url: format!("/api/v1/replays/{}/mcap", r.id),
            replay_id: r.id,
            skill_id: r.skill_id,
            hand: r.hand,
            success: r.success,
            failure_reason: r.failure_reason,
            report: r.report,
            sha256: r.sha256,
            size_bytes: r.size_bytes,
            created_at: r.created_at,
        }
    }
}

/// The replays of a skill.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ReplayList {
    /// By ascending id.
    pub items: Vec<ReplayBody>,
}

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_replay, list_replays))
        .routes(routes!(get_replay))
        .routes(routes!(download_replay))
}

/// Retargets a stored skill onto a hand, simulates it in the DFS at 1 kHz and stores the
/// report and the replay's MCAP. A replay that fails (unreachable, torque limit, slip, no force
/// closure) is stored and answered 201 like one that succeeds, with `success: false` and its
/// `failure_reason`.
#[utoipa::path(post, path = "/skills/{id}/replays", tag = "replays",
    params(("id" = i64, Path, description = "Skill id")),
    request_body(content = ReplayRequest, content_type = "application/json",
        example = json!({"hand": "allegro"})),
    security((), ("bearer" = [])),
    responses(
        (status = 201, description = "Replayed and stored (successful or not: see `success`); `Location` names the replay", body = ReplayBody,
            headers(("Location" = String, description = "URL of the replay"))),
        (status = 200, description = "The same request's job had stored this replay already", body = ReplayBody),
        (status = 202, description = "Not finished within the server's job wait (`--job-wait`): the job, which `Location` names; `GET` it until `done`, then follow its `result_url`. The same request meanwhile answers the same job", body = JobBody,
            headers(("Location" = String, description = "URL of the job"), ("Retry-After" = u32, description = "Seconds before looking again"))),
        (status = 400, description = "The id is not an integer, malformed JSON (a key twice in one object included, named), or a body that could not be read", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No skill with this id", body = ProblemBody, content_type = "application/problem+json"),
        (status = 422, description = "No hand with this name (named), a bad field, or a skill that does not describe a replayable grasp", body = ProblemBody, content_type = "application/problem+json"),
        (status = 409, description = "The job was cancelled (`DELETE /api/v1/jobs/{id}`) before it finished", body = ProblemBody, content_type = "application/problem+json"),
        (status = 503, description = "The job ran over the server's job time limit (stopped, nothing stored), too many jobs wait already (with `Retry-After`), or the data base cannot be reached", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn create_replay(
    _: WriteAccess,
    State(st): State<AppState>,
    Id(skill_id): Id,
    deadline: Option<Extension<RequestDeadline>>,
    Json(req): Json<ReplayRequest>,
) -> Result<Response, Problem> {
    // Checked here so that a missing skill or hand, or a skill that is no grasp, is answered
    // at once, not by the job.
    let skill = st.store().get_skill(skill_id).await?;
    let name = format!("skill {skill_id}");
    skill_spec_from_json(&skill.params, &name)
        .map_err(|e| Problem::unprocessable(format!("{name} cannot be replayed: {e}")))?;
    let hand = match st.store().get_hand(&req.hand).await {
        Ok(h) => h.summary.name,
        Err(StoreError::HandNotFound(name)) => {
            return Err(Problem::unprocessable(format!(
                "hand: no hand named {name:?} (GET /api/v1/hands lists them)"
            )))
        }
        Err(e) => return Err(e.into()),
    };
    let request = JobRequest::Replay { skill_id, hand };
    match jobs::submit(&st, &request, deadline.map(|e| e.0)).await? {
        Waited::Pending(job) => Ok(jobs::accepted(&job)),
        Waited::Finished { job, new } => match job.result {
            Some(JobResult::Replay { id }) => {
                let body = ReplayBody::from(st.store().get_replay(id).await?);
                if new {
                    Ok(created(body, &format!("/api/v1/replays/{id}")))
                } else {
                    Ok(axum::Json(body).into_response())
                }
            }
            _ => Err(jobs::problem_of(&job).unwrap_or_else(|| {
                Problem::internal(&format!("replay job {} ended without a replay", job.id))
            })),
        },
    }
}

/// The replays of a skill.
#[utoipa::path(get, path = "/skills/{id}/replays", tag = "replays",
    params(("id" = i64, Path, description = "Skill id")),
    responses(
        (status = 200, description = "The skill's replays by ascending id", body = ReplayList),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No skill with this id", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn list_replays(
    State(st): State<AppState>,
    Id(skill_id): Id,
) -> Result<axum::Json<ReplayList>, Problem> {
    let items = st.store().list_replays(skill_id).await?;
    Ok(axum::Json(ReplayList {
        items: items.into_iter().map(ReplayBody::from).collect(),
    }))
}

/// One replay: its report, skill and hand.
#[utoipa::path(get, path = "/replays/{id}", tag = "replays",
    params(("id" = i64, Path, description = "Replay id")),
    responses(
        (status = 200, description = "The replay", body = ReplayBody),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No replay with this id", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn get_replay(
    State(st): State<AppState>,
    Id(id): Id,
) -> Result<axum::Json<ReplayBody>, Problem> {
    Ok(axum::Json(st.store().get_replay(id).await?.into()))
}

/// The replay's MCAP file (the same topics as a session, and a `replay` metadata record with
/// the skill, the hand and the report).
#[utoipa::path(get, path = "/replays/{id}/mcap", tag = "replays",
    params(("id" = i64, Path, description = "Replay id")),
    responses(
        (status = 200, description = "The MCAP file", content_type = "application/x-mcap", body = McapFile),
        (status = 206, description = "The bytes of the one range asked for (`Range: bytes=a-b`), with `Content-Range`", content_type = "application/x-mcap", body = McapFile),
        (status = 304, description = "`If-None-Match` names the file's ETag (its SHA-256)"),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No replay with this id", body = ProblemBody, content_type = "application/problem+json"),
        (status = 416, description = "The range starts past the end of the file", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn download_replay(
    State(st): State<AppState>,
    Id(id): Id,
    request: axum::http::HeaderMap,
) -> Result<Response, Problem> {
    let path = st.store().replay_blob_path(id).await?;
    send_mcap(&path, &format!("replay-{id}.mcap"), &request, || {
        Problem::not_found(format!("no replay with id {id}"))
    })
    .await
}
