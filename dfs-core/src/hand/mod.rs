//! Hand kinematics: a general kinematic tree of links and joints (revolute, continuous,
//! prismatic, fixed, and mimic/coupled joints with limits), forward kinematics to every
//! fingertip, analytic fingertip Jacobians and the joint-space inertia M(θ).
//!
//! Generalised coordinates (the "DOFs", θ) are the independent joints; a mimic joint's value
//! is `multiplier · θ[dof] + offset`. All per-tick work writes into a preallocated
//! [`Kinematics`] of fixed capacity: no heap allocation after construction.
//!
//! [`ik`] places chosen fingertips at world targets (damped least squares, joint limits).
//! [`urdf`] builds hands from a URDF plus a [`HandSpec`]; [`builtin`] holds the built-in hands
//! (`glove10`, `allegro`, `barrett`, `inspire`, `gripper`). [`link_shapes`] gives the simple
//! solids that draw a hand and [`hand_urdf`] writes a hand back as URDF with them.

pub mod builtin;
pub mod contact_geometry;
mod glove10;
pub mod ik;
mod model;
pub mod shapes;
pub mod urdf;
pub mod urdf_write;

pub use builtin::{builtin_hand, builtin_spec, thumb_of, BUILTIN_HANDS};
pub use contact_geometry::{
    BodyPart, ContactPart, ContactPrimitive, ContactShape, MAX_CONTACT_SHAPES,
    MAX_CONTACT_SHAPES_PER_LINK,
};
pub use model::*;
pub use shapes::{link_shapes, LinkShape, Primitive, ShapeSource};
pub use urdf::{
    check_urdf_text, FingertipSpec, HandSpec, DEFAULT_ARMATURE, MAX_HAND_EXTENT, MAX_URDF_BYTES,
    MAX_URDF_DEPTH,
};
pub use urdf_write::hand_urdf;
