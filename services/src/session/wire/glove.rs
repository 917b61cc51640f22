//! Decoding the glove topics: `icms.GloveJointStates` ([`joint_states`]), `icms.GloveFeedback`
//! ([`feedback`]), and either read only as far as the reader's checks need ([`glove_shape`]).

use super::fields::{count_repeated, fields, message, name_into, repeated, string_into, vector3};
use super::reader::Reader;
use super::Result;
use crate::foxglove::Vector3;
use crate::session::messages::{FingerFeedback, GloveFeedback, GloveJointStates, GloveShape};
use crate::session::proto::{FORCE, JOINT_ANGLE, JOINT_TORQUE, JOINT_VELOCITY};

/// Decodes an `icms.GloveJointStates` into `out` (cleared first).
pub(crate) fn joint_states(buf: &[u8], out: &mut GloveJointStates) -> Result<()> {
    out.positions.clear();
    out.velocities.clear();
    out.efforts.clear();
    let mut n = 0;
    let result = fields(&mut Reader::new(buf), &mut |r, tag, wire| {
        match tag {
            1 => {
                let _ = name_into(r, wire, &mut out.names, &mut n)?;
            }
            2 => repeated(r, wire, JOINT_ANGLE, &mut out.positions)?,
            3 => repeated(r, wire, JOINT_VELOCITY, &mut out.velocities)?,
            4 => repeated(r, wire, JOINT_TORQUE, &mut out.efforts)?,
            _ => return Ok(false),
        }
        Ok(true)
    });
    out.names.truncate(n);
    result
}

/// Decodes an `icms.GloveFeedback` into `out` (cleared first).
pub(crate) fn feedback(buf: &[u8], out: &mut GloveFeedback) -> Result<()> {
    out.motor_positions.clear();
    out.motor_velocities.clear();
    out.feedback_torques.clear();
    let (mut n, mut fingers) = (0, 0);
    let result = fields(&mut Reader::new(buf), &mut |r, tag, wire| {
        match tag {
            1 => {
                let _ = name_into(r, wire, &mut out.names, &mut n)?;
            }
            2 => repeated(r, wire, JOINT_ANGLE, &mut out.motor_positions)?,
            3 => repeated(r, wire, JOINT_VELOCITY, &mut out.motor_velocities)?,
            4 => repeated(r, wire, JOINT_TORQUE, &mut out.feedback_torques)?,
            5 => {
                if fingers == out.fingers.len() {
                    out.fingers.push(FingerFeedback::default());
                }
                let f = &mut out.fingers[fingers];
                fingers += 1;
                f.feedback_force_world = Vector3::default();
                f.tip_force_world = Vector3::default();
                // The name stays for comparison with the next one (the same, tick after tick)
                // and is cleared if the message has none.
                let mut named = false;
                message(r, wire, |r, tag, wire| {
                    match tag {
                        1 => {
                            let _ = string_into(r, wire, &mut f.name)?;
                            named = true;
                        }
                        2 => vector3(r, wire, FORCE, &mut f.feedback_force_world)?,
                        3 => vector3(r, wire, FORCE, &mut f.tip_force_world)?,
                        _ => return Ok(false),
                    }
                    Ok(true)
                })?;
                if !named {
                    f.name.clear();
                }
            }
            _ => return Ok(false),
        }
        Ok(true)
    });
    out.names.truncate(n);
    out.fingers.truncate(fingers);
    result
}

/// Reads an `icms.GloveJointStates` (`feedback` false) or `icms.GloveFeedback` as far as its
/// checks need ([`GloveShape`]): its names and the number of elements of its arrays, no value
/// converted. Accepted or refused as [`joint_states`] and [`feedback`] do (prost's rules), with
/// the same names and lengths.
pub(crate) fn glove_shape(buf: &[u8], feedback: bool, out: &mut GloveShape) -> Result<()> {
    out.arrays = [0; 3];
    let before = (out.names.len(), out.fingers.len());
    let (mut n, mut fingers) = (0, 0);
    let mut reader = Reader::new(buf);
    // Every tick names the same DOFs, first: a message that begins with the name fields of
    // the one before, byte for byte, begins with its names (read from those very bytes, up to
    // a field's end), and they are passed over at once rather than read one by one.
    let same_lead = !out.lead.is_empty() && buf.starts_with(&out.lead);
    if same_lead {
        reader.buf = &buf[out.lead.len()..];
        n = out.lead_names;
    }
    // Otherwise, where this message's leading name fields end, and how many names they hold.
    let mut recording = !same_lead;
    let (mut lead_end, mut lead_names) = (0, 0);
    let mut unchanged = true;
    let names = &mut out.names;
    let tips = &mut out.fingers;
    let arrays = &mut out.arrays;
    let result = fields(&mut reader, &mut |r, tag, wire| {
        recording &= tag == 1;
        match tag {
            1 => {
                unchanged &= name_into(r, wire, names, &mut n)?;
                if recording {
                    lead_end = buf.len() - r.buf.len();
                    lead_names = n;
                }
            }
            2..=4 => arrays[tag as usize - 2] += count_repeated(r, wire)?,
            5 if feedback => {
                if fingers == tips.len() {
                    tips.push(String::new());
                }
                let name = &mut tips[fingers];
                fingers += 1;
                let mut named = false;
                let mut force = Vector3::default();
                message(r, wire, |r, tag, wire| {
                    match tag {
                        1 => {
                            unchanged &= string_into(r, wire, name)?;
                            named = true;
                        }
                        2 | 3 => vector3(r, wire, FORCE, &mut force)?,
                        _ => return Ok(false),
                    }
                    Ok(true)
                })?;
                if !named {
                    unchanged &= name.is_empty();
                    name.clear();
                }
            }
            _ => return Ok(false),
        }
        Ok(true)
    });
    out.names.truncate(n);
    out.fingers.truncate(fingers);
    out.unchanged = result.is_ok() && unchanged && (n, fingers) == before;
    if result.is_err() {
        // A message that did not decode leaves names that its bytes may not say.
        out.lead.clear();
    } else if !same_lead {
        out.lead.clear();
        out.lead.extend_from_slice(&buf[..lead_end]);
        out.lead_names = lead_names;
    }
    result
}
