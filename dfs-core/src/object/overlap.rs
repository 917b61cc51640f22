//! Whether two shapes interpenetrate: the shapes' support mappings and the
//! Gilbert-Johnson-Keerthi test on their Minkowski difference, allocation-free.

use super::Shape;
use crate::math::{Isometry, Real, Vector};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rotation;

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
}
