//! Planning a grasp where the object lies: fingertip inverse kinematics with the hand's base
//! free ([`plan_grasp`]), and the operator's choice of plan ([`plan_operator_grasp`]).

use super::power::{plan_wrap, Wrap};
use crate::error::{DfsError, Result};
use crate::hand::ik::{solve_tips, IkParams};
use crate::hand::{HandModel, Joint, JointDrive, JointKind, Kinematics, Link, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Rotation, Vector};
use crate::object::{RigidObject, Shape};
use crate::scenario::GraspStyle;

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
    /// A power grasp that wraps the hand around the object ([`plan_wrap`]): the palm,
    /// phalanges and fingertips hold it (whole-hand contact), the fingers close by torque
    /// rather than to spots, so `q_grasp`, `q_pre` and `q_open` are all the open hand and the
    /// per-fingertip `contacts_b`, `normals_b` and `normal_alignment` are zero. `None`: a
    /// fingertip grasp.
    pub wrap: Option<Wrap>,
}

/// Index of a fingertip by name.
pub(super) fn tip_index(hand: &HandModel, name: &str) -> Option<usize> {
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
    let (thumb, fingers) = grasp_tips(hand, style)?;
    let n_hand = hand.dof();
    let posture = StartPosture::new(hand, style);
    let mut kin = Kinematics::default();
    let best = best_candidate(
        hand, object, pose, style, thumb, &fingers, &posture, &mut kin,
    )?;
    let q = best.q;
    let base = Isometry::from_parts(Vector::new(q[0], q[1], q[2]).into(), best.rotation);
    let mut q_grasp = [0.0; MAX_DOF];
    q_grasp[..n_hand].copy_from_slice(&q[3..n_hand + 3]);
    let mut tips = [false; MAX_TIPS];
    for &f in fingers.iter().chain(std::iter::once(&thumb)) {
        tips[f] = true;
    }
    let opening = Opening {
        hand,
        object,
        inv_obj: pose.inverse(),
        base_pose: base,
        q_grasp,
        posture: &posture,
    };
    let (fallback_pre, q_open) = (
        opening.opened(0.015, &mut kin),
        opening.opened(0.03, &mut kin),
    );
    let q_pre = preshape(hand, object, pose, &opening, &tips, &mut kin).unwrap_or(fallback_pre);
    let mut contacts_b = [Vector::zeros(); MAX_TIPS];
    let mut normals_b = [Vector::zeros(); MAX_TIPS];
    let mut normal_alignment = [0.0; MAX_TIPS];
    hand.forward_kinematics(&base, &q_grasp[..n_hand], &mut kin);
    hand.tip_jacobians(&mut kin);
    let inv_obj = pose.inverse();
    for (k, _) in tips.iter().enumerate().filter(|(_, &t)| t) {
        let c_b = (inv_obj * kin.tip_centres[k]).coords;
        let n_out = object.shape.closest(&c_b).normal;
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
        ik_error: best.ik_error,
        style,
        contacts_b,
        normals_b,
        normal_alignment,
        wrap: None,
    })
}

/// The fingertips a grasp of `style` targets: the thumb, and the index (a pinch) or the index
/// and middle (otherwise: ring and little follow the middle finger on glove10's coupled DOFs,
/// so only the independent fingers are targeted and the others close until they touch).
fn grasp_tips(hand: &HandModel, style: GraspStyle) -> Result<(usize, Vec<usize>)> {
    let thumb = tip_index(hand, "thumb").ok_or_else(|| {
        DfsError::invalid("hand", "the operator needs a fingertip named \"thumb\"")
    })?;
    let names: &[&str] = match style {
        GraspStyle::Pinch => &["index"],
        _ => &["index", "middle"],
    };
    let fingers: Vec<usize> = names.iter().filter_map(|n| tip_index(hand, n)).collect();
    if fingers.is_empty() {
        return Err(DfsError::invalid(
            "hand",
            "the operator needs an \"index\" fingertip",
        ));
    }
    Ok((thumb, fingers))
}

/// The hand's posture the search starts from, and the DOFs it leaves alone.
struct StartPosture {
    /// Bent fingers (a stretched finger cannot push along its length); a pinch's unused
    /// fingers curled into the palm.
    q: [Real; MAX_DOF],
    /// The wrist's DOFs.
    wrist: Vec<usize>,
    /// The DOFs of the fingers a pinch does not use: they stay curled.
    frozen: Vec<usize>,
}

impl StartPosture {
    fn new(hand: &HandModel, style: GraspStyle) -> StartPosture {
        let n_hand = hand.dof();
        let wrist: Vec<usize> = (0..n_hand)
            .filter(|&d| hand.dof_names[d].starts_with("wrist"))
            .collect();
        let mut frozen: Vec<usize> = Vec::new();
        let mut q = [0.0; MAX_DOF];
        for d in 0..n_hand {
            if !wrist.contains(&d) {
                let (lo, hi) = hand.sweep_range(d);
                q[d] = lo + 0.6 * (hi - lo);
            }
        }
        if style == GraspStyle::Pinch {
            for (d, name) in hand.dof_names.iter().enumerate() {
                if ["middle", "ring", "little"]
                    .iter()
                    .any(|f| name.starts_with(f))
                {
                    q[d] = hand.dof_lower[d].max(0.0);
                    frozen.push(d);
                }
            }
        }
        StartPosture { q, wrist, frozen }
    }
}

/// The best grasp the search found: the free-base hand's configuration (base position, then
/// the hand's DOFs) and the hand's orientation.
struct Candidate {
    score: Real,
    ik_error: Real,
    q: [Real; MAX_DOF],
    rotation: Rotation,
}

/// What the fingertip targets of every candidate of one search share.
struct TargetSearch<'a> {
    hand: &'a HandModel,
    object: &'a RigidObject,
    /// The object's centre (world).
    centre: Vector,
    power: bool,
    /// [`flexion_offsets`] (power grasps; zeros otherwise).
    lateral: &'a [Real; MAX_TIPS],
    thumb: usize,
    fingers: &'a [usize],
}

/// Where one candidate puts the fingertips.
struct Placement {
    /// The grasp axis (horizontal, world) and the horizontal across it.
    a: Vector,
    side: Vector,
    /// Height above the centre.
    h: Real,
    /// The object's half width along the axis.
    half: Real,
    /// Which way the fingers' and the thumb's distal joint axes point.
    sign: Real,
    thumb_sign: Real,
    /// The fingers' spread across the axis (pinch with two fingers).
    spread: Real,
}

impl TargetSearch<'_> {
    /// The IK targets: each real fingertip on the surface (the thumb on the near side of the
    /// axis, the fingers on the far side), then each one's virtual tip 2 cm across (`n_real`
    /// and on), as [`planning_model`] numbers them.
    fn targets(&self, p: &Placement, n_real: usize) -> Vec<(usize, Point)> {
        let (hand, object, power, centre) = (self.hand, self.object, self.power, self.centre);
        let Placement {
            a,
            side,
            h,
            half,
            sign,
            thumb_sign,
            spread,
        } = *p;
        let (thumb, lateral) = (self.thumb, self.lateral);
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
        let thumb_p =
            centre - a * reach(thumb_y, hand.fingertips[thumb].radius) + side * thumb_y + up;
        targets.push((0, Point::from(thumb_p)));
        targets.push((n_real, Point::from(thumb_p + side * (0.02 * thumb_sign))));
        for (i, &f) in self.fingers.iter().enumerate() {
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
            targets.push((n_real + 1 + i, Point::from(p + side * (0.02 * sign))));
        }
        targets
    }
}

/// Searches grasp axes × hand orientations (yaw of the palm about the vertical) × heights ×
/// sides for the grasp whose fingertips reach their spots and push best along their normals
/// and the vertical; an error naming how far the fingertips stayed if none reaches.
#[allow(clippy::too_many_arguments)]
fn best_candidate(
    hand: &HandModel,
    object: &RigidObject,
    pose: &Isometry,
    style: GraspStyle,
    thumb: usize,
    fingers: &[usize],
    posture: &StartPosture,
    kin: &mut Kinematics,
) -> Result<Candidate> {
    let obj_yaw = pose.rotation.euler_angles().2;
    let centre = pose.translation.vector;
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
    let power = style == GraspStyle::Power;
    let lateral = if power {
        flexion_offsets(hand, posture, thumb, fingers, kin)
    } else {
        [0.0; MAX_TIPS]
    };
    let mut search = CandidateSearch {
        targets: TargetSearch {
            hand,
            object,
            centre,
            power,
            lateral: &lateral,
            thumb,
            fingers,
        },
        posture,
        heights,
        best: None,
        best_err: Real::INFINITY,
    };
    // Try grasp axes × hand orientations (yaw of the palm about the vertical) × heights.
    let spreads: &[Real] = if fingers.len() > 1 && !power {
        &[0.02, -0.02][..]
    } else {
        &[0.0][..]
    };
    for &(axis_angle, half) in axes {
        for (k, &spread) in (0..12).flat_map(|k| spreads.iter().map(move |s| (k, s))) {
            let psi = k as Real * std::f64::consts::PI / 6.0;
            search.orientation(obj_yaw + axis_angle, psi, half, spread, kin);
        }
    }
    let best_err = search.best_err;
    search.best.ok_or_else(|| {
        DfsError::invalid(
            "object",
            format!("no grasp of this object is reachable for the hand (fingertips {:.1} mm from the surface)", best_err * 1e3),
        )
    })
}

/// The search of [`best_candidate`]: what its candidates share, and the best found so far.
struct CandidateSearch<'a> {
    targets: TargetSearch<'a>,
    posture: &'a StartPosture,
    /// Heights above the centre tried.
    heights: &'a [Real],
    best: Option<Candidate>,
    /// The least IK error of any candidate (m).
    best_err: Real,
}

impl CandidateSearch<'_> {
    /// The candidates with the grasp axis at `yaw` (world) and the palm turned `psi` more
    /// about the vertical: each height × side (the fingers' spread `spread`, the object's half
    /// width along the axis `half`).
    fn orientation(
        &mut self,
        yaw: Real,
        psi: Real,
        half: Real,
        spread: Real,
        kin: &mut Kinematics,
    ) {
        let TargetSearch {
            hand,
            power,
            thumb,
            fingers,
            ..
        } = self.targets;
        let rot = Rotation::from_euler_angles(0.0, 0.0, yaw + psi);
        let (free, real) = planning_model(hand, rot, thumb, fingers);
        let a = Rotation::from_euler_angles(0.0, 0.0, yaw) * Vector::x();
        let side = Vector::z().cross(&a);
        let params = IkParams {
            max_iterations: 150,
            tolerance: 2e-4,
            ..IkParams::default()
        }
        .with_frozen(self.posture.frozen.iter().map(|d| d + 3));
        let signs = [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)];
        for (&h, (sign, thumb_sign)) in self
            .heights
            .iter()
            .flat_map(|h| signs.into_iter().map(move |s| (h, s)))
        {
            // Power: the flexion planes are parallel, so the thumb's axis points the
            // same way as the fingers'.
            if power && sign != thumb_sign {
                continue;
            }
            let placement = Placement {
                a,
                side,
                h,
                half,
                sign,
                thumb_sign,
                spread,
            };
            self.placement(&free, real.len(), rot, &placement, &params, kin);
        }
    }

    /// One candidate: the planning model `free` (`n_real` real fingertips) turned by `rot`,
    /// its fingertips solved for onto `p`'s targets from the start posture behind the object;
    /// kept if it reaches them and pushes better than the best so far.
    fn placement(
        &mut self,
        free: &HandModel,
        n_real: usize,
        rot: Rotation,
        p: &Placement,
        params: &IkParams,
        kin: &mut Kinematics,
    ) {
        let centre = self.targets.centre;
        let targets = self.targets.targets(p, n_real);
        let n = free.dof();
        let mut q_start = [0.0; MAX_DOF];
        q_start[3..n].copy_from_slice(&self.posture.q[..n - 3]);
        let back = rot * Vector::x() * -0.12;
        q_start[0] = centre.x + back.x;
        q_start[1] = centre.y + back.y;
        q_start[2] = centre.z + 0.05 + p.h;
        let mut q = [0.0; MAX_DOF];
        let r = solve_tips(
            free,
            &Isometry::identity(),
            &targets,
            &q_start[..n],
            params,
            kin,
            &mut q[..n],
        );
        self.best_err = self.best_err.min(r.max_error);
        if r.max_error > 0.008 {
            return;
        }
        free.tip_jacobians(kin);
        let align = push_score(free, kin, &targets, n_real, &(centre + Vector::z() * p.h));
        let score = align - r.max_error * 20.0;
        if self.best.as_ref().is_none_or(|b| score > b.score + 1e-9) {
            self.best = Some(Candidate {
                score,
                ik_error: r.max_error,
                q,
                rotation: rot,
            });
        }
    }
}

/// Power grasp: where each fingertip's flexion plane lies across the hand (m, along the
/// index's distal joint axis in the hand's base frame at the start posture), relative to the
/// middle between the thumb's and the index's planes.
fn flexion_offsets(
    hand: &HandModel,
    posture: &StartPosture,
    thumb: usize,
    fingers: &[usize],
    kin: &mut Kinematics,
) -> [Real; MAX_TIPS] {
    let mut lateral = [0.0; MAX_TIPS];
    hand.forward_kinematics(&Isometry::identity(), &posture.q[..hand.dof()], kin);
    let index = fingers[0];
    let axis = hand
        .joints
        .iter()
        .find(|j| j.child == hand.fingertips[index].link)
        .map(|j| kin.link_poses[j.child].rotation * j.axis.into_inner())
        .unwrap_or(Vector::y());
    for &k in std::iter::once(&thumb).chain(fingers) {
        lateral[k] = kin.tip_centres[k].coords.dot(&axis);
    }
    let mid = 0.5 * (lateral[thumb] + lateral[index]);
    for v in lateral.iter_mut() {
        *v -= mid;
    }
    lateral
}

/// The planning model: the hand on a free base at orientation `rot`, its fingertips reduced
/// to the ones the grasp uses (`real`, the thumb first) plus, per finger, a virtual tip 2 cm
/// along the distal joint's axis. Targeting that virtual tip beside the real one turns the
/// finger's flexion plane to contain the grasp axis: a planar finger pushes only within that
/// plane.
fn planning_model(
    hand: &HandModel,
    rot: Rotation,
    thumb: usize,
    fingers: &[usize],
) -> (HandModel, Vec<usize>) {
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
    (free, real)
}

/// How well a candidate's fingertips can push (the least of three alignments): a finger with
/// few joints only pushes within the range of its Jacobian. The thumb and the finger opposite
/// it squeeze, so they must push along their normals (horizontal, from the grasp's `centre`
/// at its height); to lift by friction the thumb must push along the vertical, and so must a
/// finger on the other side (a pinch: both). `targets` below `n_real` are real fingertips,
/// the thumb's index 0; the tip Jacobians of `kin` must be current.
fn push_score(
    free: &HandModel,
    kin: &Kinematics,
    targets: &[(usize, Point)],
    n_real: usize,
    centre: &Vector,
) -> Real {
    let (mut along_normal, mut thumb_up, mut finger_up): (Real, Real, Real) = (1.0, 1.0, 0.0);
    for &(tip, target) in targets.iter().filter(|(t, _)| *t < n_real) {
        let normal = {
            let mut v = centre - target.coords;
            v.z = 0.0;
            v.normalize()
        };
        let up = push_alignment(free, kin, tip, &Vector::z());
        if tip <= 1 {
            along_normal = along_normal.min(push_alignment(free, kin, tip, &normal));
        }
        if tip == 0 {
            thumb_up = up;
        } else {
            finger_up = finger_up.max(up);
        }
    }
    along_normal.min(thumb_up).min(finger_up)
}

/// Opening the grasp's fingers: each finger group opened (less flexion) from the grasp pose
/// until its fingertips are `clearance` off the object's surface; the wrist and the fingers a
/// pinch does not use stay as they are.
struct Opening<'a> {
    hand: &'a HandModel,
    object: &'a RigidObject,
    inv_obj: Isometry,
    base_pose: Isometry,
    q_grasp: [Real; MAX_DOF],
    posture: &'a StartPosture,
}

impl Opening<'_> {
    fn opened(&self, clearance: Real, kin: &mut Kinematics) -> [Real; MAX_DOF] {
        let (hand, q_grasp) = (self.hand, &self.q_grasp);
        let n_hand = hand.dof();
        let mut out = *q_grasp;
        for g in &hand.finger_groups {
            let dofs: Vec<usize> = g
                .dofs
                .iter()
                .copied()
                .filter(|d| !self.posture.wrist.contains(d) && !self.posture.frozen.contains(d))
                .collect();
            let mut by = 0.1;
            loop {
                let mut trial = out;
                for &d in &dofs {
                    trial[d] = (q_grasp[d] - by).clamp(hand.dof_lower[d], hand.dof_upper[d]);
                }
                hand.forward_kinematics(&self.base_pose, &trial[..n_hand], kin);
                let clear = g.tips.iter().all(|&k| {
                    let d = self
                        .object
                        .shape
                        .closest(&(self.inv_obj * kin.tip_centres[k]).coords)
                        .distance;
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
    }
}

/// The preshape proper: each fingertip 1.5 cm straight out from its contact along the normal,
/// wrist and base fixed, so that closing approaches every face head-on; `None` if the fingers
/// cannot get within 3 mm of that (the caller then opens the fingers instead).
fn preshape(
    hand: &HandModel,
    object: &RigidObject,
    pose: &Isometry,
    opening: &Opening<'_>,
    tips: &[bool; MAX_TIPS],
    kin: &mut Kinematics,
) -> Option<[Real; MAX_DOF]> {
    let n_hand = hand.dof();
    let (base_pose, q_grasp) = (&opening.base_pose, &opening.q_grasp);
    hand.forward_kinematics(base_pose, &q_grasp[..n_hand], kin);
    let mut pre_targets: Vec<(usize, Point)> = Vec::new();
    for (k, _) in tips.iter().enumerate().filter(|(_, &t)| t) {
        let c = kin.tip_centres[k];
        let n_out = object.shape.closest(&(opening.inv_obj * c).coords).normal;
        pre_targets.push((k, Point::from(c.coords + (pose.rotation * n_out) * 0.015)));
    }
    let pre_params = IkParams {
        max_iterations: 200,
        tolerance: 5e-4,
        ..IkParams::default()
    }
    .with_frozen(
        opening
            .posture
            .wrist
            .iter()
            .chain(opening.posture.frozen.iter())
            .copied(),
    );
    let mut q_pre = [0.0; MAX_DOF];
    let r = solve_tips(
        hand,
        base_pose,
        &pre_targets,
        &q_grasp[..n_hand],
        &pre_params,
        kin,
        &mut q_pre[..n_hand],
    );
    if r.max_error > 0.003 {
        None
    } else {
        Some(q_pre)
    }
}

/// The style `style` takes for `object`: `auto` is a pinch for objects narrower than 6 cm
/// along x, else a power grasp.
pub(super) fn resolve_style(style: GraspStyle, object: &RigidObject) -> GraspStyle {
    match style {
        GraspStyle::Auto if object.shape.width_x() < 0.06 => GraspStyle::Pinch,
        GraspStyle::Auto => GraspStyle::Power,
        s => s,
    }
}

/// The operator's grasp of `object` at `pose` in `style`, clear of `obstacles`: a power grasp
/// of a standing cylinder by a hand with a palm contact shape wraps the hand around it
/// ([`plan_wrap`], whole-hand contact); any other grasp is a fingertip grasp
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
pub(super) fn mount_link(hand: &HandModel, tip: usize) -> usize {
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
