//! `icms serve --blobs s3://…` (issue 24 item 2), real processes against a real S3 server
//! (s3s-fs): a simulation's session goes to the bucket and is served back from it when the
//! data directory has no copy; the bucket down while serving is a 503 naming it that recovers
//! when it is back; an unreachable bucket at start-up is an error naming it within seconds.

use crate::common;
use crate::s3_server;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use common::exit_within;
use common::server::{unchunk, Running};
use s3_server::{S3Server, BUCKET};

const ICMS: &str = env!("CARGO_BIN_EXE_icms");

fn serve(data: &Path, blobs: &str, s3: &S3Server) -> Command {
    let mut cmd = Running::command(data, &["--blobs", blobs]);
    cmd.envs(s3.env());
    cmd
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    hex::encode(sha2::Sha256::digest(bytes))
}

#[test]
fn a_server_keeps_sessions_in_the_bucket_and_answers_503_while_it_is_down() {
    let Some(mut s3) = S3Server::start("a_server_keeps_sessions_in_the_bucket") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let server = Running::start(serve(&data, &format!("s3://{BUCKET}/lab"), &s3));
    let (status, _, body) = server.request(
        "POST",
        "/api/v1/simulations",
        r#"{"scenario": "sphere-lift", "duration": 2}"#,
    );
    let body = String::from_utf8_lossy(&body).into_owned();
    assert_eq!(status, 201, "{body}");
    let created: serde_json::Value = serde_json::from_str(&body).unwrap();
    let id = created["session_id"].as_i64().unwrap();
    let (_, _, body) = server.request("GET", &format!("/api/v1/sessions/{id}"), "");
    let session: serde_json::Value = serde_json::from_slice(&body).unwrap();
    let sha = session["sha256"].as_str().unwrap().to_owned();
    let rel = format!("blobs/sha256/{}/{}.mcap", &sha[..2], &sha[2..]);
    let object = s3.object(&format!("lab/{rel}"));
    assert_eq!(sha256_hex(&std::fs::read(&object).unwrap()), sha);

    // The data directory's copy gone, the download comes from the bucket.
    std::fs::remove_file(data.join(&rel)).unwrap();
    let (status, head, body) = server.request("GET", &format!("/api/v1/sessions/{id}/mcap"), "");
    assert_eq!(status, 200, "{head}");
    assert_eq!(sha256_hex(&unchunk(&head, body)), sha);

    // The bucket down: a problem naming it, with Retry-After; the server goes on.
    std::fs::remove_file(data.join(&rel)).unwrap();
    s3.stop();
    let (status, head, body) = server.request("GET", &format!("/api/v1/sessions/{id}/mcap"), "");
    let body = String::from_utf8_lossy(&body).into_owned();
    assert_eq!(status, 503, "{head}\n{body}");
    assert!(head.to_ascii_lowercase().contains("retry-after"), "{head}");
    assert!(body.contains(&format!("s3://{BUCKET}/lab")), "{body}");
    let (status, _, _) = server.request("GET", "/healthz", "");
    assert_eq!(status, 200);
    // A simulation then stores nothing: no row names a blob that is not in the bucket.
    let (status, _, body) = server.request(
        "POST",
        "/api/v1/simulations",
        r#"{"scenario": "box-pinch-lift", "duration": 2}"#,
    );
    assert_eq!(status, 503, "{}", String::from_utf8_lossy(&body));
    let (_, _, body) = server.request("GET", "/api/v1/sessions", "");
    let page: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(page["items"].as_array().unwrap().len(), 1, "{page}");

    // Back: served again.
    s3.restart();
    let (status, head, body) = server.request("GET", &format!("/api/v1/sessions/{id}/mcap"), "");
    assert_eq!(status, 200, "{head}");
    assert_eq!(sha256_hex(&unchunk(&head, body)), sha);
}

#[test]
fn an_unreachable_bucket_at_start_up_is_an_error_naming_it_within_seconds() {
    let Some(mut s3) = S3Server::start("an_unreachable_bucket_at_start_up") else {
        return;
    };
    s3.stop();
    let tmp = tempfile::tempdir().unwrap();
    let started = Instant::now();
    let mut child = serve(&tmp.path().join("data"), "s3://icms-test/x", &s3)
        .spawn()
        .unwrap();
    let (status, err) = exit_within(
        &mut child,
        Duration::from_secs(60),
        "icms serve with its bucket unreachable",
    );
    assert!(!status.success(), "{err}");
    assert!(err.contains("s3://icms-test/x"), "{err}");
    assert!(err.contains(&format!("127.0.0.1:{}", s3.port)), "{err}");
    assert!(
        started.elapsed() < Duration::from_secs(20),
        "took {:?}",
        started.elapsed()
    );

    // And a --blobs that names no bucket is refused before anything starts.
    let out = Command::new(ICMS)
        .args(["serve", "--no-demo", "--addr", "127.0.0.1:0", "--data"])
        .arg(tmp.path().join("other"))
        .args(["--blobs", "/var/lib/icms/blobs"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("s3://BUCKET"), "{err}");
    assert!(!tmp.path().join("other").exists());
}
