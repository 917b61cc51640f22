//! A scenario's objects resolved into a validated [`Scene`]: names, the target, the table
//! height and start poses, and no two objects overlapping.

use super::*;

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
            let object = scene_object(o, &field(i), listed, several, &out)?;
            out.push(object);
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

/// One object of a scene, checked: its name (required when `listed`, unique among `before`),
/// the rigid body, its `position` (required when there are `several`) and yaw. `f` is its
/// field (`objects[2]`, or `object`).
fn scene_object(
    o: &ScenarioObject,
    f: &str,
    listed: bool,
    several: bool,
    before: &[SceneObject],
) -> Result<SceneObject> {
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
    if let Some(j) = before.iter().position(|other| other.name == name) {
        return Err(DfsError::invalid(
            format!("{f}.name"),
            format!("{name:?} names objects[{j}] too; names must be unique"),
        ));
    }
    let object = o.to_simulated_object().map_err(|e| at_object(f, e))?;
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
    Ok(SceneObject {
        name,
        spec: o.clone(),
        object,
        friction: Friction {
            mu: o.mu,
            mu_torsion: o.mu_torsion,
        },
        pose: Isometry::from_parts(position.into(), yaw),
    })
}
