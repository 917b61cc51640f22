//! MCAP-aware mutation. A file is split into its records, chunks decompressed into their
//! inner records; a mutation changes one record (a message's JSON payload, a header field, a
//! metadata value, a channel's topic, the record's bytes, its opcode, its place) and the file
//! is written back with every length, chunk size and CRC recomputed (the data section and
//! summary CRCs too), so that the reader gets past its CRC checks to the code behind them.
//! Some inputs keep a stale or zero CRC on purpose.

use serde_json::Value;

use crate::bytes;
use crate::json;
use crate::rng::Rng;

/// The MCAP magic, at both ends of a file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Opcodes used here.
pub mod op {
    /// Header.
    pub const HEADER: u8 = 0x01;
    /// Footer.
    pub const FOOTER: u8 = 0x02;
    /// Schema.
    pub const SCHEMA: u8 = 0x03;
    /// Channel.
    pub const CHANNEL: u8 = 0x04;
    /// Message.
    pub const MESSAGE: u8 = 0x05;
    /// Chunk.
    pub const CHUNK: u8 = 0x06;
    /// Metadata.
    pub const METADATA: u8 = 0x0c;
    /// Data end.
    pub const DATA_END: u8 = 0x0f;
}

/// A record outside chunks, or one inside a chunk.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Opcode.
    pub op: u8,
    /// Body.
    pub body: Vec<u8>,
}

/// A chunk with its records decompressed.
#[derive(Debug, Clone, PartialEq)]
pub struct Chunk {
    /// Message start time.
    pub start: u64,
    /// Message end time.
    pub end: u64,
    /// Compression (`zstd`, `lz4`, `` or anything).
    pub compression: String,
    /// The records inside.
    pub inner: Vec<Record>,
    /// The original body while nothing in the chunk changed (written as it was).
    pub original: Option<Vec<u8>>,
    /// How to write the uncompressed CRC once the chunk changed.
    pub crc: CrcMode,
}

/// How a changed chunk's CRC is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CrcMode {
    /// Recomputed (the reader checks it and passes).
    Fix,
    /// Zero: "not computed", the reader skips the check.
    Zero,
    /// The value the chunk had before (a mismatch).
    Stale(u32),
}

/// One top-level item.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// A record other than a chunk.
    Plain(Record),
    /// A chunk.
    Chunk(Chunk),
}

/// A parsed MCAP file.
#[derive(Debug, Clone, PartialEq)]
pub struct McapFile {
    /// Top-level records after the magic, up to and including the footer.
    pub items: Vec<Item>,
    /// Bytes after the footer (the end magic).
    pub tail: Vec<u8>,
    /// Recompute the data section and summary CRCs when writing.
    pub fix_section_crcs: bool,
}

fn u32_at(b: &[u8], i: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?))
}

fn u64_at(b: &[u8], i: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(i..i + 8)?.try_into().ok()?))
}

fn split_records(mut b: &[u8]) -> Option<Vec<Record>> {
    let mut out = Vec::new();
    while !b.is_empty() {
        let op = *b.first()?;
        let len = usize::try_from(u64_at(b, 1)?).ok()?;
        let body = b.get(9..9usize.checked_add(len)?)?;
        out.push(Record {
            op,
            body: body.to_vec(),
        });
        b = &b[9 + len..];
    }
    Some(out)
}

fn decompress(compression: &str, data: &[u8], size: usize) -> Option<Vec<u8>> {
    match compression {
        "" => Some(data.to_vec()),
        "zstd" => zstd::bulk::decompress(data, size).ok(),
        "lz4" => {
            use std::io::Read;
            let mut out = Vec::with_capacity(size);
            lz4::Decoder::new(data)
                .ok()?
                .take(size as u64 + 1)
                .read_to_end(&mut out)
                .ok()?;
            Some(out)
        }
        _ => None,
    }
}

/// Compresses for a chunk; an unknown compression name stores the bytes as they are.
pub fn compress(compression: &str, data: &[u8]) -> Vec<u8> {
    match compression {
        "zstd" => zstd::bulk::compress(data, 1).unwrap_or_else(|_| data.to_vec()),
        "lz4" => {
            use std::io::Write;
            let mut enc = match lz4::EncoderBuilder::new().level(1).build(Vec::new()) {
                Ok(e) => e,
                Err(_) => return data.to_vec(),
            };
            if enc.write_all(data).is_err() {
                return data.to_vec();
            }
            let (out, res) = enc.finish();
            if res.is_err() {
                return data.to_vec();
            }
            out
        }
        _ => data.to_vec(),
    }
}

fn parse_chunk(body: &[u8]) -> Option<Chunk> {
    let start = u64_at(body, 0)?;
    let end = u64_at(body, 8)?;
    let size = usize::try_from(u64_at(body, 16)?).ok()?;
    let clen = u32_at(body, 28)? as usize;
    let compression = std::str::from_utf8(body.get(32..32 + clen)?)
        .ok()?
        .to_owned();
    let rlen = usize::try_from(u64_at(body, 32 + clen)?).ok()?;
    let data = body.get(40 + clen..(40 + clen).checked_add(rlen)?)?;
    if size > 256 << 20 {
        return None;
    }
    let plain = decompress(&compression, data, size)?;
    Some(Chunk {
        start,
        end,
        compression,
        inner: split_records(&plain)?,
        original: Some(body.to_vec()),
        crc: CrcMode::Stale(u32_at(body, 24)?),
    })
}

impl McapFile {
    /// Parses a well-formed file (`None` for anything else: those get byte mutations).
    pub fn parse(bytes: &[u8]) -> Option<McapFile> {
        if bytes.get(..8)? != MAGIC {
            return None;
        }
        let mut items = Vec::new();
        let mut pos = 8usize;
        loop {
            let op = *bytes.get(pos)?;
            let len = usize::try_from(u64_at(bytes, pos + 1)?).ok()?;
            let body = bytes.get(pos + 9..(pos + 9).checked_add(len)?)?;
            pos += 9 + len;
            if op == op::CHUNK {
                items.push(Item::Chunk(parse_chunk(body)?));
            } else {
                items.push(Item::Plain(Record {
                    op,
                    body: body.to_vec(),
                }));
            }
            if op == op::FOOTER {
                break;
            }
        }
        Some(McapFile {
            items,
            tail: bytes[pos..].to_vec(),
            fix_section_crcs: true,
        })
    }

    /// Writes the file, recomputing lengths, changed chunks' sizes and CRCs and (when
    /// [`McapFile::fix_section_crcs`]) the data section and summary CRCs.
    pub fn write(&self) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        let mut summary_from: Option<usize> = None;
        for item in &self.items {
            match item {
                Item::Plain(r) => {
                    let start = out.len();
                    out.push(r.op);
                    out.extend_from_slice(&(r.body.len() as u64).to_le_bytes());
                    if r.op == op::DATA_END && self.fix_section_crcs && r.body.len() >= 4 {
                        let crc = crc32fast::hash(&out[..start]);
                        out.extend_from_slice(&crc.to_le_bytes());
                        out.extend_from_slice(&r.body[4..]);
                        summary_from = Some(out.len());
                    } else if r.op == op::FOOTER && self.fix_section_crcs && r.body.len() >= 20 {
                        out.extend_from_slice(&r.body[..16]);
                        let from = summary_from.unwrap_or(out.len());
                        let crc = crc32fast::hash(&out[from.min(out.len())..]);
                        out.extend_from_slice(&crc.to_le_bytes());
                        out.extend_from_slice(&r.body[20..]);
                    } else {
                        out.extend_from_slice(&r.body);
                    }
                }
                Item::Chunk(c) => {
                    let body = match &c.original {
                        Some(b) => b.clone(),
                        None => c.body(),
                    };
                    out.push(op::CHUNK);
                    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
                    out.extend_from_slice(&body);
                }
            }
        }
        out.extend_from_slice(&self.tail);
        out
    }

    /// Every (item, inner) position of a record: `(i, None)` a top-level record, `(i,
    /// Some(j))` record `j` of chunk `i`.
    fn sites(&self) -> Vec<(usize, Option<usize>)> {
        let mut s = Vec::new();
        for (i, item) in self.items.iter().enumerate() {
            match item {
                Item::Plain(_) => s.push((i, None)),
                Item::Chunk(c) => {
                    s.push((i, None));
                    s.extend((0..c.inner.len()).map(|j| (i, Some(j))));
                }
            }
        }
        s
    }

    /// The record at a site (`None` for a chunk itself), marking its chunk changed.
    fn record_mut(&mut self, site: (usize, Option<usize>)) -> Option<&mut Record> {
        match (self.items.get_mut(site.0)?, site.1) {
            (Item::Plain(r), None) => Some(r),
            (Item::Chunk(c), Some(j)) => {
                c.original = None;
                c.inner.get_mut(j)
            }
            _ => None,
        }
    }

    fn record(&self, site: (usize, Option<usize>)) -> Option<&Record> {
        match (self.items.get(site.0)?, site.1) {
            (Item::Plain(r), None) => Some(r),
            (Item::Chunk(c), Some(j)) => c.inner.get(j),
            _ => None,
        }
    }

    fn sites_with(&self, opcode: u8) -> Vec<(usize, Option<usize>)> {
        self.sites()
            .into_iter()
            .filter(|s| self.record(*s).is_some_and(|r| r.op == opcode))
            .collect()
    }

    /// A copy with every chunk recompressed as `compression` (`""`: uncompressed).
    pub fn recompressed(&self, compression: &str) -> McapFile {
        let mut f = self.clone();
        for item in &mut f.items {
            if let Item::Chunk(c) = item {
                c.compression = compression.to_owned();
                c.original = None;
                c.crc = CrcMode::Fix;
            }
        }
        f
    }

    /// A copy with every chunk's records moved out to the top level (no chunks).
    pub fn unchunked(&self) -> McapFile {
        let mut f = self.clone();
        f.items = Vec::new();
        for item in &self.items {
            match item {
                Item::Chunk(c) => f.items.extend(c.inner.iter().cloned().map(Item::Plain)),
                Item::Plain(r) if r.op == 0x07 => {} // message indexes point into chunks
                other => f.items.push(other.clone()),
            }
        }
        f
    }

    /// Sets `key` of every metadata record named `name` to `value`.
    pub fn set_metadata(&mut self, name: &str, key: &str, value: &str) {
        for site in self.sites_with(op::METADATA) {
            let Some(r) = self.record_mut(site) else {
                continue;
            };
            if let Some((n, mut entries)) = parse_metadata(&r.body) {
                if n == name {
                    for e in &mut entries {
                        if e.0 == key {
                            e.1 = value.to_owned();
                        }
                    }
                    r.body = write_metadata(&n, &entries);
                }
            }
        }
    }
}

impl Chunk {
    fn body(&self) -> Vec<u8> {
        let mut plain = Vec::new();
        for r in &self.inner {
            plain.push(r.op);
            plain.extend_from_slice(&(r.body.len() as u64).to_le_bytes());
            plain.extend_from_slice(&r.body);
        }
        let data = compress(&self.compression, &plain);
        let crc = match self.crc {
            CrcMode::Fix => crc32fast::hash(&plain),
            CrcMode::Zero => 0,
            CrcMode::Stale(c) => c,
        };
        let mut b = Vec::with_capacity(data.len() + 64);
        b.extend_from_slice(&self.start.to_le_bytes());
        b.extend_from_slice(&self.end.to_le_bytes());
        b.extend_from_slice(&(plain.len() as u64).to_le_bytes());
        b.extend_from_slice(&crc.to_le_bytes());
        b.extend_from_slice(&(self.compression.len() as u32).to_le_bytes());
        b.extend_from_slice(self.compression.as_bytes());
        b.extend_from_slice(&(data.len() as u64).to_le_bytes());
        b.extend_from_slice(&data);
        b
    }
}

fn read_str(b: &[u8], pos: &mut usize) -> Option<String> {
    let n = u32_at(b, *pos)? as usize;
    let s = std::str::from_utf8(b.get(*pos + 4..(*pos + 4).checked_add(n)?)?).ok()?;
    *pos += 4 + n;
    Some(s.to_owned())
}

fn put_str(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

/// A metadata record's name and entries.
pub fn parse_metadata(b: &[u8]) -> Option<(String, Vec<(String, String)>)> {
    let mut pos = 0;
    let name = read_str(b, &mut pos)?;
    let map_len = u32_at(b, pos)? as usize;
    pos += 4;
    let end = pos.checked_add(map_len)?;
    let mut entries = Vec::new();
    while pos < end {
        let k = read_str(b, &mut pos)?;
        let v = read_str(b, &mut pos)?;
        entries.push((k, v));
    }
    Some((name, entries))
}

/// A metadata record's body.
pub fn write_metadata(name: &str, entries: &[(String, String)]) -> Vec<u8> {
    let mut map = Vec::new();
    for (k, v) in entries {
        put_str(&mut map, k);
        put_str(&mut map, v);
    }
    let mut out = Vec::new();
    put_str(&mut out, name);
    out.extend_from_slice(&(map.len() as u32).to_le_bytes());
    out.extend_from_slice(&map);
    out
}

/// Length of a message record's header (channel, sequence, log time, publish time).
const MESSAGE_HEADER: usize = 22;

const TOPICS: [&str; 10] = [
    "/glove/joint_states",
    "/glove/feedback",
    "/dfs/contacts",
    "/object/state",
    "/tf",
    "/scene",
    "/joint_states",
    "/hand",
    "",
    "/other",
];

const INTERESTING_U64: [u64; 10] = [
    0,
    1,
    999_999,
    1_000_000,
    u64::MAX,
    u64::MAX / 2,
    1 << 63,
    1 << 32,
    100_000_000_000,
    1_700_000_000_000_000_000,
];

/// A record's place: its top-level index, and its index inside the chunk when it is inner.
type Site = (usize, Option<usize>);

/// A record of kind `opcode` picked at random (one `rng.pick` among them, none drawn when
/// there is no such record), marking its chunk changed.
fn pick_record<'f>(rng: &mut Rng, f: &'f mut McapFile, opcode: u8) -> Option<&'f mut Record> {
    let sites = f.sites_with(opcode);
    if sites.is_empty() {
        return None;
    }
    let site = *rng.pick(&sites);
    f.record_mut(site)
}

/// A message record picked at random as [`pick_record`] does, when it has a whole header.
fn pick_message<'f>(rng: &mut Rng, f: &'f mut McapFile) -> Option<&'f mut Record> {
    pick_record(rng, f, op::MESSAGE).filter(|r| r.body.len() >= MESSAGE_HEADER)
}

/// One MCAP-aware mutation. `others` are the other seed files (to splice records from).
///
/// One table of mutation kinds, weighted by the ranges of `rng.below(18)`; each kind is a
/// function of its own below.
pub fn mutate(rng: &mut Rng, f: &mut McapFile, others: &[McapFile]) {
    let sites = f.sites();
    if sites.is_empty() {
        return;
    }
    match rng.below(18) {
        0..=3 => mutate_message_payload(rng, f),
        4 => mutate_message_header(rng, f),
        5 | 6 => mutate_record_bytes(rng, f, &sites),
        7 | 8 => mutate_metadata(rng, f),
        9 => delete_record(rng, f, &sites),
        10 => duplicate_record(rng, f, &sites),
        11 => move_or_swap_record(rng, f, &sites),
        12 => mutate_chunk_header(rng, f),
        13 => mutate_opcode(rng, f, &sites),
        14 => mutate_channel(rng, f),
        15 if !others.is_empty() => splice_record(rng, f, others),
        16 => truncate_records(rng, f),
        _ => mutate_crc_mode(rng, f, &sites),
    }
}

/// A message's JSON payload.
fn mutate_message_payload(rng: &mut Rng, f: &mut McapFile) {
    if let Some(r) = pick_message(rng, f) {
        let payload = r.body.split_off(MESSAGE_HEADER);
        let n = rng.range(1, 2);
        let new = json::mutate_text(rng, &payload, &[], n);
        r.body.extend_from_slice(&new);
    }
}

/// A message header field: channel id, sequence, log time or publish time.
fn mutate_message_header(rng: &mut Rng, f: &mut McapFile) {
    if let Some(r) = pick_message(rng, f) {
        match rng.below(4) {
            0 => {
                let id = rng.below(12) as u16;
                r.body[0..2].copy_from_slice(&id.to_le_bytes());
            }
            1 => {
                let s = rng.next_u64() as u32;
                r.body[2..6].copy_from_slice(&s.to_le_bytes());
            }
            2 => {
                let t = if rng.one_in(2) {
                    *rng.pick(&INTERESTING_U64)
                } else {
                    let old = u64::from_le_bytes(r.body[6..14].try_into().unwrap_or_default());
                    old.wrapping_add(rng.next_u64() % 2_000_000_000)
                        .wrapping_sub(1_000_000_000)
                };
                r.body[6..14].copy_from_slice(&t.to_le_bytes());
            }
            _ => {
                let t = *rng.pick(&INTERESTING_U64);
                r.body[14..22].copy_from_slice(&t.to_le_bytes());
            }
        }
    }
}

/// Any record's bytes (inner or top level).
fn mutate_record_bytes(rng: &mut Rng, f: &mut McapFile, sites: &[Site]) {
    let site = *rng.pick(sites);
    if let Some(r) = f.record_mut(site) {
        let n = rng.range(1, 3);
        bytes::mutate_n(rng, &mut r.body, &[], n);
    }
}

/// A metadata value (JSON-aware when it is JSON), a key, or an entry more.
fn mutate_metadata(rng: &mut Rng, f: &mut McapFile) {
    if let Some(r) = pick_record(rng, f, op::METADATA) {
        if let Some((mut name, mut entries)) = parse_metadata(&r.body) {
            if entries.is_empty() || rng.one_in(8) {
                entries.push(("object".to_owned(), "{}".to_owned()));
            }
            let i = rng.below(entries.len());
            match rng.below(6) {
                0 => {
                    let mut k = entries[i].0.clone().into_bytes();
                    bytes::mutate(rng, &mut k, &[]);
                    entries[i].0 = String::from_utf8_lossy(&k).into_owned();
                }
                1 => {
                    let e = entries[i].clone();
                    entries.push(e);
                }
                2 => {
                    entries.remove(i);
                }
                3 if rng.one_in(4) => {
                    name = (*rng.pick(&["session", "ground_truth", "replay", ""])).to_owned();
                }
                _ => {
                    let v = entries[i].1.clone();
                    let n = rng.range(1, 2);
                    let out = json::mutate_text(rng, v.as_bytes(), &[], n);
                    entries[i].1 = String::from_utf8_lossy(&out).into_owned();
                }
            }
            r.body = write_metadata(&name, &entries);
        }
    }
}

/// Deletes a record.
fn delete_record(rng: &mut Rng, f: &mut McapFile, sites: &[Site]) {
    let site = *rng.pick(sites);
    match site {
        (i, None) => {
            f.items.remove(i);
        }
        (i, Some(j)) => {
            if let Some(Item::Chunk(c)) = f.items.get_mut(i) {
                c.original = None;
                c.inner.remove(j);
            }
        }
    }
}

/// Duplicates a record (in place or at another top-level position).
fn duplicate_record(rng: &mut Rng, f: &mut McapFile, sites: &[Site]) {
    let site = *rng.pick(sites);
    match site {
        (i, None) => {
            let item = f.items[i].clone();
            let at = if rng.one_in(2) {
                i
            } else {
                rng.below(f.items.len())
            };
            f.items.insert(at, item);
        }
        (i, Some(j)) => {
            if let Some(Item::Chunk(c)) = f.items.get_mut(i) {
                c.original = None;
                let r = c.inner[j].clone();
                let at = rng.below(c.inner.len() + 1);
                c.inner.insert(at, r);
            }
        }
    }
}

/// Moves an inner record to the top level, or swaps two top-level items.
fn move_or_swap_record(rng: &mut Rng, f: &mut McapFile, sites: &[Site]) {
    let site = *rng.pick(sites);
    if let (i, Some(j)) = site {
        if let Some(Item::Chunk(c)) = f.items.get_mut(i) {
            c.original = None;
            let r = c.inner.remove(j);
            let at = rng.below(f.items.len());
            f.items.insert(at, Item::Plain(r));
        }
    } else {
        let a = rng.below(f.items.len());
        let b = rng.below(f.items.len());
        f.items.swap(a, b);
    }
}

/// A chunk's compression or times.
fn mutate_chunk_header(rng: &mut Rng, f: &mut McapFile) {
    let chunks: Vec<usize> = (0..f.items.len())
        .filter(|&i| matches!(f.items[i], Item::Chunk(_)))
        .collect();
    if chunks.is_empty() {
        return;
    }
    let i = *rng.pick(&chunks);
    if let Item::Chunk(c) = &mut f.items[i] {
        c.original = None;
        match rng.below(3) {
            0 => {
                c.compression =
                    (*rng.pick(&["", "zstd", "lz4", "gzip", "ZSTD", "zstd\0"])).to_owned()
            }
            1 => c.start = *rng.pick(&INTERESTING_U64),
            _ => c.end = *rng.pick(&INTERESTING_U64),
        }
    }
}

/// An opcode.
fn mutate_opcode(rng: &mut Rng, f: &mut McapFile, sites: &[Site]) {
    let site = *rng.pick(sites);
    let new = *rng.pick(&[
        0x00u8, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x0b, 0x0c, 0x0d, 0x0e, 0x0f,
        0x10, 0x7f, 0x80, 0xff,
    ]);
    if let Some(r) = f.record_mut(site) {
        r.op = new;
    }
}

/// A channel's topic, encoding or schema id.
fn mutate_channel(rng: &mut Rng, f: &mut McapFile) {
    if let Some(r) = pick_record(rng, f, op::CHANNEL) {
        let mut pos = 4;
        let (Some(mut topic), Some(mut enc)) =
            (read_str(&r.body, &mut pos), read_str(&r.body, &mut pos))
        else {
            return;
        };
        let rest = r.body[pos..].to_vec();
        let mut head = r.body[..4].to_vec();
        match rng.below(3) {
            0 => topic = (*rng.pick(&TOPICS)).to_owned(),
            1 => enc = (*rng.pick(&["json", "cbor", "", "protobuf"])).to_owned(),
            _ => {
                let id = rng.below(10) as u16;
                if rng.one_in(2) {
                    head[0..2].copy_from_slice(&id.to_le_bytes());
                } else {
                    head[2..4].copy_from_slice(&id.to_le_bytes());
                }
            }
        }
        let mut body = head;
        put_str(&mut body, &topic);
        put_str(&mut body, &enc);
        body.extend_from_slice(&rest);
        r.body = body;
    }
}

/// A record from another seed file (`others` is not empty).
fn splice_record(rng: &mut Rng, f: &mut McapFile, others: &[McapFile]) {
    let o = rng.pick(others);
    if o.items.is_empty() {
        return;
    }
    let item = o.items[rng.below(o.items.len())].clone();
    let at = rng.below(f.items.len() + 1);
    f.items.insert(at, item);
}

/// Truncates the file's record list (a writer that died), maybe keeping the footer.
fn truncate_records(rng: &mut Rng, f: &mut McapFile) {
    let n = rng.below(f.items.len());
    let footer = f.items.last().cloned();
    f.items.truncate(n);
    if rng.one_in(2) {
        if let Some(ft) = footer {
            f.items.push(ft);
        }
    }
}

/// Changes how CRCs are written: the section CRCs left stale, or a chunk's zero or stale.
fn mutate_crc_mode(rng: &mut Rng, f: &mut McapFile, sites: &[Site]) {
    match rng.below(3) {
        0 => f.fix_section_crcs = false,
        _ => {
            let site = *rng.pick(sites);
            if let Some(Item::Chunk(c)) = f.items.get_mut(site.0) {
                c.original = None;
                c.crc = if rng.one_in(2) {
                    CrcMode::Zero
                } else {
                    CrcMode::Stale(rng.next_u64() as u32)
                };
            }
        }
    }
}

/// Sets every changed chunk with a stale CRC to a recomputed one, except with probability
/// `1 / keep_one_in` per chunk. Called once per input after the mutations.
pub fn fix_crcs(rng: &mut Rng, f: &mut McapFile, keep_one_in: usize) {
    for item in &mut f.items {
        if let Item::Chunk(c) = item {
            if c.original.is_none()
                && matches!(c.crc, CrcMode::Stale(_))
                && !rng.one_in(keep_one_in)
            {
                c.crc = CrcMode::Fix;
            }
        }
    }
}

/// The JSON values of a file's metadata (for splicing into other JSON).
pub fn metadata_json(f: &McapFile) -> Vec<Value> {
    let mut out = Vec::new();
    for s in f.sites_with(op::METADATA) {
        if let Some((_, entries)) = f.record(s).and_then(|r| parse_metadata(&r.body)) {
            out.extend(
                entries
                    .iter()
                    .filter_map(|(_, v)| serde_json::from_str::<Value>(v).ok()),
            );
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rewritten_sessions_keep_valid_crcs_in_every_layout() {
        let dir = tempfile::tempdir().unwrap();
        // `record` rewrites the recording (a fixed `started_at`): the CRCs this module
        // recomputes must satisfy the reader.
        let a = crate::seeds::record("sphere-lift", 1, Some(0.05), dir.path()).unwrap();
        let limits = services::mcap_io::ReadLimits::default();
        services::session::read_session_bytes(&a, "a", &limits).unwrap();
        let f = McapFile::parse(&a).unwrap();
        assert_eq!(f.write(), a, "parse and write is the identity");
        for layout in [f.recompressed(""), f.recompressed("lz4"), f.unchunked()] {
            services::session::read_session_bytes(&layout.write(), "b", &limits).unwrap();
        }
        // A changed message gets a fresh chunk CRC: the reader gets past the CRC check.
        let mut g = f.clone();
        let site = g.sites_with(op::MESSAGE)[0];
        let r = g.record_mut(site).unwrap();
        r.body.truncate(MESSAGE_HEADER);
        r.body.extend_from_slice(b"{not json nor protobuf");
        g.items.iter_mut().for_each(|i| {
            if let Item::Chunk(c) = i {
                c.crc = CrcMode::Fix;
            }
        });
        let e = services::session::read_session_bytes(&g.write(), "g", &limits).unwrap_err();
        assert!(
            !e.to_string().contains("CRC") && e.to_string().contains("message 0"),
            "{e}"
        );
    }
}
