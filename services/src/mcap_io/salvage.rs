//! [`salvage`]: recover what a dead writer left behind.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::Path;

use mcap::records::{MessageHeader, Record};

use super::reader::{scan, Batch, ReadLimits};
use super::writer::WriterOptions;
use crate::error::{RecordingError, Result};

/// What [`salvage`] recovered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SalvageReport {
    /// Messages copied to the output.
    pub messages: u64,
    /// Complete chunks read from the input.
    pub chunks: u64,
    /// Largest log time (ns) among the recovered messages.
    pub last_log_time_ns: Option<u64>,
    /// Bytes of the input after the last complete record (a partial chunk, a torn record, or
    /// anything after a corrupt record), not recovered.
    pub dropped_bytes: u64,
    /// Schemas recovered.
    pub schemas: u64,
    /// Channels recovered.
    pub channels: u64,
    /// Metadata records recovered.
    pub metadata_records: u64,
    /// The input was a complete MCAP file (footer and end magic present).
    pub input_was_complete: bool,
    /// Why reading stopped before the end, if it did (e.g. a truncated chunk or a CRC error).
    pub stop_reason: Option<String>,
}

/// Reads `input` (an MCAP file whose writer may have died: no summary, no footer, perhaps a
/// partial trailing chunk) record by record up to the first incomplete or corrupt record, and
/// writes every complete message, schema, channel, metadata record and attachment to a new,
/// finished MCAP file at `output` (zstd chunks, indexes, summary). A chunk is recovered whole
/// or not at all: its CRC must match.
///
/// Fails if `input` is not an MCAP file, if not one message could be recovered from it (an
/// empty file would read as a recovered one), or if a file cannot be opened or written. The
/// output is written as `OUTPUT.part` and renamed into place when complete: a salvage that
/// fails writes nothing at `output` and leaves a file already there as it was.
pub fn salvage(input: impl AsRef<Path>, output: impl AsRef<Path>) -> Result<SalvageReport> {
    let (input, output) = (input.as_ref(), output.as_ref());
    if let (Ok(a), Ok(b)) = (input.canonicalize(), output.canonicalize()) {
        if a == b {
            return Err(RecordingError::io(
                format!("salvaging {}", input.display()),
                std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    "the output file must not be the input file",
                ),
            ));
        }
    }
    // Written under a temporary name beside the output and renamed over it only when whole:
    // a salvage that fails leaves a file already at `output` as it was.
    let mut part_name = output.file_name().unwrap_or_default().to_os_string();
    part_name.push(".part");
    let part = output.with_file_name(part_name);
    match salvage_into(input, &part) {
        Ok(report) => {
            std::fs::rename(&part, output).map_err(|e| {
                let _ = std::fs::remove_file(&part);
                RecordingError::io(
                    format!("renaming {} to {}", part.display(), output.display()),
                    e,
                )
            })?;
            Ok(report)
        }
        Err(e) => {
            let _ = std::fs::remove_file(&part);
            Err(e)
        }
    }
}

/// [`salvage`] into `output` directly.
fn salvage_into(input: &Path, output: &Path) -> Result<SalvageReport> {
    let file = File::open(input)
        .map_err(|e| RecordingError::io(format!("opening {}", input.display()), e))?;
    let total_len = file
        .metadata()
        .map_err(|e| RecordingError::io(format!("reading {}", input.display()), e))?
        .len();
    let out_file = File::create(output)
        .map_err(|e| RecordingError::io(format!("creating {}", output.display()), e))?;
    let writer = WriterOptions::default()
        .to_mcap()
        .create(BufWriter::new(out_file))?;
    let mut copier = Copier::new(writer);

    let limits = ReadLimits::default();
    let outcome = scan(
        BufReader::with_capacity(1 << 16, file),
        Some(total_len),
        &limits,
        false,
        |batch: Batch| copier.take(batch),
    )?;
    let Copier {
        writer,
        mut report,
        write_error,
        ..
    } = copier;
    if let Some(e) = write_error {
        return Err(e.into());
    }
    report.input_was_complete = outcome.complete;
    report.dropped_bytes = total_len.saturating_sub(outcome.committed_offset);
    if outcome.complete {
        // The end magic follows the footer.
        report.dropped_bytes = report.dropped_bytes.saturating_sub(8);
    }
    report.stop_reason = outcome.error.map(|e| e.to_string());
    if report.messages == 0 {
        // Nothing to keep (a first chunk that cannot be decoded, a writer that died before
        // its first flush): an empty output would read as a recovered file.
        drop(writer);
        let _ = std::fs::remove_file(output);
        return Err(RecordingError::InvalidInput {
            location: format!("salvaging {}", input.display()),
            detail: match report.stop_reason {
                Some(reason) => format!("no message could be recovered: {reason}"),
                None => "the input holds no message".into(),
            },
        });
    }
    finish_output(writer, output)?;
    Ok(report)
}

/// Finishes the salvaged file (summary, footer) and makes it durable.
fn finish_output(mut writer: mcap::Writer<BufWriter<File>>, output: &Path) -> Result<()> {
    writer.finish()?;
    let file = writer.into_inner().into_inner().map_err(|e| {
        RecordingError::io(format!("flushing {}", output.display()), e.into_error())
    })?;
    file.sync_data()
        .map_err(|e| RecordingError::io(format!("syncing {}", output.display()), e))?;
    let mut file = file;
    file.flush()
        .map_err(|e| RecordingError::io(format!("flushing {}", output.display()), e))?;
    Ok(())
}

/// The output side of a salvage: each batch the scan hands over that links up (its channels'
/// schemas and its messages' channels known) is written whole, and counted in the report.
struct Copier {
    /// The output.
    writer: mcap::Writer<BufWriter<File>>,
    /// What was copied so far.
    report: SalvageReport,
    /// Input schema id -> output id.
    schema_ids: HashMap<u16, u16>,
    /// Input channel id -> output id.
    channel_ids: HashMap<u16, u16>,
    /// The output error that stopped the copy, if one did.
    write_error: Option<mcap::McapError>,
}

impl Copier {
    /// Nothing copied yet, into `writer`.
    fn new(writer: mcap::Writer<BufWriter<File>>) -> Self {
        Copier {
            writer,
            report: SalvageReport {
                messages: 0,
                chunks: 0,
                last_log_time_ns: None,
                dropped_bytes: 0,
                schemas: 0,
                channels: 0,
                metadata_records: 0,
                input_was_complete: false,
                stop_reason: None,
            },
            schema_ids: HashMap::new(),
            channel_ids: HashMap::new(),
            write_error: None,
        }
    }

    /// Writes `batch` if the whole of it links up; an error stops the scan (an output error
    /// is kept in `write_error` too).
    fn take(&mut self, batch: Batch) -> Result<()> {
        // Check the whole batch links up before writing any of it.
        self.check_links(&batch)?;
        let offset = batch.offset;
        let result: mcap::McapResult<()> =
            batch.records.into_iter().try_for_each(|r| self.write(r));
        if let Err(e) = result {
            // An output error: stop, and report it as such below.
            let msg = e.to_string();
            self.write_error = Some(e);
            return Err(RecordingError::Corrupt {
                offset,
                detail: format!("writing the salvaged file failed: {msg}"),
            });
        }
        if batch.is_chunk {
            self.report.chunks += 1;
        }
        Ok(())
    }

    /// Whether every channel of `batch` refers to a known schema (or none) and every message
    /// to a known channel, counting those the batch itself brings.
    fn check_links(&self, batch: &Batch) -> Result<()> {
        let offset = batch.offset;
        let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
        let mut new_schemas = std::collections::HashSet::new();
        let mut new_channels = std::collections::HashSet::new();
        for r in &batch.records {
            match r {
                Record::Schema { header, .. } => {
                    new_schemas.insert(header.id);
                }
                Record::Channel(c) => {
                    if c.schema_id != 0
                        && !self.schema_ids.contains_key(&c.schema_id)
                        && !new_schemas.contains(&c.schema_id)
                    {
                        return Err(corrupt(format!(
                            "channel {:?} refers to unknown schema {}",
                            c.topic, c.schema_id
                        )));
                    }
                    new_channels.insert(c.id);
                }
                Record::Message { header, .. }
                    if !self.channel_ids.contains_key(&header.channel_id)
                        && !new_channels.contains(&header.channel_id) =>
                {
                    return Err(corrupt(format!(
                        "message refers to unknown channel {}",
                        header.channel_id
                    )));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Writes one record of a batch that links up (a schema or channel once, under its output
    /// id); records of other kinds are left out.
    fn write(&mut self, r: Record<'static>) -> mcap::McapResult<()> {
        match r {
            Record::Schema { header, data } => {
                if let std::collections::hash_map::Entry::Vacant(e) =
                    self.schema_ids.entry(header.id)
                {
                    let id = self
                        .writer
                        .add_schema(&header.name, &header.encoding, &data)?;
                    e.insert(id);
                    self.report.schemas += 1;
                }
            }
            Record::Channel(c) => {
                if let std::collections::hash_map::Entry::Vacant(e) = self.channel_ids.entry(c.id) {
                    let schema_id = if c.schema_id == 0 {
                        0
                    } else {
                        self.schema_ids[&c.schema_id]
                    };
                    let id = self.writer.add_channel(
                        schema_id,
                        &c.topic,
                        &c.message_encoding,
                        &c.metadata,
                    )?;
                    e.insert(id);
                    self.report.channels += 1;
                }
            }
            Record::Message { header, data } => {
                let out_header = MessageHeader {
                    channel_id: self.channel_ids[&header.channel_id],
                    ..header
                };
                self.writer.write_to_known_channel(&out_header, &data)?;
                self.report.messages += 1;
                self.report.last_log_time_ns = Some(
                    self.report
                        .last_log_time_ns
                        .map_or(header.log_time, |t| t.max(header.log_time)),
                );
            }
            Record::Metadata(m) => {
                self.writer.write_metadata(&m)?;
                self.report.metadata_records += 1;
            }
            // A session's `hand.urdf`, say: kept with its times and media type.
            Record::Attachment { header, data, .. } => {
                self.writer.attach(&mcap::Attachment {
                    log_time: header.log_time,
                    create_time: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                    data,
                })?;
            }
            _ => {}
        }
        Ok(())
    }
}
