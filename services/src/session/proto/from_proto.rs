//! The fixed-point prost messages of the raw topics back in SI units (the `*_from_proto`
//! functions): each step multiplied back.

use super::*;
use crate::foxglove::{Pose, Quaternion, Vector3};
use crate::session::messages::{self, *};

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
