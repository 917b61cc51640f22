//! Decoding `icms.Contacts` ([`contacts`]), whole or only the fields segmentation reads
//! ([`contacts_lean`]).

use super::fields::{boolean, fields, intensity, message, scaled, string_into, vector3};
use super::reader::{expect, Reader, VARINT};
use super::Result;
use crate::session::messages::{Contacts, FingerContact};
use crate::session::proto::{PENETRATION, POSITION, UNIT};

/// Decodes an `icms.Contacts` into `out` (cleared first).
pub(crate) fn contacts(buf: &[u8], out: &mut Contacts) -> Result<()> {
    contacts_with(buf, out, false)
}

/// [`contacts`] of bytes that decoded before, only the fields segmentation reads: each
/// contact's name, part, link, `touching`, `in_contact`, `slip`, point, normal and intensity;
/// the others (`n_contacts`, `penetration`, the transmitted and feedback intensities,
/// `in_cone`) are skipped as unknown fields are, and stay zero.
pub(crate) fn contacts_lean(buf: &[u8], out: &mut Contacts) -> Result<()> {
    contacts_with(buf, out, true)
}

fn contacts_with(buf: &[u8], out: &mut Contacts, lean: bool) -> Result<()> {
    out.n_contacts = 0;
    let mut fingers = 0;
    let result = fields(&mut Reader::new(buf), &mut |r, tag, wire| {
        match tag {
            1 if lean => return Ok(false),
            1 => {
                expect(wire, VARINT)?;
                out.n_contacts = r.varint()? as u32;
            }
            2 => {
                if fingers == out.fingers.len() {
                    out.fingers.push(FingerContact::default());
                }
                let f = &mut out.fingers[fingers];
                fingers += 1;
                let name = std::mem::take(&mut f.name);
                let link = std::mem::take(&mut f.link);
                *f = FingerContact::default();
                f.name = name;
                f.link = link;
                let (mut named, mut linked) = (false, false);
                message(r, wire, |r, tag, wire| {
                    match tag {
                        1 => {
                            let _ = string_into(r, wire, &mut f.name)?;
                            named = true;
                        }
                        6 | 8 | 9 | 10 if lean => return Ok(false),
                        2 => f.touching = boolean(r, wire)?,
                        3 => f.in_contact = boolean(r, wire)?,
                        4 => vector3(r, wire, POSITION, &mut f.point_b)?,
                        5 => vector3(r, wire, UNIT, &mut f.normal_b)?,
                        6 => f.penetration = scaled(r, wire, PENETRATION)?,
                        7 => intensity(r, wire, &mut f.intensity)?,
                        8 => intensity(r, wire, &mut f.transmitted)?,
                        9 => intensity(r, wire, &mut f.feedback)?,
                        10 => f.in_cone = boolean(r, wire)?,
                        11 => f.slip = boolean(r, wire)?,
                        12 => {
                            expect(wire, VARINT)?;
                            f.object = r.varint()? as u32;
                        }
                        13 => {
                            expect(wire, VARINT)?;
                            f.part = crate::session::proto::part_of_number(r.varint()? as u32);
                        }
                        14 => {
                            let _ = string_into(r, wire, &mut f.link)?;
                            linked = true;
                        }
                        _ => return Ok(false),
                    }
                    Ok(true)
                })?;
                if !linked {
                    f.link.clear();
                }
                if !named {
                    f.name.clear();
                }
            }
            _ => return Ok(false),
        }
        Ok(true)
    });
    out.fingers.truncate(fingers);
    result
}
