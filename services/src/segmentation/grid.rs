//! Pass one's data: the hand's base pose resampled onto a uniform grid as object samples
//! come, and the contact state as runs (which also say which object the contacts pushed).

use dfs_core::math::{Isometry, Rotation, Vector};

use super::pose::iso;
use super::SegmentParams;
use crate::session::{Contacts, ObjectState, MAX_SESSION_OBJECTS};

/// Signals resampled onto the uniform grid: for an hour at 1 ms, 3.6 million points of 41
/// bytes (the orientation in `f32`: 16 bytes rather than 32, its angles still good to 1e-7
/// rad, see [`Grid::angle`]).
pub(super) struct Grid {
    pub(super) t0: u64,
    pub(super) dt_ns: u64,
    pub(super) base_p: Vec<Vector>,
    base_r: Vec<[f32; 4]>,
    pub(super) touching: Vec<bool>,
}

impl Grid {
    /// The number of grid points.
    pub(super) fn len(&self) -> usize {
        self.base_p.len()
    }

    /// The hand base's orientation at grid point `i`.
    pub(super) fn rot(&self, i: usize) -> Rotation {
        let [x, y, z, w] = self.base_r[i].map(f64::from);
        Rotation::new_normalize(nalgebra::Quaternion::new(w, x, y, z))
    }

    /// The angle (rad) between the orientations at grid points `a` and `b`, from the
    /// relative rotation's vector part and scalar (atan2: no loss near 0, unlike the acos of
    /// a dot product, which turns the `f32` storage's 1e-7 into 1e-3 rad).
    pub(super) fn angle(&self, a: usize, b: usize) -> f64 {
        (self.rot(a).inverse() * self.rot(b)).angle()
    }
}

/// Time after the latest contact sample during which its state holds (ns): over a longer hole
/// in the data the hand is taken as not touching.
const CONTACT_HOLD_NS: u64 = 50_000_000;

/// A run of contact samples with the same "two fingers or more in contact" state and no hole
/// of [`CONTACT_HOLD_NS`] between them: from its first sample's log time to its last's.
#[derive(Debug, Clone, Copy)]
pub(super) struct ContactRun {
    start: u64,
    end: u64,
    on: bool,
    /// Per object of the scene: how many of the run's samples had most of their transmitting
    /// fingertips on it.
    objects: [u32; MAX_SESSION_OBJECTS],
}

/// The object most of `c`'s transmitting fingertips push (the lowest index of a tie).
fn pushed_object(c: &Contacts) -> usize {
    let mut count = [0u32; MAX_SESSION_OBJECTS];
    for f in c.fingers.iter().filter(|f| f.in_contact) {
        count[(f.object as usize).min(MAX_SESSION_OBJECTS - 1)] += 1;
    }
    argmax(&count)
}

/// The index of the largest count (the lowest of a tie).
fn argmax<T: PartialOrd>(count: &[T]) -> usize {
    let mut best = 0;
    for (i, n) in count.iter().enumerate() {
        if *n > count[best] {
            best = i;
        }
    }
    best
}

/// Pass one of segmentation: the hand base's pose resampled onto the grid as object samples
/// come (in time order), and the contact state as runs. Holds the grid and the last two
/// samples, whatever the session's length.
pub(super) struct GridBuilder {
    dt_ns: u64,
    /// The last two finite samples: (log time, base pose).
    last: [Option<(u64, Isometry)>; 2],
    /// Log time of the next grid point to fill.
    next: u64,
    t0: Option<u64>,
    base_p: Vec<Vector>,
    base_r: Vec<[f32; 4]>,
    pub(super) runs: Vec<ContactRun>,
}

impl GridBuilder {
    /// An empty grid of step [`SegmentParams::grid_s`].
    pub(super) fn new(params: &SegmentParams) -> Self {
        GridBuilder {
            dt_ns: ((params.grid_s * 1e9) as u64).max(1),
            last: [None, None],
            next: 0,
            t0: None,
            base_p: Vec::new(),
            base_r: Vec::new(),
            runs: Vec::new(),
        }
    }

    /// Fills the grid points before `until` (or up to it, with `inclusive`) from the segment
    /// between the last two samples.
    fn fill(&mut self, until: u64, inclusive: bool) {
        let (Some((ta, a)), Some((tb, b))) = (self.last[0], self.last[1]) else {
            return;
        };
        while self.next < until || (inclusive && self.next == until) {
            let t = self.next;
            let s = if tb > ta {
                // In offsets: epoch-based log times (1.7e18 ns) lose 256 ns as f64.
                (t.saturating_sub(ta) as f64 / (tb - ta) as f64).clamp(0.0, 1.0)
            } else {
                0.0
            };
            self.base_p
                .push(a.translation.vector.lerp(&b.translation.vector, s));
            let q = a.rotation.nlerp(&b.rotation, s);
            self.base_r
                .push([q.i as f32, q.j as f32, q.k as f32, q.w as f32]);
            self.next += self.dt_ns;
        }
    }

    /// An `/object/state` sample: the base pose is `pose ∘ pose_in_hand⁻¹`.
    pub(super) fn object(&mut self, t: u64, o: &ObjectState) {
        let base = iso(&o.pose) * iso(&o.pose_in_hand).inverse();
        if !base.translation.vector.iter().all(|v| v.is_finite()) {
            return;
        }
        if self.t0.is_none() {
            self.t0 = Some(t);
            self.next = t;
        }
        // The grid points before this sample lie between the last one and it.
        self.last = [self.last[1], Some((t, base))];
        if self.last[0].is_some() {
            self.fill(t, false);
        }
    }

    /// A `/dfs/contacts` sample: two fingers or more in contact, or not.
    pub(super) fn contacts(&mut self, t: u64, c: &Contacts) {
        let on = c.fingers.iter().filter(|f| f.in_contact).count() >= 2;
        match self.runs.last_mut() {
            Some(r) if r.on == on && t.saturating_sub(r.end) < CONTACT_HOLD_NS => r.end = t,
            _ => self.runs.push(ContactRun {
                start: t,
                end: t,
                on,
                objects: [0; MAX_SESSION_OBJECTS],
            }),
        }
        if on {
            if let Some(r) = self.runs.last_mut() {
                r.objects[pushed_object(c)] += 1;
            }
        }
    }

    /// The grid, `None` with fewer than two object samples. Each grid point touches if the
    /// latest contact sample at or before it (or the first one, if it comes within a grid
    /// step) says so and is less than [`CONTACT_HOLD_NS`] old.
    pub(super) fn finish(mut self) -> Option<Grid> {
        let t0 = self.t0?;
        let (t1, _) = self.last[1]?;
        self.last[0]?;
        self.fill(t1, true);
        let n = self.base_p.len();
        let mut touching = vec![false; n];
        let mut r = 0usize;
        for (i, tv) in touching.iter_mut().enumerate() {
            let t = t0 + i as u64 * self.dt_ns;
            while r + 1 < self.runs.len() && self.runs[r + 1].start <= t {
                r += 1;
            }
            let Some(run) = self.runs.get(r) else {
                break;
            };
            *tv = if run.start > t {
                run.start <= t + self.dt_ns && run.on
            } else {
                run.on && (t <= run.end || t - run.end < CONTACT_HOLD_NS)
            };
        }
        Some(Grid {
            t0,
            dt_ns: self.dt_ns,
            base_p: self.base_p,
            base_r: self.base_r,
            touching,
        })
    }
}

/// The object the contacts of `runs` from `start` to `end` (log times) pushed most: the one a
/// skill of that span grasped (0 in a session of one object).
pub(super) fn grasped_object(runs: &[ContactRun], start: u64, end: u64) -> usize {
    let mut count = [0u64; MAX_SESSION_OBJECTS];
    for r in runs
        .iter()
        .filter(|r| r.on && r.end >= start && r.start <= end)
    {
        for (c, &n) in count.iter_mut().zip(&r.objects) {
            *c += u64::from(n);
        }
    }
    argmax(&count)
}
