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
        let sent = value
            .to_str()
            .ok()
            .and_then(|v| {
                v.strip_prefix("Bearer ")
                    .or_else(|| v.strip_prefix("bearer "))
            })
            .map(str::trim);
        match sent {
            Some(t) if constant_time_eq(t.as_bytes(), expected.as_bytes()) => Ok(WriteAccess),
            _ => Err(Problem::unauthorized("wrong bearer token")),
        }
    }
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
    use super::constant_time_eq;

    #[test]
    fn tokens_compare_equal_only_when_identical() {
        assert!(constant_time_eq(b"secret", b"secret"));
        assert!(!constant_time_eq(b"secret", b"secreT"));
        assert!(!constant_time_eq(b"secret", b"secret2"));
        assert!(!constant_time_eq(b"", b"x"));
    }
}
