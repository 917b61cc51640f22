//! One chunk: its records framed, its content decompressed within the budget and checked
//! against its CRC ([`unpack_chunk`]).

use super::*;

/// Chunks read and decompressed ahead of the one being filed by [`stream_raw`].
pub(super) const STREAM_CHUNKS_AHEAD: usize = 2;

/// Decompressed chunk buffers [`stream_raw`]'s calling thread hands back for reuse, at most
/// (with those in flight, the buffers it holds stay a few chunks' worth).
pub(super) const RECYCLED_BUFFERS: usize = 2;

/// Most topics a file may have (ours has nine).
pub(super) const MAX_TOPICS: usize = 1024;

/// A chunk decompressed, checked and split into records: its content, and its records other
/// than messages, parsed, in order (messages, most of a chunk, are framed again from `data`
/// when the session is built: a list of them for every chunk at once would hold 48 bytes per
/// message on top of the data).
pub(super) struct ChunkContent {
    pub(super) data: Vec<u8>,
    pub(super) others: Vec<Record<'static>>,
}

/// zstd's name for the error of an output buffer too small for the frame (stable across zstd
/// versions; were it to change, such a chunk would still be refused, as "zstd: <name>").
pub(super) const ZSTD_DST_TOO_SMALL: &str = "Destination buffer is too small";

/// Length of a message record's header: channel id, sequence, log time, publish time.
pub(super) const MESSAGE_HEADER_LEN: usize = 2 + 4 + 8 + 8;

/// Decompresses the chunk at `offset` into a buffer of its declared size (at most
/// [`ReadLimits::max_record_bytes`]; single-pass zstd decoding allocates nothing more, so no
/// window can be forced on us, and an lz4 frame is read to one byte past that size at most),
/// checks its CRC, and frames its records. Compressions: zstd, lz4, none.
pub(super) fn unpack_chunk(
    offset: u64,
    header: &ChunkHeader,
    compressed: &[u8],
    limits: &ReadLimits,
    dctx: &mut Option<zstd::zstd_safe::DCtx<'static>>,
    reuse: Option<Vec<u8>>,
) -> Result<ChunkContent> {
    let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
    limits.check_record_len(offset, op::CHUNK, header.uncompressed_size)?;
    let size = header.uncompressed_size as usize;
    let data = match header.compression.as_str() {
        "" => {
            let mut out = reuse.unwrap_or_default();
            out.clear();
            out.extend_from_slice(compressed);
            out
        }
        "zstd" => decompress_zstd(offset, compressed, size, dctx, reuse)?,
        "lz4" => decompress_lz4(offset, compressed, size, reuse)?,
        other => {
            return Err(corrupt(format!(
                "unsupported compression {other:?} (supported: zstd, lz4, none)"
            )))
        }
    };
    check_content(offset, header, &data)?;
    let others = parse_others(&data, offset, limits)?;
    Ok(ChunkContent { data, others })
}

/// The error of a chunk at `offset` whose header declares less than the content holds:
/// decompression stops at the declared `size` (which the reader counted against its budget),
/// never past it.
fn chunk_overflows(offset: u64, size: usize) -> RecordingError {
    RecordingError::Corrupt {
        offset,
        detail: format!("chunk decompresses to more than the {size} bytes its header declares"),
    }
}

/// Decompresses a zstd chunk (at `offset`) of declared `size` (at most
/// [`ReadLimits::max_record_bytes`]).
///
/// Single-pass decoding into exactly the declared size: zstd fails rather than write past it.
/// The context is the caller's, reused from chunk to chunk (its window limit is a sticky
/// parameter; each frame starts afresh), and the buffer is one handed back or pooled if one is
/// big enough (its pages already mapped; the caller checked the size against the limit).
fn decompress_zstd(
    offset: u64,
    compressed: &[u8],
    size: usize,
    dctx: &mut Option<zstd::zstd_safe::DCtx<'static>>,
    reuse: Option<Vec<u8>>,
) -> Result<Vec<u8>> {
    let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
    let mut out = match reuse {
        Some(buffer) if buffer.capacity() >= size => buffer,
        Some(small) => {
            CHUNK_BUFFERS.give(small);
            CHUNK_BUFFERS.take(size)
        }
        None => CHUNK_BUFFERS.take(size),
    };
    let dctx = bounded_dctx(dctx).map_err(|name| corrupt(format!("zstd: {name}")))?;
    let written = if out.capacity() == size {
        // Into its spare capacity, exactly the declared size: nothing to zero first.
        out.clear();
        dctx.decompress(&mut out, compressed)
    } else {
        // A bigger buffer: into its first `size` bytes (only what its previous content
        // lacks of them is zeroed).
        out.resize(size, 0);
        dctx.decompress(&mut out[..], compressed)
    }
    .map_err(|code| match zstd::zstd_safe::get_error_name(code) {
        ZSTD_DST_TOO_SMALL => chunk_overflows(offset, size),
        name => corrupt(format!("zstd: {name}")),
    })?;
    out.truncate(written);
    Ok(out)
}

/// Decompresses an LZ4 frame chunk (at `offset`) of declared `size`, read to at most one byte
/// past that size: a chunk that decodes to more is refused there, before it can grow without
/// bound.
fn decompress_lz4(
    offset: u64,
    compressed: &[u8],
    size: usize,
    reuse: Option<Vec<u8>>,
) -> Result<Vec<u8>> {
    let mut out = reuse.unwrap_or_default();
    out.clear();
    lz4::Decoder::new(compressed)
        .and_then(|d| d.take(size as u64 + 1).read_to_end(&mut out))
        .map_err(|e| RecordingError::Corrupt {
            offset,
            detail: format!("lz4: {e}"),
        })?;
    if out.len() > size {
        return Err(chunk_overflows(offset, size));
    }
    Ok(out)
}

/// Checks a decompressed chunk's content (the chunk at `offset`) against the size and the
/// CRC (unless zero) its header declares.
fn check_content(offset: u64, header: &ChunkHeader, data: &[u8]) -> Result<()> {
    let size = header.uncompressed_size as usize;
    if data.len() != size {
        return Err(RecordingError::Corrupt {
            offset,
            detail: format!(
                "chunk content is {} bytes, its header says {size}",
                data.len()
            ),
        });
    }
    if header.uncompressed_crc != 0 {
        let calculated = crc32fast::hash(data);
        if calculated != header.uncompressed_crc {
            return Err(RecordingError::ChunkCrcMismatch {
                offset,
                saved: header.uncompressed_crc,
                calculated,
            });
        }
    }
    Ok(())
}

/// Frames the records of the content `data` of the chunk at `offset`: checks each message is
/// as long as its header, and parses the others (in order).
fn parse_others(data: &[u8], offset: u64, limits: &ReadLimits) -> Result<Vec<Record<'static>>> {
    let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
    let mut others = Vec::new();
    let mut pos = 0usize;
    while let Some((opcode, start, end)) = next_chunk_record(data, pos, offset, limits)? {
        let body = &data[start..end];
        if opcode == op::MESSAGE {
            if body.len() < MESSAGE_HEADER_LEN {
                return Err(corrupt("message record shorter than its header".into()));
            }
        } else {
            super::super::lengths::check(opcode, body).map_err(corrupt)?;
            match mcap::parse_record(opcode, body) {
                Ok(Record::Unknown { opcode, .. }) if !known_or_private(opcode) => {
                    return Err(corrupt(format!(
                        "reserved record opcode {opcode:#04x} in a chunk"
                    )));
                }
                Ok(Record::Chunk { .. }) => {
                    return Err(corrupt("a chunk inside a chunk".into()));
                }
                Ok(r) => others.push(r.into_owned()),
                Err(e) => return Err(map_mcap_error(e, offset, limits)),
            }
        }
        pos = end;
    }
    Ok(others)
}

/// The record of chunk content `data` that starts at `pos`: its opcode and where its body lies
/// (`None` at the end). The errors name the chunk at `offset`.
pub(super) fn next_chunk_record(
    data: &[u8],
    pos: usize,
    offset: u64,
    limits: &ReadLimits,
) -> Result<Option<(u8, usize, usize)>> {
    let Some(rest) = data.get(pos..).filter(|r| !r.is_empty()) else {
        return Ok(None);
    };
    let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
    if rest.len() < OPCODE_LEN_SIZE as usize {
        return Err(corrupt("chunk content ends inside a record header".into()));
    }
    let opcode = rest[0];
    let len = u64::from_le_bytes(rest[1..9].try_into().expect("8 bytes"));
    limits.check_record_len(offset, opcode, len)?;
    let available = (rest.len() - OPCODE_LEN_SIZE as usize) as u64;
    if len > available {
        return Err(corrupt(format!(
            "record (opcode {opcode:#04x}) in a chunk claims {len} bytes but only {available} \
             remain"
        )));
    }
    let start = pos + OPCODE_LEN_SIZE as usize;
    Ok(Some((opcode, start, start + len as usize)))
}

/// The header of a message record whose body (at least [`MESSAGE_HEADER_LEN`] bytes) is
/// `body`.
pub(super) fn message_header(body: &[u8]) -> MessageHeader {
    let u16_at = |i: usize| u16::from_le_bytes(body[i..i + 2].try_into().expect("2 bytes"));
    let u32_at = |i: usize| u32::from_le_bytes(body[i..i + 4].try_into().expect("4 bytes"));
    let u64_at = |i: usize| u64::from_le_bytes(body[i..i + 8].try_into().expect("8 bytes"));
    MessageHeader {
        channel_id: u16_at(0),
        sequence: u32_at(2),
        log_time: u64_at(6),
        publish_time: u64_at(14),
    }
}
