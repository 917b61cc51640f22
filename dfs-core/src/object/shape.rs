//! Object shapes: their kinds and names, sizes and validation, mass properties, the nearest
//! surface point of a point, and how deep a shape rests below its centre.

use crate::error::{DfsError, Result};
use crate::math::{Mat3, Real, Rotation, Vector};
use crate::names::Named;
use serde::{Deserialize, Serialize};

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

/// The point of a shape's surface nearest a query point, as [`Shape::closest`] finds it; all
/// in the object frame B (origin at the shape's centre, axes the shape's), lengths in m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosestPoint {
    /// Signed distance (m) from the query point to the surface: positive outside the shape,
    /// negative inside, zero on the surface. Outside it is the Euclidean distance to
    /// [`point`](Self::point); inside it is minus the distance to the nearest face (box),
    /// the curved side or a cap (cylinder), or the surface (sphere).
    pub distance: Real,
    /// The nearest surface point, in B (m).
    pub point: Vector,
    /// Outward unit normal at [`point`](Self::point), in B. Where the nearest point is on an
    /// edge or corner of a box, or on a cylinder's rim, it points from
    /// [`point`](Self::point) towards the query point; for a query at a sphere's centre it
    /// is B's +z (and the point the top of the sphere), and for one on a cylinder's axis B's
    /// +x stands in for the radial direction.
    pub normal: Vector,
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

    /// The surface point nearest `p_b` (a point in B, m): the signed distance to it (negative
    /// inside), the point and the outward unit normal there ([`ClosestPoint`]).
    pub fn closest(&self, p_b: &Vector) -> ClosestPoint {
        match *self {
            Shape::Sphere { radius } => {
                let n = p_b.norm();
                let dir = if n > 1e-12 {
                    p_b * (1.0 / n)
                } else {
                    Vector::z()
                };
                ClosestPoint {
                    distance: n - radius,
                    point: dir * radius,
                    normal: dir,
                }
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

/// [`Shape::closest`] for a box of half extents `h`.
fn closest_on_box(p: &Vector, h: &Vector) -> ClosestPoint {
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
        ClosestPoint {
            distance: dist,
            point: c,
            normal: d / dist,
        }
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
        ClosestPoint {
            distance: q[axis],
            point: c,
            normal: n,
        }
    }
}

/// [`Shape::closest`] for a cylinder of radius `r` and half height `hh` along B's z.
fn closest_on_cylinder(p: &Vector, r: Real, hh: Real) -> ClosestPoint {
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
        ClosestPoint {
            distance: dist,
            point: c,
            normal: d / dist,
        }
    } else if dr > dz {
        // Closest to the curved side.
        let c = radial * r + Vector::new(0.0, 0.0, p.z.clamp(-hh, hh));
        ClosestPoint {
            distance: dr,
            point: c,
            normal: radial,
        }
    } else {
        // Closest to a cap.
        let c = Vector::new(p.x, p.y, sz * hh)
            - if rho > r {
                radial * (rho - r)
            } else {
                Vector::zeros()
            };
        ClosestPoint {
            distance: dz,
            point: c,
            normal: Vector::new(0.0, 0.0, sz),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One shape of each kind.
    fn shapes() -> [Shape; 3] {
        [
            Shape::Sphere { radius: 0.1 },
            Shape::Box {
                half_extents: [0.05, 0.03, 0.08],
            },
            Shape::Cylinder {
                radius: 0.04,
                half_height: 0.1,
            },
        ]
    }

    #[test]
    fn closest_points_lie_on_the_surface_for_every_shape() {
        let pts = [
            Vector::new(0.2, 0.01, -0.03),
            Vector::new(0.0, 0.0, 0.3),
            Vector::new(0.01, 0.005, 0.002),
            Vector::new(-0.1, 0.1, 0.2),
        ];
        for s in shapes() {
            for p in pts {
                let ClosestPoint {
                    distance: d,
                    point: c,
                    normal: n,
                } = s.closest(&p);
                let d_c = s.closest(&c).distance;
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
        for s in shapes() {
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
}
