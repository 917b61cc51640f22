//! `icms segment` end to end: a simulated session file into skills, and bad input refused.

use crate::common;
use common::icms;

use serde_json::Value;

#[test]
fn segment_prints_one_skill_with_its_phases_for_a_pinch_lift_and_none_without_contact() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("pinch.mcap");
    let f = f.to_str().unwrap();
    let (code, _, err) = icms(&[
        "simulate",
        "--scenario",
        "box-pinch-lift",
        "--seed",
        "1",
        "--out",
        f,
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = icms(&["segment", f, "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let skills = v["skills"].as_array().unwrap();
    assert_eq!(skills.len(), 1);
    let names: Vec<&str> = skills[0]["phases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["approach", "preshape", "grasp", "lift", "hold", "place", "release", "retreat"]
    );
    assert!(skills[0]["phases"][1]["start_ns"].as_u64().unwrap() > 0);
    assert_eq!(skills[0]["feature"].as_array().unwrap().len(), 16);
    assert!(skills[0]["contacts"].as_array().unwrap().len() >= 2);

    let short = dir.path().join("short.mcap");
    let short = short.to_str().unwrap();
    let (code, _, err) = icms(&[
        "simulate",
        "--scenario",
        "box-pinch-lift",
        "--duration",
        "1",
        "--out",
        short,
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = icms(&["segment", short, "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v, serde_json::json!({"skills": []}));
}

#[test]
fn segment_refuses_a_truncated_file_with_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("s.mcap");
    let (code, _, err) = icms(&[
        "simulate",
        "--scenario",
        "sphere-lift",
        "--duration",
        "1",
        "--out",
        f.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let bytes = std::fs::read(&f).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let (code, out, err) = icms(&["segment", cut.to_str().unwrap(), "--json"]);
    assert_ne!(code, 0);
    assert!(out.is_empty(), "{out}");
    assert!(err.contains("error:") && err.contains("cut.mcap"), "{err}");
    let garbage = dir.path().join("garbage.mcap");
    std::fs::write(&garbage, b"not an mcap file at all").unwrap();
    let (code, _, err) = icms(&["segment", garbage.to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(err.contains("error:"), "{err}");
}

/// A replay's MCAP (`icms replay --out`) reads like a session but holds a robot hand replaying
/// a skill: segmenting or ingesting it would store a skill of shape `unknown` with no
/// parameters. Both refuse it, saying what it is, and the data base stays empty.
#[test]
fn segment_and_ingest_refuse_a_replay_recording_saying_what_it_is() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let path = |name: &str| d.join(name).to_str().unwrap().to_owned();
    let (code, _, err) = icms(&[
        "simulate",
        "--scenario",
        "box-pinch-lift",
        "--out",
        &path("pinch.mcap"),
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = icms(&["segment", &path("pinch.mcap"), "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    std::fs::write(d.join("skill.json"), v["skills"][0].to_string()).unwrap();
    let (code, _, err) = icms(&[
        "replay",
        "--skill",
        &path("skill.json"),
        "--hand",
        "gripper",
        "--data",
        &path("db"),
        "--out",
        &path("replay.mcap"),
    ]);
    assert_eq!(code, 0, "{err}");

    let (code, out, err) = icms(&["segment", &path("replay.mcap"), "--json"]);
    assert_ne!(code, 0, "{out}");
    assert!(out.is_empty(), "{out}");
    assert!(
        err.contains("replay.mcap")
            && err.contains("replay recording")
            && err.contains("gripper")
            && err.contains("not a grasp session"),
        "{err}"
    );
    let (code, _, err) = icms(&["ingest", &path("replay.mcap"), "--data", &path("db")]);
    assert_ne!(code, 0);
    assert!(
        err.contains("replay recording") && err.contains("not a grasp session"),
        "{err}"
    );
    let (code, out, err) = icms(&["skills", "--data", &path("db"), "--json"]);
    assert_eq!(code, 0, "{err}");
    let page: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(page["items"], serde_json::json!([]), "nothing was stored");
}
