//! A replay tick (the hand's controller and the DFS) allocates nothing once the replay is set
//! up: a counting global allocator around many ticks.

use dfs_core::contact::{ContactModel, Friction};
use dfs_core::hand::{builtin_hand, thumb_of};
use dfs_core::math::{Real, Vector};
use dfs_core::object::Shape;
use dfs_core::replay::{Replay, ReplayParams, SkillContact, SkillKeyPose, SkillSpec};
use dfs_core::scenario::Phase;
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};
use std::alloc::System;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// A two-finger pinch of a box, lifted 8 cm and put back.
fn box_pinch() -> SkillSpec {
    let key = |t: Real, z: Real| SkillKeyPose {
        time_s: t,
        position: Vector::new(0.0, 0.0, z),
        rotation: Vector::zeros(),
    };
    SkillSpec {
        shape: Shape::Box {
            half_extents: [0.025, 0.025, 0.04],
        },
        mass: 0.2,
        friction: Friction {
            mu: 0.8,
            mu_torsion: 0.003,
        },
        contact_model: ContactModel::SoftFinger,
        contacts: vec![
            SkillContact {
                finger: "thumb".into(),
                position_b: Vector::new(-0.025, 0.0, 0.0),
                normal_b: Vector::x(),
            },
            SkillContact {
                finger: "index".into(),
                position_b: Vector::new(0.025, 0.0, 0.0),
                normal_b: -Vector::x(),
            },
        ],
        motion: vec![key(0.0, 0.0), key(0.8, 0.0), key(1.8, 0.08), key(2.8, 0.0)],
        phases: vec![
            (Phase::Approach, 0.5),
            (Phase::Grasp, 0.8),
            (Phase::Lift, 1.0),
            (Phase::Place, 1.0),
            (Phase::Release, 0.5),
        ],
        held_until_s: None,
    }
}

/// The allocator's counters are process-wide, so a region can catch the test harness's own
/// threads allocating on a loaded machine; of three regions of 950 ticks each, one must
/// see no allocation (a tick that allocated would show in all three).
#[test]
fn replay_ticks_allocate_nothing() {
    let hand = builtin_hand("gripper").unwrap();
    let skill = box_pinch();
    let mut replay = Replay::new(&hand, thumb_of(&hand), &skill, &ReplayParams::default()).unwrap();
    // Into the held part of the skill before measuring.
    for _ in 0..1350 {
        assert!(replay.step().unwrap());
    }
    let mut fewest = usize::MAX;
    for _ in 0..3 {
        let region = Region::new(GLOBAL);
        for _ in 0..950 {
            assert!(replay.step().unwrap());
        }
        let stats = region.change();
        fewest = fewest.min(stats.allocations + stats.reallocations);
    }
    assert_eq!(fewest, 0);
}
