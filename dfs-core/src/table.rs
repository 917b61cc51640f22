//! The table: a horizontal plane that pushes on an object only where the object touches it.
//!
//! **Model.** The object touches the table at its lowest points ([`Shape::table_points`]: a
//! sphere's lowest point; a box's corners, the 4 of the face it stands on, 2 of an edge, 1 of
//! a corner; a cylinder's rim points, the 12-gon inscribed in the end face it stands on, the
//! line it lies on, the rim point it rocks on). The table's impulse over a tick is found so
//! that the object's velocities after the tick are admissible, a velocity-level
//! complementarity problem, in four parts solved in turn until they agree (block
//! Gauss-Seidel, each block exactly):
//!
//! - **normal**: each point `k` takes an impulse `λ_k ≥ 0` along the table's normal and does
//!   not move into the table farther than its gap `d_k`: `u_k ≥ −d_k / dt`, with equality where
//!   `λ_k > 0`. A point still above the table is a *speculative* contact: it takes force only on
//!   the tick it would reach the table, and lands on it exactly (the impact is inelastic, no
//!   bounce). The points' normal velocities depend on the object's motion through three numbers
//!   only (its vertical velocity and its angular velocity about the two horizontal axes), so
//!   the block is a least-distance problem in three dimensions, solved exactly by
//!   non-negative least squares (`least_distance`) however many points share a face;
//! - **friction**: one tangential impulse at the centre of pressure `Σ λ_k p_k / Σ λ_k`, inside
//!   Coulomb's disc `|f_t| ≤ μ N`: it stops the slip there when the disc allows, else is the
//!   largest against the slip it leaves (maximal dissipation, `Metric::project`);
//! - **torsion**: a couple about the normal, at most `μ N ρ`, with `ρ` 2/3 of the touching
//!   points' mean distance from the centre of pressure (exact for a disc under even pressure);
//! - **rolling resistance** (a sphere, a cylinder lying or on its rim): a couple of at most
//!   [`rolling`](Table::rolling) × N about the horizontal axes, and as much again about the
//!   normal, stops it rolling or spinning on the spot (a 4 cm ball bumped at 0.1 m/s rolls
//!   about 1.5 cm).
//!
//! The resulting wrench is only what the points can give: its centre of pressure lies in their
//! support polygon, so an object tips when the line of its weight (with the other forces)
//! leaves the polygon, and rests flat on a face otherwise. The solve starts from the last
//! tick's impulses ([`TableSupport`], warm start): a resting object takes one sweep. Being
//! impulses over the tick rather than springs, the supports are rigid and stable at any mass
//! and step: the object's step under them is exactly the velocity they were solved for. A point
//! found below the table after the step (from the rotation's curvature within the tick, or an
//! object put into the table) is lifted out by moving the object up ([`Table::lift_out`]),
//! without changing its velocity.
//!
//! Deterministic (fixed point order, fixed iteration rules) and allocation-free.

use crate::math::{force_of, moment_of, wrench, Mat3, Real, Rotation, Vector, Wrench};
use crate::object::{ObjectState, RigidObject, Shape, TablePoint, MAX_TABLE_POINTS};
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

/// How far above the table (m) a point of the object is taken as a speculative contact, at
/// least: 5 mm (more for a fast object: twice the distance its fastest point moves in a tick).
pub const SUPPORT_MARGIN: Real = 5e-3;

/// A point less than this (m) above the table touches it: 1 nm. Without it, a resting
/// object's points, a rounding error (1e-13 m) above the table, would each tick be let fall
/// onto it at that error over the tick (1e-10 m/s), a jitter of the speeds at that level.
pub const TOUCHING_GAP: Real = 1e-9;

/// Most block sweeps per tick: 40. Fewer when the impulses settle first (a resting object's,
/// warm-started, in one; a landing's in a few).
pub const MAX_SWEEPS: usize = 40;

/// A sweep that changed the object's velocity by less than this (m/s, or rad/s times the
/// object's bounding radius) ends the solve: 1e-10.
pub const SETTLED_VELOCITY: Real = 1e-10;

/// The lever of the table's torsional friction as a share of the touching points' mean
/// distance from the centre of pressure: 2/3, the lever of a disc under even pressure (whose
/// rim the points of a standing cylinder are).
pub const TORSION_LEVER: Real = 2.0 / 3.0;

/// A horizontal table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Table {
    /// Height of its top (m, world z).
    pub height: Real,
    /// Coulomb coefficient between object and table.
    pub mu: Real,
    /// Rolling resistance of a sphere, or a cylinder lying or on its rim, as the lever (m) of
    /// the couple that resists rolling and spinning: at most `rolling × N`.
    pub rolling: Real,
}

/// An impulse on the object: linear (N·s) and angular about its centre (N·m·s), world.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Impulse {
    linear: Vector,
    angular: Vector,
}

impl Impulse {
    const ZERO: Impulse = Impulse {
        linear: Vector::new(0.0, 0.0, 0.0),
        angular: Vector::new(0.0, 0.0, 0.0),
    };

    /// `p` at the point `r` from the centre.
    fn at(r: &Vector, p: Vector) -> Impulse {
        Impulse {
            linear: p,
            angular: r.cross(&p),
        }
    }

    /// A couple `l`.
    fn couple(l: Vector) -> Impulse {
        Impulse {
            linear: Vector::zeros(),
            angular: l,
        }
    }
}

/// The table's contact with one object carried from tick to tick: the last tick's impulses,
/// from which the next tick's solve starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableSupport {
    /// The normal impulses' sum (world).
    normal: Impulse,
    /// Friction (world x, y; N·s) and torsion (world z; N·m·s).
    friction: Vector,
    /// Where the friction acted: the centre of pressure in B (m).
    pressure_b: Vector,
    /// The rolling resistance's couple (world x, y; N·m·s).
    rolling: Vector2<Real>,
    /// Each support point's normal impulse (N·s), by [`TablePoint::id`].
    normals: [Real; MAX_TABLE_POINTS],
    sweeps: usize,
}

impl Default for TableSupport {
    fn default() -> Self {
        TableSupport {
            normal: Impulse::ZERO,
            friction: Vector::zeros(),
            pressure_b: Vector::zeros(),
            rolling: Vector2::zeros(),
            normals: [0.0; MAX_TABLE_POINTS],
            sweeps: 0,
        }
    }
}

impl TableSupport {
    /// Forgets the last tick's impulses (the object left the table, or was put somewhere).
    pub fn clear(&mut self) {
        *self = TableSupport::default();
    }

    /// The last tick's normal impulse (N·s) at the support point `id` ([`TablePoint::id`]):
    /// zero for a point that did not push.
    pub fn normal_impulse(&self, id: usize) -> Real {
        self.normals.get(id).copied().unwrap_or(0.0)
    }

    /// How many block sweeps the last solve took (0 when the object was off the table).
    pub fn sweeps(&self) -> usize {
        self.sweeps
    }
}

/// The object's velocities (world linear, world angular) while impulses act on it.
struct Velocities<'a> {
    v: Vector,
    w: Vector,
    inv_mass: Real,
    inv_inertia_w: &'a Mat3,
}

impl Velocities<'_> {
    /// Adds `sign` × the impulse `i`.
    fn apply(&mut self, i: &Impulse, sign: Real) {
        self.v += i.linear * (self.inv_mass * sign);
        self.w += self.inv_inertia_w * i.angular * sign;
    }

    /// The velocity (world) of the point at `r` from the centre.
    fn at(&self, r: &Vector) -> Vector {
        self.v + self.w.cross(r)
    }
}

impl Table {
    /// The table's wrench on the object (B, at its centre) for this tick of length `dt`, given
    /// every other force on it `f_b` (B, the wrench [`integrate`](crate::object::integrate)
    /// would step it by: gravity, the hand, the gyroscopic term): zero when no point of it is
    /// within the margin of the table. Updates `support`'s warm start.
    pub fn support_wrench_b(
        &self,
        support: &mut TableSupport,
        object: &RigidObject,
        state: &ObjectState,
        f_b: &Wrench,
        dt: Real,
    ) -> Wrench {
        let rotation = state.pose.rotation;
        let shape = &object.shape;
        let size = shape.bounding_radius();
        let lowest = state.pose.translation.z - shape.support_depth(&rotation) - self.height;
        let speed = state.linear_velocity.norm() + state.angular_velocity_b.norm() * size;
        let margin = SUPPORT_MARGIN.max(2.0 * speed * dt);
        if lowest > margin {
            support.clear();
            return Wrench::zeros();
        }
        let mut found = [TablePoint::default(); MAX_TABLE_POINTS];
        let n = shape.table_points(&rotation, margin - lowest, &mut found);
        let found = &found[..n];
        let rot = rotation.to_rotation_matrix();
        let inv_inertia_w = rot * object.inertia_inv * rot.transpose();
        let inv_mass = 1.0 / object.mass;
        // The velocities after the tick under the other forces alone.
        let mut vel = Velocities {
            v: state.linear_velocity + rotation * force_of(f_b) * (dt * inv_mass),
            w: rotation * (state.angular_velocity_b + object.inertia_inv * moment_of(f_b) * dt),
            inv_mass,
            inv_inertia_w: &inv_inertia_w,
        };
        let mut rows = Rows::ZERO;
        rows.fill(self.height, state, found, &vel, dt);
        let rolling = Rolling::new(self, shape, found, &inv_inertia_w);
        let mut imp = Impulses::warm_start(support, &rotation, rolling.rolls);
        for i in [&imp.normal, &imp.friction, &imp.torsion, &imp.rolling] {
            vel.apply(i, 1.0);
        }
        support.sweeps = 0;
        for _ in 0..MAX_SWEEPS {
            support.sweeps += 1;
            let before = (vel.v, vel.w);
            self.sweep(&rows, &rolling, &mut imp, &mut vel);
            let change = (vel.v - before.0).norm() + (vel.w - before.1).norm() * size;
            if change < SETTLED_VELOCITY {
                break;
            }
        }
        imp.store(support, found, &rotation);
        imp.wrench_b(&rotation, dt)
    }

    /// One sweep of the blocks, each solved exactly with the others held: normal, friction at
    /// the centre of pressure, torsion, rolling resistance.
    #[inline]
    fn sweep(&self, rows: &Rows, rolling: &Rolling, imp: &mut Impulses, vel: &mut Velocities<'_>) {
        let (total, lever) = normal_block(rows, imp, vel);
        self.friction_block(total, imp, vel);
        self.torsion_block(total, lever, rolling.rolls, imp, vel);
        if rolling.rolls {
            self.rolling_block(total, rolling, imp, vel);
        }
    }

    /// Friction at the centre of pressure under the normal impulses' sum `total`: it stops
    /// the slip there when Coulomb's disc allows, else the largest against the slip.
    #[inline]
    fn friction_block(&self, total: Real, imp: &mut Impulses, vel: &mut Velocities<'_>) {
        let (ii, inv_mass) = (vel.inv_inertia_w, vel.inv_mass);
        vel.apply(&imp.friction, -1.0);
        let rx = imp.pressure.cross_matrix();
        let k = Mat3::identity() * inv_mass - rx * ii * rx;
        let k_t = Matrix2::new(k[(0, 0)], k[(0, 1)], k[(1, 0)], k[(1, 1)]);
        let u = vel.at(&imp.pressure);
        let stop = -(k_t.try_inverse().unwrap_or_else(Matrix2::zeros) * u.xy());
        let f = Metric::of(&k_t).project(stop, self.mu * total);
        imp.friction = Impulse::at(&imp.pressure, Vector::new(f.x, f.y, 0.0));
        vel.apply(&imp.friction, 1.0);
    }

    /// Torsion: a couple about the normal stopping the spin, at most `μ N` times the `lever`
    /// (and the rolling resistance's lever when the object `rolls`).
    #[inline]
    fn torsion_block(
        &self,
        total: Real,
        lever: Real,
        rolls: bool,
        imp: &mut Impulses,
        vel: &mut Velocities<'_>,
    ) {
        let ii = vel.inv_inertia_w;
        vel.apply(&imp.torsion, -1.0);
        let resist = total * (self.mu * lever + if rolls { self.rolling } else { 0.0 });
        let spin = if ii[(2, 2)] > 0.0 {
            (-vel.w.z / ii[(2, 2)]).clamp(-resist, resist)
        } else {
            0.0
        };
        imp.torsion = Impulse::couple(Vector::new(0.0, 0.0, spin));
        vel.apply(&imp.torsion, 1.0);
    }

    /// Rolling resistance: a couple about the horizontal axes stopping the rolling, at most
    /// [`rolling`](Table::rolling) × N.
    #[inline]
    fn rolling_block(
        &self,
        total: Real,
        rolling: &Rolling,
        imp: &mut Impulses,
        vel: &mut Velocities<'_>,
    ) {
        vel.apply(&imp.rolling, -1.0);
        let stop = -(rolling.inertia * vel.w.xy());
        let l = rolling.metric.project(stop, self.rolling * total);
        imp.rolling = Impulse::couple(Vector::new(l.x, l.y, 0.0));
        vel.apply(&imp.rolling, 1.0);
    }

    /// Lifts an object whose lowest point is below the table until it touches it; its
    /// velocity is left as it is (the support's impulses already stopped it going down).
    pub fn lift_out(&self, shape: &Shape, state: &mut ObjectState) {
        let depth = shape.support_depth(&state.pose.rotation);
        let z = &mut state.pose.translation.z;
        if *z - depth < self.height {
            *z = self.height + depth;
        }
    }
}

/// The rows of a tick's blocks, one per point of the object that may touch the table.
struct Rows {
    /// How many points.
    n: usize,
    /// Each point from the centre (world) and the least normal velocity it may have.
    r: [Vector; MAX_TABLE_POINTS],
    least: [Real; MAX_TABLE_POINTS],
    /// The normal block's constraint rows `Lᵀ a_k` ([`Rows::fill`]).
    g: [Vector; MAX_TABLE_POINTS],
}

impl Rows {
    /// No rows, to be filled ([`Rows::fill`]) where they stay.
    const ZERO: Rows = Rows {
        n: 0,
        r: [Vector::new(0.0, 0.0, 0.0); MAX_TABLE_POINTS],
        least: [0.0; MAX_TABLE_POINTS],
        g: [Vector::new(0.0, 0.0, 0.0); MAX_TABLE_POINTS],
    };

    /// The rows of the points `found` of an object in `state` (its velocities `vel` for the
    /// inverse mass and inertia) on a table at `height`, for a tick of `dt`.
    #[inline]
    fn fill(
        &mut self,
        height: Real,
        state: &ObjectState,
        found: &[TablePoint],
        vel: &Velocities<'_>,
        dt: Real,
    ) {
        let n = found.len();
        let rotation = state.pose.rotation;
        let (ii, inv_mass) = (vel.inv_inertia_w, vel.inv_mass);
        let (r, least) = (&mut self.r, &mut self.least);
        self.n = n;
        for (k, p) in found.iter().enumerate() {
            r[k] = rotation * p.p_b;
            let gap = state.pose.translation.z + r[k].z - height;
            least[k] = if gap > TOUCHING_GAP { -gap / dt } else { 0.0 };
        }
        // The normal block in the coordinates s = (v_z, ω_x, ω_y), on which a point's normal
        // velocity a_k · s depends (a_k = (1, r_y, −r_x)); a normal wrench w moves s by G w,
        // G = diag(1/m, I⁻¹ of the horizontal axes) = L Lᵀ. With s = s₀ + L x the block is
        // min |x| subject to (Lᵀ a_k) · x ≥ least_k − a_k · s₀.
        let l00 = inv_mass.sqrt();
        let l11 = ii[(0, 0)].sqrt();
        let l21 = ii[(1, 0)] / l11;
        let l22 = (ii[(1, 1)] - l21 * l21).max(0.0).sqrt();
        for (gk, rk) in self.g.iter_mut().zip(&self.r[..n]) {
            *gk = Vector::new(l00, l11 * rk.y - l21 * rk.x, -l22 * rk.x);
        }
    }

    /// The normal velocity of point `k` (a_k · s).
    #[inline]
    fn normal_velocity(&self, k: usize, vel: &Velocities<'_>) -> Real {
        let r = &self.r;
        vel.v.z + r[k].y * vel.w.x - r[k].x * vel.w.y
    }
}

/// Whether the object rolls on its points, and the rolling resistance block's inertia and
/// metric (about the horizontal axes).
struct Rolling {
    rolls: bool,
    inertia: Matrix2<Real>,
    metric: Metric,
}

impl Rolling {
    /// Rolling of `shape` on its points `found` on `table`, its inverse inertia (world)
    /// `ii`.
    #[inline]
    fn new(table: &Table, shape: &Shape, found: &[TablePoint], ii: &Mat3) -> Rolling {
        let rolls = table.rolling > 0.0 && shape.rolls_on(found);
        let roll_compliance = Matrix2::new(ii[(0, 0)], ii[(0, 1)], ii[(1, 0)], ii[(1, 1)]);
        Rolling {
            rolls,
            inertia: roll_compliance.try_inverse().unwrap_or_else(Matrix2::zeros),
            metric: Metric::of(&roll_compliance),
        }
    }
}

/// The table's impulses over the tick while the blocks are solved for them.
struct Impulses {
    normal: Impulse,
    friction: Impulse,
    torsion: Impulse,
    rolling: Impulse,
    /// Where the friction acts: the centre of pressure (world, from the object's centre).
    pressure: Vector,
    /// Each point's normal impulse.
    lambda: [Real; MAX_TABLE_POINTS],
}

impl Impulses {
    /// The last tick's impulses from `support`, for an object turned by `rotation` that
    /// `rolls` (else without rolling resistance).
    #[inline]
    fn warm_start(support: &TableSupport, rotation: &Rotation, rolls: bool) -> Impulses {
        let pressure = rotation * support.pressure_b;
        Impulses {
            normal: support.normal,
            friction: Impulse::at(
                &pressure,
                Vector::new(support.friction.x, support.friction.y, 0.0),
            ),
            torsion: Impulse::couple(Vector::new(0.0, 0.0, support.friction.z)),
            rolling: if rolls {
                Impulse::couple(Vector::new(support.rolling.x, support.rolling.y, 0.0))
            } else {
                Impulse::ZERO
            },
            pressure,
            lambda: [0.0; MAX_TABLE_POINTS],
        }
    }

    /// Keeps the impulses in `support` for the next tick's warm start (`found` the points
    /// they were solved on), with its count of sweeps.
    #[inline]
    fn store(&self, support: &mut TableSupport, found: &[TablePoint], rotation: &Rotation) {
        let sweeps = support.sweeps;
        *support = TableSupport {
            normal: self.normal,
            friction: Vector::new(
                self.friction.linear.x,
                self.friction.linear.y,
                self.torsion.angular.z,
            ),
            pressure_b: rotation.inverse() * self.pressure,
            rolling: self.rolling.angular.xy(),
            normals: [0.0; MAX_TABLE_POINTS],
            sweeps,
        };
        for (p, l) in found.iter().zip(&self.lambda[..found.len()]) {
            support.normals[p.id] = *l;
        }
    }

    /// Their sum as a wrench over the tick `dt` (B, at the centre) on an object turned by
    /// `rotation`.
    #[inline]
    fn wrench_b(&self, rotation: &Rotation, dt: Real) -> Wrench {
        let force = self.normal.linear + self.friction.linear;
        let moment = self.normal.angular
            + self.friction.angular
            + self.torsion.angular
            + self.rolling.angular;
        let to_b = rotation.inverse();
        wrench(&(to_b * force / dt), &(to_b * moment / dt))
    }
}

/// The normal block: each point's impulse `λ_k ≥ 0` so that it does not move into the table
/// farther than its gap (a least-distance problem); the impulses' sum and the torsion's lever
/// about the centre of pressure (the touching points' mean distance from it, times
/// [`TORSION_LEVER`]; 0 without touching points).
#[inline]
fn normal_block(rows: &Rows, imp: &mut Impulses, vel: &mut Velocities<'_>) -> (Real, Real) {
    let n = rows.n;
    let (r, least) = (&rows.r, &rows.least);
    let lambda = &mut imp.lambda;
    let mut h = [0.0; MAX_TABLE_POINTS];
    vel.apply(&imp.normal, -1.0);
    for k in 0..n {
        h[k] = least[k] - rows.normal_velocity(k, vel);
    }
    if !least_distance(&rows.g[..n], &h[..n], &mut lambda[..n]) {
        lambda[..n].fill(0.0);
    }
    let total: Real = lambda[..n].iter().sum();
    let mut moment = Vector::zeros();
    let mut centre = Vector::zeros();
    for (l, rk) in lambda[..n].iter().zip(&r[..n]) {
        moment += Vector::new(rk.y, -rk.x, 0.0) * *l;
        centre += rk * *l;
    }
    imp.normal = Impulse {
        linear: Vector::new(0.0, 0.0, total),
        angular: moment,
    };
    vel.apply(&imp.normal, 1.0);
    let mut lever = 0.0;
    if total > 0.0 {
        imp.pressure = centre / total;
        // The points touching after it: those moving at their least normal velocity.
        let (mut sum, mut count) = (0.0, 0);
        for k in 0..n {
            let u = rows.normal_velocity(k, vel);
            if u - least[k] <= 1e-9 {
                sum += (r[k] - imp.pressure).xy().norm();
                count += 1;
            }
        }
        if count > 0 {
            lever = TORSION_LEVER * sum / count as Real;
        }
    }
    (total, lever)
}

/// Least-distance programming (Lawson and Hanson, *Solving Least Squares Problems*, 1974,
/// ch. 23): the multipliers `λ ≥ 0` of `min |x|` subject to `g_k · x ≥ h_k`, whose solution
/// is `x = Σ λ_k g_k`, written to `lambda`. Solved as the non-negative least squares problem
/// `min |E u − (0, 0, 0, 1)|`, `u ≥ 0`, with columns `E_k = (g_k, h_k)`, by Lawson and
/// Hanson's active set method (finite; at most 4 columns are ever active); `λ = u / (1 − h·u)`.
/// Columns that depend on the active ones (points on one line with others, a rim point
/// where another is) are passed over. False when the constraints cannot all hold (not for a
/// table: an object can always move up).
fn least_distance(g: &[Vector], h: &[Real], lambda: &mut [Real]) -> bool {
    let n = g.len();
    let col = |k: usize| Vector4::new(g[k].x, g[k].y, g[k].z, h[k]);
    let f = Vector4::new(0.0, 0.0, 0.0, 1.0);
    let scale = (0..n).map(|k| col(k).norm()).fold(1.0, Real::max);
    let tol = 1e-13 * scale;
    let mut u = [0.0; MAX_TABLE_POINTS];
    let mut active = [false; MAX_TABLE_POINTS];
    let mut passed = [false; MAX_TABLE_POINTS];
    let residual = |u: &[Real; MAX_TABLE_POINTS]| {
        (0..n).fold(f, |r, k| if u[k] > 0.0 { r - col(k) * u[k] } else { r })
    };
    for _ in 0..3 * n + 4 {
        let res = residual(&u);
        let mut best = None;
        let mut most = tol;
        for k in 0..n {
            if !active[k] && !passed[k] {
                let w = col(k).dot(&res);
                if w > most {
                    most = w;
                    best = Some(k);
                }
            }
        }
        let Some(t) = best else { break };
        active[t] = true;
        let mut first = true;
        for _ in 0..=n {
            let Some(z) = least_squares_on(&active[..n], &col, &f) else {
                // t depends on the active columns.
                active[t] = false;
                passed[t] = true;
                break;
            };
            if first && z[t] <= 0.0 {
                active[t] = false;
                passed[t] = true;
                break;
            }
            first = false;
            if (0..n).all(|k| !active[k] || z[k] > 0.0) {
                u[..n].copy_from_slice(&z[..n]);
                break;
            }
            let mut alpha: Real = 1.0;
            for k in 0..n {
                if active[k] && z[k] <= 0.0 {
                    alpha = alpha.min(u[k] / (u[k] - z[k]));
                }
            }
            for k in 0..n {
                if active[k] {
                    u[k] += alpha * (z[k] - u[k]);
                    if u[k] <= 0.0 || (z[k] <= 0.0 && u[k] <= tol * 1e-3) {
                        u[k] = 0.0;
                        active[k] = false;
                        // The active set changed: a passed-over column may be independent now.
                        passed = [false; MAX_TABLE_POINTS];
                    }
                }
            }
        }
    }
    // The residual f − E u; its last entry is 1 − h·u.
    let denom = residual(&u).w;
    if denom <= 1e-14 {
        return false;
    }
    for (l, uk) in lambda.iter_mut().zip(&u[..n]) {
        *l = uk / denom;
    }
    true
}

/// The least-squares solution `z` (zero off the active columns) of `E_A z = f` over the
/// active columns (at most 4) of `col`; `None` when they are (nearly) dependent.
fn least_squares_on(
    active: &[bool],
    col: &impl Fn(usize) -> Vector4<Real>,
    f: &Vector4<Real>,
) -> Option<[Real; MAX_TABLE_POINTS]> {
    let mut idx = [0usize; 4];
    let mut m = 0;
    for (k, &a) in active.iter().enumerate() {
        if a {
            if m == 4 {
                return None;
            }
            idx[m] = k;
            m += 1;
        }
    }
    // Modified Gram-Schmidt QR (not the normal equations, which square the condition number
    // and leave a resting box's impulses 1e-10 off from tick to tick); a column with less
    // than 1e-9 of its length outside the others' span depends on them.
    let mut q = [Vector4::<Real>::zeros(); 4];
    let mut rr = Matrix4::<Real>::zeros();
    for j in 0..m {
        let c = col(idx[j]);
        let mut v = c;
        for i in 0..j {
            rr[(i, j)] = q[i].dot(&v);
            v -= q[i] * rr[(i, j)];
        }
        let len = v.norm();
        if len <= 1e-9 * c.norm() {
            return None;
        }
        rr[(j, j)] = len;
        q[j] = v / len;
    }
    let mut x = [0.0; 4];
    for i in (0..m).rev() {
        let qf = q[i].dot(f);
        x[i] = (qf - (i + 1..m).map(|p| rr[(i, p)] * x[p]).sum::<Real>()) / rr[(i, i)];
    }
    let mut z = [0.0; MAX_TABLE_POINTS];
    for i in 0..m {
        z[idx[i]] = x[i];
    }
    Some(z)
}

/// A 2×2 symmetric positive definite matrix by its eigenvalues and eigenvectors: the metric in
/// which [`Metric::project`] projects onto a disc.
#[derive(Debug, Clone, Copy)]
struct Metric {
    /// Eigenvalues.
    k: [Real; 2],
    /// Unit eigenvectors, columns.
    q: Matrix2<Real>,
}

impl Metric {
    fn of(m: &Matrix2<Real>) -> Metric {
        let (a, b, c) = (m[(0, 0)], 0.5 * (m[(0, 1)] + m[(1, 0)]), m[(1, 1)]);
        let mean = 0.5 * (a + c);
        let d = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let (k1, k2) = (mean + d, mean - d);
        // The eigenvector of k1 from the row of (M − k1 I) with more in it.
        let v = if (a - k1).abs() >= (c - k1).abs() {
            Vector2::new(b, k1 - a)
        } else {
            Vector2::new(k1 - c, b)
        };
        let n = v.norm();
        let v = if n > 0.0 {
            v / n
        } else {
            Vector2::new(1.0, 0.0)
        };
        Metric {
            k: [k1, k2.max(k1 * 1e-12)],
            q: Matrix2::new(v.x, -v.y, v.y, v.x),
        }
    }

    /// The point of the disc `|x| ≤ limit` nearest `stop` in this metric: `stop` itself inside
    /// the disc, else `(M + νI)⁻¹ M stop` on its edge (ν ≥ 0 by Newton's method on the secular
    /// equation, which from ν = 0 approaches its root from one side).
    ///
    /// With `M` a contact's tangential compliance (its `K` block) and `stop` the impulse that
    /// would stop its slip, the answer is Coulomb's law with maximal dissipation: the friction
    /// stops the slip when the disc allows, else is the largest the disc allows against the
    /// slip velocity it leaves (`u = M (x − stop) = −ν x`), which the plain projection onto the
    /// disc is not when the point is easier to push one way than another.
    fn project(&self, stop: Vector2<Real>, limit: Real) -> Vector2<Real> {
        if stop.norm_squared() <= limit * limit {
            return stop;
        }
        if limit <= 0.0 {
            return Vector2::zeros();
        }
        let s = self.q.transpose() * stop;
        let ks = [self.k[0] * s.x, self.k[1] * s.y];
        let mut nu: Real = 0.0;
        for _ in 0..30 {
            let x = [ks[0] / (self.k[0] + nu), ks[1] / (self.k[1] + nu)];
            let f = x[0] * x[0] + x[1] * x[1] - limit * limit;
            if f <= limit * limit * 1e-12 {
                break;
            }
            let df = -2.0 * (x[0] * x[0] / (self.k[0] + nu) + x[1] * x[1] / (self.k[1] + nu));
            nu -= f / df;
        }
        let x = Vector2::new(ks[0] / (self.k[0] + nu), ks[1] / (self.k[1] + nu));
        // Newton stops a hair outside the disc: onto its edge.
        let x = x * (limit / x.norm()).min(1.0);
        self.q * x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_distance_finds_the_nearest_point_of_a_polyhedron() {
        // x ≥ 1 and y ≥ 2 (z free): the nearest point to the origin is (1, 2, 0), held by both.
        let g = [Vector::x(), Vector::y(), -Vector::x()];
        let h = [1.0, 2.0, -5.0];
        let mut lambda = [0.0; 3];
        assert!(least_distance(&g, &h, &mut lambda));
        let x: Vector = g.iter().zip(&lambda).map(|(g, l)| g * *l).sum();
        assert!((x - Vector::new(1.0, 2.0, 0.0)).norm() < 1e-12, "{x:?}");
        assert_eq!(lambda[2], 0.0, "x ≤ 5 does not hold it");
        // Already satisfied: nothing.
        let mut lambda = [1.0; 2];
        assert!(least_distance(&g[..2], &[-1.0, 0.0], &mut lambda));
        assert_eq!(lambda, [0.0, 0.0]);
        // The same constraint twice and one on a line with others: passed over, same answer.
        let g = [
            Vector::x(),
            Vector::x(),
            Vector::new(1.0, 1.0, 0.0),
            Vector::y(),
        ];
        let h = [1.0, 1.0, 3.0, 2.0];
        let mut lambda = [0.0; 4];
        assert!(least_distance(&g, &h, &mut lambda));
        let x: Vector = g.iter().zip(&lambda).map(|(g, l)| g * *l).sum();
        assert!((x - Vector::new(1.0, 2.0, 0.0)).norm() < 1e-12, "{x:?}");
        // Infeasible: x ≥ 1 and −x ≥ 0.
        assert!(!least_distance(
            &[Vector::x(), -Vector::x()],
            &[1.0, 0.0],
            &mut [0.0; 2]
        ));
    }

    #[test]
    fn friction_beyond_the_disc_opposes_the_slip_it_leaves() {
        let m = Matrix2::new(3.0, 1.0, 1.0, 1.5);
        let metric = Metric::of(&m);
        // Inside: unchanged.
        let stop = Vector2::new(0.3, -0.2);
        assert_eq!(metric.project(stop, 1.0), stop);
        // Outside: on the edge, and the slip it leaves, M (x − stop), points against it.
        let stop = Vector2::new(2.0, -1.0);
        let x = metric.project(stop, 1.0);
        assert!((x.norm() - 1.0).abs() < 1e-9, "{x:?}");
        let slip = m * (x - stop);
        let cos = slip.dot(&x) / (slip.norm() * x.norm());
        assert!((cos + 1.0).abs() < 1e-9, "{cos}");
    }
}
