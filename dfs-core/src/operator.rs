//! The simulated operator (IP-flow 1 without a physical glove) and the closed 1 kHz loop.
//!
//! An operator wears the glove and performs a [`Scenario`]: scripted phases (`approach`,
//! `preshape`, `grasp`, `lift`, `hold`, `transport`, `place`, `release`, `retreat`). Like a
//! person it
//! - plans a grasp for the object where it lies (fingertip inverse kinematics with the hand's
//!   base free, [`plan_grasp`]);
//! - reaches with minimum-jerk profiles (Flash & Hogan 1985) of the arm (the hand base) and the
//!   fingers;
//! - holds its fingers with a joint-space impedance around its intention and adds grip torques
//!   `τ = Σ Jᵀ f` for the contact forces it wants;
//! - ramps force when loading and unloading, and grips with a safety margin over the slip
//!   limit for the friction it expects (Johansson & Westling 1984): grip force follows load;
//! - corrects the object's pose relative to its hand as it sees and feels it;
//! - has a physiological tremor (8-12 Hz) and the glove's sensors add noise, all from a seeded
//!   ChaCha8 stream: the same scenario and seed give bit-identical sessions.
//!
//! The glove's motors are taken to track the DFS's position commands exactly; the measured
//! angles are those plus sensor noise.

use crate::contact::{ContactModel, Friction, Intensity};
use crate::dfs::{Dfs, DfsParams, GloveSample, TickOutput};
use crate::error::{DfsError, Result};
use crate::grasp::{GraspMatrix, MAX_CONTACTS};
use crate::hand::ik::{solve_tips, IkParams};
use crate::hand::{HandModel, Joint, JointDrive, JointKind, Kinematics, Link, MAX_DOF, MAX_TIPS};
use crate::math::{force_of, moment_of, wrench, Isometry, Point, Real, Rotation, Vector, Wrench};
use crate::object::{ObjectState, RigidObject, Shape};
use crate::scenario::{GraspStyle, Phase, ResolvedTask, Scenario};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// A hand whose base can translate freely: three prismatic joints (world x, y, z) carry the
/// hand's root at the fixed orientation `rotation`. DOFs 0-2 are the base position, the
/// hand's DOFs follow. Used to plan grasps with the base position as unknown.
pub fn with_free_base(hand: &HandModel, rotation: Rotation) -> HandModel {
    let mut links = vec![
        Link { name: "__world".into(), inertial: Default::default() },
        Link { name: "__base_x".into(), inertial: Default::default() },
        Link { name: "__base_y".into(), inertial: Default::default() },
    ];
    let off = links.len();
    links.extend(hand.links.iter().cloned());
    let mut joints = Vec::with_capacity(hand.joints.len() + 3);
    let axes = [Vector::x_axis(), Vector::y_axis(), Vector::z_axis()];
    let children = [1, 2, hand.root + off];
    for k in 0..3 {
        joints.push(Joint {
            name: format!("__base_{}", ["x", "y", "z"][k]),
            kind: JointKind::Prismatic,
            parent: k,
            child: children[k],
            origin: if k == 2 { Isometry::from_parts(Vector::zeros().into(), rotation) } else { Isometry::identity() },
            axis: if k == 2 { rotation.inverse() * axes[2] } else { axes[k] },
            lower: -10.0,
            upper: 10.0,
            drive: JointDrive::Dof(k),
        });
    }
    for j in &hand.joints {
        let mut j = j.clone();
        j.parent += off;
        j.child += off;
        j.drive = match j.drive {
            JointDrive::Fixed => JointDrive::Fixed,
            JointDrive::Dof(d) => JointDrive::Dof(d + 3),
            JointDrive::Mimic { dof, multiplier, offset } => JointDrive::Mimic { dof: dof + 3, multiplier, offset },
        };
        joints.push(j);
    }
    let mut out = HandModel {
        name: format!("{}+free_base", hand.name),
        links,
        joints,
        root: 0,
        dof_names: ["__base_x", "__base_y", "__base_z"].iter().map(|s| s.to_string()).chain(hand.dof_names.iter().cloned()).collect(),
        dof_lower: [-10.0; 3].into_iter().chain(hand.dof_lower.iter().copied()).collect(),
        dof_upper: [10.0; 3].into_iter().chain(hand.dof_upper.iter().copied()).collect(),
        torque_limit: [100.0; 3].into_iter().chain(hand.torque_limit.iter().copied()).collect(),
        armature: [1.0; 3].into_iter().chain(hand.armature.iter().copied()).collect(),
        fingertips: hand
            .fingertips
            .iter()
            .map(|t| crate::hand::Fingertip { link: t.link + off, ..t.clone() })
            .collect(),
        finger_groups: Vec::new(),
    };
    out.compute_finger_groups();
    out
}

/// A planned grasp.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspPlan {
    /// Pose of the hand base at the grasp (world).
    pub base: Isometry,
    /// Joint angles with the chosen fingertips on the surface.
    pub q_grasp: [Real; MAX_DOF],
    /// Joint angles with those fingertips 2.5 cm off the surface (the preshape).
    pub q_pre: [Real; MAX_DOF],
    /// Open hand for approach and retreat.
    pub q_open: [Real; MAX_DOF],
    /// Which fingertips the grasp uses.
    pub tips: [bool; MAX_TIPS],
    /// Largest fingertip distance from its target (m).
    pub ik_error: Real,
    /// The style used.
    pub style: GraspStyle,
}

/// Index of a fingertip by name.
fn tip_index(hand: &HandModel, name: &str) -> Option<usize> {
    hand.fingertips.iter().position(|t| t.name == name)
}

/// Plans a grasp of `object` at `pose` with `hand` from above: the base orientation is palm
/// down with the fingers along the object's x axis; the thumb goes to the object's −x side and
/// the fingers to its +x side, at the height of the object's centre. Pinch uses thumb and index
/// (the other fingers curled away); power uses every finger. The base position is solved
/// together with the fingers by inverse kinematics; the wrist stays at zero.
pub fn plan_grasp(hand: &HandModel, object: &RigidObject, pose: &Isometry, style: GraspStyle) -> Result<GraspPlan> {
    let style = match style {
        GraspStyle::Auto => {
            if object.shape.width_x() < 0.06 {
                GraspStyle::Pinch
            } else {
                GraspStyle::Power
            }
        }
        s => s,
    };
    let thumb = tip_index(hand, "thumb").ok_or_else(|| DfsError::invalid("hand", "the operator needs a fingertip named \"thumb\""))?;
    let fingers: Vec<usize> = match style {
        GraspStyle::Pinch => ["index"].iter().filter_map(|n| tip_index(hand, n)).collect(),
        _ => ["index", "middle", "ring", "little"].iter().filter_map(|n| tip_index(hand, n)).collect(),
    };
    if fingers.is_empty() {
        return Err(DfsError::invalid("hand", "the operator needs an \"index\" fingertip"));
    }
    // Base orientation: palm down, fingers along the object's x axis (yaw only).
    let yaw = pose.rotation.euler_angles().2;
    let rot = Rotation::from_euler_angles(0.0, 0.0, yaw);
    let free = with_free_base(hand, rot);
    let n = free.dof();
    let mut kin = Kinematics::default();
    // Start: base above the object, fingers half flexed.
    let mut q0 = [0.0; MAX_DOF];
    for d in 3..n {
        q0[d] = 0.5 * (free.dof_lower[d].max(-1.0) + free.dof_upper[d].min(1.0)) * 0.8;
    }
    let wrist: Vec<usize> = hand.dof_names.iter().enumerate().filter(|(_, s)| s.starts_with("wrist")).map(|(i, _)| i + 3).collect();
    // The fingers not used curl into the palm and stay there.
    let mut frozen: Vec<usize> = wrist.clone();
    for d in 3..n {
        if hand.dof_names[d - 3].starts_with("wrist") {
            q0[d] = 0.0;
        }
    }
    if style == GraspStyle::Pinch {
        for (d, name) in hand.dof_names.iter().enumerate() {
            if ["middle", "ring", "little"].iter().any(|f| name.starts_with(f)) {
                q0[d + 3] = hand.dof_upper[d] * 0.9;
                frozen.push(d + 3);
            }
        }
    }
    let params = IkParams { max_iterations: 300, tolerance: 2e-4, ..IkParams::default() }.with_frozen(frozen.iter().copied());
    let centre = pose.translation.vector;
    let half_x = object.shape.width_x() / 2.0;
    let x_axis = rot * Vector::x();
    let y_axis = rot * Vector::y();
    let mut best: Option<(Real, [Real; MAX_DOF], Real)> = None;
    // Try a few contact heights; keep the best reachable.
    let heights: &[Real] = match object.shape {
        Shape::Sphere { radius } => &[0.0, 0.15 * radius, 0.3 * radius][..],
        Shape::Box { half_extents } => &[0.0, 0.3 * half_extents[2], -0.3 * half_extents[2]][..],
        Shape::Cylinder { half_height, .. } => &[0.3 * half_height, 0.0, 0.6 * half_height][..],
    };
    for &h in heights {
        let mut targets: Vec<(usize, Point)> = Vec::new();
        let surface_x = |y: Real| match object.shape {
            Shape::Sphere { radius } => ((radius * radius - h * h).max(0.0) - y * y).max(0.0).sqrt(),
            Shape::Cylinder { radius, .. } => (radius * radius - y * y).max(0.0).sqrt(),
            Shape::Box { .. } => half_x,
        };
        let tip_r = hand.fingertips[thumb].radius;
        targets.push((thumb, Point::from(centre - x_axis * (surface_x(0.0) + tip_r) + Vector::z() * h)));
        for (i, &f) in fingers.iter().enumerate() {
            // Spread the fingertips across y as a hand's fingers lie (≈ 2 cm apart).
            let y = if fingers.len() == 1 { 0.0 } else { 0.025 - 0.018 * i as Real };
            let y = y.clamp(-0.8 * half_x, 0.8 * half_x);
            let r = hand.fingertips[f].radius;
            targets.push((f, Point::from(centre + x_axis * (surface_x(y) + r) + y_axis * y + Vector::z() * h)));
        }
        let mut q_start = q0;
        q_start[0] = centre.x - x_axis.x * 0.05;
        q_start[1] = centre.y - x_axis.y * 0.05;
        q_start[2] = centre.z + 0.08 + h;
        let mut q = [0.0; MAX_DOF];
        let r = solve_tips(&free, &Isometry::identity(), &targets, &q_start[..n], &params, &mut kin, &mut q[..n]);
        if best.as_ref().is_none_or(|b| r.max_error < b.0) {
            best = Some((r.max_error, q, h));
        }
    }
    let (err, q, h) = best.expect("at least one height is tried");
    if err > 0.01 {
        return Err(DfsError::invalid("object", format!("no grasp of this object is reachable for the hand (fingertips {:.1} mm from the surface)", err * 1e3)));
    }
    let base = Isometry::from_parts(Vector::new(q[0], q[1], q[2]).into(), rot);
    let mut q_grasp = [0.0; MAX_DOF];
    q_grasp[..n - 3].copy_from_slice(&q[3..n]);
    // Preshape: the same tips 2.5 cm further out, base fixed.
    let mut tips = [false; MAX_TIPS];
    tips[thumb] = true;
    let mut pre_targets: Vec<(usize, Point)> = Vec::new();
    hand.forward_kinematics(&base, &q_grasp[..hand.dof()], &mut kin);
    for &f in fingers.iter().chain(std::iter::once(&thumb)) {
        tips[f] = true;
        let c = kin.tip_centres[f];
        let mut out = c.coords - centre - Vector::z() * h;
        out.z = 0.0;
        let out = if out.norm() > 1e-9 { out.normalize() } else { x_axis };
        pre_targets.push((f, Point::from(c.coords + out * 0.025)));
    }
    let mut q_pre = [0.0; MAX_DOF];
    let pre_params = IkParams { max_iterations: 200, tolerance: 5e-4, ..IkParams::default() }
        .with_frozen(frozen.iter().map(|d| d - 3));
    solve_tips(hand, &base, &pre_targets, &q_grasp[..hand.dof()], &pre_params, &mut kin, &mut q_pre[..hand.dof()]);
    let mut q_open = q_pre;
    for d in 0..hand.dof() {
        if !hand.dof_names[d].starts_with("wrist") && !frozen.contains(&(d + 3)) {
            q_open[d] = (q_pre[d] - 0.3).clamp(hand.dof_lower[d], hand.dof_upper[d]);
        }
    }
    Ok(GraspPlan { base, q_grasp, q_pre, q_open, tips, ik_error: err, style })
}
