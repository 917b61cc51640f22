//! The forces of a plan: the load the hand carries along the reference motion, how a finger
//! realises a contact force through its joint torques, and the force schedule with the exact
//! friction cones and the hand's torque limits.

use super::Plan;
use crate::contact::{ContactFrame, Intensity};
use crate::error::Result;
use crate::grasp::optimise::{ForceSolver, InfeasibleKind, OptimiseParams, TorqueLimits};
use crate::hand::{HandModel, Kinematics, MAX_TIPS};
use crate::math::{Real, Vector, Wrench};
use crate::replay::{FailureReason, ReplayParams, SkillSpec};
use crate::stop::Stop;
use nalgebra::{DMatrix, Matrix3};

/// The wrench (in B) the hand must apply at `t` for the reference motion: `m (a − g)`, with
/// `a` from central differences of the reference over ±25 ms. Moments are not planned.
pub(crate) fn load_at(skill: &SkillSpec, t: Real, gravity: &Vector) -> Wrench {
    let h = 0.025;
    let p = |t: Real| skill.reference(t).translation.vector;
    let a = (p(t + h) - p(t) * 2.0 + p(t - h)) / (h * h);
    let r = skill.reference(t).rotation;
    let f = r.inverse() * ((a - gravity) * skill.mass);
    Wrench::new(f.x, f.y, f.z, 0.0, 0.0, 0.0)
}

/// How a finger that cannot push in every direction realises a contact force: the force `a`
/// to command through its joint torques (`τ = Jᵀ a`) for the contact force `f`, as a matrix
/// `A` with `a = A f`, or `None` when the finger's linear Jacobian spans all three directions
/// (then `a = f`).
///
/// In the DFS the fingertip force is `(Jᵀ)⁺ τ`, in the range of the finger's Jacobian; what
/// is outside it (a finger with one actuated DOF pushes only along its motion) must come from
/// the contact's stick friction, which is tangential. So `a` is in that range and has the
/// planned normal component `nᵀ a = nᵀ f` (along the normal nothing else pushes: the normal
/// forces balance as planned), with its tangential part as close to the planned one as the
/// range allows; the rest of the planned tangential force is the stick friction's. `normal` is
/// the contact's unit normal, `j` the tip's Jacobian, `dofs` its finger's DOFs.
pub(crate) fn actuation_map(
    j: &crate::hand::TipJacobian,
    dofs: &[usize],
    normal: &Vector,
) -> Option<Matrix3<Real>> {
    let col = |d: usize| Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
    let scale = dofs.iter().map(|&d| col(d).norm()).fold(0.0, Real::max);
    let mut basis = [Vector::zeros(); 3];
    let mut nb = 0;
    for &d in dofs {
        let mut c = col(d);
        for b in &basis[..nb] {
            c -= b * b.dot(&c);
        }
        if nb < 3 && c.norm() > 1e-6 * scale && scale > 0.0 {
            basis[nb] = c.normalize();
            nb += 1;
        }
    }
    if nb == 3 {
        return None;
    }
    let p: Matrix3<Real> = basis[..nb].iter().map(|b| b * b.transpose()).sum();
    let pn = p * normal;
    // A finger that can hardly push along the normal is refused by the planner; the floor only
    // keeps this finite.
    let k = pn.norm_squared().max(1.0 / 16.0);
    Some(p + pn * (normal.transpose() * (Matrix3::identity() - p)) / k)
}

/// The map from the active fingertips' intensities to joint torques at the grasp (rows DOFs,
/// 4 columns per active tip, in the order of the fingertips): `kin` holds the hand at the
/// grasp with its tip Jacobians, `contacts` and `active` are per fingertip. B is the world at
/// the start (the start pose is not rotated).
pub(super) fn torque_map(
    hand: &HandModel,
    kin: &Kinematics,
    contacts: &[ContactFrame],
    active: &[bool],
) -> DMatrix<Real> {
    let n_hand = hand.dof();
    let n_active = active.iter().filter(|&&a| a).count();
    let mut torque_map = DMatrix::<Real>::zeros(n_hand, 4 * n_active);
    for (i, k) in (0..contacts.len()).filter(|&k| active[k]).enumerate() {
        let c = &contacts[k];
        let j = &kin.tip_jacobians[k];
        let r = c.rot_b;
        // The force commanded for each intensity (the finger's own share of it).
        let dofs = hand
            .finger_groups
            .iter()
            .find(|g| g.tips.contains(&k))
            .map_or(&[][..], |g| &g.dofs[..]);
        let a = actuation_map(j, dofs, &c.normal_b());
        for d in 0..n_hand {
            let lin = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
            let ang = Vector::new(j[(3, d)], j[(4, d)], j[(5, d)]);
            for comp in 0..3 {
                let axis = r.matrix().column(comp).into_owned();
                let commanded = a.map_or(axis, |a| a * axis);
                torque_map[(d, 4 * i + comp)] = lin.dot(&commanded);
            }
            torque_map[(d, 4 * i + 3)] = ang.dot(&c.normal_b());
        }
    }
    torque_map
}

/// Fills the force schedule, and the failure when the cones or the torques cannot carry it;
/// [`DfsError::Cancelled`] when `stop` is set (looked at every sample).
pub(super) fn plan_forces(
    plan: &mut Plan,
    skill: &SkillSpec,
    params: &ReplayParams,
    stop: &Stop,
) -> Result<()> {
    let tl = skill.timeline();
    let g = Vector::new(0.0, 0.0, -crate::math::STANDARD_GRAVITY);
    let opt = OptimiseParams {
        margin: params.friction_margin,
        min_normal: params.min_normal,
    };
    let limits = TorqueLimits {
        map: plan.torque_map.clone(),
        limits: plan.hand.torque_limit.clone(),
    };
    let tips: Vec<usize> = (0..plan.contacts.len())
        .filter(|&k| plan.active[k])
        .collect();
    let contacts: Vec<ContactFrame> = tips.iter().map(|&k| plan.contacts[k]).collect();
    // One solver each with and without the torque limits: the contacts stay, the load changes.
    let new_solver = |limits: Option<&TorqueLimits>| {
        ForceSolver::new(
            &contacts,
            skill.contact_model,
            &skill.friction,
            &opt,
            limits,
        )
    };
    let (mut cones_only, mut with_limits) = match (new_solver(None), new_solver(Some(&limits))) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e), _) | (_, Err(e)) => {
            plan.failure = Some((
                FailureReason::NoForceClosure,
                format!(
                    "the retargeted contacts cannot be planned for: {}",
                    e.reason
                ),
            ));
            return Ok(());
        }
    };
    let mut dist = vec![Intensity::zeros(); contacts.len()];
    // Static load first, without torque limits: can the contacts carry it at all?
    let static_load = load_at(skill, tl.grasp_start, &g);
    if let Err(e) = cones_only.solve_into(&static_load, &mut dist) {
        plan.fails_at_rest = true;
        let reason = match e.kind {
            InfeasibleKind::NoDistribution
            | InfeasibleKind::Solver
            | InfeasibleKind::InvalidInput => FailureReason::NoForceClosure,
        };
        plan.failure = Some((
            reason,
            format!(
                "the retargeted contacts cannot carry the object's weight inside their friction \
                 cones with a {:.0} % margin: {}",
                params.friction_margin * 100.0,
                e.reason
            ),
        ));
    }
    let mut t = tl.grasp_start;
    let step = params.force_sample_s.max(0.01);
    while t <= tl.release_start + 1e-9 {
        stop.check()?;
        let load = load_at(skill, t, &g);
        let solved = match with_limits.solve_into(&load, &mut dist) {
            Ok(_) => true,
            Err(e) => {
                plan.fails_at_rest |= t == tl.grasp_start;
                if plan.failure.is_none() {
                    plan.failure = Some((
                        FailureReason::TorqueLimit,
                        format!(
                            "carrying the load at t = {t:.2} s needs more joint torque than the \
                             hand's limits allow ({})",
                            e.reason
                        ),
                    ));
                }
                cones_only.solve_into(&load, &mut dist).is_ok()
            }
        };
        let mut row = [Intensity::zeros(); MAX_TIPS];
        if solved {
            for (&k, c) in tips.iter().zip(&dist) {
                row[k] = *c;
            }
        } else {
            // Nothing carries it: squeeze with the least normal force and let it slip.
            for &k in &tips {
                row[k][2] = params.min_normal;
            }
        }
        plan.force_times.push(t);
        plan.forces.push(row);
        t += step;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_finger_that_pushes_only_along_its_motion_is_commanded_the_planned_normal_force() {
        let mut j = crate::hand::TipJacobian::zeros();
        // One DOF moving the tip along c, 20° off the normal.
        let angle: Real = 20f64.to_radians();
        let normal = Vector::z();
        let c = Vector::new(angle.sin(), 0.0, angle.cos()) * 0.08;
        for r in 0..3 {
            j[(r, 2)] = c[r];
        }
        let f = Vector::new(0.3, -0.2, 2.0);
        let a = actuation_map(&j, &[2], &normal).unwrap() * f;
        // Along the finger's motion, with the planned normal component.
        assert!(a.cross(&c).norm() < 1e-12, "{a}");
        assert!((a.dot(&normal) - f.dot(&normal)).abs() < 1e-12);
        // Two DOFs: in their plane, same normal component, the tangential part nearest f's.
        j[(1, 3)] = 0.05;
        let a = actuation_map(&j, &[2, 3], &normal).unwrap() * f;
        assert!(a.dot(&c.cross(&Vector::y())).abs() < 1e-12, "{a}");
        assert!((a.dot(&normal) - f.dot(&normal)).abs() < 1e-12);
        assert!((a.y - f.y).abs() < 1e-12);
        // A finger that pushes in every direction is commanded the force itself.
        j[(0, 4)] = 0.07;
        assert!(actuation_map(&j, &[2, 3, 4], &normal).is_none());
    }
}
