//! The DFS's parameters ([`DfsParams`], checked by [`DfsParams::validate`]) and the damping limit
//! of the explicit object step ([`STABLE_DAMPING`]).

use crate::contact::{ContactModel, Friction};
use crate::error::{DfsError, Result};
use crate::math::{Real, Vector};

/// How much of the explicit object step's damping limit the contacts' tangential dampers may
/// use: `Σ_k c_k dt / m_k ≤ STABLE_DAMPING`, with `m_k` the object's least effective mass at
/// contact `k` for a push across the normal (`inverse_mass_across`), shared equally. An
/// explicit (symplectic Euler) step of a damper `c` on a mass `m` is stable for
/// `c dt / m < 2`; beyond it a light object rattles between the fingertips from tick to tick
/// (a 50 g solid sphere of 4 cm radius pinched by two pads at 30 N·s/m: 4.2) and is
/// flung out of the grasp. A damper stronger than that cannot act within one tick anyway.
/// The soft pads' torsional dampers get the same budget about the normal: `Σ_k c_τ dt nᵀI⁻¹n`.
pub const STABLE_DAMPING: Real = 1.5;

/// Parameters of the DFS. Units SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DfsParams {
    /// Tick length (s). Default 0.001 (1 kHz haptic rate).
    pub dt: Real,
    /// Gravity in the world frame (m/s²). Default (0, 0, −9.81).
    pub gravity: Vector,
    /// Contact model. Default point with friction.
    pub contact_model: ContactModel,
    /// Friction between fingertips and object. Default μ = 0.8, μ_t = 0.005 m. The object's of
    /// [`Dfs::new`]; a scene of [`Dfs::with_objects`] gives each object its own
    /// ([`DfsObject::friction`]).
    ///
    /// [`Dfs::new`]: super::Dfs::new
    /// [`Dfs::with_objects`]: super::Dfs::with_objects
    /// [`DfsObject::friction`]: super::DfsObject::friction
    pub friction: Friction,
    /// Gap (m) up to which a fingertip is detected as touching the object (its contact frame
    /// is known and reported); it transmits force only once the gap has closed (see
    /// `contact_preload`). Default 0.001.
    pub contact_margin: Real,
    /// Damping λ (m) of the pseudo-inverse `J (JᵀJ + λ²I)⁻¹` that resolves joint torques into
    /// fingertip forces; keeps it finite for a stretched finger. Default 1e-3.
    pub tip_force_damping: Real,
    /// Viscous damping of the glove joints (N·m·s/rad). Default 0.02.
    pub joint_damping: Real,
    /// Stiffness (N/m) keeping a touching fingertip on the surface (finger side only).
    /// Default 3000.
    pub surface_stiffness: Real,
    /// Depth (m) over which a fingertip's pad takes up the operator's push: it passes on the
    /// operator's intensities in proportion to how far it presses into the object up to this
    /// depth, and all of them beyond; across a gap, none. 0: all or nothing at the surface.
    /// Default 5e-5 (0.05 mm).
    pub contact_ramp: Real,
    /// Depth (m) at which the surface spring holds a fingertip that pushes: the pad's resting
    /// compression (the spring draws it in up to this depth and pushes it out beyond). Deeper
    /// than `contact_ramp`, so that a resting pad passes on the whole push, its depth clear of
    /// the ramp by more than the angle sensors' noise (some µm), rather than at the surface,
    /// where the contact would open and close from tick to tick. A fingertip that does not
    /// push rests on the surface. Default 1e-4 (0.1 mm).
    pub contact_preload: Real,
    /// Damping (N·s/m) of the same, and of a sticking fingertip's tangential spring to its
    /// anchor on the object. Default 30. It damps how fast the contact point of the finger
    /// dynamics' fingertip moves relative to the object (see the module documentation), never a
    /// difference of measured angles. The tangential part acts on the object too, whose
    /// step is explicit: it is limited per contact to what that step can carry (see
    /// [`STABLE_DAMPING`]), which only a light object (a solid sphere under about 0.1 kg)
    /// ever meets.
    pub surface_damping: Real,
    /// Viscous torsional coupling between a soft fingertip pad and the object (N·m·s/rad),
    /// limited by the torsional friction cone and, like the tangential damping, per contact to
    /// what the object's explicit step can carry about the normal ([`STABLE_DAMPING`] with the
    /// object's inverse inertia about the normal, which a solid sphere of 2 cm radius under
    /// about 25 g meets). Default 0.005: with the torsional stiffness,
    /// two pads pinching a 0.3 kg, 4 cm sphere are about critically damped about the pinch
    /// axis. (It was 0.05, twelve times overdamped: the pinched sphere then swung to its
    /// hanging rest over seconds, a creep of 20-50 µm/s in the hand.)
    pub torsion_damping: Real,
    /// Torsional stiffness of a sticking soft fingertip pad (N·m/rad): the pad resists being
    /// twisted about the normal from where it stuck, within the torsional friction cone.
    /// Default 0.04 (a pad with about 5 mm contact radius and the surface stiffness: k a²/2).
    pub torsion_stiffness: Real,
    /// Joint angles may exceed their limits by this much (rad or m) before a sample is refused.
    /// Default 0.05.
    pub angle_slack: Real,
    /// Joint torques may reach this multiple of the hand's torque limit before a sample is
    /// refused (the glove's sensor range). Default 2.
    pub torque_range: Real,
    /// Height (m, world z) of a horizontal table supporting the object; `None` for no table.
    pub table_height: Option<Real>,
    /// Coulomb coefficient between object and table. Default 0.5.
    pub table_mu: Real,
    /// Rolling resistance of a sphere, or a cylinder lying or on its rim, on the table: the
    /// lever (m) of the couple that resists its rolling and spinning, at most
    /// `table_rolling × N` (a box or a standing cylinder has none: its corners or rim resist).
    /// Default 0.001 (a 4 cm ball bumped at 0.1 m/s rolls about 1.5 cm).
    pub table_rolling: Real,
    /// Whole-hand contact: the hand's palm and phalanges
    /// ([`HandModel::contact_shapes`](crate::hand::HandModel)) touch objects too, each a
    /// spring-damper contact with stick friction and its own frame and cone in `W` (see
    /// [`body`](super) and the module documentation of `dfs::body`). Default false: the
    /// fingertips alone, as before issue 21 item 5.
    pub whole_hand: bool,
    /// Stiffness (N/m) of a whole-hand contact, along the normal and of its stick spring,
    /// limited per contact by [`BODY_STIFFNESS_BUDGET`]. Default 20 000 (a 5 N push presses a
    /// palm 0.25 mm in).
    ///
    /// [`BODY_STIFFNESS_BUDGET`]: super::BODY_STIFFNESS_BUDGET
    pub body_stiffness: Real,
    /// Damping (N·s/m) of a whole-hand contact, along the normal and of its stick spring, limited
    /// per contact by [`STABLE_DAMPING`]. Default 30.
    pub body_damping: Real,
}

impl Default for DfsParams {
    fn default() -> Self {
        DfsParams {
            dt: 1e-3,
            gravity: Vector::new(0.0, 0.0, -crate::math::STANDARD_GRAVITY),
            contact_model: ContactModel::PointWithFriction,
            friction: Friction::default(),
            contact_margin: 1e-3,
            tip_force_damping: 1e-3,
            joint_damping: 0.02,
            surface_stiffness: 3000.0,
            contact_ramp: 5e-5,
            contact_preload: 1e-4,
            surface_damping: 30.0,
            torsion_damping: 0.005,
            torsion_stiffness: 0.04,
            angle_slack: 0.05,
            torque_range: 2.0,
            table_height: None,
            table_mu: 0.5,
            table_rolling: 1e-3,
            whole_hand: false,
            body_stiffness: 2e4,
            body_damping: 30.0,
        }
    }
}

impl DfsParams {
    /// Checks every parameter; the error names the field.
    pub fn validate(&self) -> Result<()> {
        let pos = |f: &str, v: Real| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(DfsError::invalid(
                    f,
                    format!("must be a finite number > 0, got {v}"),
                ))
            }
        };
        let nonneg = |f: &str, v: Real| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(DfsError::invalid(
                    f,
                    format!("must be a finite number ≥ 0, got {v}"),
                ))
            }
        };
        pos("dt", self.dt)?;
        if !self.gravity.iter().all(|v| v.is_finite()) {
            return Err(DfsError::invalid("gravity", "must be finite"));
        }
        nonneg("friction.mu", self.friction.mu)?;
        nonneg("friction.mu_torsion", self.friction.mu_torsion)?;
        nonneg("contact_margin", self.contact_margin)?;
        pos("tip_force_damping", self.tip_force_damping)?;
        nonneg("joint_damping", self.joint_damping)?;
        nonneg("surface_stiffness", self.surface_stiffness)?;
        nonneg("contact_ramp", self.contact_ramp)?;
        nonneg("contact_preload", self.contact_preload)?;
        nonneg("surface_damping", self.surface_damping)?;
        nonneg("torsion_damping", self.torsion_damping)?;
        nonneg("torsion_stiffness", self.torsion_stiffness)?;
        nonneg("angle_slack", self.angle_slack)?;
        pos("torque_range", self.torque_range)?;
        nonneg("table_mu", self.table_mu)?;
        nonneg("table_rolling", self.table_rolling)?;
        nonneg("body_stiffness", self.body_stiffness)?;
        nonneg("body_damping", self.body_damping)?;
        if let Some(h) = self.table_height {
            if !h.is_finite() {
                return Err(DfsError::invalid("table_height", "must be finite"));
            }
        }
        Ok(())
    }
}
