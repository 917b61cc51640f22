//! End-to-end test support for ICMS (the tests live in `tests/tests/`): the HTTP server
//! started in-process on 127.0.0.1:0 over a temporary data directory ([`TestApp`]), the real
//! `icms` binary as a child process ([`ServerProcess`]), a small HTTP client over reqwest
//! ([`Reply`]) and simulated MCAP sessions to upload ([`session_bytes`]).

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use api::config::{ServeArgs, StoreArgs};
use api::startup::Application;
use bytes::Bytes;
use reqwest::header::{HeaderMap, AUTHORIZATION, CONTENT_TYPE};
use reqwest::{Method, StatusCode};
use serde_json::Value;
use tempfile::TempDir;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// Media type of session uploads.
pub const MCAP: &str = "application/x-mcap";

/// An HTTP reply, read whole.
#[derive(Debug, Clone)]
pub struct Reply {
    /// Status.
    pub status: StatusCode,
    /// Headers.
    pub headers: HeaderMap,
    /// Body.
    pub body: Bytes,
}

impl Reply {
    /// The body as JSON (panics, showing the body, if it is not).
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "{} body is not JSON ({e}): {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }

    /// The `Content-Type` header, or "".
    pub fn content_type(&self) -> &str {
        self.headers
            .get(CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
    }

    /// Asserts an RFC 9457 problem with `status`; returns its `detail`.
    #[track_caller]
    pub fn problem(&self, status: u16) -> String {
        assert_eq!(
            self.status.as_u16(),
            status,
            "expected {status}, got {}: {}",
            self.status,
            String::from_utf8_lossy(&self.body)
        );
        assert_eq!(self.content_type(), "application/problem+json");
        let p = self.json();
        assert_eq!(p["status"], status, "{p}");
        assert!(p["title"].as_str().is_some_and(|t| !t.is_empty()), "{p}");
        p["detail"].as_str().expect("a detail").to_string()
    }
}

/// A client of one server at `base` (e.g. `http://127.0.0.1:4321`).
#[derive(Debug, Clone)]
pub struct Client {
    /// Base URL, no trailing slash.
    pub base: String,
    http: reqwest::Client,
}

impl Client {
    /// A client of the server at `addr`.
    pub fn new(addr: SocketAddr) -> Self {
        Client {
            base: format!("http://{addr}"),
            http: reqwest::Client::builder()
                .timeout(Duration::from_secs(300))
                .build()
                .expect("reqwest client"),
        }
    }

    /// Sends a request; `body` with its content type; `token` as a bearer token.
    pub async fn send(
        &self,
        method: Method,
        path: &str,
        body: Option<(&str, Vec<u8>)>,
        token: Option<&str>,
    ) -> Reply {
        let mut req = self.http.request(method, format!("{}{path}", self.base));
        if let Some((content_type, bytes)) = body {
            req = req.header(CONTENT_TYPE, content_type).body(bytes);
        }
        if let Some(t) = token {
            req = req.header(AUTHORIZATION, format!("Bearer {t}"));
        }
        let r = req.send().await.expect("request sent");
        let status = r.status();
        let headers = r.headers().clone();
        let body = r.bytes().await.expect("response body");
        Reply {
            status,
            headers,
            body,
        }
    }

    /// `GET path`.
    pub async fn get(&self, path: &str) -> Reply {
        self.send(Method::GET, path, None, None).await
    }

    /// `DELETE path` with an optional token.
    pub async fn delete(&self, path: &str, token: Option<&str>) -> Reply {
        self.send(Method::DELETE, path, None, token).await
    }

    /// `POST /api/v1/sessions` with MCAP bytes.
    pub async fn upload(&self, mcap: &[u8], token: Option<&str>) -> Reply {
        self.send(
            Method::POST,
            "/api/v1/sessions",
            Some((MCAP, mcap.to_vec())),
            token,
        )
        .await
    }

    /// `POST path` with a JSON body.
    pub async fn post_json(&self, path: &str, body: &Value, token: Option<&str>) -> Reply {
        self.send(
            Method::POST,
            path,
            Some(("application/json", serde_json::to_vec(body).unwrap())),
            token,
        )
        .await
    }
}

/// Server settings for tests: loopback port 0, a data directory, no seeding.
pub fn test_args(data: &Path) -> ServeArgs {
    ServeArgs {
        addr: SocketAddr::from(([127, 0, 0, 1], 0)),
        store: StoreArgs::in_dir(data.to_path_buf()),
        no_demo: true,
        ..ServeArgs::default()
    }
}

/// The server running in-process (on the test's tokio runtime) over a temporary data
/// directory; [`TestApp::stop`] shuts it down gracefully and closes the database.
#[derive(Debug)]
pub struct TestApp {
    /// Its address.
    pub addr: SocketAddr,
    /// A client of it.
    pub client: Client,
    /// The data directory (kept while the app lives unless given by the caller).
    pub data: PathBuf,
    _dir: Option<TempDir>,
    shutdown: Option<oneshot::Sender<()>>,
    task: Option<JoinHandle<()>>,
    /// The port of its Foxglove WebSocket server (`--foxglove`), if one runs.
    pub foxglove_port: Option<u16>,
}

impl TestApp {
    /// Starts a server over a fresh temporary data directory with default settings.
    pub async fn spawn() -> TestApp {
        Self::spawn_with(|_| {}).await
    }

    /// Starts a server over a fresh temporary data directory; `adjust` changes the settings.
    pub async fn spawn_with(adjust: impl FnOnce(&mut ServeArgs)) -> TestApp {
        let dir = tempfile::tempdir().expect("temporary directory");
        let mut app = Self::spawn_in(dir.path(), adjust).await;
        app._dir = Some(dir);
        app
    }

    /// Starts a server over `data` (which the caller keeps).
    pub async fn spawn_in(data: &Path, adjust: impl FnOnce(&mut ServeArgs)) -> TestApp {
        let mut args = test_args(data);
        adjust(&mut args);
        let config = args.into_config().expect("valid test configuration");
        let app = Application::build(config).await.expect("server starts");
        let addr = app.local_addr();
        let foxglove_port = app.foxglove_port();
        let (tx, rx) = oneshot::channel::<()>();
        let task = tokio::spawn(async move {
            app.run_until(async {
                let _ = rx.await;
            })
            .await
            .expect("server runs");
        });
        TestApp {
            addr,
            client: Client::new(addr),
            data: data.to_path_buf(),
            _dir: None,
            shutdown: Some(tx),
            task: Some(task),
            foxglove_port,
        }
    }

    /// Shuts the server down gracefully and waits until its database is closed.
    pub async fn stop(mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        if let Some(task) = self.task.take() {
            task.await.expect("server task");
        }
    }
}

/// The WebSocket URL of `app`'s live sessions (`/api/v1/live`).
pub fn live_url(app: &TestApp) -> String {
    format!("ws://{}/api/v1/live", app.addr)
}

/// The start message of a live glove10 session of scenario `s`'s objects and target, with the
/// assistant set as `assist`.
pub fn live_start(
    s: &dfs_core::scenario::Scenario,
    assist: services::live::AssistSettings,
) -> services::live::StartMessage {
    services::live::StartMessage {
        hand: "glove10".into(),
        object: s.object.clone(),
        objects: s.objects.clone(),
        target: s.target.clone(),
        name: Some(s.name.clone()),
        wrist: None,
        assist,
        calibration: None,
        whole_hand: false,
    }
}

/// The bytes of a session simulated from a built-in scenario (glove10, 1 kHz), `duration`
/// simulated seconds or the script's length. Different seeds give different bytes.
pub fn session_bytes(scenario: &str, seed: u64, duration: Option<f64>) -> Vec<u8> {
    let s = dfs_core::scenario::Scenario::builtin(scenario, seed).expect("built-in scenario");
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("s.mcap");
    services::session::record_simulation(&s, duration, &path, |_, _| {}).expect("simulation");
    std::fs::read(&path).expect("session file")
}

/// The bytes of a session like [`session_bytes`] (script length) whose `session` record does
/// not describe the object, as a recorder that does not know it writes it: its skills have the
/// shape `unknown`.
pub fn session_bytes_without_object(scenario: &str, seed: u64) -> Vec<u8> {
    use services::session::{record_ticks, SessionInfo, SessionRecorder};
    let s = dfs_core::scenario::Scenario::builtin(scenario, seed).expect("built-in scenario");
    let mut sim =
        dfs_core::operator::Simulation::new(&s, dfs_core::hand::HandModel::glove10(), None)
            .expect("the scenario sets up");
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("s.mcap");
    let info = SessionInfo {
        scenario: s.name.clone(),
        seed: Some(seed),
        source: "simulation".to_owned(),
        ..SessionInfo::default()
    };
    let recorder = SessionRecorder::create(&path, sim.dfs().hand(), sim.dfs().object(), &info)
        .expect("recorder");
    record_ticks(&mut sim, recorder, |_, _| {}).expect("record the session");
    std::fs::read(&path).expect("session file")
}

/// The real `icms` binary running `icms serve` as a child process.
#[derive(Debug)]
pub struct ServerProcess {
    child: Child,
    /// Its address (read from its start-up line).
    pub addr: SocketAddr,
    /// A client of it.
    pub client: Client,
    stderr: std::sync::Arc<std::sync::Mutex<String>>,
    reader: Option<std::thread::JoinHandle<()>>,
}

impl ServerProcess {
    /// Runs `ICMS serve --addr 127.0.0.1:0 ARGS...` in `cwd` (`icms` is the binary's path:
    /// `env!("CARGO_BIN_EXE_icms-e2e")` in a test) with `RUST_LOG=LOG` and waits for its
    /// start-up line.
    pub fn start(icms: &str, cwd: &Path, args: &[&str], log: &str) -> ServerProcess {
        let mut child = Command::new(icms)
            .current_dir(cwd)
            .args(["serve", "--addr", "127.0.0.1:0"])
            .args(args)
            .env_remove("ICMS_TOKEN")
            .env("RUST_LOG", log)
            .env("NO_COLOR", "1")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn icms serve");
        let mut lines = BufReader::new(child.stderr.take().expect("stderr")).lines();
        let mut seen = String::new();
        let addr = loop {
            let Some(Ok(line)) = lines.next() else {
                let status = child.wait().expect("wait");
                panic!("icms serve exited ({status}) before serving:\n{seen}");
            };
            seen.push_str(&line);
            seen.push('\n');
            if let Some(rest) = line.strip_prefix("icms: serving on http://") {
                let addr = rest.split('/').next().expect("address");
                break addr.parse::<SocketAddr>().expect("socket address");
            }
        };
        let stderr = std::sync::Arc::new(std::sync::Mutex::new(seen));
        let sink = stderr.clone();
        let reader = std::thread::spawn(move || {
            for line in lines.map_while(Result::ok) {
                let mut s = sink.lock().unwrap();
                s.push_str(&line);
                s.push('\n');
            }
        });
        ServerProcess {
            child,
            addr,
            client: Client::new(addr),
            stderr,
            reader: Some(reader),
        }
    }

    /// Waits (up to `limit`) until a line of the server's log contains every one of `needles`.
    pub fn wait_for_log(&self, needles: &[&str], limit: Duration) -> bool {
        let start = std::time::Instant::now();
        while start.elapsed() < limit {
            let log = self.stderr.lock().unwrap().clone();
            if log.lines().any(|l| needles.iter().all(|n| l.contains(n))) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        false
    }

    /// Sends SIGTERM.
    pub fn terminate(&self) {
        let ok = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .expect("run kill")
            .success();
        assert!(ok, "kill -TERM failed");
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Its peak resident memory so far (`VmHWM` of `/proc/PID/status`), bytes.
    pub fn peak_rss_bytes(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid()))
            .expect("/proc/PID/status of the server");
        let kb: u64 = status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .expect("VmHWM in /proc/PID/status");
        kb * 1024
    }

    /// Everything it logged so far.
    pub fn log(&self) -> String {
        self.stderr.lock().unwrap().clone()
    }

    /// Waits at most `limit` for the process to exit: its exit code and log, or `None` (and
    /// the process is killed) if it was still running.
    pub fn wait_within(mut self, limit: Duration) -> Option<(Option<i32>, String)> {
        let start = std::time::Instant::now();
        while start.elapsed() < limit {
            if let Ok(Some(_)) = self.child.try_wait() {
                return Some(self.wait());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        None
    }

    /// Waits for the process to exit; returns its exit code and everything it logged.
    pub fn wait(mut self) -> (Option<i32>, String) {
        let status = self.child.wait().expect("wait for icms serve");
        // The reader thread ends at EOF, when the process has exited.
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
        let log = self.stderr.lock().unwrap().clone();
        (status.code(), log)
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        // A test that failed midway must not leave a server running.
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
