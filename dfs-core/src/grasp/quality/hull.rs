//! A Quickhull in six dimensions with simplicial facets: the grasp wrench space's convex hull
//! behind ε and the volume (the parent module's documentation says how and why).

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
    /// Read by the tests' [`Hull::volume`] only; [`Build::metrics`] measures the same as it
    /// checks.
    #[cfg(test)]
    interior: P,
}

/// The arrays of a build, held by the [`Build`] and then by its [`Hull`]. A thread keeps
/// those of its last hull, so that the next build reuses them instead of allocating (and
/// faulting in) a few hundred fresh kB.
#[derive(Default)]
struct Buffers {
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

impl Buffers {
    /// The thread's spare buffers (or new ones), emptied for a build of `npts` points.
    fn take_spare(npts: usize) -> Buffers {
        let mut b: Buffers = SPARE
            .try_with(|s| s.take())
            .ok()
            .flatten()
            .unwrap_or_default();
        b.topo.clear();
        b.planes.clear();
        b.outside.clear();
        b.above.clear();
        b.next.clear();
        b.next.resize(npts, NONE);
        b.work.clear();
        b.free.clear();
        b
    }
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
    #[cfg(test)]
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
    #[cfg(test)]
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

/// A hull being built: the state between two calls of [`Build::advance`], which may fall in
/// the middle of choosing the initial simplex or of a round ([`Step`]), so that a build can be
/// done a part at a time with the same operations in the same order as in one go.
pub(super) struct Build {
    tol: f64,
    /// A point strictly inside: the initial simplex's centroid, once it is chosen.
    interior: P,
    /// What a backward-stable computation of a hyperplane may leave at its vertices.
    exact: f64,
    /// Rounds begun.
    round: u32,
    /// Where the build is.
    step: Step,
    /// The initial simplex while it is chosen.
    simplex: Simplex,
    /// The point the current round makes a vertex.
    point: usize,
    buffers: Buffers,
    /// A round's visible facets, horizon ridges and new facets (in the order of the horizon
    /// ridges they were built on): kept to reuse their memory.
    visible: Vec<usize>,
    horizon: Vec<Ridge>,
    new: Vec<usize>,
    /// The checks of the built hull, once begun.
    checks: Option<Checks>,
}

/// Where a [`Build`] is: a phase and the cursor of its loop. A call of [`Build::advance`]
/// stops between two steps of a loop (a point looked at, a facet searched or made, a point
/// moved) and the next call goes on from the cursor.
#[derive(Clone, Copy)]
enum Step {
    /// Choosing the initial simplex's vertices: a pass over the points per vertex, the
    /// points before `next` looked at in this one.
    Choose { next: usize },
    /// Putting the points before `next` in the initial simplex's outside sets done.
    Assign { next: usize },
    /// Between two rounds (the initial simplex built).
    Between,
    /// The round's visibility search: `visible[..searched]` searched.
    Visible { searched: usize },
    /// The round's new facets on `horizon[..made]` made.
    Facets { made: usize },
    /// The new facets of `horizon[..paired]` paired with their neighbours.
    Pair { paired: usize },
    /// The outside points of the visible facets: `visible[..taken]`'s lists taken off their
    /// facets, those before `next` (the next point of the last list taken, or NONE) moved.
    Move { taken: usize, next: u32 },
}

/// The initial simplex while it is chosen: greedily the points farthest from the affine hull
/// of those chosen (the first the farthest from the centroid).
struct Simplex {
    centroid: P,
    /// The vertices chosen, and an orthonormal basis of their affine hull's directions from
    /// the first.
    chosen: Vec<usize>,
    basis: Vec<P>,
    /// In the current pass, the farthest point so far: its index, its distance, and its
    /// offset from the affine hull of the chosen.
    best: Option<(usize, f64, P)>,
}

/// What the steps of [`Build::advance`] cost, in sixteenths of a unit (a unit is about 0.1 µs
/// on the project's machine; measured with `icms bench recognition` on power grasps' hulls,
/// 160-200 primitives, BENCHMARKS.md issue 20, 2026-11-27).
mod cost {
    /// A unit.
    pub const UNIT: usize = 16;
    /// A point looked at in a pass choosing a vertex of the initial simplex, and more per
    /// vertex chosen before (its offset from their affine hull).
    pub const CHOOSE: usize = 1;
    pub const CHOOSE_PER_VERTEX: usize = 2;
    /// The initial simplex's facets (and the points' largest norm).
    pub const SIMPLEX: usize = 16 * UNIT;
    /// A point put in an outside set of the initial simplex (or found inside it).
    pub const ASSIGN: usize = 3;
    /// A stale entry of the work heap.
    pub const STALE: usize = UNIT;
    /// A visible facet searched (its neighbours' heights).
    pub const VISIBLE: usize = UNIT;
    /// A new facet made: turned about its ridge, and more if computed from its vertices.
    pub const NEW: usize = UNIT / 2;
    pub const PLANE: usize = 2 * UNIT;
    /// A new facet paired, and each step of its walks.
    pub const PAIR: usize = UNIT / 2;
    pub const WALK: usize = UNIT / 8;
    /// An outside point moved, and each of its heights computed.
    pub const MOVE: usize = UNIT / 4;
    pub const HEIGHT: usize = 1;
}

impl Buffers {
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

/// Builds the convex hull of `pts` (tolerance `tol` for "outside") in one go.
#[cfg(test)]
pub(super) fn build(pts: &[P], tol: f64) -> Result<Hull, HullError> {
    let mut b = start(pts, tol)?;
    while !b.advance(pts, usize::MAX)? {}
    finish(b, pts)
}

/// Starts the convex hull of `pts` (tolerance `tol` for "outside"). [`Build::advance`] goes
/// on from there (the initial simplex, the other points in its facets' outside sets, then the
/// rounds), [`finish`] ends it.
pub(super) fn start(pts: &[P], tol: f64) -> Result<Build, HullError> {
    let npts = pts.len();
    if npts < D + 1 {
        return Err(HullError::Flat);
    }
    if npts >= NONE as usize {
        return Err(HullError::Numerical("too many points"));
    }
    Ok(Build {
        tol,
        interior: P::zeros(),
        exact: 0.0,
        round: 0,
        step: Step::Choose { next: 0 },
        simplex: Simplex {
            centroid: pts.iter().sum::<P>() / npts as f64,
            chosen: Vec::with_capacity(D + 1),
            basis: Vec::with_capacity(D),
            best: None,
        },
        point: 0,
        visible: Vec::new(),
        horizon: Vec::new(),
        new: Vec::new(),
        checks: None,
        buffers: Buffers::take_spare(npts),
    })
}

/// Work done and allowed in one call of [`Build::advance`] or [`Build::check`].
struct Budget {
    spent: usize,
    limit: usize,
}

impl Budget {
    /// Whether the call stops here: some work done, and the budget spent.
    #[inline]
    fn used_up(&self) -> bool {
        self.spent > 0 && self.spent >= self.limit
    }
}

/// What the work heap gives [`Build::advance`] next.
enum Next {
    /// The live facet with the farthest outside point.
    Facet(usize),
    /// No facet has outside points: the hull is complete.
    Done,
    /// The budget ran out among stale entries.
    Paused,
}

impl Build {
    /// Goes on with the build for about `budget` units of work (at least one step; module
    /// `cost` says what each costs: a visible facet searched one unit, a new facet made half
    /// of one, an outside point moved a quarter and a sixteenth per height computed, ...), and
    /// stops as soon as they are spent, wherever it is: choosing the initial simplex (a point at a time), in a round (a
    /// point made a vertex: a facet searched, made or paired, a point moved at a time), or
    /// among the stale entries of the work heap; whether the hull is complete ([`Build::check`]
    /// it then). The operations are those of a build in one go, in the same order.
    pub(super) fn advance(&mut self, pts: &[P], budget: usize) -> Result<bool, HullError> {
        let npts = pts.len();
        let mut budget = Budget {
            spent: 0,
            limit: budget.saturating_mul(cost::UNIT),
        };
        loop {
            match self.step {
                Step::Choose { mut next } => {
                    if !self.choose(pts, &mut next, &mut budget)? {
                        self.step = Step::Choose { next };
                        return Ok(false);
                    }
                    self.step = if self.simplex.chosen.len() == D + 1 {
                        self.build_simplex(pts)?;
                        budget.spent += cost::SIMPLEX;
                        Step::Assign { next: 0 }
                    } else {
                        Step::Choose { next: 0 }
                    };
                }
                Step::Assign { mut next } => {
                    if !self.assign(pts, &mut next, &mut budget) {
                        self.step = Step::Assign { next };
                        return Ok(false);
                    }
                    self.step = Step::Between;
                }
                Step::Between => {
                    if budget.used_up() {
                        return Ok(false);
                    }
                    // Each round turns one outside point, the farthest above any facet, into
                    // a vertex: at most npts rounds.
                    let round = self.round + 1;
                    if round > npts as u32 + 1 {
                        return Err(HullError::Numerical("too many rounds"));
                    }
                    let fi = match self.farthest(&mut budget) {
                        Next::Facet(f) => f,
                        Next::Done => return Ok(true),
                        Next::Paused => return Ok(false),
                    };
                    self.round = round;
                    self.begin_round(pts, fi);
                    self.step = Step::Visible { searched: 0 };
                }
                Step::Visible { mut searched } => {
                    if !self.find_visible(pts, &mut searched, &mut budget)? {
                        self.step = Step::Visible { searched };
                        return Ok(false);
                    }
                    self.step = Step::Facets { made: 0 };
                }
                Step::Facets { mut made } => {
                    if !self.make_facets(pts, &mut made, &mut budget)? {
                        self.step = Step::Facets { made };
                        return Ok(false);
                    }
                    self.step = Step::Pair { paired: 0 };
                }
                Step::Pair { mut paired } => {
                    let done = pair_new_facets(
                        &mut self.buffers.topo,
                        &self.horizon,
                        &self.new,
                        self.visible.len(),
                        self.round,
                        &mut paired,
                        &mut budget,
                    )?;
                    if !done {
                        self.step = Step::Pair { paired };
                        return Ok(false);
                    }
                    self.step = Step::Move {
                        taken: 0,
                        next: NONE,
                    };
                }
                Step::Move {
                    mut taken,
                    mut next,
                } => {
                    if !self.move_outside(pts, &mut taken, &mut next, &mut budget) {
                        self.step = Step::Move { taken, next };
                        return Ok(false);
                    }
                    self.buffers
                        .free
                        .extend(self.visible.iter().map(|&f| f as u32));
                    self.step = Step::Between;
                }
            }
        }
    }

    /// A pass choosing the next vertex of the initial simplex, from point `next` on, as far
    /// as the budget goes; whether the pass is done (the vertex chosen then).
    fn choose(
        &mut self,
        pts: &[P],
        next: &mut usize,
        budget: &mut Budget,
    ) -> Result<bool, HullError> {
        let s = &mut self.simplex;
        let per_point = cost::CHOOSE + cost::CHOOSE_PER_VERTEX * s.chosen.len();
        while *next < pts.len() {
            if budget.used_up() {
                return Ok(false);
            }
            let i = *next;
            *next += 1;
            budget.spent += per_point;
            let r = match s.chosen.first() {
                None => pts[i] - s.centroid,
                Some(&i0) => residual(&pts[i], &pts[i0], &s.basis),
            };
            let norm = r.norm();
            // As `Iterator::max_by`: the last of equals.
            if s.best
                .is_none_or(|(_, best, _)| best.total_cmp(&norm) != std::cmp::Ordering::Greater)
            {
                s.best = Some((i, norm, r));
            }
        }
        let (best, rn, r) = s.best.take().ok_or(HullError::Flat)?;
        if !s.chosen.is_empty() {
            if rn <= self.tol {
                return Err(HullError::Flat);
            }
            s.basis.push(r / rn);
        }
        s.chosen.push(best);
        Ok(true)
    }

    /// The initial simplex's facets, its centroid the interior point.
    fn build_simplex(&mut self, pts: &[P]) -> Result<(), HullError> {
        let chosen = &self.simplex.chosen;
        let interior = chosen.iter().map(|&i| pts[i]).sum::<P>() / (D + 1) as f64;
        let size = pts.iter().fold(0.0_f64, |m, p| m.max(p.norm()));
        self.interior = interior;
        self.exact = 16.0 * f64::EPSILON * size;
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
            self.buffers.add_facet(t, pl)?;
        }
        Ok(())
    }

    /// Puts the points from `next` on that are not vertices in the outside set of the first
    /// facet of the initial simplex they are above, as far as the budget goes; whether all
    /// are.
    fn assign(&mut self, pts: &[P], next: &mut usize, budget: &mut Budget) -> bool {
        while *next < pts.len() {
            if budget.used_up() {
                return false;
            }
            let i = *next;
            *next += 1;
            budget.spent += cost::ASSIGN;
            if self.simplex.chosen.contains(&i) {
                continue;
            }
            let p = &pts[i];
            if let Some((f, d)) = (0..=D)
                .map(|f| (f, dist(&self.buffers.planes[f], p)))
                .find(|&(_, d)| d > self.tol)
            {
                self.buffers.add_outside(f, i, d);
            }
        }
        true
    }

    /// The facet with the farthest outside point; entries of removed facets or of outside
    /// sets that changed are skipped (so that a call may stop among them: taking them changes
    /// nothing else).
    #[inline]
    fn farthest(&mut self, budget: &mut Budget) -> Next {
        loop {
            match self.buffers.work.pop() {
                None => return Next::Done,
                Some((key, f)) => {
                    let f = f as usize;
                    let o = &self.buffers.outside[f];
                    if self.buffers.topo[f].alive && o.first != NONE && o.far_dist.to_bits() == key
                    {
                        return Next::Facet(f);
                    }
                    budget.spent += cost::STALE;
                    if budget.spent >= budget.limit {
                        return Next::Paused;
                    }
                }
            }
        }
    }

    /// Begins the round `self.round`: the farthest outside point of facet `fi` is to become a
    /// vertex; `fi`, which sees it, is the first visible facet.
    fn begin_round(&mut self, pts: &[P], fi: usize) {
        let pi = self.buffers.outside[fi].far as usize;
        self.point = pi;
        self.visible.clear();
        self.horizon.clear();
        self.new.clear();
        self.visible.push(fi);
        let t = &mut self.buffers.topo[fi];
        t.alive = false;
        t.seen = self.round;
        self.buffers.above[fi] = dist(&self.buffers.planes[fi], &pts[pi]);
    }

    /// The visibility search of the round's point from `visible[searched]` on, as far as the
    /// budget goes: the facets connected to the first with the point strictly outside
    /// (removed, in `visible`), and the horizon ridges between them and the hidden ones (in
    /// `horizon`); whether it is done.
    #[inline]
    fn find_visible(
        &mut self,
        pts: &[P],
        searched: &mut usize,
        budget: &mut Budget,
    ) -> Result<bool, HullError> {
        let (tol, round) = (self.tol, self.round);
        let p = pts[self.point];
        let b = &mut self.buffers;
        while *searched < self.visible.len() {
            if budget.used_up() {
                return Ok(false);
            }
            let f = self.visible[*searched];
            *searched += 1;
            budget.spent += cost::VISIBLE;
            for j in 0..D {
                let g = b.topo[f].nb[j] as usize;
                let tg = &mut b.topo[g];
                if tg.seen != round {
                    tg.seen = round;
                    let above = dist(&b.planes[g], &p);
                    b.above[g] = above;
                    if above > tol {
                        tg.alive = false;
                        self.visible.push(g);
                    }
                }
                if tg.alive {
                    let slot = b.topo[f].back[j];
                    if b.topo[g].nb[slot as usize] as usize != f {
                        return Err(HullError::Numerical("broken adjacency"));
                    }
                    self.horizon.push(Ridge { f, j, g, slot });
                }
            }
        }
        if self.horizon.is_empty() {
            return Err(HullError::Numerical("horizon is not closed"));
        }
        Ok(true)
    }

    /// A new facet on each horizon ridge from `horizon[made]` on, as far as the budget goes,
    /// through the round's point (in `new`, in the order of the ridges), adjacent to the
    /// hidden facet across the ridge; the removed facet's side of the ridge points at it too.
    /// Whether all are made.
    #[inline]
    fn make_facets(
        &mut self,
        pts: &[P],
        made: &mut usize,
        budget: &mut Budget,
    ) -> Result<bool, HullError> {
        let (interior, exact, pi) = (self.interior, self.exact, self.point);
        let b = &mut self.buffers;
        while *made < self.horizon.len() {
            if budget.used_up() {
                return Ok(false);
            }
            let r = self.horizon[*made];
            *made += 1;
            budget.spent += cost::NEW;
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
                None => {
                    budget.spent += cost::PLANE;
                    plane(pts, &t.v, &interior)
                        .ok_or(HullError::Numerical("degenerate new facet"))?
                }
            };
            if pl.d - pl.n.dot(&interior) <= 0.0 {
                return Err(HullError::Numerical("interior point on a facet"));
            }
            let id = b.add_facet(t, pl)?;
            let tg = &mut b.topo[r.g];
            tg.nb[r.slot as usize] = id as u32;
            tg.back[r.slot as usize] = r.j as u8;
            let tf = &mut b.topo[r.f];
            tf.nb[r.j] = id as u32;
            tf.back[r.j] = NEW;
            self.new.push(id);
        }
        Ok(true)
    }

    /// The visible facets' outside points go to the first new facet they are above (those on
    /// their own horizon ridges first), or are inside: the lists of `visible[..taken]` are
    /// taken off their facets, `next` is the next point of the last one (NONE: done). As far
    /// as the budget goes; whether all are moved.
    #[inline]
    fn move_outside(
        &mut self,
        pts: &[P],
        taken: &mut usize,
        next: &mut u32,
        budget: &mut Budget,
    ) -> bool {
        let (tol, pi) = (self.tol, self.point);
        let b = &mut self.buffers;
        loop {
            if *next == NONE {
                let Some(&f) = self.visible.get(*taken) else {
                    return true;
                };
                *taken += 1;
                *next = b.outside[f].first;
                b.outside[f].first = NONE;
                continue;
            }
            if budget.used_up() {
                return false;
            }
            let f = self.visible[*taken - 1];
            let qi = *next as usize;
            *next = b.next[qi];
            budget.spent += cost::MOVE;
            if qi == pi {
                continue;
            }
            let pq = &pts[qi];
            let tf = &b.topo[f];
            let mut heights = 0;
            let mut to = None;
            // Its own facet's new neighbours first, then all the new facets.
            let own = (0..D)
                .filter(|&j| tf.back[j] == NEW)
                .map(|j| tf.nb[j] as usize);
            for g in own.chain(self.new.iter().copied()) {
                heights += 1;
                let d = dist(&b.planes[g], pq);
                if d > tol {
                    to = Some((g, d));
                    break;
                }
            }
            budget.spent += cost::HEIGHT * heights;
            if let Some((g, d)) = to {
                b.add_outside(g, qi, d);
            }
        }
    }
}

/// A point's offset from the affine hull through `origin` spanned by the orthonormal `basis`
/// (projected out twice, for the rounding of the first).
#[inline]
fn residual(p: &P, origin: &P, basis: &[P]) -> P {
    let mut r = p - origin;
    for _ in 0..2 {
        for b in basis {
            r -= b * b.dot(&r);
        }
    }
    r
}

/// Pairs up the new facets (`new`, built on the ridges of `horizon`) across the ridges through
/// the new point, from `horizon[paired]` on, as far as the budget goes; whether all are paired.
/// The new facet on ridge (f, j) shares with its neighbour opposite v[k] the 4 vertices S of f
/// other than v[j] and v[k]: turning about S through the round's visible facets (`n_visible`
/// of them) from f, across the ridge opposite v[k], leads to the next horizon ridge about S,
/// whose new facet it is.
#[inline]
fn pair_new_facets(
    topo: &mut [Topo],
    horizon: &[Ridge],
    new: &[usize],
    n_visible: usize,
    round: u32,
    paired: &mut usize,
    budget: &mut Budget,
) -> Result<bool, HullError> {
    while *paired < horizon.len() {
        if budget.used_up() {
            return Ok(false);
        }
        let (r, id) = (horizon[*paired], new[*paired]);
        *paired += 1;
        let mut walked = 0usize;
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
                if steps > n_visible || ta.alive || ta.seen != round {
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
            walked += steps;
            topo[id].nb[k] = m as u32;
            topo[id].back[k] = slot as u8;
            topo[m].nb[slot] = id as u32;
            topo[m].back[slot] = k as u8;
        }
        budget.spent += cost::PAIR + cost::WALK * walked;
    }
    Ok(true)
}

/// Checks the result and measures the facets in one go ([`Build::check`], then
/// [`Build::into_hull`]).
#[cfg(test)]
pub(super) fn finish(mut b: Build, pts: &[P]) -> Result<Hull, HullError> {
    while !b.check(pts, usize::MAX)? {}
    Ok(b.into_hull())
}

/// Where the checks of a built hull are ([`Build::check`]).
struct Checks {
    /// The points by coordinate, in f64 and in f32.
    cols: Vec<f64>,
    cols32: Vec<f32>,
    /// The largest point norm, and what f32 rounding may leave of n · x.
    r: f64,
    slack: f64,
    /// The live facets, in the order of their slots, once all `listed`.
    live: Vec<usize>,
    listed: usize,
    /// Of them, how many have their adjacency checked, their points checked, and are
    /// measured.
    adjacent: usize,
    checked: usize,
    measured: usize,
    /// Over the facets measured: the sum of their simplices' volumes with the interior point
    /// (times 6!), and the least offset.
    volume: f64,
    min_offset: f64,
}

impl Build {
    /// Checks the result: each ridge of a live facet is shared with a live facet, and every
    /// point is inside every facet (with a margin of `1e3 tol` for the merged near-coplanar
    /// facets); then measures the facets. A part at a time: about `budget` units of work
    /// (like [`Build::advance`]'s, about 0.1 µs: a facet measured, two of their points
    /// checked, four of their adjacencies; at least one), whether all is done
    /// ([`Build::into_hull`], [`Build::metrics`] then). The same operations in the same
    /// order as in one go.
    pub(super) fn check(&mut self, pts: &[P], budget: usize) -> Result<bool, HullError> {
        let npts = pts.len();
        // In quarter units.
        let mut budget = Budget {
            spent: 0,
            limit: budget.saturating_mul(4),
        };
        let checks = match &mut self.checks {
            Some(c) => c,
            None => {
                budget.spent += npts / 4;
                self.checks
                    .insert(Checks::new(pts, self.buffers.topo.len()))
            }
        };
        if !checks.list(&self.buffers.topo, &mut budget) {
            return Ok(false);
        }
        if !checks.adjacency(&self.buffers.topo, &mut budget)? {
            return Ok(false);
        }
        if !checks.points(&self.buffers.planes, self.tol, npts, &mut budget)? {
            return Ok(false);
        }
        Ok(checks.measure(
            pts,
            &self.buffers.topo,
            &mut self.buffers.planes,
            &self.interior,
            &mut budget,
        ))
    }
}

impl Checks {
    /// The checks of the hull `topo` of `pts`, none done yet. The points by coordinate, so
    /// that the products vectorise, in f64 and in f32 (four to a vector register). In f32,
    /// n · x is within 9 u r of its value (u = 2⁻²⁴, r the largest point norm: the rounding
    /// of n, x, the products and their sum), so a facet all of whose points are below its
    /// limit less that in f32 passes; any other is checked again in f64.
    fn new(pts: &[P], slots: usize) -> Checks {
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
        Checks {
            cols,
            cols32,
            r,
            slack,
            live: Vec::with_capacity(slots),
            listed: 0,
            adjacent: 0,
            checked: 0,
            measured: 0,
            volume: 0.0,
            min_offset: f64::INFINITY,
        }
    }

    /// Lists the live facets (a unit per sixteen slots: a cache line each), as far as the
    /// budget goes; whether all are listed.
    fn list(&mut self, topo: &[Topo], budget: &mut Budget) -> bool {
        while self.listed < topo.len() {
            if budget.used_up() {
                return false;
            }
            let end = (self.listed + 4).min(topo.len());
            for (i, t) in topo.iter().enumerate().take(end).skip(self.listed) {
                if t.alive {
                    self.live.push(i);
                }
            }
            self.listed = end;
            budget.spent += 1;
        }
        true
    }

    /// Checks the live facets' adjacency (a unit per four facets), as far as the budget goes;
    /// whether all are checked.
    fn adjacency(&mut self, topo: &[Topo], budget: &mut Budget) -> Result<bool, HullError> {
        while self.adjacent < self.live.len() {
            if budget.used_up() {
                return Ok(false);
            }
            let i = self.live[self.adjacent];
            self.adjacent += 1;
            budget.spent += 1;
            let t = &topo[i];
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
        Ok(true)
    }

    /// Checks that the `npts` points are inside every live facet (two points a unit at 64
    /// of them), as far as the budget goes; whether all are checked.
    fn points(
        &mut self,
        planes: &[Plane],
        tol: f64,
        npts: usize,
        budget: &mut Budget,
    ) -> Result<bool, HullError> {
        let x = columns(&self.cols, npts);
        let y = columns(&self.cols32, npts);
        let (r, slack) = (self.r, self.slack);
        // A facet's points: two per unit at 64 of them.
        let per_facet = (npts / 32).max(1);
        while self.checked < self.live.len() {
            if budget.used_up() {
                return Ok(false);
            }
            let f = &planes[self.live[self.checked]];
            self.checked += 1;
            budget.spent += per_facet;
            let limit = f.d + 1e3 * tol;
            // Below limit − slack, rounded down.
            let below = limit - slack;
            let limit32 = (below - below.abs() * 2f64.powi(-23)) as f32;
            // Only well inside f32's normal range (where its rounding is relative); else
            // straight to f64.
            if (1e-30..1e30).contains(&r)
                && limit.abs() < 1e30
                && count_below32(&f.n, y, npts, limit32) as usize == npts
            {
                continue;
            }
            if count_below(&f.n, x, npts, limit) != npts {
                return Err(HullError::Numerical("a point is outside the hull"));
            }
        }
        Ok(true)
    }

    /// Measures the live facets of the hull of `pts` (`LANES` at a time, a unit per facet)
    /// and sums the volume and the least offset, as far as the budget goes; whether all are
    /// measured.
    fn measure(
        &mut self,
        pts: &[P],
        topo: &[Topo],
        planes: &mut [Plane],
        interior: &P,
        budget: &mut Budget,
    ) -> bool {
        while self.measured < self.live.len() {
            if budget.used_up() {
                return false;
            }
            let end = (self.measured + LANES).min(self.live.len());
            let chunk = &self.live[self.measured..end];
            self.measured = end;
            budget.spent += 4 * chunk.len();
            let mut vs = [topo[chunk[0]].v; LANES];
            for (l, &i) in chunk.iter().enumerate() {
                vs[l] = topo[i].v;
            }
            let m = measures(pts, &vs);
            for (l, &i) in chunk.iter().enumerate() {
                let f = &mut planes[i];
                f.measure = m[l];
                // As `Hull::volume` and a fold over `Hull::facets` sum them: in slot order.
                self.volume += f.measure * (f.d - f.n.dot(interior));
                self.min_offset = self.min_offset.min(f.d);
            }
        }
        true
    }
}

/// The six coordinates' columns of `n` points stored column after column.
#[inline]
fn columns<T>(cols: &[T], n: usize) -> [&[T]; D] {
    let (x0, rest) = cols.split_at(n);
    let (x1, rest) = rest.split_at(n);
    let (x2, rest) = rest.split_at(n);
    let (x3, rest) = rest.split_at(n);
    let (x4, x5) = rest.split_at(n);
    [x0, x1, x2, x3, x4, x5]
}

/// How many of the `npts` points (by coordinate, in f32) have `n · x ≤ limit32` in f32.
#[inline]
fn count_below32(n: &P, y: [&[f32]; D], npts: usize, limit32: f32) -> u32 {
    let [y0, y1, y2, y3, y4, y5] = y;
    let m: [f32; D] = std::array::from_fn(|c| n[c] as f32);
    // Counted in u32, the width of an f32 comparison, so that the loop vectorises.
    let mut inside32 = 0_u32;
    for i in 0..npts {
        let s =
            m[0] * y0[i] + m[1] * y1[i] + m[2] * y2[i] + m[3] * y3[i] + m[4] * y4[i] + m[5] * y5[i];
        inside32 += u32::from(s <= limit32);
    }
    inside32
}

/// How many of the `npts` points (by coordinate) have `n · x ≤ limit`.
#[inline]
fn count_below(n: &P, x: [&[f64]; D], npts: usize, limit: f64) -> usize {
    let [x0, x1, x2, x3, x4, x5] = x;
    let mut inside = 0;
    for i in 0..npts {
        let s =
            n[0] * x0[i] + n[1] * x1[i] + n[2] * x2[i] + n[3] * x3[i] + n[4] * x4[i] + n[5] * x5[i];
        inside += usize::from(s <= limit);
    }
    inside
}

impl Build {
    /// The hull's volume and the least offset of a facet's hyperplane, once [`Build::check`]
    /// is done (what [`Hull::volume`] and the least of [`Hull::facets`]' offsets say).
    pub(super) fn metrics(&self) -> Option<(f64, f64)> {
        self.checks
            .as_ref()
            .filter(|c| c.listed >= self.buffers.topo.len() && c.measured >= c.live.len())
            .map(|c| (c.volume / 720.0, c.min_offset))
    }

    /// The hull, once [`Build::check`] is done.
    pub(super) fn into_hull(self) -> Hull {
        #[cfg(test)]
        let interior = self.interior;
        Hull {
            buffers: self.buffers,
            #[cfg(test)]
            interior,
        }
    }
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
    fn a_build_a_unit_at_a_time_stops_in_every_phase_and_is_the_build_in_one_go() {
        // 120 points spread in six dimensions (a fixed xorshift sequence): rounds that see
        // many facets.
        let mut x = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let pts: Vec<P> = (0..120).map(|_| P::from_fn(|_, _| next())).collect();
        let whole = build(&pts, 1e-9).unwrap();
        let mut b = start(&pts, 1e-9).unwrap();
        let mut stopped = Vec::new();
        let mut calls = 0;
        while !b.advance(&pts, 1).unwrap() {
            calls += 1;
            let here = std::mem::discriminant(&b.step);
            if !stopped.contains(&here) {
                stopped.push(here);
            }
        }
        // Choose, Assign, Between, Visible, Facets, Pair and Move.
        assert_eq!(stopped.len(), 7, "{calls} calls");
        let mut checks = 0;
        while !b.check(&pts, 1).unwrap() {
            checks += 1;
        }
        assert!(checks > 10, "{checks}");
        let parts = b.into_hull();
        assert_eq!(parts.volume().to_bits(), whole.volume().to_bits());
        let bits = |h: &Hull| -> Vec<u64> { h.facets().map(|f| f.d.to_bits()).collect() };
        assert_eq!(bits(&parts), bits(&whole));
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
