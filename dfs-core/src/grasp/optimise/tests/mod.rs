//! Tests of the optimiser through its entry points: balance, cones, margins, least
//! normal forces, infeasible grasps and invalid input; the dual Newton method's own in
//! `newton.rs`.

use super::*;
use crate::contact::normal_and_tangential;
use crate::grasp::GraspMatrix;
use crate::math::{Vector, STANDARD_GRAVITY};
use proptest::prelude::*;

use crate::grasp::tests::{paper_contacts, paper_grasp_in_unit};

mod newton;

fn gravity_load() -> Wrench {
    Wrench::new(0.0, 0.0, STANDARD_GRAVITY, 0.0, 0.0, 0.0)
}

fn fr(mu: Real) -> Friction {
    Friction {
        mu,
        mu_torsion: 0.005,
    }
}

/// Inside the cone of `μ` (and, with `μ_t`, the elliptic soft-finger cone: the old box
/// `‖c_t‖ ≤ μ c_z`, `|c_τ| ≤ μ_t c_z` let a pad carry both at once, √2 too much).
fn inside(c: &Intensity, mu: Real, mu_t: Real, min_normal: Real) -> bool {
    let (n, t) = normal_and_tangential(c);
    let tol = 1e-6 * (1.0 + c.norm());
    let cone = if mu > 0.0 && mu_t > 0.0 {
        ((t / mu).powi(2) + (c[3] / mu_t).powi(2)).sqrt() <= n + tol / mu
    } else {
        t <= mu * n + tol && c[3].abs() <= mu_t * n + tol
    };
    n >= min_normal - tol && cone
}

#[test]
fn a_soft_pad_is_not_given_its_whole_friction_and_torsion_at_once() {
    // Two pads pinching a sphere at its equator against its weight and a twist about the
    // pinch axis: the torsion each pad carries leaves it less tangential friction (the
    // elliptic cone), so they squeeze harder than the weight alone needs, and each sits
    // on its cone.
    let r = 0.04;
    let contacts = [
        ContactFrame::from_normal(Vector::new(-r, 0.0, 0.0), Vector::x()),
        ContactFrame::from_normal(Vector::new(r, 0.0, 0.0), -Vector::x()),
    ];
    let friction = Friction {
        mu: 0.8,
        mu_torsion: 0.005,
    };
    let params = OptimiseParams {
        margin: 0.0,
        min_normal: 0.0,
    };
    let (weight, twist) = (3.0, 0.01);
    let load = Wrench::new(0.0, 0.0, weight, twist, 0.0, 0.0);
    let d = balanced(
        &contacts,
        ContactModel::SoftFinger,
        &friction,
        &load,
        &params,
    );
    // By symmetry each pad carries half the weight and half the twist: the least normal
    // force with (w/2 / μ)² + (m/2 / μ_t)² = c_z².
    let least = ((weight / 2.0 / 0.8).powi(2) + (twist / 2.0 / 0.005).powi(2)).sqrt();
    for c in &d.intensities {
        assert!((c[2] - least).abs() < 1e-4 * least, "{c:?}, least {least}");
        assert!(inside(c, 0.8, 0.005, 0.0), "{c:?}");
    }
    // The box would have let each pad push only max(w/2/μ, m/2/μ_t) = 1.875 N.
    assert!(least > 2.0);
}

/// [`optimise`]'s distribution, asserted to balance `load`.
fn balanced(
    contacts: &[ContactFrame],
    model: ContactModel,
    friction: &Friction,
    load: &Wrench,
    p: &OptimiseParams,
) -> Distribution {
    let d = optimise(contacts, model, friction, load, p).unwrap();
    assert_balances(contacts, model, &d, load);
    d
}

fn assert_balances(
    contacts: &[ContactFrame],
    model: ContactModel,
    d: &Distribution,
    load: &Wrench,
) {
    let f = contacts
        .iter()
        .zip(&d.intensities)
        .fold(Wrench::zeros(), |f, (c, i)| {
            f + c.wrench_b(&i.component_mul(&model.mask()))
        });
    assert!(
        (f - load).norm() < 1e-6 * (1.0 + load.norm()),
        "W c = {f:?}, load {load:?}"
    );
    assert!(d.residual < 1e-6 * (1.0 + load.norm()));
}

#[test]
fn the_paper_sphere_with_high_friction_is_held_inside_the_cones_with_margin() {
    let contacts = paper_contacts();
    let p = OptimiseParams::default();
    let d = balanced(
        &contacts,
        ContactModel::PointWithFriction,
        &fr(1.5),
        &gravity_load(),
        &p,
    );
    for c in &d.intensities {
        assert!(inside(c, 1.5 * 0.9, 0.0, 0.0), "{c:?}");
        assert!(c[2] > 0.0);
    }
    // With μ' = 1.35 ≥ 1.3 the minimum-norm W⁺ distribution of the paper already fits, and it
    // is the least-norm solution of the equality, so the optimiser must return it.
    let g = GraspMatrix::new(&contacts, ContactModel::PointWithFriction, &fr(1.5));
    let mut c0 = [Intensity::zeros(); 4];
    g.distribute(&gravity_load(), &mut c0);
    for (a, b) in d.intensities.iter().zip(&c0) {
        assert!((a - b).norm() < 1e-4, "{a:?} vs W⁺ {b:?}");
    }
}

#[test]
fn the_paper_sphere_with_low_friction_is_held_by_squeezing() {
    // All four contacts sit below the equator, so every inward normal points upward (n_z ≈
    // 0.61) and the normals pass through the centre (no moment). The horizontal parts of the
    // normals of contacts 2 and 4 cancel: equal normal forces of 9.81 / (2 · 0.61) ≈ 8 N on
    // them hold the sphere with no friction at all. So squeezing *does* add upward force
    // here, and a distribution inside any cone (even μ = 0) must exist, although the W⁺
    // distribution is outside the cone (ratio ≈ 1.3 > 0.3).
    let contacts = paper_contacts();
    let g = GraspMatrix::new(&contacts, ContactModel::PointWithFriction, &fr(1.5));
    let mut c0 = [Intensity::zeros(); 4];
    g.distribute(&gravity_load(), &mut c0);
    let (n, t) = normal_and_tangential(&c0[0]);
    assert!((t / n - 1.3).abs() < 0.05, "W⁺ ratio {}", t / n);

    let p = OptimiseParams::default();
    let d = balanced(
        &contacts,
        ContactModel::PointWithFriction,
        &fr(0.3),
        &gravity_load(),
        &p,
    );
    for c in &d.intensities {
        assert!(inside(c, 0.3 * 0.9, 0.0, 0.0), "{c:?}");
    }
    // More internal force than the minimum-norm distribution.
    let total: Real = d.intensities.iter().map(|c| c[2]).sum();
    let total0: Real = c0.iter().map(|c| c[2]).sum();
    assert!(total > total0);

    balanced(
        &contacts,
        ContactModel::Frictionless,
        &fr(0.0),
        &gravity_load(),
        &p,
    );
}

#[test]
fn an_antipodal_pair_on_the_equator_squeezes_enough_to_hold_one_kilogram() {
    let r = 0.05;
    let contacts = [
        ContactFrame::from_normal(Vector::new(r, 0.0, 0.0), -Vector::x()),
        ContactFrame::from_normal(Vector::new(-r, 0.0, 0.0), Vector::x()),
    ];
    let p = OptimiseParams::default();
    let mu = 0.5;
    for model in [ContactModel::PointWithFriction, ContactModel::SoftFinger] {
        let d = balanced(&contacts, model, &fr(mu), &gravity_load(), &p);
        let least = STANDARD_GRAVITY / (2.0 * mu * (1.0 - p.margin));
        for c in &d.intensities {
            assert!(c[2] >= least * (1.0 - 1e-6), "normal {} < {least}", c[2]);
            assert!(
                c[2] <= least * 1.01,
                "normal {} far above the least {least}",
                c[2]
            );
            assert!(inside(c, mu * 0.9, 0.005 * 0.9, 0.0));
        }
    }
}

#[test]
fn a_minimum_normal_force_is_respected() {
    let contacts = paper_contacts();
    let p = OptimiseParams {
        margin: 0.1,
        min_normal: 5.0,
    };
    let d = balanced(
        &contacts,
        ContactModel::SoftFinger,
        &fr(1.0),
        &gravity_load(),
        &p,
    );
    for c in &d.intensities {
        assert!(inside(c, 0.9, 0.0045, 5.0), "{c:?}");
    }
}

#[test]
fn one_contact_cannot_hold_a_load_with_a_moment() {
    let contacts = [ContactFrame::from_normal(
        Vector::new(0.0, 0.0, -0.05),
        Vector::z(),
    )];
    let p = OptimiseParams::default();
    // A moment about the normal: the point contact cannot produce it at all.
    let load = Wrench::new(0.0, 0.0, STANDARD_GRAVITY, 0.0, 0.0, 0.1);
    let e = optimise(
        &contacts,
        ContactModel::PointWithFriction,
        &fr(0.8),
        &load,
        &p,
    )
    .unwrap_err();
    assert_eq!(e.kind, InfeasibleKind::NoDistribution, "{e}");
    // A moment about x needs a tangential force along y of M / 0.05 m: 0.5 N·m needs 10 N,
    // more than μ' c_z = 0.72 · 9.81 N allows: outside the cone.
    let load = Wrench::new(0.0, 0.0, STANDARD_GRAVITY, 0.5, 0.0, 0.0);
    let e = optimise(
        &contacts,
        ContactModel::PointWithFriction,
        &fr(0.8),
        &load,
        &p,
    )
    .unwrap_err();
    assert_eq!(e.kind, InfeasibleKind::NoDistribution, "{e}");
    assert!(e
        .reason
        .contains("no distribution inside the friction cones"));
}

#[test]
fn a_frictionless_antipodal_pair_cannot_hold_a_vertical_load() {
    let contacts = [
        ContactFrame::from_normal(Vector::new(0.05, 0.0, 0.0), -Vector::x()),
        ContactFrame::from_normal(Vector::new(-0.05, 0.0, 0.0), Vector::x()),
    ];
    let e = optimise(
        &contacts,
        ContactModel::Frictionless,
        &fr(0.8),
        &gravity_load(),
        &OptimiseParams::default(),
    )
    .unwrap_err();
    assert_eq!(e.kind, InfeasibleKind::NoDistribution, "{e}");
}

#[test]
fn a_pair_that_would_need_to_pull_is_infeasible() {
    // Both contacts push upward from below... but the load pushes the object *up*: only a
    // pull could balance it.
    let contacts = [
        ContactFrame::from_normal(Vector::new(0.03, 0.0, -0.04), Vector::new(-0.03, 0.0, 0.04)),
        ContactFrame::from_normal(Vector::new(-0.03, 0.0, -0.04), Vector::new(0.03, 0.0, 0.04)),
    ];
    let load = Wrench::new(0.0, 0.0, -STANDARD_GRAVITY, 0.0, 0.0, 0.0);
    let e = optimise(
        &contacts,
        ContactModel::PointWithFriction,
        &fr(0.5),
        &load,
        &OptimiseParams::default(),
    )
    .unwrap_err();
    assert_eq!(e.kind, InfeasibleKind::NoDistribution, "{e}");
}

#[test]
fn invalid_inputs_are_reported_not_solved() {
    let contacts = paper_contacts();
    let l = gravity_load();
    let p = OptimiseParams::default();
    let m = ContactModel::PointWithFriction;
    let bad = |r: Result<Distribution, Infeasible>| {
        assert_eq!(r.unwrap_err().kind, InfeasibleKind::InvalidInput)
    };
    bad(optimise(&[], m, &fr(1.0), &l, &p));
    bad(optimise(&contacts, m, &fr(-0.1), &l, &p));
    bad(optimise(&contacts, m, &fr(Real::NAN), &l, &p));
    bad(optimise(
        &contacts,
        m,
        &fr(1.0),
        &l,
        &OptimiseParams {
            margin: 1.0,
            min_normal: 0.0,
        },
    ));
    bad(optimise(
        &contacts,
        m,
        &fr(1.0),
        &l,
        &OptimiseParams {
            margin: -0.1,
            min_normal: 0.0,
        },
    ));
    bad(optimise(
        &contacts,
        m,
        &fr(1.0),
        &l,
        &OptimiseParams {
            margin: 0.1,
            min_normal: -1.0,
        },
    ));
    bad(optimise(
        &contacts,
        m,
        &fr(1.0),
        &Wrench::new(0.0, 0.0, Real::INFINITY, 0.0, 0.0, 0.0),
        &p,
    ));
}

#[test]
fn the_optimisation_is_deterministic() {
    let contacts = paper_contacts();
    let p = OptimiseParams::default();
    let a = optimise(
        &contacts,
        ContactModel::SoftFinger,
        &fr(0.4),
        &gravity_load(),
        &p,
    )
    .unwrap();
    let b = optimise(
        &contacts,
        ContactModel::SoftFinger,
        &fr(0.4),
        &gravity_load(),
        &p,
    )
    .unwrap();
    assert_eq!(a, b);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn feasible_random_grasps_are_balanced_inside_the_cones(
        pts in prop::collection::vec(prop::array::uniform3(-1.0..1.0f64), 3..7),
        weights in prop::collection::vec(0.5..3.0f64, 7),
        tangents in prop::collection::vec(prop::array::uniform2(-1.0..1.0f64), 7),
        mu in 0.2..1.5f64,
        model in 0usize..2,
    ) {
        // A load that is feasible by construction: the wrench of intensities strictly inside
        // the cones (with the margin) of contacts on a sphere of radius 0.1.
        let model = [ContactModel::PointWithFriction, ContactModel::SoftFinger][model];
        let contacts: Vec<_> = pts.iter().filter(|p| Vector::from(**p).norm() > 0.1)
            .map(|p| { let p = Vector::from(*p).normalize() * 0.1; ContactFrame::from_normal(p, -p / 0.1) }).collect();
        prop_assume!(!contacts.is_empty());
        let f = fr(mu);
        let p = OptimiseParams::default();
        let mut load = Wrench::zeros();
        for (i, c) in contacts.iter().enumerate() {
            let n = weights[i];
            let t = tangents[i];
            let ci = Intensity::new(0.8 * mu * 0.9 * n * t[0] / 1.5, 0.8 * mu * 0.9 * n * t[1] / 1.5, n, 0.5 * 0.005 * 0.9 * n * t[0]);
            load += c.wrench_b(&ci.component_mul(&model.mask()));
        }
        let d = optimise(&contacts, model, &f, &load, &p);
        prop_assert!(d.is_ok(), "{:?}", d);
        let d = d.unwrap();
        let back = contacts.iter().zip(&d.intensities).fold(Wrench::zeros(), |w, (c, i)| w + c.wrench_b(i));
        prop_assert!((back - load).norm() < 1e-6 * (1.0 + load.norm()));
        for c in &d.intensities {
            prop_assert!(inside(c, mu * 0.9, 0.005 * 0.9, 0.0), "{:?}", c);
        }
    }
}
