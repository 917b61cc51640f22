//! Serde types for the Foxglove message schemas we record (`foxglove.FrameTransforms`,
//! `foxglove.SceneUpdate`, `foxglove.JointStates`) and read from glove recordings
//! (`foxglove.PoseInFrame`), matching the official JSON schemas in
//! `services/schemas/` field for field: same names, same JSON types, every required field present.
//!
//! Units are SI (m, rad, s); colours are 0-1. Quaternions are `{x, y, z, w}`.

use serde::{Deserialize, Serialize};

use crate::mcap_io::schemas::{self, JsonSchema};

/// Schema of [`FrameTransforms`] messages.
pub const FRAME_TRANSFORMS_SCHEMA: JsonSchema = schemas::FRAME_TRANSFORMS;
/// Schema of [`SceneUpdate`] messages.
pub const SCENE_UPDATE_SCHEMA: JsonSchema = schemas::SCENE_UPDATE;
/// Schema of [`JointStates`] messages.
pub const JOINT_STATES_SCHEMA: JsonSchema = schemas::JOINT_STATES;

/// A point in time (`time` in the schemas): seconds and nanoseconds, both non-negative.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Timestamp {
    /// Whole seconds.
    pub sec: u32,
    /// Nanoseconds, 0..=999_999_999.
    pub nsec: u32,
}

impl Timestamp {
    /// From nanoseconds (e.g. session log time). Saturates at `u32::MAX` seconds (year 2106).
    pub fn from_nanos(ns: u64) -> Self {
        let sec = ns / 1_000_000_000;
        Self {
            sec: u32::try_from(sec).unwrap_or(u32::MAX),
            nsec: (ns % 1_000_000_000) as u32,
        }
    }

    /// Total nanoseconds.
    pub fn as_nanos(self) -> u64 {
        u64::from(self.sec) * 1_000_000_000 + u64::from(self.nsec)
    }
}

/// A signed span of time (`duration` in the schemas). Zero means "forever" for a
/// [`SceneEntity::lifetime`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Duration {
    /// Whole seconds (may be negative).
    pub sec: i32,
    /// Nanoseconds, 0..=999_999_999.
    pub nsec: u32,
}

/// `foxglove.Vector3`: a 3-vector (position in m, or size).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
}

impl Vector3 {
    /// A vector from components.
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Self { x, y, z }
    }
}

/// `foxglove.Point3`: a position in 3D space (m).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point3 {
    /// x coordinate.
    pub x: f64,
    /// y coordinate.
    pub y: f64,
    /// z coordinate.
    pub z: f64,
}

/// `foxglove.Quaternion`: a rotation, `{x, y, z, w}` (w is the scalar part).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x value.
    pub x: f64,
    /// y value.
    pub y: f64,
    /// z value.
    pub z: f64,
    /// w value (scalar part).
    pub w: f64,
}

impl Quaternion {
    /// The identity rotation.
    pub const IDENTITY: Self = Self {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };
}

impl Default for Quaternion {
    fn default() -> Self {
        Self::IDENTITY
    }
}

/// `foxglove.Pose`: position and orientation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position (m).
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `foxglove.Color`: RGBA, each 0-1.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Color {
    /// Red, 0-1.
    pub r: f64,
    /// Green, 0-1.
    pub g: f64,
    /// Blue, 0-1.
    pub b: f64,
    /// Alpha, 0-1.
    pub a: f64,
}

impl Color {
    /// A colour from components.
    pub const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Self {
        Self { r, g, b, a }
    }
}

/// `foxglove.KeyValuePair`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyValuePair {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// `foxglove.FrameTransform`: pose of `child_frame_id` in `parent_frame_id`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameTransform {
    /// Timestamp of the transform.
    pub timestamp: Timestamp,
    /// Parent frame name.
    pub parent_frame_id: String,
    /// Child frame name.
    pub child_frame_id: String,
    /// Origin of the child frame in the parent frame (m).
    pub translation: Vector3,
    /// Orientation of the child frame in the parent frame.
    pub rotation: Quaternion,
}

/// `foxglove.FrameTransforms`: several transforms in one message.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameTransforms {
    /// The transforms.
    pub transforms: Vec<FrameTransform>,
}

/// `foxglove.SceneEntityDeletionType`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(into = "u8", try_from = "u8")]
pub enum SceneEntityDeletionType {
    /// Delete the entity on the same topic with the given `id` (0).
    MatchingId,
    /// Delete all entities on the same topic (1).
    All,
}

impl From<SceneEntityDeletionType> for u8 {
    fn from(t: SceneEntityDeletionType) -> u8 {
        match t {
            SceneEntityDeletionType::MatchingId => 0,
            SceneEntityDeletionType::All => 1,
        }
    }
}

impl TryFrom<u8> for SceneEntityDeletionType {
    type Error = String;
    fn try_from(v: u8) -> Result<Self, String> {
        match v {
            0 => Ok(Self::MatchingId),
            1 => Ok(Self::All),
            other => Err(format!("unknown SceneEntityDeletionType {other}")),
        }
    }
}

/// `foxglove.SceneEntityDeletion`: remove earlier entities.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneEntityDeletion {
    /// Only matching entities earlier than this are deleted.
    pub timestamp: Timestamp,
    /// Which entities to delete.
    #[serde(rename = "type")]
    pub kind: SceneEntityDeletionType,
    /// Entity id, used with [`SceneEntityDeletionType::MatchingId`].
    pub id: String,
}

/// `foxglove.ArrowPrimitive`: an arrow, tail at `pose.position`, pointing along the pose's +x.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ArrowPrimitive {
    /// Tail position and orientation (+x of this orientation is the arrow direction).
    pub pose: Pose,
    /// Shaft length (m).
    pub shaft_length: f64,
    /// Shaft diameter (m).
    pub shaft_diameter: f64,
    /// Head length (m).
    pub head_length: f64,
    /// Head diameter (m).
    pub head_diameter: f64,
    /// Colour.
    pub color: Color,
}

/// `foxglove.CubePrimitive`: a box centred on `pose`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CubePrimitive {
    /// Centre and orientation.
    pub pose: Pose,
    /// Edge lengths along x, y, z (m).
    pub size: Vector3,
    /// Colour.
    pub color: Color,
}

/// `foxglove.SpherePrimitive`: a sphere or ellipsoid centred on `pose`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SpherePrimitive {
    /// Centre and orientation.
    pub pose: Pose,
    /// Diameter along each axis (m).
    pub size: Vector3,
    /// Colour.
    pub color: Color,
}

/// `foxglove.CylinderPrimitive`: a cylinder (or cone) along the pose's z axis.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CylinderPrimitive {
    /// Centre and orientation; flat faces perpendicular to z.
    pub pose: Pose,
    /// Bounding box size (m).
    pub size: Vector3,
    /// Bottom face diameter relative to the box, 0-1.
    pub bottom_scale: f64,
    /// Top face diameter relative to the box, 0-1.
    pub top_scale: f64,
    /// Colour.
    pub color: Color,
}

/// `foxglove.LineType`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(into = "u8", try_from = "u8")]
pub enum LineType {
    /// Connected segments 0-1, 1-2, … (0).
    #[default]
    LineStrip,
    /// Closed polygon (1).
    LineLoop,
    /// Separate segments 0-1, 2-3, … (2).
    LineList,
}

impl From<LineType> for u8 {
    fn from(t: LineType) -> u8 {
        match t {
            LineType::LineStrip => 0,
            LineType::LineLoop => 1,
            LineType::LineList => 2,
        }
    }
}

impl TryFrom<u8> for LineType {
    type Error = String;
    fn try_from(v: u8) -> Result<Self, String> {
        match v {
            0 => Ok(Self::LineStrip),
            1 => Ok(Self::LineLoop),
            2 => Ok(Self::LineList),
            other => Err(format!("unknown LineType {other}")),
        }
    }
}

/// `foxglove.LinePrimitive`: points joined by lines.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LinePrimitive {
    /// How points are joined.
    #[serde(rename = "type")]
    pub kind: LineType,
    /// Origin of the points.
    pub pose: Pose,
    /// Line thickness (m, or pixels if `scale_invariant`).
    pub thickness: f64,
    /// Thickness in screen pixels rather than metres.
    pub scale_invariant: bool,
    /// The points.
    pub points: Vec<Point3>,
    /// Colour of the whole line (if `colors` is empty).
    pub color: Color,
    /// Per-point colours.
    pub colors: Vec<Color>,
    /// Indices into `points` (all points in order if empty).
    pub indices: Vec<u32>,
}

/// `foxglove.TriangleListPrimitive`: a triangle mesh.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TriangleListPrimitive {
    /// Origin of the points.
    pub pose: Pose,
    /// Vertices, three per triangle (or indexed).
    pub points: Vec<Point3>,
    /// Colour of the whole mesh (if `colors` is empty).
    pub color: Color,
    /// Per-vertex colours.
    pub colors: Vec<Color>,
    /// Indices into `points` (all points in order if empty).
    pub indices: Vec<u32>,
}

/// `foxglove.TextPrimitive`: a text label.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TextPrimitive {
    /// Position of the text.
    pub pose: Pose,
    /// Always face the camera.
    pub billboard: bool,
    /// Font size.
    pub font_size: f64,
    /// Font size in pixels rather than metres.
    pub scale_invariant: bool,
    /// Colour.
    pub color: Color,
    /// The text.
    pub text: String,
}

/// `foxglove.ModelPrimitive`: a 3D model from a URL or embedded data.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelPrimitive {
    /// Origin of the model.
    pub pose: Pose,
    /// Scale along each axis.
    pub scale: Vector3,
    /// Colour (used if `override_color`).
    pub color: Color,
    /// Replace the model's own colours with `color`.
    pub override_color: bool,
    /// URL of the model (empty if `data` is given).
    pub url: String,
    /// Media type of `data`, e.g. `model/gltf-binary`.
    pub media_type: String,
    /// Embedded model, base64.
    pub data: String,
}

/// `foxglove.SceneEntity`: a group of primitives sharing a frame.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneEntity {
    /// Timestamp of the entity.
    pub timestamp: Timestamp,
    /// Frame of reference of the primitives.
    pub frame_id: String,
    /// Identifier: replaces any earlier entity with the same id on the same topic.
    pub id: String,
    /// Time after which the entity disappears; zero means never.
    pub lifetime: Duration,
    /// Follow `frame_id` as it moves (true) or stay put in the fixed frame (false).
    pub frame_locked: bool,
    /// User metadata (unique keys).
    pub metadata: Vec<KeyValuePair>,
    /// Arrows.
    pub arrows: Vec<ArrowPrimitive>,
    /// Boxes.
    pub cubes: Vec<CubePrimitive>,
    /// Spheres.
    pub spheres: Vec<SpherePrimitive>,
    /// Cylinders.
    pub cylinders: Vec<CylinderPrimitive>,
    /// Lines.
    pub lines: Vec<LinePrimitive>,
    /// Triangle meshes.
    pub triangles: Vec<TriangleListPrimitive>,
    /// Text labels.
    pub texts: Vec<TextPrimitive>,
    /// Models.
    pub models: Vec<ModelPrimitive>,
}

impl SceneEntity {
    /// An empty entity with an id, in a frame, at a time; frame-locked, never expiring.
    pub fn new(timestamp: Timestamp, frame_id: impl Into<String>, id: impl Into<String>) -> Self {
        Self {
            timestamp,
            frame_id: frame_id.into(),
            id: id.into(),
            frame_locked: true,
            ..Self::default()
        }
    }
}

/// `foxglove.SceneUpdate`: deletions then entity additions/replacements.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneUpdate {
    /// Entities to delete.
    pub deletions: Vec<SceneEntityDeletion>,
    /// Entities to add or replace.
    pub entities: Vec<SceneEntity>,
}

/// `foxglove.JointState`: one joint. Optional quantities are omitted from the JSON when `None`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    /// Joint name.
    pub name: String,
    /// Position (rad for revolute, m for prismatic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<f64>,
    /// Velocity (rad/s or m/s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<f64>,
    /// Acceleration (rad/s² or m/s²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceleration: Option<f64>,
    /// Effort (N·m for revolute, N for prismatic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effort: Option<f64>,
}

/// `foxglove.JointStates`: the state of a set of joints at one time.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointStates {
    /// Time of the joint states.
    pub timestamp: Timestamp,
    /// The joints.
    pub joints: Vec<JointState>,
}

/// `foxglove.PoseInFrame`: a timestamped pose in a named frame (read from glove recordings:
/// a tracker's pose of the hand's base link). Schema name [`POSE_IN_FRAME_SCHEMA_NAME`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseInFrame {
    /// Time of the pose.
    #[serde(default)]
    pub timestamp: Timestamp,
    /// The frame the pose is expressed in.
    #[serde(default)]
    pub frame_id: String,
    /// The pose.
    pub pose: Pose,
}

/// Schema name of [`PoseInFrame`] messages.
pub const POSE_IN_FRAME_SCHEMA_NAME: &str = "foxglove.PoseInFrame";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamp_splits_nanoseconds() {
        let t = Timestamp::from_nanos(3_000_000_123);
        assert_eq!(t, Timestamp { sec: 3, nsec: 123 });
        assert_eq!(t.as_nanos(), 3_000_000_123);
    }

    #[test]
    fn enums_serialise_as_integers() {
        let d = SceneEntityDeletion {
            timestamp: Timestamp::default(),
            kind: SceneEntityDeletionType::All,
            id: String::new(),
        };
        let v = serde_json::to_value(&d).unwrap();
        assert_eq!(v["type"], serde_json::json!(1));
        let back: SceneEntityDeletion = serde_json::from_value(v).unwrap();
        assert_eq!(back, d);
    }
}
