//! The field readers the decoders share: scalars scaled by their step, booleans, repeated
//! values (read or only counted), strings and names into reused allocations, embedded messages
//! and the geometry types (vector, quaternion, pose, wrench, intensity).

use super::reader::{expect, Reader, LEN, VARINT};
use super::Result;
use crate::foxglove::{Pose, Quaternion, Vector3};
use crate::session::messages::Intensity4;
use crate::session::proto::{FORCE, MOMENT, POSITION, UNIT};

fn sint32(v: u64) -> i32 {
    let v = v as u32;
    ((v >> 1) as i32) ^ -((v & 1) as i32)
}

/// A `sint32` field scaled by `step`.
pub(super) fn scaled(r: &mut Reader<'_>, wire: u8, step: f64) -> Result<f64> {
    expect(wire, VARINT)?;
    Ok(f64::from(sint32(r.varint()?)) * step)
}

pub(super) fn boolean(r: &mut Reader<'_>, wire: u8) -> Result<bool> {
    expect(wire, VARINT)?;
    Ok(r.varint()? != 0)
}

/// A repeated `sint32` field, packed or not, appended to `out` scaled by `step`.
pub(super) fn repeated(r: &mut Reader<'_>, wire: u8, step: f64, out: &mut Vec<f64>) -> Result<()> {
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
pub(super) fn string_into(r: &mut Reader<'_>, wire: u8, out: &mut String) -> Result<bool> {
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
pub(super) fn same_bytes(a: &[u8], b: &[u8]) -> bool {
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
pub(super) fn name_into(
    r: &mut Reader<'_>,
    wire: u8,
    names: &mut Vec<String>,
    n: &mut usize,
) -> Result<bool> {
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
pub(super) fn count_repeated(r: &mut Reader<'_>, wire: u8) -> Result<usize> {
    if wire != LEN {
        expect(wire, VARINT)?;
        r.varint()?;
        return Ok(1);
    }
    count_packed(r.len_delimited()?)
}

/// The number of varints in a packed repeated field's bytes, each accepted or refused as
/// [`Reader::varint`] reads it.
pub(super) fn count_packed(packed: &[u8]) -> Result<usize> {
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
pub(super) fn message(
    r: &mut Reader<'_>,
    wire: u8,
    mut field: impl FnMut(&mut Reader<'_>, u32, u8) -> Result<bool>,
) -> Result<()> {
    let mut inner = r.nested(wire)?;
    fields(&mut inner, &mut field)
}

/// Every field of `r`: `field` decodes the ones it knows (returning `true`), the others are
/// skipped.
pub(super) fn fields(
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
pub(super) fn vector3(r: &mut Reader<'_>, wire: u8, step: f64, v: &mut Vector3) -> Result<()> {
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

pub(super) fn pose(r: &mut Reader<'_>, wire: u8, p: &mut Pose) -> Result<()> {
    message(r, wire, |r, tag, wire| {
        match tag {
            1 => vector3(r, wire, POSITION, &mut p.position)?,
            2 => quaternion(r, wire, &mut p.orientation)?,
            _ => return Ok(false),
        }
        Ok(true)
    })
}

pub(super) fn wrench(r: &mut Reader<'_>, wire: u8, w: &mut [f64; 6]) -> Result<()> {
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

pub(super) fn intensity(r: &mut Reader<'_>, wire: u8, c: &mut Intensity4) -> Result<()> {
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
