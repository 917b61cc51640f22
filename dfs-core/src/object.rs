//! Objects: shapes with mass properties, their state, and the Newton-Euler step (eq. 24-26).
//!
//! Formulation (NOTES.md, "eq. 25-26 mix frames"): the object frame B sits at the centre of
//! mass; position and linear velocity are in the world frame, angular velocity in B. Wrenches
//! on the object are given in B at its origin, as the paper does. Newton-Euler:
//! `m v̇ = R f_B + m g`, `H ω̇ = m_B − ω × Hω`; orientation is integrated as a unit quaternion.

use crate::error::{DfsError, Result};
use crate::math::{force_of, moment_of, wrench, Isometry, Mat3, Real, Rotation, Vector, Wrench};
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

    /// Where the shape rests on a horizontal table, for its orientation `rotation`: the centre
    /// of its lowest point, edge or face relative to the shape's centre (world frame, m), and
    /// whether that support is a face (or, for a sphere or a cylinder on its side, a point or
    /// line straight below the centre), on which the shape stands still. On an edge or a corner
    /// it tips over: the table's force at the support makes a moment about the centre. Heights
    /// within 0.5 mm count as level.
    pub fn table_support(&self, rotation: &Rotation) -> (Vector, bool) {
        const LEVEL: Real = 5e-4;
        let r = rotation.to_rotation_matrix();
        let m = r.matrix();
        match *self {
            Shape::Sphere { radius } => (Vector::new(0.0, 0.0, -radius), true),
            Shape::Box { half_extents } => {
                let mut s_b = Vector::zeros();
                let mut level = 0;
                for i in 0..3 {
                    let up = m[(2, i)];
                    if 2.0 * half_extents[i] * up.abs() < LEVEL {
                        level += 1;
                    } else {
                        s_b[i] = -up.signum() * half_extents[i];
                    }
                }
                (r * s_b, level >= 2)
            }
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let up = Vector::new(m[(2, 0)], m[(2, 1)], m[(2, 2)]);
                let radial = Vector::new(up.x, up.y, 0.0);
                let radial_norm = radial.norm();
                let standing = 2.0 * radius * radial_norm < LEVEL;
                let lying = 2.0 * half_height * up.z.abs() < LEVEL;
                let mut s_b = Vector::zeros();
                if !lying {
                    s_b.z = -up.z.signum() * half_height;
                }
                if !standing {
                    s_b -= radial * (radius / radial_norm);
                }
                (r * s_b, standing || lying)
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

    #[test]
    fn a_box_stands_on_a_face_and_tips_from_an_edge() {
        let b = Shape::Box {
            half_extents: [0.025, 0.025, 0.04],
        };
        let (s, stands) = b.table_support(&Rotation::identity());
        assert!(stands);
        assert!((s - Vector::new(0.0, 0.0, -0.04)).norm() < 1e-12);
        // Tilted 0.2 rad about x: it rests on an edge off to the side of its centre.
        let (s, stands) = b.table_support(&Rotation::from_euler_angles(0.2, 0.0, 0.0));
        assert!(!stands);
        assert!(s.y.abs() > 0.01, "the edge is beside the centre: {s:?}");
        assert!((s.z + b.support_depth(&Rotation::from_euler_angles(0.2, 0.0, 0.0))).abs() < 1e-12);
        let sphere = Shape::Sphere { radius: 0.04 };
        assert!(
            sphere
                .table_support(&Rotation::from_euler_angles(0.3, 0.2, 0.1))
                .1
        );
        let cyl = Shape::Cylinder {
            radius: 0.03,
            half_height: 0.06,
        };
        assert!(cyl.table_support(&Rotation::identity()).1, "standing");
        let on_side = Rotation::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0);
        assert!(cyl.table_support(&on_side).1, "lying on its side");
        let tilted = Rotation::from_euler_angles(0.3, 0.0, 0.0);
        let (s, stands) = cyl.table_support(&tilted);
        assert!(!stands, "on its rim");
        assert!((s.z + cyl.support_depth(&tilted)).abs() < 1e-12);
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
