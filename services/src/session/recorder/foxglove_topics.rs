//! The Foxglove topics of a tick: the objects as `/scene` and `/tf` show them
//! ([`SceneObjects`]), the messages set up once, then filled on every Foxglove tick (`/tf`,
//! `/scene` with the table, the objects and the contact forces, `/joint_states`), and the
//! conversions to the SDK's types at `f32` precision.

use dfs_core::dfs::TickOutput;
use dfs_core::hand::HandModel;
use dfs_core::math::{Isometry, Point, Rotation, Vector};
use dfs_core::object::{RigidObject, Shape};
use dfs_core::scenario::Scene;

use foxglove::messages as fg;

use super::inputs::{HandFrames, Tick};
use super::raw::Messages;
use crate::error::{RecordingError, Result};
use crate::session::*;

/// The objects as `/scene` and `/object/state` show them.
#[derive(Clone)]
pub(super) struct SceneObjects {
    /// Per object: its entity id in `/scene` and frame id in `/tf` (the grasped one's is
    /// [`OBJECT_FRAME`], the others' `object/NAME`), and its shape.
    pub(super) objects: Vec<(String, Shape)>,
    /// Index of the object whose state fills `/object/state`'s main fields.
    pub(super) primary: usize,
    /// Whether `/object/state` lists every object (a scene given as a list of objects).
    pub(super) listed: bool,
}

impl SceneObjects {
    pub(super) fn new(object: &RigidObject, scene: Option<&Scene>) -> Self {
        match scene {
            None => SceneObjects {
                objects: vec![(OBJECT_FRAME.to_owned(), object.shape)],
                primary: 0,
                listed: false,
            },
            Some(scene) => SceneObjects {
                objects: scene
                    .objects
                    .iter()
                    .enumerate()
                    .map(|(i, o)| {
                        let id = if i == scene.target {
                            OBJECT_FRAME.to_owned()
                        } else {
                            format!("{OBJECT_FRAME}/{}", o.name)
                        };
                        (id, o.object.shape)
                    })
                    .collect(),
                primary: scene.target,
                listed: true,
            },
        }
    }
}

/// `/tf`'s transforms, filled on every Foxglove tick: world → the hand's root link, parent →
/// child link per joint, world → the grasped object, then world → each other object.
pub(super) fn frame_transforms(hand: &HandModel, scene: &SceneObjects) -> fg::FrameTransforms {
    let root_name = hand.links[hand.root].name.clone();
    let transform = |parent: &str, child: &str| fg::FrameTransform {
        parent_frame_id: parent.to_owned(),
        child_frame_id: child.to_owned(),
        ..fg::FrameTransform::default()
    };
    let mut transforms = vec![transform(WORLD_FRAME, &root_name)];
    transforms.extend(
        hand.joints
            .iter()
            .map(|j| transform(&hand.links[j.parent].name, &hand.links[j.child].name)),
    );
    transforms.push(transform(WORLD_FRAME, OBJECT_FRAME));
    for (i, (id, _)) in scene.objects.iter().enumerate() {
        if i != scene.primary {
            transforms.push(transform(WORLD_FRAME, id));
        }
    }
    fg::FrameTransforms { transforms }
}

/// `/scene`'s first entity, and the other objects' entities (moved in with the first update).
pub(super) fn scene_entities(scene: &SceneObjects) -> (Vec<fg::SceneEntity>, Vec<fg::SceneEntity>) {
    let entity = |id: &str| fg::SceneEntity {
        frame_id: WORLD_FRAME.to_owned(),
        id: id.to_owned(),
        frame_locked: false,
        ..fg::SceneEntity::default()
    };
    // The grasped object (with the contact forces) first, then the table (added with the
    // first update, see `fill_foxglove`) and the other objects.
    let entities = vec![entity(OBJECT_FRAME)];
    let others: Vec<fg::SceneEntity> = scene
        .objects
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != scene.primary)
        .map(|(_, (id, _))| entity(id))
        .collect();
    (entities, others)
}

/// `/joint_states` with a joint per DOF (`names`), filled on every Foxglove tick.
pub(super) fn fox_joint_states(names: &[String]) -> fg::JointStates {
    fg::JointStates {
        timestamp: None,
        joints: names
            .iter()
            .map(|name| fg::JointState {
                name: name.clone(),
                position: Some(0.0),
                velocity: Some(0.0),
                acceleration: None,
                effort: Some(0.0),
            })
            .collect(),
    }
}

impl Messages {
    /// Fills the Foxglove topics of `tick` (a Foxglove tick): `/tf`, `/scene` and
    /// `/joint_states` (after the raw topics, whose joint values it shows).
    pub(super) fn fill_foxglove(
        &mut self,
        hand: &HandFrames,
        scene: &SceneObjects,
        table_height: Option<f64>,
        tick: &Tick<'_>,
    ) -> Result<()> {
        let stamp = Some(timestamp(tick.time_ns)?);
        let out = tick.output;
        self.fill_tf(hand, scene, tick.link_poses, out, stamp);
        self.fill_scene(scene, table_height, out, stamp);
        self.fill_arrows(hand, out);
        self.fill_joints(stamp);
        Ok(())
    }

    /// `/tf`: the hand's root link in the world, each joint's child link in its parent, and the
    /// objects in the world.
    fn fill_tf(
        &mut self,
        hand: &HandFrames,
        scene: &SceneObjects,
        link_poses: &[Isometry],
        out: &TickOutput,
        stamp: Option<fg::Timestamp>,
    ) {
        let tfs = &mut self.tf.transforms;
        let set = |tf: &mut fg::FrameTransform, iso: &Isometry| {
            tf.timestamp = stamp;
            tf.translation = Some(fg_vector(&iso.translation.vector));
            tf.rotation = Some(fg_quaternion(&iso.rotation));
        };
        set(&mut tfs[0], &link_poses[hand.root]);
        for (j, &(parent, child)) in hand.joints.iter().enumerate() {
            let rel = link_poses[parent].inverse() * link_poses[child];
            set(&mut tfs[1 + j], &rel);
        }
        // The grasped object's frame, then the others' in the scene's order.
        let first = 1 + hand.joints.len();
        set(&mut tfs[first], &out.objects[scene.primary].state.pose);
        let others = (0..scene.objects.len()).filter(|&i| i != scene.primary);
        for (k, i) in others.enumerate() {
            set(&mut tfs[first + 1 + k], &out.objects[i].state.pose);
        }
    }

    /// `/scene`: the table and each object with its shape, at its pose.
    fn fill_scene(
        &mut self,
        scene: &SceneObjects,
        table_height: Option<f64>,
        out: &TickOutput,
        stamp: Option<fg::Timestamp>,
    ) {
        // The table: a slab of TABLE_SIZE_M square under the world origin, its top at the
        // table's height (in every update, so that a viewer opening the file mid-way sees it).
        // Entities: the grasped object, the table, the other objects.
        let size = |x: f64, y: f64, z: f64| Some(fg::Vector3 { x, y, z });
        if self.scene.entities.len() == 1 {
            if table_height.is_some() {
                self.scene.entities.push(fg::SceneEntity {
                    frame_id: WORLD_FRAME.to_owned(),
                    id: TABLE_ENTITY.to_owned(),
                    ..fg::SceneEntity::default()
                });
            }
            self.scene.entities.append(&mut self.other_entities);
        }
        if let Some(h) = table_height {
            let table = &mut self.scene.entities[1];
            table.timestamp = stamp;
            table.cubes.clear();
            table.cubes.push(fg::CubePrimitive {
                pose: Some(fg_pose(&Isometry::translation(
                    0.0,
                    0.0,
                    h - 0.5 * TABLE_THICKNESS_M,
                ))),
                size: size(TABLE_SIZE_M, TABLE_SIZE_M, TABLE_THICKNESS_M),
                color: Some(rgba(0.55, 0.45, 0.35, 1.0)),
            });
        }
        let others_from = if table_height.is_some() { 2 } else { 1 };
        let others = (0..scene.objects.len()).filter(|&i| i != scene.primary);
        for (e, i) in std::iter::once((0, scene.primary))
            .chain(others.enumerate().map(|(k, i)| (others_from + k, i)))
        {
            let entity = &mut self.scene.entities[e];
            entity.timestamp = stamp;
            entity.spheres.clear();
            entity.cubes.clear();
            entity.cylinders.clear();
            entity.arrows.clear();
            let p = Some(fg_pose(&out.objects[i].state.pose));
            // The grasped object blue, the others grey.
            let colour = Some(if i == scene.primary {
                rgba(0.25, 0.5, 0.85, 0.8)
            } else {
                rgba(0.6, 0.6, 0.6, 0.8)
            });
            match scene.objects[i].1 {
                Shape::Sphere { radius } => entity.spheres.push(fg::SpherePrimitive {
                    pose: p,
                    size: size(2.0 * radius, 2.0 * radius, 2.0 * radius),
                    color: colour,
                }),
                Shape::Box { half_extents: h } => entity.cubes.push(fg::CubePrimitive {
                    pose: p,
                    size: size(2.0 * h[0], 2.0 * h[1], 2.0 * h[2]),
                    color: colour,
                }),
                Shape::Cylinder {
                    radius,
                    half_height,
                } => entity.cylinders.push(fg::CylinderPrimitive {
                    pose: p,
                    size: size(2.0 * radius, 2.0 * radius, 2.0 * half_height),
                    bottom_scale: 1.0,
                    top_scale: 1.0,
                    color: colour,
                }),
            }
        }
    }

    /// `/scene`'s contact force arrows, on the grasped object's entity.
    fn fill_arrows(&mut self, hand: &HandFrames, out: &TickOutput) {
        // The contact forces, on whichever object each fingertip pushes.
        let entity = &mut self.scene.entities[0];
        for tip in out.tips.iter().take(hand.n_tips) {
            let Some(frame) = tip.frame.filter(|_| tip.in_contact) else {
                continue;
            };
            let object_pose = &out.objects[tip.object.min(out.objects.len() - 1)]
                .state
                .pose;
            let t = &tip.transmitted;
            let f_world = object_pose.rotation * (frame.rot_b * Vector::new(t[0], t[1], t[2]));
            let magnitude = f_world.norm();
            if magnitude.is_nan() || magnitude <= 1e-9 {
                continue;
            }
            let point_world = object_pose * Point::from(frame.p_b);
            let rotation =
                Rotation::rotation_between(&Vector::x(), &f_world).unwrap_or_else(|| {
                    // Antiparallel to +x: half a turn about z.
                    Rotation::from_axis_angle(&Vector::z_axis(), std::f64::consts::PI)
                });
            let length = ARROW_M_PER_N * magnitude;
            let head = (0.25 * length).min(0.01);
            entity.arrows.push(fg::ArrowPrimitive {
                pose: Some(fg::Pose {
                    position: Some(fg_vector(&point_world.coords)),
                    orientation: Some(fg_quaternion(&rotation)),
                }),
                shaft_length: length - head,
                shaft_diameter: 0.003,
                head_length: head,
                head_diameter: 0.007,
                color: Some(if tip.slip {
                    rgba(1.0, 0.6, 0.0, 1.0)
                } else {
                    rgba(0.9, 0.1, 0.1, 1.0)
                }),
            });
        }
    }

    /// `/joint_states`: the joint values of the raw topic just filled, at `f32` precision.
    fn fill_joints(&mut self, stamp: Option<fg::Timestamp>) {
        self.fox_joints.timestamp = stamp;
        for (i, j) in self.fox_joints.joints.iter_mut().enumerate() {
            j.position = Some(f32p(self.joints.positions[i]));
            j.velocity = Some(f32p(self.joints.velocities[i]));
            j.effort = Some(f32p(self.joints.efforts[i]));
        }
    }
}

/// Id of the table's entity in `/scene`.
pub const TABLE_ENTITY: &str = "table";
/// Side of the table shown in `/scene` (m).
const TABLE_SIZE_M: f64 = 1.0;
/// Thickness of the table shown in `/scene` (m).
const TABLE_THICKNESS_M: f64 = 0.02;

/// A Foxglove timestamp of `ns` since the session's start.
pub(super) fn timestamp(ns: u64) -> Result<fg::Timestamp> {
    let sec = u32::try_from(ns / 1_000_000_000).map_err(|_| RecordingError::Serialize {
        topic: TOPIC_TF.to_owned(),
        detail: format!("log time {ns} ns is past what a Foxglove timestamp holds"),
    })?;
    Ok(fg::Timestamp::new(sec, (ns % 1_000_000_000) as u32))
}

/// A Foxglove topic's number: `x` at `f32` precision, kept as the schema's `double`.
///
/// The Foxglove topics draw what the raw topics record, and `f32` (a relative 6e-8: 60 nm at a
/// metre, 1e-7 of a unit quaternion) is far finer than the raw topics' steps (1e-6 m, 1e-6,
/// 1e-5 rad). A `double` that holds an `f32` ends in 29 zero bits, which zstd takes for
/// almost nothing: `/tf`, `/scene` and `/joint_states` come out a third smaller (0.73 MB of a
/// minute's 11.48 MB). A value beyond `f32`'s range (no real pose or angle) stays as it is,
/// never infinite.
fn f32p(x: f64) -> f64 {
    let y = x as f32;
    if y.is_finite() {
        f64::from(y)
    } else {
        x
    }
}

pub(in crate::session) fn fg_vector(v: &Vector) -> fg::Vector3 {
    fg::Vector3 {
        x: f32p(v.x),
        y: f32p(v.y),
        z: f32p(v.z),
    }
}

fn fg_quaternion(r: &Rotation) -> fg::Quaternion {
    let q = r.quaternion();
    fg::Quaternion {
        x: f32p(q.i),
        y: f32p(q.j),
        z: f32p(q.k),
        w: f32p(q.w),
    }
}

pub(in crate::session) fn fg_pose(iso: &Isometry) -> fg::Pose {
    fg::Pose {
        position: Some(fg_vector(&iso.translation.vector)),
        orientation: Some(fg_quaternion(&iso.rotation)),
    }
}

fn rgba(r: f64, g: f64, b: f64, a: f64) -> fg::Color {
    fg::Color { r, g, b, a }
}
