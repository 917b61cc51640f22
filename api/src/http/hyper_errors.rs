//! Problems for the requests hyper refuses on its own. A request whose head does not parse (a
//! `Content-Length` that is not one number, a header line with bytes HTTP forbids, a request
//! line that is not HTTP/1.x, more headers than hyper takes) never reaches the router, so no
//! middleware sees it: hyper answers `400 Bad Request` (`431` for too many or too large
//! headers, `414` for a URI too long) with an empty body and closes the connection, and hyper
//! has no hook to change that answer.
//!
//! The server wraps every connection in a [`ProblemIo`] (see [`super::server`]), which recognises that answer as
//! hyper writes it and writes the same status and headers with a problem+json body instead
//! (plus `Connection: close`, which is what hyper does next). It is recognised by its shape:
//! a 4xx head with `content-length: 0` and no `content-type`, written on its own. Every error
//! the router answers has a problem+json body ([`super::error::problem_for_bare_errors`]), so
//! such a head can only be hyper's. hyper writes it alone, as the first write after the
//! previous answer was flushed; should a pipelining client ever get it in one write with the
//! end of the previous answer, it goes out unchanged, as hyper wrote it.

use std::io;
use std::pin::Pin;
use std::task::{ready, Context, Poll};

use axum::http::StatusCode;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

use super::error::{Problem, PROBLEM_JSON};

/// A connection that passes everything through, except that hyper's bare answer to a request
/// it could not parse is written as a problem (see the module's documentation).
#[derive(Debug)]
pub struct ProblemIo<T> {
    inner: T,
    replacing: Option<Replacing>,
}

/// A problem being written in place of hyper's bare answer.
#[derive(Debug)]
struct Replacing {
    bytes: Vec<u8>,
    written: usize,
    /// Length of hyper's answer: reported as written once all of `bytes` is.
    replaces: usize,
}

impl<T> ProblemIo<T> {
    /// Wraps a connection.
    pub fn new(inner: T) -> Self {
        ProblemIo {
            inner,
            replacing: None,
        }
    }
}

impl<T: AsyncWrite + Unpin> ProblemIo<T> {
    /// Writes the rest of the replacement; then reports hyper's buffer as written.
    fn poll_replacement(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<usize>> {
        let ProblemIo { inner, replacing } = self;
        let Some(r) = replacing.as_mut() else {
            return Poll::Ready(Ok(0));
        };
        while r.written < r.bytes.len() {
            match ready!(Pin::new(&mut *inner).poll_write(cx, &r.bytes[r.written..])) {
                Ok(0) => {
                    *replacing = None;
                    return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
                }
                Ok(n) => r.written += n,
                Err(e) => {
                    *replacing = None;
                    return Poll::Ready(Err(e));
                }
            }
        }
        let n = r.replaces;
        *replacing = None;
        Poll::Ready(Ok(n))
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for ProblemIo<T> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for ProblemIo<T> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        if this.replacing.is_none() {
            let Some(bytes) = problem_for_bare_answer(buf) else {
                return Pin::new(&mut this.inner).poll_write(cx, buf);
            };
            this.replacing = Some(Replacing {
                bytes,
                written: 0,
                replaces: buf.len(),
            });
        }
        this.poll_replacement(cx)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        if this.replacing.is_none() {
            // hyper's answer is a head alone: one non-empty slice.
            let mut non_empty = bufs.iter().filter(|b| !b.is_empty());
            let alone = match (non_empty.next(), non_empty.next()) {
                (Some(only), None) => problem_for_bare_answer(only).map(|p| (p, only.len())),
                _ => None,
            };
            let Some((bytes, replaces)) = alone else {
                return Pin::new(&mut this.inner).poll_write_vectored(cx, bufs);
            };
            this.replacing = Some(Replacing {
                bytes,
                written: 0,
                replaces,
            });
        }
        this.poll_replacement(cx)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }
}

/// If `buf` is exactly hyper's bare answer to a request it could not parse (a 4xx head with
/// `content-length: 0`, no `content-type`, nothing after it), the same answer with a
/// problem+json body.
fn problem_for_bare_answer(buf: &[u8]) -> Option<Vec<u8>> {
    // Cheap rejection first: every answer passes through here.
    if !buf.starts_with(b"HTTP/1.") || buf.get(9) != Some(&b'4') || !buf.ends_with(b"\r\n\r\n") {
        return None;
    }
    let head = std::str::from_utf8(&buf[..buf.len() - 4]).ok()?;
    if head.contains("\r\n\r\n") {
        return None;
    }
    let mut lines = head.split("\r\n");
    let status_line = lines.next()?;
    let code: u16 = status_line.get(9..12)?.parse().ok()?;
    let status = StatusCode::from_u16(code).ok()?;
    let mut kept = Vec::new();
    let mut empty = false;
    for line in lines {
        let (name, value) = line.split_once(':')?;
        let name = name.trim();
        if name.eq_ignore_ascii_case("content-length") {
            if value.trim() != "0" {
                return None;
            }
            empty = true;
        } else if name.eq_ignore_ascii_case("content-type")
            || name.eq_ignore_ascii_case("transfer-encoding")
        {
            return None;
        } else if !name.eq_ignore_ascii_case("connection") {
            kept.push(line);
        }
    }
    if !empty {
        return None;
    }
    let detail = match status {
        StatusCode::BAD_REQUEST => {
            "the request could not be parsed as HTTP/1.1: a malformed request line or header \
             (for example a Content-Length that is not a single number, or a header with \
             characters HTTP does not allow); the connection is closed"
        }
        StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE => {
            "the request has more headers, or larger ones, than the server accepts; the \
             connection is closed"
        }
        StatusCode::URI_TOO_LONG => {
            "the request's URI is longer than the server accepts; the connection is closed"
        }
        other => other.canonical_reason().unwrap_or("error"),
    };
    let body = serde_json::to_vec(&Problem::new(status, detail).body()).ok()?;
    let mut out = Vec::with_capacity(buf.len() + body.len() + 96);
    out.extend_from_slice(status_line.as_bytes());
    out.extend_from_slice(b"\r\n");
    for line in kept {
        out.extend_from_slice(line.as_bytes());
        out.extend_from_slice(b"\r\n");
    }
    out.extend_from_slice(format!("content-type: {PROBLEM_JSON}\r\n").as_bytes());
    out.extend_from_slice(format!("content-length: {}\r\n", body.len()).as_bytes());
    out.extend_from_slice(b"connection: close\r\n\r\n");
    out.extend_from_slice(&body);
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::problem_for_bare_answer;

    #[test]
    fn hypers_bare_answer_becomes_a_problem_with_the_same_status_and_headers() {
        let bare = b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\
                     date: Mon, 01 Jan 2024 00:00:00 GMT\r\n\r\n";
        let out = String::from_utf8(problem_for_bare_answer(bare).unwrap()).unwrap();
        let (head, body) = out.split_once("\r\n\r\n").unwrap();
        assert!(head.starts_with("HTTP/1.1 400 Bad Request\r\n"), "{head}");
        assert!(
            head.contains("\r\ndate: Mon, 01 Jan 2024 00:00:00 GMT"),
            "{head}"
        );
        assert!(
            head.contains("\r\ncontent-type: application/problem+json"),
            "{head}"
        );
        assert!(
            head.contains(&format!("\r\ncontent-length: {}", body.len())),
            "{head}"
        );
        assert!(head.contains("\r\nconnection: close"), "{head}");
        let p: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(p["status"], 400);
        assert!(
            p["detail"].as_str().unwrap().contains("Content-Length"),
            "{p}"
        );
        let bare = b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\n\r\n";
        let out = String::from_utf8(problem_for_bare_answer(bare).unwrap()).unwrap();
        assert!(out.contains("\"status\":431"), "{out}");
    }

    #[test]
    fn every_other_answer_passes_unchanged() {
        for other in [
            &b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\n\r\n"[..],
            b"HTTP/1.1 204 No Content\r\n\r\n",
            b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/problem+json\r\n\
              content-length: 0\r\n\r\n",
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 12\r\n\r\n",
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\r\nHTTP/1.1 400 Bad Request\r\n\
              content-length: 0\r\n\r\n",
            b"HTTP/1.1 400 Bad Request\r\ntransfer-encoding: chunked\r\n\r\n",
            b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\n",
            b"{\"status\": 400}",
            b"",
        ] {
            assert_eq!(problem_for_bare_answer(other), None, "{other:?}");
        }
    }
}
