//! `/api/v1/skills`: filtered and paginated lists, one skill (served from the hot-skill cache),
//! similar skills, delete.

use axum::body::Body;
use axum::extract::State;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use dfs_core::contact::ContactModel;
use dfs_core::names::Named;
use dfs_core::scenario::Phase;
use serde::{Deserialize, Serialize};
use services::store::{ObjectShape, SkillRecord, FEATURE_DIM};
use utoipa::openapi::schema::{ObjectBuilder, Schema, Type};
use utoipa::openapi::RefOr;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{Problem, ProblemBody};
use super::extract::{Id, Query, WriteAccess};
use super::state::AppState;
use crate::filters::SkillFilters;

/// The schema of a stored object shape ([`ObjectShape`], a services type without a schema of
/// its own): its names.
pub(crate) fn object_shape_schema() -> impl Into<RefOr<Schema>> {
    ObjectBuilder::new()
        .schema_type(Type::String)
        .enum_values(Some(ObjectShape::names()))
}

/// A stored skill: the hand-independent parameters of one grasp, in the object frame B.
///
/// The store's [`SkillRecord`] with its schema: services' types have none, so the API keeps this
/// body type beside it (fields typed alike, [`From`] between them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SkillBody {
    /// Skill id.
    pub id: i64,
    /// Id of the session the skill was found in.
    pub session_id: i64,
    /// Object shape: sphere, box, cylinder, or unknown (a session stored before sessions had
    /// to name their object).
    #[schema(schema_with = object_shape_schema)]
    pub object_shape: ObjectShape,
    /// The name of the object the skill grasped, when its session names its objects (a scene
    /// of several objects); absent for a session's one unnamed object.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_name: Option<String>,
    /// Object mass, kg.
    pub object_mass: f64,
    /// Coulomb friction coefficient.
    pub mu: f64,
    /// Number of fingertip contacts.
    pub contact_count: i64,
    /// Contact model.
    pub contact_model: ContactModel,
    /// Grasp type label, e.g. precision-2vf.
    pub grasp_type: String,
    /// Ferrari-Canny ε grasp quality.
    pub quality: f64,
    /// Volume of the grasp wrench space.
    pub volume: f64,
    /// Duration of the skill, s.
    pub duration_s: f64,
    /// Start of the skill, ns since the session's start.
    pub start_ns: i64,
    /// End of the skill, ns since the session's start.
    pub end_ns: i64,
    /// Time spent in each phase, one entry per phase name in alphabetical order, summed when
    /// a phase occurs more than once (the `phase_min_s` / `phase_max_s` filters compare these
    /// sums, unrounded). The phases in time order are in the full parameters.
    pub phase_durations: Vec<PhaseDuration>,
    /// Feature vector for similarity search (16 values).
    #[schema(min_items = 16, max_items = 16)]
    pub feature: Vec<f32>,
    /// The full hand-independent parameters, as `icms segment --json` prints them.
    #[schema(value_type = Object)]
    pub params: serde_json::Value,
    /// The approach template early recognition compares (29 values: the object, then the
    /// hand's aperture, spread, elevation and pointing at 20, 12, 8, 5 and 3 cm from the
    /// object's surface, then the fingertips touching at contact onset, the grip (the hand's
    /// normal force on the object per its weight 0.8 s after the first touch) and the number of
    /// objects in the scene; `null` where the reach did not show one, and for the last two in a
    /// template computed before they were added: run `icms reprocess`). Absent when not
    /// computed (run `icms reprocess`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<Vec<Option<f32>>>,
    /// The stored skill this one matched when it was stored (on-line learning linked it);
    /// absent for a skill stored as new.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matched_skill_id: Option<i64>,
    /// Version of the segmentation that made the skill (its session's): `icms reprocess`
    /// segments sessions of older versions again. 0: stored before versions were recorded.
    pub segmentation_version: u32,
    /// When the skill was stored (UTC, RFC 3339).
    pub created_at: String,
}

/// The time a skill spent in one phase.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PhaseDuration {
    /// The phase.
    pub phase: Phase,
    /// Its duration, s, rounded to the recording's 1 ms tick ([`TICK_S`]).
    pub seconds: f64,
}

/// The recording's clock: sessions are recorded tick by tick at 1 kHz, so a phase boundary
/// is known to 1 ms and durations are given to that resolution (the store keeps the sums of
/// the boundaries' nanosecond differences, which carry sub-tick noise from the log times).
pub const TICK_S: f64 = 1e-3;

/// `x` rounded to a multiple of `step`.
fn round_to(x: f64, step: f64) -> f64 {
    // Dividing by the rounded count (not multiplying by `step`) keeps 0.8 as 0.8, not
    // 0.8000000000000002.
    (x / step).round() / (1.0 / step)
}

impl PhaseDuration {
    /// `seconds` in `phase`, rounded to [`TICK_S`].
    pub fn new(phase: Phase, seconds: f64) -> Self {
        PhaseDuration {
            phase,
            seconds: round_to(seconds, TICK_S),
        }
    }
}

impl From<SkillRecord> for SkillBody {
    fn from(s: SkillRecord) -> Self {
        debug_assert_eq!(s.feature.len(), FEATURE_DIM);
        SkillBody {
            id: s.id,
            session_id: s.session_id,
            object_shape: s.object_shape,
            object_name: s.object_name,
            object_mass: s.object_mass,
            mu: s.mu,
            contact_count: s.contact_count,
            contact_model: s.contact_model,
            grasp_type: s.grasp_type,
            quality: s.quality,
            volume: s.volume,
            duration_s: s.duration_s,
            start_ns: s.start_ns,
            end_ns: s.end_ns,
            phase_durations: s
                .phase_durations
                .into_iter()
                .map(|(phase, seconds)| PhaseDuration::new(phase, seconds))
                .collect(),
            feature: s.feature,
            params: s.params,
            approach: s.approach,
            matched_skill_id: s.matched_skill_id,
            segmentation_version: s.segmentation_version,
            created_at: s.created_at,
        }
    }
}

/// One page of skills.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SkillPage {
    /// The skills of this page, in the requested order.
    pub items: Vec<SkillBody>,
    /// Pass as `cursor` (with the same filters and sort) for the next page; `null` on the last.
    pub next_cursor: Option<String>,
}

/// A skill in brief: what a list row shows (about 300 bytes against the full skill's 8 kB,
/// most of it the parameters). `GET /skills/summaries` takes the same filters, sort and
/// pages as `GET /skills`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SkillSummary {
    /// Skill id.
    pub id: i64,
    /// Id of the session the skill was found in.
    pub session_id: i64,
    /// Object shape.
    #[schema(schema_with = object_shape_schema)]
    pub object_shape: ObjectShape,
    /// The name of the object grasped, in a scene of several; absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_name: Option<String>,
    /// Object mass, kg.
    pub object_mass: f64,
    /// Coulomb friction coefficient.
    pub mu: f64,
    /// Number of fingertip contacts.
    pub contact_count: i64,
    /// Contact model.
    pub contact_model: ContactModel,
    /// Grasp type label, e.g. precision-2vf.
    pub grasp_type: String,
    /// Ferrari-Canny ε grasp quality.
    pub quality: f64,
    /// Duration of the skill, s.
    pub duration_s: f64,
    /// When the skill was stored (UTC, RFC 3339).
    pub created_at: String,
}

impl From<SkillRecord> for SkillSummary {
    fn from(s: SkillRecord) -> Self {
        SkillSummary {
            id: s.id,
            session_id: s.session_id,
            object_shape: s.object_shape,
            object_name: s.object_name,
            object_mass: s.object_mass,
            mu: s.mu,
            contact_count: s.contact_count,
            contact_model: s.contact_model,
            grasp_type: s.grasp_type,
            quality: s.quality,
            duration_s: s.duration_s,
            created_at: s.created_at,
        }
    }
}

/// One page of skill summaries.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SkillSummaryPage {
    /// The skills of this page, in the requested order.
    pub items: Vec<SkillSummary>,
    /// Pass as `cursor` (with the same filters and sort) for the next page; `null` on the last.
    pub next_cursor: Option<String>,
}

/// Parameters of `GET /skills/{id}/similar`.
#[derive(Debug, Clone, Default, Deserialize, IntoParams)]
#[serde(default, deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct SimilarParams {
    /// How many similar skills, 1 to 1000. Default 10.
    #[param(minimum = 1, maximum = 1000)]
    pub k: Option<u32>,
}

/// A skill near another in feature space.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Neighbour {
    /// Id of the similar skill.
    pub skill_id: i64,
    /// Euclidean distance between the two feature vectors.
    pub distance: f32,
    /// The similar skill in brief, so a client needs no request per neighbour.
    pub skill: SkillSummary,
}

/// The skills most similar to one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SimilarSkills {
    /// The skill asked about.
    pub similar_to: i64,
    /// Nearest first (ties by id); the skill itself is left out.
    pub items: Vec<Neighbour>,
}

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_skills))
        .routes(routes!(list_skill_summaries))
        .routes(routes!(get_skill, delete_skill))
        .routes(routes!(similar_skills))
}

/// Skills matching every given filter, one page at a time.
#[utoipa::path(get, path = "/skills", tag = "skills",
    params(SkillFilters),
    responses(
        (status = 200, description = "One page of matching skills", body = SkillPage),
        (status = 400, description = "An invalid filter, sort, limit or cursor, or an unknown parameter", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn list_skills(
    State(st): State<AppState>,
    Query(filters): Query<SkillFilters>,
) -> Result<axum::Json<SkillPage>, Problem> {
    let q = filters.to_query()?;
    let page = st.store().query_skills(&q).await?;
    Ok(axum::Json(SkillPage {
        items: page.items.into_iter().map(SkillBody::from).collect(),
        next_cursor: page.next_cursor,
    }))
}

/// Skills matching every given filter, one page at a time, in brief: the filters, sort and
/// cursor of `GET /skills`, each item a [`SkillSummary`].
#[utoipa::path(get, path = "/skills/summaries", tag = "skills",
    params(SkillFilters),
    responses(
        (status = 200, description = "One page of matching skills, in brief", body = SkillSummaryPage),
        (status = 400, description = "An invalid filter, sort, limit or cursor, or an unknown parameter", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn list_skill_summaries(
    State(st): State<AppState>,
    Query(filters): Query<SkillFilters>,
) -> Result<axum::Json<SkillSummaryPage>, Problem> {
    let q = filters.to_query()?;
    let page = st.store().query_skills(&q).await?;
    Ok(axum::Json(SkillSummaryPage {
        items: page.items.into_iter().map(SkillSummary::from).collect(),
        next_cursor: page.next_cursor,
    }))
}

fn json_response(json: Bytes) -> Response {
    let mut r = Response::new(Body::from(json));
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r
}

/// One skill.
#[utoipa::path(get, path = "/skills/{id}", tag = "skills",
    params(("id" = i64, Path, description = "Skill id")),
    responses(
        (status = 200, description = "The skill", body = SkillBody),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No skill with this id", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn get_skill(State(st): State<AppState>, Id(id): Id) -> Result<Response, Problem> {
    let epoch = match st.cache().get(id) {
        Ok(json) => return Ok(json_response(json)),
        Err(epoch) => epoch,
    };
    let skill = SkillBody::from(st.store().get_skill(id).await?);
    let json = Bytes::from(serde_json::to_vec(&skill).map_err(|e| Problem::internal(&e))?);
    st.cache().insert(id, json.clone(), epoch);
    Ok(json_response(json))
}

/// Deletes one skill with its replays (its session stays).
#[utoipa::path(delete, path = "/skills/{id}", tag = "skills",
    params(("id" = i64, Path, description = "Skill id")),
    security((), ("bearer" = [])),
    responses(
        (status = 204, description = "Deleted, with its replays and their MCAP files"),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No skill with this id", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn delete_skill(
    _: WriteAccess,
    State(st): State<AppState>,
    Id(id): Id,
) -> Result<StatusCode, Problem> {
    let result = st.store().delete_skill(id).await;
    st.cache().remove(&[id]);
    result?;
    tracing::info!(skill_id = id, "deleted skill");
    Ok(StatusCode::NO_CONTENT)
}

/// The `k` skills nearest to one in feature space.
#[utoipa::path(get, path = "/skills/{id}/similar", tag = "skills",
    params(("id" = i64, Path, description = "Skill id"), SimilarParams),
    responses(
        (status = 200, description = "The nearest skills, nearest first", body = SimilarSkills),
        (status = 400, description = "The id is not an integer, k is out of range, or an unknown parameter", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No skill with this id", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn similar_skills(
    State(st): State<AppState>,
    Id(id): Id,
    Query(p): Query<SimilarParams>,
) -> Result<impl IntoResponse, Problem> {
    let k = p.k.unwrap_or(10);
    if !(1..=1000).contains(&k) {
        return Err(Problem::bad_request(format!("k {k} is outside 1..=1000")));
    }
    let near = st.store().nearest_to_skill(id, k as usize)?;
    let ids: Vec<i64> = near.iter().map(|&(skill_id, _)| skill_id).collect();
    // One query for every neighbour; one deleted since the index was read is left out.
    let skills = st.store().get_skills(&ids).await?;
    let distance: std::collections::HashMap<i64, f32> = near.into_iter().collect();
    let items = skills
        .into_iter()
        .map(|s| Neighbour {
            skill_id: s.id,
            distance: distance[&s.id],
            skill: SkillSummary::from(s),
        })
        .collect();
    Ok(axum::Json(SimilarSkills {
        similar_to: id,
        items,
    }))
}
