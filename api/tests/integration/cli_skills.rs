//! `icms ingest` and `icms skills` end to end: sessions into the skill data base and back.

use crate::common;
use common::{icms_in as icms, simulate_in};

use serde_json::Value;

#[test]
fn sessions_are_ingested_once_with_their_skills_and_can_be_queried() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_in(d, "two-grasps", &["--seed", "4"], "a.mcap");
    let (c, out, e) = icms(d, &["ingest", "a.mcap", "a.mcap", "--json"]);
    assert_eq!(c, 0, "{e}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let s = v["sessions"].as_array().unwrap();
    assert_eq!(
        s[0]["session_id"], s[1]["session_id"],
        "the same file is one session"
    );
    assert_eq!(s[0]["created"], Value::Bool(true));
    assert_eq!(s[1]["created"], Value::Bool(false));
    assert_eq!(
        s[0]["skill_ids"].as_array().unwrap().len(),
        2,
        "two grasps, two skills"
    );
    assert!(d.join("icms-data").join("icms.sqlite3").exists());

    let (c, out, e) = icms(
        d,
        &[
            "skills",
            "--shape",
            "box",
            "--contacts",
            "2",
            "--sort",
            "quality:desc",
            "--json",
        ],
    );
    assert_eq!(c, 0, "{e}");
    let page: Value = serde_json::from_str(&out).unwrap();
    let items = page["items"].as_array().unwrap();
    assert_eq!(items.len(), 2);
    assert!(items[0]["quality"].as_f64().unwrap() >= items[1]["quality"].as_f64().unwrap());
    let (_, out, _) = icms(d, &["skills", "--shape", "sphere", "--json"]);
    let none: Value = serde_json::from_str(&out).unwrap();
    assert!(none["items"].as_array().unwrap().is_empty());

    let id = items[0]["id"].as_i64().unwrap().to_string();
    let (c, out, e) = icms(d, &["skills", "--similar-to", &id, "--limit", "1"]);
    assert_eq!(c, 0, "{e}");
    let near: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(near["items"].as_array().unwrap().len(), 1);
}

#[test]
fn a_corrupt_file_is_refused_with_its_reason_and_stores_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("bad.mcap"), b"not an mcap file at all").unwrap();
    let (c, _, e) = icms(d, &["ingest", "bad.mcap"]);
    assert_ne!(c, 0);
    assert!(e.contains("bad.mcap") && e.contains("MCAP"), "{e}");
    let (c, out, _) = icms(d, &["skills", "--json"]);
    assert_eq!(c, 0);
    let v: Value = serde_json::from_str(&out).unwrap();
    assert!(v["items"].as_array().unwrap().is_empty());
    let (c, _, e) = icms(d, &["skills", "--cursor", "zz"]);
    assert_ne!(c, 0);
    assert!(e.contains("cursor"), "{e}");
}

#[test]
fn a_bad_file_among_several_is_reported_and_the_good_ones_are_still_stored() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_in(d, "box-pinch-lift", &["--duration", "3.5"], "good.mcap");
    std::fs::write(d.join("bad.mcap"), b"not an mcap file at all").unwrap();
    let (c, out, e) = icms(
        d,
        &["ingest", "bad.mcap", "missing.mcap", "good.mcap", "--json"],
    );
    assert_ne!(c, 0, "a file was not stored: the command fails");
    assert!(e.contains("2 of 3"), "{e}");
    assert!(e.contains("bad.mcap") && e.contains("missing.mcap"), "{e}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let stored = v["sessions"].as_array().unwrap();
    assert_eq!(stored.len(), 1);
    assert_eq!(stored[0]["file"], "good.mcap");
    let failed = v["failed"].as_array().unwrap();
    assert_eq!(failed.len(), 2);
    assert_eq!(failed[0]["file"], "bad.mcap");
    assert!(failed[0]["error"].as_str().unwrap().contains("MCAP"));
    let (c, out, _) = icms(d, &["skills", "--json"]);
    assert_eq!(c, 0);
    let v: Value = serde_json::from_str(&out).unwrap();
    assert!(!v["items"].as_array().unwrap().is_empty());
}

#[test]
fn ingest_of_no_file_and_a_data_directory_that_is_a_file_are_refused_creating_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (c, _, e) = icms(d, &["ingest", "missing.mcap", "--data", "fresh"]);
    assert_ne!(c, 0);
    assert!(e.contains("missing.mcap: not stored: no such file"), "{e}");
    assert!(
        !d.join("fresh").exists(),
        "no empty data base is left behind"
    );
    simulate_in(d, "box-pinch-lift", &["--duration", "3.5"], "a.mcap");
    std::fs::write(d.join("plain"), b"").unwrap();
    let (c, _, e) = icms(d, &["ingest", "a.mcap", "--data", "plain"]);
    assert_ne!(c, 0);
    assert!(e.contains("plain") && e.contains("not a directory"), "{e}");
}

#[test]
fn a_second_demo_with_the_same_seed_stores_nothing_twice() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let count = || {
        let (c, out, e) = icms(d, &["skills", "--json", "--limit", "1000"]);
        assert_eq!(c, 0, "{e}");
        let v: Value = serde_json::from_str(&out).unwrap();
        v["items"].as_array().unwrap().len()
    };
    let (c, out, e) = icms(d, &["demo", "--seed", "3"]);
    assert_eq!(c, 0, "{e}");
    assert!(!out.contains("kept"), "{out}");
    let first = count();
    assert!(first >= 6, "{first} skills");
    let (c, out, e) = icms(d, &["demo", "--seed", "3"]);
    assert_eq!(c, 0, "{e}");
    assert_eq!(
        out.matches("(recorded before)").count(),
        dfs_core::scenario::Scenario::BUILTINS.len(),
        "{out}"
    );
    assert_eq!(count(), first);
    let leftovers = std::fs::read_dir(d.join("icms-data").join("sessions"))
        .unwrap()
        .filter(|f| f.as_ref().unwrap().path().extension().unwrap() != "mcap")
        .count();
    assert_eq!(leftovers, 0, "no partial recordings");
}

#[test]
fn similar_skills_take_no_filters() {
    let dir = tempfile::tempdir().unwrap();
    let (c, _, e) = icms(
        dir.path(),
        &["skills", "--similar-to", "1", "--shape", "box"],
    );
    assert_eq!(c, 2, "a usage error: {e}");
    assert!(e.contains("--similar-to") && e.contains("--shape"), "{e}");
}

#[test]
fn negative_filters_and_an_out_of_range_similar_limit_are_refused_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_in(d, "box-pinch-lift", &["--duration", "3.5"], "a.mcap");
    let (c, out, e) = icms(d, &["ingest", "a.mcap", "--json"]);
    assert_eq!(c, 0, "{e}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let id = v["sessions"][0]["skill_ids"][0]
        .as_i64()
        .unwrap()
        .to_string();

    for (flags, want) in [
        (&["--mass-min", "-1"][..], "mass min -1 is negative"),
        (&["--contacts", "-3"][..], "contacts -3 is negative"),
        (
            &["--phase", "hold", "--phase-min-s", "-5"][..],
            "phase duration min -5 is negative",
        ),
        (&["--similar-to", &id, "--limit", "0"][..], "--limit 0"),
        // k = 2^32 - 1 neighbours used to reserve 64 GiB and abort.
        (
            &["--similar-to", &id, "--limit", "4294967295"][..],
            "--limit 4294967295 is outside 1..=1000",
        ),
        (&["--similar-to", "-1"][..], "no skill with id -1"),
    ] {
        let mut a = vec!["skills"];
        a.extend_from_slice(flags);
        let (c, _, e) = icms(d, &a);
        assert_eq!(c, 1, "{flags:?}: {e}");
        assert!(e.contains(want), "{flags:?}: {e}");
    }
}

/// The commands that only read the data base refuse a directory without one, naming it, and
/// create nothing there (they used to create an empty data base and list nothing).
#[test]
fn read_only_commands_refuse_a_directory_without_a_data_base_and_create_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let empty = d.join("empty");
    std::fs::create_dir(&empty).unwrap();
    for data in ["nowhere", "empty"] {
        for args in [
            &["skills", "--data", data][..],
            &["skills", "--data", data, "--json", "--shape", "box"],
            &["skills", "--data", data, "--similar-to", "1"],
            &["hands", "--data", data],
            &["hands", "--data", data, "--json"],
            &["hands", "my-hand", "--data", data],
        ] {
            let (c, out, e) = icms(d, args);
            assert_ne!(c, 0, "{args:?}: {out}");
            assert!(out.is_empty(), "{args:?}: {out}");
            assert!(
                e.contains(&format!("no ICMS data base at {data}"))
                    && e.contains("icms ingest")
                    && e.contains("icms serve"),
                "{args:?}: {e}"
            );
        }
    }
    assert!(!d.join("nowhere").exists(), "nothing created the directory");
    assert_eq!(
        std::fs::read_dir(&empty).unwrap().count(),
        0,
        "nothing created in the empty directory"
    );
    // A built-in hand needs no data base.
    let (c, _, e) = icms(d, &["hands", "allegro", "--data", "nowhere"]);
    assert_eq!(c, 0, "{e}");
    assert!(!d.join("nowhere").exists());
}
