//! Streaming a session's records to a visitor chunk by chunk ([`stream_raw`]), decompressing
//! ahead on other threads and filing the messages in time order, memory bounded by the chunks in
//! flight rather than by the file.

use super::*;

/// What [`stream_raw`] hands on, record by record in file order.
pub(crate) trait RawVisitor {
    /// Message `index` (counted per topic from 0) of `topic`, the `topic_index`th topic
    /// announced by [`RawVisitor::topic`], its payload borrowed from its chunk. An error stops
    /// the read and is its result.
    fn message(
        &mut self,
        topic_index: usize,
        topic: &RawTopic,
        index: usize,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<()>;

    /// A topic seen for the first time (its first channel record), before any of its messages.
    fn topic(&mut self, _topic: &RawTopic) -> Result<()> {
        Ok(())
    }

    /// A metadata record, as it comes.
    fn metadata(&mut self, _record: &MetadataRecord) -> Result<()> {
        Ok(())
    }

    /// Asked of [`stream_raw`]'s `early` visitor once a topic was announced: whether it takes
    /// that topic's messages on the reading thread (the main visitor then never sees them).
    fn claims(&self, _topic_index: usize) -> bool {
        false
    }
}

/// A visitor that takes nothing.
impl RawVisitor for () {
    fn message(&mut self, _: usize, _: &RawTopic, _: usize, _: u64, _: &[u8]) -> Result<()> {
        Ok(())
    }
}

/// What a streamed read leaves once every message went to the visitor: the topics (with no
/// message list) and how many messages each had, and the metadata records.
#[derive(Debug, Default)]
pub(crate) struct StreamedRaw {
    /// Topics in order of first appearance, each with its message count.
    pub topics: Vec<(RawTopic, usize)>,
    pub metadata: Vec<MetadataRecord>,
}

impl StreamedRaw {
    /// The topic named `topic` and its message count.
    pub(crate) fn topic(&self, topic: &str) -> Option<&(RawTopic, usize)> {
        self.topics.iter().find(|(t, _)| t.topic == topic)
    }
}

/// Most metadata records a streamed read keeps before refusing the file (the session reader
/// allows far fewer and says so at the end; this bounds what a file of nothing but metadata
/// can make it hold).
pub(super) const STREAM_MAX_METADATA_RECORDS: usize = 4096;

/// [`stream_raw`] of bytes in memory.
pub(crate) fn stream_raw_bytes(
    bytes: &[u8],
    limits: &ReadLimits,
    early: &mut (impl RawVisitor + Send),
    visitor: &mut impl RawVisitor,
) -> Result<StreamedRaw> {
    stream_raw(bytes, Some(bytes.len() as u64), limits, early, visitor)
}

/// [`stream_raw`] of a file.
pub(crate) fn stream_raw_file(
    path: &Path,
    limits: &ReadLimits,
    early: &mut (impl RawVisitor + Send),
    visitor: &mut impl RawVisitor,
) -> Result<StreamedRaw> {
    let (file, len) = open_with_len(path)?;
    stream_raw(file, Some(len), limits, early, visitor)
}

/// Reads an MCAP file in one pass with the checks of [`read_raw`], handing every message to a
/// visitor as its chunk is decompressed and checked, in file order, then dropping the chunk:
/// what it holds is a few chunks (each at most [`ReadLimits::max_record_bytes`]) whatever the
/// file's length. Decompression is bounded as in [`read_raw`] (the chunks' declared sizes
/// against [`ReadLimits::decompressed_limit`] of the input's length), which here bounds work,
/// not memory.
///
/// Two threads: the reading thread reads, checks, decompresses and files the records, and
/// hands the messages of the topics `early` [claims](RawVisitor::claims) to it; the calling
/// thread hands the others to `visitor`, a few chunks behind. Both see every topic and
/// metadata record announced, each in file order.
///
/// The visitors see messages before the end of the file is checked: a file truncated or
/// damaged later (a data section CRC, a missing footer) is an error at the end, after the
/// messages before the damage went by. Callers keep nothing of a read that failed.
pub(crate) fn stream_raw<R: Read + Send>(
    src: R,
    total_len: Option<u64>,
    limits: &ReadLimits,
    early: &mut (impl RawVisitor + Send),
    visitor: &mut impl RawVisitor,
) -> Result<StreamedRaw> {
    std::thread::scope(|scope| -> Result<StreamedRaw> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Filed>(STREAM_CHUNKS_AHEAD);
        // Decompressed chunks go back to the reading thread to be filled again: a fresh buffer
        // for every chunk cost a page fault (and the kernel's zeroing) per 4 kB of it.
        let (recycle, recycled) = std::sync::mpsc::sync_channel::<Vec<u8>>(RECYCLED_BUFFERS);
        let reader = scope.spawn(move || -> Result<StreamedRaw> {
            let mut filer = Filer::new(total_len, limits, early);
            filer.recycled = Some(recycled);
            let outcome = scan(src, total_len, limits, true, |batch| {
                let filed = filer.file(batch)?;
                // The calling thread stopped (an error there): stop reading.
                tx.send(filed).map_err(|_| RecordingError::WriterClosed {
                    path: std::path::PathBuf::from("the session stream"),
                })
            })?;
            outcome.into_result()?;
            Ok(filer.streamed())
        });
        let mut topics: Vec<RawTopic> = Vec::new();
        let mut failed = None;
        for filed in rx.iter() {
            match deliver(filed, &mut topics, visitor) {
                Ok(buffers) => {
                    for buffer in buffers {
                        // Full (the reader has enough) or gone: to the pool.
                        if let Err(e) = recycle.try_send(buffer) {
                            let (std::sync::mpsc::TrySendError::Full(b)
                            | std::sync::mpsc::TrySendError::Disconnected(b)) = e;
                            CHUNK_BUFFERS.give(b);
                        }
                    }
                }
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        drop(rx);
        let read = reader
            .join()
            .map_err(|_| RecordingError::WriterThreadPanicked)?;
        match failed {
            Some(e) => Err(e),
            None => read,
        }
    })
}

/// Hands the events of `filed` to `visitor` in order (`topics`: those announced so far);
/// returns its buffers, to be filled again.
pub(super) fn deliver(
    filed: Filed,
    topics: &mut Vec<RawTopic>,
    visitor: &mut impl RawVisitor,
) -> Result<Vec<Vec<u8>>> {
    for event in filed.events {
        match event {
            Event::Topic(t) => {
                let r = visitor.topic(&t);
                topics.push(*t);
                r?
            }
            Event::Metadata(m) => visitor.metadata(&m)?,
            Event::Message {
                topic,
                index,
                log_time_ns,
                buffer,
                start,
                end,
            } => visitor.message(
                topic,
                &topics[topic],
                index,
                log_time_ns,
                &filed.buffers[buffer][start..end],
            )?,
        }
    }
    Ok(filed.buffers)
}

/// What the reading thread of [`stream_raw`] hands on for one top-level record: the records'
/// events in file order, and the buffers the messages lie in (a decompressed chunk, or a
/// message outside chunks).
pub(super) struct Filed {
    pub(super) buffers: Vec<Vec<u8>>,
    pub(super) events: Vec<Event>,
}

/// One thing the calling thread of [`stream_raw`] hands its visitor.
pub(super) enum Event {
    Topic(Box<RawTopic>),
    Metadata(MetadataRecord),
    Message {
        topic: usize,
        index: usize,
        log_time_ns: u64,
        buffer: usize,
        start: usize,
        end: usize,
    },
}

/// The reading thread's filing of records: schemas, channels and topics, message counts, and
/// the messages of claimed topics handed to the early visitor.
pub(super) struct Filer<'a, E: RawVisitor> {
    pub(super) builder: SessionBuilder,
    pub(super) counts: Vec<usize>,
    pub(super) claimed: Vec<bool>,
    pub(super) limits: &'a ReadLimits,
    pub(super) early: &'a mut E,
    /// The zstd context, reused from chunk to chunk.
    pub(super) dctx: Option<zstd::zstd_safe::DCtx<'static>>,
    /// Chunk buffers the calling thread is done with, to decompress into again.
    pub(super) recycled: Option<std::sync::mpsc::Receiver<Vec<u8>>>,
}

impl<'a, E: RawVisitor> Filer<'a, E> {
    pub(super) fn new(total_len: Option<u64>, limits: &'a ReadLimits, early: &'a mut E) -> Self {
        Filer {
            builder: SessionBuilder::new(*limits, total_len, 0),
            counts: Vec::new(),
            claimed: Vec::new(),
            limits,
            early,
            dctx: None,
            recycled: None,
        }
    }

    /// What the read found, once every record was filed.
    pub(super) fn streamed(&mut self) -> StreamedRaw {
        let topics = std::mem::take(&mut self.builder.topics);
        let counts = std::mem::take(&mut self.counts);
        StreamedRaw {
            topics: topics.into_iter().zip(counts).collect(),
            metadata: std::mem::take(&mut self.builder.session.metadata),
        }
    }

    pub(super) fn file(&mut self, batch: Batch) -> Result<Filed> {
        let offset = batch.offset;
        let mut filed = Filed {
            buffers: Vec::new(),
            events: Vec::new(),
        };
        for record in batch.records {
            match record {
                Record::Chunk { header, data } => {
                    let reuse = self.recycled.as_ref().and_then(|r| r.try_recv().ok());
                    let content =
                        unpack_chunk(offset, &header, &data, self.limits, &mut self.dctx, reuse)?;
                    if let Cow::Owned(compressed) = data {
                        CHUNK_BUFFERS.give(compressed);
                    }
                    let buffer = filed.buffers.len();
                    let mut others = content.others.into_iter();
                    let mut pos = 0;
                    while let Some((opcode, start, end)) =
                        next_chunk_record(&content.data, pos, offset, self.limits)?
                    {
                        if opcode == op::MESSAGE {
                            let header = message_header(&content.data[start..end]);
                            let payload = (start + MESSAGE_HEADER_LEN, end);
                            self.message(
                                offset,
                                &header,
                                &content.data,
                                buffer,
                                payload,
                                &mut filed,
                            )?;
                        } else if let Some(r) = others.next() {
                            self.other(offset, r, &mut filed)?;
                        }
                        pos = end;
                    }
                    filed.buffers.push(content.data);
                }
                Record::Message { header, data } => {
                    let buffer = filed.buffers.len();
                    let data = data.into_owned();
                    self.message(offset, &header, &data, buffer, (0, data.len()), &mut filed)?;
                    filed.buffers.push(data);
                }
                other => self.other(offset, other, &mut filed)?,
            }
        }
        Ok(filed)
    }

    /// A message whose payload is `data[start..end]` (`data` to be `filed.buffers[buffer]`).
    pub(super) fn message(
        &mut self,
        offset: u64,
        header: &MessageHeader,
        data: &[u8],
        buffer: usize,
        (start, end): (usize, usize),
        filed: &mut Filed,
    ) -> Result<()> {
        let topic = self.builder.channel_topic(offset, header.channel_id)?;
        self.builder.count_message((end - start) as u64)?;
        let index = self.counts[topic];
        self.counts[topic] += 1;
        if self.claimed[topic] {
            let t = &self.builder.topics[topic];
            return self
                .early
                .message(topic, t, index, header.log_time, &data[start..end]);
        }
        filed.events.push(Event::Message {
            topic,
            index,
            log_time_ns: header.log_time,
            buffer,
            start,
            end,
        });
        Ok(())
    }

    /// A record other than a message: filed, new topics and metadata announced to both.
    pub(super) fn other(
        &mut self,
        offset: u64,
        record: Record<'static>,
        filed: &mut Filed,
    ) -> Result<()> {
        let is_metadata = matches!(record, Record::Metadata(_));
        self.builder.apply(offset, record)?;
        while self.counts.len() < self.builder.topics.len() {
            let index = self.counts.len();
            let t = &self.builder.topics[index];
            self.early.topic(t)?;
            self.claimed.push(self.early.claims(index));
            self.counts.push(0);
            filed.events.push(Event::Topic(Box::new(t.clone())));
        }
        if is_metadata {
            self.builder.metadata_added(offset, self.early)?;
            if let Some(m) = self.builder.session.metadata.last() {
                filed.events.push(Event::Metadata(m.clone()));
            }
        }
        Ok(())
    }
}

impl<E: RawVisitor> Drop for Filer<'_, E> {
    fn drop(&mut self) {
        if let Some(recycled) = &self.recycled {
            while let Ok(buffer) = recycled.try_recv() {
                CHUNK_BUFFERS.give(buffer);
            }
        }
    }
}
