//! Contacts: detection between fingertip spheres and the object, contact frames, the contact
//! models of the paper's Table 1 (eq. 15-16, 20) and the Coulomb friction model (eq. 17-18).
//!
//! **Contact frame rule.** z is the surface normal pointing *into* the object (a finger that
//! pushes has a positive normal intensity). x is the component of the object-frame axis least
//! aligned with z (ties broken by the lower index x < y < z) that is orthogonal to z,
//! normalised; y = z × x. The rule is deterministic but arbitrary: compare only quantities
//! that do not depend on it (normal component, tangential magnitude).
//!
//! **Intensities** are stored as a 4-vector `(c_x, c_y, c_z, c_τ)`: tangential forces along x
//! and y (N), the normal force along z (N) and the torsional moment about z (N·m). A contact
//! model uses a subset: frictionless `c_z`; point with friction `c_x, c_y, c_z`; soft finger all
//! four. Unused components are zero in every transmitted quantity.
//!
//! **Friction cones** ([`apply_friction`]). Point with friction: the exact, unilateral Coulomb
//! cone `‖c_t‖ ≤ μ c_z` (eq. 17 as the paper's NOTES correct it). Soft finger: the *elliptic*
//! soft-finger cone, which limits the tangential force and the torsion jointly,
//!
//! ```text
//! ‖c_t‖² / μ² + c_τ² / μ_t² ≤ c_z²,   c_z ≥ 0
//! ```
//!
//! the ellipsoidal approximation of a pad's limit surface (Howe & Cutkosky 1996; Kao &
//! Cutkosky 1992 for soft fingertips), as MuJoCo's elliptic cones write a `condim` 4 contact
//! (friction `(μ, μ, μ_t)`, `μ_t` a length) and GraspIt!'s soft contact linearises it. A pad
//! that carries its whole torsion `μ_t c_z` has no tangential friction left, and the other way
//! round: the box `‖c_t‖ ≤ μ c_z`, `|c_τ| ≤ μ_t c_z` would overstate what it carries by up to
//! √2. With the characteristic length `e = μ_t / μ` ([`Friction::torsion_length`]) it is the
//! second-order cone `‖(c_x, c_y, c_τ / e)‖ ≤ μ c_z`, round in intensities whose torsion is
//! measured in `c_τ / e` (N): the grasp force optimiser and the DFS's `W⁺` weigh the torsion
//! by that same length, so their results do not depend on the unit of length. With `μ = 0` or
//! `μ_t = 0` the ellipse degenerates to the other limit alone.

use crate::math::{Real, RotationMatrix, Vector, Wrench};
use nalgebra::{Matrix3, Vector4};
use serde::{Deserialize, Serialize};

/// Contact wrench intensities `(c_x, c_y, c_z, c_τ)` in the contact frame (N, N, N, N·m).
pub type Intensity = Vector4<Real>;

/// The contact models of Table 1 (MuJoCo's condim 1 / 3 / 4): `frictionless`,
/// `point_with_friction` or `soft_finger` in files, the API and the data base.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Default)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum ContactModel {
    /// One unit wrench: the normal force.
    Frictionless,
    /// Three unit wrenches: two tangential forces and the normal force.
    #[default]
    PointWithFriction,
    /// Four: point with friction plus the torsional moment about the normal.
    SoftFinger,
}

impl crate::names::Named for ContactModel {
    const WHAT: &'static str = "contact model";
    const ALL: &'static [Self] = &[
        ContactModel::Frictionless,
        ContactModel::PointWithFriction,
        ContactModel::SoftFinger,
    ];

    fn name(self) -> &'static str {
        ContactModel::name(self)
    }
}

crate::named_enum!(ContactModel);

impl ContactModel {
    /// Number of unit wrenches `k_i` the model transmits.
    pub fn dim(self) -> usize {
        match self {
            ContactModel::Frictionless => 1,
            ContactModel::PointWithFriction => 3,
            ContactModel::SoftFinger => 4,
        }
    }

    /// Which of the four intensity components the model transmits.
    pub fn mask(self) -> Intensity {
        match self {
            ContactModel::Frictionless => Intensity::new(0.0, 0.0, 1.0, 0.0),
            ContactModel::PointWithFriction => Intensity::new(1.0, 1.0, 1.0, 0.0),
            ContactModel::SoftFinger => Intensity::new(1.0, 1.0, 1.0, 1.0),
        }
    }

    /// The model's intensities as a plain list in Table 1's order (length [`dim`](Self::dim)).
    pub fn components(self, c: &Intensity) -> ([Real; 4], usize) {
        match self {
            ContactModel::Frictionless => ([c[2], 0.0, 0.0, 0.0], 1),
            ContactModel::PointWithFriction => ([c[0], c[1], c[2], 0.0], 3),
            ContactModel::SoftFinger => ([c[0], c[1], c[2], c[3]], 4),
        }
    }

    /// Name as used in files and the API.
    pub fn name(self) -> &'static str {
        match self {
            ContactModel::Frictionless => "frictionless",
            ContactModel::PointWithFriction => "point_with_friction",
            ContactModel::SoftFinger => "soft_finger",
        }
    }
}

/// Coulomb friction parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Friction {
    /// Coulomb coefficient μ (dimensionless), ≥ 0. Default 0.8.
    pub mu: Real,
    /// Torsional coefficient μ_t (m), ≥ 0: the most torsion a soft finger's pad carries per
    /// newton of normal force when it carries no tangential force, `|c_τ| ≤ μ_t c_z`; with a
    /// tangential force too, the elliptic cone of the module documentation. Default 0.005.
    pub mu_torsion: Real,
}

impl Friction {
    /// The soft-finger cone's characteristic length `e = μ_t / μ` (m): the torsion `e f`
    /// costs a pad as much of its friction as the tangential force `f`. `None` when `μ` or
    /// `μ_t` is zero (or not finite), where the cone limits only the other.
    pub fn torsion_length(&self) -> Option<Real> {
        let e = self.mu_torsion / self.mu;
        (self.mu > 0.0 && self.mu_torsion > 0.0 && e.is_finite() && e > 0.0).then_some(e)
    }
}

impl Default for Friction {
    fn default() -> Self {
        Friction {
            mu: 0.8,
            mu_torsion: 0.005,
        }
    }
}

/// The geometry of one contact on the object: point and frame in B.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactFrame {
    /// Contact point in B (m).
    pub p_b: Vector,
    /// Rotation of the contact frame C in B; its columns are the tangents x, y and the inward
    /// normal. A rotation matrix: the DFS applies it a dozen times per contact and tick.
    pub rot_b: RotationMatrix,
}

impl ContactFrame {
    /// A contact at `p_b` with inward normal `z_b` (unit), tangents by the module's rule.
    pub fn from_normal(p_b: Vector, z_b: Vector) -> Self {
        // One division per normalisation, not one per component.
        let z = z_b * (1.0 / z_b.norm());
        let mut k = 0;
        for i in 1..3 {
            if z[i].abs() < z[k].abs() - 1e-12 {
                k = i;
            }
        }
        let mut e = Vector::zeros();
        e[k] = 1.0;
        let x = e - z * z[k];
        let x = x * (1.0 / x.norm());
        let y = z.cross(&x);
        let m = Matrix3::from_columns(&[x, y, z]);
        // m is orthonormal by construction: convert it directly. (An iterative fit such as
        // `from_matrix_eps` started at the identity does not converge for frames far from it:
        // a normal of −z came out as +z.)
        let rot_b = RotationMatrix::from_matrix_unchecked(m);
        ContactFrame { p_b, rot_b }
    }

    /// Inward normal in B.
    pub fn normal_b(&self) -> Vector {
        self.rot_b * Vector::z()
    }

    /// The pose `V_i⁻¹` of C in B, whose wrench map is `Λ_i`.
    pub fn pose_in_b(&self) -> crate::math::Isometry {
        crate::math::Isometry::from_parts(
            self.p_b.into(),
            crate::math::Rotation::from_rotation_matrix(&self.rot_b),
        )
    }

    /// Wrench in B produced by intensities `c` (the columns of `ᴮW` for this contact, eq. 22).
    #[inline]
    pub fn wrench_b(&self, c: &Intensity) -> Wrench {
        let f = self.rot_b * Vector::new(c[0], c[1], c[2]);
        let m = self.p_b.cross(&f) + self.rot_b * Vector::new(0.0, 0.0, c[3]);
        crate::math::wrench(&f, &m)
    }

    /// Contact-frame intensities of a force (N) expressed in B acting at the contact point.
    #[inline]
    pub fn intensities_of_force_b(&self, f_b: &Vector) -> Intensity {
        let f_c = self.rot_b.transpose() * f_b;
        Intensity::new(f_c.x, f_c.y, f_c.z, 0.0)
    }
}

/// Unit wrenches `ᶜw_ij` of a contact model in the contact frame (Table 1), as the columns of
/// a 6x4 matrix in the `(c_x, c_y, c_z, c_τ)` layout (unused columns zero).
pub fn unit_wrenches_c(model: ContactModel) -> nalgebra::Matrix6x4<Real> {
    let mask = model.mask();
    let mut w = nalgebra::Matrix6x4::zeros();
    w[(0, 0)] = mask[0];
    w[(1, 1)] = mask[1];
    w[(2, 2)] = mask[2];
    w[(5, 3)] = mask[3];
    w
}

/// Split of a contact's intensities by the friction model (eq. 17-18).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrictionSplit {
    /// `c̃`: what acts on the object.
    pub transmitted: Intensity,
    /// `ĉ` plus the rest force `ᶜf̂`: what does not (accelerates the finger).
    pub rest: Intensity,
    /// The requested intensities were outside the cone (the contact slips).
    pub slip: bool,
    /// The normal intensity was not positive: the finger does not push (no contact force).
    pub separating: bool,
}

/// Applies the contact model and the exact, unilateral friction cone to intensities `c`
/// (eq. 15-18): components the model does not transmit go to the rest; `c_z ≤ 0` transmits
/// nothing; a tangential part beyond `μ c_z` is scaled back onto the cone (direction kept) and
/// the excess joins the rest. For the soft finger the tangential force and the torsion are
/// limited jointly by the elliptic cone `‖c_t‖²/μ² + c_τ²/μ_t² ≤ c_z²` (module documentation):
/// beyond it both are scaled back by the same factor onto the cone, the nearest point on it in
/// the metric in which it is round (`c_τ` measured as `c_τ / e`).
#[inline]
pub fn apply_friction(model: ContactModel, friction: &Friction, c: &Intensity) -> FrictionSplit {
    let masked = c.component_mul(&model.mask());
    let mut t = masked;
    let mut slip = false;
    if masked[2] <= 0.0 {
        return FrictionSplit {
            transmitted: Intensity::zeros(),
            rest: *c,
            slip: false,
            separating: true,
        };
    }
    let n = masked[2];
    let tan2 = masked[0] * masked[0] + masked[1] * masked[1];
    let mu = friction.mu.max(0.0);
    let mu_t = friction.mu_torsion.max(0.0);
    if model == ContactModel::SoftFinger && mu > 0.0 && mu_t > 0.0 {
        // The elliptic cone: ρ² = ‖c_t‖²/μ² + c_τ²/μ_t² ≤ c_z², compared squared.
        let rho2 = tan2 / (mu * mu) + (masked[3] / mu_t) * (masked[3] / mu_t);
        if rho2 > n * n {
            let s = n / rho2.sqrt();
            t[0] *= s;
            t[1] *= s;
            t[3] *= s;
            slip = true;
        }
    } else {
        // Point with friction, and the soft finger's degenerate cones (μ = 0: torsion only;
        // μ_t = 0: tangential force only), where the ellipse is the two limits apart.
        let limit = mu * n;
        // Compared squared (both sides are ≥ 0): the square root only for a contact that slips.
        if tan2 > limit * limit {
            let tan = tan2.sqrt();
            let s = if tan > 0.0 { limit / tan } else { 0.0 };
            t[0] *= s;
            t[1] *= s;
            slip = true;
        }
        let tl = mu_t * n;
        if t[3].abs() > tl {
            t[3] = t[3].signum() * tl;
            slip = true;
        }
    }
    FrictionSplit {
        transmitted: t,
        rest: c - t,
        slip,
        separating: false,
    }
}

/// How much of its friction cone intensities `c` use: 0 for a pure normal force, 1 on the
/// cone, above 1 outside it. `‖c_t‖ / (μ c_z)` for a point contact (and a soft finger whose
/// cone is degenerate), `sqrt(‖c_t‖²/μ² + c_τ²/μ_t²) / c_z` for the soft finger's elliptic
/// cone; 0 for the frictionless model. Components the model does not transmit are ignored; a
/// force that does not push (`c_z ≤ 0`) with any load on the cone, or a load the cone cannot
/// carry at all (`μ = 0`), uses it infinitely.
pub fn cone_usage(model: ContactModel, friction: &Friction, c: &Intensity) -> Real {
    let m = c.component_mul(&model.mask());
    let tan = (m[0] * m[0] + m[1] * m[1]).sqrt();
    let (mu, mu_t) = (friction.mu.max(0.0), friction.mu_torsion.max(0.0));
    let share = |load: Real, coefficient: Real| {
        if load == 0.0 {
            0.0
        } else if coefficient > 0.0 {
            load / coefficient
        } else {
            Real::INFINITY
        }
    };
    let (a, b) = (share(tan, mu), share(m[3].abs(), mu_t));
    let rho = if model == ContactModel::SoftFinger && friction.torsion_length().is_some() {
        a.hypot(b)
    } else {
        a.max(b)
    };
    if rho == 0.0 {
        0.0
    } else if m[2] > 0.0 {
        rho / m[2]
    } else {
        Real::INFINITY
    }
}

/// True when `c` is inside the model's cone (with a relative tolerance for rounding).
pub fn in_cone(model: ContactModel, friction: &Friction, c: &Intensity) -> bool {
    let s = apply_friction(model, friction, c);
    let scale = 1e-9 * (1.0 + c.norm());
    !s.separating && (s.transmitted - c.component_mul(&model.mask())).norm() <= scale
}

/// Normal force (N) and tangential magnitude (N) of intensities.
pub fn normal_and_tangential(c: &Intensity) -> (Real, Real) {
    (c[2], (c[0] * c[0] + c[1] * c[1]).sqrt())
}

/// A detected contact between a fingertip sphere and the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Contact geometry on the object surface, in B.
    pub frame: ContactFrame,
    /// Penetration depth (m): positive when the tip overlaps the object, negative for a gap.
    pub penetration: Real,
}

/// Detects a contact between a fingertip sphere (centre `centre_b` in B, radius `radius`) and
/// the object's shape. Returns the closest surface point with its frame when the gap is at most
/// `margin` (m); `None` otherwise.
pub fn detect(
    shape: &crate::object::Shape,
    centre_b: &Vector,
    radius: Real,
    margin: Real,
) -> Option<Detection> {
    let closest = shape.closest(centre_b);
    let gap = closest.distance - radius;
    if gap > margin {
        return None;
    }
    Some(Detection {
        frame: ContactFrame::from_normal(closest.point, -closest.normal),
        penetration: -gap,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::Shape;
    use proptest::prelude::*;

    #[test]
    fn contact_models_are_named_as_in_files_and_unknown_ones_are_refused() {
        crate::names::assert_serde_agrees::<ContactModel>();
        let e = serde_json::from_str::<ContactModel>("\"sticky\"").unwrap_err();
        assert!(
            e.to_string().contains(
                "unknown contact model \"sticky\"; expected one of frictionless, \
                 point_with_friction, soft_finger"
            ),
            "{e}"
        );
        assert_eq!(
            "soft_finger".parse::<ContactModel>(),
            Ok(ContactModel::SoftFinger)
        );
    }

    fn f() -> Friction {
        Friction {
            mu: 0.5,
            mu_torsion: 0.01,
        }
    }

    #[test]
    fn contact_frames_are_right_handed_with_z_into_the_object() {
        let s = Shape::Sphere { radius: 0.1 };
        let d = detect(&s, &Vector::new(0.0, 0.0, -0.11), 0.01, 1e-3).unwrap();
        assert!((d.frame.normal_b() - Vector::z()).norm() < 1e-12);
        let m = d.frame.rot_b.into_inner();
        assert!((m.determinant() - 1.0).abs() < 1e-12);
        assert!(d.penetration.abs() < 1e-12);
        assert!(detect(&s, &Vector::new(0.0, 0.0, -0.2), 0.01, 1e-3).is_none());
    }

    #[test]
    fn contact_frames_have_exactly_the_requested_normal_for_every_direction() {
        let dirs = [
            Vector::x(),
            -Vector::x(),
            Vector::y(),
            -Vector::y(),
            Vector::z(),
            -Vector::z(),
            Vector::new(-0.5, -0.5, 0.6),
        ];
        for n in dirs {
            let fr = ContactFrame::from_normal(Vector::zeros(), n);
            assert!(
                (fr.normal_b() - n.normalize()).norm() < 1e-12,
                "{n:?} -> {:?}",
                fr.normal_b()
            );
            let m = fr.rot_b.into_inner();
            assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-12);
            assert!((m.determinant() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn a_pulling_finger_transmits_nothing() {
        let s = apply_friction(
            ContactModel::PointWithFriction,
            &f(),
            &Intensity::new(0.1, 0.0, -1.0, 0.0),
        );
        assert!(s.separating);
        assert_eq!(s.transmitted, Intensity::zeros());
    }

    #[test]
    fn frictionless_contacts_pass_only_the_normal() {
        let s = apply_friction(
            ContactModel::Frictionless,
            &f(),
            &Intensity::new(0.3, 0.2, 1.0, 0.1),
        );
        assert_eq!(s.transmitted, Intensity::new(0.0, 0.0, 1.0, 0.0));
        assert_eq!(s.rest, Intensity::new(0.3, 0.2, 0.0, 0.1));
        assert!(!s.slip);
    }

    #[test]
    fn a_soft_pad_cannot_carry_its_whole_tangential_friction_and_torsion_at_once() {
        // The corner of the old box, ‖c_t‖ = μ c_z and |c_τ| = μ_t c_z: outside the elliptic
        // cone by √2, scaled back onto it with its direction in (c_t/μ, c_τ/μ_t) kept.
        let (n, fr) = (2.0, f());
        let c = Intensity::new(fr.mu * n * 0.6, fr.mu * n * 0.8, n, -fr.mu_torsion * n);
        let s = apply_friction(ContactModel::SoftFinger, &fr, &c);
        assert!(s.slip && !s.separating);
        let k = 1.0 / 2.0_f64.sqrt();
        let expected = Intensity::new(c[0] * k, c[1] * k, n, c[3] * k);
        assert!(
            (s.transmitted - expected).norm() < 1e-12,
            "{:?}",
            s.transmitted
        );
        let (_, t) = normal_and_tangential(&s.transmitted);
        let rho2 = (t / fr.mu).powi(2) + (s.transmitted[3] / fr.mu_torsion).powi(2);
        assert!((rho2 - n * n).abs() < 1e-9);
        // Inside the ellipse (a share of 0.6² + 0.7² = 0.85 of it): all of it transmitted.
        let c = Intensity::new(0.0, fr.mu * n * 0.6, n, fr.mu_torsion * n * 0.7);
        let s = apply_friction(ContactModel::SoftFinger, &fr, &c);
        assert!(!s.slip);
        assert_eq!(s.transmitted, c);
        // A point contact transmits no torsion and keeps the plain Coulomb cone.
        let c = Intensity::new(fr.mu * n, 0.0, n, fr.mu_torsion * n);
        let s = apply_friction(ContactModel::PointWithFriction, &fr, &c);
        assert!(!s.slip);
        assert_eq!(s.transmitted, Intensity::new(fr.mu * n, 0.0, n, 0.0));
    }

    #[test]
    fn the_cone_usage_is_one_on_the_cone_for_every_model() {
        let fr = f();
        let n = 2.0;
        // Friction loads ten times what the cone carries, scaled back onto it.
        for (model, c) in [
            (
                ContactModel::PointWithFriction,
                Intensity::new(0.0, 1.0, n, 0.0),
            ),
            (
                ContactModel::PointWithFriction,
                Intensity::new(0.6, -0.8, n, 0.05),
            ),
            (ContactModel::SoftFinger, Intensity::new(0.0, 1.0, n, 0.02)),
            (
                ContactModel::SoftFinger,
                Intensity::new(0.6, -0.8, n, -0.05),
            ),
            (ContactModel::SoftFinger, Intensity::new(0.0, 0.0, n, 0.3)),
        ] {
            let load = Intensity::new(10.0 * c[0], 10.0 * c[1], n, 10.0 * c[3]);
            let on = apply_friction(model, &fr, &load).transmitted;
            let u = cone_usage(model, &fr, &on);
            assert!((u - 1.0).abs() < 1e-12, "{model:?} {c:?}: {u}");
        }
        let c = Intensity::new(0.3, 0.0, 2.0, 0.01);
        let soft = cone_usage(ContactModel::SoftFinger, &fr, &c);
        assert!((soft - (0.6_f64.powi(2) + 1.0).sqrt() / 2.0).abs() < 1e-12);
        assert_eq!(cone_usage(ContactModel::PointWithFriction, &fr, &c), 0.3);
        assert_eq!(cone_usage(ContactModel::Frictionless, &fr, &c), 0.0);
        assert_eq!(
            cone_usage(
                ContactModel::PointWithFriction,
                &fr,
                &Intensity::new(0.1, 0.0, 0.0, 0.0)
            ),
            Real::INFINITY
        );
    }

    #[test]
    fn the_soft_finger_cone_without_friction_or_torsion_limits_only_the_other() {
        let c = Intensity::new(0.3, 0.4, 1.0, 0.02);
        let no_torsion = Friction {
            mu: 0.8,
            mu_torsion: 0.0,
        };
        assert_eq!(no_torsion.torsion_length(), None);
        let s = apply_friction(ContactModel::SoftFinger, &no_torsion, &c);
        assert_eq!(s.transmitted, Intensity::new(0.3, 0.4, 1.0, 0.0));
        let no_friction = Friction {
            mu: 0.0,
            mu_torsion: 0.01,
        };
        assert_eq!(no_friction.torsion_length(), None);
        let s = apply_friction(ContactModel::SoftFinger, &no_friction, &c);
        assert_eq!(s.transmitted, Intensity::new(0.0, 0.0, 1.0, 0.01));
        assert_eq!(f().torsion_length(), Some(0.01 / 0.5));
    }

    #[test]
    fn soft_finger_torsion_is_limited() {
        let s = apply_friction(
            ContactModel::SoftFinger,
            &f(),
            &Intensity::new(0.0, 0.0, 2.0, 0.5),
        );
        assert!((s.transmitted[3] - 0.02).abs() < 1e-12);
        assert!(s.slip);
    }

    proptest! {
        #[test]
        fn the_friction_split_is_inside_the_cone_and_adds_up(
            c in prop::array::uniform4(-5.0..5.0f64), mu in 0.0..2.0f64, model in 0usize..3
        ) {
            let model = [ContactModel::Frictionless, ContactModel::PointWithFriction, ContactModel::SoftFinger][model];
            let fr = Friction { mu, mu_torsion: 0.01 };
            let c = Intensity::from_row_slice(&c);
            let s = apply_friction(model, &fr, &c);
            prop_assert!((s.transmitted + s.rest - c).norm() < 1e-12);
            let (n, t) = normal_and_tangential(&s.transmitted);
            prop_assert!(n >= 0.0);
            prop_assert!(t <= mu * n + 1e-12);
            prop_assert!(s.transmitted[3].abs() <= 0.01 * n + 1e-12);
            if model == ContactModel::SoftFinger && mu > 0.0 {
                // The elliptic cone, tangential force and torsion together.
                let rho2 = (t / mu).powi(2) + (s.transmitted[3] / 0.01).powi(2);
                prop_assert!(rho2 <= n * n * (1.0 + 1e-12) + 1e-24, "{} > {}", rho2, n * n);
            }
            if !s.separating && !s.slip {
                prop_assert!(in_cone(model, &fr, &c));
            }
        }

        #[test]
        fn intensities_of_a_force_reproduce_it(p in prop::array::uniform3(-1.0..1.0f64), n in prop::array::uniform3(-1.0..1.0f64), fv in prop::array::uniform3(-3.0..3.0f64)) {
            let n = Vector::from(n);
            prop_assume!(n.norm() > 0.1);
            let fr = ContactFrame::from_normal(Vector::from(p), n);
            let force = Vector::from(fv);
            let c = fr.intensities_of_force_b(&force);
            let w = fr.wrench_b(&c);
            prop_assert!((crate::math::force_of(&w) - force).norm() < 1e-9);
            prop_assert!((crate::math::moment_of(&w) - fr.p_b.cross(&force)).norm() < 1e-9);
            let m = fr.rot_b.into_inner();
            prop_assert!((m.determinant() - 1.0).abs() < 1e-9);
        }
    }
}
