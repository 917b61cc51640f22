//! The data base commands on PostgreSQL (issue 24): `icms ingest`, `icms skills`, `icms replay
//! --skill ID`, `icms recognise` and `icms reprocess` take `--database-url` (and `--blobs`) as
//! `icms serve` does, so a user whose skills live in PostgreSQL stores, lists, replays and
//! reprocesses them from the command line too. A URL that is not PostgreSQL's, or a server
//! that does not answer, is an error naming the option.
//!
//! Skipped, saying so, without ICMS_TEST_POSTGRES_URL (failing instead under
//! ICMS_REQUIRE_TOOLS), as cli_worker.rs.

use crate::common;

use std::path::Path;
use std::process::{Command, Output};

use common::pg::{fresh_schema, postgres_or_skip};
use serde_json::Value;

fn icms(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_icms"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

fn ok_json(out: Output) -> Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn the_data_base_commands_work_on_postgresql() {
    let Some(base) = postgres_or_skip("the_data_base_commands_work_on_postgresql") else {
        return;
    };
    let rt = tokio::runtime::Runtime::new().unwrap();
    let url = fresh_schema(&rt, &base, "cli_commands");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (scenario, seed) in [("sphere-lift", "1"), ("box-pinch-lift", "2")] {
        let out = icms(
            d,
            &[
                "simulate",
                "--scenario",
                scenario,
                "--seed",
                seed,
                "--out",
                &format!("{scenario}.mcap"),
            ],
        );
        assert!(out.status.success(), "{out:?}");
    }
    let pg = ["--data", "files", "--database-url", url.as_str()];
    let ingest = ok_json(icms(
        d,
        &[
            &[
                "ingest",
                "sphere-lift.mcap",
                "box-pinch-lift.mcap",
                "--json",
            ][..],
            &pg,
        ]
        .concat(),
    ));
    assert_eq!(ingest["sessions"].as_array().unwrap().len(), 2, "{ingest}");
    // The rows are in PostgreSQL: no SQLite file in the data directory, which holds the files.
    assert!(!d.join("files/icms.sqlite3").exists());
    let skills = ok_json(icms(d, &[&["skills", "--json"][..], &pg].concat()));
    let listed = skills["items"].as_array().unwrap();
    assert!(listed.len() >= 2, "{skills}");
    let id = listed
        .iter()
        .find(|s| s["object_shape"] == "sphere")
        .unwrap()["id"]
        .as_i64()
        .unwrap()
        .to_string();
    // Without --database-url the same directory holds no data base.
    let out = icms(d, &["skills", "--data", "files"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no ICMS data base"));

    let replay = ok_json(icms(
        d,
        &[
            &["replay", "--skill", &id, "--hand", "gripper", "--json"][..],
            &pg,
        ]
        .concat(),
    ));
    assert!(replay["replay_id"].as_i64().is_some(), "{replay}");
    assert_eq!(replay["success"], true, "{replay}");
    let recognised = ok_json(icms(
        d,
        &[&["recognise", "sphere-lift.mcap", "--json"][..], &pg].concat(),
    ));
    assert!(!recognised["verdicts"].as_array().unwrap().is_empty());
    let reprocess = icms(d, &[&["reprocess"][..], &pg].concat());
    assert!(reprocess.status.success(), "{reprocess:?}");

    // What is not a PostgreSQL URL, or does not answer, is named.
    let out = icms(
        d,
        &["skills", "--data", "files", "--database-url", "mysql://x/y"],
    );
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("--database-url"), "{e}");
    let out = icms(
        d,
        &[
            "ingest",
            "sphere-lift.mcap",
            "--data",
            "files",
            "--database-url",
            "postgres://icms@127.0.0.1:1/none",
        ],
    );
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("cannot connect") && e.contains("--database-url"),
        "{e}"
    );
}
