//! Fingertip inverse kinematics: find joint angles that put chosen fingertip centres at
//! world targets, for retargeting skills onto hands and for the simulated operator.
//!
//! Levenberg-Marquardt (adaptively damped least squares) on the stacked linear fingertip
//! Jacobians, projected onto the joint limits every iteration and warm-started from the
//! previous solution. Each iteration solves `(JᵀJ + λ² I) Δθ = Jᵀ e` on a fixed-capacity
//! [`DofMatrix`] (unused and frozen DOFs padded with the identity) by Cholesky: no heap
//! allocation, and finite for a stretched (singular) finger since λ > 0.

use super::{DofMatrix, HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Vector};
use nalgebra::SVector;

/// A DOF vector of fixed capacity.
type DofVector = SVector<f64, MAX_DOF>;

/// Parameters of [`solve_tips`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkParams {
    /// Most iterations (each one forward-kinematics evaluation); default 100.
    pub max_iterations: usize,
    /// Converged when every target tip is within this distance of its target (m); default
    /// 1e-5 m.
    pub tolerance: f64,
    /// Initial and smallest damping λ (m), > 0; λ² is added to the diagonal of JᵀJ. It grows
    /// ×4 after a step that does not reduce the error and shrinks ×½ after one that does.
    /// Default 1e-3 m.
    pub damping: f64,
    /// Largest change of any DOF in one iteration (rad or m); default 0.5.
    pub max_step: f64,
    /// DOFs held at their starting value (for example the wrist); default none.
    pub frozen: [bool; MAX_DOF],
}

impl Default for IkParams {
    fn default() -> Self {
        IkParams {
            max_iterations: 100,
            tolerance: 1e-5,
            damping: 1e-3,
            max_step: 0.5,
            frozen: [false; MAX_DOF],
        }
    }
}

impl IkParams {
    /// These parameters with the given DOFs frozen (indices ≥ [`MAX_DOF`] are ignored).
    pub fn with_frozen(mut self, dofs: impl IntoIterator<Item = usize>) -> Self {
        for d in dofs {
            if let Some(f) = self.frozen.get_mut(d) {
                *f = true;
            }
        }
        self
    }
}

/// Outcome of [`solve_tips`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkResult {
    /// Every target tip ended within the tolerance.
    pub converged: bool,
    /// Iterations used.
    pub iterations: usize,
    /// Largest distance of a target tip from its target at the returned angles (m); infinite
    /// when the request was invalid.
    pub max_error: f64,
}

/// Largest damping before giving up: the error no longer decreases in any direction.
const MAX_DAMPING: f64 = 1e3;

/// Moves the fingertips `targets` (tip index, world position of its sphere centre) toward their
/// targets with the hand's base at `base`, starting from `q0` (clamped into the limits; NaN
/// entries read as 0). Writes the best angles found (always finite and within the DOF limits)
/// to `q_out`, and leaves `kin` holding their forward kinematics. Allocation-free.
///
/// The model must be valid. An invalid request (a tip index out of range, more than
/// [`MAX_TIPS`] targets, a non-finite target, `q_out` shorter than the DOF count) returns
/// `converged: false` and an infinite error with `q_out` set to the clamped `q0`.
pub fn solve_tips(
    hand: &HandModel,
    base: &Isometry,
    targets: &[(usize, Point)],
    q0: &[f64],
    params: &IkParams,
    kin: &mut Kinematics,
    q_out: &mut [f64],
) -> IkResult {
    let n = hand.dof().min(MAX_DOF);
    let mut q = DofVector::zeros();
    for (i, x) in q.iter_mut().enumerate().take(n) {
        *x = q0.get(i).copied().unwrap_or(0.0);
    }
    hand.clamp_to_limits(q.as_mut_slice());
    let valid = q_out.len() >= n
        && targets.len() <= MAX_TIPS
        && targets
            .iter()
            .all(|(k, p)| *k < hand.fingertips.len() && p.coords.iter().all(|c| c.is_finite()));
    if !valid {
        let len = q_out.len().min(n);
        q_out[..len].copy_from_slice(&q.as_slice()[..len]);
        return IkResult {
            converged: false,
            iterations: 0,
            max_error: f64::INFINITY,
        };
    }
    let lambda_min = if params.damping > 0.0 {
        params.damping
    } else {
        1e-6
    };
    let mut lambda = lambda_min;
    hand.forward_kinematics(base, q.as_slice(), kin);
    let (mut cost, mut max_error) = errors(kin, targets);
    let mut iterations = 0;
    while max_error > params.tolerance && iterations < params.max_iterations && lambda < MAX_DAMPING
    {
        iterations += 1;
        hand.tip_jacobians(kin);
        let step = damped_step(hand, kin, targets, params, lambda);
        let mut trial = q + step;
        hand.clamp_to_limits(trial.as_mut_slice());
        hand.forward_kinematics(base, trial.as_slice(), kin);
        let (trial_cost, trial_max) = errors(kin, targets);
        if trial_cost < cost {
            (q, cost, max_error) = (trial, trial_cost, trial_max);
            lambda = (lambda * 0.5).max(lambda_min);
        } else {
            lambda *= 4.0;
            hand.forward_kinematics(base, q.as_slice(), kin);
        }
    }
    q_out[..n].copy_from_slice(&q.as_slice()[..n]);
    IkResult {
        converged: max_error <= params.tolerance,
        iterations,
        max_error,
    }
}

/// Sum of squared tip errors (m²) and the largest tip error (m) for the kinematics in `kin`.
fn errors(kin: &Kinematics, targets: &[(usize, Point)]) -> (f64, f64) {
    targets.iter().fold((0.0, 0.0), |(sum, max), (k, target)| {
        let e = (target - kin.tip_centres[*k]).norm();
        (sum + e * e, f64::max(max, e))
    })
}

/// One damped least-squares step Δθ = (JᵀJ + λ² I)⁻¹ Jᵀ e over the free DOFs, each entry
/// limited to `max_step`; zero where the solve fails.
fn damped_step(
    hand: &HandModel,
    kin: &Kinematics,
    targets: &[(usize, Point)],
    params: &IkParams,
    lambda: f64,
) -> DofVector {
    let n = hand.dof().min(MAX_DOF);
    let mut a = DofMatrix::zeros();
    let mut g = DofVector::zeros();
    for (k, target) in targets {
        let jv = kin.tip_jacobians[*k].fixed_rows::<3>(0);
        let e: Vector = target - kin.tip_centres[*k];
        a += jv.transpose() * jv;
        g += jv.transpose() * e;
    }
    for i in 0..MAX_DOF {
        let free = i < n && !params.frozen[i];
        if free {
            a[(i, i)] += lambda * lambda;
        } else {
            a.row_mut(i).fill(0.0);
            a.column_mut(i).fill(0.0);
            a[(i, i)] = 1.0;
            g[i] = 0.0;
        }
    }
    let Some(cholesky) = a.cholesky() else {
        return DofVector::zeros();
    };
    let mut step = cholesky.solve(&g);
    let largest = step.amax();
    if !largest.is_finite() {
        return DofVector::zeros();
    }
    if largest > params.max_step {
        step *= params.max_step / largest;
    }
    step
}
