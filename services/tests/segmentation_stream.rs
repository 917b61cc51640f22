//! Segmentation streamed from a file in two passes ([`segment_source`]) finds what
//! segmentation of the whole session in memory finds, whatever order the file's topics come in,
//! and from a file or from bytes alike.

use dfs_core::scenario::Scenario;
use services::mcap_io::{ReadLimits, SessionWriter};
use services::segmentation::{segment, segment_source, SegmentParams};
use services::session::{
    read_session, record_simulation, SessionSource, GROUND_TRUTH_METADATA, ICMS_SCHEMAS,
    RAW_TOPICS, SESSION_METADATA, TOPIC_CONTACTS, TOPIC_GLOVE_FEEDBACK, TOPIC_GLOVE_JOINT_STATES,
    TOPIC_OBJECT_STATE,
};

#[test]
fn sessions_stream_into_the_skills_found_in_memory() {
    let dir = tempfile::tempdir().unwrap();
    // A pinch, a power grasp that carries sideways, and two grasps in one session (the
    // segmentation tests cover every scenario in memory).
    for name in ["box-pinch-lift", "cylinder-power-grasp", "two-grasps"] {
        let path = dir.path().join(format!("{name}.mcap"));
        let scenario = Scenario::builtin(name, 4).unwrap();
        record_simulation(&scenario, None, &path, |_, _| {}).unwrap();
        let in_memory = segment(&read_session(&path).unwrap(), &SegmentParams::default());
        let limits = ReadLimits::streaming();
        let (head, from_file) = segment_source(
            &SessionSource::File(&path),
            &limits,
            &SegmentParams::default(),
        )
        .unwrap();
        assert_eq!(from_file, in_memory, "{name}");
        assert!(!from_file.skills.is_empty(), "{name}: no skill");
        let bytes = std::fs::read(&path).unwrap();
        let source = SessionSource::Bytes {
            bytes: &bytes,
            name: "upload",
        };
        let (head_b, from_bytes) =
            segment_source(&source, &limits, &SegmentParams::default()).unwrap();
        assert_eq!(from_bytes, in_memory, "{name}");
        assert_eq!(head_b, head, "{name}");
        assert_eq!(
            head.metadata.get("scenario").map(String::as_str),
            Some(name)
        );
    }
}

#[test]
fn a_file_that_writes_each_topic_in_one_block_segments_as_one_written_tick_by_tick() {
    // Another recorder may write all of one topic before the next (valid MCAP: each topic in
    // time order). The second pass then sees every object state before any contact: the grasp
    // must still be found carried.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ticks.mcap");
    let scenario = Scenario::builtin("two-grasps", 1).unwrap();
    record_simulation(&scenario, None, &path, |_, _| {}).unwrap();
    let session = read_session(&path).unwrap();
    let expected = segment(&session, &SegmentParams::default());
    assert_eq!(expected.skills.len(), 2);

    for order in [
        [
            TOPIC_OBJECT_STATE,
            TOPIC_CONTACTS,
            TOPIC_GLOVE_JOINT_STATES,
            TOPIC_GLOVE_FEEDBACK,
        ],
        [
            TOPIC_CONTACTS,
            TOPIC_GLOVE_FEEDBACK,
            TOPIC_GLOVE_JOINT_STATES,
            TOPIC_OBJECT_STATE,
        ],
    ] {
        let blocks = dir.path().join("blocks.mcap");
        let mut w = SessionWriter::create(&blocks).unwrap();
        for (topic, schema) in RAW_TOPICS.iter().zip(ICMS_SCHEMAS.iter()) {
            w.register_channel(topic, schema).unwrap();
        }
        w.add_metadata(SESSION_METADATA, session.metadata.clone())
            .unwrap();
        w.add_metadata(
            GROUND_TRUTH_METADATA,
            [(
                "phases".to_owned(),
                serde_json::to_string(&session.phases).unwrap(),
            )]
            .into(),
        )
        .unwrap();
        for topic in order {
            match topic {
                TOPIC_OBJECT_STATE => {
                    for (t, m) in &session.object {
                        w.write(topic, *t, m).unwrap();
                    }
                }
                TOPIC_CONTACTS => {
                    for (t, m) in &session.contacts {
                        w.write(topic, *t, m).unwrap();
                    }
                }
                TOPIC_GLOVE_JOINT_STATES => {
                    for (t, m) in &session.joint_states {
                        w.write(topic, *t, m).unwrap();
                    }
                }
                _ => {
                    for (t, m) in &session.feedback {
                        w.write(topic, *t, m).unwrap();
                    }
                }
            }
        }
        w.finish().unwrap();
        let (_, found) = segment_source(
            &SessionSource::File(&blocks),
            &ReadLimits::streaming(),
            &SegmentParams::default(),
        )
        .unwrap();
        assert_eq!(found, expected, "topics in blocks: {order:?}");
    }
}
