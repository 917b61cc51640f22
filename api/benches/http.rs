//! HTTP benchmark (`cargo bench -p api --bench http`): `GET /api/v1/skills/{id}` of the ICMS
//! server under load, beside a bare axum + sqlx server that looks up one row and returns it as
//! JSON, in the same run; then filtered `GET /api/v1/skills` latency unloaded, and the upload
//! (read, validate, segment, store) of a 60 s session.
//!
//! Load comes from `wrk` (Debian package `wrk`) at 64 connections over uniformly random skill
//! ids, after a warm-up that has put every skill in the ICMS server's cache. The
//! load generator shares the machine's cores with the server, and the machine is noisy: the
//! ratio between servers measured in the same run is the figure that holds.
//!
//! Arguments (after `--`): `--skills N` (100000), `--seconds S` per load run (10),
//! `--connections C` (64), `--rounds R` (2), `--upload-seconds S` (60), `--json`.

use std::net::SocketAddr;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use api::config::ServeArgs;
use api::http::skills::PhaseDuration;
use api::startup::Application;
use axum::extract::{Path as UrlPath, State};
use axum::http::StatusCode;
use axum::routing::get;
use axum::{Json, Router};
use dfs_core::scenario::Phase;
use serde::Serialize;
use services::store::bench::{generate_synthetic, random_filtered_query, SplitMix64, Timing};
use services::store::{SortField, SortOrder, Store};
use sqlx::sqlite::{SqliteConnectOptions, SqlitePool, SqlitePoolOptions};
use sqlx::Row;

struct Args {
    skills: usize,
    seconds: u64,
    connections: u32,
    rounds: usize,
    upload_seconds: f64,
    json: bool,
}

fn args() -> Args {
    let mut a = Args {
        skills: 100_000,
        seconds: 10,
        connections: 64,
        rounds: 2,
        upload_seconds: 60.0,
        json: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut v = || it.next().expect("a value after the flag");
        match k.as_str() {
            "--skills" => a.skills = v().parse().expect("--skills N"),
            "--seconds" => a.seconds = v().parse().expect("--seconds S"),
            "--connections" => a.connections = v().parse().expect("--connections C"),
            "--rounds" => a.rounds = v().parse().expect("--rounds R"),
            "--upload-seconds" => a.upload_seconds = v().parse().expect("--upload-seconds S"),
            "--json" => a.json = true,
            "--bench" => {}
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

// ---- the bare server: one row lookup (and its session's segmentation version), as JSON --

#[derive(Serialize)]
struct BareSkill {
    id: i64,
    session_id: i64,
    object_shape: String,
    object_mass: f64,
    mu: f64,
    contact_count: i64,
    contact_model: String,
    grasp_type: String,
    quality: f64,
    volume: f64,
    duration_s: f64,
    start_ns: i64,
    end_ns: i64,
    phase_durations: Vec<PhaseDuration>,
    feature: Vec<f32>,
    params: serde_json::Value,
    segmentation_version: u32,
    created_at: String,
}

async fn bare_lookup(
    State(pool): State<SqlitePool>,
    UrlPath(id): UrlPath<i64>,
) -> Result<Json<BareSkill>, StatusCode> {
    let row = sqlx::query(
        "SELECT k.id, k.session_id, k.object_shape, k.object_mass, k.mu, k.contact_count, \
         k.contact_model, k.grasp_type, k.quality, k.volume, k.duration_s, k.start_ns, k.end_ns, \
         k.phase_durations, k.feature, k.params, k.created_at, s.segmentation_version \
         FROM skills k JOIN sessions s ON s.id = k.session_id WHERE k.id = ?",
    )
    .bind(id)
    .fetch_optional(&pool)
    .await
    .map_err(|_| StatusCode::INTERNAL_SERVER_ERROR)?
    .ok_or(StatusCode::NOT_FOUND)?;
    let text = |i: usize| -> Result<String, StatusCode> {
        row.try_get(i)
            .map_err(|_| StatusCode::INTERNAL_SERVER_ERROR)
    };
    let json = |i: usize| -> Result<serde_json::Value, StatusCode> {
        let s: &str = row
            .try_get(i)
            .map_err(|_| StatusCode::INTERNAL_SERVER_ERROR)?;
        serde_json::from_str(s).map_err(|_| StatusCode::INTERNAL_SERVER_ERROR)
    };
    let feature: &[u8] = row
        .try_get(14)
        .map_err(|_| StatusCode::INTERNAL_SERVER_ERROR)?;
    Ok(Json(BareSkill {
        id: row.get(0),
        session_id: row.get(1),
        object_shape: text(2)?,
        object_mass: row.get(3),
        mu: row.get(4),
        contact_count: row.get(5),
        contact_model: text(6)?,
        grasp_type: text(7)?,
        quality: row.get(8),
        volume: row.get(9),
        duration_s: row.get(10),
        start_ns: row.get(11),
        end_ns: row.get(12),
        // Stored as [phase, seconds] pairs, answered as the API does (rounded to the tick).
        phase_durations: serde_json::from_value::<Vec<(Phase, f64)>>(json(13)?)
            .map_err(|_| StatusCode::INTERNAL_SERVER_ERROR)?
            .into_iter()
            .map(|(phase, seconds)| PhaseDuration::new(phase, seconds))
            .collect(),
        feature: feature
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        params: json(15)?,
        created_at: text(16)?,
        segmentation_version: row.get(17),
    }))
}

/// Runs a server on its own thread and 2-worker runtime: `serve` gets where to send its bound
/// address and the signal to stop on. Returns the address and the stopper.
fn on_own_runtime<F, Fut>(serve: F) -> (SocketAddr, tokio::sync::oneshot::Sender<()>)
where
    F: FnOnce(std::sync::mpsc::Sender<SocketAddr>, tokio::sync::oneshot::Receiver<()>) -> Fut
        + Send
        + 'static,
    Fut: std::future::Future<Output = ()>,
{
    let (addr_tx, addr_rx) = std::sync::mpsc::channel();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    std::thread::spawn(move || {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap()
            .block_on(serve(addr_tx, stop_rx));
    });
    (addr_rx.recv().unwrap(), stop_tx)
}

/// Starts the bare server; returns its address and a stopper.
fn start_bare(db: &Path) -> (SocketAddr, tokio::sync::oneshot::Sender<()>) {
    let db = db.to_path_buf();
    on_own_runtime(move |addr_tx, stop_rx| async move {
        let opts = SqliteConnectOptions::new().filename(&db).read_only(true);
        let pool = SqlitePoolOptions::new()
            .max_connections(8)
            .connect_with(opts)
            .await
            .unwrap();
        let app = Router::new()
            .route("/api/v1/skills/{id}", get(bare_lookup))
            .with_state(pool.clone());
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        addr_tx.send(listener.local_addr().unwrap()).unwrap();
        axum::serve(listener, app)
            .with_graceful_shutdown(async {
                let _ = stop_rx.await;
            })
            .await
            .unwrap();
        pool.close().await;
    })
}

/// Starts the ICMS server (the same `Application` as `icms serve`).
fn start_icms(data: &Path, cache_mib: usize) -> (SocketAddr, tokio::sync::oneshot::Sender<()>) {
    let data = data.to_path_buf();
    on_own_runtime(move |addr_tx, stop_rx| async move {
        let config = ServeArgs {
            addr: SocketAddr::from(([127, 0, 0, 1], 0)),
            store: api::config::StoreArgs::in_dir(data),
            no_demo: true,
            cache_mib,
            ..ServeArgs::default()
        }
        .into_config()
        .unwrap();
        let app = Application::build(config).await.unwrap();
        addr_tx.send(app.local_addr()).unwrap();
        app.run_until(async {
            let _ = stop_rx.await;
        })
        .await
        .unwrap();
    })
}

// ---- wrk --------------------------------------------------------------------------------

#[derive(Debug, Clone, Serialize)]
struct Load {
    server: String,
    requests_per_s: f64,
    p50_ms: f64,
    p99_ms: f64,
    non_2xx: u64,
}

fn wrk_ms(v: &str) -> f64 {
    let (num, unit) = v.split_at(v.find(|c: char| c.is_alphabetic()).unwrap_or(v.len()));
    let n: f64 = num.parse().unwrap_or(f64::NAN);
    match unit {
        "us" => n / 1000.0,
        "ms" => n,
        "s" => n * 1000.0,
        _ => f64::NAN,
    }
}

fn run_wrk(name: &str, addr: SocketAddr, script: &Path, seconds: u64, connections: u32) -> Load {
    let out = Command::new("wrk")
        .args([
            "-t2",
            &format!("-c{connections}"),
            &format!("-d{seconds}s"),
            "--latency",
            "-s",
        ])
        .arg(script)
        .arg(format!("http://{addr}"))
        .output()
        .expect("wrk (apt-get install wrk)");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let mut load = Load {
        server: name.into(),
        requests_per_s: f64::NAN,
        p50_ms: f64::NAN,
        p99_ms: f64::NAN,
        non_2xx: 0,
    };
    for line in text.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["Requests/sec:", v] => load.requests_per_s = v.parse().unwrap_or(f64::NAN),
            ["50%", v] => load.p50_ms = wrk_ms(v),
            ["99%", v] => load.p99_ms = wrk_ms(v),
            ["Non-2xx", "or", "3xx", "responses:", v] => load.non_2xx = v.parse().unwrap_or(0),
            _ => {}
        }
    }
    assert!(
        load.requests_per_s.is_finite(),
        "wrk output not understood:\n{text}"
    );
    load
}

// ---- plain HTTP/1.1 requests for the unloaded timings -----------------------------------

/// One keep-alive connection; `request` returns the status and body.
struct Conn {
    stream: std::io::BufReader<std::net::TcpStream>,
}

impl Conn {
    fn new(addr: SocketAddr) -> Conn {
        let s = std::net::TcpStream::connect(addr).unwrap();
        s.set_nodelay(true).unwrap();
        Conn {
            stream: std::io::BufReader::new(s),
        }
    }

    fn request(&mut self, method: &str, path: &str, body: Option<(&str, &[u8])>) -> (u16, Vec<u8>) {
        use std::io::{BufRead, Read, Write};
        let mut head = format!("{method} {path} HTTP/1.1\r\nHost: bench\r\n");
        if let Some((ct, b)) = body {
            head.push_str(&format!(
                "Content-Type: {ct}\r\nContent-Length: {}\r\n",
                b.len()
            ));
        }
        head.push_str("\r\n");
        let s = self.stream.get_mut();
        s.write_all(head.as_bytes()).unwrap();
        if let Some((_, b)) = body {
            s.write_all(b).unwrap();
        }
        let mut line = String::new();
        self.stream.read_line(&mut line).unwrap();
        let status: u16 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
        let mut len = 0usize;
        loop {
            line.clear();
            self.stream.read_line(&mut line).unwrap();
            let l = line.trim_end();
            if l.is_empty() {
                break;
            }
            if let Some((k, v)) = l.split_once(':') {
                if k.eq_ignore_ascii_case("content-length") {
                    len = v.trim().parse().unwrap();
                }
            }
        }
        let mut body = vec![0u8; len];
        self.stream.read_exact(&mut body).unwrap();
        (status, body)
    }
}

fn filtered_query_timing(addr: SocketAddr, n: usize) -> Timing {
    let mut rng = SplitMix64::new(7);
    let mut conn = Conn::new(addr);
    let mut samples = Vec::with_capacity(n);
    for i in 0..n + 20 {
        let q = random_filtered_query(&mut rng);
        assert_eq!(q.sort.field, SortField::Quality);
        assert_eq!(q.sort.order, SortOrder::Desc);
        let path = format!(
            "/api/v1/skills?shape={}&mass_min={}&mass_max={}&min_quality={}&sort=-quality&limit={}",
            q.object_shape.unwrap(),
            q.mass_min.unwrap(),
            q.mass_max.unwrap(),
            q.min_quality.unwrap(),
            q.limit
        );
        let t = Instant::now();
        let (status, _) = conn.request("GET", &path, None);
        let dt = t.elapsed();
        assert_eq!(status, 200, "{path}");
        if i >= 20 {
            samples.push(dt);
        }
    }
    Timing::from_samples(samples)
}

fn main() {
    let a = args();
    let has_wrk = Command::new("wrk").arg("--version").output().is_ok();
    assert!(has_wrk, "this benchmark needs wrk: apt-get install wrk");
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("icms-data");
    fill_store(&data, a.skills);
    let script = write_wrk_script(dir.path(), a.skills);

    // Room for every skill: the figure is of answers from the cache. The server without a
    // cache gets a copy of the data base: a data directory is one server's (StoreError::InUse).
    let data_nocache = dir.path().join("icms-data-no-cache");
    copy_dir(&data, &data_nocache);
    let (icms, stop_icms) = start_icms(&data, 4096);
    let (nocache, stop_nocache) = start_icms(&data_nocache, 0);
    let (bare, stop_bare) = start_bare(&data.join(services::store::DB_FILE));
    let servers = [
        ("icms", icms),
        ("icms-no-cache", nocache),
        ("bare axum+sqlx", bare),
    ];
    assert_same_skill(icms, bare);
    warm_up(icms, &servers, &script, &a);
    let loads = load_runs(&servers, &script, &a);
    stop_nocache.send(()).ok();
    stop_bare.send(()).ok();

    let filtered = filtered_query_timing(icms, 2000);
    eprintln!(
        "filtered GET /skills over {} skills, unloaded: p50 {:.2} ms p99 {:.2} ms (n = {})",
        a.skills, filtered.p50_ms, filtered.p99_ms, filtered.n
    );
    let (upload, upload_bytes) = upload_timing(icms, dir.path(), a.upload_seconds);
    stop_icms.send(()).ok();
    std::thread::sleep(Duration::from_millis(200));
    report(
        &a,
        &Results {
            loads,
            filtered,
            upload,
            upload_bytes,
        },
    );
}

/// Copies the directory `from` (files and subdirectories) to a new directory `to`.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// Fills a fresh store at `data` with `skills` synthetic skills.
fn fill_store(data: &Path, skills: usize) {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let t = Instant::now();
    rt.block_on(async {
        let store = Store::open(data).await.unwrap();
        generate_synthetic(&store, skills, 1).await.unwrap();
        store.close().await;
    });
    eprintln!(
        "{} synthetic skills in {:.1} s",
        skills,
        t.elapsed().as_secs_f64()
    );
}

/// Writes wrk's script of `GET /api/v1/skills/{id}` over uniformly random ids into `dir`.
fn write_wrk_script(dir: &Path, skills: usize) -> std::path::PathBuf {
    let script = dir.join("random-ids.lua");
    std::fs::write(
        &script,
        format!(
            "math.randomseed(42)\nrequest = function()\n  return wrk.format(\"GET\", \
             \"/api/v1/skills/\" .. math.random(1, {}))\nend\n",
            skills
        ),
    )
    .unwrap();
    script
}

/// Same answer from both servers for one id (the bare server's JSON is the store's row).
fn assert_same_skill(icms: SocketAddr, bare: SocketAddr) {
    let (s1, b1) = Conn::new(icms).request("GET", "/api/v1/skills/7", None);
    let (s2, b2) = Conn::new(bare).request("GET", "/api/v1/skills/7", None);
    assert_eq!((s1, s2), (200, 200));
    let v1: serde_json::Value = serde_json::from_slice(&b1).unwrap();
    let v2: serde_json::Value = serde_json::from_slice(&b2).unwrap();
    assert_eq!(v1, v2, "both servers return the same skill");
}

/// Warm-up: every skill once through the caching server `icms` (its cache then holds them
/// all, as it would hold the hot skills of a real workload), then a short load on each server
/// (SQLite's page cache, connections).
fn warm_up(icms: SocketAddr, servers: &[(&str, SocketAddr)], script: &Path, a: &Args) {
    let mut conn = Conn::new(icms);
    for id in 1..=a.skills {
        let (status, _) = conn.request("GET", &format!("/api/v1/skills/{id}"), None);
        assert_eq!(status, 200);
    }
    for &(name, addr) in servers {
        run_wrk(name, addr, script, 3, a.connections);
    }
}

/// The load runs: every server in turn, `a.rounds` times.
fn load_runs(servers: &[(&str, SocketAddr)], script: &Path, a: &Args) -> Vec<Load> {
    let mut loads = Vec::new();
    for _ in 0..a.rounds {
        for &(name, addr) in servers {
            let l = run_wrk(name, addr, script, a.seconds, a.connections);
            eprintln!(
                "{:<16} {:>9.0} req/s  p50 {:.2} ms  p99 {:.2} ms  non-2xx {}",
                l.server, l.requests_per_s, l.p50_ms, l.p99_ms, l.non_2xx
            );
            loads.push(l);
        }
    }
    loads
}

/// Mean requests per second of the server `name` over its load runs.
fn mean_rps(loads: &[Load], name: &str) -> f64 {
    let v: Vec<f64> = loads
        .iter()
        .filter(|l| l.server == name)
        .map(|l| l.requests_per_s)
        .collect();
    v.iter().sum::<f64>() / v.len() as f64
}

/// Upload of a long session to `icms`: simulated first into `dir` (not timed), then uploaded,
/// deleted and uploaded again; each upload reads, validates, segments and stores it. The
/// timings and the file's size.
fn upload_timing(icms: SocketAddr, dir: &Path, upload_seconds: f64) -> (Timing, usize) {
    let scenario = dfs_core::scenario::Scenario::builtin("two-grasps", 0).unwrap();
    let file = dir.join("long.mcap");
    services::session::record_simulation(&scenario, Some(upload_seconds), &file, |_, _| {})
        .unwrap();
    let mcap = std::fs::read(&file).unwrap();
    let mut conn = Conn::new(icms);
    let mut uploads = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        let (status, body) = conn.request(
            "POST",
            "/api/v1/sessions",
            Some(("application/x-mcap", &mcap)),
        );
        uploads.push(t.elapsed());
        assert_eq!(status, 201, "{}", String::from_utf8_lossy(&body));
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        let (status, _) = conn.request(
            "DELETE",
            &format!("/api/v1/sessions/{}", v["session_id"]),
            None,
        );
        assert_eq!(status, 204);
    }
    let upload = Timing::from_samples(uploads);
    eprintln!(
        "upload of a {} s session ({:.1} MB): median {:.0} ms, max {:.0} ms",
        upload_seconds,
        mcap.len() as f64 / 1e6,
        upload.p50_ms,
        upload.max_ms
    );
    (upload, mcap.len())
}

/// What the benchmark measured.
struct Results {
    /// The load runs, in order.
    loads: Vec<Load>,
    /// Filtered `GET /api/v1/skills`, unloaded.
    filtered: Timing,
    /// The uploads of the long session.
    upload: Timing,
    /// The long session's size (bytes).
    upload_bytes: usize,
}

/// Prints the results: JSON with `a.json`, else two lines.
fn report(a: &Args, r: &Results) {
    let mean = |name: &str| mean_rps(&r.loads, name);
    let ratio = mean("icms") / mean("bare axum+sqlx");
    let ratio_nocache = mean("icms-no-cache") / mean("bare axum+sqlx");
    let report = serde_json::json!({
        "skills": a.skills,
        "connections": a.connections,
        "seconds_per_run": a.seconds,
        "get_skill_by_id": r.loads,
        "icms_over_bare": ratio,
        "icms_no_cache_over_bare": ratio_nocache,
        "filtered_query_unloaded": r.filtered,
        "upload_session_s": a.upload_seconds,
        "upload_bytes": r.upload_bytes,
        "upload_ms": r.upload,
    });
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report).unwrap());
    } else {
        println!(
            "GET /api/v1/skills/{{id}}, {} connections, {} skills: icms {:.0} req/s, \
             icms without cache {:.0} req/s, bare axum+sqlx {:.0} req/s; icms/bare = {:.2}, \
             uncached icms/bare = {:.2}",
            a.connections,
            a.skills,
            mean("icms"),
            mean("icms-no-cache"),
            mean("bare axum+sqlx"),
            ratio,
            ratio_nocache
        );
        println!(
            "filtered GET /api/v1/skills unloaded: p50 {:.2} ms, p99 {:.2} ms; upload of a {} s \
             session: median {:.0} ms",
            r.filtered.p50_ms, r.filtered.p99_ms, a.upload_seconds, r.upload.p50_ms
        );
    }
}
