//! The `services::foxglove` serde types produce JSON that the official Foxglove JSON schemas
//! accept, and the validator used here does reject broken messages.

use crate::common;

use common::*;
use serde_json::json;
use services::foxglove::*;
use services::mcap_io::schemas;

#[test]
fn frame_transforms_example_validates_against_the_official_schema() {
    assert_valid(
        &FRAME_TRANSFORMS_SCHEMA,
        &example_frame_transforms(1_500_000_000),
    );
}

#[test]
fn scene_update_example_with_every_primitive_kind_validates() {
    let mut update = example_scene_update(2_000_000_001);
    let mut extra = SceneEntity::new(Timestamp::default(), "world", "extras");
    extra.triangles.push(TriangleListPrimitive::default());
    extra.models.push(ModelPrimitive {
        url: "package://hand/mesh.glb".into(),
        media_type: "model/gltf-binary".into(),
        scale: Vector3::new(1.0, 1.0, 1.0),
        ..ModelPrimitive::default()
    });
    update.entities.push(extra);
    assert_valid(&SCENE_UPDATE_SCHEMA, &update);
}

#[test]
fn joint_states_example_with_optional_fields_omitted_validates() {
    let states = example_joint_states(999_999_999);
    let v = serde_json::to_value(&states).unwrap();
    assert!(
        v["joints"][9].get("velocity").is_none(),
        "None fields are omitted"
    );
    assert_valid(&JOINT_STATES_SCHEMA, &states);
}

#[test]
fn empty_messages_validate() {
    assert_valid(&schemas::FRAME_TRANSFORMS, &FrameTransforms::default());
    assert_valid(&schemas::SCENE_UPDATE, &SceneUpdate::default());
    assert_valid(&schemas::JOINT_STATES, &JointStates::default());
}

#[test]
fn validator_rejects_messages_that_break_the_schema() {
    // Missing the required rotation.
    let bad = json!({"transforms": [{
        "timestamp": {"sec": 0, "nsec": 0},
        "parent_frame_id": "world", "child_frame_id": "object",
        "translation": {"x": 0, "y": 0, "z": 0}
    }]});
    assert!(rejects(&FRAME_TRANSFORMS_SCHEMA, &bad));
    // nsec out of range, and null where a number is required (what serde_json makes of NaN).
    let bad = json!({"timestamp": {"sec": 0, "nsec": 1_000_000_000}, "joints": [
        {"name": "j0", "position": null}
    ]});
    if let Some(result) = validate_against(&JOINT_STATES_SCHEMA, &bad) {
        let errors = result.unwrap_err();
        assert_eq!(errors.len(), 2, "{errors:?}");
    }
    // A scene entity without its primitive arrays.
    let bad = json!({"deletions": [], "entities": [{
        "timestamp": {"sec": 0, "nsec": 0}, "frame_id": "world", "id": "x"
    }]});
    assert!(rejects(&SCENE_UPDATE_SCHEMA, &bad));
}

#[test]
fn foxglove_types_round_trip_through_json() {
    let update = example_scene_update(7);
    let text = serde_json::to_string(&update).unwrap();
    let back: SceneUpdate = serde_json::from_str(&text).unwrap();
    assert_eq!(back, update);
    let states = example_joint_states(7);
    let back: JointStates = serde_json::from_str(&serde_json::to_string(&states).unwrap()).unwrap();
    assert_eq!(back, states);
}
