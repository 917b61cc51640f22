//! The power grip (whole-hand contact, issue 21 item 5): the operator closes the fingers on an
//! object with constant flexion torques and holds the rest of the hand by a joint impedance, and
//! the closed loop that runs it on a glove whose motors track the DFS.
//!
//! One torque law ([`PowerGrip::torques`]) for everything that holds an object in a power grasp:
//! the simulated operator's wrap ([`plan_wrap`], [`crate::operator::Simulation`]), the settled
//! power grasp of `dfs_core::fixtures` (feature `fixtures`), its tests, the allocation test and
//! `icms bench tick --scene power-grasp`; one closed-loop tick ([`grip_tick`]) for the last four.
//!
//! # The wrap
//!
//! A hand built like glove10 (fingers along the palm's +x, the grasping side of the palm facing
//! −z, the thumb on +y, every finger flexing about the palm's y) wraps a standing cylinder from
//! its side: the palm's y along the cylinder's axis (the thumb up), the palm against the curved
//! side, the fingers open and straight, so that the open hand slides down over the cylinder
//! from above without touching it (the approach pose is above the grasp, along the palm's y).
//! At the grasp the fingers close around the cylinder with constant flexion torques
//! ([`WRAP_CLOSE`] of each finger DOF's torque limit) and press it into the palm; the operator
//! then squeezes as hard as friction needs to carry the load it expects (weight plus the arm's
//! acceleration) with its safety margin, through every contact of the hand: palm, phalanges and
//! fingertips ([`WRAP_NORMAL_PER_GRIP`]). The wrist and the thumb are held by a stiff impedance
//! ([`WRAP_KP_PER_LIMIT`]): people stiffen the wrist in a power grip, and the load hangs off it.

use crate::dfs::{Dfs, GloveSample, TickOutput};
use crate::error::Result;
use crate::hand::contact_geometry::closest_to_object;
use crate::hand::{BodyPart, HandModel, Kinematics, MAX_DOF};
use crate::math::{Isometry, Real, Rotation, Vector};
use crate::object::{RigidObject, Shape};

/// The closing torque of each finger DOF of a wrap, as a fraction of its torque limit, while
/// the fingers close on the object (the settled power grasp of `dfs_core::fixtures` uses the
/// same).
pub const WRAP_CLOSE: Real = 0.1;

/// Joint stiffness of the impedance holding the wrist and the thumb in a power grip, per N·m of
/// torque limit (1/rad).
pub const WRAP_KP_PER_LIMIT: Real = 5.0;

/// Its damping, per N·m of torque limit (s/rad).
pub const WRAP_KD_PER_LIMIT: Real = 0.02;

/// The normal force (N) that the contacts of glove10's wrap around a cylinder press with in
/// all, per unit of the closing level (the fraction of each finger DOF's torque limit): the
/// palm's push balances the fingers', so the whole is about twice what the fingers push with.
/// On `cylinder-power-grasp` the contacts pressed with 40-50 N per unit level; the operator
/// expects less (30), as people grip a power grasp with a wider margin than a pinch: with 60
/// the cylinder slid out of some variants' grasps while the grip relaxed after the lift.
pub const WRAP_NORMAL_PER_GRIP: Real = 30.0;

/// The most the operator squeezes a wrap with, as a fraction of each finger DOF's torque limit.
pub const WRAP_MAX_GRIP: Real = 0.6;

/// Gap (m) between the hand and the cylinder where the open hand slides down over it; the
/// preshape then brings the palm this much nearer, onto it ([`Wrap::base`]).
pub const WRAP_STANDOFF: Real = 0.003;

/// Finger joint angles of the open hand of a wrap (rad): MCP, PIP, DIP of each long finger,
/// nearly straight so that the fingers pass beside the cylinder.
pub const WRAP_OPEN_FINGER: [Real; 3] = [0.0, 0.15, 0.1];

/// Thumb CMC and MCP angles of a wrap (rad): open, clear of the cylinder, its base (the
/// thenar) beside the palm.
pub const WRAP_THUMB: [Real; 2] = [-0.8, 0.0];

/// The operator's power grip: per DOF, a closing torque scaled by the grip and a joint
/// impedance about a set posture, clamped to the glove's sensor range. Fixed-size: the operator
/// makes one every tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerGrip {
    /// Number of DOFs.
    pub n: usize,
    /// Closing torque of each DOF at grip 1 (N·m; 0 on the wrist and the thumb).
    pub close: [Real; MAX_DOF],
    /// Joint stiffness about [`set`](Self::set) (N·m/rad).
    pub kp: [Real; MAX_DOF],
    /// Joint damping (N·m·s/rad).
    pub kd: [Real; MAX_DOF],
    /// The set posture (rad).
    pub set: [Real; MAX_DOF],
    /// Largest torque magnitude of each DOF (N·m): the glove's sensor range.
    pub limit: [Real; MAX_DOF],
}

impl PowerGrip {
    /// The grip of `hand` closing the DOFs `fingers` with [`WRAP_CLOSE`] of their torque
    /// limits, the other DOFs held at `set` by [`WRAP_KP_PER_LIMIT`], every DOF damped by
    /// [`WRAP_KD_PER_LIMIT`]; torques clamped to twice the torque limits (the DFS's default
    /// sensor range).
    pub fn closing(hand: &HandModel, fingers: &[usize], set: &[Real]) -> PowerGrip {
        let n = hand.dof().min(MAX_DOF);
        let mut g = PowerGrip {
            n,
            close: [0.0; MAX_DOF],
            kp: [0.0; MAX_DOF],
            kd: [0.0; MAX_DOF],
            set: [0.0; MAX_DOF],
            limit: [0.0; MAX_DOF],
        };
        for d in 0..n {
            let lim = hand.torque_limit[d];
            g.kp[d] = lim * WRAP_KP_PER_LIMIT;
            g.kd[d] = lim * WRAP_KD_PER_LIMIT;
            g.limit[d] = 2.0 * lim;
            g.set[d] = set.get(d).copied().unwrap_or(0.0);
        }
        for &d in fingers.iter().filter(|&&d| d < n) {
            g.close[d] = WRAP_CLOSE * hand.torque_limit[d];
            // While closing, the fingers follow their torques alone.
            g.kp[d] = 0.0;
        }
        g
    }

    /// The torques for the glove's angles `q` and velocities `qd` with the closing torques
    /// scaled by `grip`: `τ = grip · close + kp (set − q) − kd q̇`, clamped to `limit`.
    pub fn torques(&self, grip: Real, q: &[Real], qd: &[Real], tau: &mut [Real]) {
        let n = self.n.min(q.len()).min(qd.len()).min(tau.len());
        for d in 0..n {
            let lim = self.limit[d];
            tau[d] = (grip * self.close[d] + self.kp[d] * (self.set[d] - q[d])
                - self.kd[d] * qd[d])
                .clamp(-lim, lim);
        }
    }
}

/// One tick of the closed loop of a power grip with the hand's base at `base`: the grip's
/// torques (scaled by `grip`) for the glove state `q`, `qd` into `tau`, the DFS's step on them,
/// and the glove's state after it (its motors track the DFS's commands exactly) back into `q`
/// and `qd`. Allocation-free.
pub fn grip_tick<'a>(
    dfs: &'a mut Dfs,
    power: &PowerGrip,
    grip: Real,
    base: Isometry,
    q: &mut [Real],
    qd: &mut [Real],
    tau: &mut [Real],
) -> Result<&'a TickOutput> {
    let n = q.len();
    power.torques(grip, q, qd, tau);
    let o = dfs.step(&GloveSample {
        q: &*q,
        tau: &*tau,
        base,
    })?;
    q.copy_from_slice(&o.motor_q[..n]);
    qd.copy_from_slice(&o.motor_qd[..n]);
    Ok(o)
}

/// A planned wrap of a standing cylinder ([module documentation](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wrap {
    /// Pose of the hand base at the grasp: the palm on the cylinder (world).
    pub base: Isometry,
    /// The palm's outward normal (world, horizontal): the base backs off along it.
    pub out: Vector,
    /// Per DOF, whether the grip closes it (the long fingers' flexions).
    pub closes: [bool; MAX_DOF],
}

/// Whether `shape` at `pose` is a cylinder standing on an end face (axis within 0.1 rad of
/// the vertical): the object a wrap grasps.
pub fn is_standing_cylinder(shape: &Shape, pose: &Isometry) -> bool {
    matches!(shape, Shape::Cylinder { .. }) && (pose.rotation * Vector::z()).z > (0.1 as Real).cos()
}

/// The smallest gap (m) between any contact shape or fingertip of `hand` (posed by `kin`) and
/// `object` at `pose`.
fn hand_gap(hand: &HandModel, kin: &Kinematics, object: &RigidObject, pose: &Isometry) -> Real {
    let inv = pose.inverse();
    let shapes = hand.contact_shapes.iter().map(|s| {
        closest_to_object(&s.primitive, &(inv * kin.link_poses[s.link]), &object.shape).gap
    });
    let tips = hand.fingertips.iter().enumerate().map(|(k, t)| {
        object
            .shape
            .closest(&(inv * kin.tip_centres[k]).coords)
            .distance
            - t.radius
    });
    shapes.chain(tips).fold(Real::INFINITY, Real::min)
}

/// Plans a wrap ([module documentation](self)) of the standing cylinder `object` at `pose`
/// with `hand`: the open posture (into `q_open`), the base at the preshape
/// ([`WRAP_STANDOFF`] off the cylinder) and the [`Wrap`]. The hand's palm yaw about the
/// cylinder's axis is the one of 12 (every 30° from the object's x axis) whose open hand keeps
/// farthest from `obstacles` (other objects and their poses). `None` when the hand has no palm
/// contact shape, no long fingers named as glove10's, or the object is not a standing cylinder.
pub fn plan_wrap(
    hand: &HandModel,
    object: &RigidObject,
    pose: &Isometry,
    obstacles: &[(RigidObject, Isometry)],
    q_open: &mut [Real; MAX_DOF],
) -> Option<(Isometry, Wrap)> {
    let Shape::Cylinder {
        radius,
        half_height,
    } = object.shape
    else {
        return None;
    };
    if !is_standing_cylinder(&object.shape, pose) {
        return None;
    }
    if !hand.contact_shapes.iter().any(|s| s.part == BodyPart::Palm) {
        return None;
    }
    let n = hand.dof().min(MAX_DOF);
    let dof = |name: &str| hand.dof_names.iter().position(|d| d == name);
    let mut closes = [false; MAX_DOF];
    *q_open = [0.0; MAX_DOF];
    for finger in ["index", "middle", "ring", "little"] {
        for (j, joint) in ["mcp", "pip", "dip"].iter().enumerate() {
            if let Some(d) = dof(&format!("{finger}_{joint}")) {
                closes[d] = true;
                q_open[d] = WRAP_OPEN_FINGER[j].clamp(hand.dof_lower[d], hand.dof_upper[d]);
            }
        }
    }
    if !closes.iter().any(|&c| c) {
        return None;
    }
    for (j, joint) in ["thumb_cmc", "thumb_mcp"].iter().enumerate() {
        if let Some(d) = dof(joint) {
            q_open[d] = WRAP_THUMB[j].clamp(hand.dof_lower[d], hand.dof_upper[d]);
        }
    }
    // The cylinder's axis along the palm's y, this far along the palm's x from the wrist: its
    // near side 15 mm from the wrist, over the eminences, where the closing fingers push it
    // (placed farther out, it slides back to them and a thick or short one tips over on the
    // way; nearer in, the fingers reach less far around it).
    let along = radius + 0.015;
    // The hand's middle (between the little finger and the thumb) a little above the
    // cylinder's centre of mass.
    let up = Vector::z();
    let centre = pose.translation.vector + (pose.rotation * up) * (0.3 * half_height);
    let yaw0 = pose.rotation.euler_angles().2;
    let mut kin = Kinematics::default();
    // The base whose palm is `gap` off the cylinder, for palm yaw `psi`.
    let base_at = |psi: Real, gap: Real, kin: &mut Kinematics| {
        let d = Rotation::from_euler_angles(0.0, 0.0, yaw0 + psi) * Vector::x();
        let z_palm = d.cross(&up);
        let rot = Rotation::from_basis_unchecked(&[d, up, z_palm]);
        // The cylinder's axis is `s` (palm −z) from the palm's origin: bisect for the gap.
        let place = |s: Real| Isometry::from_parts((centre - d * along + z_palm * s).into(), rot);
        let (mut lo, mut hi) = (0.0, 0.2 + radius);
        for _ in 0..40 {
            let s = 0.5 * (lo + hi);
            hand.forward_kinematics(&place(s), &q_open[..n], kin);
            if hand_gap(hand, kin, object, pose) < gap {
                lo = s;
            } else {
                hi = s;
            }
        }
        (place(hi), z_palm)
    };
    let mut best: Option<(Real, Isometry, Vector)> = None;
    for k in 0..12 {
        let psi = k as Real * std::f64::consts::PI / 6.0;
        let (base, out) = base_at(psi, WRAP_STANDOFF, &mut kin);
        hand.forward_kinematics(&base, &q_open[..n], &mut kin);
        let clear = obstacles
            .iter()
            .map(|(o, p)| hand_gap(hand, &kin, o, p))
            .fold(Real::INFINITY, Real::min);
        if best.as_ref().is_none_or(|b| clear > b.0 + 1e-6) {
            best = Some((clear, base, out));
        }
    }
    let (_, pre, out) = best?;
    // The palm onto the cylinder: the standoff nearer, along its normal.
    let grasp = Isometry::from_parts(
        (pre.translation.vector - out * WRAP_STANDOFF).into(),
        pre.rotation,
    );
    Some((
        pre,
        Wrap {
            base: grasp,
            out,
            closes,
        },
    ))
}
