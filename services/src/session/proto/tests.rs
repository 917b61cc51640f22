//! Tests of the protobuf encoding, the schema comparison and the conversions back to SI.

use super::*;
use crate::foxglove::{Pose, Quaternion, Vector3};
use crate::session::messages::{self, *};
use prost::Message;

#[test]
fn the_descriptor_set_holds_every_raw_topic_message() {
    let fds = prost_types::FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).unwrap();
    let names: Vec<String> = fds
        .file
        .iter()
        .flat_map(|f| f.message_type.iter().map(|m| format!("icms.{}", m.name())))
        .collect();
    for schema in super::super::RAW_SCHEMA_NAMES {
        assert!(names.iter().any(|n| n == schema), "{schema} in {names:?}");
    }
}

#[test]
fn a_schema_is_compared_field_by_field_naming_the_first_difference() {
    for name in super::super::RAW_SCHEMA_NAMES {
        assert_eq!(schema_difference(FILE_DESCRIPTOR_SET, name), None, "{name}");
    }
    let edited = |edit: &dyn Fn(&mut prost_types::FileDescriptorSet)| {
        let mut fds = prost_types::FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).unwrap();
        edit(&mut fds);
        fds.encode_to_vec()
    };
    // A field's type changed, deep inside: the path names it.
    let bytes = edited(&|fds| {
        let m = fds.file[0]
            .message_type
            .iter_mut()
            .find(|m| m.name() == "Vector3i")
            .unwrap();
        m.field[2].set_type(prost_types::field_descriptor_proto::Type::Double);
    });
    let d = schema_difference(&bytes, "icms.Contacts").unwrap();
    assert!(d.starts_with("icms.Contacts.fingers.point_b_e6.z:"), "{d}");
    assert!(
        d.contains("ours is `optional sint32 z = 3`") && d.contains("double z = 3"),
        "{d}"
    );
    // A field renumbered, removed or added.
    let bytes = edited(&|fds| {
        let m = fds.file[0]
            .message_type
            .iter_mut()
            .find(|m| m.name() == "GloveJointStates")
            .unwrap();
        m.field[1].number = Some(9);
    });
    let d = schema_difference(&bytes, "icms.GloveJointStates").unwrap();
    assert!(
        d.contains("positions_e5") && d.contains("no field 2"),
        "{d}"
    );
    let bytes = edited(&|fds| fds.file[0].message_type.retain(|m| m.name() != "Posei"));
    let d = schema_difference(&bytes, "icms.ObjectState").unwrap();
    assert!(d.contains("does not define message icms.Posei"), "{d}");
    assert!(schema_difference(b"\xff\xff", "icms.Contacts").is_some());
}

/// Whole-hand contacts on `/dfs/contacts`: a palm or phalanx entry is written only while it
/// touches, with its part and link, after the fingertips; a fingertip carries neither
/// field, so a message from before them (a file without the fields) reads as fingertips.
#[test]
fn palm_and_phalanx_contacts_are_written_while_touching_with_their_part_and_link() {
    let mut q = Quantiser::default();
    let tip = FingerContact {
        name: "index".into(),
        ..FingerContact::default()
    };
    let body = |name: &str, part, touching| FingerContact {
        name: name.into(),
        part,
        link: format!("{name}_link"),
        touching,
        in_contact: touching,
        normal_b: if touching {
            Vector3::new(0.0, 0.0, -1.0)
        } else {
            Vector3::default()
        },
        transmitted: Intensity4 {
            z: if touching { 2.5 } else { 0.0 },
            ..Intensity4::default()
        },
        ..FingerContact::default()
    };
    let m = Contacts {
        n_contacts: 2,
        fingers: vec![
            tip.clone(),
            body("thenar", ContactPart::Palm, true),
            body("index_proximal", ContactPart::Phalanx, false),
            body("little_middle", ContactPart::Phalanx, true),
        ],
    };
    let mut out = Vec::new();
    q.encode_contacts(&m, &mut out);
    let back = contacts_from_proto(canonical(&out));
    let names: Vec<&str> = back.fingers.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["index", "thenar", "little_middle"]);
    assert_eq!(back.n_tips(), 1);
    assert_eq!(back.fingers[0], tip);
    assert_eq!(back.fingers[1].part, ContactPart::Palm);
    assert_eq!(back.fingers[1].link, "thenar_link");
    assert_eq!(back.fingers[1].transmitted.z, 2.5);
    assert_eq!(back.fingers[2].part, ContactPart::Phalanx);
    // Our decoder reads the same.
    let mut ours = Contacts::default();
    super::super::wire::contacts(&out, &mut ours).unwrap();
    assert_eq!(ours, back);
    // Fingertips write neither field: the bytes are those of a file from before them.
    let mut old = Vec::new();
    q.encode_contacts(
        &Contacts {
            n_contacts: 0,
            fingers: vec![tip.clone()],
        },
        &mut old,
    );
    let proto: ContactsProto = canonical(&old);
    assert_eq!(
        (proto.fingers[0].part, proto.fingers[0].link.as_str()),
        (0, "")
    );
}

/// A v2 file written before scenes of several objects: its schema has no
/// `FingerContact.object`, `ObjectState.index`, `ObjectState.objects` nor
/// `SceneObjectState`. It is the same schema, and its messages read those as 0 and empty.
#[test]
fn a_schema_from_before_the_fields_for_several_objects_is_accepted() {
    let mut fds = prost_types::FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).unwrap();
    let file = &mut fds.file[0];
    file.message_type.retain(|m| m.name() != "SceneObjectState");
    for m in &mut file.message_type {
        let full = format!(".icms.{}", m.name());
        m.field
            .retain(|f| !ADDED_FIELDS.contains(&(full.as_str(), f.number())));
    }
    let old = fds.encode_to_vec();
    for name in super::super::RAW_SCHEMA_NAMES {
        assert_eq!(schema_difference(&old, name), None, "{name}");
    }
    // Another change is still one.
    let mut other = prost_types::FileDescriptorSet::decode(old.as_slice()).unwrap();
    let m = other.file[0]
        .message_type
        .iter_mut()
        .find(|m| m.name() == "FingerContact")
        .unwrap();
    m.field.retain(|f| f.number() != 11);
    let d = schema_difference(&other.encode_to_vec(), "icms.Contacts").unwrap();
    assert!(d.contains("slip") && d.contains("no field 11"), "{d}");
    // A message of the old layout reads the new fields as their defaults.
    let old_message = ObjectStateProto {
        pose: Some(Posei::default()),
        ..ObjectStateProto::default()
    }
    .encode_to_vec();
    let back = object_from_proto(ObjectStateProto::decode(old_message.as_slice()).unwrap());
    assert_eq!((back.index, back.objects.len()), (0, 0));
}

/// `bytes` decoded as `M`, checked to be what prost writes for it.
fn canonical<M: Message + Default>(bytes: &[u8]) -> M {
    let m = M::decode(bytes).unwrap();
    assert_eq!(m.encode_to_vec(), bytes);
    m
}

#[test]
fn the_encoding_is_prosts_with_zero_fields_and_vectors_left_out() {
    let mut q = Quantiser::default();
    // Values of every varint length (1 to 5 bytes), both signs, and zeros; a name long
    // enough that its finger's length takes two bytes.
    let long = "f".repeat(200);
    let values = [
        0.0, 1e-5, -1e-5, 0.00063, -0.02, 0.5, -3.0, 21_474.0, -21_474.83,
    ];
    let joints = GloveJointStates {
        names: vec!["a".into(), String::new(), long.clone()],
        positions: values.to_vec(),
        velocities: vec![0.0; values.len()],
        efforts: values.iter().map(|v| -v).collect(),
    };
    let mut out = vec![7];
    q.encode_joint_states(&joints, &mut out);
    assert_eq!(out[0], 7, "appended");
    let back: GloveJointStatesProto = canonical(&out[1..]);
    assert_eq!(back.names, joints.names);
    assert_eq!(back.velocities_e2, vec![0; values.len()]);
    assert_eq!(back.positions_e5[8], -2_147_483_000);
    assert_eq!(joint_states_from_proto(back).positions.len(), values.len());

    let feedback = GloveFeedback {
        names: vec!["j".into()],
        motor_positions: vec![0.1],
        motor_velocities: vec![],
        feedback_torques: vec![0.0],
        fingers: vec![
            FingerFeedback {
                name: long.clone(),
                feedback_force_world: Vector3::new(0.0, 0.0, 0.0),
                tip_force_world: Vector3::new(0.0, -1.5, 0.0),
            },
            FingerFeedback::default(),
        ],
    };
    let mut out = Vec::new();
    q.encode_feedback(&feedback, &mut out);
    let back: GloveFeedbackProto = canonical(&out);
    assert!(back.motor_velocities_e2.is_empty());
    assert_eq!(back.fingers.len(), 2);
    assert_eq!(back.fingers[0].feedback_force_world_e3, None);
    assert_eq!(
        back.fingers[0].tip_force_world_e3,
        Some(Vector3i {
            x: 0,
            y: -1500,
            z: 0
        })
    );
    assert_eq!(back.fingers[1], FingerFeedbackProto::default());

    contacts_are_prosts(&mut q, long);

    // An object at rest at the origin: every message field but the vectors is there, even
    // empty (an all-zero quaternion).
    let mut rest = messages::ObjectState::default();
    rest.pose_in_hand.orientation.w = 0.0;
    let mut out = Vec::new();
    q.encode_object(&rest, &mut out);
    let back: ObjectStateProto = canonical(&out);
    assert_eq!(back.linear_velocity_e6, None);
    assert_eq!(back.f_ext_b, Some(Wrenchi::default()));
    let pose = back.pose.unwrap();
    assert_eq!(pose.position_e6, None);
    assert_eq!(pose.orientation.map(|o| o.w_e6), Some(1_000_000));
    let in_hand = back.pose_in_hand.unwrap();
    assert_eq!(in_hand.orientation, Some(Quaternioni::default()));
    assert!(q.refused.is_none());
}

/// The contacts part of [`the_encoding_is_prosts_with_zero_fields_and_vectors_left_out`]:
/// a touching fingertip named `long` and an empty one, with and without `n_contacts`.
fn contacts_are_prosts(q: &mut Quantiser, long: String) {
    let touching = FingerContact {
        name: long,
        touching: true,
        in_contact: true,
        point_b: Vector3::new(0.01, -0.02, 0.03),
        normal_b: Vector3::new(0.0, 0.0, -1.0),
        penetration: -2e-4,
        intensity: Intensity4 {
            x: 0.5,
            y: 0.0,
            z: 3.0,
            torsion: -1e-3,
        },
        transmitted: Intensity4::default(),
        feedback: Intensity4 {
            torsion: 1e-6,
            ..Intensity4::default()
        },
        in_cone: false,
        slip: true,
        object: 3,
        part: ContactPart::Fingertip,
        link: String::new(),
    };
    for n_contacts in [0, 1] {
        let contacts = Contacts {
            n_contacts,
            fingers: vec![touching.clone(), FingerContact::default()],
        };
        let mut out = Vec::new();
        q.encode_contacts(&contacts, &mut out);
        let back: ContactsProto = canonical(&out);
        assert_eq!(back.n_contacts, n_contacts);
        let f = &back.fingers[0];
        assert!(f.touching && f.in_contact && f.slip && !f.in_cone);
        assert_eq!(
            f.normal_b_e6,
            Some(Vector3i {
                x: 0,
                y: 0,
                z: -1_000_000
            })
        );
        assert_eq!(f.penetration_e9, -200_000);
        assert_eq!(f.transmitted, None);
        assert_eq!(f.feedback.map(|c| c.torsion_e6), Some(1));
        assert_eq!(back.fingers[1], FingerContactProto::default());
        assert_eq!(
            contacts_from_proto(back).fingers[0].point_b,
            touching.point_b
        );
    }
}

#[test]
fn values_read_back_within_half_a_step_and_overflow_is_named() {
    let m = messages::ObjectState {
        pose: Pose {
            position: Vector3::new(0.123_456_789, -1.5, 2e-7),
            orientation: Quaternion {
                x: 0.0,
                y: 0.6,
                z: 0.0,
                w: 0.8,
            },
        },
        linear_velocity: Vector3::new(1e-3, 0.0, -2.0),
        angular_velocity_b: Vector3::new(3.0, 0.0, 0.0),
        f_ext_b: [0.0, 0.0, -2.943, 0.001, 0.0, 0.0],
        object_force_b: [1.0; 6],
        table_force_b: [0.0; 6],
        pose_in_hand: Pose::default(),
        index: 1,
        objects: vec![
            messages::SceneObjectState {
                pose: Pose {
                    position: Vector3::new(0.3, 0.0, 0.04),
                    orientation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: 0.0,
                        w: 1.0,
                    },
                },
                ..messages::SceneObjectState::default()
            },
            messages::SceneObjectState::default(),
        ],
    };
    let mut q = Quantiser::default();
    let back = object_from_proto(ObjectStateProto::decode(&*q.object(&m).encode_to_vec()).unwrap());
    assert!(q.refused.is_none());
    assert_eq!(back.index, 1);
    assert_eq!(back.objects.len(), 2);
    assert!((back.objects[0].pose.position.x - 0.3).abs() < 1e-12);
    assert!((back.pose.position.x - m.pose.position.x).abs() <= POSITION / 2.0);
    assert_eq!(back.pose.position.z, 0.0);
    assert!((back.f_ext_b[2] + 2.943).abs() < 1e-12);
    assert!((back.pose.orientation.w - 0.8).abs() < 1e-12);

    let mut big = m.clone();
    big.linear_velocity.x = 1e6;
    let mut q = Quantiser::default();
    q.object(&big);
    assert_eq!(q.refused, Some(("linear_velocity".to_owned(), 1e6)));
    let mut nan = m;
    nan.table_force_b[4] = f64::NAN;
    let mut q = Quantiser::default();
    q.object(&nan);
    assert_eq!(q.refused.map(|r| r.0).as_deref(), Some("table_force_b"));
}
