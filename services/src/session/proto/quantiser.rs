//! [`Quantiser`]: SI messages rounded to the `.proto`'s fixed-point steps and encoded as the
//! raw topics' protobuf bytes (through [`super::encode::Wire`]), or decoded back into the
//! prost types.

use super::encode::Wire;
use super::*;
use crate::session::messages::{self, *};

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
    pub(super) scratch: Vec<u8>,
}

/// The first value refused, as [`Quantiser::refused`] holds it.
pub(super) type Refused = Option<(String, f64)>;

/// `x / step` rounded; 0 (and the field noted in `refused`, if it is the first) if that is not
/// a finite `i32`.
#[inline(always)]
pub(super) fn quantise(refused: &mut Refused, field: &'static str, x: f64, step: f64) -> i32 {
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
pub(super) fn steps(x: f64, step: f64) -> Option<i32> {
    let v = x * (1.0 / step);
    if v.is_nan() || v.abs() > f64::from(i32::MAX) - 0.5 {
        return None;
    }
    Some((v + 0.5f64.copysign(v)) as i32)
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
