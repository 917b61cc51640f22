//! The on-line recogniser: from a stream of [`Observation`]s, which stored skill the operator
//! is performing and on which object, as early as it can say.
//!
//! # How it decides
//!
//! Every object of the scene has a [`TemplateBuilder`]. When the grasp centre crosses one of
//! [`CHECKPOINTS_M`] of an object (from the one at index [`RecogniserParams::decide_from`]
//! in) and that object is among the nearest to the hand (within
//! [`RecogniserParams::near_margin_m`] of the nearest's distance), the object's template so
//! far is compared with every stored skill's ([`RecognitionIndex::rank_templates`]):
//!
//! - nearest distance above [`RecogniserParams::open_set_distance`]: nothing stored fits,
//!   `unknown` (open set);
//! - else the [`RecogniserParams::top_k`] nearest vote for their kinds with weights
//!   `exp(−(d − d_best) / T)`; when the best skill's kind has at least
//!   [`RecogniserParams::min_confidence`] of the weight, `recognised` names the object, the
//!   skill, the confidence and the runners-up (the best skills of the other kinds). A weaker
//!   vote waits for the next checkpoint; at the contact onset the best guess is said whatever
//!   its confidence.
//!
//! A verdict is sent again only when it changes (another object, another kind, or known ↔
//! unknown), so a reach that turns to another object is followed.
//!
//! [`RecogniserParams::grasp_stage_ns`] after the first touch of the object, once two
//! contacts touch it (fingertips, and with whole-hand contact the palm and phalanges, which a
//! stored skill counts among its contacts as well), the *grasp stage* compares what is known
//! of the grasp by then (object, contacts, grasp quality: [`GRASP_STAGE_DIMS`] of the feature
//! vector `similar` uses, and the held force per weight: the grip then times the ratio the
//! stored grasps of the shape and grasp type keep, [`RecognitionIndex::held_per_grip`]) with
//! the stored skills' features, takes the [`GRASP_CANDIDATES`] nearest, orders them by what
//! the stored grasps like it (shape, grasp type) done in a scene like this one do next
//! ([`NEXT_DIMS`]: hold time, lift, transport, rotation, not seen yet) and names the first;
//! whether anything fits (`unknown`) is judged on the nearest on what is known. When nothing of the hand has
//! touched for [`RecogniserParams::release_ns`], the grasp is over and the next reach begins.
//!
//! # Cost per call
//!
//! The grasp stage's grasp quality (a convex hull in six dimensions of up to 200 primitive
//! wrenches) takes a few hundred µs: more than one observation, or one sample, may cost. It is
//! computed a part at a time ([`QualityJob`]): [`RecogniserParams::grasp_budget`] units of work
//! per observation period, in slices of [`RecogniserParams::grasp_slice`] units, the first in
//! [`Recogniser::observe`], the others in [`Recogniser::work`] calls between observations (the
//! live assistant's thread makes them while no observation waits; an offline run makes them
//! right after each observation, so both come to the same verdicts). The stored skills are
//! ranked at the observation after it is done; the verdict carries the time it is said, a few
//! observations after the decision began (the contacts it describes are those up to then). The
//! held force line and ratio of each shape are computed once, when the recogniser is made.
//!
//! A comparison with the stored skills (an approach decision's with their templates, the
//! grasp stage's with their features) reads a few hundred kB of columns with 10 000 stored
//! skills: 50-100 µs when they are not in the cache. It is done a part at a time too
//! ([`RecognitionIndex::go_on`], slices of [`RecogniserParams::grasp_slice`] units), in
//! [`Recogniser::observe`] and the [`Recogniser::work`] calls after it, which say its verdict
//! with the observation's time. What an observation decides is finished, in order, before
//! anything of the next ([`Recogniser::busy`]): the verdicts are those of one call per
//! observation.

use std::sync::Arc;

use dfs_core::contact::{ContactFrame, ContactModel, Friction};
use dfs_core::grasp::quality::{GraspQuality, QualityJob, QualityParams};
use dfs_core::hand::{MAX_CONTACT_SHAPES, MAX_TIPS};
use dfs_core::math::Vector;
use dfs_core::object::ShapeKind;
use serde::{Deserialize, Serialize};

use crate::store::FEATURE_DIM;

use super::features::{
    ObjectInfo, Observation, Progress, TemplateBuilder, CHECKPOINTS_M, GRIP_AT_NS, GRIP_DIM,
    TEMPLATE_DIM,
};
use super::index::{Ranked, RecognitionIndex, Scratch, GRASP_STAGE_DIMS, NEXT_DIMS};

/// Tuning of the recogniser. The defaults were set on `icms bench recognition`'s training
/// sessions (seeds apart from its held-out ones).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecogniserParams {
    /// First checkpoint (index into [`CHECKPOINTS_M`]) whose crossing may decide. Default 1
    /// (12 cm).
    pub decide_from: usize,
    /// Share of the vote the best kind needs. Default 0.8.
    pub min_confidence: f32,
    /// Above this nearest template distance (mean squared scaled difference) nothing stored
    /// fits. Default 6.
    pub open_set_distance: f32,
    /// Skills that vote. Default 16.
    pub top_k: usize,
    /// Temperature of the vote's weights. Default 1.
    pub temperature: f32,
    /// Objects farther than this beyond the nearest one's distance (m) are not named.
    /// Default 0.03.
    pub near_margin_m: f64,
    /// The grasp stage decides this long after a fingertip first touched the object (ns), once
    /// two touch it: late enough to see the fingers settle, early enough to say it within a
    /// second of the first touch. Default 800 ms, when the templates take the grip
    /// ([`GRIP_AT_NS`]); a decision earlier than that predicts the held force from μ.
    pub grasp_stage_ns: u64,
    /// Above this feature distance the grasp stage says `unknown` when the approach gave no
    /// verdict. Default 1.
    pub grasp_open_set_distance: f32,
    /// A grasp is over when no fingertip has touched an object this long (ns). Default 300 ms.
    pub release_ns: u64,
    /// Work of the grasp stage's grasp quality per observation period ([`QualityJob::advance`]'s
    /// units, of about 0.1 µs). Default 10 000 (about 1 ms of the 10 ms period, in slices,
    /// during the few periods a quality takes), so that the verdict of a power grasp (eight to
    /// ten contacts, 160-200 primitive wrenches), whose second contact comes late, is said
    /// within 1 s of the first touch (`icms bench recognition`, 2026-11-27: 1500 units took 26
    /// periods and said power grasps' verdicts at 1.02-1.52 s, nearest by 1 s 50 %; 5000 and
    /// more, 62 %). Since a slice stops as soon as its units are spent (before, it ended only
    /// between two rounds of the hull and did more than its units), 10 000 does what 5 000 did
    /// then: on the bench's sessions every grasp-stage verdict is the same, said as early or
    /// one or two periods earlier (with 5 000 now, four to eight periods later).
    pub grasp_budget: usize,
    /// The most of [`RecogniserParams::grasp_budget`] one call ([`Recogniser::observe`] or
    /// [`Recogniser::work`]) does, and the most of a comparison with the stored skills.
    /// Default 150 (15-20 µs, 40 µs at most): an observation arriving waits for one slice at
    /// most. A slice stops as soon as its units are spent, in the middle of a round of the
    /// hull if need be.
    pub grasp_slice: usize,
    /// Whether the grasp stage computes the grasp quality of the contacts so far and compares
    /// it (feature dimensions 3 and 4). Default true. Without it a grasp-stage decision costs
    /// the comparison only; on `icms bench recognition`'s held-out sessions (2026-11-26) the
    /// nearest stored skill was then named in 65 % against 67.5 % with it.
    pub grasp_quality: bool,
}

impl Default for RecogniserParams {
    fn default() -> Self {
        RecogniserParams {
            decide_from: 1,
            min_confidence: 0.8,
            open_set_distance: 6.0,
            top_k: 16,
            temperature: 1.0,
            near_margin_m: 0.03,
            grasp_stage_ns: GRIP_AT_NS,
            grasp_open_set_distance: 1.0,
            release_ns: 300_000_000,
            grasp_budget: 10_000,
            grasp_slice: 150,
            grasp_quality: true,
        }
    }
}

/// Which part of a grasp a verdict was made in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Before the fingertips closed: from the reach and the hand's shape.
    Approach,
    /// Shortly after they closed: from the contacts too.
    Grasp,
}

/// A stored skill a verdict names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// The skill's id.
    pub skill_id: i64,
    /// Its kind (`box/precision-2vf`).
    pub kind: String,
    /// Its distance to what was seen (see [`RecognitionIndex::rank_templates`] and
    /// [`RecognitionIndex::rank_features`]: at the grasp stage, over the dimensions known
    /// then).
    pub distance: f32,
    /// Its kind's share of the vote (approach stage; 0 at the grasp stage).
    pub confidence: f32,
}

/// What the recogniser says.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Verdict {
    /// A stored skill fits.
    Recognised {
        /// Session time of the decision (ns).
        session_ns: u64,
        /// Approach or grasp.
        stage: Stage,
        /// The object the operator is expected to grasp (its name in the scene).
        object: String,
        /// The skill.
        skill: Candidate,
        /// The best skills of the other kinds (approach), or the next nearest (grasp: in the
        /// order of what they do next, [`GRASP_CANDIDATES`]).
        runners_up: Vec<Candidate>,
    },
    /// Nothing stored fits: the grasp will be learned.
    Unknown {
        /// Session time of the decision (ns).
        session_ns: u64,
        /// Approach or grasp.
        stage: Stage,
        /// The object the operator is expected to grasp.
        object: String,
        /// The nearest stored skill, if any is stored.
        nearest: Option<Candidate>,
    },
}

impl Verdict {
    /// Session time of the decision (ns).
    pub fn session_ns(&self) -> u64 {
        match self {
            Verdict::Recognised { session_ns, .. } | Verdict::Unknown { session_ns, .. } => {
                *session_ns
            }
        }
    }

    /// The stage.
    pub fn stage(&self) -> Stage {
        match self {
            Verdict::Recognised { stage, .. } | Verdict::Unknown { stage, .. } => *stage,
        }
    }

    /// The object named.
    pub fn object(&self) -> &str {
        match self {
            Verdict::Recognised { object, .. } | Verdict::Unknown { object, .. } => object,
        }
    }

    /// The skill recognised (`None` for `unknown`).
    pub fn skill(&self) -> Option<&Candidate> {
        match self {
            Verdict::Recognised { skill, .. } => Some(skill),
            Verdict::Unknown { .. } => None,
        }
    }
}

/// What is accumulated of one fingertip's contact with the grasped object.
#[derive(Debug, Clone, Copy, Default)]
struct TipSum {
    p_b: Vector,
    n_b: Vector,
    count: u32,
}

/// The grasp being made: the object two contacts touch and what they did.
#[derive(Debug, Clone, Copy)]
struct GraspTrack {
    object: usize,
    since_ns: u64,
    observations: u32,
    tips: [TipSum; MAX_TIPS],
    /// Per whole-hand contact shape ([`Observation::body`]).
    body: [TipSum; MAX_CONTACT_SHAPES],
    decided: bool,
}

/// A grasp-stage decision under way (see the module docs).
#[derive(Debug)]
struct PendingGrasp {
    /// The object (index in the scene).
    object: usize,
    /// The query, the grasp quality's dimensions not yet filled in.
    query: [f32; FEATURE_DIM],
    /// The grasp quality of the contacts, while it is computed (`None`: no contact, or it
    /// failed: its dimensions stay 0).
    job: Option<QualityJob>,
    /// The grip on the object (the template's, [`GRIP_DIM`]; NaN when not taken).
    grip: f32,
}

/// What an observation leaves to do when [`Recogniser::observe`] returns: its decisions, in
/// the order one call would take them, for [`Recogniser::work`] to go on with.
#[derive(Debug)]
struct Unfinished {
    obs: Observation,
    /// The approach-stage decisions it takes, in order: the object and whether its best guess
    /// is said at any confidence (a checkpoint crossed, the contact onset).
    approach: [Option<(usize, bool)>; 2],
    phase: Phase,
}

/// Where an [`Unfinished`] observation is.
#[derive(Debug, Clone, Copy)]
enum Phase {
    /// Approach decision `k` (its ranking begun or not).
    Approach { k: usize, begun: bool },
    /// The grasp followed: the grasp stage's step (a slice of its quality, or its decision
    /// begun) to do.
    Grasp,
    /// The grasp-stage decision on `object`: its ranking under way.
    GraspDecision { object: usize },
}

/// The recogniser of one stream. See the module docs.
#[derive(Debug)]
pub struct Recogniser {
    index: Arc<RecognitionIndex>,
    objects: Vec<ObjectInfo>,
    params: RecogniserParams,
    builders: Vec<TemplateBuilder>,
    /// The last approach verdict of this grasp: object, and the kind (`None`: unknown).
    said: Option<(usize, Option<u32>)>,
    grasp: Option<GraspTrack>,
    pending: Option<PendingGrasp>,
    /// What the last observation left to do.
    unfinished: Option<Unfinished>,
    /// What is left of this observation period's [`RecogniserParams::grasp_budget`].
    allowance: usize,
    last_touch_ns: Option<u64>,
    scratch: Scratch,
    /// Per shape (sphere, box, cylinder): [`RecognitionIndex::held_force_line`].
    held_lines: [Option<(f32, f32)>; 3],
    /// Per shape (sphere, box, cylinder) and grasp type (precision, power):
    /// [`RecognitionIndex::held_per_grip`].
    held_per_grip: [[Option<f32>; 2]; 3],
    /// The query of the grasp-stage decision under way.
    grasp_query: Option<[f32; FEATURE_DIM]>,
    /// Decisions taken (template or feature comparisons), of them at the grasp stage, calls
    /// that worked on an approach-stage and a grasp-stage decision, and the verdicts.
    decisions: u64,
    grasp_decisions: u64,
    approach_steps: u64,
    grasp_steps: u64,
    verdicts: Vec<Verdict>,
}

impl Recogniser {
    /// A recogniser of a scene's `objects` (in the scene's order) against `index`.
    pub fn new(
        index: Arc<RecognitionIndex>,
        objects: Vec<ObjectInfo>,
        params: RecogniserParams,
    ) -> Recogniser {
        let builders = fresh_builders(&objects);
        let held_lines = std::array::from_fn(|k| {
            let mut shape = [0.0f32; 3];
            shape[k] = 1.0;
            index.held_force_line(shape)
        });
        let held_per_grip = std::array::from_fn(|k| {
            let mut shape = [0.0f32; 3];
            shape[k] = 1.0;
            [false, true].map(|power| index.held_per_grip(shape, power))
        });
        Recogniser {
            index,
            objects,
            params,
            builders,
            said: None,
            grasp: None,
            pending: None,
            unfinished: None,
            allowance: 0,
            last_touch_ns: None,
            scratch: Scratch::default(),
            held_lines,
            held_per_grip,
            grasp_query: None,
            decisions: 0,
            grasp_decisions: 0,
            approach_steps: 0,
            grasp_steps: 0,
            verdicts: Vec::new(),
        }
    }

    /// The stored skills it compares with.
    pub fn index(&self) -> &RecognitionIndex {
        &self.index
    }

    /// Every verdict so far, in order.
    pub fn verdicts(&self) -> &[Verdict] {
        &self.verdicts
    }

    /// Comparisons with the stored skills made so far.
    pub fn decisions(&self) -> u64 {
        self.decisions
    }

    /// Of [`Recogniser::decisions`], those of the grasp stage.
    pub fn grasp_decisions(&self) -> u64 {
        self.grasp_decisions
    }

    /// Calls ([`Recogniser::observe`] or [`Recogniser::work`]) that worked on a grasp-stage
    /// decision (a slice of its grasp quality, or the comparison with the stored skills).
    pub fn grasp_steps(&self) -> u64 {
        self.grasp_steps
    }

    /// Calls ([`Recogniser::observe`] or [`Recogniser::work`]) that worked on an
    /// approach-stage decision (began it, or a slice of its comparison with the stored skills).
    pub fn approach_steps(&self) -> u64 {
        self.approach_steps
    }

    /// Whether the last observation's decisions are still under way ([`Recogniser::work`]
    /// goes on with them; the next observation finishes them first).
    pub fn busy(&self) -> bool {
        self.unfinished.is_some()
    }

    /// Takes one observation; returns the verdicts it led to in this call (usually none; a
    /// decision's comparison with the stored skills may go on in [`Recogniser::work`] calls,
    /// which say its verdict, with this observation's time). What the previous observation
    /// left unfinished is finished first, whole.
    pub fn observe(&mut self, obs: &Observation) -> &[Verdict] {
        let before = self.verdicts.len();
        while !self.resume(usize::MAX) {}
        let hand = obs.hand();
        let n = self.builders.len().min(obs.n_objects);
        let mut crossed: Option<(usize, usize)> = None;
        let mut onset: Option<usize> = None;
        for i in 0..n {
            let shape = self.objects[i].shape;
            match self.builders[i].observe(obs, &hand, &shape) {
                Progress::Checkpoint(k) if crossed.is_none_or(|(_, kk)| k > kk) => {
                    crossed = Some((i, k))
                }
                Progress::Onset => onset = Some(i),
                _ => {}
            }
        }
        let mut approach = [None; 2];
        if let Some((i, k)) = crossed {
            if k >= self.params.decide_from && self.is_near(i) {
                approach[0] = Some((i, k + 1 == CHECKPOINTS_M.len()));
            }
        }
        if let Some(i) = onset {
            approach[1] = Some((i, true));
        }
        self.unfinished = Some(Unfinished {
            obs: *obs,
            approach,
            phase: Phase::Approach { k: 0, begun: false },
        });
        self.resume(self.params.grasp_slice.max(1));
        &self.verdicts[before..]
    }

    /// Does one more slice of work: of the last observation's decisions while they are under
    /// way, else of the grasp-stage decision's grasp quality if this observation period's
    /// budget allows; true while there is more of either for this period. Call it between
    /// observations (see the module docs).
    pub fn work(&mut self) -> bool {
        if self.unfinished.is_some() {
            self.resume(self.params.grasp_slice.max(1));
        } else {
            match &self.pending {
                Some(PendingGrasp { job: Some(_), .. }) if self.allowance > 0 => {}
                _ => return false,
            }
            self.advance_quality();
        }
        self.unfinished.is_some()
            || (self.allowance > 0
                && matches!(self.pending, Some(PendingGrasp { job: Some(_), .. })))
    }

    /// Goes on with what the last observation left ([`Unfinished`]) for about `budget`
    /// units of the stored skills' comparisons ([`RecognitionIndex::go_on`]'s), in the order
    /// one call would have done it; whether all of it is done. The grasp stage's slice of its
    /// grasp quality waits for a call that has compared nothing.
    fn resume(&mut self, mut budget: usize) -> bool {
        let index = Arc::clone(&self.index);
        // Whether this call compared with the stored skills for an approach-stage or a
        // grasp-stage decision.
        let (mut approach_step, mut grasp_step) = (false, false);
        while let Some(u) = &mut self.unfinished {
            let t_ns = u.obs.t_ns;
            match u.phase {
                Phase::Approach { k, begun } if k < u.approach.len() => {
                    let Some((i, last)) = u.approach[k] else {
                        u.phase = Phase::Approach {
                            k: k + 1,
                            begun: false,
                        };
                        continue;
                    };
                    if !begun {
                        // The grasp's own stage decides from here on.
                        let next = if self.grasp.is_some_and(|g| g.decided) {
                            Phase::Approach {
                                k: k + 1,
                                begun: false,
                            }
                        } else {
                            Phase::Approach { k, begun: true }
                        };
                        u.phase = next;
                        if let Phase::Approach { begun: true, .. } = next {
                            self.decisions += 1;
                            let template: [f32; TEMPLATE_DIM] = *self.builders[i].template();
                            index.begin_templates(
                                &template,
                                self.params.top_k,
                                MIN_COMPARED,
                                &mut self.scratch,
                            );
                        }
                        continue;
                    }
                    if budget == 0 {
                        return false;
                    }
                    if !approach_step {
                        self.approach_steps += 1;
                        approach_step = true;
                    }
                    if !index.go_on(&mut self.scratch, &mut budget) {
                        return false;
                    }
                    u.phase = Phase::Approach {
                        k: k + 1,
                        begun: false,
                    };
                    self.decide_approach(i, t_ns, last);
                }
                Phase::Approach { .. } => {
                    let obs = u.obs;
                    u.phase = Phase::Grasp;
                    self.track_grasp(&obs);
                    self.allowance = self.params.grasp_budget;
                }
                Phase::Grasp => {
                    let Some(p) = &self.pending else {
                        self.unfinished = None;
                        break;
                    };
                    if p.job.is_some() {
                        if approach_step || grasp_step {
                            return false;
                        }
                        self.advance_quality();
                        self.unfinished = None;
                        break;
                    }
                    let (i, query, grip) = (p.object, p.query, p.grip);
                    self.pending = None;
                    self.begin_grasp_decision(i, query, grip);
                    if let Some(u) = &mut self.unfinished {
                        u.phase = Phase::GraspDecision { object: i };
                    }
                }
                Phase::GraspDecision { object } => {
                    if budget == 0 {
                        return false;
                    }
                    if !grasp_step {
                        self.grasp_steps += 1;
                        grasp_step = true;
                    }
                    if !index.go_on(&mut self.scratch, &mut budget) {
                        return false;
                    }
                    self.unfinished = None;
                    self.decide_grasp(object, t_ns);
                }
            }
        }
        true
    }

    /// Whether object `i` is among the nearest to the hand.
    fn is_near(&self, i: usize) -> bool {
        let nearest = self
            .builders
            .iter()
            .map(|b| b.distance_m())
            .fold(f64::INFINITY, f64::min);
        self.builders[i].distance_m() <= nearest + self.params.near_margin_m
    }

    /// An approach-stage decision on object `i`, its template ranked against the stored
    /// skills' ([`RecognitionIndex::begin_templates`], in `self.scratch`); `last` says it at
    /// any confidence.
    fn decide_approach(&mut self, i: usize, t_ns: u64, last: bool) {
        let p = self.params;
        let index = Arc::clone(&self.index);
        let ranked = self.scratch.ranked().to_vec();
        let object = self.objects[i].name.clone();
        let Some(best) = ranked.first().copied() else {
            self.say(i, None, || Verdict::Unknown {
                session_ns: t_ns,
                stage: Stage::Approach,
                object,
                nearest: None,
            });
            return;
        };
        let candidate = |r: &super::index::Ranked, confidence: f32| Candidate {
            skill_id: index.skill_id(r.row),
            kind: index.kind(r.row).to_owned(),
            distance: r.distance,
            confidence,
        };
        if best.distance > p.open_set_distance {
            let nearest = candidate(&best, 0.0);
            self.say(i, None, || Verdict::Unknown {
                session_ns: t_ns,
                stage: Stage::Approach,
                object,
                nearest: Some(nearest),
            });
            return;
        }
        let (kind, confidence, shares) = vote(&index, &ranked, p.temperature);
        if confidence < p.min_confidence && !last {
            return;
        }
        let skill = candidate(&best, confidence);
        let runners_up: Vec<Candidate> = shares
            .iter()
            .filter(|s| s.0 != kind)
            .take(3)
            .map(|s| {
                let r = ranked
                    .iter()
                    .find(|r| r.row == s.2)
                    .copied()
                    .unwrap_or(best);
                candidate(&r, s.1)
            })
            .collect();
        self.say(i, Some(kind), || Verdict::Recognised {
            session_ns: t_ns,
            stage: Stage::Approach,
            object,
            skill,
            runners_up,
        });
    }

    /// Records a verdict on object `i` of kind `kind` (`None`: unknown) if it differs from the
    /// last one said of this grasp.
    fn say(&mut self, i: usize, kind: Option<u32>, verdict: impl FnOnce() -> Verdict) {
        if self.said == Some((i, kind)) {
            return;
        }
        self.said = Some((i, kind));
        self.verdicts.push(verdict());
    }

    /// Follows the grasp: the grasp stage, and the end of the grasp.
    fn track_grasp(&mut self, obs: &Observation) {
        let t = obs.t_ns;
        let mut touching_any = false;
        for touch in obs.touch[..obs.n_tips]
            .iter()
            .chain(&obs.body[..obs.n_body])
            .flatten()
        {
            touching_any |= touch.object < self.builders.len();
        }
        if touching_any {
            self.last_touch_ns = Some(t);
        } else if let Some(last) = self.last_touch_ns {
            if t.saturating_sub(last) >= self.params.release_ns {
                // The grasp is over: the next reach starts from scratch.
                self.builders = fresh_builders(&self.objects);
                self.said = None;
                self.grasp = None;
                self.pending = None;
                self.last_touch_ns = None;
            }
            return;
        }
        // The object two or more contacts touch (fingertips, and the palm and phalanges of a
        // power grasp).
        let held = (0..self.builders.len().min(obs.n_objects)).find(|&i| obs.hand_touching(i) >= 2);
        let Some(i) = held else {
            if self.grasp.is_some_and(|g| !g.decided) {
                self.grasp = None;
            }
            return;
        };
        let g = match &mut self.grasp {
            Some(g) if g.object == i => g,
            Some(g) if g.decided => return,
            _ => self.grasp.insert(GraspTrack {
                object: i,
                since_ns: t,
                observations: 0,
                tips: [TipSum::default(); MAX_TIPS],
                body: [TipSum::default(); MAX_CONTACT_SHAPES],
                decided: false,
            }),
        };
        if g.decided {
            return;
        }
        g.observations += 1;
        let sums = g.tips[..obs.n_tips]
            .iter_mut()
            .zip(&obs.touch[..obs.n_tips])
            .chain(g.body[..obs.n_body].iter_mut().zip(&obs.body[..obs.n_body]));
        for (s, touch) in sums {
            if let Some(touch) = touch.filter(|x| x.object == i) {
                s.p_b += touch.p_b;
                s.n_b += touch.normal_b;
                s.count += 1;
            }
        }
        let first_touch = self.builders[i].first_touch_ns().unwrap_or(g.since_ns);
        if t.saturating_sub(first_touch) >= self.params.grasp_stage_ns {
            g.decided = true;
            let g = *g;
            let (query, job) = grasp_query(&self.objects[g.object], &g);
            let job = job.filter(|_| self.params.grasp_quality);
            self.pending = Some(PendingGrasp {
                object: g.object,
                query,
                job,
                grip: self.builders[g.object].template()[GRIP_DIM],
            });
        }
    }

    /// One slice of the pending grasp quality: at most [`RecogniserParams::grasp_slice`] of
    /// what is left of the period's budget (the whole of an unlimited one).
    fn advance_quality(&mut self) {
        let Some(p) = &mut self.pending else { return };
        let Some(job) = &mut p.job else { return };
        self.grasp_steps += 1;
        let slice = if self.allowance == usize::MAX {
            usize::MAX
        } else {
            self.params.grasp_slice.clamp(1, self.allowance.max(1))
        };
        self.allowance = self.allowance.saturating_sub(slice);
        match job.advance(slice) {
            Ok(None) => return,
            Ok(Some(q)) => set_quality(&mut p.query, Some(&q)),
            // A hull that fails its checks: the quality's dimensions stay 0, as at ingest.
            Err(_) => set_quality(&mut p.query, None),
        }
        p.job = None;
    }

    /// Begins the grasp-stage decision on object `i`, its quality known and `grip` taken
    /// (NaN if not): the ranking of the stored skills' features against `query` (in
    /// `self.scratch`).
    fn begin_grasp_decision(&mut self, i: usize, mut query: [f32; FEATURE_DIM], grip: f32) {
        self.decisions += 1;
        self.grasp_decisions += 1;
        let index = Arc::clone(&self.index);
        // The held force per weight (dimension 5) is the mean over the whole held part, not
        // seen yet (the grip peaks at lift-off and relaxes after): it is the grip taken now
        // times the ratio the stored grasps of the shape and grasp type keep between the two
        // (a person grips alike in every grasp of one kind), or without stored grips,
        // predicted from μ as the stored grasps of the shape hold theirs.
        let mut dims = [0usize; GRASP_STAGE_DIMS.len() + 1];
        let mut n_dims = 0;
        for &d in &GRASP_STAGE_DIMS {
            if self.params.grasp_quality || !matches!(d, 3 | 4) {
                dims[n_dims] = d;
                n_dims += 1;
            }
        }
        // The query's shape, when it is one of the three.
        let shape =
            (0..3).find(|&k| (0..3).all(|j| query[13 + j] == if j == k { 1.0 } else { 0.0 }));
        let ratio = shape.and_then(|k| self.held_per_grip[k][usize::from(query[2] > 3.0)]);
        let held = match ratio.filter(|_| grip.is_finite()) {
            Some(ratio) => Some(grip * ratio),
            None => {
                let mu = self.objects[i].mu as f32;
                let line = match shape {
                    Some(k) => self.held_lines[k],
                    None => index.held_force_line([query[13], query[14], query[15]]),
                };
                line.filter(|_| mu > 0.05).map(|(a, b)| a + b / mu)
            }
        };
        if let Some(held) = held {
            query[5] = held;
            dims[n_dims] = 5;
            n_dims += 1;
        }
        self.grasp_query = Some(query);
        index.begin_features(&query, &dims[..n_dims], GRASP_CANDIDATES, &mut self.scratch);
    }

    /// The grasp-stage decision on object `i`, its ranking done: the nearest
    /// [`GRASP_CANDIDATES`] on what is known, ordered by what they will do next
    /// ([`by_what_comes_next`]), the first four said.
    fn decide_grasp(&mut self, i: usize, t_ns: u64) {
        let index = Arc::clone(&self.index);
        let mut ranked = self.scratch.ranked().to_vec();
        // Whether anything stored fits is judged on what is known (the nearest on it, which an
        // `unknown` names), before the order by what comes next.
        let nearest_known = ranked.first().copied();
        if let Some(query) = self.grasp_query.take() {
            by_what_comes_next(&index, &mut ranked, &query, self.objects.len());
        }
        ranked.truncate(4);
        let object = self.objects[i].name.clone();
        let candidate = |r: &super::index::Ranked| Candidate {
            skill_id: index.skill_id(r.row),
            kind: index.kind(r.row).to_owned(),
            distance: r.distance,
            confidence: 0.0,
        };
        let approach_unknown = self.said == Some((i, None));
        let approach_said = self.said.is_some_and(|s| s.0 == i);
        let unknown = match nearest_known {
            None => true,
            Some(best) => {
                approach_unknown
                    || (!approach_said && best.distance > self.params.grasp_open_set_distance)
            }
        };
        let verdict = if unknown {
            Verdict::Unknown {
                session_ns: t_ns,
                stage: Stage::Grasp,
                object,
                nearest: nearest_known.as_ref().map(candidate),
            }
        } else {
            Verdict::Recognised {
                session_ns: t_ns,
                stage: Stage::Grasp,
                object,
                skill: candidate(&ranked[0]),
                runners_up: ranked[1..].iter().map(candidate).collect(),
            }
        };
        self.verdicts.push(verdict);
    }
}

/// Stored skills the grasp stage ranks on what is known of the grasp; the nearest of them by
/// what it will do next is named.
pub const GRASP_CANDIDATES: usize = 8;

/// Orders `ranked` (the nearest stored skills on the dimensions known at the grasp stage,
/// their distances over those) by the whole feature vector: what the grasp does next (hold
/// time, lift, transport, rotation: [`NEXT_DIMS`], not seen yet) is taken as the mean of the
/// candidates *like it*, of the query's shape and grasp type (`query`'s dimensions 13-15, and
/// more than three contacts or not) stored in a scene of as many objects as this one
/// (`scene_objects`): what a grasp does after it closes goes with the task, and the task with
/// the scene. Candidates not like it come after those like it, whatever they do next. Each
/// candidate's distance stays the one on what is known (the order alone changes); without a
/// candidate like it the order stays.
fn by_what_comes_next(
    index: &RecognitionIndex,
    ranked: &mut [Ranked],
    query: &[f32; FEATURE_DIM],
    scene_objects: usize,
) {
    let like =
        |f: &[f32; FEATURE_DIM]| f[13..16] == query[13..16] && (f[2] > 3.0) == (query[2] > 3.0);
    let mut next = [0.0f32; NEXT_DIMS.len()];
    let mut n = 0usize;
    for r in ranked.iter() {
        let f = index.feature(r.row);
        if like(&f) && index.scene_objects(r.row) == Some(scene_objects) {
            for (v, &d) in next.iter_mut().zip(&NEXT_DIMS) {
                *v += f[d];
            }
            n += 1;
        }
    }
    if n == 0 {
        return;
    }
    for v in &mut next {
        *v /= n as f32;
    }
    // Unlike ones last, then the squared distance over the whole vector (a stable sort: ties
    // keep their order).
    let key = |r: &Ranked| {
        let f = index.feature(r.row);
        let more: f32 = next
            .iter()
            .zip(&NEXT_DIMS)
            .map(|(v, &d)| (f[d] - v).powi(2))
            .sum();
        (!like(&f), r.distance * r.distance + more)
    };
    ranked.sort_by(|a, b| {
        let (ka, kb) = (key(a), key(b));
        ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
    });
}

fn fresh_builders(objects: &[ObjectInfo]) -> Vec<TemplateBuilder> {
    objects
        .iter()
        .enumerate()
        .map(|(i, o)| TemplateBuilder::new(i, o, objects.len()))
        .collect()
}

/// What the feature vector of a grasp is known to be at the grasp stage: the object, and the
/// fingertips that touched it for 30 % of the observations since two first did (their mean
/// points and normals), as the segmentation computes them over the held part
/// (`segmentation::FEATURE_DIMENSIONS`). The other dimensions are 0 (not compared); the grasp
/// quality's (3 and 4) are filled in by [`set_quality`] from the job returned (`None`: no
/// contact, or the quality's parameters refused).
fn grasp_query(object: &ObjectInfo, g: &GraspTrack) -> ([f32; FEATURE_DIM], Option<QualityJob>) {
    let mut frames =
        [ContactFrame::from_normal(Vector::zeros(), Vector::z()); MAX_TIPS + MAX_CONTACT_SHAPES];
    let mut n = 0;
    let mut mean_abs = Vector::zeros();
    let needed = (g.observations as f64 * 0.3).max(1.0);
    for s in g.tips.iter().chain(&g.body) {
        if (s.count as f64) < needed {
            continue;
        }
        let p = s.p_b / s.count as f64;
        let Some(normal) = s.n_b.try_normalize(1e-9) else {
            continue;
        };
        frames[n] = ContactFrame::from_normal(p, normal);
        mean_abs += normal.abs();
        n += 1;
    }
    if n > 0 {
        mean_abs /= n as f64;
    }
    let sizes = object.shape.sizes();
    let qp = QualityParams {
        torque_scale: Some(sizes.iter().map(|v| v * v).sum::<f64>().sqrt()),
        ..QualityParams::default()
    };
    let friction = Friction {
        mu: object.mu,
        mu_torsion: object.mu_torsion,
    };
    let job = (n > 0)
        .then(|| QualityJob::new(&frames[..n], ContactModel::SoftFinger, &friction, &qp).ok())
        .flatten();
    let kind = object.shape.kind();
    let raw = [
        object.mass.max(1e-9).ln(),
        object.mu,
        n as f64,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        mean_abs.x,
        mean_abs.y,
        mean_abs.z,
        (kind == ShapeKind::Sphere) as u8 as f64,
        (kind == ShapeKind::Box) as u8 as f64,
        (kind == ShapeKind::Cylinder) as u8 as f64,
    ];
    (raw.map(finite_f32), job)
}

/// Fills in the grasp quality's dimensions of a grasp-stage query (ε, and the wrench space's
/// volume^(1/6)); `None` leaves them 0.
fn set_quality(query: &mut [f32; FEATURE_DIM], quality: Option<&GraspQuality>) {
    query[3] = finite_f32(quality.map_or(0.0, |q| q.epsilon));
    query[4] = finite_f32(quality.map_or(0.0, |q| q.volume.max(0.0).powf(1.0 / 6.0)));
}

fn finite_f32(v: f64) -> f32 {
    if v.is_finite() {
        v as f32
    } else {
        0.0
    }
}

/// Values a stored template and a query must have in common to be compared in an approach
/// decision: the object and one checkpoint (a skill without a template is left out; the
/// scene's value, which both have, counts among them).
pub const MIN_COMPARED: usize = super::features::OBJECT_DIMS + super::features::CHECKPOINT_DIMS;

/// On-line learning's decision for a completed grasp: the stored skill it matched, or `None`
/// (store it as new). With an approach template, the template decides as the approach stage
/// does (nearest farther than [`RecogniserParams::open_set_distance`]: new; else the vote's
/// kind), and the grasp is linked to the stored skill of that kind nearest by its whole
/// feature vector (the distance `similar` uses). Without one, the nearest by feature within
/// [`RecogniserParams::grasp_open_set_distance`] of the grasp-stage dimensions.
pub fn link_completed(
    index: &RecognitionIndex,
    template: Option<&[f32; TEMPLATE_DIM]>,
    feature: &[f32; FEATURE_DIM],
    params: &RecogniserParams,
    scratch: &mut Scratch,
) -> Option<i64> {
    if index.is_empty() {
        return None;
    }
    let all: [usize; FEATURE_DIM] = std::array::from_fn(|j| j);
    let Some(template) = template else {
        let near = index
            .rank_features(feature, &GRASP_STAGE_DIMS, 1, scratch)
            .first()?;
        if near.distance > params.grasp_open_set_distance {
            return None;
        }
        let row = index.rank_features(feature, &all, 1, scratch).first()?.row;
        return Some(index.skill_id(row));
    };
    let ranked = index
        .rank_templates(template, params.top_k, MIN_COMPARED, scratch)
        .to_vec();
    let best = *ranked.first()?;
    if best.distance > params.open_set_distance {
        return None;
    }
    let kind = vote(index, &ranked, params.temperature).0;
    let n = index.len();
    index
        .rank_features(feature, &all, n, scratch)
        .iter()
        .find(|r| index.kind_index(r.row) == kind)
        .map(|r| index.skill_id(r.row))
}

/// The kind the ranked skills vote for, its share, and every kind's (kind, share, best row).
fn vote(
    index: &RecognitionIndex,
    ranked: &[super::index::Ranked],
    temperature: f32,
) -> (u32, f32, Vec<(u32, f32, usize)>) {
    let Some(best) = ranked.first() else {
        return (0, 0.0, Vec::new());
    };
    let mut shares: Vec<(u32, f32, usize)> = Vec::new();
    let mut total = 0.0f32;
    for r in ranked {
        let w = (-(r.distance - best.distance) / temperature.max(1e-6)).exp();
        total += w;
        let k = index.kind_index(r.row);
        match shares.iter_mut().find(|s| s.0 == k) {
            Some(s) => s.1 += w,
            None => shares.push((k, w, r.row)),
        }
    }
    for s in &mut shares {
        s.1 /= total;
    }
    let kind = index.kind_index(best.row);
    let share = shares.iter().find(|s| s.0 == kind).map_or(0.0, |s| s.1);
    (kind, share, shares)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assist::features::SCENE_DIM;
    use crate::assist::index::StoredTemplate;

    /// A stored pinch (two contacts) of a sphere, or of a box with `boxed`, done in a scene of
    /// `scene` objects, that holds for `hold` s and carries `carry` m, its other dimensions
    /// `known`.
    fn skill(
        id: i64,
        boxed: bool,
        scene: f32,
        known: f32,
        hold: f32,
        carry: f32,
    ) -> StoredTemplate {
        let shape = if boxed {
            [0.0, 1.0, 0.0]
        } else {
            [1.0, 0.0, 0.0]
        };
        let mut template = [f32::NAN; TEMPLATE_DIM];
        template[..3].copy_from_slice(&shape);
        template[SCENE_DIM] = scene;
        let mut feature = [known; FEATURE_DIM];
        feature[2] = 2.0;
        feature[6..10].copy_from_slice(&[hold, 0.0, carry, 0.0]);
        feature[13..].copy_from_slice(&shape);
        StoredTemplate {
            skill_id: id,
            kind: "pinch".into(),
            object_name: None,
            template,
            feature,
        }
    }

    #[test]
    fn the_candidates_are_ordered_by_what_grasps_like_this_one_in_like_scenes_do_next() {
        // Sphere twins on what is known (1 and 3, 2 and 4): 1 and 2 were done alone on the
        // table, holding 2 and 2.2 s; 3 and 4 among three objects, holding 1 s and carrying 0.3
        // m. Box pinches done alone, holding 1 s (5, 6), are no grasps like a sphere's: they
        // take no part in what comes next.
        let index = RecognitionIndex::new([
            skill(1, false, 1.0, 0.5, 2.0, 0.0),
            skill(2, false, 1.0, 0.6, 2.2, 0.0),
            skill(3, false, 3.0, 0.5, 1.0, 0.3),
            skill(4, false, 3.0, 0.6, 1.0, 0.3),
            skill(5, true, 1.0, 0.5, 1.0, 0.0),
            skill(6, true, 1.0, 0.5, 1.0, 0.0),
            // A box pinch among three objects doing just what the sphere grasps there do.
            skill(7, true, 3.0, 0.5, 1.0, 0.3),
        ]);
        let query = index.feature(index.row_of(1).unwrap());
        let row = |id| index.row_of(id).unwrap();
        // As the known dimensions rank them: 1 and 3 at 0.1, 2 and 4 at 0.2, the boxes after.
        let ranked = || {
            [
                (1, 0.1),
                (3, 0.1),
                (7, 0.15),
                (2, 0.2),
                (4, 0.2),
                (5, 2.0),
                (6, 2.0),
            ]
            .map(|(id, distance)| Ranked {
                row: row(id),
                distance,
            })
            .to_vec()
        };
        let ids = |r: &[Ranked]| r.iter().map(|x| index.skill_id(x.row)).collect::<Vec<_>>();
        let mut among_three = ranked();
        by_what_comes_next(&index, &mut among_three, &query, 3);
        // The box that does the same comes after every sphere grasp, however near.
        assert_eq!(ids(&among_three), [3, 4, 1, 2, 7, 5, 6]);
        // The distances stay those on what is known (the order alone changes).
        let mut distances: Vec<f32> = among_three.iter().map(|r| r.distance).collect();
        distances.sort_by(f32::total_cmp);
        assert_eq!(distances, [0.1, 0.1, 0.15, 0.2, 0.2, 2.0, 2.0]);
        // Alone: the sphere grasps done alone hold 2.1 s on the mean; the boxes' 1 s does not
        // count (with them the mean would be 1.55 s, halfway between the twins).
        let mut alone = ranked();
        by_what_comes_next(&index, &mut alone, &query, 1);
        assert_eq!(ids(&alone), [1, 2, 3, 4, 7, 5, 6]);
        let mut boxes_first = ranked();
        boxes_first.swap(0, 4);
        boxes_first.swap(1, 5);
        by_what_comes_next(&index, &mut boxes_first, &query, 1);
        assert_eq!(ids(&boxes_first)[..2], [1, 2]);
        // No candidate like it in a scene of two: the order on what is known stays.
        let mut two = ranked();
        by_what_comes_next(&index, &mut two, &query, 2);
        assert_eq!(two, ranked());
    }
}
