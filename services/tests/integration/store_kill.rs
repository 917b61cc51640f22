//! Crash test: a child process ingesting sessions in a loop is killed (SIGKILL) at random
//! moments, several times; the store must then hold only whole sessions.
//!
//! The test re-executes its own binary with `ICMS_STORE_CHILD=<dir>`: in the child, the same
//! test function runs the ingest loop instead of the checks.

use crate::store_common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use sha2::{Digest, Sha256};
use sqlx::{Connection, SqliteConnection};

use services::store::bench::SplitMix64;
use services::store::{Store, DB_FILE};
use store_common::{fake_mcap, meta, skills};

const CHILD_ENV: &str = "ICMS_STORE_CHILD";
const TEST_NAME: &str = "store_kill::killed_ingests_leave_only_whole_sessions";

/// Size of session `i`'s MCAP bytes: 64 KiB to ~1 MiB, so that a kill can land mid-write.
fn size_of(i: u64) -> usize {
    64 * 1024 + (i as usize % 8) * 128 * 1024
}

/// Number of skills of session `i` (0 to 40).
fn skills_of(i: u64) -> usize {
    (i as usize * 7) % 41
}

/// The child: ingests sessions 0, 1, 2, ... until killed, printing each committed id.
async fn child_loop(dir: &Path) -> ! {
    let store = Store::open(dir).await.expect("child opens the store");
    println!("opened");
    for i in 0.. {
        let n = skills_of(i);
        let o = store
            .ingest(&fake_mcap(i, size_of(i)), meta(i, n), skills(i, n))
            .await
            .expect("child ingests");
        println!("ingested {i} as {} created={}", o.session_id, o.created);
    }
    unreachable!()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn killed_ingests_leave_only_whole_sessions() {
    if let Ok(dir) = std::env::var(CHILD_ENV) {
        child_loop(Path::new(&dir)).await;
    }
    let tmp = tempfile::tempdir().unwrap();
    let exe = std::env::current_exe().unwrap();
    let mut rng = SplitMix64::new(2026);
    let rounds = 8;
    for round in 0..rounds {
        let mut child = Command::new(&exe)
            .args(["--exact", TEST_NAME, "--nocapture", "--test-threads=1"])
            .env(CHILD_ENV, tmp.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, rx) = mpsc::channel::<String>();
        let reader = std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        if round % 2 == 1 {
            // Odd rounds: let at least one new session commit, then kill soon after.
            loop {
                let line = rx
                    .recv_timeout(Duration::from_secs(60))
                    .expect("child makes progress");
                if line.contains("created=true") {
                    break;
                }
            }
            tokio::time::sleep(Duration::from_millis(rng.index(40) as u64)).await;
        } else {
            // Even rounds: kill at any moment from start-up (open, migration) onwards.
            tokio::time::sleep(Duration::from_millis(rng.index(400) as u64)).await;
        }
        child.kill().unwrap();
        child.wait().unwrap();
        reader.join().unwrap();
    }

    let store = Store::open(tmp.path()).await.unwrap();
    store.integrity_check().await.unwrap();
    let mut sessions = Vec::new();
    let mut cursor = None;
    loop {
        let page = store.list_sessions(100, cursor.as_deref()).await.unwrap();
        sessions.extend(page.items);
        match page.next_cursor {
            Some(c) => cursor = Some(c),
            None => break,
        }
    }
    assert!(
        sessions.len() >= rounds / 2,
        "only {} sessions stored",
        sessions.len()
    );
    let mut skill_total = 0;
    let mut phase_total = 0;
    for s in &sessions {
        let i = s.meta.extra["i"].as_u64().unwrap();
        let n = s.meta.extra["skills"].as_u64().unwrap() as usize;
        let expected_bytes = fake_mcap(i, size_of(i));
        let path = store.session_blob_path(s.id).await.unwrap();
        let bytes =
            std::fs::read(&path).unwrap_or_else(|e| panic!("session {} blob {path:?}: {e}", s.id));
        assert_eq!(
            hex::encode(Sha256::digest(&bytes)),
            s.sha256,
            "session {} blob hash",
            s.id
        );
        assert_eq!(bytes, expected_bytes, "session {} blob content", s.id);
        assert_eq!(s.skill_ids.len(), n, "session {} skills", s.id);
        let expected_skills = skills(i, n);
        for (id, want) in s.skill_ids.iter().zip(&expected_skills) {
            let got = store.get_skill(*id).await.unwrap();
            assert_eq!(got.feature, want.feature);
            assert_eq!(got.phase_durations, want.phase_durations);
            phase_total += want.phase_durations.len() as i64;
        }
        skill_total += n;
    }
    let distinct: std::collections::HashSet<&str> =
        sessions.iter().map(|s| s.sha256.as_str()).collect();
    assert_eq!(distinct.len(), sessions.len());
    assert_eq!(store.skill_count(), skill_total);
    let opts = sqlx::sqlite::SqliteConnectOptions::new().filename(tmp.path().join(DB_FILE));
    let mut conn = SqliteConnection::connect_with(&opts).await.unwrap();
    let (skills_rows, phase_rows): (i64, i64) =
        sqlx::query_as("SELECT (SELECT count(*) FROM skills), (SELECT count(*) FROM skill_phases)")
            .fetch_one(&mut conn)
            .await
            .unwrap();
    assert_eq!(skills_rows as usize, skill_total);
    assert_eq!(phase_rows, phase_total);
    // A leftover blob of a killed ingest is reused: ingesting the next file works.
    let next = sessions
        .iter()
        .map(|s| s.meta.extra["i"].as_u64().unwrap())
        .max()
        .unwrap()
        + 1;
    let o = store
        .ingest(
            &fake_mcap(next, size_of(next)),
            meta(next, 1),
            skills(next, 1),
        )
        .await
        .unwrap();
    assert!(o.created);
    println!(
        "{} sessions, {skill_total} skills survived {rounds} kills intact",
        sessions.len()
    );
}
