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
    let mut magic = [0u8; 8];
    let got = read_up_to(&mut src, &mut magic)
        .map_err(|e| RecordingError::io("reading the MCAP magic", e))?;
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
    let mut offset = 8u64;
    let mut outcome = ScanOutcome {
        complete: false,
        committed_offset: offset,
        error: None,
    };
    // Decompressed bytes the chunks so far declare, against what the input's length allows.
    let budget = limits.budget(total_len);
    let mut declared = 0u64;
    // The record being read, in a buffer reused from one read to the next.
    let mut record = PooledBuffer(CHUNK_BUFFERS.take(0));
    let record = &mut record.0;
    loop {
        // Frame the next top-level record.
        let mut head = [0u8; OPCODE_LEN_SIZE as usize];
        let got = match read_up_to(&mut src, &mut head) {
            Ok(n) => n,
            Err(e) => {
                outcome.error = Some(RecordingError::io(format!("reading at byte {offset}"), e));
                return Ok(outcome);
            }
        };
        if got == 0 {
            // Clean end of input between records, but no footer: truncated.
            outcome.error = Some(RecordingError::Truncated {
                offset,
                detail: "file ends without a footer (the writer did not finish)".into(),
            });
            return Ok(outcome);
        }
        if got < head.len() {
            outcome.error = Some(RecordingError::Truncated {
                offset,
                detail: "file ends inside a record header".into(),
            });
            return Ok(outcome);
        }
        let opcode = head[0];
        let len = u64::from_le_bytes(head[1..].try_into().expect("8 bytes"));
        if !known_or_private(opcode) {
            outcome.error = Some(RecordingError::Corrupt {
                offset,
                detail: format!("reserved record opcode {opcode:#04x}"),
            });
            return Ok(outcome);
        }
        let remaining = total_len.map(|t| t.saturating_sub(offset + OPCODE_LEN_SIZE));
        if let Some(remaining) = remaining {
            if len > remaining {
                outcome.error = Some(RecordingError::Truncated {
                    offset,
                    detail: format!(
                        "record (opcode {opcode:#04x}) claims {len} bytes but only {remaining} remain"
                    ),
                });
                return Ok(outcome);
            }
        }
        if len > limits.max_record_bytes {
            outcome.error = Some(RecordingError::RecordTooLong {
                offset,
                opcode,
                len,
                limit: limits.max_record_bytes,
            });
            return Ok(outcome);
        }
        record.clear();
        if total_len.is_some() {
            // Its length is within what the input holds (checked above) and the record
            // limit: room for it at once, not grown by doubling.
            record.reserve(head.len() + len as usize);
        }
        record.extend_from_slice(&head);
        // `take` + `read_to_end` grows the buffer with the data actually present, so a bogus
        // length on a stream of unknown size cannot force a large allocation.
        if let Err(e) = (&mut src).take(len).read_to_end(record) {
            outcome.error = Some(RecordingError::io(format!("reading at byte {offset}"), e));
            return Ok(outcome);
        }
        if (record.len() as u64) < OPCODE_LEN_SIZE + len {
            outcome.error = Some(RecordingError::Truncated {
                offset,
                detail: format!("file ends inside a record (opcode {opcode:#04x})"),
            });
            return Ok(outcome);
        }

        // A chunk counts against the decompression budget with the size its header declares,
        // before anything decompresses it; none decompresses past that size.
        if opcode == op::CHUNK {
            if let Some(size) = record.get(CHUNK_SIZE_AT..CHUNK_SIZE_AT + 8) {
                let size = u64::from_le_bytes(size.try_into().expect("8 bytes"));
                declared = declared.saturating_add(size);
                if declared > budget {
                    outcome.error = Some(limits.over_limit(total_len, offset, declared));
                    return Ok(outcome);
                }
            }
        }

        // Its length-prefixed fields must fit in it: the parser allocates what they declare.
        if let Err(detail) =
            super::super::lengths::check(opcode, &record[OPCODE_LEN_SIZE as usize..])
        {
            outcome.error = Some(RecordingError::Corrupt { offset, detail });
            return Ok(outcome);
        }

        // Hand the whole record to the sans-I/O reader and drain what it yields.
        reader.insert(record.len()).copy_from_slice(record);
        reader.notify_read(record.len());
        let mut batch = Batch {
            offset,
            is_chunk: opcode == op::CHUNK,
            records: Vec::new(),
        };
        let mut is_footer = false;
        let mut failure = None;
        while let Some(event) = reader.next_event() {
            match event {
                Ok(LinearReadEvent::ReadRequest(_)) => break,
                Ok(LinearReadEvent::Record { data, opcode }) => {
                    // A record from inside a chunk: its fields too must fit in it.
                    if let Err(detail) = super::super::lengths::check(opcode, data) {
                        failure = Some(RecordingError::Corrupt { offset, detail });
                        break;
                    }
                    match mcap::parse_record(opcode, data) {
                        Ok(Record::Unknown { opcode, .. }) if !known_or_private(opcode) => {
                            failure = Some(RecordingError::Corrupt {
                                offset,
                                detail: format!("reserved record opcode {opcode:#04x} in a chunk"),
                            });
                            break;
                        }
                        Ok(Record::Chunk { header, data }) => {
                            // Its compressed bytes into a pooled buffer (the reader of the
                            // batch gives it back).
                            let mut owned = CHUNK_BUFFERS.take(data.len());
                            owned.clear();
                            owned.extend_from_slice(&data);
                            batch.records.push(Record::Chunk {
                                header,
                                data: Cow::Owned(owned),
                            });
                        }
                        Ok(r) => {
                            is_footer |= matches!(r, Record::Footer(_));
                            batch.records.push(r.into_owned());
                        }
                        Err(e) => {
                            failure = Some(map_mcap_error(e, offset, limits));
                            break;
                        }
                    }
                }
                Err(e) => {
                    failure = Some(map_mcap_error(e, offset, limits));
                    break;
                }
            }
        }
        if let Some(err) = failure {
            outcome.error = Some(err);
            return Ok(outcome);
        }
        if let Err(err) = on_batch(batch) {
            outcome.error = Some(err);
            return Ok(outcome);
        }
        offset += OPCODE_LEN_SIZE + len;
        outcome.committed_offset = offset;
        if is_footer {
            let mut end = [0u8; 8];
            let got = read_up_to(&mut src, &mut end).unwrap_or(0);
            if got == end.len() && end == *mcap::MAGIC {
                outcome.complete = true;
            } else {
                outcome.error = Some(RecordingError::Truncated {
                    offset,
                    detail: "footer is not followed by the MCAP magic".into(),
                });
            }
            return Ok(outcome);
        }
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
