//! Grasp force optimisation (beyond the paper; Buss, Hashimoto and Moore 1996): the least
//! internal force that balances a load while keeping every contact inside its exact friction
//! cone with a margin.

use crate::contact::{ContactFrame, ContactModel, Friction, Intensity};
use crate::math::{Real, Wrench};

/// Parameters of the optimisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptimiseParams {
    /// Friction margin: contacts must lie inside the cone of `μ (1 − margin)` (and the torsion
    /// cone of `μ_t (1 − margin)`). Range [0, 1). Default 0.1.
    pub margin: Real,
    /// Least normal force per contact (N), ≥ 0. Default 0.
    pub min_normal: Real,
}

impl Default for OptimiseParams {
    fn default() -> Self {
        OptimiseParams {
            margin: 0.1,
            min_normal: 0.0,
        }
    }
}

/// An optimised force distribution.
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution {
    /// Intensities per contact (layout of [`Intensity`]).
    pub intensities: Vec<Intensity>,
    /// Residual `‖W c − load‖` (should be ~0).
    pub residual: Real,
}

/// Why no distribution exists.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("infeasible grasp: {reason}")]
pub struct Infeasible {
    /// Human-readable reason.
    pub reason: String,
}

/// Finds intensities `c` with `W c = load_b` (the wrench the hand must apply, in B) and every
/// contact inside its cone with the margin, minimising `Σ‖c_i‖²` (least internal force).
pub fn optimise(
    contacts: &[ContactFrame],
    model: ContactModel,
    friction: &Friction,
    load_b: &Wrench,
    params: &OptimiseParams,
) -> Result<Distribution, Infeasible> {
    let _ = (contacts, model, friction, load_b, params);
    todo!("grasp force optimisation")
}
