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

/// The name of the one object of a scenario's `object` that gives none.
pub const DEFAULT_OBJECT_NAME: &str = "object";

/// Longest object name, in characters: 64.
pub const MAX_OBJECT_NAME_CHARS: usize = 64;

/// One object of a resolved [`Scene`]: its name, what the scenario said of it, the rigid body,
/// its fingertip friction and its start pose.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    /// Its name, unique in the scene ([`DEFAULT_OBJECT_NAME`] for an unnamed `object`).
    pub name: String,
    /// The object as the scenario (or a live session's `start`) gave it.
    pub spec: ScenarioObject,
    /// Shape and mass properties, validated for the closed loop
    /// ([`ScenarioObject::to_simulated_object`]).
    pub object: RigidObject,
    /// Friction between the fingertips and it (`mu`, `mu_torsion`).
    pub friction: Friction,
    /// Start pose in the world (the table's top at z = [`Scene::table_height`]).
    pub pose: Isometry,
}

/// A validated scene: 1 to [`MAX_OBJECTS`] objects on a table, none overlapping another, and
/// the one a script grasps. What the simulation and a live session build their DFS from
/// ([`Scene::dfs_objects`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The objects, in the order given (the DFS's object indices).
    pub objects: Vec<SceneObject>,
    /// Index of the object the script grasps.
    pub target: usize,
    /// Height of the table's top (m, world z): the lowest object's lowest point.
    pub table_height: Real,
}

/// `e` with a field `object...` renamed `prefix...` (`objects[2]` for the third object).
fn at_object(prefix: &str, e: DfsError) -> DfsError {
    match e {
        DfsError::Invalid { field, reason } if prefix != "object" => {
            let field = match field.strip_prefix("object") {
                Some(rest) => format!("{prefix}{rest}"),
                None => field,
            };
            DfsError::Invalid { field, reason }
        }
        e => e,
    }
}

impl Scene {
    /// Validates and resolves a scene given as a scenario (or a live session's `start`) gives
    /// it: exactly one of `object` (a scene of one, its name optional) and `objects` (1 to
    /// [`MAX_OBJECTS`], each named, names unique, each with its `position` when there are
    /// several), and `target`, the name of the object to grasp (required with several). A
    /// scene whose objects overlap at their start poses, or once each rests on the table, is
    /// refused naming both. Errors name the field (`objects[1].mass`, `target`).
    pub fn new(
        object: Option<&ScenarioObject>,
        objects: Option<&[ScenarioObject]>,
        target: Option<&str>,
    ) -> Result<Scene> {
        let (list, listed) = match (object, objects) {
            (Some(_), Some(_)) => {
                return Err(DfsError::invalid(
                    "objects",
                    "give either `object` (one object) or `objects` (a list), not both",
                ))
            }
            (None, None) => {
                return Err(DfsError::invalid(
                    "object",
                    "missing: a scene needs its `object` (or a list of `objects`)",
                ))
            }
            (Some(o), None) => (std::slice::from_ref(o), false),
            (None, Some(v)) => (v, true),
        };
        check(
            "objects".into(),
            (1..=MAX_OBJECTS).contains(&list.len()),
            format!("{} objects; a scene holds 1 to {MAX_OBJECTS}", list.len()),
        )?;
        let several = list.len() > 1;
        let field = |i: usize| {
            if listed {
                format!("objects[{i}]")
            } else {
                "object".to_owned()
            }
        };
        let mut out: Vec<SceneObject> = Vec::with_capacity(list.len());
        for (i, o) in list.iter().enumerate() {
            let f = field(i);
            let name = match &o.name {
                Some(n) => {
                    let chars = n.chars().count();
                    check(
                        format!("{f}.name"),
                        (1..=MAX_OBJECT_NAME_CHARS).contains(&chars),
                        format!("must be 1 to {MAX_OBJECT_NAME_CHARS} characters, got {chars}"),
                    )?;
                    check(
                        format!("{f}.name"),
                        !n.chars().any(char::is_control) && n.trim() == n,
                        "must not hold control characters or start or end with a space",
                    )?;
                    n.clone()
                }
                None if listed => {
                    return Err(DfsError::invalid(
                        format!("{f}.name"),
                        "missing: each object of `objects` needs a name",
                    ))
                }
                None => DEFAULT_OBJECT_NAME.to_owned(),
            };
            if let Some(j) = out.iter().position(|other| other.name == name) {
                return Err(DfsError::invalid(
                    format!("{f}.name"),
                    format!("{name:?} names objects[{j}] too; names must be unique"),
                ));
            }
            let object = o.to_simulated_object().map_err(|e| at_object(&f, e))?;
            if let Some(p) = o.position {
                check(
                    format!("{f}.position"),
                    p.iter().all(|v| v.is_finite() && v.abs() < 10.0),
                    "must be finite and within 10 m",
                )?;
            } else if several {
                return Err(DfsError::invalid(
                    format!("{f}.position"),
                    "missing: with several objects each needs its position (at the default, the \
                     origin, they would overlap)",
                ));
            }
            check(format!("{f}.yaw"), o.yaw.is_finite(), "must be finite")?;
            let depth = object.shape.support_depth(&Rotation::identity());
            let yaw = Rotation::from_euler_angles(0.0, 0.0, o.yaw);
            let position = o
                .position
                .map(Vector::from)
                .unwrap_or(Vector::new(0.0, 0.0, depth));
            out.push(SceneObject {
                name,
                spec: o.clone(),
                object,
                friction: Friction {
                    mu: o.mu,
                    mu_torsion: o.mu_torsion,
                },
                pose: Isometry::from_parts(position.into(), yaw),
            });
        }
        let names = || {
            out.iter()
                .map(|o| format!("{:?}", o.name))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let target = match target {
            Some(t) => out.iter().position(|o| o.name == t).ok_or_else(|| {
                DfsError::invalid(
                    "target",
                    format!(
                        "{t:?} names no object of the scene; its objects are {}",
                        names()
                    ),
                )
            })?,
            None if several => {
                return Err(DfsError::invalid(
                    "target",
                    format!(
                        "missing: with several objects, the name of the one the script grasps \
                         (one of {})",
                        names()
                    ),
                ))
            }
            None => 0,
        };
        let table_height = out
            .iter()
            .map(|o| o.pose.translation.z - o.object.shape.support_depth(&o.pose.rotation))
            .fold(Real::INFINITY, Real::min);
        let scene = Scene {
            objects: out,
            target,
            table_height,
        };
        scene.check_overlaps(&field)?;
        Ok(scene)
    }

    /// Refuses two objects that overlap at their start poses or once both rest on the table
    /// (same place and yaw, lowered onto it), naming both.
    fn check_overlaps(&self, field: &dyn Fn(usize) -> String) -> Result<()> {
        let rest = |o: &SceneObject| {
            let mut p = o.pose;
            p.translation.z = self.table_height + o.object.shape.support_depth(&p.rotation);
            p
        };
        for (j, b) in self.objects.iter().enumerate() {
            for (i, a) in self.objects[..j].iter().enumerate() {
                let (sa, sb) = (&a.object.shape, &b.object.shape);
                let when = if shapes_overlap(sa, &a.pose, sb, &b.pose) {
                    "at their start positions"
                } else if shapes_overlap(sa, &rest(a), sb, &rest(b)) {
                    "once both rest on the table"
                } else {
                    continue;
                };
                return Err(DfsError::invalid(
                    format!("{}.position", field(j)),
                    format!(
                        "{:?} and {:?} ({}) overlap {when}: objects must be placed farther \
                         apart than their sizes allow",
                        b.name,
                        a.name,
                        field(i)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The object the script grasps.
    pub fn target(&self) -> &SceneObject {
        &self.objects[self.target]
    }

    /// The index of the object named `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.objects.iter().position(|o| o.name == name)
    }

    /// The objects for [`Dfs::with_objects`](crate::dfs::Dfs::with_objects), each at rest at
    /// its start pose with its friction.
    pub fn dfs_objects(&self) -> Vec<DfsObject> {
        self.objects
            .iter()
            .map(|o| DfsObject {
                object: o.object,
                friction: o.friction,
                state: ObjectState::at_rest(o.pose),
            })
            .collect()
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

    /// Names of the built-in scenarios.
    pub const BUILTINS: &'static [&'static str] = &[
        "sphere-lift",
        "box-pinch-lift",
        "cylinder-power-grasp",
        "sphere-rotate",
        "box-slip",
        "two-grasps",
        "table-three",
    ];

    /// A built-in scenario by name, with the given seed.
    pub fn builtin(name: &str, seed: u64) -> Option<Scenario> {
        // A sphere glove10 can pinch: its 2-DOF thumb reaches about 0.11 m from the index
        // fingertip, so the paper's 0.2 m sphere cannot be grasped by opposing fingers, and a
        // two-finger pinch cannot carry the paper's 1 kg (dfs-static and the tick benchmark use
        // the paper's full-size, 1 kg sphere).
        let sphere = |mu: Real| ScenarioObject {
            name: None,
            shape: ShapeKind::Sphere,
            radius: Some(0.04),
            half_extents: None,
            half_height: None,
            mass: 0.3,
            mu,
            mu_torsion: 0.005,
            position: None,
            yaw: 0.0,
        };
        let small_box = |mu: Real| ScenarioObject {
            name: None,
            shape: ShapeKind::Box,
            radius: None,
            half_extents: Some([0.025, 0.025, 0.04]),
            half_height: None,
            mass: 0.2,
            mu,
            mu_torsion: 0.003,
            position: None,
            yaw: 0.0,
        };
        let t = |phase: Phase, duration: Real| Task {
            phase,
            duration,
            height: None,
            offset: None,
            turn: None,
        };
        let pick = || {
            vec![
                t(Phase::Approach, 0.8),
                t(Phase::Preshape, 0.5),
                t(Phase::Grasp, 0.8),
                t(Phase::Lift, 1.0),
            ]
        };
        let put = || {
            vec![
                t(Phase::Place, 1.0),
                t(Phase::Release, 0.6),
                t(Phase::Retreat, 0.6),
            ]
        };
        let (object, grasp, tasks, operator_mu) = match name {
            "sphere-lift" => {
                let mut v = pick();
                v.push(t(Phase::Hold, 2.0));
                v.extend(put());
                (sphere(0.8), GraspStyle::Pinch, v, None)
            }
            "box-pinch-lift" => {
                let mut v = pick();
                v.push(t(Phase::Hold, 1.0));
                v.extend(put());
                (small_box(0.8), GraspStyle::Pinch, v, None)
            }
            "cylinder-power-grasp" => {
                let cyl = ScenarioObject {
                    name: None,
                    shape: ShapeKind::Cylinder,
                    radius: Some(0.035),
                    half_extents: None,
                    half_height: Some(0.09),
                    mass: 0.5,
                    mu: 0.7,
                    mu_torsion: 0.005,
                    position: None,
                    yaw: 0.0,
                };
                let mut v = pick();
                v.push(t(Phase::Hold, 1.0));
                v.push(t(Phase::Transport, 1.5));
                v.extend(put());
                (cyl, GraspStyle::Power, v, None)
            }
            "sphere-rotate" => {
                let mut v = pick();
                v.push(t(Phase::Hold, 0.5));
                v.push(Task {
                    phase: Phase::Transport,
                    duration: 2.0,
                    height: None,
                    offset: Some([0.0, 0.0, 0.0]),
                    turn: Some(0.8),
                });
                v.push(t(Phase::Hold, 0.5));
                v.extend(put());
                (sphere(0.8), GraspStyle::Pinch, v, None)
            }
            "box-slip" => {
                let mut v = pick();
                v.push(t(Phase::Hold, 1.0));
                v.push(t(Phase::Retreat, 0.6));
                // The operator grips for μ = 0.8 but the surface is slippery (μ = 0.3): the
                // grip's peak at lift-off carries the box up, and as the grip relaxes to the
                // level the operator believes enough the box slides out of the grasp and falls
                // back to the table.
                (small_box(0.3), GraspStyle::Pinch, v, Some(0.8))
            }
            "two-grasps" => {
                let mut v = pick();
                v.push(t(Phase::Transport, 1.0));
                v.extend(put());
                v.extend(pick());
                v.push(t(Phase::Hold, 0.5));
                v.extend(put());
                (small_box(0.8), GraspStyle::Pinch, v, None)
            }
            "table-three" => return Some(Self::table_three(seed)),
            _ => return None,
        };
        Some(Scenario {
            name: name.into(),
            object: Some(object),
            objects: None,
            target: None,
            grasp,
            tasks,
            seed,
            operator_mu,
            vary_reach: false,
        })
    }

    /// `table-three`: a ball, a box and a cylinder on the table, 20 cm apart; the operator
    /// pinches the box between the other two, lifts it, holds it and sets it down.
    fn table_three(seed: u64) -> Scenario {
        let t = |phase: Phase, duration: Real| Task {
            phase,
            duration,
            height: None,
            offset: None,
            turn: None,
        };
        let object = |name: &str, shape: ShapeKind, position: [Real; 3]| ScenarioObject {
            name: Some(name.to_owned()),
            shape,
            radius: None,
            half_extents: None,
            half_height: None,
            mass: 0.3,
            mu: 0.8,
            mu_torsion: 0.005,
            position: Some(position),
            yaw: 0.0,
        };
        let ball = ScenarioObject {
            radius: Some(0.04),
            ..object("ball", ShapeKind::Sphere, [0.0, -0.2, 0.04])
        };
        let small_box = ScenarioObject {
            half_extents: Some([0.025, 0.025, 0.04]),
            mass: 0.2,
            mu_torsion: 0.003,
            ..object("box", ShapeKind::Box, [0.0, 0.0, 0.04])
        };
        let cylinder = ScenarioObject {
            radius: Some(0.035),
            half_height: Some(0.09),
            mass: 0.5,
            mu: 0.7,
            ..object("cylinder", ShapeKind::Cylinder, [0.0, 0.2, 0.09])
        };
        Scenario {
            name: "table-three".into(),
            object: None,
            objects: Some(vec![ball, small_box, cylinder]),
            target: Some("box".into()),
            grasp: GraspStyle::Pinch,
            tasks: vec![
                t(Phase::Approach, 0.8),
                t(Phase::Preshape, 0.5),
                t(Phase::Grasp, 0.8),
                t(Phase::Lift, 1.0),
                t(Phase::Hold, 1.0),
                t(Phase::Place, 1.0),
                t(Phase::Release, 0.6),
                t(Phase::Retreat, 0.6),
            ],
            seed,
            operator_mu: None,
            vary_reach: false,
        }
    }
}

/// Range of the factor a scenario variant ([`Scenario::variant`]) scales each size of each
/// object by (radius, each half extent, half height; drawn one by one).
pub const VARIANT_SIZE_SCALE: (Real, Real) = (0.85, 1.15);

/// Range of the factor a scenario variant scales each object's mass by.
pub const VARIANT_MASS_SCALE: (Real, Real) = (0.7, 1.3);

/// Range of the factor a scenario variant scales each object's μ (fingertip friction) by.
pub const VARIANT_MU_SCALE: (Real, Real) = (0.8, 1.2);

/// Largest shift (m) of each placed object of a scenario variant along world x and y (drawn
/// uniformly in ± this, redrawn while objects would overlap).
pub const VARIANT_JITTER_M: Real = 0.02;

/// The ChaCha8 stream of the seed a scenario variant's objects are drawn from (the tremor and
/// the noise draw from stream 0, varied reaches from
/// [`REACH_STREAM`](crate::operator::REACH_STREAM)).
pub const VARIANT_STREAM: u64 = 2;

impl Scenario {
    /// The built-in scenario `name` varied by `seed` (`None` for an unknown name): its reaches
    /// varied ([`vary_reach`](Scenario::vary_reach)), and each object's sizes, mass and μ
    /// scaled by factors drawn from [`VARIANT_SIZE_SCALE`], [`VARIANT_MASS_SCALE`] and
    /// [`VARIANT_MU_SCALE`] (`operator_mu`, where the scenario gives one, stays: in
    /// `box-slip` the operator still grips for μ 0.8). A scene of several objects
    /// (`table-three`) also has its target drawn among them, grasped as its kind is in the
    /// single-object scenarios (the ball and the box pinched, the cylinder in a power grasp),
    /// and each object shifted up to [`VARIANT_JITTER_M`] along x and y, resting on the table,
    /// none overlapping another. Draws come from the seed's [`VARIANT_STREAM`]; the same name
    /// and seed give the same variant.
    pub fn variant(name: &str, seed: u64) -> Option<Scenario> {
        let mut s = Scenario::builtin(name, seed)?;
        s.vary_reach = true;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(VARIANT_STREAM);
        let factor = |rng: &mut ChaCha8Rng, (lo, hi): (Real, Real)| rng.random_range(lo..=hi);
        let mut perturb = |o: &mut ScenarioObject| {
            for v in o
                .radius
                .iter_mut()
                .chain(o.half_extents.iter_mut().flatten())
                .chain(o.half_height.iter_mut())
            {
                *v *= factor(&mut rng, VARIANT_SIZE_SCALE);
            }
            o.mass *= factor(&mut rng, VARIANT_MASS_SCALE);
            o.mu *= factor(&mut rng, VARIANT_MU_SCALE);
        };
        if let Some(o) = s.object.as_mut() {
            perturb(o);
        }
        let Some(mut objects) = s.objects.take() else {
            return Some(s);
        };
        objects.iter_mut().for_each(&mut perturb);
        let target = rng.random_range(0..objects.len());
        s.target = objects[target].name.clone();
        s.grasp = match objects[target].shape {
            ShapeKind::Cylinder => GraspStyle::Power,
            ShapeKind::Sphere | ShapeKind::Box => GraspStyle::Pinch,
        };
        let placed: Vec<[Real; 3]> = objects
            .iter()
            .map(|o| o.position.unwrap_or_default())
            .collect();
        let rest = |o: &ScenarioObject| {
            o.to_shape()
                .map(|shape| shape.support_depth(&Rotation::from_euler_angles(0.0, 0.0, o.yaw)))
                .unwrap_or(0.0)
        };
        for attempt in 0..=8 {
            // The last attempt: where the scenario places them, unshifted.
            let shift = if attempt < 8 { VARIANT_JITTER_M } else { 0.0 };
            for (o, p) in objects.iter_mut().zip(&placed) {
                let dx = rng.random_range(-1.0..=1.0) * shift;
                let dy = rng.random_range(-1.0..=1.0) * shift;
                o.position = Some([p[0] + dx, p[1] + dy, rest(o)]);
            }
            if Scene::new(None, Some(&objects), s.target.as_deref()).is_ok() {
                break;
            }
        }
        s.objects = Some(objects);
        Some(s)
    }
}

impl Shape {
    /// Size of the object along the world x axis at yaw 0 (m): what a grasp must span.
    pub fn width_x(&self) -> Real {
        match *self {
            Shape::Sphere { radius } => 2.0 * radius,
            Shape::Box { half_extents } => 2.0 * half_extents[0],
            Shape::Cylinder { radius, .. } => 2.0 * radius,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_scenario_resolves() {
        for name in Scenario::BUILTINS {
            let s = Scenario::builtin(name, 3).unwrap();
            s.resolve().unwrap();
            assert!(s.duration() > 3.0);
        }
    }

    #[test]
    fn bad_scenarios_name_the_field() {
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.as_mut().unwrap().mass = -1.0;
        assert!(s.resolve().unwrap_err().to_string().contains("object.mass"));
        // Too light for the explicit object step (1 g diverged at lift-off): refused up front.
        s.object.as_mut().unwrap().mass = 0.001;
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("object.mass") && e.contains("0.005"), "{e}");
        s.object.as_mut().unwrap().mass = MIN_SIMULATED_MASS;
        assert!(s.resolve().is_ok());
        // A grasp file's ranges hold for scenario objects too: a 1e30 kg sphere or one 1 km
        // across is not a hand-held object.
        s.object.as_mut().unwrap().mass = 1e30;
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("object.mass"), "{e}");
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.as_mut().unwrap().radius = Some(500.0);
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("object.radius"), "{e}");
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.as_mut().unwrap().mu = -0.2;
        assert!(s.resolve().unwrap_err().to_string().contains("object.mu"));
        // And for friction: a grasp file refuses μ above 10 and μ_t above 1 m.
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.as_mut().unwrap().mu = 1e6;
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("object.mu") && e.contains("[0.0, 10.0]"), "{e}");
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.as_mut().unwrap().mu_torsion = 50.0;
        let e = s.resolve().unwrap_err().to_string();
        assert!(
            e.contains("object.mu_torsion") && e.contains("[0.0, 1.0] m"),
            "{e}"
        );
        // A lift height on a hold task was ignored.
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        let hold = s.tasks.iter().position(|t| t.phase == Phase::Hold).unwrap();
        s.tasks[hold].height = Some(0.3);
        let e = s.resolve().unwrap_err().to_string();
        assert!(
            e.contains(&format!("tasks[{hold}].height"))
                && e.contains("a hold task takes no height"),
            "{e}"
        );
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.tasks[hold].offset = Some([0.1, 0.0, 0.0]);
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains(&format!("tasks[{hold}].offset")), "{e}");
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.tasks[0].duration = 0.0;
        assert!(s
            .resolve()
            .unwrap_err()
            .to_string()
            .contains("tasks[0].duration"));
    }

    #[test]
    fn a_script_longer_than_an_hour_is_refused_naming_the_tasks() {
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.tasks = vec![
            Task {
                phase: Phase::Hold,
                duration: 600.0,
                height: None,
                offset: None,
                turn: None,
            };
            7
        ];
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("invalid tasks: the script lasts 4200 s"), "{e}");
        s.tasks.pop();
        s.resolve().unwrap();
    }

    fn hold(duration: Real) -> Task {
        Task {
            phase: Phase::Hold,
            duration,
            height: None,
            offset: None,
            turn: None,
        }
    }

    #[test]
    fn a_script_of_more_than_256_tasks_is_refused_naming_the_tasks() {
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.tasks = vec![hold(0.001); 100_000];
        let e = s.resolve().unwrap_err().to_string();
        assert_eq!(e, "invalid tasks: 100000 tasks; at most 256 are accepted");
        s.tasks = vec![hold(0.1); MAX_TASKS + 1];
        assert!(s.resolve().is_err());
        s.tasks.pop();
        s.resolve().unwrap();
    }

    #[test]
    fn a_task_shorter_than_the_shortest_phase_is_refused_naming_it() {
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.tasks[3].duration = 0.001;
        let e = s.resolve().unwrap_err().to_string();
        assert_eq!(
            e,
            "invalid tasks[3].duration: 0.001 s is shorter than the shortest phase, 0.05 s"
        );
        s.tasks[3].duration = MIN_TASK_S;
        s.resolve().unwrap();
        s.tasks[3].duration = 601.0;
        let e = s.resolve().unwrap_err().to_string();
        assert!(
            e.contains("tasks[3].duration") && e.contains("(0, 600]"),
            "{e}"
        );
    }

    /// A scenario from JSON, or serde's message (the callers add the field's path).
    fn parse(json: &serde_json::Value) -> std::result::Result<Scenario, String> {
        serde_json::from_value(json.clone()).map_err(|e| e.to_string())
    }

    #[test]
    fn an_unknown_shape_or_phase_is_refused_when_the_file_is_read_naming_it() {
        let good = serde_json::json!({
            "name": "x",
            "object": {"shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8},
            "tasks": [{"phase": "approach", "duration": 0.5}],
        });
        let s = parse(&good).unwrap();
        assert_eq!(s.object.as_ref().unwrap().shape, ShapeKind::Sphere);
        assert_eq!(s.tasks[0].phase, Phase::Approach);
        // Written back as it was read.
        let back = serde_json::to_value(&s).unwrap();
        assert_eq!(back["object"]["shape"], "sphere");
        assert_eq!(back["tasks"][0]["phase"], "approach");
        let mut bad = good.clone();
        bad["object"]["shape"] = "torus".into();
        let e = parse(&bad).unwrap_err();
        assert!(
            e.contains("unknown shape \"torus\"; expected one of sphere, box, cylinder"),
            "{e}"
        );
        let mut bad = good.clone();
        bad["tasks"][0]["phase"] = "juggle".into();
        let e = parse(&bad).unwrap_err();
        assert!(
            e.contains("unknown phase \"juggle\"; expected one of approach, preshape"),
            "{e}"
        );
        let mut bad = good;
        bad["grasp"] = "claw".into();
        let e = parse(&bad).unwrap_err();
        assert!(e.contains("unknown grasp style \"claw\""), "{e}");
    }

    #[test]
    fn phases_and_grasp_styles_are_named_as_in_files_and_phases_order_by_name() {
        crate::names::assert_serde_agrees::<Phase>();
        crate::names::assert_serde_agrees::<GraspStyle>();
        let mut sorted = Phase::ALL;
        sorted.sort();
        let names: Vec<&str> = sorted.iter().map(|p| p.name()).collect();
        let mut alphabetical = names.clone();
        alphabetical.sort_unstable();
        assert_eq!(names, alphabetical);
        // A map keyed by phase writes its keys as a map keyed by name did.
        let by_phase: std::collections::BTreeMap<Phase, u8> =
            Phase::ALL.iter().map(|p| (*p, 0)).collect();
        let by_name: std::collections::BTreeMap<&str, u8> =
            Phase::ALL.iter().map(|p| (p.name(), 0)).collect();
        assert_eq!(
            serde_json::to_string(&by_phase).unwrap(),
            serde_json::to_string(&by_name).unwrap()
        );
    }

    /// A scene of a ball, a box and a cylinder, as a scenario file gives it.
    fn three() -> serde_json::Value {
        serde_json::json!({
            "name": "three",
            "objects": [
                {"name": "ball", "shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8,
                 "position": [0.0, -0.2, 0.04]},
                {"name": "box", "shape": "box", "half_extents": [0.025, 0.025, 0.04],
                 "mass": 0.2, "mu": 0.6, "position": [0.0, 0.0, 0.04], "yaw": 0.3},
                {"name": "cylinder", "shape": "cylinder", "radius": 0.035, "half_height": 0.09,
                 "mass": 0.5, "mu": 0.7, "position": [0.0, 0.2, 0.09]},
            ],
            "target": "box",
            "tasks": [{"phase": "approach", "duration": 0.5}],
        })
    }

    fn scene_error(json: &serde_json::Value) -> String {
        parse(json)
            .unwrap()
            .resolve_scene()
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn a_scene_of_several_named_objects_resolves_with_its_target() {
        let s = parse(&three()).unwrap();
        let (scene, _) = s.resolve_scene().unwrap();
        let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["ball", "box", "cylinder"]);
        assert_eq!(scene.target, 1);
        assert_eq!(scene.target().name, "box");
        assert_eq!(scene.target().friction.mu, 0.6);
        assert_eq!(scene.table_height, 0.0);
        assert_eq!(scene.index_of("cylinder"), Some(2));
        assert_eq!(s.target_object().unwrap().name.as_deref(), Some("box"));
        let (target, _) = s.resolve().unwrap();
        assert_eq!(target, scene.target().object);
        assert_eq!(scene.dfs_objects().len(), 3);
        // Written back as it was read (with its defaults).
        let back = serde_json::to_value(&s).unwrap();
        assert_eq!(back["target"], "box");
        assert_eq!(back["objects"][2]["name"], "cylinder");
        assert_eq!(parse(&back).unwrap(), s);
        // A single object is named "object" unless named, and is its own target.
        let one = Scenario::builtin("sphere-lift", 0).unwrap();
        let (scene, _) = one.resolve_scene().unwrap();
        assert_eq!(
            (scene.objects.len(), scene.target().name.as_str()),
            (1, DEFAULT_OBJECT_NAME)
        );
        let back = serde_json::to_value(&one).unwrap();
        assert!(back.get("objects").is_none() && back.get("target").is_none());
        assert!(back["object"].get("name").is_none());
        let mut named = serde_json::to_value(&one).unwrap();
        named["object"]["name"] = "cup".into();
        named["target"] = "cup".into();
        let (scene, _) = parse(&named).unwrap().resolve_scene().unwrap();
        assert_eq!(scene.target().name, "cup");
        named["target"] = "mug".into();
        let e = scene_error(&named);
        assert!(e.contains("invalid target: \"mug\" names no object"), "{e}");
    }

    #[test]
    fn objects_and_target_are_checked_naming_the_field() {
        let mut j = three();
        j["object"] = j["objects"][0].clone();
        let e = scene_error(&j);
        assert!(e.contains("invalid objects: give either `object`"), "{e}");
        let mut j = three();
        j.as_object_mut().unwrap().remove("objects");
        let e = scene_error(&j);
        assert!(e.contains("invalid object: missing"), "{e}");
        let mut j = three();
        j.as_object_mut().unwrap().remove("target");
        let e = scene_error(&j);
        assert!(
            e.contains("invalid target: missing") && e.contains("\"ball\", \"box\""),
            "{e}"
        );
        let mut j = three();
        j["target"] = "cup".into();
        assert!(scene_error(&j).contains("invalid target: \"cup\" names no object"));
        let mut j = three();
        j["objects"][2]["name"] = "ball".into();
        let e = scene_error(&j);
        assert!(
            e.contains("invalid objects[2].name: \"ball\" names objects[0] too"),
            "{e}"
        );
        for bad in ["", " ball", &"x".repeat(65), "a\nb"] {
            let mut j = three();
            j["objects"][1]["name"] = bad.into();
            j["target"] = bad.into();
            assert!(
                scene_error(&j).contains("invalid objects[1].name"),
                "{bad:?}"
            );
        }
        let mut j = three();
        j["objects"][1]["name"] = "é".repeat(64).into();
        j["target"] = "é".repeat(64).into();
        parse(&j).unwrap().resolve_scene().unwrap();
        let mut j = three();
        j["objects"][0].as_object_mut().unwrap().remove("name");
        assert!(scene_error(&j).contains("invalid objects[0].name: missing"));
        let mut j = three();
        j["objects"][2].as_object_mut().unwrap().remove("position");
        let e = scene_error(&j);
        assert!(e.contains("invalid objects[2].position: missing"), "{e}");
        // The object's own fields, under its path.
        let mut j = three();
        j["objects"][1]["mass"] = (-1.0).into();
        assert!(scene_error(&j).contains("invalid objects[1].mass"));
        let mut j = three();
        j["objects"][2]["half_height"] = serde_json::Value::Null;
        let e = scene_error(&j);
        assert!(e.contains("invalid objects[2].half_height"), "{e}");
        let mut j = three();
        j["objects"][0]["mu"] = 20.0.into();
        assert!(scene_error(&j).contains("invalid objects[0].mu"));
        // 1 to 8 objects.
        let mut j = three();
        j["objects"] = serde_json::json!([]);
        assert!(scene_error(&j).contains("invalid objects: 0 objects"));
        let mut j = three();
        let many: Vec<serde_json::Value> = (0..9)
            .map(|i| {
                let mut o = three()["objects"][0].clone();
                o["name"] = format!("ball{i}").into();
                o["position"] = serde_json::json!([0.0, 0.1 * i as f64, 0.04]);
                o
            })
            .collect();
        j["objects"] = many.into();
        j["target"] = "ball0".into();
        let e = scene_error(&j);
        assert!(
            e.contains("invalid objects: 9 objects; a scene holds 1 to 8"),
            "{e}"
        );
        j["objects"].as_array_mut().unwrap().pop();
        parse(&j).unwrap().resolve_scene().unwrap();
        // One object in the list: the target may be left out.
        let mut j = three();
        j["objects"].as_array_mut().unwrap().truncate(1);
        j.as_object_mut().unwrap().remove("target");
        let (scene, _) = parse(&j).unwrap().resolve_scene().unwrap();
        assert_eq!(scene.target().name, "ball");
        // A field no object takes.
        let mut j = three();
        j["objects"][1]["colour"] = "red".into();
        let e = parse(&j).unwrap_err();
        assert!(e.contains("unknown field `colour`"), "{e}");
    }

    #[test]
    fn a_scene_of_overlapping_objects_is_refused_naming_both() {
        // The cylinder moved onto the box.
        let mut j = three();
        j["objects"][2]["position"] = serde_json::json!([0.05, 0.02, 0.09]);
        let e = scene_error(&j);
        assert!(
            e.contains("invalid objects[2].position")
                && e.contains("\"cylinder\" and \"box\" (objects[1]) overlap at their start"),
            "{e}"
        );
        // Beside the box, but closer than their sizes allow: the box is 2.5 cm half wide
        // (turned 0.3 rad: it reaches 3.1 cm along x), the cylinder 3.5 cm.
        let mut j = three();
        j["objects"][2]["position"] = serde_json::json!([0.062, 0.0, 0.09]);
        assert!(scene_error(&j).contains("overlap at their start"));
        j["objects"][2]["position"] = serde_json::json!([0.07, 0.0, 0.09]);
        parse(&j).unwrap().resolve_scene().unwrap();
        // Held above the box, clear of it, but falling onto it: they would overlap once both
        // rest on the table.
        let mut j = three();
        j["objects"][0]["position"] = serde_json::json!([0.0, 0.0, 0.3]);
        let e = scene_error(&j);
        assert!(
            e.contains("invalid objects[1].position")
                && e.contains(
                    "\"box\" and \"ball\" (objects[0]) overlap once both rest on the table"
                ),
            "{e}"
        );
        // Diagonal neighbours whose bounding spheres overlap but whose shapes do not.
        let mut j = three();
        j["objects"][0] = serde_json::json!({"name": "crate", "shape": "box",
            "half_extents": [0.05, 0.05, 0.05], "mass": 0.5, "mu": 0.8,
            "position": [0.085, 0.085, 0.05]});
        j["objects"][1]["yaw"] = 0.0.into();
        parse(&j).unwrap().resolve_scene().unwrap();
    }

    #[test]
    fn a_variant_perturbs_the_objects_within_their_ranges_and_varies_the_reaches() {
        assert!(Scenario::variant("juggle", 1).is_none());
        let within = |v: Real, base: Real, (lo, hi): (Real, Real)| {
            (base * lo - 1e-12..=base * hi + 1e-12).contains(&v)
        };
        let mut targets = std::collections::BTreeSet::new();
        let mut masses = std::collections::BTreeSet::new();
        for name in Scenario::BUILTINS {
            for seed in 0..30 {
                let v = Scenario::variant(name, seed).unwrap();
                let b = Scenario::builtin(name, seed).unwrap();
                assert_eq!(
                    Scenario::variant(name, seed).unwrap(),
                    v,
                    "the same each time"
                );
                assert!(v.vary_reach && !b.vary_reach);
                assert_eq!(
                    (&v.name, &v.tasks, v.seed, v.operator_mu),
                    (&b.name, &b.tasks, b.seed, b.operator_mu)
                );
                v.resolve_scene().unwrap();
                // Written with the flag, and read back as it was.
                let json = serde_json::to_value(&v).unwrap();
                assert_eq!(json["vary_reach"], true);
                assert_eq!(parse(&json).unwrap(), v);
                let pairs: Vec<(&ScenarioObject, &ScenarioObject)> =
                    match (&v.object, &b.object, &v.objects, &b.objects) {
                        (Some(x), Some(y), None, None) => vec![(x, y)],
                        (None, None, Some(x), Some(y)) => x.iter().zip(y).collect(),
                        _ => panic!("{name}: the variant keeps the scene's form"),
                    };
                for (o, base) in pairs {
                    masses.insert(o.mass.to_bits());
                    assert!(within(o.mass, base.mass, VARIANT_MASS_SCALE), "{name}");
                    assert!(within(o.mu, base.mu, VARIANT_MU_SCALE), "{name}");
                    for (x, y) in o.radius.iter().zip(&base.radius).chain(
                        o.half_extents
                            .iter()
                            .flatten()
                            .zip(base.half_extents.iter().flatten()),
                    ) {
                        assert!(within(*x, *y, VARIANT_SIZE_SCALE), "{name}");
                    }
                    if let (Some(x), Some(y)) = (o.half_height, base.half_height) {
                        assert!(within(x, y, VARIANT_SIZE_SCALE), "{name}");
                    }
                    assert_eq!(
                        (&o.name, o.shape, o.yaw),
                        (&base.name, base.shape, base.yaw)
                    );
                    if let (Some(p), Some(q)) = (o.position, base.position) {
                        // Shifted by at most the jitter, resting on the table.
                        assert!((p[0] - q[0]).abs() <= VARIANT_JITTER_M + 1e-12);
                        assert!((p[1] - q[1]).abs() <= VARIANT_JITTER_M + 1e-12);
                        let depth = o.to_shape().unwrap().support_depth(&Rotation::identity());
                        assert!((p[2] - depth).abs() < 1e-12, "{name}");
                    }
                }
                if let Some(t) = &v.target {
                    let style = match v.target_object().unwrap().shape {
                        ShapeKind::Cylinder => GraspStyle::Power,
                        _ => GraspStyle::Pinch,
                    };
                    assert_eq!(v.grasp, style);
                    targets.insert(t.clone());
                } else {
                    assert_eq!(v.grasp, b.grasp);
                }
            }
        }
        assert_eq!(
            targets.into_iter().collect::<Vec<_>>(),
            ["ball", "box", "cylinder"]
        );
        assert!(masses.len() > 100, "the masses vary");
    }

    #[test]
    fn every_builtin_task_is_within_the_task_limits() {
        for name in Scenario::BUILTINS {
            let s = Scenario::builtin(name, 0).unwrap();
            assert!(s.tasks.len() <= MAX_TASKS, "{name}");
            for t in &s.tasks {
                assert!((MIN_TASK_S..=MAX_TASK_S).contains(&t.duration), "{name}");
            }
        }
    }
}
