//! # dfs-core: the Dynamic Force Simulator
//!
//! Pure, synchronous physics after Buss and Hashimoto, *Intelligent Cooperative Manipulation
//! Using Dynamic Force Simulator* (§3): frames and wrench maps, hand kinematics, contact and
//! Coulomb friction models, the grasp matrix, Newton-Euler object dynamics, force feedback to
//! the glove, grasp force optimisation, and the DFS tick that strings them together.
//!
//! No I/O, no async, no database. The tick ([`dfs::Dfs::step`]) allocates nothing.

pub mod calibration;
pub mod contact;
pub mod coupling;
pub mod dfs;
pub mod error;
#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures;
pub mod frames;
pub mod grasp;
pub mod hand;
pub mod json_object;
pub mod math;
pub mod min_jerk;
pub mod names;
pub mod object;
pub mod operator;
pub mod replay;
pub mod scenario;
pub mod spec;
pub mod statics;
pub mod stop;
pub mod table;

pub use error::{DfsError, Result};
pub use stop::Stop;
