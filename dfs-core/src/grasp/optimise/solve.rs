//! Answering one load with a [`ForceSolver`]: the check that the load lies in the range of
//! W, the dual Newton method first (`newton.rs`), else Clarabel with the load fed in through
//! its data updates, and the post-solve checks of Clarabel's answer (residual and cones).

use super::{ForceSolver, Infeasible, InfeasibleKind, CHECK_TOLERANCE};
use crate::contact::Intensity;
use crate::math::{Real, Wrench};
use clarabel::solver::{IPSolver, SolverStatus};

impl ForceSolver {
    /// The least-internal-force distribution for `load_b` (the wrench the hand must apply, in
    /// B), written to `out` (one entry per contact); returns the residual `‖W c − load‖`.
    /// Errors as [`optimise_with_torque_limits`](super::optimise_with_torque_limits)'s.
    pub fn solve_into(
        &mut self,
        load_b: &Wrench,
        out: &mut [Intensity],
    ) -> Result<Real, Infeasible> {
        let k = self.comps.len();
        let n_contacts = self.w.ncols() / k.max(1);
        if out.len() != n_contacts || !load_b.iter().all(|v| v.is_finite()) {
            return Err(Infeasible::new(
                InfeasibleKind::InvalidInput,
                "the load must be finite and the output hold one intensity per contact",
            ));
        }
        let load_norm = load_b.norm();
        let m_eq = self.ur.ncols();
        // The load must lie in the range of W: U_r U_rᵀ load = load.
        let mut outside = *load_b;
        for j in 0..m_eq {
            let col = self.ur.column(j);
            let c: Real = (0..6).map(|i| col[i] * load_b[i]).sum();
            self.b[j] = c;
            for i in 0..6 {
                outside[i] -= col[i] * c;
            }
        }
        let outside = outside.norm();
        if outside > CHECK_TOLERANCE * (1.0 + load_norm) {
            return Err(Infeasible::new(
                InfeasibleKind::NoDistribution,
                format!(
                    "no distribution inside the friction cones balances the load (the contacts \
                     cannot produce it at all: W has rank {m_eq}, the part of the load outside \
                     its range is {outside:.3e})"
                ),
            ));
        }
        if self.solve_fast(load_b, out) {
            self.fast_solves += 1;
            return Ok(self.residual(out, load_b));
        }
        self.solve_clarabel(load_b, out)
    }

    /// Clarabel's answer for the load already in `b` (see [`solve_into`](Self::solve_into)).
    pub(super) fn solve_clarabel(
        &mut self,
        load_b: &Wrench,
        out: &mut [Intensity],
    ) -> Result<Real, Infeasible> {
        let k = self.comps.len();
        let load_norm = load_b.norm();
        self.clarabel_solves += 1;
        self.solver
            .update_b(&self.b)
            .map_err(|e| Infeasible::new(InfeasibleKind::Solver, format!("data update: {e}")))?;
        self.solver.solve();
        let status = self.solver.solution.status;
        match status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {}
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                return Err(Infeasible::new(
                    InfeasibleKind::NoDistribution,
                    format!(
                        "no distribution inside the friction cones balances the load (μ = {}, \
                         margin = {}, minimum normal force = {} N; solver status {status:?})",
                        self.friction.mu, self.margin, self.min_normal
                    ),
                ));
            }
            other => {
                return Err(Infeasible::new(
                    InfeasibleKind::Solver,
                    format!("solver stopped with status {other:?}"),
                ));
            }
        }
        let x = &self.solver.solution.x;
        for (i, c) in out.iter_mut().enumerate() {
            *c = Intensity::zeros();
            for (j, &comp) in self.comps.iter().enumerate() {
                c[comp] = x[k * i + j];
            }
        }
        let mut res = -*load_b;
        for (j, xj) in x.iter().enumerate() {
            for i in 0..6 {
                res[i] += self.w[(i, j)] * xj;
            }
        }
        let residual = res.norm();
        if residual > CHECK_TOLERANCE * (1.0 + load_norm) {
            return Err(Infeasible::new(
                InfeasibleKind::Solver,
                format!("solver returned a distribution that does not balance the load (residual {residual:.3e}, status {status:?})"),
            ));
        }
        let scale = CHECK_TOLERANCE * (1.0 + x.iter().fold(0.0_f64, |m, v| m.max(v.abs())));
        for (i, c) in out.iter().enumerate() {
            if !self.in_cone(c, scale) {
                return Err(Infeasible::new(
                    InfeasibleKind::Solver,
                    format!("solver returned a distribution outside the cone of contact {i} (status {status:?})"),
                ));
            }
        }
        Ok(residual)
    }

    /// Whether intensities `c` lie within `scale` of their cone (with the margin) and above
    /// the least normal force.
    fn in_cone(&self, c: &Intensity, scale: Real) -> bool {
        let (tx, ty) = (c[0], c[1]);
        let n = c[2] >= self.min_normal - scale;
        if self.elliptic {
            let t = c[3] / self.ell;
            n && (tx * tx + ty * ty + t * t).sqrt() <= self.mu * c[2] + scale
        } else {
            n && (tx * tx + ty * ty).sqrt() <= self.mu * c[2] + scale
                && c[3].abs() <= self.mu_t * c[2] + scale
        }
    }

    /// How many solves the dual Newton method answered, and how many Clarabel did.
    pub fn solve_counts(&self) -> (u64, u64) {
        (self.fast_solves, self.clarabel_solves)
    }

    /// `‖W c − load‖` for intensities `c`.
    fn residual(&self, c: &[Intensity], load_b: &Wrench) -> Real {
        let k = self.comps.len();
        let mut res = -*load_b;
        for (i, ci) in c.iter().enumerate() {
            for (j, &comp) in self.comps.iter().enumerate() {
                for r in 0..6 {
                    res[r] += self.w[(r, k * i + j)] * ci[comp];
                }
            }
        }
        res.norm()
    }
}
