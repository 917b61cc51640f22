//! JSON Schemas embedded in the binary, registered with MCAP channels.
//!
//! The Foxglove schemas are the official ones (MIT, Foxglove Technologies Inc; licence in
//! `services/schemas/LICENSE`), copied unchanged from `foxglove/foxglove-sdk`.

use std::borrow::Cow;

/// A named JSON Schema for one channel's messages (MCAP schema encoding `jsonschema`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JsonSchema {
    /// Schema name as written in the MCAP schema record, e.g. `foxglove.SceneUpdate` or
    /// `icms.GloveJointStates`. Foxglove picks its panels by this name.
    pub name: Cow<'static, str>,
    /// The JSON Schema document (UTF-8 JSON text).
    pub data: Cow<'static, str>,
}

impl JsonSchema {
    /// A schema from a name and JSON text, e.g. one embedded with `include_str!`.
    pub const fn new_static(name: &'static str, data: &'static str) -> Self {
        Self {
            name: Cow::Borrowed(name),
            data: Cow::Borrowed(data),
        }
    }

    /// A schema from owned strings (e.g. generated at run time).
    pub fn new(name: impl Into<String>, data: impl Into<String>) -> Self {
        Self {
            name: Cow::Owned(name.into()),
            data: Cow::Owned(data.into()),
        }
    }
}

/// `foxglove.FrameTransforms`: an array of transforms between frames (hand links, object).
pub const FRAME_TRANSFORMS: JsonSchema = JsonSchema::new_static(
    "foxglove.FrameTransforms",
    include_str!("../../schemas/foxglove.FrameTransforms.json"),
);

/// `foxglove.SceneUpdate`: entities to show in the 3D panel (object shape, force arrows).
pub const SCENE_UPDATE: JsonSchema = JsonSchema::new_static(
    "foxglove.SceneUpdate",
    include_str!("../../schemas/foxglove.SceneUpdate.json"),
);

/// `foxglove.JointStates`: named joint positions, velocities and efforts.
pub const JOINT_STATES: JsonSchema = JsonSchema::new_static(
    "foxglove.JointStates",
    include_str!("../../schemas/foxglove.JointStates.json"),
);

/// All embedded Foxglove schemas.
pub const FOXGLOVE_SCHEMAS: [JsonSchema; 3] = [FRAME_TRANSFORMS, SCENE_UPDATE, JOINT_STATES];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_schemas_are_json_with_matching_titles() {
        for schema in FOXGLOVE_SCHEMAS {
            let v: serde_json::Value = serde_json::from_str(&schema.data).unwrap();
            assert_eq!(v["title"], serde_json::Value::from(schema.name.as_ref()));
        }
    }
}
