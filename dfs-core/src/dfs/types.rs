//! What a DFS tick takes and gives: the scene's objects ([`DfsObject`]), a glove sample
//! ([`GloveSample`]) and a tick's output ([`TickOutput`], per fingertip [`TipContact`], per
//! object [`ObjectOutput`]).

use crate::contact::{ContactFrame, Friction, Intensity};
use crate::hand::{MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Point, Real, Vector, Wrench};
use crate::object::{ObjectState, RigidObject};

/// Most objects a DFS scene holds: 8.
pub const MAX_OBJECTS: usize = 8;

/// One object of a DFS scene: the rigid body, the friction between it and the fingertips, and
/// its state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DfsObject {
    /// Shape and mass properties.
    pub object: RigidObject,
    /// Coulomb friction between the fingertips and this object.
    pub friction: Friction,
    /// Its state (pose, velocities).
    pub state: ObjectState,
}

/// What a tick did to one object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectOutput {
    /// The object's state after the tick.
    pub state: ObjectState,
    /// `ᴮf̃` (N, N·m) in B: the fingers' wrench on it.
    pub object_force_b: Wrench,
    /// `f_ext` in B (includes gravity, table and the gyroscopic term).
    pub f_ext_b: Wrench,
    /// Table wrench on the object in B.
    pub table_force_b: Wrench,
    /// Number of transmitting contacts on it.
    pub n_contacts: usize,
    /// Rank of the grasp matrix of those contacts.
    pub grasp_rank: usize,
}

impl Default for ObjectOutput {
    fn default() -> Self {
        ObjectOutput {
            state: ObjectState::at_rest(Isometry::identity()),
            object_force_b: Wrench::zeros(),
            f_ext_b: Wrench::zeros(),
            table_force_b: Wrench::zeros(),
            n_contacts: 0,
            grasp_rank: 0,
        }
    }
}

/// One glove sample: measured joint angles θ, the operator's joint torques τ and the pose of
/// the hand base (from the arm tracker) in the world.
#[derive(Debug, Clone, Copy)]
pub struct GloveSample<'a> {
    /// Joint angles (rad or m), one per DOF.
    pub q: &'a [Real],
    /// Operator joint torques (N·m or N), one per DOF.
    pub tau: &'a [Real],
    /// Pose of the hand's base link in the world.
    pub base: Isometry,
}

/// Contact state of one fingertip after a tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TipContact {
    /// The fingertip is within the contact margin of the object surface (it may still be
    /// across a gap: see `in_contact`).
    pub touching: bool,
    /// Which object (index in the scene) it touches; 0 when not touching.
    pub object: usize,
    /// Pressed into the object (penetration > 0) and pushing: the contact transmits force (it
    /// is a column block of `W`).
    pub in_contact: bool,
    /// Contact geometry in B (valid when touching).
    pub frame: Option<ContactFrame>,
    /// Penetration (m), negative for a gap (valid when touching).
    pub penetration: Real,
    /// The operator's intensities `c_h` in the contact frame.
    pub intensity: Intensity,
    /// What acts on the object, `c̃_h`.
    pub transmitted: Intensity,
    /// The object's reaction `c̃_o = W⁺ f_ext`, friction-limited.
    pub reaction: Intensity,
    /// Fed back to the operator: `c̃_h − c̃_o`.
    pub feedback: Intensity,
    /// The requested intensities were outside the friction cone.
    pub slip: bool,
    /// The operator's fingertip force from τ (world frame, N).
    pub tip_force_world: Vector,
    /// Force of the object on the fingertip (world frame, N): minus the feedback.
    pub feedback_force_world: Vector,
}

/// Everything a tick produces. Fixed capacity; entries beyond the hand's tips and the scene's
/// objects are default.
///
/// `grasp_rank`, `object_force_b`, `f_ext_b`, `table_force_b` and `object` are object 0's (the
/// only one of a one-object DFS); `objects` holds every object's.
#[derive(Debug, Clone, Copy)]
pub struct TickOutput {
    /// Per fingertip.
    pub tips: [TipContact; MAX_TIPS],
    /// Number of fingertips of the hand.
    pub n_tips: usize,
    /// Number of transmitting contacts, on every object.
    pub n_contacts: usize,
    /// Rank of the grasp matrix of the transmitting contacts (object 0).
    pub grasp_rank: usize,
    /// `ᴮf̃` (N, N·m) in B (object 0).
    pub object_force_b: Wrench,
    /// `f_ext` in B (includes gravity, table and the gyroscopic term) (object 0).
    pub f_ext_b: Wrench,
    /// Table wrench on the object in B (object 0).
    pub table_force_b: Wrench,
    /// Object state after the tick (object 0).
    pub object: ObjectState,
    /// Per object of the scene, in its order.
    pub objects: [ObjectOutput; MAX_OBJECTS],
    /// Number of objects in the scene.
    pub n_objects: usize,
    /// Two objects that overlap after the tick (the pair of lowest indices, `i < j`), if any:
    /// objects do not act on each other, so one passed into the other.
    pub overlap: Option<(usize, usize)>,
    /// How many pairs of objects overlap after the tick.
    pub n_overlaps: usize,
    /// Glove motor position commands θ (the integrated finger dynamics).
    pub motor_q: [Real; MAX_DOF],
    /// Their velocities.
    pub motor_qd: [Real; MAX_DOF],
    /// Feedback joint torques `Σ Jᵀ f_fb` (N·m) the glove motors render.
    pub feedback_torque: [Real; MAX_DOF],
    /// Fingertip centres in the world (m).
    pub tip_centres: [Point; MAX_TIPS],
    /// Number of contact shapes taking part (0 unless [`DfsParams::whole_hand`]); their state
    /// is [`Dfs::body_contacts`], kept out of this output so that copying a tick's output (a
    /// recorder does, every tick) does not copy 24 contact states.
    ///
    /// [`DfsParams::whole_hand`]: super::DfsParams::whole_hand
    /// [`Dfs::body_contacts`]: super::Dfs::body_contacts
    pub n_body: usize,
}

impl Default for TickOutput {
    fn default() -> Self {
        TickOutput {
            tips: [TipContact::default(); MAX_TIPS],
            n_tips: 0,
            n_contacts: 0,
            grasp_rank: 0,
            object_force_b: Wrench::zeros(),
            f_ext_b: Wrench::zeros(),
            table_force_b: Wrench::zeros(),
            object: ObjectState::at_rest(Isometry::identity()),
            objects: [ObjectOutput::default(); MAX_OBJECTS],
            n_objects: 0,
            overlap: None,
            n_overlaps: 0,
            motor_q: [0.0; MAX_DOF],
            motor_qd: [0.0; MAX_DOF],
            feedback_torque: [0.0; MAX_DOF],
            tip_centres: [Point::origin(); MAX_TIPS],
            n_body: 0,
        }
    }
}
