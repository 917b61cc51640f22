//! Decoding the raw topics of session format 2 straight into their SI types, reusing the
//! caller's message (its vectors and name strings): no allocation per message once warm.
//!
//! # Why not prost
//!
//! prost's generated decoders (kept for encoding, and as the reference these are tested
//! against) allocate a `String` for every name and a `Vec` for every repeated field of every
//! message, and the SI conversion allocates again. A 60 s session holds 240 000 raw messages
//! with 15 to 25 names each; measured with `perf` on `icms segment` of a 60 s `sphere-lift`
//! (2026-11-25): 38 % of the time in the allocator, 0.42 s in all. A session of an hour must
//! segment in 10 s. This decoder reads the same wire format (proto3: unknown fields skipped,
//! packed or unpacked repeated scalars, a message field given twice merged, the last scalar
//! winning, groups skipped) into messages it clears and refills.
//!
//! The property tests (`tests/`) hold it to prost: on any bytes, both accept or both refuse,
//! and what both accept converts to the same SI message.
//!
//! The parts: a cursor over the wire format (`reader.rs`), the field readers the decoders share
//! (`fields.rs`), the decoders of the glove topics (`glove.rs`), of `/dfs/contacts`
//! (`contacts.rs`) and of `/object/state` (`object.rs`), and [`MessageCheck`] (`check.rs`),
//! which checks bytes against any message type without building it.

mod check;
mod contacts;
mod fields;
mod glove;
mod object;
mod reader;
#[cfg(test)]
mod tests;

pub(crate) use check::MessageCheck;
pub(crate) use contacts::{contacts, contacts_lean};
pub(crate) use glove::{feedback, glove_shape, joint_states};
pub(crate) use object::{object, object_lean};

/// Why bytes do not decode (the wording of prost's errors where there is one).
pub(crate) type DecodeError = &'static str;
type Result<T> = std::result::Result<T, DecodeError>;
