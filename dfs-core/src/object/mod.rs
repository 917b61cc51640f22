//! Objects: shapes with mass properties, their state, and the Newton-Euler step (eq. 24-26).
//!
//! Formulation (docs/physics.md, "eq. 25-26 mix frames"): the object frame B sits at the centre of
//! mass; position and linear velocity are in the world frame, angular velocity in B. Wrenches
//! on the object are given in B at its origin, as the paper does. Newton-Euler:
//! `m v̇ = R f_B + m g`, `H ω̇ = m_B − ω × Hω`; orientation is integrated as a unit quaternion.
//!
//! This file holds the rigid object, its state and the Newton-Euler step; the shapes are in
//! `shape.rs`, the points a shape may touch a table at in `table_points.rs`, the overlap test
//! of two shapes in `overlap.rs` and the surface points the replay planner uses in
//! `surface.rs`.

use crate::error::{DfsError, Result};
use crate::math::{force_of, moment_of, wrench, Isometry, Mat3, Real, Rotation, Vector, Wrench};

mod overlap;
mod shape;
mod surface;
mod table_points;

pub use overlap::{shapes_overlap, OVERLAP_TOLERANCE};
pub use shape::{ClosestPoint, Shape, ShapeKind};
pub use table_points::{TablePoint, CYLINDER_RIM_POINTS, MAX_TABLE_POINTS, RIM_LOWEST_POINT_TILT};

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
