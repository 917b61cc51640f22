//! The dual Newton method of [`ForceSolver`]: the exact least-internal-force distribution
//! when no torque limit binds, by Newton's method on the dual of the equality rows with
//! iterates exactly inside the cones (their projection in closed form, [`project_all`]).

use super::{ForceSolver, CHECK_TOLERANCE};
use crate::contact::Intensity;
use crate::math::{Real, Wrench};
use nalgebra::{Matrix6, Vector6};

impl ForceSolver {
    /// The exact distribution by Newton's method on the dual of the equality rows, warm-started
    /// from the last solve; `false` (and `out` untouched) when it does not apply or converge,
    /// for Clarabel to answer.
    ///
    /// With the torsion scaled by ℓ the problem is `min ½‖x‖²` over `x` in the product `K` of
    /// the per-contact sets `{c_z ≥ c_min, ‖(c_t, c_τ / ℓ)‖ ≤ μ' c_z}` (the elliptic soft
    /// finger's cone, round in these variables; `{c_z ≥ c_min, ‖c_t‖ ≤ μ' c_z, |c_τ| ≤ μ_t'
    /// c_z}` for a degenerate one, `c_τ` absent for a point contact) with `A x = b`
    /// (`b = U_rᵀ load`, `A` of full row rank ≤ 6). Its dual, `max_λ λᵀb − (yᵀΠ(y) −
    /// ½‖Π(y)‖²)` with `y = Aᵀλ` and `Π` the projection onto `K` (closed form per contact), is
    /// concave and smooth in at most six variables, with gradient `b − A Π(Aᵀλ)`; at its
    /// maximum `x = Π(Aᵀλ)` is the unique optimum. Every iterate's `x` lies in the cones
    /// exactly; the method stops when the equality residual is within the solver checks'
    /// tolerance. A solution that breaks a torque limit is not the constrained optimum:
    /// Clarabel then solves the full problem.
    pub(super) fn solve_fast(&mut self, load_b: &Wrench, out: &mut [Intensity]) -> bool {
        let m = self.ur.ncols();
        let tol = 0.1 * CHECK_TOLERANCE * (1.0 + load_b.norm());
        let b = nalgebra::Vector6::from_fn(|i, _| if i < m { self.b[i] } else { 0.0 });
        let mut lambda = nalgebra::Vector6::from_column_slice(&self.lambda);
        if !lambda.iter().all(|v| v.is_finite()) {
            lambda = nalgebra::Vector6::zeros();
        }
        let mut value = self.dual_at(&lambda, &b);
        let mut converged = false;
        for _ in 0..40 {
            // Gradient (the equality residual) at the current iterate; x holds Π(Aᵀλ).
            let g = self.dual_gradient(&b);
            if g.norm() <= tol {
                converged = true;
                break;
            }
            let h = self.dual_hessian(&lambda);
            let Some(direction) = newton_direction(&h, &g, m) else {
                break;
            };
            if !self.line_search(&mut lambda, &mut value, &direction, &g, &b) {
                // Restore x for lambda and give up.
                self.dual_at(&lambda, &b);
                break;
            }
        }
        if !converged {
            return false;
        }
        if !self.within_torque_limits() {
            return false;
        }
        self.lambda.copy_from_slice(lambda.as_slice());
        let k = self.comps.len();
        for (i, c) in out.iter_mut().enumerate() {
            *c = Intensity::zeros();
            for (j, &comp) in self.comps.iter().enumerate() {
                let v = self.x[k * i + j];
                c[comp] = if comp == 3 { v * self.ell } else { v };
            }
        }
        true
    }

    /// The dual's gradient `b − A Π(Aᵀλ)` (the equality residual) with `x` holding `Π(Aᵀλ)`.
    fn dual_gradient(&self, b: &Vector6<Real>) -> Vector6<Real> {
        let m = self.ur.ncols();
        let n = self.w.ncols();
        let mut g = *b;
        for i in 0..m {
            for v in 0..n {
                g[i] -= self.a_s[(i, v)] * self.x[v];
            }
        }
        g
    }

    /// `H = A J Aᵀ` at `lambda` with `J` the projection's derivative (piecewise constant),
    /// column by column from the change of Π along `Aᵀ e_j`; `x` holds `Π(Aᵀλ)`. The rows
    /// and columns past the rank are the identity's.
    fn dual_hessian(&mut self, lambda: &Vector6<Real>) -> Matrix6<Real> {
        let m = self.ur.ncols();
        let n = self.w.ncols();
        let mut h = nalgebra::Matrix6::<Real>::identity();
        let step = 1e-7 * (1.0 + lambda.norm());
        for j in 0..m {
            for v in 0..n {
                self.y[v] = (0..m).map(|i| self.a_s[(i, v)] * lambda[i]).sum::<Real>()
                    + self.a_s[(j, v)] * step;
            }
            project_all(
                &self.y,
                &mut self.x_probe,
                self.comps,
                self.mu,
                self.mu_t / self.ell,
                self.min_normal,
                self.elliptic,
            );
            for i in 0..m {
                h[(i, j)] = (0..n)
                    .map(|v| self.a_s[(i, v)] * (self.x_probe[v] - self.x[v]))
                    .sum::<Real>()
                    / step;
            }
        }
        h
    }

    /// Backtracking on the dual along `direction` from `lambda` (it must rise); on success
    /// `lambda`, `value` and `x` are the accepted step's, on failure `x` is the last trial's.
    ///
    /// Cold, at λ = 0, every normal force sits at its minimum and the squeeze direction is
    /// flat: the step is then some 1e11 times too long, and up to 64 halvings (each one
    /// projection) find the kink where the curvature starts. Two antipodal soft pads (a
    /// gripper) never got past it with 30, so every load of theirs went to Clarabel.
    fn line_search(
        &mut self,
        lambda: &mut Vector6<Real>,
        value: &mut Real,
        direction: &Vector6<Real>,
        g: &Vector6<Real>,
        b: &Vector6<Real>,
    ) -> bool {
        let mut t = 1.0;
        let slope = g.dot(direction);
        for _ in 0..64 {
            let trial = *lambda + direction * t;
            let v = self.dual_at(&trial, b);
            if v >= *value + 1e-4 * t * slope || (v - *value).abs() <= 1e-15 * (1.0 + value.abs()) {
                *lambda = trial;
                *value = v;
                return true;
            }
            t *= 0.5;
        }
        false
    }

    /// Whether the distribution in `x` keeps the torque limits, on the unscaled intensities
    /// (true without limits).
    fn within_torque_limits(&self) -> bool {
        let Some((rows, limits)) = &self.torque else {
            return true;
        };
        let n = self.w.ncols();
        let k = self.comps.len();
        let scale = CHECK_TOLERANCE * (1.0 + self.x.iter().fold(0.0_f64, |a, v| a.max(v.abs())));
        for d in 0..limits.len() {
            let tau: Real = (0..n)
                .map(|v| {
                    let unscaled = if self.comps[v % k] == 3 {
                        self.x[v] * self.ell
                    } else {
                        self.x[v]
                    };
                    rows[(d, v)] * unscaled
                })
                .sum();
            if tau.abs() > limits[d] + scale {
                return false;
            }
        }
        true
    }

    /// The dual objective at `lambda`; leaves `Π(Aᵀλ)` in `x`.
    fn dual_at(&mut self, lambda: &nalgebra::Vector6<Real>, b: &nalgebra::Vector6<Real>) -> Real {
        let m = self.ur.ncols();
        let n = self.w.ncols();
        for v in 0..n {
            self.y[v] = (0..m).map(|i| self.a_s[(i, v)] * lambda[i]).sum();
        }
        project_all(
            &self.y,
            &mut self.x,
            self.comps,
            self.mu,
            self.mu_t / self.ell,
            self.min_normal,
            self.elliptic,
        );
        let (mut yx, mut xx) = (0.0, 0.0);
        for v in 0..n {
            yx += self.y[v] * self.x[v];
            xx += self.x[v] * self.x[v];
        }
        lambda.dot(b) - (yx - 0.5 * xx)
    }
}

/// The Newton step `(H_sym + reg I)⁻¹ g` on the first `m` rows (the identity on the rest),
/// with the regularisation `reg` raised a hundredfold until the Cholesky factorisation
/// succeeds; `None` past 10⁶.
fn newton_direction(h: &Matrix6<Real>, g: &Vector6<Real>, m: usize) -> Option<Vector6<Real>> {
    let sym = (h + h.transpose()) * 0.5;
    let mut reg = 1e-12 * (1.0 + sym.trace().abs());
    loop {
        let mut a = sym;
        for i in 0..6 {
            a[(i, i)] += if i < m { reg } else { 1.0 };
        }
        if let Some(ch) = a.cholesky() {
            break Some(ch.solve(g));
        }
        reg *= 100.0;
        if reg > 1e6 {
            break None;
        }
    }
}

/// Projects every contact's block of `y` onto its set `{c_z ≥ c_min, ‖c_t‖ ≤ μ c_z, |c_τ| ≤
/// μ_τ c_z}` (the components present in `comps`), into `x`; with `elliptic`, onto `{c_z ≥
/// c_min, ‖(c_t, c_τ)‖ ≤ μ c_z}` (the torsion, already scaled, is a third tangential
/// component and `μ_τ` is not used). Per contact the nearest point keeps the tangential
/// direction and the torsion's sign: for a normal force `z` the tangential part is clipped to
/// `μ z` and the torsion to `μ_τ z`, which leaves a convex piecewise quadratic in `z` whose
/// minimiser on `[c_min, ∞)` is found interval by interval.
fn project_all(
    y: &[Real],
    x: &mut [Real],
    comps: &[usize],
    mu: Real,
    mu_tau: Real,
    c_min: Real,
    elliptic: bool,
) {
    let k = comps.len();
    let pos = |c: usize| comps.iter().position(|&x| x == c);
    let (iz, it, itau) = (pos(2).unwrap_or(0), pos(0), pos(3));
    // The elliptic cone's torsion is clipped with the tangential force, not on its own.
    let (with_tangent, itau, mu_tau) = match (elliptic, itau) {
        (true, Some(i)) => (Some(i), None, 0.0),
        (_, itau) => (None, itau, mu_tau),
    };
    for (yc, xc) in y.chunks_exact(k).zip(x.chunks_exact_mut(k)) {
        let z0 = yc[iz];
        let extra = with_tangent.map_or(0.0, |i| yc[i] * yc[i]);
        let a = it.map_or(0.0, |i| {
            (yc[i] * yc[i] + yc[i + 1] * yc[i + 1] + extra).sqrt()
        });
        let tau = itau.map_or(0.0, |i| yc[i].abs());
        // φ'(z)/2 = z − z0 − μ max(0, a − μz) − μ_τ max(0, τ − μ_τ z), increasing in z.
        let bp1 = if mu > 0.0 { a / mu } else { Real::INFINITY };
        let bp2 = if mu_tau > 0.0 {
            tau / mu_tau
        } else {
            Real::INFINITY
        };
        let root_with = |s1: bool, s2: bool| {
            let (mut num, mut den) = (z0, 1.0);
            if s1 {
                num += mu * a;
                den += mu * mu;
            }
            if s2 {
                num += mu_tau * tau;
                den += mu_tau * mu_tau;
            }
            num / den
        };
        // Try the intervals between the breakpoints in order; the root lies in exactly one.
        let mut z = root_with(false, false);
        let (lo, hi) = (bp1.min(bp2), bp1.max(bp2));
        for (s1_at, s2_at, left, right) in [
            (true, true, Real::NEG_INFINITY, lo),
            (bp1 > lo, bp2 > lo, lo, hi),
            (false, false, hi, Real::INFINITY),
        ] {
            let r = root_with(s1_at, s2_at);
            if r >= left && r <= right {
                z = r;
                break;
            }
        }
        let z = z.max(c_min).max(0.0);
        xc.copy_from_slice(yc);
        xc[iz] = z;
        if let Some(i) = it {
            let limit = mu * z;
            if a > limit {
                let f = if a > 0.0 { limit / a } else { 0.0 };
                xc[i] *= f;
                xc[i + 1] *= f;
                if let Some(j) = with_tangent {
                    xc[j] *= f;
                }
            }
        }
        if let Some(i) = itau {
            xc[i] = yc[i].clamp(-mu_tau * z, mu_tau * z);
        }
    }
}
