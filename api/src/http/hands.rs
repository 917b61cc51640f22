//! `/api/v1/hands`: the robot hands replays run on. The built-in hands (`glove10`, `allegro`,
//! `barrett`, `inspire`, `gripper`) come from the binary; uploaded hands (a URDF plus a hand
//! spec, validated by building the model before anything is stored) from the data base. A
//! hand's id in URLs is its name, unique among both kinds. Hands are never changed or deleted,
//! so stored replays keep naming hands that exist.

use axum::body::Body;
use axum::extract::State;
use axum::http::{header, HeaderValue};
use axum::response::Response;
use dfs_core::hand::HandSpec;
use serde::{Deserialize, Serialize};
use services::store::{Hand, HandSummary};
use utoipa::openapi::schema::Schema;
use utoipa::openapi::RefOr;
use utoipa::{PartialSchema, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::created;
use super::error::{Problem, ProblemBody};
use super::extract::{field_error, Json, Name, WriteAccess};
use super::state::AppState;

/// Largest URDF text an upload may hold, bytes (the built-in hands' are under 20 kB).
pub const MAX_URDF_BYTES: usize = 4 << 20;

/// Media type of a URDF download.
pub const URDF_MEDIA_TYPE: &str = "application/xml";

/// A robot hand as listed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct HandSummaryBody {
    /// Name, also the hand's id in URLs.
    pub name: String,
    /// Built into the server (not uploaded).
    pub builtin: bool,
    /// Fingertip names, the thumb first.
    pub fingers: Vec<String>,
    /// Number of DOFs (independent joints).
    pub dof: usize,
    /// DOF names.
    pub dof_names: Vec<String>,
    /// Smallest and largest joint torque limit, N·m (N for prismatic DOFs).
    #[schema(min_items = 2, max_items = 2)]
    pub torque_limit: [f64; 2],
    /// When an uploaded hand was stored (UTC, RFC 3339); `null` for a built-in hand.
    pub created_at: Option<String>,
}

impl From<HandSummary> for HandSummaryBody {
    fn from(h: HandSummary) -> Self {
        HandSummaryBody {
            name: h.name,
            builtin: h.builtin,
            fingers: h.fingers,
            dof: h.dof,
            dof_names: h.dof_names,
            torque_limit: h.torque_limit,
            created_at: h.created_at,
        }
    }
}

/// Every hand.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct HandList {
    /// The built-in hands in a fixed order, then the uploaded ones in upload order.
    pub items: Vec<HandSummaryBody>,
}

/// One hand with its spec.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct HandBody {
    /// What the list shows.
    #[serde(flatten)]
    pub summary: HandSummaryBody,
    /// The hand spec; `null` for `glove10`, which is built in code without a URDF.
    #[schema(value_type = Option<HandSpec>)]
    pub spec: Option<serde_json::Value>,
    /// Where to download the URDF text; `null` for `glove10`.
    pub urdf_url: Option<String>,
}

impl HandBody {
    fn of(h: Hand) -> Result<Self, Problem> {
        let urdf_url = h
            .urdf
            .as_ref()
            .map(|_| format!("/api/v1/hands/{}/urdf", h.summary.name));
        let spec = match h.spec {
            Some(s) => Some(serde_json::to_value(s).map_err(|e| Problem::internal(&e))?),
            None => None,
        };
        Ok(HandBody {
            summary: h.summary.into(),
            spec,
            urdf_url,
        })
    }
}

/// An upload: a hand spec and its URDF text.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(
    remote = "Self",
    deny_unknown_fields,
    expecting = "a hand upload: a JSON object {\"spec\": {...}, \"urdf\": \"<robot ...>\"}"
)]
pub struct HandUpload {
    /// The hand spec (its `urdf` file name may be omitted).
    #[schema(schema_with = upload_spec_schema)]
    pub spec: serde_json::Value,
    /// The URDF text (`<robot …>…</robot>`), at most 4 MiB.
    pub urdf: String,
}

// Only a JSON object: serde would also take the fields in a JSON array.
dfs_core::object_only!(
    HandUpload,
    "a hand upload: a JSON object {\"spec\": {...}, \"urdf\": \"<robot ...>\"}"
);

/// The schema of an upload's spec: dfs-core's [`HandSpec`] with the rules of an upload on top.
/// Its `urdf` file name may be left out (the URDF text travels beside the spec; the file is
/// stored as `NAME.urdf`), and its name is a hand's id in URLs and a file name, so it must
/// match the store's rule ([`services::store::MAX_HAND_NAME`] characters at most).
fn upload_spec_schema() -> impl Into<RefOr<Schema>> {
    let mut schema = <HandSpec as PartialSchema>::schema();
    if let RefOr::T(Schema::Object(spec)) = &mut schema {
        spec.required.retain(|field| field != "urdf");
        if let Some(RefOr::T(Schema::Object(name))) = spec.properties.get_mut("name") {
            name.pattern = Some(HAND_NAME_PATTERN.to_owned());
        }
    }
    schema
}

/// A hand name an upload may take: 1 to [`services::store::MAX_HAND_NAME`] (64) of
/// `A-Z a-z 0-9 . _ -`, starting with a letter or a digit.
const HAND_NAME_PATTERN: &str = "^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$";

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_hands, upload_hand))
        .routes(routes!(get_hand))
        .routes(routes!(get_hand_urdf))
}

/// The spec of an upload; errors name the field (`spec.fingertips[0].radius: ...`).
fn spec_of(upload: &HandUpload) -> Result<HandSpec, Problem> {
    let mut spec = upload.spec.clone();
    let Some(obj) = spec.as_object_mut() else {
        return Err(Problem::unprocessable("spec: expected a hand spec object"));
    };
    if !obj.contains_key("urdf") {
        let name = obj.get("name").and_then(|n| n.as_str()).unwrap_or("hand");
        obj.insert("urdf".into(), format!("{name}.urdf").into());
    }
    serde_path_to_error::deserialize(spec)
        .map_err(|e| Problem::unprocessable(field_error("spec", &e)))
}

/// Every hand: built-in and uploaded.
#[utoipa::path(get, path = "/hands", tag = "hands",
    responses((status = 200, description = "The built-in hands, then the uploaded ones", body = HandList)))]
async fn list_hands(State(st): State<AppState>) -> Result<axum::Json<HandList>, Problem> {
    let items = st.store().list_hands().await?;
    Ok(axum::Json(HandList {
        items: items.into_iter().map(HandSummaryBody::from).collect(),
    }))
}

/// One hand with its spec.
#[utoipa::path(get, path = "/hands/{id}", tag = "hands",
    params(("id" = String, Path, description = "The hand's name")),
    responses(
        (status = 200, description = "The hand", body = HandBody),
        (status = 400, description = "The name is not valid UTF-8 once percent-decoded", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No hand with this name", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn get_hand(
    State(st): State<AppState>,
    Name(name): Name,
) -> Result<axum::Json<HandBody>, Problem> {
    Ok(axum::Json(HandBody::of(st.store().get_hand(&name).await?)?))
}

/// The hand's URDF text.
#[utoipa::path(get, path = "/hands/{id}/urdf", tag = "hands",
    params(("id" = String, Path, description = "The hand's name")),
    responses(
        (status = 200, description = "The URDF", content_type = "application/xml", body = String),
        (status = 400, description = "The name is not valid UTF-8 once percent-decoded", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No hand with this name, or glove10 (built in code, no URDF)", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn get_hand_urdf(State(st): State<AppState>, Name(name): Name) -> Result<Response, Problem> {
    let hand = st.store().get_hand(&name).await?;
    let Some(urdf) = hand.urdf else {
        return Err(Problem::not_found(format!(
            "hand {name:?} is built in code and has no URDF"
        )));
    };
    let mut r = Response::new(Body::from(urdf));
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(URDF_MEDIA_TYPE),
    );
    Ok(r)
}

/// Uploads a robot hand: a hand spec and its URDF. The model is built first; a URDF or spec it
/// cannot be built from is refused naming the problem, and nothing is stored.
#[utoipa::path(post, path = "/hands", tag = "hands",
    request_body(content = HandUpload, content_type = "application/json",
        example = json!({"spec": {"name": "my-gripper", "torque_limit": 40.0,
            "fingertips": [{"name": "thumb", "link": "right_finger", "offset": [0, 0.01, 0.085], "radius": 0.01},
                           {"name": "finger", "link": "left_finger", "offset": [0, -0.01, 0.085], "radius": 0.01}]},
            "urdf": "<robot name=\"g\">…</robot>"})),
    security((), ("bearer" = [])),
    responses(
        (status = 201, description = "Stored; `Location` names the new hand", body = HandBody,
            headers(("Location" = String, description = "URL of the hand"))),
        (status = 400, description = "Malformed JSON (a key twice in one object included, named), or a body that could not be read", body = ProblemBody, content_type = "application/problem+json"),
        (status = 409, description = "The name is a built-in hand's or a stored hand's", body = ProblemBody, content_type = "application/problem+json"),
        (status = 422, description = "The URDF or spec is invalid, naming the problem (does not parse, a kinematic loop, several roots, an unknown fingertip link, a negative mass or radius, a bad field); nothing was stored", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn upload_hand(
    _: WriteAccess,
    State(st): State<AppState>,
    Json(upload): Json<HandUpload>,
) -> Result<Response, Problem> {
    if upload.urdf.len() > MAX_URDF_BYTES {
        return Err(Problem::unprocessable(format!(
            "urdf: {} bytes, more than the {MAX_URDF_BYTES} a hand may have",
            upload.urdf.len()
        )));
    }
    let spec = spec_of(&upload)?;
    let hand = st.store().put_hand(spec, upload.urdf).await?;
    let name = hand.summary.name.clone();
    tracing::info!(hand = %name, dof = hand.summary.dof, "hand uploaded");
    Ok(created(
        HandBody::of(hand)?,
        &format!("/api/v1/hands/{name}"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dfs_core::hand::{builtin_spec, BUILTIN_HANDS};

    #[test]
    fn the_documented_hand_spec_is_dfs_cores_and_an_upload_may_leave_out_the_urdf() {
        let doc = serde_json::to_value(crate::http::openapi(false)).unwrap();
        let spec = &doc["components"]["schemas"]["HandSpec"];
        let upload = &doc["components"]["schemas"]["HandUpload"]["properties"]["spec"];
        for name in BUILTIN_HANDS {
            let Some((builtin, _)) = builtin_spec(name) else {
                continue;
            };
            let v = serde_json::to_value(&builtin).unwrap();
            for key in v.as_object().unwrap().keys() {
                assert!(
                    spec["properties"].get(key).is_some()
                        && upload["properties"].get(key).is_some(),
                    "{name}: {key} is not documented"
                );
            }
        }
        let required = |s: &serde_json::Value| -> Vec<String> {
            serde_json::from_value(s["required"].clone()).unwrap()
        };
        assert!(required(spec).iter().any(|f| f == "urdf"));
        assert!(!required(upload).iter().any(|f| f == "urdf"), "{upload}");
        assert_eq!(upload["properties"]["name"]["pattern"], HAND_NAME_PATTERN);
        assert_eq!(
            spec["properties"]["fingertips"]["maxItems"],
            dfs_core::hand::MAX_TIPS
        );
        // The pattern is the store's rule.
        assert_eq!(
            HAND_NAME_PATTERN,
            format!(
                "^[A-Za-z0-9][A-Za-z0-9._-]{{0,{}}}$",
                services::store::MAX_HAND_NAME - 1
            )
        );
    }

    #[test]
    fn an_upload_without_a_urdf_file_name_gets_one_and_bad_fields_are_named() {
        let (spec, urdf) = builtin_spec("gripper").unwrap();
        let mut v = serde_json::to_value(&spec).unwrap();
        v.as_object_mut().unwrap().remove("urdf");
        v["name"] = "g2".into();
        let up = HandUpload {
            spec: v.clone(),
            urdf: urdf.into(),
        };
        assert_eq!(spec_of(&up).unwrap().urdf, "g2.urdf");
        v["fingertips"][1]["radius"] = "big".into();
        let p = spec_of(&HandUpload { spec: v, ..up }).unwrap_err();
        assert_eq!(p.status, axum::http::StatusCode::UNPROCESSABLE_ENTITY);
        assert!(
            p.detail.contains("spec.fingertips[1].radius"),
            "{}",
            p.detail
        );
    }
}
