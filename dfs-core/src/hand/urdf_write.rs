//! A hand written as URDF text with link geometry: [`hand_urdf`].
//!
//! What the URDF holds: every link with its inertial (mass, centre of mass, inertia in the link
//! frame) and its shapes ([`link_shapes`](super::link_shapes)) as both `<visual>` and
//! `<collision>`, coloured by where they come from (fingertip spheres apart); every joint with
//! its type, origin, axis, limits and mimic (a coupled joint names the joint that is its DOF).
//! Link and joint names are the model's, which are the frame ids of a session's `/tf`.
//!
//! What it leaves out, as URDF has no place for it: the fingertips (a [`HandSpec`](super::HandSpec)
//! says them), the armature. Each moving joint's `effort` is its DOF's torque limit;
//! `velocity`, which URDF requires, is [`URDF_VELOCITY_PLACEHOLDER`]: ICMS does not model joint
//! speed limits.

use super::shapes::{LinkShape, Primitive, ShapeSource};
use super::{HandModel, Joint, JointDrive, JointKind, Link};
use crate::error::{DfsError, Result};
use crate::math::{Isometry, Vector};

/// The `velocity` written in every moving joint's `<limit>` (rad/s or m/s). URDF requires the
/// attribute; ICMS has no joint speed limit, so the value limits nothing here and is large
/// beside any hand's joint speeds.
pub const URDF_VELOCITY_PLACEHOLDER: f64 = 100.0;
/// Colour (RGBA, 0-1) of a hand's link shapes in its URDF: light grey.
pub const LINK_RGBA: [f64; 4] = [0.78, 0.78, 0.76, 1.0];
/// Colour (RGBA, 0-1) of the fingertip contact spheres in a hand's URDF: green.
pub const FINGERTIP_RGBA: [f64; 4] = [0.3, 0.7, 0.35, 1.0];

fn vec3(v: &Vector) -> urdf_rs::Vec3 {
    urdf_rs::Vec3([v.x, v.y, v.z])
}

/// A URDF origin (xyz, fixed-axis roll-pitch-yaw) of an isometry.
fn origin(iso: &Isometry) -> urdf_rs::Pose {
    let (r, p, y) = iso.rotation.euler_angles();
    urdf_rs::Pose {
        xyz: vec3(&iso.translation.vector),
        rpy: urdf_rs::Vec3([r, p, y]),
    }
}

fn geometry(p: &Primitive) -> urdf_rs::Geometry {
    match *p {
        Primitive::Box { size } => urdf_rs::Geometry::Box { size: vec3(&size) },
        Primitive::Cylinder { radius, length } => urdf_rs::Geometry::Cylinder { radius, length },
        Primitive::Sphere { radius } => urdf_rs::Geometry::Sphere { radius },
    }
}

fn material(source: ShapeSource) -> urdf_rs::Material {
    let (name, rgba) = match source {
        ShapeSource::Fingertip => ("icms_fingertip", FINGERTIP_RGBA),
        ShapeSource::Urdf | ShapeSource::Generated => ("icms_link", LINK_RGBA),
    };
    urdf_rs::Material {
        name: name.to_owned(),
        color: Some(urdf_rs::Color {
            rgba: urdf_rs::Vec4(rgba),
        }),
        texture: None,
    }
}

/// `hand` as URDF text whose links carry `shapes` (shapes of links the hand does not have are
/// left out). Pure; parses back with [`HandModel::from_urdf`] (given a spec with the
/// fingertips) into the same kinematic tree, limits and inertials.
///
/// Fails ([`DfsError::Invalid`], field `urdf`) only if the XML writer refuses the model.
pub fn hand_urdf(hand: &HandModel, shapes: &[LinkShape]) -> Result<String> {
    let links = hand
        .links
        .iter()
        .enumerate()
        .map(|(l, link)| urdf_link(l, link, shapes))
        .collect();
    let joints = hand.joints.iter().map(|j| urdf_joint(hand, j)).collect();
    let robot = urdf_rs::Robot {
        name: hand.name.clone(),
        version: None,
        links,
        joints,
        materials: Vec::new(),
    };
    let body = urdf_rs::write_to_string(&robot)
        .map_err(|e| DfsError::invalid("urdf", format!("cannot be written: {e}")))?;
    Ok(format!(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<!-- Written by ICMS {}: the hand's \
         kinematics and inertials; link geometry of primitive shapes (its own URDF's where it \
         has them, else generated from the joints) and the fingertips' contact spheres. -->\n\
         {body}\n",
        env!("CARGO_PKG_VERSION")
    ))
}

/// Link `l` with its inertial, and those of `shapes` on it as both visuals and collisions.
fn urdf_link(l: usize, link: &Link, shapes: &[LinkShape]) -> urdf_rs::Link {
    let mine = shapes.iter().filter(|s| s.link == l);
    let i = &link.inertial.inertia;
    urdf_rs::Link {
        name: link.name.clone(),
        inertial: urdf_rs::Inertial {
            origin: urdf_rs::Pose {
                xyz: vec3(&link.inertial.com),
                rpy: urdf_rs::Vec3([0.0; 3]),
            },
            mass: urdf_rs::Mass {
                value: link.inertial.mass,
            },
            inertia: urdf_rs::Inertia {
                ixx: i[(0, 0)],
                ixy: i[(0, 1)],
                ixz: i[(0, 2)],
                iyy: i[(1, 1)],
                iyz: i[(1, 2)],
                izz: i[(2, 2)],
            },
        },
        visual: mine
            .clone()
            .map(|s| urdf_rs::Visual {
                name: None,
                origin: origin(&s.origin),
                geometry: geometry(&s.primitive),
                material: Some(material(s.source)),
            })
            .collect(),
        collision: mine
            .map(|s| urdf_rs::Collision {
                name: None,
                origin: origin(&s.origin),
                geometry: geometry(&s.primitive),
            })
            .collect(),
    }
}

/// Joint `j` of `hand`: its type, origin, axis, limits and mimic.
fn urdf_joint(hand: &HandModel, j: &Joint) -> urdf_rs::Joint {
    let link_name = |l: usize| hand.links.get(l).map_or("", |k| k.name.as_str()).to_owned();
    let effort = |d: usize| hand.torque_limit.get(d).copied().unwrap_or(0.0);
    let (effort, mimic) = match j.drive {
        JointDrive::Fixed => (0.0, None),
        JointDrive::Dof(d) => (effort(d), None),
        JointDrive::Mimic {
            dof,
            multiplier,
            offset,
        } => (
            effort(dof),
            Some(urdf_rs::Mimic {
                joint: dof_joint(hand, dof),
                multiplier: Some(multiplier),
                offset: Some(offset),
            }),
        ),
    };
    let (joint_type, limit) = type_and_limit(j, effort);
    urdf_rs::Joint {
        name: j.name.clone(),
        joint_type,
        origin: origin(&j.origin),
        parent: urdf_rs::LinkName {
            link: link_name(j.parent),
        },
        child: urdf_rs::LinkName {
            link: link_name(j.child),
        },
        axis: urdf_rs::Axis { xyz: vec3(&j.axis) },
        limit,
        calibration: None,
        dynamics: None,
        mimic,
        safety_controller: None,
    }
}

/// The joint that is DOF `d` of `hand` (the DOF's own name if none is).
fn dof_joint(hand: &HandModel, d: usize) -> String {
    hand.joints
        .iter()
        .find(|j| j.drive == JointDrive::Dof(d))
        .map(|j| j.name.clone())
        .or_else(|| hand.dof_names.get(d).cloned())
        .unwrap_or_default()
}

/// Joint `j`'s URDF type and limits, `effort` its DOF's torque limit.
fn type_and_limit(j: &Joint, effort: f64) -> (urdf_rs::JointType, urdf_rs::JointLimit) {
    let (joint_type, lower, upper, velocity) = match j.kind {
        JointKind::Revolute => (
            urdf_rs::JointType::Revolute,
            j.lower,
            j.upper,
            URDF_VELOCITY_PLACEHOLDER,
        ),
        JointKind::Prismatic => (
            urdf_rs::JointType::Prismatic,
            j.lower,
            j.upper,
            URDF_VELOCITY_PLACEHOLDER,
        ),
        // Unlimited: no lower and upper (the writer leaves infinite values out).
        JointKind::Continuous => (
            urdf_rs::JointType::Continuous,
            f64::NEG_INFINITY,
            f64::INFINITY,
            URDF_VELOCITY_PLACEHOLDER,
        ),
        JointKind::Fixed => (urdf_rs::JointType::Fixed, 0.0, 0.0, 0.0),
    };
    let limit = urdf_rs::JointLimit {
        lower,
        upper,
        effort,
        velocity,
        acceleration: f64::INFINITY,
        deceleration: f64::INFINITY,
        jerk: f64::INFINITY,
    };
    (joint_type, limit)
}
