//! The hand in a session file: its URDF with link geometry as the MCAP attachment
//! [`HAND_URDF_ATTACHMENT`], and the same link shapes drawn for Foxglove on [`TOPIC_HAND`].
//!
//! # What Foxglove draws, and why this way
//!
//! `/hand` is a `foxglove.SceneUpdate` with one entity per link: `frame_id` is the link's name
//! (a frame of `/tf`), `frame_locked` is true and the lifetime is zero, so each entity follows
//! its link as `/tf` moves it and stays until replaced. Its primitives are the link's shapes
//! ([`dfs_core::hand::link_shapes`]): the hand's own URDF primitives where it has them, else
//! generated segments, palm box and balls, and a sphere per fingertip. Foxglove documents
//! exactly this behaviour for a frame-locked entity ("follow the frame specified in
//! `frame_id` as it moves relative to the fixed frame", docs.foxglove.dev, message schema
//! SceneEntity), on the SDK's own schema, which the 3D panel reads from protobuf MCAP files
//! like `/scene`.
//!
//! The URDF route was not taken for drawing. The 3D panel's URDF layer with a *topic* source
//! lists only topics whose schema is `std_msgs/String` or `std_msgs/msg/String`
//! (`URDF_TOPIC_SCHEMAS` in Foxglove Studio's `Urdfs.ts`), ROS schema names that a protobuf
//! channel cannot carry (its schema name is its message's full name). The panel's special
//! case for a topic named `/robot_description` (any message with a `data` string) is off
//! until enabled in the panel, and it also adds the URDF's joint origins as transforms at
//! time 0, beside `/tf`'s. The URDF is in the file all the same, as an attachment, for any
//! tool that wants the model.
//!
//! # Cost
//!
//! The hand's shapes do not change, so `/hand` is sent on the first tick and then every
//! [`HAND_SCENE_PERIOD_TICKS`] ticks (1 Hz), never at the 1 kHz of the raw topics: a chunk of
//! a session (the writer closes one every second of log time) holds about one, so a viewer
//! that opens or seeks into the middle of a file draws the hand without looking back. On a
//! 60 s `sphere-lift` (glove10) the 60 messages (4.6 kB each before compression) and the 28 kB
//! attachment add 69 kB to 11.40 MB (0.6 %). The message is built once; each send restamps it
//! and allocates nothing.

use dfs_core::hand::urdf_write::{FINGERTIP_RGBA, LINK_RGBA};
use dfs_core::hand::{
    builtin_hand, builtin_spec, hand_urdf, link_shapes, HandModel, LinkShape, Primitive,
    ShapeSource,
};
use dfs_core::math::Vector;
use foxglove::messages as fg;
use foxglove::Encode;

use super::recorder::{fg_pose, fg_vector};
use crate::error::{RecordingError, Result};
use crate::mcap_io::SessionWriter;

/// Foxglove topic of the hand's link shapes (`foxglove.SceneUpdate`, one frame-locked entity
/// per link, in the link's frame).
pub const TOPIC_HAND: &str = "/hand";
/// Name of the MCAP attachment that holds the hand's URDF.
pub const HAND_URDF_ATTACHMENT: &str = "hand.urdf";
/// Media type of the [`HAND_URDF_ATTACHMENT`] (URDF is XML).
pub const HAND_URDF_MEDIA_TYPE: &str = "application/xml";
/// `/hand` is written on ticks whose index is a multiple of this: 1000, once a second at 1 kHz
/// (a multiple of [`super::FOXGLOVE_DECIMATION`], so it comes with a `/tf`).
pub const HAND_SCENE_PERIOD_TICKS: u64 = 1000;

/// The URDF text of a built-in hand, if `hand` is that hand (same name and same model).
fn builtin_source(hand: &HandModel) -> Option<&'static str> {
    let (_, urdf) = builtin_spec(&hand.name)?;
    (builtin_hand(&hand.name).ok()? == *hand).then_some(urdf)
}

/// The shapes a session draws `hand` with: those of [`link_shapes`] with the URDF the hand was
/// built from (`source_urdf`, else the built-in hand's own when `hand` is a built-in one).
pub fn hand_shapes(hand: &HandModel, source_urdf: Option<&str>) -> Vec<LinkShape> {
    link_shapes(hand, source_urdf.or_else(|| builtin_source(hand)))
}

/// The URDF a session carries for `hand` (see [`hand_shapes`]): link and joint names are the
/// frame ids of `/tf`.
pub fn session_hand_urdf(hand: &HandModel, source_urdf: Option<&str>) -> Result<String> {
    hand_urdf(hand, &hand_shapes(hand, source_urdf)).map_err(|e| RecordingError::Serialize {
        topic: HAND_URDF_ATTACHMENT.to_owned(),
        detail: e.to_string(),
    })
}

fn colour(source: ShapeSource) -> fg::Color {
    let [r, g, b, a] = match source {
        ShapeSource::Fingertip => FINGERTIP_RGBA,
        ShapeSource::Urdf | ShapeSource::Generated => LINK_RGBA,
    };
    fg::Color { r, g, b, a }
}

/// The `/hand` message for `shapes` of `hand`: one frame-locked entity per link with shapes,
/// id and frame id the link's name, unstamped.
pub fn hand_scene_update(hand: &HandModel, shapes: &[LinkShape]) -> fg::SceneUpdate {
    let mut entities = Vec::new();
    for (l, link) in hand.links.iter().enumerate() {
        let mut entity = fg::SceneEntity {
            frame_id: link.name.clone(),
            id: link.name.clone(),
            frame_locked: true,
            ..fg::SceneEntity::default()
        };
        for s in shapes.iter().filter(|s| s.link == l) {
            let pose = Some(fg_pose(&s.origin));
            let color = Some(colour(s.source));
            match s.primitive {
                Primitive::Box { size } => entity.cubes.push(fg::CubePrimitive {
                    pose,
                    size: Some(fg_vector(&size)),
                    color,
                }),
                Primitive::Cylinder { radius, length } => {
                    entity.cylinders.push(fg::CylinderPrimitive {
                        pose,
                        size: Some(fg_vector(&Vector::new(2.0 * radius, 2.0 * radius, length))),
                        bottom_scale: 1.0,
                        top_scale: 1.0,
                        color,
                    })
                }
                Primitive::Sphere { radius } => entity.spheres.push(fg::SpherePrimitive {
                    pose,
                    size: Some(fg_vector(&Vector::repeat(2.0 * radius))),
                    color,
                }),
            }
        }
        let empty = entity.cubes.is_empty() && entity.cylinders.is_empty();
        if !(empty && entity.spheres.is_empty()) {
            entities.push(entity);
        }
    }
    fg::SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

/// The hand of one recording: the `/hand` message, built once and restamped for each send.
#[derive(Debug)]
pub(crate) struct HandScene {
    update: fg::SceneUpdate,
}

impl HandScene {
    /// Writes `hand`'s URDF as the [`HAND_URDF_ATTACHMENT`] and registers [`TOPIC_HAND`] on
    /// `writer` (see [`hand_shapes`] for `source_urdf`).
    pub(crate) fn create(
        writer: &mut SessionWriter,
        hand: &HandModel,
        source_urdf: Option<&str>,
    ) -> Result<Self> {
        let shapes = hand_shapes(hand, source_urdf);
        let urdf = hand_urdf(hand, &shapes).map_err(|e| RecordingError::Serialize {
            topic: HAND_URDF_ATTACHMENT.to_owned(),
            detail: e.to_string(),
        })?;
        writer.add_attachment(HAND_URDF_ATTACHMENT, HAND_URDF_MEDIA_TYPE, urdf.as_bytes())?;
        let schema = fg::SceneUpdate::get_schema().ok_or_else(|| RecordingError::Serialize {
            topic: TOPIC_HAND.to_owned(),
            detail: "the Foxglove SDK has no schema for it".to_owned(),
        })?;
        writer.register_protobuf_channel(TOPIC_HAND, &schema.name, &schema.data)?;
        Ok(Self {
            update: hand_scene_update(hand, &shapes),
        })
    }

    /// The `/hand` message to write with tick number `tick` (0 for the first) at `time_ns`
    /// since the session's start, if that tick carries one (every [`HAND_SCENE_PERIOD_TICKS`]th).
    /// Allocates nothing.
    pub(crate) fn due(&mut self, tick: u64, time_ns: u64) -> Option<&fg::SceneUpdate> {
        if !tick.is_multiple_of(HAND_SCENE_PERIOD_TICKS) {
            return None;
        }
        let sec = u32::try_from(time_ns / 1_000_000_000).unwrap_or(u32::MAX);
        let stamp = Some(fg::Timestamp::new(sec, (time_ns % 1_000_000_000) as u32));
        for e in &mut self.update.entities {
            e.timestamp = stamp;
        }
        Some(&self.update)
    }
}
