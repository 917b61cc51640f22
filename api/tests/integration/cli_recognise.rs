//! `icms recognise` end to end: a varied session recognised against the skills stored from
//! others, before the hand touches the object; bad input refused.

use crate::common;
use common::icms;

use serde_json::Value;

fn simulate_variant(dir: &std::path::Path, name: &str, seed: u64) -> String {
    let f = dir.join(format!("{name}-{seed}.mcap"));
    let f = f.to_str().unwrap().to_owned();
    let seed = seed.to_string();
    let (code, _, err) = icms(&[
        "simulate",
        "--scenario",
        name,
        "--seed",
        &seed,
        "--variant",
        "--out",
        &f,
    ]);
    assert_eq!(code, 0, "{err}");
    f
}

#[test]
fn recognise_names_the_stored_skill_and_the_target_before_the_first_touch() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let data = data.to_str().unwrap();
    let stored: Vec<String> = (1..=3)
        .flat_map(|s| {
            [
                simulate_variant(dir.path(), "sphere-lift", s),
                simulate_variant(dir.path(), "box-pinch-lift", s),
            ]
        })
        .collect();
    let mut args = vec!["ingest", "--data", data];
    args.extend(stored.iter().map(String::as_str));
    let (code, _, err) = icms(&args);
    assert_eq!(code, 0, "{err}");

    let session = simulate_variant(dir.path(), "box-pinch-lift", 42);
    let (code, out, err) = icms(&["recognise", &session, "--data", data, "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let touch = v["first_touch_ns"]["object"].as_u64().unwrap();
    let first = &v["verdicts"][0];
    assert_eq!(first["type"], "recognised", "{v}");
    assert_eq!(first["stage"], "approach");
    assert!(
        first["skill"]["kind"].as_str().unwrap().starts_with("box/"),
        "{v}"
    );
    assert!(
        first["session_ns"].as_u64().unwrap() + 200_000_000 <= touch,
        "{v}"
    );

    // The text form says the same.
    let (code, out, _) = icms(&["recognise", &session, "--data", data]);
    assert_eq!(code, 0);
    assert!(out.contains("recognised skill"), "{out}");

    // Bad input: no data base, not a session.
    let (code, _, err) = icms(&["recognise", &session, "--data", "/nonexistent/icms"]);
    assert_ne!(code, 0);
    assert!(err.contains("no ICMS data base"), "{err}");
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap").unwrap();
    let (code, _, err) = icms(&["recognise", junk.to_str().unwrap(), "--data", data]);
    assert_ne!(code, 0);
    assert!(err.contains("junk.mcap"), "{err}");
}
