//! The DFS tick (paper Fig. 6): one [`Dfs::step`] over named stages,
//!
//! 1. [`glove`](Dfs::stage_glove): validate the glove sample (θ, τ, hand base pose), forward
//!    kinematics, fingertip Jacobians and M(θ);
//! 2. [`contacts`](Dfs::stage_contacts): fingertip spheres against the object, contact frames;
//! 3. [`forces`](Dfs::stage_forces): fingertip forces from joint torques through the damped
//!    `(Jᵀ)⁺` (eq. 14), intensities in each contact frame, the contact model and friction cone
//!    (eq. 15-18; the soft finger's cone is elliptic, see [`crate::contact`]);
//! 4. [`object`](Dfs::stage_object): `ᴮf̃ = W c̃_h` (eq. 22-23), support by the table, gravity
//!    and Newton-Euler (eq. 24-26), integration, per object; then
//!    [`overlaps`](Dfs::stage_overlaps): which objects of a scene overlap;
//! 5. [`feedback`](Dfs::stage_feedback): `c_o = W⁺ f_ext`, friction-limited (eq. 27), the
//!    feedback `c̃_h − c̃_o` per finger, finger dynamics `M θ̈ = τ − Σ Jᵀ f_fb` (eq. 19-21, in
//!    joint space so wrist torques take part) integrated to the glove motor commands.
//!
//! **Departures from the paper, documented.** The paper integrates θ̈ open-loop and moves the
//! object only by the operator's intensities. In a closed loop that lets fingers sink into the
//! object and cannot hold anything against a moving hand, so:
//! - contacts are unilateral: a fingertip within the contact margin of the object is
//!   *detected* (its contact frame is known, [`TipContact::touching`]), but only a pad pressed
//!   into the object transmits force, in proportion to how far it presses in up to a small
//!   depth ([`DfsParams::contact_ramp`], 0.05 mm) and wholly beyond: across any gap the force
//!   on the object is zero however hard the operator pushes, and it does not jump as the gap
//!   closes. What the pad does not pass on of the operator's push stays on the finger (the
//!   rest of eq. 15) and draws it in, stiffly (in the implicit step);
//! - along the normal, a detected fingertip is kept on the surface by a stiff spring-damper
//!   that acts on the finger only (integrated implicitly), across the margin's gap too. The
//!   feedback returns a pushing finger's whole push while the object does not move, so nothing
//!   else fixes its depth: the spring holds a pushing fingertip at a depth
//!   ([`DfsParams::contact_preload`], 0.1 mm) where its pad passes on all of the push, clear of
//!   the ramp, rather than at the surface itself, where the contact would open and close from
//!   tick to tick;
//! - tangentially, a *sticking* fingertip is tied to an anchor point on the object by a
//!   spring-damper acting on finger and object alike (stick friction), plus a torsional
//!   spring-damper for the soft pad (the pad's twist about the normal since it stuck); added to
//!   the operator's intensities, the total is kept inside the friction cone, and beyond it the
//!   contact slips and the anchor moves with the fingertip (a pad that only turns on the surface
//!   keeps its tangential anchor and the twist the torsional cone allows). At rest the springs
//!   hold a fixed deflection instead of creeping; near the cone's edge slow slip remains. The
//!   object is stepped explicitly, so the tangential and torsional damping are limited to what
//!   that step can carry ([`STABLE_DAMPING`]); only light objects (a solid sphere under about
//!   0.1 kg) meet the limit;
//! - the contact springs and dampers act on the fingertip of the finger dynamics, not on the
//!   measured one: the fingertip of the measured angles moved by
//!   `J (θ − θ_measured)` (first order; θ the joint angles integrated here, which the glove's
//!   motors are commanded to), with its own closest point and normal on the object, and the
//!   damper's velocity is how fast that contact point moves relative to the object. The
//!   measured angles differ from θ by the sensors' noise: differencing the measured fingertip
//!   turned a 5e-5 rad noise into some mm/s at 1 kHz, which the 30 N·s/m damper passed to the
//!   object as a 0.6-1 N force chattering near 460 Hz (and the 3 kN/m springs a few µm of it as
//!   tens of mN). Detection (which object, the contact frame, the penetration that the ramp
//!   follows) stays with the measured fingertip, whose noise the preload keeps clear of the
//!   ramp. When the glove's samples are the motor commands (replays, the virtual coupling) the
//!   two fingertips are the same.
//!
//! **Table.** An optional horizontal plane ([`crate::table`]) carries the objects before they
//! are grasped and after they are placed; the paper has no table at all. It pushes only where
//! an object touches it: at its lowest points (a sphere's lowest point; a box's 4 corners of
//! the face it stands on, 2 of an edge or 1 corner; a cylinder's rim points), each with a
//! normal force that only pushes, plus Coulomb friction (`table_mu`) at their centre of
//! pressure. The forces are found each tick as the impulses that keep those points out of the
//! table (a velocity-level complementarity problem: the normal impulses exactly, as a
//! least-distance problem, then friction, torsion and rolling resistance in turn, warm-started
//! from the last tick), so the table's moment is only what those points can give and its
//! centre of pressure stays inside their support polygon: a box tips when its centre of mass
//! (with the other forces) leaves the face or edge it stands on, and rests flat on a face
//! otherwise; a sphere or a cylinder on its side meets a small rolling resistance
//! (`table_rolling`). The supports are rigid (impulses, not springs), so they are stable for
//! any object mass at the DFS step; a landing is inelastic.
//!
//! **Several objects.** A scene holds up to [`MAX_OBJECTS`] objects ([`Dfs::with_objects`]),
//! each with its own state, Newton-Euler dynamics, table support and fingertip friction. Each
//! fingertip contacts the object it touches (the one it penetrates deepest, when it is within
//! the contact margin of several); the grasp matrix, the reaction and the feedback are formed
//! per object from the contacts on it. Objects do not act on each other: an overlap of two
//! objects (a carried object passing through another) is not resolved, but found every tick
//! ([`TickOutput::overlap`], [`Dfs::overlap_ticks`]) for the caller to report. With one object
//! ([`Dfs::new`]) every number is what the one-object DFS computed, bit for bit.
//!
//! Deterministic: the same inputs give bit-identical outputs. Allocation-free per tick.
//!
//! **Code.** This file holds [`Dfs`], what it carries per fingertip, and the order of the
//! stages; each stage's steps are in a submodule: `glove` (stage 1's checks), `contacts` (2),
//! `forces` (3), `objects` and `table` (4), `fingers` (5), and `body` the whole-hand contacts'
//! share of stages 2, 3 and 5. `build` makes a DFS; `params` and `types` hold what a caller
//! passes in and reads out (re-exported here); `tests` the tick's tests.

mod body;
mod build;
mod contacts;
mod fingers;
mod forces;
mod glove;
mod objects;
mod params;
mod table;
#[cfg(test)]
mod tests;
mod types;

pub use body::{BodyContact, BODY_STIFFNESS_BUDGET};
pub use params::{DfsParams, STABLE_DAMPING};
pub use types::{DfsObject, GloveSample, ObjectOutput, TickOutput, TipContact, MAX_OBJECTS};

use crate::contact::{ContactFrame, Intensity};
use crate::error::{DfsError, Result};
use crate::grasp::{GraspMatrix, MAX_CONTACTS};
use crate::hand::{
    DofMatrix, FkPlan, HandModel, Kinematics, MassPlan, MAX_CONTACT_SHAPES, MAX_DOF, MAX_TIPS,
};
use crate::math::{Isometry, Real, Vector};
use crate::object::{ObjectState, RigidObject};
use crate::table::TableSupport;
use build::{BodyConstants, TipDofs};
use nalgebra::Rotation3;

/// The Dynamic Force Simulator for one hand and a scene of one to [`MAX_OBJECTS`] objects.
#[derive(Debug, Clone)]
pub struct Dfs {
    hand: HandModel,
    params: DfsParams,
    /// The scene's objects (`n_objects` of them; the rest copies of the first).
    objects: [DfsObject; MAX_OBJECTS],
    n_objects: usize,
    /// Per object: constants of its body made once.
    bodies: [BodyConstants; MAX_OBJECTS],
    /// Per object: its grasp matrix of the transmitting contacts on it, rebuilt in place each
    /// tick; valid when `grasp_active` (one contact or more on it).
    grasps: [GraspMatrix; MAX_OBJECTS],
    grasp_active: [bool; MAX_OBJECTS],
    /// Per object: its transmitting contacts, `frames[start..start + len]` (the contacts are
    /// ordered by object, and by fingertip within one).
    contact_range: [(usize, usize); MAX_OBJECTS],
    /// Ticks after which two objects overlapped.
    overlap_ticks: u64,
    /// Per object: the table's impulses at its support points last tick (the warm start).
    table_support: [TableSupport; MAX_OBJECTS],
    q: [Real; MAX_DOF],
    qd: [Real; MAX_DOF],
    /// The sample's measured joint angles (the kinematics are of these).
    q_measured: [Real; MAX_DOF],
    initialised: bool,
    kin: Kinematics,
    /// M(θ) of this tick's measured angles (stage 1), turned in place into the implicit finger
    /// step's matrix in stage 5.
    mass: DofMatrix,
    /// The force stage's matrix of a finger group (eq. 14).
    scratch: DofMatrix,
    /// A finger group's joint torques, solved in place for `(Σ JᵀJ + λ²)⁻¹ τ` (stage 3's
    /// scratch).
    group_y: [Real; MAX_DOF],
    /// Per fingertip: what the tick carries from one tick to the next and from the force stage
    /// to the finger step ([`TipState`]); entries beyond the hand's fingertips unused.
    tips: [TipState; MAX_TIPS],
    /// The hand base's pose in the last sample and the one before (for its turn).
    base: Option<Isometry>,
    prev_base: Option<Isometry>,
    frames: [ContactFrame; MAX_CONTACTS],
    transmitted: [Intensity; MAX_CONTACTS],
    /// The reaction `W⁺ f_ext` of one object's contacts (stage 5's scratch; the first of them
    /// written per object).
    reaction_scratch: [Intensity; MAX_CONTACTS],
    /// One fingertip's linear Jacobian columns of the DOFs of its finger group (stage 3) or
    /// of the DOFs moving it (stage 5): scratch.
    tip_cols: [Vector; MAX_DOF],
    /// Per transmitting contact: its fingertip, or `MAX_TIPS + s` for contact shape `s`.
    contact_tip: [usize; MAX_CONTACTS],
    /// Per tip: the DOFs that move it (the wrist's and its finger's), ascending. Every other
    /// column of its Jacobian is zero, so the per-tip joint-space sums skip them.
    tip_dofs: [TipDofs; MAX_TIPS],
    /// The implicit finger step's matrix (M(θ), damping, contact springs) is solved with its
    /// DOFs in this order, finger groups first and the shared (wrist) DOFs last, where its
    /// rows' nonzeros start at `solve_first`: no fill-in, a fraction of a dense Cholesky.
    solve_order: [usize; MAX_DOF],
    solve_first: [usize; MAX_DOF],
    /// Per tip: `tip_dofs` sorted by their position in `solve_order`.
    tip_dofs_solve: [TipDofs; MAX_TIPS],
    /// The hand's structure for M(θ), made once.
    mass_plan: MassPlan,
    /// The hand's per-joint constants for forward kinematics, made once.
    fk_plan: FkPlan,
    factor: DofMatrix,
    /// The whole-hand contacts' state ([`DfsParams::whole_hand`]).
    body: body::BodyState,
    /// Each object's orientation as a matrix, applied about ten times per touching contact:
    /// made at the start of stage 2 (for detection and forces) and again after the object
    /// stage (for the feedback), in place; identity beyond the scene's objects.
    rots: [Rotation3<Real>; MAX_OBJECTS],
    /// Per contact shape, what the last tick found ([`Dfs::body_contacts`]).
    body_out: [BodyContact; MAX_CONTACT_SHAPES],
    out: TickOutput,
}

/// What the DFS carries for one fingertip: from one tick to the next (the object it touched,
/// where it stuck, its last contact point, its twist) and from the force stage to the implicit
/// finger step (its contact spring's deflection, velocity and damping). Units SI. The DOFs
/// moving each tip are the hand's structure, made once, and stay in [`Dfs`]'s `tip_dofs`.
#[derive(Debug, Clone, Copy)]
struct TipState {
    /// The object (index in the scene) it touched the tick before: its anchor and twist are on
    /// that object.
    object: usize,
    /// Where it stuck on the object (m, the object's frame B): the anchor of its tangential
    /// spring; `None` while it is not sticking.
    anchor_b: Option<Vector>,
    /// Its contact point the tick before (m, world), of the finger dynamics' fingertip; `None`
    /// when it touched nothing.
    prev_point: Option<Vector>,
    /// Its contact spring's deflection (m, world): tangential from the stick anchor plus the
    /// penetration along the normal, less the preload of a pushing tip.
    spring_err: Vector,
    /// Its velocity not explained by its joints, relative to the object (m/s, world): what the
    /// contact damper damps.
    spring_vel: Vector,
    /// It sticks: its tangential spring to the anchor acts this tick.
    stick: bool,
    /// The tangential damping of its contact spring this tick (N·s/m): the surface damping
    /// limited by [`STABLE_DAMPING`].
    tangential_damping: Real,
    /// The stiffness (N/m) along the normal with which the operator's untransmitted push draws
    /// a fingertip whose pad is on the contact ramp back in (its normal intensity over the
    /// ramp's depth; 0 off the ramp), for the implicit step.
    ramp_stiffness: Real,
    /// How far the pad has twisted about the normal since it stuck (rad).
    twist: Real,
    /// The passive friction force on the object (N, world): the transmitted tangential force
    /// beyond the operator's, which the contact spring carries on the finger side.
    passive_world: Vector,
}

impl TipState {
    /// A fingertip that has touched nothing yet, its tangential damping `surface_damping`.
    fn new(surface_damping: Real) -> Self {
        TipState {
            object: 0,
            anchor_b: None,
            prev_point: None,
            spring_err: Vector::zeros(),
            spring_vel: Vector::zeros(),
            stick: false,
            tangential_damping: surface_damping,
            ramp_stiffness: 0.0,
            twist: 0.0,
            passive_world: Vector::zeros(),
        }
    }
}

impl Dfs {
    /// The hand model.
    pub fn hand(&self) -> &HandModel {
        &self.hand
    }

    /// The object (object 0 of a scene of several).
    pub fn object(&self) -> &RigidObject {
        &self.objects[0].object
    }

    /// The object's current state (object 0 of a scene of several).
    pub fn object_state(&self) -> &ObjectState {
        &self.objects[0].state
    }

    /// Number of objects in the scene.
    pub fn n_objects(&self) -> usize {
        self.n_objects
    }

    /// The scene's objects with their current states, in the scene's order.
    pub fn objects(&self) -> &[DfsObject] {
        &self.objects[..self.n_objects]
    }

    /// How many ticks ended with two objects overlapping ([`TickOutput::overlap`]).
    pub fn overlap_ticks(&self) -> u64 {
        self.overlap_ticks
    }

    /// Parameters.
    pub fn params(&self) -> &DfsParams {
        &self.params
    }

    /// The last tick's output.
    pub fn output(&self) -> &TickOutput {
        &self.out
    }

    /// What the last tick found at each of the hand's contact shapes (palm, phalanges), in
    /// [`HandModel::contact_shapes`](crate::hand::HandModel) order: empty unless
    /// [`DfsParams::whole_hand`].
    pub fn body_contacts(&self) -> &[BodyContact] {
        &self.body_out[..self.out.n_body]
    }

    /// Kinematics of the last tick (link poses, tip centres, Jacobians).
    pub fn kinematics(&self) -> &Kinematics {
        &self.kin
    }

    /// Replaces the object's state (for example to place it at a scenario's start pose);
    /// object 0 of a scene of several.
    pub fn set_object_state(&mut self, state: ObjectState) {
        self.objects[0].state = state;
        self.table_support[0].clear();
        self.out.object = state;
        self.out.objects[0].state = state;
    }

    /// Replaces the state of object `index`; an index beyond the scene is refused.
    pub fn set_object_state_at(&mut self, index: usize, state: ObjectState) -> Result<()> {
        if index >= self.n_objects {
            return Err(DfsError::invalid(
                "object",
                format!(
                    "no object {index}: the scene has {} objects",
                    self.n_objects
                ),
            ));
        }
        if index == 0 {
            self.set_object_state(state);
        } else {
            self.objects[index].state = state;
            self.table_support[index].clear();
            self.out.objects[index].state = state;
        }
        Ok(())
    }

    /// One DFS tick. On an error (bad sample) nothing changes and no output is produced. A
    /// tick whose object update is not finite (the explicit step diverged) is refused with
    /// [`DfsError::Diverged`]; the object keeps its last finite state, so no output ever
    /// holds a NaN.
    pub fn step(&mut self, sample: &GloveSample<'_>) -> Result<&TickOutput> {
        self.stage_glove(sample)?;
        self.stage_contacts();
        self.stage_forces(sample.tau);
        let mut before = [ObjectState::at_rest(Isometry::identity()); MAX_OBJECTS];
        for (b, o) in before.iter_mut().zip(&self.objects[..self.n_objects]) {
            *b = o.state;
        }
        self.stage_object();
        if let Some(what) = self.diverged() {
            self.restore_objects(&before);
            return Err(DfsError::Diverged { what });
        }
        self.stage_overlaps();
        self.stage_feedback(sample.tau);
        Ok(&self.out)
    }

    /// Stage 1: validate the sample; kinematics, Jacobians and M(θ).
    pub fn stage_glove(&mut self, s: &GloveSample<'_>) -> Result<()> {
        self.check_sample(s)?;
        let n = self.hand.dof();
        if !self.initialised {
            self.q[..n].copy_from_slice(s.q);
            self.initialised = true;
        }
        self.q_measured[..n].copy_from_slice(s.q);
        self.prev_base = self.base.or(Some(s.base));
        self.base = Some(s.base);
        self.hand
            .forward_kinematics_planned(&self.fk_plan, &s.base, s.q, &mut self.kin);
        self.hand.tip_jacobians(&mut self.kin);
        self.hand
            .mass_matrix_planned(&self.mass_plan, &mut self.kin, &mut self.mass);
        Ok(())
    }

    /// Stage 2: contact detection between fingertip spheres and the objects: each fingertip
    /// touches the object it penetrates deepest among those within the contact margin.
    pub fn stage_contacts(&mut self) {
        self.update_rotations();
        self.detect_tip_contacts();
        if self.body.n > 0 {
            self.detect_body_contacts();
        }
    }

    /// Stage 3: fingertip forces from joint torques (eq. 14), intensities, friction (eq. 15-18)
    /// for the fingertips pressed into the object; a fingertip across a gap transmits nothing.
    pub fn stage_forces(&mut self, tau: &[Real]) {
        self.tip_forces_from_torques(tau);
        let cx = self.force_context();
        let mut n = 0;
        let mut contact_object = [0usize; MAX_CONTACTS];
        for k in 0..self.hand.fingertips.len() {
            let transmitting = self.tip_contact(k, &cx);
            if let Some((frame, transmitted, o)) = transmitting.filter(|_| n < MAX_CONTACTS) {
                self.frames[n] = frame;
                self.transmitted[n] = transmitted;
                self.contact_tip[n] = k;
                contact_object[n] = o;
                n += 1;
            }
        }
        if self.body.n > 0 {
            n = self.body_forces(n, &mut contact_object, &cx.touching);
        }
        self.out.n_contacts = n;
        self.group_contacts_by_object(&contact_object[..n]);
    }

    /// Stage 4: per object, its wrench (eq. 22-23), table support, Newton-Euler (eq. 24-26),
    /// integration.
    pub fn stage_object(&mut self) {
        for i in 0..self.n_objects {
            self.step_object(i);
        }
        let first = self.out.objects[0];
        self.out.grasp_rank = first.grasp_rank;
        self.out.object_force_b = first.object_force_b;
        self.out.f_ext_b = first.f_ext_b;
        self.out.table_force_b = first.table_force_b;
        self.out.object = first.state;
    }

    /// Stage 4b: which objects overlap after the step (objects do not act on each other, so
    /// this is reported, never resolved): [`TickOutput::overlap`] and
    /// [`TickOutput::n_overlaps`].
    pub fn stage_overlaps(&mut self) {
        let (first, count) = self.overlapping_pairs();
        self.out.overlap = first;
        self.out.n_overlaps = count;
        if count > 0 {
            self.overlap_ticks += 1;
        }
    }

    /// Stage 5: per object, the reaction `c_o = W⁺ f_ext` (eq. 27), friction-limited; feedback
    /// per finger; finger dynamics (eq. 19-21) integrated implicitly to the motor commands.
    pub fn stage_feedback(&mut self, tau: &[Real]) {
        self.update_rotations();
        self.reactions();
        self.integrate_fingers(tau);
    }
}
