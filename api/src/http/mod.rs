//! The HTTP API: one router per resource over one [`AppState`], merged by [`app`] with the
//! layers every route gets (time limit, body limit, lingering close, problem+json for every error, optional
//! CORS, request tracing), and the OpenAPI 3.1 document generated from the same handlers, so
//! the document lists exactly the routes the router serves.
//!
//! | route | |
//! |---|---|
//! | `POST /api/v1/sessions` | upload an MCAP session (201, or 200 if already stored) |
//! | `GET /api/v1/sessions`, `GET /api/v1/sessions/{id}` | list (paginated), get |
//! | `GET /api/v1/sessions/{id}/mcap`, `DELETE /api/v1/sessions/{id}` | download, delete |
//! | `POST /api/v1/simulations` | simulate a scenario server-side and store it (a job: 201, or 202 with the job) |
//! | `GET /api/v1/jobs`, `GET /api/v1/jobs/{id}`, `DELETE /api/v1/jobs/{id}` | simulations and replays as jobs: list, follow, cancel |
//! | `GET /api/v1/skills` | every store filter, sort, `limit`, `cursor` |
//! | `GET /api/v1/skills/{id}`, `GET /api/v1/skills/{id}/similar`, `DELETE /api/v1/skills/{id}` | |
//! | `GET /api/v1/hands`, `POST /api/v1/hands` | built-in and uploaded hands; upload URDF + spec |
//! | `GET /api/v1/hands/{id}`, `GET /api/v1/hands/{id}/urdf` | one hand (id = name), its URDF |
//! | `POST /api/v1/skills/{id}/replays`, `GET /api/v1/skills/{id}/replays` | replay on a hand, list |
//! | `GET /api/v1/replays/{id}`, `GET /api/v1/replays/{id}/mcap` | one replay's report, its MCAP |
//! | `GET /api/v1/live` | a live glove session (WebSocket; protocol in `docs/live.md`) |
//! | `GET /api/v1/skills/summaries`, `GET /api/v1/skills/{id}/forces` | skills in brief, a skill's contact forces |
//! | `GET /api/v1/hands/{id}/geometry`, `GET /api/v1/replays/{id}/frames` | what the web page draws in 3D |
//! | `GET /healthz`, `GET /api/v1/openapi.json` | liveness, this API's document |
//! | `GET /`, `GET /docs`, `GET /assets/...` | the web page ([`web`]), not in the document |

pub mod cache;
pub mod error;
pub mod extract;
pub mod forces;
pub mod frames;
pub mod hands;
pub mod jobs;
mod linger;
pub mod live;
pub mod meta;
pub mod replays;
pub mod server;
pub mod sessions;
pub mod simulations;
pub mod skills;
pub mod state;
pub mod web;

use std::time::Duration;

use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{header, HeaderValue, Method};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::Router;
use bytes::Bytes;
use dfs_core::contact::ContactModel;
use dfs_core::names::Named;
use dfs_core::scenario::{Phase, Scenario};
use services::store::ObjectShape;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::trace::TraceLayer;
use utoipa::openapi::schema::{ObjectBuilder, Type};
use utoipa::openapi::security::{Http, HttpAuthScheme, SecurityScheme};
use utoipa::openapi::{ContentBuilder, InfoBuilder, OpenApi, Ref, RefOr, ResponseBuilder};
use utoipa::{PartialSchema, ToSchema};
use utoipa_axum::router::OpenApiRouter;

pub use error::{Problem, ProblemBody};
pub use state::{AppState, StateConfig};

/// Prefix of every resource route.
pub const API_PREFIX: &str = "/api/v1";

/// Settings of the layers around the routes.
#[derive(Debug, Clone)]
pub struct LayerConfig {
    /// Time limit of one request, body included.
    pub request_timeout: Duration,
    /// Origins allowed to call the API from a browser; empty: no CORS headers at all.
    pub cors_origins: Vec<HeaderValue>,
}

/// Every route with its OpenAPI description, before state and layers.
pub fn routes() -> OpenApiRouter<AppState> {
    let api = OpenApiRouter::new()
        .merge(sessions::router())
        .merge(skills::router())
        .merge(forces::router())
        .merge(frames::router())
        .merge(simulations::router())
        .merge(hands::router())
        .merge(replays::router())
        .merge(jobs::router())
        .merge(live::router())
        .merge(meta::api_router());
    OpenApiRouter::new()
        .nest(API_PREFIX, api)
        .merge(meta::root_router())
}

/// The OpenAPI document of [`routes`], with the info, tags and the bearer scheme; when
/// `writes_need_token` is false the write operations carry no security requirement, as the
/// server then accepts them without one.
pub fn openapi(writes_need_token: bool) -> OpenApi {
    let (_, api) = routes().split_for_parts();
    finish_openapi(api, writes_need_token)
}

fn finish_openapi(mut api: OpenApi, writes_need_token: bool) -> OpenApi {
    api.info = InfoBuilder::new()
        .title("ICMS skill service")
        .version(env!("CARGO_PKG_VERSION"))
        .description(Some(
            "Record grasp sessions (MCAP), simulate scenarios server-side, query and browse the \
             skill data base, upload robot hands (URDF + hand spec) and replay skills on them. \
             Errors are application/problem+json (RFC 9457); a request that does not parse as \
             HTTP is refused by the HTTP layer with its status and no body. A request over the \
             server's time limit is answered 503. Simulations and replays are jobs that any \
             server or `icms worker` on the same data base runs: a request not finished within \
             the server's job wait is answered 202 with the job (GET /api/v1/jobs/{id}). \
             Operations that take query parameters refuse \
             unknown ones (400, naming them); the others ignore a query string. A JSON body \
             with a key twice in one object is refused (400, naming the key). Live glove \
             sessions are a WebSocket, GET /api/v1/live: a JSON start message, then binary \
             icms.live.Sample protobuf frames (schema at GET /api/v1/live/schema) each answered \
             by an icms.live.Feedback frame, JSON events, and end; the DFS steps at 1 kHz of \
             the samples' time, interpolating between samples; the session is recorded and \
             stored as it ends. With assist suggest or apply (and a robot hand) in the start \
             message, the assistant recognises the stored skill being performed early \
             (recognised / unknown events) and applies it on the robot hand (applying, robot, \
             robot_report events) (docs/live.md in the repository).",
        ))
        .build();
    let components = api.components.get_or_insert_with(Default::default);
    // The scenario object (dfs-core's `Scenario`) is referenced from a hand-written schema (a
    // name or an object), so the derive does not collect it: add it and the schemas it
    // refers to.
    let mut scenario = vec![(
        <Scenario as ToSchema>::name().into_owned(),
        <Scenario as PartialSchema>::schema(),
    )];
    <Scenario as ToSchema>::schemas(&mut scenario);
    components.schemas.extend(scenario);
    if writes_need_token {
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(Http::new(HttpAuthScheme::Bearer)),
        );
    }
    document_filter_values(&mut api);
    for (path, item) in api.paths.paths.iter_mut() {
        // A live session records and stores a session: it writes, though it is a GET (the
        // WebSocket upgrade).
        let get_writes = path == &format!("{API_PREFIX}/live");
        let ops = [
            (&mut item.get, get_writes),
            (&mut item.post, true),
            (&mut item.delete, true),
            (&mut item.put, true),
            (&mut item.patch, true),
        ];
        for (op, writes) in ops {
            let Some(op) = op else { continue };
            let responses = &mut op.responses.responses;
            // The time limit applies to every route, and a stopping server answers 503 too.
            responses.entry("503".into()).or_insert_with(|| {
                problem_response("Over the server's time limit, or the server is stopping")
            });
            if let Some(body) = &op.request_body {
                let types: Vec<&str> = body.content.keys().map(String::as_str).collect();
                responses
                    .entry("413".into())
                    .or_insert_with(|| problem_response("The body is over the server's limit"));
                responses.entry("415".into()).or_insert_with(|| {
                    problem_response(&format!("Content-Type is not {}", types.join(" or ")))
                });
            }
            if !writes {
                continue;
            }
            if writes_need_token {
                responses.entry("401".into()).or_insert_with(|| {
                    problem_response("A token is configured and was not sent, or a wrong one")
                });
                // Drop the empty (anonymous) alternative: a token is required.
                if let Some(sec) = op.security.as_mut() {
                    sec.retain(|s| {
                        serde_json::to_value(s).is_ok_and(|v| v != serde_json::json!({}))
                    });
                }
            } else {
                op.security = None;
            }
        }
    }
    api
}

/// A problem+json response with `description`. The responses every operation of a kind
/// shares (503 all of them, 413 and 415 those with a body, 401 writes when a token is
/// configured) are declared here once, not on each route.
fn problem_response(description: &str) -> RefOr<utoipa::openapi::Response> {
    ResponseBuilder::new()
        .description(description)
        .content(
            error::PROBLEM_JSON,
            ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("ProblemBody")))
                .build(),
        )
        .build()
        .into()
}

/// The skill filters that take one of a few names (any other is 400) list those names, the
/// names of their types, inline (a query parameter's schema is read where it stands).
fn document_filter_values(api: &mut OpenApi) {
    let Some(op) = api
        .paths
        .paths
        .get_mut(&format!("{API_PREFIX}/skills"))
        .and_then(|item| item.get.as_mut())
    else {
        return;
    };
    for p in op.parameters.iter_mut().flatten() {
        let values: Vec<&str> = match p.name.as_str() {
            "shape" => ObjectShape::names(),
            "contact_model" => ContactModel::names(),
            "phase" => Phase::names(),
            _ => continue,
        };
        p.schema = Some(
            ObjectBuilder::new()
                .schema_type(Type::String)
                .enum_values(Some(values))
                .into(),
        );
    }
}

/// The application: every route over `state`, with its layers. Also stores the OpenAPI
/// document in `state` for `GET /api/v1/openapi.json`.
pub fn app(state: AppState, layers: &LayerConfig) -> Router {
    let (router, api) = routes().split_for_parts();
    let api = finish_openapi(api, state.token().is_some());
    state.set_openapi_json(Bytes::from(
        api.to_json().expect("the OpenAPI document serialises"),
    ));
    let max_body = state.max_body();
    let mut router = router
        .merge(web::router())
        .fallback(web::not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .with_state(state)
        .layer(DefaultBodyLimit::max(max_body))
        .layer(middleware::from_fn_with_state(max_body, linger::linger))
        .layer(middleware::from_fn_with_state(
            layers.request_timeout,
            time_limit,
        ));
    if !layers.cors_origins.is_empty() {
        router = router.layer(
            CorsLayer::new()
                .allow_origin(AllowOrigin::list(layers.cors_origins.clone()))
                .allow_methods([Method::GET, Method::HEAD, Method::POST, Method::DELETE])
                // Range requests and their answers' headers: what a viewer reading a file by
                // URL in pieces (Foxglove's remote files) needs.
                .allow_headers([
                    header::AUTHORIZATION,
                    header::CONTENT_TYPE,
                    header::RANGE,
                    header::IF_NONE_MATCH,
                    header::IF_RANGE,
                ])
                .expose_headers([
                    header::ACCEPT_RANGES,
                    header::CONTENT_RANGE,
                    header::CONTENT_LENGTH,
                    header::CONTENT_DISPOSITION,
                    header::ETAG,
                ]),
        );
    }
    router
        .layer(middleware::map_response(error::problem_for_bare_errors))
        .layer(TraceLayer::new_for_http())
}

/// 405 for a method the path does not take (axum adds the `Allow` header listing those it does).
async fn method_not_allowed() -> Problem {
    Problem::new(
        axum::http::StatusCode::METHOD_NOT_ALLOWED,
        "this path does not accept this method; the Allow header lists the ones it does",
    )
}

/// 201 Created with `body` as JSON and a `Location` header naming the new resource.
pub(crate) fn created(body: impl serde::Serialize, location: &str) -> Response {
    let mut r = (axum::http::StatusCode::CREATED, axum::Json(body)).into_response();
    if let Ok(v) = HeaderValue::from_str(location) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    r
}

/// When the request's time limit runs out: set by [`time_limit`] for the handlers that wait
/// (a simulation or replay waiting for its job answers 202 before it).
#[derive(Debug, Clone, Copy)]
pub struct RequestDeadline(pub tokio::time::Instant);

/// Middleware: a request that takes longer than the limit (reading its body included) is
/// answered 503 problem+json.
async fn time_limit(State(limit): State<Duration>, mut req: Request, next: Next) -> Response {
    req.extensions_mut()
        .insert(RequestDeadline(tokio::time::Instant::now() + limit));
    match tokio::time::timeout(limit, next.run(req)).await {
        Ok(r) => r,
        Err(_) => Problem::unavailable(format!(
            "the request took longer than the server's limit of {} s",
            limit.as_secs_f64()
        ))
        .into_response(),
    }
}
