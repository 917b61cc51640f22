//! Uploads: idempotent, concurrent uploads all stored, and a restarted server finds everything.

use serde_json::Value;
use tests::{session_bytes, TestApp};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn same_upload_twice_returns_the_same_id() {
    let app = TestApp::spawn().await;
    let mcap = session_bytes("box-pinch-lift", 9, None);
    let first = app.client.upload(&mcap, None).await;
    assert_eq!(
        first.status,
        201,
        "{}",
        String::from_utf8_lossy(&first.body)
    );
    let second = app.client.upload(&mcap, None).await;
    assert_eq!(second.status, 200);
    assert!(!second.headers.contains_key("location"));
    let (a, b) = (first.json(), second.json());
    assert_eq!(a["session_id"], b["session_id"]);
    assert_eq!(a["skills"], b["skills"]);
    assert_eq!(b["created"], false);
    let all = app.client.get("/api/v1/sessions").await.json();
    assert_eq!(all["items"].as_array().unwrap().len(), 1);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sixteen_concurrent_uploads_are_all_stored_and_none_is_lost() {
    let app = TestApp::spawn().await;
    let files: Vec<Vec<u8>> = (0..16)
        .map(|seed| session_bytes("box-slip", 100 + seed, Some(1.5)))
        .collect();
    let mut tasks = Vec::new();
    for f in files.clone() {
        let c = app.client.clone();
        tasks.push(tokio::spawn(async move { c.upload(&f, None).await }));
    }
    let mut ids = Vec::new();
    for t in tasks {
        let r = t.await.unwrap();
        assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
        ids.push(r.json()["session_id"].as_i64().unwrap());
    }
    let mut unique = ids.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), 16, "sixteen different sessions: {ids:?}");

    let listed = app.client.get("/api/v1/sessions?limit=100").await.json();
    let listed: Vec<i64> = listed["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_i64().unwrap())
        .collect();
    assert_eq!(listed, unique);
    for (id, f) in ids.iter().zip(&files) {
        let got = app.client.get(&format!("/api/v1/sessions/{id}/mcap")).await;
        assert!(got.body == *f, "session {id} holds its own file");
    }
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restarted_server_finds_every_session_and_skill_again() {
    let dir = tempfile::tempdir().unwrap();
    let app = TestApp::spawn_in(dir.path(), |_| {}).await;
    let mcap = session_bytes("two-grasps", 8, None);
    let up = app.client.upload(&mcap, None).await;
    assert_eq!(up.status, 201);
    let up = up.json();
    let skills_before = app.client.get("/api/v1/skills").await.json();
    let session_before = app
        .client
        .get(&format!("/api/v1/sessions/{}", up["session_id"]))
        .await
        .json();
    app.stop().await;

    let app = TestApp::spawn_in(dir.path(), |_| {}).await;
    let skills_after: Value = app.client.get("/api/v1/skills").await.json();
    assert_eq!(skills_after, skills_before);
    assert_eq!(skills_after["items"].as_array().unwrap().len(), 2);
    let session_after = app
        .client
        .get(&format!("/api/v1/sessions/{}", up["session_id"]))
        .await
        .json();
    assert_eq!(session_after, session_before);
    let file = app
        .client
        .get(session_after["mcap_url"].as_str().unwrap())
        .await;
    assert!(file.body == mcap);
    let id = up["skills"][0]["id"].as_i64().unwrap();
    let near = app
        .client
        .get(&format!("/api/v1/skills/{id}/similar?k=1"))
        .await
        .json();
    assert_eq!(
        near["items"][0]["skill_id"], up["skills"][1]["id"],
        "the similarity index is rebuilt from the data base"
    );
    // Uploading the same file to the restarted server finds it.
    let again = app.client.upload(&mcap, None).await;
    assert_eq!(again.status, 200);
    assert_eq!(again.json()["session_id"], up["session_id"]);
    app.stop().await;
}
