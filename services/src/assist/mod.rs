//! The assistant (IP-flow 3): while an operator's glove streams, it recognises early which
//! stored skill they are performing and on which object, applies it on a robot hand, and
//! learns a grasp it does not know.
//!
//! - [`features`]: what the assistant sees of a tick ([`features::Observation`]), and the
//!   *approach template* of a grasp: the object, then the hand's aperture and pose as it comes
//!   within fixed distances of the object's surface, how many fingertips touch first, the
//!   grip 0.8 s after the touch, and how many objects the scene has.
//!   Stored skills carry theirs (computed at ingest); the stream's are built as it comes.
//! - [`index`]: the stored skills' templates and features, scanned per decision.
//! - [`recognise`]: the on-line recogniser: `recognised` / `unknown` events from the stream.
//!
//! The same code runs inside a live session (on a thread of its own, so it never delays the
//! feedback), over a recorded session (`icms recognise`) and in `icms bench recognition`.

pub mod assistant;
pub mod evaluate;
pub mod features;
pub mod index;
pub mod offline;
pub mod phase;
pub mod recognise;
pub mod record;
