//! The simulated operator (IP-flow 1 without a physical glove) and the closed 1 kHz loop.
//!
//! An operator wears the glove and performs a [`Scenario`]: scripted phases (`approach`,
//! `preshape`, `grasp`, `lift`, `hold`, `transport`, `place`, `release`, `retreat`). Like a
//! person it
//! - plans a grasp for the object where it lies ([`plan_grasp`]: fingertip inverse kinematics
//!   with the hand's base free, preferring grasps whose fingertips can push along their contact
//!   normals and the vertical);
//! - reaches with minimum-jerk profiles (Flash & Hogan 1985) of the arm (the hand base) and
//!   slides the open hand in beside the object;
//! - steers each fingertip of the grasp towards its spot on the object, closing along the
//!   normal; once touching it keeps the finger where it met the object relative to the hand;
//! - squeezes with the normal force friction needs for the load it expects (weight plus the
//!   arm's acceleration), with a safety margin for the friction it expects (Johansson &
//!   Westling 1984), ramping it up after every finger touches and down on release; friction then
//!   carries the object as the arm moves;
//! - has a physiological tremor (8-12 Hz) and the glove's sensors add noise, all from a seeded
//!   ChaCha8 stream: the same scenario and seed give bit-identical sessions.
//!
//! The glove's motors are taken to track the DFS's position commands exactly; the measured
//! angles are those plus sensor noise.

use crate::contact::{ContactModel, Friction};
use crate::dfs::{Dfs, DfsParams, GloveSample, TickOutput};
use crate::error::{DfsError, Result};
use crate::hand::ik::{solve_tips, IkParams};
use crate::hand::{HandModel, Joint, JointDrive, JointKind, Kinematics, Link, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Rotation, Vector};
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
        Link {
            name: "__world".into(),
            inertial: Default::default(),
        },
        Link {
            name: "__base_x".into(),
            inertial: Default::default(),
        },
        Link {
            name: "__base_y".into(),
            inertial: Default::default(),
        },
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
            origin: if k == 2 {
                Isometry::from_parts(Vector::zeros().into(), rotation)
            } else {
                Isometry::identity()
            },
            axis: if k == 2 {
                rotation.inverse() * axes[2]
            } else {
                axes[k]
            },
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
            JointDrive::Mimic {
                dof,
                multiplier,
                offset,
            } => JointDrive::Mimic {
                dof: dof + 3,
                multiplier,
                offset,
            },
        };
        joints.push(j);
    }
    let mut out = HandModel {
        name: format!("{}+free_base", hand.name),
        links,
        joints,
        root: 0,
        dof_names: ["__base_x", "__base_y", "__base_z"]
            .iter()
            .map(|s| s.to_string())
            .chain(hand.dof_names.iter().cloned())
            .collect(),
        dof_lower: [-10.0; 3]
            .into_iter()
            .chain(hand.dof_lower.iter().copied())
            .collect(),
        dof_upper: [10.0; 3]
            .into_iter()
            .chain(hand.dof_upper.iter().copied())
            .collect(),
        torque_limit: [100.0; 3]
            .into_iter()
            .chain(hand.torque_limit.iter().copied())
            .collect(),
        armature: [1.0; 3]
            .into_iter()
            .chain(hand.armature.iter().copied())
            .collect(),
        fingertips: hand
            .fingertips
            .iter()
            .map(|t| crate::hand::Fingertip {
                link: t.link + off,
                ..t.clone()
            })
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
    /// Joint angles with those fingertips 1.5 cm out along their contact normals (the preshape).
    pub q_pre: [Real; MAX_DOF],
    /// Open hand for approach and retreat.
    pub q_open: [Real; MAX_DOF],
    /// Which fingertips the grasp uses.
    pub tips: [bool; MAX_TIPS],
    /// Largest fingertip distance from its target (m).
    pub ik_error: Real,
    /// The style used.
    pub style: GraspStyle,
    /// Per fingertip of the grasp: the fingertip centre at the grasp, in the object frame B.
    pub contacts_b: [Vector; MAX_TIPS],
    /// Per fingertip of the grasp: the outward surface normal there, in B.
    pub normals_b: [Vector; MAX_TIPS],
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
pub fn plan_grasp(
    hand: &HandModel,
    object: &RigidObject,
    pose: &Isometry,
    style: GraspStyle,
) -> Result<GraspPlan> {
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
    let thumb = tip_index(hand, "thumb").ok_or_else(|| {
        DfsError::invalid("hand", "the operator needs a fingertip named \"thumb\"")
    })?;
    let fingers: Vec<usize> = match style {
        GraspStyle::Pinch => ["index"]
            .iter()
            .filter_map(|n| tip_index(hand, n))
            .collect(),
        // Ring and little follow the middle finger on glove10's coupled DOFs: target only the
        // independent fingers and let the others close until they touch.
        _ => ["index", "middle"]
            .iter()
            .filter_map(|n| tip_index(hand, n))
            .collect(),
    };
    if fingers.is_empty() {
        return Err(DfsError::invalid(
            "hand",
            "the operator needs an \"index\" fingertip",
        ));
    }
    let obj_yaw = pose.rotation.euler_angles().2;
    let centre = pose.translation.vector;
    let n_hand = hand.dof();
    let wrist: Vec<usize> = (0..n_hand)
        .filter(|&d| hand.dof_names[d].starts_with("wrist"))
        .collect();
    // The fingers not used curl into the palm and stay there.
    let mut frozen: Vec<usize> = Vec::new();
    let mut q_hand0 = [0.0; MAX_DOF];
    for d in 0..n_hand {
        if !wrist.contains(&d) {
            // Start from bent fingers: a stretched finger cannot push along its length.
            q_hand0[d] = hand.dof_lower[d] + 0.6 * (hand.dof_upper[d] - hand.dof_lower[d]);
        }
    }
    if style == GraspStyle::Pinch {
        for (d, name) in hand.dof_names.iter().enumerate() {
            if ["middle", "ring", "little"]
                .iter()
                .any(|f| name.starts_with(f))
            {
                q_hand0[d] = hand.dof_lower[d].max(0.0);
                frozen.push(d);
            }
        }
    }
    // Grasp axes (object frame, horizontal) and the half width of the object along them.
    let axes: &[(Real, Real)] = match object.shape {
        Shape::Box { half_extents } => &[
            (0.0, half_extents[0]),
            (std::f64::consts::FRAC_PI_2, half_extents[1]),
        ][..],
        Shape::Sphere { radius } | Shape::Cylinder { radius, .. } => &[(0.0, radius)][..],
    };
    let heights: &[Real] = match object.shape {
        Shape::Sphere { radius } => &[0.0, 0.2 * radius][..],
        Shape::Box { half_extents } => &[0.0, 0.3 * half_extents[2]][..],
        Shape::Cylinder { half_height, .. } => &[0.3 * half_height, 0.0][..],
    };
    let mut kin = Kinematics::default();
    // Best candidate: (score, ik error, q, rotation, axis, height).
    let mut best: Option<(Real, Real, [Real; MAX_DOF], Rotation, Vector, Real)> = None;
    let mut best_err = Real::INFINITY;
    // Try grasp axes × hand orientations (yaw of the palm about the vertical) × heights.
    let spreads: &[Real] = if fingers.len() > 1 {
        &[0.02, -0.02][..]
    } else {
        &[0.0][..]
    };
    for &(axis_angle, half) in axes {
        for (k, &spread) in (0..12).flat_map(|k| spreads.iter().map(move |s| (k, s))) {
            let psi = k as Real * std::f64::consts::PI / 6.0;
            let rot = Rotation::from_euler_angles(0.0, 0.0, obj_yaw + axis_angle + psi);
            // The planning model: the hand on a free base, its fingertips reduced to the ones
            // the grasp uses plus, per finger, a virtual tip 2 cm along the distal joint's axis.
            // Targeting that virtual tip beside the real one turns the finger's flexion plane
            // to contain the grasp axis: a planar finger pushes only within that plane.
            let mut free = with_free_base(hand, rot);
            let real: Vec<usize> = std::iter::once(thumb)
                .chain(fingers.iter().copied())
                .collect();
            let mut tips_free: Vec<crate::hand::Fingertip> =
                real.iter().map(|&k| free.fingertips[k].clone()).collect();
            for &f in &real {
                let tip = &hand.fingertips[f];
                let axis = hand
                    .joints
                    .iter()
                    .find(|j| j.child == tip.link)
                    .map(|j| j.axis.into_inner())
                    .unwrap_or(Vector::y());
                tips_free.push(crate::hand::Fingertip {
                    name: format!("{}__axis", tip.name),
                    link: tip.link + 3,
                    offset: tip.offset + axis * 0.02,
                    radius: tip.radius,
                });
            }
            free.fingertips = tips_free;
            free.compute_finger_groups();
            let n = free.dof();
            let a = Rotation::from_euler_angles(0.0, 0.0, obj_yaw + axis_angle) * Vector::x();
            let side = Vector::z().cross(&a);
            let params = IkParams {
                max_iterations: 150,
                tolerance: 2e-4,
                ..IkParams::default()
            }
            .with_frozen(frozen.iter().map(|d| d + 3));
            let signs = [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)];
            for (&h, (sign, thumb_sign)) in heights
                .iter()
                .flat_map(|h| signs.into_iter().map(move |s| (h, s)))
            {
                let across = |y: Real| match object.shape {
                    Shape::Sphere { radius } => (radius * radius - h * h - y * y).max(0.0).sqrt(),
                    Shape::Cylinder { radius, .. } => (radius * radius - y * y).max(0.0).sqrt(),
                    Shape::Box { .. } => half,
                };
                let mut targets: Vec<(usize, Point)> = Vec::new();
                let up = Vector::z() * h;
                let thumb_p = centre - a * (across(0.0) + hand.fingertips[thumb].radius) + up;
                targets.push((0, Point::from(thumb_p)));
                targets.push((
                    real.len(),
                    Point::from(thumb_p + side * (0.02 * thumb_sign)),
                ));
                for (i, &f) in fingers.iter().enumerate() {
                    // Fingertips side by side, about 2 cm apart, as a hand's fingers lie.
                    let y = (spread * (0.5 - i as Real)).clamp(-0.7 * half, 0.7 * half);
                    let r = hand.fingertips[f].radius;
                    let p = centre + a * (across(y) + r) + side * y + up;
                    targets.push((1 + i, Point::from(p)));
                    targets.push((real.len() + 1 + i, Point::from(p + side * (0.02 * sign))));
                }
                let mut q_start = [0.0; MAX_DOF];
                q_start[3..n].copy_from_slice(&q_hand0[..n - 3]);
                let back = rot * Vector::x() * -0.12;
                q_start[0] = centre.x + back.x;
                q_start[1] = centre.y + back.y;
                q_start[2] = centre.z + 0.05 + h;
                let mut q = [0.0; MAX_DOF];
                let r = solve_tips(
                    &free,
                    &Isometry::identity(),
                    &targets,
                    &q_start[..n],
                    &params,
                    &mut kin,
                    &mut q[..n],
                );
                best_err = best_err.min(r.max_error);
                if r.max_error > 0.008 {
                    continue;
                }
                // Prefer grasps whose fingertips can push along their contact normals: a
                // finger with few joints only pushes within the range of its Jacobian.
                free.tip_jacobians(&mut kin);
                let mut align: Real = 1.0;
                for &(tip, target) in targets.iter().filter(|(t, _)| *t < real.len()) {
                    let normal = {
                        let mut v = centre + Vector::z() * h - target.coords;
                        v.z = 0.0;
                        v.normalize()
                    };
                    // The fingertip must push along the normal and, to lift by friction, along
                    // the vertical.
                    align = align.min(push_alignment(&free, &kin, tip, &normal));
                    align = align.min(push_alignment(&free, &kin, tip, &Vector::z()));
                }
                let score = align - r.max_error * 20.0;
                if best.as_ref().is_none_or(|b| score > b.0 + 1e-9) {
                    best = Some((score, r.max_error, q, rot, a, h));
                }
            }
        }
    }
    let Some((_, err, q, rot, _axis, _h)) = best else {
        return Err(DfsError::invalid(
            "object",
            format!("no grasp of this object is reachable for the hand (fingertips {:.1} mm from the surface)", best_err * 1e3),
        ));
    };
    let n = n_hand + 3;
    let base = Isometry::from_parts(Vector::new(q[0], q[1], q[2]).into(), rot);
    let mut q_grasp = [0.0; MAX_DOF];
    q_grasp[..n - 3].copy_from_slice(&q[3..n]);
    // Preshape and open hand: the grasp pose with each finger group opened (less flexion)
    // until its fingertips are at least 1.5 cm (preshape) and 3 cm (open) off the object's
    // surface; the wrist and the fingers a pinch does not use stay as they are.
    let mut tips = [false; MAX_TIPS];
    for &f in fingers.iter().chain(std::iter::once(&thumb)) {
        tips[f] = true;
    }
    let base_pose = Isometry::from_parts(Vector::new(q[0], q[1], q[2]).into(), rot);
    let inv_obj = pose.inverse();
    let mut opened = |clearance: Real| {
        let mut out = q_grasp;
        for g in &hand.finger_groups {
            let dofs: Vec<usize> = g
                .dofs
                .iter()
                .copied()
                .filter(|d| !wrist.contains(d) && !frozen.contains(d))
                .collect();
            let mut by = 0.1;
            loop {
                let mut trial = out;
                for &d in &dofs {
                    trial[d] = (q_grasp[d] - by).clamp(hand.dof_lower[d], hand.dof_upper[d]);
                }
                hand.forward_kinematics(&base_pose, &trial[..n_hand], &mut kin);
                let clear = g.tips.iter().all(|&k| {
                    let (d, _, _) = object.shape.closest(&(inv_obj * kin.tip_centres[k]).coords);
                    d - hand.fingertips[k].radius >= clearance
                });
                out = trial;
                if clear || by > 1.5 {
                    break;
                }
                by += 0.1;
            }
        }
        out
    };
    let (fallback_pre, q_open) = (opened(0.015), opened(0.03));
    // Preshape proper: each fingertip 1.5 cm straight out from its contact along the normal,
    // wrist and base fixed, so that closing approaches every face head-on.
    hand.forward_kinematics(&base_pose, &q_grasp[..n_hand], &mut kin);
    let mut pre_targets: Vec<(usize, Point)> = Vec::new();
    for (k, _) in tips.iter().enumerate().filter(|(_, &t)| t) {
        let c = kin.tip_centres[k];
        let (_, _, n_out) = object.shape.closest(&(inv_obj * c).coords);
        pre_targets.push((k, Point::from(c.coords + (pose.rotation * n_out) * 0.015)));
    }
    let pre_params = IkParams {
        max_iterations: 200,
        tolerance: 5e-4,
        ..IkParams::default()
    }
    .with_frozen(wrist.iter().chain(frozen.iter()).copied());
    let mut q_pre = [0.0; MAX_DOF];
    let r = solve_tips(
        hand,
        &base_pose,
        &pre_targets,
        &q_grasp[..n_hand],
        &pre_params,
        &mut kin,
        &mut q_pre[..n_hand],
    );
    if r.max_error > 0.003 {
        q_pre = fallback_pre;
    }
    let mut contacts_b = [Vector::zeros(); MAX_TIPS];
    let mut normals_b = [Vector::zeros(); MAX_TIPS];
    hand.forward_kinematics(&base_pose, &q_grasp[..n_hand], &mut kin);
    for (k, _) in tips.iter().enumerate().filter(|(_, &t)| t) {
        let c_b = (inv_obj * kin.tip_centres[k]).coords;
        let (_, _, n_out) = object.shape.closest(&c_b);
        contacts_b[k] = c_b;
        normals_b[k] = n_out;
    }
    Ok(GraspPlan {
        base,
        q_grasp,
        q_pre,
        q_open,
        tips,
        ik_error: err,
        style,
        contacts_b,
        normals_b,
    })
}

/// How well fingertip `tip` can push along `dir` (unit, world): the length of the direction's
/// projection onto the well-conditioned range of the tip's linear Jacobian over its finger
/// group's DOFs (1 = fully, 0 = not at all). Directions whose singular value is below a quarter
/// of the largest do not count: joint torques cannot express a push along a stretched finger.
pub(crate) fn push_alignment(hand: &HandModel, kin: &Kinematics, tip: usize, dir: &Vector) -> Real {
    let (basis, nb) = push_basis(hand, kin, tip);
    basis
        .iter()
        .take(nb)
        .map(|b| b.dot(dir).powi(2))
        .sum::<Real>()
        .sqrt()
}

/// The directions (world, orthonormal) in which fingertip `tip` can push: eigenvectors of
/// `Σ c cᵀ` over its finger group's Jacobian columns whose eigenvalue is at least 1/16 of the
/// largest (singular value ≥ 1/4 of the largest).
fn push_basis(hand: &HandModel, kin: &Kinematics, tip: usize) -> ([Vector; 3], usize) {
    let mut out = [Vector::zeros(); 3];
    let Some(group) = hand.finger_groups.iter().find(|g| g.tips.contains(&tip)) else {
        return (out, 0);
    };
    let j = &kin.tip_jacobians[tip];
    let mut m = nalgebra::Matrix3::<Real>::zeros();
    for &d in &group.dofs {
        let c = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
        m += c * c.transpose();
    }
    let eig = nalgebra::SymmetricEigen::new(m);
    let max = eig.eigenvalues.iter().fold(0.0_f64, |a, &b| a.max(b));
    let mut nb = 0;
    if max > 0.0 {
        for k in 0..3 {
            if eig.eigenvalues[k] > max / 16.0 {
                out[nb] = eig.eigenvectors.column(k).into_owned();
                nb += 1;
            }
        }
    }
    (out, nb)
}

/// Minimum-jerk profile s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ on [0, 1] (Flash & Hogan 1985), and its
/// second derivative.
fn min_jerk(t: Real) -> (Real, Real) {
    let t = t.clamp(0.0, 1.0);
    let (t2, t3) = (t * t, t * t * t);
    (
        10.0 * t3 - 15.0 * t3 * t + 6.0 * t3 * t2,
        60.0 * t - 180.0 * t2 + 120.0 * t3,
    )
}

/// Parameters of the simulated operator. SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatorParams {
    /// Joint stiffness around the intention, as a fraction of each DOF's torque limit per
    /// radian. Default 0.5.
    pub stiffness: Real,
    /// Wrist damping (N·m·s/rad). Default 0.05. (The fingers are damped by the glove.)
    pub wrist_damping: Real,
    /// Grip safety margin over the slip limit (Johansson & Westling 1984 report 1.2-2 in
    /// people). Default 2.
    pub grip_safety: Real,
    /// Least normal force per contact while gripping (N). Default 0.5.
    pub min_normal: Real,
    /// Physiological tremor amplitude at the finger joints (rad). Default 1e-4.
    pub tremor_joint: Real,
    /// Tremor amplitude of the arm (hand base) (m). Default 5e-6.
    pub tremor_arm: Real,
    /// Standard deviation of the glove's angle sensors (rad). Default 5e-5.
    pub noise_angle: Real,
    /// Standard deviation of the glove's torque sensors (N·m). Default 2e-4.
    pub noise_torque: Real,
    /// How far past the surface the fingers aim when closing, as a fraction of the
    /// preshape-to-grasp motion. Default 0.
    pub close_overshoot: Real,
    /// Task-space stiffness steering a fingertip of the grasp towards its spot (N/m).
    /// Default 150.
    pub fingertip_stiffness: Real,
}

impl Default for OperatorParams {
    fn default() -> Self {
        OperatorParams {
            stiffness: 0.5,
            wrist_damping: 0.05,
            grip_safety: 2.0,
            min_normal: 0.5,
            tremor_joint: 1e-4,
            tremor_arm: 5e-6,
            noise_angle: 5e-5,
            noise_torque: 2e-4,
            close_overshoot: 0.0,
            fingertip_stiffness: 150.0,
        }
    }
}

/// One phase of a session's script with its time span (ns since the session's start).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseSpan {
    /// The phase.
    pub phase: Phase,
    /// Start (ns).
    pub start_ns: u64,
    /// End (ns), exclusive.
    pub end_ns: u64,
    /// The task's parameters.
    pub task: ResolvedTask,
}

/// Tick length of the closed loop (ns): 1 kHz.
pub const TICK_NS: u64 = 1_000_000;

/// The closed loop: operator → glove sample (θ, τ) → DFS tick → feedback and motor commands →
/// glove state, at 1 kHz of simulated time.
#[derive(Debug, Clone)]
pub struct Simulation {
    dfs: Dfs,
    params: OperatorParams,
    style: GraspStyle,
    spans: Vec<PhaseSpan>,
    span: usize,
    step: u64,
    n_steps: u64,
    table_height: Real,
    operator_mu: Real,
    plan: GraspPlan,
    /// The grasp phase has ended and the object is held (until release ends).
    object_held: bool,
    /// Per fingertip: the shear it feels (N), low-passed over 50 ms.
    felt_shear: [Real; MAX_TIPS],
    from_base: Isometry,
    to_base: Isometry,
    from_q: [Real; MAX_DOF],
    to_q: [Real; MAX_DOF],
    from_grip: Real,
    to_grip: Real,
    from_offset: Real,
    to_offset: Real,
    offset: Real,
    /// Where the operator saw the object when it last looked before holding it: fingertip
    /// targets are fixed to this pose until the object is held, then to the object.
    seen_object: Isometry,
    /// Per fingertip: where it first touched while holding, in the hand base's frame.
    hold_in_base: [Option<Vector>; MAX_TIPS],
    base: Isometry,
    base_acceleration: Vector,
    q_intent: [Real; MAX_DOF],
    grip: Real,
    q_meas: [Real; MAX_DOF],
    tau_meas: [Real; MAX_DOF],
    tau: [Real; MAX_DOF],
    rng: ChaCha8Rng,
    tremor_freq: [Real; MAX_DOF + 3],
    tremor_phase: [Real; MAX_DOF + 3],
}

impl Simulation {
    /// Sets up a scenario with `hand` (normally glove10). `duration_s`, when given, cuts the
    /// script short or extends its last phase. Errors name the scenario's field, or say that no
    /// grasp of the object is reachable.
    pub fn new(
        scenario: &Scenario,
        hand: HandModel,
        duration_s: Option<Real>,
    ) -> Result<Simulation> {
        let (object, tasks) = scenario.resolve()?;
        let depth = object.shape.support_depth(&Rotation::identity());
        let yaw = Rotation::from_euler_angles(0.0, 0.0, scenario.object.yaw);
        let position = scenario
            .object
            .position
            .map(Vector::from)
            .unwrap_or(Vector::new(0.0, 0.0, depth));
        let table_height = position.z - depth;
        let pose = Isometry::from_parts(position.into(), yaw);
        let mut spans = Vec::with_capacity(tasks.len());
        let mut t = 0u64;
        for task in &tasks {
            let d = (task.duration * 1e9).round() as u64 / TICK_NS * TICK_NS;
            spans.push(PhaseSpan {
                phase: task.phase,
                start_ns: t,
                end_ns: t + d.max(TICK_NS),
                task: *task,
            });
            t += d.max(TICK_NS);
        }
        let mut n_steps = t / TICK_NS;
        if let Some(d) = duration_s {
            if !(d.is_finite() && d > 0.0 && d <= 3600.0) {
                return Err(DfsError::invalid(
                    "duration",
                    format!("must be in (0, 3600] s, got {d}"),
                ));
            }
            n_steps = ((d * 1e9).round() as u64 / TICK_NS).max(1);
            let end = n_steps * TICK_NS;
            spans.retain(|s| s.start_ns < end);
            if let Some(last) = spans.last_mut() {
                last.end_ns = end;
            }
        }
        let params = DfsParams {
            // Fingertip pads are soft: they resist spin about the normal (Table 1, soft finger).
            contact_model: ContactModel::SoftFinger,
            friction: Friction {
                mu: scenario.object.mu,
                mu_torsion: scenario.object.mu_torsion,
            },
            table_height: Some(table_height),
            ..DfsParams::default()
        };
        let plan = plan_grasp(&hand, &object, &pose, scenario.grasp)?;
        let start_base = raise(&approach_pose(&plan.base, &object.shape), 0.15);
        let q0 = plan.q_open;
        let mut dfs = Dfs::new(hand, object, ObjectState::at_rest(pose), params)?;
        let n = dfs.hand().dof();
        let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
        let mut tremor_freq = [0.0; MAX_DOF + 3];
        let mut tremor_phase = [0.0; MAX_DOF + 3];
        for i in 0..MAX_DOF + 3 {
            tremor_freq[i] = 8.0 + 4.0 * rand::Rng::random::<Real>(&mut rng);
            tremor_phase[i] = std::f64::consts::TAU * rand::Rng::random::<Real>(&mut rng);
        }
        let zeros = [0.0; MAX_DOF];
        dfs.step(&GloveSample {
            q: &q0[..n],
            tau: &zeros[..n],
            base: start_base,
        })?;
        dfs.set_object_state(ObjectState::at_rest(pose));
        let operator_mu = scenario.operator_mu.unwrap_or(scenario.object.mu).max(1e-3);
        let mut sim = Simulation {
            dfs,
            params: OperatorParams::default(),
            style: scenario.grasp,
            spans,
            span: 0,
            step: 0,
            n_steps,
            table_height,
            operator_mu,
            plan,
            object_held: false,
            felt_shear: [0.0; MAX_TIPS],
            from_base: start_base,
            to_base: start_base,
            from_q: q0,
            to_q: q0,
            from_grip: 0.0,
            to_grip: 0.0,
            from_offset: 0.03,
            to_offset: 0.03,
            offset: 0.03,
            seen_object: pose,
            hold_in_base: [None; MAX_TIPS],
            base: start_base,
            base_acceleration: Vector::zeros(),
            q_intent: q0,
            grip: 0.0,
            q_meas: q0,
            tau_meas: [0.0; MAX_DOF],
            tau: [0.0; MAX_DOF],
            rng,
            tremor_freq,
            tremor_phase,
        };
        sim.begin_phase()?;
        Ok(sim)
    }

    /// The phases of the script with their time spans: the ground truth of the session.
    pub fn phases(&self) -> &[PhaseSpan] {
        &self.spans
    }

    /// The DFS (hand, object, last tick's output and kinematics).
    pub fn dfs(&self) -> &Dfs {
        &self.dfs
    }

    /// Time of the last tick (ns since the start).
    pub fn time_ns(&self) -> u64 {
        self.step.saturating_sub(1) * TICK_NS
    }

    /// Number of ticks done.
    pub fn ticks(&self) -> u64 {
        self.step
    }

    /// Total number of ticks.
    pub fn total_ticks(&self) -> u64 {
        self.n_steps
    }

    /// The phase of the last tick.
    pub fn phase(&self) -> Phase {
        self.spans[self.span.min(self.spans.len() - 1)].phase
    }

    /// The glove sample of the last tick: measured angles, measured operator torques, and the
    /// hand base pose.
    pub fn sample(&self) -> (&[Real], &[Real], &Isometry) {
        let n = self.dfs.hand().dof();
        (&self.q_meas[..n], &self.tau_meas[..n], &self.base)
    }

    /// The operator's intended joint angles at the last tick.
    pub fn intention(&self) -> &[Real] {
        &self.q_intent[..self.dfs.hand().dof()]
    }

    /// The last tick's DFS output.
    pub fn output(&self) -> &TickOutput {
        self.dfs.output()
    }

    /// The table's height (m, world z).
    pub fn table_height(&self) -> Real {
        self.table_height
    }

    /// The grasp style in use.
    pub fn style(&self) -> GraspStyle {
        self.plan.style.max_style(self.style)
    }

    /// Runs one tick. Returns `Ok(false)` when the script is over.
    pub fn step(&mut self) -> Result<bool> {
        if self.step >= self.n_steps {
            return Ok(false);
        }
        let t = self.step * TICK_NS;
        while self.span + 1 < self.spans.len() && t >= self.spans[self.span].end_ns {
            self.end_phase();
            self.span += 1;
            self.begin_phase()?;
        }
        self.update_intention(t);
        self.compute_torques();
        self.measure();
        let n = self.dfs.hand().dof();
        let (q, tau) = (self.q_meas, self.tau_meas);
        self.dfs.step(&GloveSample {
            q: &q[..n],
            tau: &tau[..n],
            base: self.base,
        })?;
        self.step += 1;
        Ok(true)
    }

    fn span_now(&self) -> &PhaseSpan {
        &self.spans[self.span]
    }

    fn end_phase(&mut self) {
        if self.span_now().phase == Phase::Grasp {
            self.object_held = true;
        }
        if self.span_now().phase == Phase::Release {
            self.object_held = false;
        }
    }

    /// Sets the targets of the phase that starts now, from where the hand and object are.
    fn begin_phase(&mut self) -> Result<()> {
        let task = self.span_now().task;
        self.from_base = self.to_base;
        self.from_q = self.to_q;
        self.from_grip = self.to_grip;
        self.from_offset = self.to_offset;
        self.seen_object = self.dfs.object_state().pose;
        let n = self.dfs.hand().dof();
        match task.phase {
            Phase::Approach => {
                let pose = self.dfs.object_state().pose;
                self.plan = plan_grasp(self.dfs.hand(), self.dfs.object(), &pose, self.style)?;
                self.to_base = approach_pose(&self.plan.base, &self.dfs.object().shape);
                self.to_q = self.plan.q_open;
                self.to_grip = 0.0;
                self.to_offset = 0.03;
                self.object_held = false;
            }
            Phase::Preshape => {
                self.to_base = self.plan.base;
                self.to_q = self.plan.q_pre;
                self.to_offset = 0.015;
            }
            Phase::Grasp => {
                let mut q = self.plan.q_grasp;
                for d in 0..n {
                    let delta = self.plan.q_grasp[d] - self.plan.q_pre[d];
                    let hand = self.dfs.hand();
                    q[d] = (q[d] + self.params.close_overshoot * delta)
                        .clamp(hand.dof_lower[d], hand.dof_upper[d]);
                }
                self.to_q = q;
                self.to_grip = 1.0;
                // Aim a little inside the surface, as a person presses on what they hold.
                self.to_offset = -0.002;
            }
            Phase::Lift => {
                self.to_base = raise(&self.from_base, task.height);
            }
            Phase::Hold => {}
            Phase::Transport => {
                let centre = self.dfs.object_state().pose.translation.vector;
                let turn = Rotation::from_euler_angles(0.0, 0.0, task.turn);
                let b = self.from_base;
                let p = centre + turn * (b.translation.vector - centre) + Vector::from(task.offset);
                self.to_base = Isometry::from_parts(p.into(), turn * b.rotation);
            }
            Phase::Place => {
                let obj = self.dfs.object_state().pose;
                let depth = self.dfs.object().shape.support_depth(&obj.rotation);
                let dz = self.table_height + depth - obj.translation.z - 0.002;
                self.to_base = raise(&self.from_base, dz);
            }
            Phase::Release => {
                self.to_q = self.plan.q_pre;
                self.to_grip = 0.0;
                self.to_offset = 0.015;
            }
            Phase::Retreat => {
                self.to_base = raise(&self.from_base, 0.10);
                self.to_q = self.plan.q_open;
                self.to_grip = 0.0;
                self.to_offset = 0.03;
            }
        }
        Ok(())
    }

    fn update_intention(&mut self, t: u64) {
        let span = *self.span_now();
        let dur = (span.end_ns - span.start_ns) as Real * 1e-9;
        let s = ((t - span.start_ns) as Real * 1e-9 / dur).clamp(0.0, 1.0);
        let (m, m2) = min_jerk(s);
        // Fingers and grip: in `grasp` the fingers close first and the grip ramps up after; in
        // `release` the grip ramps down first and the fingers open after.
        let (sq, sg) = match span.phase {
            Phase::Grasp => ((s / 0.6).min(1.0), ((s - 0.5) / 0.5).max(0.0)),
            Phase::Release => (((s - 0.4) / 0.6).max(0.0), (s / 0.4).min(1.0)),
            _ => (s, s),
        };
        let (mq, _) = min_jerk(sq);
        let (mg, _) = min_jerk(sg);
        let dp = self.to_base.translation.vector - self.from_base.translation.vector;
        let p = self.from_base.translation.vector + dp * m;
        let r = self.from_base.rotation.slerp(&self.to_base.rotation, m);
        let time = t as Real * 1e-9;
        let mut tremor = Vector::zeros();
        for (k, c) in tremor.iter_mut().enumerate() {
            let i = MAX_DOF + k;
            *c = self.params.tremor_arm
                * (std::f64::consts::TAU * self.tremor_freq[i] * time + self.tremor_phase[i]).sin();
        }
        let new_base = Isometry::from_parts((p + tremor).into(), r);
        self.base_acceleration = dp * (m2 / (dur * dur));
        self.base = new_base;
        let n = self.dfs.hand().dof();
        for d in 0..n {
            let tr = self.params.tremor_joint
                * (std::f64::consts::TAU * self.tremor_freq[d] * time + self.tremor_phase[d]).sin();
            self.q_intent[d] = self.from_q[d] + (self.to_q[d] - self.from_q[d]) * mq + tr;
        }
        self.grip = self.from_grip + (self.to_grip - self.from_grip) * mg;
        self.offset = self.from_offset + (self.to_offset - self.from_offset) * mq;
    }

    /// The operator's joint torques: impedance around the intention plus grip torques `Jᵀ f`
    /// for the contact forces it wants.
    fn compute_torques(&mut self) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let kin = self.dfs.kinematics();
        let q = &out.motor_q;
        let qd = &out.motor_qd;
        let obj_pose = if self.object_held {
            self.dfs.object_state().pose
        } else {
            self.seen_object
        };
        // The fingers of the grasp are steered in task space: each fingertip towards a point
        // on the object (in the object's frame, so it follows the object), `offset` out along
        // the surface normal, like a person reaching for a spot they see; closing makes the
        // offset zero, approaching every face head-on. The other joints (wrist, unused
        // fingers) hold the intended joint angles.
        let mut in_grasp = [false; MAX_DOF];
        let mut tau = [0.0; MAX_DOF];
        for g in &hand.finger_groups {
            if !g.tips.iter().any(|&k| self.plan.tips[k]) {
                continue;
            }
            for &d in &g.dofs {
                in_grasp[d] = true;
            }
            for &k in g.tips.iter().filter(|&&k| self.plan.tips[k]) {
                let touching = out.tips[k].touching;
                let holding = matches!(
                    self.phase(),
                    Phase::Grasp | Phase::Lift | Phase::Hold | Phase::Transport | Phase::Place
                );
                // Touching while holding, a person keeps the finger where it met the object
                // relative to the hand; the squeeze presses it on.
                if holding && touching && self.hold_in_base[k].is_none() {
                    self.hold_in_base[k] = Some((self.base.inverse() * kin.tip_centres[k]).coords);
                }
                if !holding {
                    self.hold_in_base[k] = None;
                }
                let target = match self.hold_in_base[k] {
                    Some(h) => self.base * Point::from(h),
                    None => {
                        obj_pose
                            * Point::from(
                                self.plan.contacts_b[k] + self.plan.normals_b[k] * self.offset,
                            )
                    }
                };
                let mut err = target - kin.tip_centres[k];
                let e = err.norm();
                if e > 0.03 {
                    err *= 0.03 / e;
                }
                let f = err * self.params.fingertip_stiffness;
                let j = &kin.tip_jacobians[k];
                for &d in &g.dofs {
                    tau[d] += j[(0, d)] * f.x + j[(1, d)] * f.y + j[(2, d)] * f.z;
                }
            }
        }
        for d in 0..n {
            if in_grasp[d] {
                continue;
            }
            let kp = self.params.stiffness * hand.torque_limit[d];
            let kd = if hand.dof_names[d].starts_with("wrist") {
                self.params.wrist_damping
            } else {
                0.0
            };
            tau[d] += kp * (self.q_intent[d] - q[d]) - kd * qd[d];
        }
        let alpha = (TICK_NS as Real * 1e-9 / 0.05).min(1.0);
        for k in 0..out.n_tips.min(MAX_TIPS) {
            let c = out.tips[k].transmitted;
            let shear = (c[0] * c[0] + c[1] * c[1]).sqrt();
            self.felt_shear[k] += (shear - self.felt_shear[k]) * alpha;
        }
        if self.grip > 0.0 {
            self.add_grip_torques(&mut tau);
        }
        for d in 0..n {
            let lim = 1.9 * hand.torque_limit[d];
            self.tau[d] = tau[d].clamp(-lim, lim);
        }
    }

    /// Grip torques: the operator squeezes, pressing each fingertip of the grasp along the
    /// contact normal with the force friction needs to carry the load it expects (weight plus
    /// the hand's acceleration) with its safety margin, for the friction it expects. Friction
    /// then carries the object as the arm moves (the DFS's stick friction), as in a person's
    /// grip; a squeeze too weak for the real μ lets the object slip.
    fn add_grip_torques(&self, tau: &mut [Real; MAX_DOF]) {
        let out = self.dfs.output();
        let obj = self.dfs.object();
        let st = self.dfs.object_state();
        let g = self.dfs.params().gravity;
        let kin = self.dfs.kinematics();
        let hand = self.dfs.hand();
        let p = &self.params;
        let planned = self
            .plan
            .tips
            .iter()
            .take(out.n_tips)
            .filter(|&&t| t)
            .count();
        // Fixed-capacity lists: this runs every tick of a session.
        let mut touching = [0usize; MAX_TIPS];
        let mut nt = 0;
        for k in 0..out.n_tips.min(MAX_TIPS) {
            if self.plan.tips[k] && out.tips[k].frame.is_some() {
                touching[nt] = k;
                nt += 1;
            }
        }
        let touching = &touching[..nt];
        // Squeeze only once every finger of the grasp is on the object.
        if touching.is_empty() || touching.len() < planned {
            return;
        }
        let load = ((self.base_acceleration - g) * obj.mass).norm();
        let normal = (p.grip_safety * load / (self.operator_mu * touching.len() as Real))
            .max(p.min_normal)
            * self.grip;
        // Per fingertip: the force for a unit normal push, along what it can push.
        let mut unit = [Vector::zeros(); MAX_TIPS];
        let mut ok = [false; MAX_TIPS];
        for &k in touching {
            let Some(frame) = out.tips[k].frame else {
                continue;
            };
            let n_in = st.pose.rotation * frame.normal_b();
            let (basis, nb) = push_basis(hand, kin, k);
            let mut dir = Vector::zeros();
            for b in basis.iter().take(nb) {
                dir += b * b.dot(&n_in);
            }
            let along = dir.dot(&n_in);
            if along >= 0.2 {
                unit[k] = dir / along;
                ok[k] = true;
            }
        }
        // Normal forces near the wanted squeeze with little net force: minimise
        // ‖N − N₀‖² + w ‖Σ N_k unit_k‖² (w = 4), i.e. N = (I + w AᵀA)⁻¹ N₀. An exactly
        // force-free squeeze rarely exists for two or three fingertips that push only in their
        // own planes; the stick friction absorbs the small remainder.
        let mut ks = [0usize; MAX_TIPS];
        let mut m = 0;
        for &k in touching.iter().filter(|&&k| ok[k]) {
            ks[m] = k;
            m += 1;
        }
        let mut sys = nalgebra::SMatrix::<Real, MAX_TIPS, MAX_TIPS>::identity();
        // Each fingertip's squeeze also follows the shear it feels (per-digit grip control,
        // Edin, Westling & Johansson 1992): at least the safety margin over its own shear, felt
        // with a 50 ms lag.
        let mut wanted = [normal; MAX_TIPS];
        for (idx, &k) in ks.iter().enumerate().take(m) {
            wanted[idx] =
                normal.max(p.grip_safety * self.felt_shear[k] / self.operator_mu * self.grip);
        }
        let mut mags = wanted;
        for a in 0..m {
            for b in 0..m {
                sys[(a, b)] += 4.0 * unit[ks[a]].dot(&unit[ks[b]]);
            }
        }
        if !crate::math::cholesky_solve_in_place(&mut sys, m, &mut mags) {
            mags = wanted;
        }
        let n = hand.dof();
        for (idx, &k) in ks.iter().enumerate().take(m) {
            let magnitude = mags[idx].max(p.min_normal * self.grip);
            let f = unit[k] * magnitude;
            let j = &kin.tip_jacobians[k];
            for (d, t) in tau.iter_mut().enumerate().take(n) {
                *t += j[(0, d)] * f.x + j[(1, d)] * f.y + j[(2, d)] * f.z;
            }
        }
    }

    fn measure(&mut self) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let na = Normal::new(0.0, self.params.noise_angle.max(0.0)).expect("finite σ");
        let nt = Normal::new(0.0, self.params.noise_torque.max(0.0)).expect("finite σ");
        for d in 0..n {
            let q = out.motor_q[d] + na.sample(&mut self.rng);
            self.q_meas[d] = q.clamp(hand.dof_lower[d] - 0.01, hand.dof_upper[d] + 0.01);
            self.tau_meas[d] = self.tau[d] + nt.sample(&mut self.rng);
        }
    }
}

impl GraspStyle {
    fn max_style(self, requested: GraspStyle) -> GraspStyle {
        if self == GraspStyle::Auto {
            requested
        } else {
            self
        }
    }
}

/// Where the hand waits before closing in: beside the grasp pose along the palm's y axis (the
/// fingertips close in the palm's x-z plane, so sliding along y brings them around the
/// object without touching it), by the object's size plus 5 cm, and 1 cm higher.
fn approach_pose(grasp_base: &Isometry, shape: &Shape) -> Isometry {
    let side = grasp_base.rotation * Vector::y() * (shape.bounding_radius() + 0.05);
    let mut x = *grasp_base;
    x.translation.vector += side + Vector::z() * 0.01;
    x
}

/// The pose raised by `dz` (m) along world z.
fn raise(x: &Isometry, dz: Real) -> Isometry {
    let mut y = *x;
    y.translation.vector.z += dz;
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(name: &str, seed: u64) -> (Simulation, Vec<(Phase, Real, bool, usize)>) {
        let s = Scenario::builtin(name, seed).unwrap();
        let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        let mut trace = Vec::new();
        while sim.step().unwrap() {
            let o = sim.output();
            let slip = o.tips.iter().take(o.n_tips).any(|t| t.in_contact && t.slip);
            trace.push((
                sim.phase(),
                sim.dfs().object_state().pose.translation.z,
                slip,
                o.n_contacts,
            ));
        }
        (sim, trace)
    }

    #[test]
    fn a_pinch_lift_carries_the_box_off_the_table_and_sets_it_down() {
        let (_, trace) = run("box-pinch-lift", 1);
        let start = trace[0].1;
        let lifted = trace
            .iter()
            .filter(|t| t.0 == Phase::Hold)
            .map(|t| t.1)
            .fold(0.0, Real::max);
        assert!(
            lifted > start + 0.05,
            "box rose only to {lifted} from {start}"
        );
        let end = trace.last().unwrap().1;
        assert!(
            (end - start).abs() < 0.01,
            "the box is back on the table: {end}"
        );
        assert_eq!(trace.last().unwrap().3, 0, "released");
    }

    #[test]
    fn the_same_scenario_and_seed_give_identical_sessions() {
        let a = run("box-pinch-lift", 7).1;
        let b = run("box-pinch-lift", 7).1;
        assert!(a
            .iter()
            .zip(&b)
            .all(|(x, y)| x.1.to_bits() == y.1.to_bits() && x.2 == y.2 && x.3 == y.3));
        let c = run("box-pinch-lift", 8).1;
        assert!(
            a.iter()
                .zip(&c)
                .any(|(x, y)| x.1.to_bits() != y.1.to_bits()),
            "seeds change the noise"
        );
    }

    #[test]
    fn box_slip_shows_slip_and_the_box_leaves_the_grasp() {
        let (sim, trace) = run("box-slip", 3);
        assert!(trace.iter().any(|t| t.2), "slip flags");
        let last_hold = trace.iter().rfind(|t| t.0 == Phase::Hold).unwrap();
        assert_eq!(
            last_hold.3, 0,
            "no contact left while the hand holds up high"
        );
        let table = sim.table_height();
        assert!(
            last_hold.1 < table + 0.05,
            "the box stayed down: {}",
            last_hold.1
        );
    }

    #[test]
    fn every_builtin_scenario_plans_a_grasp_and_runs_its_first_second() {
        for name in Scenario::BUILTINS {
            let s = Scenario::builtin(name, 0).unwrap();
            let mut sim = Simulation::new(&s, HandModel::glove10(), Some(1.0)).unwrap();
            while sim.step().unwrap() {}
            assert_eq!(sim.ticks(), 1000, "{name}");
            assert!(sim.phases().iter().all(|p| p.end_ns <= 1_000_000_000));
        }
    }

    #[test]
    fn a_duration_out_of_range_is_refused() {
        let s = Scenario::builtin("box-pinch-lift", 0).unwrap();
        let e = Simulation::new(&s, HandModel::glove10(), Some(-1.0)).unwrap_err();
        assert!(e.to_string().contains("duration"));
    }
}
