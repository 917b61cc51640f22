//! A replay driven by the operator's phases as they happen (issue 20, IP-flow 3): the
//! retargeted skill runs in a DFS of its own, its replay time given by a [`PhaseClock`] that
//! the on-line phase estimate drives, one 1 kHz tick at a time, with the robot's state at
//! every tick for streaming and recording.

use super::clock::PhaseClock;
use super::plan::{plan_with_stop, Plan};
use super::run::{Replay, ReplayTick, DT};
use super::{ReplayParams, ReplayReport, SkillSpec};
use crate::error::Result;
use crate::hand::{HandModel, MAX_TIPS};
use crate::math::{Isometry, Real};
use crate::scenario::Phase;
use crate::stop::Stop;

/// A [`Replay`] whose replay time comes from a [`PhaseClock`]: tell it the operator's phase
/// changes ([`DrivenReplay::set_phase`]) and [`tick`](DrivenReplay::tick) it at 1 kHz of real
/// time. A tick allocates nothing.
#[derive(Debug)]
pub struct DrivenReplay {
    replay: Replay,
    clock: PhaseClock,
    /// Per fingertip, the normal force of the last tick (N).
    normal_forces: [Real; MAX_TIPS],
    finished: bool,
}

/// The robot's state after a tick of a [`DrivenReplay`], borrowed, for streaming.
#[derive(Debug, Clone, Copy)]
pub struct DrivenTick<'a> {
    /// The replay's tick: joint angles, torques, base pose, the DFS output (the object's
    /// state, every contact) and kinematics, the object's reference pose. Its `time_ns` counts
    /// ticks since the driven replay started (real time).
    pub tick: ReplayTick<'a>,
    /// Real time of the tick on the clock's base (s), e.g. the live session's.
    pub now_s: Real,
    /// Replay time of the tick (s on the skill's timeline).
    pub replay_time_s: Real,
    /// Rate of the replay time relative to real time (1 in step with the operator, 0 waiting,
    /// up to [`super::MAX_CATCH_UP_RATE`] catching up).
    pub rate: Real,
    /// The skill's phase the replay is in.
    pub replay_phase: Phase,
    /// The operator's phase the replay follows.
    pub operator_phase: Phase,
    /// The object's pose in the world.
    pub object: &'a Isometry,
    /// Per fingertip of the hand, the normal force it transmits to the object (N; 0 when not
    /// in contact).
    pub tip_normal_forces: &'a [Real],
}

/// What starting a driven replay gives: the replay, or the report of a plan that is not
/// simulated ([`Plan::refusal`]: contacts the hand cannot reach, or that cannot carry the
/// object at rest).
#[derive(Debug)]
pub enum DrivenStart {
    /// Ready to run.
    Running(Box<DrivenReplay>),
    /// Refused before simulating, as [`super::run`] reports it.
    Refused(Box<ReplayReport>),
}

impl DrivenReplay {
    /// Plans `skill` on `hand` (fingertip `thumb` opposing the others) and sets up the DFS,
    /// the clock's real time starting at 0. Simulates even a plan [`super::run`] would refuse
    /// (see [`DrivenReplay::start`]). Errors are for invalid input only.
    pub fn new(
        hand: &HandModel,
        thumb: usize,
        skill: &SkillSpec,
        params: &ReplayParams,
    ) -> Result<DrivenReplay> {
        Ok(DrivenReplay::from_replay(
            Replay::new(hand, thumb, skill, params)?,
            0.0,
        ))
    }

    /// Plans `skill` on `hand` (planning ends early with [`crate::DfsError::Cancelled`] once
    /// `stop` is set) and, unless the plan is refused as [`super::run`] refuses it, sets up a
    /// driven replay whose clock's real time starts at `start_s`.
    pub fn start(
        hand: &HandModel,
        thumb: usize,
        skill: &SkillSpec,
        params: &ReplayParams,
        start_s: Real,
        stop: &Stop,
    ) -> Result<DrivenStart> {
        let plan = plan_with_stop(hand, thumb, skill, params, stop)?;
        if let Some(report) = plan.refusal() {
            return Ok(DrivenStart::Refused(Box::new(report)));
        }
        let replay = DrivenReplay::from_plan(plan, skill, params, start_s)?;
        Ok(DrivenStart::Running(Box::new(replay)))
    }

    /// A driven replay of a plan, the clock's real time starting at `start_s`.
    pub fn from_plan(
        plan: Plan,
        skill: &SkillSpec,
        params: &ReplayParams,
        start_s: Real,
    ) -> Result<DrivenReplay> {
        Ok(DrivenReplay::from_replay(
            Replay::from_plan(plan, skill, params)?,
            start_s,
        ))
    }

    /// Drives `replay` (not yet stepped) by a clock of its skill, its real time starting at
    /// `start_s`.
    pub fn from_replay(replay: Replay, start_s: Real) -> DrivenReplay {
        let clock = PhaseClock::starting_at(replay.skill(), start_s);
        DrivenReplay {
            replay,
            clock,
            normal_forces: [0.0; MAX_TIPS],
            finished: false,
        }
    }

    /// The operator entered `phase` at `now_s` (real time on the clock's base): see
    /// [`PhaseClock::set_phase`]. `true` when the replay follows it, `false` when it is ignored.
    pub fn set_phase(&mut self, phase: Phase, now_s: Real) -> bool {
        self.clock.set_phase(phase, now_s)
    }

    /// Advances real time by one tick (1 ms) and runs the replay's tick at the clock's replay
    /// time; `Ok(false)`, running nothing, once the replay is over (the operator retreated
    /// and the retreat's span is done). While the operator stays in a phase past its span the
    /// replay goes on ticking at the span's end (the hand holds still, the DFS runs).
    pub fn tick(&mut self) -> Result<bool> {
        if self.finished {
            return Ok(false);
        }
        let t = self.clock.advance(DT);
        if !self.replay.step_to(t)? {
            self.finished = true;
            return Ok(false);
        }
        let out = self.replay.dfs().output();
        for (k, f) in self.normal_forces.iter_mut().enumerate() {
            let tip = &out.tips[k];
            *f = if k < out.n_tips && tip.in_contact {
                tip.transmitted[2].max(0.0)
            } else {
                0.0
            };
        }
        Ok(true)
    }

    /// The robot's state after the last tick.
    pub fn state(&self) -> DrivenTick<'_> {
        let tick = self.replay.tick();
        let out = tick.output;
        DrivenTick {
            tick,
            now_s: self.clock.now(),
            replay_time_s: self.clock.time(),
            rate: self.clock.rate(),
            replay_phase: self.clock.replay_phase(),
            operator_phase: self.clock.phase(),
            object: &out.object.pose,
            tip_normal_forces: &self.normal_forces[..out.n_tips.min(MAX_TIPS)],
        }
    }

    /// The report so far (the whole replay's once [`DrivenReplay::tick`] returned `false`):
    /// `ticks` and `duration_s` count real time.
    pub fn report(&self) -> ReplayReport {
        self.replay.report()
    }

    /// The replay is over.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// The clock.
    pub fn clock(&self) -> &PhaseClock {
        &self.clock
    }

    /// The replay (its plan, DFS, timeline).
    pub fn replay(&self) -> &Replay {
        &self.replay
    }
}
