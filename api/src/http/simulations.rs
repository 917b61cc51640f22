//! `/api/v1/simulations`: a scenario (built-in name or scenario object) run server-side through
//! the closed 1 kHz loop and recorded, on the blocking pool and never on the async workers,
//! then segmented and stored like an upload. A semaphore bounds how many run at once.

use std::path::Path;

use axum::extract::State;
use axum::response::Response;
use dfs_core::scenario::Scenario;
use serde::{Deserialize, Serialize};
use services::store::IngestOutcome;
use utoipa::openapi::schema::{ObjectBuilder, OneOfBuilder, Schema, Type};
use utoipa::openapi::RefOr;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{Problem, ProblemBody};
use super::extract::{field_error, Json, WriteAccess};
use super::sessions::StoredSession;
use super::state::AppState;

/// Longest session a simulation request may ask for, simulated seconds (a minute of session
/// is about 50 MB of MCAP).
pub const MAX_SIMULATED_S: f64 = 120.0;

/// Shortest session a simulation request may ask for, simulated seconds: the shortest task of
/// a scenario ([`dfs_core::scenario::MIN_TASK_S`]). A session of a tick or two does not read
/// back as a session (fuzzing found `duration: 1e-8` answered 500).
pub const MIN_SIMULATED_S: f64 = dfs_core::scenario::MIN_TASK_S;

/// A simulation to run.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(
    remote = "Self",
    deny_unknown_fields,
    expecting = "a simulation request: a JSON object {\"scenario\": ..., \"seed\": ..., \"duration\": ...}"
)]
pub struct SimulationRequest {
    /// A built-in scenario's name (see `icms scenarios`) or a scenario object as accepted by
    /// `icms simulate --scenario FILE`.
    #[schema(schema_with = scenario_ref_schema)]
    pub scenario: serde_json::Value,
    /// Seed of the operator's tremor and sensor noise. Default: the scenario object's seed, or
    /// 0 for a built-in scenario.
    pub seed: Option<u64>,
    /// Simulated seconds: cuts the script short or extends its last phase, 0.05 to 120.
    /// Default: the script's length.
    #[schema(minimum = 0.05, maximum = 120.0)]
    pub duration: Option<f64>,
}

// Only a JSON object: serde would also take the fields in a JSON array.
dfs_core::object_only!(
    SimulationRequest,
    "a simulation request: a JSON object {\"scenario\": ..., \"seed\": ..., \"duration\": ...}"
);

fn scenario_ref_schema() -> impl Into<RefOr<Schema>> {
    let names = ObjectBuilder::new()
        .schema_type(Type::String)
        .enum_values(Some(Scenario::BUILTINS.iter().copied()))
        .description(Some("A built-in scenario"));
    OneOfBuilder::new()
        .item(names)
        .item(RefOr::Ref(utoipa::openapi::Ref::from_schema_name(
            ScenarioDoc::name(),
        )))
        .description(Some(
            "A built-in scenario's name or a scenario object (the scenario file format)",
        ))
}

/// A scenario object: the object, the grasp style and the operator's task script (the
/// scenario file format of `icms simulate --scenario FILE`).
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(as = Scenario)]
pub struct ScenarioDoc {
    /// Name.
    pub name: String,
    /// The object.
    pub object: ScenarioObjectDoc,
    /// Grasp style: auto (from the object's size), pinch or power. Default auto.
    #[schema(value_type = Option<String>, pattern = "^(auto|pinch|power)$")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grasp: Option<String>,
    /// The task script, in order.
    pub tasks: Vec<TaskDoc>,
    /// Seed of the operator's tremor and sensor noise. Default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// The friction coefficient the operator grips for, > 0. Default: the object's μ.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operator_mu: Option<f64>,
}

/// The object of a scenario.
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(as = ScenarioObject)]
pub struct ScenarioObjectDoc {
    /// sphere, box or cylinder.
    pub shape: String,
    /// Radius, m (sphere, cylinder).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Half extents, m (box).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_extents: Option<[f64; 3]>,
    /// Half height, m (cylinder, axis vertical).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_height: Option<f64>,
    /// Mass, kg, > 0.
    pub mass: f64,
    /// Coulomb friction coefficient, 0 to 10.
    #[schema(minimum = 0.0, maximum = 10.0)]
    pub mu: f64,
    /// Torsional friction, m, 0 to 1. Default 0.005.
    #[schema(minimum = 0.0, maximum = 1.0)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mu_torsion: Option<f64>,
    /// Start position of the object's centre in the world, m. Default: on the table at the
    /// origin.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<[f64; 3]>,
    /// Start rotation about the world z axis, rad. Default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yaw: Option<f64>,
}

/// One task of a scenario's script.
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(as = Task)]
pub struct TaskDoc {
    /// approach, preshape, grasp, lift, hold, transport, place, release or retreat.
    pub phase: String,
    /// Duration, s, in (0, 600].
    pub duration: f64,
    /// lift: height to raise the object, m. Default 0.10.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<f64>,
    /// transport: displacement of the object, m (world). Default (0, 0.15, 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<[f64; 3]>,
    /// transport: turn about the world z axis, rad. Default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn: Option<f64>,
}

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(run_simulation))
}

/// The scenario a request names or holds; errors name the field.
fn scenario_of(req: &SimulationRequest) -> Result<Scenario, Problem> {
    let mut scenario = match &req.scenario {
        serde_json::Value::String(name) => Scenario::builtin(name, req.seed.unwrap_or(0))
            .ok_or_else(|| {
                Problem::unprocessable(format!(
                    "scenario: no built-in scenario named {name:?} (built-in: {})",
                    Scenario::BUILTINS.join(", ")
                ))
            })?,
        v @ serde_json::Value::Object(_) => {
            let s: Scenario = serde_path_to_error::deserialize(v)
                .map_err(|e| Problem::unprocessable(field_error("scenario", &e)))?;
            s
        }
        _ => {
            return Err(Problem::unprocessable(
                "scenario: expected a built-in scenario's name or a scenario object",
            ))
        }
    };
    if let Some(seed) = req.seed {
        scenario.seed = seed;
    }
    scenario
        .resolve()
        .map_err(|e| Problem::unprocessable(format!("scenario: {e}")))?;
    let length = req.duration.unwrap_or_else(|| scenario.duration());
    if !(length.is_finite() && (MIN_SIMULATED_S..=MAX_SIMULATED_S).contains(&length)) {
        return Err(Problem::unprocessable(format!(
            "duration: the session would be {length} s long; the server simulates sessions of \
             {MIN_SIMULATED_S} to {MAX_SIMULATED_S} s"
        )));
    }
    Ok(scenario)
}

/// Simulates `scenario` into a temporary file under `scratch`, then reads and segments it: all
/// blocking work, for the blocking pool. Returns the file's bytes, metadata and skills.
fn simulate_blocking(
    scenario: &Scenario,
    duration: Option<f64>,
    scratch: &Path,
    stop: &dfs_core::Stop,
) -> Result<
    (
        Vec<u8>,
        services::store::SessionMeta,
        Vec<services::store::NewSkill>,
    ),
    Problem,
> {
    std::fs::create_dir_all(scratch).map_err(|e| Problem::internal(&e))?;
    let file = tempfile::Builder::new()
        .prefix("simulation-")
        .suffix(".mcap")
        .tempfile_in(scratch)
        .map_err(|e| Problem::internal(&e))?;
    services::session::record_simulation_until(scenario, duration, file.path(), |_, _| {}, stop)
        .map_err(|e| match e {
            services::RecordingError::InvalidInput { .. }
            | services::RecordingError::Simulation { .. } => {
                Problem::unprocessable(format!("the simulation failed: {e}"))
            }
            other => Problem::internal(&other),
        })?;
    let bytes = std::fs::read(file.path()).map_err(|e| Problem::internal(&e))?;
    let (meta, skills) = services::ingest::analyse(&bytes, &scenario.name)
        .map_err(|e| Problem::internal(&format!("a simulated session did not read back: {e}")))?;
    Ok((bytes, meta, skills))
}

/// Simulates and stores a scenario (see [`AppState::run_limited`]).
pub async fn simulate_and_store(
    st: &AppState,
    scenario: Scenario,
    duration: Option<f64>,
) -> Result<IngestOutcome, Problem> {
    let scratch = st.scratch_dir().to_path_buf();
    let (bytes, meta, skills) = st
        .run_limited(move |stop| simulate_blocking(&scenario, duration, &scratch, stop))
        .await?;
    Ok(st.store().ingest(&bytes, meta, skills).await?)
}

/// Runs a scenario server-side through the closed 1 kHz loop, records it as a session and
/// stores it with its skills.
#[utoipa::path(post, path = "/simulations", tag = "simulations",
    request_body(content = SimulationRequest, content_type = "application/json",
        example = json!({"scenario": "two-grasps", "seed": 7})),
    security((), ("bearer" = [])),
    responses(
        (status = 201, description = "Simulated and stored; `Location` names the new session", body = StoredSession,
            headers(("Location" = String, description = "URL of the session"))),
        (status = 200, description = "An identical session was already stored: that session", body = StoredSession),
        (status = 400, description = "Malformed JSON (a key twice in one object included, named), or a body that could not be read", body = ProblemBody, content_type = "application/problem+json"),
        (status = 401, description = "A token is configured and was not sent, or a wrong one", body = ProblemBody, content_type = "application/problem+json"),
        (status = 413, description = "The body is over the server's limit", body = ProblemBody, content_type = "application/problem+json"),
        (status = 415, description = "Content-Type is not application/json", body = ProblemBody, content_type = "application/problem+json"),
        (status = 422, description = "An unknown scenario, an invalid field (named) or duration, or the simulation failed", body = ProblemBody, content_type = "application/problem+json"),
        (status = 503, description = "Over the server's time limit (the simulation is stopped and not stored), every simulation turn is taken (with `Retry-After`), or the server is stopping", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn run_simulation(
    _: WriteAccess,
    State(st): State<AppState>,
    Json(req): Json<SimulationRequest>,
) -> Result<Response, Problem> {
    let scenario = scenario_of(&req)?;
    let name = scenario.name.clone();
    let out = simulate_and_store(&st, scenario, req.duration).await?;
    tracing::info!(
        scenario = %name,
        session_id = out.session_id,
        skills = out.skill_ids.len(),
        "simulated session stored"
    );
    StoredSession::reply(&st, out).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_scenario_schema_accepts_every_built_in_scenario() {
        for name in Scenario::BUILTINS {
            let s = serde_json::to_value(Scenario::builtin(name, 3).unwrap()).unwrap();
            let doc: ScenarioDoc = serde_json::from_value(s.clone())
                .unwrap_or_else(|e| panic!("{name}: the documented schema lacks a field: {e}"));
            let back: Scenario = serde_json::from_value(serde_json::to_value(doc).unwrap())
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(serde_json::to_value(back).unwrap(), s);
        }
    }

    #[test]
    fn a_duration_of_a_few_ticks_is_refused_not_simulated() {
        for d in [1e-8, 0.001, 0.049] {
            let req: SimulationRequest = serde_json::from_value(
                serde_json::json!({"scenario": "two-grasps", "duration": d}),
            )
            .unwrap();
            let p = scenario_of(&req).unwrap_err();
            assert_eq!(p.status.as_u16(), 422);
            assert!(p.detail.contains("0.05 to 120"), "{}", p.detail);
        }
    }

    #[test]
    fn a_scenario_is_refused_naming_the_field() {
        let req: SimulationRequest = serde_json::from_value(serde_json::json!({
            "scenario": {"name": "x", "object": {"shape": "box", "mass": 1.0, "mu": 0.5,
                "half_extents": [0.02, 0.02, 0.04]}, "tasks": [{"phase": "dance", "duration": 1}]}
        }))
        .unwrap();
        let p = scenario_of(&req).unwrap_err();
        assert_eq!(p.status.as_u16(), 422);
        assert!(p.detail.contains("tasks[0].phase"), "{}", p.detail);
        let req: SimulationRequest =
            serde_json::from_value(serde_json::json!({"scenario": "moonwalk"})).unwrap();
        assert!(scenario_of(&req)
            .unwrap_err()
            .detail
            .contains("sphere-lift"));
    }

    #[test]
    fn request_and_scenario_errors_speak_user_words_not_rust_type_names() {
        let e = serde_json::from_value::<SimulationRequest>(serde_json::json!(7))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("expected a simulation request: a JSON object") && !e.contains("struct"),
            "{e}"
        );
        let e = serde_json::from_value::<crate::http::replays::ReplayRequest>(serde_json::json!(
            "allegro"
        ))
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("expected a replay request") && !e.contains("struct"),
            "{e}"
        );
        let e = serde_json::from_value::<crate::http::hands::HandUpload>(serde_json::json!(null))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("expected a hand upload") && !e.contains("struct"),
            "{e}"
        );
        // A scenario in its sequence form is refused: a scenario is a JSON object.
        let e = serde_json::from_value::<Scenario>(serde_json::json!(["x", {}, "auto", [], 0]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sequence, expected a scenario: a JSON object"),
            "{e}"
        );
    }
}
