//! A live-session client (`icms glove --connect`, `icms bench live` and the tests): streams
//! glove samples to `GET /api/v1/live` over a WebSocket, one at a time (each answered before
//! the next is sent), and collects the events, the round trips and the stored session.

use std::time::{Duration, Instant};

use bytes::Bytes;
use futures_util::{SinkExt, StreamExt};
use prost::Message as _;
use serde::Serialize;
use services::live::{proto, ClientMessage, Event, StartMessage};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message;

/// One glove sample to send, already encoded ([`proto::Sample`]), with its time.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The sample's `t_ns`.
    pub t_ns: u64,
    /// The encoded sample.
    pub bytes: Bytes,
}

impl Frame {
    /// Encodes a sample.
    pub fn of(sample: &proto::Sample) -> Frame {
        Frame {
            t_ns: sample.t_ns,
            bytes: Bytes::from(sample.encode_to_vec()),
        }
    }
}

/// How to stream.
#[derive(Debug, Clone, Default)]
pub struct ClientOptions {
    /// Bearer token for a server that needs one.
    pub token: Option<String>,
    /// Send each sample at its time (relative to the first) instead of as fast as the server
    /// answers.
    pub realtime: bool,
}

/// What a live client saw: the summary `icms glove` prints last.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ClientSummary {
    /// Always `summary`.
    #[serde(rename = "type")]
    pub kind: &'static str,
    /// Samples sent.
    pub samples_sent: u64,
    /// Feedback frames received in answer to a sample.
    pub feedback_received: u64,
    /// Samples refused by the server (an `error` event instead of feedback).
    pub refused: u64,
    /// Zero-force feedback frames received because no sample came in time.
    pub stale_frames: u64,
    /// Round trip sample → answer, µs: median.
    pub p50_us: f64,
    /// 90th percentile.
    pub p90_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// 99.9th percentile.
    pub p999_us: f64,
    /// Slowest.
    pub max_us: f64,
    /// Session time (ns) of the first feedback in which a fingertip transmitted force.
    pub first_contact_ns: Option<u64>,
    /// The stored session's id.
    pub session_id: Option<i64>,
    /// Its skills.
    pub skill_ids: Vec<i64>,
    /// The assistant's events (`recognised`, `unknown`, `applying`, `robot`, `robot_report`,
    /// ...), in order, as the server sent them.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub assist_events: Vec<serde_json::Value>,
    /// Per stored skill: the stored skill it matched (`None`: stored as new).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub matched_skill_ids: Vec<Option<i64>>,
    /// Whether it was stored as incomplete.
    pub incomplete: Option<bool>,
    /// Wall-clock seconds from connecting to `stored`.
    pub seconds: f64,
    /// Every round trip (µs), for aggregating several clients; not printed.
    #[serde(skip)]
    pub round_trips_us: Vec<f64>,
}

/// Why a client failed.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ClientError(pub String);

fn err(context: &str, e: impl std::fmt::Display) -> ClientError {
    ClientError(format!("{context}: {e}"))
}

/// The value at fraction `p` of sorted `v` (0 for none).
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Connects to `url`, sends `start`, streams `frames` and ends the session; `on_event` sees
/// every event as it comes (with the session time it came at). Returns the summary once the
/// server said `stored` (or closed).
pub async fn run(
    url: &str,
    start: &StartMessage,
    frames: impl IntoIterator<Item = Frame>,
    options: &ClientOptions,
    mut on_event: impl FnMut(&Event),
) -> Result<ClientSummary, ClientError> {
    let began = Instant::now();
    let mut ws = connect(url, options).await?;
    let assist_events = start_session(&mut ws, start, &mut on_event).await?;
    let mut summary = ClientSummary {
        kind: "summary",
        assist_events,
        ..ClientSummary::default()
    };
    let mut first_t: Option<(u64, Instant)> = None;
    for frame in frames {
        if options.realtime {
            let (t0, at) = *first_t.get_or_insert((frame.t_ns, Instant::now()));
            let due = at + Duration::from_nanos(frame.t_ns.saturating_sub(t0));
            tokio::time::sleep_until(due.into()).await;
        }
        let sent = Instant::now();
        let t_ns = frame.t_ns;
        ws.send(Message::Binary(frame.bytes))
            .await
            .map_err(|e| err("sending a sample", e))?;
        summary.samples_sent += 1;
        await_answer(&mut ws, t_ns, sent, &mut summary, &mut on_event).await?;
    }
    end_session(&mut ws, &mut summary, &mut on_event).await?;
    let mut sorted = summary.round_trips_us.clone();
    sorted.sort_by(f64::total_cmp);
    summary.p50_us = percentile(&sorted, 0.5);
    summary.p90_us = percentile(&sorted, 0.9);
    summary.p99_us = percentile(&sorted, 0.99);
    summary.p999_us = percentile(&sorted, 0.999);
    summary.max_us = sorted.last().copied().unwrap_or(0.0);
    summary.seconds = began.elapsed().as_secs_f64();
    Ok(summary)
}

/// The WebSocket of a live session.
type LiveSocket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// Opens the WebSocket to `url` (with the bearer token of `options`, if any).
async fn connect(url: &str, options: &ClientOptions) -> Result<LiveSocket, ClientError> {
    let mut request = url
        .into_client_request()
        .map_err(|e| err(&format!("--connect {url}"), e))?;
    if let Some(token) = &options.token {
        let value = format!("Bearer {token}")
            .parse()
            .map_err(|e| err("the token", e))?;
        request.headers_mut().insert("authorization", value);
    }
    // A small read buffer: frames are a few hundred bytes (tungstenite's default 128 KiB is
    // zeroed as it is read into).
    let config = tokio_tungstenite::tungstenite::protocol::WebSocketConfig::default()
        .read_buffer_size(8 * 1024);
    let (ws, _) = tokio_tungstenite::connect_async_with_config(request, Some(config), true)
        .await
        .map_err(|e| err(&format!("connecting to {url}"), e))?;
    Ok(ws)
}

/// Sends `start` and reads up to its answer, `started` (an error and a close refuse the
/// session); the assistant's events that came before it.
async fn start_session(
    ws: &mut LiveSocket,
    start: &StartMessage,
    on_event: &mut impl FnMut(&Event),
) -> Result<Vec<serde_json::Value>, ClientError> {
    let start_text = serde_json::to_string(&ClientMessage::Start(Box::new(start.clone())))
        .map_err(|e| err("encoding the start message", e))?;
    ws.send(Message::Text(start_text.into()))
        .await
        .map_err(|e| err("sending start", e))?;
    // The answer to start: `started`, or an error and a close.
    let mut summary_assist = Vec::new();
    loop {
        match next(ws).await? {
            Incoming::Event(e @ Event::Started { .. }) => {
                on_event(&e);
                return Ok(summary_assist);
            }
            Incoming::Event(Event::Error { message, .. }) => {
                return Err(ClientError(format!(
                    "the server refused the session: {message}"
                )))
            }
            Incoming::Event(e) => on_event(&e),
            Incoming::Assist(v) => summary_assist.push(v),
            Incoming::Feedback(_) => {
                return Err(ClientError("feedback before the session started".into()))
            }
            Incoming::Closed(reason) => {
                return Err(ClientError(format!(
                    "the server closed the connection: {reason}"
                )))
            }
        }
    }
}

/// Reads up to the answer to the sample of time `t_ns` sent at `sent`: its feedback, or the
/// error refusing it. Events may come before the answer; a stale frame is not the answer.
async fn await_answer(
    ws: &mut LiveSocket,
    t_ns: u64,
    sent: Instant,
    summary: &mut ClientSummary,
    on_event: &mut impl FnMut(&Event),
) -> Result<(), ClientError> {
    loop {
        match next(ws).await? {
            Incoming::Feedback(fb) if fb.stale => summary.stale_frames += 1,
            Incoming::Feedback(fb) => {
                summary
                    .round_trips_us
                    .push(sent.elapsed().as_secs_f64() * 1e6);
                summary.feedback_received += 1;
                if summary.first_contact_ns.is_none() && fb.fingers.iter().any(|f| f.in_contact) {
                    summary.first_contact_ns = Some(fb.session_ns);
                }
                // A DFS failure comes as an error right after the answer; it is read with
                // the next sample's answer.
                return Ok(());
            }
            Incoming::Event(e @ Event::Error { t_ns: at, .. })
                if at.is_none() || at == Some(t_ns) =>
            {
                on_event(&e);
                // Refused (not stepped): no feedback comes for it, unless this was a DFS
                // failure after the feedback (then the feedback came first).
                summary.refused += 1;
                return Ok(());
            }
            Incoming::Event(e) => on_event(&e),
            Incoming::Assist(v) => summary.assist_events.push(v),
            Incoming::Closed(reason) => {
                return Err(ClientError(format!(
                    "the server closed the connection mid-session: {reason}"
                )))
            }
        }
    }
}

/// Sends `end` and reads up to the close, taking the stored session from `stored`.
async fn end_session(
    ws: &mut LiveSocket,
    summary: &mut ClientSummary,
    on_event: &mut impl FnMut(&Event),
) -> Result<(), ClientError> {
    let end = serde_json::to_string(&ClientMessage::End).unwrap_or_default();
    ws.send(Message::Text(end.into()))
        .await
        .map_err(|e| err("sending end", e))?;
    loop {
        match next(ws).await? {
            Incoming::Event(e) => {
                on_event(&e);
                if let Event::Stored {
                    session_id,
                    incomplete,
                    skills,
                    ..
                } = &e
                {
                    summary.session_id = Some(*session_id);
                    summary.incomplete = Some(*incomplete);
                    summary.skill_ids = skills.iter().map(|s| s.skill_id).collect();
                    summary.matched_skill_ids = skills.iter().map(|s| s.matched_skill_id).collect();
                }
            }
            Incoming::Feedback(fb) if fb.stale => summary.stale_frames += 1,
            Incoming::Feedback(_) => {}
            Incoming::Assist(v) => summary.assist_events.push(v),
            Incoming::Closed(_) => return Ok(()),
        }
    }
}

enum Incoming {
    Event(Event),
    /// An event of the assistant (`recognised`, `unknown`, `robot`, ...).
    Assist(serde_json::Value),
    Feedback(proto::Feedback),
    Closed(String),
}

async fn next<S>(ws: &mut S) -> Result<Incoming, ClientError>
where
    S: futures_util::Stream<Item = Result<Message, tokio_tungstenite::tungstenite::Error>> + Unpin,
{
    loop {
        let Some(msg) = ws.next().await else {
            return Ok(Incoming::Closed("the connection ended".into()));
        };
        match msg {
            Err(e) => return Ok(Incoming::Closed(e.to_string())),
            Ok(Message::Text(text)) => {
                if let Ok(event) = serde_json::from_str::<Event>(text.as_str()) {
                    return Ok(Incoming::Event(event));
                }
                // The assistant's events have types of their own.
                let value: serde_json::Value = serde_json::from_str(text.as_str())
                    .map_err(|e| err(&format!("an event from the server ({text})"), e))?;
                if value.get("type").and_then(|t| t.as_str()).is_none() {
                    return Err(ClientError(format!(
                        "an event from the server without a type: {text}"
                    )));
                }
                return Ok(Incoming::Assist(value));
            }
            Ok(Message::Binary(bytes)) => {
                let fb = proto::Feedback::decode(bytes.as_ref())
                    .map_err(|e| err("a feedback frame from the server", e))?;
                return Ok(Incoming::Feedback(fb));
            }
            Ok(Message::Close(frame)) => {
                return Ok(Incoming::Closed(
                    frame.map(|f| f.reason.to_string()).unwrap_or_default(),
                ))
            }
            Ok(_) => continue,
        }
    }
}

/// The samples of the simulated operator running `scenario` (glove10) for `duration` seconds
/// (default: its script), every `every`th tick (1: 1 kHz), as the glove would send them:
/// measured joint angles, operator torques and the wrist pose.
pub fn simulated_frames(
    scenario: &dfs_core::scenario::Scenario,
    duration: Option<f64>,
    every: u64,
) -> Result<Vec<Frame>, ClientError> {
    simulated_glove(scenario, duration, every).map(|g| g.frames)
}

/// What the simulated operator's glove sends ([`simulated_glove`]).
#[derive(Debug)]
pub struct SimulatedGlove {
    /// The samples, as [`simulated_frames`] gives them.
    pub frames: Vec<Frame>,
    /// Whether the operator's grasp is a power grasp with whole-hand contact
    /// ([`dfs_core::dfs::DfsParams::whole_hand`]): a live session of it needs the start
    /// message's `whole_hand` for the same contacts.
    pub whole_hand: bool,
}

/// [`simulated_frames`] and whether the simulated grasp uses the whole hand.
pub fn simulated_glove(
    scenario: &dfs_core::scenario::Scenario,
    duration: Option<f64>,
    every: u64,
) -> Result<SimulatedGlove, ClientError> {
    let mut sim = dfs_core::operator::Simulation::new(
        scenario,
        dfs_core::hand::HandModel::glove10(),
        duration,
    )
    .map_err(|e| err(&format!("scenario {:?}", scenario.name), e))?;
    let whole_hand = sim.dfs().params().whole_hand;
    let mut frames = Vec::with_capacity(sim.total_ticks() as usize / every.max(1) as usize + 1);
    let mut sample = proto::Sample::default();
    loop {
        match sim.step() {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(err(&format!("scenario {:?}", scenario.name), e)),
        }
        if sim.ticks().saturating_sub(1) % every.max(1) != 0 {
            continue;
        }
        let (q, tau, base) = sim.sample();
        sample.t_ns = sim.time_ns();
        sample.q.clear();
        sample.q.extend_from_slice(q);
        sample.tau.clear();
        sample.tau.extend_from_slice(tau);
        sample.wrist = Some(pose(base));
        frames.push(Frame::of(&sample));
    }
    Ok(SimulatedGlove { frames, whole_hand })
}

/// The samples of a glove recording, at its own times: its angles, its torques when it has
/// them, its wrist poses when it has them.
pub fn recording_frames(rec: &services::session::import::GloveRecording) -> Vec<Frame> {
    let n = rec.names.len();
    let mut sample = proto::Sample::default();
    (0..rec.len())
        .map(|i| {
            sample.t_ns = rec.times_ns[i];
            sample.q.clear();
            sample.q.extend_from_slice(&rec.q[i * n..(i + 1) * n]);
            sample.tau.clear();
            if let Some(tau) = &rec.tau {
                sample.tau.extend_from_slice(&tau[i * n..(i + 1) * n]);
            }
            sample.wrist = rec.wrist_at(rec.times_ns[i]).map(|w| pose(&w));
            Frame::of(&sample)
        })
        .collect()
}

/// A pose as the live protocol sends it.
pub fn pose(iso: &dfs_core::math::Isometry) -> proto::Pose {
    let t = iso.translation.vector;
    let r = iso.rotation;
    proto::Pose {
        position: Some(proto::Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        }),
        orientation: Some(proto::Quaternion {
            x: r.i,
            y: r.j,
            z: r.k,
            w: r.w,
        }),
    }
}
