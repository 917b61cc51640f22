//! Files written by `SessionWriter` (and by `salvage`) are readable by the reference Python MCAP
//! reader (`tests/python/read_mcap.py`, PyPI `mcap` + `zstandard`), through the indexes and
//! front to back, with the counts, schemas and metadata we wrote.

use crate::common;
use crate::interpreter;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::*;
use services::foxglove::*;
use services::mcap_io::{salvage, SessionWriter};

/// The interpreter with the reference MCAP reader (see `interpreter::python_with`).
fn python() -> Option<PathBuf> {
    interpreter::python_with(&["mcap", "zstandard", "lz4"])
}

/// Runs the checker; `None` (with a note) when the tests run without their set-up.
fn python_read(file: &Path) -> Option<serde_json::Value> {
    python_mcap_report(file, &["mcap", "zstandard", "lz4"])
}

fn write_example(path: &Path, ticks: u64) -> BTreeMap<&'static str, u64> {
    let mut w = SessionWriter::create(path).unwrap();
    w.register_channel("/tf", &FRAME_TRANSFORMS_SCHEMA).unwrap();
    w.register_channel("/scene", &SCENE_UPDATE_SCHEMA).unwrap();
    w.register_channel("/joints", &JOINT_STATES_SCHEMA).unwrap();
    w.add_metadata(
        "session",
        BTreeMap::from([("scenario".to_owned(), "pick_sphere".to_owned())]),
    )
    .unwrap();
    let mut counts = BTreeMap::new();
    for i in 0..ticks {
        let t = i * 10_000_000;
        w.write("/joints", t, &example_joint_states(t)).unwrap();
        *counts.entry("/joints").or_insert(0) += 1;
        if i % 3 == 0 {
            w.write("/tf", t, &example_frame_transforms(t)).unwrap();
            *counts.entry("/tf").or_insert(0) += 1;
        }
        if i % 25 == 0 {
            w.write("/scene", t, &example_scene_update(t)).unwrap();
            *counts.entry("/scene").or_insert(0) += 1;
        }
    }
    w.add_metadata(
        "result",
        BTreeMap::from([("ok".to_owned(), "true".to_owned())]),
    )
    .unwrap();
    w.finish().unwrap();
    counts
}

#[test]
fn python_reader_sees_every_message_schema_and_metadata_record() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let counts = write_example(&path, 260);
    let Some(report) = python_read(&path) else {
        return;
    };
    for (topic, n) in &counts {
        assert_eq!(report["topics"][topic], serde_json::json!(n), "{report}");
    }
    assert_eq!(report["topics"].as_object().unwrap().len(), counts.len());
    assert_eq!(report["schemas"]["/scene"], "foxglove.SceneUpdate");
    assert_eq!(report["schemas"]["/tf"], "foxglove.FrameTransforms");
    assert_eq!(report["schemas"]["/joints"], "foxglove.JointStates");
    assert_eq!(report["metadata"]["session"]["scenario"], "pick_sphere");
    assert_eq!(report["metadata"]["result"]["ok"], "true");
}

#[test]
fn python_reader_accepts_a_salvaged_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("crashed.mcap");
    let mut w = SessionWriter::create(&path).unwrap();
    w.register_channel("/joints", &JOINT_STATES_SCHEMA).unwrap();
    for i in 0..250u64 {
        let t = i * 10_000_000;
        w.write("/joints", t, &example_joint_states(t)).unwrap();
    }
    drop(w.into_inner());
    let out = dir.path().join("salvaged.mcap");
    let report = salvage(&path, &out).unwrap();
    assert_eq!(report.messages, 201); // up to the flush at 2.0 s
    let Some(py) = python_read(&out) else {
        return;
    };
    assert_eq!(py["topics"]["/joints"], serde_json::json!(201));
}

#[test]
fn python_checker_fails_on_a_truncated_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    write_example(&path, 30);
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let Some(python) = python() else { return };
    let output = Command::new(python)
        .arg(read_mcap_script())
        .arg(&cut)
        .output()
        .expect("running the Python MCAP reader");
    assert!(!output.status.success(), "a truncated file must fail");
}

#[test]
fn a_file_written_by_the_python_writer_reads_in_rust() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("py.mcap");
    let program = r#"
import json, sys
from mcap.writer import Writer, CompressionType
with open(sys.argv[1], "wb") as f:
    w = Writer(f, compression=CompressionType.ZSTD)
    w.start()
    sid = w.register_schema(name="foxglove.JointStates", encoding="jsonschema", data=b"{}")
    cid = w.register_channel(topic="/joints", message_encoding="json", schema_id=sid)
    for i in range(50):
        msg = {"timestamp": {"sec": 0, "nsec": i}, "joints": [{"name": "j0", "position": i * 0.1}]}
        w.add_message(channel_id=cid, log_time=i * 1000, publish_time=i * 1000,
                      data=json.dumps(msg).encode())
    w.add_metadata("session", {"k": "v"})
    w.finish()
"#;
    let Some(python) = python() else { return };
    let output = Command::new(python)
        .arg("-c")
        .arg(program)
        .arg(&path)
        .output()
        .expect("running the Python MCAP writer");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let session = services::mcap_io::read_session_file(&path, &Default::default()).unwrap();
    let joints = session
        .decode_topic::<JointStates>("/joints", "foxglove.JointStates")
        .unwrap();
    assert_eq!(joints.len(), 50);
    assert_eq!(joints[7].0, 7000);
    assert_eq!(joints[7].1.joints[0].position, Some(0.7000000000000001));
    assert_eq!(session.metadata("session").unwrap()["k"], "v");
}
