//! Test helpers shared by the services integration tests: JSON Schema validation (Python's
//! `jsonschema`) against the embedded Foxglove schemas, example messages, and a top-level MCAP
//! record lister.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use dfs_core::scenario::Scenario;
use serde_json::Value;
use services::foxglove::*;
use services::mcap_io::JsonSchema;
use services::session::{record_simulation, RecordSummary};

/// A `sphere-lift` session of seed `seed` (`seconds` long, or the whole script), simulated and
/// recorded to `sphere.mcap` in a temporary directory; the directory, the file and the
/// recording's summary. The tests that read one keep it in a `OnceLock`.
pub fn sphere_lift_session(
    seed: u64,
    seconds: Option<f64>,
) -> (tempfile::TempDir, PathBuf, RecordSummary) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sphere.mcap");
    let scenario = Scenario::builtin("sphere-lift", seed).unwrap();
    let summary = record_simulation(&scenario, seconds, &path, |_, _| {}).unwrap();
    (dir, path, summary)
}

/// The reference Python MCAP reader, `tests/python/read_mcap.py`.
pub fn read_mcap_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/python/read_mcap.py")
}

/// The reference Python reader's JSON report on `file`, run by an interpreter with `modules`
/// (`interpreter::python_with`); `None` (with a note) where the tests run without their Python
/// set-up. The reader must succeed.
pub fn python_mcap_report(file: &Path, modules: &[&str]) -> Option<Value> {
    let python = crate::interpreter::python_with(modules)?;
    let output = std::process::Command::new(python)
        .arg(read_mcap_script())
        .arg(file)
        .output()
        .expect("running the Python MCAP reader");
    assert!(
        output.status.success(),
        "read_mcap.py failed ({}): {}{}",
        output.status,
        String::from_utf8_lossy(&output.stderr),
        String::from_utf8_lossy(&output.stdout)
    );
    Some(serde_json::from_slice(&output.stdout).expect("read_mcap.py prints JSON"))
}

/// Deterministic pseudo-random numbers in [0, 1) (a 64-bit LCG): the noise of the
/// segmentation tests, offline and live.
pub struct Lcg(pub u64);

impl Lcg {
    /// The next number.
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Validates each of `instances` against `schema` (the embedded JSON Schema text) with Python's
/// `jsonschema` (tests/python/validate_json.py), a validator independent of our code; returns
/// each instance's errors, or `None` (with a note) where the tests run without their Python
/// set-up (see `interpreter::python_with`).
pub fn validate_each(schema: &JsonSchema, instances: &[Value]) -> Option<Vec<Vec<String>>> {
    let python = crate::interpreter::python_with(&["jsonschema"])?;
    let schema_json: Value = serde_json::from_str(&schema.data).expect("schema is JSON");
    let job = serde_json::json!({"schema": schema_json, "instances": instances});
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/python/validate_json.py");
    let mut child = std::process::Command::new(python)
        .arg(script)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("running validate_json.py");
    let mut stdin = child.stdin.take().expect("stdin");
    let writer = std::thread::spawn(move || serde_json::to_writer(&mut stdin, &job));
    let output = child.wait_with_output().expect("validate_json.py runs");
    writer.join().expect("writer").expect("job written");
    assert!(
        output.status.success(),
        "validate_json.py failed ({}): {}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    Some(serde_json::from_slice(&output.stdout).expect("validate_json.py prints JSON"))
}

/// Validates `instance` against `schema`: `Some(Err(every error))` when it breaks the schema,
/// `None` without the Python set-up (see [`validate_each`]).
pub fn validate_against(schema: &JsonSchema, instance: &Value) -> Option<Result<(), Vec<String>>> {
    let mut errors = validate_each(schema, std::slice::from_ref(instance))?;
    let errors = errors.pop().expect("one list per instance");
    Some(if errors.is_empty() {
        Ok(())
    } else {
        Err(errors)
    })
}

/// Serialises `msg` and validates it against `schema`, panicking with the errors.
pub fn assert_valid<T: serde::Serialize>(schema: &JsonSchema, msg: &T) {
    let value = serde_json::to_value(msg).expect("serialises");
    if let Some(Err(errors)) = validate_against(schema, &value) {
        panic!(
            "{} does not validate against {}:\n{}\n{}",
            std::any::type_name::<T>(),
            schema.name,
            errors.join("\n"),
            serde_json::to_string_pretty(&value).unwrap()
        );
    }
}

/// Whether `instance` breaks `schema`; `true` without the Python set-up, where nothing is
/// checked (see [`validate_each`]).
pub fn rejects(schema: &JsonSchema, instance: &Value) -> bool {
    validate_against(schema, instance).is_none_or(|r| r.is_err())
}

fn pose(x: f64, y: f64, z: f64) -> Pose {
    Pose {
        position: Vector3::new(x, y, z),
        orientation: Quaternion::IDENTITY,
    }
}

/// Two transforms: world → object, object → a fingertip.
pub fn example_frame_transforms(t_ns: u64) -> FrameTransforms {
    let timestamp = Timestamp::from_nanos(t_ns);
    FrameTransforms {
        transforms: vec![
            FrameTransform {
                timestamp,
                parent_frame_id: "world".into(),
                child_frame_id: "object".into(),
                translation: Vector3::new(0.0, 0.0, 0.1 + t_ns as f64 * 1e-12),
                rotation: Quaternion::IDENTITY,
            },
            FrameTransform {
                timestamp,
                parent_frame_id: "object".into(),
                child_frame_id: "thumb_tip".into(),
                translation: Vector3::new(0.054, 0.054, -0.059),
                rotation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: std::f64::consts::FRAC_1_SQRT_2,
                    w: std::f64::consts::FRAC_1_SQRT_2,
                },
            },
        ],
    }
}

/// A scene with the object sphere, a table cube, a cylinder, a contact force arrow, and a
/// deletion of all earlier entities.
pub fn example_scene_update(t_ns: u64) -> SceneUpdate {
    let timestamp = Timestamp::from_nanos(t_ns);
    let mut object = SceneEntity::new(timestamp, "object", "object");
    object.spheres.push(SpherePrimitive {
        pose: pose(0.0, 0.0, 0.0),
        size: Vector3::new(0.2, 0.2, 0.2),
        color: Color::rgba(0.2, 0.4, 0.8, 0.8),
    });
    object.cylinders.push(CylinderPrimitive {
        pose: pose(0.3, 0.0, 0.0),
        size: Vector3::new(0.05, 0.05, 0.1),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color: Color::rgba(0.5, 0.5, 0.5, 1.0),
    });
    object.metadata.push(KeyValuePair {
        key: "shape".into(),
        value: "sphere".into(),
    });
    let mut table = SceneEntity::new(timestamp, "world", "table");
    table.cubes.push(CubePrimitive {
        pose: pose(0.0, 0.0, -0.15),
        size: Vector3::new(1.0, 1.0, 0.1),
        color: Color::rgba(0.6, 0.5, 0.4, 1.0),
    });
    let mut forces = SceneEntity::new(timestamp, "object", "contact_forces");
    forces.lifetime = Duration {
        sec: 0,
        nsec: 20_000_000,
    };
    forces.arrows.push(ArrowPrimitive {
        pose: pose(0.054, 0.054, -0.059),
        shaft_length: 0.05,
        shaft_diameter: 0.004,
        head_length: 0.01,
        head_diameter: 0.008,
        color: Color::rgba(1.0, 0.1, 0.1, 1.0),
    });
    forces.lines.push(LinePrimitive {
        kind: LineType::LineList,
        pose: pose(0.0, 0.0, 0.0),
        thickness: 0.002,
        scale_invariant: false,
        points: vec![
            Point3 {
                x: 0.0,
                y: 0.0,
                z: 0.0,
            },
            Point3 {
                x: 0.0,
                y: 0.0,
                z: 0.1,
            },
        ],
        color: Color::rgba(0.0, 1.0, 0.0, 1.0),
        colors: vec![],
        indices: vec![],
    });
    forces.texts.push(TextPrimitive {
        pose: pose(0.0, 0.0, 0.15),
        billboard: true,
        font_size: 12.0,
        scale_invariant: true,
        color: Color::rgba(1.0, 1.0, 1.0, 1.0),
        text: "4 contacts".into(),
    });
    SceneUpdate {
        deletions: vec![SceneEntityDeletion {
            timestamp,
            kind: SceneEntityDeletionType::All,
            id: String::new(),
        }],
        entities: vec![object, table, forces],
    }
}

/// Ten glove joints; one with only a position, the others with position, velocity and effort.
pub fn example_joint_states(t_ns: u64) -> JointStates {
    let mut joints: Vec<JointState> = (0..9)
        .map(|i| JointState {
            name: format!("j{i}"),
            position: Some(0.1 * i as f64),
            velocity: Some(0.0),
            acceleration: None,
            effort: Some(-0.05 * i as f64),
        })
        .collect();
    joints.push(JointState {
        name: "thumb_rot".into(),
        position: Some(0.3),
        ..JointState::default()
    });
    JointStates {
        timestamp: Timestamp::from_nanos(t_ns),
        joints,
    }
}

/// A top-level MCAP record: opcode, byte offset of the opcode, body length.
#[derive(Debug, Clone, Copy)]
pub struct TopRecord {
    pub opcode: u8,
    pub offset: usize,
    pub len: usize,
}

impl TopRecord {
    /// Offset of the first body byte.
    pub fn body(&self) -> usize {
        self.offset + 9
    }
}

/// Lists the top-level records of a well-formed MCAP file (stops at the footer).
pub fn top_level_records(bytes: &[u8]) -> Vec<TopRecord> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let opcode = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        out.push(TopRecord {
            opcode,
            offset: at,
            len,
        });
        if opcode == 0x02 {
            break;
        }
        at += 9 + len;
    }
    out
}

/// MCAP opcode of a chunk record.
pub const OP_CHUNK: u8 = 0x06;
