//! A replay tick (the hand's controller and the DFS) allocates nothing once the replay is set
//! up: a counting global allocator around many ticks.

use dfs_core::contact::{ContactModel, Friction};
use dfs_core::hand::{builtin_hand, thumb_of};
use dfs_core::math::{Real, Vector};
use dfs_core::object::Shape;
use dfs_core::replay::{DrivenReplay, Replay, ReplayParams, SkillContact, SkillKeyPose, SkillSpec};
use dfs_core::scenario::Phase;
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};
use std::alloc::System;
use std::sync::Mutex;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// The tests measure one at a time (the counters are process-wide).
static MEASURING: Mutex<()> = Mutex::new(());

/// Of three regions of `f`, the fewest allocations and reallocations seen.
fn fewest_allocations(mut f: impl FnMut()) -> usize {
    let mut fewest = usize::MAX;
    for _ in 0..3 {
        let region = Region::new(GLOBAL);
        f();
        let stats = region.change();
        fewest = fewest.min(stats.allocations + stats.reallocations);
    }
    fewest
}

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
                part: dfs_core::hand::ContactPart::Fingertip,
                position_b: Vector::new(-0.025, 0.0, 0.0),
                normal_b: Vector::x(),
            },
            SkillContact {
                finger: "index".into(),
                part: dfs_core::hand::ContactPart::Fingertip,
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
    let _one = MEASURING.lock().unwrap_or_else(|e| e.into_inner());
    // Into the held part of the skill before measuring.
    for _ in 0..1350 {
        assert!(replay.step().unwrap());
    }
    let fewest = fewest_allocations(|| {
        for _ in 0..950 {
            assert!(replay.step().unwrap());
        }
    });
    assert_eq!(fewest, 0);
}

/// Nor does a tick of a replay driven by the operator's phases, its phase changes and the
/// state it streams included.
#[test]
fn driven_replay_ticks_allocate_nothing() {
    let hand = builtin_hand("gripper").unwrap();
    let skill = box_pinch();
    let mut replay =
        DrivenReplay::new(&hand, thumb_of(&hand), &skill, &ReplayParams::default()).unwrap();
    let _one = MEASURING.lock().unwrap_or_else(|e| e.into_inner());
    let tick = |replay: &mut DrivenReplay, n: usize| {
        for _ in 0..n {
            assert!(replay.tick().unwrap());
            let s = replay.state();
            assert!(s.tip_normal_forces.iter().all(|f| f.is_finite()));
        }
    };
    replay.set_phase(Phase::Approach, 0.0);
    tick(&mut replay, 500);
    replay.set_phase(Phase::Grasp, 0.5);
    tick(&mut replay, 800);
    replay.set_phase(Phase::Lift, 1.3);
    let mut at: Real = 1.3;
    let fewest = fewest_allocations(|| {
        // The operator lifting longer than the skill (the replay waits at the lift's end),
        // told of a phase the skill lacks.
        at += 0.5;
        replay.set_phase(Phase::Transport, at);
        tick(&mut replay, 600);
    });
    assert_eq!(fewest, 0);
    assert!(replay.set_phase(Phase::Place, at + 0.6));
    let fewest = fewest_allocations(|| tick(&mut replay, 300));
    assert_eq!(fewest, 0);
}
