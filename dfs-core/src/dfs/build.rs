//! Building a DFS ([`Dfs::new`], [`Dfs::with_objects`]): the hand, the parameters and the
//! scene checked, and what the tick needs made once: each object's body constants, the DOFs
//! moving each fingertip, and the order and envelope in which the implicit finger step is
//! solved.

use super::body::{self, BodyContact};
use super::objects::not_finite;
use super::{Dfs, DfsObject, DfsParams, TickOutput, TipState, MAX_OBJECTS};
use crate::contact::{ContactFrame, Intensity};
use crate::error::{DfsError, Result};
use crate::grasp::{GraspMatrix, MAX_CONTACTS};
use crate::hand::{
    DofMatrix, DofSet, HandModel, Kinematics, MAX_CONTACT_SHAPES, MAX_DOF, MAX_TIPS,
};
use crate::math::{Real, Vector, Wrench};
use crate::object::{ObjectState, RigidObject};
use crate::table::TableSupport;
use nalgebra::Rotation3;

/// Constants of one object's body, made once.
#[derive(Debug, Clone, Copy)]
pub(super) struct BodyConstants {
    /// The inverse mass (1/kg) and largest inverse principal moment of inertia
    /// (1/(kg·m²)), for a bound on the inverse effective mass at a contact.
    pub inv_mass: Real,
    pub inv_inertia_max: Real,
    /// Radius of the sphere about the centre that holds the shape (m).
    pub bounding_radius: Real,
}

impl BodyConstants {
    pub(super) fn of(object: &RigidObject) -> Self {
        BodyConstants {
            inv_mass: 1.0 / object.mass,
            inv_inertia_max: object.inertia_inv.symmetric_eigenvalues().max(),
            bounding_radius: object.shape.bounding_radius(),
        }
    }
}

/// The order and envelope for
/// [`envelope_cholesky_solve`](crate::math::envelope_cholesky_solve) of the implicit finger
/// step: the DOFs of each finger group, then the rest (the wrist's, shared by every tip, and
/// any that move no tip); `first[i]` is the first position coupled to position `i` through
/// M(θ) ([`HandModel::inertia_coupling`]) or through a fingertip moved by both DOFs (its
/// contact spring).
fn finger_step_envelope(
    hand: &HandModel,
    tip_dofs: &[TipDofs; MAX_TIPS],
    whole_hand: bool,
) -> ([usize; MAX_DOF], [usize; MAX_DOF]) {
    let n = hand.dof().min(MAX_DOF);
    let mut pattern = hand.inertia_coupling();
    let n_shapes = if whole_hand {
        hand.contact_shapes.len().min(MAX_CONTACT_SHAPES)
    } else {
        0
    };
    let shape_dofs = hand.contact_shapes[..n_shapes]
        .iter()
        .map(|s| TipDofs::of_link(hand, s.link));
    for t in tip_dofs
        .iter()
        .take(hand.fingertips.len())
        .copied()
        .chain(shape_dofs)
    {
        let set = t.as_slice().iter().fold(0 as DofSet, |s, &d| s | 1 << d);
        for &d in t.as_slice() {
            pattern[d] |= set;
        }
    }
    let mut order = [0; MAX_DOF];
    let mut placed = [false; MAX_DOF];
    let mut len = 0;
    let grouped = hand
        .finger_groups
        .iter()
        .flat_map(|g| g.dofs.iter().copied());
    for d in grouped.chain(0..n) {
        if d < n && !placed[d] {
            placed[d] = true;
            order[len] = d;
            len += 1;
        }
    }
    let mut first = [0; MAX_DOF];
    for i in 0..len {
        let row = pattern[order[i]] | 1 << order[i];
        first[i] = (0..=i).find(|&j| row & (1 << order[j]) != 0).unwrap_or(i);
    }
    (order, first)
}

/// The DOFs moving one fingertip, ascending (fixed capacity).
#[derive(Debug, Clone, Copy)]
pub(super) struct TipDofs {
    pub dofs: [usize; MAX_DOF],
    pub len: usize,
}

impl TipDofs {
    pub(super) fn of(hand: &HandModel, tip: usize) -> TipDofs {
        Self::of_link(hand, hand.fingertips[tip].link)
    }

    /// The DOFs moving `link`, ascending.
    pub(super) fn of_link(hand: &HandModel, link: usize) -> TipDofs {
        let set = hand.dofs_moving_link(link);
        let mut t = TipDofs {
            dofs: [0; MAX_DOF],
            len: 0,
        };
        for d in (0..hand.dof().min(MAX_DOF)).filter(|&d| set & (1 << d) != 0) {
            t.dofs[t.len] = d;
            t.len += 1;
        }
        t
    }

    #[inline]
    pub(super) fn as_slice(&self) -> &[usize] {
        &self.dofs[..self.len]
    }
}

/// The DOFs moving each fingertip and the implicit finger step's solve order, made once.
struct SolvePlan {
    /// Per tip: the DOFs moving it, ascending.
    tip_dofs: [TipDofs; MAX_TIPS],
    /// Per tip: the same in solve order.
    tip_dofs_solve: [TipDofs; MAX_TIPS],
    /// The solve order and envelope ([`finger_step_envelope`]).
    solve_order: [usize; MAX_DOF],
    solve_first: [usize; MAX_DOF],
    /// Per DOF: its position in the solve order.
    solve_position: [usize; MAX_DOF],
}

impl SolvePlan {
    /// The plan for `hand`, its contact shapes' DOFs in the envelope when `whole_hand`.
    fn of(hand: &HandModel, whole_hand: bool) -> Self {
        let mut tip_dofs = [TipDofs {
            dofs: [0; MAX_DOF],
            len: 0,
        }; MAX_TIPS];
        for (k, t) in tip_dofs.iter_mut().enumerate().take(hand.fingertips.len()) {
            *t = TipDofs::of(hand, k);
        }
        let (solve_order, solve_first) = finger_step_envelope(hand, &tip_dofs, whole_hand);
        let mut solve_position = [0; MAX_DOF];
        for (i, &d) in solve_order.iter().enumerate().take(hand.dof().min(MAX_DOF)) {
            solve_position[d] = i;
        }
        let mut tip_dofs_solve = tip_dofs;
        for t in tip_dofs_solve.iter_mut() {
            let len = t.len;
            t.dofs[..len].sort_by_key(|&d| solve_position[d]);
        }
        SolvePlan {
            tip_dofs,
            tip_dofs_solve,
            solve_order,
            solve_first,
            solve_position,
        }
    }
}

/// Checks that a scene of `objects` can be simulated with `hand`: no more fingertips than
/// contacts, 1 to [`MAX_OBJECTS`] objects, each with a valid friction and a finite state
/// (errors name `objects[i]`). Its first object.
fn check_scene<'a>(hand: &HandModel, objects: &'a [DfsObject]) -> Result<&'a DfsObject> {
    if hand.fingertips.len() > MAX_CONTACTS {
        return Err(DfsError::invalid(
            "hand.fingertips",
            format!("at most {MAX_CONTACTS} fingertips"),
        ));
    }
    let Some(first) = objects.first() else {
        return Err(DfsError::invalid("objects", "needs at least one object"));
    };
    if objects.len() > MAX_OBJECTS {
        return Err(DfsError::invalid(
            "objects",
            format!(
                "{} objects; at most {MAX_OBJECTS} are simulated",
                objects.len()
            ),
        ));
    }
    for (i, o) in objects.iter().enumerate() {
        for (what, v) in [("mu", o.friction.mu), ("mu_torsion", o.friction.mu_torsion)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(DfsError::invalid(
                    format!("objects[{i}].friction.{what}"),
                    format!("must be a finite number ≥ 0, got {v}"),
                ));
            }
        }
        if not_finite(&o.state, &Wrench::zeros()).is_some() {
            return Err(DfsError::invalid(
                format!("objects[{i}].state"),
                "pose and velocities must be finite",
            ));
        }
    }
    Ok(first)
}

impl Dfs {
    /// A DFS for `hand` and `object`, the object at `state`, with the friction
    /// `params.friction`: a scene of one object. Validates the hand and parameters.
    pub fn new(
        hand: HandModel,
        object: RigidObject,
        state: ObjectState,
        params: DfsParams,
    ) -> Result<Self> {
        let one = DfsObject {
            object,
            friction: params.friction,
            state,
        };
        Self::with_objects(hand, &[one], params)
    }

    /// A DFS for `hand` and a scene of 1 to [`MAX_OBJECTS`] objects, each with its own
    /// friction (`params.friction` is not used). Validates the hand, the parameters and each
    /// object's friction and state (errors name `objects[i]`).
    pub fn with_objects(hand: HandModel, objects: &[DfsObject], params: DfsParams) -> Result<Self> {
        hand.validate()?;
        params.validate()?;
        let first = check_scene(&hand, objects)?;
        let n_objects = objects.len();
        let mut scene = [*first; MAX_OBJECTS];
        scene[..n_objects].copy_from_slice(objects);
        let mut bodies = [BodyConstants::of(&first.object); MAX_OBJECTS];
        for (b, o) in bodies.iter_mut().zip(objects) {
            *b = BodyConstants::of(&o.object);
        }
        let state = first.state;
        let mut out = TickOutput {
            n_tips: hand.fingertips.len(),
            object: state,
            n_objects,
            ..TickOutput::default()
        };
        for (o, obj) in out.objects.iter_mut().zip(objects) {
            o.state = obj.state;
        }
        let plan = SolvePlan::of(&hand, params.whole_hand);
        let mass_plan = hand.mass_plan();
        let fk_plan = hand.fk_plan();
        let body = body::BodyState::new(&hand, params.whole_hand, &plan.solve_position);
        out.n_body = body.n;
        let grasp = GraspMatrix::new(&[], params.contact_model, &first.friction);
        Ok(Dfs {
            hand,
            params,
            objects: scene,
            n_objects,
            bodies,
            grasps: [grasp; MAX_OBJECTS],
            grasp_active: [false; MAX_OBJECTS],
            contact_range: [(0, 0); MAX_OBJECTS],
            overlap_ticks: 0,
            table_support: [TableSupport::default(); MAX_OBJECTS],
            q: [0.0; MAX_DOF],
            qd: [0.0; MAX_DOF],
            q_measured: [0.0; MAX_DOF],
            initialised: false,
            kin: Kinematics::default(),
            mass: DofMatrix::identity(),
            scratch: DofMatrix::identity(),
            tips: [TipState::new(params.surface_damping); MAX_TIPS],
            base: None,
            prev_base: None,
            frames: [ContactFrame::from_normal(Vector::zeros(), Vector::z()); MAX_CONTACTS],
            transmitted: [Intensity::zeros(); MAX_CONTACTS],
            contact_tip: [0; MAX_CONTACTS],
            tip_dofs: plan.tip_dofs,
            solve_order: plan.solve_order,
            solve_first: plan.solve_first,
            tip_dofs_solve: plan.tip_dofs_solve,
            mass_plan,
            fk_plan,
            factor: DofMatrix::zeros(),
            body,
            body_out: [BodyContact::default(); MAX_CONTACT_SHAPES],
            rots: [Rotation3::identity(); MAX_OBJECTS],
            reaction_scratch: [Intensity::zeros(); MAX_CONTACTS],
            tip_cols: [Vector::zeros(); MAX_DOF],
            group_y: [0.0; MAX_DOF],
            out,
        })
    }
}
