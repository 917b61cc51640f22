//! The points of a shape that may touch a table below it, for the table's contact solver:
//! which they are in an orientation, their ids from one orientation to the next, and
//! whether the shape can roll on them.

use super::Shape;
use crate::math::{Real, Rotation, Vector};

impl Shape {
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
}
