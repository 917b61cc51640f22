//! The protobuf field keys of the raw topics, taken once from the prost-generated types
//! ([`Keys`]), so that the encoder writes the fields `session.proto` defines.

use super::*;

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
pub(super) struct Keys {
    pub(super) vector: [u64; 3],
    pub(super) quaternion: [u64; 4],
    pub(super) intensity: [u64; 4],
    pub(super) position: u64,
    pub(super) orientation: u64,
    pub(super) force: u64,
    pub(super) torque: u64,
    pub(super) js_names: u64,
    pub(super) js_values: [u64; 3],
    pub(super) fb_names: u64,
    pub(super) fb_values: [u64; 3],
    pub(super) fb_fingers: u64,
    pub(super) ff_name: u64,
    pub(super) ff_feedback_force: u64,
    pub(super) ff_tip_force: u64,
    pub(super) c_n_contacts: u64,
    pub(super) c_fingers: u64,
    pub(super) fc_name: u64,
    pub(super) fc_touching: u64,
    pub(super) fc_in_contact: u64,
    pub(super) fc_point: u64,
    pub(super) fc_normal: u64,
    pub(super) fc_penetration: u64,
    pub(super) fc_intensities: [u64; 3],
    pub(super) fc_in_cone: u64,
    pub(super) fc_slip: u64,
    pub(super) fc_object: u64,
    pub(super) fc_part: u64,
    pub(super) fc_link: u64,
    /// Of `ObjectState`: pose, linear and angular velocity, the three wrenches, pose in hand.
    pub(super) object: [u64; 7],
    /// Of `ObjectState`: `index` and `objects`.
    pub(super) object_index: u64,
    pub(super) object_objects: u64,
    /// Of `SceneObjectState`: pose, linear and angular velocity.
    pub(super) scene_object: [u64; 3],
}

impl Keys {
    pub(super) fn get() -> &'static Keys {
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
