//! End-to-end tests of the MCAP layer: write with `SessionWriter`, read back with the safe
//! reader, damage files in the ways crashes and bit rot do, salvage.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;

use common::*;
use services::foxglove::*;
use services::mcap_io::{
    read_session_bytes, read_session_file, salvage, ReadLimits, SessionWriter, WriterOptions,
};
use services::RecordingError;

const TF: &str = "/tf";
const SCENE: &str = "/scene";
const JOINTS: &str = "/glove/joints";

fn session_metadata() -> BTreeMap<String, String> {
    BTreeMap::from([
        ("scenario".to_owned(), "pick_sphere".to_owned()),
        (
            "start_wall_time".to_owned(),
            "2026-11-21T08:00:00Z".to_owned(),
        ),
        ("hand".to_owned(), "glove10".to_owned()),
    ])
}

/// Writes `seconds` of session at 100 Hz on three Foxglove topics (joints every tick, transforms
/// every 2nd, scene every 10th) plus a `session` metadata record. Returns the log times written
/// per topic.
fn write_session(writer: &mut SessionWriter, ticks: u64) -> BTreeMap<&'static str, Vec<u64>> {
    writer
        .register_channel(TF, &FRAME_TRANSFORMS_SCHEMA)
        .unwrap();
    writer
        .register_channel(SCENE, &SCENE_UPDATE_SCHEMA)
        .unwrap();
    writer
        .register_channel(JOINTS, &JOINT_STATES_SCHEMA)
        .unwrap();
    writer.add_metadata("session", session_metadata()).unwrap();
    let mut times: BTreeMap<&'static str, Vec<u64>> = BTreeMap::new();
    for i in 0..ticks {
        let t = i * 10_000_000;
        writer.write(JOINTS, t, &example_joint_states(t)).unwrap();
        times.entry(JOINTS).or_default().push(t);
        if i % 2 == 0 {
            writer.write(TF, t, &example_frame_transforms(t)).unwrap();
            times.entry(TF).or_default().push(t);
        }
        if i % 10 == 0 {
            writer.write(SCENE, t, &example_scene_update(t)).unwrap();
            times.entry(SCENE).or_default().push(t);
        }
    }
    times
}

fn write_file(path: &Path, options: WriterOptions, ticks: u64) -> BTreeMap<&'static str, Vec<u64>> {
    let mut writer = SessionWriter::create_with_options(path, options).unwrap();
    let times = write_session(&mut writer, ticks);
    let summary = writer.finish().unwrap();
    assert_eq!(
        summary.messages,
        times.values().map(|v| v.len() as u64).sum::<u64>()
    );
    times
}

fn small_file(compress: bool, ticks: u64) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    write_file(
        &path,
        WriterOptions {
            compress,
            ..WriterOptions::default()
        },
        ticks,
    );
    std::fs::read(&path).unwrap()
}

/// A few kB: one joint-states topic (the scene schema alone is 40 kB, written twice), 30
/// messages in two chunks. For the tests that read a file once per byte.
fn tiny_file() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiny.mcap");
    let mut writer = SessionWriter::create(&path).unwrap();
    writer
        .register_channel(JOINTS, &JOINT_STATES_SCHEMA)
        .unwrap();
    for i in 0..30u64 {
        let t = i * 50_000_000;
        writer.write(JOINTS, t, &example_joint_states(t)).unwrap();
    }
    writer.finish().unwrap();
    std::fs::read(&path).unwrap()
}

#[test]
fn round_trip_returns_the_same_messages_at_the_same_times() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let times = write_file(&path, WriterOptions::default(), 250);
    let session = read_session_file(&path, &ReadLimits::default()).unwrap();

    assert_eq!(session.topics.len(), 3);
    assert!(session.library.starts_with("icms-services/"));
    let joints = session
        .decode_topic::<JointStates>(JOINTS, "foxglove.JointStates")
        .unwrap();
    assert_eq!(
        joints.iter().map(|(t, _)| *t).collect::<Vec<_>>(),
        times[JOINTS]
    );
    for (t, msg) in &joints {
        assert_eq!(*msg, example_joint_states(*t));
    }
    let tf = session
        .decode_topic::<FrameTransforms>(TF, "foxglove.FrameTransforms")
        .unwrap();
    assert_eq!(tf.iter().map(|(t, _)| *t).collect::<Vec<_>>(), times[TF]);
    for (t, msg) in &tf {
        assert_eq!(*msg, example_frame_transforms(*t));
    }
    let scene = session
        .decode_topic::<SceneUpdate>(SCENE, "foxglove.SceneUpdate")
        .unwrap();
    assert_eq!(
        scene.iter().map(|(t, _)| *t).collect::<Vec<_>>(),
        times[SCENE]
    );
    for (t, msg) in &scene {
        assert_eq!(*msg, example_scene_update(*t));
    }
    // Schemas are the embedded Foxglove ones, and every message validates against them.
    let topic = session
        .require_topic(SCENE, "foxglove.SceneUpdate")
        .unwrap();
    assert_eq!(
        topic.schema.as_ref().unwrap().data,
        SCENE_UPDATE_SCHEMA.data.as_bytes()
    );
    let first: Vec<_> = topic
        .json_values()
        .unwrap()
        .into_iter()
        .take(3)
        .map(|(_, v)| v)
        .collect();
    for errors in validate_each(&SCENE_UPDATE_SCHEMA, &first).unwrap_or_default() {
        assert!(errors.is_empty(), "{errors:?}");
    }
    // Sequence numbers count up per channel.
    let seqs: Vec<u32> = session.topics[TF]
        .messages
        .iter()
        .map(|m| m.sequence)
        .collect();
    assert_eq!(seqs, (0..seqs.len() as u32).collect::<Vec<_>>());
}

#[test]
fn in_memory_and_file_readers_agree() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    write_file(&path, WriterOptions::default(), 50);
    let from_file = read_session_file(&path, &ReadLimits::default()).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let from_bytes = read_session_bytes(&bytes, &ReadLimits::default()).unwrap();
    assert_eq!(from_file, from_bytes);
}

#[test]
fn metadata_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let mut writer = SessionWriter::create(&path).unwrap();
    write_session(&mut writer, 5);
    let params = BTreeMap::from([("mu".to_owned(), "1.5".to_owned())]);
    writer.add_metadata("params", params.clone()).unwrap();
    writer.add_metadata("empty", BTreeMap::new()).unwrap();
    let summary = writer.finish().unwrap();
    assert_eq!(summary.metadata_records, 3);

    let session = read_session_file(&path, &ReadLimits::default()).unwrap();
    assert_eq!(session.metadata("session"), Some(&session_metadata()));
    assert_eq!(session.metadata("params"), Some(&params));
    assert_eq!(session.metadata("empty"), Some(&BTreeMap::new()));
    assert_eq!(
        session
            .metadata
            .iter()
            .map(|m| m.name.as_str())
            .collect::<Vec<_>>(),
        ["session", "params", "empty"]
    );
}

#[test]
fn chunks_are_closed_every_second_of_log_time() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let mut writer = SessionWriter::create(&path).unwrap();
    write_session(&mut writer, 550); // 5.5 s
    let summary = writer.finish().unwrap();
    // One flush per second (5) plus the final chunk, plus the chunk closed by the metadata
    // record: far fewer than 1 MiB of data would need, but at least one per second.
    assert!(summary.chunks >= 6, "{summary:?}");
    assert_eq!(summary.log_time_range_ns, Some((0, 5_490_000_000)));
}

#[test]
fn nan_is_rejected_naming_topic_and_field_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let mut writer = SessionWriter::create(&path).unwrap();
    writer
        .register_channel(TF, &FRAME_TRANSFORMS_SCHEMA)
        .unwrap();
    writer
        .register_channel(JOINTS, &JOINT_STATES_SCHEMA)
        .unwrap();
    writer.write(TF, 0, &example_frame_transforms(0)).unwrap();

    let mut bad = example_frame_transforms(1);
    bad.transforms[1].translation.y = f64::NAN;
    let err = writer.write(TF, 1, &bad).unwrap_err();
    match &err {
        RecordingError::NonFiniteNumber { topic, path, .. } => {
            assert_eq!(topic, TF);
            assert_eq!(path, "transforms[1].translation.y");
        }
        other => panic!("unexpected {other:?}"),
    }
    assert!(err.to_string().contains("transforms[1].translation.y"));

    let mut bad = example_joint_states(2);
    bad.joints[3].effort = Some(f64::INFINITY);
    let err = writer.write(JOINTS, 2, &bad).unwrap_err();
    assert!(
        matches!(&err, RecordingError::NonFiniteNumber { path, value, .. } if path == "joints[3].effort" && value == "inf"),
        "{err:?}"
    );

    // The writer is still usable, and the bad messages are not in the file.
    writer.write(TF, 3, &example_frame_transforms(3)).unwrap();
    writer.finish().unwrap();
    let session = read_session_file(&path, &ReadLimits::default()).unwrap();
    let times: Vec<u64> = session.topics[TF]
        .messages
        .iter()
        .map(|m| m.log_time_ns)
        .collect();
    assert_eq!(times, [0, 3]);
    assert!(session.topics[JOINTS].messages.is_empty());
}

#[test]
fn writing_to_an_unregistered_topic_or_re_registering_with_another_schema_fails() {
    let dir = tempfile::tempdir().unwrap();
    let mut writer = SessionWriter::create(dir.path().join("s.mcap")).unwrap();
    let err = writer
        .write("/nope", 0, &FrameTransforms::default())
        .unwrap_err();
    assert!(
        matches!(err, RecordingError::UnregisteredTopic { .. }),
        "{err:?}"
    );
    writer
        .register_channel(TF, &FRAME_TRANSFORMS_SCHEMA)
        .unwrap();
    writer
        .register_channel(TF, &FRAME_TRANSFORMS_SCHEMA)
        .unwrap();
    let err = writer
        .register_channel(TF, &SCENE_UPDATE_SCHEMA)
        .unwrap_err();
    assert!(
        matches!(err, RecordingError::TopicConflict { .. }),
        "{err:?}"
    );
    writer.finish().unwrap();
}

#[test]
fn non_mcap_bytes_are_rejected() {
    let limits = ReadLimits::default();
    for bytes in [
        &b""[..],
        b"\x89MCA",
        b"{\"transforms\": []}",
        b"PK\x03\x04 this is a zip file, not an mcap file",
    ] {
        let err = read_session_bytes(bytes, &limits).unwrap_err();
        assert!(matches!(err, RecordingError::NotMcap), "{err:?}");
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.mcap");
    std::fs::write(&path, b"not an mcap at all").unwrap();
    assert!(matches!(
        read_session_file(&path, &limits),
        Err(RecordingError::NotMcap)
    ));
    assert!(matches!(
        salvage(&path, dir.path().join("out.mcap")),
        Err(RecordingError::NotMcap)
    ));
}

#[test]
fn truncated_files_are_reported_as_truncated() {
    let bytes = small_file(true, 120);
    let limits = ReadLimits::default();
    for cut in [bytes.len() - 1, bytes.len() - 8, bytes.len() / 2, 30, 9, 8] {
        let err = read_session_bytes(&bytes[..cut], &limits).unwrap_err();
        assert!(
            matches!(err, RecordingError::Truncated { .. }),
            "cut at {cut}: {err:?}"
        );
    }
}

#[test]
fn a_flipped_byte_inside_a_chunk_is_a_crc_error() {
    let bytes = small_file(false, 120);
    let chunk = top_level_records(&bytes)
        .into_iter()
        .find(|r| r.opcode == OP_CHUNK)
        .expect("a chunk");
    // Flip a byte near the end of the chunk's records (inside a message payload).
    let mut damaged = bytes.clone();
    let at = chunk.body() + chunk.len - 20;
    damaged[at] ^= 0x01;
    let err = read_session_bytes(&damaged, &ReadLimits::default()).unwrap_err();
    match err {
        RecordingError::ChunkCrcMismatch { offset, .. } => {
            assert_eq!(offset, chunk.offset as u64)
        }
        other => panic!("expected a CRC error, got {other:?}"),
    }
}

#[test]
fn a_flipped_byte_anywhere_in_a_compressed_chunk_is_an_error() {
    let bytes = tiny_file();
    let chunks: Vec<_> = top_level_records(&bytes)
        .into_iter()
        .filter(|r| r.opcode == OP_CHUNK)
        .collect();
    assert!(!chunks.is_empty());
    let limits = ReadLimits::default();
    for chunk in chunks {
        // Every byte: opcode, lengths, times, CRC, compression name, compressed data. A flip the
        // decoder does not notice (the message times, an unused bit of the zstd stream) is
        // caught by the data section CRC; a damaged opcode is refused rather than skipped.
        for at in chunk.offset..chunk.body() + chunk.len {
            let mut damaged = bytes.clone();
            damaged[at] ^= 0x40;
            let result = read_session_bytes(&damaged, &limits);
            assert!(
                result.is_err(),
                "flip at {at} (chunk at {}, body at {}, len {}) went unnoticed",
                chunk.offset,
                chunk.body(),
                chunk.len
            );
        }
    }
}

#[test]
fn a_damaged_chunk_opcode_is_not_skipped_silently() {
    let mut bytes = small_file(true, 12);
    let chunk = top_level_records(&bytes)
        .into_iter()
        .find(|r| r.opcode == OP_CHUNK)
        .unwrap();
    bytes[chunk.offset] = 0x46; // a reserved opcode: the spec says skip unknown records
    let err = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
    assert!(
        matches!(&err, RecordingError::Corrupt { detail, .. } if detail.contains("reserved")),
        "{err:?}"
    );
}

#[test]
fn a_flipped_length_byte_cannot_cause_a_huge_allocation() {
    let bytes = tiny_file();
    let limits = ReadLimits::default();
    for rec in top_level_records(&bytes) {
        // Set the top byte of each record length: claims ~2^62 bytes.
        let mut damaged = bytes.clone();
        damaged[rec.offset + 8] = 0x40;
        let err = read_session_bytes(&damaged, &limits).unwrap_err();
        assert!(
            matches!(err, RecordingError::Truncated { .. }),
            "record at {}: {err:?}",
            rec.offset
        );
    }
    // Every single-byte flip anywhere in the file: never a panic.
    for at in 0..bytes.len() {
        let mut damaged = bytes.clone();
        damaged[at] = damaged[at].wrapping_add(0x80);
        let _ = read_session_bytes(&damaged, &limits);
    }
}

#[test]
fn records_over_the_length_limit_are_refused() {
    let bytes = small_file(true, 120);
    let limits = ReadLimits {
        max_record_bytes: 256,
        ..ReadLimits::default()
    };
    let err = read_session_bytes(&bytes, &limits).unwrap_err();
    assert!(
        matches!(err, RecordingError::RecordTooLong { limit: 256, .. }),
        "{err:?}"
    );
    let limits = ReadLimits {
        max_total_message_bytes: 1000,
        ..ReadLimits::default()
    };
    let err = read_session_bytes(&bytes, &limits).unwrap_err();
    assert!(matches!(err, RecordingError::TooMuchData { .. }), "{err:?}");
}

#[test]
fn missing_topic_and_unexpected_schema_are_named() {
    let session = read_session_bytes(&small_file(true, 120), &ReadLimits::default()).unwrap();
    let err = session
        .require_topic("/contacts", "icms.Contacts")
        .unwrap_err();
    assert!(
        matches!(&err, RecordingError::MissingTopic { topic } if topic == "/contacts"),
        "{err:?}"
    );
    let err = session
        .require_topic(TF, "icms.GloveJointStates")
        .unwrap_err();
    match err {
        RecordingError::UnknownSchema {
            topic,
            expected,
            found,
        } => {
            assert_eq!(topic, TF);
            assert_eq!(expected, "icms.GloveJointStates");
            assert_eq!(found.as_deref(), Some("foxglove.FrameTransforms"));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn invalid_json_and_non_json_encodings_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    // A JSON topic holding a message that is not JSON.
    let path = dir.path().join("bad_json.mcap");
    let mut writer = SessionWriter::create(&path).unwrap();
    writer
        .register_channel(TF, &FRAME_TRANSFORMS_SCHEMA)
        .unwrap();
    writer.write_raw(TF, 5, b"{\"transforms\": [").unwrap();
    writer.finish().unwrap();
    let err = read_session_file(&path, &ReadLimits::default()).unwrap_err();
    assert!(
        matches!(&err, RecordingError::InvalidJson { topic, log_time_ns: 5, .. } if topic == TF),
        "{err:?}"
    );

    // A file from another tool with a protobuf topic: readable, the topic found by its schema
    // (session format 2 is protobuf), but not as a JSON topic.
    let path = dir.path().join("protobuf.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = mcap::Writer::new(file).unwrap();
        let schema = w
            .add_schema("foxglove.FrameTransforms", "protobuf", b"\x0a\x00")
            .unwrap();
        let channel = w
            .add_channel(schema, TF, "protobuf", &BTreeMap::new())
            .unwrap();
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: 0,
                log_time: 1,
                publish_time: 1,
            },
            b"\x01\x02\x03",
        )
        .unwrap();
        w.finish().unwrap();
    }
    let session = read_session_file(&path, &ReadLimits::default()).unwrap();
    assert_eq!(session.topics[TF].messages[0].data, b"\x01\x02\x03");
    let t = session
        .require_topic(TF, "foxglove.FrameTransforms")
        .unwrap();
    let err = t.json_values().unwrap_err();
    assert!(
        matches!(&err, RecordingError::NonJsonEncoding { encoding, .. } if encoding == "protobuf"),
        "{err:?}"
    );
}

#[test]
fn salvage_recovers_flushed_chunks_of_a_writer_that_died() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("crashed.mcap");
    let mut writer = SessionWriter::create(&path).unwrap();
    // 3.5 s at 100 Hz: chunks are closed after the messages at 1.0, 2.0 and 3.0 s.
    let times = write_session(&mut writer, 350);
    // The process dies: the current chunk is never closed, no summary, no footer.
    drop(writer.into_inner());

    let err = read_session_file(&path, &ReadLimits::default()).unwrap_err();
    assert!(matches!(err, RecordingError::Truncated { .. }), "{err:?}");

    let out = dir.path().join("salvaged.mcap");
    let report = salvage(&path, &out).unwrap();
    // The chunk is closed right after the joints message at 3.0 s, before the transforms and
    // scene messages of that tick.
    let flushed_at = 3_000_000_000;
    let expected: usize = times
        .values()
        .map(|ts| ts.iter().filter(|t| **t < flushed_at).count())
        .sum::<usize>()
        + 1;
    assert_eq!(report.messages, expected as u64, "{report:?}");
    assert_eq!(report.last_log_time_ns, Some(flushed_at));
    assert!(report.dropped_bytes > 0, "{report:?}");
    // The three chunks closed at 1.0, 2.0 and 3.0 s (schemas and channels are outside chunks).
    assert_eq!(report.chunks, 3, "{report:?}");
    assert_eq!((report.schemas, report.channels), (3, 3));
    assert_eq!(report.metadata_records, 1);
    assert!(!report.input_was_complete);
    assert!(report.stop_reason.is_some());

    // The salvaged file is a complete MCAP with the same messages, schemas and metadata.
    let session = read_session_file(&out, &ReadLimits::default()).unwrap();
    assert_eq!(session.metadata("session"), Some(&session_metadata()));
    let joints = session
        .decode_topic::<JointStates>(JOINTS, "foxglove.JointStates")
        .unwrap();
    let expected_joints: Vec<u64> = times[JOINTS]
        .iter()
        .copied()
        .filter(|t| *t <= flushed_at)
        .collect();
    assert_eq!(
        joints.iter().map(|(t, _)| *t).collect::<Vec<_>>(),
        expected_joints
    );
    assert_eq!(joints[5].1, example_joint_states(joints[5].0));
    session
        .require_topic(SCENE, "foxglove.SceneUpdate")
        .unwrap();
}

#[test]
fn a_copy_taken_mid_session_is_salvageable_up_to_the_last_flush() {
    // What a crash leaves on disk: the file as it is while the writer is still open.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("live.mcap");
    let mut writer = SessionWriter::create(&path).unwrap();
    write_session(&mut writer, 250); // flushed after the joints message at 2.0 s
    let snapshot = dir.path().join("snapshot.mcap");
    std::fs::copy(&path, &snapshot).unwrap();
    writer.finish().unwrap();

    let report = salvage(&snapshot, dir.path().join("out.mcap")).unwrap();
    assert_eq!(report.last_log_time_ns, Some(2_000_000_000), "{report:?}");
    // Joints at 0..=2.0 s (201), transforms every 2nd tick before 2.0 s (100), scene every
    // 10th (20).
    assert_eq!(report.messages, 201 + 100 + 20, "{report:?}");
}

#[test]
fn a_dropped_writer_still_leaves_a_complete_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dropped.mcap");
    {
        let mut writer = SessionWriter::create(&path).unwrap();
        write_session(&mut writer, 42);
        // An early return on an error path: no finish() call.
    }
    let session = read_session_file(&path, &ReadLimits::default()).unwrap();
    assert_eq!(session.topics[JOINTS].messages.len(), 42);
}

#[test]
fn salvaging_a_complete_file_copies_everything_and_drops_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ok.mcap");
    let times = write_file(&path, WriterOptions::default(), 80);
    let out = dir.path().join("copy.mcap");
    let report = salvage(&path, &out).unwrap();
    assert!(report.input_was_complete, "{report:?}");
    assert_eq!(report.dropped_bytes, 0);
    assert_eq!(report.stop_reason, None);
    assert_eq!(
        report.messages,
        times.values().map(|v| v.len() as u64).sum::<u64>()
    );
    let a = read_session_file(&path, &ReadLimits::default()).unwrap();
    let b = read_session_file(&out, &ReadLimits::default()).unwrap();
    assert_eq!(a.topics, b.topics);
    assert_eq!(a.metadata, b.metadata);
}

#[test]
fn salvage_stops_at_a_corrupt_chunk_and_keeps_the_ones_before() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ok.mcap");
    write_file(&path, WriterOptions::default(), 350);
    let mut bytes = std::fs::read(&path).unwrap();
    let chunks: Vec<_> = top_level_records(&bytes)
        .into_iter()
        .filter(|r| r.opcode == OP_CHUNK)
        .collect();
    assert!(chunks.len() >= 4);
    let bad = chunks[2];
    bytes[bad.body() + bad.len - 3] ^= 0xff;
    let damaged = dir.path().join("damaged.mcap");
    std::fs::write(&damaged, &bytes).unwrap();
    let report = salvage(&damaged, dir.path().join("out.mcap")).unwrap();
    assert_eq!(report.chunks, 2, "{report:?}");
    assert_eq!(
        report.dropped_bytes,
        (bytes.len() - bad.offset) as u64,
        "{report:?}"
    );
    assert!(report.stop_reason.unwrap().contains("corrupt"));
}

#[test]
fn salvage_refuses_to_overwrite_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    write_file(&path, WriterOptions::default(), 10);
    let before = std::fs::read(&path).unwrap();
    let err = salvage(&path, &path).unwrap_err();
    assert!(matches!(err, RecordingError::Io { .. }), "{err:?}");
    assert_eq!(std::fs::read(&path).unwrap(), before);
}

#[test]
fn a_file_of_more_topics_than_a_session_could_have_is_refused() {
    // Each topic holds its own copy of its schema: many topics sharing one large schema would
    // otherwise hold copies without bound.
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let mut w = mcap::Writer::new(&mut out).unwrap();
        let schema = w
            .add_schema("big", "jsonschema", &vec![b' '; 4096])
            .unwrap();
        for i in 0..1100 {
            w.add_channel(schema, &format!("/t{i}"), "json", &Default::default())
                .unwrap();
        }
        w.finish().unwrap();
    }
    let bytes = out.into_inner();
    let e = services::session::read_session_bytes(&bytes, "topics.mcap", &ReadLimits::default())
        .unwrap_err();
    assert!(
        e.to_string().contains("topics") || e.to_string().contains("decompress"),
        "{e}"
    );
}
