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
//! - soft finger: points of the elliptic soft-finger cone of
//!   [`apply_friction`](crate::contact::apply_friction), `‖c_t‖²/μ² + c_τ²/μ_t² ≤ c_z²`, at unit
//!   normal force, sampled as GraspIt!'s soft contact samples its friction ellipsoid
//!   (`SoftContact::setUpFrictionEdges`): latitudes 0, ±45° and ±90° with `edges`,
//!   [`soft_latitude_edges`]`(edges)` (5 for 8) and 1 directions, the force
//!   `n + μ cos λ (cos φ t_x + sin φ t_y)` with the torsion `μ_t sin λ` about the normal.
//!   The latitudes are taken in the normalised coordinates `(c_t/μ, c_τ/μ_t)`, where the cone is
//!   round, so that the primitives do not depend on the unit of length. With `μ_t = 0` the
//!   primitives are the point contact's, with `μ = 0` the two pure torsions `± μ_t`.
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
//! dimensions (tolerance `1e-9` times the largest primitive; the next point is always the one
//! farthest above any facet). A new facet's hyperplane is turned about its horizon ridge from
//! the two hyperplanes through that ridge, and kept only if all six vertices lie within
//! `16 ε` times the largest primitive of it (the backward error of a direct computation);
//! otherwise, and for the first simplex, it comes from the Householder QR factorisation of the
//! facet's edges. Every result is checked before it is used: each ridge of a facet is shared
//! with exactly one other facet, and every primitive is inside every facet (within `1e3` times
//! the tolerance, for the merged near-coplanar facets). The volume is the sum over facets of
//! the simplices they span with an interior point, each facet's 5-volume from the Householder
//! QR factorisation of its edges. For the replay planner's typical input, four soft fingers (80
//! primitives of the elliptic cone), `grasp_quality` runs 6.6 M instructions (valgrind), 0.42 of
//! what the 64 corners of the box cone they replaced took (15.6 M instructions, ~2.6 ms on the
//! project's machine then; `cargo bench -p dfs-core --bench grasp_quality`).
//! Allocates (a thread keeps its last hull's arrays for the next); meant for planning and
//! analysis, not the 1 kHz tick.

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
            ContactModel::SoftFinger if friction.mu_torsion > 0.0 => {
                let (mu, mu_t) = (friction.mu, friction.mu_torsion);
                let latitudes: &[(Real, usize)] = if mu > 0.0 {
                    let fourth = std::f64::consts::FRAC_PI_4;
                    let side = soft_latitude_edges(edges);
                    &[
                        (2.0 * fourth, 1),
                        (fourth, side),
                        (0.0, edges),
                        (-fourth, side),
                        (-2.0 * fourth, 1),
                    ]
                } else {
                    &[
                        (std::f64::consts::FRAC_PI_2, 1),
                        (-std::f64::consts::FRAC_PI_2, 1),
                    ]
                };
                for &(lat, dirs) in latitudes {
                    let (sl, cl) = lat.sin_cos();
                    for k in 0..dirs {
                        let phi = 2.0 * std::f64::consts::PI * k as Real / dirs as Real;
                        let (s, co) = phi.sin_cos();
                        let (tx, ty) = (mu * cl * co, mu * cl * s);
                        out.push(scale(c.wrench_b(&Intensity::new(tx, ty, 1.0, mu_t * sl))));
                    }
                }
            }
            ContactModel::PointWithFriction | ContactModel::SoftFinger => {
                for k in 0..edges {
                    let phi = 2.0 * std::f64::consts::PI * k as Real / edges as Real;
                    let (s, co) = phi.sin_cos();
                    let (tx, ty) = (friction.mu * co, friction.mu * s);
                    out.push(scale(c.wrench_b(&Intensity::new(tx, ty, 1.0, 0.0))));
                }
            }
        }
    }
    out
}

/// Directions of the soft-finger cone's ±45° latitudes for `edges` on its equator: GraspIt!'s
/// 5 for 8, in proportion (at least 3).
pub fn soft_latitude_edges(edges: usize) -> usize {
    (5 * edges).div_ceil(8).max(3)
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
    let volume = h.volume();
    let min_offset = h.facets().map(|f| f.d).fold(Real::INFINITY, Real::min);
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
    use std::collections::BinaryHeap;

    const D: usize = 6;
    type P = SVector<f64, D>;
    /// No facet, no point.
    const NONE: u32 = u32::MAX;
    /// In `Topo::back` of a facet that the current round removes: the neighbour across this
    /// ridge is the round's new facet on it.
    const NEW: u8 = u8::MAX;

    /// A facet's place in the hull, in one cache line: `nb[k]` is the neighbour across the
    /// ridge opposite vertex `v[k]`, and this facet is its neighbour `back[k]`.
    #[derive(Clone, Copy)]
    #[repr(align(64))]
    struct Topo {
        nb: [u32; D],
        v: [u32; D],
        back: [u8; D],
        alive: bool,
        /// The last round whose visibility search looked at the facet.
        seen: u32,
    }

    /// A facet's hyperplane `n · x = d` (`n` the outward unit normal) and, once the hull is
    /// built, 5! times the facet's 5-dimensional volume; one cache line.
    #[derive(Clone, Copy)]
    #[repr(align(64))]
    pub(super) struct Plane {
        pub n: P,
        pub d: f64,
        measure: f64,
    }

    /// A facet's outside set: the first point of a list threaded through `Build::next` (or
    /// NONE), and the farthest point with its distance above the facet.
    #[derive(Clone, Copy)]
    struct Outside {
        first: u32,
        far: u32,
        far_dist: f64,
    }

    const NO_OUTSIDE: Outside = Outside {
        first: NONE,
        far: NONE,
        far_dist: 0.0,
    };

    /// The hull: its facets (live and removed), and a point strictly inside. When dropped, it
    /// leaves its buffers to the next build on the same thread.
    pub(super) struct Hull {
        buffers: Buffers,
        interior: P,
    }

    /// The arrays of a build. A thread keeps those of its last hull, so that the next build
    /// reuses them instead of allocating (and faulting in) a few hundred fresh kB.
    #[derive(Default)]
    struct Buffers {
        topo: Vec<Topo>,
        planes: Vec<Plane>,
        outside: Vec<Outside>,
        above: Vec<f64>,
        next: Vec<u32>,
        work: BinaryHeap<(u64, u32)>,
        free: Vec<u32>,
    }

    /// Buffers larger than this many facets are not kept.
    const KEEP: usize = 1 << 15;

    thread_local! {
        static SPARE: std::cell::Cell<Option<Buffers>> = const { std::cell::Cell::new(None) };
    }

    impl Drop for Hull {
        fn drop(&mut self) {
            if self.buffers.topo.capacity() <= KEEP {
                let buffers = std::mem::take(&mut self.buffers);
                // Not during the thread's teardown, when the slot may be gone.
                let _ = SPARE.try_with(|s| s.set(Some(buffers)));
            }
        }
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
        /// The facets' hyperplanes.
        pub fn facets(&self) -> impl Iterator<Item = &Plane> {
            self.buffers
                .topo
                .iter()
                .zip(&self.buffers.planes)
                .filter(|(t, _)| t.alive)
                .map(|(_, p)| p)
        }

        /// Volume: the simplices spanned by each facet and the interior point, each the facet's
        /// 5-volume times its height above the interior point over 6.
        pub fn volume(&self) -> f64 {
            let mut vol = 0.0;
            for f in self.facets() {
                vol += f.measure * (f.d - f.n.dot(&self.interior));
            }
            vol / 720.0
        }
    }

    /// Step `K` of the QR factorisation in [`plane`]: the Householder reflection that maps
    /// edge `K`'s components `K..D` onto coordinate `K`, stored in place of them and applied to
    /// the edges after it. Returns `|r_KK|`, the distance of edge `K` from the span of the
    /// edges before it, and the reflection's factor `2 / |v|²`.
    #[inline(always)]
    fn reflect<const K: usize>(a: &mut [[f64; D]; D - 1]) -> (f64, f64) {
        let (top, rest) = a.split_at_mut(K + 1);
        let x = &mut top[K];
        let mut sq = 0.0;
        for i in K..D {
            sq += x[i] * x[i];
        }
        let r = sq.sqrt();
        // v = x − α e_K with α = −sign(x_K) r, so that |v|² = 2 r (r + |x_K|) loses nothing.
        let tau = 1.0 / (r * (r + x[K].abs()));
        x[K] += if x[K] > 0.0 { r } else { -r };
        for y in rest.iter_mut() {
            let mut s = 0.0;
            for i in K..D {
                s += x[i] * y[i];
            }
            let s = s * tau;
            for i in K..D {
                y[i] -= s * x[i];
            }
        }
        (r, tau)
    }

    /// Applies reflection `K` of [`reflect`] to `z`.
    #[inline(always)]
    fn apply<const K: usize>(a: &[[f64; D]; D - 1], tau: f64, z: &mut [f64; D]) {
        let v = &a[K];
        let mut s = 0.0;
        for i in K..D {
            s += v[i] * z[i];
        }
        let s = s * tau;
        for i in K..D {
            z[i] -= s * v[i];
        }
    }

    /// The hyperplane through the facet's vertices, oriented away from `inside`. The normal is
    /// the last column of Q in the Householder QR factorisation `[e_1 … e_5] = Q R` of the
    /// edges `e_i = p_i − p_0` (backward stable without pivoting, and the same test for
    /// degenerate facets as Gram-Schmidt: `|r_ii|` is edge i's distance from the span of the
    /// edges before it, which must exceed `1e-12 |e_i|`). `None` for a degenerate facet.
    pub(super) fn plane(pts: &[P], v: &[u32; D], inside: &P) -> Option<Plane> {
        let o: [f64; D] = pts[v[0] as usize].into();
        let mut sum = o;
        let mut a = [[0.0; D]; D - 1];
        let mut scale = [0.0; D - 1];
        for i in 0..D - 1 {
            let p: [f64; D] = pts[v[i + 1] as usize].into();
            for c in 0..D {
                a[i][c] = p[c] - o[c];
                sum[c] += p[c];
                scale[i] += a[i][c] * a[i][c];
            }
        }
        let r = [
            reflect::<0>(&mut a),
            reflect::<1>(&mut a),
            reflect::<2>(&mut a),
            reflect::<3>(&mut a),
            reflect::<4>(&mut a),
        ];
        for i in 0..D - 1 {
            // |r_ii| ≤ 1e-12 |e_i| (or NaN): the edge is (numerically) in the span of the edges
            // before it, no hyperplane.
            let independent = r[i].0 * r[i].0 > 1e-24 * scale[i];
            if !independent {
                return None;
            }
        }
        let mut z = [0.0; D];
        z[D - 1] = 1.0;
        apply::<4>(&a, r[4].1, &mut z);
        apply::<3>(&a, r[3].1, &mut z);
        apply::<2>(&a, r[2].1, &mut z);
        apply::<1>(&a, r[1].1, &mut z);
        apply::<0>(&a, r[0].1, &mut z);
        // Q is orthogonal: z is a unit vector up to rounding.
        let mut sq = 0.0;
        for c in 0..D {
            sq += z[c] * z[c];
        }
        let norm = sq.sqrt();
        if !(norm > 0.5 && norm.is_finite()) {
            return None;
        }
        let mut n = P::from(z) / norm;
        // Offset from the mean of the vertices (less rounding than one vertex).
        let mut d = n.dot(&P::from(sum)) / D as f64;
        if n.dot(inside) > d {
            n = -n;
            d = -d;
        }
        Some(Plane {
            n,
            d,
            measure: f64::NAN,
        })
    }

    /// The hyperplane through a horizon ridge and the new point, turned about the ridge from
    /// the hyperplanes of its visible and hidden facets: `a n_g − b n_f` with `a`, `b` the
    /// new point's heights above them. Accepted only if every vertex is within `exact` of
    /// it (the backward error of a direct computation), else `None`.
    fn turn(
        pts: &[P],
        v: &[u32; D],
        (pf, a): (&Plane, f64),
        (pg, b): (&Plane, f64),
        inside: &P,
        exact: f64,
    ) -> Option<Plane> {
        let m = pg.n * a - pf.n * b;
        // Heights along m (not yet normalised, so that the square root is off the path).
        let mut at = [0.0; D];
        let mut mean = 0.0;
        for i in 0..D {
            at[i] = m.dot(&pts[v[i] as usize]);
            mean += at[i];
        }
        mean /= D as f64;
        let mut worst = 0.0;
        for x in at {
            let e = (x - mean).abs();
            if e > worst {
                worst = e;
            }
        }
        let norm = m.norm();
        let ok = worst <= exact * norm && norm > 0.0 && norm.is_finite();
        if !ok {
            return None;
        }
        let mut n = m / norm;
        let mut d = mean / norm;
        if n.dot(inside) > d {
            n = -n;
            d = -d;
        }
        Some(Plane {
            n,
            d,
            measure: f64::NAN,
        })
    }

    /// How many facets [`measures`] takes side by side.
    const LANES: usize = 4;

    /// `LANES` facets' edges, coordinate by coordinate, facet by facet.
    type Edges = [[[f64; LANES]; D]; D - 1];

    /// Step `K` of the QR factorisations in [`measures`]: the Householder reflection that maps
    /// edge `K`'s components `K..D` onto coordinate `K`, applied to the edges after it, for each
    /// facet; `|r_KK|`, the distance of edge `K` from the span of the edges before it.
    #[inline(always)]
    fn reflect_lanes<const K: usize>(a: &mut Edges) -> [f64; LANES] {
        let (top, rest) = a.split_at_mut(K + 1);
        let x = &mut top[K];
        let mut r = [0.0; LANES];
        for i in K..D {
            for l in 0..LANES {
                r[l] += x[i][l] * x[i][l];
            }
        }
        let mut tau = [0.0; LANES];
        for l in 0..LANES {
            r[l] = r[l].sqrt();
            // v = x + sign(x_K) r e_K, so that |v|² = 2 r (r + |x_K|) loses nothing.
            tau[l] = 1.0 / (r[l] * (r[l] + x[K][l].abs()));
            x[K][l] += r[l].copysign(x[K][l]);
        }
        for y in rest.iter_mut() {
            let mut s = [0.0; LANES];
            for i in K..D {
                for l in 0..LANES {
                    s[l] += x[i][l] * y[i][l];
                }
            }
            for l in 0..LANES {
                s[l] *= tau[l];
            }
            for i in K..D {
                for l in 0..LANES {
                    y[i][l] -= s[l] * x[i][l];
                }
            }
        }
        r
    }

    /// 5! times the 5-volumes of `LANES` facets with vertices `vs[l]`: `|det R|` in the
    /// Householder QR factorisation of the edges `e_i = p_i − p_0` (backward stable), the
    /// product of each edge's distance from the span of the edges before it.
    fn measures(pts: &[P], vs: &[[u32; D]; LANES]) -> [f64; LANES] {
        let mut a: Edges = [[[0.0; LANES]; D]; D - 1];
        for l in 0..LANES {
            let o = &pts[vs[l][0] as usize];
            for i in 0..D - 1 {
                let p = &pts[vs[l][i + 1] as usize];
                for c in 0..D {
                    a[i][c][l] = p[c] - o[c];
                }
            }
        }
        let r = [
            reflect_lanes::<0>(&mut a),
            reflect_lanes::<1>(&mut a),
            reflect_lanes::<2>(&mut a),
            reflect_lanes::<3>(&mut a),
            reflect_lanes::<4>(&mut a),
        ];
        let mut out = [1.0; LANES];
        for ri in r {
            for l in 0..LANES {
                out[l] *= ri[l];
            }
        }
        out
    }

    fn dist(f: &Plane, p: &P) -> f64 {
        f.n.dot(p) - f.d
    }

    /// The state of a build.
    struct Build<'a> {
        pts: &'a [P],
        tol: f64,
        interior: P,
        topo: Vec<Topo>,
        planes: Vec<Plane>,
        outside: Vec<Outside>,
        /// How far the current round's point is above the facets its visibility search met.
        above: Vec<f64>,
        /// The next point in the same outside set, or NONE.
        next: Vec<u32>,
        /// Facets with outside points by the distance of the farthest (as bits, which order
        /// like the non-negative distances); stale entries are skipped when taken.
        work: BinaryHeap<(u64, u32)>,
        /// Slots of facets removed in earlier rounds, for new facets.
        free: Vec<u32>,
    }

    impl Build<'_> {
        /// Puts point `i`, `dist` above facet `f`, into `f`'s outside set.
        fn add_outside(&mut self, f: usize, i: usize, dist: f64) {
            let o = &mut self.outside[f];
            if o.first == NONE || dist > o.far_dist {
                o.far = i as u32;
                o.far_dist = dist;
                self.work.push((dist.to_bits(), f as u32));
            }
            self.next[i] = o.first;
            o.first = i as u32;
        }

        /// Stores a new facet, in a free slot if there is one; its index.
        fn add_facet(&mut self, topo: Topo, plane: Plane) -> Result<usize, HullError> {
            Ok(match self.free.pop() {
                Some(id) => {
                    let id = id as usize;
                    self.topo[id] = topo;
                    self.planes[id] = plane;
                    self.outside[id] = NO_OUTSIDE;
                    id
                }
                None => {
                    if self.topo.len() >= NONE as usize {
                        return Err(HullError::Numerical("too many facets"));
                    }
                    self.topo.push(topo);
                    self.planes.push(plane);
                    self.outside.push(NO_OUTSIDE);
                    self.above.push(0.0);
                    self.topo.len() - 1
                }
            })
        }
    }

    /// A horizon ridge: the visible facet, the index of the ridge in it, and the hidden
    /// neighbour with the ridge's index there.
    #[derive(Clone, Copy)]
    struct Ridge {
        f: usize,
        j: usize,
        g: usize,
        slot: u8,
    }

    /// Builds the convex hull of `pts` (tolerance `tol` for "outside").
    pub(super) fn build(pts: &[P], tol: f64) -> Result<Hull, HullError> {
        let npts = pts.len();
        if npts < D + 1 {
            return Err(HullError::Flat);
        }
        if npts >= NONE as usize {
            return Err(HullError::Numerical("too many points"));
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
        let size = pts.iter().fold(0.0_f64, |m, p| m.max(p.norm()));
        // What a backward-stable computation of a hyperplane may leave at its vertices.
        let exact = 16.0 * f64::EPSILON * size;
        let Buffers {
            mut topo,
            mut planes,
            mut outside,
            mut above,
            mut next,
            mut work,
            mut free,
        } = SPARE
            .try_with(|s| s.take())
            .ok()
            .flatten()
            .unwrap_or_default();
        topo.clear();
        planes.clear();
        outside.clear();
        above.clear();
        next.clear();
        next.resize(npts, NONE);
        work.clear();
        free.clear();
        let mut b = Build {
            pts,
            tol,
            interior,
            topo,
            planes,
            outside,
            above,
            next,
            work,
            free,
        };
        for k in 0..=D {
            let mut t = Topo {
                nb: [0; D],
                v: [0; D],
                back: [0; D],
                alive: true,
                seen: 0,
            };
            let mut j = 0;
            for (m, &c) in chosen.iter().enumerate() {
                if m != k {
                    // The facet omitting chosen[m] shares all but chosen[m]; in it, chosen[k]
                    // comes at k or, after the omitted chosen[m], at k − 1.
                    t.v[j] = c as u32;
                    t.nb[j] = m as u32;
                    t.back[j] = if k < m { k as u8 } else { (k - 1) as u8 };
                    j += 1;
                }
            }
            let pl = plane(pts, &t.v, &interior)
                .ok_or(HullError::Numerical("degenerate simplex facet"))?;
            b.add_facet(t, pl)?;
        }
        for (i, p) in pts.iter().enumerate() {
            if chosen.contains(&i) {
                continue;
            }
            if let Some((f, d)) = (0..=D)
                .map(|f| (f, dist(&b.planes[f], p)))
                .find(|&(_, d)| d > tol)
            {
                b.add_outside(f, i, d);
            }
        }

        let mut visible: Vec<usize> = Vec::new();
        let mut horizon: Vec<Ridge> = Vec::new();
        // The new facets, in the order of the horizon ridges they were built on.
        let mut new: Vec<usize> = Vec::new();
        // Each round turns one outside point, the farthest above any facet, into a vertex: at
        // most npts rounds.
        for round in 1..=npts as u32 + 1 {
            let fi = loop {
                match b.work.pop() {
                    None => return finish(b),
                    Some((key, f)) => {
                        let f = f as usize;
                        let o = &b.outside[f];
                        if b.topo[f].alive && o.first != NONE && o.far_dist.to_bits() == key {
                            break f;
                        }
                    }
                }
            };
            let pi = b.outside[fi].far as usize;
            let p = pts[pi];
            // Visible facets: connected to fi, with p strictly outside; and the horizon ridges
            // between them and the hidden ones.
            visible.clear();
            horizon.clear();
            visible.push(fi);
            b.topo[fi].alive = false;
            b.topo[fi].seen = round;
            b.above[fi] = dist(&b.planes[fi], &p);
            let mut s = 0;
            while s < visible.len() {
                let f = visible[s];
                s += 1;
                for j in 0..D {
                    let g = b.topo[f].nb[j] as usize;
                    let tg = &mut b.topo[g];
                    if tg.seen != round {
                        tg.seen = round;
                        let above = dist(&b.planes[g], &p);
                        b.above[g] = above;
                        if above > tol {
                            tg.alive = false;
                            visible.push(g);
                        }
                    }
                    if tg.alive {
                        let slot = b.topo[f].back[j];
                        if b.topo[g].nb[slot as usize] as usize != f {
                            return Err(HullError::Numerical("broken adjacency"));
                        }
                        horizon.push(Ridge { f, j, g, slot });
                    }
                }
            }
            if horizon.is_empty() {
                return Err(HullError::Numerical("horizon is not closed"));
            }
            new.clear();
            for r in &horizon {
                let mut t = Topo {
                    nb: [NONE; D],
                    v: b.topo[r.f].v,
                    back: [0; D],
                    alive: true,
                    seen: 0,
                };
                t.v[r.j] = pi as u32;
                t.nb[r.j] = r.g as u32;
                t.back[r.j] = r.slot;
                let (pf, pg) = (&b.planes[r.f], &b.planes[r.g]);
                let (af, ag) = (b.above[r.f], b.above[r.g]);
                let pl = match turn(pts, &t.v, (pf, af), (pg, ag), &interior, exact) {
                    Some(pl) => pl,
                    None => plane(pts, &t.v, &interior)
                        .ok_or(HullError::Numerical("degenerate new facet"))?,
                };
                if pl.d - pl.n.dot(&interior) <= 0.0 {
                    return Err(HullError::Numerical("interior point on a facet"));
                }
                let id = b.add_facet(t, pl)?;
                let tg = &mut b.topo[r.g];
                tg.nb[r.slot as usize] = id as u32;
                tg.back[r.slot as usize] = r.j as u8;
                // The removed facet's side of the ridge points at the new facet too.
                let tf = &mut b.topo[r.f];
                tf.nb[r.j] = id as u32;
                tf.back[r.j] = NEW;
                new.push(id);
            }
            // The new facets pair up across the ridges through p. The new facet on ridge (f, j)
            // shares with its neighbour opposite v[k] the 4 vertices S of f other than v[j]
            // and v[k]: turning about S through the visible facets from f, across the ridge
            // opposite v[k], leads to the next horizon ridge about S, whose new facet it is.
            let topo = &mut b.topo;
            for (r, &id) in horizon.iter().zip(&new) {
                for k in 0..D {
                    if k == r.j || topo[id].nb[k] != NONE {
                        continue;
                    }
                    // h holds S and two more vertices, at ia and ic: cross the ridge opposite ia.
                    let (mut h, mut ia, mut ic) = (r.f, k, r.j);
                    let mut steps = 0;
                    let (m, slot) = loop {
                        let th = &topo[h];
                        let across = th.nb[ia] as usize;
                        if th.back[ia] == NEW {
                            // Built on h's ridge opposite ia: its vertices are h's, in order.
                            break (across, ic);
                        }
                        steps += 1;
                        let ta = &topo[across];
                        if steps > visible.len() || ta.alive || ta.seen != round {
                            return Err(HullError::Numerical("horizon is not closed"));
                        }
                        // Where h's vertex c is in across, without branches.
                        let c = th.v[ic];
                        let (mut ic_across, mut found) = (0, 0);
                        for (i, &x) in ta.v.iter().enumerate() {
                            let here = usize::from(x == c);
                            ic_across += i * here;
                            found += here;
                        }
                        if found != 1 {
                            return Err(HullError::Numerical("broken adjacency"));
                        }
                        (h, ia, ic) = (across, ic_across, th.back[ia] as usize);
                    };
                    let taken = topo[m].nb[slot];
                    if m == id || (taken != NONE && taken as usize != id) {
                        return Err(HullError::Numerical("horizon is not closed"));
                    }
                    topo[id].nb[k] = m as u32;
                    topo[id].back[k] = slot as u8;
                    topo[m].nb[slot] = id as u32;
                    topo[m].back[slot] = k as u8;
                }
            }
            // The visible facets' outside points go to the first new facet they are above
            // (those on their own horizon ridges first), or are inside.
            for &f in &visible {
                let mut q = b.outside[f].first;
                b.outside[f].first = NONE;
                while q != NONE {
                    let qi = q as usize;
                    q = b.next[qi];
                    if qi == pi {
                        continue;
                    }
                    let pq = &pts[qi];
                    let tf = &b.topo[f];
                    let planes = &b.planes;
                    let above = |g: usize| {
                        let d = dist(&planes[g], pq);
                        (d > tol).then_some((g, d))
                    };
                    let to = (0..D)
                        .filter(|&j| tf.back[j] == NEW)
                        .find_map(|j| above(tf.nb[j] as usize))
                        .or_else(|| new.iter().copied().find_map(above));
                    if let Some((g, d)) = to {
                        b.add_outside(g, qi, d);
                    }
                }
            }
            b.free.extend(visible.iter().map(|&f| f as u32));
        }
        Err(HullError::Numerical("too many rounds"))
    }

    /// Checks the result: each ridge of a live facet is shared with a live facet, and every
    /// point is inside every facet (with a margin of `1e3 tol` for the merged near-coplanar
    /// facets).
    fn finish(b: Build) -> Result<Hull, HullError> {
        let Build {
            pts,
            tol,
            interior,
            topo,
            mut planes,
            outside,
            above,
            next,
            work,
            free,
        } = b;
        for (i, t) in topo.iter().enumerate() {
            if !t.alive {
                continue;
            }
            for k in 0..D {
                let Some(g) = topo.get(t.nb[k] as usize) else {
                    return Err(HullError::Numerical("a live facet borders a removed one"));
                };
                let s = t.back[k] as usize;
                if !g.alive {
                    return Err(HullError::Numerical("a live facet borders a removed one"));
                }
                if s >= D || g.nb[s] as usize != i || g.back[s] as usize != k {
                    return Err(HullError::Numerical("adjacency is not symmetric"));
                }
            }
        }
        // The points by coordinate, so that the products vectorise, in f64 and in f32 (four to
        // a vector register). In f32, n · x is within 9 u r of its value (u = 2⁻²⁴, r the
        // largest point norm: the rounding of n, x, the products and their sum), so a facet all
        // of whose points are below its limit less that in f32 passes; any other is checked
        // again in f64.
        let npts = pts.len();
        let r = pts.iter().fold(0.0_f64, |m, p| m.max(p.norm()));
        let slack = 9.0 * 2f64.powi(-24) * r;
        let mut cols = vec![0.0; D * npts];
        for (i, p) in pts.iter().enumerate() {
            for c in 0..D {
                cols[c * npts + i] = p[c];
            }
        }
        let cols32: Vec<f32> = cols.iter().map(|&x| x as f32).collect();
        fn split<T>(cols: &[T], n: usize) -> [&[T]; D] {
            let (x0, rest) = cols.split_at(n);
            let (x1, rest) = rest.split_at(n);
            let (x2, rest) = rest.split_at(n);
            let (x3, rest) = rest.split_at(n);
            let (x4, x5) = rest.split_at(n);
            [x0, x1, x2, x3, x4, x5]
        }
        let [x0, x1, x2, x3, x4, x5] = split(&cols, npts);
        let [y0, y1, y2, y3, y4, y5] = split(&cols32, npts);
        for (t, f) in topo.iter().zip(&planes) {
            if !t.alive {
                continue;
            }
            let n = &f.n;
            let limit = f.d + 1e3 * tol;
            // Below limit − slack, rounded down.
            let below = limit - slack;
            let limit32 = (below - below.abs() * 2f64.powi(-23)) as f32;
            // Only well inside f32's normal range (where its rounding is relative); else
            // straight to f64.
            if (1e-30..1e30).contains(&r) && limit.abs() < 1e30 {
                let m: [f32; D] = std::array::from_fn(|c| n[c] as f32);
                // Counted in u32, the width of an f32 comparison, so that the loop vectorises.
                let mut inside32 = 0_u32;
                for i in 0..npts {
                    let s = m[0] * y0[i]
                        + m[1] * y1[i]
                        + m[2] * y2[i]
                        + m[3] * y3[i]
                        + m[4] * y4[i]
                        + m[5] * y5[i];
                    inside32 += u32::from(s <= limit32);
                }
                if inside32 as usize == npts {
                    continue;
                }
            }
            let mut inside = 0;
            for i in 0..npts {
                let s = n[0] * x0[i]
                    + n[1] * x1[i]
                    + n[2] * x2[i]
                    + n[3] * x3[i]
                    + n[4] * x4[i]
                    + n[5] * x5[i];
                inside += usize::from(s <= limit);
            }
            if inside != npts {
                return Err(HullError::Numerical("a point is outside the hull"));
            }
        }
        let live: Vec<usize> = (0..topo.len()).filter(|&i| topo[i].alive).collect();
        for chunk in live.chunks(LANES) {
            let mut vs = [topo[chunk[0]].v; LANES];
            for (l, &i) in chunk.iter().enumerate() {
                vs[l] = topo[i].v;
            }
            let m = measures(pts, &vs);
            for (l, &i) in chunk.iter().enumerate() {
                planes[i].measure = m[l];
            }
        }
        Ok(Hull {
            buffers: Buffers {
                topo,
                planes,
                outside,
                above,
                next,
                work,
                free,
            },
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
            assert_eq!(h.facets().count(), 64);
            for f in h.facets() {
                assert!((f.d - 1.0 / 6f64.sqrt()).abs() < 1e-12);
            }
            assert!((h.volume() - 64.0 / 720.0).abs() < 1e-12);
        }

        #[test]
        fn tiny_and_huge_hulls_pass_their_checks() {
            // The final check runs in f32 only well inside its range: here partly or not at all.
            for s in [1e-35, 1e-20, 1.0, 1e20, 1e35] {
                let mut pts = Vec::new();
                for i in 0..D {
                    for sign in [1.0, -1.0] {
                        let mut p = P::zeros();
                        p[i] = sign * s;
                        pts.push(p);
                    }
                }
                pts.push(P::from_element(0.1 * s));
                let h = build(&pts, 1e-9 * s).unwrap();
                assert_eq!(h.facets().count(), 64);
                let v = h.volume() / s.powi(6);
                assert!((v - 64.0 / 720.0).abs() < 1e-12, "{s}: {v}");
            }
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
            for f in h.facets() {
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
                    if let Some(Plane { n: nn, d, .. }) = plane(&pts, &idx.map(|x| x as u32), &centroid) {
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
                let mut mine: Vec<f64> = h.facets().map(|f| f.d).collect();
                mine.sort_by(f64::total_cmp);
                brute.sort_by(f64::total_cmp);
                proptest::prop_assert_eq!(mine.len(), brute.len());
                for (a, b) in mine.iter().zip(&brute) {
                    proptest::prop_assert!((a - b).abs() < 1e-9);
                }
            }
        }

        /// Point sets for the comparison with the previous hull: uniform, on the lattice
        /// {-1, 0, 1}⁶ (many coplanar points), doubled, or in a hyperplane.
        fn point_sets() -> impl proptest::strategy::Strategy<Value = Vec<P>> {
            use proptest::prelude::*;
            let raw = proptest::collection::vec(proptest::array::uniform6(-1.0..1.0f64), 7..40);
            (raw, 0usize..4).prop_map(|(raw, shape)| {
                let mut pts: Vec<P> = raw.iter().map(|a| P::from_row_slice(a)).collect();
                match shape {
                    1 => pts.iter_mut().for_each(|p| p.apply(|x| *x = x.round())),
                    2 => pts.extend(pts.clone()),
                    3 => pts.iter_mut().for_each(|p| p[5] = 0.5 * p[0] - p[1]),
                    _ => {}
                }
                pts
            })
        }

        proptest::proptest! {
            #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
            #[test]
            fn the_hull_has_the_volume_and_offsets_of_the_previous_one(pts in point_sets()) {
                use super::super::reference;
                let new = build(&pts, 1e-9);
                let old = reference::build(&pts, 1e-9);
                match (new, old) {
                    (Ok(a), Ok(b)) => {
                        let (va, vb) = (a.volume(), b.volume(&pts));
                        proptest::prop_assert!((va - vb).abs() <= 1e-11 * vb, "{} vs {}", va, vb);
                        let min = |it: &mut dyn Iterator<Item = f64>| it.fold(f64::INFINITY, f64::min);
                        let (ea, eb) = (min(&mut a.facets().map(|f| f.d)), min(&mut b.facets.iter().map(|f| f.d)));
                        proptest::prop_assert!((ea - eb).abs() <= 1e-12, "{} vs {}", ea, eb);
                    }
                    (Err(HullError::Flat), Err(reference::HullError::Flat)) => {}
                    (a, b) => proptest::prop_assert!(false, "{:?} vs {:?}", a.err(), b.err()),
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

    /// What `grasp_quality` gave for the paper's sphere before its hull was rewritten (printed
    /// with `{:.17e}`), and what the previous hull gives now; the 80 soft-finger primitives are
    /// the replay planner's typical input.
    #[test]
    fn the_paper_sphere_grasp_keeps_the_quality_the_previous_hull_gave() {
        let c = crate::fixtures::paper_sphere_contacts();
        let soft = ContactModel::SoftFinger;
        let point = ContactModel::PointWithFriction;
        #[allow(clippy::excessive_precision)]
        let cases = [
            // The soft finger's primitives sample the elliptic cone since issue 21 (20 per
            // contact, 80 in all; they were the 64 corners of the box cone, ε 2.087e-1 and
            // 1.484e-2, volume 7.527 and 0.392): its values were taken with the new primitives,
            // which the previous hull gives alike.
            (
                soft,
                1.5,
                1.94274245656713918e-1,
                6.41644077360261544e0,
                true,
            ),
            (
                soft,
                0.8,
                5.74708197993849517e-3,
                3.11981282049349107e-1,
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
            let r = reference::grasp_quality(&c, m, &fr(mu), &QualityParams::default()).unwrap();
            eprintln!(
                "{m:?} μ = {mu}: ε {:.17e} volume {:.17e}; previous hull: ε {:.17e} volume {:.17e}",
                g.epsilon, g.volume, r.epsilon, r.volume
            );
            assert_eq!(g.force_closure, fc, "{m:?} μ = {mu}");
            assert!((g.epsilon - r.epsilon).abs() <= 1e-12 * g.epsilon.max(1e-3));
            assert!((g.volume - r.volume).abs() <= 1e-12 * vol);
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
