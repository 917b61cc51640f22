//! The assistant (issue 20) in live sessions over a real WebSocket: a stored skill is
//! recognised before the fingers touch, applied on a robot hand in step with the operator, and
//! the grasp linked to it; with nothing stored the grasp is `unknown` and learned; bad assist
//! settings are refused in the start answer.

use api::live_client::{self, ClientOptions};
use serde_json::{json, Value};
use services::live::{AssistMode, AssistSettings};
use tests::{live_start as start, live_url as url, session_bytes, TestApp};

async fn stream(
    app: &TestApp,
    name: &str,
    seed: u64,
    assist: AssistSettings,
) -> live_client::ClientSummary {
    let s = dfs_core::scenario::Scenario::builtin(name, seed).unwrap();
    let frames = live_client::simulated_frames(&s, None, 1).unwrap();
    live_client::run(
        &url(app),
        &start(&s, assist),
        frames,
        &ClientOptions::default(),
        |_| {},
    )
    .await
    .unwrap()
}

async fn upload(app: &TestApp, name: &str, seed: u64) -> Vec<i64> {
    let r = app
        .client
        .upload(&session_bytes(name, seed, None), None)
        .await;
    assert_eq!(r.status, 201);
    r.json()["skills"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["id"].as_i64().unwrap())
        .collect()
}

fn of_type<'a>(events: &'a [Value], kind: &str) -> Vec<&'a Value> {
    events.iter().filter(|e| e["type"] == kind).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_skill_is_recognised_early_applied_on_a_robot_hand_and_the_grasp_linked_to_it() {
    let app = TestApp::spawn().await;
    let sphere = upload(&app, "sphere-lift", 1).await;
    let boxed = upload(&app, "box-pinch-lift", 1).await;
    assert_eq!((sphere.len(), boxed.len()), (1, 1));

    let summary = stream(
        &app,
        "sphere-lift",
        2,
        AssistSettings {
            mode: AssistMode::Apply,
            robot: Some("allegro".into()),
        },
    )
    .await;
    let events = &summary.assist_events;
    let first_contact = summary.first_contact_ns.unwrap();
    // Recognised before the fingers touched, naming the object and the sphere's skill.
    let recognised = of_type(events, "recognised");
    let first = recognised.first().expect("a recognised event");
    assert_eq!(first["stage"], "approach", "{first}");
    assert_eq!(first["object"], "object");
    assert_eq!(first["skill"]["skill_id"], sphere[0], "{first}");
    assert!(
        first["skill"]["confidence"].as_f64().unwrap() >= 0.8,
        "{first}"
    );
    let decided = first["session_ns"].as_u64().unwrap();
    assert!(
        decided + 200_000_000 <= first_contact,
        "decided at {decided} ns, first contact at {first_contact} ns"
    );
    // The box's grasp is no candidate for the sphere (another shape).
    assert!(
        first["runners_up"]
            .as_array()
            .unwrap()
            .iter()
            .all(|r| r["skill_id"] != boxed[0]),
        "{first}"
    );
    // Applied on allegro, its state streamed, its report at the end.
    let applying = of_type(events, "applying");
    assert_eq!(applying.len(), 1, "{events:?}");
    assert_eq!(applying[0]["robot"], "allegro");
    let robot = of_type(events, "robot");
    assert!(robot.len() > 20, "{} robot states", robot.len());
    // The robot follows the operator's phase as it goes.
    let phases: std::collections::BTreeSet<&str> = robot
        .iter()
        .map(|r| r["robot_phase"].as_str().unwrap())
        .collect();
    assert!(
        phases.contains("lift") || phases.contains("hold"),
        "{phases:?}"
    );
    let report = of_type(events, "robot_report");
    assert_eq!(report.len(), 1, "{events:?}");
    assert_eq!(report[0]["report"]["hand"], "allegro");
    // The grasp matched the sphere's skill: linked, not new.
    assert_eq!(summary.matched_skill_ids, vec![Some(sphere[0])]);
    let id = summary.session_id.unwrap();
    let s: Value = app
        .client
        .get(&format!("/api/v1/sessions/{id}"))
        .await
        .json();
    assert_eq!(s["matched_skill_ids"], json!([sphere[0]]));
    let live = &s["meta"]["extra"]["live"];
    assert_eq!(live["assist_mode"], "apply");
    assert!(live["robot_report"].as_str().unwrap().contains("allegro"));
    let skill: Value = app
        .client
        .get(&format!("/api/v1/skills/{}", summary.skill_ids[0]))
        .await
        .json();
    assert_eq!(skill["matched_skill_id"], sphere[0]);
    let approach = skill["approach"].as_array().unwrap();
    assert_eq!(approach.len(), 29);
    // The grip 0.8 s after the touch (a pinch squeezes several times the ball's weight) and
    // the scene's one object.
    assert!(
        approach[27].as_f64().is_some_and(|g| g > 1.0),
        "{approach:?}"
    );
    assert_eq!(approach[28], 1.0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_nothing_stored_a_grasp_is_unknown_and_learned_then_recognised() {
    let app = TestApp::spawn().await;
    let suggest = || AssistSettings {
        mode: AssistMode::Suggest,
        robot: None,
    };
    let first = stream(&app, "box-pinch-lift", 3, suggest()).await;
    let unknown = of_type(&first.assist_events, "unknown");
    assert!(!unknown.is_empty(), "{:?}", first.assist_events);
    assert_eq!(unknown[0]["object"], "object");
    assert!(of_type(&first.assist_events, "recognised").is_empty());
    assert!(of_type(&first.assist_events, "applying").is_empty());
    assert_eq!(first.matched_skill_ids, vec![None], "stored as new");

    // The same grasp again: now it is known.
    let second = stream(&app, "box-pinch-lift", 4, suggest()).await;
    let recognised = of_type(&second.assist_events, "recognised");
    assert!(!recognised.is_empty(), "{:?}", second.assist_events);
    assert_eq!(recognised[0]["skill"]["skill_id"], first.skill_ids[0]);
    assert_eq!(second.matched_skill_ids, vec![Some(first.skill_ids[0])]);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_assist_settings_are_refused_in_the_start_answer_naming_the_field() {
    let app = TestApp::spawn().await;
    let s = dfs_core::scenario::Scenario::builtin("sphere-lift", 0).unwrap();
    for (assist, needle) in [
        (
            AssistSettings {
                mode: AssistMode::Apply,
                robot: Some("octopus".into()),
            },
            "assist.robot: no hand named \"octopus\"",
        ),
        (
            AssistSettings {
                mode: AssistMode::Apply,
                robot: None,
            },
            "assist.robot",
        ),
        (
            AssistSettings {
                mode: AssistMode::Suggest,
                robot: Some("allegro".into()),
            },
            "only taken with assist mode \"apply\"",
        ),
    ] {
        let err = live_client::run(
            &url(&app),
            &start(&s, assist),
            Vec::new(),
            &ClientOptions::default(),
            |_| {},
        )
        .await
        .unwrap_err()
        .to_string();
        assert!(err.contains(needle), "{err}");
    }
    app.stop().await;
}
