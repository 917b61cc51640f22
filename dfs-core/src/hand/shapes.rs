//! Simple solid shapes that draw a hand: boxes, cylinders and spheres fixed in its links'
//! frames ([`link_shapes`]). Viewers draw them at the links' poses (the session's `/tf`), and
//! [`hand_urdf`](super::hand_urdf) writes them into the hand's URDF as its link geometry.
//!
//! # Where the shapes come from
//!
//! * A hand built from a URDF (pass its text) keeps that URDF's primitive geometry, per link:
//!   its `<visual>` elements if every one is a box, cylinder, sphere or capsule (a capsule
//!   becomes a cylinder and two spheres), else its `<collision>` elements on the same terms.
//!   Meshes are referenced by file name and ICMS does not ship them, so a link whose elements
//!   are meshes (or hold a size that is not finite, not positive or over
//!   [`MAX_HAND_EXTENT`], or more than [`MAX_URDF_SHAPES_PER_LINK`] shapes) gets generated
//!   shapes instead. The built-in Allegro and Barrett hands have primitive collision boxes on
//!   every link; the Inspire hand has boxes on some links and meshes on the others; the
//!   gripper has no geometry.
//! * Generated shapes follow the kinematics ([`ShapeSource::Generated`]): a link whose child
//!   joints and fingertip centres lie at one point away from its origin is a cylinder from its
//!   origin to that point with a ball at the origin (a finger segment); one with several such
//!   points is a box around its origin and them (a palm); one with none is a ball at its
//!   origin (a wrist link between coincident joints, a base). Their thickness is
//!   [`SEGMENT_RADIUS_PER_TIP_RADIUS`] of the mean fingertip radius, within
//!   [`SEGMENT_RADIUS_RANGE`].
//! * Every fingertip adds its contact sphere ([`ShapeSource::Fingertip`]), whatever the link's
//!   other shapes: the sphere the contact model sees.

use std::collections::BTreeMap;

use super::urdf::{check_urdf_text, pose, MAX_HAND_EXTENT};
use super::HandModel;
use crate::math::{Isometry, Rotation, Vector};

/// Most shapes kept from one link of a URDF (a capsule counts as three): 8. Real hands have
/// one to three per link; a link with more gets generated shapes, so that a hostile URDF cannot
/// make every drawing of the hand large.
pub const MAX_URDF_SHAPES_PER_LINK: usize = 8;
/// Radius of generated segments and balls as a fraction of the hand's mean fingertip radius:
/// 0.8 (a finger is a little thinner than its pad).
pub const SEGMENT_RADIUS_PER_TIP_RADIUS: f64 = 0.8;
/// Range of the radius of generated segments and balls (m): 2 mm to 20 mm.
pub const SEGMENT_RADIUS_RANGE: (f64, f64) = (0.002, 0.02);
/// Radius of generated segments of a hand without fingertips (m).
const DEFAULT_SEGMENT_RADIUS: f64 = 0.008;

/// A solid centred on the origin of its frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Primitive {
    /// A box with these side lengths along the frame's x, y and z axes (m).
    Box {
        /// Side lengths (m), each > 0.
        size: Vector,
    },
    /// A cylinder along the frame's z axis (as in URDF and Foxglove).
    Cylinder {
        /// Radius (m), > 0.
        radius: f64,
        /// Length along z (m), > 0.
        length: f64,
    },
    /// A sphere.
    Sphere {
        /// Radius (m), > 0.
        radius: f64,
    },
}

/// Where a shape comes from (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShapeSource {
    /// A primitive of the hand's own URDF.
    Urdf,
    /// Generated from the link's joints and fingertips.
    Generated,
    /// A fingertip's contact sphere.
    Fingertip,
}

/// One shape of a hand, fixed in a link's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkShape {
    /// Index of the link in [`HandModel::links`].
    pub link: usize,
    /// Pose of the shape's frame (the primitive's centre and axes) in the link frame.
    pub origin: Isometry,
    /// The solid.
    pub primitive: Primitive,
    /// Where it comes from.
    pub source: ShapeSource,
}

/// The shapes that draw `hand`, in link order, then one sphere per fingertip. `source_urdf` is
/// the URDF text the hand was built from, if any: its primitive shapes are kept for the links
/// that have them (by link name). A text that does not parse is ignored (every link gets
/// generated shapes). Every link gets at least one shape.
pub fn link_shapes(hand: &HandModel, source_urdf: Option<&str>) -> Vec<LinkShape> {
    let from_urdf = source_urdf.and_then(urdf_primitives);
    let radius = segment_radius(hand);
    let mut out = Vec::new();
    for (l, link) in hand.links.iter().enumerate() {
        match from_urdf.as_ref().and_then(|m| m.get(&link.name)) {
            Some(shapes) => out.extend(shapes.iter().map(|&(origin, primitive)| LinkShape {
                link: l,
                origin,
                primitive,
                source: ShapeSource::Urdf,
            })),
            None => generated(hand, l, radius, &mut out),
        }
    }
    for tip in &hand.fingertips {
        if tip.link < hand.links.len() && finite(&tip.offset) && tip.radius > 0.0 {
            out.push(LinkShape {
                link: tip.link,
                origin: Isometry::translation(tip.offset.x, tip.offset.y, tip.offset.z),
                primitive: Primitive::Sphere { radius: tip.radius },
                source: ShapeSource::Fingertip,
            });
        }
    }
    out
}

/// The radius of generated segments (see [`SEGMENT_RADIUS_PER_TIP_RADIUS`]).
fn segment_radius(hand: &HandModel) -> f64 {
    let radii: Vec<f64> = hand
        .fingertips
        .iter()
        .map(|t| t.radius)
        .filter(|r| r.is_finite() && *r > 0.0)
        .collect();
    if radii.is_empty() {
        return DEFAULT_SEGMENT_RADIUS;
    }
    let mean = radii.iter().sum::<f64>() / radii.len() as f64;
    let (lo, hi) = SEGMENT_RADIUS_RANGE;
    (SEGMENT_RADIUS_PER_TIP_RADIUS * mean).clamp(lo, hi)
}

fn finite(v: &Vector) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Generated shapes of link `l` with segment radius `r`, appended to `out`.
fn generated(hand: &HandModel, l: usize, r: f64, out: &mut Vec<LinkShape>) {
    let children = hand
        .joints
        .iter()
        .filter(|j| j.parent == l)
        .map(|j| j.origin.translation.vector);
    let tips = hand
        .fingertips
        .iter()
        .filter(|t| t.link == l)
        .map(|t| t.offset);
    let points: Vec<Vector> = children
        .chain(tips)
        .filter(|p| finite(p) && p.norm() <= MAX_HAND_EXTENT)
        .collect();
    // Points within the ball at the origin add nothing to it.
    let far: Vec<&Vector> = points.iter().filter(|p| p.norm() > r).collect();
    let shape = |origin: Isometry, primitive: Primitive| LinkShape {
        link: l,
        origin,
        primitive,
        source: ShapeSource::Generated,
    };
    let ball = shape(Isometry::identity(), Primitive::Sphere { radius: r });
    match far.as_slice() {
        [] => out.push(ball),
        [p] => {
            let rotation = Rotation::rotation_between(&Vector::z(), p).unwrap_or_else(|| {
                // Antiparallel to z: half a turn about x.
                Rotation::from_axis_angle(&Vector::x_axis(), std::f64::consts::PI)
            });
            let centre = *p * 0.5;
            out.push(ball);
            out.push(shape(
                Isometry::from_parts(centre.into(), rotation),
                Primitive::Cylinder {
                    radius: r,
                    length: p.norm(),
                },
            ));
        }
        _ => {
            let (mut lo, mut hi) = (Vector::zeros(), Vector::zeros());
            for p in &points {
                lo = lo.inf(p);
                hi = hi.sup(p);
            }
            let centre = (lo + hi) * 0.5;
            out.push(shape(
                Isometry::translation(centre.x, centre.y, centre.z),
                Primitive::Box {
                    size: (hi - lo).add_scalar(2.0 * r),
                },
            ));
        }
    }
}

/// The primitive shapes of each link of a URDF text that has them (see the module
/// documentation); `None` if the text does not parse.
fn urdf_primitives(text: &str) -> Option<BTreeMap<String, Vec<(Isometry, Primitive)>>> {
    check_urdf_text(text).ok()?;
    let robot = urdf_rs::read_from_string(text).ok()?;
    let mut map = BTreeMap::new();
    for link in &robot.links {
        let visuals: Vec<_> = link
            .visual
            .iter()
            .map(|v| (&v.origin, &v.geometry))
            .collect();
        let collisions: Vec<_> = link
            .collision
            .iter()
            .map(|c| (&c.origin, &c.geometry))
            .collect();
        if let Some(shapes) = primitives_of(&visuals).or_else(|| primitives_of(&collisions)) {
            map.insert(link.name.clone(), shapes);
        }
    }
    Some(map)
}

/// A link's URDF elements as primitives, if they are all primitives of valid size.
fn primitives_of(
    elements: &[(&urdf_rs::Pose, &urdf_rs::Geometry)],
) -> Option<Vec<(Isometry, Primitive)>> {
    let ok = |v: f64| v.is_finite() && v > 0.0 && v <= MAX_HAND_EXTENT;
    let mut out = Vec::new();
    for &(origin, geometry) in elements {
        let in_range = origin
            .xyz
            .0
            .iter()
            .chain(origin.rpy.0.iter())
            .all(|v| v.is_finite())
            && Vector::from(origin.xyz.0).norm() <= MAX_HAND_EXTENT;
        if !in_range {
            return None;
        }
        let at = pose(origin);
        match geometry {
            urdf_rs::Geometry::Box { size } if size.0.iter().all(|&v| ok(v)) => out.push((
                at,
                Primitive::Box {
                    size: Vector::from(size.0),
                },
            )),
            urdf_rs::Geometry::Cylinder { radius, length } if ok(*radius) && ok(*length) => out
                .push((
                    at,
                    Primitive::Cylinder {
                        radius: *radius,
                        length: *length,
                    },
                )),
            urdf_rs::Geometry::Sphere { radius } if ok(*radius) => {
                out.push((at, Primitive::Sphere { radius: *radius }));
            }
            urdf_rs::Geometry::Capsule { radius, length } if ok(*radius) && ok(*length) => {
                out.push((
                    at,
                    Primitive::Cylinder {
                        radius: *radius,
                        length: *length,
                    },
                ));
                for end in [-0.5, 0.5] {
                    let cap = at * Isometry::translation(0.0, 0.0, end * length);
                    out.push((cap, Primitive::Sphere { radius: *radius }));
                }
            }
            _ => return None,
        }
    }
    (!out.is_empty() && out.len() <= MAX_URDF_SHAPES_PER_LINK).then_some(out)
}
