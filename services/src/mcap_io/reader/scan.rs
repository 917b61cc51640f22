//! The record scanner shared by the readers and salvage ([`scan`]): frames top-level records
//! itself, so it knows every record's offset and never allocates more than the bytes left.

use super::*;

/// The records that came out of one top-level record (one, or a chunk's content).
pub(crate) struct Batch {
    /// Byte offset of the top-level record.
    pub offset: u64,
    /// Whether the top-level record was a chunk.
    pub is_chunk: bool,
    /// The records, owned.
    pub records: Vec<Record<'static>>,
}

/// How a scan ended.
pub(crate) struct ScanOutcome {
    /// Footer and end magic were read.
    pub complete: bool,
    /// Offset just past the last top-level record whose batch was accepted.
    pub committed_offset: u64,
    /// Why the scan stopped early (bad record, truncation, or an error from the callback).
    pub error: Option<RecordingError>,
}

impl ScanOutcome {
    /// `Ok` for a scan that read the whole file to its footer; its error, or
    /// [`RecordingError::Truncated`] for a file that ends without one.
    pub(super) fn into_result(self) -> Result<()> {
        if let Some(err) = self.error {
            return Err(err);
        }
        if !self.complete {
            return Err(RecordingError::Truncated {
                offset: self.committed_offset,
                detail: "no footer".into(),
            });
        }
        Ok(())
    }
}

pub(super) const OPCODE_LEN_SIZE: u64 = 9;

/// Where a chunk record's `uncompressed_size` lies: after the opcode, the length and the
/// start and end times.
pub(super) const CHUNK_SIZE_AT: usize = OPCODE_LEN_SIZE as usize + 16;

/// Reads `src` record by record, calling `on_batch` with the records of each complete
/// top-level record. With `emit_chunks`, a chunk is handed over whole and still compressed (its
/// bytes are covered by the data section CRC; the caller decompresses it and checks its own
/// CRC); otherwise its records are, after its CRC matched. Stops at the first bad record or callback error and reports it in the
/// outcome; only a bad magic (or an I/O error on the first bytes) is returned as `Err`.
pub(crate) fn scan<R: Read>(
    mut src: R,
    total_len: Option<u64>,
    limits: &ReadLimits,
    emit_chunks: bool,
    mut on_batch: impl FnMut(Batch) -> Result<()>,
) -> Result<ScanOutcome> {
    let mut reader = open_reader(&mut src, limits, emit_chunks)?;
    let mut outcome = ScanOutcome {
        complete: false,
        committed_offset: 8,
        error: None,
    };
    if let Err(err) = scan_records(
        &mut src,
        &mut reader,
        total_len,
        limits,
        &mut on_batch,
        &mut outcome,
    ) {
        outcome.error = Some(err);
    }
    Ok(outcome)
}

/// Checks the MCAP magic at the start of `src` and returns the sans-I/O reader that checks the
/// records, already fed the magic.
fn open_reader<R: Read>(
    src: &mut R,
    limits: &ReadLimits,
    emit_chunks: bool,
) -> Result<LinearReader> {
    let mut magic = [0u8; 8];
    let got =
        read_up_to(src, &mut magic).map_err(|e| RecordingError::io("reading the MCAP magic", e))?;
    if got < magic.len() || magic != *mcap::MAGIC {
        return Err(RecordingError::NotMcap);
    }
    let record_limit = usize::try_from(limits.max_record_bytes).unwrap_or(usize::MAX);
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_prevalidate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(record_limit)
            .with_emit_chunks(emit_chunks),
    );
    // Replaces the built-in zstd decoder: same decoding, window capped at 16 MiB.
    reader.add_decompressor(BoundedZstd::default())?;
    // The data section CRC covers the magic too.
    reader.insert(magic.len()).copy_from_slice(&magic);
    reader.notify_read(magic.len());
    Ok(reader)
}

/// The loop of [`scan`] after the magic: frames each top-level record, checks it, hands it to
/// `reader` and its records to `on_batch`, moving `outcome.committed_offset` past each batch
/// accepted. `Ok` once the footer and the end magic were read; otherwise the error that
/// stopped it.
fn scan_records<R: Read>(
    src: &mut R,
    reader: &mut LinearReader,
    total_len: Option<u64>,
    limits: &ReadLimits,
    on_batch: &mut impl FnMut(Batch) -> Result<()>,
    outcome: &mut ScanOutcome,
) -> Result<()> {
    let mut offset = outcome.committed_offset;
    // Decompressed bytes the chunks so far declare, against what the input's length allows.
    let budget = limits.budget(total_len);
    let mut declared = 0u64;
    // The record being read, in a buffer reused from one read to the next.
    let mut record = PooledBuffer(CHUNK_BUFFERS.take(0));
    let record = &mut record.0;
    loop {
        let (opcode, len) = read_record(src, record, offset, total_len, limits)?;

        // A chunk counts against the decompression budget with the size its header declares,
        // before anything decompresses it; none decompresses past that size.
        if opcode == op::CHUNK {
            if let Some(size) = record.get(CHUNK_SIZE_AT..CHUNK_SIZE_AT + 8) {
                let size = u64::from_le_bytes(size.try_into().expect("8 bytes"));
                declared = declared.saturating_add(size);
                if declared > budget {
                    return Err(limits.over_limit(total_len, offset, declared));
                }
            }
        }

        // Its length-prefixed fields must fit in it: the parser allocates what they declare.
        super::super::lengths::check(opcode, &record[OPCODE_LEN_SIZE as usize..])
            .map_err(|detail| RecordingError::Corrupt { offset, detail })?;

        // Hand the whole record to the sans-I/O reader and drain what it yields.
        reader.insert(record.len()).copy_from_slice(record);
        reader.notify_read(record.len());
        let (batch, is_footer) = drain_batch(reader, offset, opcode == op::CHUNK, limits)?;
        on_batch(batch)?;
        offset += OPCODE_LEN_SIZE + len;
        outcome.committed_offset = offset;
        if is_footer {
            read_end_magic(src, offset)?;
            outcome.complete = true;
            return Ok(());
        }
    }
}

/// Reads the top-level record at `offset` into `record` (its opcode and length too) after
/// checking that its opcode is not reserved and that its length fits both what is left of the
/// input and the record limit; returns its opcode and length.
fn read_record<R: Read>(
    src: &mut R,
    record: &mut Vec<u8>,
    offset: u64,
    total_len: Option<u64>,
    limits: &ReadLimits,
) -> Result<(u8, u64)> {
    // Frame the next top-level record.
    let mut head = [0u8; OPCODE_LEN_SIZE as usize];
    let got = read_up_to(src, &mut head)
        .map_err(|e| RecordingError::io(format!("reading at byte {offset}"), e))?;
    if got == 0 {
        // Clean end of input between records, but no footer: truncated.
        return Err(RecordingError::Truncated {
            offset,
            detail: "file ends without a footer (the writer did not finish)".into(),
        });
    }
    if got < head.len() {
        return Err(RecordingError::Truncated {
            offset,
            detail: "file ends inside a record header".into(),
        });
    }
    let opcode = head[0];
    let len = u64::from_le_bytes(head[1..].try_into().expect("8 bytes"));
    if !known_or_private(opcode) {
        return Err(RecordingError::Corrupt {
            offset,
            detail: format!("reserved record opcode {opcode:#04x}"),
        });
    }
    let remaining = total_len.map(|t| t.saturating_sub(offset + OPCODE_LEN_SIZE));
    if let Some(remaining) = remaining {
        if len > remaining {
            return Err(RecordingError::Truncated {
                offset,
                detail: format!(
                    "record (opcode {opcode:#04x}) claims {len} bytes but only {remaining} remain"
                ),
            });
        }
    }
    limits.check_record_len(offset, opcode, len)?;
    record.clear();
    if total_len.is_some() {
        // Its length is within what the input holds (checked above) and the record
        // limit: room for it at once, not grown by doubling.
        record.reserve(head.len() + len as usize);
    }
    record.extend_from_slice(&head);
    // `take` + `read_to_end` grows the buffer with the data actually present, so a bogus
    // length on a stream of unknown size cannot force a large allocation.
    src.by_ref()
        .take(len)
        .read_to_end(record)
        .map_err(|e| RecordingError::io(format!("reading at byte {offset}"), e))?;
    if (record.len() as u64) < OPCODE_LEN_SIZE + len {
        return Err(RecordingError::Truncated {
            offset,
            detail: format!("file ends inside a record (opcode {opcode:#04x})"),
        });
    }
    Ok((opcode, len))
}

/// Drains what `reader` yields for the top-level record just given it (at `offset`) into a
/// batch; also whether the batch holds the footer.
fn drain_batch(
    reader: &mut LinearReader,
    offset: u64,
    is_chunk: bool,
    limits: &ReadLimits,
) -> Result<(Batch, bool)> {
    let mut batch = Batch {
        offset,
        is_chunk,
        records: Vec::new(),
    };
    let mut is_footer = false;
    while let Some(event) = reader.next_event() {
        match event {
            Ok(LinearReadEvent::ReadRequest(_)) => break,
            Ok(LinearReadEvent::Record { data, opcode }) => {
                is_footer |= push_record(&mut batch, opcode, data, offset, limits)?;
            }
            Err(e) => return Err(map_mcap_error(e, offset, limits)),
        }
    }
    Ok((batch, is_footer))
}

/// Checks and parses one record the reader yielded (from the top-level record at `offset`)
/// and adds it, owned, to `batch`; whether it is the footer.
fn push_record(
    batch: &mut Batch,
    opcode: u8,
    data: &[u8],
    offset: u64,
    limits: &ReadLimits,
) -> Result<bool> {
    // A record from inside a chunk: its fields too must fit in it.
    super::super::lengths::check(opcode, data)
        .map_err(|detail| RecordingError::Corrupt { offset, detail })?;
    match mcap::parse_record(opcode, data) {
        Ok(Record::Unknown { opcode, .. }) if !known_or_private(opcode) => {
            Err(RecordingError::Corrupt {
                offset,
                detail: format!("reserved record opcode {opcode:#04x} in a chunk"),
            })
        }
        Ok(Record::Chunk { header, data }) => {
            // Its compressed bytes into a pooled buffer (the reader of the batch gives it
            // back).
            let mut owned = CHUNK_BUFFERS.take(data.len());
            owned.clear();
            owned.extend_from_slice(&data);
            batch.records.push(Record::Chunk {
                header,
                data: Cow::Owned(owned),
            });
            Ok(false)
        }
        Ok(r) => {
            let is_footer = matches!(r, Record::Footer(_));
            batch.records.push(r.into_owned());
            Ok(is_footer)
        }
        Err(e) => Err(map_mcap_error(e, offset, limits)),
    }
}

/// Reads the magic that must follow the footer (which ends at `offset`).
fn read_end_magic<R: Read>(src: &mut R, offset: u64) -> Result<()> {
    let mut end = [0u8; 8];
    let got = read_up_to(src, &mut end).unwrap_or(0);
    if got == end.len() && end == *mcap::MAGIC {
        Ok(())
    } else {
        Err(RecordingError::Truncated {
            offset,
            detail: "footer is not followed by the MCAP magic".into(),
        })
    }
}

/// A buffer given back to [`CHUNK_BUFFERS`] when dropped.
pub(super) struct PooledBuffer(Vec<u8>);

impl Drop for PooledBuffer {
    fn drop(&mut self) {
        CHUNK_BUFFERS.give(std::mem::take(&mut self.0));
    }
}

/// Opcodes defined by the MCAP spec (0x01..=0x0f) or private (>= 0x80). Anything else is
/// reserved: in a file we read, it means a damaged opcode byte, and skipping the record (as the
/// spec allows for unknown records) would silently drop a whole chunk.
pub(super) fn known_or_private(opcode: u8) -> bool {
    (0x01..=0x0f).contains(&opcode) || opcode >= 0x80
}

pub(super) fn map_mcap_error(e: McapError, offset: u64, limits: &ReadLimits) -> RecordingError {
    match e {
        McapError::BadChunkCrc { saved, calculated } => RecordingError::ChunkCrcMismatch {
            offset,
            saved,
            calculated,
        },
        McapError::RecordTooLarge { opcode, len } => RecordingError::RecordTooLong {
            offset,
            opcode,
            len,
            limit: limits.max_record_bytes,
        },
        McapError::ChunkTooLarge(len) => RecordingError::RecordTooLong {
            offset,
            opcode: op::CHUNK,
            len,
            limit: limits.max_record_bytes,
        },
        McapError::BadDataCrc { saved, calculated } => RecordingError::Corrupt {
            offset,
            detail: format!(
                "data section CRC mismatch (stored {saved:08x}, computed {calculated:08x})"
            ),
        },
        McapError::BadSummaryCrc { saved, calculated } => RecordingError::Corrupt {
            offset,
            detail: format!(
                "summary section CRC mismatch (stored {saved:08x}, computed {calculated:08x})"
            ),
        },
        McapError::UnexpectedEof => RecordingError::Truncated {
            offset,
            detail: "record ends early".into(),
        },
        other => RecordingError::Corrupt {
            offset,
            detail: other.to_string(),
        },
    }
}

/// Reads until `buf` is full or the input ends; returns the bytes read.
pub(super) fn read_up_to<R: Read>(src: &mut R, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match src.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}
