//! Simulations and replays as jobs over HTTP (issue 24): 201 with the result when the job ends
//! within the server's job wait, 202 with the job's URL otherwise; the same request answers
//! the same job, and its result once done; a job is followed, listed and cancelled through
//! `/api/v1/jobs`; too many waiting jobs are refused 503 with `Retry-After`.

use std::time::Duration;

use serde_json::{json, Value};
use tests::{Client, TestApp};

/// Reads job `url` until it is over (done, failed or cancelled); its body.
async fn finished(c: &Client, url: &str) -> Value {
    for _ in 0..1200 {
        let job = c.get(url).await.json();
        if ["done", "failed", "cancelled"].contains(&job["state"].as_str().unwrap()) {
            return job;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("job {url} did not finish within a minute");
}

fn location(r: &tests::Reply) -> String {
    r.headers
        .get("location")
        .expect("a Location header")
        .to_str()
        .unwrap()
        .to_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn work_not_finished_within_the_wait_is_answered_202_with_its_job() {
    let app = TestApp::spawn_with(|a| a.job_wait = 0.0).await;
    let c = &app.client;
    let body = json!({"scenario": "box-pinch-lift", "seed": 4});
    let r = c.post_json("/api/v1/simulations", &body, None).await;
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    let job = r.json();
    let url = location(&r);
    assert_eq!(url, format!("/api/v1/jobs/{}", job["job_id"]));
    assert_eq!(job["url"], url.as_str());
    assert_eq!(job["kind"], "simulation");
    assert!(
        job["state"] == "queued" || job["state"] == "running",
        "{job}"
    );
    assert!(r.headers.get("retry-after").is_some());
    // The scenario is stored resolved: a worker of another version runs what was asked.
    assert_eq!(
        job["request"]["scenario"]["name"], "box-pinch-lift",
        "{job}"
    );
    assert_eq!(job["request"]["scenario"]["seed"], 4, "{job}");
    // The same request while it runs: the same job (or, if it ended meanwhile, its session,
    // not stored twice).
    let again = c.post_json("/api/v1/simulations", &body, None).await;
    match again.status.as_u16() {
        202 => assert_eq!(again.json()["job_id"], job["job_id"]),
        200 => assert_eq!(again.json()["created"], false),
        other => panic!("{other}: {}", String::from_utf8_lossy(&again.body)),
    }
    let done = finished(c, &url).await;
    assert_eq!(done["state"], "done", "{done}");
    assert_eq!(done["attempts"], 1);
    assert!(done["finished_at"].is_string(), "{done}");
    let session = c.get(done["result_url"].as_str().unwrap()).await;
    assert_eq!(session.status, 200);
    let session_id = session.json()["id"].clone();
    // Once done, the same request answers the job's session: 200, nothing simulated again.
    let r = c.post_json("/api/v1/simulations", &body, None).await;
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["session_id"], session_id);
    assert_eq!(r.json()["created"], false);
    // A done job cannot be cancelled.
    let d = c.delete(&url, None).await.problem(409);
    assert!(d.contains("done"), "{d}");
    // Replays are jobs too: 202, then the replay.
    let skill_id = session.json()["skill_ids"][0].as_i64().unwrap();
    let r = c
        .post_json(
            &format!("/api/v1/skills/{skill_id}/replays"),
            &json!({"hand": "gripper"}),
            None,
        )
        .await;
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    let done = finished(c, &location(&r)).await;
    assert_eq!(done["state"], "done", "{done}");
    assert_eq!(done["kind"], "replay");
    assert_eq!(
        done["request"],
        json!({"kind": "replay", "skill_id": skill_id, "hand": "gripper"})
    );
    let replay = c.get(done["result_url"].as_str().unwrap()).await.json();
    assert_eq!(replay["skill_id"], skill_id);
    assert_eq!(replay["hand"], "gripper");
    // Listed newest first, by state.
    let jobs = c.get("/api/v1/jobs?state=done").await.json();
    let kinds: Vec<&str> = jobs["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["replay", "simulation"], "{jobs}");
    let page = c.get("/api/v1/jobs?limit=1").await.json();
    assert_eq!(page["items"].as_array().unwrap().len(), 1);
    let next = page["next_before"].as_i64().unwrap();
    let rest = c.get(&format!("/api/v1/jobs?before={next}")).await.json();
    assert_eq!(rest["items"].as_array().unwrap().len(), 1, "{rest}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn work_that_finishes_within_the_wait_is_answered_with_its_result() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let r = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "box-pinch-lift", "duration": 1.0}),
            None,
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    assert!(location(&r).starts_with("/api/v1/sessions/"));
    let jobs = c.get("/api/v1/jobs").await.json();
    assert_eq!(jobs["items"][0]["state"], "done", "{jobs}");
    assert_eq!(jobs["next_before"], Value::Null);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cancelled_job_stops_and_stores_nothing_and_a_full_queue_is_503() {
    let app = TestApp::spawn_with(|a| {
        a.job_wait = 0.0;
        a.max_simulations = 1;
        a.max_queued_jobs = 1;
    })
    .await;
    let c = &app.client;
    let long = |seed| json!({"scenario": "two-grasps", "seed": seed, "duration": 120});
    let running = c.post_json("/api/v1/simulations", &long(1), None).await;
    assert_eq!(running.status, 202);
    let running_url = location(&running);
    // The one worker takes it; the next waits; one more is too many.
    for _ in 0..600 {
        if c.get(&running_url).await.json()["state"] == "running" {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let queued = c.post_json("/api/v1/simulations", &long(2), None).await;
    assert_eq!(queued.status, 202);
    assert_eq!(queued.json()["state"], "queued");
    let full = c.post_json("/api/v1/simulations", &long(3), None).await;
    let d = full.problem(503);
    assert!(d.contains("wait for a worker"), "{d}");
    assert!(full.headers.get("retry-after").is_some());
    // Cancelled while waiting: at once.
    let r = c.delete(&location(&queued), None).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.json()["state"], "cancelled");
    // Cancelled while running: its worker stops it.
    let r = c.delete(&running_url, None).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.json()["cancel_requested"], true, "{}", r.json());
    let over = finished(c, &running_url).await;
    assert_eq!(over["state"], "cancelled", "{over}");
    assert_eq!(over["result_url"], Value::Null);
    let sessions = c.get("/api/v1/sessions").await.json();
    assert_eq!(sessions["items"], json!([]), "nothing was stored");
    // Asked again, a cancelled request runs anew.
    let again = c.post_json("/api/v1/simulations", &long(1), None).await;
    assert_eq!(again.status, 202);
    assert_ne!(location(&again), running_url);
    c.delete(&location(&again), None).await;
    app.stop().await;
}

#[tokio::test]
async fn bad_job_requests_are_refused_naming_what_is_wrong() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let d = c.get("/api/v1/jobs?state=sleeping").await.problem(400);
    assert!(
        d.contains("queued, running, done, failed, cancelled"),
        "{d}"
    );
    for q in ["limit=0", "limit=201", "colour=red"] {
        c.get(&format!("/api/v1/jobs?{q}")).await.problem(400);
    }
    c.get("/api/v1/jobs/abc").await.problem(400);
    let d = c.get("/api/v1/jobs/424242").await.problem(404);
    assert!(d.contains("no job with id 424242"), "{d}");
    c.delete("/api/v1/jobs/424242", None).await.problem(404);
    // A replay of a missing skill or on a missing hand is answered at once, no job made.
    c.post_json(
        "/api/v1/skills/424242/replays",
        &json!({"hand": "gripper"}),
        None,
    )
    .await
    .problem(404);
    assert_eq!(c.get("/api/v1/jobs").await.json()["items"], json!([]));
    app.stop().await;
}
