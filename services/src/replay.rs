//! Replaying skills on robot hands: a skill's JSON (one element of `icms segment --json`'s
//! `skills`, or a stored skill's parameters) into dfs-core's [`SkillSpec`], hand specs read
//! from files, and the replay recorded as an MCAP file that Foxglove shows like a session
//! (same topics), with a `replay` metadata record holding the skill, the hand and the report.
//! A replay driven by the operator's phases as they happen ([`driven_replay`]) is the
//! assistant's `apply` mode: the live session owns it and ticks it with its own.

use std::collections::BTreeMap;
use std::path::Path;

use dfs_core::contact::Friction;
use dfs_core::hand::{builtin_hand, builtin_spec, thumb_of, ContactPart, HandModel, HandSpec};
use dfs_core::math::Vector;
use dfs_core::replay::{
    run_with_stop, DrivenReplay, DrivenStart, ReplayParams, ReplayReport, ReplayTick, SkillContact,
    SkillKeyPose, SkillSpec,
};
use dfs_core::scenario::Phase;
use dfs_core::{DfsError, Stop};

use crate::error::{RecordingError, Result};
use crate::segmentation::Skill;
use crate::session::{SessionInfo, SessionOut, SessionRecorder, TickData};

/// Name of the replay's metadata record.
pub const REPLAY_METADATA: &str = "replay";

/// A hand ready to replay on: the model, its thumb, and where it came from.
#[derive(Debug, Clone)]
pub struct LoadedHand {
    /// The model.
    pub model: HandModel,
    /// Index of the fingertip opposing the others.
    pub thumb: usize,
    /// The spec (absent for `glove10`).
    pub spec: Option<HandSpec>,
    /// The URDF text (absent for `glove10`).
    pub urdf: Option<String>,
}

impl LoadedHand {
    /// The model to replay `skill` with: for a power grasp (a skill with a palm contact) on a
    /// hand loaded without contact geometry, the model with its palm and phalanges from its
    /// URDF's `<collision>` elements
    /// ([`dfs_core::hand::contact_geometry::contact_shapes_from_urdf`]), which a power grasp's
    /// replay holds the object with; the model as it is otherwise. Collision geometry that is
    /// degenerate, or more shapes than the limits, is refused naming the link.
    pub fn model_for(&self, skill: &SkillSpec) -> Result<std::borrow::Cow<'_, HandModel>> {
        let power = skill.contacts.iter().any(|c| c.part == ContactPart::Palm);
        match &self.urdf {
            Some(urdf) if power && self.model.contact_shapes.is_empty() => {
                let mut model = self.model.clone();
                model.contact_shapes =
                    dfs_core::hand::contact_geometry::contact_shapes_from_urdf(&model, urdf)
                        .map_err(|e| {
                            invalid(
                                format!("hand {:?} URDF", self.model.name),
                                format!("its collision geometry, for a power grasp: {e}"),
                            )
                        })?;
                Ok(std::borrow::Cow::Owned(model))
            }
            _ => Ok(std::borrow::Cow::Borrowed(&self.model)),
        }
    }
}

fn invalid(location: impl Into<String>, detail: impl Into<String>) -> RecordingError {
    RecordingError::InvalidInput {
        location: location.into(),
        detail: detail.into(),
    }
}

/// A built-in hand by name.
pub fn load_builtin_hand(name: &str) -> Result<LoadedHand> {
    let model = builtin_hand(name).map_err(|e| invalid(format!("hand {name:?}"), e.to_string()))?;
    let (spec, urdf) = match builtin_spec(name) {
        Some((s, u)) => (Some(s), Some(u.to_owned())),
        None => (None, None),
    };
    let thumb = spec
        .as_ref()
        .map_or_else(|| thumb_of(&model), HandSpec::thumb_index);
    Ok(LoadedHand {
        model,
        thumb,
        spec,
        urdf,
    })
}

/// A hand from a spec's JSON text and its URDF text; errors name the problem.
pub fn load_hand_from_texts(spec_json: &str, urdf: &str, location: &str) -> Result<LoadedHand> {
    let de = &mut serde_json::Deserializer::from_str(spec_json);
    let spec: HandSpec = serde_path_to_error::deserialize(de)
        .map_err(|e| invalid(location, format!("hand spec: {e}")))?;
    let model = HandModel::from_urdf(urdf, &spec).map_err(|e| invalid(location, e.to_string()))?;
    Ok(LoadedHand {
        thumb: spec.thumb_index(),
        model,
        spec: Some(spec),
        urdf: Some(urdf.to_owned()),
    })
}

/// A hand from a spec file (its `urdf` relative to the spec's directory).
pub fn load_hand_file(path: &Path) -> Result<LoadedHand> {
    let location = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .map_err(|e| RecordingError::io(format!("reading {location}"), e))?;
    let value: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| invalid(&location, format!("hand spec is not JSON: {e}")))?;
    let urdf_name = value
        .get("urdf")
        .and_then(|u| u.as_str())
        .ok_or_else(|| invalid(&location, "hand spec: missing field `urdf`"))?;
    let urdf_path = path.parent().unwrap_or(Path::new(".")).join(urdf_name);
    let urdf = std::fs::read_to_string(&urdf_path)
        .map_err(|e| RecordingError::io(format!("reading {}", urdf_path.display()), e))?;
    load_hand_from_texts(&text, &urdf, &location)
}

/// A built-in hand name, or a spec file.
pub fn load_hand(name_or_path: &str) -> Result<LoadedHand> {
    if dfs_core::hand::BUILTIN_HANDS.contains(&name_or_path) {
        load_builtin_hand(name_or_path)
    } else if Path::new(name_or_path).is_file() {
        load_hand_file(Path::new(name_or_path))
    } else {
        Err(invalid(
            "hand",
            format!(
                "{name_or_path:?} is neither a built-in hand ({}) nor a spec file",
                dfs_core::hand::BUILTIN_HANDS.join(", ")
            ),
        ))
    }
}

/// A skill's JSON (as `icms segment --json` prints each of its `skills`, or a stored skill's
/// parameters) as a [`SkillSpec`], read through segmentation's own [`Skill`] type. Errors name
/// the field (`skill.object.shape: unknown shape "torus"; expected one of ...`).
///
/// When the contacts' grip profiles show that the recording lost the object before `release`
/// (fewer than two contacts pushing with more than 0.05 N after the grip was established),
/// [`SkillSpec::held_until_s`] says when.
pub fn skill_spec_from_json(value: &serde_json::Value, location: &str) -> Result<SkillSpec> {
    let skill = Skill::from_json(value).map_err(|e| {
        let path = e.path().to_string();
        if path == "." {
            invalid(location, format!("skill: {}", e.inner()))
        } else {
            invalid(location, format!("skill.{path}: {}", e.inner()))
        }
    })?;
    let Skill { phases, parameters } = skill;
    let object = parameters.object.ok_or_else(|| {
        invalid(
            location,
            "skill.object: the skill does not describe its object",
        )
    })?;
    let shape = object
        .to_shape()
        .map_err(|e| invalid(location, format!("skill.object: {e}")))?;
    let contacts = parameters.contacts;
    // When the recording lost the object: the grip profiles span grasp start → release end.
    let find = |phase: Phase| phases.iter().find(|p| p.phase == phase);
    let held_until_s = match (find(Phase::Grasp), phases.last()) {
        (Some(g), Some(last)) if !contacts.is_empty() => {
            let release = find(Phase::Release);
            let end = release.map_or(last.end_ns, |r| r.end_ns);
            let span = end.saturating_sub(g.start_ns) as f64 * 1e-9;
            let release_s = release.map_or(f64::INFINITY, |r| {
                r.start_ns.saturating_sub(g.start_ns) as f64 * 1e-9
            });
            let npts = contacts
                .iter()
                .map(|c| c.grip_profile.len())
                .min()
                .unwrap_or(0);
            let pushing = |k: usize| {
                contacts
                    .iter()
                    .filter(|c| c.grip_profile.get(k).is_some_and(|f| *f > 0.05))
                    .count()
                    >= 2
            };
            let mut established = false;
            let mut lost = None;
            for k in 0..npts {
                let t = span * k as f64 / (npts.max(2) - 1) as f64;
                if pushing(k) {
                    established = true;
                } else if established && t < release_s {
                    lost = Some(span * (k.saturating_sub(1)) as f64 / (npts.max(2) - 1) as f64);
                    break;
                }
            }
            lost
        }
        _ => None,
    };
    Ok(SkillSpec {
        shape,
        mass: object.mass,
        friction: Friction {
            mu: object.mu,
            mu_torsion: object.mu_torsion,
        },
        contact_model: parameters.contact_model,
        contacts: contacts
            .into_iter()
            .map(|c| SkillContact {
                finger: c.finger,
                part: c.part,
                position_b: Vector::from(c.position_b),
                normal_b: Vector::from(c.normal_b),
            })
            .collect(),
        motion: parameters
            .motion
            .iter()
            .map(|k| SkillKeyPose {
                time_s: k.time_s,
                position: Vector::from(k.position),
                rotation: Vector::from(k.rotation),
            })
            .collect(),
        phases: phases
            .iter()
            .map(|p| (p.phase, p.end_ns.saturating_sub(p.start_ns) as f64 * 1e-9))
            .collect(),
        held_until_s,
    })
}

/// Where a replay's skill comes from, for the `replay` metadata record.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReplaySource {
    /// The skill's id in the data base, if stored.
    pub skill_id: Option<i64>,
    /// Name of the skill's file or source session.
    pub skill_name: String,
}

/// Replays `skill` on `hand`; with `out`, records the replay as an MCAP file (written even
/// when the replay fails: the report says how). Errors are for invalid input and I/O only.
pub fn replay_skill(
    hand: &LoadedHand,
    skill: &SkillSpec,
    params: &ReplayParams,
    source: &ReplaySource,
    out: Option<&Path>,
) -> Result<ReplayReport> {
    replay_skill_until(
        hand,
        skill,
        params,
        source,
        out.map(SessionOut::File),
        Stop::never(),
    )
}

/// A replay's error: a stop stays a cancellation, anything else is the input's fault.
fn run_error(location: String, e: DfsError) -> RecordingError {
    match e {
        DfsError::Cancelled => RecordingError::Simulation {
            time_ns: 0,
            source: e,
        },
        e => invalid(location, e.to_string()),
    }
}

/// [`replay_skill`] that ends early when `stop` is set, planning included, with
/// [`RecordingError::Simulation`] of [`dfs_core::DfsError::Cancelled`]; a recording is
/// finished with what was recorded.
pub fn replay_skill_until(
    hand: &LoadedHand,
    skill: &SkillSpec,
    params: &ReplayParams,
    source: &ReplaySource,
    out: Option<SessionOut<'_>>,
    stop: &Stop,
) -> Result<ReplayReport> {
    let location = format!("hand {:?}", hand.model.name);
    let model = hand.model_for(skill)?;
    let Some(out) = out else {
        return dfs_core::replay::run_with_stop(&model, hand.thumb, skill, params, stop, |_| {})
            .map_err(|e| run_error(location, e));
    };
    let object = dfs_core::object::RigidObject::new(skill.shape, skill.mass)
        .map_err(|e| invalid("skill.object", e.to_string()))?;
    let info = SessionInfo {
        scenario: source.skill_name.clone(),
        seed: None,
        object_json: String::new(),
        source: "replay".to_owned(),
        extra: BTreeMap::from([("replay_hand".to_owned(), hand.model.name.clone())]),
        phases: Vec::new(),
        started_at: None,
        // The replay's DFS puts the table top at z = 0 (dfs_core::replay).
        table_height: Some(0.0),
        hand_urdf: hand.urdf.clone(),
        scene: None,
        assist_topics: false,
    };
    let mut recorder = SessionRecorder::create_to(out, &model, &object, &info)?;
    let mut failed: Option<RecordingError> = None;
    let report = run_with_stop(&model, hand.thumb, skill, params, stop, |tick| {
        if failed.is_some() {
            return;
        }
        if let Err(e) = recorder.record(&replay_tick_data(tick)) {
            failed = Some(e);
        }
    })
    .map_err(|e| run_error(location, e))?;
    if let Some(e) = failed {
        let _ = recorder.finish();
        return Err(e);
    }
    let mut meta = BTreeMap::new();
    meta.insert("hand".to_owned(), hand.model.name.clone());
    meta.insert(
        "skill_id".to_owned(),
        source.skill_id.map(|i| i.to_string()).unwrap_or_default(),
    );
    meta.insert("skill".to_owned(), source.skill_name.clone());
    meta.insert(
        "report".to_owned(),
        serde_json::to_string(&report).unwrap_or_default(),
    );
    recorder.add_metadata(REPLAY_METADATA, meta)?;
    recorder.finish()?;
    Ok(report)
}

/// A replay tick as a recorder's tick (the same topics as a session's), at the tick's own
/// `time_ns`; a live session recording its driven replay sets its own session time.
pub fn replay_tick_data<'a>(tick: &ReplayTick<'a>) -> TickData<'a> {
    TickData {
        time_ns: tick.time_ns,
        q: tick.q,
        tau: tick.tau,
        base: tick.base,
        output: tick.output,
        body: tick.body,
        kinematics: tick.kinematics,
    }
}

/// Retargets `skill` onto `hand` for a replay driven by the operator's phases as they happen
/// (the assistant's `apply` mode, [`DrivenReplay`]): its clock's real time starts at `start_s`
/// (the live session's time, so that phase changes are told in session time). A plan the hand
/// cannot carry out is [`DrivenStart::Refused`] with its report, as [`replay_skill`] reports
/// it without simulating. Errors as [`replay_skill_until`]'s: invalid input (the skill's
/// object included, as a recorded replay checks it) and [`RecordingError::Simulation`] of
/// [`DfsError::Cancelled`] once `stop` is set while planning.
pub fn driven_replay(
    hand: &LoadedHand,
    skill: &SkillSpec,
    params: &ReplayParams,
    start_s: f64,
    stop: &Stop,
) -> Result<DrivenStart> {
    dfs_core::object::RigidObject::new(skill.shape, skill.mass)
        .map_err(|e| invalid("skill.object", e.to_string()))?;
    let location = format!("hand {:?}", hand.model.name);
    let model = hand.model_for(skill)?;
    DrivenReplay::start(&model, hand.thumb, skill, params, start_s, stop)
        .map_err(|e| run_error(location, e))
}
