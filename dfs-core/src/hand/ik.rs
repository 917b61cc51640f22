//! Fingertip inverse kinematics: find joint angles that put chosen fingertip centres at
//! world targets, for retargeting skills onto hands and for the simulated operator.
//!
//! Levenberg-Marquardt (adaptively damped least squares) on the stacked linear fingertip
//! Jacobians, projected onto the joint limits every iteration and warm-started from the
//! previous solution. Each iteration solves `(JᵀJ + λ² I) Δθ = Jᵀ e` on the top-left block of
//! a fixed-capacity [`DofMatrix`] (frozen DOFs and DOFs held at a limit padded with the
//! identity) by Cholesky ([`solve_dof_spd`]): no heap allocation, and finite for a stretched
//! (singular) finger since λ > 0.

use super::{solve_dof_spd, DofMatrix, DofVector, HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Vector};

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
        let step = damped_step(hand, kin, &q, targets, params, lambda);
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

/// The normal equations of the stacked linear tip Jacobians over the first `n` DOFs: `JᵀJ`
/// and `Jᵀ e`.
fn normal_equations(
    kin: &Kinematics,
    targets: &[(usize, Point)],
    n: usize,
) -> (DofMatrix, DofVector) {
    let mut a = DofMatrix::zeros();
    let mut g = DofVector::zeros();
    for (k, target) in targets {
        let jac = &kin.tip_jacobians[*k];
        let e: Vector = target - kin.tip_centres[*k];
        for i in 0..n {
            let ji = jac.fixed_view::<3, 1>(0, i);
            g[i] += ji.dot(&e);
            for j in i..n {
                a[(i, j)] += ji.dot(&jac.fixed_view::<3, 1>(0, j));
            }
        }
    }
    for i in 0..n {
        for j in 0..i {
            a[(i, j)] = a[(j, i)];
        }
    }
    (a, g)
}

/// One damped least-squares step Δθ = (JᵀJ + λ² I)⁻¹ Jᵀ e over the free DOFs (not frozen,
/// not at a limit the step would push through), each entry limited to `max_step`; zero where
/// the solve fails.
fn damped_step(
    hand: &HandModel,
    kin: &Kinematics,
    q: &DofVector,
    targets: &[(usize, Point)],
    params: &IkParams,
    lambda: f64,
) -> DofVector {
    let n = hand.dof().min(MAX_DOF);
    let (a, g) = normal_equations(kin, targets, n);
    let mut blocked: [bool; MAX_DOF] = core::array::from_fn(|i| i >= n || params.frozen[i]);
    let mut step = DofVector::zeros();
    // Active set: a DOF resting on a limit that the step pushes through is held, and the step
    // recomputed for the others (at most once per DOF).
    for _ in 0..=n {
        step = solve_free(&a, &g, &blocked, lambda, n);
        let mut changed = false;
        for i in 0..n {
            let at_lower = q[i] <= hand.dof_lower[i] && step[i] < 0.0;
            let at_upper = q[i] >= hand.dof_upper[i] && step[i] > 0.0;
            if !blocked[i] && (at_lower || at_upper) {
                blocked[i] = true;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let largest = step.amax();
    if largest > params.max_step {
        step *= params.max_step / largest;
    }
    step
}

/// Solves `(A + λ² I) x = g` over the unblocked DOFs among the first `n` (blocked ones padded
/// with the identity and held at zero) by Cholesky; zero when that fails.
fn solve_free(
    a: &DofMatrix,
    g: &DofVector,
    blocked: &[bool; MAX_DOF],
    lambda: f64,
    n: usize,
) -> DofVector {
    let mut a = *a;
    let mut g = *g;
    for (i, &held) in blocked.iter().enumerate().take(n) {
        if held {
            a.row_mut(i).fill(0.0);
            a.column_mut(i).fill(0.0);
            a[(i, i)] = 1.0;
            g[i] = 0.0;
        } else {
            a[(i, i)] += lambda * lambda;
        }
    }
    solve_dof_spd(&a, &g, n).unwrap_or_else(DofVector::zeros)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hand::model::tests::{angles_from_unit, test_hand};

    /// Deterministic uniform samples in [0, 1) (xorshift), so the test cases are reproducible.
    struct Samples(u64);

    impl Samples {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }

        fn vec(&mut self, n: usize) -> Vec<f64> {
            (0..n).map(|_| self.next()).collect()
        }
    }

    fn base() -> Isometry {
        Isometry::new(Vector::new(0.2, 0.1, 0.9), Vector::new(0.1, -0.4, 0.2))
    }

    fn tip_targets(hand: &HandModel, q: &[f64]) -> Vec<(usize, Point)> {
        let mut kin = Kinematics::default();
        hand.forward_kinematics(&base(), q, &mut kin);
        (0..hand.fingertips.len())
            .map(|k| (k, kin.tip_centres[k]))
            .collect()
    }

    fn within_limits(hand: &HandModel, q: &[f64]) -> bool {
        q.iter()
            .enumerate()
            .all(|(i, &x)| x.is_finite() && x >= hand.dof_lower[i] && x <= hand.dof_upper[i])
    }

    fn precise() -> IkParams {
        IkParams {
            tolerance: 1e-7,
            max_iterations: 200,
            ..IkParams::default()
        }
    }

    fn check_recovery(hand: &HandModel, samples: &mut Samples, spread: f64) {
        let q_true = angles_from_unit(hand, &samples.vec(hand.dof()));
        let targets = tip_targets(hand, &q_true);
        let mut q0: Vec<f64> = q_true
            .iter()
            .map(|x| x + spread * (2.0 * samples.next() - 1.0))
            .collect();
        hand.clamp_to_limits(&mut q0);
        let mut kin = Kinematics::default();
        let mut q = vec![0.0; hand.dof()];
        let result = solve_tips(hand, &base(), &targets, &q0, &precise(), &mut kin, &mut q);
        assert!(
            result.converged && result.max_error < 1e-6,
            "{result:?} from {q0:?} to {q_true:?}"
        );
        assert!(within_limits(hand, &q));
        // kin holds the kinematics of the returned angles.
        for (k, target) in &targets {
            assert!((kin.tip_centres[*k] - target).norm() < 1e-6);
        }
    }

    #[test]
    fn targets_from_reachable_angles_are_recovered_from_a_warm_start() {
        let mut samples = Samples(0x9e37_79b9_7f4a_7c15);
        let glove = HandModel::glove10();
        let hand = test_hand();
        for _ in 0..50 {
            check_recovery(&glove, &mut samples, 0.3);
            check_recovery(&hand, &mut samples, 0.3);
        }
    }

    /// Solves for one glove fingertip with the wrist frozen from `q0`; whether it converged
    /// to within 1e-6 m with the wrist untouched.
    fn single_finger_recovered(
        glove: &HandModel,
        samples: &mut Samples,
        tip: usize,
        q0: &[f64; 10],
    ) -> bool {
        let params = IkParams {
            tolerance: 1e-7,
            ..IkParams::default()
        }
        .with_frozen(0..3);
        let mut q_true = angles_from_unit(glove, &samples.vec(10));
        q_true[..3].copy_from_slice(&q0[..3]);
        let targets = [tip_targets(glove, &q_true)[tip]];
        let mut kin = Kinematics::default();
        let mut q = [0.0; 10];
        let result = solve_tips(glove, &base(), &targets, q0, &params, &mut kin, &mut q);
        assert_eq!(q[..3], q0[..3]);
        result.converged && result.max_error < 1e-6
    }

    #[test]
    fn single_finger_targets_are_recovered_from_a_relaxed_hand_with_the_wrist_frozen() {
        let glove = HandModel::glove10();
        let mut samples = Samples(42);
        let mut relaxed = [0.4; 10];
        relaxed[..3].fill(0.0);
        for tip in (0..5).cycle().take(100) {
            assert!(
                single_finger_recovered(&glove, &mut samples, tip, &relaxed),
                "tip {tip}"
            );
        }
    }

    #[test]
    fn a_cold_start_from_the_stretched_singular_hand_still_recovers_most_targets() {
        let glove = HandModel::glove10();
        let mut samples = Samples(7);
        let recovered = (0..5)
            .cycle()
            .take(100)
            .filter(|&tip| single_finger_recovered(&glove, &mut samples, tip, &[0.0; 10]))
            .count();
        // The pincer thumb rests 30° below the palm and starts at a joint limit from the
        // stretched pose: a few more cold starts end in a local minimum there than for the
        // fingers.
        assert!(recovered >= 90, "{recovered} of 100");
    }

    #[test]
    fn the_thumb_can_pinch_against_the_index_finger() {
        let glove = HandModel::glove10();
        // An opposed thumb, and the index tip sphere touching it from the dorsal side, in the
        // index finger's plane of motion (y = 0.026 m).
        let mut q_thumb = [0.0; 10];
        q_thumb[6] = 0.0;
        q_thumb[7] = 0.3;
        let contact = glove.fingertips[0].radius + glove.fingertips[1].radius;
        let mut kin = Kinematics::default();
        glove.forward_kinematics(&Isometry::identity(), &q_thumb, &mut kin);
        let thumb = kin.tip_centres[0];
        let dy = 0.026 - thumb.y;
        assert!(dy.abs() < contact, "the thumb passes the index plane");
        let index = thumb + Vector::new(0.0, dy, (contact * contact - dy * dy).sqrt());
        let targets = [(0, thumb), (1, index)];
        let params = IkParams::default().with_frozen(0..3);
        let mut q = [0.0; 10];
        let mut q0 = [0.3; 10];
        q0[..3].fill(0.0);
        let result = solve_tips(
            &glove,
            &Isometry::identity(),
            &targets,
            &q0,
            &params,
            &mut kin,
            &mut q,
        );
        assert!(result.converged, "{result:?} {q:?}");
        assert!(((kin.tip_centres[0] - kin.tip_centres[1]).norm() - contact).abs() < 1e-4);
    }

    #[test]
    fn unreachable_targets_fail_with_finite_angles_inside_the_limits() {
        let glove = HandModel::glove10();
        let mut kin = Kinematics::default();
        let mut q = [0.0; 10];
        // Far beyond the stretched index finger: the finger is singular at the solution.
        let targets = [
            (1, Point::new(0.5, 0.026, 0.0)),
            (2, Point::new(-0.3, 0.0, 0.2)),
        ];
        for q0 in [[0.0; 10], [0.3; 10]] {
            let result = solve_tips(
                &glove,
                &Isometry::identity(),
                &targets,
                &q0,
                &IkParams::default(),
                &mut kin,
                &mut q,
            );
            assert!(!result.converged && result.max_error.is_finite() && result.max_error > 0.1);
            assert!(within_limits(&glove, &q), "{q:?}");
            assert!(kin
                .tip_centres
                .iter()
                .all(|p| p.coords.iter().all(|c| c.is_finite())));
        }
    }

    #[test]
    fn invalid_requests_report_an_infinite_error_without_panicking() {
        let glove = HandModel::glove10();
        let mut kin = Kinematics::default();
        let mut q = [0.0; 10];
        let params = IkParams::default();
        let bad_tip = [(7, Point::origin())];
        let nan_target = [(0, Point::new(f64::NAN, 0.0, 0.0))];
        let id = Isometry::identity();
        for targets in [&bad_tip[..], &nan_target[..]] {
            let result = solve_tips(
                &glove,
                &id,
                targets,
                &[f64::NAN; 10],
                &params,
                &mut kin,
                &mut q,
            );
            assert!(!result.converged && result.max_error == f64::INFINITY);
            assert!(within_limits(&glove, &q));
        }
        let mut short = [0.0; 4];
        let result = solve_tips(
            &glove,
            &id,
            &[(0, Point::origin())],
            &[0.0; 10],
            &params,
            &mut kin,
            &mut short,
        );
        assert!(!result.converged);
    }

    #[test]
    fn already_reached_targets_take_no_iterations() {
        let glove = HandModel::glove10();
        let q0 = angles_from_unit(&glove, &[0.5; 10]);
        let targets = tip_targets(&glove, &q0);
        let mut kin = Kinematics::default();
        let mut q = [0.0; 10];
        let result = solve_tips(
            &glove,
            &base(),
            &targets,
            &q0,
            &IkParams::default(),
            &mut kin,
            &mut q,
        );
        assert_eq!((result.converged, result.iterations), (true, 0));
        assert_eq!(q[..], q0[..]);
    }
}
