//! Grasp quality as GraspIt! defines it: Ferrari-Canny ε with linearised friction cones and the
//! volume of the grasp wrench space.
//!
//! **Primitive wrenches.** Each contact's friction cone is linearised by `edges` unit-normal-force
//! forces `f = n + μ (cos φ t_x + sin φ t_y)`, `φ = 2πk / edges` (GraspIt!'s default is 8 edges),
//! in the contact frame's tangents `t_x, t_y`. A force becomes the wrench `(f, (p × f) / ρ)` in
//! B, with the torque divided by a characteristic length `ρ` (GraspIt! uses the object's maximum
//! radius) so that ε does not depend on the unit of length. By contact model:
//! - frictionless: one primitive, the unit normal force (`edges` is ignored);
//! - point with friction: the `edges` cone edges;
//! - soft finger: each cone edge twice, with the torsional moment `± μ_t` about the normal added
//!   (the vertices of the product of the tangential polygon and the torsion interval, which is
//!   exactly the linearisation of [`apply_friction`](crate::contact::apply_friction)'s cone).
//!
//! **Metrics** (GraspIt!'s `QualEpsilon` and `QualVolume` on the L1 grasp wrench space, the
//! convex hull of all primitive wrenches, not including the origin):
//! - ε is the distance from the origin to the nearest facet hyperplane of the hull when the
//!   origin is strictly inside (force closure); otherwise the grasp is not force closure and ε
//!   is reported as 0 (GraspIt! returns a negative value there);
//! - the volume is the 6-dimensional volume of the hull (0 when the primitives do not span six
//!   dimensions, as for any two point contacts).
//!
//! **Convex hull.** GraspIt! calls Qhull. The `qhull` crate's build needs libclang (bindgen),
//! which this project's machines and CI do not have, and it writes to temporary files and
//! stderr; so the hull is computed here by a Quickhull with simplicial facets in six
//! dimensions (tolerance `1e-9` times the largest primitive), and every result is checked
//! (each primitive inside every facet, each ridge shared by two facets) before it is used. The
//! volume is the sum over facets of the simplices they span with an interior point.
//! Allocates; meant for planning and analysis, not the 1 kHz tick.

use crate::contact::{ContactFrame, ContactModel, Friction, Intensity};
use crate::error::{DfsError, Result};
use crate::math::{Real, Wrench};

/// Parameters of the grasp quality computation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QualityParams {
    /// Edges of each linearised friction cone, ≥ 3. Default 8 (GraspIt!'s choice).
    pub edges: usize,
    /// Characteristic length ρ (m) that divides torques, > 0. `None` (the default) uses the
    /// largest distance of a contact from B's origin, which for contacts on an object centred
    /// at B is a lower bound of its maximum radius; pass the object's maximum radius to match
    /// GraspIt! exactly.
    pub torque_scale: Option<Real>,
}

impl Default for QualityParams {
    fn default() -> Self {
        QualityParams {
            edges: 8,
            torque_scale: None,
        }
    }
}

/// The quality of a grasp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GraspQuality {
    /// Ferrari-Canny ε (dimensionless with unit normal forces: the largest wrench, in the
    /// units of the primitives, that the grasp resists in every direction). 0 when the grasp
    /// is not force closure.
    pub epsilon: Real,
    /// Volume of the grasp wrench space (the primitives' convex hull), ≥ 0.
    pub volume: Real,
    /// The origin is strictly inside the grasp wrench space: the grasp resists any wrench.
    pub force_closure: bool,
    /// The torque scale ρ (m) that was used.
    pub torque_scale: Real,
}

/// The torque scale ρ for these contacts and parameters (see [`QualityParams::torque_scale`]).
pub fn torque_scale(contacts: &[ContactFrame], params: &QualityParams) -> Real {
    match params.torque_scale {
        Some(r) => r,
        None => {
            let r = contacts.iter().fold(0.0_f64, |m, c| m.max(c.p_b.norm()));
            if r > 0.0 {
                r
            } else {
                1.0
            }
        }
    }
}

/// The primitive wrenches of the contacts (see the module documentation), torques divided by
/// `rho`.
pub fn primitive_wrenches(
    contacts: &[ContactFrame],
    model: ContactModel,
    friction: &Friction,
    edges: usize,
    rho: Real,
) -> Vec<Wrench> {
    let mut out = Vec::new();
    let scale = |mut w: Wrench| {
        for k in 3..6 {
            w[k] /= rho;
        }
        w
    };
    for c in contacts {
        match model {
            ContactModel::Frictionless => {
                out.push(scale(c.wrench_b(&Intensity::new(0.0, 0.0, 1.0, 0.0))))
            }
            ContactModel::PointWithFriction | ContactModel::SoftFinger => {
                for k in 0..edges {
                    let phi = 2.0 * std::f64::consts::PI * k as Real / edges as Real;
                    let (s, co) = phi.sin_cos();
                    let (tx, ty) = (friction.mu * co, friction.mu * s);
                    if model == ContactModel::SoftFinger {
                        for t in [friction.mu_torsion, -friction.mu_torsion] {
                            out.push(scale(c.wrench_b(&Intensity::new(tx, ty, 1.0, t))));
                        }
                    } else {
                        out.push(scale(c.wrench_b(&Intensity::new(tx, ty, 1.0, 0.0))));
                    }
                }
            }
        }
    }
    out
}

fn validate(contacts: &[ContactFrame], friction: &Friction, params: &QualityParams) -> Result<()> {
    if !(friction.mu.is_finite() && friction.mu >= 0.0) {
        return Err(DfsError::invalid(
            "friction.mu",
            format!("{} must be finite and ≥ 0", friction.mu),
        ));
    }
    if !(friction.mu_torsion.is_finite() && friction.mu_torsion >= 0.0) {
        return Err(DfsError::invalid(
            "friction.mu_torsion",
            format!("{} must be finite and ≥ 0", friction.mu_torsion),
        ));
    }
    if params.edges < 3 {
        return Err(DfsError::invalid(
            "edges",
            format!("{} friction cone edges: at least 3 needed", params.edges),
        ));
    }
    if let Some(r) = params.torque_scale {
        if !(r.is_finite() && r > 0.0) {
            return Err(DfsError::invalid(
                "torque_scale",
                format!("{r} must be finite and > 0"),
            ));
        }
    }
    for (i, c) in contacts.iter().enumerate() {
        if !(c.p_b.iter().all(|v| v.is_finite()) && c.rot_b.matrix().iter().all(|v| v.is_finite()))
        {
            return Err(DfsError::invalid(format!("contacts[{i}]"), "not finite"));
        }
    }
    Ok(())
}

/// Ferrari-Canny ε and the volume of the grasp wrench space of the contacts (module
/// documentation). No contacts, or primitives that do not span six dimensions, give a grasp
/// that is not force closure with ε = 0 and volume 0.
///
/// Errors: invalid parameters ([`DfsError::Invalid`]), or a convex hull that fails its checks
/// (numerically hopeless input).
pub fn grasp_quality(
    contacts: &[ContactFrame],
    model: ContactModel,
    friction: &Friction,
    params: &QualityParams,
) -> Result<GraspQuality> {
    validate(contacts, friction, params)?;
    let rho = torque_scale(contacts, params);
    let prims = primitive_wrenches(contacts, model, friction, params.edges, rho);
    let not_closure = GraspQuality {
        epsilon: 0.0,
        volume: 0.0,
        force_closure: false,
        torque_scale: rho,
    };
    if prims.len() < 7 {
        return Ok(not_closure);
    }
    let size = prims.iter().fold(0.0_f64, |m, w| m.max(w.norm()));
    let tol = 1e-9 * size;
    let h = match hull::build(&prims, tol) {
        Ok(h) => h,
        Err(hull::HullError::Flat) => return Ok(not_closure),
        Err(hull::HullError::Numerical(why)) => {
            return Err(DfsError::invalid(
                "grasp wrench space",
                format!("convex hull failed: {why}"),
            ))
        }
    };
    let volume = h.volume(&prims);
    let min_offset = h.facets.iter().map(|f| f.d).fold(Real::INFINITY, Real::min);
    let force_closure = min_offset > tol;
    Ok(GraspQuality {
        epsilon: if force_closure { min_offset } else { 0.0 },
        volume,
        force_closure,
        torque_scale: rho,
    })
}

/// A Quickhull in six dimensions with simplicial facets.
mod hull {
    use nalgebra::{SMatrix, SVector};

    const D: usize = 6;
    type P = SVector<f64, D>;

    /// A facet: `n · x = d` with `n` the outward unit normal; `nb[k]` is the neighbour across
    /// the ridge opposite vertex `v[k]`.
    pub(super) struct Facet {
        pub v: [usize; D],
        pub n: P,
        pub d: f64,
        nb: [usize; D],
        outside: Vec<usize>,
        alive: bool,
    }

    /// The hull: its live facets and a point strictly inside.
    pub(super) struct Hull {
        pub facets: Vec<Facet>,
        interior: P,
    }

    /// Why no hull was built.
    #[derive(Debug)]
    pub(super) enum HullError {
        /// The points do not span six dimensions.
        Flat,
        /// Rounding broke an invariant.
        Numerical(&'static str),
    }

    impl Hull {
        /// Volume: the simplices spanned by each facet and the interior point.
        pub fn volume(&self, pts: &[P]) -> f64 {
            let mut vol = 0.0;
            for f in &self.facets {
                let m = SMatrix::<f64, D, D>::from_fn(|i, j| pts[f.v[j]][i] - self.interior[i]);
                vol += m.determinant().abs();
            }
            vol / 720.0
        }
    }

    /// The hyperplane through the facet's vertices, oriented away from `inside`: the normal is
    /// what remains of the coordinate axis least in the span of the edges after twice-repeated
    /// Gram-Schmidt against them (cheaper than an SVD and as accurate here).
    fn plane(pts: &[P], v: &[usize; D], inside: &P) -> Option<(P, f64)> {
        let mut q = [P::zeros(); D - 1];
        for i in 1..D {
            let mut e = pts[v[i]] - pts[v[0]];
            let scale = e.norm();
            for _ in 0..2 {
                for qj in q.iter().take(i - 1) {
                    e -= qj * qj.dot(&e);
                }
            }
            let en = e.norm();
            if !(en > 1e-12 * scale && en.is_finite()) {
                return None;
            }
            q[i - 1] = e / en;
        }
        let axis = (0..D)
            .min_by(|&a, &b| {
                let pa: f64 = q.iter().map(|qj| qj[a] * qj[a]).sum();
                let pb: f64 = q.iter().map(|qj| qj[b] * qj[b]).sum();
                pa.total_cmp(&pb)
            })
            .unwrap_or(0);
        let mut n = P::zeros();
        n[axis] = 1.0;
        for _ in 0..2 {
            for qj in &q {
                n -= qj * qj.dot(&n);
            }
        }
        let norm = n.norm();
        if !(norm > 1e-6 && norm.is_finite()) {
            return None;
        }
        n /= norm;
        // Offset from the mean of the vertices (less rounding than one vertex).
        let mean = v.iter().map(|&i| pts[i]).sum::<P>() / D as f64;
        let mut d = n.dot(&mean);
        if n.dot(inside) > d {
            n = -n;
            d = -d;
        }
        Some((n, d))
    }

    fn dist(f: &Facet, p: &P) -> f64 {
        f.n.dot(p) - f.d
    }

    fn ridge_key(v: &[usize; D], skip: usize) -> [usize; D - 1] {
        let mut k = [0; D - 1];
        let mut j = 0;
        for (i, &x) in v.iter().enumerate() {
            if i != skip {
                k[j] = x;
                j += 1;
            }
        }
        k.sort_unstable();
        k
    }

    /// Builds the convex hull of `pts` (tolerance `tol` for "outside").
    pub(super) fn build(pts: &[P], tol: f64) -> Result<Hull, HullError> {
        let npts = pts.len();
        if npts < D + 1 {
            return Err(HullError::Flat);
        }
        // Initial simplex: greedily the points farthest from the affine hull of those chosen.
        let centroid = pts.iter().sum::<P>() / npts as f64;
        let i0 = (0..npts)
            .max_by(|&a, &b| {
                (pts[a] - centroid)
                    .norm()
                    .total_cmp(&(pts[b] - centroid).norm())
            })
            .ok_or(HullError::Flat)?;
        let mut chosen = vec![i0];
        let mut basis: Vec<P> = Vec::new();
        let residual = |p: &P, basis: &[P]| {
            let mut r = p - pts[i0];
            for _ in 0..2 {
                for b in basis {
                    r -= b * b.dot(&r);
                }
            }
            r
        };
        for _ in 0..D {
            let (best, r) = (0..npts)
                .map(|i| (i, residual(&pts[i], &basis)))
                .max_by(|a, b| a.1.norm().total_cmp(&b.1.norm()))
                .ok_or(HullError::Flat)?;
            let rn = r.norm();
            if rn <= tol {
                return Err(HullError::Flat);
            }
            basis.push(r / rn);
            chosen.push(best);
        }
        let interior = chosen.iter().map(|&i| pts[i]).sum::<P>() / (D + 1) as f64;
        let mut facets: Vec<Facet> = Vec::new();
        for k in 0..=D {
            let mut v = [0; D];
            let mut nb = [0; D];
            let mut j = 0;
            for (m, &c) in chosen.iter().enumerate() {
                if m != k {
                    v[j] = c;
                    nb[j] = m; // the facet omitting chosen[m] shares all but chosen[m]
                    j += 1;
                }
            }
            let (n, d) = plane(pts, &v, &interior)
                .ok_or(HullError::Numerical("degenerate simplex facet"))?;
            facets.push(Facet {
                v,
                n,
                d,
                nb,
                outside: Vec::new(),
                alive: true,
            });
        }
        for (i, p) in pts.iter().enumerate() {
            if chosen.contains(&i) {
                continue;
            }
            if let Some(f) = facets.iter_mut().find(|f| dist(f, p) > tol) {
                f.outside.push(i);
            }
        }

        let mut state: Vec<u8> = Vec::new();
        // Each round turns one outside point into a vertex: at most npts rounds.
        for _ in 0..=npts {
            let Some(fi) = facets.iter().position(|f| f.alive && !f.outside.is_empty()) else {
                return finish(facets, interior, pts, tol);
            };
            let pi = *facets[fi]
                .outside
                .iter()
                .max_by(|&&a, &&b| {
                    dist(&facets[fi], &pts[a]).total_cmp(&dist(&facets[fi], &pts[b]))
                })
                .ok_or(HullError::Numerical("empty outside set"))?;
            let p = pts[pi];
            // Visible facets: connected to fi, with p strictly outside.
            const UNSEEN: u8 = 0;
            const VISIBLE: u8 = 1;
            const HIDDEN: u8 = 2;
            state.clear();
            state.resize(facets.len(), UNSEEN);
            state[fi] = VISIBLE;
            let mut visible = vec![fi];
            let mut stack = vec![fi];
            while let Some(f) = stack.pop() {
                for g in facets[f].nb {
                    if state[g] == UNSEEN {
                        if dist(&facets[g], &p) > tol {
                            state[g] = VISIBLE;
                            visible.push(g);
                            stack.push(g);
                        } else {
                            state[g] = HIDDEN;
                        }
                    }
                }
            }
            // New facets on the horizon ridges.
            let mut new_ids = Vec::new();
            let mut ridges: Vec<([usize; D - 1], usize, usize)> = Vec::new();
            for &f in &visible {
                for j in 0..D {
                    let g = facets[f].nb[j];
                    if state[g] == VISIBLE {
                        continue;
                    }
                    let mut v = facets[f].v;
                    v[j] = pi;
                    let (n, d) = plane(pts, &v, &interior)
                        .ok_or(HullError::Numerical("degenerate new facet"))?;
                    if d - n.dot(&interior) <= 0.0 {
                        return Err(HullError::Numerical("interior point on a facet"));
                    }
                    let id = facets.len();
                    let slot = facets[g]
                        .nb
                        .iter()
                        .position(|&x| x == f)
                        .ok_or(HullError::Numerical("broken adjacency"))?;
                    facets[g].nb[slot] = id;
                    let mut nb = [usize::MAX; D];
                    nb[j] = g;
                    facets.push(Facet {
                        v,
                        n,
                        d,
                        nb,
                        outside: Vec::new(),
                        alive: true,
                    });
                    for k in 0..D {
                        if k == j {
                            continue;
                        }
                        ridges.push((ridge_key(&v, k), id, k));
                    }
                    new_ids.push(id);
                }
            }
            // The new facets pair up across the ridges through the new vertex: each such ridge
            // is shared by exactly two of them.
            ridges.sort_unstable();
            if new_ids.is_empty() || ridges.len() % 2 != 0 {
                return Err(HullError::Numerical("horizon is not closed"));
            }
            for pair in ridges.chunks_exact(2) {
                let ((ka, a, sa), (kb, b, sb)) = (pair[0], pair[1]);
                if ka != kb {
                    return Err(HullError::Numerical("horizon is not closed"));
                }
                facets[a].nb[sa] = b;
                facets[b].nb[sb] = a;
            }
            let mut orphans = Vec::new();
            for &f in &visible {
                orphans.append(&mut facets[f].outside);
                facets[f].alive = false;
            }
            for i in orphans {
                if i == pi {
                    continue;
                }
                if let Some(&id) = new_ids.iter().find(|&&id| dist(&facets[id], &pts[i]) > tol) {
                    facets[id].outside.push(i);
                }
            }
        }
        Err(HullError::Numerical("too many rounds"))
    }

    /// Keeps the live facets and checks the result.
    fn finish(facets: Vec<Facet>, interior: P, pts: &[P], tol: f64) -> Result<Hull, HullError> {
        let alive: Vec<usize> = (0..facets.len()).filter(|&i| facets[i].alive).collect();
        let mut index = vec![usize::MAX; facets.len()];
        for (new, &old) in alive.iter().enumerate() {
            index[old] = new;
        }
        let mut out = Vec::with_capacity(alive.len());
        for (i, f) in facets.into_iter().enumerate() {
            if index[i] == usize::MAX {
                continue;
            }
            let mut nb = f.nb;
            for x in nb.iter_mut() {
                if *x >= index.len() || index[*x] == usize::MAX {
                    return Err(HullError::Numerical("a live facet borders a removed one"));
                }
                *x = index[*x];
            }
            out.push(Facet { nb, ..f });
        }
        // Every point inside every facet (with a margin for the merged near-coplanar facets).
        for f in &out {
            for p in pts {
                if dist(f, p) > 1e3 * tol {
                    return Err(HullError::Numerical("a point is outside the hull"));
                }
            }
        }
        // Adjacency is symmetric.
        for (i, f) in out.iter().enumerate() {
            for &g in &f.nb {
                if !out[g].nb.contains(&i) {
                    return Err(HullError::Numerical("adjacency is not symmetric"));
                }
            }
        }
        Ok(Hull {
            facets: out,
            interior,
        })
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn the_hull_of_a_cross_polytope_has_its_facets_and_volume() {
            // ±e_i: 2^6 facets at distance 1/sqrt(6), volume 2^6 / 6!.
            let mut pts = Vec::new();
            for i in 0..D {
                for s in [1.0, -1.0] {
                    let mut p = P::zeros();
                    p[i] = s;
                    pts.push(p);
                }
            }
            pts.push(P::zeros());
            pts.push(P::from_element(0.1));
            let h = build(&pts, 1e-9).unwrap();
            assert_eq!(h.facets.len(), 64);
            for f in &h.facets {
                assert!((f.d - 1.0 / 6f64.sqrt()).abs() < 1e-12);
            }
            assert!((h.volume(&pts) - 64.0 / 720.0).abs() < 1e-12);
        }

        #[test]
        fn the_hull_of_a_hypercube_with_coplanar_points_has_its_volume() {
            let mut pts = Vec::new();
            for m in 0..64u32 {
                pts.push(P::from_fn(|i, _| if m >> i & 1 == 1 { 1.0 } else { -1.0 }));
            }
            // Points on faces and inside.
            pts.push(P::from_fn(|i, _| if i == 0 { 1.0 } else { 0.0 }));
            pts.push(P::from_fn(|i, _| if i == 0 { 1.0 } else { 0.3 }));
            pts.push(P::zeros());
            let h = build(&pts, 1e-9).unwrap();
            assert!((h.volume(&pts) - 64.0).abs() < 1e-9, "{}", h.volume(&pts));
            for f in &h.facets {
                assert!((f.d - 1.0).abs() < 1e-9);
            }
        }

        proptest::proptest! {
            #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
            #[test]
            fn the_hull_has_exactly_the_facets_a_brute_force_search_finds(
                raw in proptest::collection::vec(proptest::array::uniform6(-1.0..1.0f64), 7..11)
            ) {
                let pts: Vec<P> = raw.iter().map(|a| P::from_row_slice(a)).collect();
                let h = build(&pts, 1e-9).unwrap();
                let centroid = pts.iter().sum::<P>() / pts.len() as f64;
                // Every 6-subset whose hyperplane has all points on one side is a facet.
                let mut brute = Vec::new();
                let n = pts.len();
                let mut idx = [0usize, 1, 2, 3, 4, 5];
                loop {
                    if let Some((nn, d)) = plane(&pts, &idx, &centroid) {
                        if pts.iter().all(|p| nn.dot(p) - d <= 1e-9) {
                            brute.push(d);
                        }
                    }
                    // Next combination.
                    let mut i = D;
                    while i > 0 && idx[i - 1] == n - D + i - 1 {
                        i -= 1;
                    }
                    if i == 0 {
                        break;
                    }
                    idx[i - 1] += 1;
                    for j in i..D {
                        idx[j] = idx[j - 1] + 1;
                    }
                }
                let mut mine: Vec<f64> = h.facets.iter().map(|f| f.d).collect();
                mine.sort_by(f64::total_cmp);
                brute.sort_by(f64::total_cmp);
                proptest::prop_assert_eq!(mine.len(), brute.len());
                for (a, b) in mine.iter().zip(&brute) {
                    proptest::prop_assert!((a - b).abs() < 1e-9);
                }
            }
        }

        #[test]
        fn flat_point_sets_have_no_hull() {
            let pts: Vec<P> = (0..20)
                .map(|k| {
                    P::from_fn(|i, _| {
                        if i == 5 {
                            0.0
                        } else {
                            ((k * (i + 3)) % 7) as f64
                        }
                    })
                })
                .collect();
            assert!(matches!(build(&pts, 1e-9), Err(HullError::Flat)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Rotation, Vector};
    use proptest::prelude::*;

    use crate::grasp::tests::paper_contacts;

    fn on_sphere(dirs: &[[f64; 3]], r: f64) -> Vec<ContactFrame> {
        dirs.iter()
            .map(|d| {
                let d = Vector::from(*d).normalize();
                ContactFrame::from_normal(d * r, -d)
            })
            .collect()
    }

    fn fr(mu: Real) -> Friction {
        Friction {
            mu,
            mu_torsion: 0.005,
        }
    }

    fn q(c: &[ContactFrame], m: ContactModel, mu: Real, p: &QualityParams) -> GraspQuality {
        grasp_quality(c, m, &fr(mu), p).unwrap()
    }

    #[test]
    fn two_point_contacts_are_never_force_closure() {
        let pair = on_sphere(&[[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]], 0.05);
        let g = q(
            &pair,
            ContactModel::PointWithFriction,
            1.0,
            &QualityParams::default(),
        );
        assert!(!g.force_closure);
        assert_eq!(g.epsilon, 0.0);
        assert_eq!(g.volume, 0.0);
    }

    #[test]
    fn an_antipodal_soft_finger_pair_is_force_closure() {
        // Torsion resists the moment about the line through the contacts that two point
        // contacts cannot.
        let pair = on_sphere(&[[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]], 0.05);
        let g = q(
            &pair,
            ContactModel::SoftFinger,
            0.5,
            &QualityParams::default(),
        );
        assert!(g.force_closure);
        assert!(g.epsilon > 0.0 && g.volume > 0.0);
    }

    #[test]
    fn the_paper_sphere_grasp_has_consistent_quality() {
        let c = paper_contacts();
        let p = QualityParams::default();
        let high = q(&c, ContactModel::PointWithFriction, 1.5, &p);
        eprintln!("paper sphere μ = 1.5: {high:?}");
        assert!(high.force_closure && high.epsilon > 0.0 && high.volume > 0.0);
        assert!((high.torque_scale - c[0].p_b.norm().max(c[1].p_b.norm())).abs() < 1e-12);
        // With μ = 0.3 every contact force points upward (normals 52° from the vertical, cones
        // 17° wide): the grasp cannot pull the sphere down, so it is not force closure.
        let low = q(&c, ContactModel::PointWithFriction, 0.3, &p);
        eprintln!("paper sphere μ = 0.3: {low:?}");
        assert!(!low.force_closure);
        assert_eq!(low.epsilon, 0.0);
        assert!(low.volume > 0.0 && low.volume < high.volume);
        // Frictionless: four normals cannot span six dimensions.
        let none = q(&c, ContactModel::Frictionless, 1.5, &p);
        assert!(!none.force_closure && none.volume == 0.0);
        // More friction, larger space.
        let higher = q(&c, ContactModel::PointWithFriction, 2.0, &p);
        assert!(higher.epsilon > high.epsilon && higher.volume > high.volume);
    }

    #[test]
    fn epsilon_is_the_depth_of_the_origin_in_every_direction() {
        // ε ≤ h(u) = max_j u·w_j for every unit u, with equality somewhere near the minimum.
        let c = paper_contacts();
        let p = QualityParams::default();
        let g = q(&c, ContactModel::PointWithFriction, 1.5, &p);
        let prims = primitive_wrenches(
            &c,
            ContactModel::PointWithFriction,
            &fr(1.5),
            8,
            g.torque_scale,
        );
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..20000 {
            let u = Wrench::from_fn(|_, _| rnd()).normalize();
            let h = prims
                .iter()
                .map(|w| u.dot(w))
                .fold(Real::NEG_INFINITY, Real::max);
            assert!(h >= g.epsilon - 1e-9, "support {h} < ε {}", g.epsilon);
        }
    }

    #[test]
    fn scaling_the_object_leaves_the_default_metrics_unchanged_and_scales_a_fixed_torque_scale() {
        let c = paper_contacts();
        let s = 3.0;
        let big: Vec<_> = c
            .iter()
            .map(|f| ContactFrame {
                p_b: f.p_b * s,
                rot_b: f.rot_b,
            })
            .collect();
        let p = QualityParams::default();
        let a = q(&c, ContactModel::PointWithFriction, 1.5, &p);
        let b = q(&big, ContactModel::PointWithFriction, 1.5, &p);
        assert!(
            (a.epsilon - b.epsilon).abs() < 1e-9
                && (a.volume - b.volume).abs() < 1e-9 * a.volume.max(1.0)
        );
        assert!((b.torque_scale - s * a.torque_scale).abs() < 1e-12);
        // A fixed ρ: the three torque axes grow by s, so the volume grows by s³.
        let fixed = QualityParams {
            torque_scale: Some(0.1),
            ..p
        };
        let a = q(&c, ContactModel::PointWithFriction, 1.5, &fixed);
        let b = q(&big, ContactModel::PointWithFriction, 1.5, &fixed);
        assert!(
            (b.volume / a.volume - s.powi(3)).abs() < 1e-6 * s.powi(3),
            "{}",
            b.volume / a.volume
        );
        assert!(b.epsilon >= a.epsilon - 1e-12);
    }

    #[test]
    fn invalid_parameters_are_reported() {
        let c = paper_contacts();
        let m = ContactModel::PointWithFriction;
        assert!(grasp_quality(&c, m, &fr(-1.0), &QualityParams::default()).is_err());
        assert!(grasp_quality(
            &c,
            m,
            &fr(1.0),
            &QualityParams {
                edges: 2,
                torque_scale: None
            }
        )
        .is_err());
        assert!(grasp_quality(
            &c,
            m,
            &fr(1.0),
            &QualityParams {
                edges: 8,
                torque_scale: Some(0.0)
            }
        )
        .is_err());
        let g = grasp_quality(&[], m, &fr(1.0), &QualityParams::default()).unwrap();
        assert!(!g.force_closure && g.epsilon == 0.0 && g.volume == 0.0);
    }

    fn contacts_strategy() -> impl Strategy<Value = Vec<ContactFrame>> {
        prop::collection::vec(prop::array::uniform3(-1.0..1.0f64), 3..5).prop_map(|dirs| {
            let dirs: Vec<_> = dirs
                .into_iter()
                .filter(|d| Vector::from(*d).norm() > 0.2)
                .collect();
            on_sphere(&dirs, 0.05)
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]
        #[test]
        fn rotating_the_whole_grasp_leaves_epsilon_and_volume_unchanged(
            c in contacts_strategy(),
            axis in prop::array::uniform3(-1.0..1.0f64),
            angle in -3.0..3.0f64,
            mu in 0.2..1.5f64,
            model in 0usize..3,
        ) {
            let model = [ContactModel::Frictionless, ContactModel::PointWithFriction, ContactModel::SoftFinger][model];
            let axis = Vector::from(axis);
            prop_assume!(axis.norm() > 0.1);
            let r = Rotation::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
            let rc: Vec<_> = c.iter().map(|f| ContactFrame { p_b: r * f.p_b, rot_b: r.to_rotation_matrix() * f.rot_b }).collect();
            let p = QualityParams::default();
            let a = q(&c, model, mu, &p);
            let b = q(&rc, model, mu, &p);
            prop_assert_eq!(a.force_closure, b.force_closure);
            prop_assert!((a.epsilon - b.epsilon).abs() < 1e-7, "{} vs {}", a.epsilon, b.epsilon);
            prop_assert!((a.volume - b.volume).abs() < 1e-7 * (1.0 + a.volume), "{} vs {}", a.volume, b.volume);
            prop_assert_eq!(a.epsilon > 0.0, a.force_closure);
        }

        #[test]
        fn adding_a_contact_never_shrinks_the_grasp_wrench_space(
            c in contacts_strategy(),
            extra in prop::array::uniform3(-1.0..1.0f64),
            mu in 0.2..1.5f64,
        ) {
            prop_assume!(Vector::from(extra).norm() > 0.2);
            let mut more = c.clone();
            more.extend(on_sphere(&[extra], 0.05));
            // A fixed ρ: the default would change with the contacts.
            let p = QualityParams { torque_scale: Some(0.05), ..QualityParams::default() };
            let a = q(&c, ContactModel::PointWithFriction, mu, &p);
            let b = q(&more, ContactModel::PointWithFriction, mu, &p);
            prop_assert!(b.volume >= a.volume * (1.0 - 1e-9) - 1e-12, "{} < {}", b.volume, a.volume);
            prop_assert!(b.epsilon >= a.epsilon - 1e-9);
            prop_assert!(!a.force_closure || b.force_closure);
        }
    }
}
