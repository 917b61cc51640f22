//! Whole-hand contact in the DFS tick (issue 21 item 5): the palm and the phalanges
//! ([`HandModel::contact_shapes`](crate::hand::HandModel)) touch objects besides the fingertips,
//! when [`DfsParams::whole_hand`](super::DfsParams::whole_hand) is on.
//!
//! A fingertip passes on the operator's intensities (eq. 14: the joint torques resolved into
//! fingertip forces). The palm and the phalanges have no such intensities of their own: what
//! they push with is where the hand is, so each is a stiff unilateral spring-damper contact
//! (penalty) with stick friction:
//!
//! - **Detection** (stage 2): the shape's deepest point in the object, or its nearest within the
//!   contact margin ([`closest_to_object`]); the object it penetrates deepest, as a fingertip.
//! - **Force** (stage 3): along the normal `k d + c ḋ` with `d` the penetration, only while `d >
//!   0` and never pulling; across it a stick spring-damper between the material points of the
//!   hand and of the object that were together when the contact stuck (the same stiffness and
//!   damping), the whole limited by the contact model and friction cone
//!   ([`apply_friction`]); beyond the cone the contact slips and its anchor follows. The
//!   result is the contact's intensities `c̃`: one column block of `W` with its own frame, like
//!   a fingertip's, so the object's wrench, the reaction `W⁺ f_ext` and the grasp rank count it.
//! - **The hand** (stage 5) feels the opposite force at the same point (Newton's third law),
//!   through the point's Jacobian `Jᵀ` into the joint-space finger dynamics, with the spring's
//!   stiffness and damping in the implicit step (a phalanx weighs grams: an explicit spring of
//!   this stiffness would ring). Like the fingertips' springs, the force uses the fingertip of
//!   the finger dynamics (the measured link moved by `J (θ − θ_measured)`) and the velocity of
//!   the joints integrated here and of the base, never a difference of measured angles.
//! - **Stability of the object's explicit step**: per contact, the stiffness and damping are
//!   limited so that `Σ k dt² / m_eff ≤` [`BODY_STIFFNESS_BUDGET`] and `Σ c dt / m_eff ≤`
//!   [`STABLE_DAMPING`](super::STABLE_DAMPING) over the contacts on an object (a bound of the
//!   object's inverse effective mass at the contact, as for the fingertips' dampers).
//!
//! Allocation-free: fixed arrays of [`MAX_CONTACT_SHAPES`].

use super::{Dfs, TipDofs};
use crate::contact::{apply_friction, ContactFrame, Intensity};
use crate::grasp::MAX_CONTACTS;
use crate::hand::contact_geometry::closest_to_object;
use crate::hand::{HandModel, TipJacobian, MAX_CONTACT_SHAPES, MAX_DOF, MAX_TIPS};
use crate::math::{Point, Real, Vector};

/// How much of the explicit object step's stability limit the whole-hand contacts' springs may
/// use: `Σ_k k_k dt² / m_k ≤ 0.5` over the contacts on an object (an explicit step of a spring
/// `k` on a mass `m` is stable for `k dt² / m < 4`).
pub const BODY_STIFFNESS_BUDGET: Real = 0.5;

/// What a tick found at one contact shape (palm or phalanx) of the hand.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BodyContact {
    /// The shape is within the contact margin of an object.
    pub touching: bool,
    /// Which object (index in the scene); 0 when not touching.
    pub object: usize,
    /// Pressed into the object and pushing: the contact transmits force (a column block of W).
    pub in_contact: bool,
    /// Contact geometry in B (valid when touching): the point on the object's surface and the
    /// frame whose z is the normal into the object.
    pub frame: Option<ContactFrame>,
    /// Penetration (m), negative for a gap (valid when touching).
    pub penetration: Real,
    /// What acts on the object, `c̃` (N, N·m) in the contact frame.
    pub transmitted: Intensity,
    /// The object's reaction `W⁺ f_ext` at this contact, friction-limited.
    pub reaction: Intensity,
    /// The spring's tangential force was beyond the friction cone: the contact slides.
    pub slip: bool,
}

/// The DFS's per-shape state of the whole-hand contacts.
#[derive(Debug, Clone)]
pub(super) struct BodyState {
    /// Shapes taking part: the hand's contact shapes when whole-hand contact is on, else 0.
    pub n: usize,
    /// Per shape: the ball (link frame centre, radius) that holds it, for the broad phase.
    bound: [(Vector, Real); MAX_CONTACT_SHAPES],
    /// Per shape: the DOFs moving its link, in the implicit step's solve order.
    pub dofs_solve: [TipDofs; MAX_CONTACT_SHAPES],
    /// Per shape: the object its anchor is on, and the anchor: the material points of the hand
    /// (link frame) and of the object (B) that were together when it stuck.
    anchor_object: [usize; MAX_CONTACT_SHAPES],
    anchor_b: [Option<(Vector, Vector)>; MAX_CONTACT_SHAPES],
    /// Per shape: the hand's deepest point (world, measured kinematics) this tick.
    point: [Vector; MAX_CONTACT_SHAPES],
    /// Per shape: the Jacobian of that point (world; linear rows used).
    jac: [TipJacobian; MAX_CONTACT_SHAPES],
    /// Per shape, for the implicit finger step: the contact's force on the hand (world), the
    /// normal (world), the stiffness and damping along it and, when sticking, across it.
    force_world: [Vector; MAX_CONTACT_SHAPES],
    normal_world: [Vector; MAX_CONTACT_SHAPES],
    stiffness: [Real; MAX_CONTACT_SHAPES],
    damping: [Real; MAX_CONTACT_SHAPES],
    sticking: [bool; MAX_CONTACT_SHAPES],
    active: [bool; MAX_CONTACT_SHAPES],
}

impl BodyState {
    /// The state for `hand`; `on` when whole-hand contact is on.
    pub fn new(hand: &HandModel, on: bool, solve_position: &[usize; MAX_DOF]) -> Self {
        let n = if on {
            hand.contact_shapes.len().min(MAX_CONTACT_SHAPES)
        } else {
            0
        };
        let mut bound = [(Vector::zeros(), 0.0); MAX_CONTACT_SHAPES];
        let mut dofs_solve = [TipDofs {
            dofs: [0; MAX_DOF],
            len: 0,
        }; MAX_CONTACT_SHAPES];
        for (s, shape) in hand.contact_shapes.iter().take(n).enumerate() {
            bound[s] = shape.bounding_sphere();
            let mut t = TipDofs::of_link(hand, shape.link);
            let len = t.len;
            t.dofs[..len].sort_by_key(|&d| solve_position[d]);
            dofs_solve[s] = t;
        }
        BodyState {
            n,
            bound,
            dofs_solve,
            anchor_object: [0; MAX_CONTACT_SHAPES],
            anchor_b: [None; MAX_CONTACT_SHAPES],
            point: [Vector::zeros(); MAX_CONTACT_SHAPES],
            jac: [TipJacobian::zeros(); MAX_CONTACT_SHAPES],
            force_world: [Vector::zeros(); MAX_CONTACT_SHAPES],
            normal_world: [Vector::zeros(); MAX_CONTACT_SHAPES],
            stiffness: [0.0; MAX_CONTACT_SHAPES],
            damping: [0.0; MAX_CONTACT_SHAPES],
            sticking: [false; MAX_CONTACT_SHAPES],
            active: [false; MAX_CONTACT_SHAPES],
        }
    }
}

impl BodyState {
    /// Stage 5, whole hand: each active contact's force on the hand into the feedback torques
    /// `fb_torque` (`Jᵀ f`, which the finger step applies), and its spring into the implicit
    /// finger step's matrix `a` (the solve order's lower triangle) and right-hand side `rhs`.
    /// The force holds the damping of the joints' velocity at the step's start; the implicit
    /// step takes that damping at the step's end instead, so it is added back to `rhs`.
    /// `cols` is scratch for a shape's linear Jacobian columns.
    pub(super) fn add_to_finger_step(
        &self,
        dt: Real,
        qd: &[Real; MAX_DOF],
        a: &mut crate::hand::DofMatrix,
        rhs: &mut [Real; MAX_DOF],
        fb_torque: &mut [Real; MAX_DOF],
        cols: &mut [Vector; MAX_DOF],
    ) {
        for s in 0..self.n {
            if !self.active[s] {
                continue;
            }
            let j = &self.jac[s];
            let f = self.force_world[s];
            let z = self.normal_world[s];
            let (k, c) = (self.stiffness[s], self.damping[s]);
            let gain = dt * c + dt * dt * k;
            let sticking = self.sticking[s];
            let dofs = self.dofs_solve[s].as_slice();
            // The linear Jacobian columns of the shape's DOFs (column-major storage), read
            // once: the block below uses each about as often as the shape has DOFs.
            let js = j.as_slice();
            let cols = &mut cols[..dofs.len()];
            let mut v_joint = Vector::zeros();
            for (c, &d) in cols.iter_mut().zip(dofs) {
                *c = Vector::new(js[6 * d], js[6 * d + 1], js[6 * d + 2]);
                v_joint += *c * qd[d];
            }
            let cols = &*cols;
            let damped = if sticking {
                v_joint * c
            } else {
                z * (v_joint.dot(&z) * c)
            };
            for (p1, (&d1, &col1)) in dofs.iter().zip(cols).enumerate() {
                if col1 == Vector::zeros() {
                    continue;
                }
                fb_torque[d1] += col1.dot(&f);
                rhs[d1] += dt * col1.dot(&damped);
                let pc1 = if sticking {
                    col1 * gain
                } else {
                    z * (z.dot(&col1) * gain)
                };
                for (&d2, col2) in dofs[..=p1].iter().zip(cols) {
                    a[(d1, d2)] += pc1.dot(col2);
                }
            }
        }
    }
}

/// The slot of shape `s` among the contacts' owners ([`Dfs::contact_tip`]): after the tips.
#[inline]
pub(super) fn owner_of_shape(s: usize) -> usize {
    MAX_TIPS + s
}

impl Dfs {
    /// Stage 2, whole hand: each contact shape against the objects (module documentation).
    pub(super) fn detect_body_contacts(&mut self) {
        let margin = self.params.contact_margin;
        let mut inverse = [crate::math::Isometry::identity(); super::MAX_OBJECTS];
        for (inv, o) in inverse.iter_mut().zip(&self.objects[..self.n_objects]) {
            *inv = o.state.pose.inverse();
        }
        for s in 0..self.body.n {
            let shape = &self.hand.contact_shapes[s];
            let link_pose = self.kin.link_poses[shape.link];
            let (centre, radius) = self.body.bound[s];
            let centre_world = (link_pose * Point::from(centre)).coords;
            let b = &mut self.body_out[s];
            *b = BodyContact::default();
            let mut deepest_point = Vector::zeros();
            for (i, o) in self.objects[..self.n_objects].iter().enumerate() {
                let pos = o.state.pose.translation.vector;
                let reach = self.bodies[i].bounding_radius + radius + margin;
                if (centre_world - pos).norm_squared() > reach * reach * (1.0 + 1e-9) {
                    continue;
                }
                let pose_in_b = inverse[i] * link_pose;
                let c = closest_to_object(&shape.primitive, &pose_in_b, &o.object.shape);
                if c.gap > margin || (b.touching && -c.gap <= b.penetration) {
                    continue;
                }
                b.touching = true;
                b.object = i;
                b.frame = Some(ContactFrame::from_normal(c.p_b, -c.n_out_b));
                b.penetration = -c.gap;
                // The shape's deepest point: from the surface point along the outward normal by
                // the gap.
                deepest_point = (o.state.pose * Point::from(c.p_b + c.n_out_b * c.gap)).coords;
            }
            self.body.point[s] = deepest_point;
            if b.touching {
                self.hand.point_jacobian(
                    &self.kin,
                    shape.link,
                    &Point::from(deepest_point),
                    &mut self.body.jac[s],
                );
            }
        }
    }

    /// Stage 3, whole hand: the spring-damper contacts' intensities (module documentation),
    /// appended to the transmitting contacts from `n` on; returns the new count. `touching`
    /// counts every detected contact per object (for the stability budgets).
    pub(super) fn body_forces(
        &mut self,
        mut n: usize,
        contact_object: &mut [usize; MAX_CONTACTS],
        touching: &[usize; super::MAX_OBJECTS],
    ) -> usize {
        let dt = self.params.dt;
        let (k0, c0) = (self.params.body_stiffness, self.params.body_damping);
        for s in 0..self.body.n {
            self.body.active[s] = false;
            let b = self.body_out[s];
            let Some(frame) = b.frame else {
                self.body.anchor_b[s] = None;
                continue;
            };
            let o = b.object;
            if self.body.anchor_object[s] != o {
                self.body.anchor_b[s] = None;
                self.body.anchor_object[s] = o;
            }
            let state = &self.objects[o].state;
            let rot = self.rots[o];
            let rot_inv = rot.transpose();
            let pos = state.pose.translation.vector;
            let z_world = rot * frame.normal_b();
            let j = &self.body.jac[s];
            let dofs = self.body.dofs_solve[s].as_slice();
            // The point of the finger dynamics: the measured one moved by J (θ − θ_measured);
            // the velocity of the joints integrated here.
            let mut shift = Vector::zeros();
            let mut v_joint = Vector::zeros();
            for &d in dofs {
                let col = Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]);
                shift += col * (self.q[d] - self.q_measured[d]);
                v_joint += col * self.qd[d];
            }
            let point = self.body.point[s] + shift;
            let penetration = b.penetration + z_world.dot(&shift);
            // The base's motion carries the point too (arm tracker poses).
            let v_base = match (self.prev_base, self.base) {
                (Some(prev), Some(now)) => {
                    let in_base = now.inverse_transform_point(&Point::from(point));
                    (point - (prev * in_base).coords) / dt
                }
                _ => Vector::zeros(),
            };
            let w_obj = rot * state.angular_velocity_b;
            let v_obj = state.linear_velocity + w_obj.cross(&(point - pos));
            let v_rel = v_joint + v_base - v_obj;
            // Stiffness and damping within the object step's budgets (a cheap bound of the
            // inverse effective mass at the contact).
            let body = &self.bodies[o];
            let inv_mass = body.inv_mass + frame.p_b.norm_squared() * body.inv_inertia_max;
            let count = touching[o].max(1) as Real;
            let k = k0.min(BODY_STIFFNESS_BUDGET / (count * dt * dt * inv_mass));
            let c = c0.min(super::STABLE_DAMPING / (count * dt * inv_mass));
            let normal = k * penetration + c * v_rel.dot(&z_world);
            if penetration <= 0.0 || normal <= 0.0 {
                self.body.anchor_b[s] = None;
                continue;
            }
            // Stick friction ties material points: the deepest point slides along a line contact
            // as the shapes tilt, the hand's and the object's points that stuck do not.
            let link_pose = self.kin.link_poses[self.hand.contact_shapes[s].link];
            let anchor = self.body.anchor_b[s].unwrap_or((
                link_pose
                    .inverse_transform_point(&Point::from(self.body.point[s]))
                    .coords,
                rot_inv * (point - pos),
            ));
            let hand_point = (link_pose * Point::from(anchor.0)).coords + shift;
            let mut err = hand_point - (rot * anchor.1 + pos);
            err -= z_world * err.dot(&z_world);
            let v_t = v_rel - z_world * v_rel.dot(&z_world);
            let f_world = z_world * normal + err * k + v_t * c;
            let want = frame.intensities_of_force_b(&(rot_inv * f_world));
            let friction = self.objects[o].friction;
            let split = apply_friction(self.params.contact_model, &friction, &want);
            let out = &mut self.body_out[s];
            out.transmitted = split.transmitted;
            out.slip = split.slip;
            out.in_contact = !split.separating;
            if !out.in_contact {
                self.body.anchor_b[s] = None;
                continue;
            }
            let sticking = !split.slip;
            self.body.anchor_b[s] = if sticking { Some(anchor) } else { None };
            let t = split.transmitted;
            let f_obj = rot * (frame.rot_b * Vector::new(t[0], t[1], t[2]));
            // On the hand: the opposite force (Newton's third law).
            self.body.force_world[s] = -f_obj;
            self.body.normal_world[s] = z_world;
            self.body.stiffness[s] = k;
            self.body.damping[s] = c;
            self.body.sticking[s] = sticking;
            self.body.active[s] = true;
            if n < MAX_CONTACTS {
                self.frames[n] = frame;
                self.transmitted[n] = split.transmitted;
                self.contact_tip[n] = owner_of_shape(s);
                contact_object[n] = o;
                n += 1;
            }
        }
        n
    }
}
