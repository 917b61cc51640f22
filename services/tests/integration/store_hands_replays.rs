//! Store tests of migration 0002: uploaded hands beside the built-in ones, replays with their
//! blobs, and deletes of skills and sessions taking their replays and unshared blobs along.

use crate::store_common;

use store_common::Backend;

use dfs_core::hand::builtin::GRIPPER_URDF;
use dfs_core::hand::{builtin_spec, HandSpec};
use services::store::StoreError;
use store_common::{blob_count, fake_mcap, meta, skills, unreachable_report};

fn gripper_spec(name: &str) -> HandSpec {
    let mut spec = builtin_spec("gripper").unwrap().0;
    spec.name = name.into();
    spec
}

async fn the_migration_lists_built_in_hands_and_stores_an_uploaded_one_beside_them(
    backend: Backend,
) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let hands = store.list_hands().await.unwrap();
    let names: Vec<&str> = hands.iter().map(|h| h.name.as_str()).collect();
    assert_eq!(
        names,
        ["glove10", "allegro", "barrett", "inspire", "gripper"]
    );
    assert!(hands.iter().all(|h| h.builtin && h.created_at.is_none()));
    let gripper = &hands[4];
    assert_eq!(gripper.fingers, ["thumb", "finger"]);
    assert_eq!(gripper.dof, 2);

    let stored = store
        .put_hand(gripper_spec("my-gripper"), GRIPPER_URDF.into())
        .await
        .unwrap();
    assert!(!stored.summary.builtin);
    assert_eq!(stored.summary.dof, 2);
    assert_eq!(stored.summary.torque_limit, [2.0, 40.0]);
    let hands = store.list_hands().await.unwrap();
    assert_eq!(hands.len(), 6);
    assert_eq!(hands[5].name, "my-gripper");
    assert_eq!(hands[5].fingers, gripper.fingers);

    let got = store.get_hand("my-gripper").await.unwrap();
    assert_eq!(got.urdf.as_deref(), Some(GRIPPER_URDF));
    assert_eq!(got.spec.as_ref().unwrap().name, "my-gripper");
    assert_eq!(got.load().unwrap().model.dof(), 2);
    let builtin = store.get_hand("allegro").await.unwrap();
    assert!(builtin.summary.builtin);
    assert!(builtin.urdf.unwrap().contains("<robot"));
    assert!(store.get_hand("glove10").await.unwrap().spec.is_none());
    assert!(matches!(
        store.get_hand("nobody").await,
        Err(StoreError::HandNotFound(_))
    ));

    // Survives a restart.
    store.close().await;
    let store = backend.open(tmp.path()).await;
    assert_eq!(store.list_hands().await.unwrap().len(), 6);
    store.integrity_check().await.unwrap();
}

async fn hands_with_a_taken_name_or_a_bad_urdf_are_refused_and_nothing_is_stored(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    store
        .put_hand(gripper_spec("mine"), GRIPPER_URDF.into())
        .await
        .unwrap();
    for name in ["mine", "allegro"] {
        let e = store
            .put_hand(gripper_spec(name), GRIPPER_URDF.into())
            .await
            .unwrap_err();
        assert!(matches!(e, StoreError::Conflict(_)), "{name}: {e}");
        assert!(e.to_string().contains(name), "{e}");
    }
    let bad = [
        ("a", "<robot name='x'><link name='a'>".to_owned(), "parse"),
        (
            "b",
            GRIPPER_URDF.replace("<mass value=\"0.6\"/>", "<mass value=\"-0.6\"/>"),
            "mass",
        ),
        ("../etc", GRIPPER_URDF.to_owned(), "name"),
    ];
    for (name, urdf, word) in bad {
        let e = store.put_hand(gripper_spec(name), urdf).await.unwrap_err();
        assert!(matches!(e, StoreError::InvalidHand(_)), "{name}: {e}");
        assert!(e.to_string().contains(word), "{name}: {e}");
    }
    assert_eq!(store.list_hands().await.unwrap().len(), 6);
}

async fn replays_are_stored_with_their_blob_and_go_with_their_skill_or_session(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let out = store
        .ingest(&fake_mcap(1, 1000), meta(1, 2), skills(1, 2))
        .await
        .unwrap();
    let (s1, s2) = (out.skill_ids[0], out.skill_ids[1]);
    let report = unreachable_report();
    assert!(!report.success);

    let bytes = fake_mcap(100, 5000);
    let a = store
        .insert_replay(s1, "gripper", &report, bytes.clone())
        .await
        .unwrap();
    assert!(!a.success);
    assert_eq!(
        a.failure_reason,
        Some(dfs_core::replay::FailureReason::Unreachable)
    );
    assert_eq!(a.report["hand"], "gripper");
    assert_eq!(a.size_bytes, 5000);
    assert_eq!(store.get_replay(a.id).await.unwrap(), a);
    let path = store.replay_blob_path(a.id).await.unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    // The same bytes for another skill share the blob.
    let b = store
        .insert_replay(s2, "gripper", &report, bytes.clone())
        .await
        .unwrap();
    assert_eq!(store.replay_blob_path(b.id).await.unwrap(), path);
    assert_eq!(store.list_replays(s1).await.unwrap(), vec![a.clone()]);
    assert!(matches!(
        store.list_replays(999).await,
        Err(StoreError::SkillNotFound(999))
    ));
    assert!(matches!(
        store.insert_replay(999, "gripper", &report, bytes).await,
        Err(StoreError::SkillNotFound(999))
    ));
    // A replay stored before the report took the applied (clamped) torque held the peak of the
    // torque asked for, above 1: it reads back as the applied torque's peak, 1.
    let mut old = report.clone();
    old.peak_torque_ratio = 1.21;
    let c = store
        .insert_replay(s2, "gripper", &old, fake_mcap(102, 5000))
        .await
        .unwrap();
    assert_eq!(c.report["peak_torque_ratio"], 1.0);
    assert_eq!(
        store.get_replay(c.id).await.unwrap().report["peak_torque_ratio"],
        1.0
    );
    // A replay whose skill is gone (deleted while it ran) leaves no blob of its own behind.
    let before = blob_count(tmp.path());
    assert!(matches!(
        store
            .insert_replay(999, "gripper", &report, fake_mcap(101, 5000))
            .await,
        Err(StoreError::SkillNotFound(999))
    ));
    assert_eq!(blob_count(tmp.path()), before);

    // Deleting skill 1 takes replay a; the blob stays while replay b names it.
    store.delete_skill(s1).await.unwrap();
    assert!(matches!(
        store.get_replay(a.id).await,
        Err(StoreError::ReplayNotFound(_))
    ));
    assert!(path.exists());
    // Deleting the session takes skill 2, replay b and now the blob.
    store.delete_session(out.session_id).await.unwrap();
    assert!(matches!(
        store.get_replay(b.id).await,
        Err(StoreError::ReplayNotFound(_))
    ));
    assert!(!path.exists());
    store.integrity_check().await.unwrap();
}

backend_tests!(
    the_migration_lists_built_in_hands_and_stores_an_uploaded_one_beside_them,
    hands_with_a_taken_name_or_a_bad_urdf_are_refused_and_nothing_is_stored,
    replays_are_stored_with_their_blob_and_go_with_their_skill_or_session,
);
