//! The simulated operator (IP-flow 1 without a physical glove) and the closed 1 kHz loop.
//!
//! An operator wears the glove and performs a [`Scenario`]: scripted phases (`approach`,
//! `preshape`, `grasp`, `lift`, `hold`, `transport`, `place`, `release`, `retreat`). Like a
//! person it
//! - plans a grasp for the object where it lies ([`plan_grasp`]: fingertip inverse kinematics
//!   with the hand's base free, preferring grasps whose fingertips can push along their contact
//!   normals and the vertical);
//! - reaches with minimum-jerk profiles (Flash & Hogan 1985) of the arm (the hand base) and
//!   slides the open hand in beside the object;
//! - steers each fingertip of the grasp towards its spot on the object, closing along the
//!   normal; once touching it keeps the finger where it met the object relative to the hand;
//! - squeezes with the normal force friction needs for the load it expects (weight plus the
//!   arm's acceleration), with a safety margin for the friction it expects (Johansson &
//!   Westling 1984), ramping it up after every finger touches and down on release; friction then
//!   carries the object as the arm moves;
//! - has a physiological tremor (8-12 Hz) and the glove's sensors add noise, all from a seeded
//!   ChaCha8 stream: the same scenario and seed give bit-identical sessions.
//!
//! The glove's motors are taken to track the DFS's position commands exactly; the measured
//! angles are those plus sensor noise.
//!
//! # Varied reaches
//!
//! By default every seed reaches alike: the hand starts 0.15 m straight above its approach
//! pose (beside the target, where it waits before sliding in) and goes straight down to it in
//! the script's durations; only the tremor and the sensor noise differ. A scenario with
//! `vary_reach` varies the reaches by its seed, from a ChaCha8 stream of their own
//! ([`REACH_STREAM`]; the tremor and the noise are those of the same seed without it):
//! - the hand starts at a *home* [`REACH_HOME_M`] from the first approach pose, in a direction
//!   up to ±90° ([`REACH_HOME_AZIMUTH`]) about the horizontal one pointing from the target to
//!   the approach pose (the side the hand comes from) and [`REACH_HOME_ELEVATION`] above the
//!   horizontal, its palm turned up to ±[`REACH_HOME_YAW`] about the vertical from its grasp
//!   orientation;
//! - each `approach` bends off the straight line by `b sin(π u)` for the path parameter `u`
//!   (a minimum-jerk profile in time), `b` perpendicular to the line, pointing sideways or up
//!   (never down), of up to [`REACH_BEND`] of the length: zero at both ends, with continuous
//!   velocity and acceleration;
//! - its speed is scaled by `s` in [`REACH_SPEED`]: the `approach` and the `preshape` after it
//!   take their durations / `s`;
//! - with chance [`REACH_PAUSE_CHANCE`] it pauses [`REACH_PAUSE_S`] part-way
//!   ([`REACH_PAUSE_AT`] of the path): two minimum-jerk moves with a rest between them, all in
//!   `approach` (the ground truth, [`Simulation::phases`], holds the changed durations).
//!
//! The fingers of the grasp keep the open hand's posture over the first
//! [`REACH_SHAPE_FROM`] of a varied reach's path, then reach for their spots on the object.
//! Homes and bends are checked against the table and the objects: along the path the open
//! hand (its fingertips, joints and the middles of its segments) keeps [`REACH_CLEARANCE_M`]
//! from both, or at least what it keeps at the path's ends; a home is redrawn (up to 16 times,
//! then the fixed start above the approach pose is used) and a bend redrawn smaller (up to 8
//! times, then the straight line) until it does.
//!
//! In a scene of several objects ([`Scene`]) the operator plans, reaches for, squeezes and
//! carries the scenario's `target` only; the other objects stay on the table as obstacles,
//! simulated like it (a fingertip or the carried object that bumps one moves it or passes
//! into it: that is physics, and the DFS reports an overlap). A fingertip on another object
//! does not count as touching the target.

use crate::contact::ContactModel;
use crate::dfs::{Dfs, DfsParams, GloveSample, TickOutput};
use crate::error::{DfsError, Result};
use crate::hand::{HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Rotation, Vector};
use crate::object::{ObjectState, RigidObject, Shape};
use crate::scenario::{GraspStyle, Phase, ResolvedTask, Scenario, Scene, MAX_SCRIPT_S, MIN_TASK_S};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

pub mod power;
use power::{PowerGrip, Wrap};

/// A hand whose base can translate freely: three prismatic joints (world x, y, z) carry the
mod plan;
mod reach;
use plan::{mount_link, tip_index};
pub use plan::{plan_grasp, plan_operator_grasp, with_free_base, GraspPlan};
pub(crate) use plan::{push_alignment, push_basis};
use reach::{
    bend_vector, draw_home, min_jerk, reach_point, whole_ticks_ns, Reach, ReachCheck, ReachPath,
    BEND_TRIES,
};
pub use reach::{
    REACH_BEND, REACH_CLEARANCE_M, REACH_HOME_ABOVE_TABLE_M, REACH_HOME_AZIMUTH,
    REACH_HOME_ELEVATION, REACH_HOME_M, REACH_HOME_YAW, REACH_PAUSE_AT, REACH_PAUSE_CHANCE,
    REACH_PAUSE_S, REACH_SHAPE_FROM, REACH_SPEED, REACH_STREAM,
};
#[cfg(test)]
mod tests;

/// Parameters of the simulated operator. SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatorParams {
    /// Joint stiffness around the intention, as a fraction of each DOF's torque limit per
    /// radian. Default 0.5.
    pub stiffness: Real,
    /// Wrist damping (N·m·s/rad). Default 0.05. (The fingers are damped by the glove.)
    pub wrist_damping: Real,
    /// Grip safety margin over the slip limit (Johansson & Westling 1984 report 1.2-2 in
    /// people). Default 2.
    pub grip_safety: Real,
    /// Least normal force per contact while gripping (N). Default 0.5.
    pub min_normal: Real,
    /// Physiological tremor amplitude at the finger joints (rad). Default 1e-4.
    pub tremor_joint: Real,
    /// Tremor amplitude of the arm (hand base) (m). Default 5e-6.
    pub tremor_arm: Real,
    /// Standard deviation of the glove's angle sensors (rad). Default 5e-5.
    pub noise_angle: Real,
    /// Standard deviation of the glove's torque sensors (N·m). Default 2e-4.
    pub noise_torque: Real,
    /// How far past the surface the fingers aim when closing, as a fraction of the
    /// preshape-to-grasp motion. Default 0.
    pub close_overshoot: Real,
    /// Task-space stiffness steering a fingertip of the grasp towards its spot while it
    /// reaches, closes and opens (N/m). Default 150.
    pub fingertip_stiffness: Real,
    /// Task-space stiffness keeping a fingertip of the grasp where it met the object, relative
    /// to the hand, while holding (N/m). Default 1000: a pinching fingertip is about 1 N/mm
    /// stiff (finger-pad and joint impedance of a person's precision grip).
    pub hold_stiffness: Real,
    /// Damping of a finger's posture in the null space of its fingertip's task (N·m·s/rad).
    /// Default 0.005.
    pub posture_damping: Real,
    /// Task-space damping of the same, on the fingertip's velocity relative to the hand
    /// (N·s/m). Default 5: well damped, and stable at 1 kHz although the operator's torques are
    /// computed from the previous tick's state.
    pub hold_damping: Real,
    /// How far the grip rises above its static level while the object is lifted off
    /// (fraction): people grip hardest at lift-off and relax to the static level as the object
    /// comes to rest in the hand (Johansson & Westling 1984, the grip-force peak of the loading
    /// phase). Default 0.6: 1.6 times the static grip at the peak, back to it by the end of the
    /// lift.
    pub lift_grip_peak: Real,
}

impl Default for OperatorParams {
    fn default() -> Self {
        OperatorParams {
            stiffness: 0.5,
            wrist_damping: 0.05,
            grip_safety: 2.0,
            min_normal: 0.5,
            tremor_joint: 1e-4,
            tremor_arm: 5e-6,
            noise_angle: 5e-5,
            noise_torque: 2e-4,
            close_overshoot: 0.0,
            fingertip_stiffness: 150.0,
            hold_stiffness: 1000.0,
            hold_damping: 5.0,
            posture_damping: 0.005,
            lift_grip_peak: 0.6,
        }
    }
}

/// One phase of a session's script with its time span (ns since the session's start).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseSpan {
    /// The phase.
    pub phase: Phase,
    /// Start (ns).
    pub start_ns: u64,
    /// End (ns), exclusive.
    pub end_ns: u64,
    /// The task's parameters.
    pub task: ResolvedTask,
}

/// Tick length of the closed loop (ns): 1 kHz.
pub const TICK_NS: u64 = 1_000_000;

/// The closed loop: operator → glove sample (θ, τ) → DFS tick → feedback and motor commands →
/// glove state, at 1 kHz of simulated time.
#[derive(Debug, Clone)]
pub struct Simulation {
    dfs: Dfs,
    /// The scene as the scenario set it up.
    scene: Scene,
    /// Index of the object the script grasps in the scene (and the DFS).
    target: usize,
    params: OperatorParams,
    style: GraspStyle,
    spans: Vec<PhaseSpan>,
    span: usize,
    step: u64,
    n_steps: u64,
    table_height: Real,
    operator_mu: Real,
    plan: GraspPlan,
    /// The grasp phase has ended and the object is held (until release ends).
    object_held: bool,
    from_base: Isometry,
    to_base: Isometry,
    from_q: [Real; MAX_DOF],
    to_q: [Real; MAX_DOF],
    from_grip: Real,
    to_grip: Real,
    from_offset: Real,
    to_offset: Real,
    offset: Real,
    /// Where the operator saw the object when it last looked before holding it: fingertip
    /// targets are fixed to this pose until the object is held, then to the object.
    seen_object: Isometry,
    /// Per fingertip: where it first touched while holding (the pad on the surface) and the
    /// inward contact normal there, both in the frame of the link its finger is mounted on.
    hold_in_mount: [Option<(Vector, Vector)>; MAX_TIPS],
    /// Per fingertip: the link its finger is mounted on ([`mount_link`]).
    mount: [usize; MAX_TIPS],
    /// Per fingertip of the grasp: it rests on the object instead of squeezing it
    /// ([`resting_tips`]).
    resting: [bool; MAX_TIPS],
    base: Isometry,
    base_acceleration: Vector,
    q_intent: [Real; MAX_DOF],
    grip: Real,
    /// Share of the object's expected load the fingertips lift actively (0-1).
    carry: Real,
    /// The grip's rise above its static level (fraction), see
    /// [`OperatorParams::lift_grip_peak`].
    grip_boost: Real,
    q_meas: [Real; MAX_DOF],
    tau_meas: [Real; MAX_DOF],
    tau: [Real; MAX_DOF],
    rng: ChaCha8Rng,
    tremor_freq: [Real; MAX_DOF + 3],
    tremor_phase: [Real; MAX_DOF + 3],
    /// Per span: the variation of its reach (a varied `approach`), see
    /// [the module docs](self#varied-reaches).
    reaches: Vec<Option<Reach>>,
    /// The stream varied reaches draw their bends from ([`REACH_STREAM`]); `None` when the
    /// scenario does not vary its reaches.
    reach_rng: Option<ChaCha8Rng>,
    /// The varied approach under way.
    reach_path: Option<ReachPath>,
    /// In a varied approach, how far the fingers of the grasp have gone over from holding
    /// the open hand's posture to reaching for their spots on the object (0-1,
    /// [`REACH_SHAPE_FROM`]).
    reach_shaping: Real,
    /// In a wrap ([`GraspPlan::wrap`]), how far the fingers have gone over from the open
    /// hand's posture to closing by torque (0-1).
    wrap_close: Real,
    /// In a wrap, where the fingers came to rest on the object at the end of `grasp`: held
    /// there from then on (with the closing torques) until they open.
    wrap_set: Option<[Real; MAX_DOF]>,
}

impl Simulation {
    /// Sets up a scenario with `hand` (normally glove10): its scene ([`Scenario::resolve_scene`])
    /// in one DFS, the grasp planned on the target. `duration_s`, when given, cuts the
    /// script short or extends its last phase. Errors name the scenario's field, or say that no
    /// grasp of the object is reachable.
    pub fn new(
        scenario: &Scenario,
        hand: HandModel,
        duration_s: Option<Real>,
    ) -> Result<Simulation> {
        let (scene, tasks) = scenario.resolve_scene()?;
        let target = scene.target;
        let (object, pose, friction) = {
            let t = scene.target();
            (t.object, t.pose, t.friction)
        };
        let table_height = scene.table_height;
        let mut spans = Vec::with_capacity(tasks.len());
        let mut t = 0u64;
        // Varied reaches: their own stream of the seed, so the tremor and the noise below are
        // the seed's either way.
        let mut reach_rng = scenario.vary_reach.then(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
            rng.set_stream(REACH_STREAM);
            rng
        });
        let mut reaches = vec![None; tasks.len()];
        let mut speed = 1.0;
        for (i, task) in tasks.iter().enumerate() {
            let d = match (reach_rng.as_mut(), task.phase) {
                (Some(rng), Phase::Approach) => {
                    let reach = Reach::draw(rng, task.duration);
                    speed = reach.speed;
                    reaches[i] = Some(reach);
                    ((reach.move_s + reach.pause_s) * 1e9).round() as u64
                }
                (Some(_), Phase::Preshape) => whole_ticks_ns(task.duration / speed),
                _ => (task.duration * 1e9).round() as u64 / TICK_NS * TICK_NS,
            };
            spans.push(PhaseSpan {
                phase: task.phase,
                start_ns: t,
                end_ns: t + d.max(TICK_NS),
                task: *task,
            });
            t += d.max(TICK_NS);
        }
        if scenario.vary_reach && t as Real * 1e-9 > MAX_SCRIPT_S {
            return Err(DfsError::invalid(
                "vary_reach",
                format!(
                    "the varied reaches make the script last {} s; a session lasts at most \
                     {MAX_SCRIPT_S} s",
                    t as Real * 1e-9
                ),
            ));
        }
        let mut n_steps = t / TICK_NS;
        if let Some(d) = duration_s {
            // A session shorter than the shortest phase holds no motion to segment (and one of
            // a tick or two would not read back as a session).
            if !(d.is_finite() && (MIN_TASK_S..=MAX_SCRIPT_S).contains(&d)) {
                return Err(DfsError::invalid(
                    "duration",
                    format!("must be {MIN_TASK_S} to {MAX_SCRIPT_S} s, got {d}"),
                ));
            }
            n_steps = ((d * 1e9).round() as u64 / TICK_NS).max(1);
            let end = n_steps * TICK_NS;
            spans.retain(|s| s.start_ns < end);
            if let Some(last) = spans.last_mut() {
                last.end_ns = end;
            }
        }
        let obstacles: Vec<(RigidObject, Isometry)> = scene
            .objects
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != target)
            .map(|(_, o)| (o.object, o.pose))
            .collect();
        let plan = plan_operator_grasp(&hand, &object, &pose, scenario.grasp, &obstacles)?;
        let params = DfsParams {
            // Fingertip pads are soft: they resist spin about the normal (Table 1, soft finger).
            contact_model: ContactModel::SoftFinger,
            friction,
            table_height: Some(table_height),
            // A grasp that wraps the hand around the object holds it with the palm and the
            // phalanges too: whole-hand contact is the plan's, not a default of the physics
            // (fingertip sessions stay as they were, bit for bit, and their ticks as cheap).
            whole_hand: plan.wrap.is_some(),
            ..DfsParams::default()
        };
        let approach = approach_pose(&plan.base, &object.shape);
        let start_base = match reach_rng.as_mut() {
            Some(rng) => draw_home(
                rng,
                &hand,
                &plan.q_open[..hand.dof()],
                &approach,
                &pose.translation.vector,
                &scene.dfs_objects(),
                table_height,
            ),
            None => raise(&approach, 0.15),
        };
        let q0 = plan.q_open;
        let mut mount = [0; MAX_TIPS];
        for (k, m) in mount.iter_mut().enumerate().take(hand.fingertips.len()) {
            *m = mount_link(&hand, k);
        }
        let mut dfs = Dfs::with_objects(hand, &scene.dfs_objects(), params)?;
        let n = dfs.hand().dof();
        let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
        let mut tremor_freq = [0.0; MAX_DOF + 3];
        let mut tremor_phase = [0.0; MAX_DOF + 3];
        for i in 0..MAX_DOF + 3 {
            tremor_freq[i] = 8.0 + 4.0 * rand::Rng::random::<Real>(&mut rng);
            tremor_phase[i] = std::f64::consts::TAU * rand::Rng::random::<Real>(&mut rng);
        }
        let zeros = [0.0; MAX_DOF];
        dfs.step(&GloveSample {
            q: &q0[..n],
            tau: &zeros[..n],
            base: start_base,
        })?;
        for (i, o) in scene.objects.iter().enumerate() {
            dfs.set_object_state_at(i, ObjectState::at_rest(o.pose))?;
        }
        let operator_mu = scenario.operator_mu.unwrap_or(friction.mu).max(1e-3);
        let mut sim = Simulation {
            dfs,
            scene,
            target,
            params: OperatorParams::default(),
            style: scenario.grasp,
            spans,
            span: 0,
            step: 0,
            n_steps,
            table_height,
            operator_mu,
            plan,
            object_held: false,
            from_base: start_base,
            to_base: start_base,
            from_q: q0,
            to_q: q0,
            from_grip: 0.0,
            to_grip: 0.0,
            from_offset: 0.03,
            to_offset: 0.03,
            offset: 0.03,
            seen_object: pose,
            hold_in_mount: [None; MAX_TIPS],
            resting: [false; MAX_TIPS],
            mount,
            base: start_base,
            base_acceleration: Vector::zeros(),
            q_intent: q0,
            grip: 0.0,
            carry: 0.0,
            grip_boost: 0.0,
            q_meas: q0,
            tau_meas: [0.0; MAX_DOF],
            tau: [0.0; MAX_DOF],
            rng,
            tremor_freq,
            tremor_phase,
            reaches,
            reach_rng,
            reach_path: None,
            reach_shaping: 1.0,
            wrap_close: 0.0,
            wrap_set: None,
        };
        sim.begin_phase()?;
        Ok(sim)
    }

    /// The phases of the script with their time spans: the ground truth of the session.
    pub fn phases(&self) -> &[PhaseSpan] {
        &self.spans
    }

    /// The DFS (hand, objects, last tick's output and kinematics).
    pub fn dfs(&self) -> &Dfs {
        &self.dfs
    }

    /// The scene: the objects with their names and start poses, and the one the script grasps.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Index of the object the script grasps (in the scene and the DFS).
    pub fn target(&self) -> usize {
        self.target
    }

    /// The object the script grasps.
    fn target_object(&self) -> &RigidObject {
        &self.dfs.objects()[self.target].object
    }

    /// The state of the object the script grasps.
    pub fn target_state(&self) -> &ObjectState {
        &self.dfs.objects()[self.target].state
    }

    /// Fingertip `k`'s contact frame on the object the script grasps, if it touches that one.
    fn target_frame(&self, k: usize) -> Option<crate::contact::ContactFrame> {
        let tip = &self.dfs.output().tips[k];
        tip.frame.filter(|_| tip.object == self.target)
    }

    /// Time of the last tick (ns since the start).
    pub fn time_ns(&self) -> u64 {
        self.step.saturating_sub(1) * TICK_NS
    }

    /// Number of ticks done.
    pub fn ticks(&self) -> u64 {
        self.step
    }

    /// Total number of ticks.
    pub fn total_ticks(&self) -> u64 {
        self.n_steps
    }

    /// The phase of the last tick.
    pub fn phase(&self) -> Phase {
        self.spans[self.span.min(self.spans.len() - 1)].phase
    }

    /// The glove sample of the last tick: measured angles, measured operator torques, and the
    /// hand base pose.
    pub fn sample(&self) -> (&[Real], &[Real], &Isometry) {
        let n = self.dfs.hand().dof();
        (&self.q_meas[..n], &self.tau_meas[..n], &self.base)
    }

    /// The operator's intended joint angles at the last tick.
    pub fn intention(&self) -> &[Real] {
        &self.q_intent[..self.dfs.hand().dof()]
    }

    /// The last tick's DFS output.
    pub fn output(&self) -> &TickOutput {
        self.dfs.output()
    }

    /// The table's height (m, world z).
    pub fn table_height(&self) -> Real {
        self.table_height
    }

    /// The grasp style in use.
    pub fn style(&self) -> GraspStyle {
        self.plan.style.max_style(self.style)
    }

    /// Runs one tick. Returns `Ok(false)` when the script is over.
    ///
    /// A tick is a few µs of CPU, but the one that begins an `approach` task plans the grasp
    /// ([`plan_grasp`]: 15-30 ms with glove10); a script has at most
    /// [`MAX_TASKS`](crate::scenario::MAX_TASKS) tasks. Whoever drives the loop looks at its
    /// [`Stop`](crate::Stop) between steps.
    pub fn step(&mut self) -> Result<bool> {
        if self.step >= self.n_steps {
            return Ok(false);
        }
        let t = self.step * TICK_NS;
        while self.span + 1 < self.spans.len() && t >= self.spans[self.span].end_ns {
            self.end_phase();
            self.span += 1;
            self.begin_phase()?;
        }
        self.update_intention(t);
        self.compute_torques();
        self.measure();
        let n = self.dfs.hand().dof();
        let (q, tau) = (self.q_meas, self.tau_meas);
        self.dfs.step(&GloveSample {
            q: &q[..n],
            tau: &tau[..n],
            base: self.base,
        })?;
        self.step += 1;
        Ok(true)
    }

    fn span_now(&self) -> &PhaseSpan {
        &self.spans[self.span]
    }

    fn end_phase(&mut self) {
        if self.span_now().phase == Phase::Grasp {
            self.object_held = true;
            if self.plan.wrap.is_some() {
                self.wrap_set = Some(self.dfs.output().motor_q);
            }
        }
        if self.span_now().phase == Phase::Release {
            self.object_held = false;
            self.wrap_set = None;
        }
    }

    /// Sets the targets of the phase that starts now, from where the hand and object are.
    fn begin_phase(&mut self) -> Result<()> {
        let task = self.span_now().task;
        self.from_base = self.to_base;
        self.from_q = self.to_q;
        self.from_grip = self.to_grip;
        self.from_offset = self.to_offset;
        self.seen_object = self.target_state().pose;
        self.reach_path = None;
        let n = self.dfs.hand().dof();
        match task.phase {
            Phase::Approach => {
                let pose = self.target_state().pose;
                let obstacles: Vec<(RigidObject, Isometry)> = self
                    .dfs
                    .objects()
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| *i != self.target)
                    .map(|(_, o)| (o.object, o.state.pose))
                    .collect();
                self.plan = plan_operator_grasp(
                    self.dfs.hand(),
                    self.target_object(),
                    &pose,
                    self.style,
                    &obstacles,
                )?;
                self.resting = resting_tips(
                    &self.plan,
                    self.dfs.hand(),
                    self.operator_mu,
                    self.params.grip_safety,
                );
                self.to_base = approach_pose(&self.plan.base, &self.target_object().shape);
                self.to_q = self.plan.q_open;
                self.to_grip = 0.0;
                self.to_offset = 0.03;
                self.object_held = false;
                if let Some(reach) = self.reaches.get(self.span).copied().flatten() {
                    self.reach_path = Some(self.bend_reach(reach));
                }
            }
            Phase::Preshape => {
                // A wrap slides the open hand down beside the object and onto it: the palm
                // touches as the preshape ends, and the grasp only closes the fingers.
                self.to_base = self.plan.wrap.map_or(self.plan.base, |w| w.base);
                self.to_q = self.plan.q_pre;
                self.to_offset = 0.015;
            }
            Phase::Grasp => {
                let mut q = self.plan.q_grasp;
                for d in 0..n {
                    let delta = self.plan.q_grasp[d] - self.plan.q_pre[d];
                    let hand = self.dfs.hand();
                    q[d] = (q[d] + self.params.close_overshoot * delta)
                        .clamp(hand.dof_lower[d], hand.dof_upper[d]);
                }
                self.to_q = q;
                self.to_grip = 1.0;
                // Aim a little inside the surface, as a person presses on what they hold.
                self.to_offset = -0.002;
            }
            Phase::Lift => {
                self.to_base = raise(&self.from_base, task.height);
            }
            Phase::Hold => {}
            Phase::Transport => {
                let centre = self.target_state().pose.translation.vector;
                let turn = Rotation::from_euler_angles(0.0, 0.0, task.turn);
                let b = self.from_base;
                let p = centre + turn * (b.translation.vector - centre) + Vector::from(task.offset);
                self.to_base = Isometry::from_parts(p.into(), turn * b.rotation);
            }
            Phase::Place => {
                let obj = self.target_state().pose;
                let depth = self.target_object().shape.support_depth(&obj.rotation);
                let dz = self.table_height + depth - obj.translation.z - 0.002;
                self.to_base = raise(&self.from_base, dz);
            }
            Phase::Release => {
                self.to_q = self.plan.q_pre;
                self.to_grip = 0.0;
                self.to_offset = 0.015;
                // Let go from where each fingertip holds the object, not from where the plan
                // put it: an object that turned or slid in the hand (set down on a tilted
                // edge, say) would otherwise be dragged back by fingertips steering to their
                // planned spots as they open.
                let out = self.dfs.output();
                for k in 0..out.n_tips.min(MAX_TIPS) {
                    if let (true, Some(frame)) = (self.plan.tips[k], self.target_frame(k)) {
                        let n_out = -frame.normal_b();
                        let r = self.dfs.hand().fingertips[k].radius;
                        self.plan.contacts_b[k] = frame.p_b + n_out * r;
                        self.plan.normals_b[k] = n_out;
                    }
                }
            }
            Phase::Retreat => {
                self.to_base = match self.plan.wrap {
                    // The open hand backs off the object and slides up off it, the way it came.
                    Some(wrap) => {
                        let rise = self.target_object().shape.bounding_radius() + 0.06;
                        let mut x = raise(&self.from_base, rise);
                        x.translation.vector += wrap.out * (2.0 * power::WRAP_STANDOFF);
                        x
                    }
                    None => raise(&self.from_base, 0.10),
                };
                self.to_q = self.plan.q_open;
                self.to_grip = 0.0;
                self.to_offset = 0.03;
            }
        }
        Ok(())
    }

    /// The path of a varied approach from `from_base` to `to_base`: its first bend, or
    /// smaller ones drawn from the reach stream, the first that keeps clear of the table and
    /// the objects ([`ReachCheck::is_clear`]), else the straight line.
    fn bend_reach(&mut self, reach: Reach) -> ReachPath {
        let n = self.dfs.hand().dof();
        let check = ReachCheck {
            hand: self.dfs.hand(),
            q_from: &self.from_q[..n],
            q_to: &self.to_q[..n],
            from: &self.from_base,
            to: &self.to_base,
            objects: self.dfs.objects(),
            table_height: self.table_height,
        };
        let dp = self.to_base.translation.vector - self.from_base.translation.vector;
        let mut kin = Kinematics::default();
        let (mut fraction, mut angle) = (reach.bend, reach.bend_angle);
        for attempt in 1..=BEND_TRIES {
            let bend = bend_vector(&dp, fraction, angle);
            if check.is_clear(&bend, &mut kin) {
                return ReachPath { reach, bend };
            }
            let Some(rng) = self.reach_rng.as_mut() else {
                break;
            };
            let shrink = 1.0 - attempt as Real / BEND_TRIES as Real;
            fraction = rng.random_range(0.0..=REACH_BEND) * shrink;
            angle = rng.random_range(0.0..=std::f64::consts::PI);
        }
        ReachPath {
            reach,
            bend: Vector::zeros(),
        }
    }

    fn update_intention(&mut self, t: u64) {
        let span = *self.span_now();
        let dur = (span.end_ns - span.start_ns) as Real * 1e-9;
        let s = ((t - span.start_ns) as Real * 1e-9 / dur).clamp(0.0, 1.0);
        let (m, m2) = min_jerk(s);
        // Fingers and grip: in `grasp` the fingers close first and the grip ramps up after; in
        // `release` the grip ramps down first and the fingers open after.
        let (sq, sg) = match span.phase {
            Phase::Grasp => ((s / 0.6).min(1.0), ((s - 0.5) / 0.5).max(0.0)),
            Phase::Release => (((s - 0.4) / 0.6).max(0.0), (s / 0.4).min(1.0)),
            _ => (s, s),
        };
        let (mut mq, _) = min_jerk(sq);
        let (mg, _) = min_jerk(sg);
        // A wrap: the fingers close from 20 % to 50 % of `grasp`, and in `release` open after
        // the grip has gone (40 % on).
        self.wrap_close = match span.phase {
            Phase::Grasp => min_jerk((s - 0.2) / 0.3).0,
            Phase::Lift | Phase::Hold | Phase::Transport | Phase::Place => 1.0,
            Phase::Release => 1.0 - min_jerk((s - 0.4) / 0.6).0,
            _ => 0.0,
        };
        let dp = self.to_base.translation.vector - self.from_base.translation.vector;
        let (p, r, acceleration) = match &self.reach_path {
            None => (
                self.from_base.translation.vector + dp * m,
                self.from_base.rotation.slerp(&self.to_base.rotation, m),
                dp * (m2 / (dur * dur)),
            ),
            // A varied approach: along its bent path, pausing if it does; the fingers follow
            // the same progress.
            Some(path) => {
                let (u, du, ddu) = path.reach.progress((t - span.start_ns) as Real * 1e-9);
                let (sin, cos) = (std::f64::consts::PI * u).sin_cos();
                let pi = std::f64::consts::PI;
                mq = u;
                self.reach_shaping =
                    crate::min_jerk::progress((u - REACH_SHAPE_FROM) / (1.0 - REACH_SHAPE_FROM));
                (
                    reach_point(&self.from_base.translation.vector, &dp, &path.bend, u),
                    self.from_base.rotation.slerp(&self.to_base.rotation, u),
                    (dp + path.bend * (pi * cos)) * ddu - path.bend * (pi * pi * sin * du * du),
                )
            }
        };
        let time = t as Real * 1e-9;
        let mut tremor = Vector::zeros();
        for (k, c) in tremor.iter_mut().enumerate() {
            let i = MAX_DOF + k;
            *c = self.params.tremor_arm
                * (std::f64::consts::TAU * self.tremor_freq[i] * time + self.tremor_phase[i]).sin();
        }
        let new_base = Isometry::from_parts((p + tremor).into(), r);
        self.base_acceleration = acceleration;
        self.base = new_base;
        let n = self.dfs.hand().dof();
        for d in 0..n {
            let tr = self.params.tremor_joint
                * (std::f64::consts::TAU * self.tremor_freq[d] * time + self.tremor_phase[d]).sin();
            self.q_intent[d] = self.from_q[d] + (self.to_q[d] - self.from_q[d]) * mq + tr;
        }
        self.grip = self.from_grip + (self.to_grip - self.from_grip) * mg;
        // The load force: the fingertips take over the object's weight from the table early in
        // the lift (the loading phase, before the object moves: Johansson & Westling 1984) and
        // hand it back late in the place.
        self.carry = match span.phase {
            Phase::Lift => min_jerk(s / 0.3).0,
            Phase::Hold | Phase::Transport => 1.0,
            Phase::Place => 1.0 - min_jerk((s - 0.6) / 0.4).0,
            _ => 0.0,
        };
        // The grip peaks as the load comes on at lift-off and relaxes to its static level by
        // the end of the lift.
        self.grip_boost = match span.phase {
            Phase::Lift => {
                self.params.lift_grip_peak
                    * min_jerk(s / 0.3).0
                    * (1.0 - min_jerk((s - 0.3) / 0.7).0)
            }
            _ => 0.0,
        };
        self.offset = self.from_offset + (self.to_offset - self.from_offset) * mq;
    }

    /// The operator's joint torques `Jᵀ f` for the fingertips of the grasp, and an impedance
    /// around the intended angles for the other joints (wrist, unused fingers).
    ///
    /// Reaching and closing, a fingertip of the grasp is steered towards its spot on the object
    /// (in the object's frame, so it follows the object), `offset` out along the surface normal,
    /// with the soft [`OperatorParams::fingertip_stiffness`], like a person reaching for a spot
    /// they see; closing makes the offset zero, approaching every face head-on.
    ///
    /// Once it touches while holding, the operator keeps the fingertip where it met the object,
    /// relative to the palm (the link the finger is mounted on): a stiff, damped impedance ([`OperatorParams::hold_stiffness`],
    /// [`OperatorParams::hold_damping`]) about that spot pushed into the object by the pad's
    /// expected compression `N / k_s` (the DFS's surface stiffness), plus the squeeze `N` along
    /// the normal ([`Simulation::grip_forces`]). The set-points, fixed in the hand, fix the
    /// object's place in the hand: between opposing fingertips both springs hold it, and a
    /// squeeze that changes equally on both sides does not move it. Set-points relative to the
    /// palm rather than the forearm keep the fingers' impedance out of a loop through the
    /// wrist (fingertip forces turn the palm, which would move a forearm-fixed set-point).
    fn compute_torques(&mut self) {
        if let Some(wrap) = self.plan.wrap {
            self.compute_wrap_torques(&wrap);
            return;
        }
        let (mags, units, lift) = self.grip_forces();
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let kin = self.dfs.kinematics();
        let q = &out.motor_q;
        let qd = &out.motor_qd;
        let obj_pose = if self.object_held {
            self.target_state().pose
        } else {
            self.seen_object
        };
        let obj_rot = self.target_state().pose.rotation;
        let k_s = self.dfs.params().surface_stiffness;
        let holding = matches!(
            self.phase(),
            Phase::Grasp | Phase::Lift | Phase::Hold | Phase::Transport | Phase::Place
        );
        // The operator fixes the fingertips' places only once every fingertip of the grasp is
        // on the object; until then each closes softly on its spot, so the first to touch does
        // not shove the object away from the others.
        let all_touch = (0..out.n_tips.min(MAX_TIPS))
            .filter(|&k| self.plan.tips[k] && !self.resting[k])
            .all(|k| self.target_frame(k).is_some());
        let mut in_grasp = [false; MAX_DOF];
        let mut tau = [0.0; MAX_DOF];
        for g in &hand.finger_groups {
            if !g.tips.iter().any(|&k| self.plan.tips[k]) {
                continue;
            }
            for &d in &g.dofs {
                in_grasp[d] = true;
            }
        }
        for g in &hand.finger_groups {
            for &k in g.tips.iter().filter(|&&k| self.plan.tips[k]) {
                let tip = &out.tips[k];
                let x = kin.tip_centres[k];
                let mount = kin.link_poses[self.mount[k]];
                if !holding {
                    self.hold_in_mount[k] = None;
                } else if let (true, None, Some(frame)) =
                    (all_touch, self.hold_in_mount[k], self.target_frame(k))
                {
                    // Where the fingertip met the object, with the pad just on the surface, and
                    // the inward normal there, both relative to the palm.
                    let n_in = obj_rot * frame.normal_b();
                    let spot = x - n_in * tip.penetration;
                    let inv = mount.inverse();
                    self.hold_in_mount[k] = Some(((inv * spot).coords, inv.rotation * n_in));
                }
                let j = &kin.tip_jacobians[k];
                let mut f = match self.hold_in_mount[k] {
                    Some((spot, n_in)) => {
                        let target =
                            mount * Point::from(spot) + (mount.rotation * n_in) * (mags[k] / k_s);
                        let mut v = Vector::zeros();
                        for &d in &g.dofs {
                            v += Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]) * qd[d];
                        }
                        (target - x) * self.params.hold_stiffness - v * self.params.hold_damping
                    }
                    None => {
                        let target = obj_pose
                            * Point::from(
                                self.plan.contacts_b[k] + self.plan.normals_b[k] * self.offset,
                            );
                        let mut err = target - x;
                        let e = err.norm();
                        if e > 0.03 {
                            err *= 0.03 / e;
                        }
                        err * self.params.fingertip_stiffness
                    }
                };
                f += units[k] * mags[k];
                f += lift[k];
                for &d in &g.dofs {
                    tau[d] += j[(0, d)] * f.x + j[(1, d)] * f.y + j[(2, d)] * f.z;
                }
            }
            // A finger with more joints than its fingertip needs (the index: three joints in
            // its flexion plane) keeps its intended posture in the null space of the fingertip
            // task, so it neither drifts towards a stretched, singular posture nor moves the
            // fingertip: τ₀ − Jᵀ (J Jᵀ + λ²I)⁻¹ J τ₀ for the posture impedance τ₀.
            let mut planned = g.tips.iter().filter(|&&k| self.plan.tips[k]);
            if let (Some(&k), None) = (planned.next(), planned.next()) {
                let j = &kin.tip_jacobians[k];
                let mut t0 = [0.0; MAX_DOF];
                let mut jt0 = Vector::zeros();
                let mut jjt = nalgebra::Matrix3::<Real>::identity() * 1e-6;
                for &d in &g.dofs {
                    let kp = self.params.stiffness * hand.torque_limit[d];
                    t0[d] = kp * (self.q_intent[d] - q[d]) - self.params.posture_damping * qd[d];
                    let c = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
                    jt0 += c * t0[d];
                    jjt += c * c.transpose();
                }
                if let Some(y) = jjt.cholesky().map(|ch| ch.solve(&jt0)) {
                    for &d in &g.dofs {
                        let c = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
                        tau[d] += t0[d] - c.dot(&y);
                    }
                }
            }
        }
        for d in 0..n {
            let kp = self.params.stiffness * hand.torque_limit[d];
            let kd = if hand.dof_names[d].starts_with("wrist") {
                self.params.wrist_damping
            } else {
                0.0
            };
            let posture = kp * (self.q_intent[d] - q[d]) - kd * qd[d];
            if !in_grasp[d] {
                tau[d] += posture;
            } else if self.reach_path.is_some() {
                // A varied reach keeps the open hand's posture until it nears the object.
                let w = self.reach_shaping;
                tau[d] = w * tau[d] + (1.0 - w) * posture;
            }
        }
        for d in 0..n {
            let lim = 1.9 * hand.torque_limit[d];
            self.tau[d] = tau[d].clamp(-lim, lim);
        }
    }

    /// The operator's joint torques in a wrap ([`power`]): the power grip's law
    /// ([`PowerGrip::torques`]) about the intended angles, the fingers going over from their
    /// posture impedance to closing by torque as [`wrap_close`](Self::wrap_close) rises. The
    /// closing torques are scaled to the squeeze friction needs for the load the operator
    /// expects (weight plus the arm's planned acceleration) with its safety margin, for the
    /// friction it expects, through the whole hand's contacts
    /// ([`power::WRAP_NORMAL_PER_GRIP`]): `grip` ramps from the closing level
    /// ([`power::WRAP_CLOSE`]) to that squeeze, with the lift-off peak
    /// ([`OperatorParams::lift_grip_peak`]).
    fn compute_wrap_torques(&mut self, wrap: &Wrap) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let p = &self.params;
        let mut grip = PowerGrip::closing(hand, &[], &self.q_intent[..n]);
        let w = self.wrap_close;
        for d in 0..n {
            let lim = hand.torque_limit[d];
            grip.limit[d] = 1.9 * lim;
            if wrap.closes[d] {
                grip.close[d] = power::WRAP_CLOSE * lim;
                // Going over from the posture impedance to where the fingers came to rest on
                // the object (once they have: the fixture's grip), one set-point between them.
                let open = (1.0 - w) * p.stiffness * lim;
                let (held, set) = match self.wrap_set {
                    Some(set) => (w * power::WRAP_KP_PER_LIMIT * lim, set[d]),
                    None => (0.0, 0.0),
                };
                grip.kp[d] = open + held;
                if grip.kp[d] > 0.0 {
                    grip.set[d] = (open * self.q_intent[d] + held * set) / grip.kp[d];
                }
            }
        }
        let load = ((self.base_acceleration - self.dfs.params().gravity)
            * self.target_object().mass)
            .norm();
        let squeeze = (p.grip_safety * load / (self.operator_mu * power::WRAP_NORMAL_PER_GRIP))
            .clamp(power::WRAP_CLOSE, power::WRAP_MAX_GRIP)
            * (1.0 + self.grip_boost);
        let level = w + self.grip * (squeeze / power::WRAP_CLOSE - 1.0);
        let mut tau = [0.0; MAX_DOF];
        grip.torques(level, &out.motor_q[..n], &out.motor_qd[..n], &mut tau[..n]);
        self.tau[..n].copy_from_slice(&tau[..n]);
    }

    /// The squeeze: per fingertip of the grasp, the normal force `N_k` the operator presses
    /// with and the unit push `u_k` (world) that delivers it, `f_k = N_k u_k`. Zero until every
    /// fingertip of the grasp touches.
    ///
    /// The squeeze is what friction needs to carry the load the operator expects (weight plus
    /// the arm's planned acceleration, anticipated as people do: Johansson & Westling 1984)
    /// with its safety margin, for the friction it expects, and follows the grip ramp. It is not
    /// re-sized from what the fingertips feel (no slip reflex): a squeeze too weak for the real
    /// μ lets the object slip. `u_k` is the contact's inward normal projected onto the
    /// directions the fingertip can push (glove10's fingers and thumb push only in their
    /// flexion planes; eq. 14 transmits only forces in the range of Jᵀ), scaled to a unit
    /// normal component. The magnitudes are balanced so the squeezes nearly cancel: minimise
    /// ‖N − N₀‖² + w ‖Σ N_k u_k‖² (w = 4), i.e. N = (I + w AᵀA)⁻¹ N₀; for opposing fingertips
    /// the squeeze is equal and opposite.
    fn grip_forces(&self) -> ([Real; MAX_TIPS], [Vector; MAX_TIPS], [Vector; MAX_TIPS]) {
        let mut mags = [0.0; MAX_TIPS];
        let mut unit = [Vector::zeros(); MAX_TIPS];
        let mut lift = [Vector::zeros(); MAX_TIPS];
        if self.grip <= 0.0 {
            return (mags, unit, lift);
        }
        let out = self.dfs.output();
        let obj = self.target_object();
        let st = self.target_state();
        let g = self.dfs.params().gravity;
        let kin = self.dfs.kinematics();
        let hand = self.dfs.hand();
        let p = &self.params;
        let planned = (0..out.n_tips.min(MAX_TIPS))
            .filter(|&k| self.plan.tips[k] && !self.resting[k])
            .count();
        // Fixed-capacity lists: this runs every tick of a session.
        let mut touching = [0usize; MAX_TIPS];
        let mut nt = 0;
        let mut squeezing = 0;
        for k in 0..out.n_tips.min(MAX_TIPS) {
            if self.plan.tips[k] && self.target_frame(k).is_some() {
                touching[nt] = k;
                nt += 1;
                squeezing += usize::from(!self.resting[k]);
            }
        }
        let touching = &touching[..nt];
        // Squeeze only once every squeezing finger of the grasp is on the object.
        if squeezing == 0 || squeezing < planned {
            return (mags, unit, lift);
        }
        let load_force = (self.base_acceleration - g) * obj.mass;
        let load = load_force.norm();
        let normal = (p.grip_safety * load / (self.operator_mu * squeezing as Real))
            .max(p.min_normal)
            * self.grip
            * (1.0 + self.grip_boost);
        let mut ok = [false; MAX_TIPS];
        let mut range = [nalgebra::Matrix3::<Real>::zeros(); MAX_TIPS];
        let mut arm = [Vector::zeros(); MAX_TIPS];
        for &k in touching {
            let Some(frame) = self.target_frame(k) else {
                continue;
            };
            let n_in = st.pose.rotation * frame.normal_b();
            arm[k] = st.pose.rotation * frame.p_b;
            let (basis, nb) = push_basis(hand, kin, k);
            let mut dir = Vector::zeros();
            for b in basis.iter().take(nb) {
                dir += b * b.dot(&n_in);
                range[k] += b * b.transpose();
            }
            let along = dir.dot(&n_in);
            if along >= 0.2 {
                unit[k] = dir / along;
                ok[k] = true;
                // The load force is tangential: the squeeze alone sets the normal force.
                let d = dir.normalize();
                range[k] -= d * d.transpose();
            }
        }
        // The squeeze and the load are the squeezing fingertips'; a resting one only presses
        // lightly along its push.
        let mut ks = [0usize; MAX_TIPS];
        let mut m = 0;
        for &k in touching.iter().filter(|&&k| ok[k]) {
            if self.resting[k] {
                mags[k] = p.min_normal * self.grip;
            } else {
                ks[m] = k;
                m += 1;
            }
        }
        let mut sys = nalgebra::SMatrix::<Real, MAX_TIPS, MAX_TIPS>::identity();
        let wanted = [normal; MAX_TIPS];
        let mut solved = wanted;
        for a in 0..m {
            for b in 0..m {
                sys[(a, b)] += 4.0 * unit[ks[a]].dot(&unit[ks[b]]);
            }
        }
        if !crate::math::cholesky_solve_in_place(&mut sys, m, &mut solved) {
            solved = wanted;
        }
        for (idx, &k) in ks.iter().enumerate().take(m) {
            mags[k] = solved[idx].max(p.min_normal * self.grip);
        }
        for k in 0..MAX_TIPS {
            if !ok[k] {
                unit[k] = Vector::zeros();
            }
        }
        if self.carry > 0.0 && m > 0 {
            self.distribute_load(&ks[..m], &range, &arm, &mags, &unit, load_force, &mut lift);
        }
        (mags, unit, lift)
    }

    /// The load force (Johansson & Westling's "load force", beside the grip force): how the
    /// fingertips `ks` share lifting the object. Each fingertip pushes `l_k` within the
    /// directions it can push, across its push along the normal (`range[k]`, a projection: the
    /// squeeze alone sets the normal force); together with the squeeze
    /// `N_k u_k` they apply the wrench the expected motion needs, `Σ (l_k + N_k u_k) =
    /// carry · m (a − g)` and no moment about the centre of mass (`arm[k]`: contact point from
    /// the centre, world), so the stick springs are left with nothing to carry and the object
    /// does not turn in the hand when the fingertips do not sit exactly opposite. Nearest to an
    /// equal share: `l = l₀ + Aᵀ (A Aᵀ + εI)⁻¹ (b − A l₀)`, moments scaled by 1/(3 cm); the
    /// small ε leaves out what the fingertips cannot do (a moment about the line through two
    /// contacts).
    #[allow(clippy::too_many_arguments)]
    fn distribute_load(
        &self,
        ks: &[usize],
        range: &[nalgebra::Matrix3<Real>; MAX_TIPS],
        arm: &[Vector; MAX_TIPS],
        mags: &[Real; MAX_TIPS],
        unit: &[Vector; MAX_TIPS],
        load_force: Vector,
        lift: &mut [Vector; MAX_TIPS],
    ) {
        const SCALE: Real = 1.0 / 0.03;
        let want = load_force * self.carry;
        let mut squeeze_force = Vector::zeros();
        let mut squeeze_moment = Vector::zeros();
        for &k in ks {
            let f = unit[k] * mags[k];
            squeeze_force += f;
            squeeze_moment += arm[k].cross(&f);
        }
        // Per fingertip, the 6x3 block A_k = [P_k; [r_k]x P_k / L].
        let mut blocks = [nalgebra::SMatrix::<Real, 6, 3>::zeros(); MAX_TIPS];
        let mut aat = nalgebra::Matrix6::<Real>::zeros();
        let mut resid = nalgebra::Vector6::<Real>::zeros();
        let share = want / ks.len() as Real;
        let mut b = nalgebra::Vector6::<Real>::zeros();
        b.fixed_rows_mut::<3>(0).copy_from(&(want - squeeze_force));
        b.fixed_rows_mut::<3>(3)
            .copy_from(&(-squeeze_moment * SCALE));
        resid += b;
        for &k in ks {
            let p = range[k];
            let mut a = nalgebra::SMatrix::<Real, 6, 3>::zeros();
            a.fixed_view_mut::<3, 3>(0, 0).copy_from(&p);
            a.fixed_view_mut::<3, 3>(3, 0)
                .copy_from(&(arm[k].cross_matrix() * p * SCALE));
            lift[k] = p * share;
            resid -= a * share;
            aat += a * a.transpose();
            blocks[k] = a;
        }
        let eps = 1e-3 * aat.trace().max(1e-12);
        for i in 0..6 {
            aat[(i, i)] += eps;
        }
        if let Some(chol) = aat.cholesky() {
            let y = chol.solve(&resid);
            for &k in ks {
                lift[k] += blocks[k].transpose() * y;
            }
        }
    }

    fn measure(&mut self) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let na = Normal::new(0.0, self.params.noise_angle.max(0.0)).expect("finite σ");
        let nt = Normal::new(0.0, self.params.noise_torque.max(0.0)).expect("finite σ");
        for d in 0..n {
            let q = out.motor_q[d] + na.sample(&mut self.rng);
            self.q_meas[d] = q.clamp(hand.dof_lower[d] - 0.01, hand.dof_upper[d] + 0.01);
            self.tau_meas[d] = self.tau[d] + nt.sample(&mut self.rng);
        }
    }
}

impl GraspStyle {
    fn max_style(self, requested: GraspStyle) -> GraspStyle {
        if self == GraspStyle::Auto {
            requested
        } else {
            self
        }
    }
}

/// The fingertips of `plan` that rest on the object instead of squeezing it: those beside the
/// squeezing pair (thumb and index) that cannot push within the friction cone the operator
/// expects with its safety margin even before any load, i.e. whose push direction nearest the
/// contact normal ([`GraspPlan::normal_alignment`], cos θ) leans off it by tan θ > μ / safety.
/// Pressing harder with such a finger only makes it slide on the surface (a finger whose
/// flexion plane passes beside a cylinder's axis meets a surface turned away from the plane);
/// it closes until it touches and presses with the least force.
fn resting_tips(plan: &GraspPlan, hand: &HandModel, mu: Real, safety: Real) -> [bool; MAX_TIPS] {
    let mut out = [false; MAX_TIPS];
    let pair = [tip_index(hand, "thumb"), tip_index(hand, "index")];
    for (k, rest) in out.iter_mut().enumerate().take(hand.fingertips.len()) {
        if !plan.tips[k] || pair.contains(&Some(k)) {
            continue;
        }
        let c = plan.normal_alignment[k].clamp(1e-6, 1.0);
        let tan = (1.0 - c * c).sqrt() / c;
        *rest = tan * safety > mu;
    }
    out
}

/// Where the hand waits before closing in: beside the grasp pose along the palm's y axis (the
/// fingertips close in the palm's x-z plane, so sliding along y brings them around the
/// object without touching it), by the object's size plus 5 cm, and 1 cm higher.
fn approach_pose(grasp_base: &Isometry, shape: &Shape) -> Isometry {
    let side = grasp_base.rotation * Vector::y() * (shape.bounding_radius() + 0.05);
    let mut x = *grasp_base;
    x.translation.vector += side + Vector::z() * 0.01;
    x
}

/// The pose raised by `dz` (m) along world z.
fn raise(x: &Isometry, dz: Real) -> Isometry {
    let mut y = *x;
    y.translation.vector.z += dz;
    y
}
