//! The Quickhull that `grasp_quality` used before its hull was rewritten for speed, kept
//! (test builds only; its build since split into steps, the same operations in the same
//! order) as the reference that the new one is compared with.

use nalgebra::{SMatrix, SVector};

const D: usize = 6;
type P = SVector<f64, D>;

/// A facet: `n · x = d` with `n` the outward unit normal; `nb[k]` is the neighbour across
/// the ridge opposite vertex `v[k]`.
pub(crate) struct Facet {
    pub v: [usize; D],
    pub n: P,
    pub d: f64,
    nb: [usize; D],
    outside: Vec<usize>,
    alive: bool,
}

/// The hull: its live facets and a point strictly inside.
pub(crate) struct Hull {
    pub facets: Vec<Facet>,
    interior: P,
}

/// Why no hull was built.
#[derive(Debug)]
pub(crate) enum HullError {
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
pub(crate) fn build(pts: &[P], tol: f64) -> Result<Hull, HullError> {
    let npts = pts.len();
    if npts < D + 1 {
        return Err(HullError::Flat);
    }
    let chosen = initial_simplex(pts, tol)?;
    let interior = chosen.iter().map(|&i| pts[i]).sum::<P>() / (D + 1) as f64;
    let mut facets = simplex_facets(pts, &chosen, &interior, tol)?;
    let mut state: Vec<u8> = Vec::new();
    // Each round turns one outside point into a vertex: at most npts rounds.
    for _ in 0..=npts {
        let Some(fi) = facets.iter().position(|f| f.alive && !f.outside.is_empty()) else {
            return finish(facets, interior, pts, tol);
        };
        add_vertex(&mut facets, &mut state, pts, &interior, tol, fi)?;
    }
    Err(HullError::Numerical("too many rounds"))
}

/// The initial simplex's vertices: greedily the points farthest from the affine hull of those
/// chosen.
fn initial_simplex(pts: &[P], tol: f64) -> Result<Vec<usize>, HullError> {
    let npts = pts.len();
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
    Ok(chosen)
}

/// The facets of the simplex `chosen`, each of the other points in the outside set of the
/// first facet it is above.
fn simplex_facets(
    pts: &[P],
    chosen: &[usize],
    interior: &P,
    tol: f64,
) -> Result<Vec<Facet>, HullError> {
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
        let (n, d) =
            plane(pts, &v, interior).ok_or(HullError::Numerical("degenerate simplex facet"))?;
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
    Ok(facets)
}

/// A facet's state in a round's visibility search ([`visible_from`]): not met yet,
const UNSEEN: u8 = 0;
/// seen by the new point,
const VISIBLE: u8 = 1;
/// or not.
const HIDDEN: u8 = 2;

/// One round: the farthest point of facet `fi`'s outside set made a vertex, the facets it sees
/// replaced by new ones through it, their outside points given to the new ones.
fn add_vertex(
    facets: &mut Vec<Facet>,
    state: &mut Vec<u8>,
    pts: &[P],
    interior: &P,
    tol: f64,
    fi: usize,
) -> Result<(), HullError> {
    let pi = *facets[fi]
        .outside
        .iter()
        .max_by(|&&a, &&b| dist(&facets[fi], &pts[a]).total_cmp(&dist(&facets[fi], &pts[b])))
        .ok_or(HullError::Numerical("empty outside set"))?;
    let visible = visible_from(facets, state, fi, &pts[pi], tol);
    let (new_ids, ridges) = new_facets(facets, state, &visible, pts, pi, interior)?;
    pair_up(facets, ridges, &new_ids)?;
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
    Ok(())
}

/// Visible facets: connected to `fi`, with `p` strictly outside; `state` marks each facet
/// met as visible or hidden.
fn visible_from(facets: &[Facet], state: &mut Vec<u8>, fi: usize, p: &P, tol: f64) -> Vec<usize> {
    state.clear();
    state.resize(facets.len(), UNSEEN);
    state[fi] = VISIBLE;
    let mut visible = vec![fi];
    let mut stack = vec![fi];
    while let Some(f) = stack.pop() {
        for g in facets[f].nb {
            if state[g] == UNSEEN {
                if dist(&facets[g], p) > tol {
                    state[g] = VISIBLE;
                    visible.push(g);
                    stack.push(g);
                } else {
                    state[g] = HIDDEN;
                }
            }
        }
    }
    visible
}

/// The ridges of the new facets through the new vertex, as (sorted vertices, facet, index of
/// the vertex opposite).
type NewRidges = Vec<([usize; D - 1], usize, usize)>;

/// New facets on the horizon ridges of the `visible` facets, through point `pi`; their ids
/// and their ridges through `pi`.
fn new_facets(
    facets: &mut Vec<Facet>,
    state: &[u8],
    visible: &[usize],
    pts: &[P],
    pi: usize,
    interior: &P,
) -> Result<(Vec<usize>, NewRidges), HullError> {
    let mut new_ids = Vec::new();
    let mut ridges: NewRidges = Vec::new();
    for &f in visible {
        for j in 0..D {
            let g = facets[f].nb[j];
            if state[g] == VISIBLE {
                continue;
            }
            let mut v = facets[f].v;
            v[j] = pi;
            let (n, d) =
                plane(pts, &v, interior).ok_or(HullError::Numerical("degenerate new facet"))?;
            if d - n.dot(interior) <= 0.0 {
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
    Ok((new_ids, ridges))
}

/// The new facets pair up across the ridges through the new vertex: each such ridge is shared
/// by exactly two of them.
fn pair_up(
    facets: &mut [Facet],
    mut ridges: NewRidges,
    new_ids: &[usize],
) -> Result<(), HullError> {
    ridges.sort_unstable();
    if new_ids.is_empty() || !ridges.len().is_multiple_of(2) {
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
    Ok(())
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

/// `grasp_quality` as it was computed with this hull.
pub(crate) fn grasp_quality(
    contacts: &[super::ContactFrame],
    model: super::ContactModel,
    friction: &super::Friction,
    params: &super::QualityParams,
) -> crate::error::Result<super::GraspQuality> {
    use super::*;
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
    let h = match build(&prims, tol) {
        Ok(h) => h,
        Err(HullError::Flat) => return Ok(not_closure),
        Err(HullError::Numerical(why)) => {
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
