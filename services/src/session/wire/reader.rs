//! A cursor over protobuf bytes ([`Reader`]): varints, keys, length-delimited fields, skipped
//! fields and groups, nested messages to prost's recursion limit.

use super::Result;

/// Wire types of the protobuf encoding.
pub(super) const VARINT: u8 = 0;
pub(super) const I64: u8 = 1;
pub(super) const LEN: u8 = 2;
const SGROUP: u8 = 3;
const EGROUP: u8 = 4;
pub(super) const I32: u8 = 5;

/// Deepest nesting of groups skipped (prost's recursion limit).
const RECURSION_LIMIT: u32 = 100;

/// A cursor over a message's bytes, at `depth` messages below the one decoded (prost's
/// recursion limit counts them, and the groups skipped).
pub(super) struct Reader<'a> {
    pub(super) buf: &'a [u8],
    depth: u32,
}

impl<'a> Reader<'a> {
    /// A top-level message.
    pub(super) fn new(buf: &'a [u8]) -> Self {
        Reader { buf, depth: 0 }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    /// A varint: one and two bytes (keys, lengths, most values) read inline, longer ones by
    /// [`Self::varint_long`].
    #[inline(always)]
    pub(super) fn varint(&mut self) -> Result<u64> {
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
    pub(super) fn key(&mut self) -> Result<(u32, u8)> {
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

    pub(super) fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        if n > self.buf.len() {
            return Err("buffer underflow");
        }
        let (head, rest) = self.buf.split_at(n);
        self.buf = rest;
        Ok(head)
    }

    pub(super) fn len_delimited(&mut self) -> Result<&'a [u8]> {
        let n = self.varint()?;
        let n = usize::try_from(n).map_err(|_| "buffer underflow")?;
        self.take(n)
    }

    /// Skips a field of an unknown number.
    pub(super) fn skip(&mut self, tag: u32, wire: u8) -> Result<()> {
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
    pub(super) fn nested(&mut self, wire: u8) -> Result<Reader<'a>> {
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

pub(super) fn expect(wire: u8, want: u8) -> Result<()> {
    if wire == want {
        Ok(())
    } else {
        Err("invalid wire type")
    }
}
