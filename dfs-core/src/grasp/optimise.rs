//! Grasp force optimisation (beyond the paper; Buss, Hashimoto and Moore 1996): the least
//! internal force that balances a load while keeping every contact inside its exact friction
//! cone with a margin.
//!
//! The problem is a second-order cone programme solved with Clarabel:
//!
//! ```text
//! minimise    Σ_i (c_x² + c_y² + c_z² + (c_τ / ℓ)²)
//! subject to  W c = load                          (equality, W of the model's components)
//!             sqrt(c_x² + c_y²) ≤ μ (1 − margin) c_z      (point with friction, soft finger)
//!             |c_τ| ≤ μ_t (1 − margin) c_z                  (soft finger)
//!             c_z ≥ min_normal                             (every model)
//! ```
//!
//! Only the components the contact model transmits are variables. The torsion is weighted by
//! `1/ℓ²` with `ℓ` the largest distance of a contact from B's origin (1 m when all contacts sit
//! at the origin), so that a torsional moment of `ℓ · 1 N` costs as much as a force of 1 N:
//! the objective is then independent of the unit of length.
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

use crate::contact::{ContactFrame, ContactModel, Friction, Intensity};
use crate::math::{Real, Wrench};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use nalgebra::{DMatrix, DVector};

/// Relative tolerance of the post-solve checks (residual and cones).
pub const CHECK_TOLERANCE: Real = 1e-6;

/// Parameters of the optimisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptimiseParams {
    /// Friction margin: contacts must lie inside the cone of `μ (1 − margin)` (and the torsion
    /// cone of `μ_t (1 − margin)`). Range [0, 1). Default 0.1.
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
        let q = c.rot_b.coords;
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
    let load = DVector::from_column_slice(load_b.as_slice());
    let load_norm = load.norm();

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
    let load_in_range = &ur * (ur.transpose() * &load);
    let outside = (&load - &load_in_range).norm();
    if outside > CHECK_TOLERANCE * (1.0 + load_norm) {
        return Err(Infeasible::new(
            InfeasibleKind::NoDistribution,
            format!(
                "no distribution inside the friction cones balances the load (the contacts \
                 cannot produce it at all: W has rank {}, the part of the load outside its \
                 range is {outside:.3e})",
                range.len()
            ),
        ));
    }
    let a_eq = ur.transpose() * &w;
    let b_eq = ur.transpose() * &load;
    let m_eq = range.len();

    // Torsion weight.
    let ell = contacts.iter().fold(0.0_f64, |m, c| m.max(c.p_b.norm()));
    let ell = if ell > 0.0 { ell } else { 1.0 };

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
    let n_nonneg = n_contacts * if has_torsion { 3 } else { 1 } + n_torque;
    let n_soc = if has_tangent { 3 * n_contacts } else { 0 };
    let m = m_eq + n_nonneg + n_soc;
    let mut a = DMatrix::<Real>::zeros(m, n);
    let mut b = vec![0.0; m];
    a.rows_mut(0, m_eq).copy_from(&a_eq);
    b[..m_eq].copy_from_slice(b_eq.as_slice());
    let iz = comps.iter().position(|&c| c == 2).unwrap_or(0);
    let mut row = m_eq;
    for i in 0..n_contacts {
        let z = k * i + iz;
        // c_z ≥ min_normal  ⇔  s = c_z − min_normal ≥ 0.
        a[(row, z)] = -1.0;
        b[row] = -params.min_normal;
        row += 1;
        if has_torsion {
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
            // s = (μ' c_z, c_x, c_y) in the second-order cone.
            a[(row, k * i + 2)] = -mu;
            a[(row + 1, k * i)] = -1.0;
            a[(row + 2, k * i + 1)] = -1.0;
            row += 3;
            cones.push(SupportedConeT::SecondOrderConeT(3));
        }
    }
    if m_eq == 0 {
        cones.remove(0);
    }

    let settings = DefaultSettings::<Real> {
        verbose: false,
        max_threads: 1,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&p, &q, &csc(&a), &b, &cones, settings).map_err(|e| {
        Infeasible::new(InfeasibleKind::Solver, format!("solver setup failed: {e}"))
    })?;
    solver.solve();
    let status = solver.solution.status;
    match status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {}
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
            return Err(Infeasible::new(
                InfeasibleKind::NoDistribution,
                format!(
                    "no distribution inside the friction cones balances the load (μ = {}, \
                     margin = {}, minimum normal force = {} N; solver status {status:?})",
                    friction.mu, params.margin, params.min_normal
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

    let x = &solver.solution.x;
    let mut intensities = vec![Intensity::zeros(); n_contacts];
    for (i, c) in intensities.iter_mut().enumerate() {
        for (j, &comp) in comps.iter().enumerate() {
            c[comp] = x[k * i + j];
        }
    }
    let xv = DVector::from_column_slice(x);
    let residual = (&w * &xv - &load).norm();
    if residual > CHECK_TOLERANCE * (1.0 + load_norm) {
        return Err(Infeasible::new(
            InfeasibleKind::Solver,
            format!("solver returned a distribution that does not balance the load (residual {residual:.3e}, status {status:?})"),
        ));
    }
    let scale = CHECK_TOLERANCE * (1.0 + x.iter().fold(0.0_f64, |m, v| m.max(v.abs())));
    for (i, c) in intensities.iter().enumerate() {
        let tan = (c[0] * c[0] + c[1] * c[1]).sqrt();
        let ok = c[2] >= params.min_normal - scale
            && tan <= mu * c[2] + scale
            && c[3].abs() <= mu_t * c[2] + scale;
        if !ok {
            return Err(Infeasible::new(
                InfeasibleKind::Solver,
                format!("solver returned a distribution outside the cone of contact {i} (status {status:?})"),
            ));
        }
    }
    Ok(Distribution {
        intensities,
        residual,
    })
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

    fn inside(c: &Intensity, mu: Real, mu_t: Real, min_normal: Real) -> bool {
        let (n, t) = normal_and_tangential(c);
        let tol = 1e-6 * (1.0 + c.norm());
        n >= min_normal - tol && t <= mu * n + tol && c[3].abs() <= mu_t * n + tol
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
        let g = GraspMatrix::new(&contacts, ContactModel::PointWithFriction);
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
        let g = GraspMatrix::new(&contacts, ContactModel::PointWithFriction);
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
