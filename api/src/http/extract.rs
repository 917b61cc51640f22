//! Request extractors whose rejections are problems: query strings, path ids and JSON bodies
//! (axum's own would answer in plain text), and [`WriteAccess`], the bearer-token check of
//! every write endpoint.

use axum::extract::rejection::JsonRejection;
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::request::Parts;
use axum::http::{header, StatusCode};
use serde::de::DeserializeOwned;

use super::error::Problem;
use super::state::AppState;

/// A query string deserialised into `T`; anything malformed or unknown is 400.
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
                let path = e.path().to_string();
                if path == "." {
                    Problem::bad_request(format!("invalid query string: {}", e.inner()))
                } else {
                    Problem::bad_request(format!("invalid query parameter {path}: {}", e.inner()))
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
/// the body limit, 400 for malformed JSON, 422 for JSON of the wrong shape (naming the field).
#[derive(Debug, Clone)]
pub struct Json<T>(pub T);

impl<T: DeserializeOwned, S: Send + Sync> FromRequest<S> for Json<T> {
    type Rejection = Problem;

    async fn from_request(req: Request, state: &S) -> Result<Self, Problem> {
        let bytes = match axum::Json::<serde_json::Value>::from_request(req, state).await {
            Ok(axum::Json(v)) => v,
            Err(JsonRejection::MissingJsonContentType(_)) => {
                return Err(Problem::unsupported_media_type(
                    "this endpoint takes a JSON body: send Content-Type: application/json",
                ))
            }
            Err(JsonRejection::JsonSyntaxError(e)) => {
                return Err(Problem::bad_request(format!(
                    "malformed JSON: {}",
                    e.body_text()
                )))
            }
            Err(e) if e.status() == StatusCode::PAYLOAD_TOO_LARGE => {
                return Err(Problem::new(StatusCode::PAYLOAD_TOO_LARGE, e.body_text()))
            }
            Err(e) => return Err(Problem::new(e.status(), e.body_text())),
        };
        serde_path_to_error::deserialize(bytes)
            .map(Json)
            .map_err(|e| {
                let path = e.path().to_string();
                if path == "." {
                    Problem::unprocessable(e.inner().to_string())
                } else {
                    Problem::unprocessable(format!("{path}: {}", e.inner()))
                }
            })
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
