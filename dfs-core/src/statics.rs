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
//!
//! Bad input. Every number of a grasp file must lie in a physically sensible range (the
//! ranges of [`crate::spec`]; an error names the field and the range): a hand holds objects of
//! 1 mg to 10 t, 0.1 mm to 10 m in half size, under at most 10 g, with μ ≤ 10. Within those
//! ranges every output is finite; a final guard still refuses a result with a NaN or an infinite
//! value ([`DfsError::Overflow`], naming it), and an optimised distribution that does not
//! balance the load is reported infeasible, never as a solution. A contact must lie on the
//! object's surface within [`SURFACE_TOLERANCE`](crate::spec::SURFACE_TOLERANCE) of the
//! object's smallest half size. Forces up to [`FORCE_TOLERANCE`] `· (1 N + ‖L‖)` count as
//! zero: a contact carrying no force lies in its (closed) friction cone and is not reported as
//! pulling.

use crate::contact::{
    apply_friction, normal_and_tangential, ContactFrame, ContactModel, Friction, Intensity,
};
use crate::error::{DfsError, Result};
use crate::grasp::optimise::CHECK_TOLERANCE;
use crate::grasp::optimise::{optimise, OptimiseParams};
use crate::grasp::{GraspMatrix, MAX_CONTACTS};
use crate::math::{force_of, moment_of, wrench, Real, Rotation, Vector, Wrench};
use crate::object::{gravity_wrench_b, RigidObject};
use crate::spec::{check_range, GraspSpec};
use serde::Serialize;

/// Allowed `scale` of [`analyse`]: the operator pushes 0 to 100 times the holding intensities.
pub const SCALE_RANGE: (Real, Real) = (0.0, 100.0);
/// Forces (N) up to `FORCE_TOLERANCE · (1 N + ‖L‖)`, `L` the load the hand carries, count as
/// zero: a contact carrying no force lies in its closed friction cone (at its apex) and is not
/// reported as pulling. 10⁻⁶, the optimiser's own check tolerance
/// ([`crate::grasp::optimise::CHECK_TOLERANCE`]).
pub const FORCE_TOLERANCE: Real = CHECK_TOLERANCE;

/// Whether `c` lies within `tol` (N) of the model's closed friction cone: its distance to the
/// part the cone transmits. A zero force (up to `tol`) lies at the apex, inside.
fn in_closed_cone(model: ContactModel, friction: &Friction, c: &Intensity, tol: Real) -> bool {
    let masked = c.component_mul(&model.mask());
    let t = apply_friction(model, friction, c).transmitted;
    (t - masked).norm() <= tol.max(1e-9 * (1.0 + masked.norm()))
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
    /// Whether the intensities lie inside the (closed) friction cone, within
    /// [`FORCE_TOLERANCE`]: a contact carrying no force is inside.
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
        tol: Real,
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
            in_cone: in_closed_cone(model, friction, c, tol),
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
/// holding intensities (see the module docs). `scale` must lie in [`SCALE_RANGE`].
pub fn analyse(spec: &GraspSpec, scale: Real) -> Result<StaticAnalysis> {
    check_range("scale", scale, SCALE_RANGE, "")?;
    let (object, frames) = spec.resolve()?;
    let friction = spec.friction()?;
    let acc = Wrench::from_row_slice(&spec.object_acceleration);
    analyse_resolved(
        &object,
        &frames,
        spec.contact_model,
        &friction,
        &Vector::from(spec.gravity),
        &acc,
        scale,
    )
}

/// [`analyse`] after validation: the computation, the check that the optimised distribution
/// balances the load and the final guard against non-finite outputs.
fn analyse_resolved(
    object: &RigidObject,
    frames: &[ContactFrame],
    model: ContactModel,
    friction: &Friction,
    gravity: &Vector,
    acc: &Wrench,
    scale: Real,
) -> Result<StaticAnalysis> {
    let friction = *friction;
    let n = frames.len();
    let g = GraspMatrix::new(frames, model, &friction);
    let gravity_b = gravity_wrench_b(object, &Rotation::identity(), gravity);
    let load = object.spatial_inertia_times(acc) - gravity_b;
    let tol = FORCE_TOLERANCE * (1.0 + load.norm());

    let mut c_static = [Intensity::zeros(); MAX_CONTACTS];
    g.distribute(&load, &mut c_static);
    let mut c_h = [Intensity::zeros(); MAX_CONTACTS];
    let mut c_t = [Intensity::zeros(); MAX_CONTACTS];
    let mut warnings = Vec::new();
    for i in 0..n {
        c_h[i] = c_static[i] * scale;
        let split = apply_friction(model, &friction, &c_h[i]);
        c_t[i] = split.transmitted;
        let masked = c_h[i].component_mul(&model.mask());
        if in_closed_cone(model, &friction, &c_h[i], tol) {
            continue;
        }
        let (normal, tangential) = normal_and_tangential(&masked);
        if split.separating && normal < -tol {
            warnings.push(format!(
                "contact {i} would have to pull (normal intensity {} N): it transmits nothing",
                short(normal)
            ));
        } else if split.separating {
            warnings.push(format!(
                "contact {i} would need a tangential force ({} N) with no normal force: it transmits nothing",
                short(tangential)
            ));
        } else {
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
            ContactResult::new(&frames[i], model, &friction, &c_h[i], &c_t[i], &fb, tol)
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
    let (optimised, optimised_reason) = match optimise(frames, model, &friction, &load, &params) {
        Ok(d) => match unbalanced(&g, &d.intensities, &load) {
            Some(reason) => (None, Some(reason)),
            None => {
                let contacts: Vec<ContactResult> = d
                    .intensities
                    .iter()
                    .zip(frames)
                    .map(|(c, f)| ContactResult::new(f, model, &friction, c, c, c, tol))
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
        },
        Err(e) => (None, Some(e.reason)),
    };
    let r = StaticAnalysis {
        contacts,
        object_force: object_force.into(),
        f_ext: f_ext.into(),
        object_acceleration: a.into(),
        grasp_rank: g.rank,
        warnings,
        optimised,
        optimised_reason,
    };
    ensure_finite(&r)?;
    Ok(r)
}

/// A number for a message: four decimals, or four significant digits when it is small.
fn short(v: Real) -> String {
    if v == 0.0 || v.abs() >= 1e-3 {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// Why an optimiser's distribution is no solution: it does not balance `load` (within the
/// optimiser's own check tolerance) or is not finite. `None` when it is one.
fn unbalanced(g: &GraspMatrix, c: &[Intensity], load: &Wrench) -> Option<String> {
    let finite = c.iter().all(|c| c.iter().all(|v| v.is_finite()));
    let residual = if finite {
        (load - g.wrench(c)).norm()
    } else {
        Real::NAN
    };
    if residual <= CHECK_TOLERANCE * (1.0 + load.norm()) {
        None
    } else {
        Some(format!(
            "infeasible: the optimiser's distribution does not balance the load (residual {residual:.3e} N or N·m for a load of {:.3e}): no solution found",
            load.norm()
        ))
    }
}

/// The final guard: every number of the analysis is finite, or an error names the first
/// one that is not.
fn ensure_finite(r: &StaticAnalysis) -> Result<()> {
    fn check(what: impl FnOnce() -> String, values: &[Real]) -> Result<()> {
        if values.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(DfsError::Overflow { what: what() })
        }
    }
    fn contact(prefix: &str, i: usize, c: &ContactResult) -> Result<()> {
        let fields: [(&str, &[Real]); 7] = [
            ("position", &c.position),
            ("normal", &c.normal),
            ("intensity", &c.intensity),
            ("normal_force", &[c.normal_force]),
            ("tangential_force", &[c.tangential_force]),
            ("transmitted", &c.transmitted),
            ("feedback", &c.feedback),
        ];
        for (name, v) in fields {
            check(|| format!("{prefix}contacts[{i}].{name}"), v)?;
        }
        Ok(())
    }
    for (i, c) in r.contacts.iter().enumerate() {
        contact("", i, c)?;
    }
    check(|| "object_force".into(), &r.object_force)?;
    check(|| "f_ext".into(), &r.f_ext)?;
    check(|| "object_acceleration".into(), &r.object_acceleration)?;
    if let Some(o) = &r.optimised {
        for (i, c) in o.contacts.iter().enumerate() {
            contact("optimised.", i, c)?;
        }
        check(
            || "optimised.total_normal_force".into(),
            &[o.total_normal_force, o.margin],
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::Shape;
    use crate::spec::*;

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
        spec.mu = Some(0.5);
        let r = analyse(&spec, 1.0).unwrap();
        assert!(r.contacts.iter().all(|c| !c.in_cone));
        assert!(r.object_acceleration[2] < 0.0);
        assert!(!r.warnings.is_empty());
    }

    #[test]
    fn bad_grasp_files_name_the_field() {
        let mut spec = GraspSpec::paper_sphere();
        spec.mu = Some(-0.1);
        assert!(analyse(&spec, 1.0).unwrap_err().to_string().contains("mu"));
        // An unknown shape or contact model is refused as the file is read.
        let file = |shape: &str, model: &str| {
            format!(
                r#"{{"object": {{"shape": "{shape}", "radius": 0.1, "mass": 1}}, "mu": 1,
                    "contact_model": "{model}", "contacts": [{{"position": [0, 0, -0.1]}}]}}"#
            )
        };
        serde_json::from_str::<GraspSpec>(&file("sphere", "soft_finger")).unwrap();
        let e = serde_json::from_str::<GraspSpec>(&file("torus", "soft_finger")).unwrap_err();
        assert!(e.to_string().contains("unknown shape \"torus\""), "{e}");
        let e = serde_json::from_str::<GraspSpec>(&file("sphere", "sticky")).unwrap_err();
        assert!(
            e.to_string().contains("unknown contact model \"sticky\""),
            "{e}"
        );
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

    fn on_sphere(points: &[[Real; 3]]) -> GraspSpec {
        let mut spec = GraspSpec::paper_sphere();
        spec.contacts = points
            .iter()
            .map(|p| ContactSpec {
                position: *p,
                normal: None,
            })
            .collect();
        spec
    }

    #[test]
    fn numbers_outside_their_ranges_are_refused_naming_the_field_and_the_range() {
        let err = |spec: &GraspSpec, scale: Real| analyse(spec, scale).unwrap_err().to_string();
        let mut spec = GraspSpec::paper_sphere();
        spec.object.mass = 1e300;
        let e = err(&spec, 1.0);
        assert!(
            e.contains("object.mass") && e.contains("10000.0") && e.contains("1e300"),
            "{e}"
        );
        let mut spec = GraspSpec::paper_sphere();
        spec.object.radius = Some(1e-300);
        assert!(err(&spec, 1.0).contains("object.radius"));
        let mut spec = GraspSpec::paper_sphere();
        spec.gravity = [0.0, 0.0, -1e308];
        let e = err(&spec, 1.0);
        assert!(e.contains("gravity") && e.contains("100.0"), "{e}");
        let mut spec = GraspSpec::paper_sphere();
        spec.object_acceleration = [0.0, 0.0, 0.0, 0.0, 1e300, 0.0];
        assert!(err(&spec, 1.0).contains("object_acceleration (angular part)"));
        let mut spec = GraspSpec::paper_sphere();
        spec.contacts[0].position = [1e308; 3];
        let e = err(&spec, 1.0);
        assert!(e.contains("contacts[0].position"), "{e}");
        let mut spec = GraspSpec::paper_sphere();
        spec.mu = Some(1e12);
        assert!(err(&spec, 1.0).contains("mu"));
        let mut spec = GraspSpec::paper_sphere();
        spec.mu_torsion = 5.0;
        assert!(err(&spec, 1.0).contains("mu_torsion"));
        for scale in [1e308, -1.0, Real::NAN] {
            let e = err(&GraspSpec::paper_sphere(), scale);
            assert!(e.contains("scale") && e.contains("100.0"), "{e}");
        }
        // The extremes of the ranges still give finite results.
        let mut spec = GraspSpec::paper_sphere();
        spec.object.mass = MASS_RANGE.1;
        spec.gravity = [0.0, MAX_GRAVITY * 0.6, -MAX_GRAVITY * 0.8];
        spec.object_acceleration = [
            MAX_LINEAR_ACCELERATION,
            0.0,
            0.0,
            0.0,
            0.0,
            MAX_ANGULAR_ACCELERATION,
        ];
        analyse(&spec, SCALE_RANGE.1).unwrap();
    }

    #[test]
    fn an_overflowing_load_is_never_reported_as_a_feasible_distribution_or_as_nan() {
        // Past the grasp file's ranges (what `analyse` now refuses up front): the guards behind
        // them must still hold.
        let spec = GraspSpec::paper_sphere();
        let (_, frames) = spec.resolve().unwrap();
        let friction = spec.friction().unwrap();
        for (mass, g) in [(1e300, -9.81), (1.0, -1e308), (1e150, -9.81)] {
            let object = RigidObject::new(Shape::Sphere { radius: 0.1 }, mass).unwrap();
            let r = analyse_resolved(
                &object,
                &frames,
                ContactModel::PointWithFriction,
                &friction,
                &Vector::new(0.0, 0.0, g),
                &Wrench::zeros(),
                1.0,
            );
            match r {
                Err(e) => assert!(
                    matches!(e, DfsError::Overflow { .. })
                        && e.to_string().contains("not a finite number"),
                    "{e}"
                ),
                Ok(r) => {
                    if let Some(o) = &r.optimised {
                        let total: Real = o.contacts.iter().map(|c| c.normal_force).sum();
                        assert!(total > 0.0, "mass {mass} g {g}: an all-zero distribution");
                    }
                }
            }
        }
    }

    #[test]
    fn the_final_guard_names_the_output_that_is_not_finite() {
        let mut r = analyse(&GraspSpec::paper_sphere(), 1.0).unwrap();
        ensure_finite(&r).unwrap();
        r.contacts[2].feedback[1] = Real::NAN;
        let e = ensure_finite(&r).unwrap_err().to_string();
        assert!(e.contains("contacts[2].feedback"), "{e}");
        r.contacts[2].feedback[1] = 0.0;
        r.optimised.as_mut().unwrap().contacts[1].normal_force = Real::INFINITY;
        let e = ensure_finite(&r).unwrap_err().to_string();
        assert!(e.contains("optimised.contacts[1].normal_force"), "{e}");
    }

    #[test]
    fn a_distribution_that_does_not_balance_the_load_is_no_solution() {
        let spec = GraspSpec::paper_sphere();
        let (_, frames) = spec.resolve().unwrap();
        let g = GraspMatrix::new(
            &frames,
            ContactModel::PointWithFriction,
            &spec.friction().unwrap(),
        );
        let load = Wrench::new(0.0, 0.0, 9.81, 0.0, 0.0, 0.0);
        let zeros = vec![Intensity::zeros(); 4];
        assert!(unbalanced(&g, &zeros, &load)
            .unwrap()
            .contains("does not balance"));
        let mut c = [Intensity::zeros(); MAX_CONTACTS];
        g.distribute(&load, &mut c);
        assert!(unbalanced(&g, &c[..4], &load).is_none());
        c[0][0] = Real::NAN;
        assert!(unbalanced(&g, &c[..4], &load).is_some());
    }

    #[test]
    fn contacts_off_the_surface_are_refused_naming_the_contact_and_its_distance() {
        let spec = on_sphere(&[[0.5, 0.5, 0.5], [0.0, 0.076, -0.059], [0.0, -0.076, -0.059]]);
        let e = analyse(&spec, 1.0).unwrap_err().to_string();
        assert!(
            e.contains("contacts[0].position")
                && e.contains("not on the surface")
                && e.contains("7.6603e-1 m"),
            "{e}"
        );
        let spec = on_sphere(&[[0.0, 0.076, -0.059], [0.0, 0.0, 0.0]]);
        let e = analyse(&spec, 1.0).unwrap_err().to_string();
        assert!(
            e.contains("contacts[1].position") && e.contains("1.0000e-1 m"),
            "{e}"
        );
        // Within 5 % of the radius (the paper's rounded points are 3.8 mm inside): accepted.
        analyse(&on_sphere(&[[0.0, 0.0, -0.1049], [0.0, 0.0, 0.0951]]), 1.0).unwrap();
        assert!(analyse(&on_sphere(&[[0.0, 0.0, -0.1051], [0.0, 0.0, 0.1]]), 1.0).is_err());
        // Boxes and cylinders: on a face, an edge, a cap; inside them the nearest face counts.
        let on = |shape: Shape, points: &[[Real; 3]]| {
            let mut spec = on_sphere(points);
            spec.object = ObjectSpec::from_shape(&shape, 0.5);
            spec
        };
        let mut spec = on(
            Shape::Box {
                half_extents: [0.05, 0.03, 0.04],
            },
            &[[0.05, 0.01, 0.0], [-0.05, 0.03, 0.04], [0.0, 0.0, -0.0395]],
        );
        analyse(&spec, 1.0).unwrap();
        spec.contacts[2].position = [0.0, 0.0, 0.0];
        assert!(analyse(&spec, 1.0)
            .unwrap_err()
            .to_string()
            .contains("contacts[2]"));
        let mut spec = on(
            Shape::Cylinder {
                radius: 0.035,
                half_height: 0.06,
            },
            &[[0.035, 0.0, 0.02], [-0.035, 0.0, 0.02], [0.0, 0.0, 0.06]],
        );
        analyse(&spec, 1.0).unwrap();
        spec.contacts[1].position = [0.0, 0.0, 0.02];
        assert!(analyse(&spec, 1.0)
            .unwrap_err()
            .to_string()
            .contains("contacts[1]"));
    }

    #[test]
    fn a_contact_carrying_no_force_lies_in_its_cone_and_does_not_pull() {
        let mut spec = GraspSpec::paper_sphere();
        spec.gravity = [0.0; 3];
        let r = analyse(&spec, 1.0).unwrap();
        assert!(r.contacts.iter().all(|c| c.in_cone));
        assert!(r.optimised.unwrap().contacts.iter().all(|c| c.in_cone));
        assert!(r.warnings.is_empty(), "{:?}", r.warnings);
        // A frictionless box on six faces: only the bottom carries the weight; the top would
        // have to pull in the minimum-norm distribution.
        let mut spec = on_sphere(&[
            [0.05, 0.0, 0.0],
            [-0.05, 0.0, 0.0],
            [0.0, 0.05, 0.0],
            [0.0, -0.05, 0.0],
            [0.0, 0.0, -0.05],
            [0.0, 0.0, 0.05],
        ]);
        spec.object = ObjectSpec::from_shape(
            &Shape::Box {
                half_extents: [0.05; 3],
            },
            1.0,
        );
        spec.contact_model = ContactModel::Frictionless;
        spec.mu = None;
        let r = analyse(&spec, 1.0).unwrap();
        let in_cone: Vec<bool> = r.contacts.iter().map(|c| c.in_cone).collect();
        assert_eq!(in_cone, [true, true, true, true, true, false]);
        assert!(r
            .warnings
            .iter()
            .any(|w| w.starts_with("contact 5 would have to pull")));
        assert!(
            !r.warnings
                .iter()
                .any(|w| w.contains("contact 0") || w.contains("0.0000 N")),
            "{:?}",
            r.warnings
        );
        assert!(r.optimised.unwrap().contacts.iter().all(|c| c.in_cone));
    }

    #[test]
    fn a_frictionless_grasp_needs_no_mu_and_the_others_do() {
        let mut spec = on_sphere(&[[0.0, 0.0, -0.1], [0.1, 0.0, 0.0]]);
        spec.contact_model = ContactModel::Frictionless;
        spec.mu = None;
        analyse(&spec, 1.0).unwrap();
        let spec: GraspSpec = serde_json::from_str(r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "contact_model": "frictionless", "contacts": [{"position": [0, 0, -0.1]}]}"#).unwrap();
        assert_eq!(spec.mu, None);
        analyse(&spec, 1.0).unwrap();
        for model in [ContactModel::PointWithFriction, ContactModel::SoftFinger] {
            let mut s = spec.clone();
            s.contact_model = model;
            let e = analyse(&s, 1.0).unwrap_err().to_string();
            assert!(e.contains("mu") && e.contains("missing"), "{e}");
        }
    }

    #[test]
    fn a_grasp_file_object_or_contact_must_be_a_json_object() {
        let err = |text: &str| {
            serde_json::from_str::<GraspSpec>(text)
                .unwrap_err()
                .to_string()
        };
        let e = err(
            r#"[{"shape":"sphere","radius":0.1,"mass":1.0},[0,0,-9.81],"point_with_friction",1.5,0.0,[{"position":[0,0,-0.1]}],[0,0,0,0,0,0]]"#,
        );
        assert!(
            e.contains("invalid type: sequence, expected a grasp file: a JSON object"),
            "{e}"
        );
        let e = err("[]");
        assert!(
            e.contains("expected a grasp file") && !e.contains("struct"),
            "{e}"
        );
        let e = err("null");
        assert!(
            e.contains("expected a grasp file") && !e.contains("GraspSpec"),
            "{e}"
        );
        let e = err(
            r#"{"object": ["sphere", 0.1, null, null, 1.0], "mu": 1, "contacts": [{"position": [0, 0, -0.1]}]}"#,
        );
        assert!(e.contains("sequence, expected an object {\"shape\""), "{e}");
        let e = err(
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "mu": 1, "contacts": [[[0, 0, -0.1]]]}"#,
        );
        assert!(e.contains("sequence, expected a contact"), "{e}");
        // Objects still parse, with their defaults and unknown-field checks, and round-trip.
        let spec = GraspSpec::paper_sphere();
        let back: GraspSpec = serde_json::from_str(&serde_json::to_string(&spec).unwrap()).unwrap();
        assert_eq!(back, spec);
        assert!(err(r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1, "colour": 1}, "mu": 1, "contacts": []}"#).contains("unknown field `colour`"));
    }
}
