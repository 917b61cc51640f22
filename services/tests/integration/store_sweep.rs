//! Durability and leftovers (issue 17): commits are `synchronous=FULL`, an ingest that meets a
//! locked data base fails as busy, and the blob it left is swept, while blobs that rows
//! reference, or that an ingest running at the same time is about to reference, never are.

use crate::store_common;

use store_common::Backend;

use std::path::Path;
use std::time::{Duration, SystemTime};

use sqlx::{Connection, SqliteConnection};

use services::store::{Durability, Store, DB_FILE};
use store_common::{blob_count, fake_mcap, meta, skills};

/// Writes a blob file that no row references, last modified `age` ago.
fn orphan(dir: &Path, name: &str, age: Duration) -> std::path::PathBuf {
    let shard = dir.join("blobs/sha256/ff");
    std::fs::create_dir_all(&shard).unwrap();
    let path = shard.join(format!("{name}.mcap"));
    std::fs::write(&path, b"orphan").unwrap();
    let f = std::fs::File::options().write(true).open(&path).unwrap();
    f.set_modified(SystemTime::now() - age).unwrap();
    path
}

#[tokio::test]
async fn the_store_commits_with_synchronous_full_unless_asked_otherwise() {
    let tmp = tempfile::tempdir().unwrap();
    let store = Store::open(tmp.path()).await.unwrap();
    assert_eq!(store.synchronous_setting().await.unwrap(), 2, "FULL");
    store.close().await;
    let relaxed = Store::open_with_durability(&tmp.path().join("b"), Durability::Normal)
        .await
        .unwrap();
    assert_eq!(relaxed.synchronous_setting().await.unwrap(), 1, "NORMAL");
}

#[tokio::test]
async fn an_ingest_that_meets_a_locked_data_base_is_busy_and_its_blob_is_swept() {
    let tmp = tempfile::tempdir().unwrap();
    let store = Store::open(tmp.path()).await.unwrap();
    let kept = store
        .ingest(&fake_mcap(1, 5_000), meta(1, 2), skills(1, 2))
        .await
        .unwrap();
    let opts = sqlx::sqlite::SqliteConnectOptions::new().filename(tmp.path().join(DB_FILE));
    let mut other = SqliteConnection::connect_with(&opts).await.unwrap();
    sqlx::query("BEGIN IMMEDIATE")
        .execute(&mut other)
        .await
        .unwrap();
    let err = store
        .ingest(&fake_mcap(2, 5_000), meta(2, 2), skills(2, 2))
        .await
        .unwrap_err();
    assert!(err.is_busy(), "{err}");
    sqlx::query("ROLLBACK").execute(&mut other).await.unwrap();
    assert_eq!(blob_count(tmp.path()), 2, "the failed ingest left its blob");

    let young = orphan(tmp.path(), "young", Duration::ZERO);
    let old = orphan(tmp.path(), "old", Duration::from_secs(3600));
    // With a minimum age, only the old orphan goes.
    let r = store
        .sweep_orphan_blobs(Duration::from_secs(600))
        .await
        .unwrap();
    assert_eq!((r.examined, r.removed), (1, 1), "{r:?}");
    assert!(!old.exists() && young.exists());
    // Without one, every unreferenced blob goes; the stored session's stays.
    let r = store.sweep_orphan_blobs(Duration::ZERO).await.unwrap();
    assert_eq!(r.removed, 2, "{r:?}");
    assert!(!young.exists());
    assert_eq!(blob_count(tmp.path()), 1);
    let path = store.session_blob_path(kept.session_id).await.unwrap();
    assert_eq!(std::fs::read(path).unwrap(), fake_mcap(1, 5_000));
}

async fn sweeping_beside_running_ingests_never_takes_a_blob_they_store(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let ingests = (0..40u64).map(|i| {
        let store = store.clone();
        tokio::spawn(async move {
            store
                .ingest(&fake_mcap(100 + i, 20_000), meta(100 + i, 1), skills(i, 1))
                .await
                .unwrap()
        })
    });
    let ingests: Vec<_> = ingests.collect();
    let sweeper = {
        let store = store.clone();
        tokio::spawn(async move {
            let mut removed = 0;
            for _ in 0..40 {
                removed += store
                    .sweep_orphan_blobs(Duration::ZERO)
                    .await
                    .unwrap()
                    .removed;
                tokio::task::yield_now().await;
            }
            removed
        })
    };
    let mut sessions = Vec::new();
    for t in ingests {
        sessions.push(t.await.unwrap().session_id);
    }
    assert_eq!(sweeper.await.unwrap(), 0, "nothing was an orphan");
    for id in sessions {
        let path = store.session_blob_path(id).await.unwrap();
        assert!(path.exists(), "session {id}'s blob was swept");
    }
}

backend_tests!(sweeping_beside_running_ingests_never_takes_a_blob_they_store,);
