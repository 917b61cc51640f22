//! Points on a shape's surface that the replay planner places contacts at: the nearest surface
//! point with its inward normal, where a ray from the centre leaves the surface, how far a
//! contact can slide on one face, and an antipodal pinch.

use super::{ClosestPoint, Shape};
use crate::math::{perpendicular, Real, Vector};

impl Shape {
    /// The point on the surface nearest `p_b` and the inward normal there, both in B.
    pub(crate) fn on_surface(&self, p_b: &Vector) -> (Vector, Vector) {
        let c = self.closest(p_b);
        (c.point, -c.normal)
    }

    /// Where the ray from the centre along unit `dir` leaves the surface (B), with the outward
    /// normal there: bisection on the signed distance (the shapes are convex).
    pub(crate) fn surface_along(&self, dir: &Vector) -> (Vector, Vector) {
        let (mut lo, mut hi) = (0.0, self.bounding_radius() * 1.01 + 1e-6);
        for _ in 0..48 {
            let mid = 0.5 * (lo + hi);
            if self.closest(&(dir * mid)).distance < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let p = dir * hi;
        (p, self.closest(&p).normal)
    }

    /// How far (m, at most `limit`) a contact can move from the surface point nearest `p_b`
    /// along unit `dir` (B) and stay at least `margin` inside the smooth part of the surface
    /// it starts on: all the way, the surface within `margin` of the contact turns by less
    /// than 45° from the normal at the contact (a box's face up to `margin` from its edges, a
    /// cylinder's side up to `margin` from its rims; a sphere, or a cylinder's side around it,
    /// is never cut short). Steps of 0.5 mm.
    pub(crate) fn face_extent(
        &self,
        p_b: &Vector,
        dir: &Vector,
        limit: Real,
        margin: Real,
    ) -> Real {
        const STEP: Real = 5e-4;
        let cos_45 = std::f64::consts::FRAC_1_SQRT_2;
        let inside = |q: &Vector| -> bool {
            let ClosestPoint {
                point, normal: n, ..
            } = self.closest(q);
            let t1 = perpendicular(&Vector::x(), &n, &Vector::y());
            let t2 = n.cross(&t1);
            [t1, -t1, t2, -t2]
                .iter()
                .all(|t| self.closest(&(point + t * margin)).normal.dot(&n) >= cos_45)
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

    /// Two antipodal contact points through the centre of mass for a pinch along `axis` (from
    /// the thumb's side to the other): the axis is made horizontal (the contacts at the height
    /// of the centre of mass, so gravity makes no moment about the line between them) and,
    /// where the surface normal there is close to it, aligned with that normal (a box's face,
    /// a cylinder's side), so the normals are opposite and on the line. Returns (thumb point,
    /// other point, axis).
    pub(crate) fn antipodal_pair(&self, axis: &Vector) -> (Vector, Vector, Vector) {
        let horizontal = Vector::new(axis.x, axis.y, 0.0);
        let mut a = if horizontal.norm() > 0.3 {
            horizontal.normalize()
        } else {
            *axis
        };
        let (_, n) = self.surface_along(&a);
        if n.dot(&a) > 0.7 && (n.z.abs() < 1e-9 || horizontal.norm() <= 0.3) {
            a = n;
        }
        let (p_o, _) = self.surface_along(&a);
        let (p_t, _) = self.surface_along(&-a);
        (p_t, p_o, a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pinch_of_a_sphere_is_antipodal_through_its_centre_at_its_height() {
        let shape = Shape::Sphere { radius: 0.04 };
        // The recording's axis dips 6° and is off the x axis.
        let axis = Vector::new(1.0, 0.2, -0.1).normalize();
        let (t, o, a) = shape.antipodal_pair(&axis);
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
        let (t, o, a) = shape.antipodal_pair(&axis);
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
        let y = shape.face_extent(&centre, &Vector::y(), 0.05, 0.01);
        assert!((y - 0.015).abs() <= 5e-4, "{y}");
        let down = shape.face_extent(&centre, &-Vector::z(), 0.05, 0.01);
        assert!((down - 0.04).abs() <= 5e-4, "{down}");
        // Diagonally, the nearer edge counts.
        let d = Vector::new(0.0, 1.0, 1.0).normalize();
        let diag = shape.face_extent(&centre, &d, 0.05, 0.01);
        assert!((diag * d.y - 0.015).abs() <= 5e-4, "{diag}");
        // A sphere curves but has no edge: the limit.
        let sphere = Shape::Sphere { radius: 0.04 };
        let s = sphere.face_extent(&Vector::new(0.04, 0.0, 0.0), &Vector::y(), 0.032, 0.012);
        assert_eq!(s, 0.032);
    }
}
