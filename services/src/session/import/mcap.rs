//! Glove recordings in MCAP files: joints from `foxglove.JointStates`, the wrist from
//! `foxglove.PoseInFrame` or `foxglove.FrameTransforms` (see the parent module's docs), in
//! protobuf (as the Foxglove SDK writes them) or JSON.

use std::path::Path;

use dfs_core::hand::HandModel;
use dfs_core::math::{Isometry, Vector};
use serde::de::DeserializeOwned;

use super::csv::{dof_index, unit_quaternion};
use super::{invalid, GloveRecording, WristInput, WristTrack, MAX_RECORDING_NS};
use crate::error::Result;
use crate::foxglove::{
    FrameTransforms, JointState, JointStates, PoseInFrame, Timestamp, FRAME_TRANSFORMS_SCHEMA,
    JOINT_STATES_SCHEMA, POSE_IN_FRAME_SCHEMA_NAME,
};
use crate::mcap_io::{read_session_file, ReadLimits, RecordedSession};
use crate::session::MAX_RAW_MESSAGE_BYTES;

/// Reads a glove recording from an MCAP file (see the module docs) for `hand`, the wrist input
/// found automatically ([`WristInput::Auto`]).
pub fn read_glove_mcap(path: &Path, hand: &HandModel) -> Result<GloveRecording> {
    read_glove_mcap_with(path, hand, &WristInput::Auto)
}

/// [`read_glove_mcap`] with the wrist input chosen.
pub fn read_glove_mcap_with(
    path: &Path,
    hand: &HandModel,
    wrist: &WristInput,
) -> Result<GloveRecording> {
    let name = path.display().to_string();
    let recorded = read_session_file(path, &ReadLimits::default())?;
    let candidates = topics_of(&recorded, &JOINT_STATES_SCHEMA.name);
    let topic = match candidates.as_slice() {
        [] => {
            return Err(invalid(
                name,
                "no topic with schema foxglove.JointStates in the file",
            ))
        }
        [one] => *one,
        many if many.contains(&"/joint_states") => "/joint_states",
        many => {
            return Err(invalid(
                name,
                format!(
                    "several topics with schema foxglove.JointStates ({}); expected one, or one named /joint_states",
                    many.join(", ")
                ),
            ))
        }
    };
    let messages: Vec<(u64, JointStates)> = decode_messages(
        &recorded,
        &name,
        topic,
        &JOINT_STATES_SCHEMA.name,
        |pb: foxglove::messages::JointStates| {
            Ok(JointStates {
                timestamp: Timestamp::default(),
                joints: pb
                    .joints
                    .into_iter()
                    .map(|j| JointState {
                        name: j.name,
                        position: j.position,
                        velocity: j.velocity,
                        acceleration: j.acceleration,
                        effort: j.effort,
                    })
                    .collect(),
            })
        },
        |json: JointStates| Ok(json),
    )?;
    let mut rec = joints_recording(&messages, &name, topic, hand)?;
    let t0 = messages.first().map_or(0, |m| m.0);
    let root = hand.links[hand.root].name.as_str();
    rec.wrist = match wrist {
        WristInput::Ignore => None,
        WristInput::Topic(t) => {
            let Some(found) = recorded.topics.get(t.as_str()) else {
                return Err(invalid(
                    name,
                    format!("no topic {t:?} for the wrist pose in the file"),
                ));
            };
            let schema = found.schema_name().unwrap_or("");
            if schema != POSE_IN_FRAME_SCHEMA_NAME && schema != FRAME_TRANSFORMS_SCHEMA.name {
                return Err(invalid(
                    format!("{name}: {t}"),
                    format!(
                        "the wrist pose comes from a foxglove.PoseInFrame or \
                         foxglove.FrameTransforms topic, not {schema:?}"
                    ),
                ));
            }
            let track = wrist_track(&recorded, &name, t, root, t0)?;
            if track.poses.is_empty() {
                return Err(invalid(
                    format!("{name}: {t}"),
                    format!("no pose of the hand's base link {root:?}"),
                ));
            }
            Some(track)
        }
        WristInput::Auto => auto_wrist(&recorded, &name, root, t0)?,
    };
    Ok(rec)
}

/// The topics whose schema is named `schema`.
fn topics_of<'a>(recorded: &'a RecordedSession, schema: &str) -> Vec<&'a str> {
    recorded
        .topics
        .values()
        .filter(|t| t.schema_name() == Some(schema))
        .map(|t| t.topic.as_str())
        .collect()
}

/// The messages of `topic`, each as `T`: protobuf (as the Foxglove SDK writes them; decoded as
/// `P`, then `from_pb`) or JSON (decoded as `J` against the schema named `schema`, then
/// `from_json`). A conversion's error names the message.
fn decode_messages<T, P, J>(
    recorded: &RecordedSession,
    name: &str,
    topic: &str,
    schema: &str,
    from_pb: impl Fn(P) -> std::result::Result<T, String>,
    from_json: impl Fn(J) -> std::result::Result<T, String>,
) -> Result<Vec<(u64, T)>>
where
    P: prost::Message + Default,
    J: DeserializeOwned,
{
    let Some(t) = recorded.topics.get(topic) else {
        return Err(invalid(name, format!("no topic {topic:?}")));
    };
    let at = |i: usize, log_time_ns: u64| {
        format!("{name}: {topic} message {i} (log time {log_time_ns} ns)")
    };
    if t.message_encoding != "protobuf" {
        let decoded: Vec<(u64, J)> = recorded.decode_topic(topic, schema)?;
        return decoded
            .into_iter()
            .enumerate()
            .map(|(i, (log_time, m))| {
                Ok((
                    log_time,
                    from_json(m).map_err(|e| invalid(at(i, log_time), e))?,
                ))
            })
            .collect();
    }
    let encoding = t.schema.as_ref().map_or("", |s| s.encoding.as_str());
    if encoding != "protobuf" {
        return Err(invalid(
            format!("{name}: {topic}"),
            format!("protobuf messages need a protobuf schema, not {encoding:?}"),
        ));
    }
    t.messages
        .iter()
        .enumerate()
        .map(|(i, m)| {
            // Decoding may take a hundred times a message's bytes: a glove's joint state or a
            // tracker's pose is a few kB at most.
            if m.data.len() > MAX_RAW_MESSAGE_BYTES {
                return Err(invalid(
                    at(i, m.log_time_ns),
                    format!(
                        "the message is {} bytes; a glove sample holds at most {}",
                        m.data.len(),
                        MAX_RAW_MESSAGE_BYTES
                    ),
                ));
            }
            let pb = P::decode(&m.data[..]).map_err(|e| {
                invalid(
                    at(i, m.log_time_ns),
                    format!("does not decode as {schema}: {e}"),
                )
            })?;
            let value = from_pb(pb).map_err(|e| invalid(at(i, m.log_time_ns), e))?;
            Ok((m.log_time_ns, value))
        })
        .collect()
}

/// The joint angles (and torques) of `messages` for `hand`.
fn joints_recording(
    messages: &[(u64, JointStates)],
    name: &str,
    topic: &str,
    hand: &HandModel,
) -> Result<GloveRecording> {
    let n = hand.dof();
    let dof_index = dof_index(hand);
    // Torques if the first message gives an effort for every joint.
    let torques = messages
        .first()
        .is_some_and(|(_, m)| m.joints.iter().all(|j| j.effort.is_some()));
    let mut rec = GloveRecording {
        names: hand.dof_names.clone(),
        times_ns: Vec::with_capacity(messages.len()),
        q: Vec::with_capacity(messages.len() * n),
        tau: torques.then(|| Vec::with_capacity(messages.len() * n)),
        wrist: None,
    };
    let t0 = messages.first().map(|m| m.0).unwrap_or(0);
    let mut q = vec![f64::NAN; n];
    let mut tau = vec![0.0; n];
    for (i, (log_time, msg)) in messages.iter().enumerate() {
        let at = |field: String| {
            format!("{name}: {topic} message {i} (log time {log_time} ns), {field}")
        };
        q.fill(f64::NAN);
        for (j, joint) in msg.joints.iter().enumerate() {
            let Some(&d) = dof_index.get(joint.name.as_str()) else {
                return Err(invalid(
                    at(format!("joints[{j}].name")),
                    format!(
                        "unknown joint {:?}; {} has {}",
                        joint.name,
                        hand.name,
                        hand.dof_names.join(", ")
                    ),
                ));
            };
            let Some(p) = joint.position else {
                return Err(invalid(
                    at(format!("joints[{j}]")),
                    format!("joint {:?} has no position", joint.name),
                ));
            };
            let e = match (torques, joint.effort) {
                (true, Some(e)) => e,
                (false, None) => 0.0,
                (true, None) => {
                    return Err(invalid(
                        at(format!("joints[{j}]")),
                        format!(
                            "joint {:?} has no effort, but message 0 gives every joint's \
                             (efforts for every joint of every message, or for none)",
                            joint.name
                        ),
                    ))
                }
                (false, Some(_)) => {
                    return Err(invalid(
                        at(format!("joints[{j}]")),
                        format!(
                            "joint {:?} has an effort, but message 0 does not give every \
                             joint's (efforts for every joint of every message, or for none)",
                            joint.name
                        ),
                    ))
                }
            };
            if !(p.is_finite() && e.is_finite()) {
                return Err(invalid(
                    at(format!("joints[{j}]")),
                    format!(
                        "joint {:?}: position and effort must be finite numbers",
                        joint.name
                    ),
                ));
            }
            q[d] = p;
            tau[d] = e;
        }
        if let Some(d) = q.iter().position(|v| v.is_nan()) {
            return Err(invalid(
                at("joints".into()),
                format!("joint {:?} is missing", hand.dof_names[d]),
            ));
        }
        let t = log_time
            .checked_sub(t0)
            .ok_or_else(|| invalid(at("log time".into()), "before the first message"))?;
        if rec.times_ns.last().is_some_and(|&prev| t <= prev) {
            return Err(invalid(
                at("log time".into()),
                "not after the previous message",
            ));
        }
        if t > MAX_RECORDING_NS {
            return Err(invalid(
                at("log time".into()),
                "more than one hour after the first message",
            ));
        }
        rec.times_ns.push(t);
        rec.q.extend_from_slice(&q);
        if let Some(all) = &mut rec.tau {
            all.extend_from_slice(&tau);
        }
    }
    if rec.is_empty() {
        return Err(invalid(name, format!("topic {topic} has no messages")));
    }
    Ok(rec)
}

/// A pose as `[x, y, z, qx, qy, qz, qw]`, unchecked.
type RawPose = [f64; 7];

/// The wrist input found without being named: the one `foxglove.PoseInFrame` topic, else the
/// `foxglove.FrameTransforms` topic holding the base link (`/tf` if several do); `None` if no
/// topic gives a pose of it.
fn auto_wrist(
    recorded: &RecordedSession,
    name: &str,
    root: &str,
    t0: u64,
) -> Result<Option<WristTrack>> {
    let poses = topics_of(recorded, POSE_IN_FRAME_SCHEMA_NAME);
    match poses.as_slice() {
        [] => {}
        [one] => {
            let track = wrist_track(recorded, name, one, root, t0)?;
            return Ok((!track.poses.is_empty()).then_some(track));
        }
        many => {
            return Err(invalid(
                name,
                format!(
                    "several topics with schema foxglove.PoseInFrame ({}); name the wrist's \
                     (--wrist-topic)",
                    many.join(", ")
                ),
            ))
        }
    }
    let mut found = Vec::new();
    for topic in topics_of(recorded, &FRAME_TRANSFORMS_SCHEMA.name) {
        let track = wrist_track(recorded, name, topic, root, t0)?;
        if !track.poses.is_empty() {
            found.push(track);
        }
    }
    if found.len() > 1 {
        return match found.iter().position(|t| t.source == "/tf") {
            Some(i) => Ok(Some(found.swap_remove(i))),
            None => Err(invalid(
                name,
                format!(
                    "several foxglove.FrameTransforms topics give the pose of {root:?} ({}); \
                     name the wrist's (--wrist-topic)",
                    found
                        .iter()
                        .map(|t| t.source.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
        };
    }
    Ok(found.pop())
}

/// The poses of the base link `root` on `topic` (`foxglove.PoseInFrame`: every message;
/// `foxglove.FrameTransforms`: the transforms whose child frame is `root`, messages without one
/// skipped), timed by log time relative to `t0`. Errors name the message.
fn wrist_track(
    recorded: &RecordedSession,
    name: &str,
    topic: &str,
    root: &str,
    t0: u64,
) -> Result<WristTrack> {
    let schema = recorded
        .topics
        .get(topic)
        .and_then(|t| t.schema_name())
        .unwrap_or("");
    let vector = |v: Option<foxglove::messages::Vector3>| v.map_or([0.0; 3], |v| [v.x, v.y, v.z]);
    let quaternion = |q: Option<foxglove::messages::Quaternion>| {
        q.map(|q| [q.x, q.y, q.z, q.w])
            .ok_or_else(|| "the pose has no orientation".to_owned())
    };
    let raw = |p: [f64; 3], q: [f64; 4]| Some([p[0], p[1], p[2], q[0], q[1], q[2], q[3]]);
    let two = || format!("two transforms to {root:?} in one message");
    let samples: Vec<(u64, Option<RawPose>)> = if schema == POSE_IN_FRAME_SCHEMA_NAME {
        decode_messages(
            recorded,
            name,
            topic,
            POSE_IN_FRAME_SCHEMA_NAME,
            |pb: foxglove::messages::PoseInFrame| {
                let pose = pb
                    .pose
                    .ok_or_else(|| "the message has no pose".to_owned())?;
                Ok(raw(vector(pose.position), quaternion(pose.orientation)?))
            },
            |json: PoseInFrame| {
                let (p, q) = (json.pose.position, json.pose.orientation);
                Ok(raw([p.x, p.y, p.z], [q.x, q.y, q.z, q.w]))
            },
        )?
    } else {
        decode_messages(
            recorded,
            name,
            topic,
            &FRAME_TRANSFORMS_SCHEMA.name,
            |pb: foxglove::messages::FrameTransforms| {
                let mut found = pb
                    .transforms
                    .into_iter()
                    .filter(|t| t.child_frame_id == root);
                let Some(first) = found.next() else {
                    return Ok(None);
                };
                if found.next().is_some() {
                    return Err(two());
                }
                Ok(raw(vector(first.translation), quaternion(first.rotation)?))
            },
            |json: FrameTransforms| {
                let mut found = json.transforms.iter().filter(|t| t.child_frame_id == root);
                let Some(first) = found.next() else {
                    return Ok(None);
                };
                if found.next().is_some() {
                    return Err(two());
                }
                let (p, q) = (first.translation, first.rotation);
                Ok(raw([p.x, p.y, p.z], [q.x, q.y, q.z, q.w]))
            },
        )?
    };
    let mut track = WristTrack {
        source: topic.to_owned(),
        times_ns: Vec::new(),
        poses: Vec::new(),
    };
    for (i, (log_time, pose)) in samples.into_iter().enumerate() {
        let Some([x, y, z, qx, qy, qz, qw]) = pose else {
            continue;
        };
        let at = || format!("{name}: {topic} message {i} (log time {log_time} ns)");
        let rel = i64::try_from(i128::from(log_time) - i128::from(t0))
            .map_err(|_| invalid(at(), "log time too far from the glove's"))?;
        if track.times_ns.last().is_some_and(|&prev| rel <= prev) {
            return Err(invalid(at(), "not after the previous pose"));
        }
        if ![x, y, z].iter().all(|v| v.is_finite()) {
            return Err(invalid(
                at(),
                format!("the position ({x}, {y}, {z}) is not finite"),
            ));
        }
        let rotation = unit_quaternion(qx, qy, qz, qw).ok_or_else(|| {
            invalid(
                at(),
                format!("the quaternion ({qx}, {qy}, {qz}, {qw}) has no direction: not a rotation"),
            )
        })?;
        track.times_ns.push(rel);
        track
            .poses
            .push(Isometry::from_parts(Vector::new(x, y, z).into(), rotation));
    }
    Ok(track)
}
