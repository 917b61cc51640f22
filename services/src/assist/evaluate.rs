//! Scoring recognition on simulated sessions: what `icms bench recognition` prints and the
//! recognition tests assert.
//!
//! Training sessions (their skills stored, as ingest stores them) and held-out sessions (other
//! seeds) are recorded from scenarios, each session labelled with its *grasp kind*: the
//! target's shape and the grasp style (`sphere/pinch`). Each held-out session is observed
//! once ([`super::offline::Observer`]) and the recogniser run over its observations:
//!
//! - **anticipation**: the last verdict at least [`ANTICIPATION_NS`] before the first contact
//!   names the target object and a stored skill of the session's kind;
//! - **nearest**: the last verdict at most [`NEAREST_WITHIN_NS`] after the first contact names
//!   the stored skill nearest the completed grasp (by the whole feature vector, as `similar`);
//! - **open set**: with every skill of the session's kind left out of the index, the last
//!   verdict by [`NEAREST_WITHIN_NS`] after the first contact is `unknown`, and on-line learning
//!   stores the grasp as new ([`super::recognise::link_completed`]).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use dfs_core::hand::HandModel;
use dfs_core::scenario::{GraspStyle, Scenario};
use serde::Serialize;

use crate::error::RecordingError;
use crate::ingest::analyse_source;
use crate::mcap_io::ReadLimits;
use crate::session::{record_simulation, SessionSource};
use crate::store::FEATURE_DIM;

use super::features::{Observation, TEMPLATE_DIM};
use super::index::{RecognitionIndex, Scratch, StoredTemplate};
use super::offline::{scene_of, Observer};
use super::recognise::{link_completed, Recogniser, RecogniserParams, Stage, Verdict};

/// Anticipation is scored this long before the first contact (ns): 200 ms.
pub const ANTICIPATION_NS: u64 = 200_000_000;
/// The nearest stored skill is scored this long after the first contact (ns): 1 s.
pub const NEAREST_WITHIN_NS: u64 = 1_000_000_000;

/// A grasp kind of a session: the target's shape and the grasp style (`sphere/pinch`).
pub fn grasp_kind(scenario: &Scenario) -> String {
    let shape = scenario
        .target_object()
        .map_or("unknown", |o| o.shape.name());
    let style = match scenario.grasp {
        GraspStyle::Auto => "auto",
        GraspStyle::Pinch => "pinch",
        GraspStyle::Power => "power",
    };
    format!("{shape}/{style}")
}

/// A recorded session, analysed: its stored skills (training) or its observations (held out).
struct Recorded {
    scenario: Scenario,
    kind: String,
    target: String,
    /// The target's skill as ingest stores it.
    skill: Option<(Option<[f32; TEMPLATE_DIM]>, [f32; FEATURE_DIM])>,
    observations: Vec<Observation>,
    first_contact_ns: Option<u64>,
    objects: Vec<super::features::ObjectInfo>,
}

fn record(
    scenario: &Scenario,
    dir: &Path,
    keep_observations: bool,
) -> Result<Recorded, RecordingError> {
    let path = dir.join(format!("{}-{}.mcap", scenario.name, scenario.seed));
    record_simulation(scenario, None, path.as_path(), |_, _| {})?;
    let source = SessionSource::File(&path);
    let (_, skills) = analyse_source(&source)?;
    let target = scenario
        .target_object()
        .and_then(|o| o.name.clone())
        .or_else(|| scenario.target.clone());
    let skill = skills
        .iter()
        .find(|s| target.is_none() || s.object_name == target)
        .map(|s| {
            let approach = s.approach.as_deref().and_then(super::features::template_of);
            let feature =
                <[f32; FEATURE_DIM]>::try_from(s.feature.as_slice()).unwrap_or([0.0; FEATURE_DIM]);
            (approach, feature)
        });
    let head = source.stream(&ReadLimits::streaming(), &mut ())?;
    let objects = scene_of(&head.metadata)?;
    let target_name = target.unwrap_or_else(|| objects[0].name.clone());
    let target_index = objects
        .iter()
        .position(|o| o.name == target_name)
        .unwrap_or(0);
    let mut observations = Vec::new();
    let mut first_contact_ns = None;
    if keep_observations {
        let mut observer = Observer::new(HandModel::glove10(), |o: &Observation| {
            if first_contact_ns.is_none() && o.touching(target_index) > 0 {
                first_contact_ns = Some(o.t_ns);
            }
            observations.push(*o);
        });
        source.stream_again(&ReadLimits::streaming(), &mut observer)?;
    }
    let _ = std::fs::remove_file(&path);
    Ok(Recorded {
        kind: grasp_kind(scenario),
        scenario: scenario.clone(),
        target: target_name,
        skill,
        observations,
        first_contact_ns,
        objects,
    })
}

/// One held-out session's score.
#[derive(Debug, Clone, Serialize)]
pub struct SessionScore {
    /// Scenario name.
    pub scenario: String,
    /// Seed.
    pub seed: u64,
    /// Grasp kind.
    pub kind: String,
    /// The target object.
    pub target: String,
    /// First contact with the target (session ns).
    pub first_contact_ns: Option<u64>,
    /// Anticipation succeeded.
    pub anticipated: bool,
    /// When the anticipating verdict was first said (session ns), if anticipated.
    pub decided_ns: Option<u64>,
    /// That time as a fraction of the reach (session start to first contact).
    pub decided_fraction: Option<f64>,
    /// The nearest stored skill was named by 1 s after the first contact.
    pub nearest_named: bool,
    /// The stored skill nearest the completed grasp (by the whole feature vector).
    pub nearest_skill_id: Option<i64>,
    /// That skill is also the nearest on the dimensions known at the grasp stage, taken
    /// exactly from the completed grasp (what any decision 1 s after the touch could reach).
    pub nearest_on_known_dims: bool,
    /// The verdicts.
    pub verdicts: Vec<Verdict>,
}

/// The open-set score of one held-out session.
#[derive(Debug, Clone, Serialize)]
pub struct OpenSetScore {
    /// Scenario name.
    pub scenario: String,
    /// Seed.
    pub seed: u64,
    /// The kind left out of the index.
    pub kind: String,
    /// Flagged `unknown`.
    pub unknown: bool,
    /// On-line learning stores it as new.
    pub stored_as_new: bool,
}

/// Cost of recognition per call: each observation ([`Recogniser::observe`]), and each slice of
/// work the live assistant does between two ([`Recogniser::work`]: an observation's decisions,
/// the grasp stage's quality) that did some.
#[derive(Debug, Clone, Serialize)]
pub struct Cost {
    /// Stored skills in the index.
    pub stored_skills: usize,
    /// Observations made.
    pub observations: usize,
    /// Calls timed: the observations and the slices of work between them that did some.
    pub calls: usize,
    /// Mean time per call (µs).
    pub mean_us: f64,
    /// 99th percentile (µs).
    pub p99_us: f64,
    /// Slowest (µs).
    pub max_us: f64,
    /// Mean time of a call that worked on an approach-stage decision (the observation that
    /// began it, comparing the reach with the stored skills' templates, or a slice of that
    /// comparison after it) (µs).
    pub approach_decision_mean_us: f64,
    /// The slowest of those (µs).
    pub approach_decision_max_us: f64,
    /// Mean time of an approach-stage decision, all its calls together (µs).
    pub approach_decision_total_us: f64,
    /// Mean time of a call that worked on a grasp-stage decision (a slice of the grasp quality
    /// of the contacts so far, or the comparison with the stored skills' features) (µs).
    pub grasp_step_mean_us: f64,
    /// The slowest of those (µs).
    pub grasp_step_max_us: f64,
    /// Grasp-stage decisions taken.
    pub grasp_decisions: usize,
    /// Observation periods a grasp-stage decision spans, on average (from the one that began
    /// it to the one that said its verdict).
    pub grasp_steps_per_decision: f64,
    /// Each session run [`COST_REPEATS`] times (the recogniser does the same work each time),
    /// per call the least of its times (µs): what the call costs without the times the thread
    /// waited for a core on a loaded machine. Mean, p99 and max.
    pub least_mean_us: f64,
    /// See [`Cost::least_mean_us`].
    pub least_p99_us: f64,
    /// See [`Cost::least_mean_us`].
    pub least_max_us: f64,
}

/// Runs of each held-out session for [`Cost::least_mean_us`].
pub const COST_REPEATS: usize = 3;

/// The whole evaluation.
#[derive(Debug, Clone, Serialize)]
pub struct Evaluation {
    /// Skills stored from the training sessions, per kind.
    pub stored_per_kind: BTreeMap<String, usize>,
    /// Held-out sessions scored.
    pub sessions: Vec<SessionScore>,
    /// Fraction anticipated.
    pub anticipated_fraction: f64,
    /// Fraction whose nearest stored skill was named.
    pub nearest_fraction: f64,
    /// Fraction whose nearest stored skill is the nearest on the dimensions known at the grasp
    /// stage, taken exactly from the completed grasp: the most a decision then could name.
    pub nearest_bound_fraction: f64,
    /// Median decision time as a fraction of the reach.
    pub median_decided_fraction: f64,
    /// Median decision lead before the first contact (ms).
    pub median_lead_ms: f64,
    /// Open-set scores.
    pub open_set: Vec<OpenSetScore>,
    /// Fraction flagged unknown.
    pub unknown_fraction: f64,
    /// Fraction stored as new.
    pub stored_as_new_fraction: f64,
    /// Cost with the index grown to the requested size.
    pub cost: Option<Cost>,
}

/// What to evaluate.
pub struct EvalSetup<'a> {
    /// Training scenarios (their skills are stored).
    pub train: Vec<Scenario>,
    /// Held-out scenarios.
    pub test: Vec<Scenario>,
    /// Scratch directory for the session files.
    pub dir: &'a Path,
    /// The recogniser's tuning.
    pub params: RecogniserParams,
    /// Grow the index to this many skills (copies of the trained ones, perturbed) to time it.
    pub cost_skills: Option<usize>,
    /// Told of each session recorded: (done, total).
    pub progress: &'a mut dyn FnMut(usize, usize),
}

/// Runs the evaluation (see the module docs).
pub fn evaluate(mut setup: EvalSetup<'_>) -> Result<Evaluation, RecordingError> {
    let Recordings {
        stored,
        kinds_of,
        held,
    } = record_all(&mut setup)?;
    let index = Arc::new(RecognitionIndex::new(stored.clone()));
    let mut stored_per_kind = BTreeMap::new();
    for k in kinds_of.values() {
        *stored_per_kind.entry(k.clone()).or_insert(0) += 1;
    }
    let sessions = held
        .iter()
        .map(|r| score_session(&index, r, &kinds_of, &setup.params))
        .collect();
    let open_set = score_open_set(&index, &held, &kinds_of, &stored_per_kind, &setup.params);
    let cost = setup
        .cost_skills
        .map(|n| measure_cost(&stored, n, &held, &setup.params));
    Ok(summarise(stored_per_kind, sessions, open_set, cost))
}

/// The recorded sessions: the training sessions' skills as stored, and the held-out sessions.
struct Recordings {
    /// The training sessions' skills (ids from 1).
    stored: Vec<StoredTemplate>,
    /// Each stored skill's grasp kind, by id.
    kinds_of: BTreeMap<i64, String>,
    /// The held-out sessions, with their observations.
    held: Vec<Recorded>,
}

/// Records the training sessions (storing their skills), then the held-out ones, telling
/// `setup.progress` of each.
fn record_all(setup: &mut EvalSetup<'_>) -> Result<Recordings, RecordingError> {
    let total = setup.train.len() + setup.test.len();
    let mut done = 0;
    let mut stored = Vec::new();
    let mut kinds_of: BTreeMap<i64, String> = BTreeMap::new();
    for s in &setup.train {
        let r = record(s, setup.dir, false)?;
        done += 1;
        (setup.progress)(done, total);
        if let Some((approach, feature)) = r.skill {
            let id = stored.len() as i64 + 1;
            kinds_of.insert(id, r.kind.clone());
            stored.push(StoredTemplate {
                skill_id: id,
                // The index votes by the session's kind (the store votes by shape and grasp
                // type, which the kinds here refine).
                kind: r.kind.clone(),
                object_name: Some(r.target.clone()),
                template: approach.unwrap_or([f32::NAN; TEMPLATE_DIM]),
                feature,
            });
        }
    }
    let mut held = Vec::new();
    for s in &setup.test {
        held.push(record(s, setup.dir, true)?);
        done += 1;
        (setup.progress)(done, total);
    }
    Ok(Recordings {
        stored,
        kinds_of,
        held,
    })
}

/// Scores one held-out session against the whole index (the closed set).
fn score_session(
    index: &Arc<RecognitionIndex>,
    r: &Recorded,
    kinds_of: &BTreeMap<i64, String>,
    params: &RecogniserParams,
) -> SessionScore {
    let verdicts = run(index, r, params).0;
    let fc = r.first_contact_ns;
    let before = |limit: u64| verdicts.iter().filter(move |v| v.session_ns() <= limit);
    let correct = |v: &Verdict| match v {
        Verdict::Recognised { object, skill, .. } => {
            *object == r.target && kinds_of.get(&skill.skill_id) == Some(&r.kind)
        }
        Verdict::Unknown { .. } => false,
    };
    let (anticipated, decided_ns) = anticipation(&verdicts, fc, correct);
    let nearest_truth = r.skill.map(|(_, f)| nearest_by_feature(index, &f));
    let nearest_named = match (fc, nearest_truth) {
        (Some(fc), Some(Some(truth))) => before(fc + NEAREST_WITHIN_NS)
            .next_back()
            .and_then(|v| v.skill())
            .is_some_and(|c| c.skill_id == truth),
        _ => false,
    };
    // What any grasp-stage decision could do: the nearest on the dimensions known 1 s
    // after the touch, taken from the completed grasp itself (exactly, not estimated).
    let bound_named = r.skill.is_some_and(|(_, f)| {
        let mut dims: Vec<usize> = super::index::GRASP_STAGE_DIMS.to_vec();
        dims.push(5);
        let top = index
            .rank_features(&f, &dims, 1, &mut Scratch::default())
            .first()
            .map(|x| index.skill_id(x.row));
        top.is_some() && top == nearest_truth.flatten()
    });
    SessionScore {
        scenario: r.scenario.name.clone(),
        seed: r.scenario.seed,
        kind: r.kind.clone(),
        target: r.target.clone(),
        first_contact_ns: fc,
        anticipated,
        decided_ns,
        decided_fraction: decided_ns
            .zip(fc)
            .map(|(d, fc)| d as f64 / fc.max(1) as f64),
        nearest_named,
        nearest_skill_id: nearest_truth.flatten(),
        nearest_on_known_dims: bound_named,
        verdicts,
    }
}

/// Whether the last verdict [`ANTICIPATION_NS`] before the first contact `fc` is `correct`,
/// and if so when the run of correct verdicts that ends there began (session ns).
fn anticipation(
    verdicts: &[Verdict],
    fc: Option<u64>,
    correct: impl Fn(&Verdict) -> bool,
) -> (bool, Option<u64>) {
    match fc {
        Some(fc) if fc >= ANTICIPATION_NS => {
            let limit = fc - ANTICIPATION_NS;
            let before = |limit: u64| verdicts.iter().filter(move |v| v.session_ns() <= limit);
            let last = before(limit).next_back();
            let ok = last.is_some_and(&correct);
            // Decided when the run of correct verdicts that ends there began.
            let mut decided = None;
            for v in before(limit) {
                if correct(v) {
                    decided.get_or_insert(v.session_ns());
                } else {
                    decided = None;
                }
            }
            (ok, decided.filter(|_| ok))
        }
        _ => (false, None),
    }
}

/// The open set: each kind left out of the index in turn, its held-out sessions scored.
fn score_open_set(
    index: &RecognitionIndex,
    held: &[Recorded],
    kinds_of: &BTreeMap<i64, String>,
    stored_per_kind: &BTreeMap<String, usize>,
    params: &RecogniserParams,
) -> Vec<OpenSetScore> {
    let mut open_set = Vec::new();
    let kinds: Vec<String> = stored_per_kind.keys().cloned().collect();
    for kind in &kinds {
        let mut without = index.clone();
        let ids: Vec<i64> = kinds_of
            .iter()
            .filter(|(_, k)| *k == kind)
            .map(|(id, _)| *id)
            .collect();
        without.remove(&ids);
        let without = Arc::new(without);
        for r in held.iter().filter(|r| r.kind == *kind) {
            let verdicts = run(&without, r, params).0;
            let limit = r.first_contact_ns.unwrap_or(u64::MAX / 2) + NEAREST_WITHIN_NS;
            let unknown = verdicts
                .iter()
                .rfind(|v| v.session_ns() <= limit)
                .is_some_and(|v| matches!(v, Verdict::Unknown { .. }));
            let stored_as_new = r.skill.is_some_and(|(t, f)| {
                link_completed(&without, t.as_ref(), &f, params, &mut Scratch::default()).is_none()
            });
            open_set.push(OpenSetScore {
                scenario: r.scenario.name.clone(),
                seed: r.scenario.seed,
                kind: kind.clone(),
                unknown,
                stored_as_new,
            });
        }
    }
    open_set
}

/// Times recognition over the held-out sessions with the index grown to `n` skills.
fn measure_cost(
    stored: &[StoredTemplate],
    n: usize,
    held: &[Recorded],
    params: &RecogniserParams,
) -> Cost {
    let big = Arc::new(grown(stored, n));
    let mut times = Vec::new();
    let mut least = Vec::new();
    let mut approach_times = Vec::new();
    let mut grasp_times = Vec::new();
    let mut approach_decisions = 0;
    let mut grasp_decisions = 0;
    let mut grasp_periods = 0;
    for r in held {
        let (_, t, d) = run(&big, r, params);
        let mut low = t.clone();
        for _ in 1..COST_REPEATS {
            for (l, x) in low.iter_mut().zip(run(&big, r, params).1) {
                *l = l.min(x);
            }
        }
        times.extend(t);
        least.extend(low);
        approach_times.extend(d.approach);
        grasp_times.extend(d.grasp);
        approach_decisions += d.approach_decisions;
        grasp_decisions += d.grasp_decisions;
        grasp_periods += d.grasp_periods;
    }
    Cost {
        stored_skills: big.len(),
        observations: held.iter().map(|r| r.observations.len()).sum(),
        calls: times.len(),
        mean_us: mean(&times),
        p99_us: p99(&times),
        max_us: max(&times),
        approach_decision_mean_us: mean(&approach_times),
        approach_decision_max_us: max(&approach_times),
        approach_decision_total_us: approach_times.iter().sum::<f64>()
            / approach_decisions.max(1) as f64,
        grasp_step_mean_us: mean(&grasp_times),
        grasp_step_max_us: max(&grasp_times),
        grasp_decisions,
        grasp_steps_per_decision: grasp_periods as f64 / grasp_decisions.max(1) as f64,
        least_mean_us: mean(&least),
        least_p99_us: p99(&least),
        least_max_us: max(&least),
    }
}

/// The mean of `v` (0 when empty).
fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The largest of `v` (0 when empty).
fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

/// The 99th percentile of `v` (nearest rank; 0 when empty).
fn p99(v: &[f64]) -> f64 {
    let mut sorted = v.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted
        .get(((sorted.len() as f64 - 1.0) * 0.99).round() as usize)
        .copied()
        .unwrap_or(0.0)
}

/// The evaluation: the scores with their fractions and medians.
fn summarise(
    stored_per_kind: BTreeMap<String, usize>,
    sessions: Vec<SessionScore>,
    open_set: Vec<OpenSetScore>,
    cost: Option<Cost>,
) -> Evaluation {
    let frac = |n: usize, d: usize| if d == 0 { 0.0 } else { n as f64 / d as f64 };
    let mut fractions: Vec<f64> = sessions.iter().filter_map(|s| s.decided_fraction).collect();
    let mut leads: Vec<f64> = sessions
        .iter()
        .filter_map(|s| Some((s.first_contact_ns? as f64 - s.decided_ns? as f64) * 1e-6))
        .collect();
    Evaluation {
        anticipated_fraction: frac(
            sessions.iter().filter(|s| s.anticipated).count(),
            sessions.len(),
        ),
        nearest_fraction: frac(
            sessions.iter().filter(|s| s.nearest_named).count(),
            sessions.len(),
        ),
        nearest_bound_fraction: frac(
            sessions.iter().filter(|s| s.nearest_on_known_dims).count(),
            sessions.len(),
        ),
        median_decided_fraction: crate::segmentation::median(&mut fractions),
        median_lead_ms: crate::segmentation::median(&mut leads),
        unknown_fraction: frac(
            open_set.iter().filter(|s| s.unknown).count(),
            open_set.len(),
        ),
        stored_as_new_fraction: frac(
            open_set.iter().filter(|s| s.stored_as_new).count(),
            open_set.len(),
        ),
        stored_per_kind,
        sessions,
        open_set,
        cost,
    }
}

/// The times (µs) of the observations that decided, by stage, and the grasp-stage decisions.
#[derive(Debug, Default)]
struct DecisionTimes {
    /// Calls that worked on an approach-stage or a grasp-stage decision (µs).
    approach: Vec<f64>,
    grasp: Vec<f64>,
    approach_decisions: usize,
    grasp_decisions: usize,
    /// Observation periods in which a grasp-stage decision was worked on.
    grasp_periods: usize,
}

/// The recogniser over a held-out session: its verdicts, the time of every call (each
/// observation, and each slice of work after it, as the live assistant makes them) and of
/// those that decided (µs).
fn run(
    index: &Arc<RecognitionIndex>,
    r: &Recorded,
    params: &RecogniserParams,
) -> (Vec<Verdict>, Vec<f64>, DecisionTimes) {
    let mut rec = Recogniser::new(Arc::clone(index), r.objects.clone(), *params);
    let mut times = Vec::with_capacity(r.observations.len());
    let mut decided = DecisionTimes::default();
    for o in &r.observations {
        let period = (rec.grasp_steps(), rec.decisions(), rec.grasp_decisions());
        let mut first = true;
        loop {
            let steps = (rec.approach_steps(), rec.grasp_steps());
            let t = Instant::now();
            let more = if first {
                rec.observe(o);
                true
            } else {
                rec.work()
            };
            let us = t.elapsed().as_secs_f64() * 1e6;
            let (approach, grasp) = (rec.approach_steps() > steps.0, rec.grasp_steps() > steps.1);
            // Every observation, and the slices of work after it that did some.
            if first || approach || grasp {
                times.push(us);
            }
            if approach {
                decided.approach.push(us);
            } else if grasp {
                decided.grasp.push(us);
            }
            first = false;
            if !more {
                break;
            }
        }
        let grasp_decisions = (rec.grasp_decisions() - period.2) as usize;
        decided.grasp_decisions += grasp_decisions;
        decided.approach_decisions += (rec.decisions() - period.1) as usize - grasp_decisions;
        decided.grasp_periods += usize::from(rec.grasp_steps() > period.0);
    }
    (rec.verdicts().to_vec(), times, decided)
}

/// The stored skill nearest `feature` by the whole feature vector.
fn nearest_by_feature(index: &RecognitionIndex, feature: &[f32; FEATURE_DIM]) -> Option<i64> {
    let all: [usize; FEATURE_DIM] = std::array::from_fn(|j| j);
    index
        .rank_features(feature, &all, 1, &mut Scratch::default())
        .first()
        .map(|r| index.skill_id(r.row))
}

/// `n` skills: the stored ones and copies of them with their values perturbed (±5 % of each
/// value's scale), so that a scan of `n` is timed.
fn grown(stored: &[StoredTemplate], n: usize) -> RecognitionIndex {
    let mut all = stored.to_vec();
    let mut k = 0u64;
    while all.len() < n && !stored.is_empty() {
        let base = &stored[k as usize % stored.len()];
        k += 1;
        let mut t = base.clone();
        t.skill_id = 1_000_000 + k as i64;
        for (j, v) in t.template.iter_mut().enumerate() {
            let u = ((k.wrapping_mul(2654435761).wrapping_add(j as u64 * 97)) % 1000) as f32;
            *v += (u / 1000.0 - 0.5) * 0.1 * super::features::TEMPLATE_SCALE[j];
        }
        all.push(t);
    }
    RecognitionIndex::new(all)
}

/// The stage of a verdict, as a name (for reports).
pub fn stage_name(s: Stage) -> &'static str {
    match s {
        Stage::Approach => "approach",
        Stage::Grasp => "grasp",
    }
}
