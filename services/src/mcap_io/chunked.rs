//! [`ChunkedWriter`]: the MCAP records of a session, written into any [`Write`], each chunk
//! built uncompressed in memory and compressed in one call.
//!
//! Why our own writer rather than the `mcap` crate's (which `salvage` still uses): the crate
//! compresses a chunk as a zstd *stream*, record field by record field, and at 1 kHz that is a
//! few hundred thousand small writes a minute, each a call through the streaming API. On the
//! recorder's writer thread (60 s `sphere-lift`, 52.6 MB of records, zstd level 3, perf,
//! 2026-11-25) the crate spent 0.21 s of CPU, 0.15 s of it in zstd, which was more than the
//! simulation it records (0.18 s): recording cost 1.5-1.65 × the simulation alone. The same
//! records compressed in one call per 1 MiB chunk take 0.11 s (the `zstd` command-line
//! library, `ZSTD_compress`, same level), and appending a record to a `Vec` costs next to
//! nothing; see BENCHMARKS.md, "Recording". A chunk in memory also means the output needs only
//! [`Write`], not `Seek`: the recorder can write into a file, a socket or a blob store's
//! staging file alike.
//!
//! What is written (MCAP spec, <https://mcap.dev/spec>): magic, header; schema and channel
//! records in the data section, before their first message; zstd chunks (or uncompressed ones)
//! of message records, each followed by its message indexes when asked; metadata and
//! attachment records between chunks; data end with the data section's CRC; a summary with
//! schemas, channels, statistics, chunk, attachment and metadata indexes and summary offsets;
//! the footer with the summary's CRC; magic. Every chunk carries the CRC of its uncompressed
//! records. Readers: ours, the `mcap` crate's, the Python `mcap` reader and Foxglove
//! (tests/python_reader.rs and the tests below hold the writer to the first three).

use std::collections::BTreeMap;
use std::io::{self, Write};

use mcap::records::op;

/// The MCAP magic, at both ends of a file.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// How a [`ChunkedWriter`] lays out its chunks.
#[derive(Debug, Clone)]
pub(crate) struct ChunkOptions {
    /// zstd level, `None` for uncompressed chunks (`0` is zstd's default, 3).
    pub zstd_level: Option<i32>,
    /// A chunk is closed once its records reach this many bytes.
    pub chunk_size: usize,
    /// Write the message index records after each chunk.
    pub message_indexes: bool,
    /// The header's `profile` and `library`.
    pub profile: String,
    pub library: String,
}

/// Little-endian MCAP primitives appended to a byte buffer.
trait Put {
    fn u16(&mut self, v: u16);
    fn u32(&mut self, v: u32);
    fn u64(&mut self, v: u64);
    fn string(&mut self, s: &str);
    /// A `Map<string, string>`: its byte length, then the pairs.
    fn string_map(&mut self, map: &BTreeMap<String, String>);
    /// Opens a record: the opcode and a length to patch with [`Put::end_record`].
    fn start_record(&mut self, opcode: u8) -> usize;
    fn end_record(&mut self, start: usize);
}

impl Put for Vec<u8> {
    fn u16(&mut self, v: u16) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.extend_from_slice(s.as_bytes());
    }
    fn string_map(&mut self, map: &BTreeMap<String, String>) {
        let len: usize = map.iter().map(|(k, v)| 8 + k.len() + v.len()).sum();
        self.u32(len as u32);
        for (k, v) in map {
            self.string(k);
            self.string(v);
        }
    }
    fn start_record(&mut self, opcode: u8) -> usize {
        self.push(opcode);
        self.u64(0);
        self.len()
    }
    fn end_record(&mut self, start: usize) {
        let len = (self.len() - start) as u64;
        self[start - 8..start].copy_from_slice(&len.to_le_bytes());
    }
}

/// The output, counting what was written and taking the data section's CRC as it goes.
struct Counted<W> {
    inner: W,
    position: u64,
    crc: crc32fast::Hasher,
}

impl<W: Write> Counted<W> {
    fn write(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.inner.write_all(bytes)?;
        self.crc.update(bytes);
        self.position += bytes.len() as u64;
        Ok(())
    }
}

struct Schema {
    id: u16,
    name: String,
    encoding: String,
    data: Vec<u8>,
}

struct Channel {
    id: u16,
    schema_id: u16,
    topic: String,
    message_encoding: String,
    metadata: BTreeMap<String, String>,
}

/// An MCAP file being written (see the module docs). Call [`finish`](Self::finish) to write
/// the summary and footer; [`abandon`](Self::abandon) leaves the file as a crash would.
pub(crate) struct ChunkedWriter<W: Write> {
    out: Counted<W>,
    options: ChunkOptions,
    compressor: Option<zstd::bulk::Compressor<'static>>,
    /// Small records on their way out (schemas, channels, metadata, indexes).
    scratch: Vec<u8>,
    /// The open chunk's records, uncompressed, and its log time range.
    chunk: Vec<u8>,
    chunk_times: Option<(u64, u64)>,
    /// Per channel id, the open chunk's (log time, record offset) pairs, when indexing.
    message_index: BTreeMap<u16, Vec<(u64, u64)>>,
    compressed: Vec<u8>,
    schemas: Vec<Schema>,
    channels: Vec<Channel>,
    /// Index records for the summary, serialised as they are made.
    chunk_indexes: Vec<u8>,
    attachment_indexes: Vec<u8>,
    metadata_indexes: Vec<u8>,
    chunk_count: u32,
    attachment_count: u32,
    metadata_count: u32,
    channel_counts: BTreeMap<u16, u64>,
    message_times: Option<(u64, u64)>,
}

impl<W: Write> ChunkedWriter<W> {
    /// Writes the magic and the header into `out`.
    pub fn new(out: W, options: ChunkOptions) -> io::Result<Self> {
        let compressor = match options.zstd_level {
            Some(level) => Some(zstd::bulk::Compressor::new(level)?),
            None => None,
        };
        let mut w = Self {
            out: Counted {
                inner: out,
                position: 0,
                crc: crc32fast::Hasher::new(),
            },
            compressor,
            scratch: Vec::new(),
            chunk: Vec::with_capacity(options.chunk_size + 4096),
            chunk_times: None,
            message_index: BTreeMap::new(),
            compressed: Vec::new(),
            schemas: Vec::new(),
            channels: Vec::new(),
            chunk_indexes: Vec::new(),
            attachment_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            chunk_count: 0,
            attachment_count: 0,
            metadata_count: 0,
            channel_counts: BTreeMap::new(),
            message_times: None,
            options,
        };
        w.out.write(MAGIC)?;
        let s = &mut w.scratch;
        let start = s.start_record(op::HEADER);
        s.string(&w.options.profile);
        s.string(&w.options.library);
        s.end_record(start);
        w.write_scratch()?;
        Ok(w)
    }

    fn write_scratch(&mut self) -> io::Result<()> {
        let result = self.out.write(&self.scratch);
        self.scratch.clear();
        result
    }

    /// Adds a schema and returns its id; a schema identical to one added before gets that
    /// one's id (as the `mcap` crate does).
    pub fn add_schema(&mut self, name: &str, encoding: &str, data: &[u8]) -> io::Result<u16> {
        if let Some(s) = self
            .schemas
            .iter()
            .find(|s| s.name == name && s.encoding == encoding && s.data == data)
        {
            return Ok(s.id);
        }
        let id = u16::try_from(self.schemas.len() + 1)
            .map_err(|_| io::Error::other("more than 65535 schemas"))?;
        let schema = Schema {
            id,
            name: name.to_owned(),
            encoding: encoding.to_owned(),
            data: data.to_vec(),
        };
        put_schema(&mut self.scratch, &schema);
        self.write_scratch()?;
        self.schemas.push(schema);
        Ok(id)
    }

    /// Adds a channel on `schema_id` (0: none) and returns its id.
    pub fn add_channel(
        &mut self,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> io::Result<u16> {
        if schema_id != 0 && !self.schemas.iter().any(|s| s.id == schema_id) {
            return Err(io::Error::other(format!("no schema {schema_id}")));
        }
        let id = u16::try_from(self.channels.len() + 1)
            .map_err(|_| io::Error::other("more than 65535 channels"))?;
        let channel = Channel {
            id,
            schema_id,
            topic: topic.to_owned(),
            message_encoding: message_encoding.to_owned(),
            metadata: metadata.clone(),
        };
        put_channel(&mut self.scratch, &channel);
        self.write_scratch()?;
        self.channels.push(channel);
        Ok(id)
    }

    /// Appends a message record to the open chunk, closing the chunk once it is full. The
    /// caller vouches for `channel_id` (an id [`add_channel`](Self::add_channel) returned).
    pub fn write_message(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> io::Result<()> {
        let offset = self.chunk.len() as u64;
        let c = &mut self.chunk;
        c.push(op::MESSAGE);
        c.u64(22 + data.len() as u64);
        c.u16(channel_id);
        c.u32(sequence);
        c.u64(log_time);
        c.u64(publish_time);
        c.extend_from_slice(data);
        self.chunk_times = Some(match self.chunk_times {
            None => (log_time, log_time),
            Some((lo, hi)) => (lo.min(log_time), hi.max(log_time)),
        });
        if self.options.message_indexes {
            self.message_index
                .entry(channel_id)
                .or_default()
                .push((log_time, offset));
        }
        *self.channel_counts.entry(channel_id).or_insert(0) += 1;
        self.message_times = Some(match self.message_times {
            None => (log_time, log_time),
            Some((lo, hi)) => (lo.min(log_time), hi.max(log_time)),
        });
        if self.chunk.len() >= self.options.chunk_size {
            self.close_chunk()?;
        }
        Ok(())
    }

    /// The open chunk's record (compressed as the options say) into `self.compressed`; its
    /// uncompressed CRC, compression name and compressed size.
    fn build_chunk_record(&mut self) -> io::Result<(&'static str, u64)> {
        let (start, end) = self.chunk_times.unwrap_or((0, 0));
        let crc = crc32fast::hash(&self.chunk);
        let out = &mut self.compressed;
        out.clear();
        let record = out.start_record(op::CHUNK);
        out.u64(start);
        out.u64(end);
        out.u64(self.chunk.len() as u64);
        out.u32(crc);
        let compression = match self.compressor {
            Some(_) => "zstd",
            None => "",
        };
        out.string(compression);
        let len_at = out.len();
        out.u64(0);
        let data_start = out.len();
        match &mut self.compressor {
            Some(z) => {
                out.reserve(zstd::zstd_safe::compress_bound(self.chunk.len()));
                // Compressed straight after the header, into the reserved capacity.
                let mut tail = io::Cursor::new(&mut *out);
                tail.set_position(data_start as u64);
                z.compress_to_buffer(&self.chunk, &mut tail)?;
            }
            None => out.extend_from_slice(&self.chunk),
        }
        let size = (out.len() - data_start) as u64;
        out[len_at..len_at + 8].copy_from_slice(&size.to_le_bytes());
        out.end_record(record);
        Ok((compression, size))
    }

    /// Compresses and writes the open chunk, its message indexes and its chunk index entry.
    pub fn close_chunk(&mut self) -> io::Result<()> {
        if self.chunk.is_empty() {
            return Ok(());
        }
        let (compression, compressed_size) = self.build_chunk_record()?;
        let chunk_start = self.out.position;
        let compressed = std::mem::take(&mut self.compressed);
        let written = self.out.write(&compressed);
        self.compressed = compressed;
        written?;
        let chunk_length = self.out.position - chunk_start;
        let mut index_offsets = BTreeMap::new();
        let index_start = self.out.position;
        for (channel, entries) in std::mem::take(&mut self.message_index) {
            index_offsets.insert(channel, self.out.position + self.scratch.len() as u64);
            let s = &mut self.scratch;
            let start = s.start_record(op::MESSAGE_INDEX);
            s.u16(channel);
            s.u32((entries.len() * 16) as u32);
            for (time, offset) in entries {
                s.u64(time);
                s.u64(offset);
            }
            s.end_record(start);
        }
        self.write_scratch()?;
        let index_length = self.out.position - index_start;
        let (start, end) = self.chunk_times.take().unwrap_or((0, 0));
        let c = &mut self.chunk_indexes;
        let record = c.start_record(op::CHUNK_INDEX);
        c.u64(start);
        c.u64(end);
        c.u64(chunk_start);
        c.u64(chunk_length);
        c.u32((index_offsets.len() * 10) as u32);
        for (channel, offset) in index_offsets {
            c.u16(channel);
            c.u64(offset);
        }
        c.u64(index_length);
        c.string(compression);
        c.u64(compressed_size);
        c.u64(self.chunk.len() as u64);
        c.end_record(record);
        self.chunk_count += 1;
        self.chunk.clear();
        Ok(())
    }

    /// Closes the open chunk and flushes the output.
    pub fn flush(&mut self) -> io::Result<()> {
        self.close_chunk()?;
        self.out.inner.flush()
    }

    /// Writes a metadata record (closing the open chunk first).
    pub fn write_metadata(
        &mut self,
        name: &str,
        metadata: &BTreeMap<String, String>,
    ) -> io::Result<()> {
        self.close_chunk()?;
        let offset = self.out.position;
        let s = &mut self.scratch;
        let start = s.start_record(op::METADATA);
        s.string(name);
        s.string_map(metadata);
        s.end_record(start);
        let length = s.len() as u64;
        self.write_scratch()?;
        let m = &mut self.metadata_indexes;
        let start = m.start_record(op::METADATA_INDEX);
        m.u64(offset);
        m.u64(length);
        m.string(name);
        m.end_record(start);
        self.metadata_count += 1;
        Ok(())
    }

    /// Writes an attachment record (closing the open chunk first).
    pub fn attach(
        &mut self,
        log_time: u64,
        create_time: u64,
        name: &str,
        media_type: &str,
        data: &[u8],
    ) -> io::Result<()> {
        self.close_chunk()?;
        let offset = self.out.position;
        let s = &mut self.scratch;
        let start = s.start_record(op::ATTACHMENT);
        s.u64(log_time);
        s.u64(create_time);
        s.string(name);
        s.string(media_type);
        s.u64(data.len() as u64);
        s.extend_from_slice(data);
        let crc = crc32fast::hash(&s[start..]);
        s.u32(crc);
        s.end_record(start);
        let length = s.len() as u64;
        self.write_scratch()?;
        let a = &mut self.attachment_indexes;
        let start = a.start_record(op::ATTACHMENT_INDEX);
        a.u64(offset);
        a.u64(length);
        a.u64(log_time);
        a.u64(create_time);
        a.u64(data.len() as u64);
        a.string(name);
        a.string(media_type);
        a.end_record(start);
        self.attachment_count += 1;
        Ok(())
    }

    /// Closes the open chunk and writes the data end, the summary, the footer and the magic.
    /// Returns the output and the number of chunks.
    pub fn finish(mut self) -> io::Result<(W, u64)> {
        self.close_chunk()?;
        let crc = self.out.crc.clone().finalize();
        let s = &mut self.scratch;
        let start = s.start_record(op::DATA_END);
        s.u32(crc);
        s.end_record(start);
        self.write_scratch()?;

        // The summary, built in memory: its CRC runs into the footer.
        let summary_start = self.out.position;
        let mut summary = Vec::new();
        let mut offsets = Vec::new();
        let mut group = |summary: &mut Vec<u8>, opcode: u8, fill: &mut dyn FnMut(&mut Vec<u8>)| {
            let from = summary.len();
            fill(summary);
            if summary.len() > from {
                offsets.push((
                    opcode,
                    summary_start + from as u64,
                    (summary.len() - from) as u64,
                ));
            }
        };
        group(&mut summary, op::SCHEMA, &mut |s| {
            self.schemas.iter().for_each(|x| put_schema(s, x))
        });
        group(&mut summary, op::CHANNEL, &mut |s| {
            self.channels.iter().for_each(|x| put_channel(s, x))
        });
        group(&mut summary, op::STATISTICS, &mut |s| {
            let (first, last) = self.message_times.unwrap_or((0, 0));
            let start = s.start_record(op::STATISTICS);
            s.u64(self.channel_counts.values().sum());
            s.u16(self.schemas.len() as u16);
            s.u32(self.channels.len() as u32);
            s.u32(self.attachment_count);
            s.u32(self.metadata_count);
            s.u32(self.chunk_count);
            s.u64(first);
            s.u64(last);
            s.u32((self.channel_counts.len() * 10) as u32);
            for (&channel, &count) in &self.channel_counts {
                s.u16(channel);
                s.u64(count);
            }
            s.end_record(start);
        });
        group(&mut summary, op::CHUNK_INDEX, &mut |s| {
            s.extend_from_slice(&self.chunk_indexes)
        });
        group(&mut summary, op::ATTACHMENT_INDEX, &mut |s| {
            s.extend_from_slice(&self.attachment_indexes)
        });
        group(&mut summary, op::METADATA_INDEX, &mut |s| {
            s.extend_from_slice(&self.metadata_indexes)
        });
        let summary_offset_start = summary_start + summary.len() as u64;
        for (opcode, group_start, group_length) in offsets {
            let start = summary.start_record(op::SUMMARY_OFFSET);
            summary.push(opcode);
            summary.u64(group_start);
            summary.u64(group_length);
            summary.end_record(start);
        }
        // The footer: its length is known, and the CRC covers it up to its last field.
        summary.push(op::FOOTER);
        summary.u64(20);
        summary.u64(summary_start);
        summary.u64(summary_offset_start);
        let crc = crc32fast::hash(&summary);
        summary.u32(crc);
        summary.extend_from_slice(MAGIC);
        self.out.write(&summary)?;
        self.out.inner.flush()?;
        Ok((self.out.inner, u64::from(self.chunk_count)))
    }

    /// Gives the output up without finishing the file, as a process that dies while writing
    /// the open chunk would leave it: the chunks closed so far, then the first half of the
    /// open chunk's record.
    pub fn abandon(mut self) -> W {
        if !self.chunk.is_empty() && self.build_chunk_record().is_ok() {
            let half = self.compressed.len() / 2;
            let compressed = std::mem::take(&mut self.compressed);
            let _ = self.out.write(&compressed[..half]);
        }
        let _ = self.out.inner.flush();
        self.out.inner
    }
}

fn put_schema(s: &mut Vec<u8>, schema: &Schema) {
    let start = s.start_record(op::SCHEMA);
    s.u16(schema.id);
    s.string(&schema.name);
    s.string(&schema.encoding);
    s.u32(schema.data.len() as u32);
    s.extend_from_slice(&schema.data);
    s.end_record(start);
}

fn put_channel(s: &mut Vec<u8>, channel: &Channel) {
    let start = s.start_record(op::CHANNEL);
    s.u16(channel.id);
    s.u16(channel.schema_id);
    s.string(&channel.topic);
    s.string(&channel.message_encoding);
    s.string_map(&channel.metadata);
    s.end_record(start);
}

#[cfg(test)]
mod tests {
    use super::*;
    use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

    fn options(zstd_level: Option<i32>, message_indexes: bool) -> ChunkOptions {
        ChunkOptions {
            zstd_level,
            chunk_size: 4096,
            message_indexes,
            profile: "test".into(),
            library: "icms-test".into(),
        }
    }

    /// The message of `channel` number `i`: its length and bytes vary.
    fn payload(channel: u16, i: u64) -> Vec<u8> {
        (0..(i % 37 + channel as u64 * 3))
            .map(|k| (k * 31 + i * 7 + channel as u64) as u8)
            .collect()
    }

    /// A file with three channels (one without a schema, two sharing theirs), 3 000 messages
    /// over many chunks, metadata and an attachment between them.
    fn write(zstd_level: Option<i32>, message_indexes: bool) -> (Vec<u8>, u64) {
        let mut w = ChunkedWriter::new(Vec::new(), options(zstd_level, message_indexes)).unwrap();
        let s1 = w.add_schema("icms.A", "protobuf", b"descriptor a").unwrap();
        let s2 = w.add_schema("icms.B", "protobuf", b"descriptor b").unwrap();
        assert_eq!(
            w.add_schema("icms.A", "protobuf", b"descriptor a").unwrap(),
            s1
        );
        let meta = BTreeMap::from([("k".to_owned(), "v".to_owned())]);
        let ids = [
            w.add_channel(s1, "/a", "protobuf", &meta).unwrap(),
            w.add_channel(s2, "/b", "protobuf", &BTreeMap::new())
                .unwrap(),
            w.add_channel(0, "/raw", "", &BTreeMap::new()).unwrap(),
        ];
        assert!(w.add_channel(9, "/bad", "", &BTreeMap::new()).is_err());
        let mut seq = [0u32; 3];
        for i in 0..3000u64 {
            let c = (i % 3) as usize;
            w.write_message(
                ids[c],
                seq[c],
                i * 1_000_000,
                i * 1_000_000 + 5,
                &payload(ids[c], i),
            )
            .unwrap();
            seq[c] += 1;
            if i == 1500 {
                w.write_metadata("session", &meta).unwrap();
                w.attach(7, 8, "hand.urdf", "application/xml", b"<robot/>")
                    .unwrap();
            }
        }
        let (bytes, chunks) = w.finish().unwrap();
        (bytes, chunks)
    }

    /// Every record of `bytes` through the `mcap` crate's linear reader with every CRC checked.
    fn validate_crcs(bytes: &[u8]) -> mcap::McapResult<usize> {
        let mut reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_validate_chunk_crcs(true)
                .with_validate_data_section_crc(true)
                .with_validate_summary_section_crc(true)
                .with_check_finishes_after_end_magic(true),
        );
        let mut fed = 0;
        let mut records = 0;
        while let Some(event) = reader.next_event() {
            match event? {
                LinearReadEvent::ReadRequest(n) => {
                    let n = n.min(bytes.len() - fed);
                    reader.insert(n).copy_from_slice(&bytes[fed..fed + n]);
                    reader.notify_read(n);
                    fed += n;
                }
                LinearReadEvent::Record { .. } => records += 1,
            }
        }
        Ok(records)
    }

    #[test]
    fn the_mcap_crate_reads_back_every_message_record_and_index() {
        for (level, indexes) in [(Some(3), true), (Some(1), false), (None, true)] {
            let (bytes, chunks) = write(level, indexes);
            assert!(validate_crcs(&bytes).unwrap() > 3000);
            // The checks are live: a flipped bit in the data section (the header's library
            // name, then a chunk's records) or in the summary is found.
            let summary_start = mcap::read::footer(&bytes).unwrap().summary_start as usize;
            for at in [30, bytes.len() / 2, summary_start + 40] {
                let mut bad = bytes.clone();
                bad[at] ^= 0x10;
                assert!(validate_crcs(&bad).is_err(), "byte {at} of {}", bytes.len());
            }

            let messages: Vec<_> = mcap::MessageStream::new(&bytes)
                .unwrap()
                .map(Result::unwrap)
                .collect();
            assert_eq!(messages.len(), 3000);
            for (i, m) in messages.iter().enumerate() {
                let i = i as u64;
                let topic = ["/a", "/b", "/raw"][(i % 3) as usize];
                assert_eq!(m.channel.topic, topic);
                assert_eq!(m.sequence, (i / 3) as u32);
                assert_eq!(
                    (m.log_time, m.publish_time),
                    (i * 1_000_000, i * 1_000_000 + 5)
                );
                assert_eq!(m.data.as_ref(), payload(m.channel.id, i).as_slice());
            }
            assert_eq!(messages[0].channel.metadata["k"], "v");
            assert_eq!(messages[0].channel.schema.as_ref().unwrap().name, "icms.A");
            assert!(messages[2].channel.schema.is_none());

            let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
            let stats = summary.stats.as_ref().unwrap();
            assert_eq!(stats.message_count, 3000);
            assert_eq!((stats.schema_count, stats.channel_count), (2, 3));
            assert_eq!((stats.attachment_count, stats.metadata_count), (1, 1));
            assert_eq!(u64::from(stats.chunk_count), chunks);
            assert_eq!(
                (stats.message_start_time, stats.message_end_time),
                (0, 2_999_000_000)
            );
            assert!(stats.channel_message_counts.values().all(|&n| n == 1000));
            assert_eq!(summary.chunk_indexes.len() as u64, chunks);
            assert!(chunks > 10, "{chunks} chunks");
            let compression = if level.is_some() { "zstd" } else { "" };
            assert!(summary
                .chunk_indexes
                .iter()
                .all(|c| c.compression == compression));

            let a = mcap::read::attachment(&bytes, &summary.attachment_indexes[0]).unwrap();
            assert_eq!((a.log_time, a.create_time), (7, 8));
            assert_eq!(
                (a.name.as_str(), a.media_type.as_str()),
                ("hand.urdf", "application/xml")
            );
            assert_eq!(a.data.as_ref(), b"<robot/>");
            let m = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).unwrap();
            assert_eq!(
                (m.name.as_str(), m.metadata["k"].as_str()),
                ("session", "v")
            );

            // Each message index entry leads to a message with its log time.
            let mut indexed = 0;
            for chunk in &summary.chunk_indexes {
                if !indexes {
                    assert!(chunk.message_index_offsets.is_empty());
                    assert_eq!(chunk.message_index_length, 0);
                    continue;
                }
                for (_, entries) in summary.read_message_indexes(&bytes, chunk).unwrap() {
                    for e in entries {
                        let m = summary.seek_message(&bytes, chunk, &e).unwrap();
                        assert_eq!(m.log_time, e.log_time);
                        assert!(m.log_time >= chunk.message_start_time);
                        assert!(m.log_time <= chunk.message_end_time);
                        indexed += 1;
                    }
                }
            }
            assert_eq!(indexed, if indexes { 3000 } else { 0 });
        }
    }

    #[test]
    fn a_file_is_a_function_of_what_was_written() {
        assert_eq!(write(Some(3), false), write(Some(3), false));
    }

    #[test]
    fn an_abandoned_file_ends_inside_its_open_chunk() {
        let mut w = ChunkedWriter::new(Vec::new(), options(Some(3), false)).unwrap();
        let s = w.add_schema("icms.A", "protobuf", b"d").unwrap();
        let c = w
            .add_channel(s, "/a", "protobuf", &BTreeMap::new())
            .unwrap();
        for i in 0..50 {
            w.write_message(c, i, u64::from(i), u64::from(i), &[1, 2, 3])
                .unwrap();
        }
        w.flush().unwrap();
        let closed = w.out.position as usize;
        for i in 50..60 {
            w.write_message(c, i, u64::from(i), u64::from(i), &[4, 5, 6])
                .unwrap();
        }
        let bytes = w.abandon();
        assert!(bytes.len() > closed, "part of the open chunk is written");
        let read: Vec<_> = mcap::MessageStream::new(&bytes).unwrap().collect();
        assert_eq!(read.iter().filter(|m| m.is_ok()).count(), 50);
        assert!(read.last().unwrap().is_err());
    }
}
