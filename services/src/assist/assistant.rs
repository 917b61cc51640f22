//! The assistant of a live session, on a thread of its own.
//!
//! The live session hands it an [`Observation`] every [`OBSERVATION_PERIOD_NS`] of session
//! time through a bounded channel and never waits: when the channel is full (the assistant is
//! planning a robot grasp, or the machine is busy) the observation is dropped and counted. The
//! assistant says so (`behind`, with how many it missed) and goes on from the newest
//! observation: recognition takes jumps in its stride (a checkpoint crossed between two
//! observations records the hand where it is), the robot's clock catches up at its bounded
//! rate. Its events come back on a channel the session drains after each frame.
//!
//! In `apply` mode, the first `recognised` verdict starts the robot: the stored skill is
//! retargeted onto the robot hand (`dfs_core::replay`'s planner) and executed in a DFS of its
//! own ([`DrivenReplay`]), its phase driven by the operator's as [`OnlinePhase`] estimates it
//! on-line. A skill the hand cannot take is reported (`assist_error` with the planner's
//! reason) and the session goes on without the robot.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;

use dfs_core::replay::ReplayParams;
use dfs_core::replay::{DrivenReplay, DrivenStart};
use dfs_core::scenario::Phase;
use dfs_core::Stop;
use serde::Serialize;

use crate::replay::{skill_spec_from_json, LoadedHand};
use crate::segmentation::SegmentParams;
use crate::session::ASSIST_ROBOT_RATE_HZ;

use super::features::{ObjectInfo, Observation};
use super::index::RecognitionIndex;
use super::phase::{OnlinePhase, PhaseObservation};
use super::recognise::{Recogniser, RecogniserParams, Verdict};

/// Observations in flight to the assistant: 2.56 s at 100 Hz.
pub const ASSIST_QUEUE: usize = 256;

/// How the robot's scene is drawn beside the operator's (m, world x): the robot's DFS has a
/// world of its own (the table's top at z = 0, the object at the origin).
pub const ROBOT_SCENE_OFFSET_X: f64 = 0.6;

/// The stored skill's parameters (its JSON) by id, for `apply`.
pub type SkillLoader = Box<dyn Fn(i64) -> Result<serde_json::Value, String> + Send>;

/// What the assistant is to do.
pub struct AssistSetup {
    /// The stored skills.
    pub index: Arc<RecognitionIndex>,
    /// The scene's objects, in its order.
    pub objects: Vec<ObjectInfo>,
    /// Recognition's tuning.
    pub params: RecogniserParams,
    /// `apply`: the robot hand and how to load a stored skill. `None`: `suggest`.
    pub apply: Option<(LoadedHand, SkillLoader)>,
}

/// What the assistant says besides verdicts.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Notice {
    /// Observations were dropped while the assistant was busy; it goes on from the newest.
    Behind {
        /// Session time of the observation it resumed with (ns).
        session_ns: u64,
        /// Observations dropped since the last `behind`.
        dropped: u64,
    },
    /// The robot hand started applying a skill.
    Applying {
        /// Session time (ns).
        session_ns: u64,
        /// The skill.
        skill_id: i64,
        /// The robot hand.
        robot: String,
    },
    /// The assistant could not do something; the session goes on without it.
    AssistError {
        /// Session time (ns).
        session_ns: u64,
        /// What went wrong (the planner's reason for a skill the hand cannot take).
        message: String,
    },
    /// The robot's state, at [`ASSIST_ROBOT_RATE_HZ`].
    Robot(RobotState),
    /// The robot's replay report (when its replay ends, or the session does).
    RobotReport {
        /// Session time (ns).
        session_ns: u64,
        /// The skill.
        skill_id: i64,
        /// `dfs_core::replay::ReplayReport` as JSON: whether the object was held and moved
        /// as the skill demands.
        report: serde_json::Value,
    },
}

/// The robot applying a skill, at one moment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotState {
    /// Session time (ns).
    pub session_ns: u64,
    /// The skill.
    pub skill_id: i64,
    /// The operator's phase as estimated on-line.
    pub operator_phase: Phase,
    /// The skill's phase the robot is in.
    pub robot_phase: Phase,
    /// Replay time on the skill's timeline (s).
    pub replay_time_s: f64,
    /// Rate of replay time to session time (1 in step, 0 waiting for the operator).
    pub rate: f64,
    /// The robot's joint angles (rad or m), in its DOF order.
    pub q: Vec<f64>,
    /// The robot's base `[x, y, z, qx, qy, qz, qw]` in its DFS's world (m).
    pub base: [f64; 7],
    /// The object `[x, y, z, qx, qy, qz, qw]` in the robot DFS's world (m).
    pub object: [f64; 7],
    /// Fingertip centres in the robot DFS's world (m).
    pub tips: Vec<[f64; 3]>,
    /// Per fingertip, the normal force it transmits (N).
    pub tip_normal_forces: Vec<f64>,
    /// The object's bounding radius (m), to draw it.
    pub object_radius_m: f64,
}

/// An event of the assistant: a verdict or a notice (each carries its `type`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum AssistEvent {
    /// `recognised` or `unknown`.
    Verdict(Verdict),
    /// Anything else.
    Notice(Notice),
}

impl AssistEvent {
    /// Session time of the event (ns).
    pub fn session_ns(&self) -> u64 {
        match self {
            AssistEvent::Verdict(v) => v.session_ns(),
            AssistEvent::Notice(n) => match n {
                Notice::Behind { session_ns, .. }
                | Notice::Applying { session_ns, .. }
                | Notice::AssistError { session_ns, .. }
                | Notice::RobotReport { session_ns, .. } => *session_ns,
                Notice::Robot(r) => r.session_ns,
            },
        }
    }
}

/// What the assistant did, at the end of the session.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct AssistSummary {
    /// Every verdict.
    pub verdicts: Vec<Verdict>,
    /// Observations dropped while it was busy.
    pub dropped: u64,
    /// Comparisons with the stored skills.
    pub decisions: u64,
    /// The robot's replay report, if a skill was applied.
    pub robot_report: Option<serde_json::Value>,
}

/// The assistant's thread and its channels. See the module docs.
pub struct Assistant {
    tx: Option<SyncSender<Observation>>,
    events: Receiver<AssistEvent>,
    dropped: Arc<AtomicU64>,
    thread: Option<JoinHandle<AssistSummary>>,
}

impl std::fmt::Debug for Assistant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Assistant")
            .field("dropped", &self.dropped.load(Ordering::Relaxed))
            .finish_non_exhaustive()
    }
}

impl Assistant {
    /// Starts the assistant's thread.
    pub fn start(setup: AssistSetup) -> std::io::Result<Assistant> {
        let (tx, rx) = sync_channel::<Observation>(ASSIST_QUEUE);
        let (events_tx, events) = std::sync::mpsc::channel();
        let dropped = Arc::new(AtomicU64::new(0));
        let counter = Arc::clone(&dropped);
        let thread = std::thread::Builder::new()
            .name("icms-assistant".into())
            .spawn(move || Worker::new(setup, events_tx, counter).run(rx))?;
        Ok(Assistant {
            tx: Some(tx),
            events,
            dropped,
            thread: Some(thread),
        })
    }

    /// Offers an observation; never blocks. `false` when it was dropped (counted).
    pub fn offer(&self, obs: &Observation) -> bool {
        let Some(tx) = &self.tx else { return false };
        match tx.try_send(*obs) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// The events said since the last call.
    pub fn drain(&self) -> impl Iterator<Item = AssistEvent> + '_ {
        self.events.try_iter()
    }

    /// Ends the assistant: it takes what is queued, reports the robot's replay, and stops.
    /// Returns its summary and the events it said at the end.
    pub fn finish(mut self) -> (AssistSummary, Vec<AssistEvent>) {
        self.tx = None;
        let summary = self
            .thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default();
        let tail = self.events.try_iter().collect();
        (summary, tail)
    }
}

/// The robot applying a skill.
struct Robot {
    skill_id: i64,
    replay: Box<DrivenReplay>,
    dof: usize,
    object_radius_m: f64,
    next_state_ns: u64,
    reported: bool,
}

struct Worker {
    recogniser: Recogniser,
    phase: OnlinePhase,
    apply: Option<(LoadedHand, SkillLoader)>,
    robot: Option<Robot>,
    /// A skill was tried on the robot (once per session).
    tried: bool,
    /// The recogniser's verdicts said so far.
    verdicts_said: usize,
    events: std::sync::mpsc::Sender<AssistEvent>,
    dropped: Arc<AtomicU64>,
    said_dropped: u64,
    robot_report: Option<serde_json::Value>,
}

impl Worker {
    fn new(
        setup: AssistSetup,
        events: std::sync::mpsc::Sender<AssistEvent>,
        dropped: Arc<AtomicU64>,
    ) -> Worker {
        Worker {
            recogniser: Recogniser::new(setup.index, setup.objects, setup.params),
            phase: OnlinePhase::new(&SegmentParams::default()),
            apply: setup.apply,
            robot: None,
            tried: false,
            verdicts_said: 0,
            events,
            dropped,
            said_dropped: 0,
            robot_report: None,
        }
    }

    fn say(&self, e: AssistEvent) {
        let _ = self.events.send(e);
    }

    fn run(mut self, rx: Receiver<Observation>) -> AssistSummary {
        let mut last_ns = 0;
        let mut next = None;
        loop {
            let obs = match next.take() {
                Some(obs) => obs,
                None => match rx.recv() {
                    Ok(obs) => obs,
                    Err(_) => break,
                },
            };
            last_ns = obs.t_ns;
            let dropped = self.dropped.load(Ordering::Relaxed);
            if dropped > self.said_dropped {
                self.say(AssistEvent::Notice(Notice::Behind {
                    session_ns: obs.t_ns,
                    dropped: dropped - self.said_dropped,
                }));
                self.said_dropped = dropped;
            }
            self.recogniser.observe(&obs);
            self.say_verdicts();
            let change = self.phase.push(&PhaseObservation {
                t_ns: obs.t_ns,
                base: obs.base,
                touching: obs.in_contact() as u32,
            });
            self.step_robot(&obs, change.map(|c| c.phase));
            // The rest of this period's recognition work, a slice at a time while no
            // observation waits (an arriving one waits for one slice at most), and the
            // decisions of this observation whatever waits (they come before the next's).
            while self.recogniser.work() {
                self.say_verdicts();
                if self.recogniser.busy() {
                    continue;
                }
                match rx.try_recv() {
                    Ok(obs) => {
                        next = Some(obs);
                        break;
                    }
                    Err(TryRecvError::Empty) => {}
                    Err(TryRecvError::Disconnected) => break,
                }
            }
            self.say_verdicts();
        }
        self.report_robot(last_ns);
        AssistSummary {
            verdicts: self.recogniser.verdicts().to_vec(),
            dropped: self.dropped.load(Ordering::Relaxed),
            decisions: self.recogniser.decisions(),
            robot_report: self.robot_report,
        }
    }

    /// Says the recogniser's verdicts not said yet; the first that recognises a skill starts
    /// the robot (once per session), at the verdict's time.
    fn say_verdicts(&mut self) {
        while let Some(v) = self.recogniser.verdicts().get(self.verdicts_said).cloned() {
            self.verdicts_said += 1;
            let start = matches!(v, Verdict::Recognised { .. }) && !self.tried;
            let skill = v.skill().map(|c| c.skill_id);
            let t_ns = v.session_ns();
            self.say(AssistEvent::Verdict(v));
            if let (true, Some(skill_id)) = (start, skill) {
                self.start_robot(skill_id, t_ns);
            }
        }
    }

    /// Retargets `skill_id` onto the robot hand and starts it, aligned with the operator.
    fn start_robot(&mut self, skill_id: i64, t_ns: u64) {
        let Some((hand, loader)) = &self.apply else {
            return;
        };
        self.tried = true;
        let fail = |message: String| {
            AssistEvent::Notice(Notice::AssistError {
                session_ns: t_ns,
                message,
            })
        };
        let spec = match loader(skill_id).and_then(|json| {
            skill_spec_from_json(&json, &format!("skill {skill_id}")).map_err(|e| e.to_string())
        }) {
            Ok(s) => s,
            Err(e) => {
                self.say(fail(format!("skill {skill_id} cannot be applied: {e}")));
                return;
            }
        };
        let model = match hand.model_for(&spec) {
            Ok(m) => m,
            Err(e) => {
                self.say(fail(format!("skill {skill_id} cannot be applied: {e}")));
                return;
            }
        };
        let now_s = t_ns as f64 * 1e-9;
        let started = DrivenReplay::start(
            &model,
            hand.thumb,
            &spec,
            &ReplayParams::default(),
            now_s,
            Stop::never(),
        );
        match started {
            Ok(DrivenStart::Running(replay)) => {
                let mut replay = replay;
                replay.set_phase(self.phase.phase(), now_s);
                let dof = hand.model.dof();
                self.say(AssistEvent::Notice(Notice::Applying {
                    session_ns: t_ns,
                    skill_id,
                    robot: hand.model.name.clone(),
                }));
                self.robot = Some(Robot {
                    skill_id,
                    replay,
                    dof,
                    object_radius_m: spec.shape.bounding_radius(),
                    next_state_ns: t_ns,
                    reported: false,
                });
            }
            Ok(DrivenStart::Refused(report)) => {
                let reason = match (report.failure_reason, report.detail.as_str()) {
                    (Some(r), "") => r.name().to_owned(),
                    (Some(r), d) => format!("{}: {d}", r.name()),
                    (None, d) => d.to_owned(),
                };
                self.say(fail(format!(
                    "skill {skill_id} cannot be retargeted onto {}: {reason}; the session \
                     goes on without the robot",
                    hand.model.name
                )));
            }
            Err(e) => self.say(fail(format!(
                "skill {skill_id} cannot be applied on {}: {e}",
                hand.model.name
            ))),
        }
    }

    /// Steps the robot up to the observation's time, its phase following the operator's.
    fn step_robot(&mut self, obs: &Observation, change: Option<Phase>) {
        let Some(robot) = &mut self.robot else { return };
        let now_s = obs.t_ns as f64 * 1e-9;
        if let Some(p) = change {
            robot.replay.set_phase(p, now_s);
        }
        let mut failed = None;
        while robot.replay.clock().now() + 0.5e-3 < now_s && !robot.replay.is_finished() {
            match robot.replay.tick() {
                Ok(true) => {}
                Ok(false) => break,
                Err(e) => {
                    failed = Some(e.to_string());
                    break;
                }
            }
        }
        if obs.t_ns >= robot.next_state_ns {
            robot.next_state_ns = obs.t_ns + 1_000_000_000 / ASSIST_ROBOT_RATE_HZ;
            let s = robot.replay.state();
            let pose = |p: &dfs_core::math::Isometry| {
                let q = p.rotation.quaternion();
                let t = p.translation.vector;
                [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
            };
            let out = s.tick.output;
            let state = RobotState {
                session_ns: obs.t_ns,
                skill_id: robot.skill_id,
                operator_phase: s.operator_phase,
                robot_phase: s.replay_phase,
                replay_time_s: s.replay_time_s,
                rate: s.rate,
                q: s.tick.q[..robot.dof.min(s.tick.q.len())].to_vec(),
                base: pose(s.tick.base),
                object: pose(s.object),
                tips: out.tip_centres[..out.n_tips]
                    .iter()
                    .map(|p| [p.x, p.y, p.z])
                    .collect(),
                tip_normal_forces: s.tip_normal_forces.to_vec(),
                object_radius_m: robot.object_radius_m,
            };
            let _ = self.events.send(AssistEvent::Notice(Notice::Robot(state)));
        }
        if let Some(message) = failed {
            self.say(AssistEvent::Notice(Notice::AssistError {
                session_ns: obs.t_ns,
                message: format!("the robot's DFS failed: {message}; the robot stops"),
            }));
            self.report_robot(obs.t_ns);
            self.robot = None;
        } else if self.robot.as_ref().is_some_and(|r| r.replay.is_finished()) {
            self.report_robot(obs.t_ns);
        }
    }

    /// Reports the robot's replay once.
    fn report_robot(&mut self, t_ns: u64) {
        let Some(robot) = &mut self.robot else { return };
        if robot.reported {
            return;
        }
        robot.reported = true;
        let report = serde_json::to_value(robot.replay.report()).unwrap_or_default();
        self.robot_report = Some(report.clone());
        let skill_id = robot.skill_id;
        self.say(AssistEvent::Notice(Notice::RobotReport {
            session_ns: t_ns,
            skill_id,
            report,
        }));
    }
}
