//! Retargeting one step along the reference motion at a time: fingertip inverse kinematics
//! and the force distribution there.

use super::forces::load_at;
use super::Plan;
use crate::contact::{ContactFrame, Intensity};
use crate::grasp::optimise::{ForceSolver, OptimiseParams, TorqueLimits};
use crate::hand::ik::{solve_tips, IkParams};
use crate::hand::{Kinematics, MAX_DOF};
use crate::math::{Point, Real, Vector};
use crate::replay::{ReplayParams, SkillSpec};

/// One retargeting step along the reference motion: fingertip inverse kinematics for the
/// hand's base at the reference pose (warm-started from the previous step's angles) and the
/// force distribution for the load there with cones and torque limits (one solver set up for
/// the plan's contacts, fed the new load each step). Allocation-free after [`new`](Self::new)
/// apart from the solver's own work.
#[derive(Debug)]
pub struct RetargetStep<'a> {
    plan: &'a Plan,
    skill: &'a SkillSpec,
    kin: Kinematics,
    solver: Option<ForceSolver>,
    targets_b: Vec<(usize, Point)>,
    targets: Vec<(usize, Point)>,
    forces: Vec<Intensity>,
    /// The joint angles of the last step.
    pub q: [Real; MAX_DOF],
}

impl<'a> RetargetStep<'a> {
    /// Starts at the plan's grasp angles.
    pub fn new(plan: &'a Plan, skill: &'a SkillSpec, params: &ReplayParams) -> Self {
        let targets_b = plan
            .contacts
            .iter()
            .enumerate()
            .filter(|(k, _)| plan.active[*k])
            .map(|(k, c)| {
                let r = plan.hand.fingertips[k].radius;
                (k, Point::from(c.p_b - c.normal_b() * r))
            })
            .collect::<Vec<_>>();
        let contacts: Vec<ContactFrame> =
            targets_b.iter().map(|&(k, _)| plan.contacts[k]).collect();
        let limits = TorqueLimits {
            map: plan.torque_map.clone(),
            limits: plan.hand.torque_limit.clone(),
        };
        let opt = OptimiseParams {
            margin: params.friction_margin,
            min_normal: params.min_normal,
        };
        let solver = ForceSolver::new(
            &contacts,
            skill.contact_model,
            &skill.friction,
            &opt,
            Some(&limits),
        )
        .ok();
        RetargetStep {
            plan,
            skill,
            kin: Kinematics::default(),
            solver,
            targets: targets_b.clone(),
            forces: vec![Intensity::zeros(); targets_b.len()],
            targets_b,
            q: plan.q_grasp,
        }
    }

    /// Retargets the reference at `t` (s since the replay's start): returns the IK error (m)
    /// and the intensities of the grasp's contacts (the fingertips in [`Plan::active`], in
    /// order; `None` when the cones and torques cannot carry the load there).
    pub fn step(&mut self, t: Real) -> (Real, Option<&[Intensity]>) {
        let obj = self.skill.reference(t);
        let base = obj * self.plan.base_in_b0;
        for (dst, src) in self.targets.iter_mut().zip(&self.targets_b) {
            *dst = (src.0, obj * src.1);
        }
        let n = self.plan.hand.dof();
        let ik = IkParams {
            max_iterations: 20,
            tolerance: 1e-4,
            ..IkParams::default()
        };
        let q0 = self.q;
        let r = solve_tips(
            &self.plan.hand,
            &base,
            &self.targets,
            &q0[..n],
            &ik,
            &mut self.kin,
            &mut self.q[..n],
        );
        let g = Vector::new(0.0, 0.0, -crate::math::STANDARD_GRAVITY);
        let load = load_at(self.skill, t, &g);
        let solved = self
            .solver
            .as_mut()
            .is_some_and(|s| s.solve_into(&load, &mut self.forces).is_ok());
        (r.max_error, solved.then_some(&self.forces[..]))
    }
}
