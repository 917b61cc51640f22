//! A DFS tick allocates nothing: a counting global allocator around many ticks. Nor does the
//! virtual coupling of a position-only glove or a calibration applied to its samples.

use dfs_core::dfs::GloveSample;
use dfs_core::fixtures::{glove10_holding_paper_sphere, HeldSphere};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};
use std::alloc::System;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// The allocator's counters are process-wide: the two measurements run in one test so no
/// other test thread allocates during them.
#[test]
fn dfs_ticks_allocate_nothing() {
    a_dfs_tick_with_four_contacts_allocates_nothing();
    a_free_falling_object_tick_and_a_refused_sample_allocate_nothing();
    a_coupled_tick_with_a_calibration_allocates_nothing();
    a_tick_of_a_scene_of_several_objects_allocates_nothing();
    ticks_of_objects_on_a_table_allocate_nothing();
    whole_hand_ticks_of_a_power_grasp_allocate_nothing();
}

/// glove10's power grasp of a cylinder with whole-hand contact: the palm, phalanges and
/// fingertips on it, every tick detecting the shapes, their forces and the implicit finger step.
fn whole_hand_ticks_of_a_power_grasp_allocate_nothing() {
    use dfs_core::fixtures::glove10_power_grasp;
    let g = glove10_power_grasp().unwrap();
    let mut dfs = g.dfs.clone();
    let mut glove = g.glove();
    let mut body_contacts = 0;
    let region = Region::new(GLOBAL);
    for t in 0..1000 {
        let grip = 1.0 + 0.2 * (t as f64 * 0.003).sin();
        g.tick(&mut dfs, &mut glove, grip).unwrap();
        body_contacts += dfs.body_contacts().iter().filter(|b| b.in_contact).count();
    }
    let allocations = region.change().allocations;
    assert!(body_contacts >= 1000, "{body_contacts}");
    assert_eq!(allocations, 0, "whole-hand ticks allocated");
}

/// A box, a ball, a standing and a lying cylinder resting on a table, and a box tipping off an
/// edge onto it, the hand far above: the table's support of each (its lowest points, the
/// least-distance solve, friction, rolling resistance) every tick.
fn ticks_of_objects_on_a_table_allocate_nothing() {
    use dfs_core::dfs::{Dfs, DfsObject, DfsParams};
    use dfs_core::math::{Isometry, Rotation, Vector};
    use dfs_core::object::{ObjectState, RigidObject, Shape};
    let HeldSphere { dfs, q, tau, .. } = glove10_holding_paper_sphere().unwrap();
    let on_table = |x: f64, shape: Shape, rotation: Rotation| {
        let z = shape.support_depth(&rotation);
        DfsObject {
            object: RigidObject::new(shape, 0.3).unwrap(),
            friction: dfs.params().friction,
            state: ObjectState::at_rest(Isometry::from_parts(
                Vector::new(x, 0.0, z).into(),
                rotation,
            )),
        }
    };
    let small_box = Shape::Box {
        half_extents: [0.025, 0.025, 0.04],
    };
    let cylinder = Shape::Cylinder {
        radius: 0.035,
        half_height: 0.09,
    };
    let objects = [
        on_table(0.0, small_box, Rotation::identity()),
        on_table(0.2, Shape::Sphere { radius: 0.04 }, Rotation::identity()),
        on_table(0.4, cylinder, Rotation::identity()),
        on_table(
            0.6,
            cylinder,
            Rotation::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0),
        ),
        on_table(0.8, small_box, Rotation::from_euler_angles(0.3, 0.0, 0.0)),
    ];
    let params = DfsParams {
        table_height: Some(0.0),
        ..*dfs.params()
    };
    let mut scene = Dfs::with_objects(dfs.hand().clone(), &objects, params).unwrap();
    let sample = GloveSample {
        q: &q,
        tau: &tau,
        base: Isometry::translation(0.0, 0.0, 2.0),
    };
    scene.step(&sample).unwrap();
    let mut attempts = Vec::new();
    for _ in 0..5 {
        let region = Region::new(GLOBAL);
        let mut carried = 0;
        for t in 0..1000 {
            if t % 100 == 0 {
                // Start over now and then: the tipping box lands again, warm starts are lost.
                for (i, o) in objects.iter().enumerate() {
                    scene.set_object_state_at(i, o.state).unwrap();
                }
            }
            let out = scene.step(&sample).unwrap();
            carried += usize::from(out.objects[2].table_force_b[2] > 0.0);
        }
        let stats = region.change();
        assert_eq!(carried, 1000, "the table carries the standing cylinder");
        if stats.allocations == 0 && stats.reallocations == 0 {
            return;
        }
        attempts.push(stats);
    }
    panic!("ticks of objects on a table allocated in every attempt: {attempts:?}");
}

/// The paper sphere among seven other objects, two of them overlapping (every tick runs the
/// overlap test on them) and one touching the thumb: contacts on two objects, the overlap
/// stage, eight objects' dynamics.
fn a_tick_of_a_scene_of_several_objects_allocates_nothing() {
    use dfs_core::dfs::{Dfs, DfsObject, MAX_OBJECTS};
    use dfs_core::math::{Isometry, Vector};
    use dfs_core::object::{ObjectState, RigidObject, Shape};
    let HeldSphere { dfs, q, tau, base } = glove10_holding_paper_sphere().unwrap();
    let thumb = dfs
        .hand()
        .fingertips
        .iter()
        .position(|t| t.name == "thumb")
        .unwrap();
    let at = |p: Vector, shape: Shape| DfsObject {
        object: RigidObject::new(shape, 0.2).unwrap(),
        friction: dfs.params().friction,
        state: ObjectState::at_rest(Isometry::translation(p.x, p.y, p.z)),
    };
    let c = dfs.output().tip_centres[thumb].coords;
    let away = (c - dfs.object_state().pose.translation.vector).normalize();
    let r = dfs.hand().fingertips[thumb].radius;
    let mut objects = vec![
        DfsObject {
            object: *dfs.object(),
            friction: dfs.params().friction,
            state: *dfs.object_state(),
        },
        at(c + away * (r + 0.0195), Shape::Sphere { radius: 0.02 }),
        at(
            Vector::new(1.0, 0.0, 0.0),
            Shape::Box {
                half_extents: [0.03, 0.03, 0.03],
            },
        ),
        at(
            Vector::new(1.0, 0.04, 0.0),
            Shape::Cylinder {
                radius: 0.02,
                half_height: 0.05,
            },
        ),
    ];
    while objects.len() < MAX_OBJECTS {
        let x = objects.len() as f64;
        objects.push(at(
            Vector::new(-1.0, x, 0.0),
            Shape::Sphere { radius: 0.03 },
        ));
    }
    let mut scene = Dfs::with_objects(dfs.hand().clone(), &objects, *dfs.params()).unwrap();
    let sample = GloveSample {
        q: &q,
        tau: &tau,
        base,
    };
    scene.step(&sample).unwrap();
    let mut attempts = Vec::new();
    for _ in 0..5 {
        let region = Region::new(GLOBAL);
        let (mut contacts, mut overlaps, mut thumb_on_ball) = (0, 0, 0);
        for _ in 0..1000 {
            for (i, o) in objects.iter().enumerate() {
                scene.set_object_state_at(i, o.state).unwrap();
            }
            let out = scene.step(&sample).unwrap();
            contacts += out.objects[0].n_contacts;
            overlaps += usize::from(out.overlap == Some((2, 3)));
            thumb_on_ball += usize::from(out.tips[thumb].touching && out.tips[thumb].object == 1);
        }
        let stats = region.change();
        assert_eq!((contacts, overlaps, thumb_on_ball), (4000, 1000, 1000));
        if stats.allocations == 0 && stats.reallocations == 0 {
            return;
        }
        attempts.push(stats);
    }
    panic!("ticks of a scene allocated in every attempt: {attempts:?}");
}

fn a_dfs_tick_with_four_contacts_allocates_nothing() {
    let HeldSphere {
        mut dfs,
        q,
        tau,
        base,
    } = glove10_holding_paper_sphere().unwrap();
    let start = *dfs.object_state();
    let sample = GloveSample {
        q: &q,
        tau: &tau,
        base,
    };
    // Warm up outside the measured region.
    dfs.step(&sample).unwrap();
    // The counters are process-wide, and the test harness's own threads may allocate now and
    // then (a busy machine makes that likelier): a tick that allocates does so in every one of
    // the 1000 ticks of every attempt, so one clean attempt out of five proves the tick clean.
    let mut attempts = Vec::new();
    for _ in 0..5 {
        let region = Region::new(GLOBAL);
        let mut contacts = 0;
        for _ in 0..1000 {
            dfs.set_object_state(start);
            contacts += dfs.step(&sample).unwrap().n_contacts;
        }
        let stats = region.change();
        assert_eq!(contacts, 4000, "every tick must have the four contacts");
        if stats.allocations == 0 && stats.reallocations == 0 {
            return;
        }
        attempts.push(stats);
    }
    panic!("ticks allocated in every attempt: {attempts:?}");
}

fn a_free_falling_object_tick_and_a_refused_sample_allocate_nothing() {
    let HeldSphere {
        mut dfs,
        q,
        tau,
        base,
    } = glove10_holding_paper_sphere().unwrap();
    let mut bad = q.clone();
    bad[4] = f64::NAN;
    let far = dfs_core::math::Isometry::translation(0.0, 0.0, -5.0);
    let region = Region::new(GLOBAL);
    for _ in 0..100 {
        assert!(dfs
            .step(&GloveSample {
                q: &bad,
                tau: &tau,
                base
            })
            .is_err());
        dfs.step(&GloveSample {
            q: &q,
            tau: &tau,
            base: far,
        })
        .unwrap();
    }
    assert_eq!(region.change().allocations, 0);
}

/// A position-only glove's tick: calibrate the measured angles, the coupling's torques from
/// the last tick's motor state, the DFS step on the motor posture.
fn a_coupled_tick_with_a_calibration_allocates_nothing() {
    use dfs_core::calibration::Calibration;
    use dfs_core::coupling::{CouplingParams, VirtualCoupling};
    let HeldSphere {
        mut dfs,
        q,
        mut tau,
        base,
    } = glove10_holding_paper_sphere().unwrap();
    let coupling =
        VirtualCoupling::for_hand(dfs.hand(), &CouplingParams::default(), dfs.params()).unwrap();
    let calibration: Calibration =
        serde_json::from_str(r#"{"offsets": {"index_pip": 0.01}, "scales": {"index_mcp": 1.01}}"#)
            .unwrap();
    let calibration = calibration.validate(dfs.hand()).unwrap();
    let n = q.len();
    let mut measured = q.clone();
    let mut posture = q.clone();
    dfs.step(&GloveSample {
        q: &q,
        tau: &tau,
        base,
    })
    .unwrap();
    let mut attempts = Vec::new();
    for _ in 0..5 {
        let region = Region::new(GLOBAL);
        for _ in 0..1000 {
            measured.copy_from_slice(&q);
            calibration.apply(&mut measured);
            coupling
                .torques_from(&measured, dfs.output(), &mut tau)
                .unwrap();
            posture.copy_from_slice(&dfs.output().motor_q[..n]);
            dfs.step(&GloveSample {
                q: &posture,
                tau: &tau,
                base,
            })
            .unwrap();
        }
        let stats = region.change();
        if stats.allocations == 0 && stats.reallocations == 0 {
            return;
        }
        attempts.push(stats);
    }
    panic!("coupled ticks allocated in every attempt: {attempts:?}");
}
