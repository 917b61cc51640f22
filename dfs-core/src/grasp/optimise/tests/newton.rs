//! Tests of [`ForceSolver`]'s dual Newton method against Clarabel: the same answers along a
//! lift, for an antipodal pair and in any unit of length, and Clarabel left to answer when a
//! torque limit binds.

use super::*;

/// Loads along a lift: gravity plus accelerations up to 6 m/s² and moments up to 0.05 N·m,
/// deterministic (xorshift).
fn lift_loads(count: usize) -> Vec<Wrench> {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0
    };
    (0..count)
        .map(|_| {
            let m = 0.3;
            Wrench::new(
                m * 6.0 * next(),
                m * 6.0 * next(),
                m * (STANDARD_GRAVITY + 6.0 * next()),
                0.05 * next(),
                0.05 * next(),
                0.05 * next(),
            )
        })
        .collect()
}

#[test]
fn the_dual_newton_distribution_matches_clarabels_for_every_load_along_a_lift() {
    let contacts = paper_contacts();
    let params = OptimiseParams {
        margin: 0.5,
        min_normal: 0.5,
    };
    for model in [ContactModel::PointWithFriction, ContactModel::SoftFinger] {
        let mut solver = ForceSolver::new(&contacts, model, &fr(0.8), &params, None).unwrap();
        let mut fast = vec![Intensity::zeros(); 4];
        let mut reference = vec![Intensity::zeros(); 4];
        let mut solved = 0;
        for load in lift_loads(60) {
            let before = solver.solve_counts();
            let r = solver.solve_into(&load, &mut fast);
            let Ok(residual) = r else {
                // Infeasible for the fast method and Clarabel alike.
                assert!(solver.solve_clarabel(&load, &mut reference).is_err());
                continue;
            };
            assert!(residual <= CHECK_TOLERANCE * (1.0 + load.norm()));
            assert_eq!(solver.solve_counts().0, before.0 + 1, "{model:?} {load:?}");
            solver.solve_clarabel(&load, &mut reference).unwrap();
            let scale = 1.0 + reference.iter().fold(0.0_f64, |a, c| a.max(c.amax()));
            for (f, c) in fast.iter().zip(&reference) {
                assert!((f - c).amax() < 1e-5 * scale, "{model:?}: {f:?} vs {c:?}");
                assert!(inside(f, 0.4, 0.0025, 0.5), "{f:?}");
            }
            let d = Distribution {
                intensities: fast.clone(),
                residual,
            };
            assert_balances(&contacts, model, &d, &load);
            solved += 1;
        }
        assert!(solved >= 30, "{model:?}: {solved} of 60 loads held");
    }
}

#[test]
fn an_antipodal_soft_pair_along_a_lift_is_answered_by_the_dual_newton_method() {
    // A parallel gripper's two pads. Cold, at λ = 0, every normal force sits at its
    // minimum and the squeeze direction is flat in the dual: the Newton step is huge and
    // only a long backtrack finds the kink. (It used to give up there, so every load went
    // to Clarabel.)
    let r = 0.04;
    let contacts = [
        ContactFrame::from_normal(Vector::new(-r, 0.0, 0.0), Vector::x()),
        ContactFrame::from_normal(Vector::new(r, 0.0, 0.0), -Vector::x()),
    ];
    let params = OptimiseParams {
        margin: 0.5,
        min_normal: 0.5,
    };
    let friction = Friction {
        mu: 0.8,
        mu_torsion: 0.005,
    };
    let mut solver = ForceSolver::new(
        &contacts,
        ContactModel::SoftFinger,
        &friction,
        &params,
        None,
    )
    .unwrap();
    let mut fast = vec![Intensity::zeros(); 2];
    let mut reference = vec![Intensity::zeros(); 2];
    let (mut held, mut by_newton) = (0, 0);
    for load in lift_loads(60) {
        let before = solver.solve_counts();
        let Ok(residual) = solver.solve_into(&load, &mut fast) else {
            continue;
        };
        held += 1;
        assert!(residual <= CHECK_TOLERANCE * (1.0 + load.norm()));
        if solver.solve_counts().0 > before.0 {
            by_newton += 1;
            solver.solve_clarabel(&load, &mut reference).unwrap();
            let scale = 1.0 + reference.iter().fold(0.0_f64, |a, c| a.max(c.amax()));
            for (f, c) in fast.iter().zip(&reference) {
                assert!((f - c).amax() < 1e-5 * scale, "{f:?} vs {c:?}");
            }
        }
    }
    assert!(held >= 30, "{held} of 60 loads held");
    assert!(
        by_newton * 10 >= held * 9,
        "Newton answered {by_newton} of {held}"
    );
}

#[test]
fn the_optimised_distribution_does_not_depend_on_the_unit_of_length() {
    // The paper's sphere held by soft fingers against gravity and a twist, in metres and in
    // millimetres (positions, μ_t and moments a thousand times larger): the same forces and
    // a thousand times the torsions, from Clarabel and from the dual Newton method alike.
    let load = Wrench::new(0.3, -0.2, STANDARD_GRAVITY, 0.05, -0.03, 0.04);
    let params = OptimiseParams {
        margin: 0.2,
        min_normal: 0.5,
    };
    let mut answers = Vec::new();
    for s in [1.0, 1000.0] {
        let (contacts, friction, l) = paper_grasp_in_unit(s, 0.6, &load);
        let model = ContactModel::SoftFinger;
        let mut solver = ForceSolver::new(&contacts, model, &friction, &params, None).unwrap();
        let mut fast = vec![Intensity::zeros(); 4];
        let mut reference = vec![Intensity::zeros(); 4];
        solver.solve_into(&l, &mut fast).unwrap();
        assert_eq!(
            solver.solve_counts(),
            (1, 0),
            "the dual Newton method answers"
        );
        solver.solve_clarabel(&l, &mut reference).unwrap();
        for c in fast.iter().chain(&reference) {
            assert!(inside(c, 0.6 * 0.8, 0.005 * s * 0.8, 0.5), "{c:?}");
        }
        answers.push((s, fast, reference));
    }
    let (_, fast_m, clarabel_m) = &answers[0];
    let (s, fast_mm, clarabel_mm) = &answers[1];
    assert!(fast_m.iter().any(|c| c[3].abs() > 1e-4), "{fast_m:?}");
    for (m, mm, tol) in [(fast_m, fast_mm, 1e-7), (clarabel_m, clarabel_mm, 1e-5)] {
        for (a, b) in m.iter().zip(mm.iter()) {
            let back = Intensity::new(b[0], b[1], b[2], b[3] / s);
            assert!(
                (a - back).amax() < tol * (1.0 + a.amax()),
                "{a:?} vs {back:?}"
            );
        }
    }
    for (a, b) in fast_m.iter().zip(clarabel_m.iter()) {
        assert!((a - b).amax() < 1e-5 * (1.0 + b.amax()), "{a:?} vs {b:?}");
    }
}

#[test]
fn a_distribution_that_breaks_a_torque_limit_is_left_to_clarabel() {
    let contacts = paper_contacts();
    let params = OptimiseParams {
        margin: 0.5,
        min_normal: 0.5,
    };
    let model = ContactModel::SoftFinger;
    let load = gravity_load();
    let free = optimise(&contacts, model, &fr(0.8), &load, &params).unwrap();
    // One "joint" that sums the first contact's normal force, limited below what the free
    // optimum uses but above what the grasp can make do with.
    let mut map = DMatrix::zeros(1, 16);
    map[(0, 2)] = 1.0;
    let limits = TorqueLimits {
        map,
        limits: vec![0.9 * free.intensities[0][2]],
    };
    let mut solver = ForceSolver::new(&contacts, model, &fr(0.8), &params, Some(&limits)).unwrap();
    let mut out = vec![Intensity::zeros(); 4];
    solver.solve_into(&load, &mut out).unwrap();
    assert_eq!(solver.solve_counts(), (0, 1));
    assert!(out[0][2] <= limits.limits[0] + 1e-6, "{}", out[0][2]);
}
