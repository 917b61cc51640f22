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

use crate::error::{DfsError, Result};
use crate::math::Real;
use crate::names::Named;
use crate::object::{RigidObject, Shape, ShapeKind};
use crate::statics::ObjectSpec;
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
    /// ([`MU_RANGE`](crate::statics::MU_RANGE), [`MU_TORSION_RANGE`](crate::statics::MU_TORSION_RANGE)).
    pub fn to_object(&self) -> Result<RigidObject> {
        let spec = self.spec();
        let object = spec.to_object()?;
        spec.check_ranges()?;
        for (field, v, (lo, hi), unit) in [
            ("object.mu", self.mu, crate::statics::MU_RANGE, ""),
            (
                "object.mu_torsion",
                self.mu_torsion,
                crate::statics::MU_TORSION_RANGE,
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

/// A scenario file: the object, the grasp style and the operator's task script.
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
    /// The object.
    pub object: ScenarioObject,
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
    /// Validates the scenario and resolves its tasks; every error names the field.
    pub fn resolve(&self) -> Result<(RigidObject, Vec<ResolvedTask>)> {
        let o = &self.object;
        let object = o.to_simulated_object()?;
        if let Some(p) = o.position {
            check(
                "object.position".into(),
                p.iter().all(|v| v.is_finite() && v.abs() < 10.0),
                "must be finite and within 10 m",
            )?;
        }
        check("object.yaw".into(), o.yaw.is_finite(), "must be finite")?;
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
        Ok((object, out))
    }

    /// Total duration of the script (s).
    pub fn duration(&self) -> Real {
        self.tasks.iter().map(|t| t.duration).sum()
    }

    /// Names of the built-in scenarios.
    pub const BUILTINS: &'static [&'static str] = &[
        "sphere-lift",
        "box-pinch-lift",
        "cylinder-power-grasp",
        "sphere-rotate",
        "box-slip",
        "two-grasps",
    ];

    /// A built-in scenario by name, with the given seed.
    pub fn builtin(name: &str, seed: u64) -> Option<Scenario> {
        // A sphere glove10 can pinch: its 2-DOF thumb reaches about 0.11 m from the index
        // fingertip, so the paper's 0.2 m sphere cannot be grasped by opposing fingers, and a
        // two-finger pinch cannot carry the paper's 1 kg (dfs-static and the tick benchmark use
        // the paper's full-size, 1 kg sphere).
        let sphere = |mu: Real| ScenarioObject {
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
            _ => return None,
        };
        Some(Scenario {
            name: name.into(),
            object,
            grasp,
            tasks,
            seed,
            operator_mu,
        })
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
        s.object.mass = -1.0;
        assert!(s.resolve().unwrap_err().to_string().contains("object.mass"));
        // Too light for the explicit object step (1 g diverged at lift-off): refused up front.
        s.object.mass = 0.001;
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("object.mass") && e.contains("0.005"), "{e}");
        s.object.mass = MIN_SIMULATED_MASS;
        assert!(s.resolve().is_ok());
        // A grasp file's ranges hold for scenario objects too: a 1e30 kg sphere or one 1 km
        // across is not a hand-held object.
        s.object.mass = 1e30;
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("object.mass"), "{e}");
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.radius = Some(500.0);
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("object.radius"), "{e}");
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.mu = -0.2;
        assert!(s.resolve().unwrap_err().to_string().contains("object.mu"));
        // And for friction: a grasp file refuses μ above 10 and μ_t above 1 m.
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.mu = 1e6;
        let e = s.resolve().unwrap_err().to_string();
        assert!(e.contains("object.mu") && e.contains("[0.0, 10.0]"), "{e}");
        let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
        s.object.mu_torsion = 50.0;
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
        assert_eq!(s.object.shape, ShapeKind::Sphere);
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
