//! Power grasps on a robot hand (issue 21 item 5): a skill held by the palm as well as the
//! fingers (the simulated operator's wrap of a cylinder, a glove session's power grasp) is
//! retargeted as a palm placement and a wrap, not as fingertip contacts.
//!
//! # Plan
//!
//! The hand needs palm contact geometry ([`crate::hand::BodyPart::Palm`] shapes: glove10's, or
//! a URDF's `<collision>` elements on the link the fingers branch from, which services loads
//! for a power grasp). Then:
//!
//! 1. **The palm's grasping side.** Each face normal of the palm's boxes (and the axes of its
//!    other shapes) is a candidate direction `g` of the palm's inner face (hand frame, all
//!    DOFs at 0 clamped into their ranges). For a `g`, a finger DOF that spreads or twists the
//!    finger is held at that angle: its joint turns about an axis within 45° of `g`, or the
//!    finger lies across `g` and the DOF moves its tip across `g` too. Every other finger DOF
//!    flexes: its *closed* end is the one that brings the tip nearer the point where the
//!    object will be (the palm's centre plus `g` times the depth of the skill's object behind
//!    its palm contact), the other end is *open*. DOFs outside the fingers (a wrist) are held.
//! 2. **Palm placement.** The base is turned so that `g` is the skill's palm contact normal
//!    (the mean of its palm contacts', into the object), rolled about it in 12 steps, its palm
//!    centre put on the line through the palm contacts' centroid along the normal (and shifted
//!    0-4.5 cm toward the fingers, so that they reach farther around), and slid in until the
//!    open hand first touches the object. The palm must be what touches (within 1 mm), and no
//!    fingertip or contact shape's link origin of the open hand, there or 8 cm back along the
//!    normal where the approach starts, may be below the table (the wrapped hand is checked
//!    the same way).
//! 3. **The wrap.** Each finger's flexing DOFs close together from open to closed until one of
//!    its shapes (its phalanges' contact shapes or its fingertip) first touches the object;
//!    that touch is its contact (a finger touching already when open has that touch; one
//!    that never touches stays open, out of the grasp).
//!    Candidates are ranked by the number of fingers touching, plus the Ferrari-Canny ε of the
//!    palm's and the fingers' contacts, less the mean distance (m) from each of the skill's
//!    non-palm contacts to the nearest of the wrap's (the hand wraps where the recorded one
//!    did). The first touches need not be a force closure: in the DFS the fingers close on,
//!    wrapping the object.
//! 4. **Grip.** In the simulation the fingers close by torque alone: every flexing DOF of a
//!    finger taking part pushes toward closed with the same fraction (the *grip*) of its torque
//!    limit (gently, [`crate::operator::power::WRAP_CLOSE`], while the fingers close, as the
//!    operator's wrap does), and the palm, fixed to the arm, takes the reaction. The grip is
//!    planned by statics at the first touches: a finger's normal force per unit grip is
//!    `λ = (Jᵀn)·τ / |Jᵀn|²` (`J` the touching point's Jacobian over the finger's DOFs, `n` the
//!    contact normal, `τ` its closing torques at the limit), the palm's the opposite of the
//!    fingers' along its normal; friction must carry the largest load of the reference motion
//!    `m |a − g|` with the friction margin, `μ (1 − margin) (Σλ + λ_palm) · grip ≥ m |a − g|`;
//!    the grip is twice that (the first touches are not where the wrapped fingers end up), at
//!    least 0.3, at most 1. A load the fingers cannot carry even at their limits without the
//!    margin for the object at rest refuses the replay (`torque_limit`); one they cannot carry
//!    with the margin along the motion is a warning and the replay runs at grip 1.
//! 5. **Trials.** The six best-ranked wraps are tried in the DFS, in order, as the replay itself
//!    would run them, through the held motion up to 10 s into it (the built-in scenarios' held
//!    motions, lift to the end of placing, are 3-5 s; a long skill costs no more to plan): the first that keeps the object within the
//!    report's success bounds that far is the plan; if none does, the one that followed the
//!    reference longest, whose replay then reports how it failed. The force optimiser of fingertip grasps
//!    ([`crate::grasp::optimise`]) is not used: a wrap's fingers push with one level each, not
//!    with planned force vectors, and its contacts move as the fingers wrap further (the DFS
//!    finds them every tick).
//!
//! A trial costs at most the simulation up to 10 s into the held motion (for the built-in
//! skills, the whole replay but the release), so planning a power grasp takes up to six of them.

use super::base_pose::ROLLS;
use super::plan::Plan;
use super::{FailureReason, ReplayParams, ReplayQuality, SkillSpec};
use crate::contact::ContactFrame;
use crate::error::Result;
use crate::grasp::quality::{grasp_quality, QualityParams};
use crate::hand::contact_geometry::{closest_to_object, ContactPrimitive};
use crate::hand::{BodyPart, ContactPart, HandModel, Kinematics, TipJacobian, MAX_DOF};
use crate::math::{Isometry, Point, Real, Rotation, Vector};
use crate::stop::Stop;

/// How far back along the palm normal the approach starts (m); [`super::run`] uses the same.
pub(super) const APPROACH: Real = 0.08;
/// The palm must be what the open hand touches first, within this (m).
const PALM_FIRST: Real = 1e-3;
/// A finger DOF that moves its fingertip at less than this cosine to the palm normal spreads
/// or twists the finger rather than flexing it.
const LATERAL_COS: Real = std::f64::consts::FRAC_1_SQRT_2;
/// The least grip (fraction of the torque limits) a wrap holds with.
const MIN_GRIP: Real = 0.3;
/// Where the palm's contact point is placed along the palm toward the fingers from the palm
/// shapes' centre (m): nearer the fingers, they reach farther around the object.
const SHIFTS: [Real; 4] = [0.0, 0.015, 0.03, 0.045];
/// How far into the held motion a trial runs at most (s): the whole of the built-in skills'
/// (their held motions, lift to the end of placing, are 3-5 s; a wrap that held the first 2 s could still let the object go later: Allegro's wrap of the
/// simulated operator's cylinder did at 4.4 s, by how a contact point a micrometre away
/// happened to fall), and no more for a skill an hour long.
const TRIAL_HELD_S: Real = 10.0;
/// Wraps tried in the DFS, best ranked first.
const TRIALS: usize = 6;
/// Steps of a finger's closing sweep before the bisection of its first touch.
const CURL_STEPS: usize = 40;

/// A retargeted power grasp ([module documentation](self)): how the fingers close and with
/// what grip, and the contacts at the first touches.
#[derive(Debug, Clone, PartialEq)]
pub struct PowerPlan {
    /// Per DOF: +1 or −1, the direction that closes it (a flexing DOF of a finger taking part),
    /// or 0 for a DOF held at its open angle.
    pub close: [Real; MAX_DOF],
    /// The grip while the object is held: the fraction of each closing DOF's torque limit it
    /// pushes with, in (0, 1].
    pub grip: Real,
    /// The contacts at the first touches: the palm's, then each finger's.
    pub contacts: Vec<PowerContact>,
}

/// One contact of a [`PowerPlan`].
#[derive(Debug, Clone, PartialEq)]
pub struct PowerContact {
    /// The contact shape's name (its link's) or the fingertip's.
    pub name: String,
    /// Palm, phalanx or fingertip.
    pub part: ContactPart,
    /// Point on the object's surface and inward normal (B).
    pub frame: ContactFrame,
}

/// The open hand and closing directions for one palm-normal candidate `g` (hand frame).
struct Posture {
    g: Vector,
    q_open: [Real; MAX_DOF],
    /// Per DOF: +1/−1 closing direction of a flexing finger DOF, 0 held.
    close: [Real; MAX_DOF],
}

/// One placed and wrapped candidate.
struct Wrap {
    score: Real,
    base: Isometry,
    q_touch: [Real; MAX_DOF],
    close: [Real; MAX_DOF],
    q_open: [Real; MAX_DOF],
    contacts: Vec<PowerContact>,
    /// Per contact after the palm's: (link, point in the world, normal in the world, its
    /// finger's DOFs) for the grip's statics.
    touches: Vec<(usize, Point, Vector, Vec<usize>)>,
    quality: ReplayQuality,
}

/// Whether `skill` is a power grasp to be retargeted as one: it has a palm contact and the hand
/// has palm contact geometry.
pub(super) fn is_power(hand: &HandModel, skill: &SkillSpec) -> bool {
    skill.contacts.iter().any(|c| c.part == ContactPart::Palm)
        && hand.contact_shapes.iter().any(|s| s.part == BodyPart::Palm)
}

/// Plans `skill` (a power grasp: [`is_power`]) on `hand` ([module documentation](self)).
pub(super) fn plan_power(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    stop: &Stop,
) -> Result<Plan> {
    let start = skill.start_pose();
    let palm = PalmContact::of(skill, &start);
    let mut kin = Kinematics::default();
    let (wraps, placed) = ranked_wraps(hand, skill, &palm, stop, &mut kin)?;
    let planning = Planning {
        hand,
        thumb,
        skill,
        params,
        start,
        approach: palm.n_w,
    };
    // The best few wraps are tried in the DFS: the first that holds the object through the
    // skill's motion is the plan, else the one that followed it longest.
    let mut best: Option<(Real, Plan)> = None;
    for w in wraps.iter().take(TRIALS) {
        let plan = planning.candidate(w, &mut kin);
        if plan.fails_at_rest {
            if best.is_none() {
                best = Some((Real::NEG_INFINITY, plan));
            }
            continue;
        }
        let held = planning.trial(&plan, stop)?;
        if held >= 1.0 {
            return Ok(plan);
        }
        if best.as_ref().is_none_or(|b| held > b.0) {
            best = Some((held, plan));
        }
    }
    if let Some((_, plan)) = best {
        return Ok(plan);
    }
    Ok(planning.unreachable(placed))
}

/// The skill's palm contacts (a palm and its eminences may be several) taken together.
struct PalmContact {
    /// Their mean normal (world, at the object's start pose).
    n_w: Vector,
    /// Their centroid (world, at the object's start pose).
    p_w: Point,
    /// How deep the object reaches in front of the palm: its centre's distance from the palm
    /// contact along the normal.
    depth: Real,
}

impl PalmContact {
    /// The palm contacts of `skill`, whose object starts at `start`.
    fn of(skill: &SkillSpec, start: &Isometry) -> PalmContact {
        let (mut centroid, mut normal, mut count) = (Vector::zeros(), Vector::zeros(), 0.0 as Real);
        for c in skill
            .contacts
            .iter()
            .filter(|c| c.part == ContactPart::Palm)
        {
            centroid += c.position_b;
            normal += c.normal_b.normalize();
            count += 1.0;
        }
        let normal = (normal / count.max(1.0))
            .try_normalize(1e-6)
            .unwrap_or_else(|| -Vector::z());
        PalmContact {
            n_w: start.rotation * normal,
            p_w: start * Point::from(centroid / count.max(1.0)),
            depth: (-(centroid / count.max(1.0))).dot(&normal).max(0.01),
        }
    }
}

/// Every palm placement's wrap (palm normals × rolls × shifts), best ranked first, and how
/// many placements there were.
fn ranked_wraps(
    hand: &HandModel,
    skill: &SkillSpec,
    palm: &PalmContact,
    stop: &Stop,
    kin: &mut Kinematics,
) -> Result<(Vec<Wrap>, usize)> {
    let mut wraps: Vec<Wrap> = Vec::new();
    let mut placed = 0usize;
    for posture in postures(hand, palm.depth, kin) {
        for k in 0..ROLLS {
            stop.check()?;
            let roll = k as Real * std::f64::consts::TAU / ROLLS as Real;
            for shift in SHIFTS {
                let Some(base) = place_palm(
                    hand, skill, &posture, &palm.n_w, &palm.p_w, roll, shift, kin,
                ) else {
                    continue;
                };
                placed += 1;
                wraps.extend(wrap(hand, skill, &posture, base, kin));
            }
        }
    }
    wraps.sort_by(|a, b| b.score.total_cmp(&a.score));
    Ok((wraps, placed))
}

/// What the plans of one power grasp's wraps share.
struct Planning<'a> {
    hand: &'a HandModel,
    thumb: usize,
    skill: &'a SkillSpec,
    params: &'a ReplayParams,
    /// The object's start pose.
    start: Isometry,
    /// The approach direction: the palm contacts' normal (world).
    approach: Vector,
}

impl Planning<'_> {
    /// The plan of a wrap, without its grip.
    fn plan_of(&self, w: &Wrap) -> Plan {
        let hand = self.hand;
        Plan {
            hand: hand.clone(),
            thumb: self.thumb,
            base_grasp: w.base,
            base_in_b0: self.start.inverse() * w.base,
            approach_dir: self.approach,
            q_grasp: w.q_touch,
            q_pre: w.q_open,
            contacts: vec![
                ContactFrame::from_normal(Vector::zeros(), Vector::z());
                hand.fingertips.len()
            ],
            active: vec![false; hand.fingertips.len()],
            ik_error: 0.0,
            quality: w.quality,
            force_times: Vec::new(),
            forces: Vec::new(),
            torque_map: nalgebra::DMatrix::zeros(hand.dof(), 0),
            failure: None,
            fails_at_rest: false,
            power: None,
        }
    }

    /// The plan of a wrap with its grip ([`plan_grip`]) and, if the grip cannot carry the
    /// load, how it fails.
    fn candidate(&self, w: &Wrap, kin: &mut Kinematics) -> Plan {
        let mut plan = self.plan_of(w);
        let (grip, failure) = plan_grip(self.hand, self.skill, self.params, w, kin);
        if let Some((reason, why, at_rest)) = failure {
            plan.failure = Some((reason, why));
            plan.fails_at_rest = at_rest;
        }
        plan.power = Some(PowerPlan {
            close: w.close,
            grip,
            contacts: w.contacts.clone(),
        });
        plan
    }

    /// Runs `plan` in the DFS to [`TRIAL_HELD_S`] into the held motion (at most: a skill an
    /// hour long costs its trials no more than a short one's); the share of that time the
    /// object was held.
    fn trial(&self, plan: &Plan, stop: &Stop) -> Result<Real> {
        let tl = self.skill.timeline();
        let until = (tl.grasp_end + TRIAL_HELD_S).min(tl.release_start);
        let mut trial = super::run::Replay::from_plan(plan.clone(), self.skill, self.params)?;
        while (trial.ticks_run() as Real) * super::run::DT < until && trial.step()? {
            if trial.ticks_run() % 100 == 0 {
                stop.check()?;
            }
        }
        Ok(trial.held_fraction(until))
    }

    /// The plan that refuses the replay when no wrap was found in the `placed` palm
    /// placements (none if 0).
    fn unreachable(&self, placed: usize) -> Plan {
        let why = if placed == 0 {
            "a power grasp: no pose of the hand puts its palm on the skill's palm contact with the \
             open hand touching the object by the palm first and above the table"
                .to_owned()
        } else {
            format!(
                "a power grasp: in none of the {placed} palm placements do the fingers, closing \
                 from the open hand, touch the object"
            )
        };
        Plan {
            failure: Some((FailureReason::Unreachable, why)),
            fails_at_rest: true,
            ..self.plan_of(&Wrap {
                score: 0.0,
                base: self.start,
                q_touch: [0.0; MAX_DOF],
                close: [0.0; MAX_DOF],
                q_open: [0.0; MAX_DOF],
                contacts: Vec::new(),
                touches: Vec::new(),
                quality: ReplayQuality {
                    epsilon: 0.0,
                    volume: 0.0,
                    force_closure: false,
                },
            })
        }
    }
}

/// The candidate palm normals and, for each, the open hand and the closing directions.
fn postures(hand: &HandModel, depth: Real, kin: &mut Kinematics) -> Vec<Posture> {
    let n = hand.dof();
    let mut q0 = [0.0; MAX_DOF];
    for d in 0..n {
        q0[d] = 0.0_f64.clamp(hand.dof_lower[d], hand.dof_upper[d]);
    }
    hand.forward_kinematics(&Isometry::identity(), &q0[..n], kin);
    hand.tip_jacobians(kin);
    let palm = palm_centre(hand, kin);
    let mut dirs: Vec<Vector> = Vec::new();
    for s in hand
        .contact_shapes
        .iter()
        .filter(|s| s.part == BodyPart::Palm)
    {
        let link = kin.link_poses[s.link].rotation;
        let axes = match s.primitive {
            ContactPrimitive::Box { pose, .. } => {
                let r = link * pose.rotation;
                vec![r * Vector::x(), r * Vector::y(), r * Vector::z()]
            }
            _ => vec![link * Vector::x(), link * Vector::y(), link * Vector::z()],
        };
        for a in axes {
            for v in [a, -a] {
                if dirs.iter().all(|d| d.dot(&v) < 0.98) {
                    dirs.push(v);
                }
            }
        }
    }
    let mut out = Vec::new();
    for g in dirs {
        let mut q_open = q0;
        let mut close = [0.0; MAX_DOF];
        for group in &hand.finger_groups {
            let flex: Vec<usize> = group
                .dofs
                .iter()
                .copied()
                .filter(|&d| !is_lateral(hand, kin, group.tips[0], d, &g, &palm))
                .collect();
            if flex.is_empty() {
                continue;
            }
            // Each flexing DOF closes toward where the object will be: `depth` out from
            // the palm's centre along `g`.
            let tip = group.tips[0];
            let target = palm + g * depth;
            for &d in &flex {
                let (lo, hi) = hand.sweep_range(d);
                let far = |v: Real, kin: &mut Kinematics| {
                    let mut q = q0;
                    q[d] = v;
                    hand.forward_kinematics(&Isometry::identity(), &q[..n], kin);
                    (kin.tip_centres[tip].coords - target).norm()
                };
                let open_low = far(lo, kin) >= far(hi, kin);
                q_open[d] = if open_low { lo } else { hi };
                close[d] = if open_low { 1.0 } else { -1.0 };
            }
        }
        hand.forward_kinematics(&Isometry::identity(), &q0[..n], kin);
        if close.iter().any(|&c| c != 0.0) {
            out.push(Posture { g, q_open, close });
        }
    }
    out
}

/// Whether DOF `d` spreads or twists the finger of fingertip `tip` rather than flexing it
/// toward the palm's side `g`, at the angles of `kin` (tip Jacobians computed): its joint turns
/// about an axis within 45° of `g`, or the finger lies across `g` (its tip not within 45° of
/// `g` seen from the palm's centre `palm`) and the DOF moves the tip across `g` too.
fn is_lateral(
    hand: &HandModel,
    kin: &Kinematics,
    tip: usize,
    d: usize,
    g: &Vector,
    palm: &Vector,
) -> bool {
    let about_g = hand.joints.iter().enumerate().any(|(j, joint)| {
        joint.drive.dof_and_gain().map(|x| x.0) == Some(d)
            && joint.kind != crate::hand::JointKind::Prismatic
            && kin.joint_axes[j].dot(g).abs() > LATERAL_COS
    });
    let jac = &kin.tip_jacobians[tip];
    let v = Vector::new(jac[(0, d)], jac[(1, d)], jac[(2, d)]);
    let f = kin.tip_centres[tip].coords - palm;
    let across = f.dot(g).abs() < LATERAL_COS * f.norm();
    about_g || v.norm() < 1e-6 || (across && v.dot(g).abs() < LATERAL_COS * v.norm())
}

/// The centre of the palm's contact shapes (world), with `kin` posed.
fn palm_centre(hand: &HandModel, kin: &Kinematics) -> Vector {
    let palm: Vec<Vector> = hand
        .contact_shapes
        .iter()
        .filter(|s| s.part == BodyPart::Palm)
        .map(|s| {
            let c = match s.primitive {
                ContactPrimitive::Sphere { centre, .. } => centre,
                ContactPrimitive::Capsule { a, b, .. } => 0.5 * (a + b),
                ContactPrimitive::Box { pose, .. } => pose.translation.vector,
            };
            (kin.link_poses[s.link] * Point::from(c)).coords
        })
        .collect();
    palm.iter().sum::<Vector>() / palm.len().max(1) as Real
}

/// The smallest gap (m) between the palm's shapes and the object, and between any shape or
/// fingertip of the hand and the object, with `kin` posed.
fn gaps(hand: &HandModel, skill: &SkillSpec, kin: &Kinematics) -> (Real, Real) {
    let inv = skill.start_pose().inverse();
    let (mut palm, mut all) = (Real::INFINITY, Real::INFINITY);
    for s in &hand.contact_shapes {
        let gap =
            closest_to_object(&s.primitive, &(inv * kin.link_poses[s.link]), &skill.shape).gap;
        all = all.min(gap);
        if s.part == BodyPart::Palm {
            palm = palm.min(gap);
        }
    }
    for (k, t) in hand.fingertips.iter().enumerate() {
        all = all.min(
            skill
                .shape
                .closest(&(inv * kin.tip_centres[k]).coords)
                .distance
                - t.radius,
        );
    }
    (palm, all)
}

/// The lowest point (world z, m) of the hand's fingertips and shape origins, with `kin` posed.
fn lowest(hand: &HandModel, kin: &Kinematics) -> Real {
    let tips = (0..hand.fingertips.len()).map(|k| kin.tip_centres[k].z - hand.fingertips[k].radius);
    let shapes = hand
        .contact_shapes
        .iter()
        .map(|s| kin.link_poses[s.link].translation.z);
    tips.chain(shapes).fold(Real::INFINITY, Real::min)
}

/// The base with `posture`'s palm normal along `n_w`, rolled by `roll` about it, its palm
/// centre on the line through `p_w` along `n_w`, slid in until the open hand touches the
/// object; `None` when the palm is not what touches, or the hand or its approach is below the
/// table.
#[allow(clippy::too_many_arguments)] // the placement's parts, each read once
fn place_palm(
    hand: &HandModel,
    skill: &SkillSpec,
    posture: &Posture,
    n_w: &Vector,
    p_w: &Point,
    roll: Real,
    shift: Real,
    kin: &mut Kinematics,
) -> Option<Isometry> {
    let n = hand.dof();
    let turn = Rotation::rotation_between(&posture.g, n_w).unwrap_or_else(|| {
        Rotation::from_axis_angle(
            &nalgebra::Unit::new_normalize(crate::math::perpendicular(
                &Vector::x(),
                &posture.g,
                &Vector::y(),
            )),
            std::f64::consts::PI,
        )
    });
    let rotation = Rotation::from_axis_angle(&nalgebra::Unit::new_normalize(*n_w), roll) * turn;
    // The palm's centre in the hand frame, open.
    hand.forward_kinematics(&Isometry::identity(), &posture.q_open[..n], kin);
    let centre = palm_centre(hand, kin);
    // Toward the fingers: from the palm's centre to the open fingertips' centroid, square to g.
    let tips = (0..hand.fingertips.len())
        .map(|k| kin.tip_centres[k].coords)
        .sum::<Vector>()
        / hand.fingertips.len().max(1) as Real;
    let reach = tips - centre;
    let toward = (reach - posture.g * posture.g.dot(&reach))
        .try_normalize(1e-9)
        .unwrap_or_else(Vector::zeros);
    let centre = centre + toward * shift;
    // The palm's centre `s` back from the contact point along the normal.
    let at = |s: Real| {
        let t = p_w.coords - n_w * s - rotation * centre;
        Isometry::from_parts(t.into(), rotation)
    };
    let (mut lo, mut hi) = (0.0, 0.3);
    let gap_at = |s: Real, kin: &mut Kinematics| {
        hand.forward_kinematics(&at(s), &posture.q_open[..n], kin);
        gaps(hand, skill, kin)
    };
    if gap_at(hi, kin).1 <= 0.0 || gap_at(lo, kin).1 > 0.0 {
        return None;
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if gap_at(mid, kin).1 > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let (palm_gap, all_gap) = gap_at(hi, kin);
    if palm_gap - all_gap > PALM_FIRST || lowest(hand, kin) < 0.0 {
        return None;
    }
    let base = at(hi);
    let mut back = base;
    back.translation.vector -= n_w * APPROACH;
    hand.forward_kinematics(&back, &posture.q_open[..n], kin);
    if lowest(hand, kin) < 0.0 || back.translation.z < 0.0 {
        return None;
    }
    Some(base)
}

/// The fingers of `posture` closed onto the object from the open hand at `base` until each
/// first touches, the contacts and the score; `None` without a force closure.
fn wrap(
    hand: &HandModel,
    skill: &SkillSpec,
    posture: &Posture,
    base: Isometry,
    kin: &mut Kinematics,
) -> Option<Wrap> {
    let n = hand.dof();
    let start = skill.start_pose();
    let inv = start.inverse();
    let mut q = posture.q_open;
    let mut close = [0.0; MAX_DOF];
    let mut contacts = Vec::new();
    let mut touches = Vec::new();
    // The palm's contact: its deepest shape.
    hand.forward_kinematics(&base, &q[..n], kin);
    let palm = hand
        .contact_shapes
        .iter()
        .filter(|s| s.part == BodyPart::Palm)
        .map(|s| {
            (
                s,
                closest_to_object(&s.primitive, &(inv * kin.link_poses[s.link]), &skill.shape),
            )
        })
        .min_by(|a, b| a.1.gap.total_cmp(&b.1.gap))?;
    contacts.push(PowerContact {
        name: palm.0.name.clone(),
        part: ContactPart::Palm,
        frame: ContactFrame::from_normal(palm.1.p_b, -palm.1.n_out_b),
    });
    for (gi, group) in hand.finger_groups.iter().enumerate() {
        let flex: Vec<usize> = group
            .dofs
            .iter()
            .copied()
            .filter(|&d| posture.close[d] != 0.0)
            .collect();
        if flex.is_empty() {
            continue;
        }
        if let Some(touch) = curl(hand, skill, posture, &base, gi, &flex, kin, &mut q) {
            for &d in &flex {
                close[d] = posture.close[d];
            }
            contacts.push(touch.0);
            touches.push((touch.1, touch.2, touch.3, flex));
        }
    }
    if touches.is_empty() {
        return None;
    }
    hand.forward_kinematics(&base, &q[..n], kin);
    if lowest(hand, kin) < 0.0 {
        return None;
    }
    let frames: Vec<ContactFrame> = contacts.iter().map(|c| c.frame).collect();
    // The quality of the first touches, for the ranking and the report: the fingers close
    // further in the DFS, wrapping the object, so it need not be a force closure yet.
    let quality = grasp_quality(
        &frames,
        skill.contact_model,
        &skill.friction,
        &QualityParams::default(),
    )
    .ok()?;
    // Wrap where the recorded hand did: each of its non-palm contacts near one of ours.
    let others: Vec<&Vector> = skill
        .contacts
        .iter()
        .filter(|c| c.part != ContactPart::Palm)
        .map(|c| &c.position_b)
        .collect();
    let spread = others
        .iter()
        .map(|p| {
            frames
                .iter()
                .map(|f| (f.p_b - *p).norm())
                .fold(Real::INFINITY, Real::min)
        })
        .sum::<Real>()
        / others.len().max(1) as Real;
    Some(Wrap {
        score: touches.len() as Real + quality.epsilon - spread,
        base,
        q_touch: q,
        close,
        q_open: posture.q_open,
        contacts,
        touches,
        quality: ReplayQuality {
            epsilon: quality.epsilon,
            volume: quality.volume,
            force_closure: quality.force_closure,
        },
    })
}

/// A finger's first touch closing its flexing DOFs `flex` together from open to closed (in `q`,
/// left at the touch, or open when it misses): the contact, the touching link, the point and
/// the inward normal in the world. `None` when it misses or touches already when open.
#[allow(clippy::too_many_arguments)] // the sweep's parts, each read once
fn curl(
    hand: &HandModel,
    skill: &SkillSpec,
    posture: &Posture,
    base: &Isometry,
    group: usize,
    flex: &[usize],
    kin: &mut Kinematics,
    q: &mut [Real; MAX_DOF],
) -> Option<(PowerContact, usize, Point, Vector)> {
    let n = hand.dof();
    let start = skill.start_pose();
    let inv = start.inverse();
    let tips = &hand.finger_groups[group].tips;
    let shapes: Vec<usize> = hand
        .contact_shapes
        .iter()
        .enumerate()
        .filter(
            |(_, s)| matches!(s.part, BodyPart::Phalanx { finger: Some(f) } if tips.contains(&f)),
        )
        .map(|(i, _)| i)
        .collect();
    // The finger's touch at `s` (0 open, 1 closed): its deepest shape or tip.
    let touch_at = |s: Real, q: &mut [Real; MAX_DOF], kin: &mut Kinematics| {
        for &d in flex {
            let (lo, hi) = hand.sweep_range(d);
            let open = posture.q_open[d];
            let closed = if posture.close[d] > 0.0 { hi } else { lo };
            q[d] = open + (closed - open) * s;
        }
        hand.forward_kinematics(base, &q[..n], kin);
        let mut best: Option<(Real, PowerContact, usize, Point, Vector)> = None;
        for &i in &shapes {
            let sh = &hand.contact_shapes[i];
            let c = closest_to_object(
                &sh.primitive,
                &(inv * kin.link_poses[sh.link]),
                &skill.shape,
            );
            if best.as_ref().is_none_or(|b| c.gap < b.0) {
                let normal = -c.n_out_b;
                best = Some((
                    c.gap,
                    PowerContact {
                        name: sh.name.clone(),
                        part: ContactPart::Phalanx,
                        frame: ContactFrame::from_normal(c.p_b, normal),
                    },
                    sh.link,
                    start * Point::from(c.p_b),
                    start.rotation * normal,
                ));
            }
        }
        for &k in tips {
            let centre = (inv * kin.tip_centres[k]).coords;
            let closest = skill.shape.closest(&centre);
            let gap = closest.distance - hand.fingertips[k].radius;
            if best.as_ref().is_none_or(|b| gap < b.0) {
                best = Some((
                    gap,
                    PowerContact {
                        name: hand.fingertips[k].name.clone(),
                        part: ContactPart::Fingertip,
                        frame: ContactFrame::from_normal(closest.point, -closest.normal),
                    },
                    hand.fingertips[k].link,
                    start * Point::from(closest.point),
                    start.rotation * -closest.normal,
                ));
            }
        }
        best
    };
    let open = *q;
    match touch_at(0.0, q, kin) {
        None => return None,
        // Touching already when open: that is its contact.
        Some((gap, contact, link, p, normal)) if gap <= 0.0 => {
            return Some((contact, link, p, normal))
        }
        Some(_) => {}
    }
    let mut prev = 0.0;
    for i in 1..=CURL_STEPS {
        let s = i as Real / CURL_STEPS as Real;
        if touch_at(s, q, kin).is_some_and(|b| b.0 <= 0.0) {
            let (mut out, mut inside) = (prev, s);
            for _ in 0..20 {
                let mid = 0.5 * (out + inside);
                if touch_at(mid, q, kin).is_some_and(|b| b.0 > 0.0) {
                    out = mid;
                } else {
                    inside = mid;
                }
            }
            let (_, contact, link, p, normal) = touch_at(out, q, kin)?;
            return Some((contact, link, p, normal));
        }
        prev = s;
    }
    *q = open;
    None
}

/// The grip ([module documentation](self)), and a failure: the reason, the sentence and
/// whether it is there already with the object at rest.
fn plan_grip(
    hand: &HandModel,
    skill: &SkillSpec,
    params: &ReplayParams,
    w: &Wrap,
    kin: &mut Kinematics,
) -> (Real, Option<(FailureReason, String, bool)>) {
    let n = hand.dof();
    hand.forward_kinematics(&w.base, &w.q_touch[..n], kin);
    let palm_normal = w
        .contacts
        .first()
        .map_or_else(Vector::zeros, |c| c.frame.normal_b());
    let start = skill.start_pose();
    let mut fingers = 0.0;
    let mut palm = 0.0;
    let mut jac = TipJacobian::zeros();
    for (link, p, normal, flex) in &w.touches {
        hand.point_jacobian(kin, *link, p, &mut jac);
        let (mut a_tau, mut a_a) = (0.0, 0.0);
        for &d in flex {
            let a = jac[(0, d)] * normal.x + jac[(1, d)] * normal.y + jac[(2, d)] * normal.z;
            a_tau += a * w.close[d] * hand.torque_limit[d];
            a_a += a * a;
        }
        let lambda = if a_a > 1e-12 {
            (a_tau / a_a).max(0.0)
        } else {
            0.0
        };
        fingers += lambda;
        palm -= lambda * (start.rotation.inverse() * normal).dot(&palm_normal);
    }
    let squeeze = fingers + palm.max(0.0);
    let gravity = Vector::new(0.0, 0.0, -crate::math::STANDARD_GRAVITY);
    let tl = skill.timeline();
    let rest = skill.mass * crate::math::STANDARD_GRAVITY;
    let mut peak = rest;
    let mut t = tl.grasp_end;
    while t <= tl.release_start {
        let l = super::plan::load_at(skill, t, &gravity);
        peak = peak.max(Vector::new(l[0], l[1], l[2]).norm());
        t += params.force_sample_s.max(0.01);
    }
    let mu = skill.friction.mu;
    let capacity = |margin: Real| mu * (1.0 - margin) * squeeze;
    if capacity(0.0) <= 0.0 || rest > capacity(0.0) {
        return (
            1.0,
            Some((
                FailureReason::TorqueLimit,
                format!(
                    "a power grasp: the fingers closing at their torque limits press with \
                     {squeeze:.1} N in all, whose friction (μ {mu:.2}) carries {:.1} N; the \
                     object weighs {rest:.1} N",
                    capacity(0.0)
                ),
                true,
            )),
        );
    }
    let grip = peak / capacity(params.friction_margin);
    if grip > 1.0 {
        return (
            1.0,
            Some((
                FailureReason::TorqueLimit,
                format!(
                    "a power grasp: carrying the load of the motion ({peak:.1} N) with a {:.0} % \
                     friction margin needs {:.0} % of the finger torque limits",
                    params.friction_margin * 100.0,
                    grip * 100.0
                ),
                false,
            )),
        );
    }
    ((2.0 * grip).clamp(MIN_GRIP, 1.0), None)
}
