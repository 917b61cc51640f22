//! Virtual coupling: driving the DFS from a glove that measures joint positions only.
//!
//! The DFS turns the operator's joint *torques* into fingertip forces (eq. 14). Most data
//! gloves measure angles only, and a force-feedback glove without torque sensors measures its
//! angles and renders a torque. Such a glove is tied to the simulated hand by a *virtual
//! coupling* (Colgate, Stanley & Brown 1995; the proxy or god-object of haptic rendering,
//! Zilles & Salisbury 1995): a spring-damper per DOF from the measured posture to the
//! simulated hand, whose posture and velocity are the DFS's finger dynamics
//! ([`TickOutput::motor_q`], [`TickOutput::motor_qd`]):
//!
//! ```text
//! τ_d = clamp( k_d (q_measured,d − q_motor,d) − c_d q̇_motor,d ,  ±τ_max,d )
//! ```
//!
//! Each tick the DFS is stepped with the glove sample `(q = q_motor, τ)`: the simulated hand
//! is where the DFS put it (its fingertips stop on the object's surface), and the coupling
//! pulls it towards the operator's measured posture. In free space the simulated hand follows
//! the measured one; on the object the operator's fingers close further than the simulated
//! ones can, and the squeeze is the spring's stretch `k_d (q_measured − q_motor)`. The glove
//! renders the coupling's reaction `−τ` to the operator: what the operator feels of the
//! object (in steady contact it equals the DFS's feedback torque `Σ Jᵀ f_fb`, the contact
//! force on the simulated finger). A force-feedback glove lets the operator squeeze with a
//! muscle torque τ_op against it, so its measured posture settles at
//! `q_motor + τ_op / k`: the coupling hands that same torque to the DFS.
//!
//! # Default gains ([`CouplingParams`], [`VirtualCoupling::for_hand`])
//!
//! - **Stiffness from the torque limits.** `k_d = τ_max,d / (f · range_d)` with `f =`
//!   [`CouplingParams::full_torque_fraction`] (0.1): the spring reaches the DOF's torque limit
//!   when the operator's joint is a tenth of its range past the simulated one, about 9° on a
//!   finger joint of 1.6 rad (4 mm on a 4 cm gripper jaw). A squeeze is then graded over a
//!   span a person controls easily (the angle sensors of data gloves resolve well under a
//!   degree), while in free space the simulated hand stays within a fraction of that of the
//!   operator's: the tracking lag is about `(b + c_d) / k_d`, 6-20 ms on glove10 (wrist
//!   included; a hand with heavy links on weak motors is slower: Barrett's spread joints,
//!   0.05 kg·m² on 1.5 N·m, follow within about 0.4 s). The
//!   simulated operator's own posture stiffness is built the same way, in proportion to each
//!   DOF's torque limit ([`crate::operator::OperatorParams::stiffness`]).
//! - **Damping from the inertia.** `c_d = 2 ζ √(k_d M_dd) − b` (at least 0), with `ζ =`
//!   [`CouplingParams::damping_ratio`] (1, critical: no overshoot into the object), `b` the
//!   DFS's own joint damping ([`DfsParams::joint_damping`], which damps the coupled DOF too)
//!   and `M_dd` the inertia of DOF `d` with the others held (as their own couplings hold
//!   them), from the hand's joint-space inertia M(θ) (links, mimic-coupled joints and
//!   armature) with every DOF mid-range.
//! - **Within the step's stability.** The coupling is computed from the previous tick's
//!   motor state, so it enters the DFS's implicit finger step (whose own damping `b` is
//!   implicit) as an explicit force. Per DOF that step is stable when `c dt ≤ m` and
//!   `k dt² < 2 (m + b dt)`; the gains keep `c_d dt ≤ m_d` and `k_d dt² ≤ ¼ (m_d + b dt)`, an
//!   eighth of the bound, with the least inertia the DOF can have, `m_d = 1 / (M⁻¹)_dd` (the
//!   others free), which leaves room for the inertia changing with the posture and for the
//!   DOFs' coupling through M. On glove10, Allegro, Barrett, Inspire and the gripper the
//!   torque-limit stiffness stays below the cap; only very light links would meet it.
//!
//! A glove that does measure torques can use a weak coupling the same way, beside its torques,
//! to keep the simulated hand's posture on the measured one (`services::session::import`
//! does, with full torque only at a whole range's error).
//!
//! Pure computation: [`VirtualCoupling::torques`] allocates nothing (fixed-capacity arrays).

use crate::dfs::{DfsParams, TickOutput};
use crate::error::{DfsError, Result};
use crate::hand::{DofMatrix, HandModel, Kinematics, MAX_DOF};
use crate::math::{Isometry, Real};

/// How [`VirtualCoupling::for_hand`] chooses the gains (see the module docs for why).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CouplingParams {
    /// The posture error, as a fraction of each DOF's range ([`HandModel::sweep_range`]), at
    /// which the spring reaches the DOF's torque limit: `k_d = τ_max,d / (f · range_d)`.
    /// Range (0, 10]. Default 0.1.
    pub full_torque_fraction: Real,
    /// Damping ratio of each coupled DOF, counting the DFS's joint damping (0 to 2).
    /// Default 1 (critical).
    pub damping_ratio: Real,
}

impl Default for CouplingParams {
    fn default() -> Self {
        CouplingParams {
            full_torque_fraction: 0.1,
            damping_ratio: 1.0,
        }
    }
}

/// A spring-damper per DOF from a measured posture to the simulated hand (see the module
/// docs). Fixed capacity: copying it or computing torques allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualCoupling {
    /// Per DOF (N·m/rad, or N/m for a prismatic DOF).
    stiffness: [Real; MAX_DOF],
    /// Per DOF (N·m·s/rad, or N·s/m).
    damping: [Real; MAX_DOF],
    /// Per DOF: the hand's torque limit (N·m or N), the clamp.
    torque_limit: [Real; MAX_DOF],
    dof: usize,
}

impl VirtualCoupling {
    /// The default coupling of `hand` (module docs): stiffness from the torque limits, damping
    /// from the inertia, both within the stability of the DFS step of `dfs` (its `dt` and
    /// `joint_damping`). Errors name a parameter out of range.
    pub fn for_hand(hand: &HandModel, params: &CouplingParams, dfs: &DfsParams) -> Result<Self> {
        let f = params.full_torque_fraction;
        if !(f.is_finite() && f > 0.0 && f <= 10.0) {
            return Err(DfsError::invalid(
                "coupling.full_torque_fraction",
                format!("must be in (0, 10], got {f}"),
            ));
        }
        let zeta = params.damping_ratio;
        if !(zeta.is_finite() && (0.0..=2.0).contains(&zeta)) {
            return Err(DfsError::invalid(
                "coupling.damping_ratio",
                format!("must be 0 to 2, got {zeta}"),
            ));
        }
        dfs.validate()?;
        let n = hand.dof();
        if n > MAX_DOF {
            return Err(DfsError::invalid(
                "hand",
                format!("{} DOFs, at most {MAX_DOF}", n),
            ));
        }
        let (free, held) = dof_inertias(hand);
        let (dt, b) = (dfs.dt, dfs.joint_damping);
        let mut c = VirtualCoupling {
            stiffness: [0.0; MAX_DOF],
            damping: [0.0; MAX_DOF],
            torque_limit: [0.0; MAX_DOF],
            dof: n,
        };
        for d in 0..n {
            let (lo, hi) = hand.sweep_range(d);
            let range = (hi - lo).max(1e-6);
            let m = free[d];
            let k = (hand.torque_limit[d] / (f * range)).min(0.25 * (m + b * dt) / (dt * dt));
            let damping = (2.0 * zeta * (k * held[d]).sqrt() - b).clamp(0.0, m / dt);
            c.stiffness[d] = k;
            c.damping[d] = damping;
            c.torque_limit[d] = hand.torque_limit[d];
        }
        c.check()?;
        Ok(c)
    }

    /// A coupling with the given gains per DOF of `hand` (each finite and ≥ 0; `stiffness` in
    /// N·m/rad, `damping` in N·m·s/rad, N/m and N·s/m for prismatic DOFs), clamped to the
    /// hand's torque limits. Stiff gains may make the DFS step unstable: see the module docs
    /// for the bounds [`for_hand`](Self::for_hand) keeps to.
    pub fn with_gains(hand: &HandModel, stiffness: &[Real], damping: &[Real]) -> Result<Self> {
        let n = hand.dof();
        for (what, v) in [("stiffness", stiffness), ("damping", damping)] {
            if v.len() != n || n > MAX_DOF {
                return Err(DfsError::WrongLength {
                    what: if what == "stiffness" {
                        "coupling stiffness"
                    } else {
                        "coupling damping"
                    },
                    got: v.len(),
                    expected: n,
                });
            }
        }
        let mut c = VirtualCoupling {
            stiffness: [0.0; MAX_DOF],
            damping: [0.0; MAX_DOF],
            torque_limit: [0.0; MAX_DOF],
            dof: n,
        };
        c.stiffness[..n].copy_from_slice(stiffness);
        c.damping[..n].copy_from_slice(damping);
        c.torque_limit[..n].copy_from_slice(&hand.torque_limit[..n]);
        c.check()?;
        Ok(c)
    }

    /// Every gain finite and ≥ 0, every limit finite and ≥ 0; the error names the DOF.
    fn check(&self) -> Result<()> {
        for d in 0..self.dof {
            for (what, v) in [
                ("coupling stiffness", self.stiffness[d]),
                ("coupling damping", self.damping[d]),
                ("torque limit", self.torque_limit[d]),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(DfsError::invalid(
                        format!("{what} of DOF {d}"),
                        format!("must be a finite number ≥ 0, got {v}"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Number of DOFs.
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// Stiffness per DOF (N·m/rad; N/m for a prismatic DOF).
    pub fn stiffness(&self) -> &[Real] {
        &self.stiffness[..self.dof]
    }

    /// Damping per DOF (N·m·s/rad; N·s/m for a prismatic DOF).
    pub fn damping(&self) -> &[Real] {
        &self.damping[..self.dof]
    }

    /// The operator torques `τ_d = clamp(k_d (q_measured,d − q_motor,d) − c_d q̇_motor,d,
    /// ±τ_max,d)` into `tau`. Every slice must have [`dof`](Self::dof) entries
    /// ([`DfsError::WrongLength`] otherwise, `tau` untouched). A non-finite input gives a
    /// non-finite torque, which the DFS refuses naming the DOF. Allocation-free.
    pub fn torques(
        &self,
        q_measured: &[Real],
        motor_q: &[Real],
        motor_qd: &[Real],
        tau: &mut [Real],
    ) -> Result<()> {
        let n = self.dof;
        for (what, len) in [
            ("measured joint angles", q_measured.len()),
            ("motor joint angles", motor_q.len()),
            ("motor joint velocities", motor_qd.len()),
            ("joint torques", tau.len()),
        ] {
            if len != n {
                return Err(DfsError::WrongLength {
                    what,
                    got: len,
                    expected: n,
                });
            }
        }
        for d in 0..n {
            let t =
                self.stiffness[d] * (q_measured[d] - motor_q[d]) - self.damping[d] * motor_qd[d];
            let lim = self.torque_limit[d];
            // max/min, not clamp: never panics, and a NaN stays NaN for the DFS to refuse.
            tau[d] = if t.is_nan() { t } else { t.max(-lim).min(lim) };
        }
        Ok(())
    }

    /// [`torques`](Self::torques) from the DFS's last tick (`out.motor_q`, `out.motor_qd`).
    pub fn torques_from(
        &self,
        q_measured: &[Real],
        out: &TickOutput,
        tau: &mut [Real],
    ) -> Result<()> {
        let n = self.dof;
        self.torques(q_measured, &out.motor_q[..n], &out.motor_qd[..n], tau)
    }
}

/// Per DOF (kg·m², or kg for a prismatic DOF), from M(θ) with every DOF mid-range
/// ([`HandModel::sweep_range`]) and the base at the origin: `1 / (M⁻¹)_dd`, the inertia the
/// DOF has with the others free (the least, for the stability bounds), and `M_dd`, the inertia
/// it has with the others held (as their own couplings hold them; for the damping). The first
/// falls back to the second if M does not factor.
fn dof_inertias(hand: &HandModel) -> ([Real; MAX_DOF], [Real; MAX_DOF]) {
    let n = hand.dof().min(MAX_DOF);
    let mut q = [0.0; MAX_DOF];
    for (d, v) in q.iter_mut().enumerate().take(n) {
        let (lo, hi) = hand.sweep_range(d);
        *v = 0.5 * (lo + hi);
    }
    let mut kin = Box::<Kinematics>::default();
    let mut m = Box::new(DofMatrix::zeros());
    hand.forward_kinematics(&Isometry::identity(), &q[..n], &mut kin);
    hand.mass_matrix(&mut kin, &mut m);
    let block = nalgebra::DMatrix::from_fn(n, n, |i, j| m[(i, j)]);
    let (mut free, mut held) = ([0.0; MAX_DOF], [0.0; MAX_DOF]);
    let inverse = block.clone().cholesky().map(|c| c.inverse());
    for d in 0..n {
        held[d] = block[(d, d)].max(0.0);
        free[d] = match &inverse {
            Some(inv) if inv[(d, d)] > 0.0 && inv[(d, d)].is_finite() => 1.0 / inv[(d, d)],
            _ => held[d],
        };
    }
    (free, held)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::{ContactModel, Friction};
    use crate::dfs::{Dfs, GloveSample};
    use crate::hand::builtin_hand;
    use crate::object::{ObjectState, RigidObject, Shape};

    fn hands() -> Vec<HandModel> {
        crate::hand::BUILTIN_HANDS
            .iter()
            .map(|h| builtin_hand(h).unwrap())
            .collect()
    }

    #[test]
    fn torques_are_a_spring_damper_clamped_to_the_torque_limits() {
        let hand = HandModel::glove10();
        let n = hand.dof();
        let k = vec![2.0; n];
        let c = vec![0.1; n];
        let coupling = VirtualCoupling::with_gains(&hand, &k, &c).unwrap();
        let q_meas = vec![0.3; n];
        let mut motor = vec![0.2; n];
        motor[0] = -10.0; // far off: clamped
        let qd = vec![0.5; n];
        let mut tau = vec![0.0; n];
        coupling.torques(&q_meas, &motor, &qd, &mut tau).unwrap();
        assert!((tau[1] - (2.0 * 0.1 - 0.1 * 0.5)).abs() < 1e-12, "{tau:?}");
        assert_eq!(tau[0], hand.torque_limit[0]);
        motor[0] = 10.0;
        coupling.torques(&q_meas, &motor, &qd, &mut tau).unwrap();
        assert_eq!(tau[0], -hand.torque_limit[0]);
        // Wrong lengths are errors, never panics; NaN stays NaN for the DFS to refuse.
        let e = coupling
            .torques(&q_meas[..3], &motor, &qd, &mut tau)
            .unwrap_err();
        assert!(e.to_string().contains("measured joint angles"), "{e}");
        let mut nan = q_meas.clone();
        nan[2] = Real::NAN;
        coupling.torques(&nan, &motor, &qd, &mut tau).unwrap();
        assert!(tau[2].is_nan());
        assert!(VirtualCoupling::with_gains(&hand, &k[..2], &c).is_err());
        let mut bad = k.clone();
        bad[4] = -1.0;
        let e = VirtualCoupling::with_gains(&hand, &bad, &c).unwrap_err();
        assert!(e.to_string().contains("DOF 4"), "{e}");
    }

    #[test]
    fn default_gains_follow_the_torque_limits_within_the_step_stability() {
        let dfs = DfsParams::default();
        for hand in hands() {
            let c = VirtualCoupling::for_hand(&hand, &CouplingParams::default(), &dfs).unwrap();
            let (m, _) = dof_inertias(&hand);
            for d in 0..hand.dof() {
                let (lo, hi) = hand.sweep_range(d);
                let k = c.stiffness()[d];
                assert!(k > 0.0, "{} DOF {d}", hand.name);
                // Full torque at a tenth of the range: the stability cap does not bite on
                // the built-in hands.
                let expected = hand.torque_limit[d] / (0.1 * (hi - lo));
                assert!((k - expected).abs() <= 1e-9 * expected, "{} {d}", hand.name);
                assert!(k * dfs.dt * dfs.dt <= 0.25 * (m[d] + dfs.joint_damping * dfs.dt));
                assert!(c.damping()[d] * dfs.dt <= m[d] + 1e-15);
            }
        }
        let bad = CouplingParams {
            full_torque_fraction: 0.0,
            ..CouplingParams::default()
        };
        let e = VirtualCoupling::for_hand(&HandModel::glove10(), &bad, &dfs).unwrap_err();
        assert!(e.to_string().contains("full_torque_fraction"), "{e}");
    }

    /// Steps `hand` in free space for `ticks`, coupled to `target` from rest at `start`; the
    /// largest overshoot past the target (fraction of each DOF's range), the largest error at
    /// `check_tick` (fraction of the range), and the largest speed at the end.
    fn step_response(
        hand: &HandModel,
        start: &[Real],
        target: &[Real],
        ticks: usize,
        check_tick: usize,
    ) -> (Real, Real, Real) {
        let n = hand.dof();
        let params = DfsParams {
            contact_model: ContactModel::SoftFinger,
            friction: Friction::default(),
            ..DfsParams::default()
        };
        let coupling =
            VirtualCoupling::for_hand(hand, &CouplingParams::default(), &params).unwrap();
        // The object far away: nothing touches.
        let object = RigidObject::new(Shape::Sphere { radius: 0.02 }, 0.1).unwrap();
        let far = Isometry::translation(5.0, 5.0, 5.0);
        let mut dfs = Dfs::new(hand.clone(), object, ObjectState::at_rest(far), params).unwrap();
        let mut tau = vec![0.0; n];
        let mut q = start.to_vec();
        let (mut overshoot, mut error): (Real, Real) = (0.0, 0.0);
        for tick in 0..ticks {
            if tick > 0 {
                coupling
                    .torques_from(target, dfs.output(), &mut tau)
                    .unwrap();
                q.copy_from_slice(&dfs.output().motor_q[..n]);
            }
            dfs.step(&GloveSample {
                q: &q,
                tau: &tau,
                base: Isometry::identity(),
            })
            .unwrap();
            for d in 0..n {
                let (lo, hi) = hand.sweep_range(d);
                let sign = (target[d] - start[d]).signum();
                let e = (dfs.output().motor_q[d] - target[d]) / (hi - lo);
                overshoot = overshoot.max(sign * e);
                if tick == check_tick {
                    error = error.max(e.abs());
                }
            }
        }
        let speed = dfs.output().motor_qd[..n]
            .iter()
            .fold(0.0, |m: Real, v| m.max(v.abs()));
        (overshoot, error, speed)
    }

    /// Each built-in hand in free space, its coupling pulling it from one posture to another:
    /// the simulated hand settles on the measured posture (the explicit coupling is stable in
    /// the DFS's step). A step within the springs' linear range (5 % of each range) settles
    /// within 0.5 s (most DOFs within 30 ms; Barrett's spread joints, 0.05 kg·m² on a
    /// 1.5 N·m motor, are the slowest), overshooting by less than 1 % of the range (each DOF
    /// is damped for its own inertia, and the DOFs push on each other through M: glove10's
    /// thumb MCP overshoots by 0.45 %); a sudden jump that saturates the torques (20 %) within
    /// 0.7 s, by less than 5 % (2.4 % on glove10: the DOFs come out of saturation fast).
    #[test]
    fn a_coupled_hand_in_free_space_follows_the_measured_posture() {
        for hand in hands() {
            let n = hand.dof();
            let at = |f: Real| -> Vec<Real> {
                (0..n)
                    .map(|d| {
                        let (lo, hi) = hand.sweep_range(d);
                        lo + f * (hi - lo)
                    })
                    .collect()
            };
            let (overshoot, error, speed) = step_response(&hand, &at(0.5), &at(0.55), 600, 500);
            assert!(overshoot < 0.01, "{}: overshoot {overshoot}", hand.name);
            assert!(error < 0.005, "{}: error {error} at 0.5 s", hand.name);
            assert!(speed < 0.05, "{}: still moving at {speed}", hand.name);
            let (overshoot, error, speed) = step_response(&hand, &at(0.6), &at(0.4), 800, 700);
            assert!(overshoot < 0.05, "{}: overshoot {overshoot}", hand.name);
            assert!(error < 0.01, "{}: error {error} at 0.7 s", hand.name);
            assert!(speed < 0.05, "{}: still moving at {speed}", hand.name);
        }
    }
}
