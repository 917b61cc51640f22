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
//!
//! This file holds the problem's types and entry points and [`ForceSolver`]'s state; the
//! solver's set-up is in `setup.rs`, answering a load (the range check, Clarabel and the
//! post-solve checks) in `solve.rs`, and the dual Newton method in `newton.rs`.

use crate::contact::{ContactFrame, ContactModel, Friction, Intensity};
use crate::math::{Real, Wrench};
use clarabel::solver::DefaultSolver;
use nalgebra::DMatrix;

mod newton;
mod setup;
mod solve;
#[cfg(test)]
mod tests;

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
