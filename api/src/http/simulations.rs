//! `/api/v1/simulations`: a scenario (built-in name or scenario object) run server-side through
//! the closed 1 kHz loop and recorded, then segmented and stored like an upload: a job that a
//! worker of any server on the data base runs (see [`super::jobs`]).

use axum::extract::State;
use axum::response::Response;
use axum::Extension;
use dfs_core::scenario::Scenario;
use serde::Deserialize;
use services::store::{IngestOutcome, JobRequest, JobResult};
use utoipa::openapi::schema::{ObjectBuilder, OneOfBuilder, Schema, Type};
use utoipa::openapi::RefOr;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{Problem, ProblemBody};
use super::extract::{field_error, Json, WriteAccess};
use super::jobs::{self, JobBody, Waited};
use super::sessions::StoredSession;
use super::state::AppState;
use super::RequestDeadline;

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
            Scenario::name(),
        )))
        .description(Some(
            "A built-in scenario's name or a scenario object (the scenario file format)",
        ))
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
    // A scenario that varies its reaches may run longer than its script.
    let length = req.duration.unwrap_or_else(|| scenario.longest_duration());
    if !(length.is_finite() && (MIN_SIMULATED_S..=MAX_SIMULATED_S).contains(&length)) {
        return Err(Problem::unprocessable(format!(
            "duration: the session would be {length} s long; the server simulates sessions of \
             {MIN_SIMULATED_S} to {MAX_SIMULATED_S} s"
        )));
    }
    Ok(scenario)
}

/// Runs a scenario server-side through the closed 1 kHz loop, records it as a session and
/// stores it with its skills: a job, answered with its session when it finishes within the
/// server's job wait, else 202 with the job.
#[utoipa::path(post, path = "/simulations", tag = "simulations",
    request_body(content = SimulationRequest, content_type = "application/json",
        example = json!({"scenario": "two-grasps", "seed": 7})),
    security((), ("bearer" = [])),
    responses(
        (status = 201, description = "Simulated and stored; `Location` names the new session", body = StoredSession,
            headers(("Location" = String, description = "URL of the session"))),
        (status = 200, description = "An identical session was already stored (or the same request's job had stored it): that session", body = StoredSession),
        (status = 202, description = "Not finished within the server's job wait (`--job-wait`): the job, which `Location` names; `GET` it until `done`, then follow its `result_url`. The same request meanwhile answers the same job", body = JobBody,
            headers(("Location" = String, description = "URL of the job"), ("Retry-After" = u32, description = "Seconds before looking again"))),
        (status = 400, description = "Malformed JSON (a key twice in one object included, named), or a body that could not be read", body = ProblemBody, content_type = "application/problem+json"),
        (status = 422, description = "An unknown scenario, an invalid field (named) or duration, or the simulation failed", body = ProblemBody, content_type = "application/problem+json"),
        (status = 409, description = "The job was cancelled (`DELETE /api/v1/jobs/{id}`) before it finished", body = ProblemBody, content_type = "application/problem+json"),
        (status = 503, description = "The job ran over the server's job time limit (stopped, nothing stored), too many jobs wait already (with `Retry-After`), or the data base cannot be reached", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn run_simulation(
    _: WriteAccess,
    State(st): State<AppState>,
    deadline: Option<Extension<RequestDeadline>>,
    Json(req): Json<SimulationRequest>,
) -> Result<Response, Problem> {
    let request = JobRequest::Simulation {
        scenario: Box::new(scenario_of(&req)?),
        duration: req.duration,
    };
    match jobs::submit(&st, &request, deadline.map(|e| e.0)).await? {
        Waited::Pending(job) => Ok(jobs::accepted(&job)),
        Waited::Finished { job, new } => match job.result {
            Some(JobResult::Session { id, created }) => {
                let session = st.store().get_session(id).await?;
                let out = IngestOutcome {
                    session_id: id,
                    // A repeated request finds the session its job stored: 200.
                    created: created && new,
                    skill_ids: session.skill_ids,
                    matched_skill_ids: session.matched_skill_ids,
                };
                StoredSession::reply(&st, out).await
            }
            _ => Err(jobs::problem_of(&job).unwrap_or_else(|| {
                Problem::internal(&format!(
                    "simulation job {} ended without a session",
                    job.id
                ))
            })),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dfs_core::scenario::Phase;

    #[test]
    fn the_documented_scenario_schema_is_dfs_cores_scenario_type() {
        let doc = serde_json::to_value(crate::http::openapi(false)).unwrap();
        let schemas = &doc["components"]["schemas"];
        let object = &schemas["ScenarioObject"];
        assert_eq!(
            object["properties"]["shape"]["$ref"], "#/components/schemas/ShapeKind",
            "{object}"
        );
        assert_eq!(
            schemas["ShapeKind"]["enum"],
            serde_json::json!(["sphere", "box", "cylinder"])
        );
        let task = &schemas["Task"];
        assert_eq!(
            task["properties"]["phase"]["$ref"],
            "#/components/schemas/Phase"
        );
        let phases: Vec<&str> = Phase::ALL.iter().map(|p| p.name()).collect();
        assert_eq!(schemas["Phase"]["enum"], serde_json::json!(phases));
        assert_eq!(
            schemas["GraspStyle"]["enum"],
            serde_json::json!(["auto", "pinch", "power"])
        );
        // Every field a scenario file takes is documented, and the schema's bounds are the
        // code's.
        for name in Scenario::BUILTINS {
            let s = serde_json::to_value(Scenario::builtin(name, 3).unwrap()).unwrap();
            // A scene of several objects: its objects' fields as the one object's.
            let one = if s["object"].is_null() {
                &s["objects"][0]
            } else {
                &s["object"]
            };
            for (field, schema) in [
                (&s, &schemas["Scenario"]),
                (one, object),
                (&s["tasks"][0], task),
            ] {
                for key in field.as_object().unwrap().keys() {
                    assert!(
                        schema["properties"].get(key).is_some(),
                        "{name}: {key} is not documented: {schema}"
                    );
                }
            }
        }
        let (lo, hi) = dfs_core::spec::MU_RANGE;
        assert_eq!(object["properties"]["mu"]["minimum"], lo);
        assert_eq!(object["properties"]["mu"]["maximum"], hi);
        let (lo, hi) = dfs_core::spec::MU_TORSION_RANGE;
        assert_eq!(object["properties"]["mu_torsion"]["minimum"], lo);
        assert_eq!(object["properties"]["mu_torsion"]["maximum"], hi);
        let duration = &task["properties"]["duration"];
        assert_eq!(duration["minimum"], dfs_core::scenario::MIN_TASK_S);
        assert_eq!(duration["maximum"], dfs_core::scenario::MAX_TASK_S);
        let required = |schema: &serde_json::Value| -> Vec<String> {
            serde_json::from_value(schema["required"].clone()).unwrap()
        };
        assert_eq!(required(object), ["shape", "mass", "mu"]);
        assert_eq!(required(task), ["phase", "duration"]);
        // `object` or `objects` (a scene of several), exactly one: neither is required alone.
        assert_eq!(required(&schemas["Scenario"]), ["name", "tasks"]);
        for key in ["object", "objects", "target", "vary_reach"] {
            assert!(
                schemas["Scenario"]["properties"].get(key).is_some(),
                "{key}"
            );
        }
    }

    #[test]
    fn an_unknown_shape_in_a_scenario_is_refused_naming_the_field() {
        let req: SimulationRequest = serde_json::from_value(serde_json::json!({
            "scenario": {"name": "x", "object": {"shape": "torus", "mass": 1.0, "mu": 0.5,
                "radius": 0.04}, "tasks": [{"phase": "lift", "duration": 1}]}
        }))
        .unwrap();
        let p = scenario_of(&req).unwrap_err();
        assert_eq!(p.status.as_u16(), 422);
        assert!(
            p.detail.contains("scenario.object.shape")
                && p.detail.contains("unknown shape \"torus\""),
            "{}",
            p.detail
        );
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
