//! Every error status of the API, each as an RFC 9457 problem: 400, 401, 404, 405, 413, 415,
//! 422, 503; bad input never gives a 500, and a failed upload stores nothing.

use reqwest::Method;
use serde_json::json;
use tests::{session_bytes, Client, TestApp};

/// The refused requests stored nothing: no session, and the five built-in hands only.
async fn assert_nothing_stored(c: &Client) {
    assert_eq!(c.get("/api/v1/sessions").await.json()["items"], json!([]));
    assert_eq!(
        c.get("/api/v1/hands").await.json()["items"]
            .as_array()
            .unwrap()
            .len(),
        5
    );
}

const TOKEN: &str = "test-token-1234";

#[tokio::test]
async fn invalid_filters_cursors_ids_and_parameters_are_400() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let d = c.get("/api/v1/skills?mass_min=heavy").await.problem(400);
    assert!(
        d.contains("mass_min"),
        "the detail names the parameter: {d}"
    );
    let d = c.get("/api/v1/skills?colour=red").await.problem(400);
    assert!(d.contains("colour"), "{d}");
    let d = c
        .get("/api/v1/skills?mass_min=2&mass_max=1")
        .await
        .problem(400);
    assert!(d.contains("mass"), "{d}");
    c.get("/api/v1/skills?limit=0").await.problem(400);
    c.get("/api/v1/skills?limit=5000").await.problem(400);
    c.get("/api/v1/skills?sort=colour").await.problem(400);
    c.get("/api/v1/skills?phase_min_s=1").await.problem(400);
    // A value no skill can have is refused, naming the parameter, not answered with an empty
    // page.
    for (query, name) in [
        ("shape=torus", "shape"),
        ("contact_model=magic", "contact_model"),
        ("grasp_type=pinch", "grasp_type"),
        ("phase=juggle", "phase"),
    ] {
        let d = c.get(&format!("/api/v1/skills?{query}")).await.problem(400);
        assert!(d.contains(name), "{query}: {d}");
    }
    assert_eq!(
        c.get("/api/v1/skills?grasp_type=precision").await.status,
        200
    );
    let d = c
        .get("/api/v1/skills?cursor=not-a-cursor")
        .await
        .problem(400);
    assert!(d.contains("cursor"), "{d}");
    // A cursor of one sort order is refused with another.
    let by_id: String = b"v1|id:asc|5".iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(
        c.get(&format!("/api/v1/skills?cursor={by_id}"))
            .await
            .status,
        200
    );
    c.get(&format!("/api/v1/skills?sort=quality&cursor={by_id}"))
        .await
        .problem(400);
    c.get("/api/v1/sessions?cursor=zz").await.problem(400);
    c.get("/api/v1/sessions?limit=-1").await.problem(400);
    c.get("/api/v1/skills/abc").await.problem(400);
    c.get("/api/v1/sessions/1.5").await.problem(400);
    c.get("/api/v1/skills/1/similar?k=0").await.problem(400);
    app.stop().await;
}

#[tokio::test]
async fn unknown_ids_and_routes_are_404_and_wrong_methods_405() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let d = c.get("/api/v1/skills/999").await.problem(404);
    assert!(d.contains("999"), "{d}");
    c.get("/api/v1/skills/999/similar").await.problem(404);
    c.get("/api/v1/sessions/999").await.problem(404);
    c.get("/api/v1/sessions/999/mcap").await.problem(404);
    c.delete("/api/v1/sessions/999", None).await.problem(404);
    c.delete("/api/v1/skills/999", None).await.problem(404);
    c.get("/api/v1/nothing-here").await.problem(404);
    c.get("/api/v2/skills").await.problem(404);
    let r = c.send(Method::PUT, "/api/v1/skills/1", None, None).await;
    let detail = r.problem(405);
    assert!(detail.contains("Allow header"), "{detail}");
    assert_eq!(r.headers["allow"], "GET,HEAD,DELETE", "{:?}", r.headers);
    c.send(Method::PATCH, "/api/v1/sessions", None, None)
        .await
        .problem(405);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_upload_is_bound_by_max_upload_not_by_the_body_limit_of_other_routes() {
    // Uploads are streamed to disk: their limit is their own.
    let app = TestApp::spawn_with(|a| a.max_body = 64 * 1024).await;
    let c = &app.client;
    let mcap = session_bytes("box-pinch-lift", 1, Some(2.0));
    assert!(
        mcap.len() > 64 * 1024,
        "the test session is over --max-body"
    );
    let r = c.upload(&mcap, None).await;
    assert_eq!(r.status, 201, "{:?}", r.body);
    // Nothing of the upload is left in the staging area: it became the blob.
    let left = files_under(&app.data.join("blobs/sha256/staging"));
    assert!(left.is_empty(), "{left:?}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_of_the_wrong_type_or_over_the_limit_are_refused_and_store_nothing() {
    let app = TestApp::spawn_with(|a| {
        a.max_body = 64 * 1024;
        a.max_upload = 64 * 1024;
    })
    .await;
    let c = &app.client;
    let mcap = session_bytes("box-pinch-lift", 1, Some(2.0));
    assert!(mcap.len() > 64 * 1024, "the test session is over the limit");

    let r = c.upload(&mcap, None).await;
    // The rest of the body is not read: the answer says the connection closes, so the client
    // does not send the next request on it.
    assert_eq!(
        r.headers.get("connection").map(|v| v.as_bytes()),
        Some(&b"close"[..]),
        "{:?}",
        r.headers
    );
    let d = r.problem(413);
    assert!(d.contains("65536"), "{d}");
    let r = c
        .send(
            Method::POST,
            "/api/v1/sessions",
            Some(("application/octet-stream", b"abc".to_vec())),
            None,
        )
        .await;
    assert!(r.problem(415).contains("application/x-mcap"));
    c.send(Method::POST, "/api/v1/sessions", None, None)
        .await
        .problem(415);
    let r = c
        .send(
            Method::POST,
            "/api/v1/simulations",
            Some(("text/plain", b"{\"scenario\": \"box-slip\"}".to_vec())),
            None,
        )
        .await;
    r.problem(415);
    let big = json!({"scenario": "x".repeat(70 * 1024)});
    c.post_json("/api/v1/simulations", &big, None)
        .await
        .problem(413);

    let sessions = c.get("/api/v1/sessions").await.json();
    assert_eq!(sessions["items"], json!([]));
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_invalid_session_is_422_with_its_reason_and_stores_nothing() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let d = c
        .upload(b"definitely not an mcap file", None)
        .await
        .problem(422);
    assert!(d.contains("MCAP"), "the reason: {d}");

    let mcap = session_bytes("box-slip", 2, Some(1.0));
    let cut = &mcap[..mcap.len() * 2 / 3];
    let d = c.upload(cut, None).await.problem(422);
    assert!(d.contains("not a valid session"), "{d}");
    let mut flipped = mcap.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0xff;
    c.upload(&flipped, None).await.problem(422);
    c.upload(b"", None).await.problem(422);

    assert_eq!(c.get("/api/v1/sessions").await.json()["items"], json!([]));
    assert_eq!(c.get("/api/v1/skills").await.json()["items"], json!([]));
    // No blob, and nothing left of the uploads streamed to the staging area.
    let files = files_under(&app.data.join("blobs"));
    assert!(files.is_empty(), "no blob was written: {files:?}");
    app.stop().await;
}

/// The files under `dir`, at any depth (none if it does not exist).
fn files_under(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.is_dir() {
            out.extend(files_under(&path));
        } else {
            out.push(path);
        }
    }
    out
}

#[tokio::test]
async fn bad_simulation_requests_are_400_or_422_naming_the_field() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let r = c
        .send(
            Method::POST,
            "/api/v1/simulations",
            Some(("application/json", b"{\"scenario\": ".to_vec())),
            None,
        )
        .await;
    r.problem(400);
    let d = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "moonwalk"}),
            None,
        )
        .await
        .problem(422);
    assert!(
        d.contains("two-grasps"),
        "lists the built-in scenarios: {d}"
    );
    let d = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "box-slip", "seed": -1}),
            None,
        )
        .await
        .problem(422);
    assert!(d.contains("seed"), "{d}");
    let d = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "box-slip", "duration": 1e6}),
            None,
        )
        .await
        .problem(422);
    assert!(d.contains("duration"), "{d}");
    let d = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": {"name": "x", "object": {"shape": "box", "mass": -1, "mu": 0.5,
                "half_extents": [0.02, 0.02, 0.04]}, "tasks": [{"phase": "grasp", "duration": 1}]}}),
            None,
        )
        .await
        .problem(422);
    assert!(d.contains("mass"), "{d}");
    // A 1 g box made the explicit object step diverge at lift-off and the server answered 500:
    // it is refused up front now, naming the field and the bound.
    let d = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": {"name": "x", "object": {"shape": "box", "mass": 0.001, "mu": 0.8,
                "half_extents": [0.025, 0.025, 0.04]}, "tasks": [{"phase": "grasp", "duration": 1}]}}),
            None,
        )
        .await
        .problem(422);
    assert!(d.contains("object.mass") && d.contains("0.005"), "{d}");
    let d = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "box-slip", "speed": 2}),
            None,
        )
        .await
        .problem(422);
    assert!(d.contains("speed"), "{d}");
    assert_eq!(c.get("/api/v1/sessions").await.json()["items"], json!([]));
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn writes_need_the_token_when_one_is_configured_and_reads_stay_open() {
    let app = TestApp::spawn_with(|a| a.token = Some(TOKEN.into())).await;
    let c = &app.client;
    let mcap = session_bytes("box-slip", 4, Some(2.0));

    let r = c.upload(&mcap, None).await;
    assert!(r.problem(401).contains("Bearer"));
    assert!(r.headers.contains_key("www-authenticate"));
    c.upload(&mcap, Some("wrong-token")).await.problem(401);
    c.post_json(
        "/api/v1/simulations",
        &json!({"scenario": "box-slip"}),
        None,
    )
    .await
    .problem(401);
    // 401 comes before anything is read: even a bad body is refused for the token first.
    c.send(
        Method::POST,
        "/api/v1/sessions",
        Some(("text/plain", vec![])),
        None,
    )
    .await
    .problem(401);
    assert_eq!(c.get("/api/v1/sessions").await.json()["items"], json!([]));

    let r = c.upload(&mcap, Some(TOKEN)).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["session_id"].as_i64().unwrap();
    // Reads need no token.
    assert_eq!(c.get(&format!("/api/v1/sessions/{id}")).await.status, 200);
    assert_eq!(c.get("/api/v1/skills").await.status, 200);
    assert_eq!(
        c.get(&format!("/api/v1/sessions/{id}/mcap")).await.status,
        200
    );
    // Deletes do.
    c.delete(&format!("/api/v1/sessions/{id}"), None)
        .await
        .problem(401);
    c.delete(&format!("/api/v1/sessions/{id}"), Some("nope"))
        .await
        .problem(401);
    c.delete("/api/v1/skills/1", None).await.problem(401);
    assert_eq!(c.get(&format!("/api/v1/sessions/{id}")).await.status, 200);
    assert_eq!(
        c.delete(&format!("/api/v1/sessions/{id}"), Some(TOKEN))
            .await
            .status,
        204
    );
    app.stop().await;
}

/// A JSON body of the wrong shape inside a nested object names the field as `outer: ...`,
/// without a stray `..` (the path of the object itself).
#[tokio::test]
async fn a_nested_object_missing_a_field_is_named_without_stray_dots() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let d = c
        .post_json("/api/v1/simulations", &json!({"scenario": {}}), None)
        .await
        .problem(422);
    assert!(!d.contains(".."), "{d}");
    assert!(d.starts_with("scenario: ") && d.contains("`name`"), "{d}");
    let d = c
        .post_json(
            "/api/v1/hands",
            &json!({"spec": {}, "urdf": "<robot/>"}),
            None,
        )
        .await
        .problem(422);
    assert!(!d.contains(".."), "{d}");
    assert!(d.starts_with("spec: ") && d.contains("`name`"), "{d}");
    app.stop().await;
}

/// The authentication scheme is case-insensitive (RFC 9110 §11.1): `BEARER`, `bearer` and
/// `Bearer` all carry the token; another scheme is refused naming the one to use.
#[tokio::test]
async fn the_bearer_scheme_is_accepted_in_any_case_and_another_scheme_is_named() {
    let app = TestApp::spawn_with(|a| a.token = Some(TOKEN.into())).await;
    let http = reqwest::Client::new();
    let delete = |auth: String| {
        http.delete(format!("{}/api/v1/skills/999", app.client.base))
            .header(reqwest::header::AUTHORIZATION, auth)
            .send()
    };
    for scheme in ["Bearer", "bearer", "BEARER", "bEaReR"] {
        let r = delete(format!("{scheme} {TOKEN}")).await.unwrap();
        // Past the token check: the skill does not exist.
        assert_eq!(r.status(), 404, "{scheme}");
    }
    let r = delete(format!("Bearer   {TOKEN}")).await.unwrap();
    assert_eq!(r.status(), 404, "several spaces after the scheme");
    for auth in [format!("Basic {TOKEN}"), TOKEN.to_string()] {
        let r = delete(auth.clone()).await.unwrap();
        assert_eq!(r.status(), 401, "{auth}");
        let p: serde_json::Value = serde_json::from_slice(&r.bytes().await.unwrap()).unwrap();
        assert!(p["detail"].as_str().unwrap().contains("Bearer"), "{p}");
    }
    let r = delete(format!("BEARER {TOKEN}x")).await.unwrap();
    assert_eq!(r.status(), 401);
    app.stop().await;
}

/// A write refused before its body is read (401 here) still reads the body: the client, which
/// sends the whole body before it looks for an answer, gets the 401 rather than a reset
/// connection, and can send its next request on the same connection.
#[tokio::test]
async fn a_refused_upload_is_answered_after_its_body_and_the_connection_stays_open() {
    use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};

    let app = TestApp::spawn_with(|a| a.token = Some(TOKEN.into())).await;
    let body = vec![0x5a_u8; 8 << 20];
    let stream = tokio::net::TcpStream::connect(app.addr).await.unwrap();
    let (read, mut write) = stream.into_split();
    let mut read = BufReader::new(read);
    let head = format!(
        "POST /api/v1/sessions HTTP/1.1\r\nHost: {}\r\nContent-Type: application/x-mcap\r\n\
         Content-Length: {}\r\n\r\n",
        app.addr,
        body.len()
    );
    write.write_all(head.as_bytes()).await.unwrap();
    // 8 MiB is far more than the socket buffers hold: this only finishes if the server reads.
    write
        .write_all(&body)
        .await
        .expect("the server reads the refused body instead of resetting the connection");

    /// Reads one response: its status line and its body (by Content-Length).
    async fn response(read: &mut BufReader<tokio::net::tcp::OwnedReadHalf>) -> (String, String) {
        let mut status = String::new();
        read.read_line(&mut status).await.unwrap();
        let mut length = 0;
        loop {
            let mut line = String::new();
            read.read_line(&mut line).await.unwrap();
            if line == "\r\n" {
                break;
            }
            if let Some((name, value)) = line.split_once(':') {
                if name.eq_ignore_ascii_case("content-length") {
                    length = value.trim().parse().unwrap();
                }
            }
        }
        let mut body = vec![0; length];
        read.read_exact(&mut body).await.unwrap();
        (status, String::from_utf8(body).unwrap())
    }

    let (status, problem) = response(&mut read).await;
    assert!(status.starts_with("HTTP/1.1 401"), "{status}");
    assert!(problem.contains("Bearer"), "{problem}");
    let get = format!("GET /healthz HTTP/1.1\r\nHost: {}\r\n\r\n", app.addr);
    write.write_all(get.as_bytes()).await.unwrap();
    let (status, _) = response(&mut read).await;
    assert!(status.starts_with("HTTP/1.1 200"), "{status}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_request_over_the_time_limit_is_a_503_problem() {
    // Ten seconds of session take far longer than 20 ms to read and segment.
    let mcap = tests::session_bytes("two-grasps", 1, Some(10.0));
    let app = TestApp::spawn_with(|a| a.request_timeout = 0.02).await;
    let d = app.client.upload(&mcap, None).await.problem(503);
    assert!(d.contains("limit"), "{d}");
    app.stop().await;
    // A simulation is a job: the request stops waiting for it before the time limit (at 80 %
    // of it, 0.4 s here) and answers 202 with the job, which runs to its end.
    let app = TestApp::spawn_with(|a| a.request_timeout = 0.5).await;
    let r = app
        .client
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "two-grasps", "duration": 120.0}),
            None,
        )
        .await;
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    app.stop().await;
}

/// A replay's MCAP reads like a session; uploaded as one it is refused as a replay recording
/// (it used to be stored as a skill of shape `unknown` with no parameters).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replay_recording_uploaded_as_a_session_is_refused_as_one() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let r = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": "box-pinch-lift"}),
            None,
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let skill_id = r.json()["skills"][0]["id"].as_i64().unwrap();
    let r = c
        .post_json(
            &format!("/api/v1/skills/{skill_id}/replays"),
            &json!({"hand": "gripper"}),
            None,
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let mcap = c.get(r.json()["mcap_url"].as_str().unwrap()).await;
    assert_eq!(mcap.status, 200);
    let d = c.upload(&mcap.body, None).await.problem(422);
    assert!(
        d.contains("replay recording")
            && d.contains("gripper")
            && d.contains("not a grasp session"),
        "{d}"
    );
    let sessions = c.get("/api/v1/sessions").await.json();
    assert_eq!(sessions["items"].as_array().unwrap().len(), 1, "{sessions}");
    app.stop().await;
}

/// serde_json keeps the last of two equal keys, so `{"hand": "allegro", "hand": "barrett"}`
/// would silently replay on Barrett: a JSON body with a key twice, at any depth, is refused
/// naming the key, before anything runs or is stored.
#[tokio::test]
async fn a_json_body_with_a_key_twice_is_refused_naming_the_key() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let post = |path: &'static str, body: &'static str| {
        c.send(
            Method::POST,
            path,
            Some(("application/json", body.as_bytes().to_vec())),
            None,
        )
    };
    let d = post(
        "/api/v1/simulations",
        r#"{"scenario": "box-slip", "seed": 1, "scenario": "two-grasps"}"#,
    )
    .await
    .problem(400);
    assert!(d.contains("duplicate") && d.contains("\"scenario\""), "{d}");
    let d = post(
        "/api/v1/simulations",
        r#"{"scenario": {"name": "x", "object": {"shape": "box", "mass": 1, "mass": 2}}}"#,
    )
    .await
    .problem(400);
    assert!(
        d.contains("duplicate") && d.contains("\"mass\"") && d.contains("scenario.object"),
        "{d}"
    );
    let d = post(
        "/api/v1/skills/1/replays",
        r#"{"hand": "allegro", "hand": "barrett"}"#,
    )
    .await
    .problem(400);
    assert!(d.contains("\"hand\""), "{d}");
    let d = post(
        "/api/v1/hands",
        r#"{"spec": {"name": "a"}, "urdf": "<robot/>", "urdf": "<robot/>"}"#,
    )
    .await
    .problem(400);
    assert!(d.contains("\"urdf\""), "{d}");
    // Equal keys in different objects, and in the objects of a list, are fine: this body is
    // read, and refused only for its negative mass.
    let d = post(
        "/api/v1/simulations",
        r#"{"scenario": {"name": "x", "object": {"shape": "box", "mass": -1, "mu": 0.5,
            "half_extents": [0.02, 0.02, 0.04]}, "tasks": [{"phase": "grasp", "duration": 1},
            {"phase": "lift", "duration": 1}]}}"#,
    )
    .await
    .problem(422);
    assert!(d.contains("mass"), "{d}");
    assert_nothing_stored(c).await;
    app.stop().await;
}

#[tokio::test]
async fn a_json_array_in_place_of_a_request_object_is_refused_naming_the_object() {
    // serde's derived structs also take their fields in order as a JSON array: this body was
    // run as box-slip with seed 3 for 1 s. Every request body is a JSON object only.
    let app = TestApp::spawn().await;
    let c = &app.client;
    for (path, body, what) in [
        (
            "/api/v1/simulations",
            json!(["box-slip", 3, 1.0]),
            "a simulation request",
        ),
        (
            "/api/v1/skills/1/replays",
            json!(["allegro"]),
            "a replay request",
        ),
        (
            "/api/v1/hands",
            json!([{"name": "h"}, "<robot name=\"h\"/>"]),
            "a hand upload",
        ),
    ] {
        let d = c.post_json(path, &body, None).await.problem(422);
        assert!(d.contains(what) && d.contains("JSON object"), "{path}: {d}");
    }
    // A scenario object is held to a grasp file's ranges: a 1e30 kg box is no hand-held object.
    let d = c
        .post_json(
            "/api/v1/simulations",
            &json!({"scenario": {"name": "x", "object": {"shape": "box", "mass": 1e30, "mu": 0.5,
                "half_extents": [0.02, 0.02, 0.04]}, "tasks": [{"phase": "grasp", "duration": 1}]}}),
            None,
        )
        .await
        .problem(422);
    assert!(d.contains("object.mass"), "{d}");
    assert_nothing_stored(c).await;
    app.stop().await;
}

/// Sends `request` on a fresh connection and reads one answer: its status line, its headers
/// (names lower-cased) and its body (by Content-Length).
async fn raw_exchange(
    addr: std::net::SocketAddr,
    request: &[u8],
) -> (String, Vec<(String, String)>, Vec<u8>) {
    use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
    let stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    let (read, mut write) = stream.into_split();
    write.write_all(request).await.unwrap();
    let mut read = BufReader::new(read);
    let mut status = String::new();
    read.read_line(&mut status).await.unwrap();
    let mut headers = Vec::new();
    loop {
        let mut line = String::new();
        read.read_line(&mut line).await.unwrap();
        if line == "\r\n" || line.is_empty() {
            break;
        }
        let (name, value) = line.split_once(':').expect("a header line");
        headers.push((name.trim().to_ascii_lowercase(), value.trim().to_owned()));
    }
    let length: usize = headers
        .iter()
        .find(|(n, _)| n == "content-length")
        .map_or(0, |(_, v)| v.parse().unwrap());
    let mut body = vec![0; length];
    read.read_exact(&mut body).await.unwrap();
    (status.trim_end().to_owned(), headers, body)
}

/// Asserts a raw answer is the problem `status`; returns its detail.
fn raw_problem(answer: &(String, Vec<(String, String)>, Vec<u8>), status: u16) -> String {
    let (line, headers, body) = answer;
    assert!(
        line.starts_with(&format!("HTTP/1.1 {status} ")),
        "{line}: {}",
        String::from_utf8_lossy(body)
    );
    let content_type = headers.iter().find(|(n, _)| n == "content-type");
    assert_eq!(
        content_type.map(|(_, v)| v.as_str()),
        Some("application/problem+json"),
        "{line} {headers:?}"
    );
    let p: serde_json::Value = serde_json::from_slice(body)
        .unwrap_or_else(|e| panic!("{line}: not JSON ({e}): {}", String::from_utf8_lossy(body)));
    assert_eq!(p["status"], status, "{p}");
    assert!(p["title"].as_str().is_some_and(|t| !t.is_empty()), "{p}");
    p["detail"].as_str().expect("a detail").to_owned()
}

/// Requests hyper refuses before the router sees them (a Content-Length that is not a number,
/// more headers than it takes) get hyper's status with no body and a closed connection; bodies
/// that break while they are read reach the router and are problems.
#[tokio::test]
async fn requests_refused_while_parsing_or_reading_the_body() {
    let app = TestApp::spawn().await;
    let host = app.addr;
    for path in ["/api/v1/simulations", "/api/v1/sessions", "/healthz"] {
        let request = format!(
            "POST {path} HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\n\
             Content-Length: ten\r\n\r\n"
        );
        let (line, headers, body) = raw_exchange(app.addr, request.as_bytes()).await;
        assert!(line.starts_with("HTTP/1.1 400 "), "{path}: {line}");
        assert!(
            body.is_empty(),
            "{path}: {}",
            String::from_utf8_lossy(&body)
        );
        assert!(
            headers
                .iter()
                .any(|(n, v)| n == "connection" && v == "close"),
            "{headers:?}"
        );
    }
    let many: String = (0..150).map(|i| format!("X-Header-{i}: {i}\r\n")).collect();
    let request = format!("GET /healthz HTTP/1.1\r\nHost: {host}\r\n{many}\r\n");
    let (line, _, _) = raw_exchange(app.addr, request.as_bytes()).await;
    assert!(line.starts_with("HTTP/1.1 431 "), "{line}");
    // A chunked body whose chunk size is not hexadecimal: the body cannot be read.
    for (path, content_type) in [
        ("/api/v1/simulations", "application/json"),
        ("/api/v1/sessions", "application/x-mcap"),
    ] {
        let request = format!(
            "POST {path} HTTP/1.1\r\nHost: {host}\r\nContent-Type: {content_type}\r\n\
             Transfer-Encoding: chunked\r\n\r\nzz\r\n{{}}\r\n0\r\n\r\n"
        );
        let d = raw_problem(&raw_exchange(app.addr, request.as_bytes()).await, 400);
        assert!(d.contains("request body"), "{path}: {d}");
    }
    // The server still answers.
    assert_eq!(app.client.get("/healthz").await.status, 200);
    app.stop().await;
}

/// Every endpoint that takes query parameters refuses one it does not know (a typo would
/// otherwise answer as if no filter were given), naming it; endpoints that take none ignore
/// them (cache busters such as `?_=123`).
#[tokio::test]
async fn unknown_query_parameters_are_refused_where_parameters_are_taken() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    for (path, name) in [
        ("/api/v1/skills?shpe=sphere", "shpe"),
        ("/api/v1/skills?shape=box&limt=5", "limt"),
        ("/api/v1/sessions?limt=5", "limt"),
        ("/api/v1/skills/1/similar?kk=3", "kk"),
    ] {
        let d = c.get(path).await.problem(400);
        assert!(d.contains(&format!("`{name}`")), "{path}: {d}");
    }
    for path in [
        "/healthz?_=123",
        "/api/v1/openapi.json?_=123",
        "/api/v1/hands?_=123",
        "/api/v1/hands/allegro?_=123",
    ] {
        assert_eq!(c.get(path).await.status, 200, "{path}");
    }
    app.stop().await;
}
