//! Reprocessing (issue 18, item 7): stored sessions whose skills an older segmentation made
//! are segmented again from their files, one transaction per session; skills that come out
//! the same are kept (ids, replays), the others replaced; a second run does nothing; a session
//! that fails is reported and the others go on; a data base from before versions were recorded
//! is migrated to version 0 and brought up to date.

use crate::store_common;

use store_common::Backend;

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use dfs_core::scenario::Scenario;
use services::ingest::{analyse, ingest_bytes};
use services::reprocess::{reprocess, ReprocessEvent, ReprocessReport};
use services::segmentation::SEGMENTATION_VERSION;
use services::store::{SkillRecord, Store, StoreError, DB_FILE};
use sqlx::{Connection, SqliteConnection};
use store_common::{blob_count, fake_mcap, meta, skills, unreachable_report};

/// The bytes of a built-in scenario recorded with `seed` (whole, or cut to `duration` s).
fn simulate(dir: &Path, name: &str, seed: u64, duration: Option<f64>) -> Vec<u8> {
    let scenario = Scenario::builtin(name, seed).unwrap();
    let path = dir.join(format!("{name}-{seed}.mcap"));
    services::session::record_simulation(&scenario, duration, &path, |_, _| {}).unwrap();
    std::fs::read(&path).unwrap()
}

/// Marks every session as segmented by version 0, as an older segmentation left them.
async fn mark_all_stale(backend: Backend, data: &Path) {
    backend
        .sql(
            data,
            &[("UPDATE sessions SET segmentation_version = 0", None)],
        )
        .await;
}

/// Runs a reprocessing to the end; returns its report and the events' kinds in order.
async fn run(store: &Store) -> (ReprocessReport, Vec<String>) {
    let mut events = Vec::new();
    let report = reprocess(store, &AtomicBool::new(false), |e| {
        events.push(match e {
            ReprocessEvent::Started {
                index,
                total,
                session,
            } => {
                format!("started {index}/{total} {}", session.id)
            }
            ReprocessEvent::Reprocessed(r) => format!("reprocessed {}", r.session_id),
            ReprocessEvent::Skipped(s) => format!("skipped {}", s.id),
            ReprocessEvent::Failed(f) => format!("failed {}", f.session_id),
        })
    })
    .await
    .unwrap();
    (report, events)
}

/// A skill without what the store gives it (id, insertion time): what segmentation made.
fn content(s: &SkillRecord) -> SkillRecord {
    SkillRecord {
        id: 0,
        created_at: String::new(),
        ..s.clone()
    }
}

async fn skills_of(store: &Store, session_id: i64) -> Vec<SkillRecord> {
    let ids = store.get_session(session_id).await.unwrap().skill_ids;
    let mut out = Vec::new();
    for id in ids {
        out.push(store.get_skill(id).await.unwrap());
    }
    out.sort_by_key(|s| (s.start_ns, s.id));
    out
}

/// The segmentation versions of the sessions `ids`.
async fn versions(store: &Store, ids: &[i64]) -> Vec<u32> {
    let mut v = Vec::new();
    for id in ids {
        v.push(store.get_session(*id).await.unwrap().segmentation_version);
    }
    v
}

async fn reprocessing_keeps_unchanged_skills_replaces_changed_ones_and_runs_once(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let two = simulate(tmp.path(), "two-grasps", 4, None);
    let sphere = simulate(tmp.path(), "sphere-lift", 3, None);
    let store = backend.open(&data).await;
    let a = ingest_bytes(&store, two.clone(), "two.mcap".into())
        .await
        .unwrap();
    let b = ingest_bytes(&store, sphere.clone(), "sphere.mcap".into())
        .await
        .unwrap();
    assert_eq!(a.skill_ids.len(), 2, "two grasps");
    assert_eq!(b.skill_ids.len(), 1);
    // Ingest records the current version, on the session and on each skill.
    for s in [a.session_id, b.session_id] {
        let session = store.get_session(s).await.unwrap();
        assert_eq!(session.segmentation_version, SEGMENTATION_VERSION);
    }
    let originals_a = skills_of(&store, a.session_id).await;
    let originals_b = skills_of(&store, b.session_id).await;
    assert!(originals_a
        .iter()
        .chain(&originals_b)
        .all(|s| s.segmentation_version == SEGMENTATION_VERSION));
    let (changed, unchanged) = (originals_a[0].id, originals_a[1].id);
    // A replay of each skill of session a: the changed skill's goes with it, the other stays.
    let report = unreachable_report();
    let gone_replay = store
        .insert_replay(changed, "gripper", &report, fake_mcap(100, 4000))
        .await
        .unwrap();
    let kept_replay = store
        .insert_replay(unchanged, "gripper", &report, fake_mcap(101, 4000))
        .await
        .unwrap();
    let gone_replay_path = store.replay_blob_path(gone_replay.id).await.unwrap();
    let blobs_before = blob_count(&data);
    store.close().await;

    // What an older segmentation could have left: every session at version 0, one skill with
    // other parameters, and a session with a skill too many (a grasp split in two).
    mark_all_stale(backend, &data).await;
    let set_old = match backend {
        Backend::Sqlite => "json_set(params, '$.old', 1)",
        Backend::Postgres => "jsonb_set(params::jsonb, '{old}', '1')::text",
    };
    let change =
        format!("UPDATE skills SET quality = quality + 1.0, params = {set_old} WHERE id = ?");
    backend.sql(
        &data,
        &[
            (change.as_str(), Some(changed)),
            (
                "INSERT INTO skills (session_id, object_shape, object_mass, mu, contact_count, \
                 contact_model, grasp_type, quality, volume, duration_s, start_ns, end_ns, \
                 phase_durations, feature, params) SELECT session_id, object_shape, \
                 object_mass, mu, contact_count, contact_model, grasp_type, quality, volume, \
                 duration_s, start_ns, end_ns, phase_durations, feature, params \
                 FROM skills WHERE id = ?",
                Some(originals_b[0].id),
            ),
        ],
    )
    .await;
    let store = backend.open(&data).await;
    assert_eq!(store.skill_count(), 4);
    let duplicate = *store
        .get_session(b.session_id)
        .await
        .unwrap()
        .skill_ids
        .last()
        .unwrap();
    assert!(duplicate > originals_b[0].id);
    assert_eq!(
        store
            .get_skill(unchanged)
            .await
            .unwrap()
            .segmentation_version,
        0,
        "a skill reports its session's version"
    );

    let (r, events) = run(&store).await;
    assert_eq!(
        events,
        [
            format!("started 0/2 {}", a.session_id),
            format!("reprocessed {}", a.session_id),
            format!("started 1/2 {}", b.session_id),
            format!("reprocessed {}", b.session_id),
        ]
    );
    assert_eq!(r.segmentation_version, SEGMENTATION_VERSION);
    assert_eq!(
        (r.sessions_stale, r.sessions_reprocessed, r.sessions_failed),
        (2, 2, 0)
    );
    assert_eq!((r.skills_before, r.skills_after), (4, 3));
    assert_eq!((r.skills_kept, r.skills_removed, r.skills_added), (2, 2, 1));
    assert_eq!(r.replays_removed, 1);
    assert!(!r.interrupted);
    let (ra, rb) = (&r.sessions[0], &r.sessions[1]);
    assert_eq!((ra.from_version, ra.to_version), (0, SEGMENTATION_VERSION));
    assert_eq!(ra.kept_skill_ids, [unchanged]);
    assert_eq!(ra.removed_skill_ids, [changed]);
    assert_eq!(ra.added_skill_ids.len(), 1);
    assert_eq!(ra.replays_removed, 1);
    assert_eq!(rb.kept_skill_ids, [originals_b[0].id]);
    assert_eq!(rb.removed_skill_ids, [duplicate]);
    assert!(rb.added_skill_ids.is_empty());
    let new_id = ra.added_skill_ids[0];
    assert!(new_id > duplicate);

    // The skills are what a fresh ingest stores: the changed one rebuilt as it was first
    // stored, the unchanged ones kept as they were (ids and insertion times too).
    let after_a = skills_of(&store, a.session_id).await;
    let after_b = skills_of(&store, b.session_id).await;
    assert_eq!(
        after_a.iter().map(content).collect::<Vec<_>>(),
        originals_a.iter().map(content).collect::<Vec<_>>()
    );
    assert_eq!(after_a[1], originals_a[1]);
    assert_eq!(after_b, originals_b);
    let fresh = backend.open(&tmp.path().join("fresh")).await;
    let f = ingest_bytes(&fresh, two, "two.mcap".into()).await.unwrap();
    assert_eq!(
        skills_of(&fresh, f.session_id)
            .await
            .iter()
            .map(content)
            .collect::<Vec<_>>(),
        after_a.iter().map(content).collect::<Vec<_>>()
    );
    fresh.close().await;
    for s in [a.session_id, b.session_id] {
        let session = store.get_session(s).await.unwrap();
        assert_eq!(session.segmentation_version, SEGMENTATION_VERSION);
    }
    assert!(after_a
        .iter()
        .all(|s| s.segmentation_version == SEGMENTATION_VERSION));

    // The removed skill's replay and its file are gone; the kept skill's replay stays.
    assert!(matches!(
        store.get_replay(gone_replay.id).await,
        Err(StoreError::ReplayNotFound(_))
    ));
    assert!(!gone_replay_path.exists());
    assert_eq!(store.get_replay(kept_replay.id).await.unwrap(), kept_replay);
    assert_eq!(blob_count(&data), blobs_before - 1);
    // The similarity index follows: the removed skills are gone, the new one is found.
    assert_eq!(store.skill_count(), 3);
    for id in [changed, duplicate] {
        assert!(matches!(
            store.nearest_to_skill(id, 1),
            Err(StoreError::SkillNotFound(_))
        ));
    }
    let near = store.nearest_to_skill(new_id, 10).unwrap();
    assert_eq!(near.len(), 2);
    store.integrity_check().await.unwrap();

    // A second run finds nothing to do and changes nothing.
    let (again, events) = run(&store).await;
    assert!(events.is_empty(), "{events:?}");
    assert_eq!(
        (
            again.sessions_stale,
            again.sessions_reprocessed,
            again.skills_after
        ),
        (0, 0, 0)
    );
    assert_eq!(skills_of(&store, a.session_id).await, after_a);
    assert_eq!(skills_of(&store, b.session_id).await, after_b);
    store.close().await;
    // Nor does one after a restart (the index reloads the same skills).
    let store = backend.open(&data).await;
    assert_eq!(store.skill_count(), 3);
    assert_eq!(run(&store).await.0.sessions_stale, 0);
}

async fn a_session_that_fails_is_reported_keeps_its_skills_and_the_others_go_on(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let store = backend.open(&data).await;
    // Not an MCAP file at all, stored with synthetic skills.
    let junk = store
        .ingest(&fake_mcap(1, 5000), meta(1, 2), skills(1, 2))
        .await
        .unwrap();
    let good = ingest_bytes(
        &store,
        simulate(tmp.path(), "sphere-lift", 3, None),
        "good.mcap".into(),
    )
    .await
    .unwrap();
    let missing = ingest_bytes(
        &store,
        simulate(tmp.path(), "sphere-lift", 5, Some(3.0)),
        "missing.mcap".into(),
    )
    .await
    .unwrap();
    let changed = ingest_bytes(
        &store,
        simulate(tmp.path(), "sphere-lift", 6, Some(3.0)),
        "changed.mcap".into(),
    )
    .await
    .unwrap();
    // One session's file removed from the data directory, another's changed on disk.
    std::fs::remove_file(store.session_blob_path(missing.session_id).await.unwrap()).unwrap();
    let path = store.session_blob_path(changed.session_id).await.unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x20;
    std::fs::write(&path, bytes).unwrap();
    store.close().await;
    mark_all_stale(backend, &data).await;

    let store = backend.open(&data).await;
    let (r, events) = run(&store).await;
    assert_eq!(
        events.iter().filter(|e| e.starts_with("failed")).count(),
        3,
        "{events:?}"
    );
    assert_eq!(
        (r.sessions_stale, r.sessions_reprocessed, r.sessions_failed),
        (4, 1, 3)
    );
    assert_eq!(r.sessions[0].session_id, good.session_id);
    let failed: Vec<i64> = r.failed.iter().map(|f| f.session_id).collect();
    assert_eq!(
        failed,
        [junk.session_id, missing.session_id, changed.session_id]
    );
    let why = |i: usize| r.failed[i].error.to_lowercase();
    assert!(why(0).contains("mcap"), "{}", why(0));
    assert!(why(1).contains("no such file"), "{}", why(1));
    assert!(why(2).contains("sha-256"), "{}", why(2));
    assert!(r.failed.iter().all(|f| f.segmentation_version == 0));
    // The failed sessions keep their skills and their old version; the good one is current.
    for (outcome, version) in [
        (&junk, 0),
        (&missing, 0),
        (&changed, 0),
        (&good, SEGMENTATION_VERSION),
    ] {
        let s = store.get_session(outcome.session_id).await.unwrap();
        assert_eq!(s.skill_ids, outcome.skill_ids);
        assert_eq!(s.segmentation_version, version);
    }
    // The next run tries the failed ones again, and only them.
    let (again, _) = run(&store).await;
    assert_eq!(
        (
            again.sessions_stale,
            again.sessions_reprocessed,
            again.sessions_failed
        ),
        (3, 0, 3)
    );
    store.integrity_check().await.unwrap();
}

async fn a_stopped_run_leaves_whole_sessions_and_the_next_run_finishes(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let store = backend.open(&data).await;
    let mut ids = Vec::new();
    for seed in 0..3 {
        let bytes = simulate(tmp.path(), "sphere-lift", seed, Some(3.0));
        let o = ingest_bytes(&store, bytes, format!("{seed}.mcap"))
            .await
            .unwrap();
        ids.push(o.session_id);
    }
    store.close().await;
    mark_all_stale(backend, &data).await;
    // Skills as an older segmentation left them: all different, so all are replaced.
    backend
        .sql(
            &data,
            &[("UPDATE skills SET quality = quality + 1.0", None)],
        )
        .await;

    let store = backend.open(&data).await;
    let stop = AtomicBool::new(false);
    let r = reprocess(&store, &stop, |e| {
        if let ReprocessEvent::Reprocessed(_) = e {
            stop.store(true, Ordering::Relaxed);
        }
    })
    .await
    .unwrap();
    assert!(r.interrupted);
    assert_eq!((r.sessions_reprocessed, r.sessions_left), (1, 2));
    assert_eq!(versions(&store, &ids).await, [SEGMENTATION_VERSION, 0, 0]);
    let (rest, _) = run(&store).await;
    assert_eq!((rest.sessions_stale, rest.sessions_reprocessed), (2, 2));
    assert_eq!(rest.skills_removed, rest.skills_added);
    assert_eq!(versions(&store, &ids).await, [SEGMENTATION_VERSION; 3]);
    store.integrity_check().await.unwrap();
}

async fn replacing_skills_is_all_or_nothing_and_only_for_older_versions(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let old = skills(7, 3);
    let o = store
        .ingest(&fake_mcap(7, 1000), meta(7, 3), old.clone())
        .await
        .unwrap();
    // Already at the version: nothing changes.
    assert_eq!(
        store
            .replace_session_skills(o.session_id, skills(8, 1), SEGMENTATION_VERSION)
            .await
            .unwrap(),
        None
    );
    assert_eq!(
        store.get_session(o.session_id).await.unwrap().skill_ids,
        o.skill_ids
    );
    // A new skill that cannot be stored: refused, the session stays as it was.
    let mut bad = vec![old[0].clone(), skills(9, 1)[0].clone()];
    bad[1].quality = f64::NAN;
    let e = store
        .replace_session_skills(o.session_id, bad, SEGMENTATION_VERSION + 1)
        .await
        .unwrap_err();
    assert!(matches!(e, StoreError::InvalidInput(_)), "{e}");
    let s = store.get_session(o.session_id).await.unwrap();
    assert_eq!(
        (s.skill_ids, s.segmentation_version),
        (o.skill_ids.clone(), SEGMENTATION_VERSION)
    );
    // Skills 0 and 2 come out the same, 1 does not, and there is a new one.
    let new = vec![old[2].clone(), skills(10, 1)[0].clone(), old[0].clone()];
    let done = store
        .replace_session_skills(o.session_id, new, SEGMENTATION_VERSION + 1)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(done.kept_skill_ids, [o.skill_ids[0], o.skill_ids[2]]);
    assert_eq!(done.removed_skill_ids, [o.skill_ids[1]]);
    assert_eq!(done.added_skill_ids.len(), 1);
    assert_eq!(
        (done.from_version, done.to_version),
        (SEGMENTATION_VERSION, SEGMENTATION_VERSION + 1)
    );
    let added = store.get_skill(done.added_skill_ids[0]).await.unwrap();
    assert_eq!(added.feature, skills(10, 1)[0].feature);
    assert_eq!(added.phase_durations, skills(10, 1)[0].phase_durations);
    assert_eq!(added.segmentation_version, SEGMENTATION_VERSION + 1);
    assert_eq!(store.skill_count(), 3);
    assert!(matches!(
        store
            .replace_session_skills(999, Vec::new(), SEGMENTATION_VERSION)
            .await,
        Err(StoreError::SessionNotFound(999))
    ));
    // The phase rows follow the skills (the phase filter finds exactly the stored ones).
    let phases: i64 = {
        let n = backend
            .count(
                tmp.path(),
                "SELECT count(*) FROM skill_phases p JOIN skills s ON s.id = p.skill_id",
            )
            .await;
        let all = backend
            .count(tmp.path(), "SELECT count(*) FROM skill_phases")
            .await;
        assert_eq!(n, all, "no phase rows of removed skills");
        n
    };
    let expected: usize = [&old[0], &old[2], &skills(10, 1)[0]]
        .iter()
        .map(|s| s.phase_durations.len())
        .sum();
    assert_eq!(phases as usize, expected);
    store.integrity_check().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_data_base_from_before_versions_is_migrated_to_version_0_and_brought_up_to_date() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    std::fs::create_dir_all(&data).unwrap();
    // The schema as the binaries before migration 0003 left it.
    let old_migrations = tmp.path().join("migrations");
    std::fs::create_dir_all(&old_migrations).unwrap();
    let all = Path::new(env!("CARGO_MANIFEST_DIR")).join("../migrations");
    for e in std::fs::read_dir(&all).unwrap() {
        let name = e.unwrap().file_name().into_string().unwrap();
        if name.starts_with("0001_") || name.starts_with("0002_") {
            std::fs::copy(all.join(&name), old_migrations.join(&name)).unwrap();
        }
    }
    let bytes = simulate(tmp.path(), "sphere-lift", 3, None);
    let (session_meta, expected) = analyse(&bytes, "old.mcap").unwrap();
    assert!(!expected.is_empty());
    let sha = {
        use sha2::Digest;
        hex::encode(sha2::Sha256::digest(&bytes))
    };
    let rel = format!("blobs/sha256/{}/{}.mcap", &sha[..2], &sha[2..]);
    std::fs::create_dir_all(data.join(&rel).parent().unwrap()).unwrap();
    std::fs::write(data.join(&rel), &bytes).unwrap();
    {
        let opts = sqlx::sqlite::SqliteConnectOptions::new()
            .filename(data.join(DB_FILE))
            .create_if_missing(true);
        let mut conn = SqliteConnection::connect_with(&opts).await.unwrap();
        sqlx::migrate::Migrator::new(old_migrations.as_path())
            .await
            .unwrap()
            .run(&mut conn)
            .await
            .unwrap();
        // Stored by an old segmentation that found no grasp in it.
        sqlx::query(
            "INSERT INTO sessions (sha256, size_bytes, blob_path, scenario, hand, \
             object_shape, duration_ns, meta) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
        )
        .bind(&sha)
        .bind(bytes.len() as i64)
        .bind(&rel)
        .bind(session_meta.scenario.as_deref())
        .bind(&session_meta.hand)
        .bind(session_meta.object_shape.to_string())
        .bind(session_meta.duration_ns as i64)
        .bind(serde_json::to_string(&session_meta).unwrap())
        .execute(&mut conn)
        .await
        .unwrap();
        conn.close().await.unwrap();
    }

    let store = Store::open(&data).await.unwrap();
    let page = store.list_sessions(10, None).await.unwrap();
    assert_eq!(page.items.len(), 1);
    let session = &page.items[0];
    assert_eq!(session.segmentation_version, 0, "not recorded");
    assert!(session.skill_ids.is_empty());
    assert_eq!(store.skill_count(), 0);

    let (r, _) = run(&store).await;
    assert_eq!((r.sessions_stale, r.sessions_reprocessed), (1, 1));
    assert_eq!((r.skills_before, r.skills_after), (0, expected.len()));
    let got = skills_of(&store, session.id).await;
    assert_eq!(got.len(), expected.len());
    for (g, e) in got.iter().zip(&expected) {
        assert_eq!(g.params, e.params);
        assert_eq!(g.feature, e.feature);
        assert_eq!(g.grasp_type, e.grasp_type);
        assert_eq!(g.segmentation_version, SEGMENTATION_VERSION);
    }
    assert_eq!(store.skill_count(), expected.len());
    assert_eq!(
        store
            .get_session(session.id)
            .await
            .unwrap()
            .segmentation_version,
        SEGMENTATION_VERSION
    );
    // Ingesting the same file again finds the session, now with its skills.
    let o = ingest_bytes(&store, bytes, "again.mcap".into())
        .await
        .unwrap();
    assert!(!o.created);
    assert_eq!(o.skill_ids.len(), expected.len());
    store.integrity_check().await.unwrap();
}

/// A `box-pinch-lift` session ingested into a data directory of its own (under the returned
/// temporary directory): the data directory, the store, its one skill's id and template.
async fn one_stored_box_grasp(
    backend: Backend,
) -> (
    tempfile::TempDir,
    std::path::PathBuf,
    Store,
    i64,
    Vec<Option<f32>>,
) {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let store = backend.open(&data).await;
    let bytes = simulate(tmp.path(), "box-pinch-lift", 2, None);
    let o = ingest_bytes(&store, bytes, "box.mcap".into())
        .await
        .unwrap();
    assert_eq!(o.skill_ids.len(), 1);
    let id = o.skill_ids[0];
    let template = store.get_skill(id).await.unwrap().approach.unwrap();
    assert_eq!(template.len(), services::assist::features::TEMPLATE_DIM);
    (tmp, data, store, id, template)
}

/// A reprocessing of the one stale session of `store` keeps its one skill `id` and gives it
/// the whole template `fresh` (again).
async fn reprocessing_keeps_the_skill_and_gives_it(store: &Store, id: i64, fresh: &[Option<f32>]) {
    let (r, _) = run(store).await;
    assert_eq!((r.sessions_stale, r.sessions_reprocessed), (1, 1));
    assert_eq!((r.skills_kept, r.skills_added), (1, 0));
    let after = store.get_skill(id).await.unwrap();
    assert_eq!(after.approach.as_deref(), Some(fresh), "the whole template");
}

/// Issue 20: skills stored before approach templates existed (version 1, `approach` NULL, as
/// migration 0005 leaves them) get theirs from a reprocessing, keeping their ids; until then
/// they take no part in approach recognition.
async fn skills_stored_before_templates_get_them_from_reprocessing_and_keep_their_ids(
    backend: Backend,
) {
    let (_tmp, data, store, id, fresh) = one_stored_box_grasp(backend).await;
    assert!(fresh.iter().flatten().count() > 10, "{fresh:?}");
    store.close().await;
    backend
        .sql(
            &data,
            &[
                ("UPDATE skills SET approach = NULL", None),
                ("UPDATE sessions SET segmentation_version = 1", None),
            ],
        )
        .await;

    let store = backend.open(&data).await;
    assert!(store.get_skill(id).await.unwrap().approach.is_none());
    let index = store.recognition_index();
    let mut scratch = services::assist::index::Scratch::default();
    let template: [f32; services::assist::features::TEMPLATE_DIM] = fresh
        .iter()
        .map(|v| v.unwrap_or(f32::NAN))
        .collect::<Vec<_>>()
        .try_into()
        .unwrap();
    let min = services::assist::recognise::MIN_COMPARED;
    assert!(
        index
            .rank_templates(&template, 4, min, &mut scratch)
            .is_empty(),
        "a skill without a template is not compared"
    );

    reprocessing_keeps_the_skill_and_gives_it(&store, id, &fresh).await;
    let index = store.recognition_index();
    let ranked = index
        .rank_templates(&template, 4, min, &mut scratch)
        .to_vec();
    assert_eq!(ranked.len(), 1);
    assert_eq!(index.skill_id(ranked[0].row), id);
    store.integrity_check().await.unwrap();
}

/// Templates stored by segmentation version 2 (two values shorter: before the grip and the
/// scene were added) read back with those not seen, still take part in approach
/// recognition, and get the whole template again from a reprocessing, keeping their ids.
async fn templates_stored_without_the_grip_read_back_and_get_it_from_reprocessing(
    backend: Backend,
) {
    use services::assist::features::{GRIP_DIM, SCENE_DIM, TEMPLATE_DIM, TEMPLATE_DIM_V2};
    let (_tmp, data, store, id, fresh) = one_stored_box_grasp(backend).await;
    assert!(fresh[GRIP_DIM].is_some_and(|g| g > 1.0), "{fresh:?}");
    assert_eq!(fresh[SCENE_DIM], Some(1.0));
    store.close().await;
    let cut = format!(
        "UPDATE skills SET approach = substr(approach, 1, {})",
        TEMPLATE_DIM_V2 * 4
    );
    backend
        .sql(
            &data,
            &[
                (cut.as_str(), None),
                ("UPDATE sessions SET segmentation_version = 2", None),
            ],
        )
        .await;

    let store = backend.open(&data).await;
    let old = store.get_skill(id).await.unwrap().approach.unwrap();
    assert_eq!(old.len(), TEMPLATE_DIM);
    assert_eq!(old[..GRIP_DIM], fresh[..GRIP_DIM]);
    assert_eq!((old[GRIP_DIM], old[SCENE_DIM]), (None, None));
    let template: [f32; TEMPLATE_DIM] = std::array::from_fn(|j| fresh[j].unwrap_or(f32::NAN));
    let mut scratch = services::assist::index::Scratch::default();
    let min = services::assist::recognise::MIN_COMPARED;
    let index = store.recognition_index();
    let ranked = index
        .rank_templates(&template, 4, min, &mut scratch)
        .to_vec();
    assert_eq!(ranked.len(), 1, "compared without the grip and the scene");
    assert_eq!(index.skill_id(ranked[0].row), id);
    assert_eq!(
        ranked[0].distance, 0.0,
        "the values it has are the template's"
    );

    reprocessing_keeps_the_skill_and_gives_it(&store, id, &fresh).await;
    store.integrity_check().await.unwrap();
}

backend_tests!(
    reprocessing_keeps_unchanged_skills_replaces_changed_ones_and_runs_once,
    templates_stored_without_the_grip_read_back_and_get_it_from_reprocessing,
    a_session_that_fails_is_reported_keeps_its_skills_and_the_others_go_on,
    a_stopped_run_leaves_whole_sessions_and_the_next_run_finishes,
    replacing_skills_is_all_or_nothing_and_only_for_older_versions,
    skills_stored_before_templates_get_them_from_reprocessing_and_keep_their_ids,
);
