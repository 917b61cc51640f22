//! A record's length-prefixed fields checked against the bytes it holds, before the `mcap`
//! crate parses it: its string and byte-array readers allocate the length a field declares
//! (up to 4 GiB) before reading, so a 25-byte file could ask for 3.75 GiB (found by
//! `icms-fuzz session`). Field layouts as in the MCAP specification.

use mcap::records::op;

/// Walks a record body, checking that each declared length fits in what is left.
struct Fields<'a> {
    body: &'a [u8],
    pos: usize,
}

impl Fields<'_> {
    fn left(&self) -> usize {
        self.body.len().saturating_sub(self.pos)
    }

    /// Skips `n` fixed bytes (a shorter body is for the parser to refuse).
    fn fixed(&mut self, n: usize) {
        self.pos = self.pos.saturating_add(n);
    }

    fn prefix(&mut self, width: usize, what: &str) -> Result<usize, String> {
        if self.left() < width {
            // Too short to hold the prefix: the parser refuses it without allocating.
            self.pos = self.body.len();
            return Ok(0);
        }
        let mut raw = [0u8; 8];
        raw[..width].copy_from_slice(&self.body[self.pos..self.pos + width]);
        self.pos += width;
        let len = u64::from_le_bytes(raw);
        if len > self.left() as u64 {
            return Err(format!(
                "{what} declares {len} bytes but the record holds {} more",
                self.left()
            ));
        }
        Ok(len as usize)
    }

    /// A string or byte array with a u32 length.
    fn bytes32(&mut self, what: &str) -> Result<(), String> {
        let n = self.prefix(4, what)?;
        self.fixed(n);
        Ok(())
    }

    /// A byte array with a u64 length.
    fn bytes64(&mut self, what: &str) -> Result<(), String> {
        let n = self.prefix(8, what)?;
        self.fixed(n);
        Ok(())
    }

    /// A map of strings to strings: a u32 byte length, then pairs of strings. The parser reads
    /// pairs until it has consumed that many bytes, each string's length prefix from the record
    /// rather than from what is left of the map (a prefix may straddle the map's end, found by
    /// `icms-fuzz http`), so every string is checked against the record.
    fn string_map(&mut self, what: &str) -> Result<(), String> {
        let n = self.prefix(4, what)?;
        let end = self.pos + n;
        while self.pos < end && self.left() > 0 {
            self.bytes32(what)?;
            self.bytes32(what)?;
        }
        Ok(())
    }
}

/// `Err` naming the field when a length-prefixed field of record `opcode` declares more bytes
/// than `body` holds.
pub(crate) fn check(opcode: u8, body: &[u8]) -> Result<(), String> {
    let mut f = Fields { body, pos: 0 };
    match opcode {
        op::HEADER => {
            f.bytes32("header profile")?;
            f.bytes32("header library")?;
        }
        op::SCHEMA => {
            f.fixed(2);
            f.bytes32("schema name")?;
            f.bytes32("schema encoding")?;
            f.bytes32("schema data")?;
        }
        op::CHANNEL => {
            f.fixed(4);
            f.bytes32("channel topic")?;
            f.bytes32("channel message encoding")?;
            f.string_map("channel metadata")?;
        }
        op::CHUNK => {
            f.fixed(8 + 8 + 8 + 4);
            f.bytes32("chunk compression")?;
            f.bytes64("chunk records")?;
        }
        op::MESSAGE_INDEX => {
            f.fixed(2);
            f.bytes32("message index entries")?;
        }
        op::CHUNK_INDEX => {
            f.fixed(8 * 4);
            f.bytes32("chunk index message index offsets")?;
            f.fixed(8);
            f.bytes32("chunk index compression")?;
        }
        op::ATTACHMENT => {
            f.fixed(16);
            f.bytes32("attachment name")?;
            f.bytes32("attachment media type")?;
            f.bytes64("attachment data")?;
        }
        op::ATTACHMENT_INDEX => {
            f.fixed(8 * 5);
            f.bytes32("attachment index name")?;
            f.bytes32("attachment index media type")?;
        }
        op::STATISTICS => {
            f.fixed(8 + 2 + 4 * 4 + 8 + 8);
            f.bytes32("statistics channel message counts")?;
        }
        op::METADATA => {
            f.bytes32("metadata name")?;
            f.string_map("metadata")?;
        }
        op::METADATA_INDEX => {
            f.fixed(16);
            f.bytes32("metadata index name")?;
        }
        _ => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_header_whose_profile_claims_gigabytes_is_refused_naming_it() {
        let mut body = 0xF000_0000u32.to_le_bytes().to_vec();
        body.extend_from_slice(b"ros1");
        let e = check(op::HEADER, &body).unwrap_err();
        assert!(
            e.contains("header profile") && e.contains("4026531840"),
            "{e}"
        );
    }

    #[test]
    fn well_formed_records_pass() {
        let s = |t: &str| {
            let mut v = (t.len() as u32).to_le_bytes().to_vec();
            v.extend_from_slice(t.as_bytes());
            v
        };
        let mut header = s("icms");
        header.extend(s("lib"));
        assert!(check(op::HEADER, &header).is_ok());
        let mut pairs = s("k");
        pairs.extend(s("v"));
        let mut meta = s("session");
        meta.extend((pairs.len() as u32).to_le_bytes());
        meta.extend(pairs);
        assert!(check(op::METADATA, &meta).is_ok());
        // A map entry that runs past its map is refused.
        let mut bad = s("session");
        let mut pairs = s("k");
        pairs.extend(999u32.to_le_bytes());
        bad.extend((pairs.len() as u32).to_le_bytes());
        bad.extend(pairs);
        assert!(check(op::METADATA, &bad).is_err());
        // A map of 3 bytes whose first key's length prefix runs past the map's end into the
        // rest of the record, declaring 3.6 GB: the parser reads that prefix.
        let mut channel = vec![0u8; 4];
        channel.extend(s("/tf"));
        channel.extend(s("json"));
        channel.extend(3u32.to_le_bytes());
        channel.extend(3_631_182_895u32.to_le_bytes());
        channel.extend([0u8; 12]);
        let e = check(op::CHANNEL, &channel).unwrap_err();
        assert!(
            e.contains("channel metadata declares 3631182895 bytes"),
            "{e}"
        );
    }
}
