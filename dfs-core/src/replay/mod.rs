//! Skill transfer (paper §4, IP-flow 2): a skill recorded with the glove, retargeted onto a
//! robot hand of another structure ([`plan`]) and executed by that hand in the DFS at 1 kHz,
//! driven by joint torques from its controller ([`run`]), with a report of whether the object
//! was actually held ([`ReplayReport`]).
//!
//! # What a skill gives
//!
//! [`SkillSpec`]: the object (shape, mass, μ), the contact model, the contacts in the object
//! frame B with their normals and held normal forces, the object's motion as key poses relative
//! to its pose when the grasp began (B₀), the phases and their durations, and, when the
//! recording lost the object before `release`, when that happened. services converts its
//! `SkillParameters` into one.
//!
//! # Steps
//!
//! 1. **Contacts.** The skill's contacts are split into two virtual fingers: the thumb's side
//!    (contacts whose normals lie within 60° of the thumb contact's) and the opposing side. The
//!    hand's thumb ([`crate::hand::thumb_of`] or the spec's `thumb`) takes the thumb side; its
//!    other fingertips the opposing side: one-to-one when the counts match, else a new contact
//!    set: the opposing side's centre spread across the grasp axis at the hand's own finger
//!    spacing (or merged into one point), projected onto the surface, each point at most as
//!    far out as keeps its fingertip on the same face (a fingertip radius inside a box's edges:
//!    on an edge the finger would push along the neighbouring face's normal, square to the
//!    thumb's, and only friction would oppose the thumb). A hand with two
//!    fingertips (a parallel gripper) pinches antipodally through the centre of mass, at its
//!    height, along the skill's grasp axis made horizontal (a box's or cylinder's face normal
//!    when that is close).
//! 2. **Base pose.** The hand's own grasp axis (thumb tip to the centroid of the others, at
//!    mid-range joint angles) is aligned with the skill's, and 12 rolls about it are tried
//!    (approaching from below the table excluded); for each, fingertip inverse kinematics with
//!    the base position free (joint limits and mimic couplings honoured) places the fingertips
//!    on their contacts. Candidates are scored by the IK residual, by how well each fingertip
//!    can push along its contact normal and by approaching from above (and, for the curled
//!    grasps below, by grasp quality: Ferrari-Canny ε of the contacts the fingertips reach;
//!    with every tip on its own contact the candidates' contacts agree, and ε is computed once
//!    for the chosen pose). When no pose puts every
//!    fingertip on its contact (an underactuated hand cannot put every tip on an arbitrary
//!    point), the thumb and the two, then one, opposing fingers nearest it are placed (those
//!    opposing fingers only need to rest on the surface near their targets) and every other
//!    finger curls, its DOFs swept from open to closed, until its tip first touches the
//!    object; a finger whose curl misses stays open and out of the grasp
//!    ([`Plan::active`]). Such a grasp counts only when its contacts are a force closure and
//!    every finger can push along its contact normal inside the planned friction cone.
//!    Failing that too (fingers with one actuated DOF push only along their motion, far off
//!    the normals at the skill's contacts), the grasp comes from the hand's own closing
//!    motion: the object is placed where fingers meet it head-on, the fingers that push inside
//!    the planned cone take part and the others stay open (`closing.rs`). Last, a hand whose
//!    fingertips carry the names of the skill's contacts (glove10 replaying its own skill,
//!    whose ring and little fingers move with the middle finger's DOFs) puts each contact on
//!    the fingertip of its name; a finger the skill does not use goes where its coupling to a
//!    placed finger takes it (the pose is refused if that presses it into the object), or
//!    curls as above; every placed finger must push along its contact normal within the real
//!    friction cone (the recording held there, so not the planned one; a one-DOF finger that
//!    meets the contact at a slant would only turn the object out of the grasp). Otherwise
//!    the replay fails with `unreachable`.
//! 3. **Forces.** At the reference's samples (every [`ReplayParams::force_sample_s`]), the
//!    least internal force that carries the object's load `m (a − g)` with exact friction cones,
//!    a friction margin and the hand's torque limits `|Σ Jᵀ f| ≤ τ_max` (a second-order cone
//!    programme, [`crate::grasp::optimise::ForceSolver`]: set up once for the contacts, each
//!    load solved by Newton's method on its dual, warm-started, with Clarabel when a torque
//!    limit binds); infeasible without the torque limits is `no_force_closure`, feasible only
//!    without them `torque_limit`. When that is so already for the object at rest at the
//!    grasp ([`Plan::fails_at_rest`]), the replay is refused without being simulated; a load
//!    the torques cannot carry only later along the motion is a warning, and the replay runs.
//! 4. **Simulation.** [`run`]: the arm (the hand's base, moved kinematically like the
//!    operator's) approaches with the fingers preshaped 2 cm off their contacts, the fingers
//!    close under task-space steering, the grip ramps up to the planned forces `τ = Jᵀ f` (a
//!    finger whose Jacobian does not span all directions is commanded the force in its range
//!    with the planned normal component, stick friction giving the rest), the base follows the
//!    reference object motion (so the object follows only if the grasp holds it), the grip
//!    ramps down, the fingers open and the hand retreats. Every torque is clamped
//!    to the hand's limit. Two jaws on one DOF squeeze with equal force and the DFS's surface
//!    springs act on the fingers only, so a pinch carries no load along its jaw line: the hand
//!    turns by the least rotation that keeps that line horizontal while it follows the skill
//!    (otherwise gravity pulls the object along a tilted line and one jaw opens).
//!
//! # Fixed clock or the operator's phases
//!
//! [`run`] and [`Replay::step`] play the skill on a fixed clock: tick `i` at `i` ms of the
//! skill's [`Timeline`]. In the assistant's `apply` mode (IP-flow 3) the replay follows the
//! operator instead: a [`PhaseClock`] turns the operator's phase changes, as the on-line phase
//! estimate reports them, into replay time (real rate within a phase, waiting at the end of a
//! phase held longer than the skill's, catching up at most [`MAX_CATCH_UP_RATE`] × real time
//! when the operator moves on early), and [`DrivenReplay`] steps its [`Replay`] to that time
//! ([`Replay::step_to`]) every tick, exposing the robot's state ([`DrivenTick`]).

mod base_pose;
mod clock;
mod closing;
mod driven;
mod plan;
mod power;
mod run;

pub use clock::{ClockSpan, PhaseClock, MAX_CATCH_UP_RATE, MAX_HELD_CATCH_UP_RATE, RATE_SLEW};
pub use driven::{DrivenReplay, DrivenStart, DrivenTick};
pub use plan::{plan, plan_with_stop, Plan, RetargetStep};
pub use power::{PowerContact, PowerPlan};
pub use run::{run, run_with, run_with_stop, Replay, ReplayTick};

use crate::contact::{ContactModel, Friction};
use crate::math::{Isometry, Real, Rotation, Vector};
use crate::object::Shape;
use crate::scenario::Phase;

/// One contact of a skill, in the object frame B.
#[derive(Debug, Clone, PartialEq)]
pub struct SkillContact {
    /// The recording hand's fingertip or contact shape (provenance; `thumb` marks the
    /// thumb's side).
    pub finger: String,
    /// The part of the hand that touched: a fingertip, or in a whole-hand grasp the palm or a
    /// phalanx.
    pub part: crate::hand::ContactPart,
    /// Contact point in B (m).
    pub position_b: Vector,
    /// Unit normal in B, pointing into the object.
    pub normal_b: Vector,
}

/// A key pose of the object relative to its pose when the grasp began (B₀).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkillKeyPose {
    /// Time since the start of `grasp` (s).
    pub time_s: Real,
    /// Position of B in B₀ (m).
    pub position: Vector,
    /// Rotation of B relative to B₀ as a rotation vector (rad).
    pub rotation: Vector,
}

/// What a replay needs of a skill. SI units.
#[derive(Debug, Clone, PartialEq)]
pub struct SkillSpec {
    /// Object shape (B at its centre of mass).
    pub shape: Shape,
    /// Object mass (kg), > 0.
    pub mass: Real,
    /// Friction between fingertips and object.
    pub friction: Friction,
    /// Contact model of the recording.
    pub contact_model: ContactModel,
    /// The contacts (at least two for a grasp).
    pub contacts: Vec<SkillContact>,
    /// The object's motion, in time order (may be empty: the object stays).
    pub motion: Vec<SkillKeyPose>,
    /// The phases in order with their durations (s).
    pub phases: Vec<(Phase, Real)>,
    /// When the recording lost the object before `release` (s since the start of `grasp`):
    /// the reference then holds the last held pose until `place` sets it down.
    pub held_until_s: Option<Real>,
}

/// Why a replay failed: `unreachable`, `torque_limit`, `slip` or `no_force_closure`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum FailureReason {
    /// No base pose and joint angles put the fingertips on the contacts.
    Unreachable,
    /// The load needs more joint torque than the hand has.
    TorqueLimit,
    /// The object slipped out of the grasp (or away from its reference motion).
    Slip,
    /// The contacts cannot carry the load inside their friction cones at all.
    NoForceClosure,
}

impl crate::names::Named for FailureReason {
    const WHAT: &'static str = "failure reason";
    const ALL: &'static [Self] = &[
        FailureReason::Unreachable,
        FailureReason::TorqueLimit,
        FailureReason::Slip,
        FailureReason::NoForceClosure,
    ];

    fn name(self) -> &'static str {
        FailureReason::name(self)
    }
}

crate::named_enum!(FailureReason);

impl FailureReason {
    /// Name as in reports and the data base.
    pub fn name(self) -> &'static str {
        match self {
            FailureReason::Unreachable => "unreachable",
            FailureReason::TorqueLimit => "torque_limit",
            FailureReason::Slip => "slip",
            FailureReason::NoForceClosure => "no_force_closure",
        }
    }
}

/// A contact of the retargeted grasp.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
pub struct PlannedContact {
    /// The hand's fingertip.
    pub finger: String,
    /// Contact point in B (m).
    #[cfg_attr(feature = "utoipa", schema(value_type = [f64; 3]))]
    pub position_b: [Real; 3],
    /// Unit normal in B, into the object.
    #[cfg_attr(feature = "utoipa", schema(value_type = [f64; 3]))]
    pub normal_b: [Real; 3],
}

/// Grasp quality of the retargeted contacts (GraspIt!'s metrics, 8-edge cones).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
pub struct ReplayQuality {
    /// Ferrari-Canny ε (0 when not force closure).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub epsilon: Real,
    /// Volume of the grasp wrench space.
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub volume: Real,
    /// Force closure.
    pub force_closure: bool,
}

/// The outcome of a replay. Failures are reports, never errors.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[cfg_attr(feature = "utoipa", derive(utoipa::ToSchema))]
pub struct ReplayReport {
    /// The hand.
    pub hand: String,
    /// The object followed its reference motion while held and was never dropped.
    pub success: bool,
    /// Why not, when `success` is false.
    pub failure_reason: Option<FailureReason>,
    /// A sentence on what happened.
    pub detail: String,
    /// Largest distance of the object from its reference while held (m).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub position_error_max_m: Real,
    /// Root mean square of the same (m).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub position_error_rms_m: Real,
    /// Largest rotation of the object away from its reference while held (rad).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub orientation_error_max_rad: Real,
    /// Root mean square of the same (rad).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub orientation_error_rms_rad: Real,
    /// Largest distance a held contact point moved over the object's surface (m).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub max_slip_m: Real,
    /// Ticks in which a held contact slipped (outside its friction cone).
    pub slip_ticks: u64,
    /// Smallest `1 − u` of a transmitting contact while held (a fingertip, or a power grasp's
    /// palm or phalanx), `u` the share of its friction
    /// cone it uses ([`cone_usage`](crate::contact::cone_usage): `|c_t| / (μ c_n)`, with the
    /// torsion for the soft finger's elliptic cone); 1 = pure normal force, 0 = on the cone.
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub min_friction_margin: Real,
    /// Largest |τ| / τ_max of the torques the joints applied over the replay (clamped at the
    /// limit, so at most 1; 1 means a joint reached its limit).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64, minimum = 0.0, maximum = 1.0))]
    pub peak_torque_ratio: Real,
    /// The DOF where that happened.
    pub peak_torque_joint: String,
    /// Quality of the retargeted contacts.
    pub quality: ReplayQuality,
    /// The retargeted contacts.
    pub contacts: Vec<PlannedContact>,
    /// Largest fingertip distance from its contact after inverse kinematics (m).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub ik_error_m: Real,
    /// Highest rise of the object above its start (m).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub lift_height_m: Real,
    /// Simulated ticks (1 kHz).
    pub ticks: u64,
    /// Simulated time (s).
    #[cfg_attr(feature = "utoipa", schema(value_type = f64))]
    pub duration_s: Real,
}

/// Parameters of planning and replay. SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplayParams {
    /// Friction margin of the force distribution, [0, 1): contacts plan for μ (1 − margin). The
    /// margin is also the grip safety: a parallel gripper cannot push tangentially, so friction
    /// (the DFS's stick springs) carries the load on the planned normal force. Default 0.5.
    pub friction_margin: Real,
    /// Least planned normal force per contact (N). Default 0.5.
    pub min_normal: Real,
    /// Largest fingertip IK error for a reachable grasp (m). Default 0.006.
    pub reach_tolerance: Real,
    /// Reference samples of the force distribution every this many seconds. Default 0.25.
    pub force_sample_s: Real,
    /// Success: largest position error while held (m). Default 0.02.
    pub max_position_error: Real,
    /// Success: largest orientation error while held (rad). Default 0.35.
    pub max_orientation_error: Real,
    /// Task-space stiffness steering a fingertip to its contact (N/m). Default 100.
    pub fingertip_stiffness: Real,
    /// Task-space damping of the same (N·s/m). Default 3.
    pub fingertip_damping: Real,
    /// Preshape clearance of the fingertips along the contact normals (m). Default 0.02.
    pub preshape_clearance: Real,
    /// How far inside the surface the closing fingertips aim (m). Default 0.004.
    pub close_depth: Real,
}

impl Default for ReplayParams {
    fn default() -> Self {
        ReplayParams {
            friction_margin: 0.5,
            min_normal: 0.5,
            reach_tolerance: 0.006,
            force_sample_s: 0.25,
            max_position_error: 0.02,
            max_orientation_error: 0.35,
            fingertip_stiffness: 100.0,
            fingertip_damping: 3.0,
            preshape_clearance: 0.02,
            close_depth: 0.004,
        }
    }
}

/// The replay's timeline, from the skill's phases: when the grasp starts and ends, when the
/// held part ends (start of `release`), and the total.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timeline {
    /// Start of `grasp` (s since the replay's start).
    pub grasp_start: Real,
    /// End of `grasp` (start of the held motion).
    pub grasp_end: Real,
    /// Start of `place` (or of `release` when there is no place).
    pub place_start: Real,
    /// Start of `release`.
    pub release_start: Real,
    /// End of `release`.
    pub release_end: Real,
    /// End of the replay.
    pub end: Real,
}

impl SkillSpec {
    /// The replay's timeline. Phases before `grasp` last at least 0.5 s together; a missing
    /// `grasp` lasts 0.8 s, a missing `release` 0.6 s, and a 0.6 s retreat ends the replay.
    pub fn timeline(&self) -> Timeline {
        let dur = |p: Phase| -> Real {
            self.phases
                .iter()
                .filter(|(q, _)| *q == p)
                .map(|(_, d)| d.max(0.0))
                .sum()
        };
        let before = (dur(Phase::Approach) + dur(Phase::Preshape)).max(0.5);
        let grasp = if dur(Phase::Grasp) > 0.0 {
            dur(Phase::Grasp)
        } else {
            0.8
        };
        let grasp_end = before + grasp;
        let moving = dur(Phase::Lift) + dur(Phase::Hold) + dur(Phase::Transport);
        let place_start = grasp_end + moving;
        let release_start = place_start + dur(Phase::Place);
        let release = if dur(Phase::Release) > 0.0 {
            dur(Phase::Release)
        } else {
            0.6
        };
        let release_end = release_start + release;
        Timeline {
            grasp_start: before,
            grasp_end,
            place_start,
            release_start,
            release_end,
            end: release_end + dur(Phase::Retreat).max(0.6),
        }
    }

    /// Start pose of the object: at rest on a table at z = 0, B aligned with the world.
    pub fn start_pose(&self) -> Isometry {
        let depth = self.shape.support_depth(&Rotation::identity());
        Isometry::translation(0.0, 0.0, depth)
    }

    /// The skill's motion at `s` (s since the start of `grasp`) relative to B₀: cubic Hermite
    /// interpolation of the key poses' positions and rotation vectors with Catmull-Rom tangents
    /// (continuous velocity, so an arm following it needs no infinite acceleration at a key
    /// pose); held constant outside the key poses and after [`SkillSpec::held_until_s`].
    pub fn key_pose(&self, s: Real) -> Isometry {
        // Key poses after the recording lost the object are not the skill's motion.
        let held = match self.held_until_s {
            Some(h) => self.motion.partition_point(|k| k.time_s <= h + 1e-9).max(1),
            None => self.motion.len(),
        };
        let m = &self.motion[..held.min(self.motion.len())];
        let pose =
            |p: Vector, r: Vector| Isometry::from_parts(p.into(), Rotation::from_scaled_axis(r));
        let (Some(first), Some(last)) = (m.first(), m.last()) else {
            return Isometry::identity();
        };
        if s <= first.time_s || m.len() == 1 {
            return pose(first.position, first.rotation);
        }
        if s >= last.time_s {
            return pose(last.position, last.rotation);
        }
        let i = m.partition_point(|k| k.time_s <= s).clamp(1, m.len() - 1) - 1;
        let (k0, k1) = (&m[i], &m[i + 1]);
        let h = (k1.time_s - k0.time_s).max(1e-9);
        let tangent = |j: usize, f: &dyn Fn(&SkillKeyPose) -> Vector| -> Vector {
            let a = &m[j.saturating_sub(1)];
            let b = &m[(j + 1).min(m.len() - 1)];
            let dt = b.time_s - a.time_s;
            if dt > 1e-9 {
                (f(b) - f(a)) / dt
            } else {
                Vector::zeros()
            }
        };
        let u = ((s - k0.time_s) / h).clamp(0.0, 1.0);
        let (u2, u3) = (u * u, u * u * u);
        let (h00, h10, h01, h11) = (
            2.0 * u3 - 3.0 * u2 + 1.0,
            u3 - 2.0 * u2 + u,
            -2.0 * u3 + 3.0 * u2,
            u3 - u2,
        );
        let interp = |f: &dyn Fn(&SkillKeyPose) -> Vector| -> Vector {
            f(k0) * h00 + tangent(i, f) * (h10 * h) + f(k1) * h01 + tangent(i + 1, f) * (h11 * h)
        };
        pose(interp(&|k| k.position), interp(&|k| k.rotation))
    }

    /// The object's reference pose in the world at `t` (s since the replay's start), relative
    /// to [`start_pose`](Self::start_pose): still until the grasp begins, then the skill's key
    /// poses ([`key_pose`](Self::key_pose)), holding the last held pose when the recording
    /// lost the object, set down during `place` in that case.
    pub fn reference(&self, t: Real) -> Isometry {
        self.reference_in(&self.timeline(), t)
    }

    /// [`reference`](Self::reference) with the timeline already at hand (a replay computes it
    /// once rather than every tick).
    pub fn reference_in(&self, tl: &Timeline, t: Real) -> Isometry {
        let start = self.start_pose();
        let s = t - tl.grasp_start;
        let key = |s: Real| -> Isometry { self.key_pose(s) };
        let relative = match self.held_until_s {
            Some(h) if s > h => {
                let held = key(h);
                let place_s = tl.place_start - tl.grasp_start;
                let release_s = tl.release_start - tl.grasp_start;
                if s <= place_s.max(h) {
                    held
                } else {
                    // Set it down where it was held: the rise above the table goes to zero.
                    let a = ((s - place_s.max(h)) / (release_s - place_s.max(h)).max(1e-3))
                        .clamp(0.0, 1.0);
                    let a = 10.0 * a.powi(3) - 15.0 * a.powi(4) + 6.0 * a.powi(5);
                    let rest = self.shape.support_depth(&held.rotation)
                        - self.shape.support_depth(&Rotation::identity());
                    let mut down = held;
                    down.translation.vector.z += (rest - held.translation.vector.z) * a;
                    down
                }
            }
            _ => key(s.max(0.0)),
        };
        // Relative poses are of B in B₀; B₀ = start.
        start * relative
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hand::{builtin_hand, thumb_of};

    #[test]
    fn failure_reasons_are_named_as_in_reports_and_the_data_base() {
        crate::names::assert_serde_agrees::<FailureReason>();
        let e = "tired".parse::<FailureReason>().unwrap_err().to_string();
        assert!(e.starts_with("unknown failure reason \"tired\""), "{e}");
    }

    /// A two-finger pinch of a 0.2 kg box along x, lifted 8 cm over 1 s, held 0.5 s, put back.
    fn box_pinch(mass: Real) -> SkillSpec {
        let key = |t: Real, z: Real| SkillKeyPose {
            time_s: t,
            position: Vector::new(0.0, 0.0, z),
            rotation: Vector::zeros(),
        };
        SkillSpec {
            shape: Shape::Box {
                half_extents: [0.025, 0.025, 0.04],
            },
            mass,
            friction: Friction {
                mu: 0.8,
                mu_torsion: 0.003,
            },
            contact_model: ContactModel::SoftFinger,
            contacts: vec![
                SkillContact {
                    finger: "thumb".into(),
                    part: crate::hand::ContactPart::Fingertip,
                    position_b: Vector::new(-0.025, 0.0, 0.0),
                    normal_b: Vector::x(),
                },
                SkillContact {
                    finger: "index".into(),
                    part: crate::hand::ContactPart::Fingertip,
                    position_b: Vector::new(0.025, 0.0, 0.0),
                    normal_b: -Vector::x(),
                },
            ],
            motion: vec![
                key(0.0, 0.0),
                key(0.8, 0.0),
                key(1.3, 0.04),
                key(1.8, 0.08),
                key(2.3, 0.08),
                key(2.8, 0.04),
                key(3.3, 0.0),
            ],
            phases: vec![
                (Phase::Approach, 0.5),
                (Phase::Grasp, 0.8),
                (Phase::Lift, 1.0),
                (Phase::Hold, 0.5),
                (Phase::Place, 1.0),
                (Phase::Release, 0.5),
                (Phase::Retreat, 0.3),
            ],
            held_until_s: None,
        }
    }

    /// A skill held by the palm too (a power grasp) on a hand without palm contact geometry is
    /// refused naming its first palm or phalanx contact, not planned as if the palm were a
    /// fingertip.
    #[test]
    fn a_whole_hand_skill_is_refused_naming_its_palm_contact() {
        let hand = builtin_hand("allegro").unwrap();
        let mut skill = box_pinch(0.2);
        skill.contacts[1].finger = "palm".into();
        skill.contacts[1].part = crate::hand::ContactPart::Palm;
        let e = plan(&hand, thumb_of(&hand), &skill, &ReplayParams::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("skill.contacts[1]")
                && e.contains("palm contact (`palm`)")
                && e.contains("no palm contact geometry"),
            "{e}"
        );
        // A phalanx without a palm contact is neither a power grasp nor a fingertip one.
        skill.contacts[1].part = crate::hand::ContactPart::Phalanx;
        let e = plan(&hand, thumb_of(&hand), &skill, &ReplayParams::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("without a palm contact"), "{e}");
        skill.contacts[1].part = crate::hand::ContactPart::Fingertip;
        assert!(plan(&hand, thumb_of(&hand), &skill, &ReplayParams::default()).is_ok());
    }

    /// A power grasp on a hand with a palm (glove10) is planned as one, whatever the object:
    /// too big to wrap it is a report (never a panic), and a stop ends the planning.
    #[test]
    fn a_power_grasp_is_planned_as_a_wrap_and_its_failures_are_reports() {
        let hand = builtin_hand("glove10").unwrap();
        let thumb = thumb_of(&hand);
        let params = ReplayParams::default();
        let mut skill = box_pinch(0.2);
        skill.contacts[1].finger = "palm".into();
        skill.contacts[1].part = crate::hand::ContactPart::Palm;
        let p = plan(&hand, thumb, &skill, &params).unwrap();
        let power = p.power.as_ref().expect("a wrap");
        assert_eq!(power.contacts[0].part, crate::hand::ContactPart::Palm);
        assert!(power.grip > 0.0 && power.grip <= 1.0);
        assert!(power.close.iter().any(|&c| c != 0.0));
        // An object a metre across: no wrap holds it; the replay says why.
        skill.shape = Shape::Box {
            half_extents: [0.5, 0.5, 0.5],
        };
        skill.contacts[1].position_b = Vector::new(0.5, 0.0, 0.0);
        let r = run(&hand, thumb, &skill, &params).unwrap();
        assert!(!r.success && r.failure_reason.is_some(), "{}", r.detail);
        let stop = crate::Stop::default();
        stop.stop();
        assert!(matches!(
            plan_with_stop(&hand, thumb, &box_power(), &params, &stop),
            Err(crate::DfsError::Cancelled)
        ));
    }

    fn box_power() -> SkillSpec {
        let mut skill = box_pinch(0.2);
        skill.contacts[1].part = crate::hand::ContactPart::Palm;
        skill
    }

    #[test]
    fn a_retargeting_step_balances_the_load_inside_the_cones_and_torque_limits() {
        let hand = builtin_hand("gripper").unwrap();
        let skill = box_pinch(0.2);
        let params = ReplayParams::default();
        let plan = plan(&hand, thumb_of(&hand), &skill, &params).unwrap();
        assert!(plan.failure.is_none(), "{:?}", plan.failure);
        let tl = skill.timeline();
        let contacts: Vec<_> = (0..plan.contacts.len())
            .filter(|&k| plan.active[k])
            .map(|k| plan.contacts[k])
            .collect();
        let g = Vector::new(0.0, 0.0, -crate::math::STANDARD_GRAVITY);
        let mu = skill.friction.mu * (1.0 - params.friction_margin);
        let mut step = RetargetStep::new(&plan, &skill, &params);
        for i in 0..50 {
            let t = tl.grasp_end + (tl.release_start - tl.grasp_end) * i as Real / 50.0;
            let load = plan::load_at(&skill, t, &g);
            let (ik_error, forces) = step.step(t);
            assert!(ik_error < params.reach_tolerance, "{t}: {ik_error}");
            let forces = forces.expect("the box's load is carried all along");
            let mut wrench = crate::math::Wrench::zeros();
            for (c, f) in contacts.iter().zip(forces) {
                wrench += c.wrench_b(f);
                assert!(f[2] >= params.min_normal - 1e-9);
                assert!(f[0].hypot(f[1]) <= mu * f[2] + 1e-6, "{f:?}");
                // Inside the planned cone, torsion included (elliptic for a soft finger).
                let planned = crate::contact::Friction {
                    mu,
                    mu_torsion: skill.friction.mu_torsion * (1.0 - params.friction_margin),
                };
                let u = crate::contact::cone_usage(skill.contact_model, &planned, f);
                assert!(u <= 1.0 + 1e-6, "{f:?}: {u}");
            }
            assert!((wrench - load).norm() < 1e-6 * (1.0 + load.norm()), "{t}");
            let tau = &plan.torque_map
                * nalgebra::DVector::from_iterator(
                    4 * forces.len(),
                    forces.iter().flat_map(|f| f.iter().copied()),
                );
            for (d, t) in tau.iter().enumerate() {
                assert!(t.abs() <= hand.torque_limit[d] + 1e-6);
            }
        }
    }

    #[test]
    fn the_timeline_follows_the_skills_phases() {
        let tl = box_pinch(0.2).timeline();
        assert!((tl.grasp_start - 0.5).abs() < 1e-12);
        assert!((tl.grasp_end - 1.3).abs() < 1e-12);
        assert!((tl.place_start - 2.8).abs() < 1e-12);
        assert!((tl.release_start - 3.8).abs() < 1e-12);
        // The retreat lasts at least 0.6 s.
        assert!((tl.end - 4.9).abs() < 1e-12);
    }

    #[test]
    fn the_reference_passes_through_the_key_poses_with_continuous_velocity() {
        let skill = box_pinch(0.2);
        let z0 = skill.start_pose().translation.z;
        for k in &skill.motion {
            let p = skill.reference(0.5 + k.time_s).translation.vector;
            assert!((p.z - z0 - k.position.z).abs() < 1e-12, "{}", k.time_s);
        }
        // Velocity on either side of a key pose agrees (no kink for the arm to follow).
        let v = |t: Real| {
            (skill.reference(t + 1e-4).translation.z - skill.reference(t - 1e-4).translation.z)
                / 2e-4
        };
        let t = 0.5 + 1.3;
        assert!((v(t - 2e-3) - v(t + 2e-3)).abs() < 0.01);
    }

    #[test]
    fn a_reference_that_lost_the_object_holds_then_sets_it_down() {
        let mut skill = box_pinch(0.2);
        // Pretend the recording dropped it at 1.8 s after the grasp began.
        skill.held_until_s = Some(1.8);
        let z0 = skill.start_pose().translation.z;
        let tl = skill.timeline();
        let held = skill.reference(tl.grasp_start + 1.8).translation.z - z0;
        let later = skill.reference(tl.place_start - 0.01).translation.z - z0;
        assert!((held - 0.08).abs() < 1e-9 && (later - 0.08).abs() < 1e-9);
        let down = skill.reference(tl.release_start).translation.z - z0;
        assert!(down.abs() < 1e-9, "{down}");
    }

    /// `skill` replayed on the built-in hand `name` with the default parameters.
    fn replay_on(name: &str, skill: &SkillSpec) -> ReplayReport {
        let hand = builtin_hand(name).unwrap();
        run(&hand, thumb_of(&hand), skill, &ReplayParams::default()).unwrap()
    }

    /// A failed replay with `reason`, refused by the plan: nothing was simulated.
    fn assert_refused_up_front(r: &ReplayReport, reason: FailureReason) {
        assert!(!r.success);
        assert_eq!(r.failure_reason, Some(reason), "{}", r.detail);
        assert_eq!(r.ticks, 0);
    }

    #[test]
    fn a_box_pinch_replays_on_the_gripper_and_lifts_the_box() {
        let r = replay_on("gripper", &box_pinch(0.2));
        assert!(r.success, "{:?}: {}", r.failure_reason, r.detail);
        assert!(r.lift_height_m > 0.06, "{}", r.lift_height_m);
        assert!(r.position_error_max_m < 0.02);
        assert!(r.peak_torque_ratio > 0.0 && r.peak_torque_ratio <= 1.0 + 1e-9);
        assert_eq!(r.ticks, 4900);
    }

    /// The fixed-clock replay, tick for tick, as it was before replays could be driven by the
    /// operator's phases ([`Replay::step_to`]): the box pinch on the gripper, its report's
    /// numbers and a sum over every tick's base, joint angles and object pose.
    #[test]
    fn the_fixed_clock_replay_is_pinned() {
        let hand = builtin_hand("gripper").unwrap();
        let mut sum = [0.0; 3];
        let r = run_with(
            &hand,
            thumb_of(&hand),
            &box_pinch(0.2),
            &ReplayParams::default(),
            |tick| {
                sum[0] += tick.base.translation.vector.sum();
                sum[1] += tick.q.iter().sum::<Real>();
                sum[2] += tick.output.object.pose.translation.vector.sum();
            },
        )
        .unwrap();
        let got = [
            r.position_error_max_m,
            r.position_error_rms_m,
            r.orientation_error_max_rad,
            r.orientation_error_rms_rad,
            r.max_slip_m,
            r.min_friction_margin,
            r.peak_torque_ratio,
            r.lift_height_m,
            sum[0],
            sum[1],
            sum[2],
        ];
        // Taken from the replay before `step_to` existed; the joint angles' sum re-taken with
        // issue 21's contacts: a pushing pad now rests 0.1 mm in (the contact preload), so the
        // jaws sit that much further in. The box's motion is the same to the last digit.
        let pinned = [
            0.00042056261333334177,
            0.00033272708867277935,
            0.0,
            0.0,
            0.0003389494460199552,
            0.0,
            0.9687423580329151,
            0.08467833333333338,
            1289.7726830768931,
            146.56374382245906,
            317.49695474361107,
        ];
        for (i, (g, p)) in got.iter().zip(pinned).enumerate() {
            assert!((g - p).abs() <= 1e-12 * p.abs().max(1.0), "{i}: {g} != {p}");
        }
        assert!(r.success, "{}", r.detail);
        assert_eq!((r.ticks, r.slip_ticks), (4900, 1));
    }

    #[test]
    fn a_box_too_heavy_for_the_torque_limits_fails_with_torque_limit() {
        // Not even at rest: refused up front, nothing simulated.
        assert_refused_up_front(
            &replay_on("gripper", &box_pinch(8.0)),
            FailureReason::TorqueLimit,
        );
    }

    #[test]
    fn a_box_wider_than_the_gripper_opens_fails_with_unreachable() {
        let mut skill = box_pinch(0.2);
        skill.shape = Shape::Box {
            half_extents: [0.09, 0.05, 0.04],
        };
        skill.contacts[0].position_b.x = -0.09;
        skill.contacts[1].position_b.x = 0.09;
        assert_refused_up_front(&replay_on("gripper", &skill), FailureReason::Unreachable);
    }

    /// Inspire's thumb and index carry the names of a thumb-index pinch's contacts, but its
    /// one-DOF index meets the box's face far off the normal: pushing there only turns the box
    /// out of the grasp, so the plan is refused before anything runs.
    #[test]
    fn a_named_grasp_whose_finger_pushes_outside_the_friction_cone_is_unreachable() {
        assert_refused_up_front(
            &replay_on("inspire", &box_pinch(0.2)),
            FailureReason::Unreachable,
        );
    }

    /// glove10's own three-finger cylinder grasp (contacts of a `cylinder-power-grasp`
    /// recording), 0.5 kg lifted 8 cm.
    fn glove10_cylinder_skill() -> SkillSpec {
        let contact = |finger: &str, p: [Real; 3], n: [Real; 3]| SkillContact {
            finger: finger.into(),
            part: crate::hand::ContactPart::Fingertip,
            position_b: Vector::from(p),
            normal_b: Vector::from(n).normalize(),
        };
        let mut skill = box_pinch(0.5);
        skill.shape = Shape::Cylinder {
            radius: 0.035,
            half_height: 0.045,
        };
        skill.friction.mu = 0.7;
        skill.contacts = vec![
            contact(
                "thumb",
                [-0.0349, 0.0026, 0.02468],
                [0.99724, -0.07419, 0.0],
            ),
            contact(
                "index",
                [0.03484, -0.00329, 0.02019],
                [-0.99556, 0.09408, 0.0],
            ),
            contact(
                "middle",
                [0.02951, -0.01882, 0.03071],
                [-0.84306, 0.53782, 0.0],
            ),
        ];
        skill
    }

    /// The demonstrating hand replays its own cylinder grasp: its ring and little fingers
    /// follow the middle finger's DOFs, so no pose puts a contact under each of its five tips,
    /// but its closing motion, searched with the cylinder as the hand will meet it, holds it.
    #[test]
    fn glove10_replays_its_own_three_finger_cylinder_grasp() {
        let r = replay_on("glove10", &glove10_cylinder_skill());
        assert!(r.success, "{:?}: {}", r.failure_reason, r.detail);
        assert!(r.lift_height_m > 0.06, "{}", r.lift_height_m);
    }

    /// The last-resort plan for a hand with the skill's finger names takes each contact on the
    /// finger of its name and leaves the coupled ring and little fingers out of the object.
    #[test]
    fn glove10s_named_plan_puts_its_three_fingers_on_their_own_cylinder_contacts() {
        let hand = builtin_hand("glove10").unwrap();
        let thumb = thumb_of(&hand);
        let skill = glove10_cylinder_skill();
        let params = ReplayParams::default();
        let stop = crate::Stop::never();
        let best = plan::plan_candidates(&hand, thumb, &skill, &params, plan::Keys::Named, stop)
            .unwrap()
            .into_iter()
            .max_by(|a, b| a.score.total_cmp(&b.score))
            .unwrap();
        assert!(best.ok, "error {} align {}", best.error, best.align);
        assert!(best.error <= params.reach_tolerance, "{}", best.error);
        for (k, tip) in hand.fingertips.iter().enumerate() {
            let used = ["thumb", "index", "middle"].contains(&tip.name.as_str());
            assert_eq!(best.active[k], used, "{}", tip.name);
        }
    }
}
