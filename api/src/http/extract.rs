//! Request extractors whose rejections are problems: query strings, path ids and JSON bodies
//! (axum's own would answer in plain text; a JSON body with a key twice is refused rather than
//! read as its last value), reading a whole body ([`read_body`]), and [`WriteAccess`], the
//! bearer-token check of every write endpoint.

use axum::body::Body;
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::request::Parts;
use axum::http::{header, HeaderMap};
use bytes::Bytes;
use serde::de::DeserializeOwned;
use services::store::StagedBlob;

use super::error::Problem;
use super::state::AppState;

/// A query string deserialised into `T`; anything malformed, unknown (`T` denies unknown
/// fields) or repeated is 400, naming the parameter.
#[derive(Debug, Clone)]
pub struct Query<T>(pub T);

impl<T: DeserializeOwned, S: Send + Sync> FromRequestParts<S> for Query<T> {
    type Rejection = Problem;

    async fn from_request_parts(parts: &mut Parts, _state: &S) -> Result<Self, Problem> {
        let q = parts.uri.query().unwrap_or("");
        let de = serde_urlencoded::Deserializer::new(form_urlencoded::parse(q.as_bytes()));
        serde_path_to_error::deserialize(de)
            .map(Query)
            .map_err(|e| {
                let inner = e.inner().to_string();
                // The parameter structs deny unknown fields: a typo (`?shpe=box`) is refused
                // rather than answered as if the filter were absent. Say "parameter".
                if let Some(rest) = inner.strip_prefix("unknown field ") {
                    return Problem::bad_request(format!(
                        "invalid query: unknown parameter {rest}"
                    ));
                }
                if let Some(name) = inner.strip_prefix("duplicate field ") {
                    return Problem::bad_request(format!(
                        "invalid query: the parameter {name} is given twice"
                    ));
                }
                let path = e.path().to_string();
                if path == "." {
                    Problem::bad_request(format!("invalid query string: {inner}"))
                } else {
                    Problem::bad_request(format!("invalid query parameter {path}: {inner}"))
                }
            })
    }
}

/// A numeric id from the path (`/skills/{id}`); anything that is not an integer is 400.
#[derive(Debug, Clone, Copy)]
pub struct Id(pub i64);

impl<S: Send + Sync> FromRequestParts<S> for Id {
    type Rejection = Problem;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Problem> {
        let Name(raw) = Name::from_request_parts(parts, state).await?;
        raw.parse::<i64>()
            .map(Id)
            .map_err(|_| Problem::bad_request(format!("id {raw:?} is not an integer")))
    }
}

/// A name from the path (`/hands/{id}`, where a hand's id is its name).
#[derive(Debug, Clone)]
pub struct Name(pub String);

impl<S: Send + Sync> FromRequestParts<S> for Name {
    type Rejection = Problem;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Problem> {
        let axum::extract::Path(raw) =
            axum::extract::Path::<String>::from_request_parts(parts, state)
                .await
                .map_err(|e| Problem::bad_request(e.body_text()))?;
        Ok(Name(raw))
    }
}

/// A JSON body deserialised into `T`: 415 without `Content-Type: application/json`, 413 over
/// the body limit, 400 for a body that cannot be read or malformed JSON (an object with a key
/// twice included, naming the key), 422 for JSON of the wrong shape (naming the field).
#[derive(Debug, Clone)]
pub struct Json<T>(pub T);

impl<T: DeserializeOwned> FromRequest<AppState> for Json<T> {
    type Rejection = Problem;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, Problem> {
        if !is_json(req.headers()) {
            return Err(Problem::unsupported_media_type(
                "this endpoint takes a JSON body: send Content-Type: application/json",
            ));
        }
        let bytes = read_body(req.into_body(), state.max_body()).await?;
        let value = parse_json_unique_keys(&bytes)
            .map_err(|e| Problem::bad_request(format!("malformed JSON: {e}")))?;
        serde_path_to_error::deserialize(value)
            .map(Json)
            .map_err(|e| Problem::unprocessable(path_error(&e)))
    }
}

/// Whether `headers` declare a JSON body: `application/json` or `application/*+json`,
/// parameters after `;` ignored (as axum's own `Json` decides).
fn is_json(headers: &HeaderMap) -> bool {
    let Some(essence) = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
    else {
        return false;
    };
    let Some((kind, sub)) = essence.trim().split_once('/') else {
        return false;
    };
    let sub = sub.trim().to_ascii_lowercase();
    kind.eq_ignore_ascii_case("application") && (sub == "json" || sub.ends_with("+json"))
}

/// Reads a whole request body of at most `limit` bytes: over it 413, a body that cannot be read
/// (a connection closed early, a broken chunked encoding) 400, both as problems.
pub(crate) async fn read_body(body: Body, limit: usize) -> Result<Bytes, Problem> {
    axum::body::to_bytes(body, limit)
        .await
        .map_err(|e| body_error(&e, limit))
}

/// The problem of a body that could not be read: over `limit` (413), or broken (400, naming
/// the cause: hyper's "invalid chunk size line", ...).
fn body_error(e: &axum::Error, limit: usize) -> Problem {
    let over =
        std::error::Error::source(e).is_some_and(|s| s.is::<http_body_util::LengthLimitError>());
    if over {
        return Problem::too_large(limit);
    }
    let mut detail = format!("could not read the request body: {e}");
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        let text = s.to_string();
        if !detail.contains(&text) {
            detail.push_str(": ");
            detail.push_str(&text);
        }
        source = s.source();
    }
    Problem::bad_request(detail)
}

/// Bytes gathered from the body before each write to the staged file.
const STAGE_WRITE_BYTES: usize = 1 << 20;

/// Streams a request body of at most `limit` bytes into `staged` (written and hashed on a
/// blocking thread a megabyte at a time): memory stays at a megabyte or two whatever the
/// body's size. Errors as [`read_body`]'s; the staged file is dropped with them.
pub(crate) async fn stream_body(
    body: Body,
    limit: usize,
    mut staged: StagedBlob,
) -> Result<StagedBlob, Problem> {
    use http_body_util::BodyExt;
    let mut body = body;
    let mut buffer = Vec::with_capacity(STAGE_WRITE_BYTES);
    let mut total = 0usize;
    loop {
        let frame = body.frame().await;
        let done = frame.is_none();
        if let Some(frame) = frame {
            let frame = frame.map_err(|e| body_error(&e, limit))?;
            if let Ok(data) = frame.into_data() {
                total = total.saturating_add(data.len());
                if total > limit {
                    return Err(Problem::too_large(limit));
                }
                buffer.extend_from_slice(&data);
            }
        }
        if buffer.len() >= STAGE_WRITE_BYTES || (done && !buffer.is_empty()) {
            let full = std::mem::replace(&mut buffer, Vec::with_capacity(STAGE_WRITE_BYTES));
            staged = tokio::task::spawn_blocking(move || staged.write(&full).map(|()| staged))
                .await
                .map_err(|e| Problem::internal(&e))?
                .map_err(Problem::from)?;
        }
        if done {
            return Ok(staged);
        }
    }
}

/// Parses JSON text into a value, refusing an object that has a key twice: serde_json would
/// keep the last one silently, so `{"hand": "allegro", "hand": "barrett"}` would replay on
/// Barrett. The error names the key and, inside nested objects, where
/// (`scenario.object: duplicate key "mass"`). One pass, as parsing into a `Value` is.
pub(crate) fn parse_json_unique_keys(bytes: &[u8]) -> Result<serde_json::Value, String> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value =
        serde_path_to_error::deserialize::<_, UniqueKeys>(&mut de).map_err(|e| path_error(&e))?;
    de.end().map_err(|e| e.to_string())?;
    Ok(value.0)
}

/// A JSON value whose objects were checked for duplicate keys while it was read.
struct UniqueKeys(serde_json::Value);

impl<'de> serde::Deserialize<'de> for UniqueKeys {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(UniqueKeysVisitor).map(UniqueKeys)
    }
}

struct UniqueKeysVisitor;

impl<'de> serde::de::Visitor<'de> for UniqueKeysVisitor {
    type Value = serde_json::Value;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("any JSON value")
    }
    fn visit_bool<E>(self, v: bool) -> Result<Self::Value, E> {
        Ok(v.into())
    }
    fn visit_i64<E>(self, v: i64) -> Result<Self::Value, E> {
        Ok(v.into())
    }
    fn visit_u64<E>(self, v: u64) -> Result<Self::Value, E> {
        Ok(v.into())
    }
    fn visit_f64<E>(self, v: f64) -> Result<Self::Value, E> {
        Ok(serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, Into::into))
    }
    fn visit_str<E>(self, v: &str) -> Result<Self::Value, E> {
        Ok(v.into())
    }
    fn visit_string<E>(self, v: String) -> Result<Self::Value, E> {
        Ok(v.into())
    }
    fn visit_unit<E>(self) -> Result<Self::Value, E> {
        Ok(serde_json::Value::Null)
    }
    fn visit_none<E>(self) -> Result<Self::Value, E> {
        Ok(serde_json::Value::Null)
    }
    fn visit_some<D: serde::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_any(self)
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(4096));
        while let Some(UniqueKeys(v)) = seq.next_element()? {
            items.push(v);
        }
        Ok(serde_json::Value::Array(items))
    }
    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut object = serde_json::Map::new();
        while let Some(key) = map.next_key::<String>()? {
            if object.contains_key(&key) {
                return Err(serde::de::Error::custom(format_args!(
                    "duplicate key {key:?} (each key may appear once in an object)"
                )));
            }
            let UniqueKeys(v) = map.next_value()?;
            object.insert(key, v);
        }
        Ok(serde_json::Value::Object(object))
    }
}

/// A deserialisation error as `path: reason`, or `reason` alone when it is about the whole
/// value (its path is `.`): how a JSON body's and a command's JSON file's errors are told.
pub(crate) fn path_error<E: std::fmt::Display>(e: &serde_path_to_error::Error<E>) -> String {
    let path = e.path().to_string();
    if path == "." {
        e.inner().to_string()
    } else {
        format!("{path}: {}", e.inner())
    }
}

/// A deserialisation error inside the field `prefix` of a body, as `prefix.path: reason`, or
/// `prefix: reason` when the error is about the field's value itself (its path is `.`).
pub(crate) fn field_error(
    prefix: &str,
    e: &serde_path_to_error::Error<serde_json::Error>,
) -> String {
    let path = e.path().to_string();
    if path == "." {
        format!("{prefix}: {}", e.inner())
    } else {
        format!("{prefix}.{path}: {}", e.inner())
    }
}

/// Proof that the request may write: the configured bearer token was sent
/// (`Authorization: Bearer TOKEN`), or no token is configured. Otherwise 401.
#[derive(Debug, Clone, Copy)]
pub struct WriteAccess;

impl FromRequestParts<AppState> for WriteAccess {
    type Rejection = Problem;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Problem> {
        let Some(expected) = state.token() else {
            return Ok(WriteAccess);
        };
        let Some(value) = parts.headers.get(header::AUTHORIZATION) else {
            return Err(Problem::unauthorized(
                "this endpoint writes and needs the server's token: Authorization: Bearer TOKEN",
            ));
        };
        match bearer_token(value.as_bytes()) {
            Some(t) if constant_time_eq(t.as_bytes(), expected.as_bytes()) => Ok(WriteAccess),
            Some(_) => Err(Problem::unauthorized("wrong bearer token")),
            None => Err(Problem::unauthorized(
                "the Authorization header is not a bearer token: send Authorization: Bearer TOKEN",
            )),
        }
    }
}

/// The token of an `Authorization: Bearer TOKEN` header value. The scheme is matched without
/// regard to case (RFC 9110 §11.1: `Bearer`, `bearer`, `BEARER` are one scheme) and may be
/// followed by several spaces; `None` for another scheme or no token.
fn bearer_token(value: &[u8]) -> Option<&str> {
    let value = std::str::from_utf8(value).ok()?;
    let (scheme, token) = value.split_once(' ')?;
    if !scheme.eq_ignore_ascii_case("bearer") {
        return None;
    }
    let token = token.trim();
    (!token.is_empty()).then_some(token)
}

/// Compares without an early exit, so the time taken does not tell how many leading bytes of a
/// guessed token were right.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::{bearer_token, constant_time_eq};

    #[test]
    fn the_bearer_scheme_is_matched_in_any_case() {
        for v in [
            "Bearer t0k",
            "bearer t0k",
            "BEARER t0k",
            "BeArEr   t0k ",
            "Bearer t0k\t",
        ] {
            assert_eq!(bearer_token(v.as_bytes()), Some("t0k"), "{v:?}");
        }
        for v in [
            "Basic dDBr",
            "t0k",
            "Bearer",
            "Bearer ",
            "Bearert0k",
            "Token t0k",
        ] {
            assert_eq!(bearer_token(v.as_bytes()), None, "{v:?}");
        }
    }

    #[test]
    fn tokens_compare_equal_only_when_identical() {
        assert!(constant_time_eq(b"secret", b"secret"));
        assert!(!constant_time_eq(b"secret", b"secreT"));
        assert!(!constant_time_eq(b"secret", b"secret2"));
        assert!(!constant_time_eq(b"", b"x"));
    }
}
