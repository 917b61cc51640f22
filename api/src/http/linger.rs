//! Lingering close: a request refused before its body was read (401 on a missing token, 404 on
//! an unknown skill, 415 on a wrong content type) still has its body read and discarded, up to
//! the body limit, before the answer goes out.
//!
//! Without it the server answers and closes a connection whose client is still writing; the
//! kernel then resets the connection, and the reset can reach the client before it read the
//! answer, so the user sees "connection reset" instead of the 401 that says what is wrong.
//! nginx (`lingering_close`) and Go's `net/http` do the same for the same reason. Reading the
//! rest to its end also keeps the connection alive for the client's next request. The time
//! limit layer sits outside this one, so a client that trickles its body is still cut off.

use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context, Poll};

use axum::body::{Body, HttpBody};
use axum::extract::{Request, State};
use axum::http::header::CONNECTION;
use axum::http::HeaderValue;
use axum::middleware::Next;
use axum::response::Response;
use bytes::Bytes;
use http_body_util::BodyExt;

/// Where a request body that was dropped unread goes back to the middleware.
type Slot = Arc<Mutex<Option<Body>>>;

/// The request body as the handler sees it; dropped before its end, it hands what is left to
/// [`linger`].
struct Returning {
    inner: Option<Body>,
    slot: Slot,
}

impl HttpBody for Returning {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Bytes>, axum::Error>>> {
        match self.inner.as_mut() {
            Some(body) => Pin::new(body).poll_frame(cx),
            None => Poll::Ready(None),
        }
    }

    fn is_end_stream(&self) -> bool {
        self.inner.as_ref().is_none_or(HttpBody::is_end_stream)
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.inner
            .as_ref()
            .map_or_else(|| http_body::SizeHint::with_exact(0), HttpBody::size_hint)
    }
}

impl Drop for Returning {
    fn drop(&mut self) {
        if let Some(body) = self.inner.take() {
            if !body.is_end_stream() {
                *self.slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(body);
            }
        }
    }
}

/// Middleware: runs the request, then reads and discards what its handler left of the body,
/// at most `max_body` bytes (beyond that the connection is closed, and the answer carries
/// `Connection: close`).
pub async fn linger(State(max_body): State<usize>, req: Request, next: Next) -> Response {
    let (parts, body) = req.into_parts();
    if body.is_end_stream() {
        return next.run(Request::from_parts(parts, body)).await;
    }
    let slot = Slot::default();
    let body = Body::new(Returning {
        inner: Some(body),
        slot: Arc::clone(&slot),
    });
    let mut response = next.run(Request::from_parts(parts, body)).await;
    let rest = slot.lock().unwrap_or_else(PoisonError::into_inner).take();
    if let Some(rest) = rest {
        if !discard(rest, max_body).await {
            // The rest is too long to read (an upload over the limit answered 413): the
            // connection closes after this answer, and saying so keeps the client from sending
            // its next request on it (it would find the connection gone: "incomplete message").
            response
                .headers_mut()
                .insert(CONNECTION, HeaderValue::from_static("close"));
        }
    }
    response
}

/// Reads `body` to its end or until more than `max` bytes came, dropping the bytes; `true`
/// when it was read to its end.
async fn discard(mut body: Body, max: usize) -> bool {
    let mut left = max;
    loop {
        match body.frame().await {
            None => return true,
            Some(Err(_)) => return false,
            Some(Ok(frame)) => {
                if let Some(data) = frame.data_ref() {
                    match left.checked_sub(data.len()) {
                        Some(l) => left = l,
                        None => return false,
                    }
                }
            }
        }
    }
}
