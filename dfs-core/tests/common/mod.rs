//! Synthetic robot hands for the tests: URDF text built in code (a wrist of revolute joints,
//! fingers of revolute joints with cylinder links and inertials, a fixed `*_tip` link at each
//! fingertip, as the dex-urdf hands have), their hand specs, and skills taken from the
//! built-in scenarios.

#![allow(dead_code)]

use dfs_core::contact::{ContactModel, Friction};
use dfs_core::hand::{FingertipSpec, HandModel, HandSpec};
use dfs_core::math::{Isometry, Real, Rotation, Vector};
use dfs_core::operator::plan_grasp;
use dfs_core::replay::{SkillContact, SkillKeyPose, SkillSpec};
use dfs_core::scenario::{Phase, Scenario};
use std::collections::BTreeMap;
use std::fmt::Write;

/// One joint of a synthetic hand.
#[derive(Debug, Clone)]
pub struct JointDef {
    /// `revolute`, `continuous`, `prismatic` or `fixed`.
    pub kind: &'static str,
    /// Joint origin in the parent link (m) and its roll-pitch-yaw (rad).
    pub xyz: [f64; 3],
    /// Roll, pitch, yaw of the origin (rad).
    pub rpy: [f64; 3],
    /// Axis in the joint frame.
    pub axis: [f64; 3],
    /// Limits (rad or m).
    pub lower: f64,
    /// Upper limit.
    pub upper: f64,
    /// Mimics the joint of this name: (name, multiplier, offset).
    pub mimic: Option<(String, f64, f64)>,
    /// Length of the child link along its z axis (m): its inertial is a cylinder that long.
    pub length: f64,
}

/// A synthetic hand: its URDF joints as chains. Link and joint names are generated.
#[derive(Debug, Clone, Default)]
pub struct HandDef {
    /// Name of the hand.
    pub name: String,
    /// Joints from the base link to the palm (the wrist).
    pub wrist: Vec<JointDef>,
    /// Fingers: name and joints from the palm to the last link (the fingertip is a fixed
    /// `<name>_tip` link at the end of the last link).
    pub fingers: Vec<(String, Vec<JointDef>)>,
    /// Extra fingertips on intermediate links of a finger: (tip name, finger index, joint
    /// index whose child carries it).
    pub extra_tips: Vec<(String, usize, usize)>,
}

/// An `<inertial>` of a solid cylinder of radius 8 mm along z, `length` long, of 2.7 g/cm³.
fn cylinder_inertial(length: f64) -> String {
    let r: f64 = 0.008;
    let l = length.max(0.005);
    let mass = 2700.0 * std::f64::consts::PI * r * r * l;
    let ixx = mass * (3.0 * r * r + l * l) / 12.0;
    let izz = mass * r * r / 2.0;
    format!(
        "<inertial><origin xyz=\"0 0 {:.5}\" rpy=\"0 0 0\"/><mass value=\"{mass:.6}\"/>\
         <inertia ixx=\"{ixx:.4e}\" ixy=\"0\" ixz=\"0\" iyy=\"{ixx:.4e}\" iyz=\"0\" \
         izz=\"{izz:.4e}\"/></inertial>",
        l / 2.0
    )
}

fn link(name: &str, length: f64) -> String {
    let l = length.max(0.005);
    format!(
        "  <link name=\"{name}\">{}<visual><origin xyz=\"0 0 {:.5}\" rpy=\"0 0 0\"/>\
         <geometry><cylinder radius=\"0.008\" length=\"{l:.5}\"/></geometry></visual>\
         <collision><origin xyz=\"0 0 {:.5}\" rpy=\"0 0 0\"/><geometry>\
         <cylinder radius=\"0.008\" length=\"{l:.5}\"/></geometry></collision></link>\n",
        cylinder_inertial(l),
        l / 2.0,
        l / 2.0
    )
}

fn joint(name: &str, parent: &str, child: &str, j: &JointDef) -> String {
    let [x, y, z] = j.xyz;
    let [r, p, yaw] = j.rpy;
    let [ax, ay, az] = j.axis;
    let mut s = format!(
        "  <joint name=\"{name}\" type=\"{}\"><parent link=\"{parent}\"/>\
         <child link=\"{child}\"/><origin xyz=\"{x} {y} {z}\" rpy=\"{r} {p} {yaw}\"/>\
         <axis xyz=\"{ax} {ay} {az}\"/>",
        j.kind
    );
    if j.kind != "fixed" {
        let _ = write!(
            s,
            "<limit lower=\"{}\" upper=\"{}\" effort=\"1\" velocity=\"3\"/>",
            j.lower, j.upper
        );
    }
    if let Some((source, m, o)) = &j.mimic {
        let _ = write!(
            s,
            "<mimic joint=\"{source}\" multiplier=\"{m}\" offset=\"{o}\"/>"
        );
    }
    s.push_str("</joint>\n");
    s
}

/// Name of joint `i` of finger `f`.
pub fn finger_joint_name(finger: &str, i: usize) -> String {
    format!("{finger}_j{i}")
}

impl HandDef {
    /// The URDF text.
    pub fn urdf(&self) -> String {
        let mut s = format!(
            "<?xml version=\"1.0\"?>\n<!-- synthetic hand {} -->\n<robot name=\"{}\">\n",
            self.name, self.name
        );
        s.push_str(&link("base_link", 0.03));
        let mut parent = "base_link".to_owned();
        for (i, j) in self.wrist.iter().enumerate() {
            let child = if i + 1 == self.wrist.len() {
                "palm".to_owned()
            } else {
                format!("wrist_link{i}")
            };
            s.push_str(&link(&child, j.length));
            s.push_str(&joint(&format!("wrist_j{i}"), &parent, &child, j));
            parent = child;
        }
        if self.wrist.is_empty() {
            parent = "base_link".to_owned();
        }
        let palm = parent;
        for (name, joints) in &self.fingers {
            let mut parent = palm.clone();
            let mut last_length = 0.0;
            for (i, j) in joints.iter().enumerate() {
                let child = format!("{name}_link{i}");
                s.push_str(&link(&child, j.length));
                s.push_str(&joint(&finger_joint_name(name, i), &parent, &child, j));
                parent = child;
                last_length = j.length;
            }
            let tip = format!("{name}_tip");
            s.push_str(&format!("  <link name=\"{tip}\"/>\n"));
            let fixed = JointDef {
                kind: "fixed",
                xyz: [0.0, 0.0, last_length],
                rpy: [0.0; 3],
                axis: [0.0, 0.0, 1.0],
                lower: 0.0,
                upper: 0.0,
                mimic: None,
                length: 0.0,
            };
            s.push_str(&joint(&format!("{name}_tip_joint"), &parent, &tip, &fixed));
        }
        s.push_str("</robot>\n");
        s
    }

    /// The hand spec: a fingertip sphere of radius 9 mm at every `*_tip` link (and the extra
    /// tips at the middle of their links), the first finger the thumb, 1.5 N·m per joint.
    pub fn spec(&self) -> HandSpec {
        let mut fingertips: Vec<FingertipSpec> = self
            .fingers
            .iter()
            .map(|(name, _)| FingertipSpec {
                name: Some(name.clone()),
                link: format!("{name}_tip"),
                offset: [0.0, 0.0, 0.0],
                radius: 0.009,
            })
            .collect();
        for (tip, f, j) in &self.extra_tips {
            let (name, joints) = &self.fingers[*f];
            fingertips.push(FingertipSpec {
                name: Some(tip.clone()),
                link: format!("{name}_link{j}"),
                offset: [0.0, 0.0, joints[*j].length / 2.0],
                radius: 0.009,
            });
        }
        HandSpec {
            name: self.name.clone(),
            urdf: format!("{}.urdf", self.name),
            fingertips,
            torque_limit: 1.5,
            joint_torque_limits: BTreeMap::new(),
            base_link: None,
            thumb: self.fingers.first().map(|(n, _)| n.clone()),
            armature: None,
        }
    }

    /// The hand model, as the loader builds it.
    pub fn model(&self) -> dfs_core::Result<HandModel> {
        HandModel::from_urdf(&self.urdf(), &self.spec())
    }

    /// Number of DOFs (moving joints that mimic nothing).
    pub fn dof(&self) -> usize {
        self.wrist
            .iter()
            .chain(self.fingers.iter().flat_map(|(_, j)| j))
            .filter(|j| j.kind != "fixed" && j.mimic.is_none())
            .count()
    }
}

fn revolute(
    xyz: [f64; 3],
    rpy: [f64; 3],
    axis: [f64; 3],
    range: (f64, f64),
    length: f64,
) -> JointDef {
    JointDef {
        kind: "revolute",
        xyz,
        rpy,
        axis,
        lower: range.0,
        upper: range.1,
        mimic: None,
        length,
    }
}

/// A finger of `n` (1-8) revolute joints starting at `root` (palm frame, rotated by `rpy`):
/// a spread joint about x, then flexion joints about y (bending towards the palm's +x side)
/// on links of decreasing length; from a sixth joint on, a twist about z.
pub fn finger(n: usize, root: [f64; 3], rpy: [f64; 3]) -> Vec<JointDef> {
    let lengths = [0.012, 0.045, 0.03, 0.024, 0.02, 0.016, 0.014, 0.012];
    (0..n)
        .map(|i| {
            let xyz = if i == 0 {
                root
            } else {
                [0.0, 0.0, lengths[(i - 1).min(lengths.len() - 1)]]
            };
            let rpy = if i == 0 { rpy } else { [0.0; 3] };
            let length = lengths[i.min(lengths.len() - 1)];
            match i {
                0 => revolute(xyz, rpy, [1.0, 0.0, 0.0], (-0.35, 0.35), length),
                5 => revolute(xyz, rpy, [0.0, 0.0, 1.0], (-0.4, 0.4), length),
                _ => revolute(xyz, rpy, [0.0, 1.0, 0.0], (0.0, 1.5), length),
            }
        })
        .collect()
}

/// A five-finger hand (thumb, index, middle, ring, little) with `joints[k]` joints per finger
/// and a wrist of `wrist` (0-2) joints: flexion about y, deviation about x.
pub fn five_finger_hand(name: &str, wrist: usize, joints: [usize; 5]) -> HandDef {
    let wrist_joints = [
        revolute(
            [0.0, 0.0, 0.03],
            [0.0; 3],
            [0.0, 1.0, 0.0],
            (-0.5, 0.25),
            0.02,
        ),
        revolute(
            [0.0, 0.0, 0.02],
            [0.0; 3],
            [1.0, 0.0, 0.0],
            (-0.7, 0.5),
            0.09,
        ),
    ];
    let roots = [
        ([0.02, 0.035, 0.02], [-0.9, 0.5, 0.0]),
        ([0.0, 0.033, 0.095], [0.0; 3]),
        ([0.0, 0.011, 0.1], [0.0; 3]),
        ([0.0, -0.011, 0.095], [0.0; 3]),
        ([0.0, -0.033, 0.088], [0.0; 3]),
    ];
    let names = ["thumb", "index", "middle", "ring", "little"];
    HandDef {
        name: name.to_owned(),
        wrist: wrist_joints[..wrist].to_vec(),
        fingers: (0..5)
            .map(|k| {
                (
                    names[k].to_owned(),
                    finger(joints[k], roots[k].0, roots[k].1),
                )
            })
            .collect(),
        extra_tips: Vec::new(),
    }
}

/// One serial chain of `n` revolute joints (alternating axes y and x) with a fingertip at its
/// end (`index`) and one halfway (`thumb`).
pub fn chain_hand(name: &str, n: usize) -> HandDef {
    let joints = (0..n)
        .map(|i| {
            let axis = if i % 2 == 0 {
                [0.0, 1.0, 0.0]
            } else {
                [1.0, 0.0, 0.0]
            };
            revolute([0.0, 0.0, 0.02], [0.0; 3], axis, (-0.8, 0.8), 0.02)
        })
        .collect();
    HandDef {
        name: name.to_owned(),
        wrist: Vec::new(),
        fingers: vec![("index".to_owned(), joints)],
        extra_tips: vec![("thumb".to_owned(), 0, n / 2)],
    }
}

/// A skill as the segmentation takes it from a recording of the built-in scenario `name`:
/// its object and phases, the contacts of glove10's grasp of the object (the operator's own
/// plan), and the motion of its lift, hold and place.
pub fn scenario_skill(name: &str) -> SkillSpec {
    let scenario = Scenario::builtin(name, 1).expect("a built-in scenario");
    let (object, tasks) = scenario.resolve().expect("a valid scenario");
    let depth = object.shape.support_depth(&Rotation::identity());
    let pose = Isometry::translation(0.0, 0.0, depth);
    let glove = HandModel::glove10();
    let plan = plan_grasp(&glove, &object, &pose, scenario.grasp).expect("glove10 grasps it");
    let contacts = (0..glove.fingertips.len())
        .filter(|&k| plan.tips[k])
        .map(|k| SkillContact {
            finger: glove.fingertips[k].name.clone(),
            part: dfs_core::hand::ContactPart::Fingertip,
            position_b: plan.contacts_b[k] - plan.normals_b[k] * glove.fingertips[k].radius,
            normal_b: -plan.normals_b[k],
        })
        .collect();
    // The object's motion from the start of `grasp`: up by the lift height, held, set down.
    let mut motion = Vec::new();
    let mut t: Real = 0.0;
    let mut z: Real = 0.0;
    let key = |t: Real, z: Real| SkillKeyPose {
        time_s: t,
        position: Vector::new(0.0, 0.0, z),
        rotation: Vector::zeros(),
    };
    let mut grasped = false;
    for task in &tasks {
        match task.phase {
            Phase::Grasp => {
                grasped = true;
                motion.push(key(t, z));
            }
            Phase::Lift if grasped => z += task.height,
            Phase::Place if grasped => z = 0.0,
            _ => {}
        }
        if grasped {
            t += task.duration;
            motion.push(key(t, z));
        }
        if task.phase == Phase::Release && grasped {
            break;
        }
    }
    SkillSpec {
        shape: object.shape,
        mass: object.mass,
        friction: {
            let o = scenario.target_object().expect("the grasped object");
            Friction {
                mu: o.mu,
                mu_torsion: o.mu_torsion,
            }
        },
        contact_model: ContactModel::SoftFinger,
        contacts,
        motion,
        phases: tasks.iter().map(|t| (t.phase, t.duration)).collect(),
        held_until_s: None,
    }
}
