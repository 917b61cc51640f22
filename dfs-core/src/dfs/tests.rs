//! The DFS tick's tests: refused samples, free fall, determinism, the contact dampers' limits,
//! unilateral contacts across a gap, and scenes of several objects.

use super::forces::inverse_mass_across;
use super::*;
use crate::contact::Friction;
use crate::fixtures::{glove10_holding_paper_sphere, HeldSphere};
use crate::math::force_of;
use crate::math::Wrench;
use proptest::prelude::*;

fn all_finite(out: &TickOutput) -> bool {
    let s = &out.object;
    out.f_ext_b
        .iter()
        .chain(out.object_force_b.iter())
        .all(|v| v.is_finite())
        && out
            .motor_q
            .iter()
            .chain(out.motor_qd.iter())
            .chain(out.feedback_torque.iter())
            .all(|v| v.is_finite())
        && s.pose
            .translation
            .vector
            .iter()
            .chain(s.linear_velocity.iter())
            .all(|v| v.is_finite())
        && out.tips.iter().all(|t| {
            t.intensity
                .iter()
                .chain(t.feedback.iter())
                .all(|v| v.is_finite())
        })
}

#[test]
fn nan_infinite_and_out_of_range_samples_are_refused_and_change_nothing() {
    let HeldSphere {
        mut dfs,
        q,
        tau,
        base,
    } = glove10_holding_paper_sphere().unwrap();
    let before = *dfs.object_state();
    let cases: Vec<(Vec<f64>, Vec<f64>)> = vec![
        (
            {
                let mut v = q.clone();
                v[3] = f64::NAN;
                v
            },
            tau.clone(),
        ),
        (
            {
                let mut v = q.clone();
                v[0] = f64::INFINITY;
                v
            },
            tau.clone(),
        ),
        (
            {
                let mut v = q.clone();
                v[5] = 10.0;
                v
            },
            tau.clone(),
        ),
        (q.clone(), {
            let mut v = tau.clone();
            v[2] = f64::NAN;
            v
        }),
        (q.clone(), {
            let mut v = tau.clone();
            v[4] = 1e6;
            v
        }),
        (q[..5].to_vec(), tau.clone()),
        (q.clone(), tau[..3].to_vec()),
    ];
    for (qq, tt) in cases {
        assert!(dfs
            .step(&GloveSample {
                q: &qq,
                tau: &tt,
                base
            })
            .is_err());
        assert_eq!(*dfs.object_state(), before);
    }
    let mut bad_base = base;
    bad_base.translation.vector.x = f64::NAN;
    assert!(dfs
        .step(&GloveSample {
            q: &q,
            tau: &tau,
            base: bad_base
        })
        .is_err());
    assert!(all_finite(dfs.output()));
}

#[test]
fn a_diverging_object_update_is_refused_and_no_output_holds_a_nan() {
    let HeldSphere {
        mut dfs,
        q,
        tau,
        base,
    } = glove10_holding_paper_sphere().unwrap();
    // An angular velocity whose gyroscopic term overflows: the update is not finite.
    let mut s = *dfs.object_state();
    s.angular_velocity_b = Vector::new(1e200, -1e200, 1e200);
    dfs.set_object_state(s);
    let sample = GloveSample {
        q: &q,
        tau: &tau,
        base,
    };
    let err = dfs.step(&sample).unwrap_err();
    assert!(matches!(err, DfsError::Diverged { .. }), "{err}");
    assert!(err.to_string().contains("diverged"), "{err}");
    assert_eq!(*dfs.object_state(), s, "the last finite state is kept");
    assert!(all_finite(dfs.output()));
    // A sane state afterwards ticks normally again.
    let HeldSphere { dfs: fresh, .. } = glove10_holding_paper_sphere().unwrap();
    dfs.set_object_state(*fresh.object_state());
    assert!(dfs.step(&sample).is_ok());
}

#[test]
fn with_zero_contacts_the_object_falls_freely() {
    let HeldSphere {
        mut dfs, q, tau, ..
    } = glove10_holding_paper_sphere().unwrap();
    let far = Isometry::translation(0.0, 0.0, -3.0);
    let z0 = dfs.object_state().pose.translation.z;
    for _ in 0..100 {
        let out = dfs
            .step(&GloveSample {
                q: &q,
                tau: &tau,
                base: far,
            })
            .unwrap();
        assert_eq!(out.n_contacts, 0);
    }
    let s = dfs.object_state();
    assert!((s.linear_velocity.z + 9.81 * 0.1).abs() < 1e-9);
    assert!(s.pose.translation.z < z0);
}

#[test]
fn the_same_inputs_give_bit_identical_outputs() {
    let run = || {
        let HeldSphere {
            mut dfs,
            q,
            tau,
            base,
        } = glove10_holding_paper_sphere().unwrap();
        let mut trace = Vec::new();
        for i in 0..200 {
            let mut t = tau.clone();
            t[3] += 0.01 * (i as f64 * 0.1).sin();
            let out = dfs
                .step(&GloveSample {
                    q: &q,
                    tau: &t,
                    base,
                })
                .unwrap();
            trace.extend(out.f_ext_b.iter().map(|v| v.to_bits()));
            trace.extend(out.motor_q.iter().map(|v| v.to_bits()));
        }
        trace
    };
    assert_eq!(run(), run());
}

#[test]
fn the_effective_mass_across_a_contact_counts_the_turn_it_causes() {
    // A solid sphere pushed tangentially at its surface: 1/m + r²/(2/5 m r²) = 3.5/m in
    // every tangent direction.
    let (m, r) = (0.05, 0.04);
    let sphere = RigidObject::new(crate::object::Shape::Sphere { radius: r }, m).unwrap();
    let at = ContactFrame::from_normal(Vector::new(r, 0.0, 0.0), -Vector::x());
    assert!((inverse_mass_across(&sphere, &at) - 3.5 / m).abs() < 1e-9);
    // A box pushed across the normal at the centre of its +x face, (a, 0, 0): a push along
    // y also turns it about z, one along z about y; the easier turn counts.
    let h = Vector::new(0.025, 0.025, 0.04);
    let b = RigidObject::new(
        crate::object::Shape::Box {
            half_extents: [h.x, h.y, h.z],
        },
        0.2,
    )
    .unwrap();
    let at = ContactFrame::from_normal(Vector::new(h.x, 0.0, 0.0), -Vector::x());
    let (iy, iz) = (b.inertia[(1, 1)], b.inertia[(2, 2)]);
    let expected = 1.0 / 0.2 + h.x * h.x / iy.min(iz);
    assert!((inverse_mass_across(&b, &at) - expected).abs() < 1e-9);
}

#[test]
fn a_light_objects_tangential_damping_is_limited_to_what_its_step_can_carry() {
    // The paper sphere (1 kg) keeps the surface damping; the same grasp of a 20 g sphere
    // gets what the explicit step allows for four contacts.
    let HeldSphere {
        dfs: mut heavy,
        q,
        tau,
        base,
    } = glove10_holding_paper_sphere().unwrap();
    let sample = GloveSample {
        q: &q,
        tau: &tau,
        base,
    };
    heavy.step(&sample).unwrap();
    let c = heavy.params().surface_damping;
    let touching: Vec<usize> = (0..heavy.output().n_tips)
        .filter(|&k| heavy.output().tips[k].frame.is_some())
        .collect();
    assert_eq!(touching.len(), 4);
    for &k in &touching {
        assert_eq!(heavy.tips[k].tangential_damping, c);
    }
    let light_object = RigidObject::new(heavy.object().shape, 0.02).unwrap();
    let mut light = Dfs::new(
        heavy.hand().clone(),
        light_object,
        *heavy.object_state(),
        *heavy.params(),
    )
    .unwrap();
    light.step(&sample).unwrap();
    let dt = light.params().dt;
    for &k in &touching {
        let frame = light.output().tips[k].frame.unwrap();
        let limit = STABLE_DAMPING / (inverse_mass_across(&light_object, &frame) * 4.0 * dt);
        assert!(limit < c);
        assert!((light.tips[k].tangential_damping - limit).abs() < 1e-9 * c);
    }
}

#[test]
fn a_fingertip_across_a_gap_pushes_nothing_however_hard_it_is_commanded() {
    // The paper sphere's four fingertips, each commanded to push 30 N (ten times the
    // fixture's squeeze), with the sphere shrunk about its centre so that every fingertip
    // is 0.1 mm or 0.8 mm or more off its surface: within the contact margin (the
    // fixture's 5 mm, or the default 1 mm), detected, and transmitting nothing.
    let HeldSphere { dfs, q, tau, base } = glove10_holding_paper_sphere().unwrap();
    let strong: Vec<Real> = tau.iter().map(|t| 10.0 * t).collect();
    let params = DfsParams {
        torque_range: 100.0,
        ..*dfs.params()
    };
    let radius = match dfs.object().shape {
        crate::object::Shape::Sphere { radius } => radius,
        _ => unreachable!("the fixture holds a sphere"),
    };
    // The fixture's fingertips press 0.1 mm or more into the sphere: shrunk by the deepest
    // of them and the gap, every fingertip is the gap or more off its surface.
    let deepest = dfs.output().tips[..dfs.output().n_tips]
        .iter()
        .filter(|t| t.touching)
        .map(|t| t.penetration)
        .fold(0.0, Real::max);
    let sample = GloveSample {
        q: &q,
        tau: &strong,
        base,
    };
    for gap in [1e-4, 8e-4] {
        for margin in [params.contact_margin, 1e-3] {
            let object = RigidObject::new(
                crate::object::Shape::Sphere {
                    radius: radius - deepest - gap,
                },
                dfs.object().mass,
            )
            .unwrap();
            let p = DfsParams {
                contact_margin: margin,
                ..params
            };
            let mut d = Dfs::new(dfs.hand().clone(), object, *dfs.object_state(), p).unwrap();
            let out = *d.step(&sample).unwrap();
            let touching: Vec<&TipContact> = out.tips[..out.n_tips]
                .iter()
                .filter(|t| t.touching)
                .collect();
            // The deepest fingertip is the gap off, the others further (beyond the default
            // margin, some of them).
            let expected = if margin > 2e-3 { 4 } else { 1 };
            assert!(touching.len() >= expected, "gap {gap}, margin {margin}");
            for t in touching {
                assert!(t.penetration <= -gap + 1e-9, "{}", t.penetration);
                assert!(t.intensity[2] > 10.0, "commanded {}", t.intensity[2]);
                assert!(!t.in_contact && t.transmitted == Intensity::zeros());
                assert_eq!(t.feedback, Intensity::zeros());
            }
            assert_eq!(out.n_contacts, 0);
            assert_eq!(out.object_force_b, Wrench::zeros(), "gap {gap}");
            // The sphere falls freely: the fingertips hold nothing across the gap.
            let f = force_of(&out.f_ext_b);
            assert!(
                (f - d.object().mass * params.gravity).norm() < 1e-9,
                "{f:?}"
            );
            // A glove that follows its motors closes the gap under that push within a few
            // ticks, and then the pads push.
            let mut pushed = false;
            for _ in 0..50 {
                d.set_object_state(*dfs.object_state());
                let q_motor = d.output().motor_q;
                let n = q.len();
                let o = *d
                    .step(&GloveSample {
                        q: &q_motor[..n],
                        tau: &strong,
                        base,
                    })
                    .unwrap();
                for t in o.tips[..o.n_tips].iter().filter(|t| t.touching) {
                    assert!(t.penetration > 0.0 || t.transmitted == Intensity::zeros());
                }
                pushed |= o.n_contacts > 0;
            }
            assert!(pushed, "gap {gap}, margin {margin}");
        }
    }
    // Closed, the same command pushes the sphere.
    let mut closed = Dfs::new(
        dfs.hand().clone(),
        *dfs.object(),
        *dfs.object_state(),
        params,
    )
    .unwrap();
    let out = closed.step(&sample).unwrap();
    assert_eq!(out.n_contacts, 4);
    assert!(force_of(&out.object_force_b).norm() > 50.0);
}

#[test]
fn an_internal_squeeze_is_fed_back_entirely_and_does_not_move_the_object() {
    // Operator intensities that sum to zero wrench (a pure squeeze) give f_ext = gravity
    // only and feedback = the whole squeeze.
    let HeldSphere { dfs, .. } = glove10_holding_paper_sphere().unwrap();
    let out = dfs.output();
    assert_eq!(out.n_contacts, 4);
    for t in out.tips.iter().filter(|t| t.in_contact) {
        let sum = t.reaction + t.feedback;
        assert!((sum - t.transmitted).norm() < 1e-9);
    }
}

/// The paper-sphere fixture's object as one of a scene.
fn paper_sphere(dfs: &Dfs) -> DfsObject {
    DfsObject {
        object: *dfs.object(),
        friction: dfs.params().friction,
        state: *dfs.object_state(),
    }
}

fn ball_at(x: Real, y: Real, z: Real, radius: Real) -> DfsObject {
    DfsObject {
        object: RigidObject::new(crate::object::Shape::Sphere { radius }, 0.2).unwrap(),
        friction: Friction {
            mu: 0.5,
            mu_torsion: 0.0,
        },
        state: ObjectState::at_rest(Isometry::translation(x, y, z)),
    }
}

fn bits(o: &ObjectOutput) -> Vec<u64> {
    let s = &o.state;
    s.pose
        .translation
        .vector
        .iter()
        .chain(s.pose.rotation.coords.iter())
        .chain(s.linear_velocity.iter())
        .chain(s.angular_velocity_b.iter())
        .chain(o.f_ext_b.iter())
        .chain(o.object_force_b.iter())
        .map(|v| v.to_bits())
        .collect()
}

fn tip_bits(out: &TickOutput) -> Vec<u64> {
    out.tips[..out.n_tips]
        .iter()
        .flat_map(|t| {
            t.intensity
                .iter()
                .chain(t.transmitted.iter())
                .chain(t.reaction.iter())
                .chain(t.feedback.iter())
                .copied()
                .collect::<Vec<_>>()
        })
        .chain(out.motor_q.iter().copied())
        .chain(out.feedback_torque.iter().copied())
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn an_object_among_others_moves_and_feels_bit_for_bit_as_it_does_alone() {
    let HeldSphere {
        dfs: mut alone,
        q,
        tau,
        base,
    } = glove10_holding_paper_sphere().unwrap();
    // The sphere is object 1 here; two balls far off fall on their own.
    let objects = [
        ball_at(2.0, 0.0, 0.0, 0.03),
        paper_sphere(&alone),
        ball_at(-2.0, 1.0, 0.0, 0.05),
    ];
    let mut scene = Dfs::with_objects(alone.hand().clone(), &objects, *alone.params()).unwrap();
    assert_eq!(scene.n_objects(), 3);
    // Set up as the fixture set up the sphere alone: one tick, then back at rest.
    scene
        .step(&GloveSample {
            q: &q,
            tau: &tau,
            base,
        })
        .unwrap();
    for (i, o) in objects.iter().enumerate() {
        scene.set_object_state_at(i, o.state).unwrap();
    }
    for i in 0..300 {
        let mut t = tau.clone();
        t[3] += 0.02 * (i as f64 * 0.1).sin();
        let sample = GloveSample {
            q: &q,
            tau: &t,
            base,
        };
        let a = *alone.step(&sample).unwrap();
        let b = *scene.step(&sample).unwrap();
        assert_eq!(bits(&a.objects[0]), bits(&b.objects[1]), "tick {i}");
        assert_eq!(tip_bits(&a), tip_bits(&b), "tick {i}");
        assert_eq!(a.n_contacts, b.n_contacts);
        assert_eq!(b.objects[1].n_contacts, b.n_contacts);
        assert_eq!((b.objects[0].n_contacts, b.objects[2].n_contacts), (0, 0));
        for tip in b.tips[..b.n_tips].iter().filter(|t| t.touching) {
            assert_eq!(tip.object, 1);
        }
        assert_eq!(b.overlap, None);
    }
    // The balls fell freely, each from where it was.
    let dz = -9.81 * 1e-6 * 300.0 * 301.0 / 2.0;
    for i in [0, 2] {
        let s = scene.objects()[i].state;
        let z0 = objects[i].state.pose.translation.z;
        assert!((s.pose.translation.z - z0 - dz).abs() < 1e-9, "{i}");
    }
    // The legacy fields are object 0's.
    assert_eq!(scene.output().object, scene.output().objects[0].state);
    assert_eq!(*scene.object_state(), scene.objects()[0].state);
}

#[test]
fn a_fingertip_touching_two_objects_contacts_the_one_it_penetrates_deepest() {
    let HeldSphere { dfs, q, tau, base } = glove10_holding_paper_sphere().unwrap();
    let out = *dfs.output();
    let hand = dfs.hand().clone();
    let thumb = hand
        .fingertips
        .iter()
        .position(|t| t.name == "thumb")
        .unwrap();
    let index = hand
        .fingertips
        .iter()
        .position(|t| t.name == "index")
        .unwrap();
    assert!(!out.tips[thumb].touching && out.tips[index].touching);
    // A ball touching the free thumb, and one pressed into the index fingertip deeper than
    // the paper sphere is.
    let ball_on = |k: usize, gap: Real, r: Real| {
        let c = out.tip_centres[k].coords;
        let away = (c - dfs.object_state().pose.translation.vector).normalize();
        let p = c + away * (hand.fingertips[k].radius + r + gap);
        ball_at(p.x, p.y, p.z, r)
    };
    let deep = out.tips[index].penetration + 0.002;
    let objects = [
        paper_sphere(&dfs),
        ball_on(thumb, -0.0005, 0.02),
        ball_on(index, -deep, 0.01),
    ];
    let mut scene = Dfs::with_objects(hand, &objects, *dfs.params()).unwrap();
    let o = *scene
        .step(&GloveSample {
            q: &q,
            tau: &tau,
            base,
        })
        .unwrap();
    assert!(o.tips[thumb].touching && o.tips[thumb].object == 1);
    assert!(o.tips[index].touching && o.tips[index].object == 2);
    assert!((o.tips[index].penetration - deep).abs() < 1e-9);
    // The index fingertip pushes towards the paper sphere, away from the small ball behind
    // it: that contact transmits nothing; the other three push the paper sphere.
    assert!(!o.tips[index].in_contact);
    assert_eq!((o.objects[0].n_contacts, o.objects[2].n_contacts), (3, 0));
    assert_eq!(o.n_contacts, 3);
    assert_eq!(o.objects[2].object_force_b, Wrench::zeros());
    let f = o.objects[0].object_force_b;
    assert!(force_of(&f).norm() > 1.0, "{f:?}");
}

#[test]
fn objects_passing_into_each_other_are_reported_every_tick_and_counted() {
    let HeldSphere { dfs, q, tau, .. } = glove10_holding_paper_sphere().unwrap();
    let far = Isometry::translation(0.0, 0.0, -3.0);
    // Two balls falling side by side, 1 cm into each other, and a third clear of both.
    let objects = [
        ball_at(0.0, 0.0, 1.0, 0.03),
        ball_at(0.5, 0.0, 1.0, 0.03),
        ball_at(0.0, 0.05, 1.0, 0.03),
    ];
    let mut scene = Dfs::with_objects(dfs.hand().clone(), &objects, *dfs.params()).unwrap();
    for _ in 0..10 {
        let o = scene
            .step(&GloveSample {
                q: &q,
                tau: &tau,
                base: far,
            })
            .unwrap();
        assert_eq!((o.overlap, o.n_overlaps), (Some((0, 2)), 1));
        // Neither pushes the other: both fall freely.
        assert_eq!(
            o.objects[0].state.linear_velocity,
            o.objects[2].state.linear_velocity
        );
    }
    assert_eq!(scene.overlap_ticks(), 10);
    // Moved apart, the overlap ends.
    let mut apart = scene.objects()[2].state;
    apart.pose.translation.y = 0.2;
    scene.set_object_state_at(2, apart).unwrap();
    let o = scene
        .step(&GloveSample {
            q: &q,
            tau: &tau,
            base: far,
        })
        .unwrap();
    assert_eq!((o.overlap, o.n_overlaps), (None, 0));
    assert_eq!(scene.overlap_ticks(), 10);
}

#[test]
fn a_bad_scene_is_refused_naming_the_field() {
    let HeldSphere { dfs, .. } = glove10_holding_paper_sphere().unwrap();
    let hand = dfs.hand().clone();
    let p = *dfs.params();
    let e = Dfs::with_objects(hand.clone(), &[], p).unwrap_err();
    assert!(e.to_string().contains("invalid objects"), "{e}");
    let nine = [ball_at(0.0, 0.0, 0.0, 0.01); MAX_OBJECTS + 1];
    let e = Dfs::with_objects(hand.clone(), &nine, p).unwrap_err();
    assert!(e.to_string().contains("9 objects; at most 8"), "{e}");
    Dfs::with_objects(hand.clone(), &nine[..MAX_OBJECTS], p).unwrap();
    let mut bad = [ball_at(0.0, 0.0, 0.0, 0.01), ball_at(1.0, 0.0, 0.0, 0.01)];
    bad[1].friction.mu = f64::NAN;
    let e = Dfs::with_objects(hand.clone(), &bad, p).unwrap_err();
    assert!(e.to_string().contains("objects[1].friction.mu"), "{e}");
    bad[1].friction.mu = 0.5;
    bad[0].state.pose.translation.x = f64::INFINITY;
    let e = Dfs::with_objects(hand.clone(), &bad, p).unwrap_err();
    assert!(e.to_string().contains("objects[0].state"), "{e}");
    bad[0].state.pose.translation.x = 0.0;
    let mut ok = Dfs::with_objects(hand, &bad, p).unwrap();
    let e = ok
        .set_object_state_at(2, ObjectState::at_rest(Isometry::identity()))
        .unwrap_err();
    assert!(e.to_string().contains("no object 2"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn random_samples_never_produce_nan(
        dq in prop::collection::vec(-1.0..1.0f64, 10),
        dt in prop::collection::vec(-3.0..3.0f64, 10),
    ) {
        let HeldSphere { mut dfs, q, base, .. } = glove10_holding_paper_sphere().unwrap();
        let hand = dfs.hand().clone();
        let q: Vec<f64> = q.iter().zip(&dq).enumerate()
            .map(|(i, (a, b))| (a + b).clamp(hand.dof_lower[i], hand.dof_upper[i])).collect();
        let tau: Vec<f64> = dt.iter().enumerate().map(|(i, t)| t.clamp(-hand.torque_limit[i], hand.torque_limit[i])).collect();
        for _ in 0..20 {
            let out = dfs.step(&GloveSample { q: &q, tau: &tau, base }).unwrap();
            prop_assert!(all_finite(out));
        }
    }
}
