//! Grasp force optimisation (beyond the paper; Buss, Hashimoto and Moore 1996): the least
//! internal force that balances a load while keeping every contact inside its exact friction
//! cone with a margin.
//!
//! The problem is a second-order cone programme solved with Clarabel:
//!
//! ```text
//! minimise    Σ_i (c_x² + c_y² + c_z² + (c_τ / ℓ)²)
//! subject to  W c = load                          (equality, W of the model's components)
//!             sqrt(c_x² + c_y²) ≤ μ' c_z                              (point with friction)
//!             sqrt(c_x² + c_y² + (c_τ / e)²) ≤ μ' c_z                 (soft finger)
//!             c_z ≥ min_normal                                        (every model)
//! ```
//!
//! with `μ' = μ (1 − margin)`. The soft finger's cone is the elliptic one of
//! [`apply_friction`](crate::contact::apply_friction), `‖c_t‖²/μ'² + c_τ²/μ_t'² ≤ c_z²` with
//! `μ_t' = μ_t (1 − margin)`: a second-order cone once the torsion is measured by the
//! characteristic length `e = μ_t / μ` ([`Friction::torsion_length`]), a 4-dimensional one per
//! contact. Only the components the contact model transmits are variables. The torsion is
//! weighted by `1/ℓ²` with `ℓ = e` as well, so that the objective is the plain squared norm in
//! the variables where every cone is round: a torsion costs what it costs the pad's friction,
//! and the objective, the cones and so the result are independent of the unit of length (a
//! grasp in millimetres has the same forces and a thousand times the torsions). When `μ = 0` or
//! `μ_t = 0` the elliptic cone degenerates to the two limits apart, `‖c_t‖ ≤ μ' c_z` and `|c_τ| ≤
//! μ_t' c_z` (one of them zero), and `ℓ` is the largest distance of a contact from B's origin
//! (1 m when all contacts sit at the origin), a length as well.
//!
//! The equality is imposed on the range of `W` only (rows `U_rᵀ W c = U_rᵀ load` from a thin
//! SVD), after checking that the load lies in that range: a load the contacts cannot produce at
//! all (a moment about the line of two point contacts, a vertical load on a frictionless
//! horizontal pair) is reported as infeasible without calling the solver, and the solver never
//! sees redundant equality rows.
//!
//! [`optimise_with_torque_limits`] adds the hand's joint torque limits: with `T` the map from
//! the contact intensities to the joint torques `τ = Σ_i J_iᵀ f_i` (f_i the force contact i
//! applies to the object), `|T c| ≤ τ_max` row by row (two linear inequalities per joint).
//!
//! Every solution is checked after the solve: residual `‖W c − load‖ ≤ 10⁻⁶ (1 + ‖load‖)` and
//! every cone constraint within `10⁻⁶ (1 + max |c|)`. The result is deterministic: same input,
//! same output (Clarabel runs single-threaded).
//!
//! [`ForceSolver`] solves the same problem for one set of contacts and many loads (retargeting
//! along a motion): set up once, each load is answered by Newton's method on the dual of the
//! equality rows, warm-started from the previous load, whose iterates are exactly inside the
//! cones (see [`ForceSolver::solve_into`]); Clarabel, with the load fed in through its data
//! updates, answers when a torque limit binds or Newton does not converge.

use crate::contact::{ContactFrame, ContactModel, Friction, Intensity};
use crate::math::{Real, Wrench};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use nalgebra::DMatrix;

/// Relative tolerance of the post-solve checks (residual and cones).
pub const CHECK_TOLERANCE: Real = 1e-6;

/// Parameters of the optimisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptimiseParams {
    /// Friction margin: contacts must lie inside the cone of `μ (1 − margin)` (the soft
    /// finger's elliptic cone of `μ (1 − margin)` and `μ_t (1 − margin)`). Range [0, 1).
    /// Default 0.1.
    pub margin: Real,
    /// Least normal force per contact (N), ≥ 0. Default 0.
    pub min_normal: Real,
}

impl Default for OptimiseParams {
    fn default() -> Self {
        OptimiseParams {
            margin: 0.1,
            min_normal: 0.0,
        }
    }
}

/// An optimised force distribution.
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution {
    /// Intensities per contact (layout of [`Intensity`]).
    pub intensities: Vec<Intensity>,
    /// Residual `‖W c − load‖` (should be ~0).
    pub residual: Real,
}

/// What kind of failure an [`Infeasible`] reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InfeasibleKind {
    /// The input is invalid (no contacts, μ negative or not finite, margin outside [0, 1),
    /// a load or contact that is not finite, ...). A caller error.
    InvalidInput,
    /// The grasp cannot hold the load: no distribution inside the cones balances it.
    NoDistribution,
    /// The solver stopped without an answer (iteration limit, numerical trouble) or returned
    /// a distribution that fails the post-solve checks.
    Solver,
}

/// Why no distribution exists.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("infeasible grasp: {reason}")]
pub struct Infeasible {
    /// Human-readable reason.
    pub reason: String,
    /// The kind of failure.
    pub kind: InfeasibleKind,
}

impl Infeasible {
    fn new(kind: InfeasibleKind, reason: impl Into<String>) -> Self {
        Infeasible {
            reason: reason.into(),
            kind,
        }
    }
}

/// The intensity components (indices into [`Intensity`]) a model uses, in variable order.
fn components(model: ContactModel) -> &'static [usize] {
    match model {
        ContactModel::Frictionless => &[2],
        ContactModel::PointWithFriction => &[0, 1, 2],
        ContactModel::SoftFinger => &[0, 1, 2, 3],
    }
}

fn validate(
    contacts: &[ContactFrame],
    friction: &Friction,
    load_b: &Wrench,
    params: &OptimiseParams,
) -> Result<(), Infeasible> {
    let bad = |r: String| Err(Infeasible::new(InfeasibleKind::InvalidInput, r));
    if contacts.is_empty() {
        return bad("no contacts".into());
    }
    if !(friction.mu.is_finite() && friction.mu >= 0.0) {
        return bad(format!(
            "friction coefficient μ = {} must be finite and ≥ 0",
            friction.mu
        ));
    }
    if !(friction.mu_torsion.is_finite() && friction.mu_torsion >= 0.0) {
        return bad(format!(
            "torsional coefficient μ_t = {} must be finite and ≥ 0",
            friction.mu_torsion
        ));
    }
    if !(params.margin.is_finite() && (0.0..1.0).contains(&params.margin)) {
        return bad(format!(
            "friction margin {} must be in [0, 1)",
            params.margin
        ));
    }
    if !(params.min_normal.is_finite() && params.min_normal >= 0.0) {
        return bad(format!(
            "minimum normal force {} must be finite and ≥ 0",
            params.min_normal
        ));
    }
    if !load_b.iter().all(|v| v.is_finite()) {
        return bad("the load is not finite".into());
    }
    for (i, c) in contacts.iter().enumerate() {
        let q = c.rot_b.matrix();
        if !(c.p_b.iter().all(|v| v.is_finite()) && q.iter().all(|v| v.is_finite())) {
            return bad(format!("contact {i} is not finite"));
        }
    }
    Ok(())
}

/// Converts a dense matrix to CSC, dropping exact zeros.
fn csc(m: &DMatrix<Real>) -> CscMatrix<Real> {
    let mut colptr = Vec::with_capacity(m.ncols() + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            let v = m[(i, j)];
            if v != 0.0 {
                rowval.push(i);
                nzval.push(v);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(m.nrows(), m.ncols(), colptr, rowval, nzval)
}

/// Finds intensities `c` with `W c = load_b` (the wrench the hand must apply, in B) and every
/// contact inside its cone with the margin, minimising `Σ‖c_i‖²` (least internal force; the
/// torsion is weighted, see the module documentation).
///
/// Errors: [`InfeasibleKind::InvalidInput`] for bad input, [`InfeasibleKind::NoDistribution`]
/// when the grasp cannot hold the load, [`InfeasibleKind::Solver`] when the solver fails.
pub fn optimise(
    contacts: &[ContactFrame],
    model: ContactModel,
    friction: &Friction,
    load_b: &Wrench,
    params: &OptimiseParams,
) -> Result<Distribution, Infeasible> {
    optimise_with_torque_limits(contacts, model, friction, load_b, params, None)
}

/// Joint torque limits for [`optimise_with_torque_limits`]: `|Σ_k map[(d, 4 i + k)] c_i[k]| ≤
/// limits[d]` for every joint `d`, with `c_i` the intensities of contact `i` in the layout of
/// [`Intensity`] (components the contact model does not use are ignored).
#[derive(Debug, Clone, PartialEq)]
pub struct TorqueLimits {
    /// Joint torques per unit intensity: one row per joint, four columns per contact (N·m/N).
    pub map: DMatrix<Real>,
    /// Torque limit per joint (N·m), > 0.
    pub limits: Vec<Real>,
}

/// [`optimise`] with the hand's joint torque limits as further constraints (`None`: none).
/// A load the cones could carry but the torques cannot is [`InfeasibleKind::NoDistribution`]
/// too; solve once without limits to tell the two apart.
pub fn optimise_with_torque_limits(
    contacts: &[ContactFrame],
    model: ContactModel,
    friction: &Friction,
    load_b: &Wrench,
    params: &OptimiseParams,
    torque: Option<&TorqueLimits>,
) -> Result<Distribution, Infeasible> {
    validate(contacts, friction, load_b, params)?;
    let mut solver = ForceSolver::new(contacts, model, friction, params, torque)?;
    let mut intensities = vec![Intensity::zeros(); contacts.len()];
    let residual = solver.solve_into(load_b, &mut intensities)?;
    Ok(Distribution {
        intensities,
        residual,
    })
}

/// The force distribution of [`optimise_with_torque_limits`] for one set of contacts and
/// many loads: the problem is set up once (the grasp matrix's range, the cones, the torque
/// rows and Clarabel's KKT structure) and each [`solve`](Self::solve_into) only replaces the
/// load, through Clarabel's data updates. Same problem, same checks, same answers as
/// [`optimise_with_torque_limits`]; for retargeting along a reference motion, where the
/// contacts stay and the load changes every step.
pub struct ForceSolver {
    comps: &'static [usize],
    mu: Real,
    mu_t: Real,
    min_normal: Real,
    friction: Friction,
    margin: Real,
    /// W restricted to the model's components (6 × n).
    w: DMatrix<Real>,
    /// Orthonormal basis of W's range (6 × m_eq).
    ur: DMatrix<Real>,
    /// The constraint right-hand side; its first `m_eq` entries are the load's.
    b: Vec<Real>,
    solver: DefaultSolver<Real>,
    /// The equality rows `U_rᵀ W` with the torsion columns scaled by ℓ (variables in which
    /// the objective is the plain squared norm).
    a_s: DMatrix<Real>,
    /// Torsion scale ℓ (see the module documentation).
    ell: Real,
    /// The soft finger's cone is elliptic (`μ > 0` and `μ_t > 0`): with the torsion scaled
    /// by ℓ = e, the round cone `‖(c_x, c_y, c_τ / ℓ)‖ ≤ μ' c_z`.
    elliptic: bool,
    /// Torque rows on the model's components and their limits, for checking a fast solution.
    torque: Option<(DMatrix<Real>, Vec<Real>)>,
    /// Dual variables of the equality rows from the last fast solve (its warm start).
    lambda: [Real; 6],
    /// Scratch: `A_sᵀ λ`, its projection, and a perturbed projection.
    y: Vec<Real>,
    x: Vec<Real>,
    x_probe: Vec<Real>,
    /// Solves answered by the dual Newton method, and by Clarabel.
    fast_solves: u64,
    clarabel_solves: u64,
}

impl std::fmt::Debug for ForceSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ForceSolver")
            .field("contacts", &(self.w.ncols() / self.comps.len().max(1)))
            .field("variables", &self.w.ncols())
            .field("constraints", &self.b.len())
            .finish()
    }
}

impl ForceSolver {
    /// Sets the problem up for `contacts` (see [`optimise_with_torque_limits`]).
    pub fn new(
        contacts: &[ContactFrame],
        model: ContactModel,
        friction: &Friction,
        params: &OptimiseParams,
        torque: Option<&TorqueLimits>,
    ) -> Result<Self, Infeasible> {
        validate(contacts, friction, &Wrench::zeros(), params)?;
        if let Some(t) = torque {
            let ok = t.map.ncols() == 4 * contacts.len()
                && t.map.nrows() == t.limits.len()
                && t.map.iter().all(|v| v.is_finite())
                && t.limits.iter().all(|l| l.is_finite() && *l > 0.0);
            if !ok {
                return Err(Infeasible::new(
                    InfeasibleKind::InvalidInput,
                    "torque limits: the map needs 4 columns per contact and one finite limit > 0 \
                     per row",
                ));
            }
        }
        let comps = components(model);
        let k = comps.len();
        let n_contacts = contacts.len();
        let n = k * n_contacts;
        let mu = friction.mu * (1.0 - params.margin);
        let mu_t = friction.mu_torsion * (1.0 - params.margin);
        let has_tangent = model != ContactModel::Frictionless;
        let has_torsion = model == ContactModel::SoftFinger;

        // W restricted to the model's components.
        let mut w = DMatrix::<Real>::zeros(6, n);
        for (i, c) in contacts.iter().enumerate() {
            for (j, &comp) in comps.iter().enumerate() {
                let mut e = Intensity::zeros();
                e[comp] = 1.0;
                w.set_column(k * i + j, &c.wrench_b(&e));
            }
        }
        // Range of W: thin SVD of the 6 x n matrix.
        let svd = w.clone().svd(true, false);
        let u = svd
            .u
            .as_ref()
            .ok_or_else(|| Infeasible::new(InfeasibleKind::Solver, "SVD of W failed"))?;
        let smax = svd.singular_values.iter().fold(0.0_f64, |m, &s| m.max(s));
        let range: Vec<usize> = (0..svd.singular_values.len())
            .filter(|&r| svd.singular_values[r] > 1e-9 * smax.max(1e-300))
            .collect();
        let ur = DMatrix::from_fn(6, range.len(), |i, j| u[(i, range[j])]);
        let a_eq = ur.transpose() * &w;
        let m_eq = range.len();

        // Torsion weight and the soft finger's cone (module documentation).
        let elliptic_length = friction.torsion_length().filter(|_| has_torsion);
        let elliptic = elliptic_length.is_some();
        let ell = elliptic_length.unwrap_or_else(|| {
            let r = contacts.iter().fold(0.0_f64, |m, c| m.max(c.p_b.norm()));
            if r > 0.0 {
                r
            } else {
                1.0
            }
        });

        // Objective ½ xᵀ P x with P = 2 diag(weights): upper triangle of a diagonal matrix.
        let mut pdiag = Vec::with_capacity(n);
        for _ in 0..n_contacts {
            for &comp in comps {
                pdiag.push(if comp == 3 { 2.0 / (ell * ell) } else { 2.0 });
            }
        }
        let p = CscMatrix::new(n, n, (0..=n).collect(), (0..n).collect(), pdiag);
        let q = vec![0.0; n];

        // Constraints A x + s = b, s in the cones, block by block.
        let n_torque = torque.map_or(0, |t| 2 * t.limits.len());
        // The degenerate soft finger bounds its torsion by two inequalities; the elliptic one
        // in its 4-dimensional second-order cone.
        let box_torsion = has_torsion && !elliptic;
        let soc = if elliptic { 4 } else { 3 };
        let n_nonneg = n_contacts * if box_torsion { 3 } else { 1 } + n_torque;
        let n_soc = if has_tangent { soc * n_contacts } else { 0 };
        let m = m_eq + n_nonneg + n_soc;
        let mut a = DMatrix::<Real>::zeros(m, n);
        let b = vec![0.0; m];
        let mut b = b;
        a.rows_mut(0, m_eq).copy_from(&a_eq);
        let iz = comps.iter().position(|&c| c == 2).unwrap_or(0);
        let mut row = m_eq;
        for i in 0..n_contacts {
            let z = k * i + iz;
            // c_z ≥ min_normal  ⇔  s = c_z − min_normal ≥ 0.
            a[(row, z)] = -1.0;
            b[row] = -params.min_normal;
            row += 1;
            if box_torsion {
                let t = k * i + 3;
                // μ_t' c_z − c_τ ≥ 0 and μ_t' c_z + c_τ ≥ 0.
                a[(row, z)] = -mu_t;
                a[(row, t)] = 1.0;
                row += 1;
                a[(row, z)] = -mu_t;
                a[(row, t)] = -1.0;
                row += 1;
            }
        }
        if let Some(t) = torque {
            // τ_max − T c ≥ 0 and τ_max + T c ≥ 0, on the model's components.
            for d in 0..t.limits.len() {
                for sign in [1.0, -1.0] {
                    for i in 0..n_contacts {
                        for (j, &comp) in comps.iter().enumerate() {
                            a[(row, k * i + j)] = sign * t.map[(d, 4 * i + comp)];
                        }
                    }
                    b[row] = t.limits[d];
                    row += 1;
                }
            }
        }
        let mut cones = vec![
            SupportedConeT::ZeroConeT(m_eq),
            SupportedConeT::NonnegativeConeT(n_nonneg),
        ];
        if has_tangent {
            for i in 0..n_contacts {
                // s = (μ' c_z, c_x, c_y) in the second-order cone; the elliptic soft finger's
                // s = (μ' c_z, c_x, c_y, c_τ / e) (module documentation).
                a[(row, k * i + 2)] = -mu;
                a[(row + 1, k * i)] = -1.0;
                a[(row + 2, k * i + 1)] = -1.0;
                if elliptic {
                    a[(row + 3, k * i + 3)] = -1.0 / ell;
                }
                row += soc;
                cones.push(SupportedConeT::SecondOrderConeT(soc));
            }
        }
        if m_eq == 0 {
            cones.remove(0);
        }
        // No presolve: the load goes in through data updates, which it would forbid.
        let settings = DefaultSettings::<Real> {
            verbose: false,
            max_threads: 1,
            presolve_enable: false,
            ..DefaultSettings::default()
        };
        let solver = DefaultSolver::new(&p, &q, &csc(&a), &b, &cones, settings).map_err(|e| {
            Infeasible::new(InfeasibleKind::Solver, format!("solver setup failed: {e}"))
        })?;
        let mut a_s = a_eq.clone();
        if has_torsion {
            for i in 0..n_contacts {
                a_s.column_mut(k * i + 3).scale_mut(ell);
            }
        }
        let torque = torque.map(|t| {
            let rows = DMatrix::from_fn(t.limits.len(), n, |d, v| {
                t.map[(d, 4 * (v / k) + comps[v % k])]
            });
            (rows, t.limits.clone())
        });
        Ok(ForceSolver {
            comps,
            mu,
            mu_t,
            min_normal: params.min_normal,
            friction: *friction,
            margin: params.margin,
            w,
            ur,
            b,
            solver,
            a_s,
            ell,
            elliptic,
            torque,
            lambda: [0.0; 6],
            y: vec![0.0; n],
            x: vec![0.0; n],
            x_probe: vec![0.0; n],
            fast_solves: 0,
            clarabel_solves: 0,
        })
    }

    /// The least-internal-force distribution for `load_b` (the wrench the hand must apply, in
    /// B), written to `out` (one entry per contact); returns the residual `‖W c − load‖`.
    /// Errors as [`optimise_with_torque_limits`]'s.
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
    fn solve_clarabel(
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
    fn solve_fast(&mut self, load_b: &Wrench, out: &mut [Intensity]) -> bool {
        let m = self.ur.ncols();
        let n = self.w.ncols();
        let k = self.comps.len();
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
            let mut g = b;
            for i in 0..m {
                for v in 0..n {
                    g[i] -= self.a_s[(i, v)] * self.x[v];
                }
            }
            if g.norm() <= tol {
                converged = true;
                break;
            }
            // H = A J Aᵀ with J the projection's derivative (piecewise constant), column by
            // column from the change of Π along Aᵀ e_j.
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
            let sym = (h + h.transpose()) * 0.5;
            let mut reg = 1e-12 * (1.0 + sym.trace().abs());
            let direction = loop {
                let mut a = sym;
                for i in 0..6 {
                    a[(i, i)] += if i < m { reg } else { 1.0 };
                }
                if let Some(ch) = a.cholesky() {
                    break Some(ch.solve(&g));
                }
                reg *= 100.0;
                if reg > 1e6 {
                    break None;
                }
            };
            let Some(direction) = direction else {
                break;
            };
            // Backtracking on the dual (it must rise). Cold, at λ = 0, every normal force sits
            // at its minimum and the squeeze direction is flat: the step is then some 1e11
            // times too long, and up to 64 halvings (each one projection) find the kink where
            // the curvature starts. Two antipodal soft pads (a gripper) never got past it with
            // 30, so every load of theirs went to Clarabel.
            let mut t = 1.0;
            let slope = g.dot(&direction);
            let mut accepted = false;
            for _ in 0..64 {
                let trial = lambda + direction * t;
                let v = self.dual_at(&trial, &b);
                if v >= value + 1e-4 * t * slope || (v - value).abs() <= 1e-15 * (1.0 + value.abs())
                {
                    lambda = trial;
                    value = v;
                    accepted = true;
                    break;
                }
                t *= 0.5;
            }
            if !accepted {
                // Restore x for lambda and give up.
                self.dual_at(&lambda, &b);
                break;
            }
        }
        if !converged {
            return false;
        }
        // The torque limits, on the unscaled intensities.
        if let Some((rows, limits)) = &self.torque {
            let scale =
                CHECK_TOLERANCE * (1.0 + self.x.iter().fold(0.0_f64, |a, v| a.max(v.abs())));
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
        }
        self.lambda.copy_from_slice(lambda.as_slice());
        for (i, c) in out.iter_mut().enumerate() {
            *c = Intensity::zeros();
            for (j, &comp) in self.comps.iter().enumerate() {
                let v = self.x[k * i + j];
                c[comp] = if comp == 3 { v * self.ell } else { v };
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::normal_and_tangential;
    use crate::grasp::GraspMatrix;
    use crate::math::{Vector, STANDARD_GRAVITY};
    use proptest::prelude::*;

    use crate::grasp::tests::paper_contacts;

    fn gravity_load() -> Wrench {
        Wrench::new(0.0, 0.0, STANDARD_GRAVITY, 0.0, 0.0, 0.0)
    }

    fn fr(mu: Real) -> Friction {
        Friction {
            mu,
            mu_torsion: 0.005,
        }
    }

    /// Inside the cone of `μ` (and, with `μ_t`, the elliptic soft-finger cone: the old box
    /// `‖c_t‖ ≤ μ c_z`, `|c_τ| ≤ μ_t c_z` let a pad carry both at once, √2 too much).
    fn inside(c: &Intensity, mu: Real, mu_t: Real, min_normal: Real) -> bool {
        let (n, t) = normal_and_tangential(c);
        let tol = 1e-6 * (1.0 + c.norm());
        let cone = if mu > 0.0 && mu_t > 0.0 {
            ((t / mu).powi(2) + (c[3] / mu_t).powi(2)).sqrt() <= n + tol / mu
        } else {
            t <= mu * n + tol && c[3].abs() <= mu_t * n + tol
        };
        n >= min_normal - tol && cone
    }

    /// Loads along a lift: gravity plus accelerations up to 6 m/s² and moments up to 0.05 N·m,
    /// deterministic (xorshift).
    fn lift_loads(count: usize) -> Vec<Wrench> {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0
        };
        (0..count)
            .map(|_| {
                let m = 0.3;
                Wrench::new(
                    m * 6.0 * next(),
                    m * 6.0 * next(),
                    m * (STANDARD_GRAVITY + 6.0 * next()),
                    0.05 * next(),
                    0.05 * next(),
                    0.05 * next(),
                )
            })
            .collect()
    }

    #[test]
    fn the_dual_newton_distribution_matches_clarabels_for_every_load_along_a_lift() {
        let contacts = paper_contacts();
        let params = OptimiseParams {
            margin: 0.5,
            min_normal: 0.5,
        };
        for model in [ContactModel::PointWithFriction, ContactModel::SoftFinger] {
            let mut solver = ForceSolver::new(&contacts, model, &fr(0.8), &params, None).unwrap();
            let mut fast = vec![Intensity::zeros(); 4];
            let mut reference = vec![Intensity::zeros(); 4];
            let mut solved = 0;
            for load in lift_loads(60) {
                let before = solver.solve_counts();
                let r = solver.solve_into(&load, &mut fast);
                let Ok(residual) = r else {
                    // Infeasible for the fast method and Clarabel alike.
                    assert!(solver.solve_clarabel(&load, &mut reference).is_err());
                    continue;
                };
                assert!(residual <= CHECK_TOLERANCE * (1.0 + load.norm()));
                assert_eq!(solver.solve_counts().0, before.0 + 1, "{model:?} {load:?}");
                solver.solve_clarabel(&load, &mut reference).unwrap();
                let scale = 1.0 + reference.iter().fold(0.0_f64, |a, c| a.max(c.amax()));
                for (f, c) in fast.iter().zip(&reference) {
                    assert!((f - c).amax() < 1e-5 * scale, "{model:?}: {f:?} vs {c:?}");
                    assert!(inside(f, 0.4, 0.0025, 0.5), "{f:?}");
                }
                let d = Distribution {
                    intensities: fast.clone(),
                    residual,
                };
                assert_balances(&contacts, model, &d, &load);
                solved += 1;
            }
            assert!(solved >= 30, "{model:?}: {solved} of 60 loads held");
        }
    }

    #[test]
    fn an_antipodal_soft_pair_along_a_lift_is_answered_by_the_dual_newton_method() {
        // A parallel gripper's two pads. Cold, at λ = 0, every normal force sits at its
        // minimum and the squeeze direction is flat in the dual: the Newton step is huge and
        // only a long backtrack finds the kink. (It used to give up there, so every load went
        // to Clarabel.)
        let r = 0.04;
        let contacts = [
            ContactFrame::from_normal(Vector::new(-r, 0.0, 0.0), Vector::x()),
            ContactFrame::from_normal(Vector::new(r, 0.0, 0.0), -Vector::x()),
        ];
        let params = OptimiseParams {
            margin: 0.5,
            min_normal: 0.5,
        };
        let friction = Friction {
            mu: 0.8,
            mu_torsion: 0.005,
        };
        let mut solver = ForceSolver::new(
            &contacts,
            ContactModel::SoftFinger,
            &friction,
            &params,
            None,
        )
        .unwrap();
        let mut fast = vec![Intensity::zeros(); 2];
        let mut reference = vec![Intensity::zeros(); 2];
        let (mut held, mut by_newton) = (0, 0);
        for load in lift_loads(60) {
            let before = solver.solve_counts();
            let Ok(residual) = solver.solve_into(&load, &mut fast) else {
                continue;
            };
            held += 1;
            assert!(residual <= CHECK_TOLERANCE * (1.0 + load.norm()));
            if solver.solve_counts().0 > before.0 {
                by_newton += 1;
                solver.solve_clarabel(&load, &mut reference).unwrap();
                let scale = 1.0 + reference.iter().fold(0.0_f64, |a, c| a.max(c.amax()));
                for (f, c) in fast.iter().zip(&reference) {
                    assert!((f - c).amax() < 1e-5 * scale, "{f:?} vs {c:?}");
                }
            }
        }
        assert!(held >= 30, "{held} of 60 loads held");
        assert!(
            by_newton * 10 >= held * 9,
            "Newton answered {by_newton} of {held}"
        );
    }

    #[test]
    fn the_optimised_distribution_does_not_depend_on_the_unit_of_length() {
        // The paper's sphere held by soft fingers against gravity and a twist, in metres and in
        // millimetres (positions, μ_t and moments a thousand times larger): the same forces and
        // a thousand times the torsions, from Clarabel and from the dual Newton method alike.
        let load = Wrench::new(0.3, -0.2, STANDARD_GRAVITY, 0.05, -0.03, 0.04);
        let params = OptimiseParams {
            margin: 0.2,
            min_normal: 0.5,
        };
        let mut answers = Vec::new();
        for s in [1.0, 1000.0] {
            let contacts: Vec<_> = paper_contacts()
                .iter()
                .map(|c| ContactFrame {
                    p_b: c.p_b * s,
                    rot_b: c.rot_b,
                })
                .collect();
            let friction = Friction {
                mu: 0.6,
                mu_torsion: 0.005 * s,
            };
            let mut l = load;
            for k in 3..6 {
                l[k] *= s;
            }
            let model = ContactModel::SoftFinger;
            let mut solver = ForceSolver::new(&contacts, model, &friction, &params, None).unwrap();
            let mut fast = vec![Intensity::zeros(); 4];
            let mut reference = vec![Intensity::zeros(); 4];
            solver.solve_into(&l, &mut fast).unwrap();
            assert_eq!(
                solver.solve_counts(),
                (1, 0),
                "the dual Newton method answers"
            );
            solver.solve_clarabel(&l, &mut reference).unwrap();
            for c in fast.iter().chain(&reference) {
                assert!(inside(c, 0.6 * 0.8, 0.005 * s * 0.8, 0.5), "{c:?}");
            }
            answers.push((s, fast, reference));
        }
        let (_, fast_m, clarabel_m) = &answers[0];
        let (s, fast_mm, clarabel_mm) = &answers[1];
        assert!(fast_m.iter().any(|c| c[3].abs() > 1e-4), "{fast_m:?}");
        for (m, mm, tol) in [(fast_m, fast_mm, 1e-7), (clarabel_m, clarabel_mm, 1e-5)] {
            for (a, b) in m.iter().zip(mm.iter()) {
                let back = Intensity::new(b[0], b[1], b[2], b[3] / s);
                assert!(
                    (a - back).amax() < tol * (1.0 + a.amax()),
                    "{a:?} vs {back:?}"
                );
            }
        }
        for (a, b) in fast_m.iter().zip(clarabel_m.iter()) {
            assert!((a - b).amax() < 1e-5 * (1.0 + b.amax()), "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn a_soft_pad_is_not_given_its_whole_friction_and_torsion_at_once() {
        // Two pads pinching a sphere at its equator against its weight and a twist about the
        // pinch axis: the torsion each pad carries leaves it less tangential friction (the
        // elliptic cone), so they squeeze harder than the weight alone needs, and each sits
        // on its cone.
        let r = 0.04;
        let contacts = [
            ContactFrame::from_normal(Vector::new(-r, 0.0, 0.0), Vector::x()),
            ContactFrame::from_normal(Vector::new(r, 0.0, 0.0), -Vector::x()),
        ];
        let friction = Friction {
            mu: 0.8,
            mu_torsion: 0.005,
        };
        let params = OptimiseParams {
            margin: 0.0,
            min_normal: 0.0,
        };
        let (weight, twist) = (3.0, 0.01);
        let load = Wrench::new(0.0, 0.0, weight, twist, 0.0, 0.0);
        let d = optimise(
            &contacts,
            ContactModel::SoftFinger,
            &friction,
            &load,
            &params,
        )
        .unwrap();
        assert_balances(&contacts, ContactModel::SoftFinger, &d, &load);
        // By symmetry each pad carries half the weight and half the twist: the least normal
        // force with (w/2 / μ)² + (m/2 / μ_t)² = c_z².
        let least = ((weight / 2.0 / 0.8).powi(2) + (twist / 2.0 / 0.005).powi(2)).sqrt();
        for c in &d.intensities {
            assert!((c[2] - least).abs() < 1e-4 * least, "{c:?}, least {least}");
            assert!(inside(c, 0.8, 0.005, 0.0), "{c:?}");
        }
        // The box would have let each pad push only max(w/2/μ, m/2/μ_t) = 1.875 N.
        assert!(least > 2.0);
    }

    #[test]
    fn a_distribution_that_breaks_a_torque_limit_is_left_to_clarabel() {
        let contacts = paper_contacts();
        let params = OptimiseParams {
            margin: 0.5,
            min_normal: 0.5,
        };
        let model = ContactModel::SoftFinger;
        let load = gravity_load();
        let free = optimise(&contacts, model, &fr(0.8), &load, &params).unwrap();
        // One "joint" that sums the first contact's normal force, limited below what the free
        // optimum uses but above what the grasp can make do with.
        let mut map = DMatrix::zeros(1, 16);
        map[(0, 2)] = 1.0;
        let limits = TorqueLimits {
            map,
            limits: vec![0.9 * free.intensities[0][2]],
        };
        let mut solver =
            ForceSolver::new(&contacts, model, &fr(0.8), &params, Some(&limits)).unwrap();
        let mut out = vec![Intensity::zeros(); 4];
        solver.solve_into(&load, &mut out).unwrap();
        assert_eq!(solver.solve_counts(), (0, 1));
        assert!(out[0][2] <= limits.limits[0] + 1e-6, "{}", out[0][2]);
    }

    fn assert_balances(
        contacts: &[ContactFrame],
        model: ContactModel,
        d: &Distribution,
        load: &Wrench,
    ) {
        let f = contacts
            .iter()
            .zip(&d.intensities)
            .fold(Wrench::zeros(), |f, (c, i)| {
                f + c.wrench_b(&i.component_mul(&model.mask()))
            });
        assert!(
            (f - load).norm() < 1e-6 * (1.0 + load.norm()),
            "W c = {f:?}, load {load:?}"
        );
        assert!(d.residual < 1e-6 * (1.0 + load.norm()));
    }

    #[test]
    fn the_paper_sphere_with_high_friction_is_held_inside_the_cones_with_margin() {
        let contacts = paper_contacts();
        let p = OptimiseParams::default();
        let d = optimise(
            &contacts,
            ContactModel::PointWithFriction,
            &fr(1.5),
            &gravity_load(),
            &p,
        )
        .unwrap();
        assert_balances(
            &contacts,
            ContactModel::PointWithFriction,
            &d,
            &gravity_load(),
        );
        for c in &d.intensities {
            assert!(inside(c, 1.5 * 0.9, 0.0, 0.0), "{c:?}");
            assert!(c[2] > 0.0);
        }
        // With μ' = 1.35 ≥ 1.3 the minimum-norm W⁺ distribution of the paper already fits, and it
        // is the least-norm solution of the equality, so the optimiser must return it.
        let g = GraspMatrix::new(&contacts, ContactModel::PointWithFriction, &fr(1.5));
        let mut c0 = [Intensity::zeros(); 4];
        g.distribute(&gravity_load(), &mut c0);
        for (a, b) in d.intensities.iter().zip(&c0) {
            assert!((a - b).norm() < 1e-4, "{a:?} vs W⁺ {b:?}");
        }
    }

    #[test]
    fn the_paper_sphere_with_low_friction_is_held_by_squeezing() {
        // All four contacts sit below the equator, so every inward normal points upward (n_z ≈
        // 0.61) and the normals pass through the centre (no moment). The horizontal parts of the
        // normals of contacts 2 and 4 cancel: equal normal forces of 9.81 / (2 · 0.61) ≈ 8 N on
        // them hold the sphere with no friction at all. So squeezing *does* add upward force
        // here, and a distribution inside any cone (even μ = 0) must exist, although the W⁺
        // distribution is outside the cone (ratio ≈ 1.3 > 0.3).
        let contacts = paper_contacts();
        let g = GraspMatrix::new(&contacts, ContactModel::PointWithFriction, &fr(1.5));
        let mut c0 = [Intensity::zeros(); 4];
        g.distribute(&gravity_load(), &mut c0);
        let (n, t) = normal_and_tangential(&c0[0]);
        assert!((t / n - 1.3).abs() < 0.05, "W⁺ ratio {}", t / n);

        let p = OptimiseParams::default();
        let d = optimise(
            &contacts,
            ContactModel::PointWithFriction,
            &fr(0.3),
            &gravity_load(),
            &p,
        )
        .unwrap();
        assert_balances(
            &contacts,
            ContactModel::PointWithFriction,
            &d,
            &gravity_load(),
        );
        for c in &d.intensities {
            assert!(inside(c, 0.3 * 0.9, 0.0, 0.0), "{c:?}");
        }
        // More internal force than the minimum-norm distribution.
        let total: Real = d.intensities.iter().map(|c| c[2]).sum();
        let total0: Real = c0.iter().map(|c| c[2]).sum();
        assert!(total > total0);

        let d = optimise(
            &contacts,
            ContactModel::Frictionless,
            &fr(0.0),
            &gravity_load(),
            &p,
        )
        .unwrap();
        assert_balances(&contacts, ContactModel::Frictionless, &d, &gravity_load());
    }

    #[test]
    fn an_antipodal_pair_on_the_equator_squeezes_enough_to_hold_one_kilogram() {
        let r = 0.05;
        let contacts = [
            ContactFrame::from_normal(Vector::new(r, 0.0, 0.0), -Vector::x()),
            ContactFrame::from_normal(Vector::new(-r, 0.0, 0.0), Vector::x()),
        ];
        let p = OptimiseParams::default();
        let mu = 0.5;
        for model in [ContactModel::PointWithFriction, ContactModel::SoftFinger] {
            let d = optimise(&contacts, model, &fr(mu), &gravity_load(), &p).unwrap();
            assert_balances(&contacts, model, &d, &gravity_load());
            let least = STANDARD_GRAVITY / (2.0 * mu * (1.0 - p.margin));
            for c in &d.intensities {
                assert!(c[2] >= least * (1.0 - 1e-6), "normal {} < {least}", c[2]);
                assert!(
                    c[2] <= least * 1.01,
                    "normal {} far above the least {least}",
                    c[2]
                );
                assert!(inside(c, mu * 0.9, 0.005 * 0.9, 0.0));
            }
        }
    }

    #[test]
    fn a_minimum_normal_force_is_respected() {
        let contacts = paper_contacts();
        let p = OptimiseParams {
            margin: 0.1,
            min_normal: 5.0,
        };
        let d = optimise(
            &contacts,
            ContactModel::SoftFinger,
            &fr(1.0),
            &gravity_load(),
            &p,
        )
        .unwrap();
        assert_balances(&contacts, ContactModel::SoftFinger, &d, &gravity_load());
        for c in &d.intensities {
            assert!(inside(c, 0.9, 0.0045, 5.0), "{c:?}");
        }
    }

    #[test]
    fn one_contact_cannot_hold_a_load_with_a_moment() {
        let contacts = [ContactFrame::from_normal(
            Vector::new(0.0, 0.0, -0.05),
            Vector::z(),
        )];
        let p = OptimiseParams::default();
        // A moment about the normal: the point contact cannot produce it at all.
        let load = Wrench::new(0.0, 0.0, STANDARD_GRAVITY, 0.0, 0.0, 0.1);
        let e = optimise(
            &contacts,
            ContactModel::PointWithFriction,
            &fr(0.8),
            &load,
            &p,
        )
        .unwrap_err();
        assert_eq!(e.kind, InfeasibleKind::NoDistribution, "{e}");
        // A moment about x needs a tangential force along y of M / 0.05 m: 0.5 N·m needs 10 N,
        // more than μ' c_z = 0.72 · 9.81 N allows: outside the cone.
        let load = Wrench::new(0.0, 0.0, STANDARD_GRAVITY, 0.5, 0.0, 0.0);
        let e = optimise(
            &contacts,
            ContactModel::PointWithFriction,
            &fr(0.8),
            &load,
            &p,
        )
        .unwrap_err();
        assert_eq!(e.kind, InfeasibleKind::NoDistribution, "{e}");
        assert!(e
            .reason
            .contains("no distribution inside the friction cones"));
    }

    #[test]
    fn a_frictionless_antipodal_pair_cannot_hold_a_vertical_load() {
        let contacts = [
            ContactFrame::from_normal(Vector::new(0.05, 0.0, 0.0), -Vector::x()),
            ContactFrame::from_normal(Vector::new(-0.05, 0.0, 0.0), Vector::x()),
        ];
        let e = optimise(
            &contacts,
            ContactModel::Frictionless,
            &fr(0.8),
            &gravity_load(),
            &OptimiseParams::default(),
        )
        .unwrap_err();
        assert_eq!(e.kind, InfeasibleKind::NoDistribution, "{e}");
    }

    #[test]
    fn a_pair_that_would_need_to_pull_is_infeasible() {
        // Both contacts push upward from below... but the load pushes the object *up*: only a
        // pull could balance it.
        let contacts = [
            ContactFrame::from_normal(Vector::new(0.03, 0.0, -0.04), Vector::new(-0.03, 0.0, 0.04)),
            ContactFrame::from_normal(Vector::new(-0.03, 0.0, -0.04), Vector::new(0.03, 0.0, 0.04)),
        ];
        let load = Wrench::new(0.0, 0.0, -STANDARD_GRAVITY, 0.0, 0.0, 0.0);
        let e = optimise(
            &contacts,
            ContactModel::PointWithFriction,
            &fr(0.5),
            &load,
            &OptimiseParams::default(),
        )
        .unwrap_err();
        assert_eq!(e.kind, InfeasibleKind::NoDistribution, "{e}");
    }

    #[test]
    fn invalid_inputs_are_reported_not_solved() {
        let contacts = paper_contacts();
        let l = gravity_load();
        let p = OptimiseParams::default();
        let m = ContactModel::PointWithFriction;
        let bad = |r: Result<Distribution, Infeasible>| {
            assert_eq!(r.unwrap_err().kind, InfeasibleKind::InvalidInput)
        };
        bad(optimise(&[], m, &fr(1.0), &l, &p));
        bad(optimise(&contacts, m, &fr(-0.1), &l, &p));
        bad(optimise(&contacts, m, &fr(Real::NAN), &l, &p));
        bad(optimise(
            &contacts,
            m,
            &fr(1.0),
            &l,
            &OptimiseParams {
                margin: 1.0,
                min_normal: 0.0,
            },
        ));
        bad(optimise(
            &contacts,
            m,
            &fr(1.0),
            &l,
            &OptimiseParams {
                margin: -0.1,
                min_normal: 0.0,
            },
        ));
        bad(optimise(
            &contacts,
            m,
            &fr(1.0),
            &l,
            &OptimiseParams {
                margin: 0.1,
                min_normal: -1.0,
            },
        ));
        bad(optimise(
            &contacts,
            m,
            &fr(1.0),
            &Wrench::new(0.0, 0.0, Real::INFINITY, 0.0, 0.0, 0.0),
            &p,
        ));
    }

    #[test]
    fn the_optimisation_is_deterministic() {
        let contacts = paper_contacts();
        let p = OptimiseParams::default();
        let a = optimise(
            &contacts,
            ContactModel::SoftFinger,
            &fr(0.4),
            &gravity_load(),
            &p,
        )
        .unwrap();
        let b = optimise(
            &contacts,
            ContactModel::SoftFinger,
            &fr(0.4),
            &gravity_load(),
            &p,
        )
        .unwrap();
        assert_eq!(a, b);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn feasible_random_grasps_are_balanced_inside_the_cones(
            pts in prop::collection::vec(prop::array::uniform3(-1.0..1.0f64), 3..7),
            weights in prop::collection::vec(0.5..3.0f64, 7),
            tangents in prop::collection::vec(prop::array::uniform2(-1.0..1.0f64), 7),
            mu in 0.2..1.5f64,
            model in 0usize..2,
        ) {
            // A load that is feasible by construction: the wrench of intensities strictly inside
            // the cones (with the margin) of contacts on a sphere of radius 0.1.
            let model = [ContactModel::PointWithFriction, ContactModel::SoftFinger][model];
            let contacts: Vec<_> = pts.iter().filter(|p| Vector::from(**p).norm() > 0.1)
                .map(|p| { let p = Vector::from(*p).normalize() * 0.1; ContactFrame::from_normal(p, -p / 0.1) }).collect();
            prop_assume!(!contacts.is_empty());
            let f = fr(mu);
            let p = OptimiseParams::default();
            let mut load = Wrench::zeros();
            for (i, c) in contacts.iter().enumerate() {
                let n = weights[i];
                let t = tangents[i];
                let ci = Intensity::new(0.8 * mu * 0.9 * n * t[0] / 1.5, 0.8 * mu * 0.9 * n * t[1] / 1.5, n, 0.5 * 0.005 * 0.9 * n * t[0]);
                load += c.wrench_b(&ci.component_mul(&model.mask()));
            }
            let d = optimise(&contacts, model, &f, &load, &p);
            prop_assert!(d.is_ok(), "{:?}", d);
            let d = d.unwrap();
            let back = contacts.iter().zip(&d.intensities).fold(Wrench::zeros(), |w, (c, i)| w + c.wrench_b(i));
            prop_assert!((back - load).norm() < 1e-6 * (1.0 + load.norm()));
            for c in &d.intensities {
                prop_assert!(inside(c, mu * 0.9, 0.005 * 0.9, 0.0), "{:?}", c);
            }
        }
    }
}
