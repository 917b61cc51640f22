//! Replays of stored skills on robot hands: `POST /api/v1/skills/{id}/replays` retargets the
//! skill onto a hand and simulates it (on the blocking pool, under the same semaphore as the
//! simulations), stores the report and the replay's MCAP, and answers 201 with the report —
//! also when the replay failed (`success: false` with a `failure_reason`): a failed replay is a
//! result, not an error. `GET /api/v1/skills/{id}/replays`, `GET /api/v1/replays/{id}` and
//! `GET /api/v1/replays/{id}/mcap` read them back. Replays go with their skill.

use axum::extract::State;
use axum::response::Response;
use dfs_core::replay::{ReplayParams, ReplayReport, SkillSpec};
use serde::{Deserialize, Serialize};
use services::replay::{replay_skill_until, skill_spec_from_json, ReplaySource};
use services::store::{Hand, Replay, StoreError};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::created;
use super::error::{Problem, ProblemBody};
use super::extract::{Id, Json, WriteAccess};
use super::sessions::{send_mcap, McapFile};
use super::state::AppState;

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

/// A retargeted contact of a replay.
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(as = PlannedContact)]
pub struct PlannedContactDoc {
    /// The hand's fingertip.
    pub finger: String,
    /// Contact point in the object frame B, m.
    pub position_b: [f64; 3],
    /// Unit normal in B, into the object.
    pub normal_b: [f64; 3],
}

/// Grasp quality of the retargeted contacts (GraspIt!'s metrics, 8-edge cones).
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(as = ReplayQuality)]
pub struct ReplayQualityDoc {
    /// Ferrari-Canny ε (0 without force closure).
    pub epsilon: f64,
    /// Volume of the grasp wrench space.
    pub volume: f64,
    /// Force closure.
    pub force_closure: bool,
}

/// The report of a replay (dfs-core's `ReplayReport`). Failures are reports, never errors.
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(as = ReplayReport)]
pub struct ReplayReportDoc {
    /// The hand.
    pub hand: String,
    /// The object followed its reference motion while held and was never dropped.
    pub success: bool,
    /// Why not, when `success` is false.
    #[schema(value_type = Option<String>, pattern = "^(unreachable|torque_limit|slip|no_force_closure)$")]
    pub failure_reason: Option<String>,
    /// A sentence on what happened.
    pub detail: String,
    /// Largest distance of the object from its reference while held, m.
    pub position_error_max_m: f64,
    /// Root mean square of the same, m.
    pub position_error_rms_m: f64,
    /// Largest rotation of the object away from its reference while held, rad.
    pub orientation_error_max_rad: f64,
    /// Root mean square of the same, rad.
    pub orientation_error_rms_rad: f64,
    /// Largest distance a held contact point moved over the object's surface, m.
    pub max_slip_m: f64,
    /// Ticks in which a held contact slipped.
    pub slip_ticks: u64,
    /// Smallest `1 − |c_t| / (μ c_n)` of a transmitting contact while held.
    pub min_friction_margin: f64,
    /// Largest |τ| / τ_max of the torques the joints applied over the replay (clamped at the
    /// limit: at most 1, and 1 means a joint reached its limit).
    #[schema(minimum = 0.0, maximum = 1.0)]
    pub peak_torque_ratio: f64,
    /// The DOF where that happened.
    pub peak_torque_joint: String,
    /// Quality of the retargeted contacts.
    pub quality: ReplayQualityDoc,
    /// The retargeted contacts.
    pub contacts: Vec<PlannedContactDoc>,
    /// Largest fingertip distance from its contact after inverse kinematics, m.
    pub ik_error_m: f64,
    /// Highest rise of the object above its start, m.
    pub lift_height_m: f64,
    /// Simulated ticks (1 kHz).
    pub ticks: u64,
    /// Simulated time, s.
    pub duration_s: f64,
}

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
    pub failure_reason: Option<String>,
    /// The full report.
    #[schema(value_type = ReplayReportDoc)]
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

/// Replays `skill` on `hand` into a temporary file under `scratch`: blocking work, for the
/// blocking pool. Returns the report and the MCAP bytes.
fn replay_blocking(
    hand: &Hand,
    skill: &SkillSpec,
    source: &ReplaySource,
    scratch: &std::path::Path,
    stop: &dfs_core::Stop,
) -> Result<(ReplayReport, Vec<u8>), Problem> {
    let loaded = hand.load()?;
    std::fs::create_dir_all(scratch).map_err(|e| Problem::internal(&e))?;
    let file = tempfile::Builder::new()
        .prefix("replay-")
        .suffix(".mcap")
        .tempfile_in(scratch)
        .map_err(|e| Problem::internal(&e))?;
    let report = replay_skill_until(
        &loaded,
        skill,
        &ReplayParams::default(),
        source,
        Some(file.path()),
        stop,
    )
    .map_err(|e| match e {
        services::RecordingError::InvalidInput { .. } => {
            Problem::unprocessable(format!("the replay could not run: {e}"))
        }
        other => Problem::internal(&other),
    })?;
    let bytes = std::fs::read(file.path()).map_err(|e| Problem::internal(&e))?;
    Ok((report, bytes))
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
        (status = 400, description = "The id is not an integer, malformed JSON (a key twice in one object included, named), or a body that could not be read", body = ProblemBody, content_type = "application/problem+json"),
        (status = 401, description = "A token is configured and was not sent, or a wrong one", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No skill with this id", body = ProblemBody, content_type = "application/problem+json"),
        (status = 413, description = "The body is over the server's limit", body = ProblemBody, content_type = "application/problem+json"),
        (status = 415, description = "Content-Type is not application/json", body = ProblemBody, content_type = "application/problem+json"),
        (status = 422, description = "No hand with this name (named), a bad field, or a skill that does not describe a replayable grasp", body = ProblemBody, content_type = "application/problem+json"),
        (status = 503, description = "Over the server's time limit (the replay is stopped and not stored), every simulation turn is taken (with `Retry-After`), or the server is stopping", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn create_replay(
    _: WriteAccess,
    State(st): State<AppState>,
    Id(skill_id): Id,
    Json(req): Json<ReplayRequest>,
) -> Result<Response, Problem> {
    let skill = st.store().get_skill(skill_id).await?;
    let hand = match st.store().get_hand(&req.hand).await {
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
    let spec = skill_spec_from_json(&skill.params, &source.skill_name)
        .map_err(|e| Problem::unprocessable(format!("skill {skill_id} cannot be replayed: {e}")))?;
    let scratch = st.scratch_dir().to_path_buf();
    let hand_name = hand.summary.name.clone();
    let (report, bytes) = st
        .run_limited(move |stop| replay_blocking(&hand, &spec, &source, &scratch, stop))
        .await?;
    let replay = st
        .store()
        .insert_replay(skill_id, &hand_name, &report, bytes)
        .await?;
    tracing::info!(
        replay_id = replay.id,
        skill_id,
        hand = %hand_name,
        success = replay.success,
        failure_reason = replay.failure_reason.as_deref().unwrap_or(""),
        "replay stored"
    );
    let location = format!("/api/v1/replays/{}", replay.id);
    Ok(created(ReplayBody::from(replay), &location))
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
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No replay with this id", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn download_replay(State(st): State<AppState>, Id(id): Id) -> Result<Response, Problem> {
    let path = st.store().replay_blob_path(id).await?;
    send_mcap(&path, &format!("replay-{id}.mcap"), || {
        Problem::not_found(format!("no replay with id {id}"))
    })
    .await
}
