//! Live glove sessions (`GET /api/v1/live`) over a real WebSocket against the in-process
//! server: a streamed session is stored with the skills of its upload; bad input gets an
//! error event naming what is wrong and is not stepped; stale and silent gloves, disconnects
//! and tokens.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use api::live_client::{self, ClientOptions, Frame};
use futures_util::{SinkExt, StreamExt};
use prost::Message as _;
use serde_json::{json, Value};
use services::live::{proto, AssistSettings, StartMessage};
use tests::{live_start, live_url as url, session_bytes, TestApp};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message;

use crate::interpreter;

type Ws =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

fn scenario(name: &str, seed: u64) -> dfs_core::scenario::Scenario {
    dfs_core::scenario::Scenario::builtin(name, seed).unwrap()
}

fn start_for(s: &dfs_core::scenario::Scenario) -> StartMessage {
    live_start(s, AssistSettings::default())
}

/// Streams `frames` as a live session of scenario `s`'s objects, as fast as answered, to the
/// end: the client's summary.
async fn stream(
    app: &TestApp,
    s: &dfs_core::scenario::Scenario,
    frames: Vec<Frame>,
) -> live_client::ClientSummary {
    live_client::run(
        &url(app),
        &start_for(s),
        frames,
        &ClientOptions::default(),
        |_| {},
    )
    .await
    .unwrap()
}

async fn skills_of(app: &TestApp, session_id: i64) -> Vec<Value> {
    let s = app
        .client
        .get(&format!("/api/v1/sessions/{session_id}"))
        .await
        .json();
    let mut out = Vec::new();
    for id in s["skill_ids"].as_array().unwrap() {
        out.push(
            app.client
                .get(&format!("/api/v1/skills/{}", id.as_i64().unwrap()))
                .await
                .json(),
        );
    }
    out
}

/// `n` skills each, the same grasps: grasp type, contacts, contact model and shape equal,
/// start and end within 20 ms, grasp quality within 10 %.
fn assert_same_skills(live: &[Value], uploaded: &[Value], n: usize) {
    assert_eq!(live.len(), n);
    assert_eq!(uploaded.len(), n);
    for (a, b) in live.iter().zip(uploaded) {
        for key in [
            "grasp_type",
            "contact_count",
            "contact_model",
            "object_shape",
        ] {
            assert_eq!(a[key], b[key], "{key}");
        }
        for key in ["start_ns", "end_ns"] {
            let d = (a[key].as_i64().unwrap() - b[key].as_i64().unwrap()).abs();
            assert!(d <= 20_000_000, "{key} differs by {d} ns");
        }
        let (qa, qb) = (
            a["quality"].as_f64().unwrap(),
            b["quality"].as_f64().unwrap(),
        );
        assert!(
            (qa - qb).abs() <= 0.1 * qb.abs().max(1e-3),
            "quality {qa} vs {qb}"
        );
    }
}

async fn session(app: &TestApp, id: i64) -> Value {
    let r = app.client.get(&format!("/api/v1/sessions/{id}")).await;
    assert_eq!(r.status, 200);
    r.json()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_simulated_operator_streamed_live_is_stored_with_the_skills_of_its_upload() {
    let app = TestApp::spawn().await;
    let s = scenario("two-grasps", 3);
    let frames = live_client::simulated_frames(&s, None, 1).unwrap();
    let n = frames.len() as u64;
    let mut events = Vec::new();
    let summary = live_client::run(
        &url(&app),
        &start_for(&s),
        frames,
        &ClientOptions::default(),
        |e| events.push(serde_json::to_value(e).unwrap()),
    )
    .await
    .unwrap();
    assert_eq!(summary.samples_sent, n);
    assert_eq!(summary.feedback_received, n, "every sample answered");
    assert_eq!(summary.refused, 0);
    assert!(summary.first_contact_ns.is_some());
    assert_eq!(events[0]["type"], "started", "{events:?}");
    assert_eq!(events[0]["dofs"].as_array().unwrap().len(), 10);
    let stored = events.iter().find(|e| e["type"] == "stored").unwrap();
    assert_eq!(stored["incomplete"], false);
    let live_id = summary.session_id.unwrap();
    let meta = session(&app, live_id).await;
    assert_eq!(meta["meta"]["extra"]["source"], "live");
    assert_eq!(meta["meta"]["extra"]["live"]["end_reason"], "ended");
    assert_eq!(meta["meta"]["extra"]["live"]["samples"], n.to_string());
    assert_eq!(meta["meta"]["duration_ns"], (n - 1) * 1_000_000);

    // The same operator uploaded as a simulated session: the same grasps.
    let r = app
        .client
        .upload(&session_bytes("two-grasps", 3, None), None)
        .await;
    assert_eq!(r.status, 201);
    let uploaded = skills_of(&app, r.json()["session_id"].as_i64().unwrap()).await;
    let live = skills_of(&app, live_id).await;
    assert_same_skills(&live, &uploaded, 2);
    app.stop().await;
}

/// The simulated operator's power grasp streamed live with `whole_hand` (as `icms glove
/// --scenario` sends it) is the upload's power grasp, palm and all; streamed with the
/// fingertips alone, the same glove data makes no power grasp: the cylinder the palm held
/// passes through it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_power_grasp_streamed_with_whole_hand_contact_is_stored_as_its_upload_is() {
    let app = TestApp::spawn().await;
    let s = scenario("cylinder-power-grasp", 1);
    let glove = live_client::simulated_glove(&s, None, 1).unwrap();
    assert!(glove.whole_hand, "the scenario's grasp is a wrap");
    let mut ids = Vec::new();
    for whole_hand in [true, false] {
        let start = StartMessage {
            whole_hand,
            ..start_for(&s)
        };
        let summary = live_client::run(
            &url(&app),
            &start,
            glove.frames.clone(),
            &ClientOptions::default(),
            |_| {},
        )
        .await
        .unwrap();
        assert_eq!(summary.refused, 0);
        ids.push(summary.session_id.unwrap());
    }
    let meta = session(&app, ids[0]).await;
    assert_eq!(meta["meta"]["extra"]["contacts"], "whole_hand");
    let r = app
        .client
        .upload(&session_bytes("cylinder-power-grasp", 1, None), None)
        .await;
    assert_eq!(r.status, 201);
    let uploaded = skills_of(&app, r.json()["session_id"].as_i64().unwrap()).await;
    assert!(
        uploaded[0]["grasp_type"]
            .as_str()
            .unwrap()
            .starts_with("power"),
        "{uploaded:?}"
    );
    let live = skills_of(&app, ids[0]).await;
    assert_same_skills(&live, &uploaded, 1);
    let meta = session(&app, ids[1]).await;
    assert_eq!(meta["meta"]["extra"]["contacts"], "fingertips");
    let fingertips = skills_of(&app, ids[1]).await;
    assert!(
        fingertips
            .iter()
            .all(|k| !k["grasp_type"].as_str().unwrap().starts_with("power")),
        "{fingertips:?}"
    );
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_glove_at_60_hz_drives_the_1_khz_dfs_through_the_grasp() {
    let app = TestApp::spawn().await;
    let s = scenario("sphere-lift", 0);
    // Every 16th tick: 62.5 Hz.
    let frames = live_client::simulated_frames(&s, None, 16).unwrap();
    let last_t = frames.last().unwrap().t_ns;
    let summary = stream(&app, &s, frames).await;
    assert_eq!(summary.refused, 0);
    let meta = session(&app, summary.session_id.unwrap()).await;
    // Every millisecond up to the last sample was stepped.
    assert_eq!(
        meta["meta"]["extra"]["live"]["ticks"],
        (last_t / 1_000_000 + 1).to_string()
    );
    assert_eq!(summary.skill_ids.len(), 1, "{meta}");
    app.stop().await;
}

async fn connect(app: &TestApp, token: Option<&str>) -> Ws {
    let mut req = url(app).into_client_request().unwrap();
    if let Some(t) = token {
        req.headers_mut()
            .insert("authorization", format!("Bearer {t}").parse().unwrap());
    }
    tokio_tungstenite::connect_async(req).await.unwrap().0
}

async fn send_json(ws: &mut Ws, v: Value) {
    ws.send(Message::Text(v.to_string().into())).await.unwrap();
}

/// The next frame: an event (JSON) or feedback; `None` when closed.
async fn recv(ws: &mut Ws) -> Option<Result<Value, proto::Feedback>> {
    loop {
        let msg = tokio::time::timeout(Duration::from_secs(30), ws.next())
            .await
            .expect("an answer within 30 s")?;
        match msg.ok()? {
            Message::Text(t) => return Some(Ok(serde_json::from_str(t.as_str()).unwrap())),
            Message::Binary(b) => return Some(Err(proto::Feedback::decode(b.as_ref()).unwrap())),
            Message::Close(_) => return None,
            _ => continue,
        }
    }
}

async fn expect_event(ws: &mut Ws, kind: &str) -> Value {
    match recv(ws).await {
        Some(Ok(e)) if e["type"] == kind => e,
        other => panic!("expected a {kind} event, got {other:?}"),
    }
}

async fn expect_feedback(ws: &mut Ws) -> proto::Feedback {
    match recv(ws).await {
        Some(Err(fb)) => fb,
        other => panic!("expected feedback, got {other:?}"),
    }
}

fn sphere_start() -> Value {
    json!({"type": "start", "object": {"shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8}})
}

/// A glove10 sample at rest (all angles 0.1 rad, no torque) at `t_ns`.
fn sample(t_ns: u64) -> proto::Sample {
    proto::Sample {
        t_ns,
        q: vec![0.1; 10],
        tau: vec![0.0; 10],
        wrist: Some(live_client::pose(&dfs_core::math::Isometry::translation(
            0.0, 0.0, 0.3,
        ))),
    }
}

async fn send_sample(ws: &mut Ws, s: &proto::Sample) {
    ws.send(Message::Binary(s.encode_to_vec().into()))
        .await
        .unwrap();
}

/// Polls the session list until `n` sessions are stored (a disconnected client gets no
/// `stored` event).
async fn wait_for_sessions(app: &TestApp, n: usize) -> Vec<Value> {
    for _ in 0..300 {
        let r = app.client.get("/api/v1/sessions").await.json();
        let items = r["items"].as_array().unwrap().clone();
        if items.len() >= n {
            return items;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("{n} session(s) were not stored within 30 s");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_start_is_refused_before_any_sample_naming_the_field() {
    let app = TestApp::spawn().await;
    let cases = [
        (
            json!({"type": "start", "hand": "octopus", "object": sphere_start()["object"]}),
            "octopus",
        ),
        (
            json!({"type": "start", "object": {"shape": "sphere", "radius": 0.04, "mass": -1, "mu": 0.8}}),
            "mass",
        ),
        (
            json!({"type": "start", "object": {"shape": "torus", "mass": 1, "mu": 0.8}}),
            "object.shape",
        ),
        (
            json!({"type": "start", "object": sphere_start()["object"], "assist": {"mode": "apply"}}),
            "assist.robot",
        ),
        (
            json!({"type": "start", "object": sphere_start()["object"], "wrist": [0, 0, 0, 0, 0, 0, 0]}),
            "wrist",
        ),
        (
            json!({"type": "start", "object": sphere_start()["object"], "colour": "red"}),
            "colour",
        ),
        (json!({"type": "end"}), "start"),
        (json!({"hello": 1}), "type"),
    ];
    for (start, needle) in cases {
        let mut ws = connect(&app, None).await;
        send_json(&mut ws, start.clone()).await;
        let e = expect_event(&mut ws, "error").await;
        let m = e["message"].as_str().unwrap();
        assert!(m.contains(needle), "{start}: {m}");
        assert!(
            recv(&mut ws).await.is_none(),
            "{start}: closed after the error"
        );
    }
    // A binary frame first.
    let mut ws = connect(&app, None).await;
    send_sample(&mut ws, &sample(0)).await;
    let e = expect_event(&mut ws, "error").await;
    assert!(e["message"].as_str().unwrap().contains("start"), "{e}");
    // Nothing was stored.
    let r = app.client.get("/api/v1/sessions").await.json();
    assert_eq!(r["items"].as_array().unwrap().len(), 0, "{r}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_samples_get_an_error_naming_what_is_wrong_and_lose_nothing_accepted() {
    let app = TestApp::spawn().await;
    let mut ws = connect(&app, None).await;
    send_json(&mut ws, sphere_start()).await;
    let started = expect_event(&mut ws, "started").await;
    assert_eq!(started["fingers"].as_array().unwrap().len(), 5);
    send_sample(&mut ws, &sample(1_000_000_000)).await;
    let fb = expect_feedback(&mut ws).await;
    assert_eq!((fb.t_ns, fb.session_ns, fb.ticks), (1_000_000_000, 0, 1));
    assert_eq!(fb.motor_q.len(), 10);
    assert_eq!(fb.fingers.len(), 5);

    let mut wrong_length = sample(1_010_000_000);
    wrong_length.q.truncate(3);
    let mut nan = sample(1_010_000_000);
    nan.tau[4] = f64::NAN;
    let mut out_of_range = sample(1_010_000_000);
    out_of_range.q[3] = 7.0;
    let mut bad_wrist = sample(1_010_000_000);
    bad_wrist.wrist.as_mut().unwrap().orientation = Some(proto::Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 3.0,
    });
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (vec![0xff, 0xff, 0xff], "not an icms.live.Sample"),
        (wrong_length.encode_to_vec(), "q has 3 values"),
        (nan.encode_to_vec(), "tau[4]"),
        (out_of_range.encode_to_vec(), "q: "),
        (bad_wrist.encode_to_vec(), "wrist"),
        (sample(1_000_000_000).encode_to_vec(), "time order"),
        (sample(500_000_000).encode_to_vec(), "time order"),
        (sample(60_000_000_000).encode_to_vec(), "at most 10 s"),
    ];
    let refused = cases.len();
    for (frame, needle) in cases {
        ws.send(Message::Binary(frame.into())).await.unwrap();
        let e = expect_event(&mut ws, "error").await;
        let m = e["message"].as_str().unwrap();
        assert!(m.contains(needle), "expected {needle:?} in {m}");
    }
    ws.send(Message::Text("{\"type\": \"dance\"}".into()))
        .await
        .unwrap();
    let e = expect_event(&mut ws, "error").await;
    assert!(e["message"].as_str().unwrap().contains("end"), "{e}");
    // The next good sample steps every tick since the last accepted one.
    send_sample(&mut ws, &sample(1_010_000_000)).await;
    let fb = expect_feedback(&mut ws).await;
    assert_eq!((fb.session_ns, fb.ticks), (10_000_000, 10));
    send_json(&mut ws, json!({"type": "end"})).await;
    let ended = expect_event(&mut ws, "ended").await;
    assert_eq!(ended["samples"], 2);
    assert_eq!(ended["refused"], refused);
    let stored = expect_event(&mut ws, "stored").await;
    let meta = session(&app, stored["session_id"].as_i64().unwrap()).await;
    let live = &meta["meta"]["extra"]["live"];
    assert_eq!(live["ticks"], "11");
    assert_eq!(live["refused_samples"], refused.to_string());
    assert_eq!(live["incomplete"], "false");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stale_glove_gets_zero_force_and_a_silent_one_is_stored_incomplete() {
    let app = TestApp::spawn_with(|a| a.live_silence = 1.0).await;
    let s = scenario("sphere-lift", 0);
    let frames = live_client::simulated_frames(&s, Some(3.0), 1).unwrap();
    let mut ws = connect(&app, None).await;
    send_json(
        &mut ws,
        serde_json::to_value(services::live::ClientMessage::Start(Box::new(start_for(
            &s,
        ))))
        .unwrap(),
    )
    .await;
    expect_event(&mut ws, "started").await;
    // Up to the grasp: 2.5 s of samples, the fingers pushing on the sphere at the end.
    let mut last = None;
    for f in frames.iter().take(2500) {
        ws.send(Message::Binary(f.bytes.clone())).await.unwrap();
        last = Some(expect_feedback(&mut ws).await);
    }
    let last = last.unwrap();
    assert!(
        last.fingers.iter().any(|f| f.in_contact) && last.feedback_torque.iter().any(|t| *t != 0.0),
        "{last:?}"
    );
    // No sample for 100 ms: zero force, and the session says so.
    let fb = expect_feedback(&mut ws).await;
    assert!(fb.stale);
    assert!(fb.feedback_torque.iter().all(|t| *t == 0.0));
    assert!(fb
        .fingers
        .iter()
        .all(|f| !f.in_contact && f.normal_force == 0.0));
    let e = expect_event(&mut ws, "stale").await;
    assert_eq!(e["session_ns"], 2_499_000_000u64);
    // A sample resumes it.
    ws.send(Message::Binary(frames[2500].bytes.clone()))
        .await
        .unwrap();
    let fb = expect_feedback(&mut ws).await;
    assert!(!fb.stale);
    expect_event(&mut ws, "resumed").await;
    // Then silence for longer than the limit (1 s here): stale, then the session ends,
    // stored incomplete up to its last sample.
    assert!(expect_feedback(&mut ws).await.stale);
    expect_event(&mut ws, "stale").await;
    let e = expect_event(&mut ws, "error").await;
    assert!(
        e["message"].as_str().unwrap().contains("no sample for 1 s"),
        "{e}"
    );
    let ended = expect_event(&mut ws, "ended").await;
    assert_eq!(ended["reason"], "silent");
    let stored = expect_event(&mut ws, "stored").await;
    assert_eq!(stored["incomplete"], true);
    let meta = session(&app, stored["session_id"].as_i64().unwrap()).await;
    let live = &meta["meta"]["extra"]["live"];
    assert_eq!(live["end_reason"], "silent");
    assert_eq!(live["stale_periods"], "2");
    assert_eq!(live["last_tick_ns"], "2500000000");
    assert_eq!(meta["meta"]["duration_ns"], 2_500_000_000u64);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_disconnects_mid_grasp_leaves_its_session_stored_incomplete() {
    let app = TestApp::spawn().await;
    let s = scenario("sphere-lift", 1);
    let frames: Vec<Frame> = live_client::simulated_frames(&s, None, 1).unwrap();
    let mut ws = connect(&app, None).await;
    send_json(
        &mut ws,
        serde_json::to_value(services::live::ClientMessage::Start(Box::new(start_for(
            &s,
        ))))
        .unwrap(),
    )
    .await;
    expect_event(&mut ws, "started").await;
    for f in frames.iter().take(3000) {
        ws.send(Message::Binary(f.bytes.clone())).await.unwrap();
        expect_feedback(&mut ws).await;
    }
    drop(ws);
    let items = wait_for_sessions(&app, 1).await;
    let meta = &items[0]["meta"];
    assert_eq!(meta["extra"]["live"]["incomplete"], "true", "{meta}");
    assert_eq!(meta["extra"]["live"]["end_reason"], "disconnected");
    assert_eq!(meta["extra"]["live"]["samples"], "3000");
    assert_eq!(meta["duration_ns"], 2_999_000_000u64);
    // The file reads back whole.
    let r = app
        .client
        .get(&format!("/api/v1/sessions/{}/mcap", items[0]["id"]))
        .await;
    assert_eq!(r.status, 200);
    services::ingest::analyse(&r.body, "live.mcap").unwrap();
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_sessions_need_the_token_when_one_is_set() {
    let app = TestApp::spawn_with(|a| a.token = Some("s3cret".into())).await;
    let err = tokio_tungstenite::connect_async(url(&app))
        .await
        .unwrap_err();
    match err {
        tokio_tungstenite::tungstenite::Error::Http(r) => assert_eq!(r.status(), 401),
        other => panic!("expected 401, got {other}"),
    }
    let mut ws = connect(&app, Some("s3cret")).await;
    send_json(&mut ws, sphere_start()).await;
    expect_event(&mut ws, "started").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_open_at_shutdown_is_stored_incomplete_before_the_server_stops() {
    let dir = tempfile::tempdir().unwrap();
    let app = TestApp::spawn_in(dir.path(), |_| {}).await;
    let mut ws = connect(&app, None).await;
    send_json(&mut ws, sphere_start()).await;
    expect_event(&mut ws, "started").await;
    for i in 0..200u64 {
        send_sample(&mut ws, &sample(i * 1_000_000)).await;
        expect_feedback(&mut ws).await;
    }
    app.stop().await;
    let app = TestApp::spawn_in(dir.path(), |_| {}).await;
    let items = wait_for_sessions(&app, 1).await;
    assert_eq!(
        items[0]["meta"]["extra"]["live"]["end_reason"],
        "server_stopping"
    );
    assert_eq!(items[0]["meta"]["extra"]["live"]["samples"], "200");
    app.stop().await;
}

/// Runs `tests/python/SCRIPT` with `args`; its stdout, or `None` (with a note) when the tests
/// run without their Python set-up.
async fn python(modules: &[&str], script: &str, args: Vec<String>) -> Option<String> {
    let python = interpreter::python_with(modules)?;
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("python")
        .join(script);
    let out = tokio::task::spawn_blocking(move || {
        Command::new(python)
            .arg(script)
            .args(args)
            .output()
            .expect("running Python")
    })
    .await
    .unwrap();
    assert!(
        out.status.success(),
        "{}: {}{}",
        out.status,
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    Some(String::from_utf8(out.stdout).unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_python_client_streams_a_session_and_python_decodes_its_recording() {
    let app = TestApp::spawn().await;
    // A live session from Python, the frames' classes built from GET /api/v1/live/schema.
    let Some(out) = python(
        &["websockets", "google.protobuf"],
        "live_client.py",
        vec![app.addr.to_string(), "500".into()],
    )
    .await
    else {
        return;
    };
    let stored: Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(stored["type"], "stored", "{stored}");
    assert_eq!(stored["incomplete"], false);
    let meta = session(&app, stored["session_id"].as_i64().unwrap()).await;
    assert_eq!(meta["meta"]["scenario"], "python");
    assert_eq!(meta["meta"]["extra"]["live"]["samples"], "500");

    // A live recording (the simulated operator, grasping) decodes topic by topic with the
    // reference Python reader and nothing but the schemas inside the file.
    let s = scenario("sphere-lift", 2);
    let frames = live_client::simulated_frames(&s, Some(3.0), 1).unwrap();
    let summary = stream(&app, &s, frames).await;
    let r = app
        .client
        .get(&format!(
            "/api/v1/sessions/{}/mcap",
            summary.session_id.unwrap()
        ))
        .await;
    assert_eq!(r.status, 200);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("live.mcap");
    std::fs::write(&file, &r.body).unwrap();
    let Some(out) = python(
        &["mcap", "zstandard", "lz4", "mcap_protobuf"],
        "read_mcap.py",
        vec![file.display().to_string()],
    )
    .await
    else {
        return;
    };
    let report: Value = serde_json::from_str(&out).unwrap();
    let topics = report["topics"].as_object().unwrap();
    for topic in [
        "/glove/joint_states",
        "/glove/feedback",
        "/dfs/contacts",
        "/object/state",
        "/tf",
        "/scene",
        "/joint_states",
        "/hand",
    ] {
        assert!(topics[topic].as_u64().unwrap() > 0, "{topic}: {report}");
        assert_eq!(
            report["decoded"][topic], topics[topic],
            "{topic} decodes: {report}"
        );
    }
    assert_eq!(report["topics"]["/object/state"], 3000);
    assert_eq!(report["metadata"]["live"]["end_reason"], "ended");
    assert_eq!(report["metadata"]["session"]["source"], "live");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serve_foxglove_publishes_a_live_session_to_a_foxglove_websocket_client() {
    let app = TestApp::spawn_with(|a| a.foxglove = Some("127.0.0.1:0".parse().unwrap())).await;
    let port = app.foxglove_port.expect("the Foxglove server runs");
    // A Foxglove app, as its protocol (foxglove.sdk.v1: inline schemas) has it.
    let mut req = format!("ws://127.0.0.1:{port}")
        .into_client_request()
        .unwrap();
    req.headers_mut()
        .insert("sec-websocket-protocol", "foxglove.sdk.v1".parse().unwrap());
    let (mut viewer, _) = tokio_tungstenite::connect_async(req).await.unwrap();
    // A live session streaming meanwhile.
    let s = scenario("sphere-lift", 0);
    let frames = live_client::simulated_frames(&s, Some(2.0), 1).unwrap();
    let live_url = url(&app);
    let start = start_for(&s);
    let client = tokio::spawn(async move {
        let options = ClientOptions {
            token: None,
            realtime: true,
        };
        live_client::run(&live_url, &start, frames, &options, |_| {}).await
    });
    let mut subscribed = std::collections::BTreeMap::new();
    let mut got = std::collections::BTreeSet::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    while got.len() < 4 {
        let msg = tokio::time::timeout_at(deadline, viewer.next())
            .await
            .expect("Foxglove messages within 20 s")
            .unwrap()
            .unwrap();
        match msg {
            Message::Text(t) => {
                let v: Value = serde_json::from_str(t.as_str()).unwrap();
                if v["op"] != "advertise" {
                    continue;
                }
                for ch in v["channels"].as_array().unwrap() {
                    let topic = ch["topic"].as_str().unwrap().to_owned();
                    assert!(topic.starts_with("/live/1/"), "{topic}");
                    assert_eq!(ch["encoding"], "protobuf");
                    let id = subscribed.len() as u64 + 1;
                    subscribed.insert(id, (topic, ch["schemaName"].as_str().unwrap().to_owned()));
                    let sub = json!({"op": "subscribe",
                        "subscriptions": [{"id": id, "channelId": ch["id"]}]});
                    viewer
                        .send(Message::Text(sub.to_string().into()))
                        .await
                        .unwrap();
                }
            }
            Message::Binary(b) => {
                // Message data: opcode 1, subscription id (u32 LE), log time (u64 LE), payload.
                assert_eq!(b[0], 1);
                let id = u32::from_le_bytes(b[1..5].try_into().unwrap()) as u64;
                let (topic, schema) = subscribed[&id].clone();
                let payload = &b[13..];
                match schema.as_str() {
                    "foxglove.FrameTransforms" => {
                        let m = <foxglove::messages::FrameTransforms as prost::Message>::decode(
                            payload,
                        )
                        .unwrap();
                        assert!(!m.transforms.is_empty());
                    }
                    "foxglove.SceneUpdate" => {
                        let m =
                            <foxglove::messages::SceneUpdate as prost::Message>::decode(payload)
                                .unwrap();
                        assert!(!m.entities.is_empty());
                    }
                    "foxglove.JointStates" => {
                        let m =
                            <foxglove::messages::JointStates as prost::Message>::decode(payload)
                                .unwrap();
                        assert_eq!(m.joints.len(), 10);
                    }
                    other => panic!("{topic}: unexpected schema {other}"),
                }
                got.insert(topic);
            }
            _ => {}
        }
    }
    assert_eq!(
        got.into_iter().collect::<Vec<_>>(),
        [
            "/live/1/hand",
            "/live/1/joint_states",
            "/live/1/scene",
            "/live/1/tf"
        ]
    );
    let summary = client.await.unwrap().unwrap();
    assert!(summary.session_id.is_some());
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn any_stored_hand_serves_as_the_glove_model() {
    let app = TestApp::spawn().await;
    let hand = dfs_core::hand::builtin_hand("allegro").unwrap();
    let mid: Vec<f64> = (0..hand.dof())
        .map(|i| 0.5 * (hand.dof_lower[i] + hand.dof_upper[i]))
        .collect();
    let mut ws = connect(&app, None).await;
    let mut start = sphere_start();
    start["hand"] = json!("allegro");
    send_json(&mut ws, start).await;
    let started = expect_event(&mut ws, "started").await;
    assert_eq!(started["hand"], "allegro");
    assert_eq!(started["dofs"], json!(hand.dof_names));
    for i in 0..100u64 {
        let s = proto::Sample {
            t_ns: i * 1_000_000,
            q: mid.clone(),
            tau: vec![0.0; hand.dof()],
            wrist: Some(live_client::pose(&dfs_core::math::Isometry::translation(
                0.0, 0.0, 0.3,
            ))),
        };
        send_sample(&mut ws, &s).await;
        let fb = expect_feedback(&mut ws).await;
        assert_eq!(fb.motor_q.len(), hand.dof());
        assert_eq!(fb.fingers.len(), hand.fingertips.len());
    }
    send_json(&mut ws, json!({"type": "end"})).await;
    expect_event(&mut ws, "ended").await;
    let stored = expect_event(&mut ws, "stored").await;
    let meta = session(&app, stored["session_id"].as_i64().unwrap()).await;
    assert_eq!(meta["meta"]["hand"], "allegro");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_exported_to_csv_and_streamed_live_gives_the_skills_of_its_upload() {
    let app = TestApp::spawn().await;
    let dir = tempfile::tempdir().unwrap();
    let (session_file, csv) = (dir.path().join("s.mcap"), dir.path().join("s.csv"));
    let bytes = session_bytes("two-grasps", 5, None);
    std::fs::write(&session_file, &bytes).unwrap();
    services::session::export::export_glove_csv(&session_file, &csv).unwrap();
    let hand = dfs_core::hand::HandModel::glove10();
    let recording = services::session::import::read_glove_file(&csv, &hand).unwrap();
    assert!(recording.wrist.is_some() && recording.tau.is_some());
    let s = scenario("two-grasps", 5);
    let summary = stream(&app, &s, live_client::recording_frames(&recording)).await;
    assert_eq!(summary.refused, 0);
    let r = app.client.upload(&bytes, None).await;
    assert_eq!(r.status, 201);
    let uploaded = skills_of(&app, r.json()["session_id"].as_i64().unwrap()).await;
    let live = skills_of(&app, summary.session_id.unwrap()).await;
    assert_same_skills(&live, &uploaded, 2);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_glove_of_positions_only_is_coupled_and_calibrated() {
    let app = TestApp::spawn().await;
    let mut ws = connect(&app, None).await;
    let mut start = sphere_start();
    // Every raw angle reads 0.05 rad low on index_mcp.
    start["calibration"] = json!({"offsets": {"index_mcp": 0.05}});
    send_json(&mut ws, start).await;
    expect_event(&mut ws, "started").await;
    let positions = |t_ns: u64, index_mcp: f64| {
        let mut s = sample(t_ns);
        s.tau.clear();
        s.q[3] = index_mcp;
        s
    };
    send_sample(&mut ws, &positions(0, 0.05)).await;
    let fb = expect_feedback(&mut ws).await;
    // The simulated finger starts at the calibrated posture.
    assert!((fb.motor_q[3] - 0.10).abs() < 1e-9, "{:?}", fb.motor_q);
    // The operator closes index_mcp by 0.3 rad in 50 ms; the coupled finger follows.
    for i in 1..=300u64 {
        send_sample(
            &mut ws,
            &positions(i * 1_000_000, 0.05 + 0.3 * (i.min(50) as f64 / 50.0)),
        )
        .await;
        expect_feedback(&mut ws).await;
    }
    send_sample(&mut ws, &positions(301_000_000, 0.35)).await;
    let fb = expect_feedback(&mut ws).await;
    assert!((fb.motor_q[3] - 0.40).abs() < 0.02, "{:?}", fb.motor_q);
    // A glove of positions only stays one: a sample with torques is refused.
    send_sample(&mut ws, &sample(302_000_000)).await;
    let e = expect_event(&mut ws, "error").await;
    assert!(
        e["message"].as_str().unwrap().contains("positions only"),
        "{e}"
    );
    // The calibration applies before the limits (with the DFS's slack of 0.05 rad): a raw
    // angle within them may be out calibrated.
    let upper = dfs_core::hand::HandModel::glove10().dof_upper[3];
    send_sample(&mut ws, &positions(303_000_000, upper + 0.02)).await;
    let e = expect_event(&mut ws, "error").await;
    assert!(
        e["message"].as_str().unwrap().contains("(calibrated)"),
        "{e}"
    );
    send_json(&mut ws, json!({"type": "end"})).await;
    expect_event(&mut ws, "ended").await;
    let stored = expect_event(&mut ws, "stored").await;
    let meta = session(&app, stored["session_id"].as_i64().unwrap()).await;
    assert!(meta["meta"]["extra"]["calibration"]
        .as_str()
        .unwrap()
        .contains("index_mcp"));
    assert_eq!(meta["meta"]["extra"]["live"]["glove_input"], "positions");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scene_of_several_objects_streams_live_and_its_skill_names_the_target() {
    let app = TestApp::spawn().await;
    let s = scenario("table-three", 0);
    let frames = live_client::simulated_frames(&s, None, 1).unwrap();
    let summary = stream(&app, &s, frames).await;
    assert_eq!(summary.refused, 0);
    let meta = session(&app, summary.session_id.unwrap()).await;
    assert_eq!(meta["meta"]["extra"]["target"], "box", "{meta}");
    let skills = skills_of(&app, summary.session_id.unwrap()).await;
    assert_eq!(skills.len(), 1, "{meta}");
    assert_eq!(skills[0]["object_name"], "box");
    // Objects placed into one another are refused before any sample, naming both.
    let mut ws = connect(&app, None).await;
    send_json(
        &mut ws,
        json!({"type": "start", "target": "a", "objects": [
            {"name": "a", "shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8, "position": [0, 0, 0.04]},
            {"name": "b", "shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8, "position": [0.05, 0, 0.04]}
        ]}),
    )
    .await;
    let e = expect_event(&mut ws, "error").await;
    let m = e["message"].as_str().unwrap();
    assert!(
        m.contains("objects[1].position: \"b\" and \"a\"") && m.contains("overlap"),
        "{m}"
    );
    app.stop().await;
}
