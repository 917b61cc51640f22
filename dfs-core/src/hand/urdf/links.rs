//! A URDF's links: origins as isometries and each link's mass properties.

use super::tree::Tree;
use crate::error::{DfsError, Result};
use crate::hand::{Inertial, Link};
use crate::math::{Isometry, Mat3, Rotation, Vector};

/// An isometry from a URDF origin (xyz, fixed-axis roll-pitch-yaw).
pub(in crate::hand) fn pose(p: &urdf_rs::Pose) -> Isometry {
    let [x, y, z] = p.xyz.0;
    let [r, pi, ya] = p.rpy.0;
    Isometry::from_parts(
        Vector::new(x, y, z).into(),
        Rotation::from_euler_angles(r, pi, ya),
    )
}

/// The link's mass properties in the link frame; the field name of an error names the link.
fn inertial(link: &urdf_rs::Link) -> Result<Inertial> {
    let field = || format!("urdf link {:?} inertial", link.name);
    let m = link.inertial.mass.value;
    // A hand's link, not a building: the grasp file's object bound (10⁴ kg) is far above any.
    let max = crate::spec::MASS_RANGE.1;
    if !(m.is_finite() && (0.0..=max).contains(&m)) {
        return Err(DfsError::invalid(
            field(),
            format!("mass {m} kg must be finite, ≥ 0 and at most {max} kg"),
        ));
    }
    let i = &link.inertial.inertia;
    let local = Mat3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    if !local.iter().all(|v| v.is_finite()) {
        return Err(DfsError::invalid(field(), "inertia is not finite"));
    }
    let eig = local.symmetric_eigenvalues();
    let scale = eig.iter().fold(0.0_f64, |a, b| a.max(b.abs()));
    if eig.iter().any(|&e| e < -1e-9 * scale.max(1e-12)) {
        return Err(DfsError::invalid(
            field(),
            format!(
                "inertia is not positive semi-definite (eigenvalues {:.3e}, {:.3e}, {:.3e})",
                eig[0], eig[1], eig[2]
            ),
        ));
    }
    let origin = pose(&link.inertial.origin);
    let r = origin.rotation.to_rotation_matrix();
    Ok(Inertial {
        mass: m,
        com: origin.translation.vector,
        inertia: r.matrix() * local * r.matrix().transpose(),
    })
}

/// The links of the hand's subtree in its order, with their mass properties.
pub(super) fn hand_links(robot: &urdf_rs::Robot, tree: &Tree) -> Result<Vec<Link>> {
    let mut hand_links = Vec::with_capacity(tree.order_links.len());
    for &l in &tree.order_links {
        hand_links.push(Link {
            name: robot.links[l].name.clone(),
            inertial: inertial(&robot.links[l])?,
        });
    }
    Ok(hand_links)
}
