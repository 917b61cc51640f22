//! Scenes of several objects (issue 19, "Scenes with several objects"): a session records
//! every object (the `session` record lists them and the target, `/object/state` holds each
//! one's state, `/dfs/contacts` which object each fingertip touches, `/scene` and `/tf` show
//! each), overlaps of objects are reported on the session, the skill names the object it
//! grasped, and a scene of overlapping objects is refused naming both.

use std::path::Path;

use dfs_core::scenario::{Phase, Scenario, Task};
use foxglove::messages as fg;
use prost::Message;
use services::mcap_io::read_session_file;
use services::segmentation::{segment, SegmentParams};
use services::session::*;
use services::RecordingError;

fn names(json: &str) -> Vec<String> {
    let list: Vec<serde_json::Value> = serde_json::from_str(json).unwrap();
    list.iter()
        .map(|o| o["name"].as_str().unwrap().to_owned())
        .collect()
}

/// The ids of the entities of the last `/scene` update and the child frames of the last
/// `/tf` message.
fn scene_ids_and_frames(path: &Path) -> (Vec<String>, Vec<String>) {
    let recorded = read_session_file(path, &Default::default()).unwrap();
    let last = |topic: &str| recorded.topics[topic].messages.last().unwrap().data.clone();
    let scene = fg::SceneUpdate::decode(&last(TOPIC_SCENE)[..]).unwrap();
    let tf = fg::FrameTransforms::decode(&last(TOPIC_TF)[..]).unwrap();
    (
        scene.entities.iter().map(|e| e.id.clone()).collect(),
        tf.transforms
            .iter()
            .map(|t| t.child_frame_id.clone())
            .collect(),
    )
}

#[test]
fn a_session_of_three_objects_records_each_and_its_skill_names_the_box() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("three.mcap");
    let scenario = Scenario::builtin("table-three", 2).unwrap();
    record_simulation(&scenario, None, &path, |_, _| {}).unwrap();
    let session = read_session(&path).unwrap();

    // The session record lists the objects and the target; `object` is the target.
    let meta = &session.metadata;
    assert_eq!(names(&meta["objects"]), ["ball", "box", "cylinder"]);
    assert_eq!(meta["target"], "box");
    let object: serde_json::Value = serde_json::from_str(&meta["object"]).unwrap();
    assert_eq!(
        (&object["name"], &object["shape"]),
        (&"box".into(), &"box".into())
    );
    // No overlap, and the session says so.
    assert_eq!(meta["overlap_ticks"], "0");
    assert!(!meta.contains_key("first_overlap_ns"));

    // Every object's state, the box's in the main fields; the fingertips touch the box.
    let first = &session.object[0].1;
    let mut on_box = 0;
    for ((_, o), (_, c)) in session.object.iter().zip(&session.contacts) {
        assert_eq!((o.index, o.objects.len()), (1, 3));
        assert_eq!(o.objects[1].pose, o.pose);
        for i in [0, 2] {
            assert_eq!(
                o.objects[i].pose, first.objects[i].pose,
                "object {i} stays put"
            );
        }
        for f in c.fingers.iter().filter(|f| f.touching) {
            assert_eq!(f.object, 1);
            on_box += 1;
        }
    }
    assert!(on_box > 1000, "{on_box}");
    let lifted = session
        .object
        .iter()
        .map(|(_, o)| o.pose.position.z - first.pose.position.z)
        .fold(0.0, f64::max);
    assert!(lifted > 0.08, "the box rose {lifted} m");

    // The skill grasped the box, and says so.
    let seg = segment(&session, &SegmentParams::default());
    assert_eq!(seg.skills.len(), 1, "{:?}", seg.skills);
    let grasped = seg.skills[0].parameters.object.as_ref().unwrap();
    assert_eq!(grasped.name.as_deref(), Some("box"));
    assert_eq!(grasped.shape.to_string(), "box");
    assert_eq!(grasped.mass, 0.2);
    let phases: Vec<Phase> = seg.skills[0].phases.iter().map(|p| p.phase).collect();
    assert!(
        phases.contains(&Phase::Lift) && phases.contains(&Phase::Place),
        "{phases:?}"
    );
    // As the store analyses the file.
    let bytes = std::fs::read(&path).unwrap();
    let (stored, skills) = services::ingest::analyse(&bytes, "three.mcap").unwrap();
    assert_eq!(stored.object_shape.to_string(), "box");
    assert_eq!(skills.len(), 1);
    assert_eq!(skills[0].params["object"]["name"], "box");
    assert_eq!(skills[0].object_shape.to_string(), "box");
    assert_eq!(skills[0].object_name.as_deref(), Some("box"));
    // Stored, the skill keeps the name (its own column) and the session its metadata.
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let store = services::store::Store::open(dir.path()).await.unwrap();
        let outcome = store.ingest(&bytes, stored, skills).await.unwrap();
        let skill = store.get_skill(outcome.skill_ids[0]).await.unwrap();
        assert_eq!(skill.object_name.as_deref(), Some("box"));
        let session = store.get_session(outcome.session_id).await.unwrap();
        assert_eq!(session.meta.extra["target"], "box");
        assert_eq!(session.meta.extra["overlap_ticks"], "0");
    });

    // Foxglove shows each object: the target as `object`, the others by name.
    let (ids, frames) = scene_ids_and_frames(&path);
    assert_eq!(
        ids,
        ["object", TABLE_ENTITY, "object/ball", "object/cylinder"]
    );
    for frame in ["object", "object/ball", "object/cylinder"] {
        assert!(frames.iter().any(|f| f == frame), "{frame} in {frames:?}");
    }
}

#[test]
fn a_session_of_one_object_lists_none_and_its_skill_names_none() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("one.mcap");
    let scenario = Scenario::builtin("box-pinch-lift", 2).unwrap();
    record_simulation(&scenario, Some(4.0), &path, |_, _| {}).unwrap();
    let session = read_session(&path).unwrap();
    for key in ["objects", "target", "overlap_ticks"] {
        assert!(!session.metadata.contains_key(key), "{key}");
    }
    assert!(session
        .object
        .iter()
        .all(|(_, o)| o.index == 0 && o.objects.is_empty()));
    let seg = segment(&session, &SegmentParams::default());
    assert_eq!(seg.skills.len(), 1);
    let object = seg.skills[0].parameters.object.as_ref().unwrap();
    assert_eq!(object.name, None);
    let json = serde_json::to_value(&seg.skills[0]).unwrap();
    assert!(json["object"].get("name").is_none());
    let (ids, _) = scene_ids_and_frames(&path);
    assert_eq!(ids, ["object", TABLE_ENTITY]);
}

#[test]
fn a_box_carried_through_the_cylinder_is_reported_on_the_session() {
    // Lifted 10 cm and carried 20 cm towards the cylinder (18 cm tall): through it.
    let mut scenario = Scenario::builtin("table-three", 1).unwrap();
    let lift = scenario
        .tasks
        .iter()
        .position(|t| t.phase == Phase::Lift)
        .unwrap();
    scenario.tasks.truncate(lift + 1);
    scenario.tasks.push(Task {
        phase: Phase::Transport,
        duration: 1.5,
        height: None,
        offset: Some([0.0, 0.2, 0.0]),
        turn: None,
    });
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("through.mcap");
    record_simulation(&scenario, None, &path, |_, _| {}).unwrap();
    let session = read_session(&path).unwrap();
    let meta = &session.metadata;
    let ticks: u64 = meta["overlap_ticks"].parse().unwrap();
    assert!(ticks > 100, "{ticks}");
    assert_eq!(meta["first_overlap"], "box,cylinder");
    let first: u64 = meta["first_overlap_ns"].parse().unwrap();
    let transport = session
        .phases
        .iter()
        .find(|p| p.name == "transport")
        .unwrap();
    assert!(
        (transport.start_ns..transport.end_ns).contains(&first),
        "{first} in {transport:?}"
    );
}

#[test]
fn a_scene_of_overlapping_objects_is_refused_before_any_file_naming_both() {
    let mut scenario = Scenario::builtin("table-three", 0).unwrap();
    scenario.objects.as_mut().unwrap()[2].position = Some([0.05, 0.02, 0.09]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("refused.mcap");
    let e = record_simulation(&scenario, None, &path, |_, _| {}).unwrap_err();
    let RecordingError::InvalidInput { detail, .. } = &e else {
        panic!("{e}");
    };
    assert!(
        detail.contains("objects[2].position")
            && detail.contains("\"cylinder\" and \"box\"")
            && detail.contains("overlap"),
        "{detail}"
    );
    assert!(!path.exists());
}
