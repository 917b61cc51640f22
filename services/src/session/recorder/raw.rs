//! The raw topics of a tick: the reused [`Messages`] (SI messages filled in place), quantised
//! and encoded as protobuf (no allocation per tick once warm), and the velocities taken from
//! the tick before.

use dfs_core::dfs::BodyContact;
use dfs_core::hand::HandModel;
use dfs_core::math::{Isometry, Rotation, Vector};

use foxglove::messages as fg;

use super::foxglove_topics::{fox_joint_states, frame_transforms, scene_entities, SceneObjects};
use super::inputs::{Batch, HandFrames, Tick};
use super::ALL_TOPICS;
use crate::error::{RecordingError, Result};
use crate::foxglove::{Pose, Quaternion, Vector3};
use crate::session::messages::*;
use crate::session::proto::{GloveJointStatesProto, Quantiser};
use crate::session::*;

/// Reused message instances: filled in place every tick, so that serialising the raw topics
/// allocates nothing once warm. The raw topics are filled in SI units, then quantised and
/// encoded as protobuf ([`super::proto`]); the Foxglove topics are the SDK's own types.
///
/// [`super::proto`]: crate::session::proto
pub(super) struct Messages {
    /// `/glove/joint_states` without its DOF names (see `names_pb`).
    pub(super) joints: GloveJointStates,
    /// `/glove/feedback` without its DOF names (see `names_pb`).
    pub(super) feedback: GloveFeedback,
    pub(super) contacts: Contacts,
    pub(super) object: messages::ObjectState,
    /// Which object fills `object`'s main fields, and whether it lists every object.
    pub(super) primary: usize,
    pub(super) listed: bool,
    pub(super) quantiser: Quantiser,
    /// The DOF names as protobuf (`repeated string names = 1`), encoded once: the first bytes
    /// of every `/glove/joint_states` and `/glove/feedback` message (field 1 of both, so
    /// written first), the same every tick; the rest is encoded from SI messages without names.
    pub(super) names_pb: Vec<u8>,
    pub(super) tf: fg::FrameTransforms,
    pub(super) scene: fg::SceneUpdate,
    /// The entities of the objects other than the grasped one, moved into `scene` after the
    /// table's with the first update.
    pub(super) other_entities: Vec<fg::SceneEntity>,
    pub(super) fox_joints: fg::JointStates,
    pub(super) prev_q: Vec<f64>,
    pub(super) prev_time_ns: Option<u64>,
}

impl Messages {
    pub(super) fn new(hand: &HandModel, scene: &SceneObjects) -> Self {
        let n = hand.dof();
        let names = hand.dof_names.clone();
        let tip_names: Vec<String> = hand.fingertips.iter().map(|t| t.name.clone()).collect();
        let joints = GloveJointStates {
            names: names.clone(),
            positions: vec![0.0; n],
            velocities: vec![0.0; n],
            efforts: vec![0.0; n],
        };
        let feedback = GloveFeedback {
            names: names.clone(),
            motor_positions: vec![0.0; n],
            motor_velocities: vec![0.0; n],
            feedback_torques: vec![0.0; n],
            fingers: tip_names
                .iter()
                .map(|name| FingerFeedback {
                    name: name.clone(),
                    ..FingerFeedback::default()
                })
                .collect(),
        };
        let contacts = contacts_message(hand, &tip_names);
        let tf = frame_transforms(hand, scene);
        let (entities, others) = scene_entities(scene);
        let fox_joints = fox_joint_states(&names);
        // The DOF names encoded once, and left out of the SI messages.
        let names_pb = prost::Message::encode_to_vec(&GloveJointStatesProto {
            names: joints.names.clone(),
            ..GloveJointStatesProto::default()
        });
        let (mut joints, mut feedback) = (joints, feedback);
        joints.names.clear();
        feedback.names.clear();
        Self {
            quantiser: Quantiser::default(),
            names_pb,
            joints,
            feedback,
            contacts,
            object: messages::ObjectState {
                objects: if scene.listed {
                    vec![messages::SceneObjectState::default(); scene.objects.len()]
                } else {
                    Vec::new()
                },
                index: scene.primary as u32,
                ..messages::ObjectState::default()
            },
            primary: scene.primary,
            listed: scene.listed,
            other_entities: others,
            tf,
            scene: fg::SceneUpdate {
                deletions: Vec::new(),
                entities,
            },
            fox_joints,
            prev_q: vec![0.0; n],
            prev_time_ns: None,
        }
    }

    /// Fills the raw topics of `tick` and quantises them, encoding each at the end of `batch`
    /// if one is given; the first value the quantiser refuses is the error (the batch then
    /// holds the topics before its own).
    pub(super) fn raw_topics(
        &mut self,
        hand: &HandFrames,
        tick: &Tick<'_>,
        batch: Option<&mut Batch>,
    ) -> Result<()> {
        let t = tick.time_ns;
        self.fill_raw(hand, tick);
        let q = &mut self.quantiser;
        q.refused = None;
        // Without a batch (naming a refused field), the messages go to a buffer of their own.
        let mut spare = Vec::new();
        let (data, mut items) = match batch {
            Some(b) => (&mut b.data, Some(&mut b.items)),
            None => (&mut spare, None),
        };
        for topic in 0..RAW_TOPICS.len() as u8 {
            let start = data.len();
            match topic {
                0 => {
                    data.extend_from_slice(&self.names_pb);
                    q.encode_joint_states(&self.joints, data);
                }
                1 => {
                    data.extend_from_slice(&self.names_pb);
                    q.encode_feedback(&self.feedback, data);
                }
                2 => q.encode_contacts(&self.contacts, data),
                _ => q.encode_object(&self.object, data),
            }
            refused(q, topic)?;
            if let Some(items) = items.as_deref_mut() {
                items.push((topic, t, start, data.len()));
            }
        }
        Ok(())
    }

    fn fill_raw(&mut self, hand: &HandFrames, tick: &Tick<'_>) {
        let n = hand.dof;
        let out = tick.output;
        let dt = match self.prev_time_ns {
            Some(prev) if tick.time_ns > prev => (tick.time_ns - prev) as f64 * 1e-9,
            _ => 0.0,
        };
        for i in 0..n {
            let q = tick.q.get(i).copied().unwrap_or(0.0);
            self.joints.positions[i] = q;
            self.joints.velocities[i] = if dt > 0.0 {
                (q - self.prev_q[i]) / dt
            } else {
                0.0
            };
            self.joints.efforts[i] = tick.tau.get(i).copied().unwrap_or(0.0);
            self.feedback.motor_positions[i] = out.motor_q[i];
            self.feedback.motor_velocities[i] = out.motor_qd[i];
            self.feedback.feedback_torques[i] = out.feedback_torque[i];
        }
        self.contacts.n_contacts = out.n_contacts as u32;
        for k in 0..hand.n_tips {
            let tip = &out.tips[k];
            let fb = &mut self.feedback.fingers[k];
            fb.feedback_force_world = v3(&tip.feedback_force_world);
            fb.tip_force_world = v3(&tip.tip_force_world);
            let c = &mut self.contacts.fingers[k];
            c.touching = tip.touching;
            c.in_contact = tip.in_contact;
            match (&tip.frame, tip.touching) {
                (Some(frame), true) => {
                    c.point_b = v3(&frame.p_b);
                    c.normal_b = v3(&frame.normal_b());
                    c.penetration = tip.penetration;
                }
                _ => {
                    c.point_b = Vector3::default();
                    c.normal_b = Vector3::default();
                    c.penetration = 0.0;
                }
            }
            c.intensity = intensity(&tip.intensity);
            c.transmitted = intensity(&tip.transmitted);
            c.feedback = intensity(&tip.feedback);
            c.slip = tip.slip;
            c.in_cone = !tip.slip;
            c.object = if tip.touching { tip.object as u32 } else { 0 };
        }
        // Whole-hand contacts: a palm or phalanx pushes with its spring, so its intensity is
        // what it transmits; it has no feedback of its own (the hand feels it through Jᵀ).
        let none = BodyContact::default();
        for s in 0..hand.n_shapes {
            let b = tick.body.get(s).unwrap_or(&none);
            let c = &mut self.contacts.fingers[hand.n_tips + s];
            c.touching = b.touching;
            c.in_contact = b.in_contact;
            match (&b.frame, b.touching) {
                (Some(frame), true) => {
                    c.point_b = v3(&frame.p_b);
                    c.normal_b = v3(&frame.normal_b());
                    c.penetration = b.penetration;
                }
                _ => {
                    c.point_b = Vector3::default();
                    c.normal_b = Vector3::default();
                    c.penetration = 0.0;
                }
            }
            c.intensity = intensity(&b.transmitted);
            c.transmitted = intensity(&b.transmitted);
            c.slip = b.slip;
            c.in_cone = !b.slip;
            c.object = if b.touching { b.object as u32 } else { 0 };
        }
        let o = &mut self.object;
        let main = &out.objects[self.primary];
        o.pose = pose(&main.state.pose);
        o.linear_velocity = v3(&main.state.linear_velocity);
        o.angular_velocity_b = v3(&main.state.angular_velocity_b);
        o.f_ext_b = wrench6(&main.f_ext_b);
        o.object_force_b = wrench6(&main.object_force_b);
        o.table_force_b = wrench6(&main.table_force_b);
        o.pose_in_hand = pose(&(tick.base.inverse() * main.state.pose));
        if self.listed {
            for (entry, each) in o.objects.iter_mut().zip(&out.objects) {
                entry.pose = pose(&each.state.pose);
                entry.linear_velocity = v3(&each.state.linear_velocity);
                entry.angular_velocity_b = v3(&each.state.angular_velocity_b);
            }
        }
    }

    /// The tick just recorded becomes the one the next velocities are taken from (not called
    /// for a refused tick, which records nothing).
    pub(super) fn advance(&mut self, tick: &Tick<'_>) {
        for (prev, &q) in self.prev_q.iter_mut().zip(tick.q) {
            *prev = q;
        }
        self.prev_time_ns = Some(tick.time_ns);
    }
}

/// `/dfs/contacts`: the fingertips (`tip_names`), then one entry per contact shape of `hand`
/// (encoded only while it touches).
fn contacts_message(hand: &HandModel, tip_names: &[String]) -> Contacts {
    Contacts {
        n_contacts: 0,
        fingers: tip_names
            .iter()
            .map(|name| FingerContact {
                name: name.clone(),
                ..FingerContact::default()
            })
            .chain(hand.contact_shapes.iter().map(|s| {
                FingerContact {
                    name: s.name.clone(),
                    part: ContactPart::of_body(s.part),
                    link: hand
                        .links
                        .get(s.link)
                        .map(|l| l.name.clone())
                        .unwrap_or_default(),
                    ..FingerContact::default()
                }
            }))
            .collect(),
    }
}

/// The quantiser's refusal as the recorder's error: a value of raw topic `topic` that is not
/// finite or too large for its field (nothing of the tick is written then).
fn refused(q: &Quantiser, topic: u8) -> Result<()> {
    match &q.refused {
        None => Ok(()),
        Some((field, value)) => Err(RecordingError::NonFiniteNumber {
            topic: ALL_TOPICS[topic as usize].to_owned(),
            path: field.clone(),
            value: if value.is_finite() {
                format!("{value} (beyond the field's range)")
            } else {
                value.to_string()
            },
        }),
    }
}

fn v3(v: &Vector) -> Vector3 {
    Vector3::new(v.x, v.y, v.z)
}

fn quat(r: &Rotation) -> Quaternion {
    let q = r.quaternion();
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

fn pose(iso: &Isometry) -> Pose {
    Pose {
        position: v3(&iso.translation.vector),
        orientation: quat(&iso.rotation),
    }
}

fn intensity(c: &dfs_core::contact::Intensity) -> Intensity4 {
    Intensity4 {
        x: c[0],
        y: c[1],
        z: c[2],
        torsion: c[3],
    }
}

fn wrench6(w: &dfs_core::math::Wrench) -> [f64; 6] {
    [w[0], w[1], w[2], w[3], w[4], w[5]]
}
