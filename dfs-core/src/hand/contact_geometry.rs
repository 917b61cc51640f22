//! Whole-hand contact geometry (issue 21 item 5): the palm and the phalanges as link-fixed
//! solids that touch objects, besides the fingertip spheres.
//!
//! A [`ContactShape`] is a sphere, a capsule (a segment swept by a ball) or a box fixed in a
//! link's frame, with the body part it is ([`BodyPart`]: the palm or a phalanx). The DFS
//! ([`crate::dfs`]) finds, each tick and per shape, the deepest point of the shape in the
//! object (or the nearest one across a gap up to the contact margin) with
//! [`closest_to_object`]; each touching shape is one contact, with its own frame, contact model
//! and friction cone as a column block of `W`.
//!
//! # Narrow phase
//!
//! Everything is computed in the object frame B against the object's signed distance
//! ([`Shape::closest`]), which is convex for the convex objects: along a segment or over a box
//! its minimum is the deepest point.
//!
//! * A sphere: its centre against the object, exact.
//! * A capsule against a sphere: the segment's point nearest the centre, exact; against a
//!   cylinder: the segment's point nearest the cylinder's axis segment (exact wherever the
//!   contact is on the curved side, which is where wrapped fingers touch; a capsule deep in
//!   the cylinder by its cap gets a shallower point); against a box: the
//!   minimum of the signed distance along the segment by golden-section search (30 steps,
//!   exact to 1e-6 of the segment's length).
//! * A box against a sphere: the box's point nearest the centre, exact; against a cylinder:
//!   the box's point nearest the cylinder's axis segment, found exactly from the pieces of the
//!   squared distance along the axis (exact where the contact is on the curved side: a
//!   cylinder lying on the palm);
//!   against a box: the deepest of the box's eight corners and its point nearest the object's
//!   centre (a face of the palm flat on a face of a box object touches at the corner or the
//!   centre point, not over the face).
//!
//! Where the deepest point is not unique (the palm or a capsule lying parallel to a cylinder
//! against a box object), the searches take the middle of the part of the line that comes
//! within [`LINE_CONTACT_DEPTH`] (0.02 mm) of the deepest overlap: a line contact is touched at
//! its middle, and as the shapes tilt the point moves continuously to the lower end instead of
//! jumping between the ends from tick to tick.
//!
//! # Limits
//!
//! At most [`MAX_CONTACT_SHAPES`] shapes per hand and [`MAX_CONTACT_SHAPES_PER_LINK`] per link;
//! sizes finite, > 0 and at most [`MAX_HAND_EXTENT`]. [`ContactShape::validate`] and
//! [`validate_contact_shapes`] refuse anything else naming the link, as does
//! [`contact_shapes_from_urdf`] for a URDF's `<collision>` elements.

use super::urdf::{check_urdf_text, pose, MAX_HAND_EXTENT};
use super::HandModel;
use crate::error::{DfsError, Result};
use crate::math::{Isometry, Point, Real, Vector};
use crate::object::Shape;

/// Most contact shapes (palm and phalanges) per hand: 24 (glove10 has 16: the palm and 15
/// phalanges; Allegro's URDF has 19 collision boxes off its fingertip links). Fingertips are
/// counted separately ([`super::MAX_TIPS`]).
pub const MAX_CONTACT_SHAPES: usize = 24;
/// Most contact shapes fixed to one link: 8 (the Inspire hand's palm is eight boxes).
pub const MAX_CONTACT_SHAPES_PER_LINK: usize = 8;
/// Weight (m per unit² of the search parameter) that pulls a non-unique deepest point toward
/// the middle of a line contact (module documentation).
const CENTRING: Real = 1e-9;
/// Golden-section steps of the searches.
const GOLDEN_STEPS: usize = 30;
/// Bisection steps finding the ends of a line contact.
const EDGE_STEPS: usize = 16;
/// A line contact is where the shapes come within this (m) of their deepest overlap: its middle
/// is the contact point (module documentation).
pub const LINE_CONTACT_DEPTH: Real = 2e-5;

/// Which part of the hand a contact shape (and so a contact) is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BodyPart {
    /// The palm.
    Palm,
    /// A phalanx (or metacarpal) of a finger; `finger` is the index of the finger's fingertip
    /// in [`HandModel::fingertips`], or `None` for a link that carries no fingertip downstream.
    Phalanx {
        /// The fingertip of its finger, if any.
        finger: Option<usize>,
    },
}

impl BodyPart {
    /// `"palm"` or `"phalanx"`, as in session files.
    pub fn kind_name(self) -> &'static str {
        match self {
            BodyPart::Palm => "palm",
            BodyPart::Phalanx { .. } => "phalanx",
        }
    }
}

/// Which part of the hand a contact is: a fingertip, or with whole-hand contact the palm or a
/// phalanx. What session files record per contact and skills keep per contact
/// ([`crate::replay::SkillContact::part`]).
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum ContactPart {
    /// A fingertip: what every contact of a session without whole-hand contact is, and what a
    /// file written before the field existed reads as.
    #[default]
    Fingertip,
    /// The palm (whole-hand contact).
    Palm,
    /// A phalanx or metacarpal (whole-hand contact).
    Phalanx,
}

impl ContactPart {
    /// Whether this is a fingertip.
    pub fn is_fingertip(&self) -> bool {
        *self == ContactPart::Fingertip
    }

    /// The part of a hand's contact shape.
    pub fn of_body(part: BodyPart) -> ContactPart {
        match part {
            BodyPart::Palm => ContactPart::Palm,
            BodyPart::Phalanx { .. } => ContactPart::Phalanx,
        }
    }

    /// `"fingertip"`, `"palm"` or `"phalanx"`.
    pub fn name(self) -> &'static str {
        match self {
            ContactPart::Fingertip => "fingertip",
            ContactPart::Palm => "palm",
            ContactPart::Phalanx => "phalanx",
        }
    }
}

/// A solid fixed in a link's frame that touches objects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ContactPrimitive {
    /// A ball.
    Sphere {
        /// Centre in the link frame (m).
        centre: Vector,
        /// Radius (m), > 0.
        radius: Real,
    },
    /// A segment from `a` to `b` swept by a ball.
    Capsule {
        /// One end of the segment in the link frame (m).
        a: Vector,
        /// The other end (m), not at `a`.
        b: Vector,
        /// Radius (m), > 0.
        radius: Real,
    },
    /// A box.
    Box {
        /// Pose of the box's centre and axes in the link frame.
        pose: Isometry,
        /// Half side lengths along the box's axes (m), each > 0.
        half_extents: Vector,
    },
}

/// One contact shape of a hand.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactShape {
    /// Name (the link's, for example `index_proximal`, or `palm`).
    pub name: String,
    /// Index of the link in [`HandModel::links`].
    pub link: usize,
    /// The body part.
    pub part: BodyPart,
    /// The solid, in the link frame.
    pub primitive: ContactPrimitive,
}

/// Where a contact shape meets an object, in the object frame B.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeContact {
    /// Signed gap (m) between the shape and the object: negative when they overlap (minus the
    /// penetration).
    pub gap: Real,
    /// The contact point on the object's surface (B).
    pub p_b: Vector,
    /// The object's outward unit normal there (B); the contact normal into the object is its
    /// opposite.
    pub n_out_b: Vector,
}

fn finite(v: &Vector) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl ContactShape {
    /// Checks the shape for `hand`: a link of the hand, finite sizes > 0 and at most
    /// [`MAX_HAND_EXTENT`], a capsule's ends apart, positions finite and within reach. The
    /// error names the link.
    pub fn validate(&self, hand: &HandModel) -> Result<()> {
        let Some(link) = hand.links.get(self.link) else {
            return Err(DfsError::invalid(
                format!("contact shape \"{}\"", self.name),
                format!(
                    "link index {} but the hand has {} links",
                    self.link,
                    hand.links.len()
                ),
            ));
        };
        self.validate_sizes(&link.name)
    }

    fn validate_sizes(&self, link: &str) -> Result<()> {
        let field = || format!("contact shape \"{}\" on link \"{link}\"", self.name);
        let size = |what: &str, v: Real| {
            if v.is_finite() && v > 0.0 && v <= MAX_HAND_EXTENT {
                Ok(())
            } else {
                Err(DfsError::invalid(
                    field(),
                    format!("{what} must be a finite number in (0, {MAX_HAND_EXTENT}] m, got {v}"),
                ))
            }
        };
        let place = |what: &str, v: &Vector| {
            if finite(v) && v.norm() <= MAX_HAND_EXTENT {
                Ok(())
            } else {
                Err(DfsError::invalid(
                    field(),
                    format!("{what} must be finite and within {MAX_HAND_EXTENT} m, got {v:?}"),
                ))
            }
        };
        match self.primitive {
            ContactPrimitive::Sphere { centre, radius } => {
                size("radius", radius)?;
                place("centre", &centre)
            }
            ContactPrimitive::Capsule { a, b, radius } => {
                size("radius", radius)?;
                place("end a", &a)?;
                place("end b", &b)?;
                size("length", (b - a).norm())
            }
            ContactPrimitive::Box { pose, half_extents } => {
                for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                    size(&format!("half extent along {axis}"), half_extents[k])?;
                }
                place("centre", &pose.translation.vector)?;
                if !pose.rotation.coords.iter().all(|v| v.is_finite()) {
                    return Err(DfsError::invalid(field(), "orientation must be finite"));
                }
                Ok(())
            }
        }
    }

    /// Centre (link frame) and radius of a ball holding the shape.
    pub fn bounding_sphere(&self) -> (Vector, Real) {
        match self.primitive {
            ContactPrimitive::Sphere { centre, radius } => (centre, radius),
            ContactPrimitive::Capsule { a, b, radius } => {
                ((a + b) * 0.5, 0.5 * (b - a).norm() + radius)
            }
            ContactPrimitive::Box { pose, half_extents } => {
                (pose.translation.vector, half_extents.norm())
            }
        }
    }
}

/// Checks a hand's contact shapes: each valid ([`ContactShape::validate`]), at most
/// [`MAX_CONTACT_SHAPES`] in all and [`MAX_CONTACT_SHAPES_PER_LINK`] on one link. Errors name
/// the link.
pub fn validate_contact_shapes(hand: &HandModel, shapes: &[ContactShape]) -> Result<()> {
    for s in shapes {
        s.validate(hand)?;
    }
    for s in shapes {
        let on_link = shapes.iter().filter(|o| o.link == s.link).count();
        if on_link > MAX_CONTACT_SHAPES_PER_LINK {
            return Err(DfsError::invalid(
                format!("contact shapes of link \"{}\"", hand.links[s.link].name),
                format!("{on_link} shapes; at most {MAX_CONTACT_SHAPES_PER_LINK} per link"),
            ));
        }
    }
    if shapes.len() > MAX_CONTACT_SHAPES {
        let last = &shapes[MAX_CONTACT_SHAPES];
        return Err(DfsError::invalid(
            "contact_shapes",
            format!(
                "{} shapes (the {}th on link \"{}\"); at most {MAX_CONTACT_SHAPES} per hand",
                shapes.len(),
                MAX_CONTACT_SHAPES + 1,
                hand.links[last.link].name
            ),
        ));
    }
    Ok(())
}

/// Where the shape `primitive`, placed in the object frame B by `pose_in_b` (its link's pose
/// in B), meets the object `shape` (module documentation). Allocation-free.
pub fn closest_to_object(
    primitive: &ContactPrimitive,
    pose_in_b: &Isometry,
    shape: &Shape,
) -> ShapeContact {
    match *primitive {
        ContactPrimitive::Sphere { centre, radius } => {
            ball(shape, &(pose_in_b * Point::from(centre)).coords, radius)
        }
        ContactPrimitive::Capsule { a, b, radius } => {
            let a = (pose_in_b * Point::from(a)).coords;
            let b = (pose_in_b * Point::from(b)).coords;
            let t = capsule_parameter(shape, &a, &b);
            ball(shape, &(a + (b - a) * t), radius)
        }
        ContactPrimitive::Box { pose, half_extents } => {
            let box_in_b = pose_in_b * pose;
            box_contact(shape, &box_in_b, &half_extents)
        }
    }
}

/// A ball of `radius` at `c` (B) against the object.
fn ball(shape: &Shape, c: &Vector, radius: Real) -> ShapeContact {
    let c = shape.closest(c);
    ShapeContact {
        gap: c.distance - radius,
        p_b: c.point,
        n_out_b: c.normal,
    }
}

/// The parameter `t ∈ [0, 1]` of the capsule segment's point deepest in the object.
fn capsule_parameter(shape: &Shape, a: &Vector, b: &Vector) -> Real {
    let ab = b - a;
    let len2 = ab.norm_squared();
    // The segment's point nearest the centre: the answer for a sphere, the centring target
    // otherwise.
    let t_centre = (-a.dot(&ab) / len2).clamp(0.0, 1.0);
    match *shape {
        Shape::Sphere { .. } => t_centre,
        Shape::Cylinder { half_height, .. } => {
            let p0 = Vector::new(0.0, 0.0, -half_height);
            let p1 = Vector::new(0.0, 0.0, half_height);
            segment_segment(a, b, &p0, &p1, t_centre)
        }
        Shape::Box { .. } => golden(t_centre, |t| shape.closest(&(a + ab * t)).distance),
    }
}

/// The parameter on `[a, b]` of the point nearest the segment `[p0, p1]`; `prefer` where that
/// is not unique (parallel segments), clamped into the overlap.
fn segment_segment(a: &Vector, b: &Vector, p0: &Vector, p1: &Vector, prefer: Real) -> Real {
    // Minimise |a + s u − (p0 + t v)|² over s, t ∈ [0, 1].
    let u = b - a;
    let v = p1 - p0;
    let w = a - p0;
    let (uu, uv, vv, uw, vw) = (u.dot(&u), u.dot(&v), v.dot(&v), u.dot(&w), v.dot(&w));
    let det = uu * vv - uv * uv;
    let s_of_t = |t: Real| ((t * uv - uw) / uu).clamp(0.0, 1.0);
    let t_of_s = |s: Real| ((s * uv + vw) / vv).clamp(0.0, 1.0);
    if det <= 1e-12 * uu * vv {
        // Parallel: every s whose point projects onto [p0, p1] is as near; take `prefer`
        // clamped to those.
        let lo = s_of_t(0.0).min(s_of_t(1.0));
        let hi = s_of_t(0.0).max(s_of_t(1.0));
        return prefer.clamp(lo, hi);
    }
    let s = ((uv * vw - vv * uw) / det).clamp(0.0, 1.0);
    let t = t_of_s(s);
    s_of_t(t)
}

/// The minimiser over `[0, 1]` of a convex `f` (golden-section search, [`GOLDEN_STEPS`]
/// steps), moved to the middle of the interval where `f` is within [`LINE_CONTACT_DEPTH`] of its
/// minimum: where the minimum is not unique (a line contact), its middle, which moves
/// continuously as the shapes tilt; `prefer` breaks ties of the search.
fn golden(prefer: Real, f: impl Fn(Real) -> Real) -> Real {
    let g = |t: Real| f(t) + CENTRING * (t - prefer) * (t - prefer);
    let r = 0.5 * (5.0_f64.sqrt() - 1.0);
    let (mut lo, mut hi) = (0.0, 1.0);
    let mut x1 = hi - r * (hi - lo);
    let mut x2 = lo + r * (hi - lo);
    let (mut f1, mut f2) = (g(x1), g(x2));
    for _ in 0..GOLDEN_STEPS {
        if f1 <= f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - r * (hi - lo);
            f1 = g(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + r * (hi - lo);
            f2 = g(x2);
        }
    }
    let mut t = 0.5 * (lo + hi);
    // The ends are candidates too (a monotone f has its minimum there).
    let (f0, f1, ft) = (f(0.0), f(1.0), f(t));
    if f0 < ft && f0 <= f1 {
        t = 0.0;
    } else if f1 < ft {
        t = 1.0;
    }
    let level = f(t) + LINE_CONTACT_DEPTH;
    // The ends of the near-minimal interval by bisection (f convex: one interval).
    let edge = |inside: Real, outside: Real| {
        if f(outside) <= level {
            return outside;
        }
        let (mut a, mut b) = (inside, outside);
        for _ in 0..EDGE_STEPS {
            let m = 0.5 * (a + b);
            if f(m) <= level {
                a = m;
            } else {
                b = m;
            }
        }
        a
    };
    0.5 * (edge(t, 0.0) + edge(t, 1.0))
}

/// The point of the box (centre and axes `box_in_b`, half extents `h`) nearest `p` (B); `p`
/// itself inside the box.
fn clamp_to_box(box_in_b: &Isometry, h: &Vector, p: &Vector) -> Vector {
    let local = box_in_b.inverse_transform_point(&Point::from(*p)).coords;
    (box_in_b * Point::from(clamp_local(h, &local))).coords
}

/// The point of the box of half extents `h` nearest `p`, both in the box's frame.
fn clamp_local(h: &Vector, p: &Vector) -> Vector {
    Vector::new(
        p.x.clamp(-h.x, h.x),
        p.y.clamp(-h.y, h.y),
        p.z.clamp(-h.z, h.z),
    )
}

/// The parameter `s ∈ [0, 1]` of the point of the segment `p0 + d s` nearest the box of half
/// extents `h` (both in the box's frame), moved to the middle of the part of the segment within
/// [`LINE_CONTACT_DEPTH`] of that least distance, as [`golden`] does; exactly, without a search.
///
/// The squared distance `Σ_i max(|p0_i + d_i s| − h_i, 0)²` is convex in `s` and a quadratic
/// between the (at most six) values of `s` where a coordinate crosses one of the box's face
/// planes: its least value is the least of those pieces' least values, and the ends of the
/// near-least part are roots of the pieces' quadratics. Measured against the golden-section
/// search it replaces (callgrind, BENCHMARKS.md, "The power-grasp tick's narrow phase"): the
/// same answers to within the search's tolerance, at a small fraction of its instructions.
fn segment_nearest_box(p0: &Vector, d: &Vector, h: &Vector) -> Real {
    // The pieces' ends, sorted: 0, the crossings inside (0, 1), 1.
    let mut cuts = [0.0; 8];
    let mut n = 1;
    for i in 0..3 {
        if d[i] != 0.0 {
            for face in [-h[i], h[i]] {
                let s = (face - p0[i]) / d[i];
                if s > 0.0 && s < 1.0 {
                    cuts[n] = s;
                    n += 1;
                }
            }
        }
    }
    cuts[n] = 1.0;
    n += 1;
    let cuts = &mut cuts[..n];
    cuts.sort_unstable_by(Real::total_cmp);
    let f2 = |s: Real| {
        let p = p0 + d * s;
        (p - clamp_local(h, &p)).norm_squared()
    };
    // The piece [a, b]'s quadratic `qa s² + qb s + qc`: the coordinates outside the box at its
    // middle are outside over all of it.
    let piece = |a: Real, b: Real| {
        let m = 0.5 * (a + b);
        let (mut qa, mut qb, mut qc) = (0.0, 0.0, 0.0);
        for i in 0..3 {
            let x = p0[i] + d[i] * m;
            let off = if x > h[i] {
                p0[i] - h[i]
            } else if x < -h[i] {
                p0[i] + h[i]
            } else {
                continue;
            };
            qa += d[i] * d[i];
            qb += 2.0 * off * d[i];
            qc += off * off;
        }
        (qa, qb, qc)
    };
    let (mut best_s, mut best) = (0.0, f2(0.0));
    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b <= a {
            continue;
        }
        let (qa, qb, _) = piece(a, b);
        let s = if qa > 0.0 {
            (-qb / (2.0 * qa)).clamp(a, b)
        } else {
            b
        };
        let v = f2(s);
        if v < best {
            (best_s, best) = (s, v);
        }
    }
    let level = best.sqrt() + LINE_CONTACT_DEPTH;
    let level2 = level * level;
    // Where the piece [a, b]'s quadratic meets the level: the root nearer `a` (`lower`) or `b`.
    // Asked only of a piece with an end above the level, so a coordinate is outside the box
    // over it and `qa > 0`.
    let root = |a: Real, b: Real, lower: bool| {
        let (qa, qb, qc) = piece(a, b);
        let disc = (qb * qb - 4.0 * qa * (qc - level2)).max(0.0).sqrt();
        let s = (if lower { -qb - disc } else { -qb + disc }) / (2.0 * qa);
        s.clamp(a, b)
    };
    // The near-least part is one interval about `best_s` (convexity): its ends are in the
    // first piece from the left, and from the right, whose far end is within the level.
    let lo = if f2(0.0) <= level2 {
        0.0
    } else {
        cuts.windows(2)
            .find(|w| w[1] > w[0] && f2(w[1]) <= level2)
            .map_or(best_s, |w| root(w[0], w[1], true))
    };
    let hi = if f2(1.0) <= level2 {
        1.0
    } else {
        cuts.windows(2)
            .rev()
            .find(|w| w[1] > w[0] && f2(w[0]) <= level2)
            .map_or(best_s, |w| root(w[0], w[1], false))
    };
    0.5 * (lo.min(best_s) + hi.max(best_s))
}

/// A box (radius 0) against the object.
fn box_contact(shape: &Shape, box_in_b: &Isometry, h: &Vector) -> ShapeContact {
    let centre = Vector::zeros();
    match *shape {
        Shape::Sphere { .. } => ball(shape, &clamp_to_box(box_in_b, h, &centre), 0.0),
        Shape::Cylinder { half_height, .. } => {
            // Along the axis in the box's frame (distances do not change): the axis point's
            // distance from the box is that of its clamped copy.
            let rot_inv = box_in_b.rotation.inverse().to_rotation_matrix();
            let p0 = rot_inv * (Vector::new(0.0, 0.0, -half_height) - box_in_b.translation.vector);
            let d = rot_inv * Vector::new(0.0, 0.0, 2.0 * half_height);
            let s = segment_nearest_box(&p0, &d, h);
            let local = clamp_local(h, &(p0 + d * s));
            ball(shape, &(box_in_b * Point::from(local)).coords, 0.0)
        }
        Shape::Box { .. } => {
            let mut best = ball(shape, &clamp_to_box(box_in_b, h, &centre), 0.0);
            for corner in 0..8 {
                let sign = |bit: usize| if corner & (1 << bit) != 0 { 1.0 } else { -1.0 };
                let local = Vector::new(sign(0) * h.x, sign(1) * h.y, sign(2) * h.z);
                let c = ball(shape, &(box_in_b * Point::from(local)).coords, 0.0);
                if c.gap < best.gap {
                    best = c;
                }
            }
            best
        }
    }
}

/// The contact shapes of a hand from its URDF's `<collision>` elements: a `<sphere>` is a
/// sphere, a `<capsule>` a capsule along its z axis, a `<cylinder>` the capsule on the same axis
/// segment (its ends rounded) and a `<box>` a box; meshes are not contact geometry and are
/// skipped. Links that carry a fingertip are skipped too (the fingertip sphere is their
/// contact), and so is the base link's collision if `hand.root` has none. A link's shapes are
/// phalanges unless the link is the parent of two or more fingers' chains (the palm).
///
/// Refused, naming the link: a size that is not finite, not positive or over
/// [`MAX_HAND_EXTENT`] (a degenerate collision element), an origin that is not finite, more than
/// [`MAX_CONTACT_SHAPES_PER_LINK`] elements on one link, more than [`MAX_CONTACT_SHAPES`] in
/// all, or a URDF that does not parse.
pub fn contact_shapes_from_urdf(hand: &HandModel, urdf: &str) -> Result<Vec<ContactShape>> {
    check_urdf_text(urdf)?;
    let robot = urdf_rs::read_from_string(urdf)
        .map_err(|e| DfsError::invalid("urdf", format!("does not parse: {e}")))?;
    let mut out = Vec::new();
    for link in &robot.links {
        let Some(l) = hand.links.iter().position(|k| k.name == link.name) else {
            continue;
        };
        if hand.fingertips.iter().any(|t| t.link == l) {
            continue;
        }
        let part = body_part_of(hand, l);
        for (i, c) in link.collision.iter().enumerate() {
            let origin = &c.origin;
            if !origin
                .xyz
                .0
                .iter()
                .chain(origin.rpy.0.iter())
                .all(|v| v.is_finite())
            {
                return Err(DfsError::invalid(
                    format!("collision {i} of link \"{}\"", link.name),
                    "origin must be finite",
                ));
            }
            let at = pose(origin);
            let primitive = match &c.geometry {
                urdf_rs::Geometry::Sphere { radius } => ContactPrimitive::Sphere {
                    centre: at.translation.vector,
                    radius: *radius,
                },
                urdf_rs::Geometry::Capsule { radius, length }
                | urdf_rs::Geometry::Cylinder { radius, length } => {
                    let half = 0.5 * length;
                    ContactPrimitive::Capsule {
                        a: (at * Point::new(0.0, 0.0, -half)).coords,
                        b: (at * Point::new(0.0, 0.0, half)).coords,
                        radius: *radius,
                    }
                }
                urdf_rs::Geometry::Box { size } => ContactPrimitive::Box {
                    pose: at,
                    half_extents: Vector::from(size.0) * 0.5,
                },
                urdf_rs::Geometry::Mesh { .. } => continue,
            };
            let shape = ContactShape {
                name: link.name.clone(),
                link: l,
                part,
                primitive,
            };
            shape.validate_sizes(&link.name).map_err(|e| match e {
                DfsError::Invalid { reason, .. } => {
                    DfsError::invalid(format!("collision {i} of link \"{}\"", link.name), reason)
                }
                other => other,
            })?;
            out.push(shape);
        }
    }
    validate_contact_shapes(hand, &out)?;
    Ok(out)
}

/// The palm if `link` is where two or more fingers' chains branch off, else a phalanx of the
/// finger whose fingertip lies downstream of it (the first, if several).
pub fn body_part_of(hand: &HandModel, link: usize) -> BodyPart {
    let downstream: Vec<usize> = hand
        .fingertips
        .iter()
        .enumerate()
        .filter(|(_, t)| hand.is_ancestor_or_self(link, t.link))
        .map(|(k, _)| k)
        .collect();
    if downstream.len() >= 2 {
        BodyPart::Palm
    } else {
        BodyPart::Phalanx {
            finger: downstream.first().copied(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rotation;
    use proptest::prelude::*;

    fn shapes() -> [Shape; 3] {
        [
            Shape::Sphere { radius: 0.04 },
            Shape::Box {
                half_extents: [0.03, 0.05, 0.02],
            },
            Shape::Cylinder {
                radius: 0.03,
                half_height: 0.06,
            },
        ]
    }

    /// The least signed gap between a capsule and the object by brute force: 4001 points along
    /// the segment.
    fn brute_capsule(shape: &Shape, a: &Vector, b: &Vector, r: Real) -> Real {
        (0..=4000)
            .map(|i| {
                shape
                    .closest(&(a + (b - a) * (i as Real / 4000.0)))
                    .distance
                    - r
            })
            .fold(Real::INFINITY, Real::min)
    }

    /// The least signed distance from the object's surface of points of a box, by brute force
    /// over a 21³ grid.
    fn brute_box(shape: &Shape, pose: &Isometry, h: &Vector) -> Real {
        let mut best = Real::INFINITY;
        for i in 0..=20 {
            for j in 0..=20 {
                for k in 0..=20 {
                    let l = Vector::new(
                        h.x * (i as Real / 10.0 - 1.0),
                        h.y * (j as Real / 10.0 - 1.0),
                        h.z * (k as Real / 10.0 - 1.0),
                    );
                    best = best.min(shape.closest(&(pose * Point::from(l)).coords).distance);
                }
            }
        }
        best
    }

    #[test]
    fn a_capsule_across_a_cylinder_touches_its_side_at_the_crossing() {
        // A phalanx wrapped across a cylinder lying along B's z: 1 mm into its side.
        let cyl = Shape::Cylinder {
            radius: 0.03,
            half_height: 0.06,
        };
        let cap = ContactPrimitive::Capsule {
            a: Vector::new(-0.02, 0.0, 0.0),
            b: Vector::new(0.02, 0.0, 0.0),
            radius: 0.01,
        };
        let pose = Isometry::translation(0.0, 0.039, 0.01);
        let c = closest_to_object(&cap, &pose, &cyl);
        assert!((c.gap + 0.001).abs() < 1e-12, "{}", c.gap);
        assert!((c.p_b - Vector::new(0.0, 0.03, 0.01)).norm() < 1e-12);
        assert!((c.n_out_b - Vector::y()).norm() < 1e-12);
    }

    #[test]
    fn a_palm_under_a_lying_cylinder_touches_it_under_its_axis_in_the_middle_of_the_line() {
        // The palm box's face 0.5 mm into a cylinder along B's z (a line contact along z): the
        // contact is under the axis, at the middle of the part of the axis over the box.
        let cyl = Shape::Cylinder {
            radius: 0.03,
            half_height: 0.06,
        };
        let palm = ContactPrimitive::Box {
            pose: Isometry::identity(),
            half_extents: Vector::new(0.01, 0.04, 0.04),
        };
        // The box's +x face at x = −0.0295 (0.5 mm inside the side at x = −0.03), centred at
        // z = 0.02 along the axis.
        let pose = Isometry::translation(-0.0395, 0.0, 0.02);
        let c = closest_to_object(&palm, &pose, &cyl);
        assert!((c.gap + 0.0005).abs() < 1e-9, "{}", c.gap);
        assert!((c.n_out_b + Vector::x()).norm() < 1e-9, "{:?}", c.n_out_b);
        // The box spans z ∈ [−0.02, 0.06] over the axis: its middle is z = 0.02.
        assert!((c.p_b.z - 0.02).abs() < 1e-3, "{:?}", c.p_b);
    }

    #[test]
    fn a_sphere_shape_is_the_fingertip_rule() {
        let s = Shape::Sphere { radius: 0.04 };
        let p = ContactPrimitive::Sphere {
            centre: Vector::new(0.0, 0.0, 0.01),
            radius: 0.01,
        };
        // The ball's centre at z = −0.049: 9 mm off the surface, 1 mm into it.
        let c = closest_to_object(&p, &Isometry::translation(0.0, 0.0, -0.059), &s);
        assert!((c.gap + 0.001).abs() < 1e-12, "{}", c.gap);
        assert!((c.p_b - Vector::new(0.0, 0.0, -0.04)).norm() < 1e-12);
        assert!((c.n_out_b + Vector::z()).norm() < 1e-12);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]
        #[test]
        fn the_segments_point_nearest_a_box_is_the_golden_searchs(
            p0 in prop::array::uniform3(-0.08..0.08f64),
            d in prop::array::uniform3(-0.12..0.12f64),
            h in prop::array::uniform3(0.002..0.04f64),
            flat in 0usize..4,
        ) {
            let (p0, mut d, h) = (Vector::from(p0), Vector::from(d), Vector::from(h));
            // Segments parallel to a face (line contacts) too.
            if flat < 3 {
                d[flat] = 0.0;
            }
            prop_assume!(d.norm() > 0.005);
            let dist = |s: Real| {
                let p = p0 + d * s;
                (p - clamp_local(&h, &p)).norm()
            };
            let exact = segment_nearest_box(&p0, &d, &h);
            let searched = golden(0.5, dist);
            // The same point up to the search's tolerance (its ends found to 2⁻¹⁶ of the
            // segment, the least to the golden section's 30 steps).
            prop_assert!((exact - searched).abs() < 1e-4, "{exact} against {searched}");
            // Within the line contact's depth of the least distance, found by sampling.
            let least = (0..=20_000).map(|i| dist(i as Real / 20_000.0)).fold(Real::INFINITY, Real::min);
            prop_assert!(dist(exact) <= least + LINE_CONTACT_DEPTH + 1e-12);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn capsules_find_the_least_gap_to_spheres_boxes_and_cylinders(
            which in 0usize..3,
            a in prop::array::uniform3(-0.09..0.09f64),
            b in prop::array::uniform3(-0.09..0.09f64),
            r in 0.003..0.015f64,
        ) {
            let (a, b) = (Vector::from(a), Vector::from(b));
            prop_assume!((b - a).norm() > 0.005);
            let shape = shapes()[which];
            let c = closest_to_object(
                &ContactPrimitive::Capsule { a, b, radius: r },
                &Isometry::identity(),
                &shape,
            );
            let brute = brute_capsule(&shape, &a, &b, r);
            // Never deeper than the truth, which is within half a sampling step of the samples'
            // least (the signed distance is 1-Lipschitz); as deep up to the sampling for spheres
            // and boxes.
            let step = (b - a).norm() / 4000.0;
            prop_assert!(c.gap >= brute - step - 1e-12, "{} < {}", c.gap, brute);
            // Against a cylinder the segment's point nearest the axis is the deepest whenever the
            // object's surface nearest it is the curved side: every other point of the segment
            // is as far or further from the axis, and its signed distance is at least that.
            let on_side = c.n_out_b.z.abs() < 1e-12;
            if which != 2 || on_side {
                prop_assert!(c.gap <= brute + LINE_CONTACT_DEPTH + 1e-6, "{} > {} ({which})", c.gap, brute);
            }
            // The reported point is on the object's surface.
            let d = shape.closest(&c.p_b).distance;
            prop_assert!(d.abs() < 1e-9);
        }

        #[test]
        fn boxes_find_the_least_gap_to_spheres_and_lying_cylinders(
            which in prop::sample::select(vec![0usize, 2]),
            centre in prop::array::uniform3(-0.06..0.06f64),
            h in prop::array::uniform3(0.005..0.04f64),
            angle in -0.5..0.5f64,
        ) {
            let shape = shapes()[which];
            let pose = Isometry::from_parts(
                Vector::from(centre).into(),
                Rotation::from_axis_angle(&Vector::y_axis(), angle),
            );
            let h = Vector::from(h);
            let c = closest_to_object(
                &ContactPrimitive::Box { pose: Isometry::identity(), half_extents: h },
                &pose,
                &shape,
            );
            let brute = brute_box(&shape, &pose, &h);
            // The truth is within the grid's half diagonal of the grid's least.
            prop_assert!(c.gap >= brute - 0.1 * h.norm() - 1e-12, "{} < {}", c.gap, brute);
            // Exact for a sphere, and for a cylinder while the box is off its caps and outside.
            let side = which == 2 && brute > 0.0 && (centre[2].abs() + h.norm()) < 0.06;
            // (A line contact is touched at its middle, within LINE_CONTACT_DEPTH of the deepest.)
            if which == 0 || side {
                prop_assert!(c.gap <= brute + LINE_CONTACT_DEPTH + 1e-6, "{} > {} ({which})", c.gap, brute);
            }
        }
    }

    fn hand() -> HandModel {
        HandModel::glove10()
    }

    #[test]
    fn degenerate_shapes_are_refused_naming_the_link() {
        let h = hand();
        let palm = h.links.iter().position(|l| l.name == "palm").unwrap();
        let bad = [
            ContactPrimitive::Sphere {
                centre: Vector::zeros(),
                radius: 0.0,
            },
            ContactPrimitive::Sphere {
                centre: Vector::zeros(),
                radius: -0.01,
            },
            ContactPrimitive::Capsule {
                a: Vector::zeros(),
                b: Vector::zeros(),
                radius: 0.01,
            },
            ContactPrimitive::Capsule {
                a: Vector::new(Real::NAN, 0.0, 0.0),
                b: Vector::x(),
                radius: 0.01,
            },
            ContactPrimitive::Box {
                pose: Isometry::identity(),
                half_extents: Vector::new(0.01, Real::NAN, 0.01),
            },
            ContactPrimitive::Box {
                pose: Isometry::identity(),
                half_extents: Vector::new(0.01, 0.0, 0.01),
            },
        ];
        for primitive in bad {
            let s = ContactShape {
                name: "palm".into(),
                link: palm,
                part: BodyPart::Palm,
                primitive,
            };
            let e = validate_contact_shapes(&h, &[s]).unwrap_err().to_string();
            assert!(e.contains("on link \"palm\""), "{e}");
        }
    }

    #[test]
    fn too_many_shapes_are_refused_naming_the_link() {
        let h = hand();
        let palm = h.links.iter().position(|l| l.name == "palm").unwrap();
        let ball = |link| ContactShape {
            name: "b".into(),
            link,
            part: BodyPart::Palm,
            primitive: ContactPrimitive::Sphere {
                centre: Vector::zeros(),
                radius: 0.01,
            },
        };
        let five = vec![ball(palm); MAX_CONTACT_SHAPES_PER_LINK + 1];
        let e = validate_contact_shapes(&h, &five).unwrap_err().to_string();
        assert!(
            e.contains("link \"palm\"") && e.contains("at most 8 per link"),
            "{e}"
        );
        validate_contact_shapes(&h, &five[..MAX_CONTACT_SHAPES_PER_LINK]).unwrap();
        // Spread over links, the hand's limit binds.
        let many: Vec<ContactShape> = (0..h.links.len())
            .flat_map(|l| [ball(l), ball(l)])
            .take(MAX_CONTACT_SHAPES + 1)
            .collect();
        let e = validate_contact_shapes(&h, &many).unwrap_err().to_string();
        assert!(
            e.contains("at most 24 per hand") && e.contains("on link \""),
            "{e}"
        );
    }

    #[test]
    fn allegros_urdf_collision_boxes_become_its_palm_and_phalanges() {
        use crate::hand::builtin::{builtin_hand, ALLEGRO_URDF};
        let hand = builtin_hand("allegro").unwrap();
        let shapes = contact_shapes_from_urdf(&hand, ALLEGRO_URDF).unwrap();
        assert!(!shapes.is_empty() && shapes.len() <= MAX_CONTACT_SHAPES);
        validate_contact_shapes(&hand, &shapes).unwrap();
        // Its palm (where the fingers branch) is one of them; no fingertip link is.
        assert!(shapes.iter().any(|s| s.part == BodyPart::Palm));
        for s in &shapes {
            assert!(
                hand.fingertips.iter().all(|t| t.link != s.link),
                "{}",
                s.name
            );
        }
    }

    /// A two-link hand whose finger link has `collision` as its collision geometry.
    fn urdf_with(collision: &str) -> String {
        format!(
            r#"<robot name="h">
  <link name="base"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="finger"><inertial><mass value="0.02"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial>
    {collision}
  </link>
  <link name="tip"><inertial><mass value="0.01"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="j0" type="revolute"><parent link="base"/><child link="finger"/><axis xyz="0 1 0"/><limit lower="0" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="j1" type="revolute"><parent link="finger"/><child link="tip"/><origin xyz="0.05 0 0"/><axis xyz="0 1 0"/><limit lower="0" upper="1.5" effort="1" velocity="1"/></joint>
</robot>"#
        )
    }

    fn hand_of(urdf: &str) -> HandModel {
        let spec: crate::hand::HandSpec = serde_json::from_value(serde_json::json!({
            "name": "h", "urdf": "h.urdf", "torque_limit": 1.0,
            "fingertips": [{ "name": "tip", "link": "tip", "offset": [0.02, 0, 0], "radius": 0.008 }]
        }))
        .unwrap();
        HandModel::from_urdf(urdf, &spec).unwrap()
    }

    #[test]
    fn degenerate_or_too_many_urdf_collisions_are_refused_naming_the_link() {
        let capsule = r#"<collision><origin xyz="0.025 0 0" rpy="0 1.5708 0"/><geometry><capsule radius="0.008" length="0.05"/></geometry></collision>"#;
        let ok = urdf_with(capsule);
        let hand = hand_of(&ok);
        let shapes = contact_shapes_from_urdf(&hand, &ok).unwrap();
        assert_eq!(shapes.len(), 1);
        assert_eq!(shapes[0].part, BodyPart::Phalanx { finger: Some(0) });
        match shapes[0].primitive {
            ContactPrimitive::Capsule { a, b, radius } => {
                assert!((a - Vector::new(0.0, 0.0, 0.0)).norm() < 1e-4, "{a:?}");
                assert!((b - Vector::new(0.05, 0.0, 0.0)).norm() < 1e-4, "{b:?}");
                assert_eq!(radius, 0.008);
            }
            other => panic!("{other:?}"),
        }
        for bad in [
            r#"<collision><geometry><sphere radius="0"/></geometry></collision>"#,
            r#"<collision><geometry><sphere radius="-0.01"/></geometry></collision>"#,
            r#"<collision><geometry><box size="0.01 NaN 0.01"/></geometry></collision>"#,
            r#"<collision><geometry><box size="0.01 0 0.01"/></geometry></collision>"#,
            r#"<collision><geometry><cylinder radius="0.01" length="0"/></geometry></collision>"#,
        ] {
            let text = urdf_with(bad);
            let e = contact_shapes_from_urdf(&hand, &text)
                .unwrap_err()
                .to_string();
            assert!(e.contains("link \"finger\""), "{bad}: {e}");
        }
        let five = capsule.repeat(MAX_CONTACT_SHAPES_PER_LINK + 1);
        let e = contact_shapes_from_urdf(&hand, &urdf_with(&five))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("link \"finger\"") && e.contains("at most 8 per link"),
            "{e}"
        );
        // Meshes are not contact geometry.
        let mesh = r#"<collision><geometry><mesh filename="f.stl"/></geometry></collision>"#;
        assert!(contact_shapes_from_urdf(&hand, &urdf_with(mesh))
            .unwrap()
            .is_empty());
    }
}
