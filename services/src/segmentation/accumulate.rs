//! Pass two for one candidate skill: its accumulators, fed the samples of its span one by
//! one (per finger its sums and grip profile, the key poses, the carry test), and the skill's
//! parameters from them at the end.

use std::collections::BTreeMap;

use dfs_core::contact::ContactModel;
use dfs_core::math::{Isometry, Vector};
use dfs_core::scenario::Phase;

use super::carry::CarryState;
use super::params::{
    feature, finite_or_zero, grasp_type, mean_intensity, merge_slips, quality, ObjectExtent,
};
use super::pose::{arr, iso, v3};
use super::{
    ContactParams, KeyPose, ObjectParams, PhaseSpan, SegmentParams, Skill, SkillParameters,
    SkillSource, SlipEvent,
};
use crate::session::{ContactPart, Contacts, ObjectState};

/// The phases in which the hand holds the object.
const HELD: [Phase; 4] = [Phase::Lift, Phase::Hold, Phase::Transport, Phase::Place];

/// A finger's accumulators over a skill.
struct FingerAcc {
    name: String,
    /// The part of the hand (a fingertip, or a palm or phalanx contact shape).
    part: ContactPart,
    steady_n: usize,
    pos: Vector,
    nrm: Vector,
    /// Per phase index of the skill's phases: sums of the intensities and samples.
    per_phase: Vec<([f64; 4], usize)>,
    /// The grip profile at [`SegmentParams::profile_points`] evenly spaced times of the
    /// grasp: each the normal force of the last sample at or before it (the first sample's
    /// for times before it), filled as samples pass those times.
    profile: Vec<f64>,
    /// Profile points filled so far.
    profile_next: usize,
    /// The normal force of the latest sample.
    latest_normal: Option<f64>,
    slip: Option<u64>,
}

/// Pass two for one candidate skill: its parameters accumulated sample by sample, holding
/// per finger its sums and grip profile, whatever the skill's length.
pub(super) struct SkillAcc {
    phases: Vec<PhaseSpan>,
    /// Log time of the first phase's start: the skill takes samples from there (and the
    /// object sample before it, for the first contact's object position).
    pub(super) start: u64,
    /// Whether it was handed the object sample before its start.
    pub(super) seeded: bool,
    grasp_start: u64,
    grasp_end: u64,
    held_span: (u64, u64),
    object: Option<ObjectParams>,
    mu: Option<f64>,
    source: SkillSource,
    profile_times: Vec<f64>,
    fingers: Vec<FingerAcc>,
    steady_samples: usize,
    internal: (f64, usize),
    margin_n: f64,
    margin_ratio: f64,
    slips: Vec<SlipEvent>,
    last_t: u64,
    /// Index of the current phase.
    pi: usize,
    carry: CarryState,
    /// The times of the object's key poses (sorted), and for each the first object sample at
    /// or after it, filled as samples pass them; a time after the last sample takes the last.
    key_times: Vec<u64>,
    key_poses: Vec<Option<Isometry>>,
    key_next: usize,
    /// The first object sample at or after the grasp's start: the reference of the motion.
    start_pose: Option<Isometry>,
    last_object: Option<Isometry>,
    /// Which object of the session's scene the skill grasps (0 with one object).
    pub(super) object_index: u32,
}

impl SkillAcc {
    /// The accumulators of a candidate skill of `phases` (log times) on `object`.
    pub(super) fn new(
        phases: Vec<PhaseSpan>,
        object: Option<ObjectParams>,
        metadata: &BTreeMap<String, String>,
        params: &SegmentParams,
    ) -> Self {
        let mu = object.as_ref().map(|o| o.mu);
        let start_ns = phases.first().map_or(0, |p| p.start_ns);
        let end_ns = phases.last().map_or(0, |p| p.end_ns);
        let grasp_start = phases
            .iter()
            .find(|p| p.phase == Phase::Grasp)
            .map_or(start_ns, |p| p.start_ns);
        let grasp_end = phases
            .iter()
            .rev()
            .find(|p| matches!(p.phase, Phase::Release | Phase::Grasp) || HELD.contains(&p.phase))
            .map_or(end_ns, |p| p.end_ns);
        let held_span = {
            let h: Vec<&PhaseSpan> = phases.iter().filter(|p| HELD.contains(&p.phase)).collect();
            match (h.first(), h.last()) {
                (Some(a), Some(b)) => (a.start_ns, b.end_ns),
                _ => (grasp_start, grasp_end),
            }
        };
        // Offsets of the grip profile's points from the grasp's start.
        let span = (grasp_end.saturating_sub(grasp_start)).max(1) as f64;
        let npts = params.profile_points.max(2);
        let profile_times = (0..npts)
            .map(|k| span * k as f64 / (npts - 1) as f64)
            .collect();
        // The object's key poses: phase boundaries and every `keyframe_s` of the grasp.
        let mut key_times: Vec<u64> = phases
            .iter()
            .flat_map(|p| [p.start_ns, p.end_ns])
            .filter(|t| *t >= grasp_start && *t <= grasp_end)
            .collect();
        let step = (params.keyframe_s * 1e9).max(1e6) as u64;
        let mut t = grasp_start;
        while t < grasp_end {
            key_times.push(t);
            t += step;
        }
        key_times.sort_unstable();
        key_times.dedup();
        let source = SkillSource {
            scenario: metadata.get("scenario").cloned().unwrap_or_default(),
            seed: metadata.get("seed").and_then(|s| s.parse().ok()),
            metadata: metadata
                .iter()
                .filter(|(k, _)| matches!(k.as_str(), "hand" | "source" | "started_at"))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect(),
            start_ns,
            end_ns,
        };
        SkillAcc {
            start: start_ns,
            seeded: false,
            grasp_start,
            grasp_end,
            held_span,
            mu,
            object,
            source,
            profile_times,
            fingers: Vec::new(),
            steady_samples: 0,
            internal: (0.0, 0),
            margin_n: f64::INFINITY,
            margin_ratio: f64::INFINITY,
            slips: Vec::new(),
            last_t: grasp_start,
            pi: 0,
            carry: CarryState::new(&phases, params),
            key_poses: vec![None; key_times.len()],
            key_times,
            key_next: 0,
            start_pose: None,
            last_object: None,
            object_index: 0,
            phases,
        }
    }

    /// Whether samples from `t` on can change nothing: the grasp's contact samples are in,
    /// the key poses found, and whether the object was carried decided (which, for a grasp
    /// that carried it, is early: the second pass then stops reading there).
    pub(super) fn done(&self, t: u64) -> bool {
        t >= self.grasp_end
            && self.carry.done(t)
            && self.key_next == self.key_times.len()
            && self.start_pose.is_some()
    }

    /// An object sample (as the skill's object sees it).
    pub(super) fn object(&mut self, t: u64, o: &ObjectState) {
        self.carry.object(t, o);
        let b = iso(&o.pose);
        if self.start_pose.is_none() && t >= self.grasp_start {
            self.start_pose = Some(b);
        }
        while self.key_next < self.key_times.len() && self.key_times[self.key_next] <= t {
            self.key_poses[self.key_next] = Some(b);
            self.key_next += 1;
        }
        self.last_object = Some(b);
    }

    /// A contact sample (as the skill's object sees it).
    pub(super) fn contacts(&mut self, t: u64, c: &Contacts) {
        self.carry.contacts(t, c);
        if t < self.grasp_start || t >= self.grasp_end {
            return;
        }
        self.last_t = t;
        let steady = t >= self.held_span.0 && t < self.held_span.1;
        if steady {
            self.steady_samples += 1;
        }
        // Phases are in time order: advance the current one.
        while self.pi + 1 < self.phases.len() && t >= self.phases[self.pi].end_ns {
            self.pi += 1;
        }
        let pi = self.pi;
        let phase = self.phases.get(pi).map(|p| p.phase);
        let offset = t.saturating_sub(self.grasp_start) as f64;
        let mut sum_n = 0.0;
        for (fi, f) in c.fingers.iter().enumerate() {
            // Fingers come in the same order every tick; look the name up only if not.
            let found = match self.fingers.get(fi) {
                Some(a) if a.name == f.name => Some(fi),
                _ => self.fingers.iter().position(|a| a.name == f.name),
            };
            let a = match found {
                Some(i) => &mut self.fingers[i],
                None => {
                    self.fingers.push(FingerAcc {
                        name: f.name.clone(),
                        part: f.part,
                        steady_n: 0,
                        pos: Vector::zeros(),
                        nrm: Vector::zeros(),
                        per_phase: vec![([0.0; 4], 0); self.phases.len()],
                        profile: vec![0.0; self.profile_times.len()],
                        profile_next: 0,
                        latest_normal: None,
                        slip: None,
                    });
                    self.fingers.last_mut().expect("pushed")
                }
            };
            let i = &f.intensity;
            let normal = if f.in_contact { i.z.max(0.0) } else { 0.0 };
            while a.profile_next < self.profile_times.len()
                && self.profile_times[a.profile_next] < offset
            {
                a.profile[a.profile_next] = a.latest_normal.unwrap_or(normal);
                a.profile_next += 1;
            }
            a.latest_normal = Some(normal);
            if f.slip && f.touching {
                a.slip.get_or_insert(t);
            } else if let Some(s) = a.slip.take() {
                if t - s >= 2_000_000 {
                    self.slips.push(SlipEvent {
                        time_s: (s - self.grasp_start) as f64 * 1e-9,
                        finger: f.name.clone(),
                        duration_s: (t - s) as f64 * 1e-9,
                    });
                }
            }
            if !f.touching {
                continue;
            }
            sum_n += normal;
            let Some(e) = a.per_phase.get_mut(pi) else {
                continue;
            };
            for (k, v) in [i.x, i.y, i.z, i.torsion].into_iter().enumerate() {
                e.0[k] += v;
            }
            e.1 += 1;
            if steady {
                a.steady_n += 1;
                a.pos += v3(&f.point_b);
                a.nrm += v3(&f.normal_b);
            }
            // The friction margin over the held part (closing and opening are excluded: there
            // the normal force is near zero by intent).
            if let (Some(mu), true) = (self.mu, steady && f.in_contact && i.z > 0.05) {
                let ct = i.x.hypot(i.y);
                let m = mu * i.z - ct;
                self.margin_n = self.margin_n.min(m);
                if mu * i.z > 1e-6 {
                    self.margin_ratio = self.margin_ratio.min(m / (mu * i.z));
                }
            }
        }
        if steady && phase.is_some_and(|p| HELD.contains(&p)) {
            self.internal.0 += sum_n;
            self.internal.1 += 1;
        }
    }

    /// The skill, if the hand carried the object.
    pub(super) fn finish(mut self) -> Option<Skill> {
        let carried = std::mem::replace(
            &mut self.carry,
            CarryState::new(&[], &SegmentParams::default()),
        )
        .finish();
        if !carried {
            return None;
        }
        let parameters = self.parameters();
        Some(Skill {
            phases: self.phases,
            parameters,
        })
    }

    /// The skill's parameters from its accumulators (once: it takes their slips and fills
    /// their grip profiles' last points).
    fn parameters(&mut self) -> SkillParameters {
        let (object, mu) = (self.object.clone(), self.mu);
        let slips = merge_slips(self.close_fingers());
        let contacts = self.contact_params();
        // Quality on the mean contacts.
        let quality = quality(object.as_ref(), &contacts);
        let grasp_type = grasp_type(&contacts);
        let (motion, extent) = self.motion();
        let mut phase_durations = BTreeMap::new();
        for p in &self.phases {
            *phase_durations.entry(p.phase).or_insert(0.0) += (p.end_ns - p.start_ns) as f64 * 1e-9;
        }
        let internal = self.internal;
        let internal_force_n = if internal.1 > 0 {
            internal.0 / internal.1 as f64
        } else {
            0.0
        };
        let (friction_margin_n, friction_margin_ratio) = (
            finite_or_zero(self.margin_n),
            finite_or_zero(self.margin_ratio),
        );
        let hold_s = phase_durations.get(&Phase::Hold).copied().unwrap_or(0.0);
        let feature = feature(
            object.as_ref(),
            mu,
            &contacts,
            quality.as_ref(),
            internal_force_n,
            hold_s,
            extent,
        );
        let source = self.source.clone();
        SkillParameters {
            object,
            contact_model: ContactModel::SoftFinger,
            contact_count: contacts.len(),
            contacts,
            internal_force_n,
            friction_margin_n,
            friction_margin_ratio,
            motion,
            phase_durations,
            slip_events: slips,
            quality,
            grasp_type,
            source,
            feature,
        }
    }

    /// The slip events so far, with those still running at the last sample ended there; and
    /// each finger's grip profile points after its last sample given that sample's value.
    fn close_fingers(&mut self) -> Vec<SlipEvent> {
        let grasp_start = self.grasp_start;
        let last_t = self.last_t;
        let mut slips = std::mem::take(&mut self.slips);
        for a in &mut self.fingers {
            if let Some(s) = a.slip.take() {
                slips.push(SlipEvent {
                    time_s: (s - grasp_start) as f64 * 1e-9,
                    finger: a.name.clone(),
                    duration_s: (last_t - s) as f64 * 1e-9,
                });
            }
            // Profile points after the last sample: its value.
            for k in a.profile_next..a.profile.len() {
                a.profile[k] = a.latest_normal.unwrap_or(0.0);
            }
        }
        slips
    }

    /// The skill's contacts: fingers touching for at least 30 % of the steady part, at their
    /// mean position and normal there.
    fn contact_params(&self) -> Vec<ContactParams> {
        let phases = &self.phases;
        let min_n = (self.steady_samples as f64 * 0.3).max(1.0) as usize;
        self.fingers
            .iter()
            .filter(|a| a.steady_n >= min_n && a.nrm.norm() > 0.0)
            .map(|a| {
                let pos = a.pos / a.steady_n as f64;
                let nrm = a.nrm.normalize();
                let grip_profile = a.profile.clone();
                ContactParams {
                    finger: a.name.clone(),
                    part: a.part,
                    position_b: arr(&pos),
                    normal_b: arr(&nrm),
                    mean_intensity: mean_intensity(phases, &a.per_phase),
                    grip_profile,
                }
            })
            .collect()
    }

    /// The object's motion relative to B at grasp start: the first object sample at or after
    /// each key time (the last sample for a key time after it); and how far it went.
    fn motion(&self) -> (Vec<KeyPose>, ObjectExtent) {
        let grasp_start = self.grasp_start;
        let last_object = self.last_object;
        let obj_at = |k: usize| self.key_poses[k].or(last_object);
        let mut motion = Vec::new();
        let (mut lift_h, mut horiz, mut max_rot) = (0.0f64, 0.0f64, 0.0f64);
        if let Some(b0) = self.start_pose.or(last_object) {
            for (k, &t) in self.key_times.iter().enumerate() {
                if let Some(b) = obj_at(k) {
                    let rel = b0.inverse() * b;
                    let d = b.translation.vector - b0.translation.vector;
                    lift_h = lift_h.max(d.z);
                    horiz = horiz.max(d.x.hypot(d.y));
                    max_rot = max_rot.max(rel.rotation.angle());
                    motion.push(KeyPose {
                        time_s: (t - grasp_start) as f64 * 1e-9,
                        position: arr(&rel.translation.vector),
                        rotation: arr(&rel.rotation.scaled_axis()),
                    });
                }
            }
        }
        let extent = ObjectExtent {
            lift_m: lift_h,
            horizontal_m: horiz,
            rotation_rad: max_rot,
        };
        (motion, extent)
    }
}
