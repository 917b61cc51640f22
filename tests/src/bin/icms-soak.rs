//! `icms-soak`: a soak test of the real `icms serve` process (issue 17).
//!
//! ```sh
//! cargo run --release -p tests --bin icms-soak -- [--minutes 10] [--clients 32] \
//!     [--bad-fraction 0.1] [--seed 1] [--icms PATH] [--json]
//! ```
//!
//! It simulates eight distinct short sessions (2-5 s) in memory, starts `icms serve --no-demo`
//! on 127.0.0.1 port 0 over a temporary data directory, uploads two of them so that there are
//! skills, and then runs `--clients` concurrent clients for `--minutes`. Each client loops,
//! picking by weight: an upload (one of the prepared sessions; a repeated one answers 200),
//! a query (skills with random filters, sort, limit and cursor; one skill; similar skills;
//! sessions; one session and its MCAP; hands; replays; `/healthz`), a simulation (a built-in
//! scenario, random seed, 1-3 s) or a replay (a stored skill on a built-in hand); with
//! probability `--bad-fraction` it sends a bad request instead (malformed JSON, a JSON array
//! body, a truncated or corrupted MCAP, an unknown route, a bad filter value, an unknown query
//! parameter, a duplicate JSON key, a scenario with an invalid field, a wrong content type, a
//! 100 000-deep nested JSON array, ...). Only 127.0.0.1 is called, and no request starts after
//! the duration.
//!
//! Measured: every response by status and by kind of request (and endpoint), latencies, 503s
//! with `Retry-After` ("busy": the server shedding load as documented, allowed and reported
//! apart; the client then waits as told), any other 5xx, transport errors (a request that got
//! no HTTP answer: reset, closed, timed out), and the server's resident memory (`VmRSS` and
//! `VmHWM` of `/proc/PID/status`) every second: at the end of warm-up (60 s; half the run when
//! it is shorter than 2 minutes), peak, final, and the growth after warm-up.
//!
//! It passes (exit 0) when: no 5xx other than a busy 503, no transport error, the server was
//! alive throughout, its resident memory grew after warm-up by at most
//! max(20 % of the warm-up value, 64 MiB) (see [`rss_tolerance`]), and after SIGTERM it exits
//! with status 0 within 30 s. Otherwise it exits 1 and prints the failing requests and the tail
//! of the server's log. `--json` prints the summary as one JSON object.
//!
//! The server is this same program: run with `serve` as its first argument it is the `icms`
//! command line (`api::cli::run()`, with `icms`'s allocator), so `cargo run` always soaks the
//! current sources. `--icms PATH` soaks another build instead (e.g. `target/release/icms`).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use reqwest::header::{CONTENT_TYPE, RETRY_AFTER};
use reqwest::Method;
use serde_json::{json, Value};
use tests::{ServerProcess, MCAP};

/// Counts allocations, as in the real `icms` binary: this program is the server too.
#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

const USAGE: &str = "\
usage: icms-soak [--minutes M] [--clients N] [--bad-fraction F] [--seed S] [--icms PATH] [--json]

Soaks a real `icms serve` (port 0, temporary data directory) with mixed uploads, queries,
simulations, replays and bad requests from N concurrent clients for M minutes; reports requests,
statuses, 5xx, busy 503s, transport errors and the server's resident memory. Exits 1 on a
non-busy 5xx, a transport error, a crash, memory growth after warm-up beyond
max(20 %, 64 MiB), or an unclean exit after SIGTERM.

  --minutes M        duration in minutes (default 10; fractions allowed)
  --clients N        concurrent clients (default 32)
  --bad-fraction F   share of bad requests, 0..1 (default 0.1)
  --seed S           seed of the clients' choices and the prepared sessions (default 1)
  --icms PATH        the icms binary to soak (default: this program, which is icms too)
  --json             print the summary as JSON";

/// Weights of the kinds of good request (out of their sum).
const WEIGHT_UPLOAD: u32 = 12;
const WEIGHT_QUERY: u32 = 62;
const WEIGHT_SIMULATION: u32 = 10;
const WEIGHT_REPLAY: u32 = 16;

/// Built-in hands a replay may use (`glove10` replays only its own skills well; the point here
/// is load, but it is kept to the robot hands).
const HANDS: [&str; 4] = ["allegro", "barrett", "inspire", "gripper"];

/// Longest time a client's request may take; above the server's own 120 s request limit, so
/// the server's answer (503) arrives first.
const CLIENT_TIMEOUT: Duration = Duration::from_secs(180);

/// The server must exit within this long after SIGTERM.
const EXIT_LIMIT: Duration = Duration::from_secs(30);

/// Failure samples kept (the counts are complete).
const MAX_SAMPLES: usize = 25;

#[derive(Debug, Clone)]
struct Options {
    minutes: f64,
    clients: usize,
    bad_fraction: f64,
    seed: u64,
    icms: Option<PathBuf>,
    json: bool,
}

fn parse_options(args: &[String]) -> Result<Option<Options>, String> {
    let mut o = Options {
        minutes: 10.0,
        clients: 32,
        bad_fraction: 0.1,
        seed: 1,
        icms: None,
        json: false,
    };
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        let (name, inline) = match arg.split_once('=') {
            Some((n, v)) if n.starts_with("--") => (n, Some(v.to_owned())),
            _ => (arg.as_str(), None),
        };
        let mut value = || {
            inline
                .clone()
                .or_else(|| it.next().cloned())
                .ok_or_else(|| format!("{name} needs a value"))
        };
        match name {
            "-h" | "--help" => return Ok(None),
            "--json" => o.json = true,
            "--minutes" => {
                let v = value()?;
                o.minutes = v
                    .parse()
                    .ok()
                    .filter(|m: &f64| m.is_finite() && *m > 0.0 && *m <= 24.0 * 60.0)
                    .ok_or_else(|| format!("--minutes must be in (0, 1440], got {v:?}"))?;
            }
            "--clients" => {
                let v = value()?;
                o.clients = v
                    .parse()
                    .ok()
                    .filter(|n| (1..=1024).contains(n))
                    .ok_or_else(|| format!("--clients must be in 1..=1024, got {v:?}"))?;
            }
            "--bad-fraction" => {
                let v = value()?;
                o.bad_fraction = v
                    .parse()
                    .ok()
                    .filter(|f: &f64| (0.0..=1.0).contains(f))
                    .ok_or_else(|| format!("--bad-fraction must be in [0, 1], got {v:?}"))?;
            }
            "--seed" => {
                let v = value()?;
                o.seed = v
                    .parse()
                    .map_err(|_| format!("--seed must be an unsigned integer, got {v:?}"))?;
            }
            "--icms" => o.icms = Some(PathBuf::from(value()?)),
            other => return Err(format!("unknown argument {other:?}")),
        }
    }
    Ok(Some(o))
}

/// A small deterministic generator (splitmix64): the clients' choices need no quality beyond
/// variety, and a seed makes a run's mix reproducible.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9e37_79b9_7f4a_7c15)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in `0..n` (`n > 0`).
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// The kind of a request, as counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Upload,
    Query,
    Simulation,
    Replay,
    Bad,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Upload => "upload",
            Kind::Query => "query",
            Kind::Simulation => "simulation",
            Kind::Replay => "replay",
            Kind::Bad => "bad",
        }
    }
}

/// What a request should get: a good request 2xx, a bad one 4xx. A mismatch is reported
/// (with samples) but is not by itself a failure of the soak: 5xx and memory are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    Success,
    ClientError,
}

/// One request to send.
struct Req {
    kind: Kind,
    /// The endpoint (or kind of bad request), for the per-endpoint counts.
    label: &'static str,
    method: Method,
    path: String,
    body: Option<(&'static str, Vec<u8>)>,
    expect: Expect,
}

impl Req {
    fn get(kind: Kind, label: &'static str, path: String) -> Self {
        Req {
            kind,
            label,
            method: Method::GET,
            path,
            body: None,
            expect: if kind == Kind::Bad {
                Expect::ClientError
            } else {
                Expect::Success
            },
        }
    }
    fn post(kind: Kind, label: &'static str, path: &str, ct: &'static str, body: Vec<u8>) -> Self {
        Req {
            method: Method::POST,
            body: Some((ct, body)),
            ..Req::get(kind, label, path.to_owned())
        }
    }
    fn post_json(kind: Kind, label: &'static str, path: &str, body: &Value) -> Self {
        let bytes = serde_json::to_vec(body).expect("JSON");
        Req::post(kind, label, path, "application/json", bytes)
    }
    fn bad_raw(
        label: &'static str,
        method: Method,
        path: &str,
        body: Option<(&'static str, Vec<u8>)>,
    ) -> Self {
        Req {
            method,
            body,
            ..Req::get(Kind::Bad, label, path.to_owned())
        }
    }
    fn describe(&self) -> String {
        let body = match &self.body {
            Some((ct, b)) => format!(" ({} bytes of {ct})", b.len()),
            None => String::new(),
        };
        format!("{} {} [{}]{body}", self.method, self.path, self.label)
    }
}

/// Ids the clients learned from the server's answers (never guessed).
#[derive(Default)]
struct Ids {
    sessions: Vec<i64>,
    skills: Vec<i64>,
    replays: Vec<i64>,
    /// Skill listings with a next page: their query and `next_cursor` (up to 64, the older
    /// ones replaced in turn).
    cursors: Vec<(String, String)>,
    cursors_seen: usize,
}

impl Ids {
    fn learn(&mut self, req: &Req, status: u16, body: &[u8]) {
        if !(200..300).contains(&status) || req.kind == Kind::Bad {
            return;
        }
        let Ok(v) = serde_json::from_slice::<Value>(body) else {
            return;
        };
        if let Some(id) = v["session_id"].as_i64() {
            if !self.sessions.contains(&id) {
                self.sessions.push(id);
            }
            for s in v["skills"].as_array().into_iter().flatten() {
                if let Some(id) = s["id"].as_i64() {
                    if !self.skills.contains(&id) {
                        self.skills.push(id);
                    }
                }
            }
        }
        if let Some(id) = v["replay_id"].as_i64() {
            if !self.replays.contains(&id) {
                self.replays.push(id);
            }
        }
        if let (Some(c), Some(query)) = (
            v["next_cursor"].as_str(),
            req.path.strip_prefix("/api/v1/skills?"),
        ) {
            // The same filters and sort with the cursor: a cursor is refused with another sort.
            let query: Vec<&str> = query
                .split('&')
                .filter(|p| !p.is_empty() && !p.starts_with("cursor="))
                .collect();
            let entry = (query.join("&"), c.to_owned());
            if self.cursors.len() < 64 {
                self.cursors.push(entry);
            } else {
                self.cursors[self.cursors_seen % 64] = entry;
            }
            self.cursors_seen += 1;
        }
    }
}

#[derive(Default)]
struct KindStats {
    requests: u64,
    statuses: BTreeMap<u16, u64>,
    busy: u64,
    server_errors: u64,
    transport_errors: u64,
    unexpected: u64,
    latencies_ms: Vec<f32>,
}

#[derive(Default)]
struct Stats {
    kinds: BTreeMap<Kind, KindStats>,
    endpoints: BTreeMap<&'static str, BTreeMap<String, u64>>,
    /// Non-busy 5xx and transport errors: what, when, the answer.
    failures: Vec<Value>,
    /// Good requests not answered 2xx, bad ones not answered 4xx.
    unexpected: Vec<Value>,
}

/// The outcome of one request.
enum Outcome {
    Answer {
        status: u16,
        retry_after: Option<u64>,
        body: bytes::Bytes,
    },
    Transport(String),
}

/// A sample of the server's memory.
#[derive(Debug, Clone, Copy)]
struct Sample {
    t: f64,
    rss: u64,
    hwm: u64,
}

/// What `/proc/PID/status` says: `None` once the process is gone or a zombie.
fn proc_memory(pid: u32) -> Option<(u64, u64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| -> Option<u64> {
        let kb: u64 = status
            .lines()
            .find_map(|l| l.strip_prefix(name))?
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse()
            .ok()?;
        Some(kb * 1024)
    };
    let zombie = status
        .lines()
        .find_map(|l| l.strip_prefix("State:"))
        .is_some_and(|s| s.trim_start().starts_with('Z'));
    if zombie {
        return None;
    }
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

/// Largest growth of resident memory after warm-up that still passes: 20 % of the warm-up
/// value or 64 MiB, whichever is larger. Resident memory is not the live heap: glibc's malloc
/// keeps freed memory in per-thread arenas (up to 8 per core) and returns it to the system
/// lazily, and the blocking pool's threads (simulations, replays, ingests) come and go with
/// their arenas; SQLite's page cache and the hot-skill cache fill as the data base grows during
/// the run. Those make RSS step up by tens of MiB after warm-up without any leak, while a leak
/// of even 1 kB per request would add far more over 10 minutes of this load.
fn rss_tolerance(warm: u64) -> u64 {
    (warm / 5).max(64 << 20)
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

/// Shared between the clients.
struct Shared {
    http: reqwest::Client,
    base: String,
    start: Instant,
    deadline: Instant,
    bad_fraction: f64,
    /// Set when the server is gone: the clients stop.
    stop: AtomicBool,
    sessions: Vec<Vec<u8>>,
    ids: Mutex<Ids>,
    stats: Mutex<Stats>,
}

impl Shared {
    async fn send(&self, req: &Req) -> Outcome {
        let mut b = self
            .http
            .request(req.method.clone(), format!("{}{}", self.base, req.path));
        if let Some((ct, body)) = &req.body {
            b = b.header(CONTENT_TYPE, *ct).body(body.clone());
        }
        let r = match b.send().await {
            Ok(r) => r,
            Err(e) => return Outcome::Transport(error_chain(&e)),
        };
        let status = r.status().as_u16();
        let retry_after = r
            .headers()
            .get(RETRY_AFTER)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.trim().parse().ok());
        match r.bytes().await {
            Ok(body) => Outcome::Answer {
                status,
                retry_after,
                body,
            },
            Err(e) => Outcome::Transport(format!(
                "{status}, then reading the body: {}",
                error_chain(&e)
            )),
        }
    }

    /// Sends `req`, counts its outcome, learns ids; returns how long the client should wait
    /// before its next request (a busy server's `Retry-After`, or a pause after a transport
    /// error).
    async fn run(&self, req: Req) -> Duration {
        let sent = Instant::now();
        let outcome = self.send(&req).await;
        let ms = sent.elapsed().as_secs_f32() * 1000.0;
        let at = sent.duration_since(self.start).as_secs_f64();
        let mut pause = Duration::ZERO;
        let mut stats = self.stats.lock().unwrap();
        let stats = &mut *stats;
        let k = stats.kinds.entry(req.kind).or_default();
        k.requests += 1;
        k.latencies_ms.push(ms);
        let endpoint = stats.endpoints.entry(req.label).or_default();
        match outcome {
            Outcome::Transport(e) => {
                k.transport_errors += 1;
                *endpoint.entry("transport error".into()).or_default() += 1;
                if stats.failures.len() < MAX_SAMPLES {
                    stats.failures.push(json!({
                        "at_s": round1(at), "request": req.describe(), "transport_error": e,
                    }));
                }
                pause = Duration::from_millis(200);
            }
            Outcome::Answer {
                status,
                retry_after,
                body,
            } => {
                *k.statuses.entry(status).or_default() += 1;
                *endpoint.entry(status.to_string()).or_default() += 1;
                let busy = status == 503 && retry_after.is_some();
                if busy {
                    k.busy += 1;
                    pause = Duration::from_secs(retry_after.unwrap_or(1).min(60));
                } else if status >= 500 {
                    k.server_errors += 1;
                    if stats.failures.len() < MAX_SAMPLES {
                        stats.failures.push(json!({
                            "at_s": round1(at), "request": req.describe(), "status": status,
                            "answer": snippet(&body),
                        }));
                    }
                } else {
                    let ok = match req.expect {
                        Expect::Success => (200..300).contains(&status),
                        Expect::ClientError => (400..500).contains(&status),
                    };
                    if !ok {
                        k.unexpected += 1;
                        if stats.unexpected.len() < MAX_SAMPLES {
                            stats.unexpected.push(json!({
                                "at_s": round1(at), "request": req.describe(), "status": status,
                                "answer": snippet(&body),
                            }));
                        }
                    }
                    self.ids.lock().unwrap().learn(&req, status, &body);
                }
            }
        }
        pause
    }
}

fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(c) = source {
        s.push_str(": ");
        s.push_str(&c.to_string());
        source = c.source();
    }
    s
}

fn snippet(body: &[u8]) -> String {
    let text = String::from_utf8_lossy(&body[..body.len().min(400)]);
    text.into_owned()
}

fn round1(x: f64) -> f64 {
    (x * 10.0).round() / 10.0
}

/// A good query, chosen at random among the read endpoints.
fn query(rng: &mut Rng, ids: &Ids) -> Req {
    let q = |label, path: String| Req::get(Kind::Query, label, path);
    let skill = (!ids.skills.is_empty()).then(|| *rng.pick(&ids.skills));
    let session = (!ids.sessions.is_empty()).then(|| *rng.pick(&ids.sessions));
    let replay = (!ids.replays.is_empty()).then(|| *rng.pick(&ids.replays));
    match rng.below(20) {
        0..=5 => {
            if rng.chance(0.15) && !ids.cursors.is_empty() {
                let (query, c) = rng.pick(&ids.cursors).clone();
                let sep = if query.is_empty() { "" } else { "&" };
                return q(
                    "GET /skills?cursor",
                    format!("/api/v1/skills?{query}{sep}cursor={c}"),
                );
            }
            q(
                "GET /skills",
                format!("/api/v1/skills?{}", skill_filters(rng)),
            )
        }
        6..=8 => match skill {
            Some(id) => q("GET /skills/{id}", format!("/api/v1/skills/{id}")),
            None => q("GET /healthz", "/healthz".into()),
        },
        9..=10 => match skill {
            Some(id) => q(
                "GET /skills/{id}/similar",
                format!(
                    "/api/v1/skills/{id}/similar?k={}",
                    if rng.chance(0.5) {
                        5
                    } else {
                        1 + rng.below(20)
                    }
                ),
            ),
            None => q("GET /healthz", "/healthz".into()),
        },
        11 => {
            let limit = 1 + rng.below(100);
            q("GET /sessions", format!("/api/v1/sessions?limit={limit}"))
        }
        12 => match session {
            Some(id) => q("GET /sessions/{id}", format!("/api/v1/sessions/{id}")),
            None => q("GET /sessions", "/api/v1/sessions".into()),
        },
        13 => match session {
            Some(id) => q(
                "GET /sessions/{id}/mcap",
                format!("/api/v1/sessions/{id}/mcap"),
            ),
            None => q("GET /sessions", "/api/v1/sessions".into()),
        },
        14 => q("GET /hands", "/api/v1/hands".into()),
        15 => {
            let hand = rng.pick(&HANDS);
            q("GET /hands/{name}", format!("/api/v1/hands/{hand}"))
        }
        16 => match (skill, replay) {
            (_, Some(id)) if rng.chance(0.5) => {
                if rng.chance(0.3) {
                    q(
                        "GET /replays/{id}/mcap",
                        format!("/api/v1/replays/{id}/mcap"),
                    )
                } else {
                    q("GET /replays/{id}", format!("/api/v1/replays/{id}"))
                }
            }
            (Some(id), _) => q(
                "GET /skills/{id}/replays",
                format!("/api/v1/skills/{id}/replays"),
            ),
            _ => q("GET /healthz", "/healthz".into()),
        },
        17 => {
            if rng.chance(0.1) {
                q("GET /openapi.json", "/api/v1/openapi.json".into())
            } else {
                q("GET /hands", "/api/v1/hands?_=1".into())
            }
        }
        _ => q("GET /healthz", "/healthz".into()),
    }
}

/// Random valid skill filters, sort and limit.
fn skill_filters(rng: &mut Rng) -> String {
    let mut p: Vec<String> = Vec::new();
    if rng.chance(0.3) {
        p.push(format!(
            "shape={}",
            rng.pick(&["sphere", "box", "cylinder"])
        ));
    }
    if rng.chance(0.2) {
        let lo = rng.range(0.0, 0.4);
        p.push(format!("mass_min={lo:.3}"));
        if rng.chance(0.5) {
            p.push(format!("mass_max={:.3}", lo + rng.range(0.0, 0.5)));
        }
    }
    if rng.chance(0.15) {
        p.push(format!("mu_min={:.2}", rng.range(0.0, 0.8)));
    }
    if rng.chance(0.1) {
        p.push(format!("mu_max={:.2}", rng.range(0.8, 2.0)));
    }
    if rng.chance(0.15) {
        p.push(format!("contacts={}", 1 + rng.below(5)));
    }
    if rng.chance(0.1) {
        p.push(format!(
            "contact_model={}",
            rng.pick(&["soft_finger", "point_with_friction", "frictionless"])
        ));
    }
    if rng.chance(0.15) {
        p.push(format!("grasp_type={}", rng.pick(&["precision", "power"])));
    }
    if rng.chance(0.1) {
        p.push(format!("min_quality={:.4}", rng.range(0.0, 0.05)));
    }
    if rng.chance(0.15) {
        let phases = [
            "approach",
            "preshape",
            "grasp",
            "lift",
            "hold",
            "transport",
            "place",
            "release",
            "retreat",
        ];
        p.push(format!("phase={}", rng.pick(&phases)));
        if rng.chance(0.5) {
            let lo = rng.range(0.0, 1.0);
            p.push(format!("phase_min_s={lo:.2}"));
            p.push(format!("phase_max_s={:.2}", lo + rng.range(0.0, 2.0)));
        }
    }
    if rng.chance(0.5) {
        let sorts = [
            "id",
            "quality",
            "mass",
            "duration",
            "-quality",
            "-id",
            "mass:desc",
            "duration:desc",
        ];
        p.push(format!("sort={}", rng.pick(&sorts)));
    }
    if rng.chance(0.7) {
        let limit = if rng.chance(0.1) {
            1000
        } else {
            1 + rng.below(100)
        };
        p.push(format!("limit={limit}"));
    }
    p.join("&")
}

/// A bad request: each should be answered 4xx, never 5xx.
fn bad(rng: &mut Rng, shared: &Shared, ids: &Ids) -> Req {
    let skill = ids.skills.first().copied().unwrap_or(1);
    let json = |label, path: &str, body: &str| {
        Req::bad_raw(
            label,
            Method::POST,
            path,
            Some(("application/json", body.as_bytes().to_vec())),
        )
    };
    let session = rng.pick(&shared.sessions);
    match rng.below(22) {
        0 => json("malformed JSON", "/api/v1/simulations", "{\"scenario\": "),
        1 => json(
            "malformed JSON",
            &format!("/api/v1/skills/{skill}/replays"),
            "{\"hand\": allegro}",
        ),
        2 => json(
            "JSON array body",
            "/api/v1/simulations",
            "[\"box-slip\", 3, 1.0]",
        ),
        3 => json(
            "JSON array body",
            &format!("/api/v1/skills/{skill}/replays"),
            "[\"allegro\"]",
        ),
        4 => {
            let cut = &session[..session.len() * (1 + rng.below(3)) / 4];
            Req::bad_raw(
                "truncated MCAP",
                Method::POST,
                "/api/v1/sessions",
                Some((MCAP, cut.to_vec())),
            )
        }
        5 => {
            // One byte flipped in the middle half: a chunk's CRC (or the framing) breaks.
            let mut b = session.clone();
            let i = b.len() / 4 + rng.below(b.len() / 2);
            b[i] ^= 0xff;
            Req::bad_raw(
                "corrupted MCAP",
                Method::POST,
                "/api/v1/sessions",
                Some((MCAP, b)),
            )
        }
        6 => Req::bad_raw(
            "not MCAP",
            Method::POST,
            "/api/v1/sessions",
            Some((MCAP, b"definitely not an mcap file".to_vec())),
        ),
        7 => Req::get(
            Kind::Bad,
            "unknown route",
            format!("/api/v1/nothing-here/{}", rng.below(1000)),
        ),
        8 => Req::get(Kind::Bad, "unknown id", "/api/v1/skills/999999999".into()),
        9 => {
            let filters = [
                "mass_min=heavy",
                "shape=torus",
                "limit=0",
                "limit=5000",
                "sort=colour",
                "phase_min_s=1",
                "mass_min=2&mass_max=1",
                "cursor=not-a-cursor",
                "grasp_type=pinch",
            ];
            Req::get(
                Kind::Bad,
                "bad filter value",
                format!("/api/v1/skills?{}", rng.pick(&filters)),
            )
        }
        10 => {
            let paths = [
                "/api/v1/skills?shpe=box",
                "/api/v1/sessions?limt=5",
                "/api/v1/skills?shape=box&limt=5",
            ];
            Req::get(
                Kind::Bad,
                "unknown query parameter",
                (*rng.pick(&paths)).to_owned(),
            )
        }
        11 => Req::get(
            Kind::Bad,
            "unknown query parameter",
            format!("/api/v1/skills/{skill}/similar?kk=3"),
        ),
        12 => json(
            "duplicate JSON key",
            "/api/v1/simulations",
            r#"{"scenario": "box-slip", "seed": 1, "scenario": "two-grasps"}"#,
        ),
        13 => json(
            "duplicate JSON key",
            &format!("/api/v1/skills/{skill}/replays"),
            r#"{"hand": "allegro", "hand": "barrett"}"#,
        ),
        14 => {
            let bodies = [
                json!({"scenario": {"name": "x", "object": {"shape": "box", "mass": -1, "mu": 0.5,
                    "half_extents": [0.02, 0.02, 0.04]}, "tasks": [{"phase": "grasp", "duration": 1}]}}),
                json!({"scenario": "box-slip", "speed": 2}),
                json!({"scenario": "box-slip", "duration": 1e6}),
                json!({"scenario": "box-slip", "seed": -1}),
                json!({"scenario": "moonwalk"}),
                json!({"scenario": {"name": "x", "object": {"shape": "box", "mass": 0.2, "mu": 0.5,
                    "half_extents": [0.02, 0.02, 0.04]}, "tasks": [{"phase": "dance", "duration": 1}]}}),
            ];
            let body = rng.pick(&bodies);
            Req::post_json(Kind::Bad, "invalid scenario", "/api/v1/simulations", body)
        }
        15 => Req::bad_raw(
            "wrong content type",
            Method::POST,
            "/api/v1/sessions",
            Some(("application/octet-stream", session.clone())),
        ),
        16 => json_with_type(
            "wrong content type",
            "/api/v1/simulations",
            "text/plain",
            "{\"scenario\": \"box-slip\"}",
        ),
        17 => {
            let depth = 100_000;
            let body = format!("{}{}", "[".repeat(depth), "]".repeat(depth));
            let path = rng.pick(&[
                "/api/v1/simulations",
                "/api/v1/hands",
                "/api/v1/skills/1/replays",
            ]);
            json_with_type("100k-deep JSON", path, "application/json", &body)
        }
        18 => json(
            "unknown hand",
            &format!("/api/v1/skills/{skill}/replays"),
            "{\"hand\": \"octopus\"}",
        ),
        19 => Req::bad_raw(
            "wrong method",
            Method::PUT,
            &format!("/api/v1/skills/{skill}"),
            None,
        ),
        20 => Req::get(Kind::Bad, "bad id", "/api/v1/skills/abc".into()),
        _ => Req::bad_raw(
            "empty upload",
            Method::POST,
            "/api/v1/sessions",
            Some((MCAP, Vec::new())),
        ),
    }
}

fn json_with_type(label: &'static str, path: &str, ct: &'static str, body: &str) -> Req {
    Req::bad_raw(
        label,
        Method::POST,
        path,
        Some((ct, body.as_bytes().to_vec())),
    )
}

/// The next request of a client.
fn next_request(rng: &mut Rng, shared: &Shared) -> Req {
    let ids = shared.ids.lock().unwrap();
    if rng.chance(shared.bad_fraction) {
        return bad(rng, shared, &ids);
    }
    let total = WEIGHT_UPLOAD + WEIGHT_QUERY + WEIGHT_SIMULATION + WEIGHT_REPLAY;
    let mut roll = rng.below(total as usize) as u32;
    if roll < WEIGHT_UPLOAD {
        let s = rng.pick(&shared.sessions).clone();
        return Req::post(Kind::Upload, "POST /sessions", "/api/v1/sessions", MCAP, s);
    }
    roll -= WEIGHT_UPLOAD;
    if roll < WEIGHT_QUERY {
        return query(rng, &ids);
    }
    roll -= WEIGHT_QUERY;
    if roll < WEIGHT_SIMULATION || ids.skills.is_empty() {
        let scenario = rng.pick(dfs_core::scenario::Scenario::BUILTINS);
        let body = json!({
            "scenario": scenario,
            "seed": rng.next_u64() % 1_000_000_000,
            "duration": round1(rng.range(1.0, 3.0)),
        });
        return Req::post_json(
            Kind::Simulation,
            "POST /simulations",
            "/api/v1/simulations",
            &body,
        );
    }
    let skill = rng.pick(&ids.skills);
    let body = json!({"hand": rng.pick(&HANDS)});
    Req::post_json(
        Kind::Replay,
        "POST /skills/{id}/replays",
        &format!("/api/v1/skills/{skill}/replays"),
        &body,
    )
}

async fn client(shared: Arc<Shared>, seed: u64) {
    let mut rng = Rng::new(seed);
    while Instant::now() < shared.deadline && !shared.stop.load(Ordering::Relaxed) {
        let req = next_request(&mut rng, &shared);
        let pause = shared.run(req).await;
        if !pause.is_zero() {
            let until = (Instant::now() + pause).min(shared.deadline);
            tokio::time::sleep_until(until.into()).await;
        }
    }
}

/// Samples the server's memory every second until the clients are done; prints progress to
/// stderr every 30 s; sets `stop` when the server is gone.
async fn sampler(
    shared: Arc<Shared>,
    pid: u32,
    samples: Arc<Mutex<Vec<Sample>>>,
    gone: Arc<Mutex<Option<f64>>>,
) {
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    let mut next_report = 30.0;
    loop {
        tick.tick().await;
        let t = shared.start.elapsed().as_secs_f64();
        match proc_memory(pid) {
            Some((rss, hwm)) => samples.lock().unwrap().push(Sample { t, rss, hwm }),
            None => {
                *gone.lock().unwrap() = Some(t);
                shared.stop.store(true, Ordering::Relaxed);
                eprintln!("icms-soak: the server (pid {pid}) is gone at {t:.1} s");
                return;
            }
        }
        if t >= next_report {
            next_report += 30.0;
            let (req, s5, busy, te) = {
                let st = shared.stats.lock().unwrap();
                st.kinds.values().fold((0, 0, 0, 0), |a, k| {
                    (
                        a.0 + k.requests,
                        a.1 + k.server_errors,
                        a.2 + k.busy,
                        a.3 + k.transport_errors,
                    )
                })
            };
            let rss = samples.lock().unwrap().last().map_or(0, |s| s.rss);
            eprintln!(
                "icms-soak: {t:>6.0} s  {req} requests, {s5} 5xx, {busy} busy 503, {te} transport errors, RSS {:.1} MiB",
                mib(rss)
            );
        }
    }
}

fn percentile(sorted: &[f32], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    f64::from(sorted[i])
}

/// Simulates the prepared sessions (2-5 s each) on all cores.
fn prepare_sessions(seed: u64) -> Vec<Vec<u8>> {
    let plan: Vec<(&str, f64)> = vec![
        ("sphere-lift", 5.0),
        ("box-pinch-lift", 5.0),
        ("cylinder-power-grasp", 4.5),
        ("sphere-rotate", 4.0),
        ("box-slip", 3.5),
        ("two-grasps", 3.0),
        ("sphere-lift", 2.5),
        ("box-pinch-lift", 2.0),
    ];
    let threads = std::thread::available_parallelism()
        .map_or(2, |n| n.get())
        .min(plan.len());
    let out: Mutex<Vec<Option<Vec<u8>>>> = Mutex::new(vec![None; plan.len()]);
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(scenario, duration)) = plan.get(i) else {
                    return;
                };
                let bytes = tests::session_bytes(
                    scenario,
                    seed.wrapping_mul(1000).wrapping_add(i as u64),
                    Some(duration),
                );
                out.lock().unwrap()[i] = Some(bytes);
            });
        }
    });
    out.into_inner()
        .unwrap()
        .into_iter()
        .map(|b| b.expect("every session simulated"))
        .collect()
}

/// What the load phase found.
struct Load {
    elapsed: f64,
    stats: Stats,
    ids: Ids,
    samples: Vec<Sample>,
    gone_at: Option<f64>,
    unfinished: usize,
    setup_error: Option<String>,
}

async fn load(o: &Options, base: String, pid: u32, sessions: Vec<Vec<u8>>) -> Load {
    let http = reqwest::Client::builder()
        .timeout(CLIENT_TIMEOUT)
        // Below the server's 30 s keep-alive timeout: a pooled connection is never reused just
        // as the server closes it (which would look like a transport error).
        .pool_idle_timeout(Duration::from_secs(20))
        .build()
        .expect("HTTP client");
    let start = Instant::now();
    let duration = Duration::from_secs_f64(o.minutes * 60.0);
    let shared = Arc::new(Shared {
        http,
        base,
        start,
        deadline: start + duration,
        bad_fraction: o.bad_fraction,
        stop: AtomicBool::new(false),
        sessions,
        ids: Mutex::new(Ids::default()),
        stats: Mutex::new(Stats::default()),
    });
    let samples = Arc::new(Mutex::new(Vec::new()));
    let gone = Arc::new(Mutex::new(None));
    let sampler = tokio::spawn(sampler(shared.clone(), pid, samples.clone(), gone.clone()));

    // Two uploads first, so that there are skills to query and replay.
    let mut setup_error = None;
    for i in 0..2 {
        let s = shared.sessions[i].clone();
        shared
            .run(Req::post(
                Kind::Upload,
                "POST /sessions",
                "/api/v1/sessions",
                MCAP,
                s,
            ))
            .await;
    }
    if shared.ids.lock().unwrap().skills.is_empty() {
        setup_error = Some("the two first uploads gave no skills".to_owned());
        shared.stop.store(true, Ordering::Relaxed);
    }

    let mut clients = tokio::task::JoinSet::new();
    for c in 0..o.clients {
        clients.spawn(client(
            shared.clone(),
            o.seed.wrapping_mul(1_000_003).wrapping_add(c as u64),
        ));
    }
    // Every client stops starting requests at the deadline; one in flight ends within the
    // client timeout.
    let limit =
        tokio::time::Instant::from(shared.deadline + CLIENT_TIMEOUT + Duration::from_secs(10));
    while let Ok(Some(_)) = tokio::time::timeout_at(limit, clients.join_next()).await {}
    let unfinished = clients.len();
    clients.shutdown().await;
    let elapsed = start.elapsed().as_secs_f64();
    // The final sample, after the load.
    tokio::time::sleep(Duration::from_millis(1100)).await;
    sampler.abort();
    let _ = sampler.await;
    if let Some((rss, hwm)) = proc_memory(pid) {
        samples.lock().unwrap().push(Sample {
            t: start.elapsed().as_secs_f64(),
            rss,
            hwm,
        });
    }
    let shared = Arc::into_inner(shared).expect("the clients are done");
    let gone_at = *gone.lock().unwrap();
    let samples = std::mem::take(&mut *samples.lock().unwrap());
    Load {
        elapsed,
        stats: shared.stats.into_inner().unwrap(),
        ids: shared.ids.into_inner().unwrap(),
        samples,
        gone_at,
        unfinished,
        setup_error,
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    // The server: `ServerProcess` runs `<this program> serve ...`.
    if args.get(1).map(String::as_str) == Some("serve") {
        return api::cli::run();
    }
    let o = match parse_options(&args[1..]) {
        Ok(Some(o)) => o,
        Ok(None) => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("icms-soak: {e}\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    let icms = match &o.icms {
        Some(p) => p.clone(),
        None => std::env::current_exe().expect("the path of this program"),
    };
    if !icms.is_file() {
        eprintln!("icms-soak: no icms binary at {}", icms.display());
        return ExitCode::from(2);
    }

    let t = Instant::now();
    let sessions = prepare_sessions(o.seed);
    let sizes: Vec<usize> = sessions.iter().map(Vec::len).collect();
    eprintln!(
        "icms-soak: {} sessions simulated in {:.1} s ({:.1}-{:.1} MiB each)",
        sessions.len(),
        t.elapsed().as_secs_f64(),
        mib(*sizes.iter().min().unwrap() as u64),
        mib(*sizes.iter().max().unwrap() as u64),
    );

    let dir = tempfile::tempdir().expect("a temporary directory");
    let data = dir.path().join("icms-data");
    let data_arg = data.to_string_lossy().into_owned();
    let server = ServerProcess::start(
        &icms.to_string_lossy(),
        dir.path(),
        &["--no-demo", "--data", &data_arg],
        "info",
    );
    let pid = server.pid();
    eprintln!(
        "icms-soak: icms serve (pid {pid}) on {}; {} clients for {} min, {:.0} % bad requests",
        server.addr,
        o.clients,
        o.minutes,
        o.bad_fraction * 100.0
    );

    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("tokio runtime");
    let load = rt.block_on(load(&o, server.client.base.clone(), pid, sessions));
    drop(rt);

    // SIGTERM: the server must finish and exit 0 within 30 s.
    let log_before = server.log();
    let exit = if load.gone_at.is_none() {
        server.terminate();
        let t = Instant::now();
        server
            .wait_within(EXIT_LIMIT)
            .map(|(code, log)| (code, log, t.elapsed().as_secs_f64()))
    } else {
        let (code, log) = server.wait();
        Some((code, log, 0.0))
    };
    let log = exit.as_ref().map_or(log_before, |e| e.1.clone());

    let (summary, failures) = summarise(&o, &load, &exit);
    if o.json {
        println!("{}", serde_json::to_string_pretty(&summary).expect("JSON"));
    } else {
        print_human(&summary);
    }
    if failures.is_empty() {
        eprintln!("icms-soak: PASS");
        ExitCode::SUCCESS
    } else {
        eprintln!("icms-soak: FAIL:");
        for f in &failures {
            eprintln!("  - {f}");
        }
        let lines: Vec<&str> = log.lines().collect();
        let errors: Vec<&str> = lines
            .iter()
            .copied()
            .filter(|l| l.contains("ERROR") || l.contains("panicked") || l.contains("overflow"))
            .take(40)
            .collect();
        if !errors.is_empty() {
            eprintln!("--- server log: errors (first {}) ---", errors.len());
            for l in errors {
                eprintln!("{l}");
            }
        }
        eprintln!("--- server log: last {} lines ---", lines.len().min(60));
        for l in &lines[lines.len().saturating_sub(60)..] {
            eprintln!("{l}");
        }
        eprintln!(
            "--- end of server log (data directory {}, removed) ---",
            data.display()
        );
        ExitCode::FAILURE
    }
}

/// The summary as JSON, and the reasons the soak failed (none: it passed).
fn summarise(
    o: &Options,
    load: &Load,
    exit: &Option<(Option<i32>, String, f64)>,
) -> (Value, Vec<String>) {
    let mut failures = Vec::new();
    let st = &load.stats;
    let mut statuses: BTreeMap<u16, u64> = BTreeMap::new();
    let mut classes: BTreeMap<String, u64> = BTreeMap::new();
    let (mut total, mut server_errors, mut busy, mut transport, mut unexpected) = (0, 0, 0, 0, 0);
    let mut by_kind = serde_json::Map::new();
    for (kind, k) in &st.kinds {
        total += k.requests;
        server_errors += k.server_errors;
        busy += k.busy;
        transport += k.transport_errors;
        unexpected += k.unexpected;
        for (s, n) in &k.statuses {
            *statuses.entry(*s).or_default() += n;
            *classes.entry(format!("{}xx", s / 100)).or_default() += n;
        }
        let mut lat = k.latencies_ms.clone();
        lat.sort_by(f32::total_cmp);
        by_kind.insert(
            kind.name().into(),
            json!({
                "requests": k.requests,
                "statuses": k.statuses.iter().map(|(s, n)| (s.to_string(), json!(n))).collect::<serde_json::Map<_, _>>(),
                "busy_503": k.busy,
                "server_errors_5xx": k.server_errors,
                "transport_errors": k.transport_errors,
                "unexpected": k.unexpected,
                "latency_ms": {
                    "p50": round1(percentile(&lat, 0.5)),
                    "p95": round1(percentile(&lat, 0.95)),
                    "p99": round1(percentile(&lat, 0.99)),
                    "max": round1(percentile(&lat, 1.0)),
                },
            }),
        );
    }
    if transport > 0 {
        *classes.entry("transport error".into()).or_default() += transport;
    }

    // Memory.
    let samples = &load.samples;
    let planned = o.minutes * 60.0;
    let warm_at = if planned >= 120.0 {
        60.0
    } else {
        planned / 2.0
    };
    let warm = samples.iter().find(|s| s.t >= warm_at).or(samples.last());
    let last = samples.last();
    let peak_hwm = samples.iter().map(|s| s.hwm).max().unwrap_or(0);
    let peak_rss = samples.iter().map(|s| s.rss).max().unwrap_or(0);
    let after_warm_max = samples
        .iter()
        .filter(|s| s.t >= warm_at)
        .map(|s| s.rss)
        .max()
        .unwrap_or(0);
    let memory = match (warm, last) {
        (Some(w), Some(l)) => {
            let growth = l.rss as i64 - w.rss as i64;
            let tol = rss_tolerance(w.rss);
            if growth > tol as i64 {
                failures.push(format!(
                    "resident memory grew by {:.1} MiB after warm-up ({:.1} MiB at {:.0} s to {:.1} MiB), over the tolerance of {:.1} MiB",
                    growth as f64 / 1048576.0, mib(w.rss), w.t, mib(l.rss), mib(tol)
                ));
            }
            let timeline: Vec<Value> = samples
                .iter()
                .filter(|s| (s.t.round() as u64).is_multiple_of(10))
                .map(|s| json!([s.t.round(), round1(mib(s.rss))]))
                .collect();
            json!({
                "warm_up_at_s": round1(w.t),
                "rss_at_warm_up_mib": round1(mib(w.rss)),
                "peak_rss_mib": round1(mib(peak_hwm)),
                "peak_sampled_rss_mib": round1(mib(peak_rss)),
                "max_rss_after_warm_up_mib": round1(mib(after_warm_max)),
                "final_rss_mib": round1(mib(l.rss)),
                "growth_after_warm_up_mib": round1(growth as f64 / 1048576.0),
                "tolerance_mib": round1(mib(tol)),
                "samples": samples.len(),
                "rss_every_10_s_mib": timeline,
            })
        }
        _ => {
            failures.push("no memory sample of the server".into());
            Value::Null
        }
    };

    if let Some(e) = &load.setup_error {
        failures.push(e.clone());
    }
    if server_errors > 0 {
        failures.push(format!(
            "{server_errors} responses were 5xx other than a busy 503 with Retry-After"
        ));
    }
    if transport > 0 {
        failures.push(format!(
            "{transport} requests got no HTTP answer (transport errors)"
        ));
    }
    if let Some(t) = load.gone_at {
        failures.push(format!("the server died during the soak, at {t:.1} s"));
    }
    if load.unfinished > 0 {
        failures.push(format!(
            "{} clients were still waiting for an answer after the time limit",
            load.unfinished
        ));
    }
    let server_exit = match exit {
        Some((code, _, secs)) => {
            if load.gone_at.is_none() && *code != Some(0) {
                failures.push(format!(
                    "after SIGTERM the server exited with {code:?}, not 0"
                ));
            }
            json!({"code": code, "after_sigterm_s": round1(*secs)})
        }
        None => {
            failures.push(format!(
                "the server was still running {} s after SIGTERM (killed)",
                EXIT_LIMIT.as_secs()
            ));
            json!({"code": null, "after_sigterm_s": null})
        }
    };

    let by_endpoint: serde_json::Map<String, Value> = st
        .endpoints
        .iter()
        .map(|(label, counts)| ((*label).to_owned(), json!(counts)))
        .collect();
    let summary = json!({
        "duration_s": round1(load.elapsed),
        "minutes": o.minutes,
        "clients": o.clients,
        "bad_fraction": o.bad_fraction,
        "seed": o.seed,
        "requests": total,
        "served": total - transport,
        "throughput_rps": round1(total as f64 / load.elapsed.max(1e-9)),
        "server_errors_5xx": server_errors,
        "busy_503": busy,
        "transport_errors": transport,
        "unexpected": unexpected,
        "status_classes": classes,
        "statuses": statuses.iter().map(|(s, n)| (s.to_string(), json!(n))).collect::<serde_json::Map<_, _>>(),
        "by_kind": by_kind,
        "by_endpoint": by_endpoint,
        "stored": {
            "sessions": load.ids.sessions.len(),
            "skills": load.ids.skills.len(),
            "replays": load.ids.replays.len(),
        },
        "memory": memory,
        "server_exit": server_exit,
        "failure_samples": st.failures,
        "unexpected_samples": st.unexpected,
        "pass": failures.is_empty(),
        "failures": failures,
    });
    (summary, failures)
}

fn print_human(s: &Value) {
    println!(
        "icms soak: {} s, {} clients, {} % bad requests (seed {})",
        s["duration_s"],
        s["clients"],
        s["bad_fraction"].as_f64().unwrap_or(0.0) * 100.0,
        s["seed"]
    );
    println!(
        "requests: {} ({} served, {} req/s); 5xx (not busy): {}; busy 503: {}; transport errors: {}; unexpected statuses: {}",
        s["requests"], s["served"], s["throughput_rps"], s["server_errors_5xx"], s["busy_503"], s["transport_errors"], s["unexpected"]
    );
    println!("status classes: {}", s["status_classes"]);
    println!("statuses: {}", s["statuses"]);
    println!(
        "{:<11} {:>8} {:>7} {:>6} {:>6} {:>6} {:>9} {:>9} {:>9}  statuses",
        "kind", "requests", "5xx", "busy", "transp", "unexp", "p50 ms", "p99 ms", "max ms"
    );
    for (kind, k) in s["by_kind"].as_object().into_iter().flatten() {
        println!(
            "{:<11} {:>8} {:>7} {:>6} {:>6} {:>6} {:>9} {:>9} {:>9}  {}",
            kind,
            k["requests"].to_string(),
            k["server_errors_5xx"].to_string(),
            k["busy_503"].to_string(),
            k["transport_errors"].to_string(),
            k["unexpected"].to_string(),
            k["latency_ms"]["p50"].to_string(),
            k["latency_ms"]["p99"].to_string(),
            k["latency_ms"]["max"].to_string(),
            k["statuses"]
        );
    }
    println!("by endpoint:");
    for (label, counts) in s["by_endpoint"].as_object().into_iter().flatten() {
        println!("  {label:<28} {counts}");
    }
    println!("stored (seen in answers): {}", s["stored"]);
    let m = &s["memory"];
    if !m.is_null() {
        println!(
            "memory: RSS {} MiB at {} s (warm-up), peak {} MiB (VmHWM), max after warm-up {} MiB, final {} MiB; growth after warm-up {} MiB (tolerance {} MiB)",
            m["rss_at_warm_up_mib"], m["warm_up_at_s"], m["peak_rss_mib"], m["max_rss_after_warm_up_mib"], m["final_rss_mib"], m["growth_after_warm_up_mib"], m["tolerance_mib"]
        );
        let line: Vec<String> = m["rss_every_10_s_mib"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|p| format!("{}s:{}", p[0], p[1]))
            .collect();
        println!("RSS every 10 s (MiB): {}", line.join(" "));
    }
    println!("server exit after SIGTERM: {}", s["server_exit"]);
    for (title, key) in [
        ("failing requests", "failure_samples"),
        ("unexpected statuses", "unexpected_samples"),
    ] {
        let items = s[key].as_array().cloned().unwrap_or_default();
        if !items.is_empty() {
            println!("{title} (first {}):", items.len());
            for i in items {
                println!("  {i}");
            }
        }
    }
    println!(
        "result: {}",
        if s["pass"] == true {
            "PASS".to_owned()
        } else {
            format!("FAIL: {}", s["failures"])
        }
    );
}
