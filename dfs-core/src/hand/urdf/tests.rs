//! Tests of reading hands from URDF.

use super::text::nesting_depth;
use super::*;
use crate::hand::builtin::{builtin_hand, builtin_spec, GRIPPER_URDF};
use crate::hand::model::tests::{
    angles_from_unit, assert_jacobians_match_finite_differences, assert_mass_matrix_is_consistent,
};
use crate::hand::{FingerGroup, Kinematics, BUILTIN_HANDS};
use crate::hand::{Joint, JointDrive, MAX_HAND_DOF};
use crate::math::Isometry;

fn error_of(result: Result<HandModel>) -> (String, String) {
    match result {
        Err(DfsError::Invalid { field, reason }) => (field, reason),
        Err(other) => panic!("expected an invalid-model error, got {other:?}"),
        Ok(h) => panic!("expected an error, got a hand with {} DOFs", h.dof()),
    }
}

fn gripper_spec() -> HandSpec {
    builtin_spec("gripper").unwrap().0
}

#[test]
fn every_builtin_hand_loads_with_its_fingers_and_dofs() {
    let expected = [
        ("glove10", 5, 10),
        ("allegro", 4, 16),
        ("barrett", 3, 8),
        ("inspire", 5, 6),
        ("gripper", 2, 2),
    ];
    assert_eq!(BUILTIN_HANDS.len(), expected.len());
    for (name, tips, dofs) in expected {
        let hand = builtin_hand(name).unwrap();
        assert_eq!(hand.name, name);
        assert_eq!(hand.fingertips.len(), tips, "{name} fingertips");
        assert_eq!(hand.dof(), dofs, "{name} DOFs");
        hand.validate().unwrap();
    }
}

#[test]
fn inspire_mimic_joints_follow_their_source_within_their_own_limits() {
    let hand = builtin_hand("inspire").unwrap();
    let mimics: Vec<&Joint> = hand
        .joints
        .iter()
        .filter(|j| matches!(j.drive, JointDrive::Mimic { .. }))
        .collect();
    // Four finger intermediates and two thumb joints.
    assert_eq!(mimics.len(), 6);
    let j = hand
        .joints
        .iter()
        .find(|j| j.name == "index_intermediate_joint")
        .unwrap();
    let JointDrive::Mimic {
        dof,
        multiplier,
        offset,
    } = j.drive
    else {
        panic!("not a mimic");
    };
    assert_eq!(hand.dof_names[dof], "index_proximal_joint");
    assert_eq!((multiplier, offset), (1.06399, -0.04545));
    // The thumb's pitch DOF is narrowed so its intermediate joint (×1.334, ≤ 0.8) stays in.
    let pitch = hand
        .dof_names
        .iter()
        .position(|n| n == "thumb_proximal_pitch_joint")
        .unwrap();
    assert!((hand.dof_upper[pitch] - 0.8 / 1.334).abs() < 1e-12);
    for m in mimics {
        let (d, gain) = m.drive.dof_and_gain().unwrap();
        for q in [hand.dof_lower[d], hand.dof_upper[d]] {
            let mut theta = vec![0.0; hand.dof()];
            theta[d] = q;
            let v = m.drive.value(&theta);
            assert!(
                v >= m.lower - 1e-9 && v <= m.upper + 1e-9,
                "{} = {v}",
                m.name
            );
            assert!(gain != 0.0);
        }
    }
}

#[test]
fn the_gripper_jaws_share_one_dof_and_form_one_finger_group() {
    let hand = builtin_hand("gripper").unwrap();
    let jaw = hand
        .dof_names
        .iter()
        .position(|n| n == "right_finger_joint")
        .unwrap();
    assert_eq!(
        hand.finger_groups,
        vec![FingerGroup {
            tips: vec![0, 1],
            dofs: vec![jaw]
        }]
    );
    // Opening the jaw DOF moves the two pads apart symmetrically.
    let mut kin = Kinematics::default();
    let mut q = vec![0.0; 2];
    q[jaw] = 0.03;
    hand.forward_kinematics(&Isometry::identity(), &q, &mut kin);
    let gap = (kin.tip_centres[0] - kin.tip_centres[1]).norm();
    assert!((gap - (0.06 + 0.02)).abs() < 1e-12, "{gap}");
}

#[test]
fn allegro_jacobians_and_inertia_match_finite_differences() {
    let hand = builtin_hand("allegro").unwrap();
    let mut u = 0.137;
    for _ in 0..5 {
        let samples: Vec<f64> = (0..hand.dof())
            .map(|_| {
                u = (u * 7.31 + 0.123) % 1.0;
                u
            })
            .collect();
        let q = angles_from_unit(&hand, &samples);
        assert_jacobians_match_finite_differences(&hand, &q);
        let qdot: Vec<f64> = samples.iter().map(|s| 2.0 * s - 1.0).collect();
        assert_mass_matrix_is_consistent(&hand, &q, &qdot);
    }
    let inspire = builtin_hand("inspire").unwrap();
    let q = angles_from_unit(&inspire, &[0.3, 0.5, 0.7, 0.2, 0.9, 0.4]);
    assert_jacobians_match_finite_differences(&inspire, &q);
}

/// The gripper URDF with `from` replaced by `to` (which must occur).
fn edited(from: &str, to: &str) -> String {
    assert!(GRIPPER_URDF.contains(from), "{from}");
    GRIPPER_URDF.replacen(from, to, 1)
}

#[test]
fn bad_urdfs_and_specs_are_refused_naming_the_problem() {
    let spec = gripper_spec();
    let cases: Vec<(String, HandSpec, &str, &str)> = vec![
        (
            "<robot name=\"x\"><link name=".into(),
            spec.clone(),
            "urdf",
            "does not parse",
        ),
        (
            // A loop: the palm becomes the child of a finger as well.
            edited(
                "</robot>",
                "<joint name=\"loop\" type=\"fixed\"><parent link=\"left_finger\"/>\
                     <child link=\"palm\"/></joint></robot>",
            ),
            spec.clone(),
            "urdf link \"palm\"",
            "kinematic loop",
        ),
        (
            edited("</robot>", "<link name=\"stray\"/></robot>"),
            spec.clone(),
            "urdf",
            "several root links (base_link, stray)",
        ),
        (
            GRIPPER_URDF.into(),
            HandSpec {
                fingertips: vec![FingertipSpec {
                    name: None,
                    link: "nail".into(),
                    offset: [0.0; 3],
                    radius: 0.01,
                }],
                thumb: None,
                ..spec.clone()
            },
            "fingertips[0].link",
            "no link named \"nail\"",
        ),
        (
            // Every joint fixed: a hand that cannot move a finger was accepted.
            GRIPPER_URDF
                .replace("type=\"revolute\"", "type=\"fixed\"")
                .replace("type=\"prismatic\"", "type=\"fixed\"")
                .replace(
                    "<mimic joint=\"right_finger_joint\" multiplier=\"1\" offset=\"0\"/>",
                    "",
                ),
            spec.clone(),
            "urdf",
            "the hand has no actuated joint",
        ),
        (
            // Two joints mimicking each other were reported as a hand with no actuated
            // joint, not as the cycle they are.
            GRIPPER_URDF
                .replace("type=\"revolute\"", "type=\"fixed\"")
                .replace(
                    "<child link=\"right_finger\"/>",
                    "<child link=\"right_finger\"/><mimic joint=\"left_finger_joint\"/>",
                ),
            spec.clone(),
            "urdf joint \"right_finger_joint\" mimic",
            "mimic joints form a cycle",
        ),
        (
            edited("<mass value=\"0.05\"/>", "<mass value=\"1e30\"/>"),
            spec.clone(),
            "urdf link \"right_finger\" inertial",
            "at most 10000 kg",
        ),
        (
            edited("<mass value=\"0.05\"/>", "<mass value=\"-0.05\"/>"),
            spec.clone(),
            "urdf link \"right_finger\" inertial",
            "mass -0.05",
        ),
        (
            edited("ixx=\"3.5e-5\"", "ixx=\"-3.5e-5\""),
            spec.clone(),
            "urdf link \"right_finger\" inertial",
            "not positive semi-definite",
        ),
        (
            GRIPPER_URDF.into(),
            {
                let mut s = spec.clone();
                s.fingertips[1].radius = -0.01;
                s
            },
            "fingertips[1].radius",
            "radius -0.01",
        ),
        (
            edited("type=\"revolute\"", "type=\"floating\""),
            spec.clone(),
            "urdf joint \"wrist_roll\"",
            "Floating is not supported",
        ),
        (
            edited("joint=\"right_finger_joint\"", "joint=\"thumb_joint\""),
            spec.clone(),
            "urdf joint \"left_finger_joint\" mimic",
            "\"thumb_joint\", which does not exist",
        ),
        (
            edited("<child link=\"palm\"/>", "<child link=\"hand\"/>"),
            spec.clone(),
            "urdf joint \"wrist_roll\"",
            "child link \"hand\" does not exist",
        ),
        (
            edited(
                "<limit lower=\"-3.14\" upper=\"3.14\" effort=\"5\" velocity=\"3\"/>",
                "",
            ),
            spec.clone(),
            "urdf joint \"wrist_roll\" limit",
            "needs <limit",
        ),
        (
            GRIPPER_URDF.into(),
            HandSpec {
                torque_limit: 0.0,
                ..spec.clone()
            },
            "torque_limit",
            "> 0",
        ),
        (
            GRIPPER_URDF.into(),
            {
                let mut s = spec.clone();
                s.joint_torque_limits
                    .insert("left_finger_joint".into(), 5.0);
                s
            },
            "joint_torque_limits.left_finger_joint",
            "no such independent",
        ),
        (
            GRIPPER_URDF.into(),
            HandSpec {
                base_link: Some("forearm".into()),
                ..spec.clone()
            },
            "base_link",
            "no link named \"forearm\"",
        ),
        (
            "<robot name=\"x\"></robot>".into(),
            spec.clone(),
            "urdf",
            "robot \"x\" has no links",
        ),
        (
            edited("effort=\"5\" velocity=\"3\"", "effort=\"5\""),
            spec.clone(),
            "urdf",
            "missing field `velocity` (every joint <limit> needs both effort and velocity",
        ),
        (
            edited("<axis xyz=\"0 0 1\"/>", "<axis xyz=\"0 0 0\"/>"),
            spec.clone(),
            "urdf joint \"wrist_roll\"",
            "axis must be a finite, non-zero vector",
        ),
    ];
    for (urdf, spec, field, reason) in cases {
        let (f, r) = error_of(HandModel::from_urdf(&urdf, &spec));
        assert_eq!(f, field, "{r}");
        assert!(r.contains(reason), "{field}: {r:?} lacks {reason:?}");
    }
}

#[test]
fn lengths_far_beyond_a_hand_are_refused_naming_the_field() {
    let spec = gripper_spec();
    let mut far_tip = spec.clone();
    far_tip.fingertips[0].offset = [1e300, 0.0, 0.0];
    let (f, r) = error_of(HandModel::from_urdf(GRIPPER_URDF, &far_tip));
    assert_eq!(f, "fingertips[0].offset", "{r}");
    let mut huge_tip = spec.clone();
    huge_tip.fingertips[1].radius = 20.0;
    let (f, r) = error_of(HandModel::from_urdf(GRIPPER_URDF, &huge_tip));
    assert_eq!(f, "fingertips[1].radius", "{r}");
    let far_joint = edited(
        "<origin xyz=\"0 0 0.04\" rpy=\"0 0 0\"/>",
        "<origin xyz=\"1e300 0 0.04\" rpy=\"0 0 0\"/>",
    );
    let (f, r) = error_of(HandModel::from_urdf(&far_joint, &spec));
    assert!(
        f.starts_with("urdf joint") && r.contains("within 10 m"),
        "{f}: {r}"
    );
}

#[test]
fn too_many_dofs_are_refused_naming_the_limit() {
    // 33 revolute joints in a chain.
    let mut urdf = String::from("<robot name=\"snake\"><link name=\"l0\"/>");
    for i in 1..=33 {
        urdf.push_str(&format!(
            "<link name=\"l{i}\"/><joint name=\"j{i}\" type=\"revolute\">\
                 <parent link=\"l{}\"/><child link=\"l{i}\"/><axis xyz=\"0 0 1\"/>\
                 <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>",
            i - 1
        ));
    }
    urdf.push_str("</robot>");
    let spec = HandSpec {
        fingertips: vec![FingertipSpec {
            name: None,
            link: "l33".into(),
            offset: [0.0; 3],
            radius: 0.01,
        }],
        thumb: None,
        joint_torque_limits: BTreeMap::new(),
        ..gripper_spec()
    };
    let (field, reason) = error_of(HandModel::from_urdf(&urdf, &spec));
    assert_eq!(field, "urdf");
    assert!(
        reason.starts_with(
            "the hand has 33 DOFs (independent moving joints); at most 32 are accepted"
        ),
        "{reason}"
    );
    // One fewer is a hand.
    let urdf = urdf.replace(
        "type=\"revolute\"><parent link=\"l32\"",
        "type=\"fixed\"><parent link=\"l32\"",
    );
    assert_eq!(
        HandModel::from_urdf(&urdf, &spec).unwrap().dof(),
        MAX_HAND_DOF
    );
}

#[test]
fn an_axis_is_a_direction_whatever_its_length() {
    let spec = gripper_spec();
    let unit = HandModel::from_urdf(GRIPPER_URDF, &spec).unwrap();
    for axis in ["0 0 1e200", "0 0 1e-200", "0 0 7"] {
        let urdf = edited("<axis xyz=\"0 0 1\"/>", &format!("<axis xyz=\"{axis}\"/>"));
        let hand = HandModel::from_urdf(&urdf, &spec).unwrap();
        assert_eq!(hand.joints, unit.joints, "axis {axis}");
    }
}

#[test]
fn a_base_link_drops_the_links_above_it_and_continuous_joints_are_unlimited() {
    let urdf = edited("type=\"revolute\"", "type=\"continuous\"");
    let spec = HandSpec {
        base_link: Some("palm".into()),
        joint_torque_limits: BTreeMap::new(),
        ..gripper_spec()
    };
    let hand = HandModel::from_urdf(&urdf, &spec).unwrap();
    assert_eq!(hand.links[hand.root].name, "palm");
    assert_eq!(hand.dof(), 1);
    let full = HandModel::from_urdf(
        &urdf,
        &HandSpec {
            joint_torque_limits: BTreeMap::new(),
            ..gripper_spec()
        },
    )
    .unwrap();
    assert_eq!(full.dof_lower[0], f64::NEG_INFINITY);
    assert_eq!(full.dof_upper[0], f64::INFINITY);
    // A massless link reads as massless; the armature keeps M positive definite.
    assert!(full.armature.iter().all(|&a| a == DEFAULT_ARMATURE));
}

/// The gripper's URDF with `inner` inserted just inside `<robot>`.
fn gripper_with(inner: &str) -> String {
    let at = GRIPPER_URDF.find("<link").unwrap();
    format!("{}{inner}{}", &GRIPPER_URDF[..at], &GRIPPER_URDF[at..])
}

/// `depth` unknown elements, each inside the last.
fn nest(depth: usize) -> String {
    format!("{}{}", "<junk>".repeat(depth), "</junk>".repeat(depth))
}

/// Loads `urdf` on a thread with a 2 MiB stack (a tokio worker's and Rust's default):
/// before the depth check, 3000 levels overflowed it inside the XML parser.
fn load_on_small_stack(urdf: String) -> Result<HandModel> {
    std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(move || HandModel::from_urdf(&urdf, &gripper_spec()))
        .unwrap()
        .join()
        .unwrap()
}

#[test]
fn a_urdf_nesting_elements_thousands_deep_is_refused_naming_the_limit() {
    for depth in [3000, 100_000] {
        // `<robot>` is the first level.
        let (field, reason) = error_of(load_on_small_stack(gripper_with(&nest(depth - 1))));
        assert_eq!(field, "urdf");
        assert_eq!(
            reason,
            format!("the URDF nests elements {depth} deep; at most 64 are accepted")
        );
    }
    // At the limit an unknown element is ignored as before; one more is refused.
    load_on_small_stack(gripper_with(&nest(MAX_URDF_DEPTH - 1))).unwrap();
    let (_, reason) = error_of(load_on_small_stack(gripper_with(&nest(MAX_URDF_DEPTH))));
    assert!(reason.contains("65 deep; at most 64"), "{reason}");
}

#[test]
fn a_urdf_over_4_mib_is_refused_naming_the_limit() {
    let padding = " ".repeat(MAX_URDF_BYTES);
    let (field, reason) = error_of(HandModel::from_urdf(
        &gripper_with(&padding),
        &gripper_spec(),
    ));
    assert_eq!(field, "urdf");
    assert!(
        reason.starts_with("the URDF is 41")
            && reason.ends_with("bytes; at most 4194304 (4 MiB) are accepted"),
        "{reason}"
    );
}

#[test]
fn comments_cdata_instructions_and_attribute_values_do_not_count_as_nesting() {
    let depth = |s: &str| nesting_depth(s.as_bytes());
    assert_eq!(depth("<a><b/><c x=\"1\"></c></a>"), 2);
    assert_eq!(depth("<a><!-- <b><b><b> --></a>"), 1);
    assert_eq!(depth("<a><![CDATA[<b><b><b>]]></a>"), 1);
    assert_eq!(depth("<?xml version=\"1.0\"?><!DOCTYPE robot><a/>"), 1);
    assert_eq!(depth("<a x=\"<b><b>\" y='/>' z = \"<c>\"><d/></a>"), 2);
    // A quote opens a value only after `=`, as in the parser: here the tag ends at `>`
    // and the elements after it count.
    assert_eq!(depth("<a\"><b><c>"), 3);
    assert_eq!(depth("<a b\"><b><c>"), 3);
    // Unclosed constructs end the scan (the parser refuses them).
    assert_eq!(depth("<a><!-- <b><b>"), 1);
    assert_eq!(depth("<a x=\"<b><b>"), 1);
    // A processing instruction ends at the first `>` after a `?`, as the parser's does.
    assert_eq!(depth("<?p ? ><a><b>"), 2);
    // A comment full of elements in a real URDF loads.
    let hand = HandModel::from_urdf(
        &gripper_with(&format!("<!-- {} -->", nest(5000))),
        &gripper_spec(),
    )
    .unwrap();
    assert_eq!(hand.dof(), 2);
}

#[test]
fn every_built_in_urdf_nests_less_than_ten_deep() {
    for name in BUILTIN_HANDS.iter().filter(|&&n| n != "glove10") {
        let (_, urdf) = builtin_spec(name).unwrap();
        check_urdf_text(urdf).unwrap();
        let depth = nesting_depth(urdf.as_bytes());
        assert!((3..10).contains(&depth), "{name}: {depth}");
    }
}
