//! proptest strategies of the raw topics' prost messages.

use crate::session::proto::*;
use proptest::prelude::*;

pub(super) fn v3i() -> impl Strategy<Value = Option<Vector3i>> {
    proptest::option::of(
        (any::<i32>(), any::<i32>(), any::<i32>()).prop_map(|(x, y, z)| Vector3i { x, y, z }),
    )
}

pub(super) fn intensityi() -> impl Strategy<Value = Option<Intensityi>> {
    proptest::option::of(
        (any::<i32>(), any::<i32>(), any::<i32>(), any::<i32>()).prop_map(
            |(x_e3, y_e3, z_e3, torsion_e6)| Intensityi {
                x_e3,
                y_e3,
                z_e3,
                torsion_e6,
            },
        ),
    )
}

pub(super) fn posei() -> impl Strategy<Value = Option<Posei>> {
    proptest::option::of(
        (
            v3i(),
            proptest::option::of(
                (any::<i32>(), any::<i32>(), any::<i32>(), any::<i32>()).prop_map(
                    |(x_e6, y_e6, z_e6, w_e6)| Quaternioni {
                        x_e6,
                        y_e6,
                        z_e6,
                        w_e6,
                    },
                ),
            ),
        )
            .prop_map(|(position_e6, orientation)| Posei {
                position_e6,
                orientation,
            }),
    )
}

pub(super) fn wrenchi() -> impl Strategy<Value = Option<Wrenchi>> {
    proptest::option::of((v3i(), v3i()).prop_map(|(force_e3, torque_e6)| Wrenchi {
        force_e3,
        torque_e6,
    }))
}

pub(super) fn names() -> impl Strategy<Value = Vec<String>> {
    proptest::collection::vec("[a-z_0-9é]{0,8}", 0..6)
}

pub(super) fn ints() -> impl Strategy<Value = Vec<i32>> {
    proptest::collection::vec(any::<i32>(), 0..6)
}

pub(super) fn contacts_proto() -> impl Strategy<Value = ContactsProto> {
    let finger = (
        "[a-z]{0,6}",
        any::<[bool; 4]>(),
        v3i(),
        v3i(),
        any::<i32>(),
        intensityi(),
        intensityi(),
        intensityi(),
    )
        .prop_map(|(name, b, point_b_e6, normal_b_e6, pen, i, t, f)| {
            FingerContactProto {
                touching: b[0],
                in_contact: b[1],
                point_b_e6,
                normal_b_e6,
                penetration_e9: pen,
                intensity: i,
                transmitted: t,
                feedback: f,
                in_cone: b[2],
                slip: b[3],
                object: u32::from(b[0]) * u32::from(pen as u8 % 9),
                // Fingertips, palms, phalanges and a part this version does not know (3).
                part: i32::from((pen >> 8) as u8 % 4),
                link: if ((pen >> 8) as u8).is_multiple_of(4) {
                    String::new()
                } else {
                    format!("{name}_link")
                },
                name,
            }
        });
    (any::<u32>(), proptest::collection::vec(finger, 0..5)).prop_map(|(n_contacts, fingers)| {
        ContactsProto {
            n_contacts,
            fingers,
        }
    })
}

pub(super) fn feedback_proto() -> impl Strategy<Value = GloveFeedbackProto> {
    let finger = ("[a-z]{0,6}", v3i(), v3i()).prop_map(|(name, a, b)| FingerFeedbackProto {
        name,
        feedback_force_world_e3: a,
        tip_force_world_e3: b,
    });
    (
        names(),
        ints(),
        ints(),
        ints(),
        proptest::collection::vec(finger, 0..5),
    )
        .prop_map(|(names, a, b, c, fingers)| GloveFeedbackProto {
            names,
            motor_positions_e5: a,
            motor_velocities_e2: b,
            feedback_torques_e5: c,
            fingers,
        })
}

pub(super) fn object_proto() -> impl Strategy<Value = ObjectStateProto> {
    (
        posei(),
        v3i(),
        v3i(),
        wrenchi(),
        wrenchi(),
        wrenchi(),
        posei(),
        any::<u32>(),
        proptest::collection::vec((posei(), v3i(), v3i()), 0..4),
    )
        .prop_map(
            |(pose, lv, av, f, o, t, ph, index, objects)| ObjectStateProto {
                pose,
                linear_velocity_e6: lv,
                angular_velocity_b_e6: av,
                f_ext_b: f,
                object_force_b: o,
                table_force_b: t,
                pose_in_hand: ph,
                index,
                objects: objects
                    .into_iter()
                    .map(|(pose, lv, av)| SceneObjectStateProto {
                        pose,
                        linear_velocity_e6: lv,
                        angular_velocity_b_e6: av,
                    })
                    .collect(),
            },
        )
}
