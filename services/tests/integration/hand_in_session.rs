//! The hand in a session file: its URDF as the `hand.urdf` attachment, naming every `/tf` frame
//! of the hand and giving every link geometry, and its link shapes on `/hand` (frame-locked
//! `foxglove.SceneUpdate` entities in the links' frames, once a second), read back by our
//! reader and by the reference Python reader; a `/hand` message that is not a SceneUpdate is
//! refused.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use dfs_core::hand::{builtin_hand, builtin_spec, link_shapes, HandModel, HandSpec};
use dfs_core::object::{RigidObject, Shape};
use foxglove::messages as fg;
use foxglove::Encode;
use prost::Message;
use services::mcap_io::read_session_file;
use services::session::*;
use services::RecordingError;

const SECONDS: f64 = 1.5;

/// One `sphere-lift` session (glove10, seed 3, 1.5 s), recorded once for all tests.
fn session() -> &'static (tempfile::TempDir, PathBuf, RecordSummary) {
    static SESSION: OnceLock<(tempfile::TempDir, PathBuf, RecordSummary)> = OnceLock::new();
    SESSION.get_or_init(|| crate::common::sphere_lift_session(3, Some(SECONDS)))
}

/// The attachments of an MCAP file: name → (media type, data).
fn attachments(path: &Path) -> BTreeMap<String, (String, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    summary
        .attachment_indexes
        .iter()
        .map(|i| {
            let a = mcap::read::attachment(&bytes, i).unwrap();
            (a.name, (a.media_type, a.data.into_owned()))
        })
        .collect()
}

/// The hand's URDF in a session file.
fn hand_urdf_in(path: &Path) -> String {
    let all = attachments(path);
    assert_eq!(all.len(), 1, "{:?}", all.keys());
    let (media_type, data) = &all[HAND_URDF_ATTACHMENT];
    assert_eq!(media_type, HAND_URDF_MEDIA_TYPE);
    String::from_utf8(data.clone()).unwrap()
}

/// A spec with the model's fingertips (what the URDF does not say).
fn spec_of(hand: &HandModel) -> HandSpec {
    HandSpec {
        name: hand.name.clone(),
        urdf: "hand.urdf".into(),
        fingertips: hand
            .fingertips
            .iter()
            .map(|t| dfs_core::hand::FingertipSpec {
                name: Some(t.name.clone()),
                link: hand.links[t.link].name.clone(),
                offset: [t.offset.x, t.offset.y, t.offset.z],
                radius: t.radius,
            })
            .collect(),
        torque_limit: 1.0,
        joint_torque_limits: BTreeMap::new(),
        base_link: None,
        thumb: None,
        armature: None,
    }
}

#[test]
fn a_session_carries_the_hands_urdf_naming_every_tf_frame_with_geometry_on_every_link() {
    let (_, path, _) = session();
    let urdf = hand_urdf_in(path);
    let robot = urdf_rs::read_from_string(&urdf).unwrap();
    let glove = HandModel::glove10();
    assert_eq!(robot.name, "glove10");
    // The frames of the hand in /tf (all but the world and the object) are the URDF's links,
    // and each parent → child transform is one of its joints.
    let recorded = read_session_file(path, &Default::default()).unwrap();
    let tf = fg::FrameTransforms::decode(&recorded.topics[TOPIC_TF].messages[0].data[..]).unwrap();
    let mut frames = BTreeSet::new();
    let mut pairs = BTreeSet::new();
    for t in &tf.transforms {
        for f in [&t.parent_frame_id, &t.child_frame_id] {
            if f != WORLD_FRAME && f != OBJECT_FRAME {
                frames.insert(f.clone());
            }
        }
        if t.parent_frame_id != WORLD_FRAME {
            pairs.insert((t.parent_frame_id.clone(), t.child_frame_id.clone()));
        }
    }
    let links: BTreeSet<String> = robot.links.iter().map(|l| l.name.clone()).collect();
    assert_eq!(frames, links);
    let joints: BTreeSet<(String, String)> = robot
        .joints
        .iter()
        .map(|j| (j.parent.link.clone(), j.child.link.clone()))
        .collect();
    assert_eq!(pairs, joints);
    assert_eq!(robot.joints.len(), glove.joints.len());
    // glove10: every link has a shape, none a mesh.
    for link in &robot.links {
        assert!(!link.visual.is_empty(), "link {} has no visual", link.name);
        assert!(
            !link.collision.is_empty(),
            "link {} has no collision",
            link.name
        );
        assert!(link
            .visual
            .iter()
            .all(|v| !matches!(v.geometry, urdf_rs::Geometry::Mesh { .. })));
    }
    // The project's own loader reads it back as glove10's kinematic tree.
    let back = HandModel::from_urdf(&urdf, &spec_of(&glove)).unwrap();
    let names = |h: &HandModel| h.dof_names.iter().cloned().collect::<BTreeSet<_>>();
    assert_eq!(names(&back), names(&glove));
}

#[test]
fn the_hand_is_drawn_on_hand_once_a_second_as_frame_locked_entities_in_its_link_frames() {
    let (_, path, summary) = session();
    let ticks = (SECONDS * 1000.0) as u64;
    let expected = ticks.div_ceil(HAND_SCENE_PERIOD_TICKS) as usize;
    assert_eq!(
        summary.write.messages_per_topic[TOPIC_HAND],
        expected as u64
    );
    let recorded = read_session_file(path, &Default::default()).unwrap();
    let topic = &recorded.topics[TOPIC_HAND];
    assert_eq!(topic.message_encoding, "protobuf");
    let schema = topic.schema.as_ref().unwrap();
    let sdk = fg::SceneUpdate::get_schema().unwrap();
    assert_eq!((&schema.name, &schema.data[..]), (&sdk.name, &sdk.data[..]));
    assert_eq!(topic.messages.len(), expected);
    let glove = HandModel::glove10();
    let links: Vec<&str> = glove.links.iter().map(|l| l.name.as_str()).collect();
    let tf_times: Vec<u64> = recorded.topics[TOPIC_TF]
        .messages
        .iter()
        .map(|m| m.log_time_ns)
        .collect();
    for m in &topic.messages {
        // Sent with a /tf, so that the links it is drawn in are there.
        assert!(tf_times.contains(&m.log_time_ns));
        let update = fg::SceneUpdate::decode(&m.data[..]).unwrap();
        let ids: Vec<&str> = update.entities.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids, links);
        let spheres: usize = update.entities.iter().map(|e| e.spheres.len()).sum();
        assert!(spheres >= glove.fingertips.len());
        for e in &update.entities {
            assert_eq!(e.frame_id, e.id);
            assert!(e.frame_locked);
            assert!(e.lifetime.is_none());
            let stamp = e.timestamp.unwrap();
            let ns = u64::from(stamp.sec()) * 1_000_000_000 + u64::from(stamp.nsec());
            assert_eq!(ns, m.log_time_ns);
            assert!(
                e.cubes.len() + e.cylinders.len() + e.spheres.len() > 0,
                "{}",
                e.id
            );
        }
    }
    // The session reader takes it, counting it.
    let session = read_session(path).unwrap();
    assert_eq!(session.message_counts[TOPIC_HAND], expected);
    // The layout shows it.
    let layout: serde_json::Value = serde_json::from_str(include_str!(
        "../../../docs/foxglove/icms-session.layout.json"
    ))
    .unwrap();
    assert_eq!(
        layout["configById"]["3D!icms"]["topics"][TOPIC_HAND]["visible"],
        true
    );
}

#[test]
fn the_python_reader_decodes_hand_and_sees_the_urdf_attachment() {
    let (_, path, summary) = session();
    let Some(report) =
        crate::common::python_mcap_report(path, &["mcap", "zstandard", "lz4", "mcap_protobuf"])
    else {
        return;
    };
    let n = summary.write.messages_per_topic[TOPIC_HAND];
    assert_eq!(report["decoded"][TOPIC_HAND], serde_json::json!(n));
    assert_eq!(report["schemas"][TOPIC_HAND], "foxglove.SceneUpdate");
    assert_eq!(
        report["first"][TOPIC_HAND]["entities"][0]["frame_locked"],
        true
    );
    let a = &report["attachments"][HAND_URDF_ATTACHMENT];
    assert_eq!(a["media_type"], HAND_URDF_MEDIA_TYPE);
    assert_eq!(a["text"].as_str().unwrap(), hand_urdf_in(path));
}

/// A recorder for `hand` finished without ticks: the file holds the attachment.
fn urdf_written_for(hand: &HandModel, source: Option<&str>) -> urdf_rs::Robot {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hand.mcap");
    let object = RigidObject::new(Shape::Sphere { radius: 0.03 }, 0.1).unwrap();
    let info = SessionInfo {
        hand_urdf: source.map(str::to_owned),
        ..SessionInfo::default()
    };
    let rec = SessionRecorder::create(&path, hand, &object, &info).unwrap();
    rec.finish().unwrap();
    urdf_rs::read_from_string(&hand_urdf_in(&path)).unwrap()
}

fn boxes(robot: &urdf_rs::Robot) -> usize {
    robot
        .links
        .iter()
        .flat_map(|l| &l.visual)
        .filter(|v| matches!(v.geometry, urdf_rs::Geometry::Box { .. }))
        .count()
}

#[test]
fn a_robot_hand_keeps_its_own_urdf_boxes_and_a_look_alike_does_not() {
    let (_, allegro_urdf) = builtin_spec("allegro").unwrap();
    let allegro = builtin_hand("allegro").unwrap();
    let own = link_shapes(&allegro, Some(allegro_urdf))
        .iter()
        .filter(|s| matches!(s.primitive, dfs_core::hand::Primitive::Box { .. }))
        .count();
    assert!(own >= 16);
    // A built-in hand is recognised without its URDF being passed, and with it.
    assert_eq!(boxes(&urdf_written_for(&allegro, None)), own);
    assert_eq!(boxes(&urdf_written_for(&allegro, Some(allegro_urdf))), own);
    // A hand that only shares the name gets generated shapes (here one palm box at most).
    let mut other = allegro.clone();
    other.joints[0].origin.translation.vector.x += 0.01;
    assert!(boxes(&urdf_written_for(&other, None)) < own);
    // The gripper's URDF has no geometry: every link gets generated shapes all the same.
    let gripper = builtin_hand("gripper").unwrap();
    let robot = urdf_written_for(&gripper, None);
    assert!(robot.links.iter().all(|l| !l.visual.is_empty()));
}

/// A copy of the MCAP file at `path` in which every `/hand` message is `data` and `/hand`'s
/// schema is named `schema_name`.
fn with_hand_replaced(path: &Path, data: &[u8], schema_name: &str) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    let mut out = Vec::new();
    {
        let mut w = mcap::WriteOptions::new()
            .create(std::io::Cursor::new(&mut out))
            .unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        for index in &summary.metadata_indexes {
            w.write_metadata(&mcap::read::metadata(&bytes, index).unwrap())
                .unwrap();
        }
        let mut channels = BTreeMap::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            let topic = m.channel.topic.clone();
            let id = *channels.entry(topic.clone()).or_insert_with(|| {
                let s = m.channel.schema.as_ref().unwrap();
                let name = if topic == TOPIC_HAND {
                    schema_name
                } else {
                    &s.name
                };
                let schema = w.add_schema(name, &s.encoding, &s.data).unwrap();
                w.add_channel(
                    schema,
                    &topic,
                    &m.channel.message_encoding,
                    &BTreeMap::new(),
                )
                .unwrap()
            });
            let header = mcap::records::MessageHeader {
                channel_id: id,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.publish_time,
            };
            let payload: &[u8] = if topic == TOPIC_HAND { data } else { &m.data };
            w.write_to_known_channel(&header, payload).unwrap();
        }
        w.finish().unwrap();
    }
    out
}

#[test]
fn a_hand_message_that_is_not_a_scene_update_is_refused_naming_the_topic() {
    let (_, path, _) = session();
    let limits = Default::default();
    // A copy as it was reads.
    let bytes = std::fs::read(path).unwrap();
    let first = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .find(|m| m.channel.topic == TOPIC_HAND)
        .unwrap();
    let same = with_hand_replaced(path, &first.data, "foxglove.SceneUpdate");
    read_session_bytes(&same, "same.mcap", &limits).unwrap();
    // Bytes that are no protobuf message (field 0).
    let bad = with_hand_replaced(path, &[0x00, 0x01], "foxglove.SceneUpdate");
    let e = read_session_bytes(&bad, "bad.mcap", &limits).unwrap_err();
    assert!(
        matches!(e, RecordingError::InvalidInput { .. }) && e.to_string().contains(TOPIC_HAND),
        "{e}"
    );
    // Another schema on /hand.
    let other = with_hand_replaced(path, &first.data, "foxglove.FrameTransforms");
    let e = read_session_bytes(&other, "other.mcap", &limits).unwrap_err();
    assert!(e.to_string().contains(TOPIC_HAND), "{e}");
}

#[test]
fn salvaging_a_session_keeps_the_hands_urdf() {
    let (_, path, _) = session();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("salvaged.mcap");
    services::mcap_io::salvage(path, &out).unwrap();
    assert_eq!(hand_urdf_in(&out), hand_urdf_in(path));
}
