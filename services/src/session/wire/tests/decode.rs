//! The decoders of the raw topics against prost's: the same bytes accepted and refused, the same
//! SI messages, the lean decodes, merged fields and nested groups.

use super::super::fields::same_bytes;
use super::super::{
    contacts, contacts_lean, feedback, glove_shape, joint_states, object, object_lean, Result,
};
use super::check::foxglove_checks;
use super::shape::agree_shape;
use super::strategies::*;
use crate::session::messages::{
    Contacts, GloveFeedback, GloveJointStates, GloveShape, Intensity4, ObjectState,
};
use crate::session::proto::{self, *};
use proptest::prelude::*;
use prost::Message;

/// Both decoders on `bytes`: they agree on whether it decodes and, if it does, on the SI
/// message; `out` is reused from earlier calls on purpose.
fn agree<P: Message + Default, T: PartialEq + std::fmt::Debug>(
    bytes: &[u8],
    ours: fn(&[u8], &mut T) -> Result<()>,
    out: &mut T,
    convert: fn(P) -> T,
) -> std::result::Result<(), TestCaseError> {
    let theirs = P::decode(bytes);
    let mine = ours(bytes, out);
    match (theirs, mine) {
        (Ok(p), Ok(())) => prop_assert_eq!(&convert(p), &*out),
        (Err(_), Err(_)) => {}
        (t, m) => prop_assert!(
            false,
            "prost {:?}, ours {:?} on {:?}",
            t.map(drop),
            m,
            bytes
        ),
    }
    Ok(())
}

/// [`agree`] on `bytes`, on them cut short at `cut`, and with `junk` appended, reusing one
/// output message.
fn agree_whole_cut_and_extended<P: Message + Default, T: Default + PartialEq + std::fmt::Debug>(
    bytes: &[u8],
    cut: prop::sample::Index,
    junk: &[u8],
    ours: fn(&[u8], &mut T) -> Result<()>,
    convert: fn(P) -> T,
) -> std::result::Result<(), TestCaseError> {
    let mut out = T::default();
    agree(bytes, ours, &mut out, convert)?;
    // Cut short, or with bytes appended: both refuse or both read the same.
    agree(
        &bytes[..cut.index(bytes.len() + 1)],
        ours,
        &mut out,
        convert,
    )?;
    let mut longer = bytes.to_vec();
    longer.extend_from_slice(junk);
    agree(&longer, ours, &mut out, convert)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn contacts_decode_as_prost_decodes_them(m in contacts_proto(), cut in any::<prop::sample::Index>(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
        agree_whole_cut_and_extended(&m.encode_to_vec(), cut, &junk, contacts, proto::contacts_from_proto)?;
    }

    #[test]
    fn feedback_decodes_as_prost_decodes_it(m in feedback_proto(), cut in any::<prop::sample::Index>(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
        agree_whole_cut_and_extended(&m.encode_to_vec(), cut, &junk, feedback, proto::feedback_from_proto)?;
    }

    #[test]
    fn joint_states_decode_as_prost_decodes_them(names in names(), a in ints(), b in ints(), c in ints(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
        let m = GloveJointStatesProto { names, positions_e5: a, velocities_e2: b, efforts_e5: c };
        let mut out = GloveJointStates::default();
        let mut bytes = m.encode_to_vec();
        agree(&bytes, joint_states, &mut out, proto::joint_states_from_proto)?;
        bytes.extend_from_slice(&junk);
        agree(&bytes, joint_states, &mut out, proto::joint_states_from_proto)?;
    }

    #[test]
    fn object_states_decode_as_prost_decodes_them(m in object_proto(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
        let mut out = ObjectState::default();
        let mut bytes = m.encode_to_vec();
        agree(&bytes, object, &mut out, proto::object_from_proto)?;
        bytes.extend_from_slice(&junk);
        agree(&bytes, object, &mut out, proto::object_from_proto)?;
    }

    #[test]
    fn any_bytes_decode_as_prost_decodes_them(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
        agree(&bytes, contacts, &mut Contacts::default(), proto::contacts_from_proto)?;
        agree(&bytes, feedback, &mut GloveFeedback::default(), proto::feedback_from_proto)?;
        agree(&bytes, joint_states, &mut GloveJointStates::default(), proto::joint_states_from_proto)?;
        agree(&bytes, object, &mut ObjectState::default(), proto::object_from_proto)?;
        let mut shape = GloveShape::default();
        agree_shape(&bytes, false, &mut shape)?;
        agree_shape(&bytes, true, &mut shape)?;
    }

    #[test]
    fn lean_decodes_are_full_ones_without_the_fields_segmentation_skips(c in contacts_proto(), o in object_proto()) {
        let mut full = Contacts::default();
        contacts(&c.encode_to_vec(), &mut full).unwrap();
        full.n_contacts = 0;
        for f in &mut full.fingers {
            f.penetration = 0.0;
            f.transmitted = Intensity4::default();
            f.feedback = Intensity4::default();
            f.in_cone = false;
        }
        let mut lean = Contacts::default();
        contacts_lean(&c.encode_to_vec(), &mut lean).unwrap();
        prop_assert_eq!(&lean, &full);
        let mut full = ObjectState::default();
        object(&o.encode_to_vec(), &mut full).unwrap();
        let mut lean = ObjectState::default();
        object_lean(&o.encode_to_vec(), &mut lean).unwrap();
        // The scene's objects are read too (a skill may grasp any of them).
        let expected = ObjectState { pose: full.pose, pose_in_hand: full.pose_in_hand, index: full.index, objects: full.objects, ..ObjectState::default() };
        prop_assert_eq!(&lean, &expected);
    }

    #[test]
    fn same_bytes_is_slice_equality(a in proptest::collection::vec(any::<u8>(), 0..24), flip in any::<prop::sample::Index>(), bit in 0u8..8, other in proptest::collection::vec(any::<u8>(), 0..24)) {
        prop_assert_eq!(same_bytes(&a, &other), a == other);
        prop_assert!(same_bytes(&a, &a.clone()));
        if !a.is_empty() {
            let mut b = a.clone();
            b[flip.index(a.len())] ^= 1 << bit;
            prop_assert!(!same_bytes(&a, &b));
        }
    }
}

#[test]
fn a_message_field_given_twice_is_merged_and_unpacked_repeats_are_read() {
    // pose.position.x = 1 step, then pose again with only position.y: proto merges them.
    let first = ObjectStateProto {
        pose: Some(Posei {
            position_e6: Some(Vector3i { x: 1, y: 0, z: 0 }),
            orientation: None,
        }),
        ..Default::default()
    };
    let second = ObjectStateProto {
        pose: Some(Posei {
            position_e6: Some(Vector3i { x: 0, y: 2, z: 0 }),
            orientation: None,
        }),
        ..Default::default()
    };
    let mut bytes = first.encode_to_vec();
    bytes.extend(second.encode_to_vec());
    let mut out = ObjectState::default();
    object(&bytes, &mut out).unwrap();
    assert_eq!(
        out,
        proto::object_from_proto(ObjectStateProto::decode(&bytes[..]).unwrap())
    );
    assert!(
        (out.pose.position.x - 1e-6).abs() < 1e-12 && (out.pose.position.y - 2e-6).abs() < 1e-12
    );
    // positions_e5 = [3, -1] unpacked: key (2 << 3 | 0), zigzag values 6 and 1.
    let mut js = GloveJointStates::default();
    joint_states(&[0x10, 6, 0x10, 1], &mut js).unwrap();
    assert_eq!(js.positions.len(), 2);
    assert!((js.positions[0] - 3e-5).abs() < 1e-12 && (js.positions[1] + 1e-5).abs() < 1e-12);
}

fn varint_bytes(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// An unknown field 15 as `depth` groups nested in each other around an unknown varint
/// field 14, optionally inside field `inside` as an embedded message.
fn nested_groups(depth: usize, inside: Option<u8>) -> Vec<u8> {
    let mut groups = vec![15 << 3 | 3; depth];
    groups.extend_from_slice(&[14 << 3, 1]);
    groups.extend(std::iter::repeat_n(15 << 3 | 4, depth));
    match inside {
        None => groups,
        Some(field) => {
            let mut bytes = vec![field << 3 | 2];
            varint_bytes(groups.len() as u64, &mut bytes);
            bytes.extend_from_slice(&groups);
            bytes
        }
    }
}

#[test]
fn groups_nested_to_prosts_recursion_limit_are_refused_where_prost_refuses_them() {
    // 99 groups deep (at the top, or in an embedded message) read; one deeper refused,
    // whatever the field inside.
    for depth in [1, 97, 98, 99, 100, 101] {
        for inside in [None, Some(2)] {
            let bytes = nested_groups(depth, inside);
            let theirs = ContactsProto::decode(&bytes[..]).is_ok();
            let ours = contacts(&bytes, &mut Contacts::default()).is_ok();
            assert_eq!(ours, theirs, "contacts, {depth} groups in {inside:?}");
            let theirs = ObjectStateProto::decode(&bytes[..]).is_ok();
            let ours = object(&bytes, &mut ObjectState::default()).is_ok();
            assert_eq!(ours, theirs, "object, {depth} groups in {inside:?}");
            let theirs = GloveFeedbackProto::decode(&bytes[..]).is_ok();
            let ours = glove_shape(&bytes, true, &mut GloveShape::default()).is_ok();
            assert_eq!(ours, theirs, "feedback shape, {depth} groups in {inside:?}");
            let check = foxglove_checks();
            let theirs = foxglove::messages::FrameTransforms::decode(&bytes[..]).is_ok();
            assert_eq!(
                check[0].check(&bytes).is_ok(),
                theirs,
                "/tf, {depth} in {inside:?}"
            );
        }
        let deep = depth == 100 || depth == 101;
        assert_eq!(
            ContactsProto::decode(&nested_groups(depth, None)[..]).is_ok(),
            !deep
        );
    }
}
