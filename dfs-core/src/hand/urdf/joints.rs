//! A URDF's joints: the hand's DOFs (the moving joints that mimic nothing) with their limits,
//! and each joint with its drive (fixed, a DOF, or a mimic of one), axis and origin.

use super::links::pose;
use super::tree::Tree;
use super::MAX_HAND_EXTENT;
use crate::error::{DfsError, Result};
use crate::hand::{Joint, JointDrive, JointKind, MAX_HAND_DOF};
use crate::math::{UnitVector, Vector};
use std::collections::BTreeMap;

/// The hand's DOFs: the moving joints that mimic nothing, in tree order.
pub(super) struct Dofs {
    /// Each DOF's index, by its joint's name.
    pub(super) of: BTreeMap<String, usize>,
    /// Names (of their joints).
    pub(super) names: Vec<String>,
    /// Lower limits, narrowed by the joints that mimic them.
    pub(super) lower: Vec<f64>,
    /// Upper limits, narrowed likewise.
    pub(super) upper: Vec<f64>,
}

/// A joint's limits: unlimited when continuous, (0, 0) when fixed, else its `<limit>`, which
/// must be finite with lower below upper.
fn limits(joint: &urdf_rs::Joint) -> Result<(f64, f64)> {
    match joint.joint_type {
        urdf_rs::JointType::Continuous => Ok((f64::NEG_INFINITY, f64::INFINITY)),
        urdf_rs::JointType::Fixed => Ok((0.0, 0.0)),
        _ => {
            let (lo, hi) = (joint.limit.lower, joint.limit.upper);
            if !(lo.is_finite() && hi.is_finite()) || lo >= hi {
                return Err(DfsError::invalid(
                    format!("urdf joint {:?} limit", joint.name),
                    format!(
                        "lower {lo} must be below upper {hi} (a revolute or prismatic \
                         joint needs <limit lower upper>)"
                    ),
                ));
            }
            Ok((lo, hi))
        }
    }
}

/// The DOFs of the hand's subtree; more than [`MAX_HAND_DOF`] or none are refused.
pub(super) fn dofs(robot: &urdf_rs::Robot, tree: &Tree) -> Result<Dofs> {
    let mut dofs = Dofs {
        of: BTreeMap::new(),
        names: Vec::new(),
        lower: Vec::new(),
        upper: Vec::new(),
    };
    for &j in &tree.order_joints {
        let joint = &robot.joints[j];
        if joint.mimic.is_none() && !matches!(joint.joint_type, urdf_rs::JointType::Fixed) {
            let (lo, hi) = limits(joint)?;
            dofs.of.insert(joint.name.clone(), dofs.names.len());
            dofs.names.push(joint.name.clone());
            dofs.lower.push(lo);
            dofs.upper.push(hi);
        }
    }
    if dofs.names.len() > MAX_HAND_DOF {
        let reason = crate::hand::model::too_many_dofs(dofs.names.len());
        return Err(DfsError::invalid("urdf", reason));
    }
    if dofs.names.is_empty() {
        // Joints that mimic each other leave no DOF: name that cycle first.
        for &j in &tree.order_joints {
            let joint = &robot.joints[j];
            if joint.mimic.is_some() && !matches!(joint.joint_type, urdf_rs::JointType::Fixed) {
                resolve_mimic(&tree.by_name, joint)?;
            }
        }
        return Err(DfsError::invalid(
            "urdf",
            "the hand has no actuated joint (every joint of the hand's tree is fixed or \
             mimics another): it cannot close on an object",
        ));
    }
    Ok(dofs)
}

/// The joints of the hand's subtree in its order; the limits of `dofs` are narrowed so that
/// no mimic joint leaves its own range.
pub(super) fn hand_joints(
    robot: &urdf_rs::Robot,
    tree: &Tree,
    dofs: &mut Dofs,
) -> Result<Vec<Joint>> {
    let mut hand_joints = Vec::with_capacity(tree.order_joints.len());
    for &j in &tree.order_joints {
        let joint = &robot.joints[j];
        let field = || format!("urdf joint {:?}", joint.name);
        let kind = match joint.joint_type {
            urdf_rs::JointType::Revolute => JointKind::Revolute,
            urdf_rs::JointType::Continuous => JointKind::Continuous,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            _ => JointKind::Fixed,
        };
        let (lower, upper) = limits(joint)?;
        let drive = if kind == JointKind::Fixed {
            JointDrive::Fixed
        } else if joint.mimic.is_some() {
            mimic_drive(tree, joint, (lower, upper), dofs)?
        } else {
            JointDrive::Dof(dofs.of[&joint.name])
        };
        let axis = axis(joint, kind)?;
        let origin = pose(&joint.origin);
        let xyz = origin.translation.vector;
        if !(xyz.iter().all(|v| v.is_finite()) && xyz.norm() <= MAX_HAND_EXTENT) {
            return Err(DfsError::invalid(
                field(),
                format!("origin must be finite and within {MAX_HAND_EXTENT} m of its parent"),
            ));
        }
        let hand_link = |name: &str| tree.new_index[&tree.link_index[name]];
        hand_joints.push(Joint {
            name: joint.name.clone(),
            kind,
            parent: hand_link(joint.parent.link.as_str()),
            child: hand_link(joint.child.link.as_str()),
            origin,
            axis,
            lower: if kind == JointKind::Fixed { 0.0 } else { lower },
            upper: if kind == JointKind::Fixed { 0.0 } else { upper },
            drive,
        });
    }
    Ok(hand_joints)
}

/// The drive of a moving mimic `joint` with limits `(lower, upper)`: its source DOF, the
/// multiplier and the offset; the source DOF's range is narrowed to keep the joint in its own.
fn mimic_drive(
    tree: &Tree,
    joint: &urdf_rs::Joint,
    (lower, upper): (f64, f64),
    dofs: &mut Dofs,
) -> Result<JointDrive> {
    let field = || format!("urdf joint {:?}", joint.name);
    let (source, multiplier, offset) = resolve_mimic(&tree.by_name, joint)?;
    let Some(&dof) = dofs.of.get(&source) else {
        return Err(DfsError::invalid(
            field(),
            format!("mimics joint {source:?}, which is not in the hand's subtree"),
        ));
    };
    if multiplier == 0.0 {
        return Err(DfsError::invalid(field(), "mimic multiplier is 0"));
    }
    // Keep the mimic joint inside its own limits: narrow the source DOF's range.
    if lower.is_finite() || upper.is_finite() {
        let a = (lower - offset) / multiplier;
        let b = (upper - offset) / multiplier;
        dofs.lower[dof] = dofs.lower[dof].max(a.min(b));
        dofs.upper[dof] = dofs.upper[dof].min(a.max(b));
        if dofs.lower[dof] > dofs.upper[dof] {
            return Err(DfsError::invalid(
                field(),
                format!("its limits and those of {source:?} leave no common range"),
            ));
        }
    }
    Ok(JointDrive::Mimic {
        dof,
        multiplier,
        offset,
    })
}

/// The joint's unit axis. The axis is a direction, normalised as URDF readers do: scaled by
/// its largest component first, so that (0, 1e200, 0) does not overflow the norm. A fixed
/// joint's may be anything (x then); a moving joint's must be finite and non-zero.
fn axis(joint: &urdf_rs::Joint, kind: JointKind) -> Result<UnitVector> {
    let raw = Vector::from(joint.axis.xyz.0);
    let largest = raw.amax();
    if raw.iter().all(|v| v.is_finite()) && largest > 0.0 {
        Ok(UnitVector::new_normalize(raw / largest))
    } else if kind == JointKind::Fixed {
        Ok(Vector::x_axis())
    } else {
        Err(DfsError::invalid(
            format!("urdf joint {:?}", joint.name),
            "axis must be a finite, non-zero vector",
        ))
    }
}

/// The source DOF joint of a (possibly chained) mimic: (source joint name, multiplier, offset).
fn resolve_mimic(
    by_name: &BTreeMap<&str, &urdf_rs::Joint>,
    joint: &urdf_rs::Joint,
) -> Result<(String, f64, f64)> {
    let (mut mult, mut off) = (1.0, 0.0);
    let mut current = joint;
    for _ in 0..=by_name.len() {
        let Some(m) = &current.mimic else {
            return Ok((current.name.clone(), mult, off));
        };
        let Some(source) = by_name.get(m.joint.as_str()) else {
            return Err(DfsError::invalid(
                format!("urdf joint {:?} mimic", joint.name),
                format!("mimics joint {:?}, which does not exist", m.joint),
            ));
        };
        // value = a (b θ + c) + d
        let (a, d) = (m.multiplier.unwrap_or(1.0), m.offset.unwrap_or(0.0));
        if !(a.is_finite() && d.is_finite()) {
            return Err(DfsError::invalid(
                format!("urdf joint {:?} mimic", joint.name),
                "multiplier and offset must be finite",
            ));
        }
        off = a * off + d;
        mult *= a;
        if matches!(source.joint_type, urdf_rs::JointType::Fixed) {
            return Err(DfsError::invalid(
                format!("urdf joint {:?} mimic", joint.name),
                format!("mimics the fixed joint {:?}", source.name),
            ));
        }
        current = source;
    }
    Err(DfsError::invalid(
        format!("urdf joint {:?} mimic", joint.name),
        "mimic joints form a cycle",
    ))
}
