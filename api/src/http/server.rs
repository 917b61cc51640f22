//! The connection loop: hyper's HTTP/1.1 server over our listener, with the limits that keep
//! slow, idle or numerous clients from holding the server ([`ConnectionLimits`]).
//!
//! axum's `serve` takes no connection settings, so this is the loop of axum's
//! `serve-with-hyper` example with three additions:
//!
//! - **Connection limit.** At most `max_connections` connections are open; the loop accepts the
//!   next one only when one has closed (the kernel's backlog holds the rest). The default stays
//!   below the process's descriptor limit, so the database, blobs and the listener always have
//!   descriptors left and `/healthz` keeps answering.
//! - **Header and keep-alive timeouts** ([`TimedIo`]): a connection must send a request's head
//!   within `header_timeout` of its first byte, and may sit idle between requests (or after
//!   connecting) for at most `keep_alive_timeout`; then it is closed. While a request is being
//!   handled no clock runs here: the request's own time limit (`--request-timeout`) covers it.
//! - **Shutdown grace.** On shutdown the loop stops accepting, asks every connection to close
//!   after its current answer, and waits at most `shutdown_grace` for them.
//!
//! Connections may be upgraded (`GET /api/v1/live` is a WebSocket): once a request is answered
//! `101 Switching Protocols` the connection is the WebSocket's, which has clocks of its own,
//! so neither timeout applies to it any more.

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::extract::Request;
use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tokio::time::{Instant, Sleep};
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;
use tower::ServiceExt;

/// Limits on connections (see the module's documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnectionLimits {
    /// Longest time from a request's first byte until its head (request line and headers) is
    /// complete. Default 10 s.
    pub header_timeout: Duration,
    /// Longest time a connection may sit idle: after connecting, or between the end of one
    /// answer and the first byte of the next request. Default 30 s.
    pub keep_alive_timeout: Duration,
    /// Most connections open at once. Default: 1024, or the descriptor limit less 64 when
    /// that is lower.
    pub max_connections: usize,
    /// Longest wait on shutdown for open connections to finish their answers. Default 5 s.
    pub shutdown_grace: Duration,
}

/// Descriptors kept free for the database, blob files and the listener.
const RESERVED_DESCRIPTORS: usize = 64;

impl Default for ConnectionLimits {
    fn default() -> Self {
        ConnectionLimits {
            header_timeout: Duration::from_secs(10),
            keep_alive_timeout: Duration::from_secs(30),
            max_connections: default_max_connections(),
            shutdown_grace: Duration::from_secs(5),
        }
    }
}

/// 1024, or fewer when the process may open fewer descriptors (less [`RESERVED_DESCRIPTORS`]).
pub fn default_max_connections() -> usize {
    match open_file_limit() {
        Some(n) => n.saturating_sub(RESERVED_DESCRIPTORS).clamp(1, 1024),
        None => 1024,
    }
}

/// The soft limit on open descriptors, from `/proc/self/limits` (Linux); `None` elsewhere or
/// when unlimited.
pub fn open_file_limit() -> Option<usize> {
    let text = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = text.lines().find(|l| l.starts_with("Max open files"))?;
    line["Max open files".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Serves `router` on `listener` until `shutdown` completes, with `limits`; then waits at most
/// the shutdown grace for open connections.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    limits: ConnectionLimits,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> io::Result<()> {
    let slots = Arc::new(Semaphore::new(limits.max_connections.max(1)));
    // hyper-util's GracefulShutdown does not take upgradeable HTTP/1 connections: the same,
    // by hand.
    let stopping = CancellationToken::new();
    let connections = TaskTracker::new();
    let mut builder = hyper::server::conn::http1::Builder::new();
    // hyper's own header clock starts when a connection goes idle; as a backstop it gets the
    // sum of both limits, which TimedIo enforces one by one.
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.keep_alive_timeout + limits.header_timeout)
        .keep_alive(true);
    tokio::pin!(shutdown);
    loop {
        let permit = tokio::select! {
            p = Arc::clone(&slots).acquire_owned() => match p {
                Ok(p) => p,
                Err(_) => break,
            },
            () = &mut shutdown => break,
        };
        let accepted = tokio::select! {
            a = listener.accept() => a,
            () = &mut shutdown => break,
        };
        let (stream, peer) = match accepted {
            Ok(a) => a,
            Err(e) => {
                // Out of descriptors or a connection reset before it was accepted: wait a
                // little rather than spin, then go on.
                tracing::warn!(error = %e, "accepting a connection failed");
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        let activity = Arc::new(Activity::default());
        let io = TimedIo::new(stream, Arc::clone(&activity), limits);
        let router = router.clone();
        let service = hyper::service::service_fn(move |req: Request<Incoming>| {
            let busy = activity.begin();
            let call = router.clone().oneshot(req.map(axum::body::Body::new));
            async move {
                let response = call.await;
                if let Ok(r) = &response {
                    if r.status() == axum::http::StatusCode::SWITCHING_PROTOCOLS {
                        busy.0.upgraded.store(true, Ordering::SeqCst);
                    }
                }
                drop(busy);
                response
            }
        });
        let conn = builder
            .serve_connection(TokioIo::new(io), service)
            .with_upgrades();
        let stop = stopping.clone();
        connections.spawn(async move {
            tokio::pin!(conn);
            let served = tokio::select! {
                r = conn.as_mut() => r,
                () = stop.cancelled() => {
                    conn.as_mut().graceful_shutdown();
                    conn.await
                }
            };
            if let Err(e) = served {
                tracing::debug!(%peer, error = %e, "connection closed with an error");
            }
            drop(permit);
        });
    }
    drop(listener);
    tracing::info!("no longer accepting connections; finishing open ones");
    stopping.cancel();
    connections.close();
    if tokio::time::timeout(limits.shutdown_grace, connections.wait())
        .await
        .is_err()
    {
        tracing::warn!(
            grace_s = limits.shutdown_grace.as_secs_f64(),
            "connections still open after the shutdown grace: closing them"
        );
    }
    Ok(())
}

/// What one connection's requests tell its [`TimedIo`]: how many are being handled, how many
/// have started, and when the last one ended.
#[derive(Debug, Default)]
struct Activity {
    in_flight: AtomicU64,
    started: AtomicU64,
    last_end: Mutex<Option<Instant>>,
    /// Answered `101 Switching Protocols`: the connection is no longer HTTP's.
    upgraded: std::sync::atomic::AtomicBool,
}

impl Activity {
    fn begin(self: &Arc<Self>) -> Busy {
        self.started.fetch_add(1, Ordering::SeqCst);
        self.in_flight.fetch_add(1, Ordering::SeqCst);
        Busy(Arc::clone(self))
    }
}

/// A request being handled; its drop marks the end.
struct Busy(Arc<Activity>);

impl Drop for Busy {
    fn drop(&mut self) {
        if let Ok(mut t) = self.0.last_end.lock() {
            *t = Some(Instant::now());
        }
        self.0.in_flight.fetch_sub(1, Ordering::SeqCst);
    }
}

/// A connection that closes itself (a read fails with `TimedOut`) when it sits idle past the
/// keep-alive timeout or takes longer than the header timeout to send a request's head.
pub struct TimedIo<T> {
    inner: T,
    activity: Arc<Activity>,
    limits: ConnectionLimits,
    /// Start of the idle period: accept, the last answer's end or the last write.
    idle_since: Instant,
    /// When the first byte of a request head not yet handed to a handler arrived.
    head_since: Option<Instant>,
    /// Requests started when `head_since` was last cleared.
    seen_started: u64,
    timer: Option<Pin<Box<Sleep>>>,
}

impl<T> std::fmt::Debug for TimedIo<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TimedIo")
            .field("idle_since", &self.idle_since)
            .field("head_since", &self.head_since)
            .finish_non_exhaustive()
    }
}

impl<T> TimedIo<T> {
    fn new(inner: T, activity: Arc<Activity>, limits: ConnectionLimits) -> Self {
        TimedIo {
            inner,
            activity,
            limits,
            idle_since: Instant::now(),
            head_since: None,
            seen_started: 0,
            timer: None,
        }
    }

    /// When the connection is to be closed, or `None` while a request is being handled.
    fn deadline(&mut self) -> Option<Instant> {
        let started = self.activity.started.load(Ordering::SeqCst);
        if started != self.seen_started {
            self.seen_started = started;
            self.head_since = None;
        }
        if self.activity.in_flight.load(Ordering::SeqCst) > 0
            || self.activity.upgraded.load(Ordering::SeqCst)
        {
            return None;
        }
        if let Some(end) = self.activity.last_end.lock().ok().and_then(|t| *t) {
            self.idle_since = self.idle_since.max(end);
        }
        Some(match self.head_since {
            Some(t) => t + self.limits.header_timeout,
            None => self.idle_since + self.limits.keep_alive_timeout,
        })
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for TimedIo<T> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let before = buf.filled().len();
        match Pin::new(&mut this.inner).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                if buf.filled().len() > before {
                    // A byte of a new request's head, unless a handler is reading its body.
                    if this.deadline().is_some() && this.head_since.is_none() {
                        this.head_since = Some(Instant::now());
                    }
                }
                this.timer = None;
                return Poll::Ready(Ok(()));
            }
            Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
            Poll::Pending => {}
        }
        let Some(deadline) = this.deadline() else {
            this.timer = None;
            return Poll::Pending;
        };
        let timed_out = || {
            Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "idle or slow connection closed",
            )))
        };
        if Instant::now() >= deadline {
            return timed_out();
        }
        let timer = this
            .timer
            .get_or_insert_with(|| Box::pin(tokio::time::sleep_until(deadline)));
        if timer.deadline() != deadline {
            timer.as_mut().reset(deadline);
        }
        match timer.as_mut().poll(cx) {
            Poll::Ready(()) => timed_out(),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for TimedIo<T> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write(cx, buf);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            this.idle_since = Instant::now();
        }
        r
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write_vectored(cx, bufs);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            this.idle_since = Instant::now();
        }
        r
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
}
