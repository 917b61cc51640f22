//! Retargeting a skill onto a hand: contact assignment (and a new contact set when the finger
//! counts differ), the base pose, fingertip inverse kinematics and the force distribution with
//! exact friction cones and the hand's torque limits. See the module documentation of
//! [`crate::replay`].

use super::closing::closing_candidates;
use super::{FailureReason, PlannedContact, ReplayParams, ReplayQuality, SkillSpec};
use crate::contact::{ContactFrame, Intensity};
use crate::error::{DfsError, Result};
use crate::grasp::optimise::{ForceSolver, InfeasibleKind, OptimiseParams, TorqueLimits};
use crate::grasp::quality::{grasp_quality, QualityParams};
use crate::hand::ik::{solve_tips, IkParams};
use crate::hand::{HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Rotation, Vector, Wrench};
use crate::operator::{push_alignment, with_free_base};
use crate::scenario::MAX_SCRIPT_S;
use crate::stop::Stop;
use nalgebra::{DMatrix, Matrix3};

/// Rolls of the hand about the grasp axis tried when choosing the base pose.
pub(super) const ROLLS: usize = 12;

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
}

/// One candidate base pose.
pub(super) struct Candidate {
    pub(super) score: Real,
    /// Largest distance of a placed (key) fingertip from its target (m).
    pub(super) error: Real,
    /// The placed fingertips reach and, for a curled grasp, the contacts that result are a
    /// force closure the fingers can push into.
    pub(super) ok: bool,
    /// Smallest alignment of a contact's normal with the directions its finger can push in.
    pub(super) align: Real,
    pub(super) rotation: Rotation,
    pub(super) approach: Vector,
    pub(super) q_free: [Real; MAX_DOF],
    pub(super) active: [bool; MAX_TIPS],
}

/// Which fingertips the base pose and inverse kinematics place on targets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Keys {
    /// Every fingertip on its own contact.
    All,
    /// The thumb and this many opposing fingertips (those nearest the thumb); every other
    /// finger curls until it meets the surface, or stays out of the grasp.
    Nearest(usize),
    /// The fingertips named like the skill's contacts on those contacts (a skill replayed on
    /// a hand with its demonstrator's finger names, glove10 itself among them); a finger
    /// coupled to a placed one goes where the coupling takes it and must not press into the
    /// object, any other curls onto the surface or stays out of the grasp.
    Named,
}

/// Per fingertip of `hand`, the skill contact of the same finger name, if any.
fn named_contacts(hand: &HandModel, skill: &SkillSpec) -> [Option<usize>; MAX_TIPS] {
    let mut named = [None; MAX_TIPS];
    for (k, tip) in hand.fingertips.iter().enumerate().take(MAX_TIPS) {
        named[k] = skill.contacts.iter().position(|c| c.finger == tip.name);
    }
    named
}

/// Contacts of the skill on the thumb's side and on the opposing side.
pub(super) fn sides(skill: &SkillSpec) -> (Vec<usize>, Vec<usize>) {
    let n = skill.contacts.len();
    let thumb = skill
        .contacts
        .iter()
        .position(|c| c.finger == "thumb")
        .unwrap_or(0);
    let nt = skill.contacts[thumb].normal_b;
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for i in 0..n {
        if skill.contacts[i].normal_b.dot(&nt) > 0.5 {
            a.push(i);
        } else {
            b.push(i);
        }
    }
    (a, b)
}

/// Mid-range joint angles (infinite limits read as ±1).
pub(super) fn mid_angles(hand: &HandModel) -> [Real; MAX_DOF] {
    let mut q = [0.0; MAX_DOF];
    for d in 0..hand.dof() {
        let lo = hand.dof_lower[d].max(-1.0);
        let hi = hand.dof_upper[d].min(1.0).max(lo);
        q[d] = 0.5 * (lo + hi);
    }
    q
}

/// The point on the surface nearest `p_b` and the inward normal there, both in B.
pub(super) fn on_surface(skill: &SkillSpec, p_b: &Vector) -> (Vector, Vector) {
    let (_, point, outward) = skill.shape.closest(p_b);
    (point, -outward)
}

/// Rotation taking the orthonormal pair (a, d) of one frame onto (a', d') of another; the
/// identity when the pairs are not orthonormal (or not finite).
///
/// nalgebra's `from_matrix` iterates until it converges, without bound: on a matrix that is
/// not a rotation (NaN from a degenerate pair) it never returns. Here the matrix is checked
/// first and the iterations bounded ([`ALIGN_ITERATIONS`]; a rotation converges in a few).
pub(super) fn align(a_from: &Vector, d_from: &Vector, a_to: &Vector, d_to: &Vector) -> Rotation {
    let from = Matrix3::from_columns(&[*a_from, *d_from, a_from.cross(d_from)]);
    let to = Matrix3::from_columns(&[*a_to, *d_to, a_to.cross(d_to)]);
    let m = to * from.transpose();
    let rotation = m.iter().all(|v| v.is_finite())
        && (m.transpose() * m - Matrix3::identity()).amax() < 1e-6
        && m.determinant() > 0.0;
    if !rotation {
        return Rotation::identity();
    }
    Rotation::from_matrix_eps(&m, Real::EPSILON, ALIGN_ITERATIONS, Rotation::identity())
}

/// Most iterations of the rotation extraction in [`align`] (its input is a rotation matrix up
/// to rounding, which takes a handful).
const ALIGN_ITERATIONS: usize = 1000;

/// Unit vector of `v` with its component along unit `a` removed; `fallback`'s if that is ~0,
/// and if that is ~0 too (both along `a`), the coordinate axis most nearly square to `a`'s.
pub(super) fn perpendicular(v: &Vector, a: &Vector, fallback: &Vector) -> Vector {
    let off = |u: &Vector| u - a * a.dot(u);
    let p = off(v);
    if p.norm() > 1e-9 {
        return p.normalize();
    }
    let f = off(fallback);
    if f.norm() > 1e-15 {
        return f.normalize();
    }
    let axis = [Vector::x(), Vector::y(), Vector::z()]
        .into_iter()
        .min_by(|x, y| a.dot(x).abs().total_cmp(&a.dot(y).abs()))
        .unwrap_or_else(Vector::x);
    off(&axis).try_normalize(1e-12).unwrap_or_else(Vector::x)
}

/// Where the ray from the centre along unit `dir` leaves the surface (B), with the outward
/// normal there: bisection on the signed distance (the shapes are convex).
pub(super) fn surface_along(shape: &crate::object::Shape, dir: &Vector) -> (Vector, Vector) {
    let (mut lo, mut hi) = (0.0, shape.bounding_radius() * 1.01 + 1e-6);
    for _ in 0..48 {
        let mid = 0.5 * (lo + hi);
        if shape.closest(&(dir * mid)).0 < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let p = dir * hi;
    (p, shape.closest(&p).2)
}

/// How far (m, at most `limit`) a contact can move from the surface point nearest `p_b` along
/// unit `dir` (B) and stay at least `margin` inside the smooth part of the surface it starts
/// on: all the way, the surface within `margin` of the contact turns by less than 45° from the
/// normal at the contact (a box's face up to `margin` from its edges, a cylinder's side up to
/// `margin` from its rims; a sphere, or a cylinder's side around it, is never cut short).
/// Steps of 0.5 mm.
pub(super) fn face_extent(
    shape: &crate::object::Shape,
    p_b: &Vector,
    dir: &Vector,
    limit: Real,
    margin: Real,
) -> Real {
    const STEP: Real = 5e-4;
    let cos_45 = std::f64::consts::FRAC_1_SQRT_2;
    let inside = |q: &Vector| -> bool {
        let (_, point, n) = shape.closest(q);
        let t1 = perpendicular(&Vector::x(), &n, &Vector::y());
        let t2 = n.cross(&t1);
        [t1, -t1, t2, -t2]
            .iter()
            .all(|t| shape.closest(&(point + t * margin)).2.dot(&n) >= cos_45)
    };
    let mut s = 0.0;
    while s + STEP <= limit && inside(&(p_b + dir * (s + STEP))) {
        s += STEP;
    }
    if s + STEP > limit && inside(&(p_b + dir * limit)) {
        return limit;
    }
    s
}

/// Two antipodal contact points through the centre of mass for a pinch along `axis` (from the
/// thumb's side to the other): the axis is made horizontal (the contacts at the height of the
/// centre of mass, so gravity makes no moment about the line between them) and, where the
/// surface normal there is close to it, aligned with that normal (a box's face, a cylinder's
/// side), so the normals are opposite and on the line. Returns (thumb point, other point,
/// axis).
fn antipodal_pair(shape: &crate::object::Shape, axis: &Vector) -> (Vector, Vector, Vector) {
    let horizontal = Vector::new(axis.x, axis.y, 0.0);
    let mut a = if horizontal.norm() > 0.3 {
        horizontal.normalize()
    } else {
        *axis
    };
    let (_, n) = surface_along(shape, &a);
    if n.dot(&a) > 0.7 && (n.z.abs() < 1e-9 || horizontal.norm() <= 0.3) {
        a = n;
    }
    let (p_o, _) = surface_along(shape, &a);
    let (p_t, _) = surface_along(shape, &-a);
    (p_t, p_o, a)
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
    let nt = hand.fingertips.len();
    let best_of = |keys: Keys| -> Result<Option<Candidate>> {
        Ok(plan_candidates(hand, thumb, skill, params, keys, stop)?
            .into_iter()
            .max_by(|a, b| a.score.total_cmp(&b.score)))
    };
    // Every fingertip on its contact; failing that (an underactuated hand cannot put every
    // tip on an arbitrary point), the thumb and two, then one, opposing fingers placed and the
    // other fingers curled onto the surface.
    let mut best = best_of(Keys::All)?;
    // Why the curled grasps were refused, when every one was.
    let mut curled_refused = None;
    if !best.as_ref().is_some_and(|c| c.ok) && nt >= 3 {
        for n in [2, 1] {
            match best_of(Keys::Nearest(n))? {
                Some(c) if c.ok => {
                    best = Some(c);
                    curled_refused = None;
                    break;
                }
                Some(c) if c.error <= params.reach_tolerance && curled_refused.is_none() => {
                    curled_refused = Some((n, c.align));
                }
                _ => {}
            }
        }
    }
    // Failing those too (fingers that push only along their own motion, off the normals at
    // the skill's contacts), a grasp where the hand's fingers meet the object head-on.
    // Why that was refused too: the best one's alignment, or `None` when no position of the
    // object lets the thumb and another finger close onto it within the cones.
    let mut closing_refused: Option<Option<Real>> = None;
    if !best.as_ref().is_some_and(|c| c.ok) && nt >= 3 {
        let closing = closing_candidates(hand, thumb, skill, params, stop)?
            .into_iter()
            .max_by(|a, b| a.score.total_cmp(&b.score));
        match closing {
            Some(c) if c.ok => {
                best = Some(c);
                curled_refused = None;
            }
            c => closing_refused = Some(c.map(|c| c.align)),
        }
    }
    // Failing all of those, a hand with the demonstrator's finger names (glove10 replaying
    // its own skill, whose coupled fingers cannot each reach a contact of their own) takes
    // each contact on its own finger; the fingers the skill does not use go where their
    // coupling takes them, or curl. Last, so that no replay planned before changes.
    let named = named_contacts(hand, skill);
    let named_count = named.iter().flatten().count();
    // Why that was refused: the alignment of its worst finger's push with its normal.
    let mut named_refused: Option<Real> = None;
    if !best.as_ref().is_some_and(|c| c.ok)
        && named[thumb].is_some()
        && named_count == skill.contacts.len()
        && named_count >= 2
        && named_count < nt
    {
        match best_of(Keys::Named)? {
            Some(c) if c.ok => {
                best = Some(c);
                curled_refused = None;
                closing_refused = None;
            }
            Some(c) if c.error <= params.reach_tolerance => named_refused = Some(c.align),
            _ => {}
        }
    }
    let Some(best) = best else {
        return Err(DfsError::invalid("hand", "no candidate base pose"));
    };
    let best = &best;
    let reachable = best.ok;
    let start = skill.start_pose();
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
            let (p, n_in) = on_surface(skill, &c_b);
            ContactFrame::from_normal(p, n_in)
        })
        .collect();
    // Preshape: each fingertip out along its normal, base fixed, the common DOFs held.
    let mut grouped = [false; MAX_DOF];
    for g in &hand.finger_groups {
        for &d in &g.dofs {
            grouped[d] = true;
        }
    }
    let pre_targets: Vec<(usize, Point)> = (0..nt)
        .filter(|&k| active[k])
        .map(|k| {
            let c = &contacts[k];
            let out = -c.normal_b();
            let p = c.p_b + out * (hand.fingertips[k].radius + params.preshape_clearance);
            (k, start * Point::from(p))
        })
        .collect();
    stop.check()?;
    let pre_params = IkParams {
        max_iterations: 150,
        tolerance: 5e-4,
        ..IkParams::default()
    }
    .with_frozen((0..n_hand).filter(|&d| !grouped[d]));
    let mut q_pre = [0.0; MAX_DOF];
    solve_tips(
        hand,
        &base_grasp,
        &pre_targets,
        &q_grasp[..n_hand],
        &pre_params,
        &mut kin,
        &mut q_pre[..n_hand],
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
    let mut torque_map = DMatrix::<Real>::zeros(n_hand, 4 * active_contacts.len());
    for (i, k) in (0..nt).filter(|&k| active[k]).enumerate() {
        let c = &contacts[k];
        let j = &kin.tip_jacobians[k];
        let r = c.rot_b;
        // The force commanded for each intensity (the finger's own share of it).
        let dofs = hand
            .finger_groups
            .iter()
            .find(|g| g.tips.contains(&k))
            .map_or(&[][..], |g| &g.dofs[..]);
        let a = actuation_map(j, dofs, &c.normal_b());
        for d in 0..n_hand {
            let lin = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
            let ang = Vector::new(j[(3, d)], j[(4, d)], j[(5, d)]);
            for comp in 0..3 {
                let axis = r.matrix().column(comp).into_owned();
                let commanded = a.map_or(axis, |a| a * axis);
                torque_map[(d, 4 * i + comp)] = lin.dot(&commanded);
            }
            torque_map[(d, 4 * i + 3)] = ang.dot(&c.normal_b());
        }
    }
    let mut plan = Plan {
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
    };
    if !reachable {
        let mu = skill.friction.mu * (1.0 - params.friction_margin);
        let why = if let Some((n, align)) = curled_refused {
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
        let why = match closing_refused {
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
        let why = match named_refused {
            None => why,
            Some(align) => format!(
                "{why}; the fingers named like the skill's contacts reach them, but one pushes \
                 {:.1}° off its contact normal, outside even the friction cone ({:.1}°)",
                align.clamp(-1.0, 1.0).acos().to_degrees(),
                skill.friction.mu.atan().to_degrees()
            ),
        };
        plan.failure = Some((FailureReason::Unreachable, why));
        return Ok(plan);
    }
    plan_forces(&mut plan, skill, params, stop)?;
    Ok(plan)
}

/// The wrench (in B) the hand must apply at `t` for the reference motion: `m (a − g)`, with
/// `a` from central differences of the reference over ±25 ms. Moments are not planned.
pub(crate) fn load_at(skill: &SkillSpec, t: Real, gravity: &Vector) -> Wrench {
    let h = 0.025;
    let p = |t: Real| skill.reference(t).translation.vector;
    let a = (p(t + h) - p(t) * 2.0 + p(t - h)) / (h * h);
    let r = skill.reference(t).rotation;
    let f = r.inverse() * ((a - gravity) * skill.mass);
    Wrench::new(f.x, f.y, f.z, 0.0, 0.0, 0.0)
}

/// How a finger that cannot push in every direction realises a contact force: the force `a`
/// to command through its joint torques (`τ = Jᵀ a`) for the contact force `f`, as a matrix
/// `A` with `a = A f`, or `None` when the finger's linear Jacobian spans all three directions
/// (then `a = f`).
///
/// In the DFS the fingertip force is `(Jᵀ)⁺ τ`, in the range of the finger's Jacobian; what
/// is outside it (a finger with one actuated DOF pushes only along its motion) must come from
/// the contact's stick friction, which is tangential. So `a` is in that range and has the
/// planned normal component `nᵀ a = nᵀ f` (along the normal nothing else pushes: the normal
/// forces balance as planned), with its tangential part as close to the planned one as the
/// range allows; the rest of the planned tangential force is the stick friction's. `normal` is
/// the contact's unit normal, `j` the tip's Jacobian, `dofs` its finger's DOFs.
pub(crate) fn actuation_map(
    j: &crate::hand::TipJacobian,
    dofs: &[usize],
    normal: &Vector,
) -> Option<Matrix3<Real>> {
    let col = |d: usize| Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
    let scale = dofs.iter().map(|&d| col(d).norm()).fold(0.0, Real::max);
    let mut basis = [Vector::zeros(); 3];
    let mut nb = 0;
    for &d in dofs {
        let mut c = col(d);
        for b in &basis[..nb] {
            c -= b * b.dot(&c);
        }
        if nb < 3 && c.norm() > 1e-6 * scale && scale > 0.0 {
            basis[nb] = c.normalize();
            nb += 1;
        }
    }
    if nb == 3 {
        return None;
    }
    let p: Matrix3<Real> = basis[..nb].iter().map(|b| b * b.transpose()).sum();
    let pn = p * normal;
    // A finger that can hardly push along the normal is refused by the planner; the floor only
    // keeps this finite.
    let k = pn.norm_squared().max(1.0 / 16.0);
    Some(p + pn * (normal.transpose() * (Matrix3::identity() - p)) / k)
}

/// Fills the force schedule, and the failure when the cones or the torques cannot carry it;
/// [`DfsError::Cancelled`] when `stop` is set (looked at every sample).
fn plan_forces(
    plan: &mut Plan,
    skill: &SkillSpec,
    params: &ReplayParams,
    stop: &Stop,
) -> Result<()> {
    let tl = skill.timeline();
    let g = Vector::new(0.0, 0.0, -crate::math::STANDARD_GRAVITY);
    let opt = OptimiseParams {
        margin: params.friction_margin,
        min_normal: params.min_normal,
    };
    let limits = TorqueLimits {
        map: plan.torque_map.clone(),
        limits: plan.hand.torque_limit.clone(),
    };
    let tips: Vec<usize> = (0..plan.contacts.len())
        .filter(|&k| plan.active[k])
        .collect();
    let contacts: Vec<ContactFrame> = tips.iter().map(|&k| plan.contacts[k]).collect();
    // One solver each with and without the torque limits: the contacts stay, the load changes.
    let new_solver = |limits: Option<&TorqueLimits>| {
        ForceSolver::new(
            &contacts,
            skill.contact_model,
            &skill.friction,
            &opt,
            limits,
        )
    };
    let (mut cones_only, mut with_limits) = match (new_solver(None), new_solver(Some(&limits))) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e), _) | (_, Err(e)) => {
            plan.failure = Some((
                FailureReason::NoForceClosure,
                format!(
                    "the retargeted contacts cannot be planned for: {}",
                    e.reason
                ),
            ));
            return Ok(());
        }
    };
    let mut dist = vec![Intensity::zeros(); contacts.len()];
    // Static load first, without torque limits: can the contacts carry it at all?
    let static_load = load_at(skill, tl.grasp_start, &g);
    if let Err(e) = cones_only.solve_into(&static_load, &mut dist) {
        plan.fails_at_rest = true;
        let reason = match e.kind {
            InfeasibleKind::NoDistribution
            | InfeasibleKind::Solver
            | InfeasibleKind::InvalidInput => FailureReason::NoForceClosure,
        };
        plan.failure = Some((
            reason,
            format!(
                "the retargeted contacts cannot carry the object's weight inside their friction \
                 cones with a {:.0} % margin: {}",
                params.friction_margin * 100.0,
                e.reason
            ),
        ));
    }
    let mut t = tl.grasp_start;
    let step = params.force_sample_s.max(0.01);
    while t <= tl.release_start + 1e-9 {
        stop.check()?;
        let load = load_at(skill, t, &g);
        let solved = match with_limits.solve_into(&load, &mut dist) {
            Ok(_) => true,
            Err(e) => {
                plan.fails_at_rest |= t == tl.grasp_start;
                if plan.failure.is_none() {
                    plan.failure = Some((
                        FailureReason::TorqueLimit,
                        format!(
                            "carrying the load at t = {t:.2} s needs more joint torque than the \
                             hand's limits allow ({})",
                            e.reason
                        ),
                    ));
                }
                cones_only.solve_into(&load, &mut dist).is_ok()
            }
        };
        let mut row = [Intensity::zeros(); MAX_TIPS];
        if solved {
            for (&k, c) in tips.iter().zip(&dist) {
                row[k] = *c;
            }
        } else {
            // Nothing carries it: squeeze with the least normal force and let it slip.
            for &k in &tips {
                row[k][2] = params.min_normal;
            }
        }
        plan.force_times.push(t);
        plan.forces.push(row);
        t += step;
    }
    Ok(())
}

/// Scored candidate base poses (rolls about the grasp axis), each with the joint angles from
/// fingertip inverse kinematics on the hand with a free base position for the fingertips
/// `keys` places, and the other fingers curled onto the surface ([`curl_onto`]).
/// The skill's grasp axis: the centroid of its thumb-side contacts, of the others (the thumb's
/// mirror through the centre when there are none), and the unit axis from the first to the
/// second (B).
pub(super) fn grasp_axis(skill: &SkillSpec) -> (Vector, Vector, Vector) {
    let (thumb_side, other_side) = sides(skill);
    let centroid = |idx: &[usize]| -> Vector {
        idx.iter()
            .map(|&i| skill.contacts[i].position_b)
            .sum::<Vector>()
            / idx.len().max(1) as Real
    };
    let thumb_c = centroid(&thumb_side);
    let other_c = if other_side.is_empty() {
        -thumb_c
    } else {
        centroid(&other_side)
    };
    let a_s = (other_c - thumb_c)
        .try_normalize(1e-9)
        .unwrap_or_else(Vector::x);
    (thumb_c, other_c, a_s)
}

pub(super) fn plan_candidates(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    keys: Keys,
    stop: &Stop,
) -> Result<Vec<Candidate>> {
    let nt = hand.fingertips.len();
    let n_hand = hand.dof();
    let start = skill.start_pose();
    let (_, other_side) = sides(skill);
    let (thumb_c, other_c, a_s) = grasp_axis(skill);
    // A two-fingertip hand pinches antipodally through the centre of mass, at its height: the
    // squeeze then makes no moment and gravity none about the contacts (the recording's own
    // contacts may be a few millimetres off that line).
    let (thumb_c, other_c, a_s) = if nt == 2 {
        let (p_t, p_o, a) = antipodal_pair(&skill.shape, &a_s);
        (p_t, p_o, a)
    } else {
        (thumb_c, other_c, a_s)
    };
    // The hand's own grasp axis and approach direction at mid-range angles.
    let q_mid = mid_angles(hand);
    let mut kin = Kinematics::default();
    hand.forward_kinematics(&Isometry::identity(), &q_mid[..n_hand], &mut kin);
    let p_t = kin.tip_centres[thumb].coords;
    // The opposing fingertips placed on targets: all, those nearest the thumb, or those named
    // like the skill's contacts.
    let named = named_contacts(hand, skill);
    let mut others: Vec<usize> = (0..nt).filter(|&k| k != thumb).collect();
    if keys == Keys::Named {
        others.retain(|&k| named[k].is_some());
    }
    if let Keys::Nearest(n) = keys {
        others.sort_by(|&a, &b| {
            let d = |k: usize| (kin.tip_centres[k].coords - p_t).norm();
            d(a).total_cmp(&d(b))
        });
        others.truncate(n);
    }
    let mut key = [false; MAX_TIPS];
    key[thumb] = true;
    for &k in &others {
        key[k] = true;
    }
    let p_o = if others.is_empty() {
        p_t + Vector::x()
    } else {
        others
            .iter()
            .map(|&k| kin.tip_centres[k].coords)
            .sum::<Vector>()
            / others.len() as Real
    };
    let a_h = (p_o - p_t).try_normalize(1e-9).unwrap_or_else(Vector::x);
    let m_h = 0.5 * (p_t + p_o);
    let d_h = perpendicular(&m_h, &a_h, &Vector::z());
    let lat_h = a_h.cross(&d_h);
    // The placed fingertips ordered across the grasp axis, with their offsets from the middle.
    let mut lateral: Vec<(usize, Real)> = others
        .iter()
        .map(|&k| (k, (kin.tip_centres[k].coords - p_o).dot(&lat_h)))
        .collect();
    lateral.sort_by(|a, b| a.1.total_cmp(&b.1));
    let half_width = skill.shape.bounding_radius();
    let mut out = Vec::with_capacity(ROLLS);
    let ik = IkParams {
        max_iterations: 120,
        tolerance: 3e-4,
        ..IkParams::default()
    };
    let up_perp = perpendicular(&-Vector::z(), &a_s, &Vector::x());
    let side = a_s.cross(&up_perp);
    let inv_start = start.inverse();
    for r in 0..ROLLS {
        stop.check()?;
        let psi = r as Real * std::f64::consts::TAU / ROLLS as Real;
        let d_w = up_perp * psi.cos() + side * psi.sin();
        let rot = align(&a_h, &d_h, &a_s, &d_w);
        let approach = d_w;
        if approach.z > 0.35 {
            continue; // the palm would come from below the table
        }
        let lat_w = a_s.cross(&d_w);
        // Targets: tip centres in the world.
        let mut targets: Vec<(usize, Point)> = Vec::with_capacity(nt);
        let target_of = |k: usize, p_b: Vector| {
            let (p, n_in) = on_surface(skill, &p_b);
            start * Point::from(p - n_in * hand.fingertips[k].radius)
        };
        if keys == Keys::Named {
            // Each placed fingertip on the contact of its own name.
            for &k in std::iter::once(&thumb).chain(&others) {
                if let Some(i) = named[k] {
                    targets.push((k, target_of(k, skill.contacts[i].position_b)));
                }
            }
        } else {
            targets.push((thumb, target_of(thumb, thumb_c)));
            if lateral.len() == other_side.len() && !other_side.is_empty() && nt != 2 {
                let mut skill_lat: Vec<(usize, Real)> = other_side
                    .iter()
                    .map(|&i| (i, skill.contacts[i].position_b.dot(&lat_w)))
                    .collect();
                skill_lat.sort_by(|a, b| a.1.total_cmp(&b.1));
                for ((k, _), (i, _)) in lateral.iter().zip(&skill_lat) {
                    targets.push((*k, target_of(*k, skill.contacts[*i].position_b)));
                }
            } else {
                let mean = lateral.iter().map(|l| l.1).sum::<Real>() / lateral.len().max(1) as Real;
                for &(k, u) in &lateral {
                    // Spread over the opposing side's own face: a box's edge has the next
                    // face's normal, square to the thumb's, and only friction opposes the
                    // thumb there.
                    let dir = if u >= mean { lat_w } else { -lat_w };
                    let room = face_extent(
                        &skill.shape,
                        &other_c,
                        &dir,
                        0.8 * half_width,
                        hand.fingertips[k].radius,
                    );
                    let off = (u - mean).abs().min(room);
                    targets.push((k, target_of(k, other_c + dir * off)));
                }
            }
        }
        let free = with_free_base(hand, rot);
        let n = free.dof();
        let mut q_start = [0.0; MAX_DOF];
        q_start[3..n].copy_from_slice(&q_mid[..n_hand]);
        let centre = start.translation.vector;
        let base0 = centre - rot * m_h;
        q_start[..3].copy_from_slice(base0.as_slice());
        let mut q = [0.0; MAX_DOF];
        let mut res = solve_tips(
            &free,
            &Isometry::identity(),
            &targets,
            &q_start[..n],
            &ik,
            &mut kin,
            &mut q[..n],
        );
        if let Keys::Nearest(_) = keys {
            // The opposing fingers of an underactuated hand need only touch the surface near
            // their targets: each target moves to the surface point nearest the tip (tip
            // spheres resting on it), and the thumb stays on its contact.
            for _ in 0..4 {
                if res.max_error <= ik.tolerance {
                    break;
                }
                stop.check()?;
                for (k, target) in targets.iter_mut().skip(1) {
                    let c_b = (inv_start * kin.tip_centres[*k]).coords;
                    let (p, n_in) = on_surface(skill, &c_b);
                    *target = start * Point::from(p - n_in * hand.fingertips[*k].radius);
                }
                let q0 = q;
                res = solve_tips(
                    &free,
                    &Isometry::identity(),
                    &targets,
                    &q0[..n],
                    &ik,
                    &mut kin,
                    &mut q[..n],
                );
            }
        }
        // The fingers not placed curl until they meet the surface, or stay open out of it.
        let mut active = key;
        for g in &hand.finger_groups {
            if g.tips.iter().any(|&k| key[k]) || g.dofs.is_empty() {
                continue;
            }
            let dofs: Vec<usize> = g.dofs.iter().map(|&d| d + 3).collect();
            for &k in &g.tips {
                active[k] = curl_onto(&free, skill, &inv_start, k, &dofs, &mut kin, &mut q[..n]);
            }
        }
        free.forward_kinematics(&Isometry::identity(), &q[..n], &mut kin);
        // Fingertips below the table top, or a base below it, are not a grasp.
        let below =
            (0..nt).any(|k| kin.tip_centres[k].z < hand.fingertips[k].radius - 0.002) || q[2] < 0.0;
        let mut error = res.max_error;
        if below {
            error = error.max(1.0);
        }
        if keys == Keys::Named {
            // A finger the skill does not use, carried by a placed finger's coupled DOFs,
            // must stay out of the object: the demonstrator's did, or it would be a contact.
            let presses = (0..nt).any(|k| {
                let c_b = (inv_start * kin.tip_centres[k]).coords;
                !active[k] && skill.shape.closest(&c_b).0 < hand.fingertips[k].radius
            });
            if presses {
                error = error.max(1.0);
            }
        }
        free.tip_jacobians(&mut kin);
        let mut align_min: Real = 1.0;
        let mut frames = Vec::with_capacity(nt);
        for k in (0..nt).filter(|&k| active[k]) {
            let c_b = (inv_start * kin.tip_centres[k]).coords;
            let (p, n_in) = on_surface(skill, &c_b);
            frames.push(ContactFrame::from_normal(p, n_in));
            let n_world = start.rotation * n_in;
            align_min = align_min.min(push_alignment(&free, &kin, k, &n_world));
        }
        // Every tip on its own contact: the candidates' contacts are the same up to the IK
        // error, so their quality is computed once, for the chosen one (a Ferrari-Canny hull
        // is most of the planning time); curled grasps differ and need it here.
        let mu = skill.friction.mu * (1.0 - params.friction_margin);
        let pushes = align_min >= 1.0 / (1.0 + mu * mu).sqrt();
        let placed_all = matches!(keys, Keys::All | Keys::Named);
        let quality = if placed_all || error > params.reach_tolerance || !pushes {
            None
        } else {
            grasp_quality(
                &frames,
                skill.contact_model,
                &skill.friction,
                &QualityParams::default(),
            )
            .ok()
        };
        let eps = quality.map_or(0.0, |q| q.epsilon);
        let closure = quality.is_some_and(|q| q.force_closure && q.epsilon > 1e-3);
        // Every tip placed: reaching is enough (the force check follows); a curled grasp must
        // also hold.
        // A finger that cannot push along its contact normal within the planned friction cone
        // only slides over the surface (`pushes`). The demonstrator's own contacts on the
        // fingers of their names held in the recording, so there the real cone will do; but a
        // finger pushing outside even that cannot hold its contact whatever the forces (a
        // one-DOF finger meeting a box's face at a slant: its push turns the box, the thumb
        // saturates, the box falls).
        let pushes_at_all = align_min >= 1.0 / (1.0 + skill.friction.mu.powi(2)).sqrt();
        let ok = error <= params.reach_tolerance
            && match keys {
                Keys::All => true,
                Keys::Named => pushes_at_all,
                Keys::Nearest(_) => closure && pushes,
            };
        let reach_penalty = if ok { 0.0 } else { 10.0 };
        let score = -reach_penalty - 20.0 * error + align_min + 2.0 * eps - 0.3 * approach.z;
        out.push(Candidate {
            score,
            error,
            ok,
            align: align_min,
            rotation: rot,
            approach,
            q_free: q,
            active,
        });
    }
    Ok(out)
}

/// Curls the finger of fingertip `tip` (its DOFs `dofs`, all moved together from the end of
/// their range away from the object towards the other) until the tip touches the object's
/// surface; `q` then holds that first touch. A finger whose curl misses the object, or that
/// touches it even when open, is left open and `false` returned. `inv_start` maps the world
/// into B at the object's start pose.
pub(super) fn curl_onto(
    hand: &HandModel,
    skill: &SkillSpec,
    inv_start: &Isometry,
    tip: usize,
    dofs: &[usize],
    kin: &mut Kinematics,
    q: &mut [Real],
) -> bool {
    const STEPS: usize = 32;
    let radius = hand.fingertips[tip].radius;
    let mut gap = |q: &mut [Real], s: Real| -> Real {
        for &d in dofs {
            let (lo, hi) = hand.sweep_range(d);
            q[d] = lo + (hi - lo) * s;
        }
        hand.forward_kinematics(&Isometry::identity(), q, kin);
        skill
            .shape
            .closest(&(inv_start * kin.tip_centres[tip]).coords)
            .0
            - radius
    };
    let (g0, g1) = (gap(q, 0.0), gap(q, 1.0));
    let (open, closed) = if g0 >= g1 { (0.0, 1.0) } else { (1.0, 0.0) };
    if g0.max(g1) <= 0.0 {
        // In the object even when open.
        gap(q, open);
        return false;
    }
    let mut prev = open;
    for i in 1..=STEPS {
        let s = open + (closed - open) * i as Real / STEPS as Real;
        if gap(q, s) <= 0.0 {
            let (mut out, mut inside) = (prev, s);
            for _ in 0..20 {
                let mid = 0.5 * (out + inside);
                if gap(q, mid) > 0.0 {
                    out = mid;
                } else {
                    inside = mid;
                }
            }
            gap(q, out);
            return true;
        }
        prev = s;
    }
    gap(q, open);
    false
}

/// One retargeting step along the reference motion: fingertip inverse kinematics for the
/// hand's base at the reference pose (warm-started from the previous step's angles) and the
/// force distribution for the load there with cones and torque limits (one solver set up for
/// the plan's contacts, fed the new load each step). Allocation-free after [`new`](Self::new)
/// apart from the solver's own work.
#[derive(Debug)]
pub struct RetargetStep<'a> {
    plan: &'a Plan,
    skill: &'a SkillSpec,
    kin: Kinematics,
    solver: Option<ForceSolver>,
    targets_b: Vec<(usize, Point)>,
    targets: Vec<(usize, Point)>,
    forces: Vec<Intensity>,
    /// The joint angles of the last step.
    pub q: [Real; MAX_DOF],
}

impl<'a> RetargetStep<'a> {
    /// Starts at the plan's grasp angles.
    pub fn new(plan: &'a Plan, skill: &'a SkillSpec, params: &ReplayParams) -> Self {
        let targets_b = plan
            .contacts
            .iter()
            .enumerate()
            .filter(|(k, _)| plan.active[*k])
            .map(|(k, c)| {
                let r = plan.hand.fingertips[k].radius;
                (k, Point::from(c.p_b - c.normal_b() * r))
            })
            .collect::<Vec<_>>();
        let contacts: Vec<ContactFrame> =
            targets_b.iter().map(|&(k, _)| plan.contacts[k]).collect();
        let limits = TorqueLimits {
            map: plan.torque_map.clone(),
            limits: plan.hand.torque_limit.clone(),
        };
        let opt = OptimiseParams {
            margin: params.friction_margin,
            min_normal: params.min_normal,
        };
        let solver = ForceSolver::new(
            &contacts,
            skill.contact_model,
            &skill.friction,
            &opt,
            Some(&limits),
        )
        .ok();
        RetargetStep {
            plan,
            skill,
            kin: Kinematics::default(),
            solver,
            targets: targets_b.clone(),
            forces: vec![Intensity::zeros(); targets_b.len()],
            targets_b,
            q: plan.q_grasp,
        }
    }

    /// Retargets the reference at `t` (s since the replay's start): returns the IK error (m)
    /// and the intensities of the grasp's contacts (the fingertips in [`Plan::active`], in
    /// order; `None` when the cones and torques cannot carry the load there).
    pub fn step(&mut self, t: Real) -> (Real, Option<&[Intensity]>) {
        let obj = self.skill.reference(t);
        let base = obj * self.plan.base_in_b0;
        for (dst, src) in self.targets.iter_mut().zip(&self.targets_b) {
            *dst = (src.0, obj * src.1);
        }
        let n = self.plan.hand.dof();
        let ik = IkParams {
            max_iterations: 20,
            tolerance: 1e-4,
            ..IkParams::default()
        };
        let q0 = self.q;
        let r = solve_tips(
            &self.plan.hand,
            &base,
            &self.targets,
            &q0[..n],
            &ik,
            &mut self.kin,
            &mut self.q[..n],
        );
        let g = Vector::new(0.0, 0.0, -crate::math::STANDARD_GRAVITY);
        let load = load_at(self.skill, t, &g);
        let solved = self
            .solver
            .as_mut()
            .is_some_and(|s| s.solve_into(&load, &mut self.forces).is_ok());
        (r.max_error, solved.then_some(&self.forces[..]))
    }
}

impl Plan {
    /// The retargeted contacts for a report.
    pub fn planned_contacts(&self) -> Vec<PlannedContact> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::Shape;

    /// A serial chain's fingertips all lie on its axis at mid-range angles: the grasp axis and
    /// the fallback direction coincided, the rotation's matrix was NaN, and nalgebra's
    /// unbounded rotation extraction never returned.
    #[test]
    fn a_degenerate_grasp_axis_gives_a_rotation_at_once() {
        let z = Vector::z();
        let d = perpendicular(&(z * 0.1), &z, &Vector::z());
        assert!(
            (d.norm() - 1.0).abs() < 1e-12 && d.dot(&z).abs() < 1e-12,
            "{d}"
        );
        let nan = Vector::new(Real::NAN, 0.0, 0.0);
        assert_eq!(
            align(&z, &nan, &Vector::x(), &Vector::y()),
            Rotation::identity()
        );
        assert_eq!(
            align(&z, &Vector::zeros(), &Vector::x(), &Vector::y()),
            Rotation::identity()
        );
        // Orthonormal pairs: the rotation between them.
        let r = align(&Vector::x(), &Vector::y(), &Vector::y(), &-Vector::x());
        assert!((r * Vector::x() - Vector::y()).norm() < 1e-12);
        assert!((r * Vector::y() + Vector::x()).norm() < 1e-12);
    }

    #[test]
    fn a_pinch_of_a_sphere_is_antipodal_through_its_centre_at_its_height() {
        let shape = Shape::Sphere { radius: 0.04 };
        // The recording's axis dips 6° and is off the x axis.
        let axis = Vector::new(1.0, 0.2, -0.1).normalize();
        let (t, o, a) = antipodal_pair(&shape, &axis);
        assert!(a.z.abs() < 1e-12 && (a.norm() - 1.0).abs() < 1e-12);
        assert!((t + o).norm() < 1e-9, "{t} {o}");
        assert!((o.norm() - 0.04).abs() < 1e-9 && o.z.abs() < 1e-12);
        assert!(o.normalize().dot(&a) > 1.0 - 1e-9);
    }

    #[test]
    fn a_pinch_of_a_box_takes_the_centres_of_two_opposite_faces() {
        let shape = Shape::Box {
            half_extents: [0.025, 0.03, 0.04],
        };
        let axis = Vector::new(1.0, 0.15, 0.05).normalize();
        let (t, o, a) = antipodal_pair(&shape, &axis);
        assert!((a - Vector::x()).norm() < 1e-9, "{a}");
        assert!((o - Vector::new(0.025, 0.0, 0.0)).norm() < 1e-9, "{o}");
        assert!((t + o).norm() < 1e-9, "{t}");
    }

    #[test]
    fn a_spread_stays_a_margin_inside_a_box_face_and_is_not_cut_short_on_a_sphere() {
        let shape = Shape::Box {
            half_extents: [0.025, 0.025, 0.04],
        };
        let centre = Vector::new(0.025, 0.0, 0.01);
        // Along y the +x face ends 25 mm away: 15 mm leaves a 10 mm fingertip on the face.
        let y = face_extent(&shape, &centre, &Vector::y(), 0.05, 0.01);
        assert!((y - 0.015).abs() <= 5e-4, "{y}");
        let down = face_extent(&shape, &centre, &-Vector::z(), 0.05, 0.01);
        assert!((down - 0.04).abs() <= 5e-4, "{down}");
        // Diagonally, the nearer edge counts.
        let d = Vector::new(0.0, 1.0, 1.0).normalize();
        let diag = face_extent(&shape, &centre, &d, 0.05, 0.01);
        assert!((diag * d.y - 0.015).abs() <= 5e-4, "{diag}");
        // A sphere curves but has no edge: the limit.
        let sphere = Shape::Sphere { radius: 0.04 };
        let s = face_extent(
            &sphere,
            &Vector::new(0.04, 0.0, 0.0),
            &Vector::y(),
            0.032,
            0.012,
        );
        assert_eq!(s, 0.032);
    }

    #[test]
    fn a_curling_finger_stops_where_its_tip_first_touches_the_surface() {
        let hand = crate::hand::builtin_hand("inspire").unwrap();
        let skill = SkillSpec {
            shape: Shape::Sphere { radius: 0.04 },
            mass: 0.3,
            friction: crate::contact::Friction::default(),
            contact_model: crate::contact::ContactModel::SoftFinger,
            contacts: Vec::new(),
            motion: Vec::new(),
            phases: Vec::new(),
            held_until_s: None,
        };
        let index = hand
            .fingertips
            .iter()
            .position(|t| t.name == "index")
            .unwrap();
        let group = hand
            .finger_groups
            .iter()
            .find(|g| g.tips.contains(&index))
            .unwrap();
        let mut kin = Kinematics::default();
        let mut q = [0.0; MAX_DOF];
        let n = hand.dof();
        // Put the sphere in front of the open index fingertip, 2 cm further out along the palm
        // normal than the tip, where the curling finger sweeps through it.
        let half = |q: &mut [Real; MAX_DOF]| {
            for &d in &group.dofs {
                q[d] = 0.5 * (hand.dof_lower[d] + hand.dof_upper[d]);
            }
        };
        half(&mut q);
        hand.forward_kinematics(&Isometry::identity(), &q[..n], &mut kin);
        let tip_half = kin.tip_centres[index].coords;
        let centre = tip_half + tip_half.normalize() * 0.045;
        let inv = Isometry::translation(-centre.x, -centre.y, -centre.z);
        let touches = curl_onto(
            &hand,
            &skill,
            &inv,
            index,
            &group.dofs,
            &mut kin,
            &mut q[..n],
        );
        assert!(touches);
        hand.forward_kinematics(&Isometry::identity(), &q[..n], &mut kin);
        let gap =
            (kin.tip_centres[index].coords - centre).norm() - 0.04 - hand.fingertips[index].radius;
        assert!((0.0..1e-4).contains(&gap), "{gap}");
        // Far away, the curl misses and the finger is left open, out of the grasp.
        let far = Isometry::translation(-1.0, 0.0, 0.0);
        assert!(!curl_onto(
            &hand,
            &skill,
            &far,
            index,
            &group.dofs,
            &mut kin,
            &mut q[..n]
        ));
    }

    #[test]
    fn a_finger_that_pushes_only_along_its_motion_is_commanded_the_planned_normal_force() {
        let mut j = crate::hand::TipJacobian::zeros();
        // One DOF moving the tip along c, 20° off the normal.
        let angle: Real = 20f64.to_radians();
        let normal = Vector::z();
        let c = Vector::new(angle.sin(), 0.0, angle.cos()) * 0.08;
        for r in 0..3 {
            j[(r, 2)] = c[r];
        }
        let f = Vector::new(0.3, -0.2, 2.0);
        let a = actuation_map(&j, &[2], &normal).unwrap() * f;
        // Along the finger's motion, with the planned normal component.
        assert!(a.cross(&c).norm() < 1e-12, "{a}");
        assert!((a.dot(&normal) - f.dot(&normal)).abs() < 1e-12);
        // Two DOFs: in their plane, same normal component, the tangential part nearest f's.
        j[(1, 3)] = 0.05;
        let a = actuation_map(&j, &[2, 3], &normal).unwrap() * f;
        assert!(a.dot(&c.cross(&Vector::y())).abs() < 1e-12, "{a}");
        assert!((a.dot(&normal) - f.dot(&normal)).abs() < 1e-12);
        assert!((a.y - f.y).abs() < 1e-12);
        // A finger that pushes in every direction is commanded the force itself.
        j[(0, 4)] = 0.07;
        assert!(actuation_map(&j, &[2, 3, 4], &normal).is_none());
    }
}
