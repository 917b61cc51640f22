//! Importing a real glove recording: joint angles (and operator torques, when the glove
//! measures them) with the wrist pose from a tracker, from a CSV file or from Foxglove messages
//! in an MCAP file, resampled to 1 kHz and replayed through the DFS against an object into a
//! session file ([`import_glove`]). Any hand model is the glove's ([`ImportOptions::hand`]):
//! the recording's joints are its DOFs, by name. `icms export-glove` writes a session's glove
//! samples back in the CSV format ([`super::export`]).
//!
//! # CSV format
//!
//! UTF-8 text, comma-separated, one header line then one line per sample. Empty lines and lines
//! starting with `#` are ignored.
//!
//! ```text
//! time_s,wrist_roll,...,tau_wrist_roll,...,wrist_x,wrist_y,wrist_z,wrist_qx,wrist_qy,wrist_qz,wrist_qw
//! 0.000,0.0,...,0.0,...,0.1,0.0,0.25,0.0,0.0,0.0,1.0
//! ```
//!
//! - `time_s`: sample time in seconds (any origin), strictly increasing; first column.
//! - one column per DOF of the hand, named as the DOF (joint angle, rad; m for a prismatic
//!   DOF), every DOF.
//! - `tau_<DOF>` (operator joint torque, N·m; N for a prismatic DOF) for every DOF, or for
//!   none: a glove that measures positions only drives the DFS through a virtual coupling
//!   (below).
//! - the wrist pose, all seven columns or none: `wrist_x`, `wrist_y`, `wrist_z`, the position
//!   of the hand's base link in the world (m), and `wrist_qx`, `wrist_qy`, `wrist_qz`,
//!   `wrist_qw`, its orientation as a quaternion (normalised on reading; a zero one is
//!   refused). Without them the base stays at a fixed pose ([`ImportOptions::base`]).
//! - columns in any order; unknown or repeated column names are errors; every value a finite
//!   decimal number. Errors name the line and the column.
//!
//! # MCAP input
//!
//! - **Joints**: the messages of the one topic whose schema is `foxglove.JointStates` (if
//!   several, the one named `/joint_states`): every message gives `position` for every DOF of
//!   the hand and names no other joint; `effort` for every joint of every message, or for none
//!   (positions only). The message's log time is the sample time.
//! - **Wrist** ([`WristInput`]): by default the one topic of schema `foxglove.PoseInFrame`
//!   (the tracker's pose of the hand's base link; its `frame_id` is taken as the world), else
//!   the `foxglove.FrameTransforms` topic (`/tf` if several) with transforms whose
//!   `child_frame_id` is the hand's base (root) link, such as a session's own `/tf`; the parent
//!   frame is taken as the world, and messages without that transform are skipped. A topic can
//!   also be named, or wrist input ignored. Log times on the glove's clock; the tracker may run
//!   at its own rate.
//!
//! # Replay
//!
//! Samples are linearly interpolated onto a 1 kHz grid starting at the first glove sample
//! (session time 0); wrist poses likewise (position linearly, orientation by slerp along the
//! shorter arc), held at their first and last pose outside the tracker's span. A
//! [`Calibration`] maps the angles (`q = scale · q_raw + offset` per DOF) before anything else.
//! The object starts at rest at its `position` (default: resting on a table whose top is at
//! z = 0, at the origin). Contacts are soft fingertip pads, as in simulated sessions
//! ([`ImportOptions::contact_model`]).
//!
//! The DFS steps on its own finger posture, as in the paper's loop, where the glove's motors
//! put the operator's fingers where the DFS commands them (`θ_motor`, its finger dynamics
//! integrated, [`dfs_core::dfs::TickOutput::motor_q`]): the fingertips rest on the object where
//! the DFS's contacts hold them. A virtual coupling ([`dfs_core::coupling`]) ties that posture to
//! the recording's, `τ_c = clamp(k (θ_measured − θ_motor) − c θ̇_motor, ±τ_max)`, computed
//! each tick from the DFS's last motor state:
//!
//! - **A recording with torques** drives the fingers with the measured torques `τ`, plus a
//!   weak coupling against drift ([`ImportOptions::torque_coupling`]: a tenth of the default's
//!   stiffness, full torque only at a whole range's error). Stepping the recorded angles as
//!   the kinematics instead would put the fingertips where the *recording's* object was; the
//!   replayed object never sits exactly there, and the DFS's normal forces come from the
//!   operator's torques, not from how deep a fingertip presses, so nothing along the contact
//!   normals would keep it between the fingertips: exported and imported again, 3 of 8
//!   `sphere-lift` sessions (seeds 0-7) lost the sphere during the hold, rocked out of the
//!   pinch by the session's rounding (1e-5 rad, 1e-5 N·m, 1 µm). With the loop closed all 8
//!   give their skills again. `τ + τ_c` is kept within the DFS's torque range
//!   ([`DfsParams::torque_range`]); a measured torque beyond it is refused as before.
//! - **A recording of positions only** (most data gloves) is driven by the coupling alone
//!   ([`ImportOptions::coupling`], the hand's default): the simulated fingers stop on the
//!   object while the operator's close further, and the squeeze is the spring's stretch.
//!
//! The first tick starts the simulated hand at the first measured posture, at rest. Every
//! measured posture must lie within the hand's joint limits (with the DFS's slack), else the
//! import stops there as before. The session's `/glove/joint_states` holds, per tick, the
//! recording's (calibrated, interpolated) angles and torques for a recording with torques; for
//! one of positions only, what the DFS stepped (its posture and the coupling torque), so that
//! exporting either and importing it again reproduces the session.
//!
//! The `session` metadata record of an import holds, besides the usual keys, `glove_input`
//! (`torques` or `positions`), `wrist` (`fixed`, `csv` or the MCAP topic), `base_pose` for a
//! fixed base, `contact_model`, `contacts` (`fingertips`, or `whole_hand` for an import with
//! [`ImportOptions::whole_hand`]), `calibration` (JSON) when one was given, and
//! `coupling_stiffness` / `coupling_damping` (JSON arrays per DOF, the coupling in use).

mod csv;
mod mcap;

use std::collections::BTreeMap;
use std::path::Path;

use dfs_core::calibration::{Calibration, DofCalibration};
use dfs_core::contact::{ContactModel, Friction};
use dfs_core::coupling::{CouplingParams, VirtualCoupling};
use dfs_core::dfs::{Dfs, DfsParams, GloveSample};
use dfs_core::hand::HandModel;
use dfs_core::math::{Isometry, Rotation, Vector};
use dfs_core::object::ObjectState;
use dfs_core::operator::TICK_NS;
use dfs_core::scenario::ScenarioObject;

use super::recorder::{RecordSummary, SessionInfo, SessionRecorder, TickData};
use crate::error::{RecordingError, Result};

pub use self::csv::{parse_glove_csv, read_glove_csv, WRIST_COLUMNS};
pub use self::mcap::{read_glove_mcap, read_glove_mcap_with};

/// Poses of the hand's base link from a tracker, in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct WristTrack {
    /// Where they came from: `csv`, or the MCAP topic.
    pub source: String,
    /// Sample times, ns relative to the glove's first sample (a tracker may start before the
    /// glove: negative), strictly increasing.
    pub times_ns: Vec<i64>,
    /// Pose of the hand's base link in the world per sample (unit quaternions).
    pub poses: Vec<Isometry>,
}

impl WristTrack {
    /// The pose at `t_ns`: position linearly interpolated, orientation by slerp along the
    /// shorter arc, held at the first and last pose outside the track. Identity for an empty
    /// track.
    pub fn pose_at(&self, t_ns: i64) -> Isometry {
        let n = self.times_ns.len().min(self.poses.len());
        if n == 0 {
            return Isometry::identity();
        }
        let i = self.times_ns[..n].partition_point(|&t| t <= t_ns);
        if i == 0 {
            return self.poses[0];
        }
        if i >= n {
            return self.poses[n - 1];
        }
        let (t0, t1) = (self.times_ns[i - 1], self.times_ns[i]);
        let w = (t_ns - t0) as f64 / (t1 - t0) as f64;
        interpolate_pose(&self.poses[i - 1], &self.poses[i], w)
    }
}

/// `a` to `b` at `w` (0-1): position lerp, orientation slerp along the shorter arc (the two
/// signs of a quaternion are one rotation); never panics (nalgebra's `slerp` does for
/// opposite quaternions).
pub fn interpolate_pose(a: &Isometry, b: &Isometry, w: f64) -> Isometry {
    let p = a.translation.vector.lerp(&b.translation.vector, w);
    let qa = a.rotation.into_inner();
    let mut qb = b.rotation.into_inner();
    let mut dot = qa.coords.dot(&qb.coords);
    if dot < 0.0 {
        qb = -qb;
        dot = -dot;
    }
    let q = if dot > 0.9995 {
        // Nearly equal: normalised lerp (slerp's sin θ would divide by almost 0).
        qa.lerp(&qb, w)
    } else {
        let theta = dot.min(1.0).acos();
        let s = theta.sin();
        qa * (((1.0 - w) * theta).sin() / s) + qb * ((w * theta).sin() / s)
    };
    Isometry::from_parts(p.into(), Rotation::from_quaternion(q))
}

/// A glove recording: samples of joint angles (and torques) in the hand's DOF order, and the
/// wrist poses when a tracker gave them.
#[derive(Debug, Clone, PartialEq)]
pub struct GloveRecording {
    /// DOF names, in the order of the values.
    pub names: Vec<String>,
    /// Sample times (ns since the first sample), strictly increasing.
    pub times_ns: Vec<u64>,
    /// Joint angles θ (rad), `times_ns.len() × names.len()`, row by row.
    pub q: Vec<f64>,
    /// Operator joint torques τ (N·m), same layout as `q`; `None` for a glove that measures
    /// positions only (replayed through a virtual coupling).
    pub tau: Option<Vec<f64>>,
    /// The hand base's poses from a tracker; `None`: the base stays fixed.
    pub wrist: Option<WristTrack>,
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

    /// Whether the glove measured operator torques (else positions only).
    pub fn has_torques(&self) -> bool {
        self.tau.is_some()
    }

    /// Duration from the first to the last sample (ns).
    pub fn duration_ns(&self) -> u64 {
        self.times_ns.last().copied().unwrap_or(0)
    }

    /// θ and τ at `t_ns`, linearly interpolated (clamped to the recording), into `q`, `tau`
    /// (zeros for a recording without torques). Allocation-free.
    pub fn interpolate(&self, t_ns: u64, q: &mut [f64], tau: &mut [f64]) {
        let n = self.names.len();
        if self.is_empty() {
            return;
        }
        let i = self.times_ns.partition_point(|&t| t <= t_ns);
        let (a, b, w) = if i == 0 {
            (0, 0, 0.0)
        } else if i >= self.len() {
            (self.len() - 1, self.len() - 1, 0.0)
        } else {
            let (t0, t1) = (self.times_ns[i - 1], self.times_ns[i]);
            (i - 1, i, (t_ns - t0) as f64 / (t1 - t0) as f64)
        };
        let lerp = |v: &[f64], d: usize| v[a * n + d] + w * (v[b * n + d] - v[a * n + d]);
        for d in 0..n.min(q.len()) {
            q[d] = lerp(&self.q, d);
        }
        for d in 0..n.min(tau.len()) {
            tau[d] = self.tau.as_deref().map_or(0.0, |t| lerp(t, d));
        }
    }

    /// The wrist pose at `t_ns` (ns since the first sample), `None` without a tracker.
    pub fn wrist_at(&self, t_ns: u64) -> Option<Isometry> {
        let t = i64::try_from(t_ns).unwrap_or(i64::MAX);
        self.wrist.as_ref().map(|w| w.pose_at(t))
    }
}

/// Longest glove recording imported (ns from the first to the last sample): one hour, replayed
/// at 1 kHz into 3.6 million ticks.
pub const MAX_RECORDING_NS: u64 = 3_600_000_000_000;

pub(crate) fn invalid(location: impl Into<String>, detail: impl Into<String>) -> RecordingError {
    RecordingError::InvalidInput {
        location: location.into(),
        detail: detail.into(),
    }
}

/// Where the wrist poses of an MCAP glove recording come from.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum WristInput {
    /// The one `foxglove.PoseInFrame` topic, else a `foxglove.FrameTransforms` topic holding
    /// the hand's base link (module docs); none found: a fixed base.
    #[default]
    Auto,
    /// This topic (`foxglove.PoseInFrame` or `foxglove.FrameTransforms`); an error if it is
    /// missing or holds no pose of the base link.
    Topic(String),
    /// No wrist input: the base stays fixed.
    Ignore,
}

/// The coupling of a recording with torques against drift: full torque at a whole range's
/// error, a tenth of the default stiffness ([`CouplingParams::default`]), critically damped.
/// The measured torques drive the fingers; this only keeps their posture on the recorded one
/// (a tracking lag of about 60 ms on glove10's fingers).
pub const TORQUE_COUPLING: CouplingParams = CouplingParams {
    full_torque_fraction: 1.0,
    damping_ratio: 1.0,
};

/// How a measured glove sample drives the DFS, tick by tick (the module docs' "Replay"): the
/// DFS steps its own finger posture (the last tick's motor posture), driven by the measured
/// torques plus a weak coupling to the measured angles, or, for a glove that measures
/// positions only, by the coupling alone. Shared by imports and live sessions
/// ([`crate::live`]). Allocation-free.
#[derive(Debug, Clone, Copy)]
pub struct GloveDrive {
    coupling: VirtualCoupling,
    torques: bool,
    angle_slack: f64,
    torque_range: f64,
}

impl GloveDrive {
    /// The drive of `hand` in a DFS with `params`, for a glove that measures torques (or
    /// positions only); `coupling` `None`: the hand's default for that kind of glove
    /// ([`TORQUE_COUPLING`] or [`CouplingParams::default`]). Errors name what is wrong.
    pub fn new(
        hand: &HandModel,
        params: &DfsParams,
        torques: bool,
        coupling: Option<VirtualCoupling>,
    ) -> dfs_core::Result<GloveDrive> {
        let coupling = match coupling {
            Some(c) if c.dof() != hand.dof() => {
                return Err(dfs_core::DfsError::invalid(
                    "coupling",
                    format!("{} DOFs, {} has {}", c.dof(), hand.name, hand.dof()),
                ))
            }
            Some(c) => c,
            None => {
                let defaults = if torques {
                    TORQUE_COUPLING
                } else {
                    CouplingParams::default()
                };
                VirtualCoupling::for_hand(hand, &defaults, params)?
            }
        };
        Ok(GloveDrive {
            coupling,
            torques,
            angle_slack: params.angle_slack,
            torque_range: params.torque_range,
        })
    }

    /// The coupling in use.
    pub fn coupling(&self) -> &VirtualCoupling {
        &self.coupling
    }

    /// Whether the glove measures torques.
    pub fn torques(&self) -> bool {
        self.torques
    }

    /// The DFS's sample `q`, `tau` for a tick from the measured (calibrated) angles and
    /// torques (`tau_measured` is ignored for a glove of positions only) and the DFS's last
    /// output. The `first` tick starts the simulated hand at the measured posture, at rest.
    /// A measured posture outside the joint limits is an error; a measured torque out of the
    /// DFS's range is left for the DFS to refuse.
    #[allow(clippy::too_many_arguments)]
    pub fn sample(
        &self,
        hand: &HandModel,
        first: bool,
        q_measured: &[f64],
        tau_measured: &[f64],
        out: &dfs_core::dfs::TickOutput,
        q: &mut [f64],
        tau: &mut [f64],
    ) -> dfs_core::Result<()> {
        let n = hand.dof();
        if first {
            q.copy_from_slice(q_measured);
            if self.torques {
                tau.copy_from_slice(tau_measured);
            } else {
                tau.fill(0.0);
            }
            return Ok(());
        }
        hand.check_angles(q_measured, self.angle_slack)?;
        self.coupling.torques_from(q_measured, out, tau)?;
        q.copy_from_slice(&out.motor_q[..n]);
        if self.torques {
            for d in 0..n {
                let (measured, lim) = (tau_measured[d], hand.torque_limit[d] * self.torque_range);
                let total = measured + tau[d];
                tau[d] = if measured.abs() <= lim {
                    total.max(-lim).min(lim)
                } else {
                    total
                };
            }
        }
        Ok(())
    }
}

/// How a glove recording is read and replayed ([`import_glove`], [`replay_glove`]).
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// The glove's hand model: the recording's joints are its DOFs. Default glove10.
    pub hand: HandModel,
    /// The URDF text `hand` was built from (its link shapes go into the session's `hand.urdf`
    /// and `/hand`), `None` for glove10. Default `None`.
    pub hand_urdf: Option<String>,
    /// The hand base's fixed pose for a recording without wrist poses; giving one for a
    /// recording with wrist poses is an error. `None`: identity.
    pub base: Option<Isometry>,
    /// Wrist input of an MCAP recording. Default [`WristInput::Auto`].
    pub wrist: WristInput,
    /// Per-operator calibration of the angles. Default none.
    pub calibration: Option<Calibration>,
    /// The coupling of a recording without torques; `None`: the hand's default
    /// ([`VirtualCoupling::for_hand`] with [`CouplingParams::default`]).
    pub coupling: Option<VirtualCoupling>,
    /// The coupling against drift of a recording with torques; `None`: the hand's
    /// [`VirtualCoupling::for_hand`] with [`TORQUE_COUPLING`].
    pub torque_coupling: Option<VirtualCoupling>,
    /// Contact model of the fingertips. Default soft finger (pads, as in simulated sessions).
    pub contact_model: ContactModel,
    /// Whole-hand contact: the hand's palm and phalanges
    /// ([`HandModel::contact_shapes`]) touch the objects too ([`DfsParams::whole_hand`]), as
    /// in a simulated power grasp. Default false: the fingertips alone, as in every other
    /// simulated session, whose planned fingertip grasps let the phalanges pass through the
    /// object (imported with the whole hand, their phalanges would push it).
    pub whole_hand: bool,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            hand: HandModel::glove10(),
            hand_urdf: None,
            base: None,
            wrist: WristInput::Auto,
            calibration: None,
            coupling: None,
            torque_coupling: None,
            contact_model: ContactModel::SoftFinger,
            whole_hand: false,
        }
    }
}

/// Reads a glove recording for `hand`: CSV if the file name ends in `.csv`, MCAP otherwise
/// (wrist input found automatically, [`WristInput::Auto`]).
pub fn read_glove_file(path: &Path, hand: &HandModel) -> Result<GloveRecording> {
    read_glove_file_with(path, hand, &WristInput::Auto)
}

/// [`read_glove_file`] with the wrist input of an MCAP file chosen (`wrist` is ignored for a
/// CSV file, whose wrist columns are part of it).
pub fn read_glove_file_with(
    path: &Path,
    hand: &HandModel,
    wrist: &WristInput,
) -> Result<GloveRecording> {
    let is_csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if is_csv {
        read_glove_csv(path, hand)
    } else {
        read_glove_mcap_with(path, hand, wrist)
    }
}

/// The pose as the `base_pose` metadata writes it: `[x, y, z, qx, qy, qz, qw]`.
fn pose_json(p: &Isometry) -> String {
    serde_json::to_string(&[
        p.translation.x,
        p.translation.y,
        p.translation.z,
        p.rotation.i,
        p.rotation.j,
        p.rotation.k,
        p.rotation.w,
    ])
    .unwrap_or_default()
}

/// Replays `recording` (the DOFs of `options.hand`, in order) through the DFS against `object`
/// at 1 kHz into the session file `out` (see the module docs: wrist poses, calibration, the
/// DFS stepping its own finger posture coupled to the recorded one). `name` goes into the
/// `session` metadata as the scenario name. A recording shorter than the shortest phase,
/// [`MIN_TASK_S`](dfs_core::scenario::MIN_TASK_S), is refused: it holds no motion to segment.
/// A DFS error at some tick (e.g. an angle outside the joint limits) finishes the file with the
/// ticks before it and returns [`RecordingError::Simulation`] with the tick's time.
pub fn replay_glove(
    recording: &GloveRecording,
    object: &ScenarioObject,
    options: &ImportOptions,
    name: &str,
    out: &Path,
) -> Result<RecordSummary> {
    check_recording(recording, options, name)?;
    let hand = &options.hand;
    let calibration = match &options.calibration {
        Some(c) => c
            .validate(hand)
            .map_err(|e| invalid("calibration", e.to_string()))?,
        None => DofCalibration::identity(hand.dof()),
    };
    let Simulation {
        mut dfs,
        drive,
        table_height,
    } = simulation(object, options, recording.has_torques())?;
    let base = options.base.unwrap_or_else(Isometry::identity);
    let info = SessionInfo {
        scenario: name.to_owned(),
        seed: None,
        object_json: serde_json::to_string(object).unwrap_or_default(),
        source: "import-glove".to_owned(),
        extra: session_extra(recording, options, &base, drive.coupling()),
        phases: Vec::new(),
        started_at: None,
        table_height: Some(table_height),
        hand_urdf: options.hand_urdf.clone(),
        scene: None,
        assist_topics: false,
    };
    let recorder = SessionRecorder::create(out, dfs.hand(), dfs.object(), &info)?;
    replay_ticks(recording, &calibration, &drive, base, &mut dfs, recorder)
}

/// Refuses a recording [`replay_glove`] cannot replay: joints other than the hand's DOFs in
/// order, shorter than the shortest session, or with wrist poses when a fixed base is given.
fn check_recording(recording: &GloveRecording, options: &ImportOptions, name: &str) -> Result<()> {
    let hand = &options.hand;
    if recording.names != hand.dof_names {
        return Err(invalid(
            name,
            format!(
                "the recording's joints ({}) are not the DOFs of {} in order ({})",
                recording.names.join(", "),
                hand.name,
                hand.dof_names.join(", ")
            ),
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
    if let (Some(_), Some(w)) = (&options.base, &recording.wrist) {
        return Err(invalid(
            name,
            format!(
                "a fixed hand base was given, but the recording has wrist poses ({}); leave \
                 the base out, or ignore the wrist input",
                w.source
            ),
        ));
    }
    Ok(())
}

/// The DFS of an import, with the object in place, and the glove drive that steps it.
struct Simulation {
    /// The DFS.
    dfs: Dfs,
    /// How each measured sample drives it.
    drive: GloveDrive,
    /// Height of the table's top (m), the object resting on it by default.
    table_height: f64,
}

/// The DFS replaying a glove recording (with `torques`, or of positions only) against
/// `object`, placed at its `position` (default: resting on the table, at the origin), and the
/// glove drive with the coupling of `options` for that kind of glove.
fn simulation(
    object: &ScenarioObject,
    options: &ImportOptions,
    torques: bool,
) -> Result<Simulation> {
    let hand = &options.hand;
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
    let table_height = position.z - depth;
    let params = DfsParams {
        contact_model: options.contact_model,
        friction: Friction {
            mu: object.mu,
            mu_torsion: object.mu_torsion,
        },
        table_height: Some(table_height),
        whole_hand: options.whole_hand,
        ..DfsParams::default()
    };
    let given = if torques {
        options.torque_coupling
    } else {
        options.coupling
    };
    let drive = GloveDrive::new(hand, &params, torques, given)
        .map_err(|e| invalid("coupling", e.to_string()))?;
    let dfs =
        Dfs::new(hand.clone(), rigid, ObjectState::at_rest(pose), params).map_err(at_object)?;
    Ok(Simulation {
        dfs,
        drive,
        table_height,
    })
}

/// The import's keys of the `session` metadata (see the module docs), for a fixed `base` when
/// the recording has no wrist poses and the `coupling` in use.
fn session_extra(
    recording: &GloveRecording,
    options: &ImportOptions,
    base: &Isometry,
    coupling: &VirtualCoupling,
) -> BTreeMap<String, String> {
    let mut extra = BTreeMap::from([
        ("input_samples".to_owned(), recording.len().to_string()),
        (
            "contact_model".to_owned(),
            options.contact_model.name().to_owned(),
        ),
        (
            "glove_input".to_owned(),
            if recording.has_torques() {
                "torques"
            } else {
                "positions"
            }
            .to_owned(),
        ),
    ]);
    match &recording.wrist {
        Some(w) => {
            extra.insert("wrist".to_owned(), w.source.clone());
            extra.insert("wrist_samples".to_owned(), w.poses.len().to_string());
        }
        None => {
            extra.insert("wrist".to_owned(), "fixed".to_owned());
            extra.insert("base_pose".to_owned(), pose_json(base));
        }
    }
    if let Some(c) = options.calibration.as_ref().filter(|c| !c.is_empty()) {
        extra.insert(
            "calibration".to_owned(),
            serde_json::to_string(c).unwrap_or_default(),
        );
    }
    extra.insert(
        "contacts".to_owned(),
        if options.whole_hand {
            "whole_hand"
        } else {
            "fingertips"
        }
        .to_owned(),
    );
    let json = |v: &[f64]| serde_json::to_string(v).unwrap_or_default();
    extra.insert("coupling_stiffness".to_owned(), json(coupling.stiffness()));
    extra.insert("coupling_damping".to_owned(), json(coupling.damping()));
    extra
}

/// Steps `dfs` through `recording` at 1 kHz (the angles calibrated, the base at the wrist
/// pose or at `base`), recording every tick, then finishes the session file; a DFS error
/// finishes it with the ticks before and is returned with the tick's time.
fn replay_ticks(
    recording: &GloveRecording,
    calibration: &DofCalibration,
    drive: &GloveDrive,
    base: Isometry,
    dfs: &mut Dfs,
    mut recorder: SessionRecorder,
) -> Result<RecordSummary> {
    let n = dfs.hand().dof();
    let (mut q_measured, mut tau_measured) = (vec![0.0; n], vec![0.0; n]);
    let (mut q, mut tau) = (vec![0.0; n], vec![0.0; n]);
    let torques = recording.has_torques();
    let ticks = recording.duration_ns() / TICK_NS + 1;
    for k in 0..ticks {
        let t = k * TICK_NS;
        recording.interpolate(t, &mut q_measured, &mut tau_measured);
        calibration.apply(&mut q_measured);
        let base = recording.wrist_at(t).unwrap_or(base);
        let sample = drive.sample(
            dfs.hand(),
            k == 0,
            &q_measured,
            &tau_measured,
            dfs.output(),
            &mut q,
            &mut tau,
        );
        if let Err(source) = sample.and_then(|()| {
            dfs.step(&GloveSample {
                q: &q,
                tau: &tau,
                base,
            })
            .map(|_| ())
        }) {
            recorder.finish()?;
            return Err(RecordingError::Simulation { time_ns: t, source });
        }
        // A recording with torques is kept as recorded; one of positions only as stepped.
        let (q_rec, tau_rec) = if torques {
            (&q_measured, &tau_measured)
        } else {
            (&q, &tau)
        };
        let tick = TickData {
            time_ns: t,
            q: q_rec,
            tau: tau_rec,
            base: &base,
            output: dfs.output(),
            body: dfs.body_contacts(),
            kinematics: dfs.kinematics(),
        };
        if let Err(e) = recorder.record(&tick) {
            let _ = recorder.finish();
            return Err(e);
        }
    }
    recorder.finish()
}

/// [`read_glove_file_with`] then [`replay_glove`], named after the input file.
pub fn import_glove(
    input: &Path,
    object: &ScenarioObject,
    options: &ImportOptions,
    out: &Path,
) -> Result<RecordSummary> {
    let recording = read_glove_file_with(input, &options.hand, &options.wrist)?;
    let name = input
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| input.display().to_string());
    replay_glove(&recording, object, options, &name, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrist_poses_interpolate_linearly_and_by_the_shorter_arc() {
        let a = Isometry::from_parts(
            Vector::new(0.0, 0.0, 0.0).into(),
            Rotation::from_euler_angles(0.0, 0.0, 0.0),
        );
        let b = Isometry::from_parts(
            Vector::new(1.0, 2.0, 0.0).into(),
            Rotation::from_euler_angles(0.0, 0.0, 1.0),
        );
        // The same rotation with the quaternion's other sign.
        let b_neg = Isometry::from_parts(
            b.translation,
            Rotation::new_unchecked(-b.rotation.into_inner()),
        );
        let track = WristTrack {
            source: "test".into(),
            times_ns: vec![-10, 90, 190],
            poses: vec![a, b_neg, b],
        };
        let mid = track.pose_at(40);
        assert!((mid.translation.vector - Vector::new(0.5, 1.0, 0.0)).norm() < 1e-12);
        assert!(
            (mid.rotation.angle() - 0.5).abs() < 1e-9,
            "{}",
            mid.rotation.angle()
        );
        assert_eq!(track.pose_at(-100), a);
        assert_eq!(track.pose_at(1000), b);
        assert!((track.pose_at(140).rotation.angle_to(&b.rotation)).abs() < 1e-9);
        // Opposite rotations (180° apart) interpolate without panicking.
        let flip = Isometry::from_parts(
            Vector::zeros().into(),
            Rotation::from_euler_angles(0.0, 0.0, std::f64::consts::PI),
        );
        let p = interpolate_pose(&a, &flip, 0.5);
        assert!(p.rotation.coords.iter().all(|v| v.is_finite()));
        assert!((p.rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
    }
}
