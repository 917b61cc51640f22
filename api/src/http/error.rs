//! Errors as RFC 9457 problem details (`application/problem+json`): the [`Problem`] type every
//! handler returns on failure, the mapping of the store's and ingest's errors to statuses, and a
//! middleware that turns the framework's own bare error responses (unknown route, wrong method,
//! an extractor's plain-text rejection) into problems too.

use axum::body::Body;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use services::ingest::IngestError;
use services::store::StoreError;
use utoipa::ToSchema;

/// Media type of a problem body.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// `Retry-After` of a 503 for a data base locked by another writer, seconds.
pub const BUSY_RETRY_AFTER_S: u32 = 2;

/// A problem details body (RFC 9457).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, ToSchema)]
#[schema(example = json!({"type": "about:blank", "title": "Not Found", "status": 404,
    "detail": "no skill with id 42"}))]
pub struct ProblemBody {
    /// Always `about:blank`: the status and title say what kind of problem it is.
    #[serde(rename = "type")]
    pub kind: String,
    /// The HTTP status phrase, e.g. `Bad Request`.
    pub title: String,
    /// The HTTP status code.
    pub status: u16,
    /// What was wrong with this request, in words (never internals).
    pub detail: String,
}

/// An error response: a status and what was wrong. Renders as `application/problem+json`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// HTTP status.
    pub status: StatusCode,
    /// What was wrong.
    pub detail: String,
    /// Seconds after which a retry may succeed (`Retry-After`), for a busy server.
    pub retry_after_s: Option<u32>,
}

impl Problem {
    /// A problem with `status` and `detail`.
    pub fn new(status: StatusCode, detail: impl Into<String>) -> Self {
        Problem {
            status,
            detail: detail.into(),
            retry_after_s: None,
        }
    }
    /// 400: malformed input (a filter, a cursor, a parameter, a JSON body).
    pub fn bad_request(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, detail)
    }
    /// 401: a write without the configured bearer token, or with a wrong one.
    pub fn unauthorized(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::UNAUTHORIZED, detail)
    }
    /// 404: no such resource or route.
    pub fn not_found(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, detail)
    }
    /// 409: a name already taken (an uploaded hand named like a built-in or a stored hand).
    pub fn conflict(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::CONFLICT, detail)
    }
    /// 413: the request body is over the server's limit.
    pub fn too_large(limit: usize) -> Self {
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("the request body is larger than the server's limit of {limit} bytes"),
        )
    }
    /// 415: the wrong content type for this endpoint.
    pub fn unsupported_media_type(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::UNSUPPORTED_MEDIA_TYPE, detail)
    }
    /// 422: well-formed input that cannot be processed (an MCAP file that is not a valid
    /// session, a scenario that fails validation).
    pub fn unprocessable(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::UNPROCESSABLE_ENTITY, detail)
    }
    /// 503: the request took longer than the server's time limit, or the server is stopping.
    pub fn unavailable(detail: impl Into<String>) -> Self {
        Self::new(StatusCode::SERVICE_UNAVAILABLE, detail)
    }
    /// 503 with `Retry-After`: the server is busy (every turn for this work is taken, the data
    /// base is locked by another writer); the same request may succeed after `retry_after_s`.
    pub fn busy(detail: impl Into<String>, retry_after_s: u32) -> Self {
        Problem {
            retry_after_s: Some(retry_after_s),
            ..Self::new(StatusCode::SERVICE_UNAVAILABLE, detail)
        }
    }

    /// A stored recording (`what`: `session 4`, `replay 9`) that could not be read back: 404
    /// when its file is missing from the data directory; otherwise 500 naming the recording
    /// (the file was checked when it was stored, so the data directory changed under us), the
    /// reader's error in the server's log.
    pub fn stored_recording(what: &str, error: services::RecordingError) -> Self {
        match error {
            services::RecordingError::Io { source, .. }
                if source.kind() == std::io::ErrorKind::NotFound =>
            {
                Self::not_found(format!(
                    "no MCAP file for {what}: it is missing from the data directory"
                ))
            }
            error => {
                tracing::error!(%error, what, "a stored recording does not read back");
                Self::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    format!(
                        "the stored file of {what} does not read as a recording; the server's \
                         log has the details"
                    ),
                )
            }
        }
    }

    /// 500: a fault of the server; `error` is logged, the client sees no internals.
    pub fn internal(error: &dyn std::fmt::Display) -> Self {
        tracing::error!(%error, "internal error");
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal error; the server's log has the details",
        )
    }

    /// The body of this problem.
    pub fn body(&self) -> ProblemBody {
        ProblemBody {
            kind: "about:blank".into(),
            title: self
                .status
                .canonical_reason()
                .unwrap_or("Error")
                .to_string(),
            status: self.status.as_u16(),
            detail: self.detail.clone(),
        }
    }
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.status, self.detail)
    }
}

impl IntoResponse for Problem {
    fn into_response(self) -> Response {
        let body = serde_json::to_vec(&self.body()).unwrap_or_default();
        let mut r = Response::new(Body::from(body));
        *r.status_mut() = self.status;
        let h = r.headers_mut();
        h.insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
        if let Some(s) = self.retry_after_s {
            h.insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        if self.status == StatusCode::UNAUTHORIZED {
            h.insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"icms\""),
            );
        }
        r
    }
}

impl From<StoreError> for Problem {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::BadCursor | StoreError::InvalidQuery(_) => {
                Problem::bad_request(e.to_string())
            }
            StoreError::InvalidInput(_) | StoreError::InvalidHand(_) => {
                Problem::unprocessable(e.to_string())
            }
            StoreError::SessionNotFound(_)
            | StoreError::SkillNotFound(_)
            | StoreError::HandNotFound(_)
            | StoreError::ReplayNotFound(_)
            | StoreError::JobNotFound(_) => Problem::not_found(e.to_string()),
            StoreError::QueueFull(_) => Problem::busy(
                format!("the server is busy: {e}; nothing was queued"),
                BUSY_RETRY_AFTER_S,
            ),
            StoreError::Conflict(_) => Problem::conflict(e.to_string()),
            StoreError::ObjectStore { .. } => Problem::busy(
                format!("{e}; nothing was stored or changed, try again"),
                BUSY_RETRY_AFTER_S,
            ),
            StoreError::Db(sqlx::Error::PoolClosed) => {
                Problem::unavailable("the server is shutting down")
            }
            ref down if down.is_unreachable() => Problem::busy(
                "the data base cannot be reached; nothing was stored or changed, try again",
                BUSY_RETRY_AFTER_S,
            ),
            // Every pooled connection in use past the acquire timeout, or none could be made
            // (sqlx does not say which).
            StoreError::Db(sqlx::Error::PoolTimedOut) => Problem::busy(
                "the data base did not answer in time: busy with other work, or unreachable; \
                 nothing was stored or changed, try again",
                BUSY_RETRY_AFTER_S,
            ),
            ref busy if busy.is_busy() => Problem::busy(
                "the data base is busy with other writes; nothing was stored, try again",
                BUSY_RETRY_AFTER_S,
            ),
            other => Problem::internal(&other),
        }
    }
}

impl From<IngestError> for Problem {
    fn from(e: IngestError) -> Self {
        match e {
            IngestError::InvalidSession(reason) => {
                Problem::unprocessable(format!("not a valid session: {reason}"))
            }
            IngestError::Store(s) => s.into(),
        }
    }
}

/// Middleware: a response with an error status that is not already a problem (a plain-text
/// rejection of one of axum's extractors, a layer's bare status) becomes one, keeping its
/// status and headers; a short plain-text body becomes the detail. Unknown routes and methods
/// are problems already, from the router's fallbacks.
pub async fn problem_for_bare_errors(response: Response) -> Response {
    let status = response.status();
    if !(status.is_client_error() || status.is_server_error()) {
        return response;
    }
    let is_problem = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(PROBLEM_JSON.as_bytes()));
    // The web page's own not-found page (any path outside the API) is HTML for people.
    let is_html = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"text/html"));
    if is_problem || is_html {
        return response;
    }
    let is_text = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"text/plain"));
    let (mut parts, body) = response.into_parts();
    let text = if is_text {
        axum::body::to_bytes(body, 4096)
            .await
            .ok()
            .map(|b| String::from_utf8_lossy(&b).into_owned())
            .unwrap_or_default()
    } else {
        String::new()
    };
    let detail = if !text.is_empty() {
        text
    } else {
        status.canonical_reason().unwrap_or("error").to_string()
    };
    let fresh = Problem::new(status, detail).into_response();
    let (fresh_parts, body) = fresh.into_parts();
    parts.headers.remove(header::CONTENT_LENGTH);
    for (k, v) in fresh_parts.headers.iter() {
        parts.headers.insert(k, v.clone());
    }
    Response::from_parts(parts, body)
}
