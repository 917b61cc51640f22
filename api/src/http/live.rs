//! `GET /api/v1/live`: live glove sessions over a WebSocket (protocol in `docs/live.md`).
//!
//! The socket's task on the async runtime reads frames and writes answers; every DFS step
//! runs on the live stepping pool ([`LivePool`]: a few threads shared by every live session,
//! each session pinned to one), never on the runtime, and the network never stalls a step: a
//! step's answer waits for the socket, not the other way round. A session answers one frame
//! before it reads the next, so a client that stops reading stops being read (TCP's flow
//! control holds it), and memory does not grow with what a client sends.
//!
//! When the client sends `end`, disconnects, goes silent for the silence limit
//! (`--live-silence`, [`DEFAULT_SILENCE_LIMIT`](services::live::DEFAULT_SILENCE_LIMIT)) or
//! the server stops, the recording is
//! finished (every tick stepped is in it), then stored and segmented like an upload; a session
//! that did not end with `end` is stored marked incomplete.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use dfs_core::hand::HandModel;
use services::assist::assistant::{AssistSetup, SkillLoader};
use services::assist::features::ObjectInfo;
use services::assist::recognise::RecogniserParams;
use services::live::{
    AssistMode, ClientMessage, EndReason, Event, LiveConfig, LiveSession, SampleError,
    StartMessage, StoredSkill, MAX_FRAME_BYTES, STALE_AFTER,
};
use services::session::{SessionOut, SessionSource};
use services::store::{StagedBlob, StoreError};
use tokio::sync::{oneshot, OwnedSemaphorePermit, Semaphore};
use tokio::time::Instant;
use tokio_util::task::TaskTracker;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{Problem, ProblemBody};
use super::extract::WriteAccess;
use super::state::AppState;

/// The WebSocket's read buffer (bytes).
const READ_BUFFER_BYTES: usize = 8 * 1024;

/// How long a client has after the upgrade to send its `start` message.
pub const START_TIMEOUT: Duration = Duration::from_secs(10);

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(live))
        .routes(routes!(live_schema))
}

/// The binary frames' schema: `services/proto/icms/live.proto` compiled into a serialized
/// `google.protobuf.FileDescriptorSet` (package `icms.live`: `Sample`, `Feedback`), so that a
/// client builds the message classes with a protobuf runtime alone, e.g. in Python
/// `message_factory.GetMessages(FileDescriptorSet.FromString(body).file)`.
#[utoipa::path(get, path = "/live/schema", tag = "live",
    responses(
        (status = 200, description = "The FileDescriptorSet", content_type = "application/x-protobuf", body = Vec<u8>),
    ))]
async fn live_schema() -> Response {
    (
        [(axum::http::header::CONTENT_TYPE, "application/x-protobuf")],
        services::live::FILE_DESCRIPTOR_SET,
    )
        .into_response()
}

/// A few threads that step every live session's DFS; see the module docs.
pub struct LivePool {
    workers: Vec<Worker>,
}

struct Worker {
    jobs: mpsc::Sender<Job>,
    /// Sessions pinned to this worker.
    sessions: Arc<AtomicUsize>,
}

type Job = Box<dyn FnOnce() + Send>;

impl std::fmt::Debug for LivePool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LivePool")
            .field("threads", &self.workers.len())
            .finish()
    }
}

impl LivePool {
    /// A pool of `threads` stepping threads (at least one).
    pub fn new(threads: usize) -> std::io::Result<LivePool> {
        let mut workers = Vec::new();
        for i in 0..threads.max(1) {
            let (jobs, rx) = mpsc::channel::<Job>();
            std::thread::Builder::new()
                .name(format!("icms-live-{i}"))
                .spawn(move || {
                    while let Ok(job) = rx.recv() {
                        // A job that panics (a bug) loses its session, not the thread and the
                        // other sessions pinned to it.
                        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)).is_err() {
                            tracing::error!(thread = i, "a live session's step panicked");
                        }
                    }
                })?;
            workers.push(Worker {
                jobs,
                sessions: Arc::new(AtomicUsize::new(0)),
            });
        }
        Ok(LivePool { workers })
    }

    /// Pins a new session to the worker with the fewest sessions.
    fn pin(&self) -> Pinned {
        let (index, w) = self
            .workers
            .iter()
            .enumerate()
            .min_by_key(|(_, w)| w.sessions.load(Ordering::Relaxed))
            .expect("the pool has a worker");
        w.sessions.fetch_add(1, Ordering::Relaxed);
        Pinned {
            jobs: w.jobs.clone(),
            sessions: Arc::clone(&w.sessions),
            index,
        }
    }
}

/// A session's worker: its jobs run there, one at a time, in order.
struct Pinned {
    jobs: mpsc::Sender<Job>,
    sessions: Arc<AtomicUsize>,
    index: usize,
}

impl Drop for Pinned {
    fn drop(&mut self) {
        self.sessions.fetch_sub(1, Ordering::Relaxed);
    }
}

impl Pinned {
    /// Runs `f` on the session's worker and waits for its result.
    async fn run<T: Send + 'static>(&self, f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = oneshot::channel();
        let job: Job = Box::new(move || {
            let _ = tx.send(f());
        });
        if self.jobs.send(job).is_err() {
            // The worker threads live as long as the process.
            unreachable!("live stepping thread {} stopped", self.index);
        }
        match rx.await {
            Ok(v) => v,
            // The job panicked (logged on its thread): this session's task ends here.
            Err(_) => panic!("a live session's step panicked on thread {}", self.index),
        }
    }
}

/// The live sessions of a server: the stepping pool, the bound on sessions at once and the
/// sessions' tasks (so that shutdown can wait for them to be stored).
#[derive(Debug)]
pub struct LiveHub {
    pool: LivePool,
    slots: Arc<Semaphore>,
    tasks: TaskTracker,
    silence: Duration,
    /// The Foxglove SDK context whose WebSocket server shows the sessions live
    /// (`icms serve --foxglove`), and the number of the last session published.
    foxglove: std::sync::OnceLock<Arc<foxglove::Context>>,
    published: std::sync::atomic::AtomicU64,
}

impl LiveHub {
    /// A hub for at most `max_sessions` sessions at once, stepped on `threads` threads,
    /// ending a session after `silence` without a sample.
    pub fn new(max_sessions: usize, threads: usize, silence: Duration) -> std::io::Result<LiveHub> {
        Ok(LiveHub {
            pool: LivePool::new(threads)?,
            slots: Arc::new(Semaphore::new(max_sessions.max(1))),
            tasks: TaskTracker::new(),
            silence,
            foxglove: std::sync::OnceLock::new(),
            published: std::sync::atomic::AtomicU64::new(0),
        })
    }

    /// Publishes every live session from now on through `context` (its Foxglove WebSocket
    /// server), each under `/live/N/` (N counting sessions from 1). Set once.
    pub fn publish_to(&self, context: Arc<foxglove::Context>) {
        let _ = self.foxglove.set(context);
    }

    /// The live view of a new session, when the sessions are published.
    fn view(&self, started_at: std::time::SystemTime) -> Option<services::session::LiveView> {
        let context = self.foxglove.get()?;
        let n = self.published.fetch_add(1, Ordering::Relaxed) + 1;
        let epoch_ns = started_at
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        match services::session::LiveView::new(context, &format!("/live/{n}"), epoch_ns) {
            Ok(v) => Some(v),
            Err(e) => {
                tracing::warn!(error = %e, "a live session could not be published to Foxglove");
                None
            }
        }
    }

    /// Waits at most `grace` for every live session to be finished and stored (at shutdown,
    /// after the sessions were told to stop). Returns whether all were.
    pub async fn wait_stored(&self, grace: Duration) -> bool {
        self.tasks.close();
        tokio::time::timeout(grace, self.tasks.wait()).await.is_ok()
    }
}

/// Opens a live glove session (WebSocket). The protocol: the client's first message is a JSON
/// text frame `{"type": "start", "hand": ..., "object": {...}, ...}`; the server answers
/// `{"type": "started", "dofs": [...], "fingers": [...], ...}`. The client then streams glove
/// samples as binary `icms.live.Sample` protobuf frames (services/proto/icms/live.proto), each
/// answered with a binary `icms.live.Feedback`; the DFS steps at 1 kHz of the samples' time,
/// interpolating between samples. Events (`error`, `stale`, `resumed`, `ended`, `stored`) are
/// JSON text frames. With `"assist": {"mode": "suggest"}` (or `"apply"` with `"robot": HAND`)
/// the assistant sends `recognised` / `unknown` events as it recognises the stored skill being
/// performed, and in `apply` mode `applying`, `robot` and `robot_report` as the robot hand
/// applies it. `{"type": "end"}` ends the session: it is stored and segmented, `stored` names
/// its skills (each `new`, or the stored skill it matched), and the server closes. Full
/// description: docs/live.md.
#[utoipa::path(get, path = "/live", tag = "live",
    security((), ("bearer" = [])),
    responses(
        (status = 101, description = "Switching to the WebSocket protocol: the live session begins"),
        (status = 400, description = "Not a WebSocket upgrade request", body = ProblemBody, content_type = "application/problem+json"),
        (status = 503, description = "Every live session slot is taken, or the server is stopping", body = ProblemBody, content_type = "application/problem+json"),
    ))]
async fn live(
    _: WriteAccess,
    State(st): State<AppState>,
    upgrade: WebSocketUpgrade,
) -> Result<Response, Problem> {
    if st.shutdown_token().is_cancelled() {
        return Err(Problem::unavailable("the server is shutting down"));
    }
    let hub = st.live();
    let permit = Arc::clone(&hub.slots).try_acquire_owned().map_err(|_| {
        Problem::busy(
            "every live session slot is taken (icms serve --max-live); try again later",
            5,
        )
    })?;
    let tasks = hub.tasks.clone();
    Ok(upgrade
        // Frames are a few hundred bytes: tungstenite's default 128 KiB read buffer is zeroed
        // as it is read into, a memset per frame that perf showed among the top entries.
        .read_buffer_size(READ_BUFFER_BYTES)
        .max_message_size(MAX_FRAME_BYTES)
        .max_frame_size(MAX_FRAME_BYTES)
        .on_upgrade(move |socket| async move {
            tasks.track_future(run_session(socket, st, permit)).await
        }))
}

/// Sends an event; a socket that is gone is ignored (the session is stored all the same).
async fn send_event(socket: &mut WebSocket, event: &Event) -> bool {
    let text = serde_json::to_string(event).unwrap_or_default();
    socket.send(Message::Text(text.into())).await.is_ok()
}

async fn send_error(socket: &mut WebSocket, t_ns: Option<u64>, message: String) -> bool {
    send_event(socket, &Event::Error { t_ns, message }).await
}

/// Closes with `code` and `reason` (cut to the 123 bytes a close frame has).
async fn close(socket: &mut WebSocket, code: u16, reason: &str) {
    let mut end = reason.len().min(120);
    while !reason.is_char_boundary(end) {
        end -= 1;
    }
    let _ = socket
        .send(Message::Close(Some(CloseFrame {
            code,
            reason: reason[..end].into(),
        })))
        .await;
}

/// WebSocket close code: the peer broke the protocol (RFC 6455 §7.4.1).
const CLOSE_POLICY: u16 = 1008;
/// WebSocket close code: normal closure.
const CLOSE_NORMAL: u16 = 1000;
/// WebSocket close code: the server is going away.
const CLOSE_AWAY: u16 = 1001;

/// One live session, from the `start` message to `stored`.
async fn run_session(mut socket: WebSocket, st: AppState, _permit: OwnedSemaphorePermit) {
    let start = match read_start(&mut socket, &st).await {
        Ok(start) => start,
        Err(message) => {
            send_error(&mut socket, None, message.clone()).await;
            close(&mut socket, CLOSE_POLICY, &message).await;
            return;
        }
    };
    let (config, assist) = match resolve(&st, &start).await {
        Ok(c) => c,
        Err(message) => {
            send_error(&mut socket, None, message.clone()).await;
            close(&mut socket, CLOSE_POLICY, &message).await;
            return;
        }
    };
    let pinned = st.live().pool.pin();
    let store = st.store().clone();
    let view = st.live().view(config.started_at);
    let opened = pinned
        .run(move || -> Result<(StagedBlob, Box<LiveSession>), String> {
            let mut staged = store.stage_upload().map_err(|e| e.to_string())?;
            let out = SessionOut::Stream {
                out: Box::new(staged.writer().map_err(|e| e.to_string())?),
                name: staged.path().to_path_buf(),
            };
            let session = LiveSession::start_assisted(&config, out, view, assist)
                .map_err(|e| e.to_string())?;
            // Boxed: the session (its DFS some tens of kB) moves to the worker and back with
            // every frame, a pointer instead of a copy.
            Ok((staged, Box::new(session)))
        })
        .await;
    let (staged, session) = match opened {
        Ok(v) => v,
        Err(message) => {
            tracing::warn!(error = %message, "a live session could not start");
            send_error(
                &mut socket,
                None,
                format!("the session could not start: {message}"),
            )
            .await;
            close(&mut socket, 1011, "the session could not start").await;
            return;
        }
    };
    send_event(&mut socket, &session.started_event(st.live().silence)).await;
    tracing::info!(hand = %start.hand, "live session started");
    let (session, reason) = stream(&mut socket, &st, &pinned, session).await;
    let finished = pinned.run(move || session.finish(reason)).await;
    let stats = match finished {
        Ok(stats) => stats,
        Err(e) => {
            tracing::error!(error = %e, "finishing a live session's recording failed");
            send_error(&mut socket, None, format!("the recording failed: {e}")).await;
            close(&mut socket, 1011, "the recording failed").await;
            return;
        }
    };
    for text in &stats.assist_tail {
        let _ = socket.send(Message::Text(text.clone().into())).await;
    }
    send_event(
        &mut socket,
        &Event::Ended {
            reason,
            samples: stats.samples,
            refused: stats.refused,
            session_ns: stats.ticks.saturating_sub(1) * dfs_core::operator::TICK_NS,
        },
    )
    .await;
    if stats.ticks < 2 {
        let message = format!(
            "the session holds {} DFS tick(s) of the 2 a stored session needs: nothing stored",
            stats.ticks
        );
        send_error(&mut socket, None, message.clone()).await;
        close(&mut socket, CLOSE_NORMAL, "nothing to store").await;
        return;
    }
    match store_session(&st, staged).await {
        Ok(event) => {
            if let Event::Stored {
                session_id, skills, ..
            } = &event
            {
                tracing::info!(
                    session_id,
                    skills = skills.len(),
                    reason = reason.name(),
                    samples = stats.samples,
                    "live session stored"
                );
            }
            send_event(&mut socket, &event).await;
            close(&mut socket, CLOSE_NORMAL, "stored").await;
        }
        Err(p) => {
            tracing::error!(problem = %p, "storing a live session failed");
            send_error(
                &mut socket,
                None,
                format!("storing the session failed: {}", p.detail),
            )
            .await;
            close(&mut socket, 1011, "storing the session failed").await;
        }
    }
}

/// Waits for the `start` message (at most [`START_TIMEOUT`]).
async fn read_start(socket: &mut WebSocket, st: &AppState) -> Result<StartMessage, String> {
    let deadline = Instant::now() + START_TIMEOUT;
    loop {
        let msg = tokio::select! {
            m = tokio::time::timeout_at(deadline, socket.recv()) => m,
            () = st.shutdown_token().cancelled() => {
                return Err("the server is shutting down".to_owned())
            }
        };
        let msg = match msg {
            Err(_) => {
                return Err(format!(
                    "no start message within {} s of connecting",
                    START_TIMEOUT.as_secs()
                ))
            }
            Ok(None) | Ok(Some(Err(_))) => return Err("the connection closed".to_owned()),
            Ok(Some(Ok(m))) => m,
        };
        match msg {
            Message::Text(text) => {
                return match ClientMessage::parse(text.as_str()) {
                    Ok(ClientMessage::Start(start)) => Ok(*start),
                    Ok(ClientMessage::End) => {
                        Err("the first message must be start, not end".to_owned())
                    }
                    Err(e) => Err(format!("the start message is invalid: {e}")),
                };
            }
            Message::Binary(_) => {
                return Err(
                    "the first message must be a JSON text frame {\"type\": \"start\", ...}, \
                     not a binary frame"
                        .to_owned(),
                )
            }
            Message::Close(_) => return Err("the connection closed".to_owned()),
            Message::Ping(_) | Message::Pong(_) => continue,
        }
    }
}

/// A hand by name: built in, or stored (`GET /api/v1/hands`). `field` names the start's field
/// in errors.
async fn hand_named(
    st: &AppState,
    name: &str,
    field: &str,
) -> Result<services::replay::LoadedHand, String> {
    if dfs_core::hand::BUILTIN_HANDS.contains(&name) {
        return services::replay::load_builtin_hand(name).map_err(|e| format!("{field}: {e}"));
    }
    let stored = match st.store().get_hand(name).await {
        Ok(h) => h,
        Err(StoreError::HandNotFound(name)) => {
            return Err(format!(
                "{field}: no hand named {name:?} (a built-in hand or one of GET /api/v1/hands)"
            ))
        }
        Err(e) => return Err(format!("{field}: {e}")),
    };
    stored.load().map_err(|e| format!("{field}: {e}"))
}

/// The session's set-up from its `start` message: the hand looked up (built-in or stored),
/// every field validated, and the assistant's set-up when it is on (the stored skills as they
/// are now, the robot hand looked up). Errors name the field.
async fn resolve(
    st: &AppState,
    start: &StartMessage,
) -> Result<(LiveConfig, Option<AssistSetup>), String> {
    let (hand, urdf) = if start.hand == "glove10" {
        (HandModel::glove10(), None)
    } else {
        let loaded = hand_named(st, &start.hand, "hand").await?;
        (loaded.model, loaded.urdf)
    };
    let config = LiveConfig::from_start(start, hand, urdf).map_err(|e| e.to_string())?;
    let assist = match config.assist {
        AssistMode::Off => None,
        mode => {
            let apply = match (mode, &start.assist.robot) {
                (AssistMode::Apply, Some(robot)) => {
                    let robot = hand_named(st, robot, "assist.robot").await?;
                    let store = st.store().clone();
                    let runtime = tokio::runtime::Handle::current();
                    // Called on the assistant's thread, never on the runtime's.
                    let loader: SkillLoader = Box::new(move |id| {
                        runtime
                            .block_on(store.get_skill(id))
                            .map(|s| s.params)
                            .map_err(|e| e.to_string())
                    });
                    Some((robot, loader))
                }
                _ => None,
            };
            Some(AssistSetup {
                index: st.store().recognition_index(),
                objects: ObjectInfo::of_scene(&config.scene),
                params: RecogniserParams::default(),
                apply,
            })
        }
    };
    Ok((config, assist))
}

/// Streams samples until the session ends; returns the session and why it ended.
async fn stream(
    socket: &mut WebSocket,
    st: &AppState,
    pinned: &Pinned,
    mut session: Box<LiveSession>,
) -> (Box<LiveSession>, EndReason) {
    let silence = st.live().silence;
    let mut clock = SampleClock {
        last_sample: Instant::now(),
        any_sample: false,
        stale: false,
    };
    loop {
        let wait_until = if clock.any_sample && !clock.stale {
            clock.last_sample + STALE_AFTER
        } else {
            clock.last_sample + silence
        };
        let msg = tokio::select! {
            biased;
            () = st.shutdown_token().cancelled() => {
                close(socket, CLOSE_AWAY, "the server is shutting down").await;
                return (session, EndReason::ServerStopping);
            }
            m = tokio::time::timeout_at(wait_until, socket.recv()) => m,
        };
        let msg = match msg {
            Err(_) if clock.any_sample && !clock.stale => {
                clock.stale = true;
                session = go_stale(socket, pinned, session).await;
                continue;
            }
            Err(_) => {
                let message = format!(
                    "no sample for {} s: the session ends, stored as incomplete",
                    silence.as_secs_f64()
                );
                send_error(socket, None, message).await;
                return (session, EndReason::Silent);
            }
            Ok(None) | Ok(Some(Err(_))) => return (session, EndReason::Disconnected),
            Ok(Some(Ok(m))) => m,
        };
        match msg {
            Message::Binary(frame) => {
                let (s, ended) = answer_sample(socket, pinned, session, frame, &mut clock).await;
                session = s;
                if let Some(reason) = ended {
                    return (session, reason);
                }
            }
            Message::Text(text) => {
                if let Some(reason) = on_text(socket, text.as_str()).await {
                    return (session, reason);
                }
            }
            Message::Close(_) => return (session, EndReason::Disconnected),
            Message::Ping(_) | Message::Pong(_) => {}
        }
    }
}

/// When a session last had a sample: what [`stream`] waits for next (the next sample until
/// [`STALE_AFTER`], then until the silence limit).
struct SampleClock {
    /// When the last sample was answered.
    last_sample: Instant,
    /// A sample was answered.
    any_sample: bool,
    /// The session is in a stale period (no sample for [`STALE_AFTER`]).
    stale: bool,
}

/// No sample came for [`STALE_AFTER`]: sends the zero-force feedback and the `stale` event.
async fn go_stale(
    socket: &mut WebSocket,
    pinned: &Pinned,
    mut session: Box<LiveSession>,
) -> Box<LiveSession> {
    let (session, frame) = pinned
        .run(move || {
            let frame = Bytes::copy_from_slice(session.stale_feedback());
            (session, frame)
        })
        .await;
    let _ = socket.send(Message::Binary(frame)).await;
    send_event(
        socket,
        &Event::Stale {
            session_ns: session.session_ns(),
        },
    )
    .await;
    session
}

/// Steps the session on the sample `frame` and sends what it got: the error refusing it, or
/// its feedback (then `resumed`, a DFS failure and the assistant's events), the sample noted
/// on `clock`. Returns the session, and why it ended if the client is gone.
async fn answer_sample(
    socket: &mut WebSocket,
    pinned: &Pinned,
    session: Box<LiveSession>,
    frame: Bytes,
    clock: &mut SampleClock,
) -> (Box<LiveSession>, Option<EndReason>) {
    let (session, reply) = pinned.run(move || step(session, frame)).await;
    match reply {
        Reply::Refused(e) => {
            send_error(socket, e.t_ns, e.message).await;
        }
        Reply::Answered {
            feedback,
            failure,
            resumed,
            events,
        } => {
            clock.any_sample = true;
            clock.last_sample = Instant::now();
            clock.stale = false;
            if socket.send(Message::Binary(feedback)).await.is_err() {
                return (session, Some(EndReason::Disconnected));
            }
            if resumed {
                send_event(
                    socket,
                    &Event::Resumed {
                        session_ns: session.session_ns(),
                    },
                )
                .await;
            }
            if let Some(e) = failure {
                send_error(socket, e.t_ns, e.message).await;
            }
            for text in events {
                if socket.send(Message::Text(text.into())).await.is_err() {
                    return (session, Some(EndReason::Disconnected));
                }
            }
        }
    }
    (session, None)
}

/// A text frame once the session has started: `end` ends it (`Some`); anything else is
/// answered with an error.
async fn on_text(socket: &mut WebSocket, text: &str) -> Option<EndReason> {
    match ClientMessage::parse(text) {
        Ok(ClientMessage::End) => return Some(EndReason::Ended),
        Ok(ClientMessage::Start(_)) => {
            send_error(
                socket,
                None,
                "the session has started already: send samples, or end".to_owned(),
            )
            .await;
        }
        Err(e) => {
            send_error(
                socket,
                None,
                format!(
                    "a text frame must be {{\"type\": \"end\"}} once the session has \
                     started: {e}"
                ),
            )
            .await;
        }
    }
    None
}

/// What a sample frame got.
enum Reply {
    Refused(SampleError),
    Answered {
        feedback: Bytes,
        failure: Option<SampleError>,
        resumed: bool,
        events: Vec<String>,
    },
}

/// Steps one frame (on the session's worker).
fn step(mut session: Box<LiveSession>, frame: Bytes) -> (Box<LiveSession>, Reply) {
    let reply = match session.on_frame(&frame) {
        Err(e) => Reply::Refused(e),
        Ok(answer) => Reply::Answered {
            feedback: Bytes::copy_from_slice(answer.feedback),
            failure: answer.failure,
            resumed: answer.resumed,
            events: answer.events,
        },
    };
    (session, reply)
}

/// Stores a finished recording like an upload: analysed from the file on a blocking thread
/// (with an ingest turn), then moved to its content address with its rows.
async fn store_session(st: &AppState, mut staged: StagedBlob) -> Result<Event, Problem> {
    let _turn = st.ingest_turn().await?;
    let (staged, meta, skills) = tokio::task::spawn_blocking(move || {
        staged.finish().map_err(|e| Problem::internal(&e))?;
        let (meta, skills) = services::ingest::analyse_source(&SessionSource::File(staged.path()))
            .map_err(|e| Problem::internal(&format!("a live session did not read back: {e}")))?;
        Ok::<_, Problem>((staged, meta, skills))
    })
    .await
    .map_err(|e| Problem::internal(&e))??;
    let incomplete = meta
        .extra
        .get("live")
        .and_then(|l| l.get("incomplete"))
        .is_some_and(|v| v == "true");
    let out = st.store().ingest_staged(staged, meta, skills).await?;
    Ok(Event::Stored {
        session_id: out.session_id,
        created: out.created,
        incomplete,
        skills: out
            .skill_ids
            .iter()
            .zip(&out.matched_skill_ids)
            .map(|(&id, &matched)| StoredSkill {
                skill_id: id,
                new: matched.is_none(),
                matched_skill_id: matched,
            })
            .collect(),
    })
}
