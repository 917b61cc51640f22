//! Operator scenarios: an object on a table and a script of task phases, as built-ins or from a
//! JSON scenario file. Validated at the boundary: every error names its field.
//!
//! ```json
//! { "name": "my-lift",
//!   "object": { "shape": "box", "half_extents": [0.03, 0.03, 0.05], "mass": 0.3,
//!               "mu": 0.8, "position": [0.0, 0.0, 0.05], "yaw": 0.0 },
//!   "grasp": "pinch",
//!   "tasks": [ { "phase": "approach", "duration": 0.6 }, { "phase": "preshape", "duration": 0.4 },
//!              { "phase": "grasp", "duration": 0.6 }, { "phase": "lift", "duration": 0.8, "height": 0.1 },
//!              { "phase": "hold", "duration": 1.0 } ],
//!   "seed": 1 }
//! ```
//! The table's top is at the object's lowest point at its start pose. Durations in s,
//! lengths in m, angles in rad.
//!
//! A scene of several objects (up to [`MAX_OBJECTS`]) names each and says which one the script
//! grasps, instead of `"object"`:
//! ```json
//! { "name": "pick-the-box",
//!   "objects": [ { "name": "ball", "shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8,
//!                  "position": [0.0, 0.2, 0.04] },
//!                { "name": "box", "shape": "box", "half_extents": [0.025, 0.025, 0.04],
//!                  "mass": 0.2, "mu": 0.8, "position": [0.0, 0.0, 0.04] } ],
//!   "target": "box",
//!   "tasks": [ ... ] }
//! ```
//! Each object of several needs its `position`; the table's top is at the lowest object's
//! lowest point, and objects above it fall onto it. Objects do not act on each other, so a
//! scene whose objects overlap, at their start poses or once resting on the table, is refused
//! ([`Scene::new`]).
//!
//! Here: the file format and its resolution into tasks; the resolved [`Scene`] in `scene.rs`,
//! the built-in scenarios and their variants in `builtin.rs`.

mod builtin;
mod scene;

pub use builtin::{
    VARIANT_JITTER_M, VARIANT_MASS_SCALE, VARIANT_MU_SCALE, VARIANT_SIZE_SCALE, VARIANT_STREAM,
};
pub use scene::{Scene, SceneObject, DEFAULT_OBJECT_NAME, MAX_OBJECT_NAME_CHARS};

use crate::contact::Friction;
use crate::dfs::DfsObject;
pub use crate::dfs::MAX_OBJECTS;
use crate::error::{DfsError, Result};
use crate::math::{Isometry, Real, Rotation, Vector};
use crate::names::Named;
use crate::object::{shapes_overlap, ObjectState, RigidObject, Shape, ShapeKind};
use crate::spec::ObjectSpec;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// The phases of a grasp task, in the order they usually come (`Phase::ALL`), named as in
/// files, the API and the data base. (They compare by name, see `impl Ord for Phase`.)
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// The hand moves towards the object, fingers open.
    Approach,
    /// The fingers take the shape of the grasp, just off the surface.
    Preshape,
    /// The fingers close on the object and the grip force ramps up.
    Grasp,
    /// The object is lifted off the table.
    Lift,
    /// The object is held still.
    Hold,
    /// The object is carried (and optionally turned).
    Transport,
    /// The object is set down on the table.
    Place,
    /// The grip force ramps down and the fingers open.
    Release,
    /// The hand moves away.
    Retreat,
}

impl Phase {
    /// Every phase, in task order.
    pub const ALL: [Phase; 9] = [
        Phase::Approach,
        Phase::Preshape,
        Phase::Grasp,
        Phase::Lift,
        Phase::Hold,
        Phase::Transport,
        Phase::Place,
        Phase::Release,
        Phase::Retreat,
    ];

    /// Lower-case name, as in files, the API and the data base.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Approach => "approach",
            Phase::Preshape => "preshape",
            Phase::Grasp => "grasp",
            Phase::Lift => "lift",
            Phase::Hold => "hold",
            Phase::Transport => "transport",
            Phase::Place => "place",
            Phase::Release => "release",
            Phase::Retreat => "retreat",
        }
    }
}

impl Named for Phase {
    const WHAT: &'static str = "phase";
    const ALL: &'static [Self] = &Phase::ALL;

    fn name(self) -> &'static str {
        Phase::name(self)
    }
}

crate::named_enum!(Phase);

impl PartialOrd for Phase {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// Phases *compare* by name, alphabetically (`approach < grasp < hold < lift < ...`), not in
/// task order ([`Phase::ALL`]): maps keyed by phase (a skill's `phase_durations`) list them in
/// the order they had when they were keyed by name, so stored skills stay byte for byte the
/// same.
impl Ord for Phase {
    /// By name.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.name().cmp(other.name())
    }
}

/// One phase of a session with its time span, ns since the session's start: a phase of the
/// operator's script ([`Simulation::phases`](crate::operator::Simulation::phases), the
/// ground truth of a simulated session) or one that segmentation found in a recorded session.
///
/// Its JSON, in skills, skill files, the store and the HTTP API, is
/// `{"name": "grasp", "start_ns": 600000000, "end_ns": 1200000000}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PhaseSpan {
    /// The phase (`approach`, `preshape`, `grasp`, `lift`, `hold`, `transport`, `place`,
    /// `release`, `retreat`); `name` in JSON.
    #[serde(rename = "name")]
    pub phase: Phase,
    /// Start, ns since the session's start (the log time of its first `/object/state` sample:
    /// 0 in the files `icms simulate` records, later for recorders that log epoch times).
    pub start_ns: u64,
    /// End (exclusive), ns since the session's start.
    pub end_ns: u64,
}

/// How the operator grasps the object: `auto`, `pinch` or `power`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum GraspStyle {
    /// Chosen from the object's size: pinch for small, power for larger objects.
    #[default]
    Auto,
    /// Thumb against index (and middle) fingertip, from above.
    Pinch,
    /// All fingers wrapped around the object against the thumb, from above.
    Power,
}

impl Named for GraspStyle {
    const WHAT: &'static str = "grasp style";
    const ALL: &'static [Self] = &[GraspStyle::Auto, GraspStyle::Pinch, GraspStyle::Power];

    fn name(self) -> &'static str {
        match self {
            GraspStyle::Auto => "auto",
            GraspStyle::Pinch => "pinch",
            GraspStyle::Power => "power",
        }
    }
}

crate::named_enum!(GraspStyle);

/// The object of a scenario: shape, mass, friction and start pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "an object {\"shape\": ..., \"mass\": ..., \"mu\": ...}"
)]
pub struct ScenarioObject {
    /// Its name in the scene, 1 to 64 characters ([`MAX_OBJECT_NAME_CHARS`]), unique among the
    /// scene's objects: required in `objects`, optional for the one `object` (default
    /// `"object"`, [`DEFAULT_OBJECT_NAME`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(max_length = 64, min_length = 1))]
    pub name: Option<String>,
    /// The shape: `sphere`, `box` or `cylinder`.
    pub shape: ShapeKind,
    /// Radius (m), sphere or cylinder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(value_type = Option<f64>))]
    pub radius: Option<Real>,
    /// Half extents (m), box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(value_type = Option<[f64; 3]>))]
    pub half_extents: Option<[Real; 3]>,
    /// Half height (m), cylinder (axis vertical at the start pose).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(value_type = Option<f64>))]
    pub half_height: Option<Real>,
    /// Mass (kg), > 0.
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub mass: Real,
    /// Coulomb friction coefficient between fingertips and object, 0 to 10 (a grasp file's
    /// `MU_RANGE`).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64, minimum = 0.0, maximum = 10.0))]
    pub mu: Real,
    /// Torsional friction coefficient (m), 0 to 1 (a grasp file's `MU_TORSION_RANGE`).
    /// Default 0.005.
    #[serde(default = "default_mu_torsion")]
    #[cfg_attr(feature = "utoipa", schema(value_type = f64, minimum = 0.0, maximum = 1.0))]
    pub mu_torsion: Real,
    /// Start position of the object's centre in the world (m). Default: resting on a table
    /// whose top is at z = 0, at the origin.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(value_type = Option<[f64; 3]>))]
    pub position: Option<[Real; 3]>,
    /// Start rotation about the world z axis (rad). Default 0.
    #[serde(default)]
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub yaw: Real,
}

crate::object_only!(
    ScenarioObject,
    "an object {\"shape\": ..., \"mass\": ..., \"mu\": ...}",
    serialize
);
crate::object_only!(
    Task,
    "a task {\"phase\": ..., \"duration\": ...}",
    serialize
);
crate::object_only!(
    Scenario,
    "a scenario: a JSON object {\"name\": ..., \"object\": ..., \"tasks\": [...]}",
    serialize
);

fn default_mu_torsion() -> Real {
    0.005
}

impl ScenarioObject {
    fn spec(&self) -> ObjectSpec {
        ObjectSpec {
            shape: self.shape,
            radius: self.radius,
            half_extents: self.half_extents,
            half_height: self.half_height,
            mass: self.mass,
        }
    }

    /// The shape with its sizes, as [`ObjectSpec::to_shape`] builds it (each size the kind
    /// needs given, none it does not take; errors name the field).
    pub fn to_shape(&self) -> Result<Shape> {
        self.spec().to_shape()
    }

    /// The rigid object, validated with its friction: shape, sizes and mass as
    /// [`ObjectSpec::to_object`] checks them and within a grasp file's ranges
    /// ([`ObjectSpec::check_ranges`]), `mu` and `mu_torsion` within a grasp file's ranges
    /// ([`MU_RANGE`](crate::spec::MU_RANGE), [`MU_TORSION_RANGE`](crate::spec::MU_TORSION_RANGE)).
    pub fn to_object(&self) -> Result<RigidObject> {
        let spec = self.spec();
        let object = spec.to_object()?;
        spec.check_ranges()?;
        for (field, v, (lo, hi), unit) in [
            ("object.mu", self.mu, crate::spec::MU_RANGE, ""),
            (
                "object.mu_torsion",
                self.mu_torsion,
                crate::spec::MU_TORSION_RANGE,
                " m",
            ),
        ] {
            check(
                field.into(),
                v.is_finite() && (lo..=hi).contains(&v),
                format!("must be a number in [{lo:?}, {hi:?}]{unit}, got {v}"),
            )?;
        }
        Ok(object)
    }

    /// The rigid object, validated for the closed loop: as [`to_object`](Self::to_object),
    /// and at least [`MIN_SIMULATED_MASS`].
    pub fn to_simulated_object(&self) -> Result<RigidObject> {
        let object = self.to_object()?;
        if self.mass < MIN_SIMULATED_MASS {
            return Err(DfsError::invalid(
                "object.mass",
                format!(
                    "must be at least {MIN_SIMULATED_MASS} kg for the closed loop, got {}: the DFS \
                     steps the object explicitly at 1 kHz against its contact springs, and \
                     lighter objects are not stable there (1 g diverges)",
                    self.mass
                ),
            ));
        }
        Ok(object)
    }
}

/// The lightest object (kg) a scenario or an imported glove recording may hold: the DFS steps
/// the object explicitly at 1 ms against 3 kN/m contact springs; a 1 g box diverges at
/// lift-off, 2 g does not, and 5 g keeps a margin of 2.5 in mass. A thin object above it may
/// still diverge: the tick then refuses with [`DfsError::Diverged`].
pub const MIN_SIMULATED_MASS: Real = 0.005;

/// One task of the script.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "a task {\"phase\": ..., \"duration\": ...}"
)]
pub struct Task {
    /// Which phase (`approach`, `preshape`, `grasp`, `lift`, `hold`, `transport`, `place`,
    /// `release`, `retreat`).
    pub phase: Phase,
    /// Duration (s), 0.05 to 600 (`MIN_TASK_S`, `MAX_TASK_S`); the whole script at most
    /// 3600 s (`MAX_SCRIPT_S`).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64, minimum = 0.05, maximum = 600.0))]
    pub duration: Real,
    /// `lift`: height (m) to raise the object. Default 0.10.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(value_type = Option<f64>))]
    pub height: Option<Real>,
    /// `transport`: displacement of the object (m, world). Default (0, 0.15, 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(value_type = Option<[f64; 3]>))]
    pub offset: Option<[Real; 3]>,
    /// `transport`: rotation of the object about the world z axis (rad). Default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(value_type = Option<f64>))]
    pub turn: Option<Real>,
}

/// A scenario file: the object (or the objects and which one is grasped), the grasp style and
/// the operator's task script.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "a scenario: a JSON object {\"name\": ..., \"object\": ..., \"tasks\": [...]}"
)]
pub struct Scenario {
    /// Name.
    pub name: String,
    /// The object, in a scene of one. Exactly one of `object` and `objects` is given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<ScenarioObject>,
    /// The objects of a scene of 1 to 8 ([`MAX_OBJECTS`]), each named and placed
    /// (`position`), none overlapping another. Exactly one of `object` and `objects` is given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(max_items = 8, min_items = 1))]
    pub objects: Option<Vec<ScenarioObject>>,
    /// The name of the object the script grasps: required with several `objects`; with one
    /// it may name it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// Grasp style. Default auto.
    #[serde(default)]
    pub grasp: GraspStyle,
    /// The task script.
    pub tasks: Vec<Task>,
    /// Seed of the operator's tremor and the sensor noise. Default 0.
    #[serde(default)]
    pub seed: u64,
    /// The friction coefficient the operator expects and grips for, > 0. Default: the
    /// object's μ (a person adapts the grip to the surface after the first touch).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "utoipa", schema(value_type = Option<f64>))]
    pub operator_mu: Option<Real>,
    /// Vary the operator's reaches by `seed` (a ChaCha8 stream of its own, so the tremor and
    /// the sensor noise are those of the same seed without it). Default false: every seed
    /// reaches along the same straight path from 0.15 m above its approach pose, in the
    /// script's durations. When true, the hand starts at a seeded home 0.25-0.40 m from the
    /// first approach pose (on the side it approaches from, 15-60° up), and each `approach`
    /// bends sideways or upwards (up to 30 % of its length), runs at a seeded speed (its and
    /// the next `preshape`'s durations divided by 0.7-1.3) and pauses mid-way half the time
    /// (0.1-0.3 s, counted in `approach`): see
    /// [`operator`](crate::operator#varied-reaches). Written only when true.
    #[serde(default, skip_serializing_if = "is_false")]
    #[cfg_attr(feature = "utoipa", schema(default = false))]
    pub vary_reach: bool,
}

/// serde's `skip_serializing_if` for a flag written only when set.
fn is_false(v: &bool) -> bool {
    !*v
}

/// Longest script (s): the sum of a scenario's task durations, like `icms simulate --duration`.
/// A minute of session is about 30 MB of MCAP.
pub const MAX_SCRIPT_S: Real = 3600.0;

/// Most tasks in a script: 256. The built-in scenarios have 7-14; a task is a phase of a grasp
/// (a person's pick-and-place has about eight), so 256 are some 30 grasps. Each `approach`
/// plans a grasp by inverse kinematics (15-30 ms of CPU with glove10), so the count bounds the
/// set-up work a script can ask for (100 000 one-millisecond tasks were 45 minutes of CPU).
pub const MAX_TASKS: usize = 256;

/// Shortest task (s): 0.05 s, 50 ticks of the 1 kHz loop. The phases are minimum-jerk
/// motions of a hand and grip ramps; a person's shortest take a few tenths of a second (the
/// built-in scenarios' shortest is 0.5 s), and a phase of a few ticks is no motion the
/// segmentation could find, only work.
pub const MIN_TASK_S: Real = 0.05;

/// Longest task (s): 600 s, ten minutes of one phase.
pub const MAX_TASK_S: Real = 600.0;

/// A task with its phase resolved and defaults filled in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResolvedTask {
    /// The phase.
    pub phase: Phase,
    /// Duration (s).
    pub duration: Real,
    /// Lift height (m).
    pub height: Real,
    /// Transport displacement (m).
    pub offset: [Real; 3],
    /// Transport turn about z (rad).
    pub turn: Real,
}

fn check(field: String, ok: bool, reason: impl Into<String>) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(DfsError::invalid(field, reason))
    }
}

impl Scenario {
    /// Validates the scenario and resolves its tasks; every error names the field. The
    /// object is the one the script grasps ([`resolve_scene`](Self::resolve_scene) gives the
    /// whole scene).
    pub fn resolve(&self) -> Result<(RigidObject, Vec<ResolvedTask>)> {
        let (scene, tasks) = self.resolve_scene()?;
        Ok((scene.target().object, tasks))
    }

    /// The scene ([`Scene::new`] of the scenario's `object`, `objects` and `target`).
    pub fn scene(&self) -> Result<Scene> {
        Scene::new(
            self.object.as_ref(),
            self.objects.as_deref(),
            self.target.as_deref(),
        )
    }

    /// The object the script grasps as the scenario gives it: its `object`, or the one of its
    /// `objects` that `target` names (the only one, without a target). `None` when the
    /// scenario names none ([`scene`](Self::scene) says why).
    pub fn target_object(&self) -> Option<&ScenarioObject> {
        match (&self.object, &self.objects, &self.target) {
            (Some(o), None, _) => Some(o),
            (None, Some(v), Some(t)) => v.iter().find(|o| o.name.as_deref() == Some(t.as_str())),
            (None, Some(v), None) if v.len() == 1 => v.first(),
            _ => None,
        }
    }

    /// Validates the scenario and resolves its scene and tasks; every error names the field.
    pub fn resolve_scene(&self) -> Result<(Scene, Vec<ResolvedTask>)> {
        let scene = self.scene()?;
        if let Some(mu) = self.operator_mu {
            check(
                "operator_mu".into(),
                mu.is_finite() && mu > 0.0,
                format!("must be a finite number > 0, got {mu}"),
            )?;
        }
        check(
            "tasks".into(),
            !self.tasks.is_empty(),
            "needs at least one task",
        )?;
        check(
            "tasks".into(),
            self.tasks.len() <= MAX_TASKS,
            format!(
                "{} tasks; at most {MAX_TASKS} are accepted",
                self.tasks.len()
            ),
        )?;
        let mut out = Vec::with_capacity(self.tasks.len());
        for (i, t) in self.tasks.iter().enumerate() {
            let phase = t.phase;
            // A field of another phase's task is a mistake, not a default to ignore.
            let takes: &[&str] = match phase {
                Phase::Lift => &["height"],
                Phase::Transport => &["offset", "turn"],
                _ => &[],
            };
            for (field, given) in [
                ("height", t.height.is_some()),
                ("offset", t.offset.is_some()),
                ("turn", t.turn.is_some()),
            ] {
                check(
                    format!("tasks[{i}].{field}"),
                    !given || takes.contains(&field),
                    format!(
                        "a {} task takes no {field} (lift takes height; transport takes \
                         offset and turn)",
                        phase.name()
                    ),
                )?;
            }
            check(
                format!("tasks[{i}].duration"),
                t.duration.is_finite() && t.duration > 0.0 && t.duration <= MAX_TASK_S,
                format!(
                    "must be a number of seconds in (0, {MAX_TASK_S}], got {}",
                    t.duration
                ),
            )?;
            check(
                format!("tasks[{i}].duration"),
                t.duration >= MIN_TASK_S,
                format!(
                    "{} s is shorter than the shortest phase, {MIN_TASK_S} s",
                    t.duration
                ),
            )?;
            let height = t.height.unwrap_or(0.10);
            check(
                format!("tasks[{i}].height"),
                height.is_finite() && (0.0..=1.0).contains(&height),
                "must be within [0, 1] m",
            )?;
            let offset = t.offset.unwrap_or([0.0, 0.15, 0.0]);
            check(
                format!("tasks[{i}].offset"),
                offset.iter().all(|v| v.is_finite() && v.abs() <= 1.0),
                "must be finite and within 1 m",
            )?;
            let turn = t.turn.unwrap_or(0.0);
            check(
                format!("tasks[{i}].turn"),
                turn.is_finite() && turn.abs() <= std::f64::consts::PI,
                "must be within [-π, π] rad",
            )?;
            out.push(ResolvedTask {
                phase,
                duration: t.duration,
                height,
                offset,
                turn,
            });
        }
        let total: Real = out.iter().map(|t| t.duration).sum();
        check(
            "tasks".into(),
            total <= MAX_SCRIPT_S,
            format!("the script lasts {total} s; a session lasts at most {MAX_SCRIPT_S} s"),
        )?;
        Ok((scene, out))
    }

    /// Total duration of the script (s).
    pub fn duration(&self) -> Real {
        self.tasks.iter().map(|t| t.duration).sum()
    }

    /// The longest a session of the script can last (s): its [`duration`](Self::duration),
    /// or with [`vary_reach`](Self::vary_reach) the script with every `approach` and
    /// `preshape` at the slowest reach speed and every `approach` with the longest pause
    /// ([`REACH_SPEED`](crate::operator::REACH_SPEED),
    /// [`REACH_PAUSE_S`](crate::operator::REACH_PAUSE_S)).
    pub fn longest_duration(&self) -> Real {
        if !self.vary_reach {
            return self.duration();
        }
        let slowest = crate::operator::REACH_SPEED.0;
        self.tasks
            .iter()
            .map(|t| match t.phase {
                Phase::Approach => t.duration / slowest + crate::operator::REACH_PAUSE_S.1,
                Phase::Preshape => t.duration / slowest,
                _ => t.duration,
            })
            .sum()
    }
}

#[cfg(test)]
mod tests;
