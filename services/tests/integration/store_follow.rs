//! Several stores on one PostgreSQL data base answer the same (issue 24): a skill stored,
//! replaced or deleted through one store shows in the k-nearest and recognition indexes of
//! another (different data directories, one schema) within seconds, and when the other's
//! listening connection is lost and comes back, what it missed meanwhile is reloaded.
//!
//! PostgreSQL only: skipped, saying so, without ICMS_TEST_POSTGRES_URL (failing instead
//! under ICMS_REQUIRE_TOOLS), as the other store tests.

use crate::store_common;
use crate::tcp_relay;

use std::time::{Duration, Instant};

use services::segmentation::SEGMENTATION_VERSION;
use services::store::{Database, SkillsChanged, Store};
use sqlx::Connection as _;
use store_common::{fake_mcap, meta, skills, Backend};
use tcp_relay::Relay;

/// How long a change may take to show in the other store.
const DEADLINE: Duration = Duration::from_secs(5);

/// Waits until `ok` holds, at most [`DEADLINE`], failing with `what` otherwise.
async fn eventually(what: &str, mut ok: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ok() {
        assert!(
            start.elapsed() < DEADLINE,
            "not within {DEADLINE:?}: {what}"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Whether `store`'s k-nearest index and recognition index both hold skill `id`.
fn indexed(store: &Store, id: i64) -> bool {
    store.nearest_to_skill(id, 1).is_ok() && store.recognition_index().row_of(id).is_some()
}

/// Whether neither index of `store` holds skill `id`.
fn forgotten(store: &Store, id: i64) -> bool {
    store.nearest_to_skill(id, 1).is_err() && store.recognition_index().row_of(id).is_none()
}

/// The URL of a schema of its own in the test data base (made here), or `None` to skip.
async fn shared_database(test: &str, tmp: &std::path::Path) -> Option<String> {
    let backend = Backend::postgres_or_skip(test)?;
    match backend.database(tmp).await {
        Database::Postgres(url) => Some(url),
        Database::Sqlite => unreachable!("a PostgreSQL backend"),
    }
}

async fn open(dir: &std::path::Path, url: &str) -> Store {
    Store::open_in(dir, &Database::Postgres(url.to_owned()))
        .await
        .unwrap_or_else(|e| panic!("opening a store in {}: {e}", dir.display()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_skill_stored_replaced_or_deleted_through_one_store_shows_in_the_others_indexes() {
    let tmp = tempfile::tempdir().unwrap();
    let Some(url) = shared_database("store_follow::two_stores", tmp.path()).await else {
        return;
    };
    let a = open(&tmp.path().join("a"), &url).await;
    let b = open(&tmp.path().join("b"), &url).await;
    let mut b_changes = b.skill_changes();

    // Stored through A: B's `nearest` and recognition find it.
    let new = skills(41, 6);
    let o = a
        .ingest(&fake_mcap(1, 700), meta(1, 6), new.clone())
        .await
        .unwrap();
    for &id in &o.skill_ids {
        eventually(
            &format!("skill {id} stored through A in B's indexes"),
            || indexed(&b, id),
        )
        .await;
    }
    let first = o.skill_ids[0];
    let nearest = b.nearest(&new[0].feature, 1).unwrap();
    assert_eq!(
        nearest[0].0, first,
        "B's nearest to the skill's own feature"
    );
    assert_eq!(b.skill_count(), a.skill_count());

    // Deleted through A: gone from B's indexes, and B's subscribers are told.
    a.delete_skill(first).await.unwrap();
    eventually(
        &format!("skill {first} deleted through A gone from B"),
        || forgotten(&b, first),
    )
    .await;
    let told = tokio::time::timeout(DEADLINE, async {
        loop {
            match b_changes.recv().await.unwrap() {
                SkillsChanged::Skills(ids) if ids.contains(&first) => break,
                _ => {}
            }
        }
    })
    .await;
    assert!(told.is_ok(), "B's subscribers were not told of the delete");

    // Replaced through A (reprocessing): B drops the old skills and finds the new ones.
    let replaced = a
        .replace_session_skills(o.session_id, skills(42, 3), SEGMENTATION_VERSION + 1)
        .await
        .unwrap()
        .expect("replaced");
    assert!(!replaced.added_skill_ids.is_empty());
    for &id in &replaced.added_skill_ids {
        eventually(&format!("skill {id} added by a replacement in B"), || {
            indexed(&b, id)
        })
        .await;
    }
    for &id in &replaced.removed_skill_ids {
        eventually(
            &format!("skill {id} removed by a replacement gone from B"),
            || forgotten(&b, id),
        )
        .await;
    }

    // The session deleted through A: none of its skills is left in B.
    a.delete_session(o.session_id).await.unwrap();
    eventually("the deleted session's skills gone from B", || {
        b.skill_count() == 0 && b.recognition_index().is_empty()
    })
    .await;
    // B's own writes go the other way, and their echo in B changes nothing.
    let o = b
        .ingest(&fake_mcap(2, 700), meta(2, 2), skills(43, 2))
        .await
        .unwrap();
    for &id in &o.skill_ids {
        eventually(
            &format!("skill {id} stored through B in A's indexes"),
            || indexed(&a, id),
        )
        .await;
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(b.skill_count(), 2);
    a.close().await;
    b.close().await;
}

/// `url` with its `host:port` replaced by `addr`; and the `host:port` it named.
fn through(url: &str, addr: std::net::SocketAddr) -> (String, String) {
    let start = url.find('@').expect("a URL with a user") + 1;
    let end = start + url[start..].find('/').expect("a URL with a data base");
    (
        format!("{}{addr}{}", &url[..start], &url[end..]),
        url[start..end].to_owned(),
    )
}

/// The pids of the connections named `application_name`.
async fn backends(url: &str, application_name: &str) -> Vec<i32> {
    let mut conn = sqlx::PgConnection::connect(url).await.unwrap();
    let pids = sqlx::query_scalar("SELECT pid FROM pg_stat_activity WHERE application_name = $1")
        .bind(application_name)
        .fetch_all(&mut conn)
        .await
        .unwrap();
    conn.close().await.unwrap();
    pids
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_store_whose_listening_connection_was_lost_reloads_what_it_missed() {
    let tmp = tempfile::tempdir().unwrap();
    let Some(url) = shared_database("store_follow::reconnect", tmp.path()).await else {
        return;
    };
    let a = open(&tmp.path().join("a"), &url).await;
    let (relay_url, upstream) = through(&url, "127.0.0.1:1".parse().unwrap());
    let relay = Relay::to(upstream);
    let (relay_url, _) = through(&relay_url, relay.addr);
    // B reaches PostgreSQL through the relay; A directly.
    let b = open(&tmp.path().join("b"), &relay_url).await;
    let kept = a
        .ingest(&fake_mcap(1, 700), meta(1, 3), skills(51, 3))
        .await
        .unwrap()
        .skill_ids;
    for &id in &kept {
        eventually(&format!("skill {id} in B before the cut"), || {
            indexed(&b, id)
        })
        .await;
    }
    let name = b.follower_application_name().expect("B listens");
    let pids = backends(&url, &name).await;
    assert_eq!(pids.len(), 1, "B's listening connection {name:?}: {pids:?}");
    let mut b_changes = b.skill_changes();

    // B's listener is cut off, and cannot come back while A writes.
    relay.hold();
    let mut conn = sqlx::PgConnection::connect(&url).await.unwrap();
    let ended: bool = sqlx::query_scalar("SELECT pg_terminate_backend($1, 5000)")
        .bind(pids[0])
        .fetch_one(&mut conn)
        .await
        .unwrap();
    conn.close().await.unwrap();
    assert!(ended, "B's listening connection was not terminated");
    let added = a
        .ingest(&fake_mcap(2, 700), meta(2, 2), skills(52, 2))
        .await
        .unwrap()
        .skill_ids;
    a.delete_skill(kept[0]).await.unwrap();
    // Nothing reached B: its notifications are lost.
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(
        added.iter().all(|&id| forgotten(&b, id)) && indexed(&b, kept[0]),
        "B saw A's writes while it was cut off: the test does not test the reconnection"
    );
    assert!(backends(&url, &name).await.is_empty(), "B listens again");

    // Back: B listens again, reloads, and tells its subscribers everything may have changed.
    relay.release();
    for &id in &added {
        eventually(
            &format!("skill {id} stored while B was cut off, in B"),
            || indexed(&b, id),
        )
        .await;
    }
    eventually(
        &format!("skill {} deleted while B was cut off, gone from B", kept[0]),
        || forgotten(&b, kept[0]),
    )
    .await;
    let told = tokio::time::timeout(DEADLINE, async {
        while b_changes.recv().await.unwrap() != SkillsChanged::All {}
    })
    .await;
    assert!(
        told.is_ok(),
        "B's subscribers were not told to drop everything"
    );
    assert_eq!(backends(&url, &name).await.len(), 1, "B listens again");
    assert_eq!(b.skill_count(), a.skill_count());
    // And it follows again.
    a.delete_skill(kept[1]).await.unwrap();
    eventually(
        &format!("skill {} deleted after the reconnection", kept[1]),
        || forgotten(&b, kept[1]),
    )
    .await;
    a.close().await;
    b.close().await;
}
