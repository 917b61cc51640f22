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
    Quaternioni, Vector3i, Wrenchi,
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

/// Rounds SI values to integer steps, remembering the first one that is not finite or does not
/// fit an `i32` (the recorder refuses the tick then, naming it).
#[derive(Debug, Default)]
pub struct Quantiser {
    /// The first value refused: its field (`efforts[2]`, `pose`) and value.
    pub refused: Option<(String, f64)>,
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

impl Quantiser {
    /// `x / step` rounded; 0 (and the field noted) if that is not a finite `i32`.
    #[inline]
    pub fn q(&mut self, field: &'static str, x: f64, step: f64) -> i32 {
        steps(x, step).unwrap_or_else(|| {
            self.refused.get_or_insert_with(|| (field.to_owned(), x));
            0
        })
    }

    fn v3(&mut self, field: &'static str, v: &Vector3, step: f64) -> Option<Vector3i> {
        let out = Vector3i {
            x: self.q(field, v.x, step),
            y: self.q(field, v.y, step),
            z: self.q(field, v.z, step),
        };
        // Leave an all-zero vector out of the message (protobuf's default).
        (out != Vector3i::default()).then_some(out)
    }

    fn pose(&mut self, field: &'static str, p: &Pose) -> Posei {
        Posei {
            position_e6: self.v3(field, &p.position, POSITION),
            orientation: Some(Quaternioni {
                x_e6: self.q(field, p.orientation.x, UNIT),
                y_e6: self.q(field, p.orientation.y, UNIT),
                z_e6: self.q(field, p.orientation.z, UNIT),
                w_e6: self.q(field, p.orientation.w, UNIT),
            }),
        }
    }

    fn wrench(&mut self, field: &'static str, w: &[f64; 6]) -> Wrenchi {
        Wrenchi {
            force_e3: self.v3(field, &Vector3::new(w[0], w[1], w[2]), FORCE),
            torque_e6: self.v3(field, &Vector3::new(w[3], w[4], w[5]), MOMENT),
        }
    }

    fn intensity(&mut self, field: &'static str, c: &Intensity4) -> Option<Intensityi> {
        let out = Intensityi {
            x_e3: self.q(field, c.x, FORCE),
            y_e3: self.q(field, c.y, FORCE),
            z_e3: self.q(field, c.z, FORCE),
            torsion_e6: self.q(field, c.torsion, MOMENT),
        };
        (out != Intensityi::default()).then_some(out)
    }

    fn fill(&mut self, field: &'static str, out: &mut Vec<i32>, values: &[f64], step: f64) {
        out.clear();
        for (i, &x) in values.iter().enumerate() {
            out.push(steps(x, step).unwrap_or_else(|| {
                self.refused
                    .get_or_insert_with(|| (format!("{field}[{i}]"), x));
                0
            }));
        }
    }

    /// `/glove/joint_states` into `out`, reusing its buffers (names are copied only when they
    /// differ).
    pub fn joint_states(&mut self, m: &GloveJointStates, out: &mut GloveJointStatesProto) {
        if out.names != m.names {
            out.names.clone_from(&m.names);
        }
        self.fill(
            "positions",
            &mut out.positions_e5,
            &m.positions,
            JOINT_ANGLE,
        );
        self.fill(
            "velocities",
            &mut out.velocities_e2,
            &m.velocities,
            JOINT_VELOCITY,
        );
        self.fill("efforts", &mut out.efforts_e5, &m.efforts, JOINT_TORQUE);
    }

    /// `/glove/feedback` into `out`, reusing its buffers.
    pub fn feedback(&mut self, m: &GloveFeedback, out: &mut GloveFeedbackProto) {
        if out.names != m.names {
            out.names.clone_from(&m.names);
        }
        self.fill(
            "motor_positions",
            &mut out.motor_positions_e5,
            &m.motor_positions,
            JOINT_ANGLE,
        );
        self.fill(
            "motor_velocities",
            &mut out.motor_velocities_e2,
            &m.motor_velocities,
            JOINT_VELOCITY,
        );
        self.fill(
            "feedback_torques",
            &mut out.feedback_torques_e5,
            &m.feedback_torques,
            JOINT_TORQUE,
        );
        out.fingers
            .resize_with(m.fingers.len(), FingerFeedbackProto::default);
        for (f, o) in m.fingers.iter().zip(out.fingers.iter_mut()) {
            if o.name != f.name {
                o.name.clone_from(&f.name);
            }
            o.feedback_force_world_e3 =
                self.v3("feedback_force_world", &f.feedback_force_world, FORCE);
            o.tip_force_world_e3 = self.v3("tip_force_world", &f.tip_force_world, FORCE);
        }
    }

    /// `/dfs/contacts` into `out`, reusing its buffers.
    pub fn contacts(&mut self, m: &Contacts, out: &mut ContactsProto) {
        out.n_contacts = m.n_contacts;
        out.fingers
            .resize_with(m.fingers.len(), FingerContactProto::default);
        for (f, o) in m.fingers.iter().zip(out.fingers.iter_mut()) {
            if o.name != f.name {
                o.name.clone_from(&f.name);
            }
            o.touching = f.touching;
            o.in_contact = f.in_contact;
            o.point_b_e6 = self.v3("point_b", &f.point_b, POSITION);
            o.normal_b_e6 = self.v3("normal_b", &f.normal_b, UNIT);
            o.penetration_e9 = self.q("penetration", f.penetration, PENETRATION);
            o.intensity = self.intensity("intensity", &f.intensity);
            o.transmitted = self.intensity("transmitted", &f.transmitted);
            o.feedback = self.intensity("feedback", &f.feedback);
            o.in_cone = f.in_cone;
            o.slip = f.slip;
        }
    }

    /// `/object/state`.
    pub fn object(&mut self, m: &messages::ObjectState) -> ObjectStateProto {
        ObjectStateProto {
            pose: Some(self.pose("pose", &m.pose)),
            linear_velocity_e6: self.v3("linear_velocity", &m.linear_velocity, LINEAR_VELOCITY),
            angular_velocity_b_e6: self.v3(
                "angular_velocity_b",
                &m.angular_velocity_b,
                ANGULAR_VELOCITY,
            ),
            f_ext_b: Some(self.wrench("f_ext_b", &m.f_ext_b)),
            object_force_b: Some(self.wrench("object_force_b", &m.object_force_b)),
            table_force_b: Some(self.wrench("table_force_b", &m.table_force_b)),
            pose_in_hand: Some(self.pose("pose_in_hand", &m.pose_in_hand)),
        }
    }
}

/// Where the protobuf schema `theirs` (a serialised `FileDescriptorSet`, as a file's schema
/// record holds it) defines message `name` (e.g. `icms.Contacts`) differently from ours:
/// `None` if it is the same (same fields, numbers, types and labels, recursively through the
/// messages it uses; names of files and comments may differ), else which field differs and
/// how. A raw topic of another layout would decode into wrong numbers, not fail.
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
        };
        let mut q = Quantiser::default();
        let back =
            object_from_proto(ObjectStateProto::decode(&*q.object(&m).encode_to_vec()).unwrap());
        assert!(q.refused.is_none());
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
