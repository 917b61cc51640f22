//! Grasps planned from the hand's own closing motion, the last resort of step 2 (base pose) of
//! [`crate::replay`] when neither every fingertip nor the thumb and its nearest fingers can be
//! put on the skill's contacts so that they push into the object.
//!
//! In the DFS a fingertip force comes from joint torques through `Jᵀ`, so it lies in the range
//! of the finger's Jacobian. A finger with one actuated DOF (mimic-coupled joints) pushes only
//! along its own motion direction; placed on an arbitrary contact it pushes off the normal,
//! outside the friction cone, and slides. So instead of asking where the skill touched, this
//! asks where the hand's fingers meet the object head-on:
//!
//! 1. **Closing paths** (hand frame, once per plan). Each single-tip finger's DOFs are swept
//!    together from one end of their range to the other; a finger with more DOFs holds its
//!    first one at a few preset values and sweeps the others. Each sample keeps the tip centre
//!    and the directions the finger can push in ([`crate::operator::push_alignment`]'s basis).
//! 2. **Object positions** (hand frame), with the object in a given orientation there. Where a
//!    finger pushes exactly along the normal, the
//!    object's centre lies on the finger's motion line, the object's depth ahead of the tip:
//!    one candidate per sample of every finger but the thumb, and the midpoints of two
//!    fingers' candidates (a pair side by side, both slightly off their lines). For each
//!    candidate, every finger closes from its open end until the tip first touches the
//!    surface; a finger whose push there lies within the planned friction cone (μ (1 − margin),
//!    half-angle α) of the normal takes part, the others stay open (and must then clear the
//!    object by 3 mm). Of the thumb's paths that push within the cone, the one whose normal
//!    best balances the others' is taken: δ, the distance of the normals' convex hull from the
//!    origin, is 0 when normal forces alone can balance and must stay below sin α (beyond it
//!    no forces in the cones balance). Candidates are scored by the worst alignment of a
//!    finger's push with its normal (cosine of the angle) minus δ, plus a little per finger
//!    taking part; the best few are refined by a pattern search over the position.
//! 3. **Base pose** (world). A sphere looks the same from every side: its hand-frame grasps
//!    are found once, and as for the other grasps the grasp's own axis (thumb contact to the
//!    centroid of the others) is aligned with the skill's and rolls about it are tried (the
//!    palm not from below the table). Any other shape is not: the rolls come first (the hand's
//!    own axis, thumb tip to the other fingertips at mid-range angles, along the skill's), and
//!    each roll's hand-frame grasps are found with the object in the orientation that roll
//!    gives it in the hand (a box probed along the hand's own axes and then turned with the
//!    hand met the fingers at other angles than probed: Inspire found no grasp of a box or a
//!    cylinder, glove10 none of its own cylinder). In each, the fingers close onto the object
//!    at its start pose in the world, and the grasp counts only when every finger taking part
//!    still pushes within the cone, δ < sin α, no fingertip or the base is below the table,
//!    the open fingers clear the object and the approach (the preshaped hand moving in along
//!    the approach direction) touches nothing. The best that counts must also be a force closure
//!    inside the planned cones (Ferrari-Canny ε > 1e-3 with μ (1 − margin): one hull, more only
//!    when it fails).
//!
//! The planned forces then carry the load with the normal components the fingers push and the
//! tangential rest from stick friction ([`super::plan::actuation_map`]).

use super::base_pose::{curl_onto, grasp_axis, mid_angles, Candidate, ROLLS};
use super::{ReplayParams, SkillSpec};
use crate::contact::ContactFrame;
use crate::error::Result;
use crate::grasp::quality::{grasp_quality, QualityParams};
use crate::hand::{HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{align, perpendicular, Isometry, Point, Real, Rotation, Vector};
use crate::object::Shape;
use crate::operator::{push_alignment, push_basis, with_free_base};
use crate::stop::Stop;

/// Samples along one closing path.
const SAMPLES: usize = 48;
/// Preset values of the first DOF of a finger with several.
const PRESETS: usize = 7;
/// Hand-frame grasps carried on to the world stage.
const KEEP: usize = 3;
/// Open fingers keep at least this far from the object (m).
const CLEARANCE: Real = 0.003;
/// How far the preshaped hand moves in along the approach direction (m); see `run`.
const APPROACH: Real = 0.08;
/// Object centres probed between two looks at the [`Stop`]: a probe closes every path (up to
/// 42 on a hand of six multi-joint fingers, 48 samples each), so 64 probes are a few ms
/// (at most 30 ms on a loaded machine for a 30-DOF hand).
const PROBES_PER_CHECK: usize = 64;
/// Most improving moves of the pattern search ([`Probe::refine`]) per step size: each moves
/// the centre by the step, so 64 of the smallest (0.5 mm) are 3 cm, beyond any refinement.
const REFINE_MOVES: usize = 64;

/// One closing path of a finger, sampled in the hand frame.
struct Path {
    tip: usize,
    /// The finger's DOF held fixed, with its value.
    preset: Option<(usize, Real)>,
    /// The DOFs swept together, from their lower limits (s = 0) to their upper ones (s = 1).
    swept: Vec<usize>,
    /// Tip centre per sample.
    p: Vec<Vector>,
    /// Push basis per sample.
    basis: Vec<([Vector; 3], usize)>,
}

impl Path {
    fn s(i: usize) -> Real {
        i as Real / (SAMPLES - 1) as Real
    }

    /// Sets the path's DOFs in `q` (hand DOFs, shifted by `shift`) at `s`.
    fn set(&self, hand: &HandModel, s: Real, shift: usize, q: &mut [Real]) {
        if let Some((d, v)) = self.preset {
            q[d + shift] = v;
        }
        for &d in &self.swept {
            let (lo, hi) = hand.sweep_range(d);
            q[d + shift] = lo + (hi - lo) * s;
        }
    }
}

/// Where a path first touches the object, closing from its open end.
#[derive(Debug, Clone, Copy)]
struct Touch {
    path: usize,
    /// Alignment of the push with the normal there (cosine).
    align: Real,
    /// Path parameter at the touch.
    s: Real,
    /// Contact point on the surface and inward normal (hand frame).
    point: Vector,
    normal: Vector,
}

/// A grasp in the hand frame: the object's centre and which paths touch it.
#[derive(Debug, Clone)]
struct HandGrasp {
    centre: Vector,
    score: Real,
    /// Distance of the contact normals' convex hull from the origin (0: they balance).
    delta: Real,
    touches: [Option<Touch>; MAX_TIPS],
    /// Per fingertip not taking part: the path and end it stays open at.
    open: [Option<(usize, Real)>; MAX_TIPS],
}

/// The object in the hand frame: shape, orientation and centre.
struct Probe<'a> {
    shape: &'a Shape,
    /// Rotation of B in the hand frame.
    orient: Rotation,
    paths: &'a [Path],
    radius: &'a [Real],
    thumb: usize,
    tips: &'a [usize],
    need: Real,
    /// Sine of the planned cone's half-angle.
    need_sin: Real,
}

impl Probe<'_> {
    fn gap(&self, centre: &Vector, p: &Vector, tip: usize) -> Real {
        self.shape
            .closest(&self.orient.inverse_transform_vector(&(p - centre)))
            .distance
            - self.radius[tip]
    }

    /// Path `pi` closing from its open end (the end farther from the surface): that end and
    /// its gap, and where the tip first touches the object, if it does.
    fn touch(&self, centre: &Vector, pi: usize) -> (Real, Real, Option<Touch>) {
        let path = &self.paths[pi];
        let g0 = self.gap(centre, &path.p[0], path.tip);
        let g1 = self.gap(centre, &path.p[SAMPLES - 1], path.tip);
        let (from_start, open_gap, open_s) = if g0 >= g1 {
            (true, g0, 0.0)
        } else {
            (false, g1, 1.0)
        };
        if open_gap <= 0.0 {
            return (open_s, open_gap, None);
        }
        let idx = |j: usize| if from_start { j } else { SAMPLES - 1 - j };
        let mut prev = open_gap;
        for j in 1..SAMPLES {
            let i = idx(j);
            let g = self.gap(centre, &path.p[i], path.tip);
            if g <= 0.0 {
                let a = prev / (prev - g).max(1e-12);
                let ip = idx(j - 1);
                let p = path.p[ip] + (path.p[i] - path.p[ip]) * a;
                let closest = self
                    .shape
                    .closest(&self.orient.inverse_transform_vector(&(p - centre)));
                let (point, normal) =
                    (self.orient * closest.point, -(self.orient * closest.normal));
                let (b, nb) = &path.basis[if a < 0.5 { ip } else { i }];
                let align = b
                    .iter()
                    .take(*nb)
                    .map(|b| b.dot(&normal).powi(2))
                    .sum::<Real>()
                    .sqrt();
                let s = Path::s(ip) + (Path::s(i) - Path::s(ip)) * a;
                let touch = Touch {
                    path: pi,
                    align,
                    s,
                    point: point + centre,
                    normal,
                };
                return (open_s, open_gap, Some(touch));
            }
            prev = g;
        }
        (open_s, open_gap, None)
    }

    /// The grasp with the object's centre at `centre`, or `None` when the thumb or every other
    /// finger fails to push into it, or a finger can neither push nor stay clear of it.
    fn grasp(&self, centre: &Vector) -> Option<HandGrasp> {
        let mut touches = [None; MAX_TIPS];
        let mut open = [None; MAX_TIPS];
        for &k in self.tips.iter().filter(|&&k| k != self.thumb) {
            let mut best: Option<Touch> = None;
            let mut clear: Option<(usize, Real, Real)> = None;
            for (pi, path) in self.paths.iter().enumerate() {
                if path.tip != k {
                    continue;
                }
                let (end, g, touch) = self.touch(centre, pi);
                if let Some(t) = touch {
                    if best.is_none_or(|b| t.align > b.align) {
                        best = Some(t);
                    }
                }
                if clear.is_none_or(|c| g > c.2) {
                    clear = Some((pi, end, g));
                }
            }
            match best {
                Some(t) if t.align >= self.need => touches[k] = Some(t),
                _ => match clear {
                    Some((pi, end, g)) if g >= CLEARANCE => open[k] = Some((pi, end)),
                    _ => return None,
                },
            }
        }
        // The thumb: of its paths that push into the object, the one that best opposes the
        // other fingers (the normals' hull nearest the origin).
        let mut normals = [Vector::zeros(); MAX_TIPS];
        let mut m = 0;
        for t in touches.iter().flatten() {
            normals[m] = t.normal;
            m += 1;
        }
        if m == 0 {
            return None;
        }
        let mut thumb: Option<(Touch, Real)> = None;
        for pi in (0..self.paths.len()).filter(|&pi| self.paths[pi].tip == self.thumb) {
            let Some(t) = self.touch(centre, pi).2.filter(|t| t.align >= self.need) else {
                continue;
            };
            normals[m] = t.normal;
            let delta = hull_distance(&normals[..=m]);
            if thumb.is_none_or(|(b, d)| t.align - delta > b.align - d) {
                thumb = Some((t, delta));
            }
        }
        let (t, delta) = thumb?;
        touches[self.thumb] = Some(t);
        let worst = touches
            .iter()
            .flatten()
            .map(|t| t.align)
            .fold(1.0, Real::min);
        Some(HandGrasp {
            centre: *centre,
            score: worst - delta + 0.02 * (m + 1) as Real,
            delta,
            touches,
            open,
        })
    }

    /// Pattern search on the centre from `g` (steps of 4, 2, 1 and 0.5 mm, at most
    /// [`REFINE_MOVES`] moves each).
    fn refine(&self, mut g: HandGrasp) -> HandGrasp {
        for step in [0.004, 0.002, 0.001, 0.0005] {
            for _ in 0..REFINE_MOVES {
                let mut improved = false;
                for axis in 0..3 {
                    for sign in [1.0, -1.0] {
                        let mut c = g.centre;
                        c[axis] += sign * step;
                        if let Some(h) = self.grasp(&c) {
                            if h.score > g.score + 1e-6 {
                                g = h;
                                improved = true;
                            }
                        }
                    }
                }
                if !improved {
                    break;
                }
            }
        }
        g
    }
}

/// Distance from the origin to the convex hull of `points` (Frank-Wolfe on the simplex weights;
/// a few points, accurate to about 1e-3).
fn hull_distance(points: &[Vector]) -> Real {
    let mut x = points.iter().sum::<Vector>() / points.len().max(1) as Real;
    for _ in 0..64 {
        let Some(v) = points.iter().min_by(|a, b| a.dot(&x).total_cmp(&b.dot(&x))) else {
            break;
        };
        let d = v - x;
        let dd = d.norm_squared();
        if dd < 1e-14 {
            break;
        }
        x += d * (-x.dot(&d) / dd).clamp(0.0, 1.0);
    }
    x.norm()
}

/// The closing paths of every single-tip finger, sampled at the hand's base (identity), the
/// DOFs outside finger groups at mid range.
fn closing_paths(hand: &HandModel, q_rest: &[Real]) -> Vec<Path> {
    let n = hand.dof();
    let mut kin = Kinematics::default();
    let mut q = [0.0; MAX_DOF];
    let mut out = Vec::new();
    for g in &hand.finger_groups {
        let ([tip], false) = (g.tips.as_slice(), g.dofs.is_empty()) else {
            continue;
        };
        let presets: Vec<Option<(usize, Real)>> = if g.dofs.len() == 1 {
            vec![None]
        } else {
            let d = g.dofs[0];
            (0..PRESETS)
                .map(|i| {
                    let (lo, hi) = hand.sweep_range(d);
                    let v = lo + (hi - lo) * i as Real / (PRESETS - 1) as Real;
                    Some((d, v))
                })
                .collect()
        };
        for preset in presets {
            let swept: Vec<usize> = g
                .dofs
                .iter()
                .copied()
                .filter(|&d| preset.is_none_or(|(p, _)| p != d))
                .collect();
            let mut path = Path {
                tip: *tip,
                preset,
                swept,
                p: Vec::with_capacity(SAMPLES),
                basis: Vec::with_capacity(SAMPLES),
            };
            for i in 0..SAMPLES {
                q[..n].copy_from_slice(&q_rest[..n]);
                path.set(hand, Path::s(i), 0, &mut q);
                hand.forward_kinematics(&Isometry::identity(), &q[..n], &mut kin);
                hand.tip_jacobians(&mut kin);
                path.p.push(kin.tip_centres[*tip].coords);
                path.basis.push(push_basis(hand, &kin, *tip));
            }
            out.push(path);
        }
    }
    out
}

/// The hand-frame grasps of the object as `probe` holds it: object centres on the fingers'
/// motion lines, the object's depth ahead of the tip, and midway between two fingers' such
/// centres; the best few distinct ones refined, those whose normals can balance inside the
/// planned cones kept (at most [`KEEP`]). [`crate::DfsError::Cancelled`] when `stop` is set
/// (looked at every [`PROBES_PER_CHECK`] centres).
fn hand_grasps(
    probe: &Probe<'_>,
    paths: &[Path],
    radius: &[Real],
    stop: &Stop,
) -> Result<Vec<HandGrasp>> {
    let mut heads: Vec<Vec<Vector>> = Vec::new();
    for path in paths.iter().filter(|p| p.tip != probe.thumb) {
        let mut h = Vec::with_capacity(2 * SAMPLES);
        for i in 1..SAMPLES - 1 {
            let Some(m) = (path.p[i + 1] - path.p[i - 1]).try_normalize(1e-9) else {
                continue;
            };
            for dir in [m, -m] {
                let dir_b = probe.orient.inverse_transform_vector(&-dir);
                let depth = probe.shape.surface_along(&dir_b).0.norm();
                h.push(path.p[i] + dir * (radius[path.tip] + depth));
            }
        }
        heads.push(h);
    }
    let mut centres: Vec<Vector> = heads.iter().flatten().copied().collect();
    for a in 0..heads.len() {
        for b in a + 1..heads.len() {
            for (x, y) in heads[a].iter().zip(&heads[b]) {
                centres.push(0.5 * (x + y));
            }
        }
    }
    let mut found: Vec<HandGrasp> = Vec::new();
    for chunk in centres.chunks(PROBES_PER_CHECK) {
        stop.check()?;
        found.extend(chunk.iter().filter_map(|c| probe.grasp(c)));
    }
    found.sort_by(|a, b| b.score.total_cmp(&a.score));
    // Refine the best few distinct ones; keep those that are a force closure.
    let mut kept: Vec<HandGrasp> = Vec::new();
    for g in found {
        if kept.len() >= KEEP {
            break;
        }
        stop.check()?;
        if kept.iter().any(|k| (k.centre - g.centre).norm() < 0.004) {
            continue;
        }
        let g = probe.refine(g);
        // The normals cannot balance inside the planned cones: no force closure.
        if g.delta >= probe.need_sin || kept.iter().any(|k| (k.centre - g.centre).norm() < 0.002) {
            continue;
        }
        kept.push(g);
    }
    Ok(kept)
}

/// Candidate base poses for a grasp planned from the hand's closing motion (module
/// documentation). Empty when the hand has no such grasp of the object.
pub(super) fn closing_candidates(
    hand: &HandModel,
    thumb: usize,
    skill: &SkillSpec,
    params: &ReplayParams,
    stop: &Stop,
) -> Result<Vec<Candidate>> {
    stop.check()?;
    let nt = hand.fingertips.len();
    let q_rest = mid_angles(hand);
    let paths = closing_paths(hand, &q_rest);
    let tips: Vec<usize> = (0..nt)
        .filter(|&k| paths.iter().any(|p| p.tip == k))
        .collect();
    if !tips.contains(&thumb) {
        return Ok(Vec::new());
    }
    let radius: Vec<Real> = hand.fingertips.iter().map(|t| t.radius).collect();
    let mu = skill.friction.mu * (1.0 - params.friction_margin);
    let start = skill.start_pose();
    let closing = Closing {
        hand,
        thumb,
        skill,
        params,
        q_rest: &q_rest,
        paths: &paths,
        tips: &tips,
        radius: &radius,
        need: 1.0 / (1.0 + mu * mu).sqrt(),
        need_sin: mu / (1.0 + mu * mu).sqrt(),
        start,
        inv_start: start.inverse(),
    };
    let rolls = Rolls::of(skill);
    // Each hand-frame grasp with the rotations of the hand tried for it in the world.
    let trials = if matches!(skill.shape, Shape::Sphere { .. }) {
        closing.sphere_trials(&rolls, stop)?
    } else {
        closing.rolled_trials(&rolls, stop)?
    };
    let mut kin = Kinematics::default();
    let mut out = Vec::new();
    let mut frames: Vec<Vec<ContactFrame>> = Vec::new();
    for trial in &trials {
        stop.check()?;
        let (candidate, contacts) = closing.world_candidate(trial, &mut kin);
        out.push(candidate);
        frames.push(contacts);
    }
    keep_force_closure(&mut out, &frames, skill, mu, stop)?;
    Ok(out)
}

/// What the search for grasps from the hand's closing motion shares (module documentation).
struct Closing<'a> {
    hand: &'a HandModel,
    thumb: usize,
    skill: &'a SkillSpec,
    params: &'a ReplayParams,
    /// The hand's DOFs at mid range ([`mid_angles`]).
    q_rest: &'a [Real; MAX_DOF],
    paths: &'a [Path],
    /// The fingertips with closing paths.
    tips: &'a [usize],
    /// Each fingertip's radius.
    radius: &'a [Real],
    /// Cosine and sine of the planned cone's half-angle.
    need: Real,
    need_sin: Real,
    /// The object's start pose, and its inverse.
    start: Isometry,
    inv_start: Isometry,
}

/// A hand-frame grasp with a rotation of the hand tried for it in the world.
struct Trial {
    grasp: HandGrasp,
    rotation: Rotation,
    /// The approach direction (world).
    approach: Vector,
}

/// The skill's grasp axis (from its thumb's side to the other) and the hand's rolls about it.
struct Rolls {
    a_s: Vector,
    /// Across the axis: the one nearest straight down, and the third direction.
    up_perp: Vector,
    side: Vector,
}

impl Rolls {
    /// The rolls about `skill`'s grasp axis.
    fn of(skill: &SkillSpec) -> Rolls {
        let (_, _, a_s) = grasp_axis(skill);
        let up_perp = perpendicular(&-Vector::z(), &a_s, &Vector::x());
        let side = a_s.cross(&up_perp);
        Rolls { a_s, up_perp, side }
    }

    /// The hand's rotation for a hand-frame grasp (its own grasp axis `a_h` along the skill's,
    /// approach `d_h`) at roll `r` about it, with the approach direction; `None` from below
    /// the table.
    fn roll(&self, a_h: &Vector, d_h: &Vector, r: usize) -> Option<(Rotation, Vector)> {
        let psi = r as Real * std::f64::consts::TAU / ROLLS as Real;
        let d_w = self.up_perp * psi.cos() + self.side * psi.sin();
        // The palm would come from below the table.
        (d_w.z <= 0.35).then(|| (align(a_h, d_h, &self.a_s, &d_w), d_w))
    }
}

/// The hand posed for a [`Trial`] in the world ([`Closing::pose`]).
struct Posed {
    /// The hand with a free base in the trial's rotation.
    free: HandModel,
    /// Its configuration: base position, then the hand's DOFs.
    q: [Real; MAX_DOF],
    /// The fingertips that touch the object.
    active: [bool; MAX_TIPS],
}

impl Closing<'_> {
    /// The object as held in orientation `orient` (hand frame).
    fn probe(&self, orient: Rotation) -> Probe<'_> {
        Probe {
            shape: &self.skill.shape,
            orient,
            paths: self.paths,
            radius: self.radius,
            thumb: self.thumb,
            tips: self.tips,
            need: self.need,
            need_sin: self.need_sin,
        }
    }

    /// A sphere looks the same from every side: its grasps are found once and the hand is
    /// rolled about their own axes.
    fn sphere_trials(&self, rolls: &Rolls, stop: &Stop) -> Result<Vec<Trial>> {
        let (thumb, nt) = (self.thumb, self.hand.fingertips.len());
        let mut trials = Vec::new();
        let probe = self.probe(Rotation::identity());
        for g in hand_grasps(&probe, self.paths, self.radius, stop)? {
            let Some(t_thumb) = g.touches[thumb] else {
                continue;
            };
            let used = (0..nt).filter(|&k| k != thumb && g.touches[k].is_some());
            let n_used = used.clone().count();
            let others = used
                .filter_map(|k| g.touches[k].map(|t| t.point))
                .sum::<Vector>()
                / n_used.max(1) as Real;
            let a_h = (others - t_thumb.point)
                .try_normalize(1e-9)
                .unwrap_or_else(Vector::x);
            let d_h = perpendicular(&g.centre, &a_h, &Vector::z());
            for r in 0..ROLLS {
                if let Some((rotation, approach)) = rolls.roll(&a_h, &d_h, r) {
                    trials.push(Trial {
                        grasp: g.clone(),
                        rotation,
                        approach,
                    });
                }
            }
        }
        Ok(trials)
    }

    /// Any other shape than a sphere is found in the orientation the world will give it: for
    /// each roll of the hand's own grasp axis (thumb to the other fingertips, at mid-range
    /// angles) about the skill's, B in the hand frame is the inverse of the hand's rotation.
    fn rolled_trials(&self, rolls: &Rolls, stop: &Stop) -> Result<Vec<Trial>> {
        let (hand, thumb) = (self.hand, self.thumb);
        let mut kin = Kinematics::default();
        hand.forward_kinematics(&Isometry::identity(), &self.q_rest[..hand.dof()], &mut kin);
        let p_t = kin.tip_centres[thumb].coords;
        let others: Vec<usize> = self.tips.iter().copied().filter(|&k| k != thumb).collect();
        let p_o = others
            .iter()
            .map(|&k| kin.tip_centres[k].coords)
            .sum::<Vector>()
            / others.len().max(1) as Real;
        let a_h = (p_o - p_t).try_normalize(1e-9).unwrap_or_else(Vector::x);
        let d_h = perpendicular(&(0.5 * (p_t + p_o)), &a_h, &Vector::z());
        let mut trials = Vec::new();
        for r in 0..ROLLS {
            let Some((rotation, approach)) = rolls.roll(&a_h, &d_h, r) else {
                continue;
            };
            let orient = rotation.inverse() * self.start.rotation;
            for grasp in hand_grasps(&self.probe(orient), self.paths, self.radius, stop)? {
                trials.push(Trial {
                    grasp,
                    rotation,
                    approach,
                });
            }
        }
        Ok(trials)
    }

    /// The hand placed for `trial` with the object at its start pose: each finger at its
    /// hand-frame touch or open end, then the fingers taking part closed onto the object where
    /// it really lies.
    fn pose(&self, trial: &Trial, kin: &mut Kinematics) -> Posed {
        let (hand, g, rot) = (self.hand, &trial.grasp, trial.rotation);
        let (nt, n_hand) = (hand.fingertips.len(), hand.dof());
        let used: Vec<usize> = (0..nt).filter(|&k| g.touches[k].is_some()).collect();
        let free = with_free_base(hand, rot);
        let n = free.dof();
        let base = self.start.translation.vector - rot * g.centre;
        let mut q = [0.0; MAX_DOF];
        q[..3].copy_from_slice(base.as_slice());
        q[3..n].copy_from_slice(&self.q_rest[..n_hand]);
        let mut active = [false; MAX_TIPS];
        for k in 0..nt {
            if let Some(t) = g.touches[k] {
                self.paths[t.path].set(hand, t.s, 3, &mut q);
                active[k] = true;
            } else if let Some((pi, end)) = g.open[k] {
                self.paths[pi].set(hand, end, 3, &mut q);
            }
        }
        // Close the fingers taking part onto the object where it really lies.
        for &k in &used {
            let path = &self.paths[g.touches[k].map_or(0, |t| t.path)];
            let dofs: Vec<usize> = path.swept.iter().map(|&d| d + 3).collect();
            active[k] = curl_onto(
                &free,
                self.skill,
                &self.inv_start,
                k,
                &dofs,
                kin,
                &mut q[..n],
            );
        }
        Posed { free, q, active }
    }

    /// The world candidate of `trial` and its contacts (B): it counts when every finger taking
    /// part still pushes within the cone, the normals can balance inside it, no fingertip or
    /// the base is below the table, the open fingers clear the object and the approach touches
    /// nothing.
    fn world_candidate(
        &self,
        trial: &Trial,
        kin: &mut Kinematics,
    ) -> (Candidate, Vec<ContactFrame>) {
        let (skill, params, radius) = (self.skill, self.params, self.radius);
        let (start, inv_start) = (&self.start, &self.inv_start);
        let (nt, d_w) = (self.hand.fingertips.len(), trial.approach);
        let Posed { free, q, active } = self.pose(trial, kin);
        let n = free.dof();
        free.forward_kinematics(&Isometry::identity(), &q[..n], kin);
        free.tip_jacobians(kin);
        let gap = |p: &Point, k: usize| -> Real {
            skill.shape.closest(&(inv_start * p).coords).distance - radius[k]
        };
        let mut ok = active[self.thumb] && active.iter().filter(|&&a| a).count() >= 2;
        ok &= q[2] >= 0.0;
        let mut worst: Real = 1.0;
        let mut error: Real = 0.0;
        let mut contacts = Vec::with_capacity(nt);
        let mut normals = [Vector::zeros(); MAX_TIPS];
        for k in 0..nt {
            let c = kin.tip_centres[k];
            ok &= c.z >= radius[k] - 0.002;
            if active[k] {
                let c_b = (inv_start * c).coords;
                let (p, n_in) = skill.shape.on_surface(&c_b);
                let n_world = start.rotation * n_in;
                normals[contacts.len()] = n_in;
                contacts.push(ContactFrame::from_normal(p, n_in));
                worst = worst.min(push_alignment(&free, kin, k, &n_world));
                error = error.max(gap(&c, k).abs());
                // The preshaped tip moving in along the approach touches nothing.
                let pre = start * Point::from(p - n_in * (radius[k] + params.preshape_clearance));
                ok &= (1..=8).all(|i| gap(&(pre - d_w * (APPROACH * i as Real / 8.0)), k) > 0.0);
            } else {
                ok &= gap(&c, k) >= CLEARANCE;
                ok &= (1..=8).all(|i| gap(&(c - d_w * (APPROACH * i as Real / 8.0)), k) > 0.0);
            }
        }
        ok &= worst >= self.need && error <= params.reach_tolerance;
        let delta = hull_distance(&normals[..contacts.len()]);
        ok &= delta < self.need_sin;
        let score = if ok { 0.0 } else { -10.0 } + worst - delta + 0.02 * contacts.len() as Real
            - 0.3 * d_w.z;
        let candidate = Candidate {
            score,
            error,
            ok,
            align: worst,
            rotation: trial.rotation,
            approach: d_w,
            q_free: q,
            active,
        };
        (candidate, contacts)
    }
}

/// Of the candidates `out` that count, the best that is a force closure inside the planned
/// cones (μ with the margin, `mu`, as the forces are planned): one hull for the chosen grasp,
/// more only when it fails; those found not to be no longer count.
fn keep_force_closure(
    out: &mut [Candidate],
    frames: &[Vec<ContactFrame>],
    skill: &SkillSpec,
    mu: Real,
    stop: &Stop,
) -> Result<()> {
    let planned = crate::contact::Friction {
        mu,
        ..skill.friction
    };
    let mut order: Vec<usize> = (0..out.len()).filter(|&i| out[i].ok).collect();
    order.sort_by(|&a, &b| out[b].score.total_cmp(&out[a].score));
    for i in order {
        stop.check()?;
        let closure = grasp_quality(
            &frames[i],
            skill.contact_model,
            &planned,
            &QualityParams::default(),
        )
        .is_ok_and(|q| q.force_closure && q.epsilon > 1e-3);
        if closure {
            break;
        }
        out[i].ok = false;
        out[i].score -= 10.0;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::plan::plan;
    use super::super::{SkillContact, SkillKeyPose};
    use super::*;
    use crate::contact::{ContactModel, Friction};
    use crate::hand::{builtin_hand, thumb_of};
    use crate::scenario::Phase;

    /// An 8 cm, 0.3 kg sphere held by a thumb and four fingers on the opposite side, lifted
    /// 10 cm.
    fn sphere_lift() -> SkillSpec {
        let contact = |finger: &str, dir: Vector| SkillContact {
            finger: finger.into(),
            part: crate::hand::ContactPart::Fingertip,
            position_b: -dir.normalize() * 0.04,
            normal_b: dir.normalize(),
        };
        let key = |t: Real, z: Real| SkillKeyPose {
            time_s: t,
            position: Vector::new(0.0, 0.0, z),
            rotation: Vector::zeros(),
        };
        SkillSpec {
            shape: Shape::Sphere { radius: 0.04 },
            mass: 0.3,
            friction: Friction {
                mu: 0.8,
                mu_torsion: 0.005,
            },
            contact_model: ContactModel::SoftFinger,
            contacts: vec![
                contact("thumb", Vector::x()),
                contact("index", Vector::new(-1.0, -0.3, 0.5)),
                contact("middle", Vector::new(-1.0, 0.05, 0.1)),
                contact("ring", Vector::new(-1.0, 0.1, -0.15)),
                contact("little", Vector::new(-1.0, 0.1, -0.3)),
            ],
            motion: vec![key(0.0, 0.0), key(0.8, 0.0), key(1.8, 0.1), key(3.8, 0.1)],
            phases: vec![
                (Phase::Approach, 0.8),
                (Phase::Grasp, 0.8),
                (Phase::Lift, 1.0),
                (Phase::Hold, 2.0),
                (Phase::Release, 0.6),
            ],
            held_until_s: None,
        }
    }

    #[test]
    fn an_underactuated_hand_grasps_a_sphere_where_its_fingers_close_onto_it_head_on() {
        let hand = builtin_hand("inspire").unwrap();
        let skill = sphere_lift();
        let params = ReplayParams::default();
        let p = plan(&hand, thumb_of(&hand), &skill, &params).unwrap();
        assert!(p.failure.is_none(), "{:?}", p.failure);
        let thumb = thumb_of(&hand);
        assert!(p.active[thumb]);
        let used: Vec<usize> = (0..p.active.len()).filter(|&k| p.active[k]).collect();
        assert!(used.len() >= 2, "{used:?}");
        // Every finger taking part pushes along its normal within the planned cone.
        let mu = skill.friction.mu * (1.0 - params.friction_margin);
        let mut kin = Kinematics::default();
        let n = hand.dof();
        hand.forward_kinematics(&p.base_grasp, &p.q_grasp[..n], &mut kin);
        hand.tip_jacobians(&mut kin);
        let start = skill.start_pose();
        for &k in &used {
            let c = &p.contacts[k];
            let n_world = start.rotation * c.normal_b();
            let a = push_alignment(&hand, &kin, k, &n_world);
            assert!(a >= 1.0 / (1.0 + mu * mu).sqrt(), "{k}: {a}");
            let gap = (start.inverse() * kin.tip_centres[k]).coords.norm()
                - 0.04
                - hand.fingertips[k].radius;
            assert!(gap.abs() < params.reach_tolerance, "{k}: {gap}");
        }
        // A force closure inside the planned cones, not only inside the real ones.
        let frames: Vec<ContactFrame> = used.iter().map(|&k| p.contacts[k]).collect();
        let q = grasp_quality(
            &frames,
            skill.contact_model,
            &Friction {
                mu,
                ..skill.friction
            },
            &QualityParams::default(),
        )
        .unwrap();
        assert!(q.force_closure && q.epsilon > 1e-3, "{q:?}");
        // The fingers left out are clear of the object.
        for k in (0..p.active.len()).filter(|&k| !p.active[k]) {
            let gap = (start.inverse() * kin.tip_centres[k]).coords.norm()
                - 0.04
                - hand.fingertips[k].radius;
            assert!(gap >= CLEARANCE - 1e-9, "{k}: {gap}");
        }
        // The force schedule carries the lift.
        assert!(!p.forces.is_empty());
    }

    #[test]
    fn an_underactuated_sphere_lift_replays_on_inspire() {
        let hand = builtin_hand("inspire").unwrap();
        let r = super::super::run(
            &hand,
            thumb_of(&hand),
            &sphere_lift(),
            &ReplayParams::default(),
        )
        .unwrap();
        assert!(r.success, "{:?}: {}", r.failure_reason, r.detail);
        assert!(r.lift_height_m > 0.08, "{}", r.lift_height_m);
        assert!(r.position_error_max_m < 0.02, "{}", r.position_error_max_m);
        assert!(r.peak_torque_ratio <= 1.0 + 1e-9);
    }
}
