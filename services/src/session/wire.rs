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
//! The property tests below hold it to prost: on any bytes, both accept or both refuse, and
//! what both accept converts to the same SI message.

use super::messages::{
    Contacts, FingerContact, FingerFeedback, GloveFeedback, GloveJointStates, GloveShape,
    Intensity4, ObjectState, SceneObjectState,
};
use super::proto::{
    ANGULAR_VELOCITY, FORCE, JOINT_ANGLE, JOINT_TORQUE, JOINT_VELOCITY, LINEAR_VELOCITY, MOMENT,
    PENETRATION, POSITION, UNIT,
};
use crate::foxglove::{Pose, Quaternion, Vector3};

/// Why bytes do not decode (the wording of prost's errors where there is one).
pub(crate) type DecodeError = &'static str;
type Result<T> = std::result::Result<T, DecodeError>;

/// Wire types of the protobuf encoding.
const VARINT: u8 = 0;
const I64: u8 = 1;
const LEN: u8 = 2;
const SGROUP: u8 = 3;
const EGROUP: u8 = 4;
const I32: u8 = 5;

/// Deepest nesting of groups skipped (prost's recursion limit).
const RECURSION_LIMIT: u32 = 100;

/// A cursor over a message's bytes, at `depth` messages below the one decoded (prost's
/// recursion limit counts them, and the groups skipped).
struct Reader<'a> {
    buf: &'a [u8],
    depth: u32,
}

impl<'a> Reader<'a> {
    /// A top-level message.
    fn new(buf: &'a [u8]) -> Self {
        Reader { buf, depth: 0 }
    }

    fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    /// A varint: one and two bytes (keys, lengths, most values) read inline, longer ones by
    /// [`Self::varint_long`].
    #[inline(always)]
    fn varint(&mut self) -> Result<u64> {
        match self.buf {
            [b0, rest @ ..] if *b0 < 0x80 => {
                self.buf = rest;
                Ok(u64::from(*b0))
            }
            [b0, b1, rest @ ..] if *b1 < 0x80 => {
                self.buf = rest;
                Ok(u64::from(*b0 & 0x7f) | u64::from(*b1) << 7)
            }
            _ => self.varint_long(),
        }
    }

    /// A varint of any length (up to 10 bytes, the last at most 1, as prost reads them):
    /// unrolled where ten bytes remain (no bounds check per byte), a loop near the end.
    #[inline(never)]
    fn varint_long(&mut self) -> Result<u64> {
        if let Some(b) = self.buf.first_chunk::<10>() {
            let mut value = 0u64;
            for (i, &byte) in b.iter().enumerate() {
                value |= u64::from(byte & 0x7f) << (7 * i);
                if byte < 0x80 {
                    if i == 9 && byte > 1 {
                        return Err("invalid varint");
                    }
                    self.buf = &self.buf[i + 1..];
                    return Ok(value);
                }
            }
            return Err("invalid varint");
        }
        let mut value = 0u64;
        for (i, &byte) in self.buf.iter().take(10).enumerate() {
            if i == 9 && byte > 1 {
                return Err("invalid varint");
            }
            value |= u64::from(byte & 0x7f) << (7 * i);
            if byte < 0x80 {
                self.buf = &self.buf[i + 1..];
                return Ok(value);
            }
        }
        Err("invalid varint")
    }

    /// The next field's number and wire type.
    #[inline]
    fn key(&mut self) -> Result<(u32, u8)> {
        let key = self.varint()?;
        if key > u64::from(u32::MAX) {
            return Err("invalid key value");
        }
        let wire = (key & 7) as u8;
        if wire > I32 {
            return Err("invalid wire type value");
        }
        let tag = (key >> 3) as u32;
        if tag == 0 {
            return Err("invalid tag value: 0");
        }
        Ok((tag, wire))
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        if n > self.buf.len() {
            return Err("buffer underflow");
        }
        let (head, rest) = self.buf.split_at(n);
        self.buf = rest;
        Ok(head)
    }

    fn len_delimited(&mut self) -> Result<&'a [u8]> {
        let n = self.varint()?;
        let n = usize::try_from(n).map_err(|_| "buffer underflow")?;
        self.take(n)
    }

    /// Skips a field of an unknown number.
    fn skip(&mut self, tag: u32, wire: u8) -> Result<()> {
        self.skip_at(tag, wire, self.depth)
    }

    /// [`Self::skip`] at `depth` (inside groups): as prost, refused at its recursion limit
    /// whatever the field.
    fn skip_at(&mut self, tag: u32, wire: u8, depth: u32) -> Result<()> {
        if depth >= RECURSION_LIMIT {
            return Err("recursion limit reached");
        }
        match wire {
            VARINT => self.varint().map(drop),
            I64 => self.take(8).map(drop),
            I32 => self.take(4).map(drop),
            LEN => self.len_delimited().map(drop),
            SGROUP => loop {
                let (inner, w) = self.key()?;
                if w == EGROUP {
                    if inner != tag {
                        return Err("unexpected end group tag");
                    }
                    return Ok(());
                }
                self.skip_at(inner, w, depth + 1)?;
            },
            _ => Err("unexpected end group tag"),
        }
    }

    /// The embedded message of a length-delimited field, one level down (refused at prost's
    /// recursion limit).
    fn nested(&mut self, wire: u8) -> Result<Reader<'a>> {
        expect(wire, LEN)?;
        if self.depth >= RECURSION_LIMIT {
            return Err("recursion limit reached");
        }
        Ok(Reader {
            buf: self.len_delimited()?,
            depth: self.depth + 1,
        })
    }
}

fn expect(wire: u8, want: u8) -> Result<()> {
    if wire == want {
        Ok(())
    } else {
        Err("invalid wire type")
    }
}

fn sint32(v: u64) -> i32 {
    let v = v as u32;
    ((v >> 1) as i32) ^ -((v & 1) as i32)
}

/// A `sint32` field scaled by `step`.
fn scaled(r: &mut Reader<'_>, wire: u8, step: f64) -> Result<f64> {
    expect(wire, VARINT)?;
    Ok(f64::from(sint32(r.varint()?)) * step)
}

fn boolean(r: &mut Reader<'_>, wire: u8) -> Result<bool> {
    expect(wire, VARINT)?;
    Ok(r.varint()? != 0)
}

/// A repeated `sint32` field, packed or not, appended to `out` scaled by `step`.
fn repeated(r: &mut Reader<'_>, wire: u8, step: f64, out: &mut Vec<f64>) -> Result<()> {
    if wire == LEN {
        let mut packed = Reader::new(r.len_delimited()?);
        while !packed.is_empty() {
            out.push(f64::from(sint32(packed.varint()?)) * step);
        }
        Ok(())
    } else {
        out.push(scaled(r, wire, step)?);
        Ok(())
    }
}

/// A string field into `out` (its allocation reused); `true` if it held that string already.
fn string_into(r: &mut Reader<'_>, wire: u8, out: &mut String) -> Result<bool> {
    expect(wire, LEN)?;
    let bytes = r.len_delimited()?;
    // The same name as the message before (every tick names the same DOFs and fingertips):
    // already valid UTF-8, nothing to copy.
    if same_bytes(out.as_bytes(), bytes) {
        return Ok(true);
    }
    let s = std::str::from_utf8(bytes)
        .map_err(|_| "invalid string value: data is not UTF-8 encoded")?;
    out.clear();
    out.push_str(s);
    Ok(false)
}

/// `a == b`, names of 4 to 16 bytes (most DOF and fingertip names) compared as two words
/// each, without the library call a slice comparison makes (a tenth of reading a glove
/// message went to it).
#[inline]
fn same_bytes(a: &[u8], b: &[u8]) -> bool {
    let n = a.len();
    if n != b.len() {
        return false;
    }
    if (8..=16).contains(&n) {
        let word = |s: Option<&[u8; 8]>| s.map(|w| u64::from_le_bytes(*w));
        word(a.first_chunk()) == word(b.first_chunk())
            && word(a.last_chunk()) == word(b.last_chunk())
    } else if (4..8).contains(&n) {
        let word = |s: Option<&[u8; 4]>| s.map(|w| u32::from_le_bytes(*w));
        word(a.first_chunk()) == word(b.first_chunk())
            && word(a.last_chunk()) == word(b.last_chunk())
    } else {
        a == b
    }
}

/// A repeated string field: the next of `names`, counted by `n` (entries past `n` are spare
/// allocations from earlier messages); `true` if that entry held that string already.
fn name_into(r: &mut Reader<'_>, wire: u8, names: &mut Vec<String>, n: &mut usize) -> Result<bool> {
    if *n == names.len() {
        names.push(String::new());
    }
    let same = string_into(r, wire, &mut names[*n])?;
    *n += 1;
    Ok(same)
}

/// How many values an occurrence of a repeated `sint32` field holds (packed: its varints
/// counted, each accepted or refused as [`Reader::varint`] reads it; unpacked: one), none
/// converted.
fn count_repeated(r: &mut Reader<'_>, wire: u8) -> Result<usize> {
    if wire != LEN {
        expect(wire, VARINT)?;
        r.varint()?;
        return Ok(1);
    }
    count_packed(r.len_delimited()?)
}

/// The number of varints in a packed repeated field's bytes, each accepted or refused as
/// [`Reader::varint`] reads it.
fn count_packed(packed: &[u8]) -> Result<usize> {
    // Each varint ends at its first byte below 0x80; at most ten bytes, the tenth at most 1.
    let (mut n, mut run) = (0usize, 0usize);
    for &byte in packed {
        if byte < 0x80 {
            if run == 9 && byte > 1 {
                return Err("invalid varint");
            }
            n += 1;
            run = 0;
        } else {
            run += 1;
            if run == 10 {
                return Err("invalid varint");
            }
        }
    }
    if run != 0 {
        return Err("invalid varint");
    }
    Ok(n)
}

/// The fields of an embedded message, each handed to `field`.
fn message(
    r: &mut Reader<'_>,
    wire: u8,
    mut field: impl FnMut(&mut Reader<'_>, u32, u8) -> Result<bool>,
) -> Result<()> {
    let mut inner = r.nested(wire)?;
    fields(&mut inner, &mut field)
}

/// Every field of `r`: `field` decodes the ones it knows (returning `true`), the others are
/// skipped.
fn fields(
    r: &mut Reader<'_>,
    field: &mut impl FnMut(&mut Reader<'_>, u32, u8) -> Result<bool>,
) -> Result<()> {
    while !r.is_empty() {
        let (tag, wire) = r.key()?;
        if !field(r, tag, wire)? {
            r.skip(tag, wire)?;
        }
    }
    Ok(())
}

#[inline]
fn vector3(r: &mut Reader<'_>, wire: u8, step: f64, v: &mut Vector3) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => v.x = scaled(r, wire, step)?,
            2 => v.y = scaled(r, wire, step)?,
            3 => v.z = scaled(r, wire, step)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

fn quaternion(r: &mut Reader<'_>, wire: u8, q: &mut Quaternion) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => q.x = scaled(r, wire, UNIT)?,
            2 => q.y = scaled(r, wire, UNIT)?,
            3 => q.z = scaled(r, wire, UNIT)?,
            4 => q.w = scaled(r, wire, UNIT)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

fn pose(r: &mut Reader<'_>, wire: u8, p: &mut Pose) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => vector3(r, wire, POSITION, &mut p.position)?,
            2 => quaternion(r, wire, &mut p.orientation)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

fn wrench(r: &mut Reader<'_>, wire: u8, w: &mut [f64; 6]) -> Result<()> {
    let mut f = Vector3::new(w[0], w[1], w[2]);
    let mut t = Vector3::new(w[3], w[4], w[5]);
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => vector3(r, wire, FORCE, &mut f)?,
            2 => vector3(r, wire, MOMENT, &mut t)?,
            _ => return Ok(false),
        }
        Ok(true)
    })?;
    *w = [f.x, f.y, f.z, t.x, t.y, t.z];
    Ok(())
}

fn intensity(r: &mut Reader<'_>, wire: u8, c: &mut Intensity4) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => c.x = scaled(r, wire, FORCE)?,
            2 => c.y = scaled(r, wire, FORCE)?,
            3 => c.z = scaled(r, wire, FORCE)?,
            4 => c.torsion = scaled(r, wire, MOMENT)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

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
                            f.part = super::proto::part_of_number(r.varint()? as u32);
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

/// What a field's bytes must be, by its type in a message prost decodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FieldKind {
    /// Integers, `bool`, enums: a varint (packed or not if repeated).
    Varint,
    /// `double`, `fixed64`, `sfixed64`: eight bytes (packed or not if repeated).
    Fixed64,
    /// `float`, `fixed32`, `sfixed32`: four bytes (packed or not if repeated).
    Fixed32,
    /// `string`: length-delimited UTF-8.
    Str,
    /// `bytes`: length-delimited.
    Bytes,
    /// An embedded message: the index of its type in [`MessageCheck::messages`].
    Message(usize),
}

/// One field of a message type.
#[derive(Debug, Clone, Copy)]
struct FieldSpec {
    number: u32,
    kind: FieldKind,
    repeated: bool,
}

/// Whether bytes decode as a protobuf message type, as prost decodes them into the Rust type
/// generated from its `.proto` (proto3: unknown fields skipped, groups skipped to prost's
/// recursion limit, packed or unpacked repeated scalars, strings UTF-8): the same bytes
/// accepted and refused, nothing built. Made from the type's file descriptor set; for the
/// Foxglove topics, whose messages prost decoded only to be checked (allocating every
/// string and vector: a tenth of an ingest's CPU).
#[derive(Debug)]
pub(crate) struct MessageCheck {
    /// Per message type, its fields by ascending number.
    messages: Vec<Vec<FieldSpec>>,
    root: usize,
}

impl MessageCheck {
    /// The check of message type `root` (its full name, `foxglove.SceneUpdate`) described in
    /// `descriptor_set` (a serialized `FileDescriptorSet` holding it and its dependencies);
    /// `None` if it does not describe it (or uses groups).
    pub(crate) fn new(descriptor_set: &[u8], root: &str) -> Option<MessageCheck> {
        use prost::Message;
        use prost_types::field_descriptor_proto::{Label, Type};
        use prost_types::DescriptorProto;
        fn collect<'d>(
            prefix: &str,
            types: &'d [DescriptorProto],
            out: &mut Vec<(String, &'d DescriptorProto)>,
        ) {
            for t in types {
                let name = format!("{prefix}.{}", t.name());
                collect(&name, &t.nested_type, out);
                out.push((name, t));
            }
        }
        let set = prost_types::FileDescriptorSet::decode(descriptor_set).ok()?;
        let mut types = Vec::new();
        for file in &set.file {
            let prefix = match file.package() {
                "" => String::new(),
                p => format!(".{p}"),
            };
            collect(&prefix, &file.message_type, &mut types);
        }
        let index = |name: &str| types.iter().position(|(n, _)| n == name);
        let mut messages = Vec::with_capacity(types.len());
        for (_, t) in &types {
            let mut fields = Vec::with_capacity(t.field.len());
            for f in &t.field {
                let kind = match Type::try_from(f.r#type?).ok()? {
                    Type::Double | Type::Fixed64 | Type::Sfixed64 => FieldKind::Fixed64,
                    Type::Float | Type::Fixed32 | Type::Sfixed32 => FieldKind::Fixed32,
                    Type::Int64
                    | Type::Uint64
                    | Type::Int32
                    | Type::Uint32
                    | Type::Sint32
                    | Type::Sint64
                    | Type::Bool
                    | Type::Enum => FieldKind::Varint,
                    Type::String => FieldKind::Str,
                    Type::Bytes => FieldKind::Bytes,
                    Type::Message => FieldKind::Message(index(f.type_name())?),
                    Type::Group => return None,
                };
                fields.push(FieldSpec {
                    number: u32::try_from(f.number()).ok()?,
                    kind,
                    repeated: f.label() == Label::Repeated,
                });
            }
            fields.sort_by_key(|f| f.number);
            messages.push(fields);
        }
        let root = index(&format!(".{root}"))?;
        Some(MessageCheck { messages, root })
    }

    /// `Ok` if `buf` decodes as the message type, as prost would decode it.
    pub(crate) fn check(&self, buf: &[u8]) -> Result<()> {
        self.message(&mut Reader::new(buf), self.root)
    }

    fn message(&self, r: &mut Reader<'_>, message: usize) -> Result<()> {
        let fields = &self.messages[message];
        while !r.is_empty() {
            let (tag, wire) = r.key()?;
            match fields.iter().find(|f| f.number == tag) {
                Some(f) => self.field(r, f, wire)?,
                None => r.skip(tag, wire)?,
            }
        }
        Ok(())
    }

    fn field(&self, r: &mut Reader<'_>, f: &FieldSpec, wire: u8) -> Result<()> {
        // Repeated scalars come packed (length-delimited) or one by one.
        let packed = f.repeated && wire == LEN;
        let fixed = |r: &mut Reader<'_>, size: usize, one: u8| {
            if packed {
                // Values cut by the field's end: prost reads past it and fails.
                if r.len_delimited()?.len() % size != 0 {
                    return Err("delimited length exceeded");
                }
                Ok(())
            } else {
                expect(wire, one)?;
                r.take(size).map(drop)
            }
        };
        match f.kind {
            FieldKind::Varint if packed => count_packed(r.len_delimited()?).map(drop),
            FieldKind::Varint => {
                expect(wire, VARINT)?;
                r.varint().map(drop)
            }
            FieldKind::Fixed64 => fixed(r, 8, I64),
            FieldKind::Fixed32 => fixed(r, 4, I32),
            FieldKind::Str => {
                expect(wire, LEN)?;
                std::str::from_utf8(r.len_delimited()?)
                    .map(drop)
                    .map_err(|_| "invalid string value: data is not UTF-8 encoded")
            }
            FieldKind::Bytes => {
                expect(wire, LEN)?;
                r.len_delimited().map(drop)
            }
            FieldKind::Message(m) => {
                let mut inner = r.nested(wire)?;
                self.message(&mut inner, m)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::proto::{self, *};
    use super::*;
    use proptest::prelude::*;
    use prost::Message;

    fn v3i() -> impl Strategy<Value = Option<Vector3i>> {
        proptest::option::of(
            (any::<i32>(), any::<i32>(), any::<i32>()).prop_map(|(x, y, z)| Vector3i { x, y, z }),
        )
    }

    fn intensityi() -> impl Strategy<Value = Option<Intensityi>> {
        proptest::option::of(
            (any::<i32>(), any::<i32>(), any::<i32>(), any::<i32>()).prop_map(
                |(x_e3, y_e3, z_e3, torsion_e6)| Intensityi {
                    x_e3,
                    y_e3,
                    z_e3,
                    torsion_e6,
                },
            ),
        )
    }

    fn posei() -> impl Strategy<Value = Option<Posei>> {
        proptest::option::of(
            (
                v3i(),
                proptest::option::of(
                    (any::<i32>(), any::<i32>(), any::<i32>(), any::<i32>()).prop_map(
                        |(x_e6, y_e6, z_e6, w_e6)| Quaternioni {
                            x_e6,
                            y_e6,
                            z_e6,
                            w_e6,
                        },
                    ),
                ),
            )
                .prop_map(|(position_e6, orientation)| Posei {
                    position_e6,
                    orientation,
                }),
        )
    }

    fn wrenchi() -> impl Strategy<Value = Option<Wrenchi>> {
        proptest::option::of((v3i(), v3i()).prop_map(|(force_e3, torque_e6)| Wrenchi {
            force_e3,
            torque_e6,
        }))
    }

    fn names() -> impl Strategy<Value = Vec<String>> {
        proptest::collection::vec("[a-z_0-9é]{0,8}", 0..6)
    }

    fn ints() -> impl Strategy<Value = Vec<i32>> {
        proptest::collection::vec(any::<i32>(), 0..6)
    }

    fn contacts_proto() -> impl Strategy<Value = ContactsProto> {
        let finger = (
            "[a-z]{0,6}",
            any::<[bool; 4]>(),
            v3i(),
            v3i(),
            any::<i32>(),
            intensityi(),
            intensityi(),
            intensityi(),
        )
            .prop_map(|(name, b, point_b_e6, normal_b_e6, pen, i, t, f)| {
                FingerContactProto {
                    touching: b[0],
                    in_contact: b[1],
                    point_b_e6,
                    normal_b_e6,
                    penetration_e9: pen,
                    intensity: i,
                    transmitted: t,
                    feedback: f,
                    in_cone: b[2],
                    slip: b[3],
                    object: u32::from(b[0]) * u32::from(pen as u8 % 9),
                    // Fingertips, palms, phalanges and a part this version does not know (3).
                    part: i32::from((pen >> 8) as u8 % 4),
                    link: if ((pen >> 8) as u8).is_multiple_of(4) {
                        String::new()
                    } else {
                        format!("{name}_link")
                    },
                    name,
                }
            });
        (any::<u32>(), proptest::collection::vec(finger, 0..5)).prop_map(|(n_contacts, fingers)| {
            ContactsProto {
                n_contacts,
                fingers,
            }
        })
    }

    fn feedback_proto() -> impl Strategy<Value = GloveFeedbackProto> {
        let finger = ("[a-z]{0,6}", v3i(), v3i()).prop_map(|(name, a, b)| FingerFeedbackProto {
            name,
            feedback_force_world_e3: a,
            tip_force_world_e3: b,
        });
        (
            names(),
            ints(),
            ints(),
            ints(),
            proptest::collection::vec(finger, 0..5),
        )
            .prop_map(|(names, a, b, c, fingers)| GloveFeedbackProto {
                names,
                motor_positions_e5: a,
                motor_velocities_e2: b,
                feedback_torques_e5: c,
                fingers,
            })
    }

    fn object_proto() -> impl Strategy<Value = ObjectStateProto> {
        (
            posei(),
            v3i(),
            v3i(),
            wrenchi(),
            wrenchi(),
            wrenchi(),
            posei(),
            any::<u32>(),
            proptest::collection::vec((posei(), v3i(), v3i()), 0..4),
        )
            .prop_map(
                |(pose, lv, av, f, o, t, ph, index, objects)| ObjectStateProto {
                    pose,
                    linear_velocity_e6: lv,
                    angular_velocity_b_e6: av,
                    f_ext_b: f,
                    object_force_b: o,
                    table_force_b: t,
                    pose_in_hand: ph,
                    index,
                    objects: objects
                        .into_iter()
                        .map(|(pose, lv, av)| SceneObjectStateProto {
                            pose,
                            linear_velocity_e6: lv,
                            angular_velocity_b_e6: av,
                        })
                        .collect(),
                },
            )
    }

    /// Both decoders on `bytes`: they agree on whether it decodes and, if it does, on the SI
    /// message; `out` is reused from earlier calls on purpose.
    fn agree<P: Message + Default, T: PartialEq + std::fmt::Debug>(
        bytes: &[u8],
        ours: fn(&[u8], &mut T) -> Result<()>,
        out: &mut T,
        convert: fn(P) -> T,
    ) -> std::result::Result<(), TestCaseError> {
        let theirs = P::decode(bytes);
        let mine = ours(bytes, out);
        match (theirs, mine) {
            (Ok(p), Ok(())) => prop_assert_eq!(&convert(p), &*out),
            (Err(_), Err(_)) => {}
            (t, m) => prop_assert!(
                false,
                "prost {:?}, ours {:?} on {:?}",
                t.map(drop),
                m,
                bytes
            ),
        }
        Ok(())
    }

    /// [`agree`] on `bytes`, on them cut short at `cut`, and with `junk` appended, reusing one
    /// output message.
    fn agree_whole_cut_and_extended<
        P: Message + Default,
        T: Default + PartialEq + std::fmt::Debug,
    >(
        bytes: &[u8],
        cut: prop::sample::Index,
        junk: &[u8],
        ours: fn(&[u8], &mut T) -> Result<()>,
        convert: fn(P) -> T,
    ) -> std::result::Result<(), TestCaseError> {
        let mut out = T::default();
        agree(bytes, ours, &mut out, convert)?;
        // Cut short, or with bytes appended: both refuse or both read the same.
        agree(
            &bytes[..cut.index(bytes.len() + 1)],
            ours,
            &mut out,
            convert,
        )?;
        let mut longer = bytes.to_vec();
        longer.extend_from_slice(junk);
        agree(&longer, ours, &mut out, convert)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn contacts_decode_as_prost_decodes_them(m in contacts_proto(), cut in any::<prop::sample::Index>(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
            agree_whole_cut_and_extended(&m.encode_to_vec(), cut, &junk, contacts, proto::contacts_from_proto)?;
        }

        #[test]
        fn feedback_decodes_as_prost_decodes_it(m in feedback_proto(), cut in any::<prop::sample::Index>(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
            agree_whole_cut_and_extended(&m.encode_to_vec(), cut, &junk, feedback, proto::feedback_from_proto)?;
        }

        #[test]
        fn joint_states_decode_as_prost_decodes_them(names in names(), a in ints(), b in ints(), c in ints(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
            let m = GloveJointStatesProto { names, positions_e5: a, velocities_e2: b, efforts_e5: c };
            let mut out = GloveJointStates::default();
            let mut bytes = m.encode_to_vec();
            agree(&bytes, joint_states, &mut out, proto::joint_states_from_proto)?;
            bytes.extend_from_slice(&junk);
            agree(&bytes, joint_states, &mut out, proto::joint_states_from_proto)?;
        }

        #[test]
        fn object_states_decode_as_prost_decodes_them(m in object_proto(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
            let mut out = ObjectState::default();
            let mut bytes = m.encode_to_vec();
            agree(&bytes, object, &mut out, proto::object_from_proto)?;
            bytes.extend_from_slice(&junk);
            agree(&bytes, object, &mut out, proto::object_from_proto)?;
        }

        #[test]
        fn any_bytes_decode_as_prost_decodes_them(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
            agree(&bytes, contacts, &mut Contacts::default(), proto::contacts_from_proto)?;
            agree(&bytes, feedback, &mut GloveFeedback::default(), proto::feedback_from_proto)?;
            agree(&bytes, joint_states, &mut GloveJointStates::default(), proto::joint_states_from_proto)?;
            agree(&bytes, object, &mut ObjectState::default(), proto::object_from_proto)?;
            let mut shape = GloveShape::default();
            agree_shape(&bytes, false, &mut shape)?;
            agree_shape(&bytes, true, &mut shape)?;
        }

        #[test]
        fn joint_states_shapes_read_as_prost_decodes_them(names in names(), a in ints(), b in ints(), c in ints(), cut in any::<prop::sample::Index>(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
            let m = GloveJointStatesProto { names, positions_e5: a, velocities_e2: b, efforts_e5: c };
            agree_shape_whole_cut_and_extended(&m.encode_to_vec(), false, cut, &junk)?;
        }

        #[test]
        fn feedback_shapes_read_as_prost_decodes_them(m in feedback_proto(), cut in any::<prop::sample::Index>(), junk in proptest::collection::vec(any::<u8>(), 0..12)) {
            agree_shape_whole_cut_and_extended(&m.encode_to_vec(), true, cut, &junk)?;
        }

        #[test]
        fn lean_decodes_are_full_ones_without_the_fields_segmentation_skips(c in contacts_proto(), o in object_proto()) {
            let mut full = Contacts::default();
            contacts(&c.encode_to_vec(), &mut full).unwrap();
            full.n_contacts = 0;
            for f in &mut full.fingers {
                f.penetration = 0.0;
                f.transmitted = Intensity4::default();
                f.feedback = Intensity4::default();
                f.in_cone = false;
            }
            let mut lean = Contacts::default();
            contacts_lean(&c.encode_to_vec(), &mut lean).unwrap();
            prop_assert_eq!(&lean, &full);
            let mut full = ObjectState::default();
            object(&o.encode_to_vec(), &mut full).unwrap();
            let mut lean = ObjectState::default();
            object_lean(&o.encode_to_vec(), &mut lean).unwrap();
            // The scene's objects are read too (a skill may grasp any of them).
            let expected = ObjectState { pose: full.pose, pose_in_hand: full.pose_in_hand, index: full.index, objects: full.objects, ..ObjectState::default() };
            prop_assert_eq!(&lean, &expected);
        }

        #[test]
        fn packed_arrays_count_as_prost_reads_them(payload in proptest::collection::vec(prop_oneof![0x80u8..=0xff, 0u8..=0x7f, Just(1u8), Just(0u8)], 0..40), field in 2u8..=4) {
            // One packed field of long, short, cut or overlong varints (tenth bytes 0, 1 or
            // more): counted where prost reads it, refused where prost refuses it.
            let mut bytes = vec![field << 3 | 2, payload.len() as u8];
            bytes.extend_from_slice(&payload);
            let mut shape = GloveShape::default();
            agree_shape(&bytes, false, &mut shape)?;
            agree_shape(&bytes, true, &mut shape)?;
        }

        #[test]
        fn shapes_read_one_after_another_read_as_prost_decodes_each(a in feedback_proto(), b in feedback_proto(), cut in any::<prop::sample::Index>(), order in proptest::collection::vec(0u8..4, 1..8)) {
            // Messages that begin with the names of the one before, and ones that do not, in
            // any order, into one shape.
            let (a, b) = (a.encode_to_vec(), b.encode_to_vec());
            let a_cut = a[..cut.index(a.len() + 1)].to_vec();
            let mut a_longer = a.clone();
            a_longer.extend_from_slice(&b);
            let mut out = GloveShape::default();
            for i in order {
                let bytes = [&a, &b, &a_cut, &a_longer][usize::from(i)];
                agree_shape(bytes, true, &mut out)?;
                agree_shape(bytes, false, &mut out)?;
            }
        }

        #[test]
        fn a_shape_is_unchanged_only_when_its_names_are(a in feedback_proto(), b in feedback_proto(), again in any::<bool>()) {
            // Read `a`, then `b` (or `a` again): `unchanged` says whether the names and
            // fingertips are those of the message before, never wrongly yes.
            let second = if again { a.clone() } else { b };
            let mut shape = GloveShape::default();
            let first_ok = glove_shape(&a.encode_to_vec(), true, &mut shape).is_ok();
            prop_assert!(first_ok);
            let (names, tips) = (shape.names.clone(), shape.fingers.clone());
            glove_shape(&second.encode_to_vec(), true, &mut shape).unwrap();
            let same = shape.names == names && shape.fingers == tips;
            prop_assert!(!shape.unchanged || same, "unchanged, but {:?} {:?} -> {:?} {:?}", names, tips, shape.names, shape.fingers);
            prop_assert!(!again || shape.unchanged);
        }

        #[test]
        fn same_bytes_is_slice_equality(a in proptest::collection::vec(any::<u8>(), 0..24), flip in any::<prop::sample::Index>(), bit in 0u8..8, other in proptest::collection::vec(any::<u8>(), 0..24)) {
            prop_assert_eq!(same_bytes(&a, &other), a == other);
            prop_assert!(same_bytes(&a, &a.clone()));
            if !a.is_empty() {
                let mut b = a.clone();
                b[flip.index(a.len())] ^= 1 << bit;
                prop_assert!(!same_bytes(&a, &b));
            }
        }
    }

    /// What prost decodes of `bytes` as `icms.GloveFeedback` (`feedback`) or
    /// `icms.GloveJointStates`, as a shape: names, array lengths, fingertip names.
    fn prost_shape(bytes: &[u8], feedback: bool) -> Option<(Vec<String>, [usize; 3], Vec<String>)> {
        if feedback {
            let m = GloveFeedbackProto::decode(bytes).ok()?;
            let arrays = [
                m.motor_positions_e5.len(),
                m.motor_velocities_e2.len(),
                m.feedback_torques_e5.len(),
            ];
            Some((
                m.names,
                arrays,
                m.fingers.into_iter().map(|f| f.name).collect(),
            ))
        } else {
            let m = GloveJointStatesProto::decode(bytes).ok()?;
            let arrays = [
                m.positions_e5.len(),
                m.velocities_e2.len(),
                m.efforts_e5.len(),
            ];
            Some((m.names, arrays, Vec::new()))
        }
    }

    /// [`glove_shape`] and prost agree on whether `bytes` decode and on the shape; `out` is
    /// reused from earlier calls on purpose.
    fn agree_shape(
        bytes: &[u8],
        feedback: bool,
        out: &mut GloveShape,
    ) -> std::result::Result<(), TestCaseError> {
        let theirs = prost_shape(bytes, feedback);
        let mine = glove_shape(bytes, feedback, out);
        match (theirs, mine) {
            (Some((names, arrays, fingers)), Ok(())) => {
                prop_assert_eq!(&names, &out.names);
                prop_assert_eq!(arrays, out.arrays);
                prop_assert_eq!(&fingers, &out.fingers);
            }
            (None, Err(_)) => prop_assert!(!out.unchanged),
            (t, m) => prop_assert!(false, "prost {:?}, ours {:?} on {:?}", t, m, bytes),
        }
        Ok(())
    }

    /// [`agree_shape`] on `bytes`, cut short at `cut`, and with `junk` appended.
    fn agree_shape_whole_cut_and_extended(
        bytes: &[u8],
        feedback: bool,
        cut: prop::sample::Index,
        junk: &[u8],
    ) -> std::result::Result<(), TestCaseError> {
        let mut out = GloveShape::default();
        agree_shape(bytes, feedback, &mut out)?;
        agree_shape(&bytes[..cut.index(bytes.len() + 1)], feedback, &mut out)?;
        let mut longer = bytes.to_vec();
        longer.extend_from_slice(junk);
        agree_shape(&longer, feedback, &mut out)
    }

    #[test]
    fn a_message_field_given_twice_is_merged_and_unpacked_repeats_are_read() {
        // pose.position.x = 1 step, then pose again with only position.y: proto merges them.
        let first = ObjectStateProto {
            pose: Some(Posei {
                position_e6: Some(Vector3i { x: 1, y: 0, z: 0 }),
                orientation: None,
            }),
            ..Default::default()
        };
        let second = ObjectStateProto {
            pose: Some(Posei {
                position_e6: Some(Vector3i { x: 0, y: 2, z: 0 }),
                orientation: None,
            }),
            ..Default::default()
        };
        let mut bytes = first.encode_to_vec();
        bytes.extend(second.encode_to_vec());
        let mut out = ObjectState::default();
        object(&bytes, &mut out).unwrap();
        assert_eq!(
            out,
            proto::object_from_proto(ObjectStateProto::decode(&bytes[..]).unwrap())
        );
        assert!(
            (out.pose.position.x - 1e-6).abs() < 1e-12
                && (out.pose.position.y - 2e-6).abs() < 1e-12
        );
        // positions_e5 = [3, -1] unpacked: key (2 << 3 | 0), zigzag values 6 and 1.
        let mut js = GloveJointStates::default();
        joint_states(&[0x10, 6, 0x10, 1], &mut js).unwrap();
        assert_eq!(js.positions.len(), 2);
        assert!((js.positions[0] - 3e-5).abs() < 1e-12 && (js.positions[1] + 1e-5).abs() < 1e-12);
    }

    fn varint_bytes(mut v: u64, out: &mut Vec<u8>) {
        while v >= 0x80 {
            out.push(v as u8 | 0x80);
            v >>= 7;
        }
        out.push(v as u8);
    }

    /// An unknown field 15 as `depth` groups nested in each other around an unknown varint
    /// field 14, optionally inside field `inside` as an embedded message.
    fn nested_groups(depth: usize, inside: Option<u8>) -> Vec<u8> {
        let mut groups = vec![15 << 3 | 3; depth];
        groups.extend_from_slice(&[14 << 3, 1]);
        groups.extend(std::iter::repeat_n(15 << 3 | 4, depth));
        match inside {
            None => groups,
            Some(field) => {
                let mut bytes = vec![field << 3 | 2];
                varint_bytes(groups.len() as u64, &mut bytes);
                bytes.extend_from_slice(&groups);
                bytes
            }
        }
    }

    #[test]
    fn groups_nested_to_prosts_recursion_limit_are_refused_where_prost_refuses_them() {
        // 99 groups deep (at the top, or in an embedded message) read; one deeper refused,
        // whatever the field inside.
        for depth in [1, 97, 98, 99, 100, 101] {
            for inside in [None, Some(2)] {
                let bytes = nested_groups(depth, inside);
                let theirs = ContactsProto::decode(&bytes[..]).is_ok();
                let ours = contacts(&bytes, &mut Contacts::default()).is_ok();
                assert_eq!(ours, theirs, "contacts, {depth} groups in {inside:?}");
                let theirs = ObjectStateProto::decode(&bytes[..]).is_ok();
                let ours = object(&bytes, &mut ObjectState::default()).is_ok();
                assert_eq!(ours, theirs, "object, {depth} groups in {inside:?}");
                let theirs = GloveFeedbackProto::decode(&bytes[..]).is_ok();
                let ours = glove_shape(&bytes, true, &mut GloveShape::default()).is_ok();
                assert_eq!(ours, theirs, "feedback shape, {depth} groups in {inside:?}");
                let check = foxglove_checks();
                let theirs = foxglove::messages::FrameTransforms::decode(&bytes[..]).is_ok();
                assert_eq!(
                    check[0].check(&bytes).is_ok(),
                    theirs,
                    "/tf, {depth} in {inside:?}"
                );
            }
            let deep = depth == 100 || depth == 101;
            assert_eq!(
                ContactsProto::decode(&nested_groups(depth, None)[..]).is_ok(),
                !deep
            );
        }
    }

    /// The checks of the three Foxglove types, as the reader makes them.
    fn foxglove_checks() -> &'static [MessageCheck; 3] {
        use foxglove::messages as fg;
        use foxglove::Encode;
        static CHECKS: std::sync::OnceLock<[MessageCheck; 3]> = std::sync::OnceLock::new();
        CHECKS.get_or_init(|| {
            let make = |s: Option<foxglove::Schema>| {
                let s = s.unwrap();
                MessageCheck::new(&s.data, &s.name).unwrap()
            };
            [
                make(fg::FrameTransforms::get_schema()),
                make(fg::SceneUpdate::get_schema()),
                make(fg::JointStates::get_schema()),
            ]
        })
    }

    /// Real Foxglove messages of a short simulated session: `/tf`, `/scene` and `/hand`
    /// (scene updates), `/joint_states`, with which of [`foxglove_checks`] reads each.
    fn foxglove_samples() -> &'static Vec<(usize, Vec<u8>)> {
        static SAMPLES: std::sync::OnceLock<Vec<(usize, Vec<u8>)>> = std::sync::OnceLock::new();
        SAMPLES.get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("s.mcap");
            let scenario =
                dfs_core::scenario::Scenario::builtin("cylinder-power-grasp", 1).unwrap();
            crate::session::record_simulation(&scenario, Some(3.0), &path, |_, _| {}).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            let mut samples = Vec::new();
            for m in mcap::MessageStream::new(&bytes).unwrap() {
                let m = m.unwrap();
                let which = match m.channel.topic.as_str() {
                    "/tf" => 0,
                    "/scene" | "/hand" => 1,
                    "/joint_states" => 2,
                    _ => continue,
                };
                // A few of each (the scene's change as the grasp goes).
                if samples.iter().filter(|(w, _)| *w == which).count() < 40 || m.sequence % 97 == 0
                {
                    samples.push((which, m.data.to_vec()));
                }
            }
            assert!((0..3).all(|w| samples.iter().any(|(s, _)| *s == w)));
            samples
        })
    }

    /// prost's verdict on `bytes` as Foxglove type `which`.
    fn prost_accepts(which: usize, bytes: &[u8]) -> bool {
        use foxglove::messages as fg;
        match which {
            0 => fg::FrameTransforms::decode(bytes).is_ok(),
            1 => fg::SceneUpdate::decode(bytes).is_ok(),
            _ => fg::JointStates::decode(bytes).is_ok(),
        }
    }

    #[test]
    fn real_foxglove_messages_pass_their_check_and_fail_the_others_where_prost_does() {
        let checks = foxglove_checks();
        for (which, bytes) in foxglove_samples() {
            assert!(checks[*which].check(bytes).is_ok());
            for other in 0..3 {
                assert_eq!(
                    checks[other].check(bytes).is_ok(),
                    prost_accepts(other, bytes),
                    "type {other} on a message of type {which}"
                );
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]

        #[test]
        fn foxglove_checks_accept_and_refuse_what_prost_does(
            sample in any::<prop::sample::Index>(),
            edits in proptest::collection::vec((0u8..5, any::<prop::sample::Index>(), any::<u8>()), 1..4),
        ) {
            // A real message damaged: bits flipped, bytes set, inserted or removed, cut short.
            let samples = foxglove_samples();
            let (which, original) = &samples[sample.index(samples.len())];
            let mut bytes = original.clone();
            for (kind, at, byte) in edits {
                let i = at.index(bytes.len() + 1);
                match kind {
                    0 if i < bytes.len() => bytes[i] ^= 1 << (byte % 8),
                    1 if i < bytes.len() => bytes[i] = byte,
                    2 => bytes.insert(i, byte),
                    3 if i < bytes.len() => { bytes.remove(i); }
                    _ => bytes.truncate(i),
                }
            }
            let checks = foxglove_checks();
            for t in [*which, (*which + 1) % 3] {
                prop_assert_eq!(checks[t].check(&bytes).is_ok(), prost_accepts(t, &bytes), "type {} on {:?}", t, bytes);
            }
        }

        #[test]
        fn foxglove_checks_of_any_bytes_agree_with_prost(bytes in proptest::collection::vec(any::<u8>(), 0..96)) {
            let checks = foxglove_checks();
            for t in 0..3 {
                prop_assert_eq!(checks[t].check(&bytes).is_ok(), prost_accepts(t, &bytes), "type {} on {:?}", t, bytes);
            }
        }
    }
}
