//! Objects: shapes with mass properties, their state, and the Newton-Euler step (eq. 24-26).
//!
//! Formulation (docs/physics.md, "eq. 25-26 mix frames"): the object frame B sits at the centre of
//! mass; position and linear velocity are in the world frame, angular velocity in B. Wrenches
//! on the object are given in B at its origin, as the paper does. Newton-Euler:
//! `m v̇ = R f_B + m g`, `H ω̇ = m_B − ω × Hω`; orientation is integrated as a unit quaternion.

use crate::error::{DfsError, Result};
use crate::math::{force_of, moment_of, wrench, Isometry, Mat3, Real, Rotation, Vector, Wrench};
use crate::names::Named;
use serde::{Deserialize, Serialize};

mod surface;

/// The kind of an object's shape, without its sizes: `sphere`, `box` or `cylinder` in files,
/// the API and the data base.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    /// A sphere ([`Shape::Sphere`]).
    Sphere,
    /// A box ([`Shape::Box`]).
    Box,
    /// A cylinder ([`Shape::Cylinder`]).
    Cylinder,
}

impl Named for ShapeKind {
    const WHAT: &'static str = "shape";
    const ALL: &'static [Self] = &[ShapeKind::Sphere, ShapeKind::Box, ShapeKind::Cylinder];

    fn name(self) -> &'static str {
        ShapeKind::name(self)
    }
}

crate::named_enum!(ShapeKind);

impl ShapeKind {
    /// Name as in files, the API and the data base.
    pub fn name(self) -> &'static str {
        match self {
            ShapeKind::Sphere => "sphere",
            ShapeKind::Box => "box",
            ShapeKind::Cylinder => "cylinder",
        }
    }

    /// What the list of sizes of a shape of this kind holds (see [`Shape::sizes`]).
    pub fn sizes_meaning(self) -> &'static str {
        match self {
            ShapeKind::Sphere => "[radius]",
            ShapeKind::Box => "[half extent x, y, z]",
            ShapeKind::Cylinder => "[radius, half height]",
        }
    }
}

/// Geometric shape of an object, centred at the object frame B.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum Shape {
    /// A sphere of `radius` (m).
    Sphere {
        /// Radius (m), > 0.
        radius: Real,
    },
    /// A box with half extents along B's x, y, z (m).
    Box {
        /// Half extents (m), each > 0.
        half_extents: [Real; 3],
    },
    /// A cylinder with its axis along B's z.
    Cylinder {
        /// Radius (m), > 0.
        radius: Real,
        /// Half of the height (m), > 0.
        half_height: Real,
    },
}

impl Shape {
    /// The kind of the shape.
    pub fn kind(&self) -> ShapeKind {
        match self {
            Shape::Sphere { .. } => ShapeKind::Sphere,
            Shape::Box { .. } => ShapeKind::Box,
            Shape::Cylinder { .. } => ShapeKind::Cylinder,
        }
    }

    /// Name of the shape ("sphere", "box", "cylinder").
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// The shape's sizes as one list (m), the form a skill's object takes (`"size"`):
    /// `[radius]` (sphere), the half extents (box), `[radius, half_height]` (cylinder).
    pub fn sizes(&self) -> Vec<Real> {
        match *self {
            Shape::Sphere { radius } => vec![radius],
            Shape::Box { half_extents } => half_extents.to_vec(),
            Shape::Cylinder {
                radius,
                half_height,
            } => vec![radius, half_height],
        }
    }

    /// The shape of `kind` with the sizes of [`sizes`](Self::sizes), validated
    /// ([`validate`](Self::validate)); an error names `field` (the list's field, e.g.
    /// `object.size`) when the list is not as long as the kind needs.
    pub fn from_sizes(kind: ShapeKind, sizes: &[Real], field: &str) -> Result<Shape> {
        let wrong = || {
            DfsError::invalid(
                field,
                format!(
                    "a {kind} takes {} (m), got {} values",
                    kind.sizes_meaning(),
                    sizes.len()
                ),
            )
        };
        let shape = match (kind, sizes) {
            (ShapeKind::Sphere, &[radius]) => Shape::Sphere { radius },
            (ShapeKind::Box, &[x, y, z]) => Shape::Box {
                half_extents: [x, y, z],
            },
            (ShapeKind::Cylinder, &[radius, half_height]) => Shape::Cylinder {
                radius,
                half_height,
            },
            _ => return Err(wrong()),
        };
        shape.validate()?;
        Ok(shape)
    }

    /// Checks that every dimension is finite and positive; the error names the field.
    pub fn validate(&self) -> Result<()> {
        let check = |field: &str, v: Real| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(DfsError::invalid(
                    format!("object.{field}"),
                    format!("must be a finite number > 0, got {v}"),
                ))
            }
        };
        match *self {
            Shape::Sphere { radius } => check("radius", radius),
            Shape::Box { half_extents } => {
                for (i, h) in half_extents.iter().enumerate() {
                    check(&format!("half_extents[{i}]"), *h)?;
                }
                Ok(())
            }
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                check("radius", radius)?;
                check("half_height", half_height)
            }
        }
    }

    /// Principal moments of inertia about B's axes (kg·m²) of a uniform solid of mass `mass`:
    /// the one formula of the mass properties, for the simulation and the skills alike.
    pub fn principal_inertia(&self, mass: Real) -> [Real; 3] {
        match *self {
            Shape::Sphere { radius } => [0.4 * mass * radius * radius; 3],
            Shape::Box {
                half_extents: [a, b, c],
            } => {
                // Full edge lengths squared.
                let (x, y, z) = (4.0 * a * a, 4.0 * b * b, 4.0 * c * c);
                [
                    mass * (y + z) / 12.0,
                    mass * (x + z) / 12.0,
                    mass * (x + y) / 12.0,
                ]
            }
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let ixx = mass * (3.0 * radius * radius + 4.0 * half_height * half_height) / 12.0;
                [ixx, ixx, 0.5 * mass * radius * radius]
            }
        }
    }

    /// Rotational inertia about the centre for a uniform solid of mass `mass` (kg·m²): the
    /// [`principal_inertia`](Self::principal_inertia) on the diagonal.
    pub fn inertia(&self, mass: Real) -> Mat3 {
        Mat3::from_diagonal(&Vector::from(self.principal_inertia(mass)))
    }

    /// Signed distance from a point in B to the surface (negative inside), the closest surface
    /// point, and the outward unit normal there.
    pub fn closest(&self, p_b: &Vector) -> (Real, Vector, Vector) {
        match *self {
            Shape::Sphere { radius } => {
                let n = p_b.norm();
                let dir = if n > 1e-12 {
                    p_b * (1.0 / n)
                } else {
                    Vector::z()
                };
                (n - radius, dir * radius, dir)
            }
            Shape::Box { half_extents } => closest_on_box(p_b, &Vector::from(half_extents)),
            Shape::Cylinder {
                radius,
                half_height,
            } => closest_on_cylinder(p_b, radius, half_height),
        }
    }

    /// Distance (m) from the centre to the lowest point when the object is rotated by
    /// `rotation` in the world (the depth it rests at on a horizontal table).
    pub fn support_depth(&self, rotation: &Rotation) -> Real {
        let r = rotation.to_rotation_matrix();
        let m = r.matrix();
        match *self {
            Shape::Sphere { radius } => radius,
            Shape::Box { half_extents } => (0..3).map(|i| m[(2, i)].abs() * half_extents[i]).sum(),
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let az = m[(2, 2)].abs();
                radius * (1.0 - az * az).max(0.0).sqrt() + half_height * az
            }
        }
    }

    /// The shape's points that can touch a horizontal table below it, for its orientation
    /// `rotation` in the world: those no more than `margin` (m) above its lowest point, written
    /// to `out` (the rest of it untouched); returns how many. Each point keeps its
    /// [`id`](TablePoint::id) from one orientation to the next, so a contact solver can start
    /// from the last tick's impulses.
    ///
    /// - a sphere: its lowest point;
    /// - a box: its corners (the 4 of its lowest face when it stands on it, 2 of an edge, 1 of a
    ///   corner);
    /// - a cylinder: [`CYLINDER_RIM_POINTS`] points evenly around the rim of each end face, and
    ///   each rim's lowest point when the face is tilted: standing, the rim points of the lower
    ///   face (a regular polygon inscribed in it); lying, the two rims' lowest points (the line
    ///   it lies on); on its rim, its lowest point.
    pub fn table_points(
        &self,
        rotation: &Rotation,
        margin: Real,
        out: &mut [TablePoint; MAX_TABLE_POINTS],
    ) -> usize {
        let r = rotation.to_rotation_matrix();
        let m = r.matrix();
        // The world's up in B: a point's height above the centre is `up_b · p_b`.
        let up_b = Vector::new(m[(2, 0)], m[(2, 1)], m[(2, 2)]);
        let reach = margin - self.support_depth(rotation);
        let mut n = 0;
        let mut push = |id: usize, p_b: Vector| {
            if up_b.dot(&p_b) <= reach && n < MAX_TABLE_POINTS {
                out[n] = TablePoint { id, p_b };
                n += 1;
            }
        };
        match *self {
            Shape::Sphere { radius } => push(0, -up_b * radius),
            Shape::Box { half_extents: h } => {
                for id in 0..8 {
                    let sign = |bit: usize| if id & (1 << bit) == 0 { -1.0 } else { 1.0 };
                    push(
                        id,
                        Vector::new(sign(0) * h[0], sign(1) * h[1], sign(2) * h[2]),
                    );
                }
            }
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let across = Vector::new(up_b.x, up_b.y, 0.0).norm();
                for (cap, z) in [-half_height, half_height].into_iter().enumerate() {
                    let first = cap * (CYLINDER_RIM_POINTS + 1);
                    for (j, (c, s)) in RIM_DIRECTIONS.iter().enumerate() {
                        push(first + j, Vector::new(radius * c, radius * s, z));
                    }
                    // Tilted, the rim's lowest point lies between the fixed ones. Within 0.01
                    // rad of level it is left out: it is then less than 0.04 % of the radius
                    // lower than the nearest fixed point (12 µm on a 3.5 cm rim), and its
                    // direction is ill-defined near level.
                    if across > RIM_LOWEST_POINT_TILT {
                        let k = radius / across;
                        push(
                            first + CYLINDER_RIM_POINTS,
                            Vector::new(-up_b.x * k, -up_b.y * k, z),
                        );
                    }
                }
            }
        }
        n
    }

    /// Whether the shape can roll on a table where `points` ([`table_points`](Self::table_points))
    /// touch it: a sphere always, a cylinder lying or on its rim (a rim's lowest point among
    /// them); a box, or a cylinder standing on an end face, not.
    pub fn rolls_on(&self, points: &[TablePoint]) -> bool {
        match self {
            Shape::Sphere { .. } => true,
            Shape::Box { .. } => false,
            Shape::Cylinder { .. } => points
                .iter()
                .any(|p| p.id % (CYLINDER_RIM_POINTS + 1) == CYLINDER_RIM_POINTS),
        }
    }

    /// Bounding radius about the centre (m).
    pub fn bounding_radius(&self) -> Real {
        match *self {
            Shape::Sphere { radius } => radius,
            Shape::Box { half_extents } => Vector::from(half_extents).norm(),
            Shape::Cylinder {
                radius,
                half_height,
            } => (radius * radius + half_height * half_height).sqrt(),
        }
    }
}

impl Shape {
    /// The shape's support point in direction `d_b` (B): its point farthest along `d_b`, the
    /// support mapping that [`shapes_overlap`] runs GJK on. Any farthest point when several
    /// are (a face): the one with coordinates of the positive sign where `d_b` has a zero.
    pub fn support(&self, d_b: &Vector) -> Vector {
        let sign = |v: Real| if v < 0.0 { -1.0 } else { 1.0 };
        match *self {
            Shape::Sphere { radius } => {
                let n = d_b.norm();
                if n > 0.0 {
                    d_b * (radius / n)
                } else {
                    Vector::new(radius, 0.0, 0.0)
                }
            }
            Shape::Box { half_extents: h } => {
                Vector::new(sign(d_b.x) * h[0], sign(d_b.y) * h[1], sign(d_b.z) * h[2])
            }
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let rho = (d_b.x * d_b.x + d_b.y * d_b.y).sqrt();
                let (x, y) = if rho > 0.0 {
                    (d_b.x * radius / rho, d_b.y * radius / rho)
                } else {
                    (0.0, 0.0)
                };
                Vector::new(x, y, sign(d_b.z) * half_height)
            }
        }
    }
}

/// How many points evenly spaced around each rim of a cylinder may touch a table
/// ([`Shape::table_points`]): 12. A cylinder standing on an end face rests on the regular
/// 12-gon they make, whose edges lie within 3.4 % of the radius of the rim.
pub const CYLINDER_RIM_POINTS: usize = 12;

/// The most points of one shape that may touch a table ([`Shape::table_points`]): a
/// cylinder's [`CYLINDER_RIM_POINTS`] and lowest point on each rim.
pub const MAX_TABLE_POINTS: usize = 2 * (CYLINDER_RIM_POINTS + 1);

/// How far (the sine of the angle) an end face of a cylinder must be tilted for its rim's
/// lowest point to be one of the points that may touch a table ([`Shape::table_points`]):
/// 0.01.
pub const RIM_LOWEST_POINT_TILT: Real = 0.01;

/// `(cos, sin)` of the directions of a cylinder's rim points, 30° apart.
const RIM_DIRECTIONS: [(Real, Real); CYLINDER_RIM_POINTS] = {
    const H: Real = 0.866_025_403_784_438_6; // √3 / 2
    [
        (1.0, 0.0),
        (H, 0.5),
        (0.5, H),
        (0.0, 1.0),
        (-0.5, H),
        (-H, 0.5),
        (-1.0, 0.0),
        (-H, -0.5),
        (-0.5, -H),
        (0.0, -1.0),
        (0.5, -H),
        (H, -0.5),
    ]
};

/// A point of a shape that may touch a table ([`Shape::table_points`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TablePoint {
    /// Which of the shape's points it is: the same point has the same id in every
    /// orientation (a box's corner, a cylinder's rim point; a rim's lowest point, which moves
    /// around the rim, keeps one id too). Below [`MAX_TABLE_POINTS`].
    pub id: usize,
    /// The point in B (m).
    pub p_b: Vector,
}

impl Default for TablePoint {
    fn default() -> Self {
        TablePoint {
            id: 0,
            p_b: Vector::zeros(),
        }
    }
}

/// How deep (m) two shapes must interpenetrate before [`shapes_overlap`] calls it an overlap:
/// 0.1 mm. Shapes that only touch, or are a rounding error apart, do not overlap.
pub const OVERLAP_TOLERANCE: Real = 1e-4;

/// The support point (world) of shape `a` at `pose_a` minus that of `b` at `pose_b` in the
/// opposite direction: the support mapping of the Minkowski difference A − B along `d`.
fn minkowski_support(
    a: &Shape,
    pose_a: &Isometry,
    b: &Shape,
    pose_b: &Isometry,
    d: &Vector,
) -> Vector {
    let sa =
        pose_a.rotation * a.support(&(pose_a.rotation.inverse() * d)) + pose_a.translation.vector;
    let sb =
        pose_b.rotation * b.support(&(pose_b.rotation.inverse() * -d)) + pose_b.translation.vector;
    sa - sb
}

/// Whether two shapes at their world poses interpenetrate by more than [`OVERLAP_TOLERANCE`]:
/// the Gilbert-Johnson-Keerthi test on the shapes' support mappings ([`Shape::support`]), exact
/// for these convex shapes up to the tolerance. Bounding spheres farther apart than their radii
/// answer at once. Allocation-free (the DFS runs it every tick for each pair of objects).
pub fn shapes_overlap(a: &Shape, pose_a: &Isometry, b: &Shape, pose_b: &Isometry) -> bool {
    let between = pose_b.translation.vector - pose_a.translation.vector;
    let reach = a.bounding_radius() + b.bounding_radius() - OVERLAP_TOLERANCE;
    if between.norm_squared() >= reach * reach || reach <= 0.0 {
        return false;
    }
    let support = |d: &Vector| minkowski_support(a, pose_a, b, pose_b, d);
    // The simplex, newest point last.
    let mut simplex = [Vector::zeros(); 4];
    let mut d = if between.norm_squared() > 0.0 {
        -between
    } else {
        Vector::x()
    };
    simplex[0] = support(&d);
    let mut n = 1;
    d = -simplex[0];
    for _ in 0..64 {
        let len = d.norm();
        if len < 1e-12 {
            // The origin lies on the simplex: the shapes touch at least; only a penetration
            // deeper than the tolerance counts, and that keeps the origin off every face.
            return false;
        }
        let p = support(&d);
        // No point of A − B lies past the origin along d by more than the tolerance: a plane
        // separates the shapes (up to it).
        if p.dot(&d) / len < OVERLAP_TOLERANCE {
            return false;
        }
        simplex[n] = p;
        n += 1;
        if next_simplex(&mut simplex, &mut n, &mut d) {
            return true;
        }
    }
    // No separating plane found in 64 steps: GJK converges in a few for these shapes, so the
    // origin is (as good as) inside.
    true
}

/// One GJK simplex update: reduces `simplex[..n]` (newest last) to the feature nearest the
/// origin and sets `d` towards the origin from it; true when a tetrahedron encloses the origin.
fn next_simplex(s: &mut [Vector; 4], n: &mut usize, d: &mut Vector) -> bool {
    let same = |a: &Vector, b: &Vector| a.dot(b) > 0.0;
    match *n {
        2 => {
            let (a, b) = (s[1], s[0]);
            let (ab, ao) = (b - a, -a);
            if same(&ab, &ao) {
                *d = ab.cross(&ao).cross(&ab);
                if d.norm_squared() < 1e-24 {
                    // The origin on the segment's line: any direction across it.
                    *d = any_orthogonal(&ab);
                }
            } else {
                s[0] = a;
                *n = 1;
                *d = ao;
            }
            false
        }
        3 => {
            let (a, b, c) = (s[2], s[1], s[0]);
            triangle(s, n, d, a, b, c)
        }
        4 => {
            let (a, b, c, dd) = (s[3], s[2], s[1], s[0]);
            let ao = -a;
            let (ab, ac, ad) = (b - a, c - a, dd - a);
            let abc = ab.cross(&ac);
            let acd = ac.cross(&ad);
            let adb = ad.cross(&ab);
            // Each face's normal, turned away from the fourth point.
            let out = |nrm: Vector, other: &Vector| if nrm.dot(other) > 0.0 { -nrm } else { nrm };
            let (abc, acd, adb) = (out(abc, &ad), out(acd, &ab), out(adb, &ac));
            if same(&abc, &ao) {
                return triangle(s, n, d, a, b, c);
            }
            if same(&acd, &ao) {
                return triangle(s, n, d, a, c, dd);
            }
            if same(&adb, &ao) {
                return triangle(s, n, d, a, dd, b);
            }
            true
        }
        _ => false,
    }
}

/// The triangle case of [`next_simplex`]: `a` the newest point.
fn triangle(
    s: &mut [Vector; 4],
    n: &mut usize,
    d: &mut Vector,
    a: Vector,
    b: Vector,
    c: Vector,
) -> bool {
    let same = |x: &Vector, y: &Vector| x.dot(y) > 0.0;
    let ao = -a;
    let (ab, ac) = (b - a, c - a);
    let abc = ab.cross(&ac);
    if same(&abc.cross(&ac), &ao) {
        if same(&ac, &ao) {
            s[0] = c;
            s[1] = a;
            *n = 2;
            *d = ac.cross(&ao).cross(&ac);
            if d.norm_squared() < 1e-24 {
                *d = any_orthogonal(&ac);
            }
            return false;
        }
        return line_or_point(s, n, d, a, b);
    }
    if same(&ab.cross(&abc), &ao) {
        return line_or_point(s, n, d, a, b);
    }
    if same(&abc, &ao) {
        s[0] = c;
        s[1] = b;
        s[2] = a;
        *d = abc;
    } else {
        s[0] = b;
        s[1] = c;
        s[2] = a;
        *d = -abc;
    }
    *n = 3;
    if d.norm_squared() < 1e-24 {
        // A degenerate (flat) triangle: search across it.
        *d = any_orthogonal(&ab);
    }
    false
}

fn line_or_point(s: &mut [Vector; 4], n: &mut usize, d: &mut Vector, a: Vector, b: Vector) -> bool {
    let (ab, ao) = (b - a, -a);
    if ab.dot(&ao) > 0.0 {
        s[0] = b;
        s[1] = a;
        *n = 2;
        *d = ab.cross(&ao).cross(&ab);
        if d.norm_squared() < 1e-24 {
            *d = any_orthogonal(&ab);
        }
    } else {
        s[0] = a;
        *n = 1;
        *d = ao;
    }
    false
}

/// A unit vector orthogonal to `v` (any, deterministic).
fn any_orthogonal(v: &Vector) -> Vector {
    let axis = if v.x.abs() < 0.6 {
        Vector::x()
    } else {
        Vector::y()
    };
    let o = v.cross(&axis);
    let n = o.norm();
    if n > 0.0 {
        o / n
    } else {
        Vector::z()
    }
}

fn closest_on_box(p: &Vector, h: &Vector) -> (Real, Vector, Vector) {
    let q = p.abs() - h;
    let outside = Vector::new(q.x.max(0.0), q.y.max(0.0), q.z.max(0.0));
    if outside.norm() > 0.0 {
        // Outside: clamp to the box.
        let c = Vector::new(
            p.x.clamp(-h.x, h.x),
            p.y.clamp(-h.y, h.y),
            p.z.clamp(-h.z, h.z),
        );
        let d = p - c;
        let dist = d.norm();
        (dist, c, d / dist)
    } else {
        // Inside: the nearest face.
        let mut axis = 0;
        for k in 1..3 {
            if q[k] > q[axis] {
                axis = k;
            }
        }
        let s = if p[axis] >= 0.0 { 1.0 } else { -1.0 };
        let mut c = *p;
        c[axis] = s * h[axis];
        let mut n = Vector::zeros();
        n[axis] = s;
        (q[axis], c, n)
    }
}

fn closest_on_cylinder(p: &Vector, r: Real, hh: Real) -> (Real, Vector, Vector) {
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    let radial = if rho > 1e-12 {
        Vector::new(p.x / rho, p.y / rho, 0.0)
    } else {
        Vector::x()
    };
    let dr = rho - r;
    let dz = p.z.abs() - hh;
    let sz = if p.z >= 0.0 { 1.0 } else { -1.0 };
    if dr > 0.0 && dz > 0.0 {
        // Outside near the rim: closest point on the rim circle.
        let c = radial * r + Vector::new(0.0, 0.0, sz * hh);
        let d = p - c;
        let dist = d.norm();
        (dist, c, d / dist)
    } else if dr > dz {
        // Closest to the curved side.
        let c = radial * r + Vector::new(0.0, 0.0, p.z.clamp(-hh, hh));
        (dr, c, radial)
    } else {
        // Closest to a cap.
        let c = Vector::new(p.x, p.y, sz * hh)
            - if rho > r {
                radial * (rho - r)
            } else {
                Vector::zeros()
            };
        (dz, c, Vector::new(0.0, 0.0, sz))
    }
}

/// A rigid object: shape, mass properties and friction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidObject {
    /// Geometry, centred at B.
    pub shape: Shape,
    /// Mass (kg), > 0.
    pub mass: Real,
    /// Rotational inertia about the centre of mass in B (kg·m²).
    pub inertia: Mat3,
    /// Its inverse.
    pub inertia_inv: Mat3,
}

impl RigidObject {
    /// A uniform solid of the given shape and mass; validates both.
    pub fn new(shape: Shape, mass: Real) -> Result<Self> {
        shape.validate()?;
        if !(mass.is_finite() && mass > 0.0) {
            return Err(DfsError::invalid(
                "object.mass",
                format!("must be a finite number > 0 kg, got {mass}"),
            ));
        }
        let inertia = shape.inertia(mass);
        let inertia_inv = inertia
            .try_inverse()
            .ok_or_else(|| DfsError::invalid("object", "singular inertia"))?;
        Ok(RigidObject {
            shape,
            mass,
            inertia,
            inertia_inv,
        })
    }

    /// Spatial inertia `M* = diag(m I, H)` applied to an acceleration (v̇, ω̇).
    pub fn spatial_inertia_times(&self, acc: &Wrench) -> Wrench {
        wrench(
            &(force_of(acc) * self.mass),
            &(self.inertia * moment_of(acc)),
        )
    }
}

/// State of an object: pose of B in the world, world linear velocity, body angular velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectState {
    /// Pose of B in the world frame.
    pub pose: Isometry,
    /// Velocity of B's origin in the world frame (m/s).
    pub linear_velocity: Vector,
    /// Angular velocity in B (rad/s).
    pub angular_velocity_b: Vector,
}

impl ObjectState {
    /// At rest at `pose`.
    pub fn at_rest(pose: Isometry) -> Self {
        ObjectState {
            pose,
            linear_velocity: Vector::zeros(),
            angular_velocity_b: Vector::zeros(),
        }
    }

    /// Twist in B (linear velocity rotated into B, angular velocity in B).
    pub fn twist_b(&self) -> Wrench {
        wrench(
            &(self.pose.rotation.inverse() * self.linear_velocity),
            &self.angular_velocity_b,
        )
    }

    /// Velocity (world frame) of a point given in B.
    pub fn point_velocity(&self, p_b: &Vector) -> Vector {
        self.linear_velocity + self.pose.rotation * self.angular_velocity_b.cross(p_b)
    }
}

/// The gravity wrench `M* [ᴮg; 0]` in B (eq. 24) for gravity `g_world`.
pub fn gravity_wrench_b(obj: &RigidObject, rotation: &Rotation, g_world: &Vector) -> Wrench {
    wrench(&(rotation.inverse() * g_world * obj.mass), &Vector::zeros())
}

/// `f_ext` (eq. 26): the wrench in B that accelerates the object, from the hand's wrench
/// `f_hand_b`, gravity, and the gyroscopic term `ω × Hω`. (The paper's `ω × m v` term is the
/// body-frame linear formulation; with world-frame linear motion it vanishes.)
pub fn external_wrench_b(
    obj: &RigidObject,
    state: &ObjectState,
    f_hand_b: &Wrench,
    g_world: &Vector,
) -> Wrench {
    let w = state.angular_velocity_b;
    let gyro = w.cross(&(obj.inertia * w));
    let g = gravity_wrench_b(obj, &state.pose.rotation, g_world);
    f_hand_b + g - wrench(&Vector::zeros(), &gyro)
}

/// Accelerations from `f_ext` in B: (world linear acceleration, body angular acceleration).
/// `f_ext` already contains gravity and the gyroscopic term (see [`external_wrench_b`]).
pub fn accelerations(obj: &RigidObject, state: &ObjectState, f_ext_b: &Wrench) -> (Vector, Vector) {
    let a_world = state.pose.rotation * force_of(f_ext_b) / obj.mass;
    let alpha_b = obj.inertia_inv * moment_of(f_ext_b);
    (a_world, alpha_b)
}

/// One semi-implicit Euler step of length `dt` (s) under `f_ext` in B. Velocities first,
/// then pose with the new velocities; orientation by the exponential map, renormalised.
pub fn integrate(obj: &RigidObject, state: &mut ObjectState, f_ext_b: &Wrench, dt: Real) {
    let (a, alpha) = accelerations(obj, state, f_ext_b);
    state.linear_velocity += a * dt;
    state.angular_velocity_b += alpha * dt;
    state.pose.translation.vector += state.linear_velocity * dt;
    let dq = Rotation::from_scaled_axis(state.angular_velocity_b * dt);
    state.pose.rotation = Rotation::new_normalize((state.pose.rotation * dq).into_inner());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The points of `shape` within 0.1 mm of its lowest at `rotation`: their ids, and each
    /// one's height above the centre.
    fn lowest(shape: &Shape, rotation: &Rotation) -> Vec<(usize, Real)> {
        let mut out = [TablePoint::default(); MAX_TABLE_POINTS];
        let n = shape.table_points(rotation, 1e-4, &mut out);
        out[..n]
            .iter()
            .map(|p| (p.id, (rotation * p.p_b).z))
            .collect()
    }

    #[test]
    fn a_shape_touches_a_table_at_its_lowest_face_edge_or_corner() {
        let b = Shape::Box {
            half_extents: [0.025, 0.025, 0.04],
        };
        let level = Rotation::identity();
        let face = lowest(&b, &level);
        assert_eq!(
            face.iter().map(|p| p.0).collect::<Vec<_>>(),
            [0, 1, 2, 3],
            "the bottom face's corners"
        );
        assert!(face.iter().all(|p| (p.1 + 0.04).abs() < 1e-15));
        // Tilted 0.2 rad about x: the edge of its two corners on the −y side.
        let tilted = Rotation::from_euler_angles(0.2, 0.0, 0.0);
        let edge = lowest(&b, &tilted);
        assert_eq!(edge.len(), 2, "{edge:?}");
        for (id, z) in &edge {
            assert!((z + b.support_depth(&tilted)).abs() < 1e-15);
            assert_eq!(id & 0b110, 0b000, "y and z negative: {id}");
        }
        let corner = lowest(&b, &Rotation::from_euler_angles(0.2, 0.3, 0.1));
        assert_eq!(corner.len(), 1);

        let sphere = Shape::Sphere { radius: 0.04 };
        let r = Rotation::from_euler_angles(0.3, 0.2, 0.1);
        let p = lowest(&sphere, &r);
        assert_eq!(p.len(), 1);
        assert!((p[0].1 + 0.04).abs() < 1e-15);

        let cyl = Shape::Cylinder {
            radius: 0.03,
            half_height: 0.06,
        };
        let standing = lowest(&cyl, &level);
        assert_eq!(
            standing.len(),
            CYLINDER_RIM_POINTS,
            "the lower rim, no lowest point"
        );
        assert!(standing.iter().all(|p| p.0 < CYLINDER_RIM_POINTS));
        let on_side = Rotation::from_euler_angles(std::f64::consts::FRAC_PI_2 + 0.1, 0.0, 0.0)
            * Rotation::from_euler_angles(0.0, 0.0, 0.1);
        let lying = Rotation::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0)
            * Rotation::from_euler_angles(0.0, 0.0, 0.1);
        let line = lowest(&cyl, &lying);
        assert_eq!(
            line.iter().map(|p| p.0).collect::<Vec<_>>(),
            [CYLINDER_RIM_POINTS, 2 * CYLINDER_RIM_POINTS + 1],
            "each rim's lowest point"
        );
        assert!(line
            .iter()
            .all(|p| (p.1 + cyl.support_depth(&lying)).abs() < 1e-15));
        let rim = lowest(&cyl, &on_side);
        assert_eq!(rim.len(), 1, "on its rim: {rim:?}");
        assert!((rim[0].1 + cyl.support_depth(&on_side)).abs() < 1e-15);

        // What rolls: a sphere, a cylinder lying or on its rim; not a box, nor a cylinder
        // standing.
        let mut out = [TablePoint::default(); MAX_TABLE_POINTS];
        let mut rolls = |shape: &Shape, r: &Rotation| {
            let n = shape.table_points(r, 1e-4, &mut out);
            shape.rolls_on(&out[..n])
        };
        assert!(rolls(&sphere, &level));
        assert!(!rolls(&b, &tilted));
        assert!(!rolls(&cyl, &level));
        assert!(rolls(&cyl, &lying));
        assert!(rolls(&cyl, &on_side));
    }

    #[test]
    fn an_object_with_no_hand_falls_at_g() {
        let obj = RigidObject::new(Shape::Sphere { radius: 0.1 }, 1.0).unwrap();
        let mut s = ObjectState::at_rest(Isometry::identity());
        let g = Vector::new(0.0, 0.0, -9.81);
        for _ in 0..1000 {
            let f = external_wrench_b(&obj, &s, &Wrench::zeros(), &g);
            integrate(&obj, &mut s, &f, 1e-3);
        }
        assert!((s.linear_velocity.z + 9.81).abs() < 1e-9);
        // Semi-implicit Euler: z = -g dt² n(n+1)/2.
        assert!((s.pose.translation.z + 9.81 * 1e-6 * 1000.0 * 1001.0 / 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_torque_free_spinning_box_keeps_its_angular_momentum_and_unit_quaternion() {
        let obj = RigidObject::new(
            Shape::Box {
                half_extents: [0.05, 0.1, 0.2],
            },
            2.0,
        )
        .unwrap();
        let mut s = ObjectState::at_rest(Isometry::identity());
        s.angular_velocity_b = Vector::new(0.1, 3.0, 0.1);
        let l0 = s.pose.rotation * (obj.inertia * s.angular_velocity_b);
        for _ in 0..2000 {
            let f = external_wrench_b(&obj, &s, &Wrench::zeros(), &Vector::zeros());
            integrate(&obj, &mut s, &f, 1e-4);
        }
        let l1 = s.pose.rotation * (obj.inertia * s.angular_velocity_b);
        assert!((l1 - l0).norm() / l0.norm() < 1e-2);
        assert!((s.pose.rotation.into_inner().norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn closest_points_lie_on_the_surface_for_every_shape() {
        let shapes = [
            Shape::Sphere { radius: 0.1 },
            Shape::Box {
                half_extents: [0.05, 0.03, 0.08],
            },
            Shape::Cylinder {
                radius: 0.04,
                half_height: 0.1,
            },
        ];
        let pts = [
            Vector::new(0.2, 0.01, -0.03),
            Vector::new(0.0, 0.0, 0.3),
            Vector::new(0.01, 0.005, 0.002),
            Vector::new(-0.1, 0.1, 0.2),
        ];
        for s in shapes {
            for p in pts {
                let (d, c, n) = s.closest(&p);
                let (d_c, _, _) = s.closest(&c);
                assert!(d_c.abs() < 1e-9, "{s:?} {p:?}");
                assert!((n.norm() - 1.0).abs() < 1e-9);
                if d > 0.0 {
                    assert!(((p - c).norm() - d).abs() < 1e-9);
                }
            }
        }
    }

    #[test]
    fn shape_kinds_are_named_as_in_files_and_unknown_ones_are_refused() {
        crate::names::assert_serde_agrees::<ShapeKind>();
        assert_eq!("box".parse::<ShapeKind>(), Ok(ShapeKind::Box));
        assert_eq!(format!("[{:<8}]", ShapeKind::Box), "[box     ]");
        let e = serde_json::from_str::<ShapeKind>("\"torus\"").unwrap_err();
        assert!(
            e.to_string()
                .contains("unknown shape \"torus\"; expected one of sphere, box, cylinder"),
            "{e}"
        );
        assert!(
            "Sphere".parse::<ShapeKind>().is_err(),
            "names are lower case"
        );
        let e = serde_json::from_str::<ShapeKind>("3").unwrap_err();
        assert!(e.to_string().contains("expected a shape name"), "{e}");
    }

    #[test]
    fn a_shape_goes_to_its_list_of_sizes_and_back() {
        let shapes = [
            Shape::Sphere { radius: 0.1 },
            Shape::Box {
                half_extents: [0.05, 0.03, 0.08],
            },
            Shape::Cylinder {
                radius: 0.04,
                half_height: 0.1,
            },
        ];
        for s in shapes {
            assert_eq!(Shape::from_sizes(s.kind(), &s.sizes(), "size"), Ok(s));
        }
        let e = Shape::from_sizes(ShapeKind::Box, &[0.1], "skill.object.size").unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid skill.object.size: a box takes [half extent x, y, z] (m), got 1 values"
        );
        let e = Shape::from_sizes(ShapeKind::Sphere, &[-0.1], "size").unwrap_err();
        assert!(e.to_string().contains("object.radius"), "{e}");
    }

    #[test]
    fn the_principal_inertia_is_the_diagonal_of_the_inertia() {
        let b = Shape::Box {
            half_extents: [0.025, 0.025, 0.04],
        };
        let i = b.principal_inertia(0.2);
        // m (b² + c²) / 12 with full edges 0.05 and 0.08.
        assert!((i[0] - 0.2 * (0.0025 + 0.0064) / 12.0).abs() < 1e-15);
        assert!((i[2] - 0.2 * 0.005 / 12.0).abs() < 1e-15);
        let m = b.inertia(0.2);
        assert_eq!([m[(0, 0)], m[(1, 1)], m[(2, 2)]], i);
        assert_eq!(m[(0, 1)], 0.0);
    }

    fn at(x: Real, y: Real, z: Real, yaw: Real) -> Isometry {
        Isometry::from_parts(
            Vector::new(x, y, z).into(),
            Rotation::from_euler_angles(0.0, 0.0, yaw),
        )
    }

    #[test]
    fn spheres_overlap_when_closer_than_their_radii_and_touching_ones_do_not() {
        let (a, b) = (
            Shape::Sphere { radius: 0.04 },
            Shape::Sphere { radius: 0.03 },
        );
        let o = Isometry::identity();
        for (d, overlap) in [(0.069, true), (0.0695, true), (0.07, false), (0.071, false)] {
            assert_eq!(
                shapes_overlap(&a, &o, &b, &at(d, 0.0, 0.0, 0.0)),
                overlap,
                "{d}"
            );
            // Any direction, either order.
            let p = at(d * 0.6, d * 0.48, -d * 0.64, 0.0);
            assert_eq!(shapes_overlap(&b, &p, &a, &o), overlap, "{d}");
        }
        assert!(shapes_overlap(&a, &o, &b, &o), "concentric");
    }

    #[test]
    fn boxes_and_cylinders_overlap_by_their_shapes_not_their_bounding_spheres() {
        let cube = Shape::Box {
            half_extents: [0.05, 0.05, 0.05],
        };
        let o = Isometry::identity();
        assert!(!shapes_overlap(&cube, &o, &cube, &at(0.101, 0.0, 0.0, 0.0)));
        assert!(shapes_overlap(&cube, &o, &cube, &at(0.099, 0.0, 0.0, 0.0)));
        // Diagonal neighbours: bounding spheres (0.087 m each) overlap, the cubes do not.
        assert!(!shapes_overlap(
            &cube,
            &o,
            &cube,
            &at(0.102, 0.102, 0.0, 0.0)
        ));
        // Turned 45°, a cube reaches 0.0707 m along x.
        let reach = 0.05 * 2.0_f64.sqrt();
        let turned = |x: Real| at(x, 0.0, 0.0, std::f64::consts::FRAC_PI_4);
        assert!(!shapes_overlap(
            &cube,
            &o,
            &cube,
            &turned(0.05 + reach + 0.001)
        ));
        assert!(shapes_overlap(
            &cube,
            &o,
            &cube,
            &turned(0.05 + reach - 0.001)
        ));
        // A small cube at 45° beside an upright cylinder (r 3 cm): its corner meets the side
        // where √2 (c − 0.02) = 0.03.
        let cyl = Shape::Cylinder {
            radius: 0.03,
            half_height: 0.05,
        };
        let small = Shape::Box {
            half_extents: [0.02, 0.02, 0.02],
        };
        assert!(!shapes_overlap(
            &cyl,
            &o,
            &small,
            &at(0.043, 0.043, 0.0, 0.0)
        ));
        assert!(shapes_overlap(
            &cyl,
            &o,
            &small,
            &at(0.0395, 0.0395, 0.0, 0.0)
        ));
        // Above the cylinder's cap.
        assert!(!shapes_overlap(&cyl, &o, &small, &at(0.0, 0.0, 0.071, 0.0)));
        assert!(shapes_overlap(&cyl, &o, &small, &at(0.0, 0.0, 0.069, 0.0)));
    }

    /// Penetration depth of two boxes by the separating axis theorem (15 axes), negative when
    /// a plane separates them: an oracle independent of GJK.
    fn box_depth(ha: [Real; 3], pa: &Isometry, hb: [Real; 3], pb: &Isometry) -> Real {
        let ra = pa.rotation.to_rotation_matrix();
        let rb = pb.rotation.to_rotation_matrix();
        let axes_a: Vec<Vector> = (0..3).map(|i| ra.matrix().column(i).into_owned()).collect();
        let axes_b: Vec<Vector> = (0..3).map(|i| rb.matrix().column(i).into_owned()).collect();
        let mut axes: Vec<Vector> = axes_a.iter().chain(&axes_b).copied().collect();
        for a in &axes_a {
            for b in &axes_b {
                let c = a.cross(b);
                if c.norm() > 1e-9 {
                    axes.push(c.normalize());
                }
            }
        }
        let d = pb.translation.vector - pa.translation.vector;
        axes.iter()
            .map(|n| {
                let ea: Real = (0..3).map(|i| ha[i] * axes_a[i].dot(n).abs()).sum();
                let eb: Real = (0..3).map(|i| hb[i] * axes_b[i].dot(n).abs()).sum();
                ea + eb - d.dot(n).abs()
            })
            .fold(Real::INFINITY, Real::min)
    }

    #[test]
    fn gjk_agrees_with_the_separating_axis_test_on_random_boxes() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut checked = 0;
        for _ in 0..4000 {
            let mut h = || [0.0; 3].map(|_: Real| rng.random_range(0.005..0.06));
            let (ha, hb) = (h(), h());
            let mut pose = || {
                Isometry::from_parts(
                    Vector::new(
                        rng.random_range(-0.1..0.1),
                        rng.random_range(-0.1..0.1),
                        rng.random_range(-0.1..0.1),
                    )
                    .into(),
                    Rotation::from_euler_angles(
                        rng.random_range(-3.0..3.0),
                        rng.random_range(-3.0..3.0),
                        rng.random_range(-3.0..3.0),
                    ),
                )
            };
            let (pa, pb) = (pose(), pose());
            let depth = box_depth(ha, &pa, hb, &pb);
            let (a, b) = (
                Shape::Box { half_extents: ha },
                Shape::Box { half_extents: hb },
            );
            let gjk = shapes_overlap(&a, &pa, &b, &pb);
            if depth > OVERLAP_TOLERANCE + 1e-6 {
                assert!(gjk, "depth {depth}: {ha:?} {pa:?} {hb:?} {pb:?}");
                checked += 1;
            } else if depth < -1e-6 {
                assert!(!gjk, "apart by {}: {ha:?} {pa:?} {hb:?} {pb:?}", -depth);
                checked += 1;
            }
        }
        assert!(checked > 3500, "{checked}");
    }

    #[test]
    fn bad_shapes_and_masses_name_the_field() {
        let e = RigidObject::new(Shape::Sphere { radius: 0.1 }, -1.0).unwrap_err();
        assert!(e.to_string().contains("object.mass"));
        let e = RigidObject::new(
            Shape::Box {
                half_extents: [0.1, f64::NAN, 0.1],
            },
            1.0,
        )
        .unwrap_err();
        assert!(e.to_string().contains("half_extents[1]"));
    }
}
