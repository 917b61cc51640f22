//! `icms serve` and its data base at start-up: an unreachable PostgreSQL is a clear error
//! naming it within seconds, a second server on one SQLite data directory is refused naming
//! the first, and with ICMS_TEST_POSTGRES_URL set a server really serves from PostgreSQL.

use crate::common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::exit_within;
use common::pg::{fresh_schema, postgres_or_skip};
use common::server::Running;

const ICMS: &str = env!("CARGO_BIN_EXE_icms");

/// Runs `icms serve ARGS` (no demo, any free port) to its end, which must come within
/// `limit`; its exit code, stderr and how long it took.
fn serve_to_the_end(data: &Path, args: &[&str], limit: Duration) -> (i32, String, Duration) {
    let start = Instant::now();
    let mut child = Command::new(ICMS)
        .args(["serve", "--no-demo", "--addr", "127.0.0.1:0", "--data"])
        .arg(data)
        .args(args)
        .env_remove("DATABASE_URL")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (status, err) = exit_within(&mut child, limit, &format!("icms serve {args:?}"));
    (status.code().unwrap_or(-1), err, start.elapsed())
}

#[test]
fn an_unreachable_database_is_an_error_naming_it_within_seconds_without_its_password() {
    let tmp = tempfile::tempdir().unwrap();
    // Nothing listens on port 1: refused at once.
    let url = "postgres://icms:s3cret@127.0.0.1:1/x";
    let (code, err, took) = serve_to_the_end(
        &tmp.path().join("data"),
        &["--database-url", url],
        Duration::from_secs(30),
    );
    assert_ne!(code, 0, "{err}");
    assert!(err.contains("postgres://icms:***@127.0.0.1:1/x"), "{err}");
    assert!(
        err.contains("cannot connect to the PostgreSQL data base"),
        "{err}"
    );
    assert!(!err.contains("s3cret"), "the password is shown: {err}");
    assert!(took < Duration::from_secs(10), "took {took:?}");
}

#[test]
fn a_database_that_does_not_answer_is_given_up_after_the_connect_timeout() {
    let tmp = tempfile::tempdir().unwrap();
    // A listener that accepts and never answers: the connection is made, the handshake hangs.
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = silent.local_addr().unwrap().port();
    let url = format!("postgres://icms@127.0.0.1:{port}/x");
    let (code, err, took) = serve_to_the_end(
        &tmp.path().join("data"),
        &["--database-url", &url],
        Duration::from_secs(30),
    );
    drop(silent);
    assert_ne!(code, 0, "{err}");
    assert!(err.contains(&format!("127.0.0.1:{port}")), "{err}");
    assert!(err.contains("no answer within 5 s"), "{err}");
    assert!(took < Duration::from_secs(15), "took {took:?}");
}

#[test]
fn a_database_url_of_another_kind_is_refused_naming_what_is_accepted() {
    let tmp = tempfile::tempdir().unwrap();
    let (code, err, _) = serve_to_the_end(
        &tmp.path().join("data"),
        &["--database-url", "mysql://root:pw@localhost/icms"],
        Duration::from_secs(30),
    );
    assert_ne!(code, 0, "{err}");
    assert!(err.contains("mysql://root:***@localhost/icms"), "{err}");
    assert!(err.contains("postgres://"), "{err}");
    assert!(
        !tmp.path().join("data").exists(),
        "a data directory was made"
    );
}

#[test]
fn a_second_server_on_one_sqlite_data_directory_is_refused_naming_the_first() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let first = Running::serve(&data, &[]);
    let (code, err, took) = serve_to_the_end(&data, &[], Duration::from_secs(30));
    assert_ne!(code, 0, "{err}");
    assert!(err.contains("is in use by another icms process"), "{err}");
    assert!(err.contains(&format!("pid {}", first.child.id())), "{err}");
    assert!(took < Duration::from_secs(10), "took {took:?}");
    // The first still answers.
    assert_eq!(first.call("GET", "/healthz").0, 200);
}

#[test]
fn a_server_on_postgres_stores_in_it_and_a_restart_finds_the_same_rows() {
    let Some(base) =
        postgres_or_skip("a_server_on_postgres_stores_in_it_and_a_restart_finds_the_same_rows")
    else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // A schema of its own in the test data base.
    let schema = format!("api_serve_{}", std::process::id());
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let url = fresh_schema(&rt, &base, &schema);
    let data = tmp.path().join("blobs");
    let ingested = {
        // With the demo: the server seeds the empty data base with simulated sessions.
        let mut child = Command::new(ICMS)
            .args([
                "serve",
                "--addr",
                "127.0.0.1:0",
                "--database-url",
                &url,
                "--data",
            ])
            .arg(&data)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        // Wait for the seeding to store some skills.
        let deadline = Instant::now() + Duration::from_secs(240);
        let count = |rt: &tokio::runtime::Runtime| -> i64 {
            rt.block_on(async {
                use sqlx::Connection as _;
                let Ok(mut conn) = sqlx::PgConnection::connect(&url).await else {
                    return 0;
                };
                let n: i64 = sqlx::query_scalar("SELECT count(*) FROM skills")
                    .fetch_one(&mut conn)
                    .await
                    .unwrap_or(0);
                let _ = conn.close().await;
                n
            })
        };
        let mut n = 0;
        while Instant::now() < deadline {
            n = count(&rt);
            if n > 0 {
                break;
            }
            std::thread::sleep(Duration::from_millis(500));
        }
        let _ = child.kill();
        let _ = child.wait();
        assert!(n > 0, "no skill was stored in PostgreSQL");
        n
    };
    // No SQLite file: the rows are in PostgreSQL.
    assert!(!data.join("icms.sqlite3").exists());
    let server = Running::serve(&data, &["--database-url", &url]);
    let (status, body) = server.call("GET", "/api/v1/skills?limit=1000");
    assert_eq!(status, 200, "{body}");
    let page: serde_json::Value = serde_json::from_str(&body).unwrap();
    let items = page["items"].as_array().unwrap();
    assert!(
        !items.is_empty() && items.len() as i64 <= ingested,
        "{body}"
    );
    let id = items[0]["id"].as_i64().unwrap();
    let (status, body) = server.call("GET", &format!("/api/v1/skills/{id}"));
    assert_eq!(status, 200, "{body}");
}
