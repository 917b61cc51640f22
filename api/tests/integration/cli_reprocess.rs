//! `icms reprocess` end to end: stale sessions segmented again once, failures reported with
//! exit code 1 while the others go on, and runs killed at random moments leaving every session
//! whole (as it was, or reprocessed).

use crate::common;
use common::{icms_in as icms, simulate_in};

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use serde_json::Value;
use services::segmentation::SEGMENTATION_VERSION;
use sqlx::{Connection, Row, SqliteConnection};

/// Runs SQL statements on the data base in `data` (no `icms` running on it).
fn sql(data: &Path, statements: &[&str]) {
    let db = data.join("icms.sqlite3");
    let statements: Vec<String> = statements.iter().map(|s| s.to_string()).collect();
    rt().block_on(async move {
        let opts = sqlx::sqlite::SqliteConnectOptions::new().filename(db);
        let mut conn = SqliteConnection::connect_with(&opts).await.unwrap();
        for s in statements {
            sqlx::query(&s).execute(&mut conn).await.unwrap();
        }
        conn.close().await.unwrap();
    })
}

fn rt() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

/// What an older segmentation could have left: every session at version 0, every skill with
/// other parameters (so that reprocessing replaces each of them).
fn age_everything(data: &Path) {
    sql(
        data,
        &[
            "UPDATE sessions SET segmentation_version = 0",
            "UPDATE skills SET quality = quality + 1.0, params = json_set(params, '$.old', 1)",
        ],
    );
}

fn json(out: &str) -> Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

/// The skills as `icms skills --json` lists them, by id.
fn skills(d: &Path) -> Vec<Value> {
    let (c, out, e) = icms(d, &["skills", "--limit", "1000", "--json"]);
    assert_eq!(c, 0, "{e}");
    json(&out)["items"].as_array().unwrap().clone()
}

/// A skill's content: what segmentation made (without id, session, insertion time, version).
fn content(s: &Value) -> Value {
    let mut s = s.clone();
    for k in ["id", "created_at", "segmentation_version"] {
        s.as_object_mut().unwrap().remove(k);
    }
    s
}

#[test]
fn reprocess_brings_stale_sessions_up_to_date_once_and_says_what_it_did() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_in(d, "two-grasps", &["--seed", "4"], "a.mcap");
    simulate_in(d, "sphere-lift", &["--seed", "3"], "b.mcap");
    let (c, _, e) = icms(d, &["ingest", "a.mcap", "b.mcap"]);
    assert_eq!(c, 0, "{e}");
    let fresh = skills(d);
    assert_eq!(fresh.len(), 3);
    for s in &fresh {
        assert_eq!(s["segmentation_version"], SEGMENTATION_VERSION, "{s}");
    }
    let (c, out, e) = icms(d, &["skills"]);
    assert_eq!(c, 0, "{e}");
    assert!(
        out.lines()
            .all(|l| l.ends_with(&format!("segmentation v{SEGMENTATION_VERSION}"))),
        "{out}"
    );

    // Everything up to date: nothing to do.
    let (c, out, e) = icms(d, &["reprocess", "--json"]);
    assert_eq!(c, 0, "{e}");
    assert!(
        e.is_empty(),
        "no progress when stderr is not a terminal: {e}"
    );
    let r = json(&out);
    assert_eq!(r["segmentation_version"], SEGMENTATION_VERSION);
    assert_eq!(r["sessions_stale"], 0);
    assert_eq!(r["sessions_reprocessed"], 0);

    // One skill of the first session as an older segmentation made it.
    let changed = fresh[0]["id"].as_i64().unwrap();
    sql(
        &d.join("icms-data"),
        &[
            "UPDATE sessions SET segmentation_version = 0",
            &format!("UPDATE skills SET quality = quality + 1.0 WHERE id = {changed}"),
        ],
    );
    assert!(skills(d).iter().all(|s| s["segmentation_version"] == 0));
    let (c, out, e) = icms(d, &["reprocess"]);
    assert_eq!(c, 0, "{e}");
    assert!(e.is_empty(), "{e}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 3, "{out}");
    assert!(
        lines[0].starts_with(&format!(
            "session 1: segmentation version 0 → {SEGMENTATION_VERSION}: skills 2 → 2 \
             (1 kept, 1 removed [{changed}], 1 added [4])"
        )),
        "{out}"
    );
    assert!(
        lines[1].starts_with("session 2: ") && lines[1].contains("skills 1 → 1 (1 kept)"),
        "{out}"
    );
    assert!(
        lines[2].starts_with(&format!(
            "reprocessed 2 of 2 session(s) segmented before version {SEGMENTATION_VERSION}: \
             skills 3 → 3 (2 kept, 1 removed, 1 added), 0 replay(s) removed"
        )),
        "{out}"
    );
    let after = skills(d);
    assert_eq!(
        after
            .iter()
            .map(|s| s["id"].as_i64().unwrap())
            .collect::<Vec<_>>(),
        [2, 3, 4]
    );
    for s in &after {
        assert_eq!(s["segmentation_version"], SEGMENTATION_VERSION, "{s}");
    }
    // The rebuilt skill is the one first stored; the others are untouched.
    assert_eq!(content(&after[2]), content(&fresh[0]));
    assert_eq!(after[0], fresh[1]);
    assert_eq!(after[1], fresh[2]);

    // A second run does nothing.
    let (c, out, e) = icms(d, &["reprocess", "--json"]);
    assert_eq!(c, 0, "{e}");
    assert_eq!(json(&out)["sessions_stale"], 0);
    assert_eq!(skills(d), after);
}

#[test]
fn a_session_that_fails_is_named_and_the_exit_code_is_1() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_in(d, "sphere-lift", &["--seed", "3"], "a.mcap");
    simulate_in(d, "sphere-lift", &["--seed", "4"], "b.mcap");
    let (c, _, e) = icms(d, &["ingest", "a.mcap", "b.mcap"]);
    assert_eq!(c, 0, "{e}");
    // Session 2's file disappears from the data directory.
    let data = d.join("icms-data");
    let db = data.join("icms.sqlite3");
    let blob: String = rt().block_on(async move {
        let opts = sqlx::sqlite::SqliteConnectOptions::new().filename(db);
        let mut conn = SqliteConnection::connect_with(&opts).await.unwrap();
        let p = sqlx::query_scalar("SELECT blob_path FROM sessions WHERE id = 2")
            .fetch_one(&mut conn)
            .await
            .unwrap();
        conn.close().await.unwrap();
        p
    });
    std::fs::remove_file(data.join(blob)).unwrap();
    age_everything(&data);

    let (c, out, e) = icms(d, &["reprocess", "--json"]);
    assert_eq!(c, 1, "{e}");
    let r = json(&out);
    assert_eq!(r["sessions_stale"], 2);
    assert_eq!(r["sessions_reprocessed"], 1);
    assert_eq!(r["sessions_failed"], 1);
    assert_eq!(r["sessions"][0]["session_id"], 1);
    assert_eq!(r["failed"][0]["session_id"], 2);
    assert_eq!(r["failed"][0]["segmentation_version"], 0);
    assert!(
        e.contains("session 2: not reprocessed: ") && e.contains("No such file"),
        "{e}"
    );
    assert!(
        e.contains("error: 1 of 2 session(s) not reprocessed"),
        "{e}"
    );
    let versions: Vec<Value> = skills(d)
        .iter()
        .map(|s| s["segmentation_version"].clone())
        .collect();
    assert_eq!(
        versions,
        [Value::from(0), Value::from(SEGMENTATION_VERSION)]
    );

    // Still failing the next time, and still the only one tried.
    let (c, out, _) = icms(d, &["reprocess", "--json"]);
    assert_eq!(c, 1);
    assert_eq!(json(&out)["sessions_stale"], 1);
}

#[test]
fn a_directory_without_a_data_base_is_an_error_and_nothing_is_created() {
    let dir = tempfile::tempdir().unwrap();
    let (c, out, e) = icms(dir.path(), &["reprocess", "--data", "nowhere"]);
    assert_eq!(c, 1);
    assert!(out.is_empty(), "{out}");
    assert!(e.contains("no ICMS data base at nowhere"), "{e}");
    assert!(!dir.path().join("nowhere").exists());
}

/// Per session: (segmentation version, its skills' ids, how many of them an older segmentation
/// made), and the skills' content (quality, params) by session in time order.
type State = Vec<(i64, i64, Vec<i64>, usize, Vec<(f64, String)>)>;

fn state(data: &Path) -> State {
    let db = data.join("icms.sqlite3");
    rt().block_on(async move {
        let opts = sqlx::sqlite::SqliteConnectOptions::new()
            .filename(db)
            .read_only(true);
        let mut conn = SqliteConnection::connect_with(&opts).await.unwrap();
        let ok: String = sqlx::query_scalar("PRAGMA integrity_check")
            .fetch_one(&mut conn)
            .await
            .unwrap();
        assert_eq!(ok, "ok");
        let dangling: i64 = sqlx::query_scalar(
            "SELECT count(*) FROM skill_phases WHERE skill_id NOT IN (SELECT id FROM skills)",
        )
        .fetch_one(&mut conn)
        .await
        .unwrap();
        assert_eq!(dangling, 0, "phase rows of removed skills");
        let sessions = sqlx::query("SELECT id, segmentation_version FROM sessions ORDER BY id")
            .fetch_all(&mut conn)
            .await
            .unwrap();
        let mut out = Vec::new();
        for s in sessions {
            let id: i64 = s.get(0);
            let rows = sqlx::query(
                "SELECT id, quality, params, json_extract(params, '$.old') IS NOT NULL, \
                 (SELECT count(*) FROM skill_phases WHERE skill_id = skills.id) \
                 FROM skills WHERE session_id = ? ORDER BY start_ns, id",
            )
            .bind(id)
            .fetch_all(&mut conn)
            .await
            .unwrap();
            let mut ids = Vec::new();
            let mut old = 0;
            let mut contents = Vec::new();
            for r in rows {
                ids.push(r.get::<i64, _>(0));
                let is_old: bool = r.get(3);
                old += usize::from(is_old);
                let phases: i64 = r.get(4);
                assert!(
                    phases > 0,
                    "skill {} has its phase rows",
                    r.get::<i64, _>(0)
                );
                contents.push((r.get::<f64, _>(1), r.get::<String, _>(2)));
            }
            out.push((id, s.get(1), ids, old, contents));
        }
        conn.close().await.unwrap();
        out
    })
}

#[test]
fn killed_reprocess_runs_leave_every_session_whole() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = d.join("icms-data");
    let files: Vec<String> = (0..6).map(|i| format!("s{i}.mcap")).collect();
    for (i, f) in files.iter().enumerate() {
        simulate_in(d, "sphere-lift", &["--seed", &i.to_string()], f);
    }
    let mut args = vec!["ingest"];
    args.extend(files.iter().map(String::as_str));
    let (c, _, e) = icms(d, &args);
    assert_eq!(c, 0, "{e}");
    let fresh = state(&data);
    assert!(
        fresh.iter().all(|s| !s.2.is_empty()),
        "every session has a skill"
    );
    age_everything(&data);
    let aged = state(&data);

    // Each session, after any kill, is either as aged (version 0, the same skills) or as a
    // fresh ingest made it (the current version, the fresh content, new ids).
    let check = |now: &State| -> usize {
        let mut done = 0;
        for ((n, f), a) in now.iter().zip(&fresh).zip(&aged) {
            if n.1 == 0 {
                assert_eq!(n, a, "session {} is as it was", n.0);
            } else {
                assert_eq!(n.1, i64::from(SEGMENTATION_VERSION));
                assert_eq!(n.3, 0, "session {}: no skill of the old segmentation", n.0);
                assert_eq!(n.4, f.4, "session {}: the fresh skills", n.0);
                assert!(n.2.iter().all(|id| !a.2.contains(id)));
                done += 1;
            }
        }
        done
    };
    let mut done = 0;
    let mut killed_midway = 0;
    let mut progress = Vec::new();
    // Deterministic kill moments: right away, then after the first reprocessed session (as
    // its line is printed) plus a few ms, inside the next session's work.
    for (round, delay_ms) in [0u64, 3, 10, 30, 60, 120].into_iter().enumerate() {
        let mut child = Command::new(env!("CARGO_BIN_EXE_icms"))
            .current_dir(d)
            .args(["reprocess"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        // Kept open until the child is gone: it must die of the kill, not of a closed pipe.
        let mut stdout = BufReader::new(child.stdout.take().unwrap());
        if round > 0 {
            let mut line = String::new();
            stdout.read_line(&mut line).unwrap();
        }
        std::thread::sleep(Duration::from_millis(delay_ms));
        let finished = child.try_wait().unwrap().is_some();
        child.kill().unwrap();
        child.wait().unwrap();
        drop(stdout);
        let now = check(&state(&data));
        assert!(
            now >= done,
            "round {round}: {now} sessions done, {done} before"
        );
        if !finished && now < fresh.len() {
            killed_midway += 1;
        }
        done = now;
        progress.push(now);
    }
    assert!(
        killed_midway >= 2,
        "the kills landed before the end of the runs ({killed_midway})"
    );
    // A last run finishes the rest.
    let (c, out, e) = icms(d, &["reprocess", "--json"]);
    assert_eq!(c, 0, "{e}");
    let r = json(&out);
    assert_eq!(
        r["sessions_stale"].as_u64().unwrap() as usize,
        fresh.len() - done
    );
    assert_eq!(check(&state(&data)), fresh.len());
    println!(
        "{killed_midway} runs killed before their end; sessions done after each: {progress:?}"
    );
}
