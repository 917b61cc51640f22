//! Store tests: ingest, idempotency, concurrency, delete, restart, refusing foreign databases,
//! and k-nearest search.

use crate::store_common;

use store_common::Backend;

use std::collections::HashSet;
use std::path::Path;

use sha2::{Digest, Sha256};
use sqlx::{Connection, SqliteConnection};

use services::store::{Store, StoreError, DB_FILE, FEATURE_DIM};
use store_common::{blob_count, fake_mcap, meta, skills};

async fn raw_conn(path: &Path) -> SqliteConnection {
    let opts = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(path)
        .create_if_missing(true);
    SqliteConnection::connect_with(&opts).await.unwrap()
}

async fn ingesting_the_same_bytes_twice_gives_the_same_session_and_one_blob(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let bytes = fake_mcap(1, 10_000);
    let a = store
        .ingest(&bytes, meta(1, 3), skills(1, 3))
        .await
        .unwrap();
    let b = store
        .ingest(&bytes, meta(1, 3), skills(1, 3))
        .await
        .unwrap();
    assert!(a.created);
    assert!(!b.created);
    assert_eq!(a.session_id, b.session_id);
    assert_eq!(a.skill_ids, b.skill_ids);
    assert_eq!(a.skill_ids.len(), 3);
    let page = store.list_sessions(100, None).await.unwrap();
    assert_eq!(page.items.len(), 1);
    assert_eq!(blob_count(tmp.path()), 1);
    assert_eq!(store.skill_count(), 3);

    let s = store.get_session(a.session_id).await.unwrap();
    assert_eq!(s.sha256, hex::encode(Sha256::digest(&bytes)));
    assert_eq!(s.size_bytes, bytes.len() as i64);
    assert_eq!(s.meta, meta(1, 3));
    let on_disk = std::fs::read(store.session_blob_path(a.session_id).await.unwrap()).unwrap();
    assert_eq!(on_disk, bytes);
    let skill = store.get_skill(a.skill_ids[0]).await.unwrap();
    assert_eq!(skill.session_id, a.session_id);
    let expected = &skills(1, 3)[0];
    assert_eq!(skill.phase_durations, expected.phase_durations);
    assert_eq!(skill.feature, expected.feature);
    assert_eq!(skill.quality, expected.quality);
}

async fn concurrent_ingests_store_every_file_once(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let mut tasks = Vec::new();
    for i in 0..16u64 {
        let store = store.clone();
        tasks.push(tokio::spawn(async move {
            store
                .ingest(&fake_mcap(i, 50_000), meta(i, 5), skills(i, 5))
                .await
                .unwrap()
        }));
    }
    let same = fake_mcap(999, 80_000);
    for _ in 0..8 {
        let store = store.clone();
        let same = same.clone();
        tasks.push(tokio::spawn(async move {
            store
                .ingest(&same, meta(999, 2), skills(999, 2))
                .await
                .unwrap()
        }));
    }
    let mut outcomes = Vec::new();
    for t in tasks {
        outcomes.push(t.await.unwrap());
    }
    let distinct: HashSet<i64> = outcomes[..16].iter().map(|o| o.session_id).collect();
    assert_eq!(distinct.len(), 16);
    assert!(outcomes[..16].iter().all(|o| o.created));
    let same_ids: HashSet<i64> = outcomes[16..].iter().map(|o| o.session_id).collect();
    assert_eq!(same_ids.len(), 1);
    assert_eq!(outcomes[16..].iter().filter(|o| o.created).count(), 1);
    assert!(outcomes[16..].iter().all(|o| o.skill_ids.len() == 2));

    let page = store.list_sessions(1000, None).await.unwrap();
    assert_eq!(page.items.len(), 17);
    assert_eq!(blob_count(tmp.path()), 17);
    assert_eq!(store.skill_count(), 16 * 5 + 2);
    store.integrity_check().await.unwrap();
}

async fn deleting_a_session_removes_its_rows_skills_and_blob(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let keep = store
        .ingest(&fake_mcap(1, 1000), meta(1, 2), skills(1, 2))
        .await
        .unwrap();
    let gone = store
        .ingest(&fake_mcap(2, 1000), meta(2, 4), skills(2, 4))
        .await
        .unwrap();
    let path = store.session_blob_path(gone.session_id).await.unwrap();
    assert!(path.exists());
    store.delete_session(gone.session_id).await.unwrap();
    assert!(!path.exists());
    assert!(matches!(
        store.get_session(gone.session_id).await,
        Err(StoreError::SessionNotFound(_))
    ));
    for id in &gone.skill_ids {
        assert!(matches!(
            store.get_skill(*id).await,
            Err(StoreError::SkillNotFound(_))
        ));
    }
    assert_eq!(store.skill_count(), 2);
    let near: Vec<i64> = store
        .nearest(&[0.0; FEATURE_DIM], 10)
        .unwrap()
        .into_iter()
        .map(|n| n.0)
        .collect();
    assert_eq!(near.len(), 2);
    assert!(near.iter().all(|id| keep.skill_ids.contains(id)));
    let phases = backend
        .count(tmp.path(), "SELECT count(*) FROM skill_phases")
        .await;
    assert_eq!(phases, 2 * 5);
    assert!(matches!(
        store.delete_session(gone.session_id).await,
        Err(StoreError::SessionNotFound(_))
    ));
    // The same file again is a new session, with its blob back.
    let again = store
        .ingest(&fake_mcap(2, 1000), meta(2, 4), skills(2, 4))
        .await
        .unwrap();
    assert!(again.created);
    assert!(store
        .session_blob_path(again.session_id)
        .await
        .unwrap()
        .exists());
}

async fn deleting_a_skill_keeps_its_session(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let s = store
        .ingest(&fake_mcap(1, 1000), meta(1, 3), skills(1, 3))
        .await
        .unwrap();
    store.delete_skill(s.skill_ids[1]).await.unwrap();
    let session = store.get_session(s.session_id).await.unwrap();
    assert_eq!(session.skill_ids, vec![s.skill_ids[0], s.skill_ids[2]]);
    assert_eq!(store.skill_count(), 2);
    assert!(matches!(
        store.delete_skill(s.skill_ids[1]).await,
        Err(StoreError::SkillNotFound(_))
    ));
    // Several at once come back in the order asked, the deleted one left out.
    let ids = [s.skill_ids[2], s.skill_ids[1], s.skill_ids[0]];
    let got: Vec<i64> = store
        .get_skills(&ids)
        .await
        .unwrap()
        .iter()
        .map(|k| k.id)
        .collect();
    assert_eq!(got, vec![s.skill_ids[2], s.skill_ids[0]]);
    assert!(store.get_skills(&[]).await.unwrap().is_empty());
}

async fn invalid_skills_are_refused_and_store_nothing(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let mut bad = skills(1, 2);
    bad[1].feature.pop();
    let err = store
        .ingest(&fake_mcap(1, 1000), meta(1, 2), bad)
        .await
        .unwrap_err();
    assert!(matches!(err, StoreError::InvalidInput(_)), "{err}");
    let mut bad = skills(1, 2);
    bad[0].quality = f64::NAN;
    let err = store
        .ingest(&fake_mcap(1, 1000), meta(1, 2), bad)
        .await
        .unwrap_err();
    assert!(matches!(err, StoreError::InvalidInput(_)), "{err}");
    assert!(store
        .list_sessions(10, None)
        .await
        .unwrap()
        .items
        .is_empty());
    assert_eq!(store.skill_count(), 0);
}

async fn a_session_without_skills_is_stored(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let s = store
        .ingest(&fake_mcap(1, 100), meta(1, 0), vec![])
        .await
        .unwrap();
    assert!(s.created);
    assert!(s.skill_ids.is_empty());
    assert!(store
        .get_session(s.session_id)
        .await
        .unwrap()
        .skill_ids
        .is_empty());
}

async fn reopening_the_store_finds_everything_again(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let mut outcomes = Vec::new();
    {
        let store = backend.open(tmp.path()).await;
        for i in 0..3 {
            outcomes.push(
                store
                    .ingest(&fake_mcap(i, 2000), meta(i, 4), skills(i, 4))
                    .await
                    .unwrap(),
            );
        }
        store.close().await;
    }
    let store = backend.open(tmp.path()).await;
    assert_eq!(store.skill_count(), 12);
    let page = store.list_sessions(10, None).await.unwrap();
    assert_eq!(page.items.len(), 3);
    for (i, o) in outcomes.iter().enumerate() {
        let s = store.get_session(o.session_id).await.unwrap();
        assert_eq!(s.skill_ids, o.skill_ids);
        assert_eq!(
            std::fs::read(store.session_blob_path(o.session_id).await.unwrap()).unwrap(),
            fake_mcap(i as u64, 2000)
        );
        // The reloaded feature index finds each skill as its own nearest neighbour.
        let f = store.get_skill(o.skill_ids[0]).await.unwrap().feature;
        assert_eq!(store.nearest(&f, 1).unwrap()[0], (o.skill_ids[0], 0.0));
    }
    let again = store
        .ingest(&fake_mcap(1, 2000), meta(1, 4), skills(1, 4))
        .await
        .unwrap();
    assert!(!again.created);
    assert_eq!(again.session_id, outcomes[1].session_id);
}

#[tokio::test]
async fn a_foreign_sqlite_file_is_refused_untouched() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join(DB_FILE);
    {
        let mut conn = raw_conn(&path).await;
        sqlx::query("CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)")
            .execute(&mut conn)
            .await
            .unwrap();
        conn.close().await.unwrap();
    }
    let before = std::fs::read(&path).unwrap();
    let err = Store::open(tmp.path()).await.unwrap_err();
    assert!(
        matches!(&err, StoreError::NotOurs(p) if p == &path),
        "{err}"
    );
    assert!(err.to_string().contains("not an ICMS database"), "{err}");
    assert_eq!(std::fs::read(&path).unwrap(), before);
}

/// `open_existing` (for commands that only read) never creates a data base: a missing
/// directory, an empty one or one with an empty database file is `NoDataBase`, left as it was.
#[tokio::test]
async fn opening_an_existing_store_creates_nothing_where_there_is_none() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("missing");
    let err = Store::open_existing(&missing).await.unwrap_err();
    assert!(
        matches!(&err, StoreError::NoDataBase(p) if p == &missing),
        "{err}"
    );
    assert!(err.to_string().contains("no ICMS data base at"), "{err}");
    assert!(!missing.exists());
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    assert!(matches!(
        Store::open_existing(&empty).await,
        Err(StoreError::NoDataBase(_))
    ));
    assert_eq!(std::fs::read_dir(&empty).unwrap().count(), 0);
    std::fs::write(empty.join(DB_FILE), b"").unwrap();
    assert!(matches!(
        Store::open_existing(&empty).await,
        Err(StoreError::NoDataBase(_))
    ));
    assert_eq!(std::fs::read(empty.join(DB_FILE)).unwrap(), b"");
    // A file where the directory should be.
    let file = tmp.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    assert!(matches!(
        Store::open_existing(&file).await,
        Err(StoreError::NoDataBase(_))
    ));

    let made = tmp.path().join("made");
    let store = Store::open(&made).await.unwrap();
    store
        .ingest(&fake_mcap(1, 1000), meta(1, 2), skills(1, 2))
        .await
        .unwrap();
    store.close().await;
    let store = Store::open_existing(&made).await.unwrap();
    assert_eq!(store.skill_count(), 2);
    store.close().await;
}

#[tokio::test]
async fn a_database_with_another_application_id_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join(DB_FILE);
    {
        let mut conn = raw_conn(&path).await;
        sqlx::query("PRAGMA application_id = 1234")
            .execute(&mut conn)
            .await
            .unwrap();
        conn.close().await.unwrap();
    }
    assert!(matches!(
        Store::open(tmp.path()).await,
        Err(StoreError::NotOurs(_))
    ));
}

#[tokio::test]
async fn a_file_that_is_not_sqlite_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join(DB_FILE), vec![0x42u8; 8192]).unwrap();
    let err = Store::open(tmp.path()).await.unwrap_err();
    assert!(matches!(err, StoreError::NotOurs(_)), "{err}");
}

#[tokio::test]
async fn a_schema_newer_than_the_binary_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    Store::open(tmp.path()).await.unwrap().close().await;
    {
        let mut conn = raw_conn(&tmp.path().join(DB_FILE)).await;
        sqlx::query(
            "INSERT INTO _sqlx_migrations (version, description, success, checksum, execution_time) \
             VALUES (9999, 'from the future', 1, x'00', 0)",
        )
        .execute(&mut conn)
        .await
        .unwrap();
        conn.close().await.unwrap();
    }
    let err = Store::open(tmp.path()).await.unwrap_err();
    match &err {
        StoreError::SchemaTooNew { found, supported } => {
            assert_eq!(*found, 9999);
            // The newest migration this binary carries.
            let newest = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../migrations"))
                .unwrap()
                .filter_map(|e| {
                    let name = e.unwrap().file_name().into_string().unwrap();
                    name.split('_').next().and_then(|v| v.parse::<i64>().ok())
                })
                .max()
                .unwrap();
            assert_eq!(*supported, newest);
        }
        other => panic!("expected SchemaTooNew, got {other}"),
    }
    assert!(err.to_string().contains("newer than this binary"), "{err}");
}

async fn nearest_returns_the_exact_neighbours_of_a_small_set(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let mut all = Vec::new();
    for i in 0..5u64 {
        let new = skills(100 + i, 40);
        let o = store
            .ingest(&fake_mcap(i, 500), meta(i, 40), new.clone())
            .await
            .unwrap();
        all.extend(
            o.skill_ids
                .into_iter()
                .zip(new.into_iter().map(|s| s.feature)),
        );
    }
    let dist = |a: &[f32], b: &[f32]| -> f32 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y) * (x - y))
            .sum::<f32>()
            .sqrt()
    };
    let brute = |q: &[f32], exclude: Option<i64>, k: usize| -> Vec<i64> {
        let mut v: Vec<(f32, i64)> = all
            .iter()
            .filter(|(id, _)| Some(*id) != exclude)
            .map(|(id, f)| (dist(q, f), *id))
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        v.into_iter().take(k).map(|x| x.1).collect()
    };
    let q = [0.1f32; FEATURE_DIM];
    let got = store.nearest(&q, 7).unwrap();
    assert_eq!(
        got.iter().map(|g| g.0).collect::<Vec<_>>(),
        brute(&q, None, 7)
    );
    for w in got.windows(2) {
        assert!(w[0].1 <= w[1].1);
    }
    let (id, f) = &all[17];
    let got = store.nearest_to_skill(*id, 5).unwrap();
    assert_eq!(
        got.iter().map(|g| g.0).collect::<Vec<_>>(),
        brute(f, Some(*id), 5)
    );
    assert!((got[0].1 - dist(f, &all.iter().find(|a| a.0 == got[0].0).unwrap().1)).abs() < 1e-6);
    assert_eq!(store.nearest(&q, 1000).unwrap().len(), 200);
    assert!(store.nearest(&q, 0).unwrap().is_empty());
    assert!(matches!(
        store.nearest(&[0.0; 3], 1),
        Err(StoreError::InvalidQuery(_))
    ));
    assert!(matches!(
        store.nearest_to_skill(-1, 1),
        Err(StoreError::SkillNotFound(-1))
    ));
}

async fn an_ingested_skill_is_labelled_and_found_by_its_whole_grasp_type(backend: Backend) {
    // The store documents labels such as `precision-2vf` and filters by them, but stored only
    // the family (`precision`): a filter by the whole label never found a real skill.
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("s.mcap");
    let scenario = dfs_core::scenario::Scenario::builtin("sphere-lift", 3).unwrap();
    services::session::record_simulation(&scenario, None, &path, |_, _| {}).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let (meta, skills) = services::ingest::analyse(&bytes, "s.mcap").unwrap();
    assert_eq!(skills.len(), 1);
    let label = skills[0].grasp_type.clone();
    let params = &skills[0].params["grasp_type"];
    assert_eq!(
        label,
        format!(
            "{}-{}vf",
            params["label"].as_str().unwrap(),
            params["opposing_virtual_fingers"]
        )
    );
    let store = backend.open(&tmp.path().join("data")).await;
    let s = store.ingest(&bytes, meta, skills).await.unwrap();
    for filter in [label.as_str(), label.split('-').next().unwrap()] {
        let q = services::store::SkillQuery {
            grasp_type: Some(filter.to_owned()),
            ..Default::default()
        };
        let page = store.query_skills(&q).await.unwrap();
        let ids: Vec<i64> = page.items.iter().map(|k| k.id).collect();
        assert_eq!(ids, s.skill_ids, "grasp_type={filter}");
    }
}

/// One writer per data directory: a second open to write is refused naming the holder (two
/// servers would answer from caches the other's writes leave stale), a reader still opens, and
/// once the writer closes the next one comes in.
#[tokio::test]
async fn a_second_writer_of_a_data_directory_is_refused_naming_the_first() {
    let tmp = tempfile::tempdir().unwrap();
    let first = Store::open(tmp.path()).await.unwrap();
    for second in [
        Store::open(tmp.path()).await,
        Store::open_existing_to_write(tmp.path()).await,
    ] {
        match second {
            Err(StoreError::InUse { dir, holder }) => {
                assert_eq!(dir, tmp.path());
                assert!(
                    holder.contains(&format!("pid {}", std::process::id())),
                    "{holder}"
                );
            }
            other => panic!("a second writer opened: {other:?}"),
        }
    }
    let reader = Store::open_existing(tmp.path()).await.unwrap();
    assert_eq!(reader.skill_count(), 0);
    reader.close().await;
    first.close().await;
    let next = Store::open(tmp.path()).await.unwrap();
    next.close().await;
}

backend_tests!(
    ingesting_the_same_bytes_twice_gives_the_same_session_and_one_blob,
    concurrent_ingests_store_every_file_once,
    deleting_a_session_removes_its_rows_skills_and_blob,
    deleting_a_skill_keeps_its_session,
    invalid_skills_are_refused_and_store_nothing,
    a_session_without_skills_is_stored,
    reopening_the_store_finds_everything_again,
    nearest_returns_the_exact_neighbours_of_a_small_set,
    an_ingested_skill_is_labelled_and_found_by_its_whole_grasp_type,
);
