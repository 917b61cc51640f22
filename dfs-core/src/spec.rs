//! What a grasp file, a scenario and a hand file may say: the physically sensible ranges of
//! their numbers (a hand holds objects of 1 mg to 10 t, 0.1 mm to 10 m in half size, under at
//! most 10 g, with μ ≤ 10), and the grasp file's format ([`GraspSpec`], its [`ObjectSpec`] and
//! [`ContactSpec`]s) with its validation. An error names the field and the range. The static
//! analysis of a grasp file is [`crate::statics`].

use crate::contact::{ContactFrame, ContactModel, Friction};
use crate::error::{DfsError, Result};
use crate::grasp::MAX_CONTACTS;
use crate::math::{Real, Vector};
use crate::object::{ClosestPoint, RigidObject, Shape, ShapeKind};
use serde::{Deserialize, Serialize};

/// Allowed object mass (kg) in a grasp file: 1 mg to 10 t.
pub const MASS_RANGE: (Real, Real) = (1e-6, 1e4);
/// Allowed radius, half extent and half height (m) in a grasp file: 0.1 mm to 10 m.
pub const SIZE_RANGE: (Real, Real) = (1e-4, 10.0);
/// Largest gravity (m/s², norm) in a grasp file: about 10 g, beyond any load a hand holds.
pub const MAX_GRAVITY: Real = 100.0;
/// Largest requested linear object acceleration (m/s², norm) in a grasp file.
pub const MAX_LINEAR_ACCELERATION: Real = 1e3;
/// Largest requested angular object acceleration (rad/s², norm) in a grasp file.
pub const MAX_ANGULAR_ACCELERATION: Real = 1e4;
/// Allowed Coulomb coefficient μ: real surfaces stay below 2 or so.
pub const MU_RANGE: (Real, Real) = (0.0, 10.0);
/// Allowed torsional coefficient μ_t (m): a fingertip pad's is a few millimetres.
pub const MU_TORSION_RANGE: (Real, Real) = (0.0, 1.0);
/// How far (as a fraction of the object's smallest half size: a sphere's radius, a box's
/// smallest half extent, the smaller of a cylinder's radius and half height) a contact
/// position may lie from the object's surface. 5 %: the paper's §3.4 contact points are
/// rounded to 1 mm and lie 3.5 to 3.8 mm inside its 0.1 m sphere.
pub const SURFACE_TOLERANCE: Real = 0.05;

pub(crate) fn check_range(
    field: impl Into<String>,
    v: Real,
    (lo, hi): (Real, Real),
    unit: &str,
) -> Result<()> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(DfsError::invalid(
            field,
            format!("must be a number in [{lo:?}, {hi:?}]{unit}, got {v:?}"),
        ))
    }
}

fn check_norm(field: &str, values: &[Real], max: Real, unit: &str) -> Result<()> {
    finite_field(field.into(), values)?;
    let n = values.iter().map(|v| v * v).sum::<Real>().sqrt();
    if n <= max {
        Ok(())
    } else {
        Err(DfsError::invalid(
            field,
            format!("its magnitude must be at most {max:?} {unit}, got {n:?}"),
        ))
    }
}

/// The object of a grasp file, as written: `{"shape": "sphere", "radius": 0.1, "mass": 1.0}`.
/// A box takes `half_extents: [x, y, z]`, a cylinder `radius` and `half_height` (m, MuJoCo's
/// convention of half sizes); the cylinder's axis is B's z.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "an object {\"shape\": ..., \"mass\": ...}"
)]
pub struct ObjectSpec {
    /// The shape: `sphere`, `box` or `cylinder`.
    pub shape: ShapeKind,
    /// Radius (m) of a sphere or cylinder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<Real>,
    /// Half extents (m) of a box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_extents: Option<[Real; 3]>,
    /// Half height (m) of a cylinder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_height: Option<Real>,
    /// Mass (kg), > 0.
    pub mass: Real,
}

impl ObjectSpec {
    /// The object, validated; errors name the field (`object.radius`, ...).
    pub fn to_object(&self) -> Result<RigidObject> {
        RigidObject::new(self.to_shape()?, self.mass)
    }

    /// The shape with its sizes: each size the kind needs is given and none it does not
    /// take; errors name the field. The sizes themselves are checked by
    /// [`to_object`](Self::to_object) ([`Shape::validate`]) and
    /// [`check_ranges`](Self::check_ranges).
    pub fn to_shape(&self) -> Result<Shape> {
        let need = |v: Option<Real>, field: &str| {
            v.ok_or_else(|| {
                DfsError::invalid(
                    format!("object.{field}"),
                    format!("missing (required for a {})", self.shape),
                )
            })
        };
        let unexpected = |present: bool, field: &str| {
            if present {
                Err(DfsError::invalid(
                    format!("object.{field}"),
                    format!("not a parameter of a {}", self.shape),
                ))
            } else {
                Ok(())
            }
        };
        let shape = match self.shape {
            ShapeKind::Sphere => {
                unexpected(self.half_extents.is_some(), "half_extents")?;
                unexpected(self.half_height.is_some(), "half_height")?;
                Shape::Sphere {
                    radius: need(self.radius, "radius")?,
                }
            }
            ShapeKind::Box => {
                unexpected(self.radius.is_some(), "radius")?;
                unexpected(self.half_height.is_some(), "half_height")?;
                Shape::Box {
                    half_extents: self.half_extents.ok_or_else(|| {
                        DfsError::invalid("object.half_extents", "missing (required for a box)")
                    })?,
                }
            }
            ShapeKind::Cylinder => {
                unexpected(self.half_extents.is_some(), "half_extents")?;
                Shape::Cylinder {
                    radius: need(self.radius, "radius")?,
                    half_height: need(self.half_height, "half_height")?,
                }
            }
        };
        Ok(shape)
    }

    /// Checks that the mass and every size given lie in [`MASS_RANGE`] and [`SIZE_RANGE`]
    /// (a grasp file's ranges); errors name the field and the range.
    pub fn check_ranges(&self) -> Result<()> {
        check_range("object.mass", self.mass, MASS_RANGE, " kg")?;
        if let Some(r) = self.radius {
            check_range("object.radius", r, SIZE_RANGE, " m")?;
        }
        if let Some(h) = self.half_extents {
            for (i, v) in h.iter().enumerate() {
                check_range(format!("object.half_extents[{i}]"), *v, SIZE_RANGE, " m")?;
            }
        }
        if let Some(h) = self.half_height {
            check_range("object.half_height", h, SIZE_RANGE, " m")?;
        }
        Ok(())
    }

    /// The spec of an object.
    pub fn from_shape(shape: &Shape, mass: Real) -> Self {
        let mut s = ObjectSpec {
            shape: shape.kind(),
            radius: None,
            half_extents: None,
            half_height: None,
            mass,
        };
        match *shape {
            Shape::Sphere { radius } => s.radius = Some(radius),
            Shape::Box { half_extents } => s.half_extents = Some(half_extents),
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                s.radius = Some(radius);
                s.half_height = Some(half_height);
            }
        }
        s
    }
}

/// One contact of a grasp file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "a contact {\"position\": [x, y, z]}"
)]
pub struct ContactSpec {
    /// Contact point in the object frame B (m).
    pub position: [Real; 3],
    /// Inward contact normal in B (z of the contact frame, pointing into the object). When
    /// absent it comes from the shape: the inward normal at the surface point closest to
    /// `position`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal: Option<[Real; 3]>,
}

crate::object_only!(
    ObjectSpec,
    "an object {\"shape\": ..., \"mass\": ...}",
    serialize
);
crate::object_only!(
    ContactSpec,
    "a contact {\"position\": [x, y, z]}",
    serialize
);
crate::object_only!(
    GraspSpec,
    "a grasp file: a JSON object {\"object\": ..., \"contacts\": [...], ...}",
    serialize
);

fn default_gravity() -> [Real; 3] {
    [0.0, 0.0, -crate::math::STANDARD_GRAVITY]
}

/// A grasp file (docs/skills.md, "Grasp file"): an object, contacts in B, contact and friction
/// model, gravity in B and a requested object acceleration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    remote = "Self",
    expecting = "a grasp file: a JSON object {\"object\": ..., \"contacts\": [...], ...}"
)]
pub struct GraspSpec {
    /// The object.
    pub object: ObjectSpec,
    /// Gravity in B (m/s²). Default (0, 0, −9.81).
    #[serde(default = "default_gravity")]
    pub gravity: [Real; 3],
    /// Contact model. Default point with friction.
    #[serde(default)]
    pub contact_model: ContactModel,
    /// Coulomb coefficient μ in [`MU_RANGE`]. Required, except for the frictionless model,
    /// which transmits no tangential force and ignores it (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mu: Option<Real>,
    /// Torsional coefficient μ_t (m) in [`MU_TORSION_RANGE`], for the soft finger. Default 0.
    #[serde(default)]
    pub mu_torsion: Real,
    /// Contacts, 1 to 30 ([`MAX_CONTACTS`]: fingertips and whole-hand contacts).
    pub contacts: Vec<ContactSpec>,
    /// Requested object acceleration in B: (linear m/s², angular rad/s²). Default zero.
    #[serde(default)]
    pub object_acceleration: [Real; 6],
}

fn finite_field(field: String, values: &[Real]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(DfsError::invalid(
            field,
            format!("component {i} is not a finite number"),
        )),
        None => Ok(()),
    }
}

impl GraspSpec {
    /// The paper's §3.4 example: a 1 kg sphere of radius 0.1 m on four point contacts with
    /// friction, μ = 1.5 (the minimum-norm solution needs μ ≥ 1.3, docs/physics.md).
    pub fn paper_sphere() -> Self {
        let pts = [
            [0.054, 0.054, -0.059],
            [0.0, 0.076, -0.059],
            [-0.054, 0.054, -0.059],
            [0.0, -0.076, -0.059],
        ];
        GraspSpec {
            object: ObjectSpec::from_shape(&Shape::Sphere { radius: 0.1 }, 1.0),
            gravity: default_gravity(),
            contact_model: ContactModel::PointWithFriction,
            mu: Some(1.5),
            mu_torsion: 0.0,
            contacts: pts
                .iter()
                .map(|p| ContactSpec {
                    position: *p,
                    normal: None,
                })
                .collect(),
            object_acceleration: [0.0; 6],
        }
    }

    /// The built-in grasps by name.
    pub fn builtin(name: &str) -> Option<Self> {
        match name {
            "paper-sphere" => Some(Self::paper_sphere()),
            _ => None,
        }
    }

    /// Names of the built-in grasps.
    pub const BUILTINS: &'static [&'static str] = &["paper-sphere"];

    /// The friction coefficients, validated: `mu` is required except for the frictionless
    /// model (default 0 there); both lie in their ranges.
    pub fn friction(&self) -> Result<Friction> {
        let mu = match (self.mu, self.contact_model) {
            (Some(mu), _) => mu,
            (None, ContactModel::Frictionless) => 0.0,
            (None, model) => {
                return Err(DfsError::invalid(
                    "mu",
                    format!("missing (required for the {} contact model; only a frictionless grasp may omit it)", model.name()),
                ));
            }
        };
        check_range("mu", mu, MU_RANGE, "")?;
        check_range("mu_torsion", self.mu_torsion, MU_TORSION_RANGE, " m")?;
        Ok(Friction {
            mu,
            mu_torsion: self.mu_torsion,
        })
    }

    /// Validates every field and builds the object and contact frames; errors name the field
    /// and, for a number out of range, the range.
    pub fn resolve(&self) -> Result<(RigidObject, Vec<ContactFrame>)> {
        self.object.check_ranges()?;
        let object = self.object.to_object()?;
        check_norm("gravity", &self.gravity, MAX_GRAVITY, "m/s²")?;
        finite_field("object_acceleration".into(), &self.object_acceleration)?;
        check_norm(
            "object_acceleration (linear part)",
            &self.object_acceleration[..3],
            MAX_LINEAR_ACCELERATION,
            "m/s²",
        )?;
        check_norm(
            "object_acceleration (angular part)",
            &self.object_acceleration[3..],
            MAX_ANGULAR_ACCELERATION,
            "rad/s²",
        )?;
        self.friction()?;
        if self.contacts.is_empty() || self.contacts.len() > MAX_CONTACTS {
            return Err(DfsError::invalid(
                "contacts",
                format!(
                    "need 1 to {MAX_CONTACTS} contacts, got {}",
                    self.contacts.len()
                ),
            ));
        }
        let mut frames = Vec::with_capacity(self.contacts.len());
        for (i, c) in self.contacts.iter().enumerate() {
            finite_field(format!("contacts[{i}].position"), &c.position)?;
            let p = Vector::from(c.position);
            let ClosestPoint {
                distance,
                normal: n_out,
                ..
            } = object.shape.closest(&p);
            let tol = surface_tolerance(&object.shape);
            if distance.is_nan() || distance.abs() > tol {
                return Err(DfsError::invalid(
                    format!("contacts[{i}].position"),
                    format!(
                        "must be on the object's surface within {:.3e} m ({} % of the object's smallest half size), but contact {i} is not on the surface: it lies {}",
                        tol,
                        SURFACE_TOLERANCE * 100.0,
                        if distance.is_finite() {
                            format!("{:.4e} m from it", distance.abs())
                        } else {
                            "too far from it to measure".to_string()
                        }
                    ),
                ));
            }
            let z = match c.normal {
                Some(n) => {
                    finite_field(format!("contacts[{i}].normal"), &n)?;
                    let n = Vector::from(n);
                    // Scaled first: a normal such as (1e308, 1e308, 0) has an infinite norm.
                    let big = n.amax();
                    if big < 1e-9 {
                        return Err(DfsError::invalid(
                            format!("contacts[{i}].normal"),
                            "must not be the zero vector",
                        ));
                    }
                    let z = (n / big).normalize();
                    // The normal is the inward one (the contact frame's z): one pointing out
                    // of the object is a sign mistake, which would only show as a contact
                    // that "would have to pull".
                    let inward = z.dot(&-n_out);
                    if inward.is_nan() || inward <= 0.0 {
                        return Err(DfsError::invalid(
                            format!("contacts[{i}].normal"),
                            format!(
                                "must point into the object, but it is {:.0}° from the inward \
                                 surface normal there (is its sign flipped?)",
                                inward.clamp(-1.0, 1.0).acos().to_degrees()
                            ),
                        ));
                    }
                    z
                }
                None => -n_out,
            };
            frames.push(ContactFrame::from_normal(p, z));
        }
        Ok((object, frames))
    }
}

/// The largest distance (m) a contact may lie from the surface of `shape`:
/// [`SURFACE_TOLERANCE`] times its smallest half size.
pub fn surface_tolerance(shape: &Shape) -> Real {
    let smallest = match *shape {
        Shape::Sphere { radius } => radius,
        Shape::Box { half_extents } => half_extents.iter().copied().fold(Real::INFINITY, Real::min),
        Shape::Cylinder {
            radius,
            half_height,
        } => radius.min(half_height),
    };
    SURFACE_TOLERANCE * smallest
}
