//! The assistant in a live session's recording: its events on
//! [`crate::session::TOPIC_ASSIST_EVENTS`] (`foxglove.Log`), the robot on
//! [`crate::session::TOPIC_ASSIST_ROBOT`] (`foxglove.SceneUpdate`), its summary in the `live`
//! metadata record.

use std::collections::BTreeMap;

use foxglove::messages as fg;

use crate::live::AssistMode;
use crate::session::{AssistTopic, SessionRecorder, WORLD_FRAME};

use super::assistant::{AssistEvent, AssistSummary, Notice, RobotState, ROBOT_SCENE_OFFSET_X};

fn timestamp(ns: u64) -> Option<fg::Timestamp> {
    Some(fg::Timestamp::new(
        (ns / 1_000_000_000) as u32,
        (ns % 1_000_000_000) as u32,
    ))
}

/// Records one event: the robot's state as a scene, anything else as a log line.
pub fn log_event(recorder: &mut SessionRecorder, e: &AssistEvent) {
    let t = e.session_ns();
    match e {
        AssistEvent::Notice(Notice::Robot(r)) => {
            recorder.log_assist(AssistTopic::Robot, t, &robot_scene(r));
        }
        _ => {
            let level = match e {
                AssistEvent::Notice(Notice::AssistError { .. } | Notice::Behind { .. }) => {
                    fg::log::Level::Warning
                }
                _ => fg::log::Level::Info,
            };
            let log = fg::Log {
                timestamp: timestamp(t),
                level: level as i32,
                message: serde_json::to_string(e).unwrap_or_default(),
                name: "icms.assist".to_owned(),
                file: String::new(),
                line: 0,
            };
            recorder.log_assist(AssistTopic::Events, t, &log);
        }
    }
}

/// The robot as Foxglove draws it: a sphere per fingertip (red when it pushes) and the object,
/// [`ROBOT_SCENE_OFFSET_X`] beside the operator's scene.
fn robot_scene(r: &RobotState) -> fg::SceneUpdate {
    let shifted = |p: [f64; 3]| fg::Vector3 {
        x: p[0] + ROBOT_SCENE_OFFSET_X,
        y: p[1],
        z: p[2],
    };
    let sphere = |p: [f64; 3], d: f64, c: fg::Color| fg::SpherePrimitive {
        pose: Some(fg::Pose {
            position: Some(shifted(p)),
            orientation: Some(fg::Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }),
        }),
        size: Some(fg::Vector3 { x: d, y: d, z: d }),
        color: Some(c),
    };
    let mut spheres: Vec<fg::SpherePrimitive> = r
        .tips
        .iter()
        .zip(&r.tip_normal_forces)
        .map(|(p, f)| {
            let c = if *f > 0.05 {
                fg::Color {
                    r: 0.9,
                    g: 0.2,
                    b: 0.2,
                    a: 1.0,
                }
            } else {
                fg::Color {
                    r: 0.3,
                    g: 0.8,
                    b: 0.3,
                    a: 1.0,
                }
            };
            sphere(*p, 0.016, c)
        })
        .collect();
    let o = r.object;
    spheres.push(sphere(
        [o[0], o[1], o[2]],
        2.0 * r.object_radius_m,
        fg::Color {
            r: 0.85,
            g: 0.6,
            b: 0.2,
            a: 0.6,
        },
    ));
    fg::SceneUpdate {
        deletions: Vec::new(),
        entities: vec![fg::SceneEntity {
            timestamp: timestamp(r.session_ns),
            frame_id: WORLD_FRAME.to_owned(),
            id: "assist_robot".to_owned(),
            frame_locked: false,
            spheres,
            ..fg::SceneEntity::default()
        }],
    }
}

/// The assistant's part of the `live` metadata record: mode, verdicts, drops, the robot's
/// report.
pub fn summary_metadata(mode: AssistMode, s: &AssistSummary) -> BTreeMap<String, String> {
    let mut m = BTreeMap::from([
        (
            "assist_mode".to_owned(),
            serde_json::to_value(mode)
                .ok()
                .and_then(|v| v.as_str().map(str::to_owned))
                .unwrap_or_default(),
        ),
        (
            "assist_verdicts".to_owned(),
            serde_json::to_string(&s.verdicts).unwrap_or_default(),
        ),
        ("assist_dropped".to_owned(), s.dropped.to_string()),
        ("assist_decisions".to_owned(), s.decisions.to_string()),
    ]);
    if let Some(r) = &s.robot_report {
        m.insert("robot_report".to_owned(), r.to_string());
    }
    m
}
