//! Varied reaches (`vary_reach`): the home, bend, speed and pause of each approach, drawn from
//! the seed and checked against the table and the objects (see the module docs of
//! [`super`]).

use super::{raise, TICK_NS};
use crate::dfs::DfsObject;
use crate::hand::{HandModel, Kinematics, MAX_DOF};
use crate::math::{Isometry, Point, Real, Rotation, Vector};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// The minimum-jerk profile at `t` ([`crate::min_jerk::progress`]) and its second derivative.
pub(super) fn min_jerk(t: Real) -> (Real, Real) {
    (
        crate::min_jerk::progress(t),
        crate::min_jerk::acceleration(t),
    )
}

/// The ChaCha8 stream of the scenario's seed that varied reaches draw from (`vary_reach`);
/// the tremor and the sensor noise draw from stream 0, so they stay those of the seed.
pub const REACH_STREAM: u64 = 1;

/// Range of a varied reach's speed factor `s`: its `approach` and the `preshape` after it take
/// their script durations / `s`.
pub const REACH_SPEED: (Real, Real) = (0.7, 1.3);

/// Largest bend of a varied reach off its straight line, as a fraction of its length (the
/// bend is drawn uniformly from 0 to this).
pub const REACH_BEND: Real = 0.3;

/// Chance that a varied reach pauses part-way.
pub const REACH_PAUSE_CHANCE: Real = 0.5;

/// Range of a varied reach's pause (s).
pub const REACH_PAUSE_S: (Real, Real) = (0.1, 0.3);

/// Range of where a varied reach pauses: the fraction of its path (and of its moving time)
/// before the pause.
pub const REACH_PAUSE_AT: (Real, Real) = (0.3, 0.7);

/// Range of the distance (m) of a varied start (the home) from the first approach pose.
pub const REACH_HOME_M: (Real, Real) = (0.25, 0.40);

/// Range of the elevation (rad) of the home above the first approach pose: 15° to 60°.
pub const REACH_HOME_ELEVATION: (Real, Real) =
    (std::f64::consts::PI / 12.0, std::f64::consts::PI / 3.0);

/// Largest azimuth (rad) of the home about the horizontal direction from the target to the
/// first approach pose: ±90°, the half-circle on the side the hand approaches from.
pub const REACH_HOME_AZIMUTH: Real = std::f64::consts::FRAC_PI_2;

/// Largest turn (rad) of the hand at its home about the vertical, from its grasp orientation
/// (it turns back during the first approach).
pub const REACH_HOME_YAW: Real = 0.4;

/// Clearance (m) a varied reach keeps between the open hand and the table or any object, or
/// at least what it keeps at the reach's ends (the approach pose is beside the target).
pub const REACH_CLEARANCE_M: Real = 0.02;

/// Least height (m) of the hand's base at its home above the table's top.
pub const REACH_HOME_ABOVE_TABLE_M: Real = 0.05;

/// Fraction of a varied reach's path over which the fingers of the grasp keep the open hand's
/// posture; over the rest they go over (a minimum-jerk blend of the two controls) to reaching
/// for their spots on the object, as they do throughout a reach that is not varied. (Reaching
/// for spots from afar pulls the thumb down and sideways by up to 10 cm, into whatever lies
/// under the path.)
pub const REACH_SHAPE_FROM: Real = 0.6;

/// Homes drawn before the fixed start (0.15 m above the approach pose) is used.
pub(super) const HOME_TRIES: usize = 16;

/// Bends tried (each redrawn smaller) before the straight line is used.
pub(super) const BEND_TRIES: usize = 8;

/// Points along a reach at which its clearance is checked.
pub(super) const CLEARANCE_SAMPLES: usize = 48;

/// The seeded variation of one `approach` task, drawn when the simulation is set up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Reach {
    /// Speed factor ([`REACH_SPEED`]).
    pub(super) speed: Real,
    /// Moving time (s, whole ticks), the pause excluded.
    pub(super) move_s: Real,
    /// The pause (s, whole ticks; 0 for none).
    pub(super) pause_s: Real,
    /// Fraction of the path, and of the moving time, before the pause.
    pub(super) pause_at: Real,
    /// The first bend to try: fraction of the length ([`REACH_BEND`]).
    pub(super) bend: Real,
    /// ... and its direction about the line (rad, 0 to π: sideways, up, other side).
    pub(super) bend_angle: Real,
}

impl Reach {
    /// Draws a reach for an `approach` of `duration` s: speed, pause and bend.
    pub(super) fn draw(rng: &mut ChaCha8Rng, duration: Real) -> Reach {
        let speed = rng.random_range(REACH_SPEED.0..=REACH_SPEED.1);
        let pauses = rng.random::<Real>() < REACH_PAUSE_CHANCE;
        let pause_s = rng.random_range(REACH_PAUSE_S.0..=REACH_PAUSE_S.1);
        let pause_at = rng.random_range(REACH_PAUSE_AT.0..=REACH_PAUSE_AT.1);
        let bend = rng.random_range(0.0..=REACH_BEND);
        let bend_angle = rng.random_range(0.0..=std::f64::consts::PI);
        Reach {
            speed,
            move_s: whole_ticks_ns(duration / speed).max(TICK_NS) as Real * 1e-9,
            pause_s: if pauses {
                whole_ticks_ns(pause_s) as Real * 1e-9
            } else {
                0.0
            },
            pause_at,
            bend,
            bend_angle,
        }
    }

    /// The path parameter `u` (0 to 1) at `t` s into the reach, with `du/dt` and `d²u/dt²`:
    /// a minimum-jerk move to [`pause_at`](Self::pause_at), the pause, and a minimum-jerk
    /// move on to 1 (one move when there is no pause); each rests at both ends, so `u` has
    /// continuous first and second derivatives.
    pub(super) fn progress(&self, t: Real) -> (Real, Real, Real) {
        let at = if self.pause_s > 0.0 {
            self.pause_at
        } else {
            1.0
        };
        let t1 = at * self.move_s;
        if t >= self.move_s + self.pause_s {
            return (1.0, 0.0, 0.0);
        }
        let (from, share, start, dur) = if t < t1 {
            (0.0, at, 0.0, t1)
        } else if t < t1 + self.pause_s {
            return (at, 0.0, 0.0);
        } else {
            (at, 1.0 - at, t1 + self.pause_s, self.move_s - t1)
        };
        if dur <= 0.0 {
            return (from + share, 0.0, 0.0);
        }
        let tau = (t - start) / dur;
        (
            from + share * crate::min_jerk::progress(tau),
            share * crate::min_jerk::velocity(tau) / dur,
            share * crate::min_jerk::acceleration(tau) / (dur * dur),
        )
    }
}

/// A duration rounded to whole ticks (ns), as a script's tasks are.
pub(super) fn whole_ticks_ns(seconds: Real) -> u64 {
    (seconds * 1e9).round() as u64 / TICK_NS * TICK_NS
}

/// The varied approach under way: its reach and its bend.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ReachPath {
    pub(super) reach: Reach,
    /// The bend: the path's displacement from the straight line halfway (m, world).
    pub(super) bend: Vector,
}

/// The bend of a reach along `dp` (m): `fraction` of its length, perpendicular to it, turned
/// `angle` (0 to π) about it from horizontal through up (never down).
pub(super) fn bend_vector(dp: &Vector, fraction: Real, angle: Real) -> Vector {
    let len = dp.norm();
    if len < 1e-9 {
        return Vector::zeros();
    }
    let d = dp / len;
    let e1 = Vector::z()
        .cross(&d)
        .try_normalize(1e-6)
        .unwrap_or(Vector::x());
    let mut e2 = d.cross(&e1);
    if e2.z < 0.0 {
        e2 = -e2;
    }
    (e1 * angle.cos() + e2 * angle.sin()) * (fraction * len)
}

/// The point of a reach from `from` by `dp` with bend `bend` at path parameter `u`.
pub(super) fn reach_point(from: &Vector, dp: &Vector, bend: &Vector, u: Real) -> Vector {
    from + dp * u + bend * (std::f64::consts::PI * u).sin()
}

/// The points of the hand a reach keeps clear of the table and the objects, with their radii
/// (m), from `kin` (the hand's forward kinematics): every link's origin (the joints), the
/// middle of every link between two joints, every fingertip sphere and the middle of its
/// distal segment.
pub(super) fn hand_points(hand: &HandModel, kin: &Kinematics, out: &mut Vec<(Vector, Real)>) {
    out.clear();
    let origin = |l: usize| kin.link_poses[l].translation.vector;
    for l in 0..hand.links.len() {
        out.push((origin(l), 0.0));
    }
    for j in &hand.joints {
        out.push(((origin(j.parent) + origin(j.child)) * 0.5, 0.0));
    }
    for (k, tip) in hand.fingertips.iter().enumerate() {
        let c = kin.tip_centres[k].coords;
        out.push((c, tip.radius));
        out.push(((c + origin(tip.link)) * 0.5, 0.0));
    }
}

/// How far (m) a sphere of radius `r` at `p` is from the table's top and from every object.
pub(super) fn clearance(p: &Vector, r: Real, objects: &[DfsObject], table_height: Real) -> Real {
    objects.iter().fold(p.z - r - table_height, |c, o| {
        let local = o.state.pose.inverse_transform_point(&Point::from(*p));
        c.min(o.object.shape.closest(&local.coords).distance - r)
    })
}

/// A reach of the hand from `from` to `to`, its joints going from `q_from` to `q_to`, bent by
/// `bend`, as [`reach_is_clear`] checks it.
pub(super) struct ReachCheck<'a> {
    pub(super) hand: &'a HandModel,
    pub(super) q_from: &'a [Real],
    pub(super) q_to: &'a [Real],
    pub(super) from: &'a Isometry,
    pub(super) to: &'a Isometry,
    pub(super) objects: &'a [DfsObject],
    pub(super) table_height: Real,
}

impl ReachCheck<'_> {
    /// The hand's pose and joints at path parameter `u` along the reach bent by `bend`, into
    /// `kin`, and its points ([`hand_points`]) into `points`.
    pub(super) fn points_at(
        &self,
        u: Real,
        bend: &Vector,
        q: &mut [Real; MAX_DOF],
        kin: &mut Kinematics,
        points: &mut Vec<(Vector, Real)>,
    ) {
        let a = self.from.translation.vector;
        let dp = self.to.translation.vector - a;
        let base = Isometry::from_parts(
            reach_point(&a, &dp, bend, u).into(),
            self.from.rotation.slerp(&self.to.rotation, u),
        );
        let n = self.q_from.len();
        for d in 0..n {
            q[d] = self.q_from[d] + (self.q_to[d] - self.q_from[d]) * u;
        }
        self.hand.forward_kinematics(&base, &q[..n], kin);
        hand_points(self.hand, kin, points);
    }

    /// The least clearance ([`clearance`]) of each hand point at `u`.
    pub(super) fn clearances_at(&self, u: Real, bend: &Vector, kin: &mut Kinematics) -> Vec<Real> {
        let mut q = [0.0; MAX_DOF];
        let mut points = Vec::new();
        self.points_at(u, bend, &mut q, kin, &mut points);
        points
            .iter()
            .map(|(p, r)| clearance(p, *r, self.objects, self.table_height))
            .collect()
    }

    /// Whether the reach bent by `bend` keeps clear: at [`CLEARANCE_SAMPLES`] points along
    /// it, every hand point keeps from the table and every object at least the least of
    /// [`REACH_CLEARANCE_M`] and its clearances at the reach's start and end, less 2 mm.
    pub(super) fn is_clear(&self, bend: &Vector, kin: &mut Kinematics) -> bool {
        let start = self.clearances_at(0.0, bend, kin);
        let end = self.clearances_at(1.0, bend, kin);
        let mut q = [0.0; MAX_DOF];
        let mut points = Vec::new();
        (1..CLEARANCE_SAMPLES).all(|i| {
            let u = i as Real / CLEARANCE_SAMPLES as Real;
            self.points_at(u, bend, &mut q, kin, &mut points);
            points.iter().enumerate().all(|(k, (p, r))| {
                let least = REACH_CLEARANCE_M.min(start[k]).min(end[k]) - 0.002;
                clearance(p, *r, self.objects, self.table_height) >= least
            })
        })
    }
}

/// The varied start of a simulation ([`REACH_HOME_M`] and the other `REACH_HOME_` ranges):
/// drawn from `rng` until one keeps [`REACH_CLEARANCE_M`] clear of the table and the objects,
/// has its base [`REACH_HOME_ABOVE_TABLE_M`] above the table and a straight reach from it to
/// `approach` keeps clear ([`ReachCheck::is_clear`]); after [`HOME_TRIES`] draws, the fixed
/// start 0.15 m above `approach`.
pub(super) fn draw_home(
    rng: &mut ChaCha8Rng,
    hand: &HandModel,
    q_open: &[Real],
    approach: &Isometry,
    target: &Vector,
    objects: &[DfsObject],
    table_height: Real,
) -> Isometry {
    let a = approach.translation.vector;
    let mut out = a - target;
    out.z = 0.0;
    let out = out
        .try_normalize(1e-6)
        .or_else(|| {
            let mut y = approach.rotation * Vector::y();
            y.z = 0.0;
            y.try_normalize(1e-6)
        })
        .unwrap_or(Vector::x());
    let side = Vector::z().cross(&out);
    let mut kin = Kinematics::default();
    for _ in 0..HOME_TRIES {
        let distance = rng.random_range(REACH_HOME_M.0..=REACH_HOME_M.1);
        let azimuth = rng.random_range(-REACH_HOME_AZIMUTH..=REACH_HOME_AZIMUTH);
        let elevation = rng.random_range(REACH_HOME_ELEVATION.0..=REACH_HOME_ELEVATION.1);
        let yaw = rng.random_range(-REACH_HOME_YAW..=REACH_HOME_YAW);
        let dir = (out * azimuth.cos() + side * azimuth.sin()) * elevation.cos()
            + Vector::z() * elevation.sin();
        let home = Isometry::from_parts(
            (a + dir * distance).into(),
            Rotation::from_euler_angles(0.0, 0.0, yaw) * approach.rotation,
        );
        if home.translation.z < table_height + REACH_HOME_ABOVE_TABLE_M {
            continue;
        }
        let check = ReachCheck {
            hand,
            q_from: q_open,
            q_to: q_open,
            from: &home,
            to: approach,
            objects,
            table_height,
        };
        let straight = Vector::zeros();
        let clear_at_home = check
            .clearances_at(0.0, &straight, &mut kin)
            .iter()
            .all(|&c| c >= REACH_CLEARANCE_M);
        if clear_at_home && check.is_clear(&straight, &mut kin) {
            return home;
        }
    }
    raise(approach, 0.15)
}
