//! `icms worker` as a user starts it (issue 24, work spread over machines): a server that runs
//! no jobs itself and workers on one PostgreSQL data base and one bucket; a worker killed
//! (SIGKILL) in the middle of a job loses no job: another worker takes it once the dead one's
//! lease has run out, and the server answers its session, file included. On SQLite a worker
//! beside a running server is refused, naming the server.
//!
//! The PostgreSQL test is skipped, saying so, without ICMS_TEST_POSTGRES_URL or s3s-fs
//! (failing instead under ICMS_REQUIRE_TOOLS), as cli_serve_follow.rs.

use crate::common;
use crate::s3_server;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::pg::{fresh_schema, postgres_or_skip};
use common::server::{unchunk, Running};
use s3_server::{S3Server, BUCKET};
use serde_json::Value;

/// A running `icms worker` and what it wrote to stderr so far.
struct Worker {
    child: Child,
    log: Arc<Mutex<String>>,
}

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Worker {
    /// `icms worker --data data args…`, its environment `env`.
    fn start(data: &Path, args: &[&str], env: &[(&'static str, String)]) -> Worker {
        let mut child = Command::new(env!("CARGO_BIN_EXE_icms"))
            .args(["worker", "--data"])
            .arg(data)
            .args(args)
            .envs(env.iter().cloned())
            .env_remove("DATABASE_URL")
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let log = Arc::new(Mutex::new(String::new()));
        let stderr = child.stderr.take().unwrap();
        let sink = Arc::clone(&log);
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let mut l = sink.lock().unwrap();
                l.push_str(&line);
                l.push('\n');
            }
        });
        Worker { child, log }
    }

    /// Waits up to `limit` for `needle` in the log.
    fn wait_for(&self, needle: &str, limit: Duration) -> bool {
        let start = Instant::now();
        while start.elapsed() < limit {
            if self.log.lock().unwrap().contains(needle) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }

    fn log(&self) -> String {
        self.log.lock().unwrap().clone()
    }
}

fn json(server: &Running, method: &str, path: &str, body: &str) -> (u16, Value) {
    let (status, _, bytes) = server.request(method, path, body);
    let v = serde_json::from_slice(&bytes).unwrap_or_else(|e| {
        panic!(
            "{method} {path}: {status}, not JSON ({e}): {}",
            String::from_utf8_lossy(&bytes)
        )
    });
    (status, v)
}

#[test]
fn a_worker_killed_mid_job_loses_no_job() {
    let test = "a_worker_killed_mid_job_loses_no_job";
    let Some(base) = postgres_or_skip(test) else {
        return;
    };
    let Some(s3) = S3Server::start(test) else {
        return;
    };
    let rt = tokio::runtime::Runtime::new().unwrap();
    let url = fresh_schema(&rt, &base, "t_cli_worker_kill");
    let blobs = format!("s3://{BUCKET}/workers");
    let tmp = tempfile::tempdir().unwrap();
    let env = s3.env();
    // The server only takes requests: the workers run the jobs.
    let mut cmd = Running::command(
        &tmp.path().join("server"),
        &[
            "--database-url",
            &url,
            "--blobs",
            &blobs,
            "--max-simulations",
            "0",
            "--job-wait",
            "0",
        ],
    );
    cmd.envs(env.iter().cloned());
    let server = Running::start(cmd);
    // The first worker's claims last a second without renewal.
    let first = Worker::start(
        &tmp.path().join("w1"),
        &[
            "--database-url",
            &url,
            "--blobs",
            &blobs,
            "--workers",
            "1",
            "--lease",
            "1",
        ],
        &env,
    );
    let (status, job) = json(
        &server,
        "POST",
        "/api/v1/simulations",
        r#"{"scenario": "two-grasps", "seed": 9, "duration": 120}"#,
    );
    assert_eq!(status, 202, "{job}");
    let job_url = job["url"].as_str().unwrap().to_owned();
    assert!(
        first.wait_for("job claimed", Duration::from_secs(60)),
        "{}",
        first.log()
    );
    let (_, running) = json(&server, "GET", &job_url, "");
    assert_eq!(running["state"], "running", "{running}");
    let dead = running["worker"].as_str().unwrap().to_owned();
    drop(first); // SIGKILL, mid-job: no renewal, no release.
    let (_, still) = json(&server, "GET", &job_url, "");
    assert_eq!(still["state"], "running", "nothing ended the job: {still}");

    let second = Worker::start(
        &tmp.path().join("w2"),
        &["--database-url", &url, "--blobs", &blobs, "--workers", "1"],
        &env,
    );
    let start = Instant::now();
    let done = loop {
        let (_, j) = json(&server, "GET", &job_url, "");
        if j["state"] != "running" && j["state"] != "queued" {
            break j;
        }
        assert!(
            start.elapsed() < Duration::from_secs(180),
            "the job was not finished by the second worker: {j}\n{}",
            second.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(done["state"], "done", "{done}\n{}", second.log());
    assert_eq!(done["attempts"], 2, "{done}");
    assert_ne!(done["worker"], dead.as_str(), "{done}");
    // One session, stored by the second worker, its file read through the server.
    let (_, sessions) = json(&server, "GET", "/api/v1/sessions", "");
    assert_eq!(sessions["items"].as_array().unwrap().len(), 1, "{sessions}");
    let session_url = done["result_url"].as_str().unwrap();
    let (status, head, body) = server.request("GET", &format!("{session_url}/mcap"), "");
    assert_eq!(status, 200, "{head}");
    assert!(unchunk(&head, body).starts_with(b"\x89MCAP"));
    // SIGTERM: the worker stops and closes the data base.
    let pid = second.child.id().to_string();
    assert!(Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .unwrap()
        .success());
    assert!(
        second.wait_for("database closed", Duration::from_secs(30)),
        "{}",
        second.log()
    );
}

#[test]
fn a_worker_is_refused_where_it_cannot_help() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let server = Running::serve(&data, &[]);
    let out = Command::new(env!("CARGO_BIN_EXE_icms"))
        .args(["worker", "--data"])
        .arg(&data)
        .env_remove("DATABASE_URL")
        .env_remove("ICMS_BLOBS")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("in use by another icms process") && stderr.contains("serve"),
        "{stderr}"
    );
    drop(server);
    // PostgreSQL without the servers' bucket: its files would be out of the servers' reach.
    let out = Command::new(env!("CARGO_BIN_EXE_icms"))
        .args(["worker", "--data"])
        .arg(&data)
        .args(["--database-url", "postgres://icms@127.0.0.1:1/none"])
        .env_remove("ICMS_BLOBS")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("--blobs"), "{stderr}");
    for bad in [
        ["--workers", "0"],
        ["--lease", "0"],
        ["--job-timeout", "nan"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_icms"))
            .args(["worker", "--data"])
            .arg(&data)
            .args(bad)
            .env_remove("DATABASE_URL")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{bad:?}: {stderr}");
        assert!(stderr.contains(bad[0]), "{bad:?}: {stderr}");
    }
}
