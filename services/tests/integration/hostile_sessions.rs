//! Session files whose framing is sound but whose content is not: arrays that disagree with
//! their names, no fingers, orientations that are no rotation, numbers JSON cannot hold as
//! finite, sessions of one tick, metadata repeated or huge. Each is refused by every read (a
//! full read, segmentation's, an upload's), naming the topic, the message and the field. The
//! files are written in session format 1 (JSON), where every fault can be written; each is
//! also written again in format 2 (protobuf) where it can be (30 of the 41 cases), and must
//! be refused there with the same words.

use std::collections::BTreeMap;

use dfs_core::hand::HandModel;
use serde_json::{json, Value};
use services::foxglove::Quaternion;
use services::mcap_io::{ReadLimits, SessionWriter};
use services::session::*;
use services::RecordingError;

const MS: u64 = 1_000_000;

/// The session's hand: glove10's DOFs and fingertips.
fn hand() -> (Vec<String>, Vec<String>) {
    let hand = HandModel::glove10();
    let tips = hand.fingertips.iter().map(|t| t.name.clone()).collect();
    (hand.dof_names.clone(), tips)
}

const OBJECT: &str = r#"{"shape":"box","half_extents":[0.025,0.025,0.04],"mass":0.2,"mu":0.8}"#;

/// The `session` metadata record of a valid session.
fn session_record() -> BTreeMap<String, String> {
    BTreeMap::from([
        ("object".to_owned(), OBJECT.to_owned()),
        ("scenario".to_owned(), "hostile".to_owned()),
    ])
}

/// The JSON text of tick `k`'s message on `topic`, valid.
fn message(topic: &str, k: u64) -> String {
    let (dofs, tips) = hand();
    let n = dofs.len();
    let q: Vec<f64> = (0..n)
        .map(|i| 0.01 * (i as f64 + k as f64 * 1e-3))
        .collect();
    let v = match topic {
        TOPIC_GLOVE_JOINT_STATES => serde_json::to_value(GloveJointStates {
            names: dofs,
            positions: q,
            velocities: vec![0.0; n],
            efforts: vec![0.01; n],
        }),
        TOPIC_GLOVE_FEEDBACK => serde_json::to_value(GloveFeedback {
            names: dofs,
            motor_positions: q,
            motor_velocities: vec![0.0; n],
            feedback_torques: vec![0.0; n],
            fingers: tips
                .iter()
                .map(|t| FingerFeedback {
                    name: t.clone(),
                    tip_force_world: services::foxglove::Vector3::new(0.1, 0.2, 0.3),
                    ..FingerFeedback::default()
                })
                .collect(),
        }),
        TOPIC_CONTACTS => serde_json::to_value(Contacts {
            n_contacts: 0,
            fingers: tips
                .iter()
                .map(|t| FingerContact {
                    name: t.clone(),
                    ..FingerContact::default()
                })
                .collect(),
        }),
        _ => {
            let mut o = ObjectState::default();
            o.pose.position.z = 0.04;
            o.f_ext_b = [0.0, 0.0, -1.962, 0.0, 0.0, 0.0];
            serde_json::to_value(o)
        }
    };
    v.unwrap().to_string()
}

/// A session file of `ticks` 1 ms ticks on the four raw topics with `metadata`, each message's
/// JSON text passed through `edit(topic, tick, text)` first.
fn session_file(
    ticks: u64,
    metadata: &[(&str, BTreeMap<String, String>)],
    edit: impl Fn(&str, u64, &mut String),
) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hostile.mcap");
    let mut w = SessionWriter::create(&path).unwrap();
    for (topic, schema) in RAW_TOPICS.iter().zip(ICMS_SCHEMAS.iter()) {
        w.register_channel(topic, schema).unwrap();
    }
    for (name, record) in metadata {
        w.add_metadata(name, record.clone()).unwrap();
    }
    for k in 0..ticks {
        for topic in RAW_TOPICS {
            let mut text = message(topic, k);
            edit(topic, k, &mut text);
            w.write_raw(topic, k * MS, text.as_bytes()).unwrap();
        }
    }
    w.finish().unwrap();
    std::fs::read(&path).unwrap()
}

/// A valid session of 30 ticks with `edit` applied.
fn edited(edit: impl Fn(&str, u64, &mut String)) -> Vec<u8> {
    session_file(30, &[(SESSION_METADATA, session_record())], edit)
}

/// `text` with the JSON value at `pointer` replaced by `value` (or added, in an object).
fn set(text: &mut String, pointer: &str, value: Value) {
    let mut v: Value = serde_json::from_str(text).unwrap();
    let (parent, key) = pointer.rsplit_once('/').unwrap();
    match v.pointer_mut(parent) {
        Some(Value::Object(o)) => {
            o.insert(key.to_owned(), value);
        }
        Some(Value::Array(a)) => a[key.parse::<usize>().unwrap()] = value,
        _ => panic!("no {pointer} in {text}"),
    }
    *text = v.to_string();
}

/// Edits message `tick` of `topic` (or every message, with `None`) by `f`.
fn on(
    topic: &'static str,
    tick: Option<u64>,
    f: impl Fn(&mut String),
) -> impl Fn(&str, u64, &mut String) {
    move |t, k, text| {
        if t == topic && tick.is_none_or(|tick| tick == k) {
            f(text)
        }
    }
}

/// Every way a session is read refuses `bytes` with an error whose text contains each of
/// `want`: a full read, segmentation's (two raw topics checked but not kept), an upload's.
#[track_caller]
fn assert_refused(bytes: &[u8], want: &[&str]) -> RecordingError {
    let limits = ReadLimits::default();
    let mut errors = Vec::new();
    for topics in [DecodeTopics::ALL, DecodeTopics::SEGMENTATION] {
        errors.push(read_session_bytes_with(bytes, "hostile.mcap", &limits, topics).unwrap_err());
    }
    errors.push(services::ingest::analyse(bytes, "hostile.mcap").unwrap_err());
    let first = errors[0].to_string();
    for e in &errors {
        let text = e.to_string();
        for w in want {
            assert!(text.contains(w), "{w:?} not in {text:?}");
        }
        assert_eq!(text, first, "the reads disagree");
    }
    // The same content in session format 2 (protobuf) is refused alike, where the edit can be
    // written there at all (a JSON-only fault such as a wrong type or 1e400 cannot).
    if let Some(v2) = in_format_2(bytes) {
        for topics in [DecodeTopics::ALL, DecodeTopics::SEGMENTATION] {
            let text = read_session_bytes_with(&v2, "hostile.mcap", &limits, topics)
                .expect_err("format 2 accepted what format 1 refuses")
                .to_string();
            for w in want {
                assert!(text.contains(w), "format 2: {w:?} not in {text:?}");
            }
        }
        services::ingest::analyse(&v2, "hostile.mcap").expect_err("format 2 ingest");
    }
    errors.swap_remove(0)
}

/// `bytes` (a format 1 file of `session_file`) written again in format 2: each raw message
/// parsed into its SI type, quantised and encoded as the recorder does, the metadata copied.
/// `None` where a message is not of its type or not finite (format 2 cannot hold it).
fn in_format_2(bytes: &[u8]) -> Option<Vec<u8>> {
    use prost::Message;
    use services::session::proto::{self, Quantiser};
    let raw = services::mcap_io::read_session_bytes(bytes, &ReadLimits::default()).ok()?;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v2.mcap");
    let mut w = SessionWriter::create(&path).unwrap();
    for (topic, name) in RAW_TOPICS.iter().zip(RAW_SCHEMA_NAMES) {
        w.register_protobuf_channel(topic, name, proto::FILE_DESCRIPTOR_SET)
            .unwrap();
    }
    for m in &raw.metadata {
        w.add_metadata(&m.name, m.entries.clone()).unwrap();
    }
    let mut all: Vec<(u64, &str, &[u8])> = RAW_TOPICS
        .iter()
        .filter_map(|t| raw.topics.get(*t))
        .flat_map(|t| {
            t.messages
                .iter()
                .map(move |m| (m.log_time_ns, t.topic.as_str(), &m.data[..]))
        })
        .collect();
    all.sort_by_key(|m| m.0);
    for (time, topic, data) in all {
        let mut q = Quantiser::default();
        let encoded = match topic {
            TOPIC_GLOVE_JOINT_STATES => {
                let mut p = Default::default();
                q.joint_states(&serde_json::from_slice(data).ok()?, &mut p);
                proto::GloveJointStatesProto::encode_to_vec(&p)
            }
            TOPIC_GLOVE_FEEDBACK => {
                let mut p = Default::default();
                q.feedback(&serde_json::from_slice(data).ok()?, &mut p);
                proto::GloveFeedbackProto::encode_to_vec(&p)
            }
            TOPIC_CONTACTS => {
                let mut p = Default::default();
                q.contacts(&serde_json::from_slice(data).ok()?, &mut p);
                proto::ContactsProto::encode_to_vec(&p)
            }
            _ => q
                .object(&serde_json::from_slice(data).ok()?)
                .encode_to_vec(),
        };
        if q.refused.is_some() {
            return None;
        }
        w.write_raw(topic, time, &encoded).unwrap();
    }
    w.finish().unwrap();
    Some(std::fs::read(&path).unwrap())
}

#[test]
fn a_session_of_valid_ticks_reads_and_ingests_every_way() {
    let bytes = edited(|_, _, _| {});
    let s = read_session_bytes(&bytes, "ok.mcap", &ReadLimits::default()).unwrap();
    assert_eq!((s.ticks(), s.contacts.len(), s.object.len()), (30, 30, 30));
    read_session_bytes_with(
        &bytes,
        "ok.mcap",
        &ReadLimits::default(),
        DecodeTopics::SEGMENTATION,
    )
    .unwrap();
    services::ingest::analyse(&bytes, "ok.mcap").unwrap();
}

#[test]
fn joint_state_arrays_whose_length_disagrees_with_names_are_refused_naming_the_message() {
    // Two positions for ten joints, or a thousand: both were stored.
    let e = assert_refused(
        &edited(on(TOPIC_GLOVE_JOINT_STATES, Some(17), |t| {
            set(t, "/positions", json!([0.1, 0.2]))
        })),
        &["topic /glove/joint_states message 17 (log time 17000000 ns): positions has 2 elements for 10 names"],
    );
    assert!(matches!(e, RecordingError::InvalidInput { .. }), "{e:?}");
    assert_refused(
        &edited(on(TOPIC_GLOVE_JOINT_STATES, Some(17), |t| {
            set(t, "/positions", json!(vec![0.0; 1000]))
        })),
        &[
            "/glove/joint_states message 17",
            "positions has 1000 elements for 10 names",
        ],
    );
    for field in ["velocities", "efforts"] {
        assert_refused(
            &edited(on(TOPIC_GLOVE_JOINT_STATES, Some(3), |t| {
                set(t, &format!("/{field}"), json!(vec![0.0; 9]))
            })),
            &[
                "/glove/joint_states message 3",
                &format!("{field} has 9 elements for 10 names"),
            ],
        );
    }
}

#[test]
fn feedback_arrays_whose_length_disagrees_with_names_are_refused_naming_the_message() {
    for field in ["motor_positions", "motor_velocities", "feedback_torques"] {
        assert_refused(
            &edited(on(TOPIC_GLOVE_FEEDBACK, Some(29), |t| {
                set(t, &format!("/{field}"), json!([]))
            })),
            &[
                "topic /glove/feedback message 29 (log time 29000000 ns)",
                &format!("{field} has 0 elements for 10 names"),
            ],
        );
    }
}

#[test]
fn dof_names_that_are_empty_too_many_or_change_during_the_session_are_refused() {
    let resize = |n: usize| {
        move |topic: &str, _: u64, text: &mut String| {
            let names: Vec<String> = (0..n).map(|i| format!("j{i}")).collect();
            let fields: &[&str] = match topic {
                TOPIC_GLOVE_JOINT_STATES => &["positions", "velocities", "efforts"],
                TOPIC_GLOVE_FEEDBACK => {
                    &["motor_positions", "motor_velocities", "feedback_torques"]
                }
                _ => return,
            };
            set(text, "/names", json!(names));
            for f in fields {
                set(text, &format!("/{f}"), json!(vec![0.0; n]));
            }
        }
    };
    assert_refused(
        &edited(resize(0)),
        &[
            "/glove/joint_states message 0",
            "names has 0 entries; a hand has 1 to 64 DOFs",
        ],
    );
    assert_refused(
        &edited(resize(65)),
        &[
            "/glove/joint_states message 0",
            "names has 65 entries; a hand has 1 to 64 DOFs",
        ],
    );
    // 64 DOFs, named alike on both topics, are a hand.
    read_session_bytes(&edited(resize(64)), "big.mcap", &ReadLimits::default()).unwrap();
    // A DOF renamed halfway: a second hand in one session.
    assert_refused(
        &edited(on(TOPIC_GLOVE_JOINT_STATES, Some(5), |t| {
            set(t, "/names/3", json!("pinky_mcp"))
        })),
        &[
            "topic /glove/joint_states message 5",
            "names[3] is \"pinky_mcp\", not \"index_mcp\" as in the DOF names of /glove/joint_states message 0",
        ],
    );
    // The feedback names other DOFs than the glove.
    assert_refused(
        &edited(on(TOPIC_GLOVE_FEEDBACK, None, |t| {
            set(t, "/names/0", json!("elbow"))
        })),
        // (Each topic is checked against its own message 0 as it is read, the topics against
        // each other at the end.)
        &[
            "topic /glove/feedback",
            "the DOF names of /glove/feedback message 0 are [\"elbow\"",
            "the DOF names of /glove/joint_states message 0 [\"wrist_roll\"",
        ],
    );
    // A DOF dropped from one message, its arrays with it.
    assert_refused(
        &edited(on(TOPIC_GLOVE_JOINT_STATES, Some(4), |t| {
            let mut v: Value = serde_json::from_str(t).unwrap();
            for f in ["names", "positions", "velocities", "efforts"] {
                v[f].as_array_mut().unwrap().pop();
            }
            *t = v.to_string();
        })),
        &[
            "topic /glove/joint_states message 4",
            "names has 9 entries, the DOF names of /glove/joint_states message 0 are 10",
        ],
    );
}

#[test]
fn finger_lists_that_are_empty_too_long_or_change_during_the_session_are_refused() {
    assert_refused(
        &edited(on(TOPIC_CONTACTS, None, |t| set(t, "/fingers", json!([])))),
        &[
            "topic /dfs/contacts message 0",
            "fingers has 0 entries; a hand has 1 to 16 fingertips",
        ],
    );
    assert_refused(
        &edited(on(TOPIC_GLOVE_FEEDBACK, Some(3), |t| {
            set(t, "/fingers", json!([]))
        })),
        &["topic /glove/feedback message 3", "fingers has 0 entries"],
    );
    let seventeen: Vec<Value> = (0..17)
        .map(|i| json!({"name": format!("tip{i}"), "touching": false, "in_contact": false, "in_cone": true, "slip": false}))
        .collect();
    assert_refused(
        &edited(on(TOPIC_CONTACTS, None, move |t| {
            set(t, "/fingers", json!(seventeen))
        })),
        &[
            "topic /dfs/contacts message 0",
            "fingers has 17 entries; a hand has 1 to 16 fingertips",
        ],
    );
    assert_refused(
        &edited(on(TOPIC_CONTACTS, Some(8), |t| {
            set(t, "/fingers/1/name", json!("pinky"))
        })),
        &[
            "topic /dfs/contacts message 8",
            "fingers[1].name is \"pinky\", not \"index\" as in the fingertips of /dfs/contacts message 0",
        ],
    );
    assert_refused(
        &edited(on(TOPIC_GLOVE_FEEDBACK, Some(12), |t| {
            let mut v: Value = serde_json::from_str(t).unwrap();
            v["fingers"].as_array_mut().unwrap().pop();
            *t = v.to_string();
        })),
        &[
            "topic /glove/feedback message 12",
            "fingers has 4 entries, the fingertips of /glove/feedback message 0 are 5",
        ],
    );
}

#[test]
fn orientations_that_are_not_unit_quaternions_are_refused_and_rounded_ones_are_not() {
    let q = |q: Quaternion| json!({"x": q.x, "y": q.y, "z": q.z, "w": q.w});
    let zero = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 0.0,
    };
    assert_refused(
        &edited(on(TOPIC_OBJECT_STATE, Some(2), move |t| {
            set(t, "/pose/orientation", q(zero))
        })),
        &[
            "topic /object/state message 2 (log time 2000000 ns)",
            "pose.orientation has norm 0.0000; an orientation is a unit quaternion (norm within 0.01 of 1)",
        ],
    );
    let doubled = Quaternion {
        w: 2.0,
        ..Quaternion::IDENTITY
    };
    assert_refused(
        &edited(on(TOPIC_OBJECT_STATE, Some(9), move |t| {
            set(t, "/pose_in_hand/orientation", q(doubled))
        })),
        &[
            "topic /object/state message 9",
            "pose_in_hand.orientation has norm 2.0000",
        ],
    );
    // Printed to two decimals, or through f32: a rotation still.
    for rounded in [
        Quaternion {
            x: 0.71,
            y: 0.0,
            z: 0.0,
            w: 0.71,
        },
        Quaternion {
            w: 0.995,
            ..Quaternion::IDENTITY
        },
    ] {
        let bytes = edited(on(TOPIC_OBJECT_STATE, None, move |t| {
            set(t, "/pose/orientation", q(rounded))
        }));
        read_session_bytes(&bytes, "rounded.mcap", &ReadLimits::default()).unwrap();
    }
}

#[test]
fn contact_normals_of_touching_fingers_that_are_not_unit_vectors_are_refused() {
    let touching = |normal: Value| {
        move |t: &mut String| {
            set(t, "/fingers/1/touching", json!(true));
            set(t, "/fingers/1/normal_b", normal.clone());
        }
    };
    // A touching finger with no normal: segmentation averaged it into a NaN normal.
    assert_refused(
        &edited(on(
            TOPIC_CONTACTS,
            Some(4),
            touching(json!({"x": 0.0, "y": 0.0, "z": 0.0})),
        )),
        &[
            "topic /dfs/contacts message 4 (log time 4000000 ns)",
            "fingers[1].normal_b has norm 0.0000 while the finger touches; a contact normal is a \
             unit vector (norm within 0.01 of 1)",
        ],
    );
    let bytes = edited(on(
        TOPIC_CONTACTS,
        None,
        touching(json!({"x": 0.6, "y": 0.0, "z": -0.8})),
    ));
    read_session_bytes(&bytes, "touching.mcap", &ReadLimits::default()).unwrap();
}

#[test]
fn numbers_too_large_for_a_finite_double_are_refused_on_every_raw_topic_naming_the_field() {
    // JSON has no NaN or infinity; 1e999 is its way to write one. Topics that segmentation
    // does not keep were only checked to be JSON, and let it through.
    for (topic, pointer, field) in [
        (TOPIC_GLOVE_JOINT_STATES, "/positions/3", "positions[3]"),
        (
            TOPIC_GLOVE_FEEDBACK,
            "/fingers/1/tip_force_world/y",
            "fingers[1].tip_force_world.y",
        ),
        (
            TOPIC_CONTACTS,
            "/fingers/0/penetration",
            "fingers[0].penetration",
        ),
        (TOPIC_OBJECT_STATE, "/f_ext_b/2", "f_ext_b[2]"),
    ] {
        let bytes = edited(on(topic, Some(6), move |t| {
            set(t, pointer, json!(123456.0));
            *t = t.replace("123456.0", "-1e999");
        }));
        let e = assert_refused(
            &bytes,
            &[
                &format!("message 6 on topic {topic:?} (log time 6000000 ns)"),
                &format!("at {field}: number out of range"),
            ],
        );
        assert!(
            matches!(e, RecordingError::InvalidJson { index: 6, .. }),
            "{e:?}"
        );
    }
}

#[test]
fn a_session_shorter_than_two_ticks_is_refused() {
    // One message per topic: a session 0 ns long.
    let one = session_file(1, &[(SESSION_METADATA, session_record())], |_, _, _| {});
    assert_refused(
        &one,
        &[
            "topic /glove/joint_states",
            "has one message: a session lasts at least 1 ms (two ticks at 1 kHz) on every raw topic",
        ],
    );
    // Two ticks half a millisecond apart.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("short.mcap");
    let mut w = SessionWriter::create(&path).unwrap();
    for (topic, schema) in RAW_TOPICS.iter().zip(ICMS_SCHEMAS.iter()) {
        w.register_channel(topic, schema).unwrap();
    }
    w.add_metadata(SESSION_METADATA, session_record()).unwrap();
    for t in [0, MS / 2] {
        for topic in RAW_TOPICS {
            w.write_raw(topic, t, message(topic, 0).as_bytes()).unwrap();
        }
    }
    w.finish().unwrap();
    assert_refused(
        &std::fs::read(&path).unwrap(),
        &[
            "topic /glove/joint_states",
            "spans 500000 ns: a session lasts at least 1 ms",
        ],
    );
    // Two ticks 1 ms apart are the shortest session.
    let two = session_file(2, &[(SESSION_METADATA, session_record())], |_, _, _| {});
    services::ingest::analyse(&two, "two.mcap").unwrap();
}

#[test]
fn metadata_records_repeated_too_many_or_too_large_are_refused_naming_the_record() {
    let file =
        |metadata: &[(&str, BTreeMap<String, String>)]| session_file(3, metadata, |_, _, _| {});
    let record = |pairs: &[(&str, String)]| -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    };
    let mut other = session_record();
    other.insert("object".into(), OBJECT.replace("0.2", "0.3"));
    // Two `session` records: which object was grasped?
    assert_refused(
        &file(&[
            (SESSION_METADATA, session_record()),
            (SESSION_METADATA, other),
        ]),
        &[
            "hostile.mcap: metadata session",
            "the file has 2 `session` metadata records; a session has one at most",
        ],
    );
    let phases = record(&[("phases", "[]".into())]);
    assert_refused(
        &file(&[
            (SESSION_METADATA, session_record()),
            (GROUND_TRUTH_METADATA, phases.clone()),
            (GROUND_TRUTH_METADATA, phases),
        ]),
        &["the file has 2 `ground_truth` metadata records"],
    );
    // A 1 MB value: stored, then listed with every page of sessions.
    let mut big = session_record();
    big.insert("notes".into(), "x".repeat(1_000_000));
    assert_refused(
        &file(&[(SESSION_METADATA, big)]),
        &[
            "hostile.mcap: metadata session.notes",
            "the value is 1000000 bytes long; a metadata value has at most 65536 bytes",
        ],
    );
    // At the limit it is read.
    let mut at_limit = session_record();
    at_limit.insert("notes".into(), "x".repeat(MAX_METADATA_VALUE_BYTES));
    services::ingest::analyse(&file(&[(SESSION_METADATA, at_limit)]), "ok.mcap").unwrap();
    // Five values of 60 kB: each allowed, together over 256 KiB.
    let mut many = vec![(SESSION_METADATA, session_record())];
    for k in 0..5 {
        many.push((
            "notes",
            record(&[(&format!("part{k}"), "y".repeat(60_000))]),
        ));
    }
    assert_refused(
        &file(&many),
        &[
            "metadata notes",
            "more than 262144 bytes of names, keys and values",
        ],
    );
    // Records and entries by the hundred.
    let mut records = vec![(SESSION_METADATA, session_record())];
    records.extend((0..64).map(|_| ("extra", BTreeMap::new())));
    assert_refused(
        &file(&records),
        &[
            "metadata records",
            "65 metadata records; a session has at most 64",
        ],
    );
    let mut wide = session_record();
    wide.extend((0..300).map(|i| (format!("k{i}"), String::new())));
    assert_refused(
        &file(&[(SESSION_METADATA, wide)]),
        &[
            "metadata session",
            "has 302 entries; a metadata record has at most 256",
        ],
    );
    let mut long_key = session_record();
    long_key.insert("k".repeat(1000), "v".into());
    assert_refused(
        &file(&[(SESSION_METADATA, long_key)]),
        &[
            "metadata session.kkkk",
            "the key is 1000 bytes long; a key has at most 256",
        ],
    );
}

#[test]
fn a_fault_past_the_first_block_of_messages_is_named_by_its_number_in_the_topic() {
    // Messages are checked in parallel blocks of 1024: the number is the topic's, not the
    // block's.
    let bytes = session_file(
        1500,
        &[(SESSION_METADATA, session_record())],
        |topic, k, t| {
            if topic == TOPIC_GLOVE_FEEDBACK && k == 1300 {
                set(t, "/feedback_torques", json!([1.0]));
            }
        },
    );
    assert_refused(
        &bytes,
        &[
            "topic /glove/feedback message 1300 (log time 1300000000 ns)",
            "feedback_torques has 1 elements for 10 names",
        ],
    );
}

#[test]
fn messages_of_the_wrong_shape_are_refused_alike_whether_kept_or_only_checked() {
    // Segmentation reads the glove topics into lighter shapes than the full messages: the
    // same JSON must pass or fail both.
    for (topic, edit) in [
        (TOPIC_GLOVE_JOINT_STATES, json!({"extra": 1})),
        (TOPIC_GLOVE_JOINT_STATES, json!({"positions": null})),
        (TOPIC_GLOVE_JOINT_STATES, json!({"positions": ["0.1"]})),
        (TOPIC_GLOVE_JOINT_STATES, json!({"names": [1, 2]})),
        (
            TOPIC_GLOVE_FEEDBACK,
            json!({"fingers": [{"name": "thumb"}]}),
        ),
        (
            TOPIC_GLOVE_FEEDBACK,
            json!({"fingers": [{"name": "thumb", "tip_force_world": {"x": 0, "y": 0}}]}),
        ),
        (
            TOPIC_GLOVE_FEEDBACK,
            json!({"fingers": [{"name": "thumb", "tip_force_world": {"x": 0, "y": 0, "z": 0}, "grip": 1}]}),
        ),
    ] {
        let bytes = edited(on(topic, Some(1), move |t| {
            let mut v: Value = serde_json::from_str(t).unwrap();
            for (k, x) in edit.as_object().unwrap() {
                v[k] = x.clone();
            }
            *t = v.to_string();
        }));
        let e = assert_refused(&bytes, &[&format!("message 1 on topic {topic:?}")]);
        assert!(matches!(e, RecordingError::InvalidJson { .. }), "{e:?}");
    }
    // Names with JSON escapes are read as the names they spell.
    let bytes = edited(|topic, _, t| {
        if topic == TOPIC_GLOVE_JOINT_STATES || topic == TOPIC_GLOVE_FEEDBACK {
            *t = t.replace("\"wrist_roll\"", "\"wrist\\u005froll\"");
        }
    });
    services::ingest::analyse(&bytes, "escaped.mcap").unwrap();
}
