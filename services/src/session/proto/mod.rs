//! Session format v2: the raw topics as protobuf, generated from `proto/icms/session.proto`
//! (the one definition of their fields, units and steps), and the conversions between those
//! fixed-point messages and the SI types of [`super::messages`] that the rest of the code
//! works with.
//!
//! Each conversion pair sits together: [`Quantiser`] rounds SI values to the steps the
//! `.proto` names (`_eN`: steps of 10^-N SI units), and the `from_proto` functions multiply
//! back. A value read back is the recorded one to within half a step.
//!
//! The parts: [`Quantiser`] (quantisation and encoding, in `quantiser.rs`) writes through a
//! branch-free protobuf cursor (`encode.rs`) with field keys taken from the generated types
//! (`keys.rs`); `from_proto.rs` converts back to SI; [`schema_difference`] (`schema.rs`)
//! compares a file's schema with ours.

use super::messages::ContactPart;

mod encode;
mod from_proto;
mod keys;
mod quantiser;
mod schema;
#[cfg(test)]
mod tests;

pub use from_proto::{
    contacts_from_proto, feedback_from_proto, joint_states_from_proto, object_from_proto,
};
pub use quantiser::Quantiser;
pub use schema::{schema_difference, ADDED_FIELDS};

#[allow(missing_docs, clippy::all, clippy::pedantic)]
mod generated {
    include!(concat!(env!("OUT_DIR"), "/icms.rs"));
}

pub use generated::{
    Contacts as ContactsProto, FingerContact as FingerContactProto,
    FingerFeedback as FingerFeedbackProto, GloveFeedback as GloveFeedbackProto,
    GloveJointStates as GloveJointStatesProto, Intensityi, ObjectState as ObjectStateProto, Posei,
    Quaternioni, SceneObjectState as SceneObjectStateProto, Vector3i, Wrenchi,
};

/// The compiled `proto/icms/session.proto` (a serialised `google.protobuf.FileDescriptorSet`):
/// the MCAP schema data of every raw topic of a v2 session.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/icms_session.fds"));

/// Message encoding and schema encoding of v2 channels (MCAP's well-known `protobuf`).
pub const PROTOBUF: &str = "protobuf";

/// The session format written by this build: 2 (protobuf on every topic). Format 1 (JSON on
/// every topic) is still read. Written as `format_version` in the `session` metadata record;
/// a file without it is format 1.
pub const FORMAT_VERSION: u32 = 2;

/// Step of a joint angle, rad (the `_e5` fields of the glove topics).
pub const JOINT_ANGLE: f64 = 1e-5;
/// Step of a joint velocity, rad/s (`_e2`).
pub const JOINT_VELOCITY: f64 = 1e-2;
/// Step of a joint torque, N·m (`_e5`).
pub const JOINT_TORQUE: f64 = 1e-5;
/// Step of a force, N (`_e3`).
pub const FORCE: f64 = 1e-3;
/// Step of a moment (contact torsion, wrench torques), N·m (`_e6`).
pub const MOMENT: f64 = 1e-6;
/// Step of a position, m (`_e6`).
pub const POSITION: f64 = 1e-6;
/// Step of a unit vector's or quaternion's component (`_e6`).
pub const UNIT: f64 = 1e-6;
/// Step of a penetration depth, m (`_e9`).
pub const PENETRATION: f64 = 1e-9;
/// Step of a linear velocity, m/s (`_e6`).
pub const LINEAR_VELOCITY: f64 = 1e-6;
/// Step of an angular velocity, rad/s (`_e6`).
pub const ANGULAR_VELOCITY: f64 = 1e-6;

/// The protobuf number of a contact's part (`icms.ContactPart`).
pub(crate) fn part_number(p: ContactPart) -> u32 {
    match p {
        ContactPart::Fingertip => 0,
        ContactPart::Palm => 1,
        ContactPart::Phalanx => 2,
    }
}

/// A contact's part from its protobuf number; a number this version does not know (a later
/// part) reads as a phalanx: some part of the hand other than a fingertip.
pub(crate) fn part_of_number(n: u32) -> ContactPart {
    match n {
        0 => ContactPart::Fingertip,
        1 => ContactPart::Palm,
        _ => ContactPart::Phalanx,
    }
}
