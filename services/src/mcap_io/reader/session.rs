//! A session read whole: the raw topics' messages indexed in their decompressed buffers
//! ([`RawSession`]), built record by record from a scan ([`SessionBuilder`]).

use super::*;

/// Where a message's payload lies: `buffers[buffer][start..end]` of a [`RawSession`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MessageRef {
    /// Log time, ns.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// Channel sequence number.
    pub sequence: u32,
    pub(super) buffer: u32,
    pub(super) start: usize,
    pub(super) end: usize,
}

/// One topic of a [`RawSession`]: like [`TopicRecording`], with the payloads left in place.
#[derive(Debug, Clone)]
pub(crate) struct RawTopic {
    pub topic: String,
    pub message_encoding: String,
    pub schema: Option<SchemaInfo>,
    pub messages: Vec<MessageRef>,
}

impl RawTopic {
    /// Same checks as [`RecordedSession::require_topic`].
    pub(crate) fn require(&self, schema_name: &str) -> Result<()> {
        check_topic(
            &self.topic,
            &self.message_encoding,
            self.schema.as_ref(),
            schema_name,
        )
    }

    /// Whether the topic carries JSON messages.
    pub(crate) fn is_json(&self) -> bool {
        self.message_encoding == MESSAGE_ENCODING
    }

    /// Whether the topic carries protobuf messages.
    pub(crate) fn is_protobuf(&self) -> bool {
        self.message_encoding == PROTOBUF
    }
}

/// A session read and checked structurally (CRCs, limits, links between records) but with
/// every message payload still inside its decompressed chunk: no copy per message. Messages
/// are not yet checked to be JSON: [`RawSession::check_json`] or a decoder does that.
#[derive(Debug, Default)]
pub(crate) struct RawSession {
    pub profile: String,
    pub library: String,
    pub topics: BTreeMap<String, RawTopic>,
    pub metadata: Vec<MetadataRecord>,
    /// Decompressed chunk contents, then the payloads of messages outside chunks.
    pub(super) buffers: Vec<Vec<u8>>,
}

impl RawSession {
    /// The payload of `m`.
    pub(crate) fn data(&self, m: &MessageRef) -> &[u8] {
        &self.buffers[m.buffer as usize][m.start..m.end]
    }

    /// Checks that every message of every `json` topic `check(topic)` selects is valid JSON,
    /// in parallel; the first invalid message in topic and file order is the error.
    pub(crate) fn check_json(&self, check: impl Fn(&str) -> bool) -> Result<()> {
        let jobs: Vec<(&RawTopic, usize, &[MessageRef])> = self
            .topics
            .values()
            .filter(|t| t.is_json() && check(&t.topic))
            .flat_map(|t| {
                t.messages
                    .chunks(MESSAGES_PER_JOB)
                    .enumerate()
                    .map(move |(k, m)| (t, k * MESSAGES_PER_JOB, m))
            })
            .collect();
        par_map(jobs.len(), |i| {
            let (t, first, messages) = jobs[i];
            self.check_json_of(t, first, messages)
        })
        .into_iter()
        .collect()
    }

    /// Checks that each of `messages` (of topic `t`, the first of them its message number
    /// `first`) is valid JSON.
    pub(crate) fn check_json_of(
        &self,
        t: &RawTopic,
        first: usize,
        messages: &[MessageRef],
    ) -> Result<()> {
        for (i, m) in messages.iter().enumerate() {
            check_message(&t.topic, first + i, m.log_time_ns, self.data(m))?;
        }
        Ok(())
    }

    /// The owned form: one `Vec` per message.
    pub(super) fn into_recorded(self) -> RecordedSession {
        let topics = self
            .topics
            .values()
            .map(|t| {
                let messages = t
                    .messages
                    .iter()
                    .map(|m| RecordedMessage {
                        log_time_ns: m.log_time_ns,
                        publish_time_ns: m.publish_time_ns,
                        sequence: m.sequence,
                        data: self.data(m).to_vec(),
                    })
                    .collect();
                (
                    t.topic.clone(),
                    TopicRecording {
                        topic: t.topic.clone(),
                        message_encoding: t.message_encoding.clone(),
                        schema: t.schema.clone(),
                        messages,
                    },
                )
            })
            .collect();
        RecordedSession {
            profile: self.profile,
            library: self.library,
            topics,
            metadata: self.metadata,
        }
    }
}

pub(super) struct SessionBuilder {
    /// Schemas, metadata and buffers (topics are in `topics` until the end).
    pub(super) session: RawSession,
    /// Topics in order of first appearance.
    pub(super) topics: Vec<RawTopic>,
    /// Topic name -> index in `topics`.
    pub(super) topic_index: HashMap<String, usize>,
    pub(super) schemas: HashMap<u16, SchemaInfo>,
    /// Channel id -> (topic name, index in `topics`).
    pub(super) channels: HashMap<u16, (String, usize)>,
    /// The same lookup by the message's channel id, as an index (`u32::MAX`: none): hashing
    /// the id of every message cost more than filing it.
    pub(super) channel_topics: Vec<u32>,
    pub(super) total_bytes: u64,
    pub(super) limits: ReadLimits,
    /// Length of the input, if known.
    pub(super) input_len: Option<u64>,
    /// Bytes held against [`ReadLimits::decompressed_limit`]: the decompressed chunks, the
    /// payloads of messages outside chunks, and [`MessageRef`]s.
    pub(super) held: u64,
    /// Payloads of messages outside chunks.
    pub(super) loose: Vec<u8>,
    /// Index `loose` will have in the session's buffers.
    pub(super) loose_buffer: u32,
}

impl SessionBuilder {
    pub(super) fn new(limits: ReadLimits, input_len: Option<u64>, loose_buffer: u32) -> Self {
        SessionBuilder {
            session: RawSession::default(),
            topics: Vec::new(),
            topic_index: HashMap::new(),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            channel_topics: Vec::new(),
            total_bytes: 0,
            limits,
            input_len,
            held: 0,
            loose: Vec::new(),
            loose_buffer,
        }
    }

    /// The index in `topics` of the channel `channel_id` of a message at `offset`.
    pub(super) fn channel_topic(&self, offset: u64, channel_id: u16) -> Result<usize> {
        self.channel_topics
            .get(usize::from(channel_id))
            .filter(|&&topic| topic != u32::MAX)
            .map(|&topic| topic as usize)
            .ok_or_else(|| RecordingError::Corrupt {
                offset,
                detail: format!("message refers to unknown channel id {channel_id}"),
            })
    }

    /// Counts a message's payload against [`ReadLimits::max_total_message_bytes`].
    pub(super) fn count_message(&mut self, bytes: u64) -> Result<()> {
        self.total_bytes += bytes;
        if self.total_bytes > self.limits.max_total_message_bytes {
            return Err(RecordingError::TooMuchData {
                limit: self.limits.max_total_message_bytes,
            });
        }
        Ok(())
    }

    /// The metadata record just applied, handed to `visitor`; too many records are refused.
    pub(super) fn metadata_added(
        &mut self,
        offset: u64,
        visitor: &mut impl RawVisitor,
    ) -> Result<()> {
        // Kept to the end of the read (and copied for the calling thread): counted against
        // the input's budget like the chunks of a whole-file read.
        let bytes = self.session.metadata.last().map_or(0, |m| {
            m.name.len()
                + m.entries
                    .iter()
                    .map(|(k, v)| k.len() + v.len())
                    .sum::<usize>()
        });
        self.hold(offset, 2 * bytes as u64)?;
        let records = &self.session.metadata;
        if records.len() > STREAM_MAX_METADATA_RECORDS {
            return Err(RecordingError::Corrupt {
                offset,
                detail: format!("more than {STREAM_MAX_METADATA_RECORDS} metadata records"),
            });
        }
        match records.last() {
            Some(record) => visitor.metadata(record),
            None => Ok(()),
        }
    }

    /// Counts `bytes` more against the budget of the input's length.
    pub(super) fn hold(&mut self, offset: u64, bytes: u64) -> Result<()> {
        self.held = self.held.saturating_add(bytes);
        if self.held > self.limits.budget(self.input_len) {
            return Err(self.limits.over_limit(self.input_len, offset, self.held));
        }
        Ok(())
    }

    /// A message outside chunks: its payload copied into `loose` and filed.
    pub(super) fn loose_message(
        &mut self,
        offset: u64,
        header: &MessageHeader,
        data: &[u8],
    ) -> Result<()> {
        self.hold(offset, data.len() as u64)?;
        let start = self.loose.len();
        self.loose.extend_from_slice(data);
        let end = self.loose.len();
        self.message(offset, header, self.loose_buffer, start, end)
    }

    pub(super) fn message(
        &mut self,
        offset: u64,
        header: &MessageHeader,
        buffer: u32,
        start: usize,
        end: usize,
    ) -> Result<()> {
        let topic = self.channel_topic(offset, header.channel_id)?;
        self.count_message((end - start) as u64)?;
        // A message's index entry is held too: for a file of tiny messages it outweighs them.
        self.hold(offset, std::mem::size_of::<MessageRef>() as u64)?;
        self.topics[topic].messages.push(MessageRef {
            log_time_ns: header.log_time,
            publish_time_ns: header.publish_time,
            sequence: header.sequence,
            buffer,
            start,
            end,
        });
        Ok(())
    }

    pub(super) fn apply(&mut self, offset: u64, record: Record<'static>) -> Result<()> {
        let corrupt = |detail: String| RecordingError::Corrupt { offset, detail };
        match record {
            Record::Header(h) => {
                self.session.profile = h.profile;
                self.session.library = h.library;
            }
            Record::Schema { header, data } => {
                if header.id == 0 {
                    return Err(corrupt("schema with id 0".into()));
                }
                let info = SchemaInfo {
                    name: header.name,
                    encoding: header.encoding,
                    data: data.into_owned(),
                };
                if let Some(old) = self.schemas.get(&header.id) {
                    if *old != info {
                        return Err(corrupt(format!(
                            "schema id {} redefined with different content",
                            header.id
                        )));
                    }
                } else {
                    self.schemas.insert(header.id, info);
                }
            }
            Record::Channel(c) => {
                let schema = if c.schema_id == 0 {
                    None
                } else {
                    Some(self.schemas.get(&c.schema_id).cloned().ok_or_else(|| {
                        corrupt(format!(
                            "channel {:?} refers to unknown schema id {}",
                            c.topic, c.schema_id
                        ))
                    })?)
                };
                if let Some((old_topic, _)) = self.channels.get(&c.id) {
                    if *old_topic != c.topic {
                        return Err(corrupt(format!(
                            "channel id {} redefined with topic {:?}",
                            c.id, c.topic
                        )));
                    }
                }
                let index = match self.topic_index.get(&c.topic) {
                    Some(&index) => {
                        let t = &self.topics[index];
                        if t.schema != schema || t.message_encoding != c.message_encoding {
                            return Err(corrupt(format!(
                                "topic {:?} has two channels with different schemas or \
                                 encodings",
                                c.topic
                            )));
                        }
                        index
                    }
                    None => {
                        // Each topic holds its own copy of its schema: a file of many topics
                        // sharing one large schema would otherwise hold copies without bound.
                        if self.topics.len() >= MAX_TOPICS {
                            return Err(corrupt(format!(
                                "more than {MAX_TOPICS} topics (a session has about ten)"
                            )));
                        }
                        let copy = schema.as_ref().map_or(0, |s| s.data.len()) + c.topic.len();
                        self.hold(offset, 2 * copy as u64)?;
                        self.topics.push(RawTopic {
                            topic: c.topic.clone(),
                            message_encoding: c.message_encoding.clone(),
                            schema,
                            messages: Vec::new(),
                        });
                        self.topic_index
                            .insert(c.topic.clone(), self.topics.len() - 1);
                        self.topics.len() - 1
                    }
                };
                let id = usize::from(c.id);
                if self.channel_topics.len() <= id {
                    self.channel_topics.resize(id + 1, u32::MAX);
                }
                // At most MAX_TOPICS topics.
                self.channel_topics[id] = index as u32;
                self.channels.insert(c.id, (c.topic, index));
            }
            Record::Message { header, data } => self.loose_message(offset, &header, &data)?,
            Record::Metadata(m) => self.session.metadata.push(MetadataRecord {
                name: m.name,
                entries: m.metadata,
            }),
            _ => {}
        }
        Ok(())
    }
}
