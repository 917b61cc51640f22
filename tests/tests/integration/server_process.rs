//! The real `icms serve` as a process: a fresh data directory is created and seeded, SIGTERM
//! lets an in-flight request finish and closes the database, a restart finds everything, and
//! serving beyond loopback without a token is refused at start-up.

use std::time::Duration;

use serde_json::Value;
use tests::{session_bytes, ServerProcess};

const ICMS: &str = env!("CARGO_BIN_EXE_icms-e2e");

#[test]
fn serve_creates_and_seeds_a_fresh_data_directory_and_a_restart_finds_it_again() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(ICMS, dir.path(), &[], "info");
    assert!(dir.path().join("icms-data").join("icms.sqlite3").exists());
    // Seeding runs in the background: one session per built-in scenario.
    let builtins = dfs_core::scenario::Scenario::BUILTINS.len();
    let mut sessions = Value::Null;
    for _ in 0..600 {
        sessions = rt.block_on(server.client.get("/api/v1/sessions")).json();
        if sessions["items"].as_array().unwrap().len() == builtins {
            break;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    assert_eq!(
        sessions["items"].as_array().unwrap().len(),
        builtins,
        "{sessions}"
    );
    let skills = rt.block_on(server.client.get("/api/v1/skills")).json();
    assert!(skills["items"].as_array().unwrap().len() >= builtins);
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
    assert!(log.contains("database closed"), "{log}");

    // Restarted: everything is there, and nothing is seeded twice.
    let server = ServerProcess::start(ICMS, dir.path(), &[], "info");
    let again = rt.block_on(server.client.get("/api/v1/sessions")).json();
    assert_eq!(again, sessions);
    assert_eq!(
        rt.block_on(server.client.get("/api/v1/skills")).json(),
        skills
    );
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
    assert!(
        !log.contains("seeding"),
        "an existing data base is not seeded: {log}"
    );
}

#[test]
fn sigterm_lets_an_in_flight_upload_finish_and_closes_the_database() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(ICMS, dir.path(), &["--no-demo"], "info,tower_http=debug");
    // A long session takes a while to decode and segment: SIGTERM arrives meanwhile.
    let mcap = session_bytes("two-grasps", 11, Some(40.0));
    let client = server.client.clone();
    let upload = rt.spawn(async move { client.upload(&mcap, None).await });
    // SIGTERM once the server has started processing the upload (tower_http logs it).
    assert!(
        server.wait_for_log(
            &[
                "method=POST",
                "/api/v1/sessions",
                "started processing request"
            ],
            Duration::from_secs(120)
        ),
        "the upload reached the server"
    );
    server.terminate();
    let reply = rt.block_on(upload).unwrap();
    assert_eq!(
        reply.status,
        201,
        "{}",
        String::from_utf8_lossy(&reply.body)
    );
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
    let shutdown = log.find("shutting down").expect("shutdown logged");
    let closed = log.find("database closed").expect("database closed logged");
    assert!(shutdown < closed, "{log}");

    // The upload that finished during shutdown is stored.
    let server = ServerProcess::start(ICMS, dir.path(), &["--no-demo"], "info,tower_http=debug");
    let s = rt.block_on(server.client.get("/api/v1/sessions")).json();
    assert_eq!(s["items"].as_array().unwrap().len(), 1, "{s}");
    server.terminate();
    assert_eq!(server.wait().0, Some(0));
}

#[test]
fn serving_beyond_loopback_without_a_token_is_refused_at_start_up() {
    let dir = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(ICMS)
        .current_dir(dir.path())
        .args(["serve", "--addr", "0.0.0.0:0", "--no-demo"])
        .env_remove("ICMS_TOKEN")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("without a token") && err.contains("ICMS_TOKEN"),
        "{err}"
    );
    assert!(
        !dir.path().join("icms-data").exists(),
        "refused before touching anything"
    );
}

/// A second `icms serve` on a data directory another one serves is refused at start-up, naming
/// the first (its caches would go stale under the other's writes); `icms ingest` there too.
#[test]
fn a_second_server_on_one_data_directory_is_refused_naming_the_first() {
    let dir = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(ICMS, dir.path(), &["--no-demo"], "info");
    let second = std::process::Command::new(ICMS)
        .current_dir(dir.path())
        .args(["serve", "--addr", "127.0.0.1:0", "--no-demo"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(!second.status.success(), "{err}");
    assert!(err.contains("in use by another icms process"), "{err}");
    assert!(err.contains("icms-e2e serve"), "{err}");
    let session = dir.path().join("s.mcap");
    std::fs::write(&session, session_bytes("sphere-lift", 1, Some(1.0))).unwrap();
    let ingest = std::process::Command::new(ICMS)
        .current_dir(dir.path())
        .args(["ingest", "--data", "icms-data"])
        .arg(&session)
        .output()
        .unwrap();
    assert!(!ingest.status.success());
    assert!(String::from_utf8_lossy(&ingest.stderr).contains("in use by another icms process"));
    server.terminate();
    let (code, log) = server.wait();
    assert_eq!(code, Some(0), "{log}");
}
