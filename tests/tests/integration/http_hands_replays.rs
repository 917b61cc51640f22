//! Robot hands and replays over HTTP (issue 6, item 4): built-in and uploaded hands, every bad
//! URDF refused with 422 naming the problem and nothing stored, replays of a stored skill on a
//! hand (201 with the report, also when the replay fails), fetched back with their MCAP, and
//! deleted with their skill.

use std::path::Path;

use serde_json::{json, Value};
use services::mcap_io::{read_session_bytes, ReadLimits};
use services::replay::REPLAY_METADATA;
use tests::{session_bytes_without_object, Client, TestApp};

const TOKEN: &str = "hands-token";

/// The built-in gripper's spec under another name, without its `urdf` file name.
fn gripper_spec(name: &str) -> Value {
    let (spec, _) = dfs_core::hand::builtin_spec("gripper").unwrap();
    let mut v = serde_json::to_value(spec).unwrap();
    v["name"] = json!(name);
    v.as_object_mut().unwrap().remove("urdf");
    v
}

fn gripper_urdf() -> String {
    dfs_core::hand::builtin::GRIPPER_URDF.to_owned()
}

fn blob_path(data: &Path, sha256: &str) -> std::path::PathBuf {
    data.join(format!(
        "blobs/sha256/{}/{}.mcap",
        &sha256[..2],
        &sha256[2..]
    ))
}

/// Runs `POST /simulations` with `body`: the stored session and the id of its first skill.
async fn simulate(c: &Client, body: Value) -> (Value, i64) {
    let r = c.post_json("/api/v1/simulations", &body, None).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let sim = r.json();
    let skill_id = sim["skills"][0]["id"].as_i64().unwrap();
    (sim, skill_id)
}

async fn hand_names(c: &Client) -> Vec<String> {
    let r = c.get("/api/v1/hands").await;
    assert_eq!(r.status, 200);
    r.json()["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| h["name"].as_str().unwrap().to_owned())
        .collect()
}

#[tokio::test]
async fn built_in_hands_are_listed_and_an_uploaded_hand_joins_them_once() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let list = c.get("/api/v1/hands").await.json();
    let items = list["items"].as_array().unwrap();
    let names: Vec<&str> = items.iter().map(|h| h["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        ["glove10", "allegro", "barrett", "inspire", "gripper"]
    );
    let allegro = &items[1];
    assert_eq!(allegro["builtin"], true);
    assert_eq!(allegro["dof"], 16);
    assert_eq!(allegro["fingers"].as_array().unwrap().len(), 4);
    assert_eq!(allegro["torque_limit"], json!([0.7, 0.7]));

    let g = c.get("/api/v1/hands/gripper").await.json();
    assert_eq!(g["spec"]["fingertips"][0]["link"], "right_finger");
    assert_eq!(g["urdf_url"], "/api/v1/hands/gripper/urdf");
    let urdf = c.get("/api/v1/hands/gripper/urdf").await;
    assert_eq!(urdf.status, 200);
    assert_eq!(urdf.content_type(), "application/xml");
    assert_eq!(urdf.body, gripper_urdf().as_bytes());
    let glove = c.get("/api/v1/hands/glove10").await.json();
    assert_eq!(glove["spec"], Value::Null);
    c.get("/api/v1/hands/glove10/urdf").await.problem(404);

    let upload = json!({"spec": gripper_spec("my-gripper"), "urdf": gripper_urdf()});
    let r = c.post_json("/api/v1/hands", &upload, None).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(
        r.headers["location"].to_str().unwrap(),
        "/api/v1/hands/my-gripper"
    );
    let h = r.json();
    assert_eq!(h["builtin"], false);
    assert_eq!(h["dof"], 2);
    assert_eq!(h["fingers"], json!(["thumb", "finger"]));
    assert_eq!(h["spec"]["urdf"], "my-gripper.urdf");
    assert!(h["created_at"].as_str().is_some());
    assert_eq!(hand_names(c).await.last().unwrap(), "my-gripper");
    assert_eq!(
        c.get("/api/v1/hands/my-gripper").await.json()["spec"],
        h["spec"]
    );
    assert_eq!(
        c.get("/api/v1/hands/my-gripper/urdf").await.body,
        gripper_urdf().as_bytes()
    );

    // The same name again, or a built-in's name: 409, nothing changes.
    let d = c
        .post_json("/api/v1/hands", &upload, None)
        .await
        .problem(409);
    assert!(d.contains("my-gripper"), "{d}");
    let clash = json!({"spec": gripper_spec("allegro"), "urdf": gripper_urdf()});
    let d = c
        .post_json("/api/v1/hands", &clash, None)
        .await
        .problem(409);
    assert!(
        d.contains("built-in") && d.contains("cannot be replaced"),
        "{d}"
    );
    // A built-in's name in another case was stored beside it: "Allegro" and "allegro".
    for name in ["Allegro", "GLOVE10"] {
        let clash = json!({"spec": gripper_spec(name), "urdf": gripper_urdf()});
        let d = c
            .post_json("/api/v1/hands", &clash, None)
            .await
            .problem(409);
        assert!(d.contains("only in case") && d.contains(name), "{d}");
    }
    assert_eq!(hand_names(c).await.len(), 6);
    c.get("/api/v1/hands/nobody").await.problem(404);
    app.stop().await;
}

#[tokio::test]
async fn every_bad_hand_is_refused_with_422_naming_the_problem_and_nothing_is_stored() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let urdf = gripper_urdf();
    let two_roots = urdf.replace(
        "</robot>",
        "<link name=\"stray\"/><link name=\"stray_child\"/>\
         <joint name=\"stray_joint\" type=\"fixed\"><parent link=\"stray\"/>\
         <child link=\"stray_child\"/></joint></robot>",
    );
    // palm's parent joint is wrist_roll; a second joint into palm closes a loop.
    let with_loop = urdf.replace(
        "</robot>",
        "<joint name=\"loop_joint\" type=\"fixed\"><parent link=\"left_finger\"/>\
         <child link=\"palm\"/></joint></robot>",
    );
    let negative_mass = urdf.replace("<mass value=\"0.6\"/>", "<mass value=\"-0.6\"/>");
    let mut unknown_tip = gripper_spec("bad-tip");
    unknown_tip["fingertips"][1]["link"] = json!("nail");
    let mut negative_radius = gripper_spec("bad-radius");
    negative_radius["fingertips"][0]["radius"] = json!(-0.01);

    let cases = [
        (
            "does not parse",
            gripper_spec("bad-xml"),
            "<robot name=\"x\"><link name=\"a\">".to_owned(),
            &["urdf", "does not parse"][..],
        ),
        ("loop", gripper_spec("bad-loop"), with_loop, &["loop"][..]),
        (
            "two roots",
            gripper_spec("bad-roots"),
            two_roots,
            &["root", "stray"][..],
        ),
        (
            "unknown fingertip link",
            unknown_tip,
            urdf.clone(),
            &["fingertips[1].link", "nail"][..],
        ),
        (
            "negative mass",
            gripper_spec("bad-mass"),
            negative_mass,
            &["palm", "mass"][..],
        ),
        (
            "negative radius",
            negative_radius,
            urdf.clone(),
            &["fingertips[0].radius"][..],
        ),
    ];
    for (what, spec, urdf, words) in cases {
        let d = c
            .post_json("/api/v1/hands", &json!({"spec": spec, "urdf": urdf}), None)
            .await
            .problem(422);
        for w in words {
            assert!(d.contains(w), "{what}: the detail names {w:?}: {d}");
        }
    }
    // Malformed uploads: a spec field of the wrong type, a missing URDF.
    let mut typo = gripper_spec("bad-type");
    typo["torque_limit"] = json!("strong");
    let d = c
        .post_json("/api/v1/hands", &json!({"spec": typo, "urdf": urdf}), None)
        .await
        .problem(422);
    assert!(d.contains("spec.torque_limit"), "{d}");
    let d = c
        .post_json("/api/v1/hands", &json!({"spec": gripper_spec("x")}), None)
        .await
        .problem(422);
    assert!(d.contains("urdf"), "{d}");
    assert_eq!(hand_names(c).await.len(), 5, "nothing was stored");
    app.stop().await;
}

#[tokio::test]
async fn hand_uploads_and_replays_need_the_token_when_one_is_configured() {
    let app = TestApp::spawn_with(|a| a.token = Some(TOKEN.into())).await;
    let c = &app.client;
    let upload = json!({"spec": gripper_spec("tok-gripper"), "urdf": gripper_urdf()});
    c.post_json("/api/v1/hands", &upload, None)
        .await
        .problem(401);
    c.post_json("/api/v1/hands", &upload, Some("wrong"))
        .await
        .problem(401);
    c.post_json(
        "/api/v1/skills/1/replays",
        &json!({"hand": "gripper"}),
        None,
    )
    .await
    .problem(401);
    assert_eq!(hand_names(c).await.len(), 5);
    let r = c.post_json("/api/v1/hands", &upload, Some(TOKEN)).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    // Reads stay open.
    assert_eq!(c.get("/api/v1/hands/tok-gripper").await.status, 200);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_skill_replays_on_hands_and_its_replays_are_fetched_and_deleted_with_it() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let (_, skill_id) = simulate(c, json!({"scenario": "box-pinch-lift"})).await;
    let replays = format!("/api/v1/skills/{skill_id}/replays");

    // On the built-in gripper: held.
    let r = c
        .post_json(&replays, &json!({"hand": "gripper"}), None)
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let ok = r.json();
    let ok_id = ok["replay_id"].as_i64().unwrap();
    assert_eq!(
        r.headers["location"].to_str().unwrap(),
        format!("/api/v1/replays/{ok_id}")
    );
    assert_eq!(ok["skill_id"], skill_id);
    assert_eq!(ok["hand"], "gripper");
    assert_eq!(ok["success"], true, "{}", ok["report"]);
    assert_eq!(ok["report"]["success"], true);
    assert_eq!(ok["failure_reason"], Value::Null);
    // The document's schema of the report (dfs-core's `ReplayReport`) names every field the
    // server sends.
    let doc = c.get("/api/v1/openapi.json").await.json();
    let schema = &doc["components"]["schemas"]["ReplayReport"]["properties"];
    for key in ok["report"].as_object().unwrap().keys() {
        assert!(
            schema.get(key).is_some(),
            "the documented report lacks {key}"
        );
    }
    assert!(ok["report"]["lift_height_m"].as_f64().unwrap() > 0.05);

    // Read back: the report, and the MCAP with the replay's metadata.
    let got = c.get(&format!("/api/v1/replays/{ok_id}")).await;
    assert_eq!(got.status, 200);
    assert_eq!(got.json(), ok);
    let mcap = c.get(ok["mcap_url"].as_str().unwrap()).await;
    assert_eq!(mcap.status, 200);
    assert_eq!(mcap.content_type(), "application/x-mcap");
    assert!(mcap.body.starts_with(b"\x89MCAP0\r\n"));
    assert_eq!(mcap.body.len() as i64, ok["size_bytes"].as_i64().unwrap());
    let rec = read_session_bytes(&mcap.body, &ReadLimits::default()).unwrap();
    let meta = rec.metadata(REPLAY_METADATA).unwrap();
    assert_eq!(meta["hand"], "gripper");
    assert_eq!(meta["skill_id"], skill_id.to_string());

    // An uploaded copy of the gripper replays like it.
    let upload = json!({"spec": gripper_spec("my-gripper"), "urdf": gripper_urdf()});
    assert_eq!(
        c.post_json("/api/v1/hands", &upload, None).await.status,
        201
    );
    let r = c
        .post_json(&replays, &json!({"hand": "my-gripper"}), None)
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let mine = r.json();
    assert_eq!(mine["hand"], "my-gripper");
    assert_eq!(mine["success"], true, "{}", mine["report"]);

    // A gripper whose jaws open 2 cm cannot take the 5 cm box: a failed replay, still 201.
    let tiny_urdf = gripper_urdf().replace("upper=\"0.055\"", "upper=\"0.010\"");
    let upload = json!({"spec": gripper_spec("tiny-gripper"), "urdf": tiny_urdf});
    assert_eq!(
        c.post_json("/api/v1/hands", &upload, None).await.status,
        201
    );
    let r = c
        .post_json(&replays, &json!({"hand": "tiny-gripper"}), None)
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let failed = r.json();
    assert_eq!(failed["success"], false);
    assert_eq!(
        failed["failure_reason"], "unreachable",
        "{}",
        failed["report"]
    );
    assert_eq!(failed["report"]["failure_reason"], "unreachable");
    assert_eq!(
        c.get(failed["mcap_url"].as_str().unwrap()).await.status,
        200
    );

    // Bad requests store nothing.
    let d = c
        .post_json(&replays, &json!({"hand": "nobody"}), None)
        .await
        .problem(422);
    assert!(d.contains("nobody"), "{d}");
    c.post_json(&replays, &json!({"hnad": "gripper"}), None)
        .await
        .problem(422);
    c.post_json(
        "/api/v1/skills/99999/replays",
        &json!({"hand": "gripper"}),
        None,
    )
    .await
    .problem(404);

    let list = c.get(&replays).await.json();
    let ids: Vec<i64> = list["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["replay_id"].as_i64().unwrap())
        .collect();
    assert_eq!(
        ids,
        [
            ok_id,
            mine["replay_id"].as_i64().unwrap(),
            failed["replay_id"].as_i64().unwrap()
        ]
    );
    let blobs: Vec<_> = [&ok, &mine, &failed]
        .iter()
        .map(|r| blob_path(&app.data, r["sha256"].as_str().unwrap()))
        .collect();
    assert!(blobs.iter().all(|b| b.exists()));

    // Deleting the skill takes its replays and their files.
    assert_eq!(
        c.delete(&format!("/api/v1/skills/{skill_id}"), None)
            .await
            .status,
        204
    );
    for r in [&ok, &mine, &failed] {
        let id = r["replay_id"].as_i64().unwrap();
        c.get(&format!("/api/v1/replays/{id}")).await.problem(404);
        c.get(&format!("/api/v1/replays/{id}/mcap"))
            .await
            .problem(404);
    }
    assert!(blobs.iter().all(|b| !b.exists()), "replay blobs removed");
    c.get(&replays).await.problem(404);
    c.get("/api/v1/replays/abc").await.problem(400);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn deleting_a_session_deletes_the_replays_of_its_skills() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let (sim, skill_id) = simulate(c, json!({"scenario": "box-pinch-lift", "seed": 2})).await;
    // A too-small gripper fails at planning: a fast replay.
    let tiny_urdf = gripper_urdf().replace("upper=\"0.055\"", "upper=\"0.010\"");
    let upload = json!({"spec": gripper_spec("tiny"), "urdf": tiny_urdf});
    assert_eq!(
        c.post_json("/api/v1/hands", &upload, None).await.status,
        201
    );
    let r = c
        .post_json(
            &format!("/api/v1/skills/{skill_id}/replays"),
            &json!({"hand": "tiny"}),
            None,
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let replay = r.json();
    let blob = blob_path(&app.data, replay["sha256"].as_str().unwrap());
    assert!(blob.exists());
    let session = sim["session_id"].as_i64().unwrap();
    assert_eq!(
        c.delete(&format!("/api/v1/sessions/{session}"), None)
            .await
            .status,
        204
    );
    let id = replay["replay_id"].as_i64().unwrap();
    c.get(&format!("/api/v1/replays/{id}")).await.problem(404);
    assert!(!blob.exists());
    // The hand stays.
    assert_eq!(c.get("/api/v1/hands/tiny").await.status, 200);
    app.stop().await;
}

/// A session file without the object's metadata (a recorder that does not know the object)
/// is refused naming the missing field: its skills had object shape `unknown`, mass 0 and
/// μ 0, which no replay can use. `unknown` stays a shape the filter takes, for data bases that
/// stored such skills before.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_without_object_metadata_is_refused_and_unknown_is_still_a_shape_filter() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    simulate(c, json!({"scenario": "box-pinch-lift"})).await;
    let d = c
        .upload(&session_bytes_without_object("box-pinch-lift", 1), None)
        .await
        .problem(422);
    assert!(
        d.contains("has no `object` in its `session` metadata record"),
        "{d}"
    );
    assert_eq!(
        c.get("/api/v1/sessions").await.json()["items"]
            .as_array()
            .unwrap()
            .len(),
        1
    );
    let page = c.get("/api/v1/skills?shape=unknown").await;
    assert_eq!(page.status, 200, "{}", String::from_utf8_lossy(&page.body));
    assert_eq!(page.json()["items"], json!([]));
    // The document lists the shapes the filter takes, `unknown` among them.
    let doc = c.get("/api/v1/openapi.json").await.json();
    let shape = doc["paths"]["/api/v1/skills"]["get"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "shape")
        .unwrap()
        .clone();
    assert_eq!(
        shape["schema"]["enum"],
        json!(["sphere", "box", "cylinder", "unknown"]),
        "{shape}"
    );
    c.get("/api/v1/skills?shape=cone").await.problem(400);
    app.stop().await;
}

/// A session of format 1 (JSON topics, `services/tests/fixtures/session-v1.mcap`) is
/// uploaded, stored, listed, downloaded unchanged and its skill replayed, as a format 2 one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_format_1_session_uploads_and_its_skill_replays() {
    let app = TestApp::spawn().await;
    let c = &app.client;
    let v1 = std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../services/tests/fixtures/session-v1.mcap"),
    )
    .unwrap();
    let r = c.upload(&v1, None).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let up = r.json();
    let session_id = up["session_id"].as_i64().unwrap();
    let skill_id = up["skills"][0]["id"].as_i64().unwrap();
    assert_eq!(up["skills"].as_array().unwrap().len(), 1);
    assert_eq!(up["skills"][0]["object_shape"], "sphere");
    let back = c.get(&format!("/api/v1/sessions/{session_id}/mcap")).await;
    assert_eq!(back.status, 200);
    assert_eq!(back.body[..], v1[..], "the stored blob is the upload");
    let r = c
        .post_json(
            &format!("/api/v1/skills/{skill_id}/replays"),
            &json!({"hand": "gripper"}),
            None,
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["skill_id"], skill_id);
}
