//! Candidate base poses for a grasp with fingertips placed on targets: every fingertip on its
//! own contact, the thumb and the opposing fingers nearest it (the others curled onto the
//! surface), or the fingers named like the skill's contacts. Each roll about the grasp axis is
//! one candidate: its targets, the fingertip inverse kinematics that reaches for them, the
//! curl of the fingers not placed, and a score.

use crate::contact::ContactFrame;
use crate::error::Result;
use crate::grasp::quality::{grasp_quality, QualityParams};
use crate::hand::ik::{solve_tips, IkParams, IkResult};
use crate::hand::{HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{align, perpendicular, Isometry, Point, Real, Vector};
use crate::operator::{push_alignment, with_free_base};
use crate::replay::base_pose::{curl_onto, grasp_axis, mid_angles, sides, Candidate, ROLLS};
use crate::replay::{ReplayParams, SkillSpec};
use crate::stop::Stop;

/// Which fingertips the base pose and inverse kinematics place on targets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(in crate::replay) enum Keys {
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
pub(super) fn named_contacts(hand: &HandModel, skill: &SkillSpec) -> [Option<usize>; MAX_TIPS] {
    let mut named = [None; MAX_TIPS];
    for (k, tip) in hand.fingertips.iter().enumerate().take(MAX_TIPS) {
        named[k] = skill.contacts.iter().position(|c| c.finger == tip.name);
    }
    named
}

/// The grasp as the skill has it (B) and as the hand makes it at mid-range angles (hand
/// frame): what every roll of a search shares.
struct Layout {
    /// The skill's contacts on the side opposing the thumb.
    other_side: Vec<usize>,
    /// Centroid of the thumb-side contacts (B).
    thumb_c: Vector,
    /// Centroid of the opposing contacts (B).
    other_c: Vector,
    /// The skill's unit grasp axis, thumb side to the other (B).
    a_s: Vector,
    /// Mid-range joint angles.
    q_mid: [Real; MAX_DOF],
    /// The opposing fingertips placed on targets.
    others: Vec<usize>,
    /// Per fingertip: placed on a target (the thumb and `others`).
    key: [bool; MAX_TIPS],
    /// Per fingertip, the skill contact of its name ([`named_contacts`]).
    named: [Option<usize>; MAX_TIPS],
    /// The hand's unit grasp axis, its middle and the direction square to it (hand frame).
    a_h: Vector,
    m_h: Vector,
    d_h: Vector,
    /// The placed opposing fingertips ordered across the grasp axis, with their offsets from
    /// the middle.
    lateral: Vec<(usize, Real)>,
}

impl Layout {
    /// The layout for `keys`; `kin` is left with the hand at mid-range angles.
    fn new(
        hand: &HandModel,
        thumb: usize,
        skill: &SkillSpec,
        keys: Keys,
        kin: &mut Kinematics,
    ) -> Layout {
        let nt = hand.fingertips.len();
        let (_, other_side) = sides(skill);
        let (thumb_c, other_c, a_s) = grasp_axis(skill);
        // A two-fingertip hand pinches antipodally through the centre of mass, at its height:
        // the squeeze then makes no moment and gravity none about the contacts (the
        // recording's own contacts may be a few millimetres off that line).
        let (thumb_c, other_c, a_s) = if nt == 2 {
            skill.shape.antipodal_pair(&a_s)
        } else {
            (thumb_c, other_c, a_s)
        };
        // The hand's own grasp axis and approach direction at mid-range angles.
        let q_mid = mid_angles(hand);
        hand.forward_kinematics(&Isometry::identity(), &q_mid[..hand.dof()], kin);
        let p_t = kin.tip_centres[thumb].coords;
        // The opposing fingertips placed on targets: all, those nearest the thumb, or those
        // named like the skill's contacts.
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
        let mut lateral: Vec<(usize, Real)> = others
            .iter()
            .map(|&k| (k, (kin.tip_centres[k].coords - p_o).dot(&lat_h)))
            .collect();
        lateral.sort_by(|a, b| a.1.total_cmp(&b.1));
        Layout {
            other_side,
            thumb_c,
            other_c,
            a_s,
            q_mid,
            others,
            key,
            named,
            a_h,
            m_h,
            d_h,
            lateral,
        }
    }
}

/// Scored candidate base poses (rolls about the grasp axis), each with the joint angles from
/// fingertip inverse kinematics on the hand with a free base position for the fingertips
/// `keys` places, and the other fingers curled onto the surface ([`curl_onto`]).
pub(in crate::replay) fn plan_candidates(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    keys: Keys,
    stop: &Stop,
) -> Result<Vec<Candidate>> {
    let n_hand = hand.dof();
    let start = skill.start_pose();
    let mut kin = Kinematics::default();
    let layout = Layout::new(hand, thumb, skill, keys, &mut kin);
    let mut out = Vec::with_capacity(ROLLS);
    let ik = IkParams {
        max_iterations: 120,
        tolerance: 3e-4,
        ..IkParams::default()
    };
    let up_perp = perpendicular(&-Vector::z(), &layout.a_s, &Vector::x());
    let side = layout.a_s.cross(&up_perp);
    let inv_start = start.inverse();
    for r in 0..ROLLS {
        stop.check()?;
        let psi = r as Real * std::f64::consts::TAU / ROLLS as Real;
        let d_w = up_perp * psi.cos() + side * psi.sin();
        let rot = align(&layout.a_h, &layout.d_h, &layout.a_s, &d_w);
        let approach = d_w;
        if approach.z > 0.35 {
            continue; // the palm would come from below the table
        }
        let lat_w = layout.a_s.cross(&d_w);
        let mut targets = roll_targets(hand, thumb, skill, &layout, keys, &lat_w);
        let free = with_free_base(hand, rot);
        let n = free.dof();
        let mut q_start = [0.0; MAX_DOF];
        q_start[3..n].copy_from_slice(&layout.q_mid[..n_hand]);
        let centre = start.translation.vector;
        let base0 = centre - rot * layout.m_h;
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
            res = settle_on_surface(&free, skill, &ik, &mut targets, &mut kin, &mut q, res, stop)?;
        }
        // The fingers not placed curl until they meet the surface, or stay open out of it.
        let mut active = layout.key;
        for g in &hand.finger_groups {
            if g.tips.iter().any(|&k| layout.key[k]) || g.dofs.is_empty() {
                continue;
            }
            let dofs: Vec<usize> = g.dofs.iter().map(|&d| d + 3).collect();
            for &k in &g.tips {
                active[k] = curl_onto(&free, skill, &inv_start, k, &dofs, &mut kin, &mut q[..n]);
            }
        }
        free.forward_kinematics(&Isometry::identity(), &q[..n], &mut kin);
        let pose = Pose {
            rotation: rot,
            approach,
            q,
            active,
            ik_error: res.max_error,
        };
        out.push(score(hand, &free, skill, params, keys, &mut kin, pose));
    }
    Ok(out)
}

/// The fingertip targets (world) for one roll, whose lateral direction across the grasp axis
/// is `lat_w` (world): the thumb's first.
fn roll_targets(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    layout: &Layout,
    keys: Keys,
    lat_w: &Vector,
) -> Vec<(usize, Point)> {
    let nt = hand.fingertips.len();
    let start = skill.start_pose();
    let half_width = skill.shape.bounding_radius();
    let mut targets: Vec<(usize, Point)> = Vec::with_capacity(nt);
    let target_of = |k: usize, p_b: Vector| {
        let (p, n_in) = skill.shape.on_surface(&p_b);
        start * Point::from(p - n_in * hand.fingertips[k].radius)
    };
    if keys == Keys::Named {
        // Each placed fingertip on the contact of its own name.
        for &k in std::iter::once(&thumb).chain(&layout.others) {
            if let Some(i) = layout.named[k] {
                targets.push((k, target_of(k, skill.contacts[i].position_b)));
            }
        }
        return targets;
    }
    targets.push((thumb, target_of(thumb, layout.thumb_c)));
    let (lateral, other_side) = (&layout.lateral, &layout.other_side);
    if lateral.len() == other_side.len() && !other_side.is_empty() && nt != 2 {
        let mut skill_lat: Vec<(usize, Real)> = other_side
            .iter()
            .map(|&i| (i, skill.contacts[i].position_b.dot(lat_w)))
            .collect();
        skill_lat.sort_by(|a, b| a.1.total_cmp(&b.1));
        for ((k, _), (i, _)) in lateral.iter().zip(&skill_lat) {
            targets.push((*k, target_of(*k, skill.contacts[*i].position_b)));
        }
    } else {
        let mean = lateral.iter().map(|l| l.1).sum::<Real>() / lateral.len().max(1) as Real;
        for &(k, u) in lateral {
            // Spread over the opposing side's own face: a box's edge has the next face's
            // normal, square to the thumb's, and only friction opposes the thumb there.
            let dir = if u >= mean { *lat_w } else { -lat_w };
            let room = skill.shape.face_extent(
                &layout.other_c,
                &dir,
                0.8 * half_width,
                hand.fingertips[k].radius,
            );
            let off = (u - mean).abs().min(room);
            targets.push((k, target_of(k, layout.other_c + dir * off)));
        }
    }
    targets
}

/// The opposing fingers of an underactuated hand need only touch the surface near their
/// targets: each target (after the thumb's, which stays on its contact) moves to the surface
/// point nearest the tip (tip spheres resting on it) and the inverse kinematics of the hand
/// with a free base (`free`) runs again from `q`, at most 4 times.
#[allow(clippy::too_many_arguments)] // the state of one roll, passed on unchanged
fn settle_on_surface(
    free: &HandModel,
    skill: &SkillSpec,
    ik: &IkParams,
    targets: &mut [(usize, Point)],
    kin: &mut Kinematics,
    q: &mut [Real; MAX_DOF],
    mut res: IkResult,
    stop: &Stop,
) -> Result<IkResult> {
    let start = skill.start_pose();
    let inv_start = start.inverse();
    let n = free.dof();
    for _ in 0..4 {
        if res.max_error <= ik.tolerance {
            break;
        }
        stop.check()?;
        for (k, target) in targets.iter_mut().skip(1) {
            let c_b = (inv_start * kin.tip_centres[*k]).coords;
            let (p, n_in) = skill.shape.on_surface(&c_b);
            *target = start * Point::from(p - n_in * free.fingertips[*k].radius);
        }
        let q0 = *q;
        res = solve_tips(
            free,
            &Isometry::identity(),
            targets,
            &q0[..n],
            ik,
            kin,
            &mut q[..n],
        );
    }
    Ok(res)
}

/// Where one roll put the hand, before it is scored.
struct Pose {
    rotation: crate::math::Rotation,
    approach: Vector,
    /// Joint angles of the hand with a free base (the base position first).
    q: [Real; MAX_DOF],
    /// Per fingertip: it touches the object (placed, or curled onto it).
    active: [bool; MAX_TIPS],
    /// Largest distance of a placed fingertip from its target (m).
    ik_error: Real,
}

/// Scores one roll's pose: `kin` holds `free` (the hand with a free base) at `pose.q`.
fn score(
    hand: &HandModel,
    free: &HandModel,
    skill: &SkillSpec,
    params: &ReplayParams,
    keys: Keys,
    kin: &mut Kinematics,
    pose: Pose,
) -> Candidate {
    let nt = hand.fingertips.len();
    let inv_start = skill.start_pose().inverse();
    let Pose {
        rotation,
        approach,
        q,
        active,
        ik_error,
    } = pose;
    // Fingertips below the table top, or a base below it, are not a grasp.
    let below =
        (0..nt).any(|k| kin.tip_centres[k].z < hand.fingertips[k].radius - 0.002) || q[2] < 0.0;
    let mut error = ik_error;
    if below {
        error = error.max(1.0);
    }
    if keys == Keys::Named {
        // A finger the skill does not use, carried by a placed finger's coupled DOFs, must
        // stay out of the object: the demonstrator's did, or it would be a contact.
        let presses = (0..nt).any(|k| {
            let c_b = (inv_start * kin.tip_centres[k]).coords;
            !active[k] && skill.shape.closest(&c_b).distance < hand.fingertips[k].radius
        });
        if presses {
            error = error.max(1.0);
        }
    }
    free.tip_jacobians(kin);
    let mut align_min: Real = 1.0;
    let mut frames = Vec::with_capacity(nt);
    for k in (0..nt).filter(|&k| active[k]) {
        let c_b = (inv_start * kin.tip_centres[k]).coords;
        let (p, n_in) = skill.shape.on_surface(&c_b);
        frames.push(ContactFrame::from_normal(p, n_in));
        let n_world = skill.start_pose().rotation * n_in;
        align_min = align_min.min(push_alignment(free, kin, k, &n_world));
    }
    // Every tip on its own contact: the candidates' contacts are the same up to the IK error,
    // so their quality is computed once, for the chosen one (a Ferrari-Canny hull is most of
    // the planning time); curled grasps differ and need it here.
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
    // only slides over the surface (`pushes`). The demonstrator's own contacts on the fingers
    // of their names held in the recording, so there the real cone will do; but a finger
    // pushing outside even that cannot hold its contact whatever the forces (a one-DOF finger
    // meeting a box's face at a slant: its push turns the box, the thumb saturates, the box
    // falls).
    let pushes_at_all = align_min >= 1.0 / (1.0 + skill.friction.mu.powi(2)).sqrt();
    let ok = error <= params.reach_tolerance
        && match keys {
            Keys::All => true,
            Keys::Named => pushes_at_all,
            Keys::Nearest(_) => closure && pushes,
        };
    let reach_penalty = if ok { 0.0 } else { 10.0 };
    let score = -reach_penalty - 20.0 * error + align_min + 2.0 * eps - 0.3 * approach.z;
    Candidate {
        score,
        error,
        ok,
        align: align_min,
        rotation,
        approach,
        q_free: q,
        active,
    }
}
