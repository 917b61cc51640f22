//! Session format v2: the raw topics as protobuf, generated from `proto/icms/session.proto`
//! (the one definition of their fields, units and steps), and the conversions between those
//! fixed-point messages and the SI types of [`super::messages`] that the rest of the code
//! works with.
//!
//! Each conversion pair sits together: [`Quantiser`] rounds SI values to the steps the
//! `.proto` names (`_eN`: steps of 10^-N SI units), and the `from_proto` functions multiply
//! back. A value read back is the recorded one to within half a step.

use super::messages::{self, *};
use crate::foxglove::{Pose, Quaternion, Vector3};

#[allow(missing_docs, clippy::all, clippy::pedantic)]
mod generated {
    include!(concat!(env!("OUT_DIR"), "/icms.rs"));
}

pub use generated::{
    Contacts as ContactsProto, FingerContact as FingerContactProto,
    FingerFeedback as FingerFeedbackProto, GloveFeedback as GloveFeedbackProto,
    GloveJointStates as GloveJointStatesProto, Intensityi, ObjectState as ObjectStateProto, Posei,
    Quaternioni, SceneObjectState as SceneObjectStateProto, Vector3i, Wrenchi,
};

/// The compiled `proto/icms/session.proto` (a serialised `google.protobuf.FileDescriptorSet`):
/// the MCAP schema data of every raw topic of a v2 session.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/icms_session.fds"));

/// Message encoding and schema encoding of v2 channels (MCAP's well-known `protobuf`).
pub const PROTOBUF: &str = "protobuf";

/// The session format written by this build: 2 (protobuf on every topic). Format 1 (JSON on
/// every topic) is still read. Written as `format_version` in the `session` metadata record;
/// a file without it is format 1.
pub const FORMAT_VERSION: u32 = 2;

/// Step of a joint angle, rad (the `_e5` fields of the glove topics).
pub const JOINT_ANGLE: f64 = 1e-5;
/// Step of a joint velocity, rad/s (`_e2`).
pub const JOINT_VELOCITY: f64 = 1e-2;
/// Step of a joint torque, N·m (`_e5`).
pub const JOINT_TORQUE: f64 = 1e-5;
/// Step of a force, N (`_e3`).
pub const FORCE: f64 = 1e-3;
/// Step of a moment (contact torsion, wrench torques), N·m (`_e6`).
pub const MOMENT: f64 = 1e-6;
/// Step of a position, m (`_e6`).
pub const POSITION: f64 = 1e-6;
/// Step of a unit vector's or quaternion's component (`_e6`).
pub const UNIT: f64 = 1e-6;
/// Step of a penetration depth, m (`_e9`).
pub const PENETRATION: f64 = 1e-9;
/// Step of a linear velocity, m/s (`_e6`).
pub const LINEAR_VELOCITY: f64 = 1e-6;
/// Step of an angular velocity, rad/s (`_e6`).
pub const ANGULAR_VELOCITY: f64 = 1e-6;

/// Rounds SI values to integer steps and writes the raw topics' protobuf encoding, remembering
/// the first value that is not finite or does not fit an `i32` (the recorder refuses the tick
/// then, naming it).
///
/// The `encode_*` methods write a message's bytes straight from the SI message: what prost
/// writes for the fixed-point message (the same bytes: fields in tag order, zeros and `None`
/// left out), without building it. The field keys come from the prost-generated types, so
/// `proto/icms/session.proto` stays the one definition of the fields; the methods that fill the
/// prost types ([`joint_states`](Self::joint_states), ...) decode those bytes.
#[derive(Debug, Default)]
pub struct Quantiser {
    /// The first value refused: its field (`efforts[2]`, `pose`) and value.
    pub refused: Option<(String, f64)>,
    /// Where messages are written before they are appended to the caller's buffer: kept at
    /// its longest, so that its room is zeroed once, not for every message.
    scratch: Vec<u8>,
}

/// The first value refused, as [`Quantiser::refused`] holds it.
type Refused = Option<(String, f64)>;

/// `x / step` rounded; 0 (and the field noted in `refused`, if it is the first) if that is not
/// a finite `i32`.
#[inline(always)]
fn quantise(refused: &mut Refused, field: &'static str, x: f64, step: f64) -> i32 {
    steps(x, step).unwrap_or_else(|| {
        refused.get_or_insert_with(|| (field.to_owned(), x));
        0
    })
}

/// `x / step` rounded (half away from zero), if that is a finite `i32`. Written for speed, as
/// the recorder calls it about 130 times a tick: a multiplication by the inverse (folded at
/// compile time for the constant steps) instead of a division, and the rounding by hand (the
/// baseline x86-64 target has no rounding instruction, and `f64::round` is a libm call).
#[inline]
fn steps(x: f64, step: f64) -> Option<i32> {
    let v = x * (1.0 / step);
    if v.is_nan() || v.abs() > f64::from(i32::MAX) - 0.5 {
        return None;
    }
    Some((v + 0.5f64.copysign(v)) as i32)
}

/// Protobuf's zigzag encoding of an `sint32`.
#[inline(always)]
fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

/// Bytes of the varint of `v` (1 to 10).
#[inline(always)]
fn varint_len(v: u64) -> usize {
    (64 - (v | 1).leading_zeros() as usize).div_ceil(7)
}

/// The key (field number and wire type, as a varint) that prost writes first for a message
/// with only the field that `set` sets.
fn key_of<M: prost::Message + Default>(set: impl FnOnce(&mut M)) -> u64 {
    let mut m = M::default();
    set(&mut m);
    let bytes = m.encode_to_vec();
    let mut key = 0;
    for (i, b) in bytes.iter().take(10).enumerate() {
        key |= u64::from(b & 0x7f) << (7 * i);
        if b & 0x80 == 0 {
            return key;
        }
    }
    panic!("no field key in {bytes:?}")
}

/// The keys of every field of the raw topics, taken from the prost-generated types (see
/// [`key_of`]): the field numbers are those of `session.proto`, and a field renamed or removed
/// there does not compile here.
struct Keys {
    vector: [u64; 3],
    quaternion: [u64; 4],
    intensity: [u64; 4],
    position: u64,
    orientation: u64,
    force: u64,
    torque: u64,
    js_names: u64,
    js_values: [u64; 3],
    fb_names: u64,
    fb_values: [u64; 3],
    fb_fingers: u64,
    ff_name: u64,
    ff_feedback_force: u64,
    ff_tip_force: u64,
    c_n_contacts: u64,
    c_fingers: u64,
    fc_name: u64,
    fc_touching: u64,
    fc_in_contact: u64,
    fc_point: u64,
    fc_normal: u64,
    fc_penetration: u64,
    fc_intensities: [u64; 3],
    fc_in_cone: u64,
    fc_slip: u64,
    fc_object: u64,
    fc_part: u64,
    fc_link: u64,
    /// Of `ObjectState`: pose, linear and angular velocity, the three wrenches, pose in hand.
    object: [u64; 7],
    /// Of `ObjectState`: `index` and `objects`.
    object_index: u64,
    object_objects: u64,
    /// Of `SceneObjectState`: pose, linear and angular velocity.
    scene_object: [u64; 3],
}

impl Keys {
    fn get() -> &'static Keys {
        static KEYS: std::sync::OnceLock<Keys> = std::sync::OnceLock::new();
        KEYS.get_or_init(Keys::new)
    }

    fn new() -> Self {
        let v3 = || Some(Vector3i { x: 1, y: 0, z: 0 });
        let name = || "a".to_owned();
        let one = || vec![1];
        let int4 = || {
            Some(Intensityi {
                x_e3: 1,
                ..Intensityi::default()
            })
        };
        Self {
            vector: [
                key_of(|m: &mut Vector3i| m.x = 1),
                key_of(|m: &mut Vector3i| m.y = 1),
                key_of(|m: &mut Vector3i| m.z = 1),
            ],
            quaternion: [
                key_of(|m: &mut Quaternioni| m.x_e6 = 1),
                key_of(|m: &mut Quaternioni| m.y_e6 = 1),
                key_of(|m: &mut Quaternioni| m.z_e6 = 1),
                key_of(|m: &mut Quaternioni| m.w_e6 = 1),
            ],
            intensity: [
                key_of(|m: &mut Intensityi| m.x_e3 = 1),
                key_of(|m: &mut Intensityi| m.y_e3 = 1),
                key_of(|m: &mut Intensityi| m.z_e3 = 1),
                key_of(|m: &mut Intensityi| m.torsion_e6 = 1),
            ],
            position: key_of(|m: &mut Posei| m.position_e6 = v3()),
            orientation: key_of(|m: &mut Posei| m.orientation = Some(Quaternioni::default())),
            force: key_of(|m: &mut Wrenchi| m.force_e3 = v3()),
            torque: key_of(|m: &mut Wrenchi| m.torque_e6 = v3()),
            js_names: key_of(|m: &mut GloveJointStatesProto| m.names = vec![name()]),
            js_values: [
                key_of(|m: &mut GloveJointStatesProto| m.positions_e5 = one()),
                key_of(|m: &mut GloveJointStatesProto| m.velocities_e2 = one()),
                key_of(|m: &mut GloveJointStatesProto| m.efforts_e5 = one()),
            ],
            fb_names: key_of(|m: &mut GloveFeedbackProto| m.names = vec![name()]),
            fb_values: [
                key_of(|m: &mut GloveFeedbackProto| m.motor_positions_e5 = one()),
                key_of(|m: &mut GloveFeedbackProto| m.motor_velocities_e2 = one()),
                key_of(|m: &mut GloveFeedbackProto| m.feedback_torques_e5 = one()),
            ],
            fb_fingers: key_of(|m: &mut GloveFeedbackProto| {
                m.fingers = vec![FingerFeedbackProto::default()]
            }),
            ff_name: key_of(|m: &mut FingerFeedbackProto| m.name = name()),
            ff_feedback_force: key_of(|m: &mut FingerFeedbackProto| {
                m.feedback_force_world_e3 = v3()
            }),
            ff_tip_force: key_of(|m: &mut FingerFeedbackProto| m.tip_force_world_e3 = v3()),
            c_n_contacts: key_of(|m: &mut ContactsProto| m.n_contacts = 1),
            c_fingers: key_of(|m: &mut ContactsProto| {
                m.fingers = vec![FingerContactProto::default()]
            }),
            fc_name: key_of(|m: &mut FingerContactProto| m.name = name()),
            fc_touching: key_of(|m: &mut FingerContactProto| m.touching = true),
            fc_in_contact: key_of(|m: &mut FingerContactProto| m.in_contact = true),
            fc_point: key_of(|m: &mut FingerContactProto| m.point_b_e6 = v3()),
            fc_normal: key_of(|m: &mut FingerContactProto| m.normal_b_e6 = v3()),
            fc_penetration: key_of(|m: &mut FingerContactProto| m.penetration_e9 = 1),
            fc_intensities: [
                key_of(|m: &mut FingerContactProto| m.intensity = int4()),
                key_of(|m: &mut FingerContactProto| m.transmitted = int4()),
                key_of(|m: &mut FingerContactProto| m.feedback = int4()),
            ],
            fc_in_cone: key_of(|m: &mut FingerContactProto| m.in_cone = true),
            fc_slip: key_of(|m: &mut FingerContactProto| m.slip = true),
            fc_object: key_of(|m: &mut FingerContactProto| m.object = 1),
            fc_part: key_of(|m: &mut FingerContactProto| m.part = 1),
            fc_link: key_of(|m: &mut FingerContactProto| m.link = name()),
            object: [
                key_of(|m: &mut ObjectStateProto| m.pose = Some(Posei::default())),
                key_of(|m: &mut ObjectStateProto| m.linear_velocity_e6 = v3()),
                key_of(|m: &mut ObjectStateProto| m.angular_velocity_b_e6 = v3()),
                key_of(|m: &mut ObjectStateProto| m.f_ext_b = Some(Wrenchi::default())),
                key_of(|m: &mut ObjectStateProto| m.object_force_b = Some(Wrenchi::default())),
                key_of(|m: &mut ObjectStateProto| m.table_force_b = Some(Wrenchi::default())),
                key_of(|m: &mut ObjectStateProto| m.pose_in_hand = Some(Posei::default())),
            ],
            object_index: key_of(|m: &mut ObjectStateProto| m.index = 1),
            object_objects: key_of(|m: &mut ObjectStateProto| {
                m.objects = vec![SceneObjectStateProto::default()]
            }),
            scene_object: [
                key_of(|m: &mut SceneObjectStateProto| m.pose = Some(Posei::default())),
                key_of(|m: &mut SceneObjectStateProto| m.linear_velocity_e6 = v3()),
                key_of(|m: &mut SceneObjectStateProto| m.angular_velocity_b_e6 = v3()),
            ],
        }
    }
}

/// Writes the varint of a value (a zigzagged `sint32`, a `uint32`: at most 5 bytes) at `pos`
/// without a branch: each 7-bit group shifted to its byte, the continuation bits of all bytes
/// but the last set, 8 bytes stored and `pos` moved by the varint's length. `buf` must have 8
/// bytes from `pos`.
#[inline(always)]
fn put_value(buf: &mut [u8], pos: &mut usize, v: u32) {
    /// Per count of leading zero bits of the value: the varint's length and its continuation
    /// bits.
    const LENGTHS: [(usize, u64); 33] = {
        let mut t = [(0, 0); 33];
        let mut lz = 0;
        while lz <= 32 {
            let bits: usize = if lz == 32 { 1 } else { 32 - lz };
            let n = bits.div_ceil(7);
            t[lz] = (n, 0x8080_8080_8080_8080 & ((1u64 << (8 * (n - 1))) - 1));
            lz += 1;
        }
        t
    };
    let x = u64::from(v);
    let w = (x & 0x7f)
        | ((x << 1) & 0x7f00)
        | ((x << 2) & 0x7f_0000)
        | ((x << 3) & 0x7f00_0000)
        | ((x << 4) & 0x7f_0000_0000);
    let (n, continuation) = LENGTHS[v.leading_zeros() as usize];
    buf[*pos..*pos + 8].copy_from_slice(&(w | continuation).to_le_bytes());
    *pos += n;
}

/// Writes a key (a varint: one byte for field numbers under 16) at `pos` and returns the
/// position after it. `buf` must have 10 bytes from `pos`.
#[inline(always)]
fn put_key(buf: &mut [u8], pos: &mut usize, mut key: u64) -> usize {
    while key >= 0x80 {
        buf[*pos] = (key & 0x7f) as u8 | 0x80;
        *pos += 1;
        key >>= 7;
    }
    buf[*pos] = key as u8;
    *pos += 1;
    *pos
}

/// Protobuf bytes appended to a `Vec<u8>` without a branch on the values where it can be
/// helped: each write makes room first, a varint is stored as 8 bytes and the cursor moved by
/// its length, a zero field is written and then taken back, and a length-delimited field gets
/// one byte for its length, widened (the body moved) in the rare case it needs more.
struct Wire<'a> {
    /// The message, from 0 to `pos`; what follows is room for the next writes.
    buf: &'a mut Vec<u8>,
    pos: usize,
    refused: &'a mut Refused,
    keys: &'static Keys,
}

impl<'a> Wire<'a> {
    /// A message written into `q`'s scratch buffer.
    fn new(q: &'a mut Quantiser) -> Self {
        Self {
            buf: &mut q.scratch,
            pos: 0,
            refused: &mut q.refused,
            keys: Keys::get(),
        }
    }

    /// Appends the message to `out`.
    fn finish(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.buf[..self.pos]);
    }

    #[inline(always)]
    fn q(&mut self, field: &'static str, x: f64, step: f64) -> i32 {
        quantise(self.refused, field, x, step)
    }

    /// Makes sure `n` bytes can be written at the cursor.
    #[inline(always)]
    fn room(&mut self, n: usize) {
        if self.buf.len() < self.pos + n {
            self.grow(n);
        }
    }

    #[cold]
    #[inline(never)]
    fn grow(&mut self, n: usize) {
        let len = (self.pos + n).max(2 * self.buf.len()).max(4096);
        self.buf.resize(len, 0);
    }

    /// A key, or a length: one byte almost always (field numbers under 16, short messages),
    /// a branch the processor gets right.
    #[inline(always)]
    fn varint(&mut self, v: u64) {
        if v < 0x80 {
            self.buf[self.pos] = v as u8;
            self.pos += 1;
        } else {
            self.long_varint(v);
        }
    }

    #[cold]
    #[inline(never)]
    fn long_varint(&mut self, mut v: u64) {
        self.room(10);
        while v >= 0x80 {
            self.buf[self.pos] = (v & 0x7f) as u8 | 0x80;
            self.pos += 1;
            v >>= 7;
        }
        self.buf[self.pos] = v as u8;
        self.pos += 1;
    }

    /// A value's varint (see [`put_value`]); needs 8 bytes of room.
    #[inline(always)]
    fn value(&mut self, v: u32) {
        put_value(&mut self.buf[..], &mut self.pos, v);
    }

    /// An `sint32` field (left out when 0).
    #[inline(always)]
    fn sint32(&mut self, key: u64, v: i32) {
        self.room(16);
        let start = self.pos;
        self.varint(key);
        self.value(zigzag(v));
        if v == 0 {
            self.pos = start;
        }
    }

    /// A `uint32` field (left out when 0).
    #[inline(always)]
    fn uint32(&mut self, key: u64, v: u32) {
        self.room(16);
        let start = self.pos;
        self.varint(key);
        self.value(v);
        if v == 0 {
            self.pos = start;
        }
    }

    /// A `bool` field (left out when false).
    #[inline(always)]
    fn bool(&mut self, key: u64, v: bool) {
        self.room(16);
        let start = self.pos;
        self.varint(key);
        self.varint(1);
        if !v {
            self.pos = start;
        }
    }

    /// A string (one of a `repeated string`, or a `string` field when not empty).
    fn string(&mut self, key: u64, s: &str) {
        self.room(24 + s.len());
        self.varint(key);
        self.varint(s.len() as u64);
        self.buf[self.pos..self.pos + s.len()].copy_from_slice(s.as_bytes());
        self.pos += s.len();
    }

    /// Starts a length-delimited field: its key and one byte for its length.
    #[inline(always)]
    fn begin(&mut self, key: u64) -> usize {
        self.room(16);
        self.varint(key);
        self.pos += 1;
        self.pos - 1
    }

    /// Ends the length-delimited field [`begin`](Self::begin) started at `at`.
    #[inline(always)]
    fn end(&mut self, at: usize) {
        let len = self.pos - at - 1;
        if len < 0x80 {
            self.buf[at] = len as u8;
        } else {
            self.long_length(at, len);
        }
    }

    #[cold]
    #[inline(never)]
    fn long_length(&mut self, at: usize, len: usize) {
        let n = varint_len(len as u64);
        self.room(n);
        self.buf.copy_within(at + 1..self.pos, at + n);
        let mut v = len;
        for i in 0..n {
            self.buf[at + i] = (v & 0x7f) as u8 | if i + 1 < n { 0x80 } else { 0 };
            v >>= 7;
        }
        self.pos += n - 1;
    }

    /// A `Vector3i` field (left out when all zero).
    #[inline(always)]
    fn vector(&mut self, key: u64, field: &'static str, v: &Vector3, step: f64) {
        let x = self.q(field, v.x, step);
        let y = self.q(field, v.y, step);
        let z = self.q(field, v.z, step);
        if (x | y | z) == 0 {
            return;
        }
        self.small(key, &self.keys.vector, [x, y, z]);
    }

    /// A `Posei` field.
    fn pose(&mut self, key: u64, field: &'static str, p: &Pose) {
        let at = self.begin(key);
        self.vector(self.keys.position, field, &p.position, POSITION);
        let o = &p.orientation;
        let values = [
            self.q(field, o.x, UNIT),
            self.q(field, o.y, UNIT),
            self.q(field, o.z, UNIT),
            self.q(field, o.w, UNIT),
        ];
        self.small(self.keys.orientation, &self.keys.quaternion, values);
        self.end(at);
    }

    /// A `Wrenchi` field.
    fn wrench(&mut self, key: u64, field: &'static str, w: &[f64; 6]) {
        let at = self.begin(key);
        let force = Vector3::new(w[0], w[1], w[2]);
        self.vector(self.keys.force, field, &force, FORCE);
        let torque = Vector3::new(w[3], w[4], w[5]);
        self.vector(self.keys.torque, field, &torque, MOMENT);
        self.end(at);
    }

    /// An `Intensityi` field (left out when all zero).
    #[inline(always)]
    fn intensity(&mut self, key: u64, field: &'static str, c: &Intensity4) {
        let values = [
            self.q(field, c.x, FORCE),
            self.q(field, c.y, FORCE),
            self.q(field, c.z, FORCE),
            self.q(field, c.torsion, MOMENT),
        ];
        if values == [0; 4] {
            return;
        }
        self.small(key, &self.keys.intensity, values);
    }

    /// A message field of `N` `sint32` fields (keys `keys`; zeros left out), written with the
    /// buffer and cursor held in registers (through `self`, each byte stored would make the
    /// compiler load them again).
    #[inline(always)]
    fn small<const N: usize>(&mut self, key: u64, keys: &[u64; N], values: [i32; N]) {
        self.room(16 + 16 * N);
        let (buf, mut pos) = (&mut self.buf[..], self.pos);
        let at = put_key(buf, &mut pos, key);
        pos += 1;
        for (&k, v) in keys.iter().zip(values) {
            let start = pos;
            put_key(buf, &mut pos, k);
            put_value(buf, &mut pos, zigzag(v));
            if v == 0 {
                pos = start;
            }
        }
        self.pos = pos;
        self.end(at);
    }

    /// A packed `repeated sint32` field (left out when empty); a value refused is named
    /// `field[i]`.
    fn packed(&mut self, key: u64, field: &'static str, values: &[f64], step: f64) {
        if values.is_empty() {
            return;
        }
        self.room(16 + 8 * values.len());
        let (buf, mut pos) = (&mut self.buf[..], self.pos);
        let at = put_key(buf, &mut pos, key);
        pos += 1;
        for (i, &x) in values.iter().enumerate() {
            let v = steps(x, step).unwrap_or_else(|| {
                self.refused
                    .get_or_insert_with(|| (format!("{field}[{i}]"), x));
                0
            });
            put_value(buf, &mut pos, zigzag(v));
        }
        self.pos = pos;
        self.end(at);
    }
}

impl Quantiser {
    /// `x / step` rounded; 0 (and the field noted) if that is not a finite `i32`.
    #[inline]
    pub fn q(&mut self, field: &'static str, x: f64, step: f64) -> i32 {
        quantise(&mut self.refused, field, x, step)
    }

    /// Appends the protobuf encoding of `/glove/joint_states` to `out`.
    pub fn encode_joint_states(&mut self, m: &GloveJointStates, out: &mut Vec<u8>) {
        let mut w = Wire::new(self);
        let k = w.keys;
        for name in &m.names {
            w.string(k.js_names, name);
        }
        w.packed(k.js_values[0], "positions", &m.positions, JOINT_ANGLE);
        w.packed(k.js_values[1], "velocities", &m.velocities, JOINT_VELOCITY);
        w.packed(k.js_values[2], "efforts", &m.efforts, JOINT_TORQUE);
        w.finish(out);
    }

    /// Appends the protobuf encoding of `/glove/feedback` to `out`.
    pub fn encode_feedback(&mut self, m: &GloveFeedback, out: &mut Vec<u8>) {
        let mut w = Wire::new(self);
        let k = w.keys;
        for name in &m.names {
            w.string(k.fb_names, name);
        }
        let (p, v, t) = (&m.motor_positions, &m.motor_velocities, &m.feedback_torques);
        w.packed(k.fb_values[0], "motor_positions", p, JOINT_ANGLE);
        w.packed(k.fb_values[1], "motor_velocities", v, JOINT_VELOCITY);
        w.packed(k.fb_values[2], "feedback_torques", t, JOINT_TORQUE);
        for f in &m.fingers {
            let at = w.begin(k.fb_fingers);
            if !f.name.is_empty() {
                w.string(k.ff_name, &f.name);
            }
            let force = &f.feedback_force_world;
            w.vector(k.ff_feedback_force, "feedback_force_world", force, FORCE);
            w.vector(k.ff_tip_force, "tip_force_world", &f.tip_force_world, FORCE);
            w.end(at);
        }
        w.finish(out);
    }

    /// Appends the protobuf encoding of `/dfs/contacts` to `out`.
    pub fn encode_contacts(&mut self, m: &Contacts, out: &mut Vec<u8>) {
        let mut w = Wire::new(self);
        let k = w.keys;
        w.uint32(k.c_n_contacts, m.n_contacts);
        // A palm or phalanx contact shape is written only while it touches (fingertips always).
        for f in m
            .fingers
            .iter()
            .filter(|f| f.part.is_fingertip() || f.touching)
        {
            let at = w.begin(k.c_fingers);
            if !f.name.is_empty() {
                w.string(k.fc_name, &f.name);
            }
            w.bool(k.fc_touching, f.touching);
            w.bool(k.fc_in_contact, f.in_contact);
            w.vector(k.fc_point, "point_b", &f.point_b, POSITION);
            w.vector(k.fc_normal, "normal_b", &f.normal_b, UNIT);
            let penetration = w.q("penetration", f.penetration, PENETRATION);
            w.sint32(k.fc_penetration, penetration);
            let [ki, kt, kf] = k.fc_intensities;
            w.intensity(ki, "intensity", &f.intensity);
            w.intensity(kt, "transmitted", &f.transmitted);
            w.intensity(kf, "feedback", &f.feedback);
            w.bool(k.fc_in_cone, f.in_cone);
            w.bool(k.fc_slip, f.slip);
            w.uint32(k.fc_object, f.object);
            w.uint32(k.fc_part, part_number(f.part));
            if !f.link.is_empty() {
                w.string(k.fc_link, &f.link);
            }
            w.end(at);
        }
        w.finish(out);
    }

    /// Appends the protobuf encoding of `/object/state` to `out`.
    pub fn encode_object(&mut self, m: &messages::ObjectState, out: &mut Vec<u8>) {
        let mut w = Wire::new(self);
        let k = w.keys.object;
        w.pose(k[0], "pose", &m.pose);
        let (v, omega) = (&m.linear_velocity, &m.angular_velocity_b);
        w.vector(k[1], "linear_velocity", v, LINEAR_VELOCITY);
        w.vector(k[2], "angular_velocity_b", omega, ANGULAR_VELOCITY);
        w.wrench(k[3], "f_ext_b", &m.f_ext_b);
        w.wrench(k[4], "object_force_b", &m.object_force_b);
        w.wrench(k[5], "table_force_b", &m.table_force_b);
        w.pose(k[6], "pose_in_hand", &m.pose_in_hand);
        let keys = w.keys;
        w.uint32(keys.object_index, m.index);
        let k = keys.scene_object;
        for o in &m.objects {
            let at = w.begin(keys.object_objects);
            w.pose(k[0], "objects.pose", &o.pose);
            let (v, omega) = (&o.linear_velocity, &o.angular_velocity_b);
            w.vector(k[1], "objects.linear_velocity", v, LINEAR_VELOCITY);
            w.vector(k[2], "objects.angular_velocity_b", omega, ANGULAR_VELOCITY);
            w.end(at);
        }
        w.finish(out);
    }

    /// `/glove/joint_states` into `out` (the decoding of
    /// [`encode_joint_states`](Self::encode_joint_states)).
    pub fn joint_states(&mut self, m: &GloveJointStates, out: &mut GloveJointStatesProto) {
        let mut bytes = Vec::new();
        self.encode_joint_states(m, &mut bytes);
        *out = decode_own(&bytes);
    }

    /// `/glove/feedback` into `out` (the decoding of [`encode_feedback`](Self::encode_feedback)).
    pub fn feedback(&mut self, m: &GloveFeedback, out: &mut GloveFeedbackProto) {
        let mut bytes = Vec::new();
        self.encode_feedback(m, &mut bytes);
        *out = decode_own(&bytes);
    }

    /// `/dfs/contacts` into `out` (the decoding of [`encode_contacts`](Self::encode_contacts)).
    pub fn contacts(&mut self, m: &Contacts, out: &mut ContactsProto) {
        let mut bytes = Vec::new();
        self.encode_contacts(m, &mut bytes);
        *out = decode_own(&bytes);
    }

    /// `/object/state` (the decoding of [`encode_object`](Self::encode_object)).
    pub fn object(&mut self, m: &messages::ObjectState) -> ObjectStateProto {
        let mut bytes = Vec::new();
        self.encode_object(m, &mut bytes);
        decode_own(&bytes)
    }
}

/// A message the [`Quantiser`] encoded, decoded.
fn decode_own<M: prost::Message + Default>(bytes: &[u8]) -> M {
    M::decode(bytes).expect("the quantiser writes valid protobuf")
}

/// Fields added to format 2 since its first files (message, field number): a file's schema
/// may lack them (a file written before them), and its messages then read them as protobuf's
/// default (0, empty). For scenes of several objects: `FingerContact.object`,
/// `ObjectState.index` and `ObjectState.objects`; for whole-hand contact `FingerContact.part`
/// and `FingerContact.link` (a file without them holds fingertips alone).
pub const ADDED_FIELDS: [(&str, i32); 5] = [
    (".icms.FingerContact", 12),
    (".icms.ObjectState", 8),
    (".icms.ObjectState", 9),
    (".icms.FingerContact", 13),
    (".icms.FingerContact", 14),
];

/// The protobuf number of a contact's part (`icms.ContactPart`).
pub(crate) fn part_number(p: ContactPart) -> u32 {
    match p {
        ContactPart::Fingertip => 0,
        ContactPart::Palm => 1,
        ContactPart::Phalanx => 2,
    }
}

/// A contact's part from its protobuf number; a number this version does not know (a later
/// part) reads as a phalanx: some part of the hand other than a fingertip.
pub(crate) fn part_of_number(n: u32) -> ContactPart {
    match n {
        0 => ContactPart::Fingertip,
        1 => ContactPart::Palm,
        _ => ContactPart::Phalanx,
    }
}

/// Where the protobuf schema `theirs` (a serialised `FileDescriptorSet`, as a file's schema
/// record holds it) defines message `name` (e.g. `icms.Contacts`) differently from ours:
/// `None` if it is the same (same fields, numbers, types and labels, recursively through the
/// messages it uses; names of files and comments may differ; a field of [`ADDED_FIELDS`] may
/// be missing), else which field differs and how. A raw topic of another layout would decode
/// into wrong numbers, not fail.
pub fn schema_difference(theirs: &[u8], name: &str) -> Option<String> {
    use prost::Message;
    use prost_types::FileDescriptorSet;
    let ours = FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).expect("our descriptor set");
    let theirs = match FileDescriptorSet::decode(theirs) {
        Ok(fds) => fds,
        Err(e) => {
            return Some(format!(
                "the schema is not a protobuf FileDescriptorSet: {e}"
            ))
        }
    };
    let (ours, theirs) = (message_index(&ours), message_index(&theirs));
    let mut seen = std::collections::BTreeSet::new();
    compare_message(&ours, &theirs, &format!(".{name}"), name, &mut seen)
}

type MessageIndex<'a> = std::collections::BTreeMap<String, &'a prost_types::DescriptorProto>;

fn message_index(fds: &prost_types::FileDescriptorSet) -> MessageIndex<'_> {
    fn add<'a>(out: &mut MessageIndex<'a>, scope: &str, m: &'a prost_types::DescriptorProto) {
        let full = format!("{scope}.{}", m.name());
        for nested in &m.nested_type {
            add(out, &full, nested);
        }
        out.insert(full, m);
    }
    let mut out = MessageIndex::new();
    for f in &fds.file {
        let scope = if f.package().is_empty() {
            String::new()
        } else {
            format!(".{}", f.package())
        };
        for m in &f.message_type {
            add(&mut out, &scope, m);
        }
    }
    out
}

fn compare_message(
    ours: &MessageIndex<'_>,
    theirs: &MessageIndex<'_>,
    full: &str,
    path: &str,
    seen: &mut std::collections::BTreeSet<String>,
) -> Option<String> {
    if !seen.insert(full.to_owned()) {
        return None;
    }
    let mine = ours.get(full)?;
    let Some(other) = theirs.get(full) else {
        return Some(format!(
            "{path}: the schema does not define message {}",
            full.trim_start_matches('.')
        ));
    };
    let describe = |f: &prost_types::FieldDescriptorProto| {
        format!(
            "{} {} {} = {}",
            f.label()
                .as_str_name()
                .trim_start_matches("LABEL_")
                .to_lowercase(),
            if f.type_name().is_empty() {
                f.r#type()
                    .as_str_name()
                    .trim_start_matches("TYPE_")
                    .to_lowercase()
            } else {
                f.type_name().trim_start_matches('.').to_owned()
            },
            f.name(),
            f.number()
        )
    };
    for f in &mine.field {
        let at = format!("{path}.{}", f.name());
        let Some(g) = other.field.iter().find(|g| g.number() == f.number()) else {
            if ADDED_FIELDS.contains(&(full, f.number())) {
                continue;
            }
            return Some(format!(
                "{at}: ours is `{}`; the file's schema has no field {}",
                describe(f),
                f.number()
            ));
        };
        if (g.name(), g.r#type(), g.label(), g.type_name())
            != (f.name(), f.r#type(), f.label(), f.type_name())
        {
            return Some(format!(
                "{at}: ours is `{}`, the file's is `{}`",
                describe(f),
                describe(g)
            ));
        }
        if !f.type_name().is_empty() {
            if let Some(d) = compare_message(ours, theirs, f.type_name(), &at, seen) {
                return Some(d);
            }
        }
    }
    if let Some(g) = other
        .field
        .iter()
        .find(|g| !mine.field.iter().any(|f| f.number() == g.number()))
    {
        return Some(format!(
            "{path}.{}: the file's schema has `{}`, which ours has not",
            g.name(),
            describe(g)
        ));
    }
    None
}

fn s(v: i32, step: f64) -> f64 {
    f64::from(v) * step
}

fn v3(v: Option<Vector3i>, step: f64) -> Vector3 {
    let v = v.unwrap_or_default();
    Vector3::new(s(v.x, step), s(v.y, step), s(v.z, step))
}

fn pose(p: Option<Posei>) -> Pose {
    let p = p.unwrap_or_default();
    let o = p.orientation.unwrap_or_default();
    Pose {
        position: v3(p.position_e6, POSITION),
        orientation: Quaternion {
            x: s(o.x_e6, UNIT),
            y: s(o.y_e6, UNIT),
            z: s(o.z_e6, UNIT),
            w: s(o.w_e6, UNIT),
        },
    }
}

fn wrench(w: Option<Wrenchi>) -> [f64; 6] {
    let w = w.unwrap_or_default();
    let f = v3(w.force_e3, FORCE);
    let t = v3(w.torque_e6, MOMENT);
    [f.x, f.y, f.z, t.x, t.y, t.z]
}

fn intensity(c: Option<Intensityi>) -> Intensity4 {
    let c = c.unwrap_or_default();
    Intensity4 {
        x: s(c.x_e3, FORCE),
        y: s(c.y_e3, FORCE),
        z: s(c.z_e3, FORCE),
        torsion: s(c.torsion_e6, MOMENT),
    }
}

fn all(v: &[i32], step: f64) -> Vec<f64> {
    v.iter().map(|&x| s(x, step)).collect()
}

/// `/glove/joint_states` in SI units.
pub fn joint_states_from_proto(m: GloveJointStatesProto) -> GloveJointStates {
    GloveJointStates {
        positions: all(&m.positions_e5, JOINT_ANGLE),
        velocities: all(&m.velocities_e2, JOINT_VELOCITY),
        efforts: all(&m.efforts_e5, JOINT_TORQUE),
        names: m.names,
    }
}

/// `/glove/feedback` in SI units.
pub fn feedback_from_proto(m: GloveFeedbackProto) -> GloveFeedback {
    GloveFeedback {
        motor_positions: all(&m.motor_positions_e5, JOINT_ANGLE),
        motor_velocities: all(&m.motor_velocities_e2, JOINT_VELOCITY),
        feedback_torques: all(&m.feedback_torques_e5, JOINT_TORQUE),
        names: m.names,
        fingers: m
            .fingers
            .into_iter()
            .map(|f| FingerFeedback {
                feedback_force_world: v3(f.feedback_force_world_e3, FORCE),
                tip_force_world: v3(f.tip_force_world_e3, FORCE),
                name: f.name,
            })
            .collect(),
    }
}

/// `/dfs/contacts` in SI units.
pub fn contacts_from_proto(m: ContactsProto) -> Contacts {
    Contacts {
        n_contacts: m.n_contacts,
        fingers: m
            .fingers
            .into_iter()
            .map(|f| FingerContact {
                touching: f.touching,
                in_contact: f.in_contact,
                point_b: v3(f.point_b_e6, POSITION),
                normal_b: v3(f.normal_b_e6, UNIT),
                penetration: s(f.penetration_e9, PENETRATION),
                intensity: intensity(f.intensity),
                transmitted: intensity(f.transmitted),
                feedback: intensity(f.feedback),
                in_cone: f.in_cone,
                slip: f.slip,
                object: f.object,
                part: part_of_number(f.part as u32),
                link: f.link,
                name: f.name,
            })
            .collect(),
    }
}

/// `/object/state` in SI units.
pub fn object_from_proto(m: ObjectStateProto) -> messages::ObjectState {
    messages::ObjectState {
        pose: pose(m.pose),
        linear_velocity: v3(m.linear_velocity_e6, LINEAR_VELOCITY),
        angular_velocity_b: v3(m.angular_velocity_b_e6, ANGULAR_VELOCITY),
        f_ext_b: wrench(m.f_ext_b),
        object_force_b: wrench(m.object_force_b),
        table_force_b: wrench(m.table_force_b),
        pose_in_hand: pose(m.pose_in_hand),
        index: m.index,
        objects: m
            .objects
            .into_iter()
            .map(|o| messages::SceneObjectState {
                pose: pose(o.pose),
                linear_velocity: v3(o.linear_velocity_e6, LINEAR_VELOCITY),
                angular_velocity_b: v3(o.angular_velocity_b_e6, ANGULAR_VELOCITY),
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
        let back =
            object_from_proto(ObjectStateProto::decode(&*q.object(&m).encode_to_vec()).unwrap());
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
}
