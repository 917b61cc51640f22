//! `/api/v1/sessions`: upload an MCAP session (read, validated, segmented and stored with its
//! skills in one atomic, idempotent step), list, get, download and delete sessions.

use axum::body::Body;
use axum::extract::State;
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use services::ingest::ingest_staged;
use services::store::{
    IngestOutcome, ObjectShape, SessionMeta, SessionQuery, SessionRecord, StoreError, DEFAULT_LIMIT,
};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::created;
use super::error::{Problem, ProblemBody};
use super::extract::{stream_body, Id, Query, WriteAccess};
use super::skills::{object_shape_schema, SkillBody};
use super::state::AppState;

/// Media type of a session upload or download.
pub const MCAP: &str = "application/x-mcap";

/// An MCAP file in a request or response body (documentation only: the bytes travel as they
/// are).
#[derive(Debug, Clone, Copy)]
pub struct McapFile;

impl utoipa::PartialSchema for McapFile {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        utoipa::openapi::schema::ObjectBuilder::new()
            .schema_type(utoipa::openapi::schema::Type::String)
            .content_media_type(MCAP)
            .description(Some("An MCAP session file"))
            .into()
    }
}

impl ToSchema for McapFile {}

/// Metadata of a recorded session.
///
/// The store's [`SessionMeta`] with its schema: services' types have none, so the API keeps
/// this body type beside it (fields typed alike, [`From`] between them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SessionMetaBody {
    /// Name of the simulated operator scenario, if the session was simulated.
    pub scenario: Option<String>,
    /// Seed of the simulation, if simulated.
    pub seed: Option<u64>,
    /// Hand (glove) that performed the session, e.g. glove10.
    pub hand: String,
    /// Object shape: sphere, box, cylinder, or unknown (a session file without the object).
    #[schema(schema_with = object_shape_schema)]
    pub object_shape: ObjectShape,
    /// Object mass, kg.
    pub object_mass: f64,
    /// Coulomb friction coefficient.
    pub mu: f64,
    /// Length of the session, ns.
    pub duration_ns: u64,
    /// Wall-clock start time (RFC 3339), if known.
    pub started_at: Option<String>,
    /// Every metadata field of the session file (free-form).
    #[schema(value_type = Object)]
    pub extra: serde_json::Value,
}

impl From<SessionMeta> for SessionMetaBody {
    fn from(m: SessionMeta) -> Self {
        SessionMetaBody {
            scenario: m.scenario,
            seed: m.seed,
            hand: m.hand,
            object_shape: m.object_shape,
            object_mass: m.object_mass,
            mu: m.mu,
            duration_ns: m.duration_ns,
            started_at: m.started_at,
            extra: m.extra,
        }
    }
}

/// A stored session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SessionBody {
    /// Session id.
    pub id: i64,
    /// Hex SHA-256 of the MCAP file (the same bytes are one session).
    pub sha256: String,
    /// Size of the MCAP file, bytes.
    pub size_bytes: i64,
    /// Session metadata.
    pub meta: SessionMetaBody,
    /// Ids of the session's skills, ascending.
    pub skill_ids: Vec<i64>,
    /// Per skill (in `skill_ids`' order): the stored skill it matched when it was stored
    /// (on-line learning linked the grasp to it), `null` for a skill stored as new.
    pub matched_skill_ids: Vec<Option<i64>>,
    /// Version of the segmentation that made its skills: `icms reprocess` segments sessions of
    /// older versions again. 0: stored before versions were recorded.
    pub segmentation_version: u32,
    /// When the session was stored (UTC, RFC 3339).
    pub created_at: String,
    /// Where to download the MCAP file.
    pub mcap_url: String,
}

impl From<SessionRecord> for SessionBody {
    fn from(s: SessionRecord) -> Self {
        SessionBody {
            mcap_url: format!("/api/v1/sessions/{}/mcap", s.id),
            id: s.id,
            sha256: s.sha256,
            size_bytes: s.size_bytes,
            meta: s.meta.into(),
            skill_ids: s.skill_ids,
            matched_skill_ids: s.matched_skill_ids,
            segmentation_version: s.segmentation_version,
            created_at: s.created_at,
        }
    }
}

/// One page of sessions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SessionPage {
    /// Sessions by id, in the order asked for (ascending by default).
    pub items: Vec<SessionBody>,
    /// Pass as `cursor` for the next page; `null` on the last.
    pub next_cursor: Option<String>,
}

/// Filters, order and page of `GET /sessions`. Every filter is optional and matches exactly.
#[derive(Debug, Clone, Default, Deserialize, IntoParams)]
#[serde(default, deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct SessionParams {
    /// Scenario name, e.g. sphere-lift (simulated sessions; a recorded one has none).
    pub scenario: Option<String>,
    /// Hand (glove) that performed the session, e.g. glove10.
    pub hand: Option<String>,
    /// Object shape: sphere, box, cylinder, or unknown.
    #[param(value_type = Option<String>)]
    pub shape: Option<ObjectShape>,
    /// Order by id: `id` (oldest first, the default) or `-id` (newest first; also `id:asc`,
    /// `id:desc`).
    pub sort: Option<String>,
    /// Page size, 1 to 1000. Default 50.
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<u32>,
    /// `next_cursor` of the previous page, passed back with the same filters and sort.
    pub cursor: Option<String>,
}

impl SessionParams {
    /// The store query these parameters ask for; a sort other than by id is
    /// [`StoreError::InvalidQuery`] (the store checks limit and cursor).
    pub fn to_query(&self) -> Result<SessionQuery, StoreError> {
        let newest_first = match self.sort.as_deref() {
            None | Some("id" | "id:asc") => false,
            Some("-id" | "id:desc") => true,
            Some(other) => {
                return Err(StoreError::InvalidQuery(format!(
                    "sort {other:?} is not one of id, -id, id:asc, id:desc (sessions sort by id)"
                )))
            }
        };
        Ok(SessionQuery {
            scenario: self.scenario.clone(),
            hand: self.hand.clone(),
            object_shape: self.shape,
            newest_first,
            limit: self.limit.unwrap_or(DEFAULT_LIMIT),
            cursor: self.cursor.clone(),
        })
    }
}

/// A session stored (or found already stored) with its skills.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct StoredSession {
    /// Id of the session.
    pub session_id: i64,
    /// `true` if this request stored it, `false` if the same bytes were already stored.
    pub created: bool,
    /// The session's skills, by ascending id.
    pub skills: Vec<SkillBody>,
}

impl StoredSession {
    /// The reply for an ingest: 201 with `Location` if created, else 200.
    pub async fn reply(st: &AppState, out: IngestOutcome) -> Result<Response, Problem> {
        let mut skills = Vec::with_capacity(out.skill_ids.len());
        for id in &out.skill_ids {
            skills.push(SkillBody::from(st.store().get_skill(*id).await?));
        }
        let body = StoredSession {
            session_id: out.session_id,
            created: out.created,
            skills,
        };
        if out.created {
            Ok(created(
                body,
                &format!("/api/v1/sessions/{}", out.session_id),
            ))
        } else {
            Ok(axum::Json(body).into_response())
        }
    }
}

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(upload_session, list_sessions))
        .routes(routes!(get_session, delete_session))
        .routes(routes!(download_session))
}

/// Whether `headers` declare an MCAP body (parameters after `;` are ignored).
fn is_mcap(headers: &HeaderMap) -> bool {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .is_some_and(|m| m.trim().eq_ignore_ascii_case(MCAP))
}

/// Uploads a session file: it is read (chunk CRCs checked), segmented into skills and stored
/// with them in one transaction. The same bytes again return the stored session.
#[utoipa::path(post, path = "/sessions", tag = "sessions",
    request_body(content = McapFile, content_type = "application/x-mcap",
        description = "An MCAP session file as `icms simulate` or `icms import-glove` writes it"),
    security((), ("bearer" = [])),
    responses(
        (status = 201, description = "Stored; `Location` names the new session", body = StoredSession,
            headers(("Location" = String, description = "URL of the session"))),
        (status = 200, description = "The same bytes were already stored: that session", body = StoredSession),
        (status = 400, description = "The body could not be read (e.g. broken chunked encoding); nothing was stored", body = ProblemBody, content_type = "application/problem+json"),
        (status = 422, description = "Not a valid session file, with the reason (a replay recording, as `icms replay --out` or a replay's MCAP download writes, is not a session); nothing was stored", body = ProblemBody, content_type = "application/problem+json"),
        (status = 503, description = "Over the server's time limit, the data base is busy, or every upload turn is taken (with `Retry-After`)", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn upload_session(
    _: WriteAccess,
    State(st): State<AppState>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, Problem> {
    if !is_mcap(&headers) {
        return Err(Problem::unsupported_media_type(format!(
            "upload a session as Content-Type: {MCAP}"
        )));
    }
    let limit = st.max_upload();
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit as u64) {
        return Err(Problem::too_large(limit));
    }
    // Streamed to a file beside the blobs, hashed on the way: an upload takes no memory.
    let store = st.store().clone();
    let staged = tokio::task::spawn_blocking(move || store.stage_upload())
        .await
        .map_err(|e| Problem::internal(&e))??;
    let staged = stream_body(body, limit, staged).await?;
    let size = staged.len();
    // Segmenting a session holds its grid (41 bytes per ms): so many at once.
    let _turn = st.ingest_turn().await?;
    let out = ingest_staged(st.store(), staged, "upload".into()).await?;
    tracing::info!(
        session_id = out.session_id,
        created = out.created,
        skills = out.skill_ids.len(),
        size,
        "session uploaded"
    );
    StoredSession::reply(&st, out).await
}

/// Sessions matching every given filter, by id (ascending, or newest first with
/// `sort=-id`), one page at a time.
#[utoipa::path(get, path = "/sessions", tag = "sessions",
    params(SessionParams),
    responses(
        (status = 200, description = "One page of sessions", body = SessionPage),
        (status = 400, description = "An invalid shape, sort, limit or cursor, or an unknown parameter", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn list_sessions(
    State(st): State<AppState>,
    Query(p): Query<SessionParams>,
) -> Result<axum::Json<SessionPage>, Problem> {
    let page = st.store().query_sessions(&p.to_query()?).await?;
    Ok(axum::Json(SessionPage {
        items: page.items.into_iter().map(SessionBody::from).collect(),
        next_cursor: page.next_cursor,
    }))
}

/// One session with its skill ids.
#[utoipa::path(get, path = "/sessions/{id}", tag = "sessions",
    params(("id" = i64, Path, description = "Session id")),
    responses(
        (status = 200, description = "The session", body = SessionBody),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No session with this id", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn get_session(
    State(st): State<AppState>,
    Id(id): Id,
) -> Result<axum::Json<SessionBody>, Problem> {
    Ok(axum::Json(st.store().get_session(id).await?.into()))
}

/// The session's MCAP file, as uploaded or recorded.
#[utoipa::path(get, path = "/sessions/{id}/mcap", tag = "sessions",
    params(("id" = i64, Path, description = "Session id")),
    responses(
        (status = 200, description = "The MCAP file", content_type = "application/x-mcap", body = McapFile),
        (status = 206, description = "The bytes of the one range asked for (`Range: bytes=a-b`), with `Content-Range`", content_type = "application/x-mcap", body = McapFile),
        (status = 304, description = "`If-None-Match` names the file's ETag (its SHA-256)"),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No session with this id", body = ProblemBody, content_type = "application/problem+json"),
        (status = 416, description = "The range starts past the end of the file", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn download_session(
    State(st): State<AppState>,
    Id(id): Id,
    request: HeaderMap,
) -> Result<Response, Problem> {
    let path = st.store().session_blob_path(id).await?;
    send_mcap(
        &path,
        &format!("session-{id}.mcap"),
        &request,
        // Deleted between the lookup and the open, or the file was removed from the data
        // directory behind the server's back: say both rather than deny the session exists.
        || {
            Problem::not_found(format!(
                "no MCAP file for session {id}: the session was just deleted, or its file is \
                 missing from the data directory"
            ))
        },
    )
    .await
}

/// Streams the MCAP file at `path` as an attachment named `filename`; `missing` is the problem
/// when the file is gone (its row was deleted since the lookup).
///
/// For viewers that read a file by URL in pieces (Foxglove's remote files): `Accept-Ranges:
/// bytes`, a single `Range: bytes=a-b` (or `a-`, `-n`) answered 206 with `Content-Range`, a
/// range past the end 416, and the blob's SHA-256 as a strong `ETag` (`If-None-Match` → 304,
/// `If-Range` honoured). Several ranges in one request are answered with the whole file.
pub(super) async fn send_mcap(
    path: &std::path::Path,
    filename: &str,
    request: &HeaderMap,
    missing: impl FnOnce() -> Problem,
) -> Result<Response, Problem> {
    use tokio::io::{AsyncReadExt, AsyncSeekExt};
    let mut file = match tokio::fs::File::open(path).await {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(missing()),
        Err(e) => return Err(Problem::internal(&e)),
    };
    let len = file
        .metadata()
        .await
        .map_err(|e| Problem::internal(&e))?
        .len();
    let etag = etag_of(path);
    let matches = |value: &HeaderValue| {
        etag.as_deref().is_some_and(|tag| {
            value
                .to_str()
                .is_ok_and(|v| v.split(',').any(|t| t.trim() == tag || t.trim() == "*"))
        })
    };
    if request.get(header::IF_NONE_MATCH).is_some_and(matches) {
        let mut r = StatusCode::NOT_MODIFIED.into_response();
        insert_file_headers(r.headers_mut(), etag.as_deref(), filename);
        return Ok(r);
    }
    let if_range_ok = request.get(header::IF_RANGE).is_none_or(|v| {
        etag.as_deref()
            .is_some_and(|tag| v.as_bytes() == tag.as_bytes())
    });
    let range = match request.get(header::RANGE) {
        Some(v) if if_range_ok => byte_range(v.to_str().unwrap_or(""), len),
        _ => RangeAsked::Whole,
    };
    let (status, start, count) = match range {
        RangeAsked::Whole => (StatusCode::OK, 0, len),
        RangeAsked::Part { start, end } => (StatusCode::PARTIAL_CONTENT, start, end + 1 - start),
        RangeAsked::Unsatisfiable => {
            let mut r = Problem::new(
                StatusCode::RANGE_NOT_SATISFIABLE,
                format!(
                    "the range {:?} starts past the file's {len} bytes",
                    request[header::RANGE]
                ),
            )
            .into_response();
            if let Ok(v) = HeaderValue::from_str(&format!("bytes */{len}")) {
                r.headers_mut().insert(header::CONTENT_RANGE, v);
            }
            return Ok(r);
        }
    };
    if start > 0 {
        file.seek(std::io::SeekFrom::Start(start))
            .await
            .map_err(|e| Problem::internal(&e))?;
    }
    let body = Body::from_stream(tokio_util::io::ReaderStream::with_capacity(
        file.take(count),
        256 * 1024,
    ));
    let mut r = Response::new(body);
    *r.status_mut() = status;
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(MCAP));
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(count));
    if status == StatusCode::PARTIAL_CONTENT {
        if let Ok(v) = HeaderValue::from_str(&format!("bytes {start}-{}/{len}", start + count - 1))
        {
            h.insert(header::CONTENT_RANGE, v);
        }
    }
    insert_file_headers(h, etag.as_deref(), filename);
    Ok(r)
}

fn insert_file_headers(h: &mut HeaderMap, etag: Option<&str>, filename: &str) {
    h.insert(header::ACCEPT_RANGES, HeaderValue::from_static("bytes"));
    if let Some(v) = etag.and_then(|t| HeaderValue::from_str(t).ok()) {
        h.insert(header::ETAG, v);
    }
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{filename}\"")) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
}

/// The strong entity tag of a content-addressed blob (`blobs/sha256/ab/cdef….mcap`): its
/// quoted SHA-256, which changes exactly when its bytes do.
fn etag_of(path: &std::path::Path) -> Option<String> {
    let prefix = path.parent()?.file_name()?.to_str()?;
    let rest = path.file_stem()?.to_str()?;
    let hex = format!("{prefix}{rest}");
    (hex.len() == 64 && hex.bytes().all(|b| b.is_ascii_hexdigit())).then(|| format!("\"{hex}\""))
}

/// What a `Range` header asks of a file of `len` bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RangeAsked {
    /// No usable range (absent, malformed, several ranges): the whole file, 200.
    Whole,
    /// Bytes `start..=end`, 206.
    Part { start: u64, end: u64 },
    /// A range starting past the end, 416.
    Unsatisfiable,
}

/// Parses one `bytes=a-b`, `bytes=a-` or `bytes=-n` range (RFC 9110 §14.1.2); anything else
/// is ignored, as the RFC allows.
fn byte_range(value: &str, len: u64) -> RangeAsked {
    let Some(spec) = value.trim().strip_prefix("bytes=") else {
        return RangeAsked::Whole;
    };
    if spec.contains(',') {
        return RangeAsked::Whole;
    }
    let Some((a, b)) = spec.trim().split_once('-') else {
        return RangeAsked::Whole;
    };
    let (a, b) = (a.trim(), b.trim());
    let parse = |s: &str| s.parse::<u64>().ok();
    match (a.is_empty(), b.is_empty()) {
        // The last n bytes.
        (true, false) => match parse(b) {
            Some(0) => RangeAsked::Unsatisfiable,
            Some(n) if len > 0 => RangeAsked::Part {
                start: len.saturating_sub(n),
                end: len - 1,
            },
            Some(_) => RangeAsked::Unsatisfiable,
            None => RangeAsked::Whole,
        },
        (false, _) => {
            let Some(start) = parse(a) else {
                return RangeAsked::Whole;
            };
            let end = if b.is_empty() {
                Some(u64::MAX)
            } else {
                parse(b)
            };
            match end {
                None => RangeAsked::Whole,
                Some(end) if end < start => RangeAsked::Whole,
                Some(_) if start >= len => RangeAsked::Unsatisfiable,
                Some(end) => RangeAsked::Part {
                    start,
                    end: end.min(len - 1),
                },
            }
        }
        (true, true) => RangeAsked::Whole,
    }
}

#[cfg(test)]
mod range_tests {
    use super::{byte_range, etag_of, RangeAsked};

    #[test]
    fn ranges_parse_as_rfc_9110_says() {
        use RangeAsked::*;
        assert_eq!(byte_range("bytes=0-99", 1000), Part { start: 0, end: 99 });
        assert_eq!(
            byte_range("bytes=900-", 1000),
            Part {
                start: 900,
                end: 999
            }
        );
        assert_eq!(
            byte_range("bytes=900-5000", 1000),
            Part {
                start: 900,
                end: 999
            }
        );
        assert_eq!(
            byte_range("bytes=-100", 1000),
            Part {
                start: 900,
                end: 999
            }
        );
        assert_eq!(byte_range("bytes=-5000", 1000), Part { start: 0, end: 999 });
        assert_eq!(byte_range("bytes=1000-", 1000), Unsatisfiable);
        assert_eq!(byte_range("bytes=-0", 1000), Unsatisfiable);
        assert_eq!(byte_range("bytes=0-1,5-9", 1000), Whole);
        assert_eq!(byte_range("bytes=9-1", 1000), Whole);
        assert_eq!(byte_range("items=0-1", 1000), Whole);
        assert_eq!(byte_range("bytes=x-1", 1000), Whole);
    }

    #[test]
    fn a_blob_path_gives_its_sha256_as_etag() {
        let hex = "ab".to_owned() + &"c".repeat(62);
        let p = std::path::PathBuf::from(format!("/d/blobs/sha256/ab/{}.mcap", &hex[2..]));
        assert_eq!(etag_of(&p), Some(format!("\"{hex}\"")));
        assert_eq!(etag_of(std::path::Path::new("/tmp/x.mcap")), None);
    }
}

/// Deletes a session with its skills, their replays and the MCAP files.
#[utoipa::path(delete, path = "/sessions/{id}", tag = "sessions",
    params(("id" = i64, Path, description = "Session id")),
    security((), ("bearer" = [])),
    responses(
        (status = 204, description = "Deleted, with its skills, their replays and the MCAP files"),
        (status = 400, description = "The id is not an integer", body = ProblemBody, content_type = "application/problem+json"),
        (status = 404, description = "No session with this id", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn delete_session(
    _: WriteAccess,
    State(st): State<AppState>,
    Id(id): Id,
) -> Result<StatusCode, Problem> {
    // Skills are created with their session and never added later, so these are all of them.
    let skill_ids = st.store().get_session(id).await?.skill_ids;
    let result = st.store().delete_session(id).await;
    st.cache().remove(&skill_ids);
    result?;
    tracing::info!(session_id = id, skills = skill_ids.len(), "deleted session");
    Ok(StatusCode::NO_CONTENT)
}
