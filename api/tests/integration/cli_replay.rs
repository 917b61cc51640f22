//! `icms replay` and `icms hands` with a data base: a stored skill's replay is stored beside it,
//! a hand from a spec file is stored with it and listed; bad hands are refused naming the
//! problem.

use crate::common;
use common::{icms_in as icms, simulate_in};

use serde_json::Value;
use services::store::Store;

/// Writes the gripper's spec (named `name`, jaw stroke `stroke` m) and URDF into `dir`; returns
/// the spec file's name.
fn write_gripper(dir: &std::path::Path, name: &str, stroke: &str, tip_link: &str) -> String {
    let (mut spec, urdf) = dfs_core::hand::builtin_spec("gripper").unwrap();
    spec.name = name.into();
    spec.urdf = format!("{name}.urdf");
    spec.fingertips[1].link = tip_link.into();
    let urdf = urdf.replace("upper=\"0.055\"", &format!("upper=\"{stroke}\""));
    std::fs::write(dir.join(&spec.urdf), urdf).unwrap();
    let file = format!("{name}.json");
    std::fs::write(dir.join(&file), serde_json::to_string(&spec).unwrap()).unwrap();
    file
}

fn json(out: &str) -> Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("not JSON ({e}): {out}"))
}

#[test]
fn a_stored_skill_replays_into_the_data_base_with_its_hand() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_in(d, "box-pinch-lift", &[], "a.mcap");
    let (c, out, e) = icms(d, &["ingest", "a.mcap", "--json"]);
    assert_eq!(c, 0, "{e}");
    let skill = json(&out)["sessions"][0]["skill_ids"][0].as_i64().unwrap();
    let skill = skill.to_string();

    let (c, out, e) = icms(
        d,
        &["replay", "--skill", &skill, "--hand", "gripper", "--json"],
    );
    assert_eq!(c, 0, "{e}");
    let report = json(&out);
    assert_eq!(report["success"], true, "{report}");
    let held_id = report["replay_id"].as_i64().expect("a stored replay's id");

    // A hand from a spec file too small for the box: a failed replay, stored with its hand.
    let tiny = write_gripper(d, "tiny", "0.010", "left_finger");
    let (c, out, e) = icms(d, &["replay", "--skill", &skill, "--hand", &tiny, "--json"]);
    assert_eq!(c, 0, "a failed replay is a report: {e}");
    let report = json(&out);
    assert_eq!(report["success"], false);
    assert_eq!(report["failure_reason"], "unreachable");
    let failed_id = report["replay_id"].as_i64().unwrap();
    // Stored now: usable by name, and listed.
    let (c, out, e) = icms(d, &["hands", "--data", "icms-data", "--json"]);
    assert_eq!(c, 0, "{e}");
    let hands = json(&out);
    let last = hands.as_array().unwrap().last().unwrap().clone();
    assert_eq!(last["name"], "tiny");
    assert_eq!(last["builtin"], false);
    let (c, out, e) = icms(
        d,
        &["replay", "--skill", &skill, "--hand", "tiny", "--json"],
    );
    assert_eq!(c, 0, "{e}");
    assert_eq!(json(&out)["failure_reason"], "unreachable");

    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let store = Store::open(&d.join("icms-data")).await.unwrap();
        let skill: i64 = skill.parse().unwrap();
        let replays = store.list_replays(skill).await.unwrap();
        assert_eq!(replays.len(), 3);
        assert_eq!(replays[0].id, held_id);
        assert_eq!(replays[0].hand, "gripper");
        assert!(replays[0].success);
        assert_eq!(replays[1].id, failed_id);
        assert_eq!(replays[1].hand, "tiny");
        let bytes = std::fs::read(store.replay_blob_path(held_id).await.unwrap()).unwrap();
        assert!(bytes.starts_with(b"\x89MCAP0\r\n"));
        store.close().await;
    });
}

#[test]
fn a_skill_file_replays_without_touching_a_data_base_and_bad_hands_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let nail = write_gripper(d, "nail", "0.055", "nail");
    let (c, _, e) = icms(d, &["hands", &nail]);
    assert_ne!(c, 0);
    assert!(
        e.contains("fingertips[1].link") && e.contains("nail"),
        "{e}"
    );
    let (c, _, e) = icms(d, &["replay", "--skill", "7", "--hand", "gripper"]);
    assert_ne!(c, 0);
    assert!(e.contains("no skill data base"), "{e}");
    let (c, _, e) = icms(d, &["hands", "nobody", "--data", "icms-data"]);
    assert_ne!(c, 0);
    assert!(e.contains("nobody"), "{e}");
    assert!(!d.join("icms-data").exists(), "nothing created a data base");
}

#[test]
fn replay_never_records_over_its_inputs_and_a_session_file_is_not_a_skill() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_in(d, "box-pinch-lift", &[], "a.mcap");
    let (c, out, e) = icms(d, &["segment", "a.mcap", "--json"]);
    assert_eq!(c, 0, "{e}");
    let skill = json(&out)["skills"][0].to_string();
    std::fs::write(d.join("skill.json"), &skill).unwrap();
    let spec = write_gripper(d, "jaw", "0.055", "left_finger");
    let before = std::fs::read(d.join(&spec)).unwrap();
    let urdf_before = std::fs::read(d.join("jaw.urdf")).unwrap();
    // `--out` the skill file (also by another path), the hand's spec or the spec's URDF: the
    // recording overwrote it.
    for (out, flag) in [
        ("skill.json", "the --skill file"),
        ("./skill.json", "the --skill file"),
        (spec.as_str(), "the --hand file"),
        ("jaw.urdf", "the URDF of the --hand spec"),
    ] {
        let (c, _, e) = icms(
            d,
            &[
                "replay",
                "--skill",
                "skill.json",
                "--hand",
                &spec,
                "--out",
                out,
            ],
        );
        assert_ne!(c, 0);
        assert!(e.contains(&format!("is {flag}:")), "{out}: {e}");
    }
    assert_eq!(
        std::fs::read_to_string(d.join("skill.json")).unwrap(),
        skill
    );
    assert_eq!(std::fs::read(d.join(&spec)).unwrap(), before);
    assert_eq!(std::fs::read(d.join("jaw.urdf")).unwrap(), urdf_before);
    // A built-in hand reads no file: a file that shares its name may be recorded to.
    std::fs::write(d.join("gripper"), "not a hand").unwrap();
    let (c, _, e) = icms(
        d,
        &[
            "replay",
            "--skill",
            "skill.json",
            "--hand",
            "gripper",
            "--out",
            "gripper",
        ],
    );
    assert_eq!(c, 0, "{e}");
    assert!(std::fs::metadata(d.join("gripper")).unwrap().len() > 100);
    // A session file given as the skill: "stream did not contain valid UTF-8".
    let (c, _, e) = icms(d, &["replay", "--skill", "a.mcap", "--hand", "gripper"]);
    assert_ne!(c, 0);
    assert!(
        e.contains("not a skill JSON file") && e.contains("icms segment"),
        "{e}"
    );
    // A spec file is shown as one, not as an uploaded hand.
    let (c, out, e) = icms(d, &["hands", &spec]);
    assert_eq!(c, 0, "{e}");
    assert!(
        out.contains("(spec file)") && !out.contains("uploaded"),
        "{out}"
    );
}
