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
//! [`Scenario`]: crate::scenario::Scenario
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
//!
//! # Files
//!
//! This file holds the operator's parameters, the loop's state and its tick; `setup.rs` sets
//! a scenario up, `phases.rs` sets each phase's targets, `intention.rs` moves the intention
//! along them, `torques.rs` turns it into the operator's joint torques and `grip.rs` sizes
//! the squeeze and the load the fingertips carry. The grasp plan is `plan.rs`, varied
//! reaches `reach.rs`, the wrap `power.rs`.

use crate::dfs::{Dfs, GloveSample, TickOutput};
use crate::error::Result;
use crate::hand::{MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Real, Vector};
use crate::object::{ObjectState, RigidObject};
use crate::scenario::{GraspStyle, Phase, PhaseSpan, ResolvedTask, Scene};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

pub mod power;

mod grip;
mod intention;
mod phases;
mod plan;
mod reach;
mod setup;
mod torques;
use phases::{approach_pose, raise};
pub use plan::{plan_grasp, plan_operator_grasp, with_free_base, GraspPlan};
pub(crate) use plan::{push_alignment, push_basis};
use reach::{Reach, ReachPath};
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

/// One phase of a session's script: its time span (ns since the session's start) and the
/// task the operator carries out in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScriptPhase {
    /// The phase and its time span (ns since the session's start, end exclusive), in whole
    /// ticks.
    pub span: PhaseSpan,
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
    spans: Vec<ScriptPhase>,
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
    /// Per fingertip: the link its finger is mounted on ([`mount_link`](plan::mount_link)).
    mount: [usize; MAX_TIPS],
    /// Per fingertip of the grasp: it rests on the object instead of squeezing it
    /// ([`resting_tips`](phases::resting_tips)).
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
    /// The phases of the script with their time spans and tasks: the ground truth of the
    /// session.
    pub fn phases(&self) -> &[ScriptPhase] {
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
        self.spans[self.span.min(self.spans.len() - 1)].span.phase
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
        while self.span + 1 < self.spans.len() && t >= self.spans[self.span].span.end_ns {
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

    fn span_now(&self) -> &ScriptPhase {
        &self.spans[self.span]
    }

    fn end_phase(&mut self) {
        if self.span_now().span.phase == Phase::Grasp {
            self.object_held = true;
            if self.plan.wrap.is_some() {
                self.wrap_set = Some(self.dfs.output().motor_q);
            }
        }
        if self.span_now().span.phase == Phase::Release {
            self.object_held = false;
            self.wrap_set = None;
        }
    }

    /// The glove's sensors: the motors' angles (the DFS's commands) and the operator's
    /// torques, each with its noise.
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
