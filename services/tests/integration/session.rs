//! Sessions end to end in the library: a simulated scenario recorded to MCAP, read back with the
//! same samples, valid against every schema, readable by the reference Python reader,
//! deterministic; imports of glove recordings; failures leave readable files.

use crate::common;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::OnceLock;

use common::rejects;
use dfs_core::hand::HandModel;
use dfs_core::operator::Simulation;
use dfs_core::scenario::Scenario;
use services::foxglove::JOINT_STATES_SCHEMA;
use services::mcap_io::{read_session_file, SessionWriter};
use services::session::import::{import_glove, parse_glove_csv, read_glove_mcap, ImportOptions};
use services::session::*;
use services::RecordingError;

const SECONDS: f64 = 2.5;

/// One simulated `sphere-lift` session (seed 7, 2.5 s), recorded once for all tests.
fn sphere_session() -> &'static (tempfile::TempDir, PathBuf, RecordSummary) {
    static SESSION: OnceLock<(tempfile::TempDir, PathBuf, RecordSummary)> = OnceLock::new();
    SESSION.get_or_init(|| crate::common::sphere_lift_session(7, Some(SECONDS)))
}

fn scenario_object(name: &str) -> dfs_core::scenario::ScenarioObject {
    Scenario::builtin(name, 0).unwrap().object.unwrap()
}

#[test]
fn a_simulated_session_reads_back_with_the_samples_written() {
    let (_, path, summary) = sphere_session();
    let ticks = (SECONDS * 1000.0) as usize;
    assert_eq!(summary.ticks as usize, ticks);
    let session = read_session(path).unwrap();
    assert_eq!(session.ticks(), ticks);
    assert_eq!(session.feedback.len(), ticks);
    assert_eq!(session.contacts.len(), ticks);
    assert_eq!(session.object.len(), ticks);
    let fox = ticks.div_ceil(FOXGLOVE_DECIMATION as usize);
    for topic in FOXGLOVE_TOPICS {
        assert_eq!(session.message_counts[topic], fox, "{topic}");
    }
    assert_eq!(session.scenario(), Some("sphere-lift"));
    for key in [
        "seed",
        "hand",
        "object",
        "rate_hz",
        "software_version",
        "started_at",
    ] {
        assert!(session.metadata.contains_key(key), "session.{key}");
    }
    assert_eq!(session.metadata["rate_hz"], "1000");
    assert_eq!(session.metadata["seed"], "7");
    assert_eq!(session.metadata["hand"], "glove10");
    assert!(session.phases.len() >= 3);
    assert_eq!(session.phases[0].name, "approach");
    assert_eq!(session.phases[0].start_ns, 0);

    // The same samples as the simulation produced, value for value, to the recorded
    // resolution (each field's step, `services::session::proto`): within half a step.
    let half = |step: f64| 0.5 * step * (1.0 + 1e-9);
    let (angle, torque, position, force) = (
        half(proto::JOINT_ANGLE),
        half(proto::JOINT_TORQUE),
        half(proto::POSITION),
        half(proto::FORCE),
    );
    let close = |read: &[f64], sim: &[f64], tol: f64, what: &str| {
        assert_eq!(read.len(), sim.len(), "{what}");
        for (r, s) in read.iter().zip(sim) {
            assert!((r - s).abs() <= tol, "{what}: read {r}, simulated {s}");
        }
    };
    let scenario = Scenario::builtin("sphere-lift", 7).unwrap();
    let mut sim = Simulation::new(&scenario, HandModel::glove10(), Some(SECONDS)).unwrap();
    let mut i = 0;
    while sim.step().unwrap() {
        let (q, tau, base) = sim.sample();
        let (t, js) = &session.joint_states[i];
        assert_eq!(*t, sim.time_ns());
        close(&js.positions, q, angle, "positions");
        close(&js.efforts, tau, torque, "efforts");
        let out = sim.output();
        let (_, fb) = &session.feedback[i];
        close(
            &fb.feedback_torques,
            &out.feedback_torque[..q.len()],
            torque,
            "feedback torques",
        );
        let (_, obj) = &session.object[i];
        let p = out.object.pose.translation.vector;
        close(
            &[
                obj.pose.position.x,
                obj.pose.position.y,
                obj.pose.position.z,
            ],
            &[p.x, p.y, p.z],
            position,
            "object position",
        );
        let in_hand = base.inverse() * out.object.pose;
        close(
            &[obj.pose_in_hand.position.z],
            &[in_hand.translation.z],
            position,
            "object in hand",
        );
        let (_, c) = &session.contacts[i];
        assert_eq!(c.n_contacts as usize, out.n_contacts);
        for (k, f) in c.fingers.iter().enumerate() {
            assert_eq!(f.in_contact, out.tips[k].in_contact);
            assert_eq!(f.slip, out.tips[k].slip);
            assert_eq!(f.in_cone, !f.slip);
            close(
                &[f.transmitted.z],
                &[out.tips[k].transmitted[2]],
                force,
                "transmitted normal force",
            );
            if !out.tips[k].touching {
                assert_eq!(
                    f.point_b,
                    Default::default(),
                    "no contact point when not touching"
                );
            }
        }
        i += 1;
    }
    assert_eq!(i, ticks);
}

/// Every message of `topic` decodes as `M`; their number and the decoded messages.
fn decode_all<M: prost::Message + Default>(
    recorded: &services::mcap_io::RecordedSession,
    topic: &str,
    schema_name: &str,
) -> Vec<M> {
    let t = &recorded.topics[topic];
    assert_eq!(t.message_encoding, "protobuf", "{topic}");
    let schema = t.schema.as_ref().unwrap();
    assert_eq!(
        (schema.name.as_str(), schema.encoding.as_str()),
        (schema_name, "protobuf")
    );
    t.messages
        .iter()
        .map(|m| M::decode(&m.data[..]).unwrap_or_else(|e| panic!("{topic}: {e}")))
        .collect()
}

#[test]
fn every_foxglove_topic_carries_the_sdk_schema_and_decodes_as_it() {
    use foxglove::messages as fg;
    use foxglove::Encode;
    let (_, path, _) = sphere_session();
    let recorded = read_session_file(path, &Default::default()).unwrap();
    for (topic, schema) in [
        (TOPIC_TF, fg::FrameTransforms::get_schema().unwrap()),
        (TOPIC_SCENE, fg::SceneUpdate::get_schema().unwrap()),
        (TOPIC_JOINT_STATES, fg::JointStates::get_schema().unwrap()),
    ] {
        let s = recorded.topics[topic].schema.as_ref().unwrap();
        assert_eq!(s.name, schema.name, "{topic}");
        assert_eq!(
            s.data[..],
            schema.data[..],
            "{topic}: the SDK's descriptor set"
        );
    }
    // The scene shows the sphere, and force arrows once fingers push.
    let scenes: Vec<fg::SceneUpdate> = decode_all(&recorded, TOPIC_SCENE, "foxglove.SceneUpdate");
    assert!(scenes.iter().all(|s| s.entities[0].spheres.len() == 1));
    // ... and the table, its top at the simulation's table height (0 for a built-in scenario).
    let table = &scenes[0].entities[1];
    assert_eq!(table.id, services::session::TABLE_ENTITY);
    let cube = &table.cubes[0];
    let top = cube.pose.unwrap().position.unwrap().z + 0.5 * cube.size.unwrap().z;
    let sim = Simulation::new(
        &Scenario::builtin("sphere-lift", 7).unwrap(),
        HandModel::glove10(),
        Some(SECONDS),
    )
    .unwrap();
    // (Foxglove topics carry their numbers at f32 precision: 60 nm at a metre.)
    assert!((top - sim.table_height()).abs() < 1e-7, "table top {top}");
    assert!(scenes.iter().any(|s| !s.entities[0].arrows.is_empty()));
    // /tf: world → base, one transform per joint, world → object.
    let tf: Vec<fg::FrameTransforms> = decode_all(&recorded, TOPIC_TF, "foxglove.FrameTransforms");
    let transforms = &tf[0].transforms;
    assert_eq!(transforms.len(), HandModel::glove10().joints.len() + 2);
    assert_eq!(transforms[0].parent_frame_id, "world");
    assert_eq!(transforms.last().unwrap().child_frame_id, "object");
    let joints: Vec<fg::JointStates> =
        decode_all(&recorded, TOPIC_JOINT_STATES, "foxglove.JointStates");
    assert_eq!(joints[0].joints.len(), HandModel::glove10().dof());
}

#[test]
fn every_raw_topic_is_protobuf_of_our_schema_and_every_message_decodes() {
    let (_, path, _) = sphere_session();
    let recorded = read_session_file(path, &Default::default()).unwrap();
    let ours = services::session::proto::FILE_DESCRIPTOR_SET;
    for topic in RAW_TOPICS {
        assert_eq!(
            recorded.topics[topic].schema.as_ref().unwrap().data[..],
            ours[..]
        );
    }
    let n = decode_all::<proto::GloveJointStatesProto>(
        &recorded,
        TOPIC_GLOVE_JOINT_STATES,
        RAW_SCHEMA_NAMES[0],
    )
    .len();
    assert_eq!(
        decode_all::<proto::GloveFeedbackProto>(
            &recorded,
            TOPIC_GLOVE_FEEDBACK,
            RAW_SCHEMA_NAMES[1]
        )
        .len(),
        n
    );
    assert_eq!(
        decode_all::<proto::ContactsProto>(&recorded, TOPIC_CONTACTS, RAW_SCHEMA_NAMES[2]).len(),
        n
    );
    assert_eq!(
        decode_all::<proto::ObjectStateProto>(&recorded, TOPIC_OBJECT_STATE, RAW_SCHEMA_NAMES[3])
            .len(),
        n
    );
    let session = read_session(path).unwrap();
    assert_eq!(session.metadata["format_version"], "2");
}

#[test]
fn the_icms_schemas_reject_a_message_missing_a_field() {
    let (_, path, _) = sphere_session();
    let session = read_session(path).unwrap();
    let mut v = serde_json::to_value(&session.object[0].1).unwrap();
    v.as_object_mut().unwrap().remove("pose_in_hand");
    assert!(rejects(&OBJECT_STATE_SCHEMA, &v));
    let mut v = serde_json::to_value(&session.contacts[0].1).unwrap();
    v["fingers"][0]["slip"] = serde_json::json!("no");
    assert!(rejects(&CONTACTS_SCHEMA, &v));
}

#[test]
fn the_python_reader_reads_every_message_of_a_simulated_session() {
    let (_, path, summary) = sphere_session();
    // The reference reader (`scripts/test` sets up its interpreter; a plain `cargo test`
    // without it skips this check, saying so).
    let Some(report) =
        common::python_mcap_report(path, &["mcap", "zstandard", "lz4", "mcap_protobuf"])
    else {
        return;
    };
    for (topic, n) in &summary.write.messages_per_topic {
        assert_eq!(report["topics"][topic], serde_json::json!(n), "{topic}");
        // Every topic is protobuf, decoded from the schemas inside the file alone.
        assert_eq!(report["decoded"][topic], serde_json::json!(n), "{topic}");
    }
    assert_eq!(
        report["first"][TOPIC_OBJECT_STATE]["pose"]["orientation"]["w_e6"], 1_000_000,
        "the sphere rests upright at the start"
    );
    assert_eq!(
        report["messages"],
        serde_json::json!(summary.write.messages)
    );
    assert_eq!(report["schemas"][TOPIC_CONTACTS], "icms.Contacts");
    assert_eq!(report["metadata"]["session"]["scenario"], "sphere-lift");
    let phases: Vec<GroundTruthPhase> = serde_json::from_str(
        report["metadata"]["ground_truth"]["phases"]
            .as_str()
            .unwrap(),
    )
    .unwrap();
    assert!(!phases.is_empty());
}

#[test]
fn the_same_scenario_and_seed_give_byte_identical_files() {
    let (_, first, _) = sphere_session();
    let dir = tempfile::tempdir().unwrap();
    let second = dir.path().join("again.mcap");
    let scenario = Scenario::builtin("sphere-lift", 7).unwrap();
    record_simulation(&scenario, Some(SECONDS), &second, |_, _| {}).unwrap();
    // Byte for byte: `started_at` is fixed unless a live recording passes its start.
    assert_eq!(
        std::fs::read(first).unwrap(),
        std::fs::read(&second).unwrap()
    );
    let a = read_session_file(first, &Default::default()).unwrap();
    let b = read_session_file(&second, &Default::default()).unwrap();
    assert_eq!(a.topics, b.topics);
    let other = dir.path().join("other-seed.mcap");
    let scenario = Scenario::builtin("sphere-lift", 8).unwrap();
    record_simulation(&scenario, Some(0.5), &other, |_, _| {}).unwrap();
    let c = read_session_file(&other, &Default::default()).unwrap();
    assert_ne!(
        a.topics[TOPIC_GLOVE_JOINT_STATES].messages[..500],
        c.topics[TOPIC_GLOVE_JOINT_STATES].messages[..],
        "another seed gives other sensor noise"
    );
}

#[test]
fn progress_is_reported_up_to_the_total() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = Scenario::builtin("box-pinch-lift", 1).unwrap();
    let mut calls = Vec::new();
    record_simulation(&scenario, Some(0.3), &dir.path().join("p.mcap"), |d, t| {
        calls.push((d, t))
    })
    .unwrap();
    assert_eq!(calls.last(), Some(&(300, 300)));
    assert!(calls.windows(2).all(|w| w[0].0 < w[1].0));
}

/// A CSV of glove10 angles and torques: the first `seconds` of the simulated session, every
/// 2 ms; `bad_at` replaces one angle with a value far outside the joint limits from that line on.
fn csv_from_session(session: &Session, seconds: f64, bad_at: Option<usize>) -> String {
    let names = &session.joint_states[0].1.names;
    let mut text = String::from("# glove10 test recording\ntime_s");
    for n in names {
        text += &format!(",{n}");
    }
    for n in names {
        text += &format!(",tau_{n}");
    }
    text.push('\n');
    let rows = (seconds * 1000.0) as usize;
    for (row, (t, js)) in session
        .joint_states
        .iter()
        .take(rows)
        .step_by(2)
        .enumerate()
    {
        text += &format!("{}", *t as f64 * 1e-9 + 10.0);
        for (d, q) in js.positions.iter().enumerate() {
            let q = if bad_at.is_some_and(|b| row >= b) && d == 4 {
                40.0
            } else {
                *q
            };
            text += &format!(",{q}");
        }
        for tau in &js.efforts {
            text += &format!(",{tau}");
        }
        text.push('\n');
    }
    text
}

#[test]
fn importing_a_glove_csv_produces_a_session_that_reads_back() {
    let (_, path, _) = sphere_session();
    let session = read_session(path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("glove.csv");
    std::fs::write(&csv, csv_from_session(&session, 1.0, None)).unwrap();
    let out = dir.path().join("imported.mcap");
    let summary = import_glove(
        &csv,
        &scenario_object("sphere-lift"),
        &ImportOptions::default(),
        &out,
    )
    .unwrap();
    // Samples at 0, 2, ..., 998 ms: 999 ticks at 1 kHz.
    assert_eq!(summary.ticks, 999);
    let imported = read_session(&out).unwrap();
    assert_eq!(imported.ticks(), 999);
    assert!(imported.phases.is_empty());
    assert_eq!(imported.metadata["source"], "import-glove");
    // Even ticks carry the recorded samples; odd ones are interpolated between them.
    assert_eq!(
        imported.joint_states[10].1.positions,
        session.joint_states[10].1.positions
    );
    assert_eq!(imported.joint_states[10].0, 10_000_000);
}

#[test]
fn importing_glove_joint_states_from_an_mcap_produces_a_session_that_reads_back() {
    let (_, path, _) = sphere_session();
    let session = read_session(path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("glove.mcap");
    let mut w = SessionWriter::create(&input).unwrap();
    w.register_channel("/glove", &JOINT_STATES_SCHEMA).unwrap();
    for (t, js) in session.joint_states.iter().take(500) {
        let msg = services::foxglove::JointStates {
            timestamp: services::foxglove::Timestamp::from_nanos(*t),
            joints: js
                .names
                .iter()
                .enumerate()
                .map(|(d, name)| services::foxglove::JointState {
                    name: name.clone(),
                    position: Some(js.positions[d]),
                    velocity: None,
                    acceleration: None,
                    effort: Some(js.efforts[d]),
                })
                .collect(),
        };
        w.write("/glove", *t + 5_000_000_000, &msg).unwrap();
    }
    w.finish().unwrap();
    let out = dir.path().join("imported.mcap");
    let summary = import_glove(
        &input,
        &scenario_object("sphere-lift"),
        &ImportOptions::default(),
        &out,
    )
    .unwrap();
    assert_eq!(summary.ticks, 500);
    let imported = read_session(&out).unwrap();
    assert_eq!(imported.ticks(), 500);
    assert_eq!(imported.joint_states[123].1, {
        let mut expected = session.joint_states[123].1.clone();
        expected.velocities = imported.joint_states[123].1.velocities.clone();
        expected
    });
}

#[test]
fn an_import_that_fails_midway_leaves_a_readable_file_up_to_the_failure() {
    let (_, path, _) = sphere_session();
    let session = read_session(path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("bad.csv");
    // From line 300 (t = 0.6 s) on, one angle is far outside its limits.
    std::fs::write(&csv, csv_from_session(&session, 1.0, Some(300))).unwrap();
    let out = dir.path().join("partial.mcap");
    let err = import_glove(
        &csv,
        &scenario_object("sphere-lift"),
        &ImportOptions::default(),
        &out,
    )
    .unwrap_err();
    let RecordingError::Simulation { time_ns, .. } = &err else {
        panic!("expected a simulation error, got {err}");
    };
    assert!(
        (590_000_000..=600_000_000).contains(time_ns),
        "{time_ns}: {err}"
    );
    assert!(err.to_string().contains("t = 0.5"), "{err}");
    let partial = read_session(&out).unwrap();
    assert_eq!(partial.ticks() as u64, time_ns / 1_000_000);
}

/// The columns of a glove CSV: time, the angles, then the torques (`tau_<dof>`).
fn glove_csv_header(hand: &HandModel) -> Vec<String> {
    std::iter::once("time_s".to_owned())
        .chain(hand.dof_names.iter().cloned())
        .chain(hand.dof_names.iter().map(|n| format!("tau_{n}")))
        .collect()
}

#[test]
fn bad_glove_csv_input_is_rejected_naming_the_line_and_column() {
    let hand = HandModel::glove10();
    let header = glove_csv_header(&hand);
    let row = |v: &str| {
        let mut r = vec!["0.0".to_owned()];
        r.extend(std::iter::repeat_n(v.to_owned(), header.len() - 1));
        r.join(",")
    };
    let err = |text: String| {
        parse_glove_csv(&text, "g.csv", &hand)
            .unwrap_err()
            .to_string()
    };

    let mut unknown = header.clone();
    unknown[3] = "pinky_twist".into();
    let e = err(format!("{}\n{}\n", unknown.join(","), row("0")));
    assert!(
        e.contains("line 1, column 4") && e.contains("pinky_twist"),
        "{e}"
    );

    let e = err(format!("{}\n{}\n0.001,0.0\n", header.join(","), row("0")));
    assert!(e.contains("g.csv line 3") && e.contains("columns"), "{e}");

    let e = err(format!("{}\n{}\n", header.join(","), row("NaN")));
    assert!(
        e.contains("line 2, column") && e.contains("not a finite number"),
        "{e}"
    );

    let e = err(format!("{}\n", header[..header.len() - 1].join(",")));
    assert!(e.contains("missing column tau_"), "{e}");

    let e = err(format!(
        "{}\n{}\n{}\n",
        header.join(","),
        row("0"),
        row("0")
    ));
    assert!(e.contains("line 3, column time_s"), "{e}");
}

#[test]
fn a_glove_recording_shorter_than_the_shortest_phase_is_refused() {
    let hand = HandModel::glove10();
    let header = glove_csv_header(&hand).join(",");
    let row = |t: f64| {
        let mut r = vec![t.to_string()];
        r.extend(std::iter::repeat_n(
            "0".to_owned(),
            2 * hand.dof_names.len(),
        ));
        r.join(",")
    };
    let dir = tempfile::tempdir().unwrap();
    let import = |rows: &[f64]| {
        let input = dir.path().join("g.csv");
        let text: Vec<String> = rows.iter().map(|&t| row(t)).collect();
        std::fs::write(&input, format!("{header}\n{}\n", text.join("\n"))).unwrap();
        import_glove(
            &input,
            &scenario_object("sphere-lift"),
            &ImportOptions::default(),
            &dir.path().join("out.mcap"),
        )
    };
    for rows in [&[0.0][..], &[0.0, 0.001], &[0.0, 0.049]] {
        let e = import(rows).unwrap_err().to_string();
        assert!(
            e.contains("g.csv") && e.contains("shortest session, 0.05 s"),
            "{e}"
        );
    }
    let summary = import(&[0.0, 0.05]).unwrap();
    assert_eq!(summary.ticks, 51);
    let back = read_session(dir.path().join("out.mcap")).unwrap();
    assert_eq!(back.ticks(), 51);
}

#[test]
fn glove_mcap_input_with_an_unknown_joint_is_rejected_naming_the_message() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("glove.mcap");
    let mut w = SessionWriter::create(&input).unwrap();
    w.register_channel("/glove", &JOINT_STATES_SCHEMA).unwrap();
    let msg = services::foxglove::JointStates {
        timestamp: Default::default(),
        joints: vec![services::foxglove::JointState {
            name: "elbow".into(),
            position: Some(0.0),
            effort: Some(0.0),
            ..Default::default()
        }],
    };
    w.write("/glove", 0, &msg).unwrap();
    w.finish().unwrap();
    let e = read_glove_mcap(&input, &HandModel::glove10())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("message 0") && e.contains("joints[0].name") && e.contains("elbow"),
        "{e}"
    );
}

#[test]
fn a_file_without_the_raw_topics_or_with_foreign_schemas_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("not-a-session.mcap");
    let mut w = SessionWriter::create(&path).unwrap();
    w.register_channel(TOPIC_JOINT_STATES, &JOINT_STATES_SCHEMA)
        .unwrap();
    w.write(TOPIC_JOINT_STATES, 0, &common::example_joint_states(0))
        .unwrap();
    w.finish().unwrap();
    let e = read_session(&path).unwrap_err();
    assert!(
        matches!(&e, RecordingError::MissingTopic { topic } if topic == TOPIC_GLOVE_JOINT_STATES),
        "{e}"
    );

    let path = dir.path().join("foreign.mcap");
    let mut w = SessionWriter::create(&path).unwrap();
    for topic in RAW_TOPICS {
        w.register_channel(topic, &JOINT_STATES_SCHEMA).unwrap();
    }
    w.finish().unwrap();
    let e = read_session(&path).unwrap_err();
    assert!(matches!(e, RecordingError::UnknownSchema { .. }), "{e}");
    assert!(e.to_string().contains("icms.GloveJointStates"), "{e}");
}

#[test]
fn a_tick_with_a_nan_is_refused_and_the_rest_of_the_session_still_reads() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nan.mcap");
    let scenario = Scenario::builtin("sphere-lift", 1).unwrap();
    let mut sim = Simulation::new(&scenario, HandModel::glove10(), Some(0.1)).unwrap();
    let dfs = sim.dfs();
    let mut rec = SessionRecorder::create(
        &path,
        dfs.hand(),
        dfs.object(),
        &SessionInfo {
            scenario: "nan-test".into(),
            ..Default::default()
        },
    )
    .unwrap();
    let mut refused = 0;
    while sim.step().unwrap() {
        let (q, tau, base) = sim.sample();
        let mut tau = tau.to_vec();
        if sim.ticks() == 50 {
            tau[2] = f64::NAN;
        }
        let tick = TickData {
            time_ns: sim.time_ns(),
            q,
            tau: &tau,
            base,
            output: sim.output(),
            body: sim.dfs().body_contacts(),
            kinematics: sim.dfs().kinematics(),
        };
        match rec.record(&tick) {
            Ok(()) => {}
            Err(RecordingError::NonFiniteNumber { topic, path, .. }) => {
                assert_eq!(topic, TOPIC_GLOVE_JOINT_STATES);
                assert_eq!(path, "efforts[2]");
                refused += 1;
            }
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(refused, 1);
    let summary = rec.finish().unwrap();
    assert_eq!(summary.ticks, 99);
    let session = read_session(&path).unwrap();
    assert_eq!(session.ticks(), 99);
    let counts: BTreeMap<_, _> = RAW_TOPICS
        .iter()
        .map(|t| (t.to_string(), 99usize))
        .collect();
    for (t, n) in counts {
        assert_eq!(session.message_counts[&t], n);
    }
}

#[test]
fn a_topic_left_undecoded_is_still_checked_for_valid_json() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad-feedback.mcap");
    let mut w = SessionWriter::create(&path).unwrap();
    for (topic, schema) in RAW_TOPICS.iter().zip(ICMS_SCHEMAS.iter()) {
        w.register_channel(topic, schema).unwrap();
    }
    for t in [0, MS] {
        w.write(TOPIC_CONTACTS, t, &contacts()).unwrap();
        w.write(TOPIC_OBJECT_STATE, t, &ObjectState::default())
            .unwrap();
        w.write(TOPIC_GLOVE_JOINT_STATES, t, &joint_states())
            .unwrap();
    }
    w.write(TOPIC_GLOVE_FEEDBACK, 0, &feedback()).unwrap();
    w.write_raw(TOPIC_GLOVE_FEEDBACK, MS, b"{\"names\": [")
        .unwrap();
    w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    for topics in [DecodeTopics::ALL, DecodeTopics::SEGMENTATION] {
        let e = read_session_bytes_with(&bytes, "bad", &Default::default(), topics).unwrap_err();
        assert!(
            matches!(&e, RecordingError::InvalidJson { topic, log_time_ns: MS, .. }
                if topic == TOPIC_GLOVE_FEEDBACK),
            "{topics:?}: {e}"
        );
    }
    // Decoding only what segmentation needs leaves the other raw topics empty.
    let bytes = raw_topics_file(&two_ticks_each(), None);
    let s = read_session_bytes_with(
        &bytes,
        "good",
        &Default::default(),
        DecodeTopics::SEGMENTATION,
    )
    .unwrap();
    assert_eq!((s.contacts.len(), s.object.len()), (2, 2));
    assert_eq!((s.joint_states.len(), s.feedback.len()), (0, 0));
    assert_eq!(s.message_counts[TOPIC_GLOVE_FEEDBACK], 2);
}

/// One millisecond (ns).
const MS: u64 = 1_000_000;

/// The DOFs of the small hand of the hand-made files below.
const DOFS: [&str; 2] = ["j0", "j1"];
/// Its fingertips.
const TIPS: [&str; 2] = ["thumb", "index"];

/// A `/glove/joint_states` message of the small hand.
fn joint_states() -> GloveJointStates {
    GloveJointStates {
        names: DOFS.map(String::from).to_vec(),
        positions: vec![0.1, 0.2],
        velocities: vec![0.0; 2],
        efforts: vec![0.0; 2],
    }
}

/// A `/glove/feedback` message of the small hand.
fn feedback() -> GloveFeedback {
    GloveFeedback {
        names: DOFS.map(String::from).to_vec(),
        motor_positions: vec![0.1, 0.2],
        motor_velocities: vec![0.0; 2],
        feedback_torques: vec![0.0; 2],
        fingers: TIPS
            .iter()
            .map(|name| FingerFeedback {
                name: name.to_string(),
                ..FingerFeedback::default()
            })
            .collect(),
    }
}

/// A `/dfs/contacts` message of the small hand: no contact.
fn contacts() -> Contacts {
    Contacts {
        n_contacts: 0,
        fingers: TIPS
            .iter()
            .map(|name| FingerContact {
                name: name.to_string(),
                ..FingerContact::default()
            })
            .collect(),
    }
}

/// Two ticks (0 and 1 ms) on every raw topic: the shortest session read.
fn two_ticks_each() -> Vec<(&'static str, u64)> {
    RAW_TOPICS
        .iter()
        .flat_map(|t| [(*t, 0), (*t, MS)])
        .collect()
}

/// A file with the four raw topics (two ticks of the small hand) and a `session` metadata
/// record whose `object` is `object`.
fn file_with_session_object(object: &str) -> Vec<u8> {
    let meta = BTreeMap::from([("object".to_owned(), object.to_owned())]);
    raw_topics_file(&two_ticks_each(), Some(meta))
}

#[test]
fn a_session_whose_object_is_impossible_is_refused_naming_the_field() {
    let good = r#"{"shape":"box","half_extents":[0.025,0.025,0.04],"mass":0.2,"mu":0.8}"#;
    read_session_bytes(&file_with_session_object(good), "good", &Default::default()).unwrap();
    // Each used to be read (and stored by an upload) as it was: a skill of mass -1 that the
    // store's mass filters and every replay then tripped over; an object that did not parse
    // at all became shape "unknown" with mass 0.
    for (object, names) in [
        (good.replace("0.2", "-1"), "object.mass"),
        (good.replace("0.2", "0"), "object.mass"),
        (good.replace("[0.025,", "[-0.025,"), "half_extents"),
        (good.replace("0.8", "-0.5"), "object.mu"),
        (good.replace("0.8", "1e999"), "number out of range"),
        (good.replace("box", "torus"), "object.shape"),
        ("not json".to_owned(), "expected"),
    ] {
        let e = read_session_bytes(
            &file_with_session_object(&object),
            "odd",
            &Default::default(),
        )
        .unwrap_err();
        let text = e.to_string();
        assert!(
            matches!(e, RecordingError::InvalidInput { .. })
                && text.contains("session.object")
                && text.contains(names),
            "{object}: {text}"
        );
    }
}

/// A file with the four raw topics, one message of the small hand each per `(topic, log time)`
/// of `times`, and `session` metadata when given.
fn raw_topics_file(times: &[(&str, u64)], session: Option<BTreeMap<String, String>>) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("times.mcap");
    let mut w = SessionWriter::create(&path).unwrap();
    for (topic, schema) in RAW_TOPICS.iter().zip(ICMS_SCHEMAS.iter()) {
        w.register_channel(topic, schema).unwrap();
    }
    for &(topic, t) in times {
        match topic {
            TOPIC_CONTACTS => w.write(topic, t, &contacts()),
            TOPIC_OBJECT_STATE => w.write(topic, t, &ObjectState::default()),
            TOPIC_GLOVE_JOINT_STATES => w.write(topic, t, &joint_states()),
            _ => w.write(topic, t, &feedback()),
        }
        .unwrap();
    }
    if let Some(meta) = session {
        w.add_metadata(SESSION_METADATA, meta).unwrap();
    }
    w.finish().unwrap();
    std::fs::read(&path).unwrap()
}

#[test]
fn raw_topics_whose_log_times_go_back_or_span_more_than_two_hours_are_refused() {
    let ticks = |topic| (0..3).map(move |k| (topic, k * 1_000_000));
    let ok: Vec<(&str, u64)> = RAW_TOPICS.iter().flat_map(|t| ticks(*t)).collect();
    let session =
        read_session_bytes(&raw_topics_file(&ok, None), "ok", &Default::default()).unwrap();
    assert_eq!(session.object.len(), 3);

    // One object state a day after the rest: segmentation would resample the whole day.
    let mut far = ok.clone();
    far.push((TOPIC_OBJECT_STATE, 86_400_000_000_000));
    // An object state that goes back in time.
    let mut back = ok.clone();
    back.push((TOPIC_OBJECT_STATE, 500_000));
    // A log time the store's signed columns cannot hold.
    let mut huge = ok.clone();
    huge.push((TOPIC_OBJECT_STATE, u64::MAX));
    for (times, want) in [
        (far, "a session spans at most 7260 s"),
        (back, "goes back before the previous message's"),
        (huge, "beyond 2^63 ns"),
    ] {
        let bytes = raw_topics_file(&times, None);
        for topics in [DecodeTopics::ALL, DecodeTopics::SEGMENTATION] {
            let e = read_session_bytes_with(&bytes, "odd.mcap", &Default::default(), topics)
                .unwrap_err();
            let text = e.to_string();
            assert!(
                matches!(e, RecordingError::InvalidInput { .. })
                    && text.contains("topic /object/state message 3 (log time")
                    && text.contains(want),
                "{text}"
            );
        }
    }
}

#[test]
fn raw_topics_that_are_empty_stand_still_or_stop_early_are_refused_naming_the_topic() {
    // 0.5 s of ticks on every raw topic but `short`, which has `short_ticks` of them from
    // `from`.
    let file = |short: &'static str, from: u64, short_ticks: u64, step: u64| {
        let times: Vec<(&str, u64)> = RAW_TOPICS
            .iter()
            .flat_map(|&t| {
                let (a, n, dt) = if t == short {
                    (from, short_ticks, step)
                } else {
                    (0, 500, 1_000_000)
                };
                (0..n).map(move |k| (t, a + k * dt))
            })
            .collect();
        raw_topics_file(&times, None)
    };
    let ms = 1_000_000;
    read_session_bytes(
        &file(TOPIC_OBJECT_STATE, 0, 500, ms),
        "whole",
        &Default::default(),
    )
    .unwrap();
    // Each was read as a session (an upload stored it): with no contacts or no object states
    // it gave no skill, with an object stream that stops at 0.2 s a shorter skill than the
    // glove stream says.
    let mut cases = vec![];
    for topic in RAW_TOPICS {
        cases.push((file(topic, 0, 0, ms), topic, "has no messages".to_owned()));
        cases.push((
            file(topic, 0, 500, 0),
            topic,
            "the same log time".to_owned(),
        ));
    }
    cases.push((
        file(TOPIC_OBJECT_STATE, 0, 200, ms),
        TOPIC_OBJECT_STATE,
        "ends at 0.199 s, 0.300 s before the session's last raw message".to_owned(),
    ));
    cases.push((
        file(TOPIC_CONTACTS, 300 * ms, 200, ms),
        TOPIC_CONTACTS,
        "starts at 0.300 s".to_owned(),
    ));
    for (bytes, topic, want) in cases {
        for topics in [DecodeTopics::ALL, DecodeTopics::SEGMENTATION] {
            let e = read_session_bytes_with(&bytes, "odd.mcap", &Default::default(), topics)
                .unwrap_err();
            let text = e.to_string();
            assert!(
                matches!(e, RecordingError::InvalidInput { .. })
                    && text.contains(&format!("topic {topic}"))
                    && text.contains(&want),
                "{topic} {want}: {text}"
            );
        }
    }
}

#[test]
fn glove_mcap_input_spanning_more_than_an_hour_is_rejected_naming_the_message() {
    let hand = HandModel::glove10();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("glove.mcap");
    let mut w = SessionWriter::create(&input).unwrap();
    w.register_channel("/glove", &JOINT_STATES_SCHEMA).unwrap();
    let msg = services::foxglove::JointStates {
        timestamp: Default::default(),
        joints: hand
            .dof_names
            .iter()
            .map(|name| services::foxglove::JointState {
                name: name.clone(),
                position: Some(0.0),
                effort: Some(0.0),
                ..Default::default()
            })
            .collect(),
    };
    // Replayed at 1 kHz, the second message would ask for 10^15 ticks.
    for t in [0, 1_000_000, 1_000_000_000_000_000_000] {
        w.write("/glove", t, &msg).unwrap();
    }
    w.finish().unwrap();
    let e = read_glove_mcap(&input, &hand).unwrap_err().to_string();
    assert!(
        e.contains("message 2") && e.contains("log time") && e.contains("one hour"),
        "{e}"
    );
}

#[test]
fn a_glove_csv_saved_with_a_byte_order_mark_reads_like_one_without() {
    let hand = HandModel::glove10();
    let header = glove_csv_header(&hand);
    let zeros = vec!["0.0"; header.len() - 1].join(",");
    let text = format!("{}\n0.0,{zeros}\n0.01,{zeros}\n", header.join(","));
    let plain = parse_glove_csv(&text, "g.csv", &hand).unwrap();
    let with_bom = parse_glove_csv(&format!("\u{feff}{text}"), "g.csv", &hand).unwrap();
    assert_eq!(with_bom, plain);
    assert_eq!(plain.len(), 2);
}

/// `bytes` written again with every chunk compressed by `compression` (messages, schemas,
/// channels and metadata as they were), by the mcap crate's own writer.
fn recompressed(bytes: &[u8], compression: mcap::Compression) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    let mut w = mcap::WriteOptions::new()
        .compression(Some(compression))
        .create(&mut out)
        .unwrap();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        w.write(&m.unwrap()).unwrap();
    }
    for r in mcap::read::LinearReader::new(bytes).unwrap() {
        if let mcap::records::Record::Metadata(m) = r.unwrap() {
            w.write_metadata(&m).unwrap();
        }
    }
    w.finish().unwrap();
    drop(w);
    out.into_inner()
}

#[test]
fn a_session_in_lz4_chunks_reads_and_salvages_like_the_zstd_one() {
    // LZ4 is the MCAP CLI's and Foxglove's other chunk compression: it was refused as an
    // "unsupported compression".
    let (_, path, _) = sphere_session();
    let zstd = std::fs::read(path).unwrap();
    let lz4 = recompressed(&zstd, mcap::Compression::Lz4);
    let expected = read_session(path).unwrap();
    let read = read_session_bytes(&lz4, "lz4.mcap", &Default::default()).unwrap();
    assert_eq!(read, expected);
    let dir = tempfile::tempdir().unwrap();
    let (input, out) = (dir.path().join("lz4.mcap"), dir.path().join("out.mcap"));
    std::fs::write(&input, &lz4).unwrap();
    let report = services::mcap_io::salvage(&input, &out).unwrap();
    assert!(
        report.input_was_complete && report.stop_reason.is_none(),
        "{report:?}"
    );
    assert_eq!(read_session(&out).unwrap(), expected);
}

#[test]
fn chunks_in_an_unknown_compression_are_refused_and_salvage_recovers_nothing_from_them() {
    let (_, path, _) = sphere_session();
    let mut bytes = recompressed(&std::fs::read(path).unwrap(), mcap::Compression::Lz4);
    // Every chunk (and chunk index) says "zz4" instead of "lz4".
    let mut renamed = 0;
    for i in 0..bytes.len() - 7 {
        if bytes[i..i + 7] == [3, 0, 0, 0, b'l', b'z', b'4'] {
            bytes[i + 4] = b'z';
            renamed += 1;
        }
    }
    assert!(renamed >= 2, "{renamed}");
    let e = read_session_bytes(&bytes, "odd.mcap", &Default::default()).unwrap_err();
    assert!(
        e.to_string().contains("unsupported compression \"zz4\""),
        "{e}"
    );
    // Salvage said it recovered a file (0 messages, exit 0) and left an empty one behind.
    let dir = tempfile::tempdir().unwrap();
    let (input, out) = (dir.path().join("odd.mcap"), dir.path().join("out.mcap"));
    std::fs::write(&input, &bytes).unwrap();
    let e = services::mcap_io::salvage(&input, &out).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("no message could be recovered") && text.contains("zz4"),
        "{text}"
    );
    assert!(!out.exists());
}

#[test]
fn a_session_that_does_not_name_its_object_is_not_segmented_or_stored() {
    // It was stored with skills of shape "unknown", mass 0 and μ 0, which no replay can use.
    let ticks: Vec<(&str, u64)> = RAW_TOPICS
        .iter()
        .flat_map(|&t| (0..300).map(move |k| (t, k * 1_000_000)))
        .collect();
    let object = r#"{"shape":"box","half_extents":[0.025,0.025,0.04],"mass":0.2,"mu":0.8}"#;
    let with = |meta: Option<&[(&str, &str)]>| {
        let meta = meta.map(|m| {
            m.iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        });
        raw_topics_file(&ticks, meta)
    };
    services::ingest::analyse(&with(Some(&[("object", object)])), "named.mcap").unwrap();
    for (bytes, want) in [
        (with(None), "has no `session` metadata record"),
        (
            with(Some(&[("scenario", "mine")])),
            "has no `object` in its `session` metadata record",
        ),
        (with(Some(&[("object", " ")])), "has no `object`"),
    ] {
        let e = services::ingest::analyse(&bytes, "odd.mcap").unwrap_err();
        let text = e.to_string();
        assert!(
            matches!(e, RecordingError::InvalidInput { .. })
                && text.starts_with("odd.mcap: ")
                && text.contains(want),
            "{text}"
        );
        let session = read_session_bytes(&bytes, "odd.mcap", &Default::default()).unwrap();
        assert!(session.ensure_grasp_session("odd.mcap").is_err());
    }
}

/// The sphere session rewritten message by message through `SessionWriter`: `schema` may
/// replace a topic's schema data, `message` a message's bytes (topic, index, bytes).
fn rewritten(
    schema: impl Fn(&str, &[u8]) -> Vec<u8>,
    message: impl Fn(&str, usize, &[u8]) -> Vec<u8>,
) -> Vec<u8> {
    let (_, path, _) = sphere_session();
    let recorded = read_session_file(path, &Default::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rewritten.mcap");
    let mut w = SessionWriter::create(&out).unwrap();
    for m in &recorded.metadata {
        w.add_metadata(&m.name, m.entries.clone()).unwrap();
    }
    for (topic, t) in &recorded.topics {
        let s = t.schema.as_ref().unwrap();
        w.register_protobuf_channel(topic, &s.name, &schema(topic, &s.data))
            .unwrap();
    }
    // In tick order, as the recorder writes them.
    let mut all: Vec<(u64, &str, usize, &[u8])> = recorded
        .topics
        .iter()
        .flat_map(|(topic, t)| {
            t.messages
                .iter()
                .enumerate()
                .map(move |(i, m)| (m.log_time_ns, topic.as_str(), i, &m.data[..]))
        })
        .collect();
    all.sort_by_key(|m| m.0);
    for (time, topic, i, data) in all {
        w.write_raw(topic, time, &message(topic, i, data)).unwrap();
    }
    w.finish().unwrap();
    std::fs::read(out).unwrap()
}

#[test]
fn a_format_2_file_whose_raw_schema_differs_from_ours_is_refused_naming_the_field() {
    use prost::Message;
    let limits = Default::default();
    // Unchanged, the rewritten file reads.
    let same = rewritten(|_, d| d.to_vec(), |_, _, d| d.to_vec());
    read_session_bytes(&same, "same.mcap", &limits).unwrap();
    // The penetration's type changed in the schema of /dfs/contacts: decoding with it would
    // give other numbers, so the file is refused before any message is decoded.
    let bytes = rewritten(
        |topic, d| {
            if topic != TOPIC_CONTACTS {
                return d.to_vec();
            }
            let mut fds = prost_types::FileDescriptorSet::decode(d).unwrap();
            let m = fds.file[0]
                .message_type
                .iter_mut()
                .find(|m| m.name() == "FingerContact")
                .unwrap();
            let f = m
                .field
                .iter_mut()
                .find(|f| f.name() == "penetration_e9")
                .unwrap();
            f.set_type(prost_types::field_descriptor_proto::Type::Int64);
            fds.encode_to_vec()
        },
        |_, _, d| d.to_vec(),
    );
    let e = read_session_bytes(&bytes, "other.mcap", &limits).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("topic /dfs/contacts schema icms.Contacts")
            && text.contains("icms.Contacts.fingers.penetration_e9")
            && text.contains("int64"),
        "{text}"
    );
    // A schema that is not a descriptor set at all.
    let bytes = rewritten(
        |topic, d| {
            if topic == TOPIC_OBJECT_STATE {
                b"not protobuf".to_vec()
            } else {
                d.to_vec()
            }
        },
        |_, _, d| d.to_vec(),
    );
    let e = read_session_bytes(&bytes, "bad.mcap", &limits).unwrap_err();
    assert!(e.to_string().contains("icms.ObjectState"), "{e}");
}

#[test]
fn a_format_2_message_that_does_not_decode_is_refused_naming_topic_and_index() {
    let limits = Default::default();
    for (topic, index) in [
        (TOPIC_OBJECT_STATE, 17),
        (TOPIC_GLOVE_JOINT_STATES, 0),
        (TOPIC_TF, 3),
        (TOPIC_SCENE, 1),
    ] {
        // A length-delimited field that claims more bytes than the message has.
        let bytes = rewritten(
            |_, d| d.to_vec(),
            |t, i, d| {
                if t == topic && i == index {
                    let mut m = d.to_vec();
                    m.extend_from_slice(&[0x0a, 0xff, 0x01]);
                    m
                } else {
                    d.to_vec()
                }
            },
        );
        let e = read_session_bytes(&bytes, "x.mcap", &limits).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains(&format!("topic {topic} message {index} "))
                && text.contains("does not decode"),
            "{topic}: {text}"
        );
        // Nothing is stored from it: ingest refuses it as a whole.
        assert!(services::ingest::analyse(&bytes, "x.mcap").is_err());
    }
}

/// Every message path of the Foxglove layout we ship names a topic of a session and fields
/// its schema has (walked through the file's own descriptor sets).
#[test]
fn the_foxglove_layout_plots_fields_a_session_has() {
    use prost::Message;
    let layout: serde_json::Value = serde_json::from_str(include_str!(
        "../../../docs/foxglove/icms-session.layout.json"
    ))
    .unwrap();
    let (_, path, _) = sphere_session();
    let recorded = read_session_file(path, &Default::default()).unwrap();
    let mut paths = Vec::new();
    for panel in layout["configById"].as_object().unwrap().values() {
        for p in panel["paths"].as_array().into_iter().flatten() {
            paths.push(p["value"].as_str().unwrap().to_owned());
        }
        if let Some(t) = panel["topicPath"].as_str() {
            paths.push(t.to_owned());
        }
        for t in panel["topics"]
            .as_object()
            .into_iter()
            .flat_map(|m| m.keys())
        {
            paths.push(t.clone());
        }
    }
    assert!(paths.len() >= 8, "{paths:?}");
    for p in &paths {
        let topic = recorded
            .topics
            .keys()
            .filter(|t| p == *t || p.starts_with(&format!("{t}.")))
            .max_by_key(|t| t.len())
            .unwrap_or_else(|| panic!("{p}: no such topic in a session"));
        let schema = recorded.topics[topic].schema.as_ref().unwrap();
        let fds = prost_types::FileDescriptorSet::decode(&schema.data[..]).unwrap();
        let find = |full: &str| {
            fds.file
                .iter()
                .flat_map(|f| {
                    f.message_type
                        .iter()
                        .map(move |m| (format!(".{}.{}", f.package(), m.name()), m))
                })
                .find(|(n, _)| n == full)
                .map(|(_, m)| m.clone())
                .unwrap_or_else(|| panic!("{p}: {full} not in the schema"))
        };
        let mut message = find(&format!(".{}", schema.name));
        let rest = p[topic.len()..].trim_start_matches('.');
        for name in rest.split('.').filter(|s| !s.is_empty()) {
            let name = name.split('[').next().unwrap();
            let field = message
                .field
                .iter()
                .find(|f| f.name() == name)
                .unwrap_or_else(|| panic!("{p}: {} has no field {name}", message.name()))
                .clone();
            if !field.type_name().is_empty() {
                message = find(field.type_name());
            }
        }
    }
}

#[test]
fn an_oversized_format_2_message_is_refused_on_a_raw_topic_and_left_unchecked_on_a_foxglove_one() {
    let limits = Default::default();
    // An unknown length-delimited field (number 99) of 300 kB: prost would skip it, but a
    // message that large is refused before it is decoded.
    let padding = |d: &[u8]| {
        let mut m = d.to_vec();
        m.extend_from_slice(&[0x9a, 0x06]); // field 99, wire type 2
        let n = 300_000u32;
        let mut v = n;
        while v >= 0x80 {
            m.push((v as u8) | 0x80);
            v >>= 7;
        }
        m.push(v as u8);
        m.extend(std::iter::repeat_n(0u8, n as usize));
        m
    };
    // Message 0 too, which is read first as the session's reference for names.
    for index in [5, 0] {
        let bytes = rewritten(
            |_, d| d.to_vec(),
            |t, i, d| {
                if t == TOPIC_CONTACTS && i == index {
                    padding(d)
                } else {
                    d.to_vec()
                }
            },
        );
        let e = read_session_bytes(&bytes, "big.mcap", &limits).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains(&format!("topic /dfs/contacts message {index} "))
                && text.contains(&format!("at most {MAX_RAW_MESSAGE_BYTES}")),
            "{text}"
        );
    }
    // A raw topic's schema padded with 100 000 empty file descriptors (2 bytes each on the wire,
    // hundreds in memory) is refused before it is decoded.
    let bytes = rewritten(
        |topic, d| {
            let mut d = d.to_vec();
            if topic == TOPIC_GLOVE_JOINT_STATES {
                for _ in 0..100_000 {
                    d.extend_from_slice(&[0x0a, 0x00]);
                }
            }
            d
        },
        |_, _, d| d.to_vec(),
    );
    let e = read_session_bytes(&bytes, "schema.mcap", &limits).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("topic /glove/joint_states schema icms.GloveJointStates")
            && text.contains(&format!("at most {MAX_RAW_SCHEMA_BYTES}")),
        "{text}"
    );
    // 150 000 empty scene entities (2 bytes each on the wire, hundreds in memory) and a
    // malformed tail: the message is not decoded (it would not decode), and the session reads.
    let scene = |n: usize| {
        rewritten(
            |_, d| d.to_vec(),
            move |t, i, d| {
                if t == TOPIC_SCENE && i == 1 {
                    let mut m = d.to_vec();
                    for _ in 0..n {
                        m.extend_from_slice(&[0x12, 0x00]);
                    }
                    m.extend_from_slice(&[0x0a, 0xff, 0x01]);
                    m
                } else {
                    d.to_vec()
                }
            },
        )
    };
    read_session_bytes(&scene(150_000), "scene.mcap", &limits).unwrap();
    // Under the limit, the same tail is decoded and refused.
    let e = read_session_bytes(&scene(10), "scene.mcap", &limits).unwrap_err();
    assert!(e.to_string().contains("topic /scene message 1 "), "{e}");
}
