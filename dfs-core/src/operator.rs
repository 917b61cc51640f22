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
//!
//! # Varied reaches
//!
//! By default every seed reaches alike: the hand starts 0.15 m straight above its approach
//! pose (beside the target, where it waits before sliding in) and goes straight down to it in
//! the script's durations; only the tremor and the sensor noise differ. A scenario with
//! `vary_reach` varies the reaches by its seed, from a ChaCha8 stream of their own
//! ([`REACH_STREAM`]; the tremor and the noise are those of the same seed without it):
//! - the hand starts at a *home* [`REACH_HOME_M`] from the first approach pose, in a direction
//!   up to ±90° ([`REACH_HOME_AZIMUTH`]) about the horizontal one pointing from the target to
//!   the approach pose (the side the hand comes from) and [`REACH_HOME_ELEVATION`] above the
//!   horizontal, its palm turned up to ±[`REACH_HOME_YAW`] about the vertical from its grasp
//!   orientation;
//! - each `approach` bends off the straight line by `b sin(π u)` for the path parameter `u`
//!   (a minimum-jerk profile in time), `b` perpendicular to the line, pointing sideways or up
//!   (never down), of up to [`REACH_BEND`] of the length: zero at both ends, with continuous
//!   velocity and acceleration;
//! - its speed is scaled by `s` in [`REACH_SPEED`]: the `approach` and the `preshape` after it
//!   take their durations / `s`;
//! - with chance [`REACH_PAUSE_CHANCE`] it pauses [`REACH_PAUSE_S`] part-way
//!   ([`REACH_PAUSE_AT`] of the path): two minimum-jerk moves with a rest between them, all in
//!   `approach` (the ground truth, [`Simulation::phases`], holds the changed durations).
//!
//! The fingers of the grasp keep the open hand's posture over the first
//! [`REACH_SHAPE_FROM`] of a varied reach's path, then reach for their spots on the object.
//! Homes and bends are checked against the table and the objects: along the path the open
//! hand (its fingertips, joints and the middles of its segments) keeps [`REACH_CLEARANCE_M`]
//! from both, or at least what it keeps at the path's ends; a home is redrawn (up to 16 times,
//! then the fixed start above the approach pose is used) and a bend redrawn smaller (up to 8
//! times, then the straight line) until it does.
//!
//! In a scene of several objects ([`Scene`]) the operator plans, reaches for, squeezes and
//! carries the scenario's `target` only; the other objects stay on the table as obstacles,
//! simulated like it (a fingertip or the carried object that bumps one moves it or passes
//! into it: that is physics, and the DFS reports an overlap). A fingertip on another object
//! does not count as touching the target.

use crate::contact::ContactModel;
use crate::dfs::DfsObject;
use crate::dfs::{Dfs, DfsParams, GloveSample, TickOutput};
use crate::error::{DfsError, Result};
use crate::hand::ik::{solve_tips, IkParams};
use crate::hand::{HandModel, Joint, JointDrive, JointKind, Kinematics, Link, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Rotation, Vector};
use crate::object::{ObjectState, RigidObject, Shape};
use crate::scenario::{GraspStyle, Phase, ResolvedTask, Scenario, Scene, MAX_SCRIPT_S, MIN_TASK_S};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

pub mod power;
use power::{plan_wrap, PowerGrip, Wrap};

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
        contact_shapes: Vec::new(),
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
    /// Per fingertip of the grasp: how well it can push along its contact normal at the grasp,
    /// the cosine of the angle between the inward normal and the nearest direction the
    /// fingertip can push in (1 = straight along the normal).
    pub normal_alignment: [Real; MAX_TIPS],
    /// A power grasp that wraps the hand around the object ([`power::plan_wrap`]): the palm,
    /// phalanges and fingertips hold it (whole-hand contact), the fingers close by torque
    /// rather than to spots, so `q_grasp`, `q_pre` and `q_open` are all the open hand and the
    /// per-fingertip `contacts_b`, `normals_b` and `normal_alignment` are zero. `None`: a
    /// fingertip grasp.
    pub wrap: Option<Wrap>,
}

/// Index of a fingertip by name.
fn tip_index(hand: &HandModel, name: &str) -> Option<usize> {
    hand.fingertips.iter().position(|t| t.name == name)
}

/// Plans a grasp of `object` at `pose` with `hand` from above: the base orientation is palm
/// down with the fingers along the object's x axis; the thumb goes to the object's −x side and
/// the fingers to its +x side, at the height of the object's centre. Pinch uses thumb and index
/// (the other fingers curled away); power uses every finger. The base position is solved
/// together with the fingers and the wrist by inverse kinematics.
///
/// In a power grasp each fingertip goes where its own flexion plane meets the object: the
/// fingers push only within those planes (eq. 14 transmits only forces in the range of Jᵀ), and
/// a hand's planes lie side by side, fixed by its anatomy (glove10: the thumb's 8 mm radial of
/// the index's, the middle finger's 2 cm ulnar of it). The object's axis goes midway between
/// the thumb's and the index's planes, so the two oppose each other across it and push along
/// their contact normals; the other fingers meet a curved surface where it turns away from
/// their planes, and only rest on it where it turns too far ([`GraspPlan::normal_alignment`]).
pub fn plan_grasp(
    hand: &HandModel,
    object: &RigidObject,
    pose: &Isometry,
    style: GraspStyle,
) -> Result<GraspPlan> {
    // Within capacity, with room for the free base the search adds.
    hand.validate()?;
    let style = resolve_style(style, object);
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
            let (lo, hi) = hand.sweep_range(d);
            q_hand0[d] = lo + 0.6 * (hi - lo);
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
    // Above the centre of mass: an object hangs from the line through two opposing contacts
    // like a pendulum, stable only below it (a soft pad resists spin about its normal only
    // viscously, so an object pinched below its centre slowly rolls out).
    let heights: &[Real] = match object.shape {
        Shape::Sphere { radius } => &[0.35 * radius, 0.25 * radius][..],
        Shape::Box { half_extents } => &[0.4 * half_extents[2], 0.25 * half_extents[2]][..],
        Shape::Cylinder { half_height, .. } => &[0.3 * half_height, 0.0][..],
    };
    let mut kin = Kinematics::default();
    // Power: where each fingertip's flexion plane lies across the hand (m, along the index's
    // distal joint axis in the hand's base frame at the start posture), relative to the middle
    // between the thumb's and the index's planes.
    let power = style == GraspStyle::Power;
    let mut lateral = [0.0; MAX_TIPS];
    if power {
        hand.forward_kinematics(&Isometry::identity(), &q_hand0[..n_hand], &mut kin);
        let index = fingers[0];
        let axis = hand
            .joints
            .iter()
            .find(|j| j.child == hand.fingertips[index].link)
            .map(|j| kin.link_poses[j.child].rotation * j.axis.into_inner())
            .unwrap_or(Vector::y());
        for &k in std::iter::once(&thumb).chain(&fingers) {
            lateral[k] = kin.tip_centres[k].coords.dot(&axis);
        }
        let mid = 0.5 * (lateral[thumb] + lateral[index]);
        for v in lateral.iter_mut() {
            *v -= mid;
        }
    }
    // Best candidate: (score, ik error, q, rotation, axis, height).
    let mut best: Option<(Real, Real, [Real; MAX_DOF], Rotation, Vector, Real)> = None;
    let mut best_err = Real::INFINITY;
    // Try grasp axes × hand orientations (yaw of the palm about the vertical) × heights.
    let spreads: &[Real] = if fingers.len() > 1 && !power {
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
                // Power: the flexion planes are parallel, so the thumb's axis points the
                // same way as the fingers'.
                if power && sign != thumb_sign {
                    continue;
                }
                let across = |y: Real| match object.shape {
                    Shape::Sphere { radius } => (radius * radius - h * h - y * y).max(0.0).sqrt(),
                    Shape::Cylinder { radius, .. } => (radius * radius - y * y).max(0.0).sqrt(),
                    Shape::Box { .. } => half,
                };
                // Where fingertip `k` of radius `r` meets the surface at `y` across the grasp
                // axis, along the axis from the centre: a power grasp puts the fingertip's
                // centre on the cylinder's surface grown by its radius, off the axis line too.
                let reach = |y: Real, r: Real| match object.shape {
                    Shape::Cylinder { radius, .. } if power => {
                        ((radius + r) * (radius + r) - y * y).max(0.0).sqrt()
                    }
                    _ => across(y) + r,
                };
                let mut targets: Vec<(usize, Point)> = Vec::new();
                let up = Vector::z() * h;
                let thumb_y = sign * lateral[thumb];
                let thumb_p = centre - a * reach(thumb_y, hand.fingertips[thumb].radius)
                    + side * thumb_y
                    + up;
                targets.push((0, Point::from(thumb_p)));
                targets.push((
                    real.len(),
                    Point::from(thumb_p + side * (0.02 * thumb_sign)),
                ));
                for (i, &f) in fingers.iter().enumerate() {
                    // Pinch: the fingertip opposite the thumb. Power: each fingertip in its
                    // own flexion plane.
                    let y = if power {
                        sign * lateral[f]
                    } else {
                        (spread * (0.5 - i as Real)).clamp(-0.7 * half, 0.7 * half)
                    };
                    let r = hand.fingertips[f].radius;
                    let p = centre + a * reach(y, r) + side * y + up;
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
                // The thumb and the finger opposite it squeeze: they must push along their
                // normals. To lift by friction, the thumb must push along the vertical, and so
                // must a finger on the other side (a pinch: both).
                let (mut along_normal, mut thumb_up, mut finger_up): (Real, Real, Real) =
                    (1.0, 1.0, 0.0);
                for &(tip, target) in targets.iter().filter(|(t, _)| *t < real.len()) {
                    let normal = {
                        let mut v = centre + Vector::z() * h - target.coords;
                        v.z = 0.0;
                        v.normalize()
                    };
                    let up = push_alignment(&free, &kin, tip, &Vector::z());
                    if tip <= 1 {
                        along_normal = along_normal.min(push_alignment(&free, &kin, tip, &normal));
                    }
                    if tip == 0 {
                        thumb_up = up;
                    } else {
                        finger_up = finger_up.max(up);
                    }
                }
                let align = along_normal.min(thumb_up).min(finger_up);
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
    let mut normal_alignment = [0.0; MAX_TIPS];
    hand.forward_kinematics(&base_pose, &q_grasp[..n_hand], &mut kin);
    hand.tip_jacobians(&mut kin);
    for (k, _) in tips.iter().enumerate().filter(|(_, &t)| t) {
        let c_b = (inv_obj * kin.tip_centres[k]).coords;
        let (_, _, n_out) = object.shape.closest(&c_b);
        contacts_b[k] = c_b;
        normals_b[k] = n_out;
        normal_alignment[k] = push_alignment(hand, &kin, k, &-(pose.rotation * n_out));
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
        normal_alignment,
        wrap: None,
    })
}

/// The style `style` takes for `object`: `auto` is a pinch for objects narrower than 6 cm
/// along x, else a power grasp.
fn resolve_style(style: GraspStyle, object: &RigidObject) -> GraspStyle {
    match style {
        GraspStyle::Auto if object.shape.width_x() < 0.06 => GraspStyle::Pinch,
        GraspStyle::Auto => GraspStyle::Power,
        s => s,
    }
}

/// The operator's grasp of `object` at `pose` in `style`, clear of `obstacles`: a power grasp
/// of a standing cylinder by a hand with a palm contact shape wraps the hand around it
/// ([`power::plan_wrap`], whole-hand contact); any other grasp is a fingertip grasp
/// ([`plan_grasp`]).
pub fn plan_operator_grasp(
    hand: &HandModel,
    object: &RigidObject,
    pose: &Isometry,
    style: GraspStyle,
    obstacles: &[(RigidObject, Isometry)],
) -> Result<GraspPlan> {
    if resolve_style(style, object) == GraspStyle::Power {
        let mut q_open = [0.0; MAX_DOF];
        if let Some((base, wrap)) = plan_wrap(hand, object, pose, obstacles, &mut q_open) {
            let mut tips = [false; MAX_TIPS];
            for (k, t) in tips.iter_mut().enumerate().take(hand.fingertips.len()) {
                *t = hand.fingertips[k].name != "thumb";
            }
            return Ok(GraspPlan {
                base,
                q_grasp: q_open,
                q_pre: q_open,
                q_open,
                tips,
                ik_error: 0.0,
                style: GraspStyle::Power,
                contacts_b: [Vector::zeros(); MAX_TIPS],
                normals_b: [Vector::zeros(); MAX_TIPS],
                normal_alignment: [0.0; MAX_TIPS],
                wrap: Some(wrap),
            });
        }
    }
    plan_grasp(hand, object, pose, style)
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
pub(crate) fn push_basis(hand: &HandModel, kin: &Kinematics, tip: usize) -> ([Vector; 3], usize) {
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

/// The link fingertip `tip`'s finger is mounted on (glove10: the palm): walking up from the
/// fingertip's link, the parent of the first joint not driven by the finger group's DOFs.
fn mount_link(hand: &HandModel, tip: usize) -> usize {
    let dofs: &[usize] = hand
        .finger_groups
        .iter()
        .find(|g| g.tips.contains(&tip))
        .map(|g| g.dofs.as_slice())
        .unwrap_or(&[]);
    let mut link = hand.fingertips[tip].link;
    while let Some(j) = hand.joints.iter().find(|j| j.child == link) {
        let in_group = match j.drive {
            JointDrive::Dof(d) | JointDrive::Mimic { dof: d, .. } => dofs.contains(&d),
            JointDrive::Fixed => true,
        };
        if !in_group {
            return j.parent;
        }
        link = j.parent;
    }
    link
}

/// The minimum-jerk profile at `t` ([`crate::min_jerk::progress`]) and its second derivative.
fn min_jerk(t: Real) -> (Real, Real) {
    (
        crate::min_jerk::progress(t),
        crate::min_jerk::acceleration(t),
    )
}

/// The ChaCha8 stream of the scenario's seed that varied reaches draw from (`vary_reach`);
/// the tremor and the sensor noise draw from stream 0, so they stay those of the seed.
pub const REACH_STREAM: u64 = 1;

/// Range of a varied reach's speed factor `s`: its `approach` and the `preshape` after it take
/// their script durations / `s`.
pub const REACH_SPEED: (Real, Real) = (0.7, 1.3);

/// Largest bend of a varied reach off its straight line, as a fraction of its length (the
/// bend is drawn uniformly from 0 to this).
pub const REACH_BEND: Real = 0.3;

/// Chance that a varied reach pauses part-way.
pub const REACH_PAUSE_CHANCE: Real = 0.5;

/// Range of a varied reach's pause (s).
pub const REACH_PAUSE_S: (Real, Real) = (0.1, 0.3);

/// Range of where a varied reach pauses: the fraction of its path (and of its moving time)
/// before the pause.
pub const REACH_PAUSE_AT: (Real, Real) = (0.3, 0.7);

/// Range of the distance (m) of a varied start (the home) from the first approach pose.
pub const REACH_HOME_M: (Real, Real) = (0.25, 0.40);

/// Range of the elevation (rad) of the home above the first approach pose: 15° to 60°.
pub const REACH_HOME_ELEVATION: (Real, Real) =
    (std::f64::consts::PI / 12.0, std::f64::consts::PI / 3.0);

/// Largest azimuth (rad) of the home about the horizontal direction from the target to the
/// first approach pose: ±90°, the half-circle on the side the hand approaches from.
pub const REACH_HOME_AZIMUTH: Real = std::f64::consts::FRAC_PI_2;

/// Largest turn (rad) of the hand at its home about the vertical, from its grasp orientation
/// (it turns back during the first approach).
pub const REACH_HOME_YAW: Real = 0.4;

/// Clearance (m) a varied reach keeps between the open hand and the table or any object, or
/// at least what it keeps at the reach's ends (the approach pose is beside the target).
pub const REACH_CLEARANCE_M: Real = 0.02;

/// Least height (m) of the hand's base at its home above the table's top.
pub const REACH_HOME_ABOVE_TABLE_M: Real = 0.05;

/// Fraction of a varied reach's path over which the fingers of the grasp keep the open hand's
/// posture; over the rest they go over (a minimum-jerk blend of the two controls) to reaching
/// for their spots on the object, as they do throughout a reach that is not varied. (Reaching
/// for spots from afar pulls the thumb down and sideways by up to 10 cm, into whatever lies
/// under the path.)
pub const REACH_SHAPE_FROM: Real = 0.6;

/// Homes drawn before the fixed start (0.15 m above the approach pose) is used.
const HOME_TRIES: usize = 16;

/// Bends tried (each redrawn smaller) before the straight line is used.
const BEND_TRIES: usize = 8;

/// Points along a reach at which its clearance is checked.
const CLEARANCE_SAMPLES: usize = 48;

/// The seeded variation of one `approach` task, drawn when the simulation is set up.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Reach {
    /// Speed factor ([`REACH_SPEED`]).
    speed: Real,
    /// Moving time (s, whole ticks), the pause excluded.
    move_s: Real,
    /// The pause (s, whole ticks; 0 for none).
    pause_s: Real,
    /// Fraction of the path, and of the moving time, before the pause.
    pause_at: Real,
    /// The first bend to try: fraction of the length ([`REACH_BEND`]).
    bend: Real,
    /// ... and its direction about the line (rad, 0 to π: sideways, up, other side).
    bend_angle: Real,
}

impl Reach {
    /// Draws a reach for an `approach` of `duration` s: speed, pause and bend.
    fn draw(rng: &mut ChaCha8Rng, duration: Real) -> Reach {
        let speed = rng.random_range(REACH_SPEED.0..=REACH_SPEED.1);
        let pauses = rng.random::<Real>() < REACH_PAUSE_CHANCE;
        let pause_s = rng.random_range(REACH_PAUSE_S.0..=REACH_PAUSE_S.1);
        let pause_at = rng.random_range(REACH_PAUSE_AT.0..=REACH_PAUSE_AT.1);
        let bend = rng.random_range(0.0..=REACH_BEND);
        let bend_angle = rng.random_range(0.0..=std::f64::consts::PI);
        Reach {
            speed,
            move_s: whole_ticks_ns(duration / speed).max(TICK_NS) as Real * 1e-9,
            pause_s: if pauses {
                whole_ticks_ns(pause_s) as Real * 1e-9
            } else {
                0.0
            },
            pause_at,
            bend,
            bend_angle,
        }
    }

    /// The path parameter `u` (0 to 1) at `t` s into the reach, with `du/dt` and `d²u/dt²`:
    /// a minimum-jerk move to [`pause_at`](Self::pause_at), the pause, and a minimum-jerk
    /// move on to 1 (one move when there is no pause); each rests at both ends, so `u` has
    /// continuous first and second derivatives.
    fn progress(&self, t: Real) -> (Real, Real, Real) {
        let at = if self.pause_s > 0.0 {
            self.pause_at
        } else {
            1.0
        };
        let t1 = at * self.move_s;
        if t >= self.move_s + self.pause_s {
            return (1.0, 0.0, 0.0);
        }
        let (from, share, start, dur) = if t < t1 {
            (0.0, at, 0.0, t1)
        } else if t < t1 + self.pause_s {
            return (at, 0.0, 0.0);
        } else {
            (at, 1.0 - at, t1 + self.pause_s, self.move_s - t1)
        };
        if dur <= 0.0 {
            return (from + share, 0.0, 0.0);
        }
        let tau = (t - start) / dur;
        (
            from + share * crate::min_jerk::progress(tau),
            share * crate::min_jerk::velocity(tau) / dur,
            share * crate::min_jerk::acceleration(tau) / (dur * dur),
        )
    }
}

/// A duration rounded to whole ticks (ns), as a script's tasks are.
fn whole_ticks_ns(seconds: Real) -> u64 {
    (seconds * 1e9).round() as u64 / TICK_NS * TICK_NS
}

/// The varied approach under way: its reach and its bend.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ReachPath {
    reach: Reach,
    /// The bend: the path's displacement from the straight line halfway (m, world).
    bend: Vector,
}

/// The bend of a reach along `dp` (m): `fraction` of its length, perpendicular to it, turned
/// `angle` (0 to π) about it from horizontal through up (never down).
fn bend_vector(dp: &Vector, fraction: Real, angle: Real) -> Vector {
    let len = dp.norm();
    if len < 1e-9 {
        return Vector::zeros();
    }
    let d = dp / len;
    let e1 = Vector::z()
        .cross(&d)
        .try_normalize(1e-6)
        .unwrap_or(Vector::x());
    let mut e2 = d.cross(&e1);
    if e2.z < 0.0 {
        e2 = -e2;
    }
    (e1 * angle.cos() + e2 * angle.sin()) * (fraction * len)
}

/// The point of a reach from `from` by `dp` with bend `bend` at path parameter `u`.
fn reach_point(from: &Vector, dp: &Vector, bend: &Vector, u: Real) -> Vector {
    from + dp * u + bend * (std::f64::consts::PI * u).sin()
}

/// The points of the hand a reach keeps clear of the table and the objects, with their radii
/// (m), from `kin` (the hand's forward kinematics): every link's origin (the joints), the
/// middle of every link between two joints, every fingertip sphere and the middle of its
/// distal segment.
fn hand_points(hand: &HandModel, kin: &Kinematics, out: &mut Vec<(Vector, Real)>) {
    out.clear();
    let origin = |l: usize| kin.link_poses[l].translation.vector;
    for l in 0..hand.links.len() {
        out.push((origin(l), 0.0));
    }
    for j in &hand.joints {
        out.push(((origin(j.parent) + origin(j.child)) * 0.5, 0.0));
    }
    for (k, tip) in hand.fingertips.iter().enumerate() {
        let c = kin.tip_centres[k].coords;
        out.push((c, tip.radius));
        out.push(((c + origin(tip.link)) * 0.5, 0.0));
    }
}

/// How far (m) a sphere of radius `r` at `p` is from the table's top and from every object.
fn clearance(p: &Vector, r: Real, objects: &[DfsObject], table_height: Real) -> Real {
    objects.iter().fold(p.z - r - table_height, |c, o| {
        let local = o.state.pose.inverse_transform_point(&Point::from(*p));
        c.min(o.object.shape.closest(&local.coords).0 - r)
    })
}

/// A reach of the hand from `from` to `to`, its joints going from `q_from` to `q_to`, bent by
/// `bend`, as [`reach_is_clear`] checks it.
struct ReachCheck<'a> {
    hand: &'a HandModel,
    q_from: &'a [Real],
    q_to: &'a [Real],
    from: &'a Isometry,
    to: &'a Isometry,
    objects: &'a [DfsObject],
    table_height: Real,
}

impl ReachCheck<'_> {
    /// The hand's pose and joints at path parameter `u` along the reach bent by `bend`, into
    /// `kin`, and its points ([`hand_points`]) into `points`.
    fn points_at(
        &self,
        u: Real,
        bend: &Vector,
        q: &mut [Real; MAX_DOF],
        kin: &mut Kinematics,
        points: &mut Vec<(Vector, Real)>,
    ) {
        let a = self.from.translation.vector;
        let dp = self.to.translation.vector - a;
        let base = Isometry::from_parts(
            reach_point(&a, &dp, bend, u).into(),
            self.from.rotation.slerp(&self.to.rotation, u),
        );
        let n = self.q_from.len();
        for d in 0..n {
            q[d] = self.q_from[d] + (self.q_to[d] - self.q_from[d]) * u;
        }
        self.hand.forward_kinematics(&base, &q[..n], kin);
        hand_points(self.hand, kin, points);
    }

    /// The least clearance ([`clearance`]) of each hand point at `u`.
    fn clearances_at(&self, u: Real, bend: &Vector, kin: &mut Kinematics) -> Vec<Real> {
        let mut q = [0.0; MAX_DOF];
        let mut points = Vec::new();
        self.points_at(u, bend, &mut q, kin, &mut points);
        points
            .iter()
            .map(|(p, r)| clearance(p, *r, self.objects, self.table_height))
            .collect()
    }

    /// Whether the reach bent by `bend` keeps clear: at [`CLEARANCE_SAMPLES`] points along
    /// it, every hand point keeps from the table and every object at least the least of
    /// [`REACH_CLEARANCE_M`] and its clearances at the reach's start and end, less 2 mm.
    fn is_clear(&self, bend: &Vector, kin: &mut Kinematics) -> bool {
        let start = self.clearances_at(0.0, bend, kin);
        let end = self.clearances_at(1.0, bend, kin);
        let mut q = [0.0; MAX_DOF];
        let mut points = Vec::new();
        (1..CLEARANCE_SAMPLES).all(|i| {
            let u = i as Real / CLEARANCE_SAMPLES as Real;
            self.points_at(u, bend, &mut q, kin, &mut points);
            points.iter().enumerate().all(|(k, (p, r))| {
                let least = REACH_CLEARANCE_M.min(start[k]).min(end[k]) - 0.002;
                clearance(p, *r, self.objects, self.table_height) >= least
            })
        })
    }
}

/// The varied start of a simulation ([`REACH_HOME_M`] and the other `REACH_HOME_` ranges):
/// drawn from `rng` until one keeps [`REACH_CLEARANCE_M`] clear of the table and the objects,
/// has its base [`REACH_HOME_ABOVE_TABLE_M`] above the table and a straight reach from it to
/// `approach` keeps clear ([`ReachCheck::is_clear`]); after [`HOME_TRIES`] draws, the fixed
/// start 0.15 m above `approach`.
fn draw_home(
    rng: &mut ChaCha8Rng,
    hand: &HandModel,
    q_open: &[Real],
    approach: &Isometry,
    target: &Vector,
    objects: &[DfsObject],
    table_height: Real,
) -> Isometry {
    let a = approach.translation.vector;
    let mut out = a - target;
    out.z = 0.0;
    let out = out
        .try_normalize(1e-6)
        .or_else(|| {
            let mut y = approach.rotation * Vector::y();
            y.z = 0.0;
            y.try_normalize(1e-6)
        })
        .unwrap_or(Vector::x());
    let side = Vector::z().cross(&out);
    let mut kin = Kinematics::default();
    for _ in 0..HOME_TRIES {
        let distance = rng.random_range(REACH_HOME_M.0..=REACH_HOME_M.1);
        let azimuth = rng.random_range(-REACH_HOME_AZIMUTH..=REACH_HOME_AZIMUTH);
        let elevation = rng.random_range(REACH_HOME_ELEVATION.0..=REACH_HOME_ELEVATION.1);
        let yaw = rng.random_range(-REACH_HOME_YAW..=REACH_HOME_YAW);
        let dir = (out * azimuth.cos() + side * azimuth.sin()) * elevation.cos()
            + Vector::z() * elevation.sin();
        let home = Isometry::from_parts(
            (a + dir * distance).into(),
            Rotation::from_euler_angles(0.0, 0.0, yaw) * approach.rotation,
        );
        if home.translation.z < table_height + REACH_HOME_ABOVE_TABLE_M {
            continue;
        }
        let check = ReachCheck {
            hand,
            q_from: q_open,
            q_to: q_open,
            from: &home,
            to: approach,
            objects,
            table_height,
        };
        let straight = Vector::zeros();
        let clear_at_home = check
            .clearances_at(0.0, &straight, &mut kin)
            .iter()
            .all(|&c| c >= REACH_CLEARANCE_M);
        if clear_at_home && check.is_clear(&straight, &mut kin) {
            return home;
        }
    }
    raise(approach, 0.15)
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
    /// Task-space stiffness steering a fingertip of the grasp towards its spot while it
    /// reaches, closes and opens (N/m). Default 150.
    pub fingertip_stiffness: Real,
    /// Task-space stiffness keeping a fingertip of the grasp where it met the object, relative
    /// to the hand, while holding (N/m). Default 1000: a pinching fingertip is about 1 N/mm
    /// stiff (finger-pad and joint impedance of a person's precision grip).
    pub hold_stiffness: Real,
    /// Damping of a finger's posture in the null space of its fingertip's task (N·m·s/rad).
    /// Default 0.005.
    pub posture_damping: Real,
    /// Task-space damping of the same, on the fingertip's velocity relative to the hand
    /// (N·s/m). Default 5: well damped, and stable at 1 kHz although the operator's torques are
    /// computed from the previous tick's state.
    pub hold_damping: Real,
    /// How far the grip rises above its static level while the object is lifted off
    /// (fraction): people grip hardest at lift-off and relax to the static level as the object
    /// comes to rest in the hand (Johansson & Westling 1984, the grip-force peak of the loading
    /// phase). Default 0.6: 1.6 times the static grip at the peak, back to it by the end of the
    /// lift.
    pub lift_grip_peak: Real,
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
            hold_stiffness: 1000.0,
            hold_damping: 5.0,
            posture_damping: 0.005,
            lift_grip_peak: 0.6,
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
    /// The scene as the scenario set it up.
    scene: Scene,
    /// Index of the object the script grasps in the scene (and the DFS).
    target: usize,
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
    /// Per fingertip: where it first touched while holding (the pad on the surface) and the
    /// inward contact normal there, both in the frame of the link its finger is mounted on.
    hold_in_mount: [Option<(Vector, Vector)>; MAX_TIPS],
    /// Per fingertip: the link its finger is mounted on ([`mount_link`]).
    mount: [usize; MAX_TIPS],
    /// Per fingertip of the grasp: it rests on the object instead of squeezing it
    /// ([`resting_tips`]).
    resting: [bool; MAX_TIPS],
    base: Isometry,
    base_acceleration: Vector,
    q_intent: [Real; MAX_DOF],
    grip: Real,
    /// Share of the object's expected load the fingertips lift actively (0-1).
    carry: Real,
    /// The grip's rise above its static level (fraction), see
    /// [`OperatorParams::lift_grip_peak`].
    grip_boost: Real,
    q_meas: [Real; MAX_DOF],
    tau_meas: [Real; MAX_DOF],
    tau: [Real; MAX_DOF],
    rng: ChaCha8Rng,
    tremor_freq: [Real; MAX_DOF + 3],
    tremor_phase: [Real; MAX_DOF + 3],
    /// Per span: the variation of its reach (a varied `approach`), see
    /// [the module docs](self#varied-reaches).
    reaches: Vec<Option<Reach>>,
    /// The stream varied reaches draw their bends from ([`REACH_STREAM`]); `None` when the
    /// scenario does not vary its reaches.
    reach_rng: Option<ChaCha8Rng>,
    /// The varied approach under way.
    reach_path: Option<ReachPath>,
    /// In a varied approach, how far the fingers of the grasp have gone over from holding
    /// the open hand's posture to reaching for their spots on the object (0-1,
    /// [`REACH_SHAPE_FROM`]).
    reach_shaping: Real,
    /// In a wrap ([`GraspPlan::wrap`]), how far the fingers have gone over from the open
    /// hand's posture to closing by torque (0-1).
    wrap_close: Real,
    /// In a wrap, where the fingers came to rest on the object at the end of `grasp`: held
    /// there from then on (with the closing torques) until they open.
    wrap_set: Option<[Real; MAX_DOF]>,
}

impl Simulation {
    /// Sets up a scenario with `hand` (normally glove10): its scene ([`Scenario::resolve_scene`])
    /// in one DFS, the grasp planned on the target. `duration_s`, when given, cuts the
    /// script short or extends its last phase. Errors name the scenario's field, or say that no
    /// grasp of the object is reachable.
    pub fn new(
        scenario: &Scenario,
        hand: HandModel,
        duration_s: Option<Real>,
    ) -> Result<Simulation> {
        let (scene, tasks) = scenario.resolve_scene()?;
        let target = scene.target;
        let (object, pose, friction) = {
            let t = scene.target();
            (t.object, t.pose, t.friction)
        };
        let table_height = scene.table_height;
        let mut spans = Vec::with_capacity(tasks.len());
        let mut t = 0u64;
        // Varied reaches: their own stream of the seed, so the tremor and the noise below are
        // the seed's either way.
        let mut reach_rng = scenario.vary_reach.then(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
            rng.set_stream(REACH_STREAM);
            rng
        });
        let mut reaches = vec![None; tasks.len()];
        let mut speed = 1.0;
        for (i, task) in tasks.iter().enumerate() {
            let d = match (reach_rng.as_mut(), task.phase) {
                (Some(rng), Phase::Approach) => {
                    let reach = Reach::draw(rng, task.duration);
                    speed = reach.speed;
                    reaches[i] = Some(reach);
                    ((reach.move_s + reach.pause_s) * 1e9).round() as u64
                }
                (Some(_), Phase::Preshape) => whole_ticks_ns(task.duration / speed),
                _ => (task.duration * 1e9).round() as u64 / TICK_NS * TICK_NS,
            };
            spans.push(PhaseSpan {
                phase: task.phase,
                start_ns: t,
                end_ns: t + d.max(TICK_NS),
                task: *task,
            });
            t += d.max(TICK_NS);
        }
        if scenario.vary_reach && t as Real * 1e-9 > MAX_SCRIPT_S {
            return Err(DfsError::invalid(
                "vary_reach",
                format!(
                    "the varied reaches make the script last {} s; a session lasts at most \
                     {MAX_SCRIPT_S} s",
                    t as Real * 1e-9
                ),
            ));
        }
        let mut n_steps = t / TICK_NS;
        if let Some(d) = duration_s {
            // A session shorter than the shortest phase holds no motion to segment (and one of
            // a tick or two would not read back as a session).
            if !(d.is_finite() && (MIN_TASK_S..=MAX_SCRIPT_S).contains(&d)) {
                return Err(DfsError::invalid(
                    "duration",
                    format!("must be {MIN_TASK_S} to {MAX_SCRIPT_S} s, got {d}"),
                ));
            }
            n_steps = ((d * 1e9).round() as u64 / TICK_NS).max(1);
            let end = n_steps * TICK_NS;
            spans.retain(|s| s.start_ns < end);
            if let Some(last) = spans.last_mut() {
                last.end_ns = end;
            }
        }
        let obstacles: Vec<(RigidObject, Isometry)> = scene
            .objects
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != target)
            .map(|(_, o)| (o.object, o.pose))
            .collect();
        let plan = plan_operator_grasp(&hand, &object, &pose, scenario.grasp, &obstacles)?;
        let params = DfsParams {
            // Fingertip pads are soft: they resist spin about the normal (Table 1, soft finger).
            contact_model: ContactModel::SoftFinger,
            friction,
            table_height: Some(table_height),
            // A grasp that wraps the hand around the object holds it with the palm and the
            // phalanges too: whole-hand contact is the plan's, not a default of the physics
            // (fingertip sessions stay as they were, bit for bit, and their ticks as cheap).
            whole_hand: plan.wrap.is_some(),
            ..DfsParams::default()
        };
        let approach = approach_pose(&plan.base, &object.shape);
        let start_base = match reach_rng.as_mut() {
            Some(rng) => draw_home(
                rng,
                &hand,
                &plan.q_open[..hand.dof()],
                &approach,
                &pose.translation.vector,
                &scene.dfs_objects(),
                table_height,
            ),
            None => raise(&approach, 0.15),
        };
        let q0 = plan.q_open;
        let mut mount = [0; MAX_TIPS];
        for (k, m) in mount.iter_mut().enumerate().take(hand.fingertips.len()) {
            *m = mount_link(&hand, k);
        }
        let mut dfs = Dfs::with_objects(hand, &scene.dfs_objects(), params)?;
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
        for (i, o) in scene.objects.iter().enumerate() {
            dfs.set_object_state_at(i, ObjectState::at_rest(o.pose))?;
        }
        let operator_mu = scenario.operator_mu.unwrap_or(friction.mu).max(1e-3);
        let mut sim = Simulation {
            dfs,
            scene,
            target,
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
            hold_in_mount: [None; MAX_TIPS],
            resting: [false; MAX_TIPS],
            mount,
            base: start_base,
            base_acceleration: Vector::zeros(),
            q_intent: q0,
            grip: 0.0,
            carry: 0.0,
            grip_boost: 0.0,
            q_meas: q0,
            tau_meas: [0.0; MAX_DOF],
            tau: [0.0; MAX_DOF],
            rng,
            tremor_freq,
            tremor_phase,
            reaches,
            reach_rng,
            reach_path: None,
            reach_shaping: 1.0,
            wrap_close: 0.0,
            wrap_set: None,
        };
        sim.begin_phase()?;
        Ok(sim)
    }

    /// The phases of the script with their time spans: the ground truth of the session.
    pub fn phases(&self) -> &[PhaseSpan] {
        &self.spans
    }

    /// The DFS (hand, objects, last tick's output and kinematics).
    pub fn dfs(&self) -> &Dfs {
        &self.dfs
    }

    /// The scene: the objects with their names and start poses, and the one the script grasps.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Index of the object the script grasps (in the scene and the DFS).
    pub fn target(&self) -> usize {
        self.target
    }

    /// The object the script grasps.
    fn target_object(&self) -> &RigidObject {
        &self.dfs.objects()[self.target].object
    }

    /// The state of the object the script grasps.
    pub fn target_state(&self) -> &ObjectState {
        &self.dfs.objects()[self.target].state
    }

    /// Fingertip `k`'s contact frame on the object the script grasps, if it touches that one.
    fn target_frame(&self, k: usize) -> Option<crate::contact::ContactFrame> {
        let tip = &self.dfs.output().tips[k];
        tip.frame.filter(|_| tip.object == self.target)
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
    ///
    /// A tick is a few µs of CPU, but the one that begins an `approach` task plans the grasp
    /// ([`plan_grasp`]: 15-30 ms with glove10); a script has at most
    /// [`MAX_TASKS`](crate::scenario::MAX_TASKS) tasks. Whoever drives the loop looks at its
    /// [`Stop`](crate::Stop) between steps.
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
            if self.plan.wrap.is_some() {
                self.wrap_set = Some(self.dfs.output().motor_q);
            }
        }
        if self.span_now().phase == Phase::Release {
            self.object_held = false;
            self.wrap_set = None;
        }
    }

    /// Sets the targets of the phase that starts now, from where the hand and object are.
    fn begin_phase(&mut self) -> Result<()> {
        let task = self.span_now().task;
        self.from_base = self.to_base;
        self.from_q = self.to_q;
        self.from_grip = self.to_grip;
        self.from_offset = self.to_offset;
        self.seen_object = self.target_state().pose;
        self.reach_path = None;
        let n = self.dfs.hand().dof();
        match task.phase {
            Phase::Approach => {
                let pose = self.target_state().pose;
                let obstacles: Vec<(RigidObject, Isometry)> = self
                    .dfs
                    .objects()
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| *i != self.target)
                    .map(|(_, o)| (o.object, o.state.pose))
                    .collect();
                self.plan = plan_operator_grasp(
                    self.dfs.hand(),
                    self.target_object(),
                    &pose,
                    self.style,
                    &obstacles,
                )?;
                self.resting = resting_tips(
                    &self.plan,
                    self.dfs.hand(),
                    self.operator_mu,
                    self.params.grip_safety,
                );
                self.to_base = approach_pose(&self.plan.base, &self.target_object().shape);
                self.to_q = self.plan.q_open;
                self.to_grip = 0.0;
                self.to_offset = 0.03;
                self.object_held = false;
                if let Some(reach) = self.reaches.get(self.span).copied().flatten() {
                    self.reach_path = Some(self.bend_reach(reach));
                }
            }
            Phase::Preshape => {
                // A wrap slides the open hand down beside the object and onto it: the palm
                // touches as the preshape ends, and the grasp only closes the fingers.
                self.to_base = self.plan.wrap.map_or(self.plan.base, |w| w.base);
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
                let centre = self.target_state().pose.translation.vector;
                let turn = Rotation::from_euler_angles(0.0, 0.0, task.turn);
                let b = self.from_base;
                let p = centre + turn * (b.translation.vector - centre) + Vector::from(task.offset);
                self.to_base = Isometry::from_parts(p.into(), turn * b.rotation);
            }
            Phase::Place => {
                let obj = self.target_state().pose;
                let depth = self.target_object().shape.support_depth(&obj.rotation);
                let dz = self.table_height + depth - obj.translation.z - 0.002;
                self.to_base = raise(&self.from_base, dz);
            }
            Phase::Release => {
                self.to_q = self.plan.q_pre;
                self.to_grip = 0.0;
                self.to_offset = 0.015;
                // Let go from where each fingertip holds the object, not from where the plan
                // put it: an object that turned or slid in the hand (set down on a tilted
                // edge, say) would otherwise be dragged back by fingertips steering to their
                // planned spots as they open.
                let out = self.dfs.output();
                for k in 0..out.n_tips.min(MAX_TIPS) {
                    if let (true, Some(frame)) = (self.plan.tips[k], self.target_frame(k)) {
                        let n_out = -frame.normal_b();
                        let r = self.dfs.hand().fingertips[k].radius;
                        self.plan.contacts_b[k] = frame.p_b + n_out * r;
                        self.plan.normals_b[k] = n_out;
                    }
                }
            }
            Phase::Retreat => {
                self.to_base = match self.plan.wrap {
                    // The open hand backs off the object and slides up off it, the way it came.
                    Some(wrap) => {
                        let rise = self.target_object().shape.bounding_radius() + 0.06;
                        let mut x = raise(&self.from_base, rise);
                        x.translation.vector += wrap.out * (2.0 * power::WRAP_STANDOFF);
                        x
                    }
                    None => raise(&self.from_base, 0.10),
                };
                self.to_q = self.plan.q_open;
                self.to_grip = 0.0;
                self.to_offset = 0.03;
            }
        }
        Ok(())
    }

    /// The path of a varied approach from `from_base` to `to_base`: its first bend, or
    /// smaller ones drawn from the reach stream, the first that keeps clear of the table and
    /// the objects ([`ReachCheck::is_clear`]), else the straight line.
    fn bend_reach(&mut self, reach: Reach) -> ReachPath {
        let n = self.dfs.hand().dof();
        let check = ReachCheck {
            hand: self.dfs.hand(),
            q_from: &self.from_q[..n],
            q_to: &self.to_q[..n],
            from: &self.from_base,
            to: &self.to_base,
            objects: self.dfs.objects(),
            table_height: self.table_height,
        };
        let dp = self.to_base.translation.vector - self.from_base.translation.vector;
        let mut kin = Kinematics::default();
        let (mut fraction, mut angle) = (reach.bend, reach.bend_angle);
        for attempt in 1..=BEND_TRIES {
            let bend = bend_vector(&dp, fraction, angle);
            if check.is_clear(&bend, &mut kin) {
                return ReachPath { reach, bend };
            }
            let Some(rng) = self.reach_rng.as_mut() else {
                break;
            };
            let shrink = 1.0 - attempt as Real / BEND_TRIES as Real;
            fraction = rng.random_range(0.0..=REACH_BEND) * shrink;
            angle = rng.random_range(0.0..=std::f64::consts::PI);
        }
        ReachPath {
            reach,
            bend: Vector::zeros(),
        }
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
        let (mut mq, _) = min_jerk(sq);
        let (mg, _) = min_jerk(sg);
        // A wrap: the fingers close from 20 % to 50 % of `grasp`, and in `release` open after
        // the grip has gone (40 % on).
        self.wrap_close = match span.phase {
            Phase::Grasp => min_jerk((s - 0.2) / 0.3).0,
            Phase::Lift | Phase::Hold | Phase::Transport | Phase::Place => 1.0,
            Phase::Release => 1.0 - min_jerk((s - 0.4) / 0.6).0,
            _ => 0.0,
        };
        let dp = self.to_base.translation.vector - self.from_base.translation.vector;
        let (p, r, acceleration) = match &self.reach_path {
            None => (
                self.from_base.translation.vector + dp * m,
                self.from_base.rotation.slerp(&self.to_base.rotation, m),
                dp * (m2 / (dur * dur)),
            ),
            // A varied approach: along its bent path, pausing if it does; the fingers follow
            // the same progress.
            Some(path) => {
                let (u, du, ddu) = path.reach.progress((t - span.start_ns) as Real * 1e-9);
                let (sin, cos) = (std::f64::consts::PI * u).sin_cos();
                let pi = std::f64::consts::PI;
                mq = u;
                self.reach_shaping =
                    crate::min_jerk::progress((u - REACH_SHAPE_FROM) / (1.0 - REACH_SHAPE_FROM));
                (
                    reach_point(&self.from_base.translation.vector, &dp, &path.bend, u),
                    self.from_base.rotation.slerp(&self.to_base.rotation, u),
                    (dp + path.bend * (pi * cos)) * ddu - path.bend * (pi * pi * sin * du * du),
                )
            }
        };
        let time = t as Real * 1e-9;
        let mut tremor = Vector::zeros();
        for (k, c) in tremor.iter_mut().enumerate() {
            let i = MAX_DOF + k;
            *c = self.params.tremor_arm
                * (std::f64::consts::TAU * self.tremor_freq[i] * time + self.tremor_phase[i]).sin();
        }
        let new_base = Isometry::from_parts((p + tremor).into(), r);
        self.base_acceleration = acceleration;
        self.base = new_base;
        let n = self.dfs.hand().dof();
        for d in 0..n {
            let tr = self.params.tremor_joint
                * (std::f64::consts::TAU * self.tremor_freq[d] * time + self.tremor_phase[d]).sin();
            self.q_intent[d] = self.from_q[d] + (self.to_q[d] - self.from_q[d]) * mq + tr;
        }
        self.grip = self.from_grip + (self.to_grip - self.from_grip) * mg;
        // The load force: the fingertips take over the object's weight from the table early in
        // the lift (the loading phase, before the object moves: Johansson & Westling 1984) and
        // hand it back late in the place.
        self.carry = match span.phase {
            Phase::Lift => min_jerk(s / 0.3).0,
            Phase::Hold | Phase::Transport => 1.0,
            Phase::Place => 1.0 - min_jerk((s - 0.6) / 0.4).0,
            _ => 0.0,
        };
        // The grip peaks as the load comes on at lift-off and relaxes to its static level by
        // the end of the lift.
        self.grip_boost = match span.phase {
            Phase::Lift => {
                self.params.lift_grip_peak
                    * min_jerk(s / 0.3).0
                    * (1.0 - min_jerk((s - 0.3) / 0.7).0)
            }
            _ => 0.0,
        };
        self.offset = self.from_offset + (self.to_offset - self.from_offset) * mq;
    }

    /// The operator's joint torques `Jᵀ f` for the fingertips of the grasp, and an impedance
    /// around the intended angles for the other joints (wrist, unused fingers).
    ///
    /// Reaching and closing, a fingertip of the grasp is steered towards its spot on the object
    /// (in the object's frame, so it follows the object), `offset` out along the surface normal,
    /// with the soft [`OperatorParams::fingertip_stiffness`], like a person reaching for a spot
    /// they see; closing makes the offset zero, approaching every face head-on.
    ///
    /// Once it touches while holding, the operator keeps the fingertip where it met the object,
    /// relative to the palm (the link the finger is mounted on): a stiff, damped impedance ([`OperatorParams::hold_stiffness`],
    /// [`OperatorParams::hold_damping`]) about that spot pushed into the object by the pad's
    /// expected compression `N / k_s` (the DFS's surface stiffness), plus the squeeze `N` along
    /// the normal ([`Simulation::grip_forces`]). The set-points, fixed in the hand, fix the
    /// object's place in the hand: between opposing fingertips both springs hold it, and a
    /// squeeze that changes equally on both sides does not move it. Set-points relative to the
    /// palm rather than the forearm keep the fingers' impedance out of a loop through the
    /// wrist (fingertip forces turn the palm, which would move a forearm-fixed set-point).
    fn compute_torques(&mut self) {
        if let Some(wrap) = self.plan.wrap {
            self.compute_wrap_torques(&wrap);
            return;
        }
        let (mags, units, lift) = self.grip_forces();
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let kin = self.dfs.kinematics();
        let q = &out.motor_q;
        let qd = &out.motor_qd;
        let obj_pose = if self.object_held {
            self.target_state().pose
        } else {
            self.seen_object
        };
        let obj_rot = self.target_state().pose.rotation;
        let k_s = self.dfs.params().surface_stiffness;
        let holding = matches!(
            self.phase(),
            Phase::Grasp | Phase::Lift | Phase::Hold | Phase::Transport | Phase::Place
        );
        // The operator fixes the fingertips' places only once every fingertip of the grasp is
        // on the object; until then each closes softly on its spot, so the first to touch does
        // not shove the object away from the others.
        let all_touch = (0..out.n_tips.min(MAX_TIPS))
            .filter(|&k| self.plan.tips[k] && !self.resting[k])
            .all(|k| self.target_frame(k).is_some());
        let mut in_grasp = [false; MAX_DOF];
        let mut tau = [0.0; MAX_DOF];
        for g in &hand.finger_groups {
            if !g.tips.iter().any(|&k| self.plan.tips[k]) {
                continue;
            }
            for &d in &g.dofs {
                in_grasp[d] = true;
            }
        }
        for g in &hand.finger_groups {
            for &k in g.tips.iter().filter(|&&k| self.plan.tips[k]) {
                let tip = &out.tips[k];
                let x = kin.tip_centres[k];
                let mount = kin.link_poses[self.mount[k]];
                if !holding {
                    self.hold_in_mount[k] = None;
                } else if let (true, None, Some(frame)) =
                    (all_touch, self.hold_in_mount[k], self.target_frame(k))
                {
                    // Where the fingertip met the object, with the pad just on the surface, and
                    // the inward normal there, both relative to the palm.
                    let n_in = obj_rot * frame.normal_b();
                    let spot = x - n_in * tip.penetration;
                    let inv = mount.inverse();
                    self.hold_in_mount[k] = Some(((inv * spot).coords, inv.rotation * n_in));
                }
                let j = &kin.tip_jacobians[k];
                let mut f = match self.hold_in_mount[k] {
                    Some((spot, n_in)) => {
                        let target =
                            mount * Point::from(spot) + (mount.rotation * n_in) * (mags[k] / k_s);
                        let mut v = Vector::zeros();
                        for &d in &g.dofs {
                            v += Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]) * qd[d];
                        }
                        (target - x) * self.params.hold_stiffness - v * self.params.hold_damping
                    }
                    None => {
                        let target = obj_pose
                            * Point::from(
                                self.plan.contacts_b[k] + self.plan.normals_b[k] * self.offset,
                            );
                        let mut err = target - x;
                        let e = err.norm();
                        if e > 0.03 {
                            err *= 0.03 / e;
                        }
                        err * self.params.fingertip_stiffness
                    }
                };
                f += units[k] * mags[k];
                f += lift[k];
                for &d in &g.dofs {
                    tau[d] += j[(0, d)] * f.x + j[(1, d)] * f.y + j[(2, d)] * f.z;
                }
            }
            // A finger with more joints than its fingertip needs (the index: three joints in
            // its flexion plane) keeps its intended posture in the null space of the fingertip
            // task, so it neither drifts towards a stretched, singular posture nor moves the
            // fingertip: τ₀ − Jᵀ (J Jᵀ + λ²I)⁻¹ J τ₀ for the posture impedance τ₀.
            let mut planned = g.tips.iter().filter(|&&k| self.plan.tips[k]);
            if let (Some(&k), None) = (planned.next(), planned.next()) {
                let j = &kin.tip_jacobians[k];
                let mut t0 = [0.0; MAX_DOF];
                let mut jt0 = Vector::zeros();
                let mut jjt = nalgebra::Matrix3::<Real>::identity() * 1e-6;
                for &d in &g.dofs {
                    let kp = self.params.stiffness * hand.torque_limit[d];
                    t0[d] = kp * (self.q_intent[d] - q[d]) - self.params.posture_damping * qd[d];
                    let c = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
                    jt0 += c * t0[d];
                    jjt += c * c.transpose();
                }
                if let Some(y) = jjt.cholesky().map(|ch| ch.solve(&jt0)) {
                    for &d in &g.dofs {
                        let c = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
                        tau[d] += t0[d] - c.dot(&y);
                    }
                }
            }
        }
        for d in 0..n {
            let kp = self.params.stiffness * hand.torque_limit[d];
            let kd = if hand.dof_names[d].starts_with("wrist") {
                self.params.wrist_damping
            } else {
                0.0
            };
            let posture = kp * (self.q_intent[d] - q[d]) - kd * qd[d];
            if !in_grasp[d] {
                tau[d] += posture;
            } else if self.reach_path.is_some() {
                // A varied reach keeps the open hand's posture until it nears the object.
                let w = self.reach_shaping;
                tau[d] = w * tau[d] + (1.0 - w) * posture;
            }
        }
        for d in 0..n {
            let lim = 1.9 * hand.torque_limit[d];
            self.tau[d] = tau[d].clamp(-lim, lim);
        }
    }

    /// The operator's joint torques in a wrap ([`power`]): the power grip's law
    /// ([`PowerGrip::torques`]) about the intended angles, the fingers going over from their
    /// posture impedance to closing by torque as [`wrap_close`](Self::wrap_close) rises. The
    /// closing torques are scaled to the squeeze friction needs for the load the operator
    /// expects (weight plus the arm's planned acceleration) with its safety margin, for the
    /// friction it expects, through the whole hand's contacts
    /// ([`power::WRAP_NORMAL_PER_GRIP`]): `grip` ramps from the closing level
    /// ([`power::WRAP_CLOSE`]) to that squeeze, with the lift-off peak
    /// ([`OperatorParams::lift_grip_peak`]).
    fn compute_wrap_torques(&mut self, wrap: &Wrap) {
        let hand = self.dfs.hand();
        let n = hand.dof();
        let out = self.dfs.output();
        let p = &self.params;
        let mut grip = PowerGrip::closing(hand, &[], &self.q_intent[..n]);
        let w = self.wrap_close;
        for d in 0..n {
            let lim = hand.torque_limit[d];
            grip.limit[d] = 1.9 * lim;
            if wrap.closes[d] {
                grip.close[d] = power::WRAP_CLOSE * lim;
                // Going over from the posture impedance to where the fingers came to rest on
                // the object (once they have: the fixture's grip), one set-point between them.
                let open = (1.0 - w) * p.stiffness * lim;
                let (held, set) = match self.wrap_set {
                    Some(set) => (w * power::WRAP_KP_PER_LIMIT * lim, set[d]),
                    None => (0.0, 0.0),
                };
                grip.kp[d] = open + held;
                if grip.kp[d] > 0.0 {
                    grip.set[d] = (open * self.q_intent[d] + held * set) / grip.kp[d];
                }
            }
        }
        let load = ((self.base_acceleration - self.dfs.params().gravity)
            * self.target_object().mass)
            .norm();
        let squeeze = (p.grip_safety * load / (self.operator_mu * power::WRAP_NORMAL_PER_GRIP))
            .clamp(power::WRAP_CLOSE, power::WRAP_MAX_GRIP)
            * (1.0 + self.grip_boost);
        let level = w + self.grip * (squeeze / power::WRAP_CLOSE - 1.0);
        let mut tau = [0.0; MAX_DOF];
        grip.torques(level, &out.motor_q[..n], &out.motor_qd[..n], &mut tau[..n]);
        self.tau[..n].copy_from_slice(&tau[..n]);
    }

    /// The squeeze: per fingertip of the grasp, the normal force `N_k` the operator presses
    /// with and the unit push `u_k` (world) that delivers it, `f_k = N_k u_k`. Zero until every
    /// fingertip of the grasp touches.
    ///
    /// The squeeze is what friction needs to carry the load the operator expects (weight plus
    /// the arm's planned acceleration, anticipated as people do: Johansson & Westling 1984)
    /// with its safety margin, for the friction it expects, and follows the grip ramp. It is not
    /// re-sized from what the fingertips feel (no slip reflex): a squeeze too weak for the real
    /// μ lets the object slip. `u_k` is the contact's inward normal projected onto the
    /// directions the fingertip can push (glove10's fingers and thumb push only in their
    /// flexion planes; eq. 14 transmits only forces in the range of Jᵀ), scaled to a unit
    /// normal component. The magnitudes are balanced so the squeezes nearly cancel: minimise
    /// ‖N − N₀‖² + w ‖Σ N_k u_k‖² (w = 4), i.e. N = (I + w AᵀA)⁻¹ N₀; for opposing fingertips
    /// the squeeze is equal and opposite.
    fn grip_forces(&self) -> ([Real; MAX_TIPS], [Vector; MAX_TIPS], [Vector; MAX_TIPS]) {
        let mut mags = [0.0; MAX_TIPS];
        let mut unit = [Vector::zeros(); MAX_TIPS];
        let mut lift = [Vector::zeros(); MAX_TIPS];
        if self.grip <= 0.0 {
            return (mags, unit, lift);
        }
        let out = self.dfs.output();
        let obj = self.target_object();
        let st = self.target_state();
        let g = self.dfs.params().gravity;
        let kin = self.dfs.kinematics();
        let hand = self.dfs.hand();
        let p = &self.params;
        let planned = (0..out.n_tips.min(MAX_TIPS))
            .filter(|&k| self.plan.tips[k] && !self.resting[k])
            .count();
        // Fixed-capacity lists: this runs every tick of a session.
        let mut touching = [0usize; MAX_TIPS];
        let mut nt = 0;
        let mut squeezing = 0;
        for k in 0..out.n_tips.min(MAX_TIPS) {
            if self.plan.tips[k] && self.target_frame(k).is_some() {
                touching[nt] = k;
                nt += 1;
                squeezing += usize::from(!self.resting[k]);
            }
        }
        let touching = &touching[..nt];
        // Squeeze only once every squeezing finger of the grasp is on the object.
        if squeezing == 0 || squeezing < planned {
            return (mags, unit, lift);
        }
        let load_force = (self.base_acceleration - g) * obj.mass;
        let load = load_force.norm();
        let normal = (p.grip_safety * load / (self.operator_mu * squeezing as Real))
            .max(p.min_normal)
            * self.grip
            * (1.0 + self.grip_boost);
        let mut ok = [false; MAX_TIPS];
        let mut range = [nalgebra::Matrix3::<Real>::zeros(); MAX_TIPS];
        let mut arm = [Vector::zeros(); MAX_TIPS];
        for &k in touching {
            let Some(frame) = self.target_frame(k) else {
                continue;
            };
            let n_in = st.pose.rotation * frame.normal_b();
            arm[k] = st.pose.rotation * frame.p_b;
            let (basis, nb) = push_basis(hand, kin, k);
            let mut dir = Vector::zeros();
            for b in basis.iter().take(nb) {
                dir += b * b.dot(&n_in);
                range[k] += b * b.transpose();
            }
            let along = dir.dot(&n_in);
            if along >= 0.2 {
                unit[k] = dir / along;
                ok[k] = true;
                // The load force is tangential: the squeeze alone sets the normal force.
                let d = dir.normalize();
                range[k] -= d * d.transpose();
            }
        }
        // The squeeze and the load are the squeezing fingertips'; a resting one only presses
        // lightly along its push.
        let mut ks = [0usize; MAX_TIPS];
        let mut m = 0;
        for &k in touching.iter().filter(|&&k| ok[k]) {
            if self.resting[k] {
                mags[k] = p.min_normal * self.grip;
            } else {
                ks[m] = k;
                m += 1;
            }
        }
        let mut sys = nalgebra::SMatrix::<Real, MAX_TIPS, MAX_TIPS>::identity();
        let wanted = [normal; MAX_TIPS];
        let mut solved = wanted;
        for a in 0..m {
            for b in 0..m {
                sys[(a, b)] += 4.0 * unit[ks[a]].dot(&unit[ks[b]]);
            }
        }
        if !crate::math::cholesky_solve_in_place(&mut sys, m, &mut solved) {
            solved = wanted;
        }
        for (idx, &k) in ks.iter().enumerate().take(m) {
            mags[k] = solved[idx].max(p.min_normal * self.grip);
        }
        for k in 0..MAX_TIPS {
            if !ok[k] {
                unit[k] = Vector::zeros();
            }
        }
        if self.carry > 0.0 && m > 0 {
            self.distribute_load(&ks[..m], &range, &arm, &mags, &unit, load_force, &mut lift);
        }
        (mags, unit, lift)
    }

    /// The load force (Johansson & Westling's "load force", beside the grip force): how the
    /// fingertips `ks` share lifting the object. Each fingertip pushes `l_k` within the
    /// directions it can push, across its push along the normal (`range[k]`, a projection: the
    /// squeeze alone sets the normal force); together with the squeeze
    /// `N_k u_k` they apply the wrench the expected motion needs, `Σ (l_k + N_k u_k) =
    /// carry · m (a − g)` and no moment about the centre of mass (`arm[k]`: contact point from
    /// the centre, world), so the stick springs are left with nothing to carry and the object
    /// does not turn in the hand when the fingertips do not sit exactly opposite. Nearest to an
    /// equal share: `l = l₀ + Aᵀ (A Aᵀ + εI)⁻¹ (b − A l₀)`, moments scaled by 1/(3 cm); the
    /// small ε leaves out what the fingertips cannot do (a moment about the line through two
    /// contacts).
    #[allow(clippy::too_many_arguments)]
    fn distribute_load(
        &self,
        ks: &[usize],
        range: &[nalgebra::Matrix3<Real>; MAX_TIPS],
        arm: &[Vector; MAX_TIPS],
        mags: &[Real; MAX_TIPS],
        unit: &[Vector; MAX_TIPS],
        load_force: Vector,
        lift: &mut [Vector; MAX_TIPS],
    ) {
        const SCALE: Real = 1.0 / 0.03;
        let want = load_force * self.carry;
        let mut squeeze_force = Vector::zeros();
        let mut squeeze_moment = Vector::zeros();
        for &k in ks {
            let f = unit[k] * mags[k];
            squeeze_force += f;
            squeeze_moment += arm[k].cross(&f);
        }
        // Per fingertip, the 6x3 block A_k = [P_k; [r_k]x P_k / L].
        let mut blocks = [nalgebra::SMatrix::<Real, 6, 3>::zeros(); MAX_TIPS];
        let mut aat = nalgebra::Matrix6::<Real>::zeros();
        let mut resid = nalgebra::Vector6::<Real>::zeros();
        let share = want / ks.len() as Real;
        let mut b = nalgebra::Vector6::<Real>::zeros();
        b.fixed_rows_mut::<3>(0).copy_from(&(want - squeeze_force));
        b.fixed_rows_mut::<3>(3)
            .copy_from(&(-squeeze_moment * SCALE));
        resid += b;
        for &k in ks {
            let p = range[k];
            let mut a = nalgebra::SMatrix::<Real, 6, 3>::zeros();
            a.fixed_view_mut::<3, 3>(0, 0).copy_from(&p);
            a.fixed_view_mut::<3, 3>(3, 0)
                .copy_from(&(arm[k].cross_matrix() * p * SCALE));
            lift[k] = p * share;
            resid -= a * share;
            aat += a * a.transpose();
            blocks[k] = a;
        }
        let eps = 1e-3 * aat.trace().max(1e-12);
        for i in 0..6 {
            aat[(i, i)] += eps;
        }
        if let Some(chol) = aat.cholesky() {
            let y = chol.solve(&resid);
            for &k in ks {
                lift[k] += blocks[k].transpose() * y;
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

/// The fingertips of `plan` that rest on the object instead of squeezing it: those beside the
/// squeezing pair (thumb and index) that cannot push within the friction cone the operator
/// expects with its safety margin even before any load, i.e. whose push direction nearest the
/// contact normal ([`GraspPlan::normal_alignment`], cos θ) leans off it by tan θ > μ / safety.
/// Pressing harder with such a finger only makes it slide on the surface (a finger whose
/// flexion plane passes beside a cylinder's axis meets a surface turned away from the plane);
/// it closes until it touches and presses with the least force.
fn resting_tips(plan: &GraspPlan, hand: &HandModel, mu: Real, safety: Real) -> [bool; MAX_TIPS] {
    let mut out = [false; MAX_TIPS];
    let pair = [tip_index(hand, "thumb"), tip_index(hand, "index")];
    for (k, rest) in out.iter_mut().enumerate().take(hand.fingertips.len()) {
        if !plan.tips[k] || pair.contains(&Some(k)) {
            continue;
        }
        let c = plan.normal_alignment[k].clamp(1e-6, 1.0);
        let tan = (1.0 - c * c).sqrt() / c;
        *rest = tan * safety > mu;
    }
    out
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
        for seed in [1, 3, 6] {
            let (sim, trace) = run("box-slip", seed);
            let rest = trace[0].1;
            let table = sim.table_height();
            // The grip's lift-off peak carries the box up ...
            let (peak_at, peak) = trace
                .iter()
                .enumerate()
                .map(|(i, t)| (i, t.1))
                .fold((0, f64::MIN), |a, b| if b.1 > a.1 { b } else { a });
            assert!(
                peak > rest + 0.01,
                "seed {seed}: the box never rose ({peak} vs {rest})"
            );
            assert!(trace[peak_at].3 >= 2, "seed {seed}: held at the top");
            // ... it slips while held ...
            assert!(
                trace[peak_at..].iter().any(|t| t.2 && t.3 > 0),
                "seed {seed}: no slip flags after lift-off"
            );
            // ... and falls out of the grasp back to the table while the hand stays up.
            let last_hold = trace.iter().rfind(|t| t.0 == Phase::Hold).unwrap();
            assert_eq!(
                last_hold.3, 0,
                "seed {seed}: no contact left while the hand is up"
            );
            let st = sim.dfs().object_state();
            let depth = sim.dfs().object().shape.support_depth(&st.pose.rotation);
            assert!(
                last_hold.1 < peak - 0.05 && st.pose.translation.z - depth - table < 1e-3,
                "seed {seed}: the box is back on the table: {}",
                last_hold.1
            );
        }
    }

    /// Drift of the held object relative to the hand during `hold` (m/s): the least-squares
    /// slope (linear trend) of its position relative to the palm (the hand proper; the wrist's
    /// own compliance under the lift's end is not the grasp's), per axis, as a vector's
    /// length. The standard creep measure: zero-mean tremor does not count as drift. `hold_s`
    /// replaces the script's hold duration. Also returns the least number of contacts seen
    /// during `hold` and the object's lowest height above its start then.
    fn hold_drift(name: &str, seed: u64, hold_s: Option<Real>) -> (Real, usize, Real) {
        let mut s = Scenario::builtin(name, seed).unwrap();
        for t in s.tasks.iter_mut().filter(|t| t.phase == Phase::Hold) {
            t.duration = hold_s.unwrap_or(t.duration);
        }
        let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        let palm_link = sim
            .dfs()
            .hand()
            .links
            .iter()
            .position(|l| l.name == "palm")
            .expect("glove10 has a palm");
        let start = sim.dfs().object_state().pose.translation.z;
        let mut samples: Vec<(Real, Vector)> = Vec::new();
        let (mut contacts, mut lowest) = (usize::MAX, Real::INFINITY);
        while sim.step().unwrap() {
            if sim.phase() != Phase::Hold {
                continue;
            }
            let st = sim.dfs().object_state();
            let palm = sim.dfs().kinematics().link_poses[palm_link];
            let rel = (palm.inverse() * st.pose).translation.vector;
            samples.push((sim.time_ns() as Real * 1e-9, rel));
            contacts = contacts.min(sim.output().n_contacts);
            lowest = lowest.min(st.pose.translation.z - start);
        }
        let n = samples.len() as Real;
        let tm = samples.iter().map(|s| s.0).sum::<Real>() / n;
        let pm = samples.iter().map(|s| s.1).sum::<Vector>() / n;
        let stt: Real = samples.iter().map(|s| (s.0 - tm).powi(2)).sum();
        let slope = samples
            .iter()
            .map(|s| (s.1 - pm) * (s.0 - tm))
            .sum::<Vector>()
            / stt;
        (slope.norm(), contacts, lowest)
    }

    #[test]
    fn in_sphere_lift_both_fingertips_hold_the_sphere_up_through_hold_for_every_seed() {
        for seed in 0..5 {
            let (_, contacts, lowest) = hold_drift("sphere-lift", seed, None);
            assert!(contacts >= 2, "seed {seed}: only {contacts} contacts");
            assert!(lowest > 0.08, "seed {seed}: the sphere sank to {lowest} m");
        }
    }

    /// The creep of the held sphere relative to the palm, over a hold long enough that the
    /// fingers' tremor (8-12 Hz, whose beats and contact nonlinearity leave sub-hertz wander of
    /// a few µm) does not pass for a trend: 8 s. Over the built-in script's 2 s hold the same
    /// least-squares slope is 0.6-1.4 µm/s for seeds 0-4, and falls as T^-1.5 with the
    /// window, the signature of noise rather than creep (a creep keeps its rate).
    #[test]
    fn in_sphere_lift_the_held_sphere_drifts_below_1_um_per_s_relative_to_the_hand() {
        for seed in 0..5 {
            let (drift, contacts, _) = hold_drift("sphere-lift", seed, Some(8.0));
            assert!(contacts >= 2, "seed {seed}: dropped");
            assert!(drift < 1e-6, "seed {seed}: drift {} um/s", drift * 1e6);
        }
    }

    /// What happens to the object over a run of `scenario`: its height above the start at the
    /// end of `lift`, the least height and contacts during `hold`, the least height during
    /// `transport` and its sideways travel, and at the end its height above the start, its
    /// tilt from upright (rad) and the contacts left.
    struct Outcome {
        lifted: Real,
        hold_low: Real,
        hold_contacts: usize,
        transport_low: Real,
        carried: Real,
        end: Real,
        tilt: Real,
        end_contacts: usize,
    }

    fn outcome(scenario: &Scenario) -> Outcome {
        let mut sim = Simulation::new(scenario, HandModel::glove10(), None).unwrap();
        let start = sim.dfs().object_state().pose.translation.vector;
        let mut o = Outcome {
            lifted: 0.0,
            hold_low: Real::INFINITY,
            hold_contacts: usize::MAX,
            transport_low: Real::INFINITY,
            carried: 0.0,
            end: 0.0,
            tilt: 0.0,
            end_contacts: 0,
        };
        while sim.step().unwrap() {
            let p = sim.dfs().object_state().pose.translation.vector - start;
            match sim.phase() {
                Phase::Lift => o.lifted = p.z,
                Phase::Hold => {
                    o.hold_low = o.hold_low.min(p.z);
                    o.hold_contacts = o.hold_contacts.min(sim.output().n_contacts);
                }
                Phase::Transport => {
                    o.transport_low = o.transport_low.min(p.z);
                    o.carried = p.y;
                }
                _ => {}
            }
        }
        let st = sim.dfs().object_state();
        o.end = st.pose.translation.z - start.z;
        o.tilt = (st.pose.rotation * Vector::z()).angle(&Vector::z());
        o.end_contacts = sim.output().n_contacts;
        o
    }

    #[test]
    fn cylinder_power_grasp_lifts_holds_carries_and_sets_down_the_cylinder_for_every_seed() {
        for seed in 0..6 {
            let o = outcome(&Scenario::builtin("cylinder-power-grasp", seed).unwrap());
            assert!(o.lifted > 0.05, "seed {seed}: lifted only {} m", o.lifted);
            assert!(
                o.hold_low > 0.05 && o.hold_contacts >= 3,
                "seed {seed}: held at {} m on {} contacts",
                o.hold_low,
                o.hold_contacts
            );
            assert!(
                o.transport_low > 0.05 && (o.carried - 0.15).abs() < 0.02,
                "seed {seed}: carried {} m sideways, as low as {} m",
                o.carried,
                o.transport_low
            );
            assert!(
                o.end.abs() < 0.005 && o.tilt < 0.05,
                "seed {seed}: set down at {} m, tilted {} rad",
                o.end,
                o.tilt
            );
            assert_eq!(o.end_contacts, 0, "seed {seed}: released");
        }
    }

    /// Light spheres are lifted, held and set down like the built-in 300 g one. Below about
    /// 80 g the contacts' tangential dampers (30 N·s/m) were more than the object's explicit
    /// step can carry about its rolling axis: the sphere rattled between the pads from tick
    /// to tick and was flung out of the pinch (50 g: no lift at all; 100 g of 3 cm at μ 0.6:
    /// dropped while placing). The DFS now limits them (`dfs::STABLE_DAMPING`).
    ///
    /// Each is tried on seeds 0-5, and every seed lifts it. The 50 g sphere of 4 cm is held
    /// and set down in most of them, not all: since the table pushes only where the sphere
    /// touches it, the sphere turns on the table under the fingertips' uneven push and twist as
    /// they close on it (the table held a sphere's rotation still before), and in seeds 2 and 4
    /// the pinch it is lifted in then lets it swing out during the hold (4 of seeds 0-11 drop
    /// it; none did before). The 10 g and 100 g ones are held in every seed.
    #[test]
    fn pinches_lift_hold_and_set_down_spheres_of_10_to_100_g() {
        for (radius, mass, mu, need) in [
            (0.02, 0.01, 0.8, 6),
            (0.04, 0.05, 0.8, 3),
            (0.03, 0.1, 0.6, 6),
        ] {
            let mut held = Vec::new();
            for seed in 0..6 {
                let mut s = Scenario::builtin("sphere-lift", seed).unwrap();
                let o = s.object.as_mut().unwrap();
                o.radius = Some(radius);
                o.mass = mass;
                o.mu = mu;
                let o = outcome(&s);
                assert!(
                    o.lifted > 0.08,
                    "r {radius} m {mass} mu {mu} seed {seed}: lifted {}",
                    o.lifted
                );
                if o.hold_low > 0.08 && o.hold_contacts >= 2 && o.end.abs() < 0.005 {
                    held.push(seed);
                }
            }
            assert!(
                held.len() >= need,
                "r {radius} m {mass} mu {mu}: held and set down in seeds {held:?} only"
            );
        }
    }

    /// Thinner, thicker, lighter and heavier upright cylinders than the built-in's are lifted
    /// and carried as well. (They land a few degrees off upright when set down, on the rim,
    /// and rock back onto their end face after the release; before the table pushed only
    /// where an object touches it, the slenderest, heaviest ones fell over.)
    #[test]
    fn power_grasps_lift_and_carry_cylinders_of_25_to_45_mm_radius_and_200_to_800_g() {
        for (radius, mass) in [(0.025, 0.2), (0.025, 0.8), (0.045, 0.2), (0.045, 0.8)] {
            let mut s = Scenario::builtin("cylinder-power-grasp", 1).unwrap();
            let o = s.object.as_mut().unwrap();
            o.radius = Some(radius);
            o.mass = mass;
            let o = outcome(&s);
            assert!(
                o.lifted > 0.05 && o.hold_low > 0.05 && o.transport_low > 0.05,
                "r {radius} m {mass}: lifted {}, held {}, carried as low as {}",
                o.lifted,
                o.hold_low,
                o.transport_low
            );
            assert!(
                o.hold_contacts >= 2,
                "r {radius} m {mass}: {} contacts",
                o.hold_contacts
            );
        }
    }

    /// The operator's power grasp of `cylinder-power-grasp` wraps the hand around the cylinder:
    /// whole-hand contact on, and through `hold` the palm (its eminences) presses it, with at
    /// least two long fingers wrapped around it (touching by a phalanx or the fingertip).
    #[test]
    fn the_power_grasp_presses_the_cylinder_into_the_palm_with_the_fingers_wrapped_around_it() {
        use crate::hand::BodyPart;
        let s = Scenario::builtin("cylinder-power-grasp", 0).unwrap();
        let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        assert!(sim.plan.wrap.is_some() && sim.dfs().params().whole_hand);
        let shapes = sim.dfs().hand().contact_shapes.clone();
        let (mut hold_ticks, mut palm_ticks, mut wrapped_ticks) = (0, 0, 0);
        while sim.step().unwrap() {
            if sim.phase() != Phase::Hold {
                continue;
            }
            hold_ticks += 1;
            let pressing: Vec<usize> = (0..sim.output().n_body)
                .filter(|&i| sim.dfs().body_contacts()[i].in_contact)
                .collect();
            palm_ticks += usize::from(pressing.iter().any(|&i| shapes[i].part == BodyPart::Palm));
            let out = sim.output();
            let thumb = tip_index(sim.dfs().hand(), "thumb");
            let fingers: std::collections::BTreeSet<usize> = pressing
                .iter()
                .filter_map(|&i| match shapes[i].part {
                    BodyPart::Phalanx { finger } => finger,
                    BodyPart::Palm => None,
                })
                .chain((0..out.n_tips).filter(|&k| out.tips[k].in_contact))
                .filter(|&k| Some(k) != thumb)
                .collect();
            wrapped_ticks += usize::from(fingers.len() >= 2);
        }
        assert!(hold_ticks > 500);
        assert_eq!(palm_ticks, hold_ticks, "the palm let go");
        assert_eq!(wrapped_ticks, hold_ticks, "fewer than two fingers wrapped");
    }

    /// Pinches and fingertip grasps keep fingertip contact alone; a wrap is planned for a
    /// standing cylinder in a power grasp, its open hand clear of the cylinder above it and at
    /// the preshape, its palm on the cylinder at the grasp.
    #[test]
    fn a_wrap_is_planned_for_a_standing_cylinder_with_the_open_hand_clear_of_it() {
        let hand = HandModel::glove10();
        let s = Scenario::builtin("cylinder-power-grasp", 0).unwrap();
        let (object, _) = s.resolve().unwrap();
        let pose = Isometry::translation(0.0, 0.0, 0.09);
        let plan = plan_operator_grasp(&hand, &object, &pose, GraspStyle::Power, &[]).unwrap();
        let wrap = plan.wrap.expect("a wrap");
        let n = hand.dof();
        let mut kin = Kinematics::default();
        let gap = |base: &Isometry, kin: &mut Kinematics| {
            hand.forward_kinematics(base, &plan.q_open[..n], kin);
            let inv = pose.inverse();
            hand.contact_shapes
                .iter()
                .map(|c| {
                    crate::hand::contact_geometry::closest_to_object(
                        &c.primitive,
                        &(inv * kin.link_poses[c.link]),
                        &object.shape,
                    )
                    .gap
                })
                .fold(Real::INFINITY, Real::min)
        };
        let pre = gap(&plan.base, &mut kin);
        assert!((pre - power::WRAP_STANDOFF).abs() < 1e-4, "{pre}");
        // The grasp is the standoff nearer along the palm's normal: the nearest shape (an
        // eminence's edge) within it.
        let at = gap(&wrap.base, &mut kin);
        assert!((-1e-4..pre - 1e-3).contains(&at), "{at}");
        let above = approach_pose(&plan.base, &object.shape);
        assert!(gap(&above, &mut kin) > 0.02);
        // The palm's y (the thumb's side) up, its grasping side towards the cylinder.
        assert!((plan.base.rotation * Vector::y()).z > 0.999);
        let towards = pose.translation.vector - wrap.base.translation.vector;
        assert!((wrap.base.rotation * -Vector::z()).dot(&towards) > 0.0);
        // A pinch, and a power grasp of a sphere, stay fingertip grasps.
        let sphere = RigidObject::new(Shape::Sphere { radius: 0.04 }, 0.3).unwrap();
        for (o, style) in [(&object, GraspStyle::Pinch), (&sphere, GraspStyle::Power)] {
            let p = plan_operator_grasp(&hand, o, &pose, style, &[]).unwrap();
            assert!(p.wrap.is_none());
        }
    }

    #[test]
    fn a_power_grasp_opposes_thumb_and_index_across_the_cylinder_along_their_normals() {
        let s = Scenario::builtin("cylinder-power-grasp", 0).unwrap();
        let (object, _) = s.resolve().unwrap();
        let pose = Isometry::translation(0.0, 0.0, 0.09);
        let hand = HandModel::glove10();
        let plan = plan_grasp(&hand, &object, &pose, GraspStyle::Power).unwrap();
        let [thumb, index, middle] =
            ["thumb", "index", "middle"].map(|n| tip_index(&hand, n).unwrap());
        assert!(plan.tips[thumb] && plan.tips[index] && plan.tips[middle]);
        for k in [thumb, index] {
            assert!(
                plan.normal_alignment[k] > 0.98,
                "tip {k} pushes {} along its normal",
                plan.normal_alignment[k]
            );
        }
        // Opposite across the axis, each in its own flexion plane (8 mm apart on glove10).
        assert!(plan.normals_b[thumb].dot(&plan.normals_b[index]) < -0.95);
        let across = (plan.contacts_b[thumb] - plan.contacts_b[index]).y.abs();
        assert!((across - 0.008).abs() < 0.002, "{across}");
        // The middle finger's plane passes 2.4 cm beside the axis: it only rests on the
        // curved surface.
        let resting = resting_tips(&plan, &hand, 0.7, OperatorParams::default().grip_safety);
        assert!(resting[middle] && !resting[thumb] && !resting[index]);
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
    fn in_table_three_the_operator_lifts_the_box_from_between_the_ball_and_the_cylinder() {
        for seed in [0, 3] {
            let s = Scenario::builtin("table-three", seed).unwrap();
            let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
            assert_eq!(sim.scene().target().name, "box");
            let target = sim.target();
            assert_eq!(target, 1);
            let start: Vec<Vector> = sim
                .dfs()
                .objects()
                .iter()
                .map(|o| o.state.pose.translation.vector)
                .collect();
            let (mut lifted, mut others, mut overlaps) = (0.0, 0, 0);
            while sim.step().unwrap() {
                let out = sim.output();
                overlaps += usize::from(out.overlap.is_some());
                for tip in out.tips[..out.n_tips].iter().filter(|t| t.touching) {
                    others += usize::from(tip.object != target);
                }
                if sim.phase() == Phase::Hold {
                    let z = sim.target_state().pose.translation.z - start[target].z;
                    lifted = Real::max(lifted, z);
                }
            }
            assert!(lifted > 0.08, "seed {seed}: the box rose {lifted} m");
            assert_eq!(others, 0, "seed {seed}: a fingertip touched an obstacle");
            assert_eq!(overlaps, 0, "seed {seed}");
            let end = sim.dfs().objects();
            assert!(
                (end[target].state.pose.translation.vector - start[target]).norm() < 0.01,
                "seed {seed}: the box is set back down where it was"
            );
            // Resting on the table, the others stay where they were (to rounding: the table's
            // support of a cylinder on its 12 rim points balances to 1e-17 m).
            for i in [0, 2] {
                let moved = (end[i].state.pose.translation.vector - start[i]).norm();
                assert!(moved < 1e-9, "seed {seed}: object {i} moved {moved} m");
            }
            assert_eq!(sim.output().n_contacts, 0, "released");
        }
    }

    /// A hash (FNV-1a over the bits) of every 10th tick's base position, measured angles and
    /// torques and target pose of a run, with the run's last target and base poses.
    fn fingerprint(s: &Scenario) -> (u64, u64, Isometry, Isometry) {
        let mut sim = Simulation::new(s, HandModel::glove10(), None).unwrap();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut mix = |v: Real| {
            for b in v.to_bits().to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        while sim.step().unwrap() {
            if !sim.ticks().is_multiple_of(10) {
                continue;
            }
            let (q, tau, base) = sim.sample();
            for v in base.translation.vector.iter().chain(q).chain(tau) {
                mix(*v);
            }
            let st = sim.target_state();
            let pose = &st.pose;
            for v in pose
                .translation
                .vector
                .iter()
                .chain(pose.rotation.coords.iter())
            {
                mix(*v);
            }
        }
        let (_, _, base) = sim.sample();
        (sim.ticks(), h, sim.target_state().pose, *base)
    }

    /// `vary_reach` off (absent from the file, or false) leaves a session as it was before the
    /// field existed: `sphere-lift` seed 7 as computed before it, on x86-64 Linux bit for bit
    /// (elsewhere the platform's `sin` may round differently: to 1e-9 m there). Re-taken with
    /// issue 21's contact forces (no force across a gap, the pads at the contact preload, stick
    /// dampers without the sensors' noise, the elliptic soft-finger cone) together with the
    /// table that pushes only where the object touches it: the sphere is set down 0.57 mm and
    /// 1.0° from where it was before them.
    #[test]
    fn without_vary_reach_a_session_is_the_one_it_was_before() {
        let builtin = Scenario::builtin("sphere-lift", 7).unwrap();
        assert!(!builtin.vary_reach);
        let mut json = serde_json::to_value(&builtin).unwrap();
        assert!(json.get("vary_reach").is_none(), "not written when off");
        let absent: Scenario = serde_json::from_value(json.clone()).unwrap();
        json["vary_reach"] = false.into();
        let off: Scenario = serde_json::from_value(json).unwrap();
        assert_eq!((&absent, &off), (&builtin, &builtin));
        let (ticks, hash, object, base) = fingerprint(&absent);
        // Computed before `vary_reach` existed; again with the table that pushes only where the
        // object touches it and issue 21's contact forces (see above).
        let before_object = Isometry::from_parts(
            Vector::new(
                f64::from_bits(0xbf75_ebde_2ee3_965e),
                f64::from_bits(0xbf51_c295_7aac_a686),
                f64::from_bits(0x3fa4_7ae1_47ae_147c),
            )
            .into(),
            nalgebra::UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(
                f64::from_bits(0x3fef_f21b_2ddd_ab36),
                f64::from_bits(0xbfad_c418_6e87_2efe),
                f64::from_bits(0xbf64_e103_7fa3_ac5e),
                f64::from_bits(0x3f5b_68d4_4e7f_011c),
            )),
        );
        let before_base = Vector::new(
            f64::from_bits(0xbfa3_9a46_223c_d271),
            f64::from_bits(0xbfa0_f823_c88b_0412),
            f64::from_bits(0x3fcf_1251_ccde_a5c4),
        );
        assert_eq!(ticks, 7300);
        let moved = (object.translation.vector - before_object.translation.vector).norm();
        let turned = object.rotation.angle_to(&before_object.rotation);
        let base_moved = (base.translation.vector - before_base).norm();
        assert!(
            moved < 1e-9 && turned < 1e-9 && base_moved < 1e-9,
            "object {moved} m, {turned} rad, base {base_moved} m from before"
        );
        if cfg!(all(target_arch = "x86_64", target_os = "linux")) {
            assert_eq!(hash, 0x5be8_5ddb_bfac_c8fb, "{hash:#x}");
            assert_eq!(object, before_object);
            assert_eq!(base.translation.vector, before_base);
        }
    }

    /// A varied run of `name` with `seed` up to the end of its first approach: the
    /// simulation, the approach's path, and per tick the base position, its planned
    /// acceleration and whether any fingertip touched anything or any object overlapped
    /// another.
    fn varied(name: &str, seed: u64) -> (Simulation, ReachPath, Vec<(Vector, Vector, bool)>) {
        let mut s = Scenario::builtin(name, seed).unwrap();
        s.vary_reach = true;
        let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        let path = sim.reach_path.expect("a varied approach");
        let mut trace = Vec::new();
        while sim.step().unwrap() {
            if sim.span > 0 {
                break;
            }
            let out = sim.output();
            let touched = out.tips[..out.n_tips].iter().any(|t| t.touching);
            trace.push((
                sim.base.translation.vector,
                sim.base_acceleration,
                touched || out.overlap.is_some(),
            ));
        }
        (sim, path, trace)
    }

    #[test]
    fn varied_reaches_differ_by_seed_keep_the_noise_and_their_durations_make_the_ground_truth() {
        let plain = Simulation::new(
            &Scenario::builtin("table-three", 4).unwrap(),
            HandModel::glove10(),
            None,
        )
        .unwrap();
        let mut s = Scenario::builtin("table-three", 4).unwrap();
        s.vary_reach = true;
        let a = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        // The tremor and the noise stream are the seed's, varied or not.
        assert_eq!(
            (a.tremor_freq, a.tremor_phase),
            (plain.tremor_freq, plain.tremor_phase)
        );
        assert_eq!(a.rng, plain.rng);
        // The plain start is 15 cm above the approach pose; a varied one is not.
        let approach = approach_pose(&plain.plan.base, &plain.target_object().shape);
        assert_eq!(plain.base, raise(&approach, 0.15));
        s.seed = 5;
        let b = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        for sim in [&a, &b] {
            let d = (sim.base.translation.vector - approach.translation.vector).norm();
            assert!(
                (REACH_HOME_M.0 - 1e-9..=REACH_HOME_M.1 + 1e-9).contains(&d),
                "home {d} m from the approach pose"
            );
            assert!(
                sim.base.translation.z > sim.table_height + REACH_HOME_ABOVE_TABLE_M,
                "home above the table"
            );
            // The spans tile the session; only approach and preshape changed, and the session
            // is no longer than the scenario says it can be.
            assert!(sim.n_steps as Real * 1e-3 <= s.longest_duration() + 1e-9);
            assert!(s.longest_duration() > s.duration());
            assert_eq!(sim.spans[0].start_ns, 0);
            assert!(sim.spans.windows(2).all(|w| w[0].end_ns == w[1].start_ns));
            assert_eq!(sim.spans.last().unwrap().end_ns, sim.n_steps * TICK_NS);
            for (v, p) in sim.spans.iter().zip(&plain.spans) {
                let (dv, dp) = (v.end_ns - v.start_ns, p.end_ns - p.start_ns);
                match v.phase {
                    Phase::Approach | Phase::Preshape => {
                        let r = dv as Real / dp as Real;
                        assert!((0.7..=1.0 / 0.7 + 0.3 / 0.8 + 1e-9).contains(&r), "{r}")
                    }
                    _ => assert_eq!(dv, dp),
                }
            }
        }
        assert!((a.base.translation.vector - b.base.translation.vector).norm() > 0.01);
        assert_ne!(a.spans, b.spans);
        assert_ne!(a.reach_path, b.reach_path);
    }

    /// The varied reaches' random parts over many seeds: within their ranges, every one
    /// taken, a pause about half the time.
    #[test]
    fn varied_reaches_spread_over_their_ranges() {
        let mut pauses = 0;
        let (mut slow, mut fast) = (Real::INFINITY, 0.0 as Real);
        for seed in 0..200 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(REACH_STREAM);
            let r = Reach::draw(&mut rng, 0.8);
            assert!((REACH_SPEED.0..=REACH_SPEED.1).contains(&r.speed));
            assert!((r.move_s - 0.8 / r.speed).abs() <= 1e-3);
            slow = slow.min(r.speed);
            fast = fast.max(r.speed);
            if r.pause_s > 0.0 {
                pauses += 1;
                assert!((REACH_PAUSE_S.0 - 1e-3..=REACH_PAUSE_S.1 + 1e-3).contains(&r.pause_s));
            }
            assert!((0.0..=REACH_BEND).contains(&r.bend));
            // The path parameter runs from 0 to 1, rests in the pause, and its derivatives
            // are those of its values.
            let total = r.move_s + r.pause_s;
            let (u0, _, _) = r.progress(0.0);
            let (u1, v1, _) = r.progress(total);
            assert_eq!((u0, u1, v1), (0.0, 1.0, 0.0));
            let h = 1e-5;
            for k in 1..100 {
                let t = total * k as Real / 100.0;
                let (u, v, a) = r.progress(t);
                let (up, vp, _) = r.progress(t + h);
                let (um, vm, _) = r.progress(t - h);
                assert!((0.0..=1.0).contains(&u));
                assert!(((up - um) / (2.0 * h) - v).abs() < 1e-4, "{seed} {t}");
                assert!(
                    ((vp - vm) / (2.0 * h) - a).abs() < 1e-2 * (1.0 + a.abs()),
                    "{t}"
                );
            }
        }
        assert!((70..=130).contains(&pauses), "{pauses} of 200 pause");
        assert!(slow < 0.75 && fast > 1.25, "{slow} {fast}");
    }

    #[test]
    fn a_varied_first_approach_is_smooth_clear_of_everything_and_as_planned() {
        for (name, seed) in [
            ("table-three", 1),
            ("table-three", 2),
            ("table-three", 9),
            ("sphere-lift", 3),
            ("cylinder-power-grasp", 4),
        ] {
            let (sim, path, trace) = varied(name, seed);
            let end = approach_pose(&sim.plan.base, &sim.target_object().shape);
            let last = trace.last().unwrap().0;
            assert!(
                (last - end.translation.vector).norm() < 1e-4,
                "{name} {seed}"
            );
            let mut moved = 0.0 as Real;
            for (i, w) in trace.windows(3).enumerate() {
                let step = (w[1].0 - w[0].0).norm();
                moved = moved.max(step);
                assert!(step < 3e-3, "{name} {seed}: a {step} m jump at tick {i}");
                // The planned acceleration is the path's (the tremor, 5 µm at 8-12 Hz, adds up
                // to 0.05 m/s²).
                let second = (w[2].0 - 2.0 * w[1].0 + w[0].0) / 1e-6;
                let err = (second - w[1].1).norm();
                assert!(
                    err < 0.1 + 0.01 * w[1].1.norm(),
                    "{name} {seed}: acceleration {} vs {} at tick {i}",
                    second,
                    w[1].1
                );
            }
            assert!(moved > 5e-4, "{name} {seed}: it moved");
            assert!(
                trace.iter().all(|t| !t.2),
                "{name} {seed}: touched or overlapped while approaching"
            );
            assert!(
                trace.iter().all(|t| t.0.z > sim.table_height + 0.02),
                "{name} {seed}: the base stayed above the table"
            );
            // Bent as drawn (or less, never down), paused as drawn.
            let len = (end.translation.vector - trace[0].0).norm();
            assert!(path.bend.norm() <= REACH_BEND * len + 1e-9);
            let span = &sim.spans[0];
            let planned = path.reach.move_s + path.reach.pause_s;
            assert!(((span.end_ns - span.start_ns) as Real * 1e-9 - planned).abs() < 1e-9);
        }
    }

    /// Over the variants of `table-three` (every object a target in turn) and `two-grasps`
    /// (a second reach from where the first grasp left the hand): no fingertip touches
    /// anything while the hand reaches, none ever touches an object but the target, no two
    /// objects overlap, and the hand (its joints and fingertips) stays above the table.
    #[test]
    fn varied_reaches_touch_nothing_on_the_way_and_stay_above_the_table() {
        let runs = (1..=20)
            .map(|seed| ("table-three", seed))
            .chain((1..=5).map(|seed| ("two-grasps", seed)));
        for (name, seed) in runs {
            let s = Scenario::variant(name, seed).unwrap();
            let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
            let target = sim.target();
            let mut points = Vec::new();
            while sim.step().unwrap() {
                let out = sim.output();
                assert!(out.overlap.is_none(), "{name} {seed}");
                for tip in out.tips[..out.n_tips].iter().filter(|t| t.touching) {
                    assert_eq!(tip.object, target, "{name} {seed}: touched another object");
                    assert_ne!(
                        sim.phase(),
                        Phase::Approach,
                        "{name} {seed}: touched while reaching, at {} ms",
                        sim.ticks()
                    );
                }
                if sim.phase() == Phase::Approach {
                    hand_points(sim.dfs.hand(), sim.dfs.kinematics(), &mut points);
                    let low = points
                        .iter()
                        .map(|(p, r)| p.z - r - sim.table_height)
                        .fold(Real::INFINITY, Real::min);
                    assert!(low > 0.0, "{name} {seed}: {low} m above the table");
                }
            }
        }
    }

    #[test]
    fn a_varied_second_grasp_reaches_from_where_the_hand_is() {
        let mut s = Scenario::builtin("two-grasps", 3).unwrap();
        s.vary_reach = true;
        let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        let second = sim
            .spans
            .iter()
            .enumerate()
            .filter(|(_, p)| p.phase == Phase::Approach)
            .nth(1)
            .unwrap()
            .0;
        let mut before = None;
        let mut prev: Option<Vector> = None;
        while sim.step().unwrap() {
            let p = sim.base.translation.vector;
            if let Some(q) = prev {
                assert!((p - q).norm() < 3e-3, "a jump at {}", sim.ticks());
            }
            prev = Some(p);
            if sim.span + 1 == second {
                before = Some(p);
            }
            if sim.span == second {
                assert!(sim.reach_path.is_some());
                // Started where the retreat left the hand.
                let start = sim.from_base.translation.vector;
                assert!((start - before.unwrap()).norm() < 1e-4);
            }
        }
    }

    #[test]
    fn a_duration_out_of_range_is_refused() {
        let s = Scenario::builtin("box-pinch-lift", 0).unwrap();
        let e = Simulation::new(&s, HandModel::glove10(), Some(-1.0)).unwrap_err();
        assert!(e.to_string().contains("duration"));
    }
}
