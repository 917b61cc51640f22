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

/// What a second read hands its visitor: every contact and object sample (log time, fingers
/// touching, object position), until it has taken `limit` of them.
#[derive(Default)]
struct Samples {
    limit: usize,
    seen: Vec<(u64, usize, [u64; 3])>,
}

impl services::session::SessionVisitor for Samples {
    fn wants(&self) -> services::session::DecodeTopics {
        services::session::DecodeTopics::SEGMENTATION
    }
    fn contacts(
        &mut self,
        t: u64,
        m: &services::session::Contacts,
    ) -> Result<(), services::RecordingError> {
        let touching = m.fingers.iter().filter(|f| f.touching).count();
        self.seen.push((t, touching, [0; 3]));
        Ok(())
    }
    fn object(
        &mut self,
        t: u64,
        m: &services::session::ObjectState,
    ) -> Result<(), services::RecordingError> {
        let p = &m.pose.position;
        self.seen
            .push((t, usize::MAX, [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]));
        Ok(())
    }
    fn done(&self) -> bool {
        self.seen.len() >= self.limit
    }
}

#[test]
fn a_second_read_from_the_kept_messages_hands_on_what_the_file_holds() {
    use services::session::{KeptMessages, KEPT_MESSAGES_BUDGET};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let scenario = Scenario::builtin("sphere-lift", 2).unwrap();
    record_simulation(&scenario, Some(3.0), &path, |_, _| {}).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let limits = ReadLimits::streaming();
    for source in [
        SessionSource::File(&path),
        SessionSource::Bytes {
            bytes: &bytes,
            name: "upload",
        },
    ] {
        // The whole file, and a read that stops a third of the way.
        for limit in [usize::MAX, 4000] {
            let mut reread = Samples {
                limit,
                ..Samples::default()
            };
            source.stream_again(&limits, &mut reread).unwrap();
            assert!(!reread.seen.is_empty());
            // Kept within the budget, and over a budget (kept nothing: the file is read again).
            for (budget, complete) in [(KEPT_MESSAGES_BUDGET, true), (10_000, false)] {
                let mut kept = KeptMessages::new(budget);
                let mut first = Samples {
                    limit: usize::MAX,
                    ..Samples::default()
                };
                source
                    .stream_keeping(&limits, &mut first, &mut kept)
                    .unwrap();
                let wants = services::session::DecodeTopics::SEGMENTATION;
                assert_eq!(kept.covers(wants), complete, "budget {budget}");
                assert!(kept.held_bytes() <= budget);
                if complete {
                    assert!(!kept.covers(services::session::DecodeTopics::ALL));
                }
                let mut second = Samples {
                    limit,
                    ..Samples::default()
                };
                source
                    .stream_again_kept(&limits, &mut second, &kept)
                    .unwrap();
                assert_eq!(second.seen, reread.seen, "budget {budget}, limit {limit}");
                if limit == usize::MAX {
                    assert_eq!(first.seen, reread.seen);
                }
            }
        }
    }
}
