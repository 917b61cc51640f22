//! On-line phase estimation: the live counterpart of [`crate::segmentation`].
//!
//! [`OnlinePhase`] is fed one [`PhaseObservation`] at a time (the hand base's pose and how many
//! fingertips push on an object) and says which [`Phase`] the operator is in *now*, so that a
//! robot executing a recognised skill can follow the operator's phase as it happens rather
//! than a fixed replay clock. It is causal (a decision uses only the samples up to it), does a
//! constant amount of work and no heap allocation per sample, and works on the sample times
//! it is given: any rate from 100 Hz to 1 kHz and more, with jitter and gaps.
//!
//! # Method
//!
//! The cues are the offline segmentation's, with its thresholds ([`SegmentParams`]):
//!
//! - **Moves of the hand base.** The base pose is low-pass filtered (first order, 10 ms, on
//!   the sample times given: a wrist tracker's ±0.1 mm of noise a sample would otherwise read
//!   as 5 mm/s, above the exit speed). Its speed (linear plus
//!   [`SegmentParams::rotation_radius`] × angular) is a *backward* difference over `2 ×`
//!   [`SegmentParams::speed_window_s`] (30 ms; the offline uses a central difference over the
//!   same span), from the current pose to the one interpolated at the window's start in a
//!   small ring of recent poses (linear across gaps, as the offline's resampling). It
//!   therefore lags the offline speed by [`SegmentParams::speed_window_s`] plus the filter's
//!   10 ms. A move starts when the speed exceeds [`SegmentParams::move_enter_speed`] and the
//!   hand has covered a third of [`SegmentParams::min_move_m`] (0.5 mm) since the speed rose
//!   above [`SegmentParams::move_exit_speed`]; it ends when the speed falls below the exit
//!   speed (hysteresis). Two moves back to back, whose speed dips between them without falling
//!   below the exit speed (a slightly noisy or sparsely sampled dip), are split where the speed
//!   fell below a tenth of the first one's peak and then doubled. A move's estimated start is
//!   the start of the window in which the speed first rose above the exit threshold (or the
//!   split); its estimated end the middle of the window in which it fell below it, less the
//!   filter's delay. Moves too slow for the enter speed are not seen (the offline's second pass
//!   for slow moves has no on-line counterpart).
//! - **Contact.** Contact is on while at least two fingertips push (as the offline contact
//!   episodes). An episode ends when contact has been off for
//!   [`SegmentParams::contact_gap_s`] (shorter gaps are bridged, as offline).
//!
//! # Labels
//!
//! The offline grammar, made causal:
//!
//! - **approach**: the phase before anything happens, and of the first move before contact.
//! - **preshape**: a move that starts before contact after an earlier move before contact has
//!   ended (a *move after a pause*: offline, the last of two or more moves before contact is
//!   the preshape; on-line one cannot know that a move is the last, so every later one is
//!   taken as the preshape). Decided at the move's start.
//! - **grasp**: when the preshape move ends (the hand comes to rest before contact: offline,
//!   the rest from the last move before contact to the first move in contact), or when contact
//!   begins, whichever comes first; after a single approach move (no preshape) only when contact
//!   begins, then starting at that move's end. If the hand moves again before contact, that
//!   move is a preshape again (a pause mid-approach after two moves reads as `grasp` for the
//!   length of the pause).
//! - **lift** / **place** / **transport**: a move that starts in contact, from the direction
//!   of the (filtered) base's displacement since the move's estimated start, as offline:
//!   mostly a turn (displacement below half of `rotation_radius` × angle) is `transport`;
//!   otherwise more than [`SegmentParams::vertical_fraction`] of the displacement up is
//!   `lift`, down is `place`, else `transport`. Decided at the move's start, when the direction
//!   is already clear for a hand's smooth moves; a move that turns on its way is labelled by
//!   its start. (Of two moves in contact back to back, the second is labelled as it starts:
//!   a lift then a transport, with no hold between.)
//! - **hold**: when a `lift` or `transport` move ends in contact (offline drops holds shorter
//!   than 150 ms between two moves; on-line one cannot wait that long without the same lag).
//! - **release**: when a `place` move ends.
//! - **retreat**: a move that starts after the contact episode ended, or an upward move after
//!   contact has been off for 50 ms or after a `place` (offline: the first lift after the
//!   episode or after a place).
//! - After a retreat has ended, the next move starts a new **approach** (starting at the
//!   retreat's end, as offline), and a new contact (of at least
//!   [`SegmentParams::min_contact_s`]) a new **grasp**.
//!
//! A decision is a [`PhaseChange`]: the phase, the sample time at which it was decided and the
//! estimated start of the phase (earlier: the start of a move is seen once it is under way).
//! [`phase_lag`] measures the decisions' lag behind an offline segmentation's boundaries.
//!
//! # Odd input
//!
//! A sample whose time does not advance past the last one's is ignored (duplicates,
//! out-of-order samples). A base pose with a non-finite coordinate is missing: the sample
//! still updates the contact state. Nothing panics.

use dfs_core::dfs::TickOutput;
use dfs_core::math::{Isometry, Rotation, Vector};
use dfs_core::scenario::Phase;
use serde::Serialize;

use crate::segmentation::{PhaseSpan, SegmentParams};

/// One sample of what the on-line phase estimate looks at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseObservation {
    /// The sample's time (ns, any origin; must increase from sample to sample: a sample whose
    /// time does not is ignored).
    pub t_ns: u64,
    /// The hand's base (wrist) in the world. A non-finite coordinate makes the pose missing.
    pub base: Isometry,
    /// How many fingertips are in contact, pushing on an object
    /// ([`dfs_core::dfs::TipContact::in_contact`]): on any object of the scene, as the
    /// offline segmentation counts them, or on the target only if the caller knows which one
    /// it is.
    pub touching: u32,
}

impl PhaseObservation {
    /// The observation of one DFS tick: `base` (the glove sample's hand base) and the tick's
    /// fingertips in contact, on any object (as the offline segmentation counts them).
    pub fn from_tick(t_ns: u64, base: &Isometry, out: &TickOutput) -> Self {
        let touching = out
            .tips
            .iter()
            .take(out.n_tips)
            .filter(|t| t.in_contact)
            .count() as u32;
        PhaseObservation {
            t_ns,
            base: *base,
            touching,
        }
    }
}

/// A change of phase decided by [`OnlinePhase::push`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct PhaseChange {
    /// The phase entered.
    pub phase: Phase,
    /// Time of the sample at which the change was decided (ns, the samples' clock).
    pub decided_ns: u64,
    /// Estimated start of the phase (ns, the samples' clock): at or before `decided_ns`.
    pub start_ns: u64,
}

/// Samples kept for the backward speed window (see [`OnlinePhase`]): at most about 35 are
/// needed, whatever the sample rate.
const RING: usize = 48;

/// Samples closer than the window / this are thinned out of the ring (see [`OnlinePhase`]).
const RING_DENSITY: u64 = 16;

/// Time constant of the low-pass filter on the base pose (s): it takes the noise of a wrist
/// tracker (±0.1 mm a sample) well under the exit speed at 1 kHz, for 10 ms of delay.
const FILTER_S: f64 = 0.01;

/// A move starts once it has covered this fraction of [`SegmentParams::min_move_m`] (the
/// offline's smallest move) since its speed rose above the exit threshold: no sensor noise
/// covers it, and a hand's move covers it early (0.5 mm: the first 8 % of a 10 cm lift).
const CONFIRM_FRACTION: f64 = 1.0 / 3.0;

/// Two moves back to back (the speed never falls below the exit threshold between them) are
/// told apart when the speed dips below this fraction of the first one's peak...
const SPLIT_DIP: f64 = 0.1;

/// ... and then rises to this multiple of the dip (and above the enter threshold), having
/// covered [`CONFIRM_FRACTION`] of the smallest move since.
const SPLIT_RISE: f64 = 2.0;

/// A pose at a time.
#[derive(Debug, Clone, Copy)]
struct Stamp {
    t: u64,
    p: Vector,
    r: Rotation,
}

impl Stamp {
    const ZERO: Stamp = Stamp {
        t: 0,
        p: Vector::new(0.0, 0.0, 0.0),
        r: Rotation::new_unchecked(nalgebra::Quaternion::new(1.0, 0.0, 0.0, 0.0)),
    };
}

/// Where the estimate is in a grasp cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// Before contact: approach, preshape, grasp (no contact yet).
    Reach,
    /// A contact episode began: grasp, lift, hold, transport, place, release.
    Held,
    /// The retreat was decided.
    Away,
}

/// What the speed hysteresis decided at a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
enum MoveEvent {
    None,
    /// A move started (its estimated start is `move_from`).
    Started,
    /// The move ended; its estimated end (ns).
    Ended(u64),
    /// The move ended (estimated end, ns) and the next one started, back to back.
    Split(u64),
}

/// The on-line phase estimate: see the [module](self) documentation for its rules.
///
/// Feed it every sample with [`OnlinePhase::push`]; [`OnlinePhase::phase`] is the current
/// phase. Its state is a fixed-size value (about 3.5 KiB): no allocation after
/// [`OnlinePhase::new`].
#[derive(Debug, Clone)]
pub struct OnlinePhase {
    /// Length of the backward speed window (ns).
    window_ns: u64,
    enter: f64,
    exit: f64,
    rotation_radius: f64,
    vertical_fraction: f64,
    contact_gap_ns: u64,
    min_contact_ns: u64,
    /// Contact off for this long before an upward move makes it a retreat (the offline's 50 ms
    /// tolerance).
    retreat_off_ns: u64,

    /// Time constant of the pose's low-pass filter (ns).
    filter_ns: u64,
    /// A move starts once it has covered this far (m, rotations × `rotation_radius`).
    confirm_m: f64,

    /// The low-pass filtered pose.
    filtered: Option<Stamp>,
    /// Recent filtered poses, oldest first from `head`, thinned to one per window /
    /// [`RING_DENSITY`].
    ring: [Stamp; RING],
    head: usize,
    len: usize,
    /// Time of the last sample taken.
    last_t: Option<u64>,
    /// Latest speed (m/s).
    speed: f64,
    /// While at rest: the window start (time and pose) when the speed rose above the exit
    /// threshold.
    rise: Option<Stamp>,
    moving: bool,
    /// Estimated start (time and pose) of the current or last move.
    move_from: Stamp,
    /// Estimated end of the last move.
    last_move_end: Option<u64>,
    /// Highest speed of the current move (since its start or its last split).
    peak: f64,
    /// The lowest speed since that peak, and the filtered pose there.
    valley: Option<(Stamp, f64)>,

    contact_on: bool,
    /// Start of the current run of contact.
    on_since: u64,
    /// Last sample with contact on.
    last_on: Option<u64>,
    /// The contact episode of this cycle ended (contact off for the gap).
    episode_over: bool,

    stage: Stage,
    phase: Phase,
    /// Moves ended before contact in this cycle.
    reach_moves: u32,
    /// Label of the last move in contact.
    last_label: Option<Phase>,
    /// End of the retreat move, once it ended.
    retreat_end: Option<u64>,
    /// When the retreat was decided.
    retreat_at: u64,
}

impl OnlinePhase {
    /// An estimate with the offline segmentation's thresholds (speed window, enter and exit
    /// speeds, rotation radius, vertical fraction, contact gap, shortest contact); it starts
    /// in `approach`. Non-finite or negative parameters fall back to the defaults'.
    pub fn new(params: &SegmentParams) -> Self {
        let d = SegmentParams::default();
        let pos = |v: f64, dv: f64| if v.is_finite() && v > 0.0 { v } else { dv };
        let ns = |s: f64| (s * 1e9).round().clamp(1.0, 1e15) as u64;
        let half = pos(params.speed_window_s, d.speed_window_s);
        let exit = pos(params.move_exit_speed, d.move_exit_speed);
        OnlinePhase {
            window_ns: ns(2.0 * half),
            enter: pos(params.move_enter_speed, d.move_enter_speed).max(exit),
            exit,
            rotation_radius: pos(params.rotation_radius, d.rotation_radius),
            vertical_fraction: pos(params.vertical_fraction, d.vertical_fraction),
            contact_gap_ns: ns(pos(params.contact_gap_s, d.contact_gap_s)),
            min_contact_ns: ns(pos(params.min_contact_s, d.min_contact_s)),
            retreat_off_ns: 50_000_000,
            filter_ns: ns(FILTER_S),
            confirm_m: pos(params.min_move_m, d.min_move_m) * CONFIRM_FRACTION,
            filtered: None,
            ring: [Stamp::ZERO; RING],
            head: 0,
            len: 0,
            last_t: None,
            speed: 0.0,
            rise: None,
            moving: false,
            move_from: Stamp::ZERO,
            last_move_end: None,
            peak: 0.0,
            valley: None,
            contact_on: false,
            on_since: 0,
            last_on: None,
            episode_over: false,
            stage: Stage::Reach,
            phase: Phase::Approach,
            reach_moves: 0,
            last_label: None,
            retreat_end: None,
            retreat_at: 0,
        }
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The hand base's latest speed (m/s; linear plus rotation radius × angular).
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The hand base is in a move.
    pub fn moving(&self) -> bool {
        self.moving
    }

    /// Takes one sample; returns the change of phase decided at it, if any. A sample that
    /// decides two changes (one after a long gap: a move ends and contact begins) returns the
    /// later; [`OnlinePhase::phase`] is always the current one.
    pub fn push(&mut self, obs: &PhaseObservation) -> Option<PhaseChange> {
        let t = obs.t_ns;
        if self.last_t.is_some_and(|last| t <= last) {
            return None;
        }
        self.last_t = Some(t);
        let event = match finite_pose(&obs.base) {
            Some(now) => self.update_speed(Stamp { t, ..now }),
            None => MoveEvent::None,
        };
        let mut change = None;
        // A move's end, then contact, then a move's start: a sample after a gap that ends the
        // preshape and begins contact is a grasp; one that begins contact and a move, a move
        // in contact.
        if let MoveEvent::Ended(end) = event {
            change = self.move_ended(t, end).or(change);
        }
        change = self.update_contact(t, obs.touching).or(change);
        match event {
            MoveEvent::Started => change = self.move_started(t).or(change),
            MoveEvent::Split(_) => {
                // The move before counts as ended, the next is labelled as any move: a
                // preshape after an approach, a transport after a lift. (A preshape or a
                // lift split in two stays one, without a rest between.)
                if self.stage == Stage::Reach {
                    self.reach_moves = self.reach_moves.saturating_add(1);
                }
                change = self.move_started(t).or(change);
            }
            _ => {}
        }
        change
    }

    fn at(&self, i: usize) -> Stamp {
        self.ring[(self.head + i) % RING]
    }

    fn pop_front(&mut self) {
        self.head = (self.head + 1) % RING;
        self.len -= 1;
    }

    /// Adds `now` to the ring, in place of the last sample if that one is within the thinning
    /// spacing of the one before it.
    fn record(&mut self, now: Stamp) {
        let spacing = self.window_ns / RING_DENSITY;
        if self.len >= 2 && now.t.saturating_sub(self.at(self.len - 2).t) < spacing {
            let i = (self.head + self.len - 1) % RING;
            self.ring[i] = now;
            return;
        }
        if self.len == RING {
            self.pop_front();
        }
        let i = (self.head + self.len) % RING;
        self.ring[i] = now;
        self.len += 1;
    }

    /// Updates the filtered pose and the speed with the pose `raw` and runs the move
    /// hysteresis.
    fn update_speed(&mut self, raw: Stamp) -> MoveEvent {
        let now = match self.filtered {
            None => raw,
            Some(f) => {
                // First order on the sample times given: a long gap lets the new pose through.
                let a = 1.0 - (-((raw.t - f.t) as f64) / self.filter_ns as f64).exp();
                Stamp {
                    t: raw.t,
                    p: f.p.lerp(&raw.p, a),
                    r: interpolate(&f.r, &raw.r, a),
                }
            }
        };
        self.filtered = Some(now);
        self.record(now);
        let tq = now.t.saturating_sub(self.window_ns);
        while self.len >= 2 && self.at(1).t <= tq {
            self.pop_front();
        }
        let a = self.at(0);
        let from = if a.t >= tq || self.len < 2 {
            a
        } else {
            let b = self.at(1);
            let s = (tq - a.t) as f64 / (b.t - a.t) as f64;
            Stamp {
                t: tq,
                p: a.p.lerp(&b.p, s),
                r: interpolate(&a.r, &b.r, s),
            }
        };
        let span = now.t - from.t;
        // Less than half a window of history (the stream's first samples): no speed yet.
        self.speed = if span.saturating_mul(2) < self.window_ns {
            0.0
        } else {
            let lin = (now.p - from.p).norm();
            let ang = angle_between(&from.r, &now.r);
            (lin + self.rotation_radius * ang) / (span as f64 * 1e-9)
        };
        if !self.moving {
            if self.speed > self.exit {
                let rise = *self.rise.get_or_insert(from);
                let covered =
                    (now.p - rise.p).norm() + self.rotation_radius * angle_between(&rise.r, &now.r);
                if self.speed > self.enter && covered >= self.confirm_m {
                    self.moving = true;
                    self.move_from = rise;
                    self.rise = None;
                    self.peak = self.speed;
                    self.valley = None;
                    return MoveEvent::Started;
                }
            } else {
                self.rise = None;
            }
            return MoveEvent::None;
        }
        let delay = self.window_ns / 2 + self.filter_ns;
        if self.speed < self.exit {
            self.moving = false;
            let end = now.t.saturating_sub(delay).max(self.move_from.t);
            self.last_move_end = Some(end);
            return MoveEvent::Ended(end);
        }
        // Two moves back to back: the speed dipped deep below the move's peak and rose again.
        if self.speed > self.peak {
            self.peak = self.speed;
            self.valley = None;
        } else if self.valley.is_none_or(|(_, v)| self.speed < v) {
            self.valley = Some((now, self.speed));
        }
        if let Some((v, low)) = self.valley {
            let covered = (now.p - v.p).norm() + self.rotation_radius * angle_between(&v.r, &now.r);
            if low < SPLIT_DIP * self.peak
                && self.speed > self.enter.max(SPLIT_RISE * low)
                && covered >= self.confirm_m
            {
                let end = v.t.saturating_sub(delay).max(self.move_from.t);
                self.last_move_end = Some(end);
                self.move_from = Stamp { t: end, ..v };
                self.peak = self.speed;
                self.valley = None;
                return MoveEvent::Split(end);
            }
        }
        MoveEvent::None
    }

    /// Enters `phase` (decided at `t`, estimated to start at `start`) unless already in it.
    fn set(&mut self, phase: Phase, t: u64, start: u64) -> Option<PhaseChange> {
        if phase == self.phase {
            return None;
        }
        self.phase = phase;
        Some(PhaseChange {
            phase,
            decided_ns: t,
            start_ns: start.min(t),
        })
    }

    /// The label of the move in contact under way, from the (filtered) base's displacement
    /// since its start, as offline: a turn is a transport; mostly up a lift, mostly down a
    /// place, otherwise a transport.
    fn classify(&self) -> Phase {
        let Some(now) = self.filtered else {
            return Phase::Transport;
        };
        let dp = now.p - self.move_from.p;
        let angle = angle_between(&self.move_from.r, &now.r);
        let h = dp.norm();
        if h < self.rotation_radius * angle * 0.5 {
            Phase::Transport
        } else if dp.z > self.vertical_fraction * h {
            Phase::Lift
        } else if dp.z < -self.vertical_fraction * h {
            Phase::Place
        } else {
            Phase::Transport
        }
    }

    fn move_started(&mut self, t: u64) -> Option<PhaseChange> {
        let start = self.move_from.t;
        match self.stage {
            Stage::Reach => match self.phase {
                // The first move of the reach is the approach itself.
                Phase::Approach if self.reach_moves == 0 => None,
                // A move after a pause before contact (or the hand moving on after the
                // preshape came to rest): the preshape.
                _ => self.set(Phase::Preshape, t, start),
            },
            Stage::Held => {
                let label = self.classify();
                let off_for = match (self.contact_on, self.last_on) {
                    (false, Some(on)) => t.saturating_sub(on),
                    (false, None) => u64::MAX,
                    (true, _) => 0,
                };
                let up_after = label == Phase::Lift
                    && (off_for > self.retreat_off_ns || self.last_label == Some(Phase::Place));
                if self.episode_over || up_after {
                    self.stage = Stage::Away;
                    self.retreat_at = t;
                    self.retreat_end = None;
                    self.set(Phase::Retreat, t, start)
                } else {
                    self.last_label = Some(label);
                    self.set(label, t, start)
                }
            }
            Stage::Away => match self.retreat_end {
                // The hand moves again after the retreat: a new reach.
                Some(end) => {
                    self.new_cycle();
                    self.set(Phase::Approach, t, end)
                }
                None => None,
            },
        }
    }

    fn move_ended(&mut self, t: u64, end: u64) -> Option<PhaseChange> {
        match self.stage {
            Stage::Reach => {
                self.reach_moves = self.reach_moves.saturating_add(1);
                if self.phase == Phase::Preshape {
                    self.set(Phase::Grasp, t, end)
                } else {
                    None
                }
            }
            Stage::Held => match self.phase {
                Phase::Lift | Phase::Transport => self.set(Phase::Hold, t, end),
                Phase::Place => self.set(Phase::Release, t, end),
                _ => None,
            },
            Stage::Away => {
                self.retreat_end.get_or_insert(end);
                None
            }
        }
    }

    fn new_cycle(&mut self) {
        self.stage = Stage::Reach;
        self.reach_moves = 0;
        self.last_label = None;
        self.episode_over = false;
        self.retreat_end = None;
    }

    fn update_contact(&mut self, t: u64, touching: u32) -> Option<PhaseChange> {
        if touching < 2 {
            self.contact_on = false;
            if self.stage == Stage::Held
                && self
                    .last_on
                    .is_some_and(|on| t.saturating_sub(on) >= self.contact_gap_ns)
            {
                self.episode_over = true;
            }
            return None;
        }
        if !self.contact_on {
            self.contact_on = true;
            self.on_since = t;
        }
        self.last_on = Some(t);
        let confirmed = t - self.on_since >= self.min_contact_ns;
        match self.stage {
            // Contact ends the reach: the grasp, from the end of the last move before it (or
            // now, if the hand is moving).
            Stage::Reach => {
                self.stage = Stage::Held;
                self.last_label = None;
                self.episode_over = false;
                let start = match (self.moving, self.last_move_end) {
                    (false, Some(end)) => end,
                    _ => t,
                };
                self.set(Phase::Grasp, t, start)
            }
            // A new episode after the last one ended, or after the retreat: a new grasp.
            Stage::Held if self.episode_over && confirmed => {
                self.episode_over = false;
                self.last_label = None;
                self.set(Phase::Grasp, t, self.on_since)
            }
            // (A contact held since before the retreat is not a new one.)
            Stage::Away if confirmed && self.on_since > self.retreat_at => {
                self.new_cycle();
                self.stage = Stage::Held;
                self.set(Phase::Grasp, t, self.on_since)
            }
            _ => None,
        }
    }
}

/// The pose as a [`Stamp`] (time 0), `None` if a coordinate is not finite or the rotation has
/// no direction; the rotation normalised.
fn finite_pose(base: &Isometry) -> Option<Stamp> {
    let p = base.translation.vector;
    let q = base.rotation.into_inner();
    if !p.iter().chain(q.coords.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let n = q.norm();
    if n <= 1e-9 {
        return None;
    }
    Some(Stamp {
        t: 0,
        p,
        r: Rotation::new_unchecked(q / n),
    })
}

/// Normalised linear interpolation of two rotations (the shorter way round).
fn interpolate(a: &Rotation, b: &Rotation, s: f64) -> Rotation {
    let (qa, mut qb) = (a.into_inner(), b.into_inner());
    if qa.coords.dot(&qb.coords) < 0.0 {
        qb = -qb;
    }
    let q = qa.lerp(&qb, s);
    let n = q.norm();
    if n > 1e-12 {
        Rotation::new_unchecked(q / n)
    } else {
        *a
    }
}

/// The angle (rad) between two rotations, from the relative rotation's vector part and scalar
/// (atan2: exact near 0).
fn angle_between(a: &Rotation, b: &Rotation) -> f64 {
    let q = (a.inverse() * b).into_inner();
    2.0 * q.imag().norm().atan2(q.w.abs())
}

/// An on-line change matches an offline boundary of the same phase only within this distance
/// (ns) of it: half a second.
pub const MATCH_WINDOW_NS: u64 = 500_000_000;

/// One offline phase boundary and the on-line change matched to it (see [`phase_lag`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BoundaryLag {
    /// The phase that starts at the boundary.
    pub phase: Phase,
    /// The boundary: the offline phase's start (ns).
    pub offline_ns: u64,
    /// `decided_ns − offline_ns` of the matched on-line change (ms), `None` if none matched.
    pub lag_ms: Option<f64>,
    /// `start_ns − offline_ns` of the matched on-line change (ms): the error of its estimated
    /// start.
    pub start_error_ms: Option<f64>,
}

/// Lag of on-line phase changes behind offline boundaries (see [`phase_lag`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LagStats {
    /// Every boundary, with its lag when matched.
    pub boundaries: Vec<BoundaryLag>,
    /// The lags of the matched boundaries (ms; positive: the on-line decision came after the
    /// offline boundary).
    pub lags_ms: Vec<f64>,
    /// Median of the lags' absolute values (ms; 0 when none matched).
    pub median_abs_ms: f64,
    /// 90th percentile (nearest rank) of the lags' absolute values (ms; 0 when none matched).
    pub p90_abs_ms: f64,
    /// Boundaries matched.
    pub matched: usize,
    /// Boundaries.
    pub total: usize,
}

impl LagStats {
    /// The statistics of a set of boundaries (of one session or many).
    pub fn from_boundaries(boundaries: Vec<BoundaryLag>) -> Self {
        let lags_ms: Vec<f64> = boundaries.iter().filter_map(|b| b.lag_ms).collect();
        let mut abs: Vec<f64> = lags_ms.iter().map(|l| l.abs()).collect();
        abs.sort_by(f64::total_cmp);
        let median = crate::segmentation::median(&mut abs.clone());
        let p90 = match abs.len() {
            0 => 0.0,
            n => abs[((0.9 * n as f64).ceil() as usize).clamp(1, n) - 1],
        };
        LagStats {
            matched: lags_ms.len(),
            total: boundaries.len(),
            boundaries,
            lags_ms,
            median_abs_ms: median,
            p90_abs_ms: p90,
        }
    }

    /// These statistics and `other`'s together (several sessions).
    pub fn merged(&self, other: &LagStats) -> LagStats {
        let mut b = self.boundaries.clone();
        b.extend_from_slice(&other.boundaries);
        LagStats::from_boundaries(b)
    }

    /// Fraction of the boundaries matched (1 when there are none).
    pub fn matched_fraction(&self) -> f64 {
        if self.total == 0 {
            1.0
        } else {
            self.matched as f64 / self.total as f64
        }
    }

    /// The statistics of each phase's boundaries, in [`Phase::ALL`] order (phases without a
    /// boundary left out).
    pub fn per_phase(&self) -> Vec<(Phase, LagStats)> {
        Phase::ALL
            .iter()
            .filter_map(|&p| {
                let b: Vec<BoundaryLag> = self
                    .boundaries
                    .iter()
                    .filter(|b| b.phase == p)
                    .copied()
                    .collect();
                (!b.is_empty()).then(|| (p, LagStats::from_boundaries(b)))
            })
            .collect()
    }
}

/// The lag of on-line phase changes behind an offline segmentation of the same session (same
/// clock): every offline boundary (the start of each phase after the first, `offline` being a
/// session's phases in time order, every skill's) is matched to the on-line change into the
/// same phase whose decision is nearest in time, within [`MATCH_WINDOW_NS`]; its lag is
/// `decided_ns − boundary`.
pub fn phase_lag(online: &[PhaseChange], offline: &[PhaseSpan]) -> LagStats {
    let boundaries = offline
        .iter()
        .skip(1)
        .map(|span| {
            let b = span.start_ns;
            let best = online
                .iter()
                .filter(|c| c.phase == span.phase && c.decided_ns.abs_diff(b) <= MATCH_WINDOW_NS)
                .min_by_key(|c| c.decided_ns.abs_diff(b));
            let ms = |t: u64| (t as f64 - b as f64) * 1e-6;
            BoundaryLag {
                phase: span.phase,
                offline_ns: b,
                lag_ms: best.map(|c| ms(c.decided_ns)),
                start_error_ms: best.map(|c| ms(c.start_ns)),
            }
        })
        .collect();
    LagStats::from_boundaries(boundaries)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic session: minimum-jerk moves of the hand base and intervals of contact.
    struct Synth {
        /// (start s, duration s, displacement m, turn about z rad).
        moves: Vec<(f64, f64, Vector, f64)>,
        /// (from s, to s): three fingertips in contact.
        contact: Vec<(f64, f64)>,
        end_s: f64,
    }

    impl Synth {
        /// Approach (down), preshape (sideways), grasp, lift, hold, place, release, retreat:
        /// the built-in scenarios' script. Boundaries (s): preshape 0.8, grasp 1.3, lift 2.1,
        /// hold 3.1, place 4.1, release 5.1, retreat 5.7.
        fn pick() -> Synth {
            Synth {
                moves: vec![
                    (0.0, 0.8, Vector::new(0.0, 0.0, -0.15), 0.0),
                    (0.8, 0.5, Vector::new(0.0, -0.09, -0.01), 0.0),
                    (2.1, 1.0, Vector::new(0.0, 0.0, 0.1), 0.0),
                    (4.1, 1.0, Vector::new(0.0, 0.0, -0.098), 0.0),
                    (5.7, 0.6, Vector::new(0.0, 0.0, 0.1), 0.0),
                ],
                contact: vec![(1.6, 5.4)],
                end_s: 6.8,
            }
        }

        fn base(&self, t: f64) -> Isometry {
            let mut p = Vector::new(0.3, 0.1, 0.3);
            let mut yaw = 0.0;
            for &(s, d, dp, turn) in &self.moves {
                let x = ((t - s) / d).clamp(0.0, 1.0);
                let m = x * x * x * (10.0 - 15.0 * x + 6.0 * x * x);
                p += dp * m;
                yaw += turn * m;
            }
            Isometry::from_parts(p.into(), Rotation::from_euler_angles(0.0, 0.0, yaw))
        }

        fn obs(&self, t_ns: u64) -> PhaseObservation {
            let t = t_ns as f64 * 1e-9;
            let on = self.contact.iter().any(|&(a, b)| t >= a && t < b);
            PhaseObservation {
                t_ns,
                base: self.base(t),
                touching: if on { 3 } else { 0 },
            }
        }

        /// Sample times every `step_ns`.
        fn times(&self, step_ns: u64) -> Vec<u64> {
            (0..)
                .map(|i| i * step_ns)
                .take_while(|&t| (t as f64) * 1e-9 <= self.end_s)
                .collect()
        }
    }

    fn feed(synth: &Synth, times: &[u64]) -> Vec<PhaseChange> {
        let mut est = OnlinePhase::new(&SegmentParams::default());
        times
            .iter()
            .filter_map(|&t| est.push(&synth.obs(t)))
            .collect()
    }

    fn names(changes: &[PhaseChange]) -> Vec<Phase> {
        changes.iter().map(|c| c.phase).collect()
    }

    const PICK: [Phase; 7] = [
        Phase::Preshape,
        Phase::Grasp,
        Phase::Lift,
        Phase::Hold,
        Phase::Place,
        Phase::Release,
        Phase::Retreat,
    ];
    const PICK_S: [f64; 7] = [0.8, 1.3, 2.1, 3.1, 4.1, 5.1, 5.7];

    /// Every change within `tol_ms` after (or 30 ms before) its boundary.
    fn assert_near(changes: &[PhaseChange], boundaries: &[f64], tol_ms: f64) {
        assert_eq!(changes.len(), boundaries.len(), "{changes:?}");
        for (c, b) in changes.iter().zip(boundaries) {
            let lag = c.decided_ns as f64 * 1e-6 - b * 1e3;
            assert!((-30.0..=tol_ms).contains(&lag), "{c:?} vs {b} s: {lag} ms");
            assert!(c.start_ns <= c.decided_ns);
        }
    }

    #[test]
    fn a_scripted_pick_is_followed_phase_by_phase_at_1_khz_and_100_hz() {
        let synth = Synth::pick();
        for step in [1_000_000, 10_000_000] {
            let changes = feed(&synth, &synth.times(step));
            assert_eq!(names(&changes), PICK, "{changes:?}");
            assert_near(&changes, &PICK_S, 100.0);
        }
    }

    #[test]
    fn jittered_sample_times_at_any_rate_change_nothing() {
        let synth = Synth::pick();
        let mut state = 12345u64;
        let mut rand = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for mean_ms in [1.0, 3.0, 10.0] {
            let mut times = Vec::new();
            let mut t = 0.0f64;
            while t <= synth.end_s {
                times.push((t * 1e9) as u64);
                // ±50 % jitter around the mean period.
                t += mean_ms * 1e-3 * (0.5 + rand());
            }
            let changes = feed(&synth, &times);
            assert_eq!(names(&changes), PICK, "{mean_ms} ms: {changes:?}");
            assert_near(&changes, &PICK_S, 100.0);
        }
    }

    #[test]
    fn a_pause_mid_approach_keeps_the_approach_and_the_move_after_it_is_the_preshape() {
        // Down, half a second's pause, then sideways into the grasp: as offline, the move
        // after the pause is the preshape, and the pause is the approach's.
        let mut synth = Synth::pick();
        synth.moves[0] = (0.0, 0.5, Vector::new(0.0, 0.0, -0.15), 0.0);
        for m in &mut synth.moves[1..] {
            m.0 += 0.2;
        }
        synth.contact = vec![(1.8, 5.6)];
        synth.end_s += 0.2;
        let changes = feed(&synth, &synth.times(1_000_000));
        assert_eq!(names(&changes), PICK, "{changes:?}");
        assert_near(&changes, &PICK_S.map(|b| b + 0.2), 100.0);

        // Down in two moves with half a second between them, a fifth of a second's pause, then
        // sideways: the second move reads as a preshape and its rest as the grasp until the
        // hand moves on (offline, only the last move is the preshape).
        let mut synth = Synth::pick();
        synth.moves[0] = (0.0, 0.5, Vector::new(0.0, 0.0, -0.08), 0.0);
        synth
            .moves
            .insert(1, (1.0, 0.4, Vector::new(0.0, 0.0, -0.07), 0.0));
        for m in &mut synth.moves[2..] {
            m.0 += 0.8;
        }
        synth.contact = vec![(2.4, 6.2)];
        synth.end_s += 0.8;
        let changes = feed(&synth, &synth.times(1_000_000));
        let expected = [
            Phase::Preshape,
            Phase::Grasp,
            Phase::Preshape,
            Phase::Grasp,
            Phase::Lift,
            Phase::Hold,
            Phase::Place,
            Phase::Release,
            Phase::Retreat,
        ];
        assert_eq!(names(&changes), expected, "{changes:?}");
        assert_near(
            &changes,
            &[1.0, 1.4, 1.6, 2.1, 2.9, 3.9, 4.9, 5.9, 6.5],
            100.0,
        );
        // Nothing changes in the first pause.
        assert!(changes[0].decided_ns > 1_000_000_000, "{changes:?}");
    }

    #[test]
    fn a_single_approach_move_is_grasped_when_contact_begins() {
        let mut synth = Synth::pick();
        synth.moves.remove(1);
        let changes = feed(&synth, &synth.times(1_000_000));
        assert_eq!(names(&changes), &PICK[1..], "{changes:?}");
        // Decided at contact (1.6 s), starting at the move's end (0.8 s).
        assert_eq!(changes[0].decided_ns, 1_600_000_000);
        let start = changes[0].start_ns as f64 * 1e-6;
        assert!((750.0..=820.0).contains(&start), "{changes:?}");
    }

    #[test]
    fn a_gap_in_the_samples_delays_decisions_to_the_next_sample_only() {
        let synth = Synth::pick();
        // Nothing from 3.05 s to 3.3 s (the lift's last 50 ms and the hold's start) nor from
        // 4.0 to 4.3 s (the place's start): the speed across a gap is its mean speed, as
        // offline (linear interpolation).
        let times: Vec<u64> = synth
            .times(1_000_000)
            .into_iter()
            .filter(|&t| !(3_050_000_000..3_300_000_000).contains(&t))
            .filter(|&t| !(4_000_000_000..4_300_000_000).contains(&t))
            .collect();
        let changes = feed(&synth, &times);
        assert_eq!(names(&changes), PICK, "{changes:?}");
        // Both are seen at the first sample after their gap.
        assert_eq!(changes[3].decided_ns, 3_300_000_000, "{changes:?}");
        assert_eq!(changes[4].decided_ns, 4_300_000_000, "{changes:?}");
        assert!(changes[4].start_ns < 4_300_000_000);
    }

    #[test]
    fn nan_poses_duplicates_and_samples_back_in_time_are_ignored() {
        let synth = Synth::pick();
        let mut est = OnlinePhase::new(&SegmentParams::default());
        let mut changes = Vec::new();
        for (i, t) in synth.times(1_000_000).into_iter().enumerate() {
            let mut obs = synth.obs(t);
            match i % 7 {
                0 => obs.base.translation.vector.x = f64::NAN,
                3 => {
                    obs.base.rotation =
                        Rotation::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0))
                }
                5 => obs.base.translation.vector.z = f64::INFINITY,
                _ => {}
            }
            changes.extend(est.push(&obs));
            // The same time again, and an earlier one with a wild pose and contact: nothing.
            let phase = est.phase();
            assert_eq!(est.push(&obs), None);
            let mut back = synth.obs(t.saturating_sub(5_000_000));
            back.base.translation.vector.z += 1.0;
            back.touching = 5 - back.touching.min(5);
            assert_eq!(est.push(&back), None);
            assert_eq!(est.phase(), phase);
            assert!(est.speed().is_finite());
        }
        assert_eq!(names(&changes), PICK, "{changes:?}");
        assert_near(&changes, &PICK_S, 100.0);
        // A zero quaternion, an empty stream's first sample: no panic.
        let mut est = OnlinePhase::new(&SegmentParams::default());
        let mut obs = synth.obs(0);
        obs.base.rotation = Rotation::new_unchecked(nalgebra::Quaternion::new(0.0, 0.0, 0.0, 0.0));
        assert_eq!(est.push(&obs), None);
        assert_eq!(est.phase(), Phase::Approach);
    }

    #[test]
    fn a_turn_in_contact_is_a_transport_and_a_new_reach_after_the_retreat_an_approach() {
        let mut synth = Synth::pick();
        // A turn on the spot while held (3.2-4.0 s), the place after it, and after the retreat
        // a second reach and grasp of something else.
        synth
            .moves
            .push((3.2, 0.8, Vector::new(0.0, 0.0, 0.0), 0.8));
        synth.moves[3].0 += 0.9;
        synth.moves[4].0 += 0.9;
        synth.contact = vec![(1.6, 6.3), (8.5, 9.5)];
        synth
            .moves
            .push((7.4, 0.6, Vector::new(0.1, 0.0, -0.1), 0.0));
        synth
            .moves
            .push((8.0, 0.3, Vector::new(0.03, 0.0, 0.0), 0.0));
        synth.end_s = 9.8;
        synth.moves.sort_by(|a, b| a.0.total_cmp(&b.0));
        let changes = feed(&synth, &synth.times(2_000_000));
        let expected = [
            Phase::Preshape,
            Phase::Grasp,
            Phase::Lift,
            Phase::Hold,
            Phase::Transport,
            Phase::Hold,
            Phase::Place,
            Phase::Release,
            Phase::Retreat,
            Phase::Approach,
            Phase::Preshape,
            Phase::Grasp,
        ];
        assert_eq!(names(&changes), expected, "{changes:?}");
        // The second approach starts at the retreat's end (7.2 s).
        let approach = changes[9];
        assert!(
            (7.1e9..=7.25e9).contains(&(approach.start_ns as f64)),
            "{approach:?}"
        );
    }

    #[test]
    fn the_lag_matches_each_boundary_to_the_nearest_change_into_its_phase() {
        let span = |phase, start_ns, end_ns| PhaseSpan {
            phase,
            start_ns,
            end_ns,
        };
        let ms = 1_000_000;
        let offline = [
            span(Phase::Approach, 0, 800 * ms),
            span(Phase::Preshape, 800 * ms, 1300 * ms),
            span(Phase::Grasp, 1300 * ms, 2100 * ms),
            span(Phase::Lift, 2100 * ms, 3100 * ms),
            span(Phase::Hold, 3100 * ms, 9000 * ms),
        ];
        let change = |phase, decided, start| PhaseChange {
            phase,
            decided_ns: decided * ms,
            start_ns: start * ms,
        };
        let online = [
            change(Phase::Preshape, 840, 790),
            change(Phase::Grasp, 1290, 1280),
            change(Phase::Hold, 1500, 1500),
            change(Phase::Lift, 2170, 2110),
            // The hold's nearest change is 1.6 s away: unmatched.
            change(Phase::Hold, 4700, 4700),
        ];
        let s = phase_lag(&online, &offline);
        assert_eq!((s.matched, s.total), (3, 4));
        assert_eq!(s.lags_ms, vec![40.0, -10.0, 70.0]);
        assert_eq!(s.median_abs_ms, 40.0);
        assert_eq!(s.p90_abs_ms, 70.0);
        assert_eq!(s.matched_fraction(), 0.75);
        assert_eq!(s.boundaries[0].start_error_ms, Some(-10.0));
        assert_eq!(s.boundaries[3].lag_ms, None);
        let per = s.per_phase();
        assert_eq!(
            per.iter().map(|(p, _)| *p).collect::<Vec<_>>(),
            [Phase::Preshape, Phase::Grasp, Phase::Lift, Phase::Hold]
        );
        let both = s.merged(&s);
        assert_eq!((both.matched, both.total), (6, 8));
        assert_eq!(both.median_abs_ms, 40.0);
        let none = phase_lag(&[], &[]);
        assert_eq!((none.total, none.median_abs_ms), (0, 0.0));
        assert_eq!(none.matched_fraction(), 1.0);
    }
}
