//! Static force analysis of a grasp (paper §3.4): the grasp file, the minimum-norm
//! intensities that hold the object, the object's response when the operator pushes `scale`
//! times harder, the feedback to the operator, and the optimised distribution.
//!
//! Semantics, for a grasp with contacts `i`, grasp matrix `W` and a requested object
//! acceleration `a` (default zero):
//! - the load the hand must carry is `L = M* a − M* [ᴮg; 0]` (eq. 24-26 with zero velocity);
//! - the operator's intensities are `c_h = scale · W⁺ L` (eq. 27 read backwards: the
//!   minimum-norm distribution); friction limits them to `c̃_h` (eq. 17-18);
//! - the object force is `ᴮf̃ = W c̃_h` (eq. 23), `f_ext = ᴮf̃ + M*[ᴮg; 0]` (eq. 26) and the
//!   object acceleration `M*⁻¹ f_ext`;
//! - the object's reaction is `c̃_o = W⁺ f_ext`, friction-limited, and the feedback to the
//!   operator is `c̃_h − c̃_o` per contact (Fig. 4).
//!
//! With the paper's sphere and `scale = 1.5`, `f_ext = (0, 0, 4.905, 0, 0, 0)` and the feedback
//! equals the static case: the operator feels the sphere's weight.

use crate::contact::{
    apply_friction, in_cone, normal_and_tangential, ContactFrame, ContactModel, Friction, Intensity,
};
use crate::error::{DfsError, Result};
use crate::grasp::optimise::{optimise, OptimiseParams};
use crate::grasp::{GraspMatrix, MAX_CONTACTS};
use crate::math::{force_of, moment_of, wrench, Real, Rotation, Vector, Wrench};
use crate::object::{gravity_wrench_b, RigidObject, Shape};
use serde::{Deserialize, Serialize};

/// The object of a grasp file, as written: `{"shape": "sphere", "radius": 0.1, "mass": 1.0}`.
/// A box takes `half_extents: [x, y, z]`, a cylinder `radius` and `half_height` (m, MuJoCo's
/// convention of half sizes); the cylinder's axis is B's z.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// "sphere", "box" or "cylinder".
    pub shape: String,
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
        let shape = match self.shape.as_str() {
            "sphere" => {
                unexpected(self.half_extents.is_some(), "half_extents")?;
                unexpected(self.half_height.is_some(), "half_height")?;
                Shape::Sphere {
                    radius: need(self.radius, "radius")?,
                }
            }
            "box" => {
                unexpected(self.radius.is_some(), "radius")?;
                unexpected(self.half_height.is_some(), "half_height")?;
                Shape::Box {
                    half_extents: self.half_extents.ok_or_else(|| {
                        DfsError::invalid("object.half_extents", "missing (required for a box)")
                    })?,
                }
            }
            "cylinder" => {
                unexpected(self.half_extents.is_some(), "half_extents")?;
                Shape::Cylinder {
                    radius: need(self.radius, "radius")?,
                    half_height: need(self.half_height, "half_height")?,
                }
            }
            other => {
                return Err(DfsError::invalid(
                    "object.shape",
                    format!(
                        "unknown shape {other:?}; expected \"sphere\", \"box\" or \"cylinder\""
                    ),
                ))
            }
        };
        RigidObject::new(shape, self.mass)
    }

    /// The spec of an object.
    pub fn from_shape(shape: &Shape, mass: Real) -> Self {
        let mut s = ObjectSpec {
            shape: shape.name().into(),
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
#[serde(deny_unknown_fields)]
pub struct ContactSpec {
    /// Contact point in the object frame B (m).
    pub position: [Real; 3],
    /// Inward contact normal in B (z of the contact frame, pointing into the object). When
    /// absent it comes from the shape: the inward normal at the surface point closest to
    /// `position`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal: Option<[Real; 3]>,
}

fn default_gravity() -> [Real; 3] {
    [0.0, 0.0, -crate::math::STANDARD_GRAVITY]
}

/// A grasp file (DESIGN.md, "Grasp file"): an object, contacts in B, contact and friction
/// model, gravity in B and a requested object acceleration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraspSpec {
    /// The object.
    pub object: ObjectSpec,
    /// Gravity in B (m/s²). Default (0, 0, −9.81).
    #[serde(default = "default_gravity")]
    pub gravity: [Real; 3],
    /// Contact model. Default point with friction.
    #[serde(default)]
    pub contact_model: ContactModel,
    /// Coulomb coefficient μ ≥ 0.
    pub mu: Real,
    /// Torsional coefficient μ_t ≥ 0 (m), for the soft finger. Default 0.
    #[serde(default)]
    pub mu_torsion: Real,
    /// Contacts, 1 to 6.
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
    /// friction, μ = 1.5 (the minimum-norm solution needs μ ≥ 1.3, NOTES.md).
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
            mu: 1.5,
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

    /// Validates every field and builds the object and contact frames; errors name the field.
    pub fn resolve(&self) -> Result<(RigidObject, Vec<ContactFrame>)> {
        let object = self.object.to_object()?;
        finite_field("gravity".into(), &self.gravity)?;
        finite_field("object_acceleration".into(), &self.object_acceleration)?;
        if !(self.mu.is_finite() && self.mu >= 0.0) {
            return Err(DfsError::invalid(
                "mu",
                format!("must be a finite number ≥ 0, got {}", self.mu),
            ));
        }
        if !(self.mu_torsion.is_finite() && self.mu_torsion >= 0.0) {
            return Err(DfsError::invalid(
                "mu_torsion",
                format!("must be a finite number ≥ 0, got {}", self.mu_torsion),
            ));
        }
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
            let z = match c.normal {
                Some(n) => {
                    finite_field(format!("contacts[{i}].normal"), &n)?;
                    let n = Vector::from(n);
                    if n.norm() < 1e-9 {
                        return Err(DfsError::invalid(
                            format!("contacts[{i}].normal"),
                            "must not be the zero vector",
                        ));
                    }
                    n.normalize()
                }
                None => {
                    let (_, _, n_out) = object.shape.closest(&p);
                    -n_out
                }
            };
            frames.push(ContactFrame::from_normal(p, z));
        }
        Ok((object, frames))
    }
}

/// Per-contact results of the static analysis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ContactResult {
    /// Contact point in B (m).
    pub position: [Real; 3],
    /// Inward normal in B.
    pub normal: [Real; 3],
    /// The operator's intensities in Table 1's order (frictionless: `[c_n]`; point with
    /// friction: `[c_x, c_y, c_z]`; soft finger: `[c_x, c_y, c_z, c_τ]`), N and N·m.
    pub intensity: Vec<Real>,
    /// Normal force (N), positive pushing.
    pub normal_force: Real,
    /// Magnitude of the tangential force (N).
    pub tangential_force: Real,
    /// Whether the intensities lie inside the friction cone.
    pub in_cone: bool,
    /// The transmitted (friction-limited) intensities, same order.
    pub transmitted: Vec<Real>,
    /// The force fed back to the operator: `c̃_h − c̃_o`, same order.
    pub feedback: Vec<Real>,
}

impl ContactResult {
    fn new(
        frame: &ContactFrame,
        model: ContactModel,
        friction: &Friction,
        c: &Intensity,
        t: &Intensity,
        fb: &Intensity,
    ) -> Self {
        let (n, tan) = normal_and_tangential(&c.component_mul(&model.mask()));
        let list = |v: &Intensity| {
            let (a, k) = model.components(v);
            a[..k].to_vec()
        };
        ContactResult {
            position: frame.p_b.into(),
            normal: frame.normal_b().into(),
            intensity: list(c),
            normal_force: n,
            tangential_force: tan,
            in_cone: in_cone(model, friction, c),
            transmitted: list(t),
            feedback: list(fb),
        }
    }
}

/// The optimised distribution of a static analysis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OptimisedResult {
    /// Friction margin used (fraction of μ).
    pub margin: Real,
    /// Per-contact intensities.
    pub contacts: Vec<ContactResult>,
    /// Sum of the normal forces (N): the grip effort.
    pub total_normal_force: Real,
}

/// The result of [`analyse`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StaticAnalysis {
    /// Per-contact operator intensities, transmitted part and feedback.
    pub contacts: Vec<ContactResult>,
    /// `ᴮf̃ = W c̃_h` (force N, moment N·m) in B.
    pub object_force: [Real; 6],
    /// `f_ext` in B: what accelerates the object.
    pub f_ext: [Real; 6],
    /// Resulting object acceleration in B (m/s², rad/s²).
    pub object_acceleration: [Real; 6],
    /// Rank of the grasp matrix (6 for a grasp that can resist every wrench direction).
    pub grasp_rank: usize,
    /// Problems with the grasp (single contact, collinear contacts, slip), empty when none.
    pub warnings: Vec<String>,
    /// The least-internal-force distribution inside the cones, or `None` when infeasible.
    pub optimised: Option<OptimisedResult>,
    /// Why the optimisation is infeasible, when it is.
    pub optimised_reason: Option<String>,
}

/// Static analysis of a grasp file with the operator pushing `scale` times the minimum-norm
/// holding intensities (see the module docs).
pub fn analyse(spec: &GraspSpec, scale: Real) -> Result<StaticAnalysis> {
    if !scale.is_finite() {
        return Err(DfsError::invalid(
            "scale",
            format!("must be finite, got {scale}"),
        ));
    }
    let (object, frames) = spec.resolve()?;
    let model = spec.contact_model;
    let friction = Friction {
        mu: spec.mu,
        mu_torsion: spec.mu_torsion,
    };
    let n = frames.len();
    let g = GraspMatrix::new(&frames, model);
    let gravity_b = gravity_wrench_b(&object, &Rotation::identity(), &Vector::from(spec.gravity));
    let acc = Wrench::from_row_slice(&spec.object_acceleration);
    let load = object.spatial_inertia_times(&acc) - gravity_b;

    let mut c_static = [Intensity::zeros(); MAX_CONTACTS];
    g.distribute(&load, &mut c_static);
    let mut c_h = [Intensity::zeros(); MAX_CONTACTS];
    let mut c_t = [Intensity::zeros(); MAX_CONTACTS];
    let mut warnings = Vec::new();
    for i in 0..n {
        c_h[i] = c_static[i] * scale;
        let split = apply_friction(model, &friction, &c_h[i]);
        c_t[i] = split.transmitted;
        if split.separating && c_h[i].norm() > 1e-12 {
            warnings.push(format!(
                "contact {i} would have to pull (normal intensity {:.4} N): it transmits nothing",
                c_h[i][2]
            ));
        } else if split.slip {
            warnings.push(format!("contact {i} is outside its friction cone: it slips and transmits only the cone's part"));
        }
    }
    let object_force = g.wrench(&c_t[..n]);
    let f_ext = object_force + gravity_b;
    let a = wrench(
        &(force_of(&f_ext) / object.mass),
        &(object.inertia_inv * moment_of(&f_ext)),
    );
    let mut c_o = [Intensity::zeros(); MAX_CONTACTS];
    g.distribute(&f_ext, &mut c_o);
    let contacts: Vec<ContactResult> = (0..n)
        .map(|i| {
            let reaction = apply_friction(model, &friction, &c_o[i]).transmitted;
            let fb = c_t[i] - reaction;
            ContactResult::new(&frames[i], model, &friction, &c_h[i], &c_t[i], &fb)
        })
        .collect();
    if n == 1 {
        warnings
            .push("a single contact cannot resist every wrench: the grasp is degenerate".into());
    } else if g.rank < 6 {
        warnings.push(format!("the grasp matrix has rank {} < 6 (for example collinear contacts): some wrenches cannot be resisted", g.rank));
    }
    // c_static = W⁺ L already: what it reproduces is the part of the load W can carry.
    let residual_load = load - g.wrench(&c_static[..n]);
    if residual_load.norm() > 1e-9 * (1.0 + load.norm()) {
        warnings.push(format!(
            "the contacts cannot balance the load exactly (residual {:.4} N or N·m)",
            residual_load.norm()
        ));
    }

    let params = OptimiseParams::default();
    let (optimised, optimised_reason) = match optimise(&frames, model, &friction, &load, &params) {
        Ok(d) => {
            let contacts: Vec<ContactResult> = d
                .intensities
                .iter()
                .zip(&frames)
                .map(|(c, f)| ContactResult::new(f, model, &friction, c, c, c))
                .collect();
            let total = contacts.iter().map(|c| c.normal_force).sum();
            (
                Some(OptimisedResult {
                    margin: params.margin,
                    contacts,
                    total_normal_force: total,
                }),
                None,
            )
        }
        Err(e) => (None, Some(e.reason)),
    };
    Ok(StaticAnalysis {
        contacts,
        object_force: object_force.into(),
        f_ext: f_ext.into(),
        object_acceleration: a.into(),
        grasp_rank: g.rank,
        warnings,
        optimised,
        optimised_reason,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[Real], b: &[Real], tol: Real) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn the_paper_sphere_balances_gravity_and_reproduces_the_notes_table() {
        let r = analyse(&GraspSpec::paper_sphere(), 1.0).unwrap();
        assert!(close(
            &r.object_force,
            &[0.0, 0.0, 9.81, 0.0, 0.0, 0.0],
            1e-9
        ));
        assert!(close(&r.f_ext, &[0.0; 6], 1e-9));
        let table = [
            (1.197, 1.550),
            (0.954, 1.229),
            (1.197, 1.550),
            (2.660, 3.427),
        ];
        for (c, (n, t)) in r.contacts.iter().zip(table) {
            assert!((c.normal_force - n).abs() / n < 0.01);
            assert!((c.tangential_force - t).abs() / t < 0.01);
            assert!(c.in_cone);
        }
        assert_eq!(r.grasp_rank, 6);
        assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    }

    #[test]
    fn pushing_one_and_a_half_times_harder_lifts_the_sphere_at_half_g_and_feeds_back_its_weight() {
        let s = analyse(&GraspSpec::paper_sphere(), 1.0).unwrap();
        let r = analyse(&GraspSpec::paper_sphere(), 1.5).unwrap();
        assert!(close(
            &r.object_force,
            &[0.0, 0.0, 14.715, 0.0, 0.0, 0.0],
            1e-9
        ));
        assert!(close(&r.f_ext, &[0.0, 0.0, 4.905, 0.0, 0.0, 0.0], 1e-9));
        assert!(close(
            &r.object_acceleration,
            &[0.0, 0.0, 4.905, 0.0, 0.0, 0.0],
            1e-9
        ));
        for (a, b) in r.contacts.iter().zip(&s.contacts) {
            assert!(close(&a.feedback, &b.feedback, 1e-9));
            assert!(close(&b.feedback, &b.intensity, 1e-9));
        }
    }

    #[test]
    fn too_little_friction_makes_contacts_slip_and_the_sphere_fall() {
        let mut spec = GraspSpec::paper_sphere();
        spec.mu = 0.5;
        let r = analyse(&spec, 1.0).unwrap();
        assert!(r.contacts.iter().all(|c| !c.in_cone));
        assert!(r.object_acceleration[2] < 0.0);
        assert!(!r.warnings.is_empty());
    }

    #[test]
    fn bad_grasp_files_name_the_field() {
        let mut spec = GraspSpec::paper_sphere();
        spec.mu = -0.1;
        assert!(analyse(&spec, 1.0).unwrap_err().to_string().contains("mu"));
        let mut spec = GraspSpec::paper_sphere();
        spec.object.shape = "torus".into();
        assert!(analyse(&spec, 1.0)
            .unwrap_err()
            .to_string()
            .contains("object.shape"));
        let mut spec = GraspSpec::paper_sphere();
        spec.contacts[2].position[1] = Real::NAN;
        assert!(analyse(&spec, 1.0)
            .unwrap_err()
            .to_string()
            .contains("contacts[2].position"));
        let mut spec = GraspSpec::paper_sphere();
        spec.contacts.clear();
        assert!(analyse(&spec, 1.0)
            .unwrap_err()
            .to_string()
            .contains("contacts"));
        let mut spec = GraspSpec::paper_sphere();
        spec.object.radius = None;
        assert!(analyse(&spec, 1.0)
            .unwrap_err()
            .to_string()
            .contains("object.radius"));
    }

    #[test]
    fn degenerate_grasps_are_reported_not_fatal() {
        let mut spec = GraspSpec::paper_sphere();
        spec.contacts.truncate(1);
        let r = analyse(&spec, 1.0).unwrap();
        assert!(r.warnings.iter().any(|w| w.contains("single contact")));
        assert!(r.object_force.iter().chain(&r.f_ext).all(|v| v.is_finite()));
        let mut spec = GraspSpec::paper_sphere();
        spec.contacts = vec![
            ContactSpec {
                position: [-0.1, 0.0, 0.0],
                normal: None,
            },
            ContactSpec {
                position: [0.1, 0.0, 0.0],
                normal: None,
            },
        ];
        let r = analyse(&spec, 1.0).unwrap();
        assert!(r.warnings.iter().any(|w| w.contains("rank")));
        assert!(r
            .contacts
            .iter()
            .all(|c| c.intensity.iter().all(|v| v.is_finite())));
    }
}
