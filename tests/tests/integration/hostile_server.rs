//! The real `icms serve` process under hostile and heavy input (issue 17): no request may crash,
//! pin or starve it. Each test bounds its own time; none asserts how fast anything is.

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use tests::ServerProcess;

const ICMS: &str = env!("CARGO_BIN_EXE_icms-e2e");

fn start(dir: &std::path::Path, args: &[&str]) -> ServerProcess {
    let mut all = vec!["--no-demo"];
    all.extend_from_slice(args);
    ServerProcess::start(ICMS, dir, &all, "info,tower_http=debug")
}

fn healthy(rt: &tokio::runtime::Runtime, server: &ServerProcess) {
    let r = rt.block_on(server.client.get("/healthz"));
    assert_eq!(r.status.as_u16(), 200, "{}", server.log());
}

/// A URDF whose `<robot>` holds an unknown element nested `depth` deep.
fn nested_urdf(depth: usize) -> String {
    let mut s = String::from("<robot name=\"deep\"><link name=\"palm\"/>");
    s.push_str(&"<x>".repeat(depth));
    s.push_str(&"</x>".repeat(depth));
    s.push_str("</robot>");
    s
}

#[test]
fn a_deeply_nested_urdf_or_json_body_is_refused_and_the_server_lives() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), &[]);
    let spec = json!({"name": "deep", "fingertips": [
        {"name": "a", "link": "palm", "offset": [0, 0, 0], "radius": 0.01},
        {"name": "b", "link": "palm", "offset": [0, 0, 0], "radius": 0.01}],
        "torque_limit": 0.7});
    for depth in [3_000, 100_000] {
        let body = json!({"spec": spec, "urdf": nested_urdf(depth)});
        let r = rt.block_on(server.client.post_json("/api/v1/hands", &body, None));
        let detail = r.problem(422);
        assert!(
            detail.contains("deep") && detail.contains("at most"),
            "{depth}: {detail}"
        );
        healthy(&rt, &server);
    }
    // JSON nested past serde_json's recursion limit, on every JSON endpoint.
    let deep_json = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    for path in [
        "/api/v1/hands",
        "/api/v1/simulations",
        "/api/v1/skills/1/replays",
    ] {
        let r = rt.block_on(server.client.send(
            reqwest::Method::POST,
            path,
            Some(("application/json", deep_json.clone().into_bytes())),
            None,
        ));
        assert!(r.status.is_client_error(), "{path}: {}", r.status);
        healthy(&rt, &server);
    }
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
}

#[test]
fn work_over_the_job_time_limit_is_stopped_and_its_turn_freed() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let dir = tempfile::tempdir().unwrap();
    // One worker; a job may run 0.3 s: a 120 s simulation takes longer than that.
    let server = start(
        dir.path(),
        &["--job-timeout", "0.3", "--max-simulations", "1"],
    );
    let long = json!({"scenario": "two-grasps", "seed": 1, "duration": 120});
    let r = rt.block_on(server.client.post_json("/api/v1/simulations", &long, None));
    let detail = r.problem(503);
    assert!(
        detail.contains("time limit") && detail.contains("--job-timeout"),
        "{detail}"
    );
    assert!(
        server.wait_for_log(
            &["work stopped before it finished"],
            Duration::from_secs(60)
        ),
        "the simulation was stopped:\n{}",
        server.log()
    );
    let jobs = rt.block_on(server.client.get("/api/v1/jobs")).json();
    assert_eq!(jobs["items"][0]["state"], "failed", "{jobs}");
    assert_eq!(jobs["items"][0]["error"]["status"], 503, "{jobs}");
    // The one worker is free again: a short simulation runs and is stored.
    let short = json!({"scenario": "two-grasps", "seed": 1, "duration": 0.2});
    let r = rt.block_on(server.client.post_json("/api/v1/simulations", &short, None));
    assert_eq!(
        r.status.as_u16(),
        201,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    healthy(&rt, &server);
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
}

#[test]
fn sigterm_stops_work_in_flight_and_its_jobs_wait_for_the_next_start() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), &["--max-simulations", "2"]);
    let mut calls = Vec::new();
    for seed in [2, 3] {
        let client = server.client.clone();
        let body = json!({"scenario": "two-grasps", "seed": seed, "duration": 120});
        calls.push(
            rt.spawn(async move { client.post_json("/api/v1/simulations", &body, None).await }),
        );
    }
    let began = Instant::now();
    while server.log().matches("job claimed").count() < 2 {
        assert!(
            began.elapsed() < Duration::from_secs(60),
            "both jobs were claimed: {}",
            server.log()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(300));
    server.terminate();
    let Some((code, log)) = server.wait_within(Duration::from_secs(30)) else {
        panic!("icms serve was still running 30 s after SIGTERM");
    };
    assert_eq!(code, Some(0), "{log}");
    assert!(log.contains("database closed"), "{log}");
    assert!(
        log.contains("the job goes back to the queue"),
        "the running jobs were given back: {log}"
    );
    for call in calls {
        // Each call was answered (202 with its job: the server stopped waiting at shutdown)
        // or its connection was closed by the exit; none hangs.
        if let Ok(Ok(r)) =
            rt.block_on(async { tokio::time::timeout(Duration::from_secs(30), call).await })
        {
            assert_eq!(
                r.status.as_u16(),
                202,
                "{}",
                String::from_utf8_lossy(&r.body)
            );
        }
    }
    // Nothing accepted is lost: started again, the server finds both jobs waiting (or already
    // running again), their interrupted attempts not counted.
    let server = start(dir.path(), &["--max-simulations", "2"]);
    let jobs = rt.block_on(server.client.get("/api/v1/jobs")).json();
    let items = jobs["items"].as_array().unwrap();
    assert_eq!(items.len(), 2, "{jobs}");
    for j in items {
        assert!(
            j["state"] == "queued" || (j["state"] == "running" && j["attempts"] == 1),
            "{j}"
        );
    }
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
}

/// An MCAP file of `messages` messages of `size` zero bytes each on one schemaless topic, in
/// zstd chunks: a few kB that decompress to `messages * size` bytes.
fn zstd_bomb(messages: usize, size: usize) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let opts = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(8 << 20));
        let mut w = opts.create(&mut out).unwrap();
        // The topic as a session has it (a topic without its schema would be refused as it
        // appears, before any chunk is decompressed).
        let schema = w
            .add_schema("icms.GloveJointStates", "jsonschema", b"{}")
            .unwrap();
        let channel = w
            .add_channel(schema, "/glove/joint_states", "json", &BTreeMap::new())
            .unwrap();
        let zeros = vec![0u8; size];
        for i in 0..messages {
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: i as u64 * 1_000_000,
                publish_time: i as u64 * 1_000_000,
            };
            w.write_to_known_channel(&header, &zeros).unwrap();
        }
        w.finish().unwrap();
    }
    out.into_inner()
}

#[test]
fn a_decompression_bomb_is_refused_within_a_bounded_memory() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), &[]);
    healthy(&rt, &server);
    let before = server.peak_rss_bytes();
    // 1 GiB of messages in a file of well under a megabyte.
    let bomb = zstd_bomb(1024, 1 << 20);
    assert!(bomb.len() < 1 << 20, "{} bytes", bomb.len());
    let mut calls = Vec::new();
    for _ in 0..3 {
        let client = server.client.clone();
        let body = bomb.clone();
        calls.push(rt.spawn(async move { client.upload(&body, None).await }));
    }
    for call in calls {
        let r = rt.block_on(call).unwrap();
        // Refused at the first problem in file order, streaming: the ratio, or (as here, the
        // first chunk being within it) that chunk's first message, 1 MiB of zeros. Either way
        // the reader stops there, having held a chunk.
        let detail = r.problem(422);
        assert!(
            detail.contains("decompress") || detail.contains("message 0"),
            "{detail}"
        );
    }
    let grown = server.peak_rss_bytes().saturating_sub(before);
    assert!(
        grown < 256 << 20,
        "three bombs at once grew the server by {} MiB",
        grown >> 20
    );
    healthy(&rt, &server);
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
}

/// Reads from `s` until EOF or an error (the server closed it), at most `limit`; whether it
/// was closed.
fn closed_within(s: &mut TcpStream, limit: Duration) -> bool {
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let start = Instant::now();
    let mut buf = [0u8; 4096];
    while start.elapsed() < limit {
        match s.read(&mut buf) {
            Ok(0) => return true,
            Ok(_) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => return true,
        }
    }
    false
}

#[test]
fn idle_and_slow_connections_are_closed_and_a_full_house_still_answers() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = start(
        dir.path(),
        &[
            "--header-timeout",
            "1",
            "--keep-alive-timeout",
            "1",
            "--max-connections",
            "8",
        ],
    );
    // Half a request head, then nothing.
    let mut slow = TcpStream::connect(server.addr).unwrap();
    slow.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
        .unwrap();
    // Connected, nothing sent.
    let mut idle = TcpStream::connect(server.addr).unwrap();
    // One answered request, then idle on keep-alive.
    let mut kept = TcpStream::connect(server.addr).unwrap();
    kept.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        .unwrap();
    for (name, s) in [
        ("slow", &mut slow),
        ("idle", &mut idle),
        ("kept", &mut kept),
    ] {
        assert!(
            closed_within(s, Duration::from_secs(20)),
            "the {name} connection is still open"
        );
    }
    // Every connection slot taken by idle clients: a new request waits for the first of them to
    // time out, then is answered.
    let hogs: Vec<TcpStream> = (0..8)
        .map(|_| TcpStream::connect(server.addr).unwrap())
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    healthy(&rt, &server);
    drop(hogs);
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
}

#[test]
fn numeric_options_out_of_range_are_refused_without_a_panic() {
    for (option, value) in [
        ("--request-timeout", "1e30"),
        ("--request-timeout", "inf"),
        ("--header-timeout", "0"),
        ("--keep-alive-timeout", "-1"),
        ("--queue-wait", "NaN"),
        ("--max-connections", "0"),
        ("--max-ingests", "0"),
    ] {
        let out = std::process::Command::new(ICMS)
            .args(["serve", "--no-demo", "--addr", "127.0.0.1:0"])
            .arg(format!("{option}={value}"))
            .env_remove("ICMS_TOKEN")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        // Refused with an error (1, or clap's 2 for a value that is not a number), never a
        // panic (101) or a server that starts.
        assert!(
            matches!(out.status.code(), Some(1 | 2)),
            "{option} {value}: {:?} {stderr}",
            out.status
        );
        assert!(
            stderr.contains(option) && !stderr.contains("panicked"),
            "{option} {value}: {stderr}"
        );
    }
}

#[test]
fn an_upload_while_another_writer_holds_the_data_base_gets_503_with_retry_after() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), &[]);
    let db = dir.path().join("icms-data").join("icms.sqlite3");
    let session = tests::session_bytes("sphere-lift", 5, Some(2.0));
    let reply = rt.block_on(async {
        use sqlx::Connection;
        let opts = sqlx::sqlite::SqliteConnectOptions::new().filename(&db);
        let mut other = sqlx::SqliteConnection::connect_with(&opts).await.unwrap();
        sqlx::query("BEGIN IMMEDIATE")
            .execute(&mut other)
            .await
            .unwrap();
        let reply = server.client.upload(&session, None).await;
        sqlx::query("ROLLBACK").execute(&mut other).await.unwrap();
        reply
    });
    let detail = reply.problem(503);
    assert!(detail.contains("busy"), "{detail}");
    let retry: u64 = reply.headers["retry-after"]
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!(retry >= 1, "{retry}");
    // Once the other writer is done, the same upload is stored.
    let again = rt.block_on(server.client.upload(&session, None));
    assert_eq!(again.status.as_u16(), 201, "{:?}", again.json());
    let listed: Value = rt.block_on(server.client.get("/api/v1/sessions")).json();
    assert_eq!(listed["items"].as_array().unwrap().len(), 1);
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
}
