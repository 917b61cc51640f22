//! Stage 3 of the tick, [`Dfs::stage_forces`], in named steps: the operator's fingertip forces
//! from the joint torques (eq. 14), then per touching fingertip the finger dynamics' fingertip
//! on the object, the share of the operator's push its pad passes on, the stick spring and its
//! damping, the soft pad's torsion, and the friction cone (eq. 15-18), whose outcome the
//! fingertip's [`TipState`] carries to the finger step and the next tick; last, the
//! transmitting contacts ordered by object.

use super::{Dfs, TipState, MAX_OBJECTS, STABLE_DAMPING};
use crate::contact::{apply_friction, ContactFrame, ContactModel, FrictionSplit, Intensity};
use crate::hand::MAX_DOF;
use crate::math::{cholesky_solve_in_place, Real, Vector};
use crate::object::{ClosestPoint, RigidObject};
use nalgebra::Rotation3;

/// What the force stage uses of the scene at every fingertip this tick (besides the objects'
/// orientations, [`Dfs`]'s `rots`).
pub(super) struct ForceContext {
    /// The tick length (s).
    pub dt: Real,
    /// The contact model is the soft finger's (the pads twist).
    pub soft: bool,
    /// How fast the hand base turns (rad/s, world), for a soft pad's spin; zero otherwise.
    pub w_base: Vector,
    /// Per object: how many fingertips and contact shapes touch it.
    pub touching: [usize; MAX_OBJECTS],
}

/// The fingertip of the finger dynamics at its object: the measured fingertip moved by
/// `J (θ − θ_measured)`, with its own closest point and normal on the object.
struct DynamicsTip {
    /// Its contact point (m, world): its centre, a radius along the inward normal.
    point: Vector,
    /// The contact normal into the object (world).
    z_world: Vector,
    /// The object's outward normal at the closest point (B).
    n_out_b: Vector,
    /// How far it presses into the object (m), negative across a gap.
    penetration: Real,
}

/// A touching fingertip's tangential spring to its anchor on the object.
struct TangentialSpring {
    /// The anchor (m, B): where it stuck, or its contact point if it did not.
    anchor_b: Vector,
    /// The spring's deflection across the normal (m, world).
    err: Vector,
    /// The object's angular velocity (rad/s, world).
    w_obj: Vector,
    /// How fast the contact point moves relative to the object (m/s, world).
    v_rel: Vector,
}

/// A soft pad's twist about the normal this tick (all zero for other contact models).
#[derive(Clone, Copy)]
struct PadTwist {
    /// The pad's spin relative to the object about the normal (rad/s).
    spin: Real,
    /// Its twist since it stuck, this tick's spin included (rad).
    twist: Real,
    /// Its torsional damping (N·m·s/rad), limited by the object's explicit step.
    damping: Real,
}

/// What a touching fingertip asks of the friction cone, and what its contact is settled with.
struct TipPush {
    /// The contact frame, of the measured fingertip.
    frame: ContactFrame,
    /// The object touched (index in the scene).
    object: usize,
    /// The operator's intensities `c_h`.
    c: Intensity,
    /// The share of them the pad passes on.
    passed: Intensity,
    /// The same plus the stick spring's and the torsion's intensities: what the cone limits.
    with_passive: Intensity,
    /// The torsional moment asked for (N·m): twist spring and spin damper.
    torsion: Real,
    /// The pad's spin, twist and torsional damping.
    twist: PadTwist,
    /// The finger dynamics' fingertip at the object.
    at: DynamicsTip,
    /// The stick spring to the anchor.
    spring: TangentialSpring,
}

/// The share of the operator's intensities `c` a pad passes on, pressed `pressed` (m) into the
/// object with the contact ramp `ramp` (m): in proportion up to the ramp's depth, all of them
/// beyond, none across a gap (module documentation). With it, the stiffness (N/m) with which
/// the push not passed on draws a pad on the ramp in (0 off the ramp).
#[inline]
fn pad_share(pressed: Real, ramp: Real, c: &Intensity) -> (Intensity, Real) {
    let share = if pressed <= 0.0 {
        0.0
    } else if pressed < ramp {
        pressed / ramp
    } else {
        1.0
    };
    let passed = c * share;
    let ramp_stiffness = if share > 0.0 && share < 1.0 && c[2] > 0.0 {
        c[2] / ramp
    } else {
        0.0
    };
    (passed, ramp_stiffness)
}

/// The object's largest inverse effective mass (1/kg) at the contact `frame` for a push across
/// its normal: the maximum over unit tangents `t` of `1/m + (r × t)ᵀ I⁻¹ (r × t)`, `r` the
/// contact point from the centre of mass (B), the larger eigenvalue of a 2x2 matrix.
pub(super) fn inverse_mass_across(object: &RigidObject, frame: &ContactFrame) -> Real {
    let r = frame.p_b;
    let m = frame.rot_b.matrix();
    let u1 = r.cross(&Vector::new(m[(0, 0)], m[(1, 0)], m[(2, 0)]));
    let u2 = r.cross(&Vector::new(m[(0, 1)], m[(1, 1)], m[(2, 1)]));
    let (iu1, iu2) = (object.inertia_inv * u1, object.inertia_inv * u2);
    let (a, b, c) = (u1.dot(&iu1), u1.dot(&iu2), u2.dot(&iu2));
    let half_gap = 0.5 * (a - c);
    1.0 / object.mass + 0.5 * (a + c) + (half_gap * half_gap + b * b).sqrt()
}

impl TipState {
    /// Forgets where the tip stuck, its last contact point and its twist: it touches nothing,
    /// or another object than the tick before.
    fn release(&mut self) {
        self.anchor_b = None;
        self.prev_point = None;
        self.twist = 0.0;
    }
}

impl Dfs {
    /// The operator's fingertip forces from the joint torques through the damped `(Jᵀ)⁺`
    /// (eq. 14), per finger group, into the output's
    /// [`TipContact::tip_force_world`](super::TipContact::tip_force_world).
    pub(super) fn tip_forces_from_torques(&mut self, tau: &[Real]) {
        let lam2 = self.params.tip_force_damping * self.params.tip_force_damping;
        for g in &self.hand.finger_groups {
            let m = g.dofs.len().min(MAX_DOF);
            if m == 0 {
                continue;
            }
            let dofs = &g.dofs[..m];
            // A = Σ_tips J_gᵀ J_g + λ² I over the group's DOFs, its upper triangle (all that
            // the solve reads); y = A⁻¹ τ_g; f_tip = J_tip y. Each tip's linear Jacobian
            // columns of the group's DOFs are read once, into the DFS's scratch.
            let a = &mut self.scratch;
            let y = &mut self.group_y[..m];
            for (ib, &db) in dofs.iter().enumerate() {
                y[ib] = tau[db];
                for ia in 0..ib {
                    a[(ia, ib)] = 0.0;
                }
                a[(ib, ib)] = lam2;
            }
            let cols = &mut self.tip_cols[..m];
            for &tip in &g.tips {
                let js = self.kin.tip_jacobians[tip].as_slice();
                for (c, &d) in cols.iter_mut().zip(dofs) {
                    *c = Vector::new(js[6 * d], js[6 * d + 1], js[6 * d + 2]);
                }
                for (ib, cb) in cols.iter().enumerate() {
                    for (ia, ca) in cols[..=ib].iter().enumerate() {
                        a[(ia, ib)] += ca.x * cb.x + ca.y * cb.y + ca.z * cb.z;
                    }
                }
            }
            if !cholesky_solve_in_place(a, m, y) {
                continue;
            }
            for &tip in &g.tips {
                let j = &self.kin.tip_jacobians[tip];
                let mut f = Vector::zeros();
                for (&yi, &da) in y.iter().zip(dofs) {
                    f += Vector::new(j[(0, da)], j[(1, da)], j[(2, da)]) * yi;
                }
                self.out.tips[tip].tip_force_world = f;
            }
        }
    }

    /// The base's turn and how many contacts touch each object.
    #[inline]
    pub(super) fn force_context(&self) -> ForceContext {
        let dt = self.params.dt;
        // How fast the hand base turns (world), from the arm tracker's poses: a soft pad's
        // spin about the normal is its base's and its joints'.
        let soft = self.params.contact_model == ContactModel::SoftFinger;
        let w_base = match (soft, self.prev_base, self.base) {
            (true, Some(prev), Some(now)) => {
                (now.rotation * prev.rotation.inverse()).scaled_axis() / dt
            }
            _ => Vector::zeros(),
        };
        let mut touching = [0usize; MAX_OBJECTS];
        for t in self.out.tips[..self.hand.fingertips.len()]
            .iter()
            .filter(|t| t.frame.is_some())
        {
            touching[t.object] += 1;
        }
        for b in self.body_out[..self.body.n]
            .iter()
            .filter(|b| b.frame.is_some())
        {
            touching[b.object] += 1;
        }
        ForceContext {
            dt,
            soft,
            w_base,
            touching,
        }
    }

    /// Fingertip `k`'s contact this tick: its intensities, what its pad passes on within the
    /// friction cone together with its stick spring and torsion (into the tick's output and
    /// its [`TipState`]). The contact frame, transmitted intensities and object when it
    /// transmits force; `None` when it touches nothing or does not push.
    #[inline]
    pub(super) fn tip_contact(
        &mut self,
        k: usize,
        cx: &ForceContext,
    ) -> Option<(ContactFrame, Intensity, usize)> {
        let tip = &mut self.tips[k];
        tip.passive_world = Vector::zeros();
        tip.stick = false;
        tip.ramp_stiffness = 0.0;
        let Some(frame) = self.out.tips[k].frame else {
            tip.release();
            return None;
        };
        let o = self.out.tips[k].object;
        if tip.object != o {
            // It went from one object to another: its anchor and twist were on the other.
            tip.release();
            tip.object = o;
        }
        let push = self.tip_push(k, frame, o, cx);
        let split = apply_friction(
            self.params.contact_model,
            &self.objects[o].friction,
            &push.with_passive,
        );
        self.settle_tip(k, cx, &push, &split)
            .then_some((frame, split.transmitted, o))
    }

    /// What touching fingertip `k` asks of the friction cone on object `o`: the operator's
    /// intensities its pad passes on, plus the stick spring's and the torsion's.
    #[inline]
    fn tip_push(&mut self, k: usize, frame: ContactFrame, o: usize, cx: &ForceContext) -> TipPush {
        let rot = self.rots[o];
        let rot_inv = rot.transpose();
        // The tangential damping the object's explicit step can carry, shared by the tips
        // touching it ([`STABLE_DAMPING`]): per tip, `c / m_eff` may not exceed this.
        let damping_budget = STABLE_DAMPING / (cx.touching[o].max(1) as Real * cx.dt);
        let c = frame.intensities_of_force_b(&(rot_inv * self.out.tips[k].tip_force_world));
        let at = self.dynamics_tip(k, o, &rot, &rot_inv);
        // The pad passes on the operator's intensities in proportion to how far the
        // measured fingertip presses into the object, up to the contact ramp's depth (all of
        // them beyond): nothing across a gap, and continuously so (module documentation).
        let (passed, ramp_stiffness) =
            pad_share(self.out.tips[k].penetration, self.params.contact_ramp, &c);
        self.tips[k].ramp_stiffness = ramp_stiffness;
        let spring = self.tangential_spring(k, o, &rot, &rot_inv, &at, cx.dt);
        let damping = self.tangential_damping_at(o, &frame, damping_budget);
        self.tips[k].tangential_damping = damping;
        // Passive friction: a sticking fingertip drags the object along with it (tangential
        // spring-damper to the anchor), within the friction cone together with the
        // operator's own tangential force.
        let (z_world, v_rel) = (at.z_world, spring.v_rel);
        let passive_w = spring.err * self.params.surface_stiffness
            + (v_rel - z_world * v_rel.dot(&z_world)) * damping;
        let passive_c = frame.intensities_of_force_b(&(rot_inv * passive_w));
        let twist = if cx.soft {
            self.torsion(k, o, &at, &spring.w_obj, cx, damping_budget)
        } else {
            PadTwist {
                spin: 0.0,
                twist: 0.0,
                damping: 0.0,
            }
        };
        let torsion = twist.twist * self.params.torsion_stiffness + twist.spin * twist.damping;
        let with_passive = if passed[2] > 0.0 {
            passed + Intensity::new(passive_c[0], passive_c[1], 0.0, torsion)
        } else {
            passed
        };
        TipPush {
            frame,
            object: o,
            c,
            passed,
            with_passive,
            torsion,
            twist,
            at,
            spring,
        }
    }

    /// Fingertip `k` of the finger dynamics at object `o` (orientation `rot`, its inverse
    /// `rot_inv`).
    ///
    /// The contact acts on the fingertip of the finger dynamics: the measured one moved
    /// by J (θ − θ_measured) (first order), θ the joint angles the glove's motors are
    /// commanded to, with its own closest point and normal on the object. The measured
    /// angles differ from θ by the sensors' noise, which the stiff springs would pass on
    /// to the object as force (and a curved surface's normal turns with it).
    #[inline]
    fn dynamics_tip(
        &self,
        k: usize,
        o: usize,
        rot: &Rotation3<Real>,
        rot_inv: &Rotation3<Real>,
    ) -> DynamicsTip {
        let j = &self.kin.tip_jacobians[k];
        let mut shift = Vector::zeros();
        for &d in self.tip_dofs[k].as_slice() {
            shift +=
                Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]) * (self.q[d] - self.q_measured[d]);
        }
        let centre = self.out.tip_centres[k].coords + shift;
        let radius = self.hand.fingertips[k].radius;
        let pos = self.objects[o].state.pose.translation.vector;
        let ClosestPoint {
            distance,
            normal: n_out_b,
            ..
        } = self.objects[o]
            .object
            .shape
            .closest(&(rot_inv * (centre - pos)));
        let z_world = -(rot * n_out_b);
        DynamicsTip {
            point: centre + z_world * radius,
            z_world,
            n_out_b,
            penetration: radius - distance,
        }
    }

    /// Fingertip `k`'s contact spring on object `o`: its deflection from where it stuck on the
    /// object, and how fast its contact point moves relative to the object; the latter, less
    /// what its joints explain, into its [`TipState::spring_vel`], and the contact point into
    /// its [`TipState::prev_point`].
    #[inline]
    fn tangential_spring(
        &mut self,
        k: usize,
        o: usize,
        rot: &Rotation3<Real>,
        rot_inv: &Rotation3<Real>,
        at: &DynamicsTip,
        dt: Real,
    ) -> TangentialSpring {
        let state = &self.objects[o].state;
        let pos = state.pose.translation.vector;
        let tip_point = at.point;
        let z_world = at.z_world;
        let tip_b = rot_inv * (tip_point - pos);
        let anchor_b = self.tips[k].anchor_b.unwrap_or(tip_b);
        let mut err = tip_point - (rot * anchor_b + pos);
        err -= z_world * err.dot(&z_world);
        let w_obj = rot * state.angular_velocity_b;
        let v_obj = state.linear_velocity + w_obj.cross(&(tip_point - pos));
        // The stick damper's velocity: how fast that contact point moves relative to the
        // object, the rate of the spring's deflection. Of the finger dynamics' fingertip, it
        // follows the joint velocities and the base, never a difference of measured angles,
        // whose sensor noise the damper would amplify.
        let v_rel = self.tips[k]
            .prev_point
            .map(|prev| (tip_point - prev) / dt - v_obj)
            .unwrap_or_else(Vector::zeros);
        self.tips[k].prev_point = Some(tip_point);
        let j = &self.kin.tip_jacobians[k];
        let mut v_joint = Vector::zeros();
        for &d in self.tip_dofs[k].as_slice() {
            v_joint += Vector::new(j[(0, d)], j[(1, d)], j[(2, d)]) * self.qd[d];
        }
        self.tips[k].spring_vel = v_rel - v_joint;
        TangentialSpring {
            anchor_b,
            err,
            w_obj,
            v_rel,
        }
    }

    /// The tangential damping (N·s/m) at a contact `frame` on object `o`: the surface damping,
    /// limited to `budget` per unit inverse effective mass ([`STABLE_DAMPING`]). A cheap bound
    /// on the inverse effective mass first (|r × t| ≤ |r|), the exact one only when that bound
    /// limits it.
    #[inline]
    fn tangential_damping_at(&self, o: usize, frame: &ContactFrame, budget: Real) -> Real {
        let body = &self.bodies[o];
        let mut damping = self.params.surface_damping;
        let bound = body.inv_mass + frame.p_b.norm_squared() * body.inv_inertia_max;
        if damping * bound > budget {
            damping = damping.min(budget / inverse_mass_across(&self.objects[o].object, frame));
        }
        damping
    }

    /// A soft pad's torsion (a point contact transmits none): the fingertip pad drags the
    /// object's spin about the normal along, a torsional spring-damper from where it stuck.
    ///
    /// Its damping is limited to what the object's explicit step can carry, shared as the
    /// tangential damping is: `c_τ nᵀ I⁻¹ n` within the same `budget` per contact. A light
    /// object's spin would otherwise ring from tick to tick at the torsional cone's limit (a
    /// 10 g, 2 cm sphere: c_τ dt nᵀ I⁻¹ n = 3), which the elliptic cone takes out of the pad's
    /// tangential friction.
    #[inline]
    fn torsion(
        &self,
        k: usize,
        o: usize,
        at: &DynamicsTip,
        w_obj: &Vector,
        cx: &ForceContext,
        budget: Real,
    ) -> PadTwist {
        let j = &self.kin.tip_jacobians[k];
        let mut w_tip = cx.w_base;
        for &d in self.tip_dofs[k].as_slice() {
            w_tip += Vector::new(j[(3, d)], j[(4, d)], j[(5, d)]) * self.qd[d];
        }
        let spin = (w_tip - w_obj).dot(&at.z_world);
        let mut c_t = self.params.torsion_damping;
        let inv_inertia = at
            .n_out_b
            .dot(&(self.objects[o].object.inertia_inv * at.n_out_b));
        if c_t * inv_inertia > budget {
            c_t = budget / inv_inertia;
        }
        PadTwist {
            spin,
            twist: self.tips[k].twist + spin * cx.dt,
            damping: c_t,
        }
    }

    /// Fingertip `k`'s contact settled by the friction cone (`split` of `push`): into the
    /// tick's output, and into its [`TipState`] whether it sticks, its twist, anchor, spring
    /// deflection and passive friction. Whether it transmits force.
    #[inline]
    fn settle_tip(
        &mut self,
        k: usize,
        cx: &ForceContext,
        push: &TipPush,
        split: &FrictionSplit,
    ) -> bool {
        let (c, z_world) = (push.c, push.at.z_world);
        let t = &mut self.out.tips[k];
        t.intensity = c;
        t.transmitted = split.transmitted;
        t.slip = split.slip;
        t.in_contact = !split.separating;
        let in_contact = t.in_contact;
        // The pad sticks unless it slides: the cone limits its tangential force. A pad that
        // only spins on the surface (torsional slip of the soft finger, with no tangential
        // force) keeps its tangential anchor.
        let tangential = |c: &Intensity| c[0] * c[0] + c[1] * c[1];
        let slides = split.slip && tangential(&split.transmitted) < tangential(&push.with_passive);
        let stick = in_contact && !slides;
        let p = &self.params;
        let tip = &mut self.tips[k];
        tip.stick = stick;
        // Beyond the torsional cone the pad turns on the surface and keeps only the twist
        // the cone allows.
        let PadTwist {
            spin,
            twist,
            damping: torsion_damping,
        } = push.twist;
        tip.twist = if !cx.soft || !in_contact || c[2] <= 0.0 {
            0.0
        } else if p.torsion_stiffness > 0.0 && split.transmitted[3] != push.torsion {
            (split.transmitted[3] - spin * torsion_damping) / p.torsion_stiffness
        } else {
            twist
        };
        tip.anchor_b = if stick {
            Some(push.spring.anchor_b)
        } else {
            None
        };
        // The normal spring (on the finger only) holds a detected fingertip on the surface,
        // across the contact margin's gap too, and one that pushes at the preload depth.
        let depth = if c[2] > 0.0 {
            push.at.penetration - p.contact_preload
        } else {
            push.at.penetration
        };
        tip.spring_err = if stick {
            push.spring.err + z_world * depth
        } else {
            z_world * depth
        };
        if in_contact {
            let tangential = split.transmitted - push.passed.component_mul(&p.contact_model.mask());
            tip.passive_world = self.rots[push.object]
                * (push.frame.rot_b * Vector::new(tangential[0], tangential[1], 0.0));
        }
        in_contact
    }

    /// Orders the transmitting contacts by object (stably: by fingertip within one) and sets
    /// each object's range of them. With one object nothing moves.
    pub(super) fn group_contacts_by_object(&mut self, contact_object: &[usize]) {
        let n = contact_object.len();
        let mut count = [0usize; MAX_OBJECTS];
        for &o in contact_object {
            count[o] += 1;
        }
        let mut start = 0;
        for (o, range) in self.contact_range[..self.n_objects].iter_mut().enumerate() {
            *range = (start, count[o]);
            start += count[o];
        }
        if contact_object.iter().all(|&o| o == contact_object[0]) {
            return;
        }
        let (frames, transmitted, tips) = (self.frames, self.transmitted, self.contact_tip);
        let mut next = [0usize; MAX_OBJECTS];
        for (o, r) in self.contact_range[..self.n_objects].iter().enumerate() {
            next[o] = r.0;
        }
        for i in 0..n {
            let o = contact_object[i];
            let to = next[o];
            next[o] += 1;
            self.frames[to] = frames[i];
            self.transmitted[to] = transmitted[i];
            self.contact_tip[to] = tips[i];
        }
    }
}
