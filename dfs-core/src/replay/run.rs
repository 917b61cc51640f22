//! The simulated replay: the hand's controller drives its joints by torques in the DFS at
//! 1 kHz (contacts, friction, object dynamics) through the skill's phases, and the report.

use super::plan::{actuation_map, plan_with_stop, Plan};
use super::{FailureReason, ReplayParams, ReplayQuality, ReplayReport, SkillSpec, Timeline};
use crate::contact::cone_usage;
use crate::dfs::{Dfs, DfsParams, GloveSample, TickOutput};
use crate::error::Result;
use crate::hand::{DofMatrix, HandModel, JointKind, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Vector};
use crate::min_jerk::progress as min_jerk;
use crate::object::{ObjectState, RigidObject};
use crate::stop::Stop;

/// Tick length (s): 1 kHz.
pub(super) const DT: Real = 1e-3;

/// One tick of a replay, for recording.
#[derive(Debug, Clone, Copy)]
pub struct ReplayTick<'a> {
    /// Tick time, ns since the replay's start.
    pub time_ns: u64,
    /// Joint angles θ fed to the DFS.
    pub q: &'a [Real],
    /// The controller's joint torques τ.
    pub tau: &'a [Real],
    /// Pose of the hand's base (the arm's flange) in the world.
    pub base: &'a Isometry,
    /// The DFS output of the tick.
    pub output: &'a TickOutput,
    /// The tick's whole-hand contacts ([`Dfs::body_contacts`]; empty without whole-hand
    /// contact).
    pub body: &'a [crate::dfs::BodyContact],
    /// The DFS kinematics of the tick.
    pub kinematics: &'a Kinematics,
    /// The object's reference pose at this tick.
    pub reference: &'a Isometry,
}

/// A replay in progress: the plan, the DFS and the controller's state.
#[derive(Debug)]
pub struct Replay {
    plan: Plan,
    skill: SkillSpec,
    params: ReplayParams,
    timeline: Timeline,
    dfs: Dfs,
    kp: [Real; MAX_DOF],
    kd: [Real; MAX_DOF],
    grasp_dof: [bool; MAX_DOF],
    tau: [Real; MAX_DOF],
    q: [Real; MAX_DOF],
    base: Isometry,
    pre_base: Isometry,
    start_z: Real,
    step: u64,
    n_steps: u64,
    stats: Stats,
    /// The object's reference pose at the current tick.
    reference: Isometry,
    /// Where the base is when the grasp releases.
    release_base: Isometry,
    /// For two fingertips driven by one DOF (a parallel gripper's jaws): the line between them
    /// at the grasp, as its direction and midpoint in the base frame.
    jaw_line: Option<(Vector, Point)>,
}

/// Running statistics for the report.
#[derive(Debug, Default, Clone, Copy)]
struct Stats {
    pos_max: Real,
    pos_sq: Real,
    rot_max: Real,
    rot_sq: Real,
    held_ticks: u64,
    slip_ticks: u64,
    max_slip: Real,
    min_margin: Option<Real>,
    peak_ratio: Real,
    peak_dof: usize,
    saturated_ticks: u64,
    lift: Real,
    anchors: [Option<Vector>; MAX_TIPS],
    lost_at: Option<Real>,
}

impl Replay {
    /// Plans `skill` on `hand` and sets up the DFS. Errors are for invalid input only.
    pub fn new(
        hand: &HandModel,
        thumb: usize,
        skill: &SkillSpec,
        params: &ReplayParams,
    ) -> Result<Replay> {
        Replay::new_with_stop(hand, thumb, skill, params, Stop::never())
    }

    /// [`Replay::new`], its planning ended early with [`crate::DfsError::Cancelled`] once
    /// `stop` is set ([`super::plan_with_stop`]). A caller stepping the replay looks at `stop`
    /// between [`Replay::step`]s itself, as [`run_with_stop`] does.
    pub fn new_with_stop(
        hand: &HandModel,
        thumb: usize,
        skill: &SkillSpec,
        params: &ReplayParams,
        stop: &Stop,
    ) -> Result<Replay> {
        let plan = plan_with_stop(hand, thumb, skill, params, stop)?;
        Replay::from_plan(plan, skill, params)
    }

    /// Sets up the DFS for a plan.
    pub fn from_plan(plan: Plan, skill: &SkillSpec, params: &ReplayParams) -> Result<Replay> {
        let object = RigidObject::new(skill.shape, skill.mass)?;
        let dfs_params = DfsParams {
            contact_model: skill.contact_model,
            friction: skill.friction,
            table_height: Some(0.0),
            // A power grasp holds the object with the palm and the phalanges too.
            whole_hand: plan.power.is_some(),
            ..DfsParams::default()
        };
        let start = skill.start_pose();
        let hand = plan.hand.clone();
        let n = hand.dof();
        let timeline = skill.timeline();
        let mut pre_base = plan.base_grasp;
        pre_base.translation.vector -= plan.approach_dir * super::power::APPROACH;
        let mut dfs = Dfs::new(hand, object, ObjectState::at_rest(start), dfs_params)?;
        let zeros = [0.0; MAX_DOF];
        dfs.step(&GloveSample {
            q: &plan.q_pre[..n],
            tau: &zeros[..n],
            base: pre_base,
        })?;
        dfs.set_object_state(ObjectState::at_rest(start));
        // Joint gains from the torque limits, kept stable at 1 kHz for the joint's inertia.
        let mut kin = Kinematics::default();
        let mut m = DofMatrix::identity();
        let hand = dfs.hand();
        hand.forward_kinematics(&pre_base, &plan.q_pre[..n], &mut kin);
        hand.mass_matrix(&mut kin, &mut m);
        let mut kp = [0.0; MAX_DOF];
        let mut kd = [0.0; MAX_DOF];
        for d in 0..n {
            let prismatic = hand.joints.iter().any(|j| {
                j.kind == JointKind::Prismatic && j.drive.dof_and_gain().map(|x| x.0) == Some(d)
            });
            let scale = if prismatic { 0.02 } else { 0.5 };
            let md = m[(d, d)].max(1e-9);
            kp[d] = (hand.torque_limit[d] / scale).min(0.3 * md / (DT * DT));
            kd[d] = (1.4 * (kp[d] * md).sqrt()).min(0.5 * md / DT);
        }
        let mut grasp_dof = [false; MAX_DOF];
        if let Some(power) = &plan.power {
            for d in 0..n {
                grasp_dof[d] = power.close[d] != 0.0;
            }
        }
        for g in &hand.finger_groups {
            if g.tips.iter().any(|&k| plan.active[k]) {
                for &d in &g.dofs {
                    grasp_dof[d] = true;
                }
            }
        }
        let n_steps = (timeline.end / DT).round() as u64;
        let pinch = match hand.finger_groups.as_slice() {
            [g] if g.tips.len() == 2 && hand.fingertips.len() == 2 && plan.power.is_none() => {
                Some((g.tips[0], g.tips[1]))
            }
            _ => None,
        };
        let jaw_line = pinch.map(|(a, b)| {
            let to_base = plan.base_in_b0.inverse();
            let centre = |k: usize| {
                let c = &plan.contacts[k];
                to_base * Point::from(c.p_b - c.normal_b() * hand.fingertips[k].radius)
            };
            let (pa, pb) = (centre(a), centre(b));
            (
                (pb - pa).normalize(),
                Point::from(0.5 * (pa.coords + pb.coords)),
            )
        });
        let mut q = [0.0; MAX_DOF];
        q[..n].copy_from_slice(&plan.q_pre[..n]);
        let mut replay = Replay {
            start_z: start.translation.z,
            plan,
            skill: skill.clone(),
            params: *params,
            timeline,
            dfs,
            kp,
            kd,
            grasp_dof,
            tau: [0.0; MAX_DOF],
            q,
            base: pre_base,
            pre_base,
            step: 0,
            n_steps,
            stats: Stats::default(),
            jaw_line,
            reference: start,
            release_base: Isometry::identity(),
        };
        let release = replay.timeline.release_start;
        replay.release_base = replay.follow(release);
        Ok(replay)
    }

    /// Ticks run so far.
    pub fn ticks_run(&self) -> u64 {
        self.step
    }

    /// The share of the held part of the replay from the end of `grasp` to `until` (s) for
    /// which the object stayed within the success bounds of its reference: 1 when it never
    /// left them (so far).
    pub(super) fn held_fraction(&self, until: Real) -> Real {
        let tl = &self.timeline;
        let span = (until - tl.grasp_end).max(1e-3);
        match self.stats.lost_at {
            None => 1.0,
            Some(t) => ((t - tl.grasp_end) / span).clamp(0.0, 1.0),
        }
    }

    /// The plan.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The DFS.
    pub fn dfs(&self) -> &Dfs {
        &self.dfs
    }

    /// Number of ticks of the whole replay.
    pub fn total_ticks(&self) -> u64 {
        self.n_steps
    }

    /// Where the base follows the object's reference at `t` (the jaws of a pinch kept level).
    fn follow(&self, t: Real) -> Isometry {
        let reference = self.skill.reference_in(&self.timeline, t);
        self.level_jaws(reference * self.plan.base_in_b0)
    }

    /// Where the base is at `t`, and the planned fingertip offset off the surface (m), grip
    /// (0..1) and whether the fingers are preshaped (joint control) at `t`.
    fn schedule(&self, t: Real) -> (Isometry, Real, Real, bool) {
        let tl = &self.timeline;
        let p = &self.params;
        if t < tl.grasp_start {
            let s = min_jerk(t / tl.grasp_start.max(1e-3));
            let a = self.pre_base;
            let b = self.plan.base_grasp;
            let pos = a.translation.vector.lerp(&b.translation.vector, s);
            return (
                Isometry::from_parts(pos.into(), b.rotation),
                p.preshape_clearance,
                0.0,
                true,
            );
        }
        if t < tl.grasp_end {
            let s = (t - tl.grasp_start) / (tl.grasp_end - tl.grasp_start).max(1e-3);
            let close = min_jerk(s / 0.6);
            let grip = min_jerk((s - 0.5) / 0.5);
            let offset = p.preshape_clearance + (-p.close_depth - p.preshape_clearance) * close;
            return (self.plan.base_grasp, offset, grip, false);
        }
        if t < tl.release_start {
            // The tick's reference is the skill's at `t`.
            let base = self.level_jaws(self.reference * self.plan.base_in_b0);
            return (base, -p.close_depth, 1.0, false);
        }
        let at_release = self.release_base;
        if t < tl.release_end {
            let s = (t - tl.release_start) / (tl.release_end - tl.release_start).max(1e-3);
            let grip = 1.0 - min_jerk(s / 0.4);
            let open = min_jerk((s - 0.4) / 0.6);
            let offset = -p.close_depth + (p.preshape_clearance + p.close_depth) * open;
            return (at_release, offset, grip, false);
        }
        let s = min_jerk((t - tl.release_end) / (tl.end - tl.release_end).max(1e-3));
        let mut b = at_release;
        b.translation.vector += (Vector::z() * 0.1 - self.plan.approach_dir * 0.05) * s;
        (b, p.preshape_clearance, 0.0, true)
    }

    /// The controller: joint torques for this tick from the last tick's state.
    fn control(&mut self, t: Real, offset: Real, grip: Real, preshaped: bool) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let kin = self.dfs.kinematics();
        let q = &out.motor_q;
        let qd = &out.motor_qd;
        let reference = self.reference;
        let obj = self.dfs.object_state().pose;
        let mut tau = [0.0; MAX_DOF];
        if let Some(power) = &self.plan.power {
            self.power_torques(power, t, q, qd, &mut tau);
            self.clamp_torques(t, &tau);
            return;
        }
        // Posture: joint-space impedance to the preshape or grasp angles; weak on the fingers
        // while they are steered in task space.
        for d in 0..n {
            let (target, w) = if preshaped {
                (self.plan.q_pre[d], 1.0)
            } else if self.grasp_dof[d] {
                (self.plan.q_grasp[d], 0.1)
            } else {
                (self.plan.q_grasp[d], 1.0)
            };
            tau[d] += w * (self.kp[d] * (target - q[d]) - self.kd[d] * qd[d]);
        }
        if !preshaped {
            let forces = self.plan.forces_at(t);
            for g in &hand.finger_groups {
                for &k in g.tips.iter().filter(|&&k| self.plan.active[k]) {
                    let tip = &hand.fingertips[k];
                    let c = &self.plan.contacts[k];
                    let j = &kin.tip_jacobians[k];
                    let touching = out.tips[k].frame.is_some();
                    let f = if touching && grip > 0.0 {
                        // The planned force, in B (the planned contact frame's axes: a contact
                        // frame's tangent axes can flip as the contact point moves).
                        // The normal force along the actual normal where it touches.
                        let ck = forces[k];
                        let tangential = c.rot_b * Vector::new(ck[0], ck[1], 0.0);
                        let normal = out.tips[k].frame.map_or(c.normal_b(), |f| f.normal_b());
                        let f_b = tangential + normal * ck[2].max(self.params.min_normal);
                        let f = obj.rotation * f_b * grip;
                        // What the finger can push; stick friction makes up the rest.
                        match actuation_map(j, &g.dofs, &(obj.rotation * normal)) {
                            Some(a) => a * f,
                            None => f,
                        }
                    } else {
                        // Steer the fingertip to its contact, `offset` out along the normal.
                        let p = c.p_b - c.normal_b() * (tip.radius + offset);
                        let target = reference * Point::from(p);
                        let mut err = target - kin.tip_centres[k];
                        let e = err.norm();
                        if e > 0.03 {
                            err *= 0.03 / e;
                        }
                        let mut v = Vector::zeros();
                        for d in 0..n {
                            v += Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]) * qd[d];
                        }
                        err * self.params.fingertip_stiffness - v * self.params.fingertip_damping
                    };
                    for &d in &g.dofs {
                        tau[d] += j[(0, d)] * f.x + j[(1, d)] * f.y + j[(2, d)] * f.z;
                    }
                }
            }
        }
        self.clamp_torques(t, &tau);
    }

    /// The torques of a power grasp ([`super::power`]): the fingers taking part close by
    /// torque alone, each flexing DOF pushing with the same fraction of its limit (up to
    /// [`crate::operator::power::WRAP_CLOSE`] over the first 30 % of `grasp` while they close,
    /// to the planned grip over its last 40 %, down over the first 40 % of `release`), then
    /// open back by joint impedance; every other DOF is held at its angle.
    fn power_torques(
        &self,
        power: &super::PowerPlan,
        t: Real,
        q: &[Real],
        qd: &[Real],
        tau: &mut [Real; MAX_DOF],
    ) {
        let tl = &self.timeline;
        let phase = |a: Real, b: Real| ((t - a) / (b - a).max(1e-3)).clamp(0.0, 1.0);
        let (level, open) = if t < tl.grasp_start {
            (0.0, 1.0)
        } else if t < tl.release_start {
            // Closing gently (as the operator's wrap does), then squeezing.
            let s = phase(tl.grasp_start, tl.grasp_end);
            let gentle = crate::operator::power::WRAP_CLOSE.min(power.grip);
            (
                gentle * min_jerk(s / 0.3) + (power.grip - gentle) * min_jerk((s - 0.6) / 0.4),
                0.0,
            )
        } else {
            let s = phase(tl.release_start, tl.release_end);
            (
                power.grip * (1.0 - min_jerk(s / 0.4)),
                min_jerk((s - 0.4) / 0.6),
            )
        };
        let hand = self.dfs.hand();
        for d in 0..hand.dof() {
            let damping = self.kd[d] * qd[d];
            tau[d] = if power.close[d] != 0.0 {
                power.close[d] * hand.torque_limit[d] * level
                    + open * self.kp[d] * (self.plan.q_pre[d] - q[d])
                    - damping
            } else {
                self.kp[d] * (self.plan.q_grasp[d] - q[d]) - damping
            };
        }
    }

    /// Clamps the controller's torques `tau` at the tick at `t` to the hand's limits into
    /// `self.tau`, with the statistics of saturation and the peak.
    fn clamp_torques(&mut self, t: Real, tau: &[Real; MAX_DOF]) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let held = t >= self.timeline.grasp_end && t < self.timeline.release_start;
        let mut saturated = false;
        for d in 0..n {
            let lim = hand.torque_limit[d];
            // Saturated: the controller asked for the limit or more.
            if tau[d].abs() >= 0.999 * lim && self.grasp_dof[d] {
                saturated = true;
            }
            self.tau[d] = tau[d].clamp(-lim, lim);
            // The peak of what the joint applied, at most its limit.
            let ratio = self.tau[d].abs() / lim;
            if ratio > self.stats.peak_ratio {
                self.stats.peak_ratio = ratio;
                self.stats.peak_dof = d;
            }
        }
        if held && saturated {
            self.stats.saturated_ticks += 1;
        }
    }

    /// A pinch's jaws squeeze with equal force, so they can carry no load along the line between
    /// them: in the DFS nothing pushes back when the object moves along it (a real jaw's
    /// contact stiffness would). Following the skill's rotation as it is would tilt that line
    /// and let gravity pull the object along it; the hand turns by the least rotation about the
    /// jaws' midpoint that keeps the line horizontal (the object's orientation error shows it).
    fn level_jaws(&self, base: Isometry) -> Isometry {
        let Some((u_base, mid_base)) = self.jaw_line else {
            return base;
        };
        let u = base.rotation * u_base;
        let Some(level) = Vector::new(u.x, u.y, 0.0).try_normalize(1e-6) else {
            return base;
        };
        let Some(turn) = crate::math::Rotation::rotation_between(&u, &level) else {
            return base;
        };
        let mid = base * mid_base;
        let about_mid = Isometry::from_parts((mid.coords - turn * mid.coords).into(), turn);
        about_mid * base
    }

    /// Runs one tick on the fixed clock (tick `i` at replay time `i · 1 ms`); `Ok(false)` when
    /// the replay is over.
    pub fn step(&mut self) -> Result<bool> {
        if self.step >= self.n_steps {
            return Ok(false);
        }
        self.run_tick(self.step as Real * DT)?;
        Ok(true)
    }

    /// Runs one tick (1 ms of simulation) at replay time `t` (s on the skill's [`Timeline`])
    /// instead of the fixed clock's: a replay driven by the operator's phases
    /// ([`super::PhaseClock`], [`super::DrivenReplay`]) steps to the time its clock gives.
    /// `t` should not decrease from one tick to the next and should move by little more than a
    /// tick's worth (the base follows the schedule at `t` kinematically, so a jump in `t` is a
    /// jump of the arm). `Ok(false)`, running nothing, once `t` reaches the timeline's end (or
    /// is not a number); the report's `ticks` and `duration_s` count the ticks run.
    pub fn step_to(&mut self, t: Real) -> Result<bool> {
        if t.is_nan() || t >= self.timeline.end {
            return Ok(false);
        }
        self.run_tick(t.max(0.0))?;
        Ok(true)
    }

    /// The skill's timeline.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// The skill replayed.
    pub fn skill(&self) -> &SkillSpec {
        &self.skill
    }

    /// One tick at replay time `t`.
    fn run_tick(&mut self, t: Real) -> Result<()> {
        self.reference = self.skill.reference_in(&self.timeline, t);
        let (base, offset, grip, preshaped) = self.schedule(t);
        self.control(t, offset, grip, preshaped);
        let n = self.dfs.hand().dof();
        self.base = base;
        self.q[..n].copy_from_slice(&self.dfs.output().motor_q[..n]);
        if self.step == 0 {
            self.q[..n].copy_from_slice(&self.plan.q_pre[..n]);
        }
        let (q, tau) = (self.q, self.tau);
        self.dfs.step(&GloveSample {
            q: &q[..n],
            tau: &tau[..n],
            base,
        })?;
        self.observe(t);
        self.step += 1;
        Ok(())
    }

    /// Updates the statistics after the tick at `t`.
    fn observe(&mut self, t: Real) {
        let tl = self.timeline;
        let state = *self.dfs.object_state();
        let out = self.dfs.output();
        let s = &mut self.stats;
        s.lift = s.lift.max(state.pose.translation.z - self.start_z);
        if !(t >= tl.grasp_end && t < tl.release_start) {
            return;
        }
        let reference = self.reference;
        let e_pos = (state.pose.translation.vector - reference.translation.vector).norm();
        let e_rot = (reference.rotation.inverse() * state.pose.rotation).angle();
        s.pos_max = s.pos_max.max(e_pos);
        s.rot_max = s.rot_max.max(e_rot);
        s.pos_sq += e_pos * e_pos;
        s.rot_sq += e_rot * e_rot;
        s.held_ticks += 1;
        if s.lost_at.is_none()
            && (e_pos > self.params.max_position_error || e_rot > self.params.max_orientation_error)
        {
            s.lost_at = Some(t);
        }
        let mu = self.skill.friction.mu;
        let mut slip = false;
        for k in 0..out.n_tips.min(MAX_TIPS) {
            let tip = &out.tips[k];
            let Some(frame) = tip.frame.filter(|_| tip.in_contact) else {
                continue;
            };
            slip |= tip.slip;
            let anchor = *s.anchors[k].get_or_insert(frame.p_b);
            s.max_slip = s.max_slip.max((frame.p_b - anchor).norm());
            let c = tip.transmitted;
            if c[2] > 0.05 && mu > 0.0 {
                let model = self.dfs.params().contact_model;
                let margin = 1.0 - cone_usage(model, &self.skill.friction, &c);
                s.min_margin = Some(s.min_margin.map_or(margin, |m: Real| m.min(margin)));
            }
        }
        // A power grasp's palm and phalanges (none without whole-hand contact).
        for b in self.dfs.body_contacts() {
            if !(b.in_contact && b.frame.is_some()) {
                continue;
            }
            slip |= b.slip;
            let c = b.transmitted;
            if c[2] > 0.05 && mu > 0.0 {
                let model = self.dfs.params().contact_model;
                let margin = 1.0 - cone_usage(model, &self.skill.friction, &c);
                s.min_margin = Some(s.min_margin.map_or(margin, |m: Real| m.min(margin)));
            }
        }
        if slip {
            s.slip_ticks += 1;
        }
    }

    /// The report (after the last tick, or early).
    pub fn report(&self) -> ReplayReport {
        let s = &self.stats;
        let held = s.held_ticks.max(1) as Real;
        let sim_ok = s.lost_at.is_none() && s.held_ticks > 0;
        let planned = self.plan.failure.clone();
        let (success, reason, detail) = match (sim_ok, planned) {
            (true, None) => (
                true,
                None,
                format!(
                    "held the object through the skill's motion (largest error {:.1} mm, \
                     {:.1}°)",
                    s.pos_max * 1e3,
                    s.rot_max.to_degrees()
                ),
            ),
            (true, Some((r, why))) => (
                true,
                None,
                format!(
                    "held the object, though planning warned ({}): {why}",
                    r.name()
                ),
            ),
            (false, Some((r, why))) => (false, Some(r), why),
            (false, None) => {
                let lost = s.lost_at.unwrap_or(0.0);
                let frac = s.saturated_ticks as Real / held;
                if frac > 0.2 {
                    (
                        false,
                        Some(FailureReason::TorqueLimit),
                        format!(
                            "the object left its reference at t = {lost:.2} s with the finger \
                             joints at their torque limits {:.0} % of the time",
                            frac * 100.0
                        ),
                    )
                } else {
                    (
                        false,
                        Some(FailureReason::Slip),
                        format!(
                            "the object slipped away from its reference at t = {lost:.2} s \
                             (error over {:.0} mm or {:.0}°)",
                            self.params.max_position_error * 1e3,
                            self.params.max_orientation_error.to_degrees()
                        ),
                    )
                }
            }
        };
        let hand = &self.plan.hand;
        ReplayReport {
            hand: hand.name.clone(),
            success,
            failure_reason: reason,
            detail,
            position_error_max_m: s.pos_max,
            position_error_rms_m: (s.pos_sq / held).sqrt(),
            orientation_error_max_rad: s.rot_max,
            orientation_error_rms_rad: (s.rot_sq / held).sqrt(),
            max_slip_m: s.max_slip,
            slip_ticks: s.slip_ticks,
            min_friction_margin: s.min_margin.unwrap_or(0.0),
            peak_torque_ratio: s.peak_ratio,
            peak_torque_joint: hand.dof_names.get(s.peak_dof).cloned().unwrap_or_default(),
            quality: self.plan.quality,
            contacts: self.plan.planned_contacts(),
            ik_error_m: self.plan.ik_error,
            lift_height_m: s.lift,
            ticks: self.step,
            duration_s: self.step as Real * DT,
        }
    }

    /// The last tick as a [`ReplayTick`] (`time_ns` of the last tick run).
    pub fn tick(&self) -> ReplayTick<'_> {
        let n = self.dfs.hand().dof();
        ReplayTick {
            time_ns: self.step.saturating_sub(1) * 1_000_000,
            q: &self.q[..n],
            tau: &self.tau[..n],
            base: &self.base,
            output: self.dfs.output(),
            body: self.dfs.body_contacts(),
            kinematics: self.dfs.kinematics(),
            reference: &self.reference,
        }
    }
}

impl Plan {
    /// The report of a plan that is not simulated, as [`run`] gives it: contacts the hand
    /// cannot reach, or contacts that cannot carry the object at rest
    /// ([`Plan::fails_at_rest`]); `None` when the plan is to be simulated.
    pub fn refusal(&self) -> Option<ReplayReport> {
        if self.fails_at_rest || matches!(self.failure, Some((FailureReason::Unreachable, _))) {
            Some(refused_report(self))
        } else {
            None
        }
    }
}

/// A report for a plan that is not simulated (unreachable contacts, or contacts that cannot
/// carry the object at rest, [`Plan::fails_at_rest`]): nothing ran.
fn refused_report(plan: &Plan) -> ReplayReport {
    let (reason, detail) = plan
        .failure
        .clone()
        .unwrap_or((FailureReason::Unreachable, String::new()));
    ReplayReport {
        hand: plan.hand.name.clone(),
        success: false,
        failure_reason: Some(reason),
        detail,
        position_error_max_m: 0.0,
        position_error_rms_m: 0.0,
        orientation_error_max_rad: 0.0,
        orientation_error_rms_rad: 0.0,
        max_slip_m: 0.0,
        slip_ticks: 0,
        min_friction_margin: 0.0,
        peak_torque_ratio: 0.0,
        peak_torque_joint: String::new(),
        quality: ReplayQuality { ..plan.quality },
        contacts: plan.planned_contacts(),
        ik_error_m: plan.ik_error,
        lift_height_m: 0.0,
        ticks: 0,
        duration_s: 0.0,
    }
}

/// Retargets `skill` onto `hand` and simulates it; see [`run_with`].
pub fn run(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
) -> Result<ReplayReport> {
    run_with_stop(hand, thumb, skill, params, Stop::never(), |_| {})
}

/// Retargets `skill` onto `hand` (fingertip `thumb` opposing the others), simulates it at
/// 1 kHz and reports; `on_tick` sees every tick (for recording). Failures are reports; errors
/// are for invalid input (a bad hand or skill). Runs to its end: see [`run_with_stop`].
pub fn run_with(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    on_tick: impl FnMut(&ReplayTick<'_>),
) -> Result<ReplayReport> {
    run_with_stop(hand, thumb, skill, params, Stop::never(), on_tick)
}

/// [`run_with`], ending early with [`crate::DfsError::Cancelled`] once `stop` is set: planning
/// looks at it as [`super::plan_with_stop`] does, the simulation before every tick (a tick of
/// the largest hand is some 10 µs). A replay lasts at most [`crate::scenario::MAX_SCRIPT_S`] of
/// simulated time plus its fixed approach and retreat.
pub fn run_with_stop(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    stop: &Stop,
    mut on_tick: impl FnMut(&ReplayTick<'_>),
) -> Result<ReplayReport> {
    let plan = plan_with_stop(hand, thumb, skill, params, stop)?;
    if let Some(report) = plan.refusal() {
        return Ok(report);
    }
    let mut replay = Replay::from_plan(plan, skill, params)?;
    loop {
        stop.check()?;
        if !replay.step()? {
            break;
        }
        on_tick(&replay.tick());
    }
    Ok(replay.report())
}
