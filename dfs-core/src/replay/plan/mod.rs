//! Retargeting a skill onto a hand: contact assignment (and a new contact set when the finger
//! counts differ), the base pose, fingertip inverse kinematics and the force distribution with
//! exact friction cones and the hand's torque limits. See the module documentation of
//! [`crate::replay`].
//!
//! Here: the [`Plan`], validation and the choice among the searches' candidates with the
//! sentence for a refusal. The placed and curled candidates are in `candidates`, the forces in
//! `forces`, one step along the motion in `step`; the closing-motion search is
//! [`super::closing`], and what the searches share is in [`super::base_pose`].

mod candidates;
mod forces;
mod step;

pub(in crate::replay) use candidates::{plan_candidates, Keys};
pub(in crate::replay) use forces::actuation_map;
pub(in crate::replay) use forces::load_at;
pub use step::RetargetStep;

use super::base_pose::Candidate;
use super::closing::closing_candidates;
use super::{FailureReason, PlannedContact, ReplayParams, ReplayQuality};
use crate::contact::{ContactFrame, Intensity};
use crate::error::{DfsError, Result};
use crate::grasp::quality::{grasp_quality, QualityParams};
use crate::hand::ik::{solve_tips, IkParams};
use crate::hand::{ContactPart, HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Vector};
use crate::replay::SkillSpec;
use crate::scenario::MAX_SCRIPT_S;
use crate::stop::Stop;
use candidates::named_contacts;
use forces::{plan_forces, torque_map};
use nalgebra::DMatrix;

/// A retargeted grasp: where the hand goes, its joint angles, its contacts and the planned
/// contact forces along the reference motion.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The hand.
    pub hand: HandModel,
    /// Index of the thumb (the fingertip opposing the others).
    pub thumb: usize,
    /// Pose of the hand's base at the grasp (world).
    pub base_grasp: Isometry,
    /// The same relative to the object's start pose (B₀): the base follows the object.
    pub base_in_b0: Isometry,
    /// Direction (world) in which the hand approaches the object.
    pub approach_dir: Vector,
    /// Joint angles with the fingertips on their contacts.
    pub q_grasp: [Real; MAX_DOF],
    /// Joint angles with the fingertips [`ReplayParams::preshape_clearance`] off them.
    pub q_pre: [Real; MAX_DOF],
    /// Per fingertip of the hand: its contact (point where the sphere touches, inward normal)
    /// in B; meaningful for the fingertips in [`Plan::active`] only.
    pub contacts: Vec<ContactFrame>,
    /// Per fingertip: it takes part in the grasp. A finger of an underactuated hand whose curl
    /// misses the object stays open and out of the grasp.
    pub active: Vec<bool>,
    /// Largest fingertip distance from its target after inverse kinematics (m).
    pub ik_error: Real,
    /// Grasp quality of `contacts`.
    pub quality: ReplayQuality,
    /// Times (s since the replay's start) of the force samples.
    pub force_times: Vec<Real>,
    /// Planned intensities per force sample and fingertip (contact frames of `contacts`).
    pub forces: Vec<[Intensity; MAX_TIPS]>,
    /// Map from intensities to joint torques at the grasp (rows DOFs, 4 columns per active
    /// tip, in the order of the fingertips).
    pub torque_map: DMatrix<Real>,
    /// A reason the grasp cannot work, found while planning, with a sentence.
    pub failure: Option<(FailureReason, String)>,
    /// The failure (`no_force_closure` or `torque_limit`) is there already at the grasp, with
    /// the object at rest: the contacts cannot carry its weight at all, so the replay is not
    /// simulated (it could only drop the object). A failure later along the motion (a
    /// transient the torques cannot follow) is a warning: the replay runs and tells.
    pub fails_at_rest: bool,
    /// A power grasp's wrap (the skill held by the palm: [`crate::replay`]'s power grasps);
    /// `None` for a fingertip grasp. Its fingertips are then not [`Plan::active`]: the
    /// fingers close by torque and touch where they wrap.
    pub power: Option<super::power::PowerPlan>,
}

/// Validates a skill for replay; the error names the field.
fn validate(skill: &SkillSpec, thumb: usize, hand: &HandModel) -> Result<()> {
    skill.shape.validate()?;
    if !(skill.mass.is_finite() && skill.mass > 0.0) {
        return Err(DfsError::invalid("skill.object.mass", "must be > 0"));
    }
    if !(skill.friction.mu.is_finite() && skill.friction.mu >= 0.0) {
        return Err(DfsError::invalid(
            "skill.object.mu",
            "must be finite and ≥ 0",
        ));
    }
    if !(skill.friction.mu_torsion.is_finite() && skill.friction.mu_torsion >= 0.0) {
        return Err(DfsError::invalid(
            "skill.object.mu_torsion",
            "must be finite and ≥ 0",
        ));
    }
    for (i, (_, d)) in skill.phases.iter().enumerate() {
        if !(d.is_finite() && *d >= 0.0) {
            return Err(DfsError::invalid(
                format!("skill.phases[{i}]"),
                format!("duration {d} s must be finite and ≥ 0"),
            ));
        }
    }
    let total: Real = skill.phases.iter().map(|(_, d)| d).sum();
    if total > MAX_SCRIPT_S {
        return Err(DfsError::invalid(
            "skill.phases",
            format!("the phases last {total:.1} s; a replay lasts at most {MAX_SCRIPT_S} s"),
        ));
    }
    for (i, k) in skill.motion.iter().enumerate() {
        let finite = k.time_s.is_finite()
            && k.position
                .iter()
                .chain(k.rotation.iter())
                .all(|v| v.is_finite())
            && k.position.norm() <= 10.0;
        if !finite {
            return Err(DfsError::invalid(
                format!("skill.motion[{i}]"),
                "time, position and rotation must be finite, the position within 10 m",
            ));
        }
    }
    if skill.contacts.is_empty() {
        return Err(DfsError::invalid(
            "skill.contacts",
            "the skill has no contacts",
        ));
    }
    for (i, c) in skill.contacts.iter().enumerate() {
        // A power grasp held by the palm or the phalanges: the planner retargets fingertip
        // contacts only, so it says so rather than putting a fingertip where the palm was.
        if !c.part.is_fingertip() && !super::power::is_power(hand, skill) {
            let why = if skill.contacts.iter().any(|c| c.part == ContactPart::Palm) {
                "and the hand has no palm contact geometry to replay it with (its URDF's \
                 <collision> elements on the link its fingers branch from)"
            } else {
                "without a palm contact: a power grasp is replayed from its palm contact, and \
                 a fingertip grasp from fingertips only"
            };
            return Err(DfsError::invalid(
                format!("skill.contacts[{i}]"),
                format!(
                    "a {} contact (`{}`) of a whole-hand grasp, {why}",
                    c.part.name(),
                    c.finger
                ),
            ));
        }
        let ok = c
            .position_b
            .iter()
            .chain(c.normal_b.iter())
            .all(|v| v.is_finite())
            && c.normal_b.norm() > 0.5;
        if !ok {
            return Err(DfsError::invalid(
                format!("skill.contacts[{i}]"),
                "position and unit normal must be finite",
            ));
        }
    }
    if thumb >= hand.fingertips.len() {
        return Err(DfsError::invalid("thumb", "no such fingertip"));
    }
    hand.validate()
}

/// Retargets `skill` onto `hand` (whose fingertip `thumb` opposes the others). Planning
/// failures (unreachable contacts, loads the cones or the torques cannot carry) are in
/// [`Plan::failure`]; errors are for invalid input only. Runs to its end: see
/// [`plan_with_stop`].
pub fn plan(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
) -> Result<Plan> {
    plan_with_stop(hand, thumb, skill, params, Stop::never())
}

/// [`plan`], ending early with [`DfsError::Cancelled`] once `stop` is set: it is looked at
/// before every candidate base pose and inverse-kinematics solve, every few hundred probes of
/// the closing-motion search and every force sample, so a stop is honoured within about
/// 0.1 s of CPU even on a hand of [`crate::hand::MAX_HAND_DOF`] DOFs.
///
/// The work is bounded without it too: 12 rolls of the base pose per kind of grasp (every tip
/// placed; the thumb and two, then one, fingers placed with the others curled; the hand's own
/// closing motion, at most 3 hand-frame grasps per roll; the fingers named like the skill's
/// contacts), inverse kinematics of at most 150 iterations, the force distribution at most
/// [`MAX_SCRIPT_S`] / [`ReplayParams::force_sample_s`] samples (each a capped Newton solve,
/// or Clarabel's of at most 200 iterations).
pub fn plan_with_stop(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    stop: &Stop,
) -> Result<Plan> {
    validate(skill, thumb, hand)?;
    stop.check()?;
    if super::power::is_power(hand, skill) {
        return super::power::plan_power(hand, thumb, skill, params, stop);
    }
    let (best, refusals) = choose(hand, thumb, skill, params, stop)?;
    let mut plan = grasp_plan(hand, thumb, skill, params, &best, stop)?;
    if !best.ok {
        let why = refusals.sentence(&best, skill, params);
        plan.failure = Some((FailureReason::Unreachable, why));
        return Ok(plan);
    }
    plan_forces(&mut plan, skill, params, stop)?;
    Ok(plan)
}

/// Why the searches after the first refused their grasps, when no candidate is good: for
/// the sentence in [`Plan::failure`].
#[derive(Debug, Default)]
struct Refusals {
    /// The curled grasps (thumb and `n` fingers placed): `n` and the best one's alignment.
    curled: Option<(usize, Real)>,
    /// The hand's own closing motion: the best one's alignment, or `None` when no position of
    /// the object lets the thumb and another finger close onto it within the cones.
    closing: Option<Option<Real>>,
    /// The fingers named like the skill's contacts: the alignment of its worst finger's push
    /// with its normal.
    named: Option<Real>,
}

/// The best candidate base pose of the searches tried in turn until one is good, with why
/// the later ones were refused.
fn choose(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    stop: &Stop,
) -> Result<(Candidate, Refusals)> {
    let nt = hand.fingertips.len();
    let best_of = |keys: Keys| -> Result<Option<Candidate>> {
        Ok(plan_candidates(hand, thumb, skill, params, keys, stop)?
            .into_iter()
            .max_by(|a, b| a.score.total_cmp(&b.score)))
    };
    let mut refused = Refusals::default();
    // Every fingertip on its contact; failing that (an underactuated hand cannot put every
    // tip on an arbitrary point), the thumb and two, then one, opposing fingers placed and the
    // other fingers curled onto the surface.
    let mut best = best_of(Keys::All)?;
    if !best.as_ref().is_some_and(|c| c.ok) && nt >= 3 {
        for n in [2, 1] {
            match best_of(Keys::Nearest(n))? {
                Some(c) if c.ok => {
                    best = Some(c);
                    refused.curled = None;
                    break;
                }
                Some(c) if c.error <= params.reach_tolerance && refused.curled.is_none() => {
                    refused.curled = Some((n, c.align));
                }
                _ => {}
            }
        }
    }
    // Failing those too (fingers that push only along their own motion, off the normals at
    // the skill's contacts), a grasp where the hand's fingers meet the object head-on.
    if !best.as_ref().is_some_and(|c| c.ok) && nt >= 3 {
        let closing = closing_candidates(hand, thumb, skill, params, stop)?
            .into_iter()
            .max_by(|a, b| a.score.total_cmp(&b.score));
        match closing {
            Some(c) if c.ok => {
                best = Some(c);
                refused.curled = None;
            }
            c => refused.closing = Some(c.map(|c| c.align)),
        }
    }
    // Failing all of those, a hand with the demonstrator's finger names (glove10 replaying
    // its own skill, whose coupled fingers cannot each reach a contact of their own) takes
    // each contact on its own finger; the fingers the skill does not use go where their
    // coupling takes them, or curl. Last, so that no replay planned before changes.
    let named = named_contacts(hand, skill);
    let named_count = named.iter().flatten().count();
    if !best.as_ref().is_some_and(|c| c.ok)
        && named[thumb].is_some()
        && named_count == skill.contacts.len()
        && named_count >= 2
        && named_count < nt
    {
        match best_of(Keys::Named)? {
            Some(c) if c.ok => {
                best = Some(c);
                refused.curled = None;
                refused.closing = None;
            }
            Some(c) if c.error <= params.reach_tolerance => refused.named = Some(c.align),
            _ => {}
        }
    }
    match best {
        Some(best) => Ok((best, refused)),
        None => Err(DfsError::invalid("hand", "no candidate base pose")),
    }
}

/// The plan for the grasp at candidate `best`: its base pose, joint angles and the contacts
/// the fingertips reach, the preshape, the grasp's quality and the torque map; no forces and
/// no failure yet.
fn grasp_plan(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    best: &Candidate,
    stop: &Stop,
) -> Result<Plan> {
    let start = skill.start_pose();
    let nt = hand.fingertips.len();
    let n_hand = hand.dof();
    let mut kin = Kinematics::default();
    let active: Vec<bool> = best.active[..nt].to_vec();
    let base_grasp = Isometry::from_parts(
        Vector::new(best.q_free[0], best.q_free[1], best.q_free[2]).into(),
        best.rotation,
    );
    let mut q_grasp = [0.0; MAX_DOF];
    q_grasp[..n_hand].copy_from_slice(&best.q_free[3..n_hand + 3]);
    // The contacts the fingertips reach.
    hand.forward_kinematics(&base_grasp, &q_grasp[..n_hand], &mut kin);
    let inv = start.inverse();
    let contacts: Vec<ContactFrame> = (0..nt)
        .map(|k| {
            let c_b = (inv * kin.tip_centres[k]).coords;
            let (p, n_in) = skill.shape.on_surface(&c_b);
            ContactFrame::from_normal(p, n_in)
        })
        .collect();
    stop.check()?;
    let q_pre = preshape(
        hand,
        &base_grasp,
        &q_grasp,
        &contacts,
        &active,
        skill,
        params,
        &mut kin,
    );
    let active_contacts: Vec<ContactFrame> = (0..nt)
        .filter(|&k| active[k])
        .map(|k| contacts[k])
        .collect();
    let quality = grasp_quality(
        &active_contacts,
        skill.contact_model,
        &skill.friction,
        &QualityParams::default(),
    )
    .map(|q| ReplayQuality {
        epsilon: q.epsilon,
        volume: q.volume,
        force_closure: q.force_closure,
    })
    .unwrap_or(ReplayQuality {
        epsilon: 0.0,
        volume: 0.0,
        force_closure: false,
    });
    // Torque map at the grasp (B = world at the start: the start pose is not rotated).
    hand.forward_kinematics(&base_grasp, &q_grasp[..n_hand], &mut kin);
    hand.tip_jacobians(&mut kin);
    let torque_map = torque_map(hand, &kin, &contacts, &active);
    Ok(Plan {
        hand: hand.clone(),
        thumb,
        base_grasp,
        base_in_b0: inv * base_grasp,
        approach_dir: best.approach,
        q_grasp,
        q_pre,
        contacts,
        active,
        ik_error: best.error,
        quality,
        force_times: Vec::new(),
        forces: Vec::new(),
        torque_map,
        failure: None,
        fails_at_rest: false,
        power: None,
    })
}

/// The preshape: each active fingertip out along its contact normal by
/// [`ReplayParams::preshape_clearance`], the base at `base_grasp`, the DOFs common to several
/// fingers held at `q_grasp`.
#[allow(clippy::too_many_arguments)] // the grasp's parts, each read once
fn preshape(
    hand: &HandModel,
    base_grasp: &Isometry,
    q_grasp: &[Real; MAX_DOF],
    contacts: &[ContactFrame],
    active: &[bool],
    skill: &SkillSpec,
    params: &ReplayParams,
    kin: &mut Kinematics,
) -> [Real; MAX_DOF] {
    let start = skill.start_pose();
    let n_hand = hand.dof();
    let mut grouped = [false; MAX_DOF];
    for g in &hand.finger_groups {
        for &d in &g.dofs {
            grouped[d] = true;
        }
    }
    let pre_targets: Vec<(usize, Point)> = (0..contacts.len())
        .filter(|&k| active[k])
        .map(|k| {
            let c = &contacts[k];
            let out = -c.normal_b();
            let p = c.p_b + out * (hand.fingertips[k].radius + params.preshape_clearance);
            (k, start * Point::from(p))
        })
        .collect();
    let pre_params = IkParams {
        max_iterations: 150,
        tolerance: 5e-4,
        ..IkParams::default()
    }
    .with_frozen((0..n_hand).filter(|&d| !grouped[d]));
    let mut q_pre = [0.0; MAX_DOF];
    solve_tips(
        hand,
        base_grasp,
        &pre_targets,
        &q_grasp[..n_hand],
        &pre_params,
        kin,
        &mut q_pre[..n_hand],
    );
    q_pre
}

impl Refusals {
    /// The sentence for a plan whose best candidate `best` is not good.
    fn sentence(&self, best: &Candidate, skill: &SkillSpec, params: &ReplayParams) -> String {
        let mu = skill.friction.mu * (1.0 - params.friction_margin);
        let why = if let Some((n, align)) = self.curled {
            format!(
                "no base pose puts every fingertip on its contact (the best misses by {:.1} mm); \
                 the thumb and {n} opposing finger(s) reach the object with the others curled \
                 onto it, but a finger there cannot push along its contact normal within the \
                 friction cone (alignment {align:.2}, needs {:.2})",
                best.error * 1e3,
                1.0 / (1.0 + mu * mu).sqrt()
            )
        } else if best.error > params.reach_tolerance {
            format!(
                "no base pose puts the fingertips on their contacts: the best misses by {:.1} mm \
                 (tolerance {:.1} mm)",
                best.error * 1e3,
                params.reach_tolerance * 1e3
            )
        } else {
            "the fingers that reach the object do not make a force closure".to_owned()
        };
        let cone = (mu.atan()).to_degrees();
        let why = match self.closing {
            None => why,
            Some(None) => format!(
                "{why}; nor does the hand's own closing motion: no position of the object lets \
                 the thumb and another finger close onto it pushing within {cone:.1}° of the \
                 normals with their normals balancing"
            ),
            Some(Some(align)) => format!(
                "{why}; nor does the hand's own closing motion: its best grasp there has a \
                 finger pushing {:.1}° off its normal (the planned cone allows {cone:.1}°), an \
                 approach that touches the object, or no force closure",
                align.clamp(-1.0, 1.0).acos().to_degrees()
            ),
        };
        match self.named {
            None => why,
            Some(align) => format!(
                "{why}; the fingers named like the skill's contacts reach them, but one pushes \
                 {:.1}° off its contact normal, outside even the friction cone ({:.1}°)",
                align.clamp(-1.0, 1.0).acos().to_degrees(),
                skill.friction.mu.atan().to_degrees()
            ),
        }
    }
}

impl Plan {
    /// The retargeted contacts for a report.
    pub fn planned_contacts(&self) -> Vec<PlannedContact> {
        if let Some(power) = &self.power {
            return power
                .contacts
                .iter()
                .map(|c| {
                    let (p, n) = (c.frame.p_b, c.frame.normal_b());
                    PlannedContact {
                        finger: c.name.clone(),
                        position_b: [p.x, p.y, p.z],
                        normal_b: [n.x, n.y, n.z],
                    }
                })
                .collect();
        }
        self.contacts
            .iter()
            .enumerate()
            .filter(|(k, _)| self.active[*k])
            .map(|(k, c)| {
                let n = c.normal_b();
                PlannedContact {
                    finger: self.hand.fingertips[k].name.clone(),
                    position_b: [c.p_b.x, c.p_b.y, c.p_b.z],
                    normal_b: [n.x, n.y, n.z],
                }
            })
            .collect()
    }

    /// Planned intensities of every fingertip at `t`, linearly interpolated between the force
    /// samples (held at the ends). Allocation-free.
    pub fn forces_at(&self, t: Real) -> [Intensity; MAX_TIPS] {
        let n = self.force_times.len();
        if n == 0 {
            return [Intensity::zeros(); MAX_TIPS];
        }
        if t <= self.force_times[0] {
            return self.forces[0];
        }
        if t >= self.force_times[n - 1] {
            return self.forces[n - 1];
        }
        let i = self
            .force_times
            .partition_point(|&x| x <= t)
            .clamp(1, n - 1);
        let (t0, t1) = (self.force_times[i - 1], self.force_times[i]);
        let a = ((t - t0) / (t1 - t0).max(1e-12)).clamp(0.0, 1.0);
        let mut out = [Intensity::zeros(); MAX_TIPS];
        for k in 0..MAX_TIPS {
            out[k] = self.forces[i - 1][k] * (1.0 - a) + self.forces[i][k] * a;
        }
        out
    }
}
