//! Decoding `icms.ObjectState` ([`object`]), whole or only the fields segmentation reads
//! ([`object_lean`]).

use super::fields::{fields, message, pose, vector3, wrench};
use super::reader::{expect, Reader, VARINT};
use super::Result;
use crate::foxglove::{Pose, Quaternion, Vector3};
use crate::session::messages::{ObjectState, SceneObjectState};
use crate::session::proto::{ANGULAR_VELOCITY, LINEAR_VELOCITY};

/// A pose of all zeros: protobuf's default, not the identity (a missing orientation reads as
/// the zero quaternion, which the reader's check refuses, as it should).
fn zero_pose() -> Pose {
    Pose {
        position: Vector3::default(),
        orientation: Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 0.0,
        },
    }
}

/// Decodes an `icms.ObjectState` into `out` (reset first).
pub(crate) fn object(buf: &[u8], out: &mut ObjectState) -> Result<()> {
    object_with(buf, out, false)
}

/// [`object`] of bytes that decoded before, only the fields segmentation reads: `pose`,
/// `pose_in_hand`, `index` and `objects`; the velocities and wrenches are skipped as unknown
/// fields are, and stay zero.
pub(crate) fn object_lean(buf: &[u8], out: &mut ObjectState) -> Result<()> {
    object_with(buf, out, true)
}

fn object_with(buf: &[u8], out: &mut ObjectState, lean: bool) -> Result<()> {
    // The list of objects keeps its room from message to message.
    let mut objects = std::mem::take(&mut out.objects);
    *out = ObjectState {
        pose: zero_pose(),
        pose_in_hand: zero_pose(),
        ..ObjectState::default()
    };
    let mut n = 0;
    let result = fields(&mut Reader::new(buf), &mut |r, tag, wire| {
        match tag {
            2..=6 if lean => return Ok(false),
            1 => pose(r, wire, &mut out.pose)?,
            2 => vector3(r, wire, LINEAR_VELOCITY, &mut out.linear_velocity)?,
            3 => vector3(r, wire, ANGULAR_VELOCITY, &mut out.angular_velocity_b)?,
            4 => wrench(r, wire, &mut out.f_ext_b)?,
            5 => wrench(r, wire, &mut out.object_force_b)?,
            6 => wrench(r, wire, &mut out.table_force_b)?,
            7 => pose(r, wire, &mut out.pose_in_hand)?,
            8 => {
                expect(wire, VARINT)?;
                out.index = r.varint()? as u32;
            }
            9 => {
                if n == objects.len() {
                    objects.push(SceneObjectState::default());
                }
                let o = &mut objects[n];
                n += 1;
                *o = SceneObjectState {
                    pose: zero_pose(),
                    ..SceneObjectState::default()
                };
                message(r, wire, |r, tag, wire| {
                    match tag {
                        1 => pose(r, wire, &mut o.pose)?,
                        2 => vector3(r, wire, LINEAR_VELOCITY, &mut o.linear_velocity)?,
                        3 => vector3(r, wire, ANGULAR_VELOCITY, &mut o.angular_velocity_b)?,
                        _ => return Ok(false),
                    }
                    Ok(true)
                })?;
            }
            _ => return Ok(false),
        }
        Ok(true)
    });
    objects.truncate(n);
    out.objects = objects;
    result
}
