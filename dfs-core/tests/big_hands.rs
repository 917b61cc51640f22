//! Hands of 20-32 DOFs (five fingers of 4-6 joints with a wrist, as the largest dexterous
//! hands have, and long serial chains) load, plan and replay the built-in scenarios' skills:
//! success or a failure report, never a panic; a hand beyond the capacity is refused when it is
//! loaded, naming the limit; any hand the loader accepts plans without panicking; and planning
//! and replay end with `Cancelled` once their `Stop` is set.

mod common;

use common::*;
use dfs_core::hand::{thumb_of, HandModel, MAX_HAND_DOF};
use dfs_core::replay::{plan, plan_with_stop, run, run_with_stop, ReplayParams, SkillSpec};
use dfs_core::{DfsError, Stop};
use proptest::prelude::*;
use std::sync::{Arc, OnceLock};

/// The skills of three built-in scenarios: a pinch of a sphere, a pinch of a box, a power
/// grasp of a cylinder.
fn skills() -> &'static [(&'static str, SkillSpec)] {
    static SKILLS: OnceLock<Vec<(&'static str, SkillSpec)>> = OnceLock::new();
    SKILLS.get_or_init(|| {
        ["sphere-lift", "box-pinch-lift", "cylinder-power-grasp"]
            .into_iter()
            .map(|name| (name, scenario_skill(name)))
            .collect()
    })
}

fn skill(name: &str) -> &'static SkillSpec {
    &skills()
        .iter()
        .find(|(n, _)| *n == name)
        .expect("a skill of the list")
        .1
}

/// Loads `def`, checks its DOF count, and replays `skill_names` on it: each replay reports
/// (success or a failure with its reason), none panics or errs.
fn replays_on(def: &HandDef, dof: usize, skill_names: &[&str]) {
    let hand = def.model().unwrap_or_else(|e| panic!("{}: {e}", def.name));
    assert_eq!(hand.dof(), dof, "{}", def.name);
    let thumb = def.spec().thumb_index();
    for &name in skill_names {
        let report = run(&hand, thumb, skill(name), &ReplayParams::default())
            .unwrap_or_else(|e| panic!("{} {name}: {e}", def.name));
        assert_eq!(report.hand, def.name);
        assert!(
            report.success || report.failure_reason.is_some(),
            "{} {name}: a failed replay says why",
            def.name
        );
        assert!(report.position_error_max_m.is_finite() && report.peak_torque_ratio <= 1.0 + 1e-9);
    }
}

#[test]
fn a_five_finger_hand_of_20_dofs_replays_the_builtin_skills() {
    let def = five_finger_hand("hand20", 0, [4, 4, 4, 4, 4]);
    replays_on(
        &def,
        20,
        &["sphere-lift", "box-pinch-lift", "cylinder-power-grasp"],
    );
}

/// The Shadow hand's shape: 22 finger joints and a 2-DOF wrist, 24 DOFs; planning added the
/// free base's 3 to them and ran out of its 24-DOF arrays (`range end index 27 out of range
/// for slice of length 24`).
#[test]
fn a_hand_of_24_dofs_with_a_two_dof_wrist_replays_the_builtin_skills() {
    let def = five_finger_hand("hand22+2", 2, [5, 4, 4, 4, 5]);
    replays_on(&def, 24, &["sphere-lift", "cylinder-power-grasp"]);
    let def = five_finger_hand("hand24+2", 2, [5, 5, 4, 5, 5]);
    replays_on(&def, 26, &["sphere-lift", "cylinder-power-grasp"]);
}

/// The box pinch takes these hands through every planning stage, the search of the hand's own
/// closing motion last (its dearest: each finger of several joints has seven closing paths).
#[test]
fn a_hand_of_30_dofs_with_a_wrist_replays_the_builtin_skills() {
    let def = five_finger_hand("hand28+2", 2, [6, 6, 5, 5, 6]);
    replays_on(
        &def,
        30,
        &["sphere-lift", "box-pinch-lift", "cylinder-power-grasp"],
    );
}

#[test]
fn a_hand_of_the_largest_accepted_size_replays_the_builtin_skills() {
    let def = five_finger_hand("hand30+2", 2, [6, 6, 6, 6, 6]);
    replays_on(&def, MAX_HAND_DOF, &["sphere-lift", "cylinder-power-grasp"]);
}

/// A single chain of 24 (and 32) joints with a fingertip halfway and one at its end: both
/// tips lie on one line at mid-range angles, and the base-pose search's rotation from that
/// degenerate grasp axis never returned.
#[test]
fn serial_chain_hands_of_24_and_32_dofs_replay_the_builtin_skills() {
    for n in [24, MAX_HAND_DOF] {
        let def = chain_hand(&format!("chain{n}"), n);
        replays_on(
            &def,
            n,
            &["sphere-lift", "box-pinch-lift", "cylinder-power-grasp"],
        );
    }
}

#[test]
fn a_hand_over_the_capacity_is_refused_at_load_naming_the_limit() {
    for (joints, dof) in [([6, 6, 6, 6, 7], 33), ([8, 8, 8, 8, 8], 42)] {
        let def = five_finger_hand("too-big", 2, joints);
        assert_eq!(def.dof(), dof);
        let err = def.model().unwrap_err();
        assert_eq!(
            err,
            DfsError::invalid(
                "urdf",
                format!(
                    "the hand has {dof} DOFs (independent moving joints); at most 32 are \
                     accepted (the largest dexterous hands have about 30 with their wrist)"
                )
            )
        );
    }
    let err = chain_hand("snake", 40).model().unwrap_err().to_string();
    assert!(
        err.contains("40 DOFs") && err.contains("at most 32"),
        "{err}"
    );
}

#[test]
fn planning_and_replay_end_with_cancelled_once_stopped() {
    let params = ReplayParams::default();
    let hand = five_finger_hand("hand28+2", 2, [6, 6, 5, 5, 6])
        .model()
        .unwrap();
    // Stopped before it starts.
    let stop = Stop::new();
    stop.stop();
    let r = plan_with_stop(&hand, 0, skill("sphere-lift"), &params, &stop);
    assert_eq!(r.unwrap_err(), DfsError::Cancelled);
    // Stopped while it plans: the box pinch searches the hand's closing motion for seconds.
    let stop = Arc::new(Stop::new());
    let setter = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(50));
            stop.stop();
        })
    };
    let r = plan_with_stop(&hand, 0, skill("box-pinch-lift"), &params, &stop);
    setter.join().unwrap();
    assert_eq!(r.unwrap_err(), DfsError::Cancelled);
    // Stopped while it runs: no tick after the one that saw the stop set.
    let glove = HandModel::glove10();
    let stop = Stop::new();
    let mut ticks = 0;
    let thumb = thumb_of(&glove);
    let r = run_with_stop(&glove, thumb, skill("sphere-lift"), &params, &stop, |_| {
        ticks += 1;
        if ticks == 500 {
            stop.stop();
        }
    });
    assert_eq!(r.unwrap_err(), DfsError::Cancelled);
    assert_eq!(ticks, 500);
    // Never stopped, the same replay runs to its end.
    let report = run(&glove, thumb, skill("sphere-lift"), &params).unwrap();
    assert!(report.ticks > 500);
}

/// One joint of a random hand: mostly revolute, some prismatic, continuous or fixed, any axis
/// and origin, some mimicking the joint before them.
fn joint_def() -> impl Strategy<Value = JointDef> {
    let kind = prop_oneof![
        6 => Just("revolute"),
        1 => Just("prismatic"),
        1 => Just("continuous"),
        1 => Just("fixed"),
    ];
    (
        kind,
        prop::array::uniform3(-0.04..0.04f64),
        prop::array::uniform3(-1.5..1.5f64),
        prop::array::uniform3(-1.0..1.0f64),
        (-1.5..0.5f64, 0.05..2.5f64),
        prop::option::weighted(0.15, (0.3..1.5f64, -0.1..0.1f64)),
        0.005..0.05f64,
    )
        .prop_map(|(kind, xyz, rpy, axis, (lower, span), mimic, length)| {
            let scale = if kind == "prismatic" { 0.03 } else { 1.0 };
            JointDef {
                kind,
                xyz: [xyz[0], xyz[1], xyz[2].abs() + 0.01],
                rpy,
                axis,
                lower: lower * scale,
                upper: (lower + span) * scale,
                // Filled in with the name of the joint before it.
                mimic: mimic.map(|(m, o)| (String::new(), m, o)),
                length,
            }
        })
}

/// A random hand: a wrist of 0-3 joints and 1-6 fingers of 1-7 joints (the first the thumb,
/// then index, middle, ...), now and then a second fingertip halfway along a finger.
fn hand_def() -> impl Strategy<Value = HandDef> {
    let names = ["thumb", "index", "middle", "ring", "little", "sixth"];
    (
        prop::collection::vec(joint_def(), 0..=3),
        prop::collection::vec(prop::collection::vec(joint_def(), 1..=7), 1..=6),
        prop::option::weighted(0.2, (0..6usize, 0..7usize)),
    )
        .prop_map(move |(wrist, fingers, extra)| {
            let mut fingers: Vec<(String, Vec<JointDef>)> = fingers
                .into_iter()
                .enumerate()
                .map(|(k, joints)| (names[k].to_owned(), joints))
                .collect();
            for (name, joints) in &mut fingers {
                for i in 0..joints.len() {
                    if let Some((source, _, _)) = &mut joints[i].mimic {
                        if i == 0 {
                            joints[i].mimic = None;
                        } else {
                            *source = finger_joint_name(name, i - 1);
                        }
                    }
                }
            }
            let mut wrist = wrist;
            wrist.iter_mut().for_each(|j| j.mimic = None);
            let extra_tips = match extra {
                Some((f, j)) if f < fingers.len() && fingers.len() < 6 => {
                    vec![("extra".to_owned(), f, j.min(fingers[f].1.len() - 1))]
                }
                _ => Vec::new(),
            };
            HandDef {
                name: "random".to_owned(),
                wrist,
                fingers,
                extra_tips,
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Planning is the part that sizes its arrays by the hand; a replay of what it plans is the
    /// DFS, tested on its own.
    #[test]
    fn every_hand_the_loader_accepts_plans_without_panicking(
        def in hand_def(),
        which in 0..3usize,
    ) {
        let Ok(hand) = def.model() else {
            // Refused with an error: nothing to plan.
            return Ok(());
        };
        let (name, skill) = &skills()[which];
        match plan(&hand, def.spec().thumb_index(), skill, &ReplayParams::default()) {
            Ok(p) => prop_assert!(
                p.q_grasp[..hand.dof()].iter().all(|q| q.is_finite()),
                "{name}"
            ),
            Err(e) => prop_assert!(matches!(e, DfsError::Invalid { .. }), "{name}: {e}"),
        }
    }
}
