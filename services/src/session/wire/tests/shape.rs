//! [`glove_shape`] against prost: the same names, array lengths and fingertips, accepted and
//! refused alike, message after message into one shape.

use super::super::glove_shape;
use super::strategies::{feedback_proto, ints, names};
use crate::session::messages::GloveShape;
use crate::session::proto::{GloveFeedbackProto, GloveJointStatesProto};
use proptest::prelude::*;
use prost::Message;

/// What prost decodes of `bytes` as `icms.GloveFeedback` (`feedback`) or
/// `icms.GloveJointStates`, as a shape: names, array lengths, fingertip names.
fn prost_shape(bytes: &[u8], feedback: bool) -> Option<(Vec<String>, [usize; 3], Vec<String>)> {
    if feedback {
        let m = GloveFeedbackProto::decode(bytes).ok()?;
        let arrays = [
            m.motor_positions_e5.len(),
            m.motor_velocities_e2.len(),
            m.feedback_torques_e5.len(),
        ];
        Some((
            m.names,
            arrays,
            m.fingers.into_iter().map(|f| f.name).collect(),
        ))
    } else {
        let m = GloveJointStatesProto::decode(bytes).ok()?;
        let arrays = [
            m.positions_e5.len(),
            m.velocities_e2.len(),
            m.efforts_e5.len(),
        ];
        Some((m.names, arrays, Vec::new()))
    }
}

/// [`glove_shape`] and prost agree on whether `bytes` decode and on the shape; `out` is
/// reused from earlier calls on purpose.
pub(super) fn agree_shape(
    bytes: &[u8],
    feedback: bool,
    out: &mut GloveShape,
) -> std::result::Result<(), TestCaseError> {
    let theirs = prost_shape(bytes, feedback);
    let mine = glove_shape(bytes, feedback, out);
    match (theirs, mine) {
        (Some((names, arrays, fingers)), Ok(())) => {
            prop_assert_eq!(&names, &out.names);
            prop_assert_eq!(arrays, out.arrays);
            prop_assert_eq!(&fingers, &out.fingers);
        }
        (None, Err(_)) => prop_assert!(!out.unchanged),
        (t, m) => prop_assert!(false, "prost {:?}, ours {:?} on {:?}", t, m, bytes),
    }
    Ok(())
}

/// [`agree_shape`] on `bytes`, cut short at `cut`, and with `junk` appended.
fn agree_shape_whole_cut_and_extended(
    bytes: &[u8],
    feedback: bool,
    cut: prop::sample::Index,
    junk: &[u8],
) -> std::result::Result<(), TestCaseError> {
    let mut out = GloveShape::default();
    agree_shape(bytes, feedback, &mut out)?;
    agree_shape(&bytes[..cut.index(bytes.len() + 1)], feedback, &mut out)?;
    let mut longer = bytes.to_vec();
    longer.extend_from_slice(junk);
    agree_shape(&longer, feedback, &mut out)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn joint_states_shapes_read_as_prost_decodes_them(names in names(), a in ints(), b in ints(), c in ints(), cut in any::<prop::sample::Index>(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
        let m = GloveJointStatesProto { names, positions_e5: a, velocities_e2: b, efforts_e5: c };
        agree_shape_whole_cut_and_extended(&m.encode_to_vec(), false, cut, &junk)?;
    }

    #[test]
    fn feedback_shapes_read_as_prost_decodes_them(m in feedback_proto(), cut in any::<prop::sample::Index>(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
        agree_shape_whole_cut_and_extended(&m.encode_to_vec(), true, cut, &junk)?;
    }

    #[test]
    fn packed_arrays_count_as_prost_reads_them(payload in proptest::collection::vec(prop_oneof![0x80u8..=0xff, 0u8..=0x7f, Just(1u8), Just(0u8)], 0..40), field in 2u8..=4) {
        // One packed field of long, short, cut or overlong varints (tenth bytes 0, 1 or
        // more): counted where prost reads it, refused where prost refuses it.
        let mut bytes = vec![field << 3 | 2, payload.len() as u8];
        bytes.extend_from_slice(&payload);
        let mut shape = GloveShape::default();
        agree_shape(&bytes, false, &mut shape)?;
        agree_shape(&bytes, true, &mut shape)?;
    }

    #[test]
    fn shapes_read_one_after_another_read_as_prost_decodes_each(a in feedback_proto(), b in feedback_proto(), cut in any::<prop::sample::Index>(), order in proptest::collection::vec(0u8..4, 1..8)) {
        // Messages that begin with the names of the one before, and ones that do not, in
        // any order, into one shape.
        let (a, b) = (a.encode_to_vec(), b.encode_to_vec());
        let a_cut = a[..cut.index(a.len() + 1)].to_vec();
        let mut a_longer = a.clone();
        a_longer.extend_from_slice(&b);
        let mut out = GloveShape::default();
        for i in order {
            let bytes = [&a, &b, &a_cut, &a_longer][usize::from(i)];
            agree_shape(bytes, true, &mut out)?;
            agree_shape(bytes, false, &mut out)?;
        }
    }

    #[test]
    fn a_shape_is_unchanged_only_when_its_names_are(a in feedback_proto(), b in feedback_proto(), again in any::<bool>()) {
        // Read `a`, then `b` (or `a` again): `unchanged` says whether the names and
        // fingertips are those of the message before, never wrongly yes.
        let second = if again { a.clone() } else { b };
        let mut shape = GloveShape::default();
        let first_ok = glove_shape(&a.encode_to_vec(), true, &mut shape).is_ok();
        prop_assert!(first_ok);
        let (names, tips) = (shape.names.clone(), shape.fingers.clone());
        glove_shape(&second.encode_to_vec(), true, &mut shape).unwrap();
        let same = shape.names == names && shape.fingers == tips;
        prop_assert!(!shape.unchanged || same, "unchanged, but {:?} {:?} -> {:?} {:?}", names, tips, shape.names, shape.fingers);
        prop_assert!(!again || shape.unchanged);
    }
}
