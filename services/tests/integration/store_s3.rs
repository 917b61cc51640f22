//! Blobs in an S3-compatible bucket (issue 24 item 2), against a real S3 server: `s3s-fs`
//! (the Rust registry's S3 server on a directory; scripts/test installs it), one per test,
//! whose directory shows what the bucket holds.

use crate::s3_server;
use crate::store_common;

use std::path::Path;
use std::time::{Duration, Instant};

use s3_server::{S3Server, BUCKET, KEY_ID, SECRET};

use services::store::{Blobs, Database, S3Bucket, Store, StoreError};
use store_common::{fake_mcap, meta, skills, Backend};

/// The blob paths (relative, `blobs/sha256/…`) of the files under `root`.
fn blob_files(root: &Path) -> Vec<String> {
    fn walk(base: &Path, p: &Path, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(p) else {
            return;
        };
        for e in entries.flatten() {
            let path = e.path();
            if path.is_dir() {
                walk(base, &path, out);
            } else if path.extension().is_some_and(|x| x == "mcap") {
                let rel = path.strip_prefix(base).unwrap().to_string_lossy();
                out.push(rel.replace('\\', "/"));
            }
        }
    }
    let mut out = Vec::new();
    walk(root, &root.join("blobs"), &mut out);
    out.sort();
    out
}

async fn open(dir: &Path, database: &Database, bucket: S3Bucket) -> Store {
    Store::open_on(dir, database, &Blobs::S3(bucket))
        .await
        .unwrap_or_else(|e| panic!("opening a store with its blobs in a bucket: {e}"))
}

async fn blobs_are_objects_in_the_bucket_and_come_back_from_it(backend: Backend) {
    let Some(s3) = S3Server::start("blobs_are_objects_in_the_bucket") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let database = backend.database(tmp.path()).await;
    let store = open(tmp.path(), &database, s3.bucket("lab/one")).await;
    let bytes = fake_mcap(7, 40_000);
    let a = store
        .ingest(&bytes, meta(7, 2), skills(7, 2))
        .await
        .unwrap();
    let big = fake_mcap(8, 40 << 20); // past one PUT: a multipart upload
    let b = store.ingest(&big, meta(8, 1), skills(8, 1)).await.unwrap();

    let local = blob_files(tmp.path());
    assert_eq!(local.len(), 2, "{local:?}");
    let objects = blob_files(&s3.root.path().join(BUCKET).join("lab/one"));
    assert_eq!(objects, local, "each blob is an object under the prefix");
    for rel in &local {
        assert_eq!(
            std::fs::read(s3.object(&format!("lab/one/{rel}"))).unwrap(),
            std::fs::read(tmp.path().join(rel)).unwrap()
        );
    }

    // The data directory's copies are a cache: gone, they come back from the bucket.
    std::fs::remove_dir_all(tmp.path().join("blobs/sha256")).unwrap();
    let path = store.session_blob_path(a.session_id).await.unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    assert_eq!(store.read_session_blob(b.session_id).await.unwrap(), big);

    // Deleting the session deletes its object.
    store.delete_session(a.session_id).await.unwrap();
    let objects = blob_files(&s3.root.path().join(BUCKET).join("lab/one"));
    assert_eq!(objects.len(), 1, "{objects:?}");
    assert!(!path.exists());
    store.close().await;
}

async fn a_second_store_on_the_same_rows_and_bucket_reads_what_the_first_wrote(backend: Backend) {
    let Some(s3) = S3Server::start("a_second_store_reads_what_the_first_wrote") else {
        return;
    };
    let (dir_a, dir_b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let database = backend.database(dir_a.path()).await;
    let a = open(dir_a.path(), &database, s3.bucket("")).await;
    let bytes = fake_mcap(11, 100_000);
    let stored = a.ingest(&bytes, meta(11, 1), skills(11, 1)).await.unwrap();
    if backend == Backend::Sqlite {
        // One SQLite file is one server's: the second is refused on the same directory, and
        // has other rows in another; the bucket alone is not shared state.
        let err = Store::open_on(dir_a.path(), &database, &Blobs::S3(s3.bucket("")))
            .await
            .unwrap_err();
        assert!(matches!(err, StoreError::InUse { .. }), "{err}");
        return;
    }
    let b = open(dir_b.path(), &database, s3.bucket("")).await;
    assert!(blob_files(dir_b.path()).is_empty());
    let path = b.session_blob_path(stored.session_id).await.unwrap();
    assert!(path.starts_with(dir_b.path()));
    assert_eq!(std::fs::read(path).unwrap(), bytes);
    // Deleted through B, the object goes, and A (whose copy was its own) cannot serve it.
    b.delete_session(stored.session_id).await.unwrap();
    assert!(blob_files(s3.root.path().join(BUCKET).as_path()).is_empty());
    let err = a.session_blob_path(stored.session_id).await.unwrap_err();
    assert!(matches!(err, StoreError::SessionNotFound(_)), "{err}");
}

async fn an_object_changed_in_the_bucket_is_refused_not_served(backend: Backend) {
    let Some(s3) = S3Server::start("an_object_changed_in_the_bucket_is_refused") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let database = backend.database(tmp.path()).await;
    let store = open(tmp.path(), &database, s3.bucket("p")).await;
    let stored = store
        .ingest(&fake_mcap(3, 9_000), meta(3, 1), skills(3, 1))
        .await
        .unwrap();
    let rel = blob_files(tmp.path()).pop().unwrap();
    std::fs::remove_file(tmp.path().join(&rel)).unwrap();
    std::fs::write(s3.object(&format!("p/{rel}")), b"not the stored bytes").unwrap();
    let err = store
        .session_blob_path(stored.session_id)
        .await
        .unwrap_err();
    assert!(
        matches!(&err, StoreError::Corrupt(m) if m.contains("SHA-256")),
        "{err}"
    );
    assert!(
        !tmp.path().join(&rel).exists(),
        "nothing is left where the copy goes"
    );
    // A missing object is an error naming the bucket, not a hang or a panic.
    std::fs::remove_file(s3.object(&format!("p/{rel}"))).unwrap();
    let err = store
        .session_blob_path(stored.session_id)
        .await
        .unwrap_err();
    assert!(
        matches!(&err, StoreError::ObjectStore { bucket, .. } if bucket.contains("s3://icms-test/p")),
        "{err}"
    );
}

async fn the_sweep_removes_orphan_objects_and_keeps_referenced_and_young_ones(backend: Backend) {
    let Some(s3) = S3Server::start("the_sweep_removes_orphan_objects") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let database = backend.database(tmp.path()).await;
    let store = open(tmp.path(), &database, s3.bucket("")).await;
    let kept = store
        .ingest(&fake_mcap(1, 5_000), meta(1, 1), skills(1, 1))
        .await
        .unwrap();
    // An orphan object written by another server (no copy here), and one that is not a blob.
    let orphan = format!("blobs/sha256/ee/{}.mcap", "e".repeat(62));
    std::fs::create_dir_all(s3.object("blobs/sha256/ee")).unwrap();
    std::fs::write(s3.object(&orphan), b"orphan").unwrap();
    std::fs::write(s3.object("blobs/sha256/ee/notes.txt"), b"not a blob").unwrap();

    let r = store
        .sweep_orphan_blobs(Duration::from_secs(600))
        .await
        .unwrap();
    assert_eq!(r.removed, 0, "young objects stay: {r:?}");
    assert!(s3.object(&orphan).exists());

    let r = store.sweep_orphan_blobs(Duration::ZERO).await.unwrap();
    assert_eq!((r.removed, r.removed_bytes), (1, 6), "{r:?}");
    assert!(!s3.object(&orphan).exists());
    assert!(s3.object("blobs/sha256/ee/notes.txt").exists());
    let path = store.session_blob_path(kept.session_id).await.unwrap();
    assert_eq!(std::fs::read(path).unwrap(), fake_mcap(1, 5_000));
    assert_eq!(blob_files(s3.root.path().join(BUCKET).as_path()).len(), 1);
}

/// Two servers on one PostgreSQL schema and one bucket: while one is ingesting (it holds the
/// cross-server blob lock shared, from its upload to its row's commit), the other's sweep
/// removes nothing and says it skipped; once the lock is let go, the sweep removes an orphan.
async fn a_sweep_skips_while_another_server_ingests_and_removes_after(backend: Backend) {
    let Some(s3) = S3Server::start("a_sweep_skips_while_another_server_ingests") else {
        return;
    };
    let (dir_a, dir_b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let database = backend.database(dir_a.path()).await;
    let a = open(dir_a.path(), &database, s3.bucket("")).await;
    let kept = a
        .ingest(&fake_mcap(21, 5_000), meta(21, 1), skills(21, 1))
        .await
        .unwrap();
    let orphan = format!("blobs/sha256/dd/{}.mcap", "d".repeat(62));
    std::fs::create_dir_all(s3.object("blobs/sha256/dd")).unwrap();
    std::fs::write(s3.object(&orphan), b"orphan!").unwrap();
    let hold = a.hold_shared_blob_lock().await.unwrap();
    if backend == Backend::Sqlite {
        // One server per SQLite file: nothing to order across servers.
        assert!(!hold.is_held());
        hold.release().await;
        let r = a.sweep_orphan_blobs(Duration::ZERO).await.unwrap();
        assert_eq!((r.removed, r.skipped_busy), (1, false), "{r:?}");
        return;
    }
    assert!(hold.is_held());
    let b = open(dir_b.path(), &database, s3.bucket("")).await;

    let r = b.sweep_orphan_blobs(Duration::ZERO).await.unwrap();
    assert!(r.skipped_busy, "A is ingesting: {r:?}");
    assert_eq!(r.removed, 0, "{r:?}");
    assert!(s3.object(&orphan).exists());
    // A delete through B leaves its blob to a later sweep rather than wait or race.
    b.delete_session(kept.session_id).await.unwrap();
    assert_eq!(blob_files(s3.root.path().join(BUCKET).as_path()).len(), 2);
    // A's own ingests go on meanwhile (the lock is shared).
    let more = a
        .ingest(&fake_mcap(22, 5_000), meta(22, 1), skills(22, 1))
        .await
        .unwrap();

    hold.release().await;
    let r = b.sweep_orphan_blobs(Duration::ZERO).await.unwrap();
    assert!(!r.skipped_busy, "{r:?}");
    assert_eq!(
        r.removed, 2,
        "the orphan and the deleted session's blob: {r:?}"
    );
    assert!(!s3.object(&orphan).exists());
    let left = blob_files(s3.root.path().join(BUCKET).as_path());
    assert_eq!(left.len(), 1, "{left:?}");
    assert_eq!(
        b.read_session_blob(more.session_id).await.unwrap(),
        fake_mcap(22, 5_000)
    );
    a.close().await;
    b.close().await;
}

/// Sets the modification time of the file at `path` to `ago` before now.
fn used_ago(path: &Path, ago: Duration) {
    std::fs::File::options()
        .write(true)
        .open(path)
        .unwrap()
        .set_modified(std::time::SystemTime::now() - ago)
        .unwrap();
}

async fn the_copies_of_a_buckets_blobs_are_trimmed_least_recently_used_first(backend: Backend) {
    let Some(s3) = S3Server::start("the_copies_are_trimmed") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let database = backend.database(tmp.path()).await;
    let store = open(tmp.path(), &database, s3.bucket("trim")).await;
    const SIZE: usize = 100_000;
    let mut ids = Vec::new();
    for i in 0..4u64 {
        let out = store
            .ingest(
                &fake_mcap(100 + i, SIZE),
                meta(100 + i, 1),
                skills(100 + i, 1),
            )
            .await
            .unwrap();
        ids.push(out.session_id);
    }
    let minute = Duration::from_secs(60);
    let paths: Vec<_> = {
        let mut v = Vec::new();
        for id in &ids {
            v.push(store.session_blob_path(*id).await.unwrap());
        }
        v
    };
    // Last used 40, 30 and 20 minutes ago, and now.
    for (p, ago) in paths.iter().zip([40, 30, 20]) {
        used_ago(p, minute * ago);
    }
    let young = Duration::from_secs(600);
    let r = store
        .trim_blob_copies(2 * SIZE as u64 + SIZE as u64 / 2, young)
        .await
        .unwrap();
    assert_eq!((r.copies, r.bytes), (4, 4 * SIZE as u64), "{r:?}");
    assert_eq!((r.removed, r.removed_bytes), (2, 2 * SIZE as u64), "{r:?}");
    let kept: Vec<bool> = paths.iter().map(|p| p.exists()).collect();
    assert_eq!(
        kept,
        [false, false, true, true],
        "the least recently used went first"
    );
    // Never one used within the last ten minutes, however small the bound.
    let r = store.trim_blob_copies(0, young).await.unwrap();
    assert_eq!(r.removed, 1, "{r:?}");
    assert!(paths[3].exists());
    // The objects stay in the bucket: a removed copy comes back when read, and is young then.
    let again = store.session_blob_path(ids[0]).await.unwrap();
    assert_eq!(std::fs::read(&again).unwrap(), fake_mcap(100, SIZE));
    assert_eq!(store.trim_blob_copies(0, young).await.unwrap().removed, 0);
    // Reading a copy marks it used: one used 20 minutes ago and read now stays.
    used_ago(&again, minute * 20);
    store.session_blob_path(ids[0]).await.unwrap();
    assert_eq!(store.trim_blob_copies(0, young).await.unwrap().removed, 0);
    assert!(again.exists());
    // Without a bucket the files are the blobs: nothing is ever trimmed.
    let plain_dir = tempfile::tempdir().unwrap();
    let plain = backend.open(plain_dir.path()).await;
    let out = plain
        .ingest(&fake_mcap(200, SIZE), meta(200, 1), skills(200, 1))
        .await
        .unwrap();
    let path = plain.session_blob_path(out.session_id).await.unwrap();
    used_ago(&path, minute * 60);
    let r = plain.trim_blob_copies(0, young).await.unwrap();
    assert_eq!(r, services::store::TrimReport::default());
    assert!(path.exists());
}

backend_tests!(
    the_copies_of_a_buckets_blobs_are_trimmed_least_recently_used_first,
    a_sweep_skips_while_another_server_ingests_and_removes_after,
    blobs_are_objects_in_the_bucket_and_come_back_from_it,
    a_second_store_on_the_same_rows_and_bucket_reads_what_the_first_wrote,
    an_object_changed_in_the_bucket_is_refused_not_served,
    the_sweep_removes_orphan_objects_and_keeps_referenced_and_young_ones,
);

#[tokio::test]
async fn an_unreachable_or_missing_bucket_is_a_clear_error_at_open() {
    let Some(s3) = S3Server::start("an_unreachable_or_missing_bucket") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // No such bucket on a server that answers.
    let missing = S3Bucket {
        bucket: "no-such-bucket".into(),
        ..s3.bucket("")
    };
    let err = Store::open_on(tmp.path(), &Database::Sqlite, &Blobs::S3(missing))
        .await
        .unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("s3://no-such-bucket"), "{msg}");
    // Wrong credentials.
    let wrong = S3Bucket {
        credentials: Some((KEY_ID.into(), "not-the-secret".into())),
        ..s3.bucket("")
    };
    let err = Store::open_on(tmp.path(), &Database::Sqlite, &Blobs::S3(wrong))
        .await
        .unwrap_err();
    assert!(matches!(&err, StoreError::ObjectStore { .. }), "{err}");
    // Nothing listens at the endpoint: an error naming it, well within the connect limit.
    let port = s3.port;
    drop(s3);
    let gone = S3Bucket {
        endpoint: Some(format!("http://127.0.0.1:{port}")),
        credentials: Some((KEY_ID.into(), SECRET.into())),
        bucket: BUCKET.into(),
        prefix: String::new(),
    };
    let started = Instant::now();
    let err = Store::open_on(tmp.path(), &Database::Sqlite, &Blobs::S3(gone))
        .await
        .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("s3://icms-test") && msg.contains(&format!("127.0.0.1:{port}")),
        "{msg}"
    );
    assert!(
        started.elapsed() < services::store::BUCKET_CONNECT_TIMEOUT + Duration::from_secs(5),
        "gave up after {:?}",
        started.elapsed()
    );
    // Nothing was created for a store that did not open.
    assert!(!tmp.path().join(services::store::DB_FILE).exists());
}

#[test]
fn a_blobs_argument_names_a_bucket_or_is_refused_naming_what_is_accepted() {
    assert_eq!(Blobs::from_arg(None).unwrap(), Blobs::Local);
    assert_eq!(Blobs::from_arg(Some("  ")).unwrap(), Blobs::Local);
    let Blobs::S3(b) = Blobs::from_arg(Some("s3://lab-data/icms/sessions/")).unwrap() else {
        panic!("a bucket");
    };
    assert_eq!(
        (b.bucket.as_str(), b.prefix.as_str()),
        ("lab-data", "icms/sessions")
    );
    assert_eq!(b.url(), "s3://lab-data/icms/sessions");
    for bad in [
        "lab-data",
        "gs://lab-data",
        "s3://",
        "s3://Lab_Data",
        "s3://ab",
        "s3://lab-data/a/../b",
        "s3://lab-data/a//b",
    ] {
        let err = Blobs::from_arg(Some(bad)).unwrap_err().to_string();
        assert!(
            err.contains(bad) && err.contains("s3://BUCKET"),
            "{bad}: {err}"
        );
    }
}
