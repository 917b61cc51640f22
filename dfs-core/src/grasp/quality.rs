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
        if !(c.p_b.iter().all(|v| v.is_finite()) && c.rot_b.coords.iter().all(|v| v.is_finite())) {
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
    let volume = h.volume();
    let min_offset = h.facets.iter().map(|f| f.d).fold(Real::INFINITY, Real::min);
    let force_closure = min_offset > tol;
    Ok(GraspQuality {
        epsilon: if force_closure { min_offset } else { 0.0 },
        volume,
        force_closure,
        torque_scale: rho,
    })
}

#[cfg(test)]
mod reference;

/// A Quickhull in six dimensions with simplicial facets.
mod hull {
    use nalgebra::SVector;

    const D: usize = 6;
    type P = SVector<f64, D>;
    /// No facet, no point.
    const NONE: usize = usize::MAX;

    /// A facet: `n · x = d` with `n` the outward unit normal; `nb[k]` is the neighbour across
    /// the ridge opposite vertex `v[k]`.
    pub(super) struct Facet {
        pub v: [usize; D],
        pub n: P,
        pub d: f64,
        /// 5! times the facet's 5-dimensional volume.
        measure: f64,
        nb: [usize; D],
        /// The first point of the outside set, a list threaded through `Build::next`, or NONE.
        outside: usize,
        /// The outside point farthest above the facet, and its distance.
        far: usize,
        far_dist: f64,
        /// The last round whose visibility search looked at the facet.
        seen: usize,
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
        /// Volume: the simplices spanned by each facet and the interior point, each the facet's
        /// 5-volume times its height above the interior point over 6.
        pub fn volume(&self) -> f64 {
            let mut vol = 0.0;
            for f in &self.facets {
                vol += f.measure * (f.d - f.n.dot(&self.interior));
            }
            vol / 720.0
        }
    }

    /// A facet's hyperplane `n · x = d` and 5! times its 5-volume.
    pub(super) struct Plane {
        pub n: P,
        pub d: f64,
        measure: f64,
    }

    /// The hyperplane through the facet's vertices, oriented away from `inside`. The normal is
    /// the null vector of the 5×6 matrix of the edges `p_i − p_0`: Gaussian elimination with
    /// complete pivoting, then back-substitution with 1 in the column left without a pivot.
    /// The generalised cross product of the edges (whose norm is 5! times the facet's volume)
    /// is that null vector times the product of the pivots, up to sign.
    pub(super) fn plane(pts: &[P], v: &[usize; D], inside: &P) -> Option<Plane> {
        let o = pts[v[0]];
        let mut a = [[0.0_f64; D]; D - 1];
        for (i, row) in a.iter_mut().enumerate() {
            let p = &pts[v[i + 1]];
            for c in 0..D {
                row[c] = p[c] - o[c];
            }
        }
        let mut col = [0, 1, 2, 3, 4, 5];
        let mut scale = 0.0;
        let mut measure = 1.0;
        for k in 0..D - 1 {
            let (mut pr, mut pc, mut best) = (k, k, -1.0_f64);
            for (i, row) in a.iter().enumerate().skip(k) {
                for c in k..D {
                    let x = row[c].abs();
                    if x > best {
                        (pr, pc, best) = (i, c, x);
                    }
                }
            }
            if k == 0 {
                scale = best;
            }
            // An edge (numerically) in the span of the others: no hyperplane.
            if !(best > 1e-12 * scale && best.is_finite()) {
                return None;
            }
            a.swap(k, pr);
            if pc != k {
                for row in a.iter_mut() {
                    row.swap(k, pc);
                }
                col.swap(k, pc);
            }
            measure *= best;
            let (top, rest) = a.split_at_mut(k + 1);
            let pivot_row = &top[k];
            for row in rest {
                let l = row[k] / pivot_row[k];
                for c in k + 1..D {
                    row[c] -= l * pivot_row[c];
                }
            }
        }
        let mut y = [0.0; D];
        y[D - 1] = 1.0;
        for k in (0..D - 1).rev() {
            let mut s = 0.0;
            for c in k + 1..D {
                s += a[k][c] * y[c];
            }
            y[k] = -s / a[k][k];
        }
        let mut n = P::zeros();
        for k in 0..D {
            n[col[k]] = y[k];
        }
        let norm = n.norm();
        if !norm.is_finite() {
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
        Some(Plane {
            n,
            d,
            measure: measure * norm,
        })
    }

    fn dist(f: &Facet, p: &P) -> f64 {
        f.n.dot(p) - f.d
    }

    impl Facet {
        fn new(v: [usize; D], plane: Plane, nb: [usize; D]) -> Facet {
            Facet {
                v,
                n: plane.n,
                d: plane.d,
                measure: plane.measure,
                nb,
                outside: NONE,
                far: NONE,
                far_dist: 0.0,
                seen: 0,
                alive: true,
            }
        }
    }

    /// Where `x` is in `a`.
    fn position(a: &[usize; D], x: usize) -> Result<usize, HullError> {
        a.iter()
            .position(|&y| y == x)
            .ok_or(HullError::Numerical("broken adjacency"))
    }

    /// The state of a build.
    struct Build<'a> {
        pts: &'a [P],
        tol: f64,
        interior: P,
        facets: Vec<Facet>,
        /// The next point in the same outside set, or NONE.
        next: Vec<usize>,
        /// Facets that were given outside points (some may have died since).
        work: Vec<usize>,
    }

    impl Build<'_> {
        /// Puts point `i`, `dist` above facet `f`, into `f`'s outside set.
        fn add_outside(&mut self, f: usize, i: usize, dist: f64) {
            let fa = &mut self.facets[f];
            if fa.outside == NONE {
                self.work.push(f);
                fa.far = i;
                fa.far_dist = dist;
            } else if dist > fa.far_dist {
                fa.far = i;
                fa.far_dist = dist;
            }
            self.next[i] = fa.outside;
            fa.outside = i;
        }
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
        let mut b = Build {
            pts,
            tol,
            interior,
            facets: Vec::with_capacity(64 * npts),
            next: vec![NONE; npts],
            work: Vec::new(),
        };
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
            let pl = plane(pts, &v, &interior)
                .ok_or(HullError::Numerical("degenerate simplex facet"))?;
            b.facets.push(Facet::new(v, pl, nb));
        }
        for (i, p) in pts.iter().enumerate() {
            if chosen.contains(&i) {
                continue;
            }
            if let Some((f, d)) = (0..=D)
                .map(|f| (f, dist(&b.facets[f], p)))
                .find(|&(_, d)| d > tol)
            {
                b.add_outside(f, i, d);
            }
        }

        let mut visible: Vec<usize> = Vec::new();
        // The visible facet and the index of the horizon ridge each new facet was built on.
        let mut origin: Vec<(usize, usize)> = Vec::new();
        // Each round turns one outside point into a vertex: at most npts rounds.
        for round in 1..=npts + 1 {
            let fi = loop {
                match b.work.pop() {
                    None => return finish(b),
                    Some(f) if b.facets[f].alive && b.facets[f].outside != NONE => break f,
                    Some(_) => {}
                }
            };
            let pi = b.facets[fi].far;
            let p = pts[pi];
            // Visible facets: connected to fi, with p strictly outside.
            let facets = &mut b.facets;
            visible.clear();
            visible.push(fi);
            facets[fi].alive = false;
            facets[fi].seen = round;
            let mut s = 0;
            while s < visible.len() {
                let f = visible[s];
                s += 1;
                for j in 0..D {
                    let g = facets[f].nb[j];
                    let fg = &mut facets[g];
                    if fg.seen != round {
                        fg.seen = round;
                        if dist(fg, &p) > tol {
                            fg.alive = false;
                            visible.push(g);
                        }
                    }
                }
            }
            // New facets on the horizon ridges; the visible facet's side of the ridge is
            // pointed at the new facet too.
            let first = facets.len();
            origin.clear();
            for &f in &visible {
                for j in 0..D {
                    let g = facets[f].nb[j];
                    if !facets[g].alive {
                        continue;
                    }
                    let mut v = facets[f].v;
                    v[j] = pi;
                    let pl = plane(pts, &v, &interior)
                        .ok_or(HullError::Numerical("degenerate new facet"))?;
                    if pl.d - pl.n.dot(&interior) <= 0.0 {
                        return Err(HullError::Numerical("interior point on a facet"));
                    }
                    let id = facets.len();
                    let slot = position(&facets[g].nb, f)?;
                    facets[g].nb[slot] = id;
                    facets[f].nb[j] = id;
                    let mut nb = [NONE; D];
                    nb[j] = g;
                    facets.push(Facet::new(v, pl, nb));
                    origin.push((f, j));
                }
            }
            if facets.len() == first {
                return Err(HullError::Numerical("horizon is not closed"));
            }
            // The new facets pair up across the ridges through p. The new facet N on ridge
            // (f, j) shares with its neighbour opposite v[k] the 4 vertices S = f.v less v[j]
            // and v[k]: turning about S through the visible facets from f, across the ridge
            // opposite v[k], leads to the next horizon ridge about S, whose new facet is it.
            for id in first..facets.len() {
                let (f, j) = origin[id - first];
                for k in 0..D {
                    if k == j || facets[id].nb[k] != NONE {
                        continue;
                    }
                    // h holds S and {a, c}; cross the ridge opposite a.
                    let (mut h, mut a, mut c) = (f, facets[f].v[k], facets[f].v[j]);
                    let mut steps = 0;
                    let (m, slot) = loop {
                        steps += 1;
                        if steps > visible.len() {
                            return Err(HullError::Numerical("horizon is not closed"));
                        }
                        let across = facets[h].nb[position(&facets[h].v, a)?];
                        if across >= first {
                            break (across, position(&facets[across].v, c)?);
                        }
                        if facets[across].alive || facets[across].seen != round {
                            return Err(HullError::Numerical("horizon is not closed"));
                        }
                        let x = facets[across].v[position(&facets[across].nb, h)?];
                        (h, a, c) = (across, c, x);
                    };
                    if m == id || (facets[m].nb[slot] != NONE && facets[m].nb[slot] != id) {
                        return Err(HullError::Numerical("horizon is not closed"));
                    }
                    facets[id].nb[k] = m;
                    facets[m].nb[slot] = id;
                }
            }
            // The visible facets' outside points go to the first new facet they are above
            // (those on their own horizon ridges first), or are inside.
            for &f in &visible {
                let mut q = b.facets[f].outside;
                b.facets[f].outside = NONE;
                while q != NONE {
                    let after = b.next[q];
                    if q != pi {
                        let pq = &pts[q];
                        let fa = &b.facets;
                        let above = |g: usize| {
                            let d = dist(&fa[g], pq);
                            (d > tol).then_some((g, d))
                        };
                        let to = fa[f]
                            .nb
                            .iter()
                            .filter(|&&g| g >= first)
                            .find_map(|&g| above(g))
                            .or_else(|| (first..fa.len()).find_map(above));
                        if let Some((g, d)) = to {
                            b.add_outside(g, q, d);
                        }
                    }
                    q = after;
                }
            }
        }
        Err(HullError::Numerical("too many rounds"))
    }

    /// Keeps the live facets and checks the result.
    fn finish(b: Build) -> Result<Hull, HullError> {
        let Build {
            pts,
            tol,
            interior,
            facets,
            ..
        } = b;
        let mut index = vec![NONE; facets.len()];
        let mut count = 0;
        for (i, f) in facets.iter().enumerate() {
            if f.alive {
                index[i] = count;
                count += 1;
            }
        }
        let mut out = Vec::with_capacity(count);
        for f in facets {
            if !f.alive {
                continue;
            }
            let mut nb = f.nb;
            for x in nb.iter_mut() {
                if *x >= index.len() || index[*x] == NONE {
                    return Err(HullError::Numerical("a live facet borders a removed one"));
                }
                *x = index[*x];
            }
            out.push(Facet { nb, ..f });
        }
        // Adjacency is symmetric: each ridge is shared by two facets.
        for (i, f) in out.iter().enumerate() {
            for &g in &f.nb {
                if !out[g].nb.contains(&i) {
                    return Err(HullError::Numerical("adjacency is not symmetric"));
                }
            }
        }
        check_points(&out, pts, tol)?;
        Ok(Hull {
            facets: out,
            interior,
        })
    }

    /// Checks every point inside every facet, with a margin of `1e3 tol` for the merged
    /// near-coplanar facets. Neighbouring facets whose hyperplanes agree within `tol` on the
    /// points' ball (`|n − n'| r + |d − d'| ≤ tol`, `r` the largest point norm) are grouped,
    /// and each group is checked once against its representative's hyperplane with the margin
    /// less the group's largest such deviation: the same guarantee, a fraction of the work.
    fn check_points(facets: &[Facet], pts: &[P], tol: f64) -> Result<(), HullError> {
        let r = pts.iter().fold(0.0_f64, |m, p| m.max(p.norm()));
        let dev = |a: &Facet, b: &Facet| (a.n - b.n).norm() * r + (a.d - b.d).abs();
        let mut parent: Vec<usize> = (0..facets.len()).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        for (i, f) in facets.iter().enumerate() {
            for &g in &f.nb {
                if g > i && dev(f, &facets[g]) <= tol {
                    let (ri, rg) = (root(&mut parent, i), root(&mut parent, g));
                    parent[rg] = ri;
                }
            }
        }
        // The margin each facet is checked with: NaN for a facet covered by its group's.
        let mut margin = vec![f64::NAN; facets.len()];
        for i in 0..facets.len() {
            let ri = root(&mut parent, i);
            let e = dev(&facets[i], &facets[ri]);
            if e <= tol {
                let m = 1e3 * tol - e;
                if margin[ri].is_nan() || margin[ri] > m {
                    margin[ri] = m;
                }
            } else {
                margin[i] = 1e3 * tol;
            }
        }
        for (f, &m) in facets.iter().zip(&margin) {
            if m.is_nan() {
                continue;
            }
            for p in pts {
                let d = dist(f, p);
                if d > m || d.is_nan() {
                    return Err(HullError::Numerical("a point is outside the hull"));
                }
            }
        }
        Ok(())
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
            assert!((h.volume() - 64.0 / 720.0).abs() < 1e-12);
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
            assert!((h.volume() - 64.0).abs() < 1e-9, "{}", h.volume());
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
                    if let Some(Plane { n: nn, d, .. }) = plane(&pts, &idx, &centroid) {
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
            let rc: Vec<_> = c.iter().map(|f| ContactFrame { p_b: r * f.p_b, rot_b: r * f.rot_b }).collect();
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

    /// What `grasp_quality` gave for the paper's sphere before its hull was rewritten (printed
    /// with `{:.17e}`); the 64 soft-finger primitives are the replay planner's typical input.
    #[test]
    fn the_paper_sphere_grasp_keeps_the_quality_the_previous_hull_gave() {
        let c = crate::fixtures::paper_sphere_contacts();
        let soft = ContactModel::SoftFinger;
        let point = ContactModel::PointWithFriction;
        #[allow(clippy::excessive_precision)]
        let cases = [
            (
                soft,
                1.5,
                2.08710838445038016e-1,
                7.52653361620829209e0,
                true,
            ),
            (
                soft,
                0.8,
                1.48370329956183100e-2,
                3.92025186505562173e-1,
                true,
            ),
            (
                point,
                1.5,
                1.88250423052098687e-1,
                6.31318952205986417e0,
                true,
            ),
            (point, 0.3, 0.0, 4.92580246979437437e-3, false),
        ];
        for (m, mu, eps, vol, fc) in cases {
            let g = q(&c, m, mu, &QualityParams::default());
            eprintln!(
                "{m:?} μ = {mu}: ε {:.17e} volume {:.17e}",
                g.epsilon, g.volume
            );
            assert_eq!(g.force_closure, fc, "{m:?} μ = {mu}");
            assert!(
                (g.epsilon - eps).abs() <= 1e-12 * eps,
                "{m:?} μ = {mu}: ε {}",
                g.epsilon
            );
            assert!(
                (g.volume - vol).abs() <= 1e-12 * vol,
                "{m:?} μ = {mu}: volume {}",
                g.volume
            );
        }
    }

    /// Contacts for the comparison with the previous hull: anywhere, in a plane, doubled, or
    /// in antipodal pairs on a sphere (flat and degenerate wrench sets among them).
    fn any_contacts() -> impl Strategy<Value = Vec<ContactFrame>> {
        let one = (
            prop::array::uniform3(-0.1..0.1f64),
            prop::array::uniform3(-1.0..1.0f64),
        );
        (prop::collection::vec(one, 0..6), 0usize..4).prop_map(|(raw, shape)| {
            let mut out = Vec::new();
            for (p, n) in raw {
                let (mut p, mut n) = (Vector::from(p), Vector::from(n));
                if shape == 1 {
                    p.z = 0.0;
                    n.z = 0.0;
                }
                if n.norm() < 0.1 {
                    continue;
                }
                match shape {
                    2 => out.extend([ContactFrame::from_normal(p, n); 2]),
                    3 => out.extend(on_sphere(&[n.into(), (-n).into()], 0.05)),
                    _ => out.push(ContactFrame::from_normal(p, n)),
                }
            }
            out
        })
    }

    fn same_as_before(
        new: &Result<GraspQuality>,
        old: &Result<GraspQuality>,
    ) -> std::result::Result<(), TestCaseError> {
        match (new, old) {
            (Ok(a), Ok(b)) => {
                prop_assert_eq!(a.force_closure, b.force_closure, "{:?} vs {:?}", a, b);
                prop_assert_eq!(a.torque_scale, b.torque_scale);
                prop_assert!(
                    (a.epsilon - b.epsilon).abs() <= 1e-12 * b.epsilon.max(1e-3),
                    "ε {:e} vs {:e}",
                    a.epsilon,
                    b.epsilon
                );
                prop_assert!(
                    (a.volume - b.volume).abs() <= 1e-11 * b.volume,
                    "volume {:e} vs {:e}",
                    a.volume,
                    b.volume
                );
            }
            (Err(_), Err(_)) => {}
            _ => prop_assert!(false, "{:?} vs {:?}", new, old),
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(96))]
        #[test]
        fn the_quality_is_what_the_previous_hull_gave(
            c in any_contacts(),
            model in 0usize..3,
            mu in prop_oneof![Just(0.0), 0.0..2.0f64],
            mu_torsion in prop_oneof![Just(0.0), 0.0..0.02f64],
            edges in 3usize..10,
        ) {
            let model = [ContactModel::Frictionless, ContactModel::PointWithFriction, ContactModel::SoftFinger][model];
            let friction = Friction { mu, mu_torsion };
            let p = QualityParams { edges, ..QualityParams::default() };
            let new = grasp_quality(&c, model, &friction, &p);
            let old = reference::grasp_quality(&c, model, &friction, &p);
            same_as_before(&new, &old)?;
        }
    }
}
