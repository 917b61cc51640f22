//! Whether the hand carried the object during a skill, decided as the samples come.

use dfs_core::math::Vector;
use dfs_core::scenario::Phase;

use super::pose::v3;
use super::{PhaseSpan, SegmentParams};
use crate::session::{Contacts, ObjectState};

/// Whether the hand carried the object during a skill, decided as the samples come: at some
/// contact sample from the start of `grasp` to the skill's end with at least two fingertips
/// transmitting force, the object (its last sample at or before that time) is
/// [`SegmentParams::min_carry_m`] or more from where it was when two fingertips first
/// transmitted force, and it moved with the hand: its displacement relative to the hand's base
/// is less than half its displacement in the world. An object the fingers squeeze but cannot
/// lift (too heavy, too small to hold, frictionless), one pushed or knocked away, or one that
/// only rocks in the fingers is not carried.
///
/// Contacts and object samples come interleaved tick by tick in our files (a handful wait
/// here); a file that writes one topic well ahead of the other makes the one ahead wait, up to
/// the skill's length.
pub(super) struct CarryState {
    from: u64,
    to: u64,
    min_carry_m: f64,
    /// Contact samples (log times) waiting for the object's sample at or before them.
    pending: std::collections::VecDeque<u64>,
    /// Object samples that a contact sample to come may need: (log time, position in the
    /// world, position in the hand), from the latest one at or before the later of `from` and
    /// the last contact sample.
    track: std::collections::VecDeque<(u64, Vector, Vector)>,
    /// Log time of the latest contact sample.
    last_contact: u64,
    reference: Option<(Vector, Vector)>,
    carried: bool,
}

impl CarryState {
    /// The test for a skill of `phases` (log times).
    pub(super) fn new(phases: &[PhaseSpan], params: &SegmentParams) -> Self {
        let first = phases.first().map_or(0, |p| p.start_ns);
        CarryState {
            from: phases
                .iter()
                .find(|p| p.phase == Phase::Grasp)
                .map_or(first, |p| p.start_ns),
            to: phases.last().map_or(0, |p| p.end_ns),
            min_carry_m: params.min_carry_m,
            pending: std::collections::VecDeque::new(),
            track: std::collections::VecDeque::new(),
            last_contact: 0,
            reference: None,
            carried: false,
        }
    }

    /// A contact sample.
    pub(super) fn contacts(&mut self, t: u64, c: &Contacts) {
        self.last_contact = t;
        if !self.carried
            && t >= self.from
            && t < self.to
            && c.fingers.iter().filter(|f| f.in_contact).count() >= 2
        {
            self.pending.push_back(t);
        }
        self.resolve(false);
    }

    /// An object sample.
    pub(super) fn object(&mut self, t: u64, o: &ObjectState) {
        let (p, h) = (v3(&o.pose.position), v3(&o.pose_in_hand.position));
        // Past the skill's end one sample is enough (it says the ones before are final): the
        // track holds at most the skill's samples, whatever the order of the file's topics.
        let past_end = self.track.back().is_some_and(|s| s.0 >= self.to);
        if self.carried || past_end || !p.iter().chain(h.iter()).all(|v| v.is_finite()) {
            return;
        }
        self.track.push_back((t, p, h));
        self.resolve(false);
    }

    /// Decides the waiting contact samples that an object sample after them (or, at the
    /// `end`, the last one) has made decidable, then forgets the object samples no contact
    /// sample to come can need.
    fn resolve(&mut self, end: bool) {
        while let Some(&tc) = self.pending.front() {
            if self.carried {
                self.pending.clear();
                break;
            }
            if !end && self.track.back().is_none_or(|s| s.0 <= tc) {
                break;
            }
            while self.track.len() >= 2 && self.track[1].0 <= tc {
                self.track.pop_front();
            }
            let Some(&(_, p, h)) = self.track.front() else {
                break;
            };
            self.pending.pop_front();
            match self.reference {
                None => self.reference = Some((p, h)),
                Some((p0, h0)) => {
                    let moved = (p - p0).norm();
                    if moved >= self.min_carry_m && (h - h0).norm() < 0.5 * moved {
                        self.carried = true;
                    }
                }
            }
        }
        if self.pending.is_empty() {
            let keep_from = self.last_contact.max(self.from);
            while self.track.len() >= 2 && self.track[1].0 <= keep_from {
                self.track.pop_front();
            }
        }
        if self.carried {
            self.track.clear();
        }
    }

    /// Whether nothing more can change the verdict once both topics reached `t`.
    pub(super) fn done(&self, t: u64) -> bool {
        self.carried || (t >= self.to && self.pending.is_empty())
    }

    /// Whether the hand carried the object, once every sample is in.
    pub(super) fn finish(mut self) -> bool {
        self.resolve(true);
        self.carried
    }
}
