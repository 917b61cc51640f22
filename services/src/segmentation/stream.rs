//! The two streamed passes over a session's samples ([`SessionVisitor`]s): pass one builds the
//! grid and plans the candidate skills, pass two feeds each candidate the samples of its span
//! (as its object sees them) and keeps the grasps.

use std::collections::BTreeMap;

use super::accumulate::SkillAcc;
use super::grammar::plan;
use super::grid::{grasped_object, GridBuilder};
use super::params::{is_grasp, object_params};
use super::pose::{iso, pose_of};
use super::{SegmentParams, Segmentation};
use crate::error::RecordingError;
use crate::session::{Contacts, DecodeTopics, ObjectState, SessionVisitor};

/// Pass one: the grid, then the candidate skills.
pub(super) struct PassOne {
    grid: GridBuilder,
}

impl PassOne {
    /// Pass one, on a grid of step [`SegmentParams::grid_s`].
    pub(super) fn new(params: &SegmentParams) -> Self {
        PassOne {
            grid: GridBuilder::new(params),
        }
    }

    /// The second pass, for the candidate skills the grid holds.
    pub(super) fn finish(
        self,
        metadata: &BTreeMap<String, String>,
        params: &SegmentParams,
    ) -> PassTwo {
        let runs = self.grid.runs.clone();
        let (t0, skills) = match self.grid.finish() {
            None => (0, Vec::new()),
            Some(g) => {
                let skills = plan(&g, params)
                    .into_iter()
                    .map(|phases| {
                        let start = phases.first().map_or(0, |p| p.start_ns);
                        let end = phases.last().map_or(0, |p| p.end_ns);
                        let index = grasped_object(&runs, start, end);
                        let object = object_params(metadata, index);
                        let mut acc = SkillAcc::new(phases, object, metadata, params);
                        acc.object_index = index as u32;
                        acc
                    })
                    .collect();
                (g.t0, skills)
            }
        };
        PassTwo {
            t0,
            skills,
            first_open: 0,
            last_contact: 0,
            last_object: 0,
            before: None,
        }
    }
}

impl SessionVisitor for PassOne {
    fn wants(&self) -> DecodeTopics {
        DecodeTopics::SEGMENTATION
    }
    fn contacts(&mut self, t: u64, m: &Contacts) -> Result<(), RecordingError> {
        self.grid.contacts(t, m);
        Ok(())
    }
    fn object(&mut self, t: u64, m: &ObjectState) -> Result<(), RecordingError> {
        self.grid.object(t, m);
        Ok(())
    }
}

/// Pass two: each candidate skill's accumulators, fed the samples of its time span.
pub(super) struct PassTwo {
    /// Log time of the grid's first point: session time 0.
    t0: u64,
    skills: Vec<SkillAcc>,
    /// Skills before this one have seen every sample they need.
    first_open: usize,
    /// Log times of the latest contact and object samples.
    last_contact: u64,
    last_object: u64,
    /// The latest object sample.
    before: Option<(u64, ObjectState)>,
}

impl PassTwo {
    /// The grasps among the candidate skills, in session time.
    pub(super) fn finish(self) -> Segmentation {
        let t0 = self.t0;
        let skills = self
            .skills
            .into_iter()
            .filter_map(SkillAcc::finish)
            .filter(|s| is_grasp(&s.parameters))
            .map(|mut s| {
                // Log times to session time: recorders need not start their clocks at 0 (ROS
                // bags and most MCAP writers log epoch times).
                for p in &mut s.phases {
                    p.start_ns -= t0;
                    p.end_ns -= t0;
                }
                s.parameters.source.start_ns -= t0;
                s.parameters.source.end_ns -= t0;
                s
            })
            .collect();
        Segmentation { skills }
    }
}

impl PassTwo {
    /// Skips the skills that samples from here on cannot change.
    fn close(&mut self) {
        let t = self.last_contact.min(self.last_object);
        while self.skills.get(self.first_open).is_some_and(|s| s.done(t)) {
            self.first_open += 1;
        }
    }
}

impl SessionVisitor for PassTwo {
    fn wants(&self) -> DecodeTopics {
        DecodeTopics::SEGMENTATION
    }
    fn contacts(&mut self, t: u64, m: &Contacts) -> Result<(), RecordingError> {
        self.last_contact = t;
        // Skills are in time order: those not started yet take nothing.
        for s in &mut self.skills[self.first_open..] {
            if t < s.start {
                break;
            }
            s.contacts(t, &contacts_on(m, s.object_index));
        }
        self.close();
        Ok(())
    }
    fn object(&mut self, t: u64, m: &ObjectState) -> Result<(), RecordingError> {
        self.last_object = t;
        for s in &mut self.skills[self.first_open..] {
            if t < s.start {
                break;
            }
            let index = s.object_index;
            if !s.seeded {
                s.seeded = true;
                if let Some((tp, p)) = &self.before {
                    s.object(*tp, &object_view(p, index));
                }
            }
            s.object(t, &object_view(m, index));
        }
        self.before = Some((t, m.clone()));
        self.close();
        Ok(())
    }
    fn done(&self) -> bool {
        self.first_open == self.skills.len()
    }
    fn segmentation_fields_only(&self) -> bool {
        true
    }
}

/// `c` as a skill of object `index` sees it: the fingertips touching another object of the
/// scene are not touching (its object). Borrowed when none does (always with one object).
fn contacts_on(c: &Contacts, index: u32) -> std::borrow::Cow<'_, Contacts> {
    if c.fingers.iter().all(|f| !f.touching || f.object == index) {
        return std::borrow::Cow::Borrowed(c);
    }
    let mut own = c.clone();
    for f in own
        .fingers
        .iter_mut()
        .filter(|f| f.touching && f.object != index)
    {
        *f = crate::session::FingerContact {
            name: std::mem::take(&mut f.name),
            part: f.part,
            link: std::mem::take(&mut f.link),
            ..Default::default()
        };
    }
    own.n_contacts = own.fingers.iter().filter(|f| f.in_contact).count() as u32;
    std::borrow::Cow::Owned(own)
}

/// Object `index`'s state from an `/object/state` sample: the sample itself when its main
/// fields are that object's (always with one object), else its entry in `objects` with its
/// pose in the hand (the hand's base from the main fields); wrenches are not recorded for it.
/// An index the sample does not list gives the sample.
fn object_view(m: &ObjectState, index: u32) -> std::borrow::Cow<'_, ObjectState> {
    let Some(o) = m.objects.get(index as usize).filter(|_| m.index != index) else {
        return std::borrow::Cow::Borrowed(m);
    };
    let base = iso(&m.pose) * iso(&m.pose_in_hand).inverse();
    let pose = iso(&o.pose);
    std::borrow::Cow::Owned(ObjectState {
        pose: o.pose,
        linear_velocity: o.linear_velocity,
        angular_velocity_b: o.angular_velocity_b,
        pose_in_hand: pose_of(&(base.inverse() * pose)),
        index,
        ..ObjectState::default()
    })
}
