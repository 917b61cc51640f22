//! Conversions between the recorded poses and vectors (Foxglove types) and the math types.

use dfs_core::math::{Isometry, Rotation, Vector};

use crate::foxglove::Pose;

/// A recorded pose as an isometry (a zero quaternion as the identity rotation).
pub(crate) fn iso(p: &Pose) -> Isometry {
    let q = nalgebra::Quaternion::new(
        p.orientation.w,
        p.orientation.x,
        p.orientation.y,
        p.orientation.z,
    );
    let r = if q.norm() > 1e-9 {
        Rotation::from_quaternion(q)
    } else {
        Rotation::identity()
    };
    Isometry::from_parts(
        Vector::new(p.position.x, p.position.y, p.position.z).into(),
        r,
    )
}

/// An isometry as a recorded pose (the inverse of [`iso`]).
pub(super) fn pose_of(i: &Isometry) -> Pose {
    let q = i.rotation.quaternion();
    Pose {
        position: crate::foxglove::Vector3::new(
            i.translation.vector.x,
            i.translation.vector.y,
            i.translation.vector.z,
        ),
        orientation: crate::foxglove::Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// A recorded vector as a math vector.
pub(super) fn v3(v: &crate::foxglove::Vector3) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

/// A vector as the array a skill's JSON holds.
pub(super) fn arr(v: &Vector) -> [f64; 3] {
    [v.x, v.y, v.z]
}
