//! Skill replay on robot hands, end to end: a built-in scenario recorded with glove10,
//! segmented into a skill, retargeted onto a hand and simulated in the DFS.

use dfs_core::replay::{
    DrivenReplay, DrivenStart, FailureReason, ReplayParams, ReplayReport, SkillSpec,
};
use dfs_core::scenario::{Phase, Scenario};
use dfs_core::Stop;
use services::mcap_io::{read_session_file, ReadLimits};
use services::replay::{
    driven_replay, load_builtin_hand, load_hand_from_texts, replay_skill, skill_spec_from_json,
    LoadedHand, ReplaySource, REPLAY_METADATA,
};
use services::segmentation::{segment, SegmentParams, Skill};
use services::session::{
    read_session, record_simulation, TOPIC_JOINT_STATES, TOPIC_SCENE, TOPIC_TF,
};
use services::RecordingError;

/// The first skill of a built-in scenario recorded with glove10 (seed 0).
fn recorded_skill(scenario: &str) -> SkillSpec {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let s = Scenario::builtin(scenario, 0).unwrap();
    record_simulation(&s, None, &path, |_, _| {}).unwrap();
    let session = read_session(&path).unwrap();
    let seg = segment(&session, &SegmentParams::default());
    let json = serde_json::to_value(&seg.skills[0]).unwrap();
    // The JSON reads back into segmentation's own types, unchanged.
    assert_eq!(Skill::from_json(&json).unwrap(), seg.skills[0]);
    assert_eq!(
        serde_json::from_value::<Skill>(json.clone()).unwrap(),
        seg.skills[0]
    );
    skill_spec_from_json(&json, scenario).unwrap()
}

fn replay(hand: &LoadedHand, skill: &SkillSpec) -> ReplayReport {
    replay_skill(
        hand,
        skill,
        &ReplayParams::default(),
        &ReplaySource::default(),
        None,
    )
    .unwrap()
}

/// A failed replay with `reason`, refused by the plan: nothing was simulated.
fn assert_refused_up_front(r: &ReplayReport, reason: FailureReason) {
    assert!(!r.success);
    assert_eq!(r.failure_reason, Some(reason), "{}", r.detail);
    assert_eq!(r.ticks, 0);
}

#[test]
fn a_sphere_lift_recorded_with_glove10_replays_on_allegro_barrett_inspire_and_the_gripper() {
    let skill = recorded_skill("sphere-lift");
    // The glove10 operator holds the sphere through the whole skill now.
    assert!(skill.held_until_s.is_none());
    // Inspire's fingers have one actuated DOF each: its grasp comes from where they close onto
    // the sphere head-on, not from the skill's contacts.
    for name in ["allegro", "barrett", "inspire", "gripper"] {
        let r = replay(&load_builtin_hand(name).unwrap(), &skill);
        assert!(r.success, "{name}: {:?} {}", r.failure_reason, r.detail);
        assert!(r.lift_height_m > 0.07, "{name} lifted {}", r.lift_height_m);
        assert!(
            r.position_error_max_m < 0.02,
            "{name}: {}",
            r.position_error_max_m
        );
        assert!(r.quality.force_closure, "{name}");
    }
}

/// A driven replay of `skill` on `hand`, its clock starting at session time 10 s.
fn start_driven(hand: &LoadedHand, skill: &SkillSpec) -> DrivenStart {
    driven_replay(hand, skill, &ReplayParams::default(), 10.0, Stop::never()).unwrap()
}

/// Drives `replay` by the operator's phases `(phase, seconds in it)` from session time 10 s
/// and ticks it to its end; the report and the object's last reference.
fn drive(replay: &mut DrivenReplay, schedule: &[(Phase, f64)]) -> (ReplayReport, [f64; 3]) {
    let mut now = 10.0;
    'schedule: for &(phase, d) in schedule {
        assert!(replay.set_phase(phase, now), "{phase:?}");
        for _ in 0..(d / 1e-3).round() as usize {
            if !replay.tick().unwrap() {
                assert_eq!(phase, Phase::Retreat, "over early at {now}");
                break 'schedule;
            }
            now += 1e-3;
        }
    }
    while replay.tick().unwrap() {}
    let s = replay.state();
    assert!((s.now_s - now).abs() < 1.0, "{} vs {now}", s.now_s);
    let r = s.tick.reference.translation.vector;
    (replay.report(), [r.x, r.y, r.z])
}

/// In the assistant's `apply` mode the skill follows the operator's phases as they happen: the
/// glove10 sphere lift on allegro, barrett and inspire, driven by the skill's own phases at its
/// own times, holds like the fixed-clock replay; driven by a slower operator (each phase 1.5×,
/// the hold 3×) or a quicker one (0.7×), it still holds the sphere, lifts it and sets it down
/// where the skill did.
#[test]
fn a_recorded_sphere_lift_replays_driven_by_the_operators_phases() {
    let skill = recorded_skill("sphere-lift");
    let last = skill.motion.last().unwrap();
    let end = skill.start_pose() * skill.key_pose(last.time_s);
    for name in ["allegro", "barrett", "inspire"] {
        let hand = load_builtin_hand(name).unwrap();
        let fixed = replay(&hand, &skill);
        assert!(fixed.success, "{name}: {}", fixed.detail);
        let scaled = |f: f64, hold: f64| -> Vec<(Phase, f64)> {
            let k = |p: Phase| if p == Phase::Hold { hold } else { f };
            skill.phases.iter().map(|&(p, d)| (p, d * k(p))).collect()
        };
        for (what, schedule) in [
            ("own", scaled(1.0, 1.0)),
            ("stretched", scaled(1.5, 3.0)),
            ("compressed", scaled(0.7, 0.7)),
        ] {
            let DrivenStart::Running(mut driven) = start_driven(&hand, &skill) else {
                panic!("{name}: refused");
            };
            let (r, reference) = drive(&mut driven, &schedule);
            eprintln!(
                "{name} {what}: {} {:.2} mm (fixed clock {:.2} mm), lifted {:.1} mm",
                r.success,
                r.position_error_max_m * 1e3,
                fixed.position_error_max_m * 1e3,
                r.lift_height_m * 1e3
            );
            assert!(
                r.success,
                "{name} {what}: {:?} {}",
                r.failure_reason, r.detail
            );
            assert!(r.position_error_max_m < 0.02, "{name} {what}");
            assert!(r.lift_height_m > 0.07, "{name} {what}: {}", r.lift_height_m);
            if what == "own" {
                let (a, b) = (fixed.position_error_max_m, r.position_error_max_m);
                assert!((a - b).abs() < 0.005, "{name}: {a} vs {b}");
            }
            let e = (0..3)
                .map(|i| (reference[i] - end.translation.vector[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(e < 1e-9, "{name} {what}: {e}");
        }
    }
}

/// A plan the hand cannot carry out is refused before anything runs, driven or not; a skill
/// whose object is invalid is refused naming it.
#[test]
fn a_driven_replay_is_refused_like_a_replay() {
    let skill = recorded_skill("box-pinch-lift");
    let inspire = load_builtin_hand("inspire").unwrap();
    let DrivenStart::Refused(r) = start_driven(&inspire, &skill) else {
        panic!("inspire cannot pinch the box");
    };
    assert_refused_up_front(&r, FailureReason::Unreachable);
    let mut bad = skill.clone();
    bad.mass = -1.0;
    let err =
        driven_replay(&inspire, &bad, &ReplayParams::default(), 0.0, Stop::never()).unwrap_err();
    assert!(matches!(err, RecordingError::InvalidInput { .. }), "{err}");
    assert!(err.to_string().contains("skill.object"), "{err}");
}

#[test]
fn a_box_pinch_lift_recorded_with_glove10_replays_on_the_gripper_into_an_mcap() {
    let skill = recorded_skill("box-pinch-lift");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("replay.mcap");
    let source = ReplaySource {
        skill_id: Some(7),
        skill_name: "box-pinch-lift".into(),
    };
    let hand = load_builtin_hand("gripper").unwrap();
    let r = replay_skill(&hand, &skill, &ReplayParams::default(), &source, Some(&out)).unwrap();
    assert!(r.success, "{:?} {}", r.failure_reason, r.detail);
    assert!(r.lift_height_m > 0.05);
    let rec = read_session_file(&out, &ReadLimits::default()).unwrap();
    let counts = rec.message_counts();
    for topic in [TOPIC_TF, TOPIC_SCENE, TOPIC_JOINT_STATES] {
        assert!(counts.get(topic).copied().unwrap_or(0) > 0, "{topic}");
    }
    let meta = rec.metadata(REPLAY_METADATA).unwrap();
    assert_eq!(meta["hand"], "gripper");
    assert_eq!(meta["skill_id"], "7");
    let report: serde_json::Value = serde_json::from_str(&meta["report"]).unwrap();
    assert_eq!(report["success"], true);

    // The reference Python reader decodes every message of every topic of the replay from the
    // schemas inside the file (`scripts/test` installs it; without it this check is skipped).
    if let Some(read) =
        crate::common::python_mcap_report(&out, &["mcap", "zstandard", "lz4", "mcap_protobuf"])
    {
        for (topic, n) in &counts {
            assert_eq!(read["decoded"][topic], serde_json::json!(n), "{topic}");
        }
    }

    // It reads like a session, but it is a replay: segmenting or ingesting it would store a
    // skill of shape `unknown` with no parameters. Ingest refuses it, naming what it is.
    let replay = read_session(&out).unwrap();
    assert!(replay.is_replay());
    let err = replay.ensure_grasp_session("replay.mcap").unwrap_err();
    assert!(
        matches!(err, RecordingError::ReplayRecording { .. }),
        "{err}"
    );
    let bytes = std::fs::read(&out).unwrap();
    let err = services::ingest::analyse(&bytes, "replay.mcap").unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("replay.mcap is a replay recording of box-pinch-lift on the hand gripper")
            && text.contains("not a grasp session"),
        "{text}"
    );
}

#[test]
fn a_box_pinch_lift_recorded_with_glove10_replays_on_barrett_with_both_fingers_opposing_the_thumb()
{
    // glove10 pinched the box between the thumb and one finger; Barrett's two fingers are
    // spread over the face opposite the thumb, not onto its edges, where they would touch the
    // side faces and only friction would oppose the thumb (the box turned and slipped).
    let skill = recorded_skill("box-pinch-lift");
    let r = replay(&load_builtin_hand("barrett").unwrap(), &skill);
    assert!(r.success, "{:?} {}", r.failure_reason, r.detail);
    assert!(r.lift_height_m > 0.07, "lifted {}", r.lift_height_m);
    assert!(r.position_error_max_m < 0.02, "{}", r.position_error_max_m);
    let thumb = r.contacts.iter().find(|c| c.finger == "thumb").unwrap();
    for c in r.contacts.iter().filter(|c| c.finger != "thumb") {
        let dot: f64 = (0..3).map(|i| c.normal_b[i] * thumb.normal_b[i]).sum();
        assert!(dot < -0.99, "{} pushes along {:?}", c.finger, c.normal_b);
    }
}

#[test]
fn a_box_pinch_lift_on_inspire_fails_up_front_as_unreachable_rather_than_dropping_the_box() {
    // Inspire's index has one DOF: on the box's face opposite the thumb it pushes ~58° off the
    // normal, outside the friction cone (39° at μ 0.8). Replayed, the box turned over and fell
    // with the thumb at 1.5 times its torque limit; the plan now refuses it, and nothing runs.
    let skill = recorded_skill("box-pinch-lift");
    let r = replay(&load_builtin_hand("inspire").unwrap(), &skill);
    assert_refused_up_front(&r, FailureReason::Unreachable);
    assert!(
        r.detail.contains("outside even the friction cone"),
        "{}",
        r.detail
    );
}

#[test]
fn a_simulated_session_is_a_grasp_session_not_a_replay() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let s = Scenario::builtin("box-pinch-lift", 0).unwrap();
    record_simulation(&s, Some(1.0), &path, |_, _| {}).unwrap();
    let session = read_session(&path).unwrap();
    assert!(!session.is_replay());
    session.ensure_grasp_session("session.mcap").unwrap();
    assert!(services::ingest::analyse(&std::fs::read(&path).unwrap(), "s").is_ok());
}

#[test]
fn a_hand_too_small_to_reach_the_object_fails_with_unreachable() {
    let skill = recorded_skill("sphere-lift");
    // The gripper with a 15 mm stroke per jaw opens to 5 cm: the 8 cm sphere does not fit.
    let urdf = dfs_core::hand::builtin::GRIPPER_URDF.replace("upper=\"0.055\"", "upper=\"0.015\"");
    let spec = serde_json::to_string(&dfs_core::hand::builtin_spec("gripper").unwrap().0).unwrap();
    let small = load_hand_from_texts(&spec, &urdf, "small gripper").unwrap();
    assert_refused_up_front(&replay(&small, &skill), FailureReason::Unreachable);
}

#[test]
fn a_sphere_heavier_than_the_torque_limits_allow_fails_with_torque_limit() {
    let mut skill = recorded_skill("sphere-lift");
    skill.mass *= 20.0; // 6 kg on 0.7 N·m joints
                        // Not even at rest: refused before it runs, not simulated dropping the sphere.
    let r = replay(&load_builtin_hand("allegro").unwrap(), &skill);
    assert_refused_up_front(&r, FailureReason::TorqueLimit);
}

#[test]
fn the_peak_torque_ratio_is_of_the_torque_applied() {
    // Allegro carrying the 0.5 kg cylinder asks more than its 0.7 N·m at a joint: the report
    // said 1.21 "of the limit", a torque no joint applied. The demand is clamped at the limit.
    // The operator's cylinder skill is now a whole-hand power grasp, which replays refuse:
    // its motion with the fingertip grasp the operator used before the wrap (thumb, index and
    // middle, `operator::plan_grasp`).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let s = Scenario::builtin("cylinder-power-grasp", 0).unwrap();
    record_simulation(&s, None, &path, |_, _| {}).unwrap();
    let seg = segment(&read_session(&path).unwrap(), &SegmentParams::default());
    let mut json = serde_json::to_value(&seg.skills[0]).unwrap();
    let (object, _) = s.resolve().unwrap();
    let glove = dfs_core::hand::HandModel::glove10();
    let pose = dfs_core::math::Isometry::translation(0.0, 0.0, 0.09);
    let plan = dfs_core::operator::plan_grasp(
        &glove,
        &object,
        &pose,
        dfs_core::scenario::GraspStyle::Power,
    )
    .unwrap();
    let contacts: Vec<serde_json::Value> = (0..glove.fingertips.len())
        .filter(|&k| plan.tips[k])
        .map(|k| {
            let r = glove.fingertips[k].radius;
            let p = plan.contacts_b[k] - plan.normals_b[k] * r;
            let n = -plan.normals_b[k];
            serde_json::json!({
                "finger": glove.fingertips[k].name,
                "position_b": [p.x, p.y, p.z],
                "normal_b": [n.x, n.y, n.z],
            })
        })
        .collect();
    // (A skill's JSON holds its parameters at the top level.)
    let at = if json.get("contacts").is_some() {
        &mut json
    } else {
        &mut json["parameters"]
    };
    at["contact_count"] = contacts.len().into();
    at["contacts"] = contacts.into();
    let skill = skill_spec_from_json(&json, "fingertips.json").unwrap();
    let r = replay(&load_builtin_hand("allegro").unwrap(), &skill);
    assert!(r.ticks > 0, "{}", r.detail);
    assert!(
        r.peak_torque_ratio > 0.5 && r.peak_torque_ratio <= 1.0,
        "{}",
        r.peak_torque_ratio
    );
}

/// The operator's power grasp is held by the palm and the phalanges too. A robot hand with palm
/// contact geometry (its URDF's collision elements) replays it as a power grasp: the palm on
/// the skill's palm contact, the fingers wrapped, and the recorded replay shows the palm
/// pressing the cylinder through the lift. A hand without palm geometry refuses it, naming the
/// palm contact.
#[test]
fn a_power_grasp_replays_with_the_palm_on_allegro_and_barrett() {
    use dfs_core::hand::ContactPart;
    let skill = recorded_skill("cylinder-power-grasp");
    assert!(skill.contacts.iter().any(|c| c.part == ContactPart::Palm));
    let dir = tempfile::tempdir().unwrap();
    for name in ["allegro", "barrett"] {
        let hand = load_builtin_hand(name).unwrap();
        let out = dir.path().join(format!("{name}.mcap"));
        let r = replay_skill(
            &hand,
            &skill,
            &ReplayParams::default(),
            &ReplaySource::default(),
            Some(&out),
        )
        .unwrap();
        assert!(r.success, "{name}: {:?} {}", r.failure_reason, r.detail);
        assert!(r.lift_height_m > 0.07, "{name} lifted {}", r.lift_height_m);
        assert!(r.position_error_max_m < 0.02, "{name}");
        // The report's contacts are the wrap's: the palm's first, then the fingers'.
        let model = hand.model_for(&skill).unwrap();
        let palm_names: Vec<&str> = model
            .contact_shapes
            .iter()
            .filter(|s| s.part == dfs_core::hand::BodyPart::Palm)
            .map(|s| s.name.as_str())
            .collect();
        assert!(
            palm_names.contains(&r.contacts[0].finger.as_str()),
            "{name}"
        );
        assert!(r.contacts.len() >= 3, "{name}: {:?}", r.contacts);
        // In the recording, the palm pushes on the cylinder while it is lifted and carried: all
        // the time on Barrett, part of it on Allegro (whose thumb and fingers then carry it).
        let rec = read_session(&out).unwrap();
        assert!(rec.is_replay());
        let lifted = |t: &(u64, services::session::Contacts)| {
            rec.object
                .iter()
                .find(|(ts, _)| *ts == t.0)
                .is_some_and(|(_, o)| o.pose.position.z > skill.start_pose().translation.z + 0.05)
        };
        let (mut held, mut palm) = (0, 0);
        for c in rec.contacts.iter().filter(|c| lifted(c)) {
            held += 1;
            if c.1
                .fingers
                .iter()
                .any(|f| f.part == ContactPart::Palm && f.in_contact)
            {
                palm += 1;
            }
        }
        assert!(held > 500, "{name}: {held} lifted ticks");
        assert!(palm * 3 > held, "{name}: palm pushing {palm} of {held}");
    }
    // Inspire and glove10 report (held, or how the object got away), never err.
    for name in ["inspire", "glove10"] {
        let r = replay(&load_builtin_hand(name).unwrap(), &skill);
        assert!(r.ticks > 0 || r.failure_reason.is_some(), "{name}");
        assert!(r.success || !r.detail.is_empty(), "{name}");
    }
    // Degenerate collision geometry is refused naming the link, not replayed.
    let mut broken = load_builtin_hand("allegro").unwrap();
    broken.urdf = broken.urdf.map(|u| {
        u.replacen(
            r#"<box size="0.0414 0.112 0.0448"/>"#,
            r#"<box size="0 0.112 0.0448"/>"#,
            1,
        )
    });
    let refused = |hand: &LoadedHand| {
        replay_skill(
            hand,
            &skill,
            &ReplayParams::default(),
            &ReplaySource::default(),
            None,
        )
        .unwrap_err()
        .to_string()
    };
    let e = refused(&broken);
    assert!(
        e.contains("collision 0 of link \"base_link\"") && e.contains("got 0"),
        "{e}"
    );
    // The gripper has no palm to hold it with: refused, naming the palm contact.
    let e = refused(&load_builtin_hand("gripper").unwrap());
    assert!(
        e.contains("skill.contacts[") && e.contains("palm contact") && e.contains("no palm"),
        "{e}"
    );
}

#[test]
fn bad_hand_specs_are_refused_naming_the_problem() {
    let urdf = dfs_core::hand::builtin::GRIPPER_URDF;
    let err = load_hand_from_texts("{\"name\": 3}", urdf, "spec.json").unwrap_err();
    assert!(err.to_string().contains("name"), "{err}");
    let spec = r#"{"name": "g", "urdf": "g.urdf", "torque_limit": 5,
        "fingertips": [{"link": "nail", "offset": [0, 0, 0], "radius": 0.01}]}"#;
    let err = load_hand_from_texts(spec, urdf, "spec.json").unwrap_err();
    assert!(err.to_string().contains("no link named \"nail\""), "{err}");
}

#[test]
fn a_skill_file_with_phases_longer_than_an_hour_or_a_far_key_pose_is_refused_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let s = Scenario::builtin("box-pinch-lift", 0).unwrap();
    record_simulation(&s, Some(3.5), &path, |_, _| {}).unwrap();
    let session = read_session(&path).unwrap();
    let seg = segment(&session, &SegmentParams::default());
    let skill = serde_json::to_value(&seg.skills[0]).unwrap();
    let gripper = load_builtin_hand("gripper").unwrap();
    let run = |json: &serde_json::Value| {
        let spec = skill_spec_from_json(json, "skill.json").unwrap();
        replay_skill(
            &gripper,
            &spec,
            &ReplayParams::default(),
            &ReplaySource::default(),
            None,
        )
    };

    // A hold of 10^9 s: replayed at 1 kHz it would run for ever.
    let mut long = skill.clone();
    let phases = long["phases"].as_array_mut().unwrap();
    let end = phases.last().unwrap()["end_ns"].as_u64().unwrap();
    phases.push(serde_json::json!({"name": "hold", "start_ns": end, "end_ns": end + 1_000_000_000_000_000_000u64}));
    let e = run(&long).unwrap_err().to_string();
    assert!(
        e.contains("skill.phases") && e.contains("at most 3600 s"),
        "{e}"
    );

    let mut far = skill.clone();
    far["motion"] = serde_json::json!([
        {"time_s": 0.0, "position": [0.0, 0.0, 0.0], "rotation": [0.0, 0.0, 0.0]},
        {"time_s": 1.0, "position": [0.0, 0.0, 1e300], "rotation": [0.0, 0.0, 0.0]}
    ]);
    let e = run(&far).unwrap_err().to_string();
    assert!(e.contains("skill.motion[1]"), "{e}");
}

/// A hand-written skill with only what replay needs (the form `icms replay --skill FILE`
/// takes), with `edit` applied.
fn hand_written_skill(edit: impl FnOnce(&mut serde_json::Value)) -> serde_json::Value {
    let mut skill = serde_json::json!({
        "phases": [
            {"name": "approach", "start_ns": 0, "end_ns": 500_000_000u64},
            {"name": "grasp", "start_ns": 500_000_000u64, "end_ns": 1_000_000_000u64},
            {"name": "lift", "start_ns": 1_000_000_000u64, "end_ns": 1_500_000_000u64}
        ],
        "object": {"shape": "box", "size": [0.025, 0.025, 0.04], "mass": 0.2, "mu": 0.8},
        "contact_model": "soft_finger",
        "contacts": [
            {"position_b": [0.025, 0.0, 0.0], "normal_b": [-1.0, 0.0, 0.0]},
            {"position_b": [-0.025, 0.0, 0.0], "normal_b": [1.0, 0.0, 0.0]}
        ]
    });
    edit(&mut skill);
    skill
}

#[test]
fn a_skill_with_an_unknown_shape_contact_model_or_phase_is_refused_naming_the_field() {
    let spec = skill_spec_from_json(&hand_written_skill(|_| {}), "skill.json").unwrap();
    assert_eq!(
        spec.shape,
        dfs_core::object::Shape::Box {
            half_extents: [0.025, 0.025, 0.04]
        }
    );
    assert_eq!(spec.friction.mu_torsion, 0.0, "mu_torsion defaults to 0");
    type Edit = fn(&mut serde_json::Value);
    let cases: [(&str, Edit, &str); 5] = [
        (
            "shape",
            |s| s["object"]["shape"] = "torus".into(),
            "skill.object.shape: unknown shape \"torus\"; expected one of sphere, box, cylinder",
        ),
        (
            "contact model",
            |s| s["contact_model"] = "sticky".into(),
            "skill.contact_model: unknown contact model \"sticky\"; expected one of \
             frictionless, point_with_friction, soft_finger",
        ),
        (
            "phase",
            |s| s["phases"][1]["name"] = "juggle".into(),
            "skill.phases[1].name: unknown phase \"juggle\"; expected one of approach, preshape",
        ),
        (
            "sizes of another shape",
            |s| s["object"]["size"] = serde_json::json!([0.03]),
            "skill.object: invalid object.size: a box takes [half extent x, y, z] (m), got 1 values",
        ),
        (
            "missing contacts",
            |s| {
                s.as_object_mut().unwrap().remove("contacts");
            },
            "skill: missing field `contacts`",
        ),
    ];
    for (what, edit, message) in cases {
        let e = skill_spec_from_json(&hand_written_skill(edit), "skill.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains(message), "{what}: {e}");
    }
}
