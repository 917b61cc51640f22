//! The assistant over a recorded session: the file's samples turned into [`Observation`]s,
//! for the approach templates stored with a session's skills at ingest and for
//! `icms recognise`.
//!
//! A session file records the glove's joint angles, the contacts and the objects, not the
//! fingertips: they are recomputed by forward kinematics of the hand the session names
//! (`hand` metadata), with the base at `object pose ∘ pose_in_hand⁻¹` as the segmentation
//! finds it. A session of a hand that is not built in needs its model given
//! ([`Observer::new`]); without one, its skills get no template (they are still matched by
//! their features).

use std::collections::BTreeMap;

use dfs_core::dfs::MAX_OBJECTS;
use dfs_core::hand::{
    builtin_hand, thumb_of, HandModel, Kinematics, MAX_CONTACT_SHAPES, MAX_DOF, MAX_TIPS,
};
use dfs_core::math::{Isometry, Vector};
use dfs_core::scenario::{ScenarioObject, DEFAULT_OBJECT_NAME};

use crate::error::RecordingError;
use crate::mcap_io::ReadLimits;
use crate::segmentation::{iso, Skill};
use crate::session::{
    Contacts, DecodeTopics, GloveJointStates, KeptMessages, ObjectState, SessionSource,
    SessionVisitor,
};

use super::features::{
    ObjectInfo, Observation, TemplateBuilder, TipTouch, GRIP_AT_NS, ONSET_WINDOW_NS, TEMPLATE_DIM,
};

/// Observations are made every this much session time (ns): 10 ms, 100 Hz. The hand moves at
/// most a few millimetres between two at a person's speed.
pub const OBSERVATION_PERIOD_NS: u64 = 10_000_000;

/// The objects of a session as its `session` metadata lists them (`objects`, or the one
/// `object`), in the scene's order. Errors name the metadata key.
pub fn scene_of(metadata: &BTreeMap<String, String>) -> Result<Vec<ObjectInfo>, RecordingError> {
    let invalid = |key: &str, detail: String| RecordingError::InvalidInput {
        location: format!("metadata session.{key}"),
        detail,
    };
    let list: Vec<ScenarioObject> = match (metadata.get("objects"), metadata.get("object")) {
        (Some(text), _) if !text.is_empty() => {
            serde_json::from_str(text).map_err(|e| invalid("objects", e.to_string()))?
        }
        (_, Some(text)) if !text.is_empty() => {
            vec![serde_json::from_str(text).map_err(|e| invalid("object", e.to_string()))?]
        }
        _ => {
            return Err(invalid(
                "object",
                "the session does not describe its object".to_owned(),
            ))
        }
    };
    if list.is_empty() {
        return Err(invalid("objects", "the scene has no object".to_owned()));
    }
    list.into_iter()
        .take(MAX_OBJECTS)
        .enumerate()
        .map(|(i, o)| {
            let shape = o
                .to_shape()
                .map_err(|e| invalid(&format!("objects[{i}]"), e.to_string()))?;
            Ok(ObjectInfo {
                name: o.name.unwrap_or_else(|| DEFAULT_OBJECT_NAME.to_owned()),
                shape,
                mass: o.mass,
                mu: o.mu,
                mu_torsion: o.mu_torsion,
            })
        })
        .collect()
}

/// The built-in hand a session names (`hand` metadata), if it is one.
pub fn builtin_hand_of(metadata: &BTreeMap<String, String>) -> Option<HandModel> {
    builtin_hand(metadata.get("hand")?).ok()
}

/// The latest sample of each topic an observation is made of.
struct Latest {
    q_ns: Option<u64>,
    q: [f64; MAX_DOF],
    contacts_ns: Option<u64>,
    touch: [Option<TipTouch>; MAX_TIPS],
    /// Per whole-hand contact shape (slots in the order their names were first seen).
    body: [Option<TipTouch>; MAX_CONTACT_SHAPES],
    object_ns: Option<u64>,
    base: Isometry,
    n_objects: usize,
    objects: [Isometry; MAX_OBJECTS],
}

/// Turns a session's samples into an [`Observation`] every [`OBSERVATION_PERIOD_NS`] of
/// session time (the ticks whose joint angles, contacts and object state have all come), and
/// hands each to `f`. Session time counts from the first `/object/state` sample, as the
/// segmentation's does.
pub struct Observer<F> {
    hand: HandModel,
    kin: Box<Kinematics>,
    thumb: usize,
    latest: Box<Latest>,
    /// The whole-hand contact shapes' names, in the order they were first seen: their slots.
    body_names: Vec<String>,
    t0: Option<u64>,
    next_ns: u64,
    until_ns: Option<u64>,
    f: F,
}

impl<F: FnMut(&Observation)> Observer<F> {
    /// An observer with `hand`'s kinematics.
    pub fn new(hand: HandModel, f: F) -> Observer<F> {
        let thumb = thumb_of(&hand);
        Observer {
            kin: Box::default(),
            hand,
            thumb,
            latest: Box::new(Latest {
                q_ns: None,
                q: [0.0; MAX_DOF],
                contacts_ns: None,
                touch: [None; MAX_TIPS],
                body: [None; MAX_CONTACT_SHAPES],
                object_ns: None,
                base: Isometry::identity(),
                n_objects: 0,
                objects: [Isometry::identity(); MAX_OBJECTS],
            }),
            body_names: Vec::new(),
            t0: None,
            next_ns: 0,
            until_ns: None,
            f,
        }
    }

    /// Stops reading after this session time (ns): [`SessionVisitor::done`] says so.
    pub fn until(mut self, session_ns: u64) -> Self {
        self.until_ns = Some(session_ns);
        self
    }

    fn maybe_observe(&mut self) {
        let l = &self.latest;
        let (Some(tq), Some(tc), Some(to)) = (l.q_ns, l.contacts_ns, l.object_ns) else {
            return;
        };
        if tq != tc || tc != to {
            return;
        }
        let Some(t0) = self.t0 else { return };
        let t = to.saturating_sub(t0);
        if t < self.next_ns {
            return;
        }
        self.next_ns = t + OBSERVATION_PERIOD_NS;
        let n = self.hand.dof();
        self.hand
            .forward_kinematics(&l.base, &l.q[..n], &mut self.kin);
        let mut o = Observation::empty();
        o.t_ns = t;
        o.base = l.base;
        o.n_tips = self.hand.fingertips.len().min(MAX_TIPS);
        o.thumb = self.thumb.min(o.n_tips.saturating_sub(1));
        o.tips[..o.n_tips].copy_from_slice(&self.kin.tip_centres[..o.n_tips]);
        o.touch = l.touch;
        o.n_body = self.body_names.len();
        o.body = l.body;
        o.n_objects = l.n_objects;
        o.objects = l.objects;
        (self.f)(&o);
    }
}

fn v3(v: &crate::foxglove::Vector3) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

impl<F: FnMut(&Observation)> SessionVisitor for Observer<F> {
    fn wants(&self) -> DecodeTopics {
        APPROACH_TOPICS
    }

    fn done(&self) -> bool {
        self.until_ns
            .is_some_and(|u| self.next_ns > u + OBSERVATION_PERIOD_NS)
    }

    fn joint_states(&mut self, t: u64, m: &GloveJointStates) -> Result<(), RecordingError> {
        let n = m.positions.len().min(MAX_DOF);
        self.latest.q = [0.0; MAX_DOF];
        self.latest.q[..n].copy_from_slice(&m.positions[..n]);
        self.latest.q_ns = Some(t);
        self.maybe_observe();
        Ok(())
    }

    fn contacts(&mut self, t: u64, m: &Contacts) -> Result<(), RecordingError> {
        // The hand's fingertips first, in its order; then, with whole-hand contact, the palm
        // and phalanx shapes that touch, by name.
        let n_tips = self.hand.fingertips.len().min(MAX_TIPS);
        let l = &mut *self.latest;
        l.touch = [None; MAX_TIPS];
        l.body = [None; MAX_CONTACT_SHAPES];
        for (k, f) in m.fingers.iter().enumerate() {
            let touch = f.touching.then(|| TipTouch {
                object: f.object as usize,
                p_b: v3(&f.point_b),
                normal_b: v3(&f.normal_b),
                in_contact: f.in_contact,
                normal_force: if f.in_contact {
                    f.transmitted.z.max(0.0)
                } else {
                    0.0
                },
            });
            if k < n_tips {
                l.touch[k] = touch;
                continue;
            }
            let slot = match self.body_names.iter().position(|n| *n == f.name) {
                Some(slot) => slot,
                // A file naming more shapes than a hand can have: the rest are not observed.
                None if self.body_names.len() >= MAX_CONTACT_SHAPES => continue,
                None => {
                    self.body_names.push(f.name.clone());
                    self.body_names.len() - 1
                }
            };
            l.body[slot] = touch;
        }
        self.latest.contacts_ns = Some(t);
        self.maybe_observe();
        Ok(())
    }

    fn object(&mut self, t: u64, m: &ObjectState) -> Result<(), RecordingError> {
        self.t0.get_or_insert(t);
        let l = &mut self.latest;
        l.base = iso(&m.pose) * iso(&m.pose_in_hand).inverse();
        if m.objects.is_empty() {
            l.n_objects = 1;
            l.objects[0] = iso(&m.pose);
        } else {
            l.n_objects = m.objects.len().min(MAX_OBJECTS);
            for (i, o) in m.objects.iter().take(MAX_OBJECTS).enumerate() {
                l.objects[i] = iso(&o.pose);
            }
        }
        l.object_ns = Some(t);
        self.maybe_observe();
        Ok(())
    }
}

/// The raw topics the assistant observes: joint angles (forward kinematics of the hand),
/// contacts (the touch) and object states (where the objects are).
pub const APPROACH_TOPICS: DecodeTopics = DecodeTopics {
    joint_states: true,
    feedback: false,
    contacts: true,
    object: true,
};

/// The approach template of each of a session's skills (see
/// [`super::features`]), in the skills' order: built from the skill's first phase to
/// [`GRIP_AT_NS`] after its first touch (the grip), on the object it grasped. `None` for every skill
/// when the session's hand is not built in and `hand` is not given, or its objects are not
/// described. Reads the messages `kept` by segmentation's first pass if they hold the joint
/// angles, contacts and object states ([`APPROACH_TOPICS`]); otherwise the file once more, up
/// to the last skill's grip.
pub fn approach_templates(
    source: &SessionSource<'_>,
    kept: Option<&KeptMessages>,
    metadata: &BTreeMap<String, String>,
    skills: &[Skill],
    hand: Option<HandModel>,
) -> Result<Vec<Option<[f32; TEMPLATE_DIM]>>, RecordingError> {
    let none = vec![None; skills.len()];
    let (Some(hand), Ok(objects)) = (
        hand.or_else(|| builtin_hand_of(metadata)),
        scene_of(metadata),
    ) else {
        return Ok(none);
    };
    if skills.is_empty() {
        return Ok(none);
    }
    // Each skill's builder, on its object, fed over its span.
    struct Track {
        builder: TemplateBuilder,
        start_ns: u64,
        end_ns: u64,
    }
    let mut tracks: Vec<Option<Track>> = skills
        .iter()
        .map(|s| {
            let name = s
                .parameters
                .object
                .as_ref()
                .and_then(|o| o.name.as_deref())
                .unwrap_or(DEFAULT_OBJECT_NAME);
            let i = objects.iter().position(|o| o.name == name).or(
                // A session's one object, whatever its name.
                (objects.len() == 1).then_some(0),
            )?;
            Some(Track {
                builder: TemplateBuilder::new(i, &objects[i], objects.len()),
                start_ns: s.phases.first()?.start_ns,
                // The template ends with the grip, GRIP_AT_NS after the first touch: the
                // fingers close on the object in `grasp` (the first phase in contact ends it),
                // so the file is read no further than the end of the last grasp's `grasp`
                // phase and that delay.
                end_ns: s
                    .phases
                    .iter()
                    .find(|p| p.phase == dfs_core::scenario::Phase::Grasp)
                    .or(s.phases.last())?
                    .end_ns
                    + ONSET_WINDOW_NS.max(GRIP_AT_NS)
                    + OBSERVATION_PERIOD_NS,
            })
        })
        .collect();
    let last_end = tracks.iter().flatten().map(|t| t.end_ns).max().unwrap_or(0);
    let shapes: Vec<_> = objects.iter().map(|o| o.shape).collect();
    let observer = Observer::new(hand, |obs: &Observation| {
        let hand_view = obs.hand();
        for t in tracks.iter_mut().flatten() {
            if obs.t_ns < t.start_ns || obs.t_ns > t.end_ns || t.builder.done() {
                continue;
            }
            let shape = shapes[t.builder.object()];
            t.builder.observe(obs, &hand_view, &shape);
        }
    });
    let mut observer = observer.until(last_end + ONSET_WINDOW_NS);
    match kept {
        Some(kept) => source.stream_again_kept(&ReadLimits::streaming(), &mut observer, kept)?,
        None => source.stream_again(&ReadLimits::streaming(), &mut observer)?,
    }
    drop(observer);
    Ok(tracks
        .into_iter()
        .map(|t| t.map(|t| *t.builder.template()))
        .collect())
}

/// What the assistant said over a recorded session ([`recognise_source`]).
#[derive(Debug, Clone, serde::Serialize)]
pub struct RecognitionRun {
    /// The session's objects, in its scene's order.
    pub objects: Vec<String>,
    /// Observations made (one per [`OBSERVATION_PERIOD_NS`]).
    pub observations: u64,
    /// Session time (ns) a fingertip first touched each object, by object name.
    pub first_touch_ns: BTreeMap<String, u64>,
    /// The verdicts, with their session times.
    pub verdicts: Vec<super::recognise::Verdict>,
}

/// Runs the live assistant's recogniser over a recorded session against `index`, as it would
/// have run while the session streamed (`icms recognise`). The hand is the session's built-in
/// hand unless `hand` is given. A replay recording is refused.
pub fn recognise_source(
    source: &SessionSource<'_>,
    index: std::sync::Arc<super::index::RecognitionIndex>,
    hand: Option<HandModel>,
    params: &super::recognise::RecogniserParams,
) -> Result<RecognitionRun, RecordingError> {
    let head = source.stream(&ReadLimits::streaming(), &mut ())?;
    head.ensure_grasp_session(&source.name())?;
    let objects = scene_of(&head.metadata)?;
    let Some(hand) = hand.or_else(|| builtin_hand_of(&head.metadata)) else {
        return Err(RecordingError::InvalidInput {
            location: "metadata session.hand".to_owned(),
            detail: format!(
                "{:?} is not a built-in hand: its model is needed to see the fingertips",
                head.metadata.get("hand").map(String::as_str).unwrap_or("")
            ),
        });
    };
    let names: Vec<String> = objects.iter().map(|o| o.name.clone()).collect();
    let mut recogniser = super::recognise::Recogniser::new(index, objects, *params);
    let mut first_touch_ns = BTreeMap::new();
    let mut observations = 0u64;
    let mut observer = Observer::new(hand, |o: &Observation| {
        observations += 1;
        for (i, name) in names.iter().enumerate() {
            if o.touching(i) > 0 {
                first_touch_ns.entry(name.clone()).or_insert(o.t_ns);
            }
        }
        recogniser.observe(o);
        // The period's remaining recognition work, as the live assistant does it between
        // observations.
        while recogniser.work() {}
    });
    source.stream_again(&ReadLimits::streaming(), &mut observer)?;
    drop(observer);
    Ok(RecognitionRun {
        objects: names,
        observations,
        first_touch_ns,
        verdicts: recogniser.verdicts().to_vec(),
    })
}
