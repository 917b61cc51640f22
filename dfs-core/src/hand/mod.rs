//! Hand kinematics: a general kinematic tree of links and joints (revolute, continuous,
//! prismatic, fixed, and mimic/coupled joints with limits), forward kinematics to every
//! fingertip, analytic fingertip Jacobians and the joint-space inertia M(θ).
//!
//! Generalised coordinates (the "DOFs", θ) are the independent joints; a mimic joint's value
//! is `multiplier · θ[dof] + offset`. All per-tick work writes into a preallocated
//! [`Kinematics`] of fixed capacity: no heap allocation after construction.
//!
//! [`ik`] places chosen fingertips at world targets (damped least squares, joint limits).

mod glove10;
pub mod ik;
mod model;

pub use model::*;
