//! Decoding the raw topics of session format 2 straight into their SI types, reusing the
//! caller's message (its vectors and name strings): no allocation per message once warm.
//!
//! # Why not prost
//!
//! prost's generated decoders (kept for encoding, and as the reference these are tested
//! against) allocate a `String` for every name and a `Vec` for every repeated field of every
//! message, and the SI conversion allocates again. A 60 s session holds 240 000 raw messages
//! with 15 to 25 names each; measured with `perf` on `icms segment` of a 60 s `sphere-lift`
//! (2026-11-25): 38 % of the time in the allocator, 0.42 s in all. A session of an hour must
//! segment in 10 s. This decoder reads the same wire format (proto3: unknown fields skipped,
//! packed or unpacked repeated scalars, a message field given twice merged, the last scalar
//! winning, groups skipped) into messages it clears and refills.
//!
//! The property tests below hold it to prost: on any bytes, both accept or both refuse, and
//! what both accept converts to the same SI message.

use super::messages::{
    Contacts, FingerContact, FingerFeedback, GloveFeedback, GloveJointStates, Intensity4,
    ObjectState,
};
use super::proto::{
    ANGULAR_VELOCITY, FORCE, JOINT_ANGLE, JOINT_TORQUE, JOINT_VELOCITY, LINEAR_VELOCITY, MOMENT,
    PENETRATION, POSITION, UNIT,
};
use crate::foxglove::{Pose, Quaternion, Vector3};

/// Why bytes do not decode (the wording of prost's errors where there is one).
pub(crate) type DecodeError = &'static str;
type Result<T> = std::result::Result<T, DecodeError>;

/// Wire types of the protobuf encoding.
const VARINT: u8 = 0;
const I64: u8 = 1;
const LEN: u8 = 2;
const SGROUP: u8 = 3;
const EGROUP: u8 = 4;
const I32: u8 = 5;

/// Deepest nesting of groups skipped (prost's recursion limit).
const RECURSION_LIMIT: u32 = 100;

/// A cursor over a message's bytes.
struct Reader<'a> {
    buf: &'a [u8],
}

impl<'a> Reader<'a> {
    fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    #[inline]
    fn varint(&mut self) -> Result<u64> {
        let mut value = 0u64;
        for (i, &byte) in self.buf.iter().take(10).enumerate() {
            if i == 9 && byte > 1 {
                return Err("invalid varint");
            }
            value |= u64::from(byte & 0x7f) << (7 * i);
            if byte < 0x80 {
                self.buf = &self.buf[i + 1..];
                return Ok(value);
            }
        }
        Err("invalid varint")
    }

    /// The next field's number and wire type.
    fn key(&mut self) -> Result<(u32, u8)> {
        let key = self.varint()?;
        if key > u64::from(u32::MAX) {
            return Err("invalid key value");
        }
        let wire = (key & 7) as u8;
        if wire > I32 {
            return Err("invalid wire type value");
        }
        let tag = (key >> 3) as u32;
        if tag == 0 {
            return Err("invalid tag value: 0");
        }
        Ok((tag, wire))
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        if n > self.buf.len() {
            return Err("buffer underflow");
        }
        let (head, rest) = self.buf.split_at(n);
        self.buf = rest;
        Ok(head)
    }

    fn len_delimited(&mut self) -> Result<&'a [u8]> {
        let n = self.varint()?;
        let n = usize::try_from(n).map_err(|_| "buffer underflow")?;
        self.take(n)
    }

    /// Skips a field of an unknown number.
    fn skip(&mut self, tag: u32, wire: u8, depth: u32) -> Result<()> {
        match wire {
            VARINT => self.varint().map(drop),
            I64 => self.take(8).map(drop),
            I32 => self.take(4).map(drop),
            LEN => self.len_delimited().map(drop),
            SGROUP => {
                if depth >= RECURSION_LIMIT {
                    return Err("recursion limit reached");
                }
                loop {
                    let (inner, w) = self.key()?;
                    if w == EGROUP {
                        if inner != tag {
                            return Err("unexpected end group tag");
                        }
                        return Ok(());
                    }
                    self.skip(inner, w, depth + 1)?;
                }
            }
            _ => Err("unexpected end group tag"),
        }
    }
}

fn expect(wire: u8, want: u8) -> Result<()> {
    if wire == want {
        Ok(())
    } else {
        Err("invalid wire type")
    }
}

fn sint32(v: u64) -> i32 {
    let v = v as u32;
    ((v >> 1) as i32) ^ -((v & 1) as i32)
}

/// A `sint32` field scaled by `step`.
fn scaled(r: &mut Reader<'_>, wire: u8, step: f64) -> Result<f64> {
    expect(wire, VARINT)?;
    Ok(f64::from(sint32(r.varint()?)) * step)
}

fn boolean(r: &mut Reader<'_>, wire: u8) -> Result<bool> {
    expect(wire, VARINT)?;
    Ok(r.varint()? != 0)
}

/// A repeated `sint32` field, packed or not, appended to `out` scaled by `step`.
fn repeated(r: &mut Reader<'_>, wire: u8, step: f64, out: &mut Vec<f64>) -> Result<()> {
    if wire == LEN {
        let mut packed = Reader {
            buf: r.len_delimited()?,
        };
        while !packed.is_empty() {
            out.push(f64::from(sint32(packed.varint()?)) * step);
        }
        Ok(())
    } else {
        out.push(scaled(r, wire, step)?);
        Ok(())
    }
}

/// A string field into `out` (its allocation reused).
fn string_into(r: &mut Reader<'_>, wire: u8, out: &mut String) -> Result<()> {
    expect(wire, LEN)?;
    let bytes = r.len_delimited()?;
    // The same name as the message before (every tick names the same DOFs and fingertips):
    // already valid UTF-8, nothing to copy.
    if out.as_bytes() == bytes {
        return Ok(());
    }
    let s = std::str::from_utf8(bytes)
        .map_err(|_| "invalid string value: data is not UTF-8 encoded")?;
    out.clear();
    out.push_str(s);
    Ok(())
}

/// A repeated string field: the next of `names`, counted by `n` (entries past `n` are spare
/// allocations from earlier messages).
fn name_into(r: &mut Reader<'_>, wire: u8, names: &mut Vec<String>, n: &mut usize) -> Result<()> {
    if *n == names.len() {
        names.push(String::new());
    }
    string_into(r, wire, &mut names[*n])?;
    *n += 1;
    Ok(())
}

/// The fields of an embedded message, each handed to `field`.
fn message(
    r: &mut Reader<'_>,
    wire: u8,
    mut field: impl FnMut(&mut Reader<'_>, u32, u8) -> Result<bool>,
) -> Result<()> {
    expect(wire, LEN)?;
    let mut inner = Reader {
        buf: r.len_delimited()?,
    };
    fields(&mut inner, &mut field)
}

/// Every field of `r`: `field` decodes the ones it knows (returning `true`), the others are
/// skipped.
fn fields(
    r: &mut Reader<'_>,
    field: &mut impl FnMut(&mut Reader<'_>, u32, u8) -> Result<bool>,
) -> Result<()> {
    while !r.is_empty() {
        let (tag, wire) = r.key()?;
        if !field(r, tag, wire)? {
            r.skip(tag, wire, 0)?;
        }
    }
    Ok(())
}

#[inline]
fn vector3(r: &mut Reader<'_>, wire: u8, step: f64, v: &mut Vector3) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => v.x = scaled(r, wire, step)?,
            2 => v.y = scaled(r, wire, step)?,
            3 => v.z = scaled(r, wire, step)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

fn quaternion(r: &mut Reader<'_>, wire: u8, q: &mut Quaternion) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => q.x = scaled(r, wire, UNIT)?,
            2 => q.y = scaled(r, wire, UNIT)?,
            3 => q.z = scaled(r, wire, UNIT)?,
            4 => q.w = scaled(r, wire, UNIT)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

fn pose(r: &mut Reader<'_>, wire: u8, p: &mut Pose) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => vector3(r, wire, POSITION, &mut p.position)?,
            2 => quaternion(r, wire, &mut p.orientation)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

fn wrench(r: &mut Reader<'_>, wire: u8, w: &mut [f64; 6]) -> Result<()> {
    let mut f = Vector3::new(w[0], w[1], w[2]);
    let mut t = Vector3::new(w[3], w[4], w[5]);
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => vector3(r, wire, FORCE, &mut f)?,
            2 => vector3(r, wire, MOMENT, &mut t)?,
            _ => return Ok(false),
        }
        Ok(true)
    })?;
    *w = [f.x, f.y, f.z, t.x, t.y, t.z];
    Ok(())
}

fn intensity(r: &mut Reader<'_>, wire: u8, c: &mut Intensity4) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => c.x = scaled(r, wire, FORCE)?,
            2 => c.y = scaled(r, wire, FORCE)?,
            3 => c.z = scaled(r, wire, FORCE)?,
            4 => c.torsion = scaled(r, wire, MOMENT)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

/// Decodes an `icms.GloveJointStates` into `out` (cleared first).
pub(crate) fn joint_states(buf: &[u8], out: &mut GloveJointStates) -> Result<()> {
    out.positions.clear();
    out.velocities.clear();
    out.efforts.clear();
    let mut n = 0;
    let result = fields(&mut Reader { buf }, &mut |r, tag, wire| {
        match tag {
            1 => name_into(r, wire, &mut out.names, &mut n)?,
            2 => repeated(r, wire, JOINT_ANGLE, &mut out.positions)?,
            3 => repeated(r, wire, JOINT_VELOCITY, &mut out.velocities)?,
            4 => repeated(r, wire, JOINT_TORQUE, &mut out.efforts)?,
            _ => return Ok(false),
        }
        Ok(true)
    });
    out.names.truncate(n);
    result
}

/// Decodes an `icms.GloveFeedback` into `out` (cleared first).
pub(crate) fn feedback(buf: &[u8], out: &mut GloveFeedback) -> Result<()> {
    out.motor_positions.clear();
    out.motor_velocities.clear();
    out.feedback_torques.clear();
    let (mut n, mut fingers) = (0, 0);
    let result = fields(&mut Reader { buf }, &mut |r, tag, wire| {
        match tag {
            1 => name_into(r, wire, &mut out.names, &mut n)?,
            2 => repeated(r, wire, JOINT_ANGLE, &mut out.motor_positions)?,
            3 => repeated(r, wire, JOINT_VELOCITY, &mut out.motor_velocities)?,
            4 => repeated(r, wire, JOINT_TORQUE, &mut out.feedback_torques)?,
            5 => {
                if fingers == out.fingers.len() {
                    out.fingers.push(FingerFeedback::default());
                }
                let f = &mut out.fingers[fingers];
                fingers += 1;
                f.feedback_force_world = Vector3::default();
                f.tip_force_world = Vector3::default();
                // The name stays for comparison with the next one (the same, tick after tick)
                // and is cleared if the message has none.
                let mut named = false;
                message(r, wire, |r, tag, wire| {
                    match tag {
                        1 => {
                            string_into(r, wire, &mut f.name)?;
                            named = true;
                        }
                        2 => vector3(r, wire, FORCE, &mut f.feedback_force_world)?,
                        3 => vector3(r, wire, FORCE, &mut f.tip_force_world)?,
                        _ => return Ok(false),
                    }
                    Ok(true)
                })?;
                if !named {
                    f.name.clear();
                }
            }
            _ => return Ok(false),
        }
        Ok(true)
    });
    out.names.truncate(n);
    out.fingers.truncate(fingers);
    result
}

/// Decodes an `icms.Contacts` into `out` (cleared first).
pub(crate) fn contacts(buf: &[u8], out: &mut Contacts) -> Result<()> {
    out.n_contacts = 0;
    let mut fingers = 0;
    let result = fields(&mut Reader { buf }, &mut |r, tag, wire| {
        match tag {
            1 => {
                expect(wire, VARINT)?;
                out.n_contacts = r.varint()? as u32;
            }
            2 => {
                if fingers == out.fingers.len() {
                    out.fingers.push(FingerContact::default());
                }
                let f = &mut out.fingers[fingers];
                fingers += 1;
                let name = std::mem::take(&mut f.name);
                *f = FingerContact::default();
                f.name = name;
                let mut named = false;
                message(r, wire, |r, tag, wire| {
                    match tag {
                        1 => {
                            string_into(r, wire, &mut f.name)?;
                            named = true;
                        }
                        2 => f.touching = boolean(r, wire)?,
                        3 => f.in_contact = boolean(r, wire)?,
                        4 => vector3(r, wire, POSITION, &mut f.point_b)?,
                        5 => vector3(r, wire, UNIT, &mut f.normal_b)?,
                        6 => f.penetration = scaled(r, wire, PENETRATION)?,
                        7 => intensity(r, wire, &mut f.intensity)?,
                        8 => intensity(r, wire, &mut f.transmitted)?,
                        9 => intensity(r, wire, &mut f.feedback)?,
                        10 => f.in_cone = boolean(r, wire)?,
                        11 => f.slip = boolean(r, wire)?,
                        _ => return Ok(false),
                    }
                    Ok(true)
                })?;
                if !named {
                    f.name.clear();
                }
            }
            _ => return Ok(false),
        }
        Ok(true)
    });
    out.fingers.truncate(fingers);
    result
}

/// A pose of all zeros: protobuf's default, not the identity (a missing orientation reads as
/// the zero quaternion, which the reader's check refuses, as it should).
fn zero_pose() -> Pose {
    Pose {
        position: Vector3::default(),
        orientation: Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 0.0,
        },
    }
}

/// Decodes an `icms.ObjectState` into `out` (reset first).
pub(crate) fn object(buf: &[u8], out: &mut ObjectState) -> Result<()> {
    *out = ObjectState {
        pose: zero_pose(),
        pose_in_hand: zero_pose(),
        ..ObjectState::default()
    };
    fields(&mut Reader { buf }, &mut |r, tag, wire| {
        match tag {
            1 => pose(r, wire, &mut out.pose)?,
            2 => vector3(r, wire, LINEAR_VELOCITY, &mut out.linear_velocity)?,
            3 => vector3(r, wire, ANGULAR_VELOCITY, &mut out.angular_velocity_b)?,
            4 => wrench(r, wire, &mut out.f_ext_b)?,
            5 => wrench(r, wire, &mut out.object_force_b)?,
            6 => wrench(r, wire, &mut out.table_force_b)?,
            7 => pose(r, wire, &mut out.pose_in_hand)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

#[cfg(test)]
mod tests {
    use super::super::proto::{self, *};
    use super::*;
    use proptest::prelude::*;
    use prost::Message;

    fn v3i() -> impl Strategy<Value = Option<Vector3i>> {
        proptest::option::of(
            (any::<i32>(), any::<i32>(), any::<i32>()).prop_map(|(x, y, z)| Vector3i { x, y, z }),
        )
    }

    fn intensityi() -> impl Strategy<Value = Option<Intensityi>> {
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

    fn posei() -> impl Strategy<Value = Option<Posei>> {
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

    fn wrenchi() -> impl Strategy<Value = Option<Wrenchi>> {
        proptest::option::of((v3i(), v3i()).prop_map(|(force_e3, torque_e6)| Wrenchi {
            force_e3,
            torque_e6,
        }))
    }

    fn names() -> impl Strategy<Value = Vec<String>> {
        proptest::collection::vec("[a-z_0-9é]{0,8}", 0..6)
    }

    fn ints() -> impl Strategy<Value = Vec<i32>> {
        proptest::collection::vec(any::<i32>(), 0..6)
    }

    fn contacts_proto() -> impl Strategy<Value = ContactsProto> {
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
                    name,
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
                }
            });
        (any::<u32>(), proptest::collection::vec(finger, 0..5)).prop_map(|(n_contacts, fingers)| {
            ContactsProto {
                n_contacts,
                fingers,
            }
        })
    }

    fn feedback_proto() -> impl Strategy<Value = GloveFeedbackProto> {
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

    fn object_proto() -> impl Strategy<Value = ObjectStateProto> {
        (
            posei(),
            v3i(),
            v3i(),
            wrenchi(),
            wrenchi(),
            wrenchi(),
            posei(),
        )
            .prop_map(|(pose, lv, av, f, o, t, ph)| ObjectStateProto {
                pose,
                linear_velocity_e6: lv,
                angular_velocity_b_e6: av,
                f_ext_b: f,
                object_force_b: o,
                table_force_b: t,
                pose_in_hand: ph,
            })
    }

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
    fn agree_whole_cut_and_extended<
        P: Message + Default,
        T: Default + PartialEq + std::fmt::Debug,
    >(
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
            (out.pose.position.x - 1e-6).abs() < 1e-12
                && (out.pose.position.y - 2e-6).abs() < 1e-12
        );
        // positions_e5 = [3, -1] unpacked: key (2 << 3 | 0), zigzag values 6 and 1.
        let mut js = GloveJointStates::default();
        joint_states(&[0x10, 6, 0x10, 1], &mut js).unwrap();
        assert_eq!(js.positions.len(), 2);
        assert!((js.positions[0] - 3e-5).abs() < 1e-12 && (js.positions[1] + 1e-5).abs() < 1e-12);
    }
}
