//! The built-in hands: `glove10` (the paper's glove, built in code), and URDF hands embedded in
//! the binary with their hand specs: `allegro`, `barrett`, `inspire` (URDFs from dex-urdf, MIT,
//! licences beside them under `dfs-core/hands/`) and `gripper` (a two-finger parallel gripper
//! written for ICMS).
//!
//! # Torque limits and fingertips
//!
//! URDF `effort` values are often placeholders (10 N·m on every Allegro joint, 0 on the
//! Barrett), so the specs give the makers' figures or values derived from them:
//!
//! * Allegro Hand V4 (Wonik Robotics datasheet): 0.70 N·m per joint. Fingertip spheres of
//!   radius 12 mm centred at the `link_*_tip` frames (the rounded tips are 24 mm wide).
//! * Barrett BH8-282 (Barrett Technology datasheet): 15 N active fingertip force; over the
//!   ≈ 0.1 m from a finger's base joint to its tip that is 1.5 N·m, used for every joint.
//!   Fingertip spheres of radius 10 mm 5 cm out along the distal links. Note that the URDF's
//!   proximal links have their centre of mass 0.3 m outside the hand (an error of the source
//!   model, kept as it is: it only slows the spread joints).
//! * Inspire RH56 (Inspire Robots): 10 N grip force per finger over ≈ 75 mm from the MCP joint
//!   to the tip: 0.75 N·m per finger DOF; the thumb's pitch 1.0 N·m (15 N over 65 mm), its yaw
//!   0.5 N·m. Fingertip spheres of radius 8 mm just inside the `*_tip` frames.
//! * `gripper`: 40 N on the jaw DOF (the mimic splits it: 20 N squeeze per jaw), 2 N·m wrist.

use super::urdf::{FingertipSpec, HandSpec};
use super::HandModel;
use crate::error::{DfsError, Result};
use std::collections::BTreeMap;

/// Names of the built-in hands.
pub const BUILTIN_HANDS: [&str; 5] = ["glove10", "allegro", "barrett", "inspire", "gripper"];

/// The Allegro right hand's URDF (dex-urdf, BSD/MIT; see `dfs-core/hands/allegro_hand`).
pub const ALLEGRO_URDF: &str = include_str!("../../hands/allegro_hand/allegro_hand_right.urdf");
/// The Barrett BH8 hand's URDF (dex-urdf; see `dfs-core/hands/barrett_hand`).
pub const BARRETT_URDF: &str = include_str!("../../hands/barrett_hand/bhand_model.urdf");
/// The Inspire right hand's URDF (dex-urdf; see `dfs-core/hands/inspire_hand`).
pub const INSPIRE_URDF: &str = include_str!("../../hands/inspire_hand/inspire_hand_right.urdf");
/// The ICMS parallel gripper's URDF (`dfs-core/hands/gripper`).
pub const GRIPPER_URDF: &str = include_str!("../../hands/gripper/gripper.urdf");

fn tip(name: &str, link: &str, offset: [f64; 3], radius: f64) -> FingertipSpec {
    FingertipSpec {
        name: Some(name.to_owned()),
        link: link.to_owned(),
        offset,
        radius,
    }
}

fn spec(
    name: &str,
    urdf: &str,
    fingertips: Vec<FingertipSpec>,
    torque_limit: f64,
    joints: &[(&str, f64)],
) -> HandSpec {
    HandSpec {
        name: name.to_owned(),
        urdf: urdf.to_owned(),
        fingertips,
        torque_limit,
        joint_torque_limits: joints
            .iter()
            .map(|(j, t)| ((*j).to_owned(), *t))
            .collect::<BTreeMap<_, _>>(),
        base_link: None,
        thumb: Some("thumb".to_owned()),
        armature: None,
    }
}

/// The hand spec and URDF text of a built-in URDF hand (`None` for `glove10` and unknown names).
pub fn builtin_spec(name: &str) -> Option<(HandSpec, &'static str)> {
    let s = match name {
        "allegro" => (
            spec(
                "allegro",
                "allegro_hand_right.urdf",
                vec![
                    tip("thumb", "link_15.0_tip", [0.0, 0.0, 0.0], 0.012),
                    tip("index", "link_3.0_tip", [0.0, 0.0, 0.0], 0.012),
                    tip("middle", "link_7.0_tip", [0.0, 0.0, 0.0], 0.012),
                    tip("ring", "link_11.0_tip", [0.0, 0.0, 0.0], 0.012),
                ],
                0.7,
                &[],
            ),
            ALLEGRO_URDF,
        ),
        "barrett" => (
            spec(
                "barrett",
                "bhand_model.urdf",
                vec![
                    tip("thumb", "finger_3_dist_link", [-0.035, 0.035, 0.0], 0.01),
                    tip("finger1", "finger_1_dist_link", [-0.035, 0.035, 0.0], 0.01),
                    tip("finger2", "finger_2_dist_link", [-0.035, 0.035, 0.0], 0.01),
                ],
                1.5,
                &[],
            ),
            BARRETT_URDF,
        ),
        "inspire" => (
            spec(
                "inspire",
                "inspire_hand_right.urdf",
                vec![
                    tip("thumb", "thumb_tip", [-0.005, -0.0035, 0.0], 0.008),
                    tip("index", "index_tip", [0.0, -0.006, 0.0], 0.008),
                    tip("middle", "middle_tip", [0.0, -0.006, 0.0], 0.008),
                    tip("ring", "ring_tip", [0.0, -0.006, 0.0], 0.008),
                    tip("little", "pinky_tip", [0.0, -0.006, 0.0], 0.008),
                ],
                0.75,
                &[
                    ("thumb_proximal_pitch_joint", 1.0),
                    ("thumb_proximal_yaw_joint", 0.5),
                ],
            ),
            INSPIRE_URDF,
        ),
        "gripper" => (
            spec(
                "gripper",
                "gripper.urdf",
                vec![
                    tip("thumb", "right_finger", [0.0, 0.01, 0.085], 0.01),
                    tip("finger", "left_finger", [0.0, -0.01, 0.085], 0.01),
                ],
                40.0,
                &[("wrist_roll", 2.0)],
            ),
            GRIPPER_URDF,
        ),
        _ => return None,
    };
    Some(s)
}

/// A built-in hand model by name: `glove10`, `allegro`, `barrett`, `inspire`, `gripper`.
pub fn builtin_hand(name: &str) -> Result<HandModel> {
    if name == "glove10" {
        return Ok(HandModel::glove10());
    }
    let (spec, urdf) = builtin_spec(name).ok_or_else(|| {
        DfsError::invalid(
            "hand",
            format!(
                "no built-in hand {name:?} (built-in: {})",
                BUILTIN_HANDS.join(", ")
            ),
        )
    })?;
    HandModel::from_urdf(urdf, &spec)
}

/// Index of the fingertip that opposes the others: the one named `thumb`, else the first.
pub fn thumb_of(hand: &HandModel) -> usize {
    hand.fingertips
        .iter()
        .position(|t| t.name == "thumb")
        .unwrap_or(0)
}
