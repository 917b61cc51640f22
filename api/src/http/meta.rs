//! `GET /healthz` and `GET /api/v1/openapi.json`: liveness (the database answers) and the
//! OpenAPI 3.1 document generated from the handlers.

use axum::extract::State;
use axum::http::{header, HeaderValue};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{Problem, ProblemBody};
use super::state::AppState;

/// The answer of `GET /healthz`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Health {
    /// `ok`.
    pub status: String,
    /// Skills in the data base.
    pub skills: usize,
    /// Version of the server.
    pub version: String,
}

/// Routes at the root (`/healthz`).
pub fn root_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(healthz))
}

/// Routes under `/api/v1` (`/openapi.json`).
pub fn api_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(openapi_json))
}

/// Liveness: the server runs and its database answers.
#[utoipa::path(get, path = "/healthz", tag = "meta",
    responses(
        (status = 200, description = "Healthy", body = Health),
        (status = 503, description = "The database does not answer (or the server is stopping)", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn healthz(State(st): State<AppState>) -> Result<axum::Json<Health>, Problem> {
    st.store().list_sessions(1, None).await.map_err(|e| {
        tracing::warn!(error = %e, "health check failed");
        Problem::unavailable("the database does not answer")
    })?;
    Ok(axum::Json(Health {
        status: "ok".into(),
        skills: st.store().skill_count(),
        version: env!("CARGO_PKG_VERSION").into(),
    }))
}

/// This API's OpenAPI 3.1 document.
#[utoipa::path(get, path = "/openapi.json", tag = "meta",
    responses((status = 200, description = "The OpenAPI 3.1 document", body = Object)))]
async fn openapi_json(State(st): State<AppState>) -> Response {
    let mut r = st.openapi_json().into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r
}
