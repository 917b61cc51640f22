//! Setting a [`ForceSolver`] up for one set of contacts: the grasp matrix on the model's
//! components and its range, the torsion scale, and Clarabel's objective, constraint rows and
//! cones (the problem of the module documentation, built once for every load).

use super::{
    components, validate, ForceSolver, Infeasible, InfeasibleKind, OptimiseParams, TorqueLimits,
};
use crate::contact::{ContactFrame, ContactModel, Friction, Intensity};
use crate::math::{Real, Wrench};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, SupportedConeT};
use nalgebra::DMatrix;

impl ForceSolver {
    /// Sets the problem up for `contacts` (see [`optimise_with_torque_limits`]).
    ///
    /// [`optimise_with_torque_limits`]: super::optimise_with_torque_limits
    pub fn new(
        contacts: &[ContactFrame],
        model: ContactModel,
        friction: &Friction,
        params: &OptimiseParams,
        torque: Option<&TorqueLimits>,
    ) -> Result<Self, Infeasible> {
        validate(contacts, friction, &Wrench::zeros(), params)?;
        check_torque_limits(torque, contacts.len())?;
        let comps = components(model);
        let k = comps.len();
        let n_contacts = contacts.len();
        let n = k * n_contacts;
        let mu = friction.mu * (1.0 - params.margin);
        let mu_t = friction.mu_torsion * (1.0 - params.margin);
        let has_tangent = model != ContactModel::Frictionless;
        let has_torsion = model == ContactModel::SoftFinger;

        let w = restricted_grasp_matrix(contacts, comps);
        let ur = range_basis(&w)?;
        let a_eq = ur.transpose() * &w;
        let (ell, elliptic) = torsion_scale(contacts, friction, has_torsion);
        let (p, q) = objective(n_contacts, comps, ell);
        let layout = Layout {
            comps,
            n_contacts,
            mu,
            mu_t,
            min_normal: params.min_normal,
            has_tangent,
            has_torsion,
            ell,
            elliptic,
        };
        let (a, b, cones) = layout.constraints(&a_eq, torque);
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
}

/// Refuses torque limits whose map does not have four columns per contact and one row per
/// finite limit > 0.
fn check_torque_limits(torque: Option<&TorqueLimits>, n_contacts: usize) -> Result<(), Infeasible> {
    if let Some(t) = torque {
        let ok = t.map.ncols() == 4 * n_contacts
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
    Ok(())
}

/// W restricted to the model's components `comps` (6 × `comps.len()` per contact).
fn restricted_grasp_matrix(contacts: &[ContactFrame], comps: &[usize]) -> DMatrix<Real> {
    let k = comps.len();
    let mut w = DMatrix::<Real>::zeros(6, k * contacts.len());
    for (i, c) in contacts.iter().enumerate() {
        for (j, &comp) in comps.iter().enumerate() {
            let mut e = Intensity::zeros();
            e[comp] = 1.0;
            w.set_column(k * i + j, &c.wrench_b(&e));
        }
    }
    w
}

/// An orthonormal basis of the range of `w` (6 × its rank), from a thin SVD of the 6 x n
/// matrix.
fn range_basis(w: &DMatrix<Real>) -> Result<DMatrix<Real>, Infeasible> {
    let svd = w.clone().svd(true, false);
    let u = svd
        .u
        .as_ref()
        .ok_or_else(|| Infeasible::new(InfeasibleKind::Solver, "SVD of W failed"))?;
    let smax = svd.singular_values.iter().fold(0.0_f64, |m, &s| m.max(s));
    let range: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&r| svd.singular_values[r] > 1e-9 * smax.max(1e-300))
        .collect();
    Ok(DMatrix::from_fn(6, range.len(), |i, j| u[(i, range[j])]))
}

/// The torsion weight's length ℓ and whether the soft finger's cone is elliptic (module
/// documentation): the characteristic length `μ_t / μ` when the model has a torsion and
/// both coefficients are positive, else the largest distance of a contact from B's origin
/// (1 m when all sit at it).
fn torsion_scale(
    contacts: &[ContactFrame],
    friction: &Friction,
    has_torsion: bool,
) -> (Real, bool) {
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
    (ell, elliptic)
}

/// The objective `½ xᵀ P x + qᵀ x`: `P = 2 diag(weights)` (upper triangle of a diagonal
/// matrix), the torsion weighted by `1/ℓ²`, and `q = 0`.
fn objective(n_contacts: usize, comps: &[usize], ell: Real) -> (CscMatrix<Real>, Vec<Real>) {
    let n = comps.len() * n_contacts;
    let mut pdiag = Vec::with_capacity(n);
    for _ in 0..n_contacts {
        for &comp in comps {
            pdiag.push(if comp == 3 { 2.0 / (ell * ell) } else { 2.0 });
        }
    }
    let p = CscMatrix::new(n, n, (0..=n).collect(), (0..n).collect(), pdiag);
    let q = vec![0.0; n];
    (p, q)
}

/// The problem's shape, as [`ForceSolver::new`] derives it from the contact model, the
/// friction and the parameters: what the constraint rows are made of.
struct Layout {
    comps: &'static [usize],
    n_contacts: usize,
    /// `μ' = μ (1 − margin)`.
    mu: Real,
    /// `μ_t' = μ_t (1 − margin)`.
    mu_t: Real,
    min_normal: Real,
    has_tangent: bool,
    has_torsion: bool,
    ell: Real,
    elliptic: bool,
}

impl Layout {
    /// The constraints `A x + s = b`, `s` in the cones, block by block: the equality rows
    /// `a_eq` (none when W has rank 0), the nonnegative rows (least normal forces, a
    /// degenerate soft finger's torsion bounds, the torque limits), then one second-order
    /// cone per contact when the model has friction.
    fn constraints(
        &self,
        a_eq: &DMatrix<Real>,
        torque: Option<&TorqueLimits>,
    ) -> (DMatrix<Real>, Vec<Real>, Vec<SupportedConeT<Real>>) {
        let (k, n_contacts) = (self.comps.len(), self.n_contacts);
        let n = k * n_contacts;
        let m_eq = a_eq.nrows();
        let n_torque = torque.map_or(0, |t| 2 * t.limits.len());
        // The degenerate soft finger bounds its torsion by two inequalities; the elliptic one
        // in its 4-dimensional second-order cone.
        let box_torsion = self.has_torsion && !self.elliptic;
        let soc = if self.elliptic { 4 } else { 3 };
        let n_nonneg = n_contacts * if box_torsion { 3 } else { 1 } + n_torque;
        let n_soc = if self.has_tangent {
            soc * n_contacts
        } else {
            0
        };
        let m = m_eq + n_nonneg + n_soc;
        let mut a = DMatrix::<Real>::zeros(m, n);
        let mut b = vec![0.0; m];
        a.rows_mut(0, m_eq).copy_from(a_eq);
        let mut row = self.normal_rows(&mut a, &mut b, m_eq, box_torsion);
        if let Some(t) = torque {
            row = self.torque_rows(&mut a, &mut b, row, t);
        }
        let mut cones = vec![
            SupportedConeT::ZeroConeT(m_eq),
            SupportedConeT::NonnegativeConeT(n_nonneg),
        ];
        if self.has_tangent {
            self.cone_rows(&mut a, row, soc, &mut cones);
        }
        if m_eq == 0 {
            cones.remove(0);
        }
        (a, b, cones)
    }

    /// Per contact from `row` on, `c_z ≥ min_normal` and with `box_torsion` the torsion's
    /// two bounds; returns the next row.
    fn normal_rows(
        &self,
        a: &mut DMatrix<Real>,
        b: &mut [Real],
        mut row: usize,
        box_torsion: bool,
    ) -> usize {
        let k = self.comps.len();
        let iz = self.comps.iter().position(|&c| c == 2).unwrap_or(0);
        for i in 0..self.n_contacts {
            let z = k * i + iz;
            // c_z ≥ min_normal  ⇔  s = c_z − min_normal ≥ 0.
            a[(row, z)] = -1.0;
            b[row] = -self.min_normal;
            row += 1;
            if box_torsion {
                let t = k * i + 3;
                // μ_t' c_z − c_τ ≥ 0 and μ_t' c_z + c_τ ≥ 0.
                a[(row, z)] = -self.mu_t;
                a[(row, t)] = 1.0;
                row += 1;
                a[(row, z)] = -self.mu_t;
                a[(row, t)] = -1.0;
                row += 1;
            }
        }
        row
    }

    /// From `row` on, `τ_max − T c ≥ 0` and `τ_max + T c ≥ 0` on the model's components, per
    /// joint; returns the next row.
    fn torque_rows(
        &self,
        a: &mut DMatrix<Real>,
        b: &mut [Real],
        mut row: usize,
        t: &TorqueLimits,
    ) -> usize {
        let k = self.comps.len();
        for d in 0..t.limits.len() {
            for sign in [1.0, -1.0] {
                for i in 0..self.n_contacts {
                    for (j, &comp) in self.comps.iter().enumerate() {
                        a[(row, k * i + j)] = sign * t.map[(d, 4 * i + comp)];
                    }
                }
                b[row] = t.limits[d];
                row += 1;
            }
        }
        row
    }

    /// From `row` on, each contact's second-order cone of `soc` rows, pushed onto `cones`.
    fn cone_rows(
        &self,
        a: &mut DMatrix<Real>,
        mut row: usize,
        soc: usize,
        cones: &mut Vec<SupportedConeT<Real>>,
    ) {
        let k = self.comps.len();
        for i in 0..self.n_contacts {
            // s = (μ' c_z, c_x, c_y) in the second-order cone; the elliptic soft finger's
            // s = (μ' c_z, c_x, c_y, c_τ / e) (module documentation).
            a[(row, k * i + 2)] = -self.mu;
            a[(row + 1, k * i)] = -1.0;
            a[(row + 2, k * i + 1)] = -1.0;
            if self.elliptic {
                a[(row + 3, k * i + 3)] = -1.0 / self.ell;
            }
            row += soc;
            cones.push(SupportedConeT::SecondOrderConeT(soc));
        }
    }
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
