//! [`KeptMessages`]: the raw messages a first read handed on, kept (within a budget) for a
//! second read that then reads no file.

use crate::mcap_io::pool::Pool;
use crate::session::*;

/// Default budget of [`KeptMessages`]: 32 MiB, the contacts and object states of about two
/// minutes of session (190 to 240 bytes a millisecond, and 48 of index).
pub const KEPT_MESSAGES_BUDGET: usize = 32 << 20;

/// The raw messages a first read ([`SessionSource::stream_keeping`]) handed its visitor, as
/// they were in the file, for a second read ([`SessionSource::stream_again_kept`]) that then
/// reads no file: no decompression, no CRC, no framing, and no checks (these very bytes were
/// checked). Up to a budget of bytes: a read that would keep more drops them all and keeps
/// nothing further (the second read then reads the file again), so memory stays bounded
/// whatever the session's length.
#[derive(Debug)]
pub struct KeptMessages {
    budget: usize,
    /// Raw topics kept besides those the first read's visitor takes ([`KeptMessages::also`]).
    pub(super) also: DecodeTopics,
    /// The raw topics kept: those the first read's visitor took, and `also`.
    topics: DecodeTopics,
    /// Whether every message of `topics` the read handed on is here (false once over budget,
    /// or before a read).
    pub(super) complete: bool,
    pub(super) messages: Vec<KeptMessage>,
    pub(super) bytes: Vec<u8>,
}

/// One kept message: where its payload lies in [`KeptMessages::bytes`], what it was.
#[derive(Debug, Clone, Copy)]
pub(super) struct KeptMessage {
    pub(super) log_time_ns: u64,
    pub(super) start: u32,
    pub(super) len: u32,
    pub(super) index: u32,
    pub(super) raw: u8,
    pub(super) protobuf: bool,
}

/// The payloads of kept messages, reused from one segmentation to the next (16 MiB: a
/// minute of session, or a few short ones analysed side by side).
static KEPT_BYTES: Pool<u8> = Pool::new(16 << 20, 1);
/// Their index, likewise (a minute's is 3 MB).
static KEPT_INDEX: Pool<KeptMessage> = Pool::new(6 << 20, 1);

impl KeptMessages {
    /// Keeps at most `budget` bytes (payloads and their index).
    pub fn new(budget: usize) -> Self {
        KeptMessages {
            budget,
            also: DecodeTopics::NONE,
            topics: DecodeTopics::NONE,
            complete: false,
            messages: Vec::new(),
            bytes: Vec::new(),
        }
    }

    /// Keeps the messages of `topics` as well as those the first read's visitor takes, for a
    /// later reader of other topics (ingest's approach templates read the joint angles after
    /// segmentation, which reads contacts and object states).
    pub fn also(mut self, topics: DecodeTopics) -> Self {
        self.also = topics;
        self
    }

    /// Empty, ready to keep the messages of `topics` of a new read of a file of `len` bytes
    /// (their room taken at once: the contacts and object states are 85 to 100 % of one of
    /// our session files' length, one message per 95 to 120 bytes of it).
    pub(super) fn start(&mut self, topics: DecodeTopics, len: usize) -> &mut Self {
        self.release();
        let room = len.min(self.budget);
        self.bytes = KEPT_BYTES.take(room);
        self.bytes.clear();
        self.messages = KEPT_INDEX.take(room / 90);
        self.messages.clear();
        self.topics = topics.union(self.also);
        self.complete = true;
        self
    }

    /// Gives the buffers back to their pools.
    pub(super) fn release(&mut self) {
        KEPT_BYTES.give(std::mem::take(&mut self.bytes));
        KEPT_INDEX.give(std::mem::take(&mut self.messages));
    }

    /// Whether it holds every message of `topics` of the read (none dropped for the budget).
    pub fn covers(&self, topics: DecodeTopics) -> bool {
        self.complete && (0..RAW_TOPICS.len()).all(|i| !topics.has(i) || self.topics.has(i))
    }

    /// Bytes held (payloads and index).
    pub fn held_bytes(&self) -> usize {
        self.bytes.len() + self.messages.len() * std::mem::size_of::<KeptMessage>()
    }

    /// Keeps a message; over the budget (or past what the index can say), drops everything.
    pub(super) fn keep(&mut self, raw: usize, protobuf: bool, index: usize, t: u64, data: &[u8]) {
        if !self.complete || !self.topics.has(raw) {
            return;
        }
        let entry = (
            u32::try_from(self.bytes.len()),
            u32::try_from(data.len()),
            u32::try_from(index),
        );
        let over =
            self.held_bytes() + data.len() + std::mem::size_of::<KeptMessage>() > self.budget;
        match entry {
            (Ok(start), Ok(len), Ok(index)) if !over => {
                self.bytes.extend_from_slice(data);
                self.messages.push(KeptMessage {
                    log_time_ns: t,
                    start,
                    len,
                    index,
                    raw: raw as u8,
                    protobuf,
                });
            }
            _ => {
                self.complete = false;
                self.release();
            }
        }
    }
}

impl Drop for KeptMessages {
    fn drop(&mut self) {
        self.release();
    }
}
