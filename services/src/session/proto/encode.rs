//! Protobuf bytes written by hand: branch-free varints ([`put_value`], [`put_key`]) and the
//! [`Wire`] cursor the [`Quantiser`] encodes the raw topics with.

use super::keys::Keys;
use super::quantiser::{quantise, steps, Refused};
use super::*;
use crate::foxglove::{Pose, Vector3};
use crate::session::messages::Intensity4;

/// Protobuf's zigzag encoding of an `sint32`.
#[inline(always)]
fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

/// Bytes of the varint of `v` (1 to 10).
#[inline(always)]
fn varint_len(v: u64) -> usize {
    (64 - (v | 1).leading_zeros() as usize).div_ceil(7)
}

/// Writes the varint of a value (a zigzagged `sint32`, a `uint32`: at most 5 bytes) at `pos`
/// without a branch: each 7-bit group shifted to its byte, the continuation bits of all bytes
/// but the last set, 8 bytes stored and `pos` moved by the varint's length. `buf` must have 8
/// bytes from `pos`.
#[inline(always)]
fn put_value(buf: &mut [u8], pos: &mut usize, v: u32) {
    /// Per count of leading zero bits of the value: the varint's length and its continuation
    /// bits.
    const LENGTHS: [(usize, u64); 33] = {
        let mut t = [(0, 0); 33];
        let mut lz = 0;
        while lz <= 32 {
            let bits: usize = if lz == 32 { 1 } else { 32 - lz };
            let n = bits.div_ceil(7);
            t[lz] = (n, 0x8080_8080_8080_8080 & ((1u64 << (8 * (n - 1))) - 1));
            lz += 1;
        }
        t
    };
    let x = u64::from(v);
    let w = (x & 0x7f)
        | ((x << 1) & 0x7f00)
        | ((x << 2) & 0x7f_0000)
        | ((x << 3) & 0x7f00_0000)
        | ((x << 4) & 0x7f_0000_0000);
    let (n, continuation) = LENGTHS[v.leading_zeros() as usize];
    buf[*pos..*pos + 8].copy_from_slice(&(w | continuation).to_le_bytes());
    *pos += n;
}

/// Writes a key (a varint: one byte for field numbers under 16) at `pos` and returns the
/// position after it. `buf` must have 10 bytes from `pos`.
#[inline(always)]
fn put_key(buf: &mut [u8], pos: &mut usize, mut key: u64) -> usize {
    while key >= 0x80 {
        buf[*pos] = (key & 0x7f) as u8 | 0x80;
        *pos += 1;
        key >>= 7;
    }
    buf[*pos] = key as u8;
    *pos += 1;
    *pos
}

/// Protobuf bytes appended to a `Vec<u8>` without a branch on the values where it can be
/// helped: each write makes room first, a varint is stored as 8 bytes and the cursor moved by
/// its length, a zero field is written and then taken back, and a length-delimited field gets
/// one byte for its length, widened (the body moved) in the rare case it needs more.
pub(super) struct Wire<'a> {
    /// The message, from 0 to `pos`; what follows is room for the next writes.
    buf: &'a mut Vec<u8>,
    pos: usize,
    refused: &'a mut Refused,
    pub(super) keys: &'static Keys,
}

impl<'a> Wire<'a> {
    /// A message written into `q`'s scratch buffer.
    pub(super) fn new(q: &'a mut Quantiser) -> Self {
        Self {
            buf: &mut q.scratch,
            pos: 0,
            refused: &mut q.refused,
            keys: Keys::get(),
        }
    }

    /// Appends the message to `out`.
    pub(super) fn finish(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.buf[..self.pos]);
    }

    #[inline(always)]
    pub(super) fn q(&mut self, field: &'static str, x: f64, step: f64) -> i32 {
        quantise(self.refused, field, x, step)
    }

    /// Makes sure `n` bytes can be written at the cursor.
    #[inline(always)]
    fn room(&mut self, n: usize) {
        if self.buf.len() < self.pos + n {
            self.grow(n);
        }
    }

    #[cold]
    #[inline(never)]
    fn grow(&mut self, n: usize) {
        let len = (self.pos + n).max(2 * self.buf.len()).max(4096);
        self.buf.resize(len, 0);
    }

    /// A key, or a length: one byte almost always (field numbers under 16, short messages),
    /// a branch the processor gets right.
    #[inline(always)]
    fn varint(&mut self, v: u64) {
        if v < 0x80 {
            self.buf[self.pos] = v as u8;
            self.pos += 1;
        } else {
            self.long_varint(v);
        }
    }

    #[cold]
    #[inline(never)]
    fn long_varint(&mut self, mut v: u64) {
        self.room(10);
        while v >= 0x80 {
            self.buf[self.pos] = (v & 0x7f) as u8 | 0x80;
            self.pos += 1;
            v >>= 7;
        }
        self.buf[self.pos] = v as u8;
        self.pos += 1;
    }

    /// A value's varint (see [`put_value`]); needs 8 bytes of room.
    #[inline(always)]
    fn value(&mut self, v: u32) {
        put_value(&mut self.buf[..], &mut self.pos, v);
    }

    /// An `sint32` field (left out when 0).
    #[inline(always)]
    pub(super) fn sint32(&mut self, key: u64, v: i32) {
        self.room(16);
        let start = self.pos;
        self.varint(key);
        self.value(zigzag(v));
        if v == 0 {
            self.pos = start;
        }
    }

    /// A `uint32` field (left out when 0).
    #[inline(always)]
    pub(super) fn uint32(&mut self, key: u64, v: u32) {
        self.room(16);
        let start = self.pos;
        self.varint(key);
        self.value(v);
        if v == 0 {
            self.pos = start;
        }
    }

    /// A `bool` field (left out when false).
    #[inline(always)]
    pub(super) fn bool(&mut self, key: u64, v: bool) {
        self.room(16);
        let start = self.pos;
        self.varint(key);
        self.varint(1);
        if !v {
            self.pos = start;
        }
    }

    /// A string (one of a `repeated string`, or a `string` field when not empty).
    pub(super) fn string(&mut self, key: u64, s: &str) {
        self.room(24 + s.len());
        self.varint(key);
        self.varint(s.len() as u64);
        self.buf[self.pos..self.pos + s.len()].copy_from_slice(s.as_bytes());
        self.pos += s.len();
    }

    /// Starts a length-delimited field: its key and one byte for its length.
    #[inline(always)]
    pub(super) fn begin(&mut self, key: u64) -> usize {
        self.room(16);
        self.varint(key);
        self.pos += 1;
        self.pos - 1
    }

    /// Ends the length-delimited field [`begin`](Self::begin) started at `at`.
    #[inline(always)]
    pub(super) fn end(&mut self, at: usize) {
        let len = self.pos - at - 1;
        if len < 0x80 {
            self.buf[at] = len as u8;
        } else {
            self.long_length(at, len);
        }
    }

    #[cold]
    #[inline(never)]
    fn long_length(&mut self, at: usize, len: usize) {
        let n = varint_len(len as u64);
        self.room(n);
        self.buf.copy_within(at + 1..self.pos, at + n);
        let mut v = len;
        for i in 0..n {
            self.buf[at + i] = (v & 0x7f) as u8 | if i + 1 < n { 0x80 } else { 0 };
            v >>= 7;
        }
        self.pos += n - 1;
    }

    /// A `Vector3i` field (left out when all zero).
    #[inline(always)]
    pub(super) fn vector(&mut self, key: u64, field: &'static str, v: &Vector3, step: f64) {
        let x = self.q(field, v.x, step);
        let y = self.q(field, v.y, step);
        let z = self.q(field, v.z, step);
        if (x | y | z) == 0 {
            return;
        }
        self.small(key, &self.keys.vector, [x, y, z]);
    }

    /// A `Posei` field.
    pub(super) fn pose(&mut self, key: u64, field: &'static str, p: &Pose) {
        let at = self.begin(key);
        self.vector(self.keys.position, field, &p.position, POSITION);
        let o = &p.orientation;
        let values = [
            self.q(field, o.x, UNIT),
            self.q(field, o.y, UNIT),
            self.q(field, o.z, UNIT),
            self.q(field, o.w, UNIT),
        ];
        self.small(self.keys.orientation, &self.keys.quaternion, values);
        self.end(at);
    }

    /// A `Wrenchi` field.
    pub(super) fn wrench(&mut self, key: u64, field: &'static str, w: &[f64; 6]) {
        let at = self.begin(key);
        let force = Vector3::new(w[0], w[1], w[2]);
        self.vector(self.keys.force, field, &force, FORCE);
        let torque = Vector3::new(w[3], w[4], w[5]);
        self.vector(self.keys.torque, field, &torque, MOMENT);
        self.end(at);
    }

    /// An `Intensityi` field (left out when all zero).
    #[inline(always)]
    pub(super) fn intensity(&mut self, key: u64, field: &'static str, c: &Intensity4) {
        let values = [
            self.q(field, c.x, FORCE),
            self.q(field, c.y, FORCE),
            self.q(field, c.z, FORCE),
            self.q(field, c.torsion, MOMENT),
        ];
        if values == [0; 4] {
            return;
        }
        self.small(key, &self.keys.intensity, values);
    }

    /// A message field of `N` `sint32` fields (keys `keys`; zeros left out), written with the
    /// buffer and cursor held in registers (through `self`, each byte stored would make the
    /// compiler load them again).
    #[inline(always)]
    fn small<const N: usize>(&mut self, key: u64, keys: &[u64; N], values: [i32; N]) {
        self.room(16 + 16 * N);
        let (buf, mut pos) = (&mut self.buf[..], self.pos);
        let at = put_key(buf, &mut pos, key);
        pos += 1;
        for (&k, v) in keys.iter().zip(values) {
            let start = pos;
            put_key(buf, &mut pos, k);
            put_value(buf, &mut pos, zigzag(v));
            if v == 0 {
                pos = start;
            }
        }
        self.pos = pos;
        self.end(at);
    }

    /// A packed `repeated sint32` field (left out when empty); a value refused is named
    /// `field[i]`.
    pub(super) fn packed(&mut self, key: u64, field: &'static str, values: &[f64], step: f64) {
        if values.is_empty() {
            return;
        }
        self.room(16 + 8 * values.len());
        let (buf, mut pos) = (&mut self.buf[..], self.pos);
        let at = put_key(buf, &mut pos, key);
        pos += 1;
        for (i, &x) in values.iter().enumerate() {
            let v = steps(x, step).unwrap_or_else(|| {
                self.refused
                    .get_or_insert_with(|| (format!("{field}[{i}]"), x));
                0
            });
            put_value(buf, &mut pos, zigzag(v));
        }
        self.pos = pos;
        self.end(at);
    }
}
