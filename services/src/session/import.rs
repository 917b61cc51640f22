//! Importing a real glove recording: joint angles and operator torques from a CSV file or from
//! `foxglove.JointStates` messages in an MCAP file, resampled to 1 kHz and replayed through the
//! DFS against an object into a session file ([`import_glove`]).
//!
//! # CSV format
//!
//! UTF-8 text, comma-separated, one header line then one line per sample. Empty lines and lines
//! starting with `#` are ignored.
//!
//! ```text
//! time_s,wrist_roll,wrist_pitch,...,tau_wrist_roll,tau_wrist_pitch,...
//! 0.000,0.0,0.1,...,0.0,0.02,...
//! ```
//!
//! - `time_s`: sample time in seconds (any origin), strictly increasing; first column.
//! - one column per DOF of the hand named as the DOF (joint angle, rad), and one named
//!   `tau_<DOF>` (operator joint torque, N·m), in any order. Every DOF needs both; unknown or
//!   repeated column names are errors.
//! - every value a finite decimal number.
//!
//! # MCAP input
//!
//! Messages of the one topic whose schema is `foxglove.JointStates` (if several, the one named
//! `/joint_states`): every message must give `position` and `effort` for every DOF of the hand
//! and name no other joint. The message's log time is the sample time.
//!
//! # Replay
//!
//! Samples are linearly interpolated onto a 1 kHz grid starting at the first sample (session
//! time 0). The hand base stays at a fixed pose (identity unless given); the object starts at
//! rest at its `position` (default: resting on a table whose top is at z = 0, at the origin).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use dfs_core::contact::{ContactModel, Friction};
use dfs_core::dfs::{Dfs, DfsParams, GloveSample};
use dfs_core::hand::HandModel;
use dfs_core::math::{Isometry, Rotation, Vector};
use dfs_core::object::ObjectState;
use dfs_core::operator::TICK_NS;
use dfs_core::scenario::ScenarioObject;

use super::recorder::{RecordSummary, SessionInfo, SessionRecorder, TickData};
use crate::error::{RecordingError, Result};
use crate::foxglove::{JointState, JointStates, Timestamp, JOINT_STATES_SCHEMA};
use crate::mcap_io::{read_session_file, ReadLimits};

/// A glove recording: samples of joint angles and torques in the hand's DOF order.
#[derive(Debug, Clone, PartialEq)]
pub struct GloveRecording {
    /// DOF names, in the order of the values.
    pub names: Vec<String>,
    /// Sample times (ns since the first sample), strictly increasing.
    pub times_ns: Vec<u64>,
    /// Joint angles θ (rad), `times_ns.len() × names.len()`, row by row.
    pub q: Vec<f64>,
    /// Operator joint torques τ (N·m), same layout as `q`.
    pub tau: Vec<f64>,
}

impl GloveRecording {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.times_ns.len()
    }

    /// Whether there is no sample.
    pub fn is_empty(&self) -> bool {
        self.times_ns.is_empty()
    }

    /// Duration from the first to the last sample (ns).
    pub fn duration_ns(&self) -> u64 {
        self.times_ns.last().copied().unwrap_or(0)
    }

    /// θ and τ at `t_ns`, linearly interpolated (clamped to the recording), into `q`, `tau`.
    pub fn interpolate(&self, t_ns: u64, q: &mut [f64], tau: &mut [f64]) {
        let n = self.names.len();
        let i = self.times_ns.partition_point(|&t| t <= t_ns);
        let (a, b, w) = if i == 0 {
            (0, 0, 0.0)
        } else if i >= self.len() {
            (self.len() - 1, self.len() - 1, 0.0)
        } else {
            let (t0, t1) = (self.times_ns[i - 1], self.times_ns[i]);
            (i - 1, i, (t_ns - t0) as f64 / (t1 - t0) as f64)
        };
        for d in 0..n {
            let lerp = |v: &[f64]| v[a * n + d] + w * (v[b * n + d] - v[a * n + d]);
            q[d] = lerp(&self.q);
            tau[d] = lerp(&self.tau);
        }
    }
}

/// Longest glove recording imported (ns from the first to the last sample): one hour, replayed
/// at 1 kHz into 3.6 million ticks.
pub const MAX_RECORDING_NS: u64 = 3_600_000_000_000;

fn invalid(location: impl Into<String>, detail: impl Into<String>) -> RecordingError {
    RecordingError::InvalidInput {
        location: location.into(),
        detail: detail.into(),
    }
}

/// Reads a glove CSV file (format in the module docs) for `hand`.
pub fn read_glove_csv(path: &Path, hand: &HandModel) -> Result<GloveRecording> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| RecordingError::io(format!("reading {}", path.display()), e))?;
    parse_glove_csv(&text, &path.display().to_string(), hand)
}

/// Parses glove CSV text; `name` (e.g. the file name) prefixes error locations.
pub fn parse_glove_csv(text: &str, name: &str, hand: &HandModel) -> Result<GloveRecording> {
    let n = hand.dof();
    // Spreadsheets export UTF-8 with a byte order mark; it is not part of the first column.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((header_line, header)) = lines.next() else {
        return Err(invalid(name, "empty file: expected a header line"));
    };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    if columns[0] != "time_s" {
        return Err(invalid(
            format!("{name} line {header_line}, column 1"),
            format!("the first column must be time_s, found {:?}", columns[0]),
        ));
    }
    let dof_index: HashMap<&str, usize> = hand
        .dof_names
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    // Per column after time_s: (is torque, DOF index).
    let mut mapping = Vec::with_capacity(columns.len() - 1);
    let mut seen = vec![[false; 2]; n];
    for (c, col) in columns.iter().enumerate().skip(1) {
        let (torque, joint) = match col.strip_prefix("tau_") {
            Some(j) if !dof_index.contains_key(col) => (true, j),
            _ => (false, *col),
        };
        let Some(&d) = dof_index.get(joint) else {
            return Err(invalid(
                format!("{name} line {header_line}, column {}", c + 1),
                format!(
                    "unknown joint name {col:?}; expected time_s, then the DOFs of {} ({}) and tau_<DOF> for each",
                    hand.name,
                    hand.dof_names.join(", ")
                ),
            ));
        };
        if std::mem::replace(&mut seen[d][usize::from(torque)], true) {
            return Err(invalid(
                format!("{name} line {header_line}, column {}", c + 1),
                format!("column {col:?} appears twice"),
            ));
        }
        mapping.push((torque, d));
    }
    for (d, s) in seen.iter().enumerate() {
        for (k, prefix) in ["", "tau_"].iter().enumerate() {
            if !s[k] {
                return Err(invalid(
                    format!("{name} line {header_line}"),
                    format!("missing column {prefix}{}", hand.dof_names[d]),
                ));
            }
        }
    }
    let mut rec = GloveRecording {
        names: hand.dof_names.clone(),
        times_ns: Vec::new(),
        q: Vec::new(),
        tau: Vec::new(),
    };
    let mut t0: Option<f64> = None;
    let mut row_q = vec![0.0; n];
    let mut row_tau = vec![0.0; n];
    for (line_no, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != columns.len() {
            return Err(invalid(
                format!("{name} line {line_no}"),
                format!("{} columns, the header has {}", fields.len(), columns.len()),
            ));
        }
        let number = |c: usize| -> Result<f64> {
            let v: f64 = fields[c].parse().map_err(|_| {
                invalid(
                    format!("{name} line {line_no}, column {}", columns[c]),
                    format!("not a number: {:?}", fields[c]),
                )
            })?;
            if !v.is_finite() {
                return Err(invalid(
                    format!("{name} line {line_no}, column {}", columns[c]),
                    format!("{v} is not a finite number"),
                ));
            }
            Ok(v)
        };
        let t = number(0)?;
        let start = *t0.get_or_insert(t);
        let t_ns = ((t - start) * 1e9).round();
        if !(0.0..=MAX_RECORDING_NS as f64).contains(&t_ns) {
            return Err(invalid(
                format!("{name} line {line_no}, column time_s"),
                "time must not go back before the first sample, nor exceed one hour after it",
            ));
        }
        let t_ns = t_ns as u64;
        if let Some(&prev) = rec.times_ns.last() {
            if t_ns <= prev {
                return Err(invalid(
                    format!("{name} line {line_no}, column time_s"),
                    format!("time {t} s is not after the previous sample"),
                ));
            }
        }
        for (c, &(torque, d)) in mapping.iter().enumerate() {
            let v = number(c + 1)?;
            if torque {
                row_tau[d] = v;
            } else {
                row_q[d] = v;
            }
        }
        rec.times_ns.push(t_ns);
        rec.q.extend_from_slice(&row_q);
        rec.tau.extend_from_slice(&row_tau);
    }
    if rec.is_empty() {
        return Err(invalid(name, "no samples after the header"));
    }
    Ok(rec)
}

/// Reads `foxglove.JointStates` messages from an MCAP file (see the module docs) for `hand`.
pub fn read_glove_mcap(path: &Path, hand: &HandModel) -> Result<GloveRecording> {
    let name = path.display().to_string();
    let recorded = read_session_file(path, &ReadLimits::default())?;
    let candidates: Vec<&str> = recorded
        .topics
        .values()
        .filter(|t| t.schema_name() == Some(&JOINT_STATES_SCHEMA.name))
        .map(|t| t.topic.as_str())
        .collect();
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
    let t = &recorded.topics[topic];
    let messages: Vec<(u64, JointStates)> = if t.message_encoding == "protobuf" {
        // As the Foxglove SDK and session format 2 write it.
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
                // Decoding may take a hundred times a message's bytes: a joint state of a hand
                // is a few kB at most.
                if m.data.len() > super::read::MAX_RAW_MESSAGE_BYTES {
                    return Err(invalid(
                        format!(
                            "{name}: {topic} message {i} (log time {} ns)",
                            m.log_time_ns
                        ),
                        format!(
                            "the message is {} bytes; a joint state holds at most {}",
                            m.data.len(),
                            super::read::MAX_RAW_MESSAGE_BYTES
                        ),
                    ));
                }
                let pb = <foxglove::messages::JointStates as prost::Message>::decode(&m.data[..])
                    .map_err(|e| {
                    invalid(
                        format!(
                            "{name}: {topic} message {i} (log time {} ns)",
                            m.log_time_ns
                        ),
                        format!("does not decode as foxglove.JointStates: {e}"),
                    )
                })?;
                let joints = pb
                    .joints
                    .into_iter()
                    .map(|j| JointState {
                        name: j.name,
                        position: j.position,
                        velocity: j.velocity,
                        acceleration: j.acceleration,
                        effort: j.effort,
                    })
                    .collect();
                Ok((
                    m.log_time_ns,
                    JointStates {
                        timestamp: Timestamp::default(),
                        joints,
                    },
                ))
            })
            .collect::<Result<_>>()?
    } else {
        recorded.decode_topic(topic, &JOINT_STATES_SCHEMA.name)?
    };
    let n = hand.dof();
    let dof_index: HashMap<&str, usize> = hand
        .dof_names
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    let mut rec = GloveRecording {
        names: hand.dof_names.clone(),
        times_ns: Vec::with_capacity(messages.len()),
        q: Vec::with_capacity(messages.len() * n),
        tau: Vec::with_capacity(messages.len() * n),
    };
    let t0 = messages.first().map(|m| m.0).unwrap_or(0);
    for (i, (log_time, msg)) in messages.iter().enumerate() {
        let at = |field: String| {
            format!("{name}: {topic} message {i} (log time {log_time} ns), {field}")
        };
        let mut q = vec![f64::NAN; n];
        let mut tau = vec![f64::NAN; n];
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
            let (Some(p), Some(e)) = (joint.position, joint.effort) else {
                return Err(invalid(
                    at(format!("joints[{j}]")),
                    format!("joint {:?} needs both position and effort", joint.name),
                ));
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
        rec.tau.extend_from_slice(&tau);
    }
    if rec.is_empty() {
        return Err(invalid(name, format!("topic {topic} has no messages")));
    }
    Ok(rec)
}

/// Reads a glove recording: CSV if the file name ends in `.csv`, MCAP otherwise.
pub fn read_glove_file(path: &Path, hand: &HandModel) -> Result<GloveRecording> {
    let is_csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if is_csv {
        read_glove_csv(path, hand)
    } else {
        read_glove_mcap(path, hand)
    }
}

/// Replays `recording` (glove10 DOFs) through the DFS against `object` with the hand base fixed
/// at `base`, at 1 kHz, into the session file `out`. `name` goes into the `session` metadata
/// as the scenario name. A recording shorter than the shortest phase,
/// [`MIN_TASK_S`](dfs_core::scenario::MIN_TASK_S), is refused: it holds no motion to segment. A DFS error at some tick (e.g. an angle outside the joint limits)
/// finishes the file with the ticks before it and returns [`RecordingError::Simulation`] with
/// the tick's time.
pub fn replay_glove(
    recording: &GloveRecording,
    object: &ScenarioObject,
    base: Isometry,
    name: &str,
    out: &Path,
) -> Result<RecordSummary> {
    let hand = HandModel::glove10();
    if recording.names != hand.dof_names {
        return Err(invalid(
            name,
            "the recording's joints are not glove10's DOFs in order",
        ));
    }
    let shortest_ns = (dfs_core::scenario::MIN_TASK_S * 1e9) as u64;
    if recording.duration_ns() < shortest_ns {
        return Err(invalid(
            name,
            format!(
                "the recording spans {} s, shorter than the shortest session, {} s",
                recording.duration_ns() as f64 * 1e-9,
                dfs_core::scenario::MIN_TASK_S
            ),
        ));
    }
    let at_object = |source: dfs_core::DfsError| invalid("object", source.to_string());
    let rigid = object.to_simulated_object().map_err(at_object)?;
    let depth = rigid.shape.support_depth(&Rotation::identity());
    let position = object
        .position
        .map(Vector::from)
        .unwrap_or(Vector::new(0.0, 0.0, depth));
    let pose = Isometry::from_parts(
        position.into(),
        Rotation::from_euler_angles(0.0, 0.0, object.yaw),
    );
    let params = DfsParams {
        contact_model: ContactModel::PointWithFriction,
        friction: Friction {
            mu: object.mu,
            mu_torsion: object.mu_torsion,
        },
        table_height: Some(position.z - depth),
        ..DfsParams::default()
    };
    let mut dfs = Dfs::new(hand, rigid, ObjectState::at_rest(pose), params).map_err(at_object)?;
    let info = SessionInfo {
        scenario: name.to_owned(),
        seed: None,
        object_json: serde_json::to_string(object).unwrap_or_default(),
        source: "import-glove".to_owned(),
        extra: BTreeMap::from([
            (
                "base_pose".to_owned(),
                serde_json::to_string(&[
                    base.translation.x,
                    base.translation.y,
                    base.translation.z,
                    base.rotation.i,
                    base.rotation.j,
                    base.rotation.k,
                    base.rotation.w,
                ])
                .unwrap_or_default(),
            ),
            ("input_samples".to_owned(), recording.len().to_string()),
        ]),
        phases: Vec::new(),
        started_at: None,
        table_height: Some(position.z - depth),
        hand_urdf: None,
        scene: None,
    };
    let mut recorder = SessionRecorder::create(out, dfs.hand(), dfs.object(), &info)?;
    let n = recording.names.len();
    let (mut q, mut tau) = (vec![0.0; n], vec![0.0; n]);
    let ticks = recording.duration_ns() / TICK_NS + 1;
    for k in 0..ticks {
        let t = k * TICK_NS;
        recording.interpolate(t, &mut q, &mut tau);
        let sample = GloveSample {
            q: &q,
            tau: &tau,
            base,
        };
        if let Err(source) = dfs.step(&sample) {
            recorder.finish()?;
            return Err(RecordingError::Simulation { time_ns: t, source });
        }
        let tick = TickData {
            time_ns: t,
            q: &q,
            tau: &tau,
            base: &base,
            output: dfs.output(),
            kinematics: dfs.kinematics(),
        };
        if let Err(e) = recorder.record(&tick) {
            let _ = recorder.finish();
            return Err(e);
        }
    }
    recorder.finish()
}

/// [`read_glove_file`] then [`replay_glove`], named after the input file.
pub fn import_glove(
    input: &Path,
    object: &ScenarioObject,
    base: Isometry,
    out: &Path,
) -> Result<RecordSummary> {
    let hand = HandModel::glove10();
    let recording = read_glove_file(input, &hand)?;
    let name = input
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| input.display().to_string());
    replay_glove(&recording, object, base, &name, out)
}
