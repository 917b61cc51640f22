//! Ingest: a session file becomes a stored session with its skills, in one step — read and
//! validated (CRC prevalidation, record limits, decompression bounded by the upload's length,
//! contents checked), segmented into hand-independent skills, and stored atomically and
//! idempotently by [`Store::ingest`].
//!
//! Memory: a session is read in two streamed passes ([`segment_source`](crate::segmentation::segment_source)), holding a chunk at
//! a time, the hand's base resampled onto a 1 ms grid (41 bytes per millisecond of session),
//! the joint angles, contacts and object states of a session of a minute or so between the
//! passes (read by the second pass and then by the approach templates), and
//! each grasp's accumulators: 34 MB for a minute, 218 MB for an hour (see [`segment_source`](crate::segmentation::segment_source)).
//! [`ingest_files`] analyses [`INGEST_FILES_IN_FLIGHT`] files at once.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};

use crate::assist::offline::{approach_templates, APPROACH_TOPICS};
use crate::error::RecordingError;
use crate::mcap_io::pool::CHUNK_BUFFERS;
use crate::mcap_io::ReadLimits;
use crate::segmentation::{segment_source_keeping, SegmentParams, Skill};
use crate::session::{KeptMessages, SessionSource, KEPT_MESSAGES_BUDGET};
use crate::store::{
    IngestOutcome, NewSkill, ObjectShape, SessionMeta, StagedBlob, Store, StoreError,
};

/// Why an ingest failed. Nothing is stored in either case.
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// The bytes are not a valid session (corrupt, truncated, missing topics, ...).
    #[error("not a valid session: {0}")]
    InvalidSession(#[from] RecordingError),
    /// The store refused or failed.
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// Reads, validates and segments a session held in memory: the session's metadata for the
/// store and one [`NewSkill`] per grasp (with the full parameters as JSON). A replay recording
/// is refused ([`RecordingError::ReplayRecording`]).
pub fn analyse(bytes: &[u8], name: &str) -> Result<(SessionMeta, Vec<NewSkill>), RecordingError> {
    analyse_source(&SessionSource::Bytes { bytes, name })
}

/// [`analyse`] of a session file or bytes, streamed ([`segment_source`](crate::segmentation::segment_source)): memory bounded by
/// the session's grid and a chunk, not the file.
pub fn analyse_source(
    source: &SessionSource<'_>,
) -> Result<(SessionMeta, Vec<NewSkill>), RecordingError> {
    // A replay's MCAP reads like a session but is a robot replaying a skill: its "skill" would
    // be shape `unknown` with no parameters (refused by `segment_source`).
    // The first pass keeps the joint angles too, so the approach templates below need no third
    // pass over the file. They add about half to what segmentation keeps (0.67 MB a second of
    // a three-object session in all), so the budget grows by half: the sessions whose second
    // pass reads no file stay the same (a minute or so).
    let mut kept = KeptMessages::new(KEPT_MESSAGES_BUDGET * 3 / 2).also(APPROACH_TOPICS);
    let (head, seg) = segment_source_keeping(
        source,
        &ReadLimits::streaming(),
        &SegmentParams::default(),
        &mut kept,
    )?;
    let m = &head.metadata;
    let object: serde_json::Value = m
        .get("object")
        .and_then(|s| serde_json::from_str(s).ok())
        .unwrap_or(serde_json::Value::Null);
    let (first, last) = head.object_span_ns;
    let meta = SessionMeta {
        scenario: m.get("scenario").cloned(),
        seed: m.get("seed").and_then(|s| s.parse().ok()),
        hand: m.get("hand").cloned().unwrap_or_else(|| "unknown".into()),
        object_shape: object
            .get("shape")
            .and_then(|v| v.as_str())
            .and_then(|name| name.parse().ok())
            .unwrap_or(ObjectShape::Unknown),
        object_mass: object.get("mass").and_then(|v| v.as_f64()).unwrap_or(0.0),
        mu: object.get("mu").and_then(|v| v.as_f64()).unwrap_or(0.0),
        duration_ns: last.saturating_sub(first),
        started_at: m.get("started_at").cloned(),
        extra: extra_of(m, head.live.as_ref()),
    };
    // What recognition needs of each grasp: its approach template, from the kept messages (or
    // the file once more, for a long session) up to the last grasp's grip, 0.8 s after its
    // first touch.
    let templates = approach_templates(source, Some(&kept), m, &seg.skills, None)?;
    drop(kept);
    let skills = seg
        .skills
        .iter()
        .zip(templates)
        .map(|(s, t)| {
            let mut new = to_new_skill(s);
            new.approach = t.map(|t| t.to_vec());
            new
        })
        .collect();
    Ok((meta, skills))
}

/// A session's further parameters for the store: its `session` metadata record, and a live
/// session's `live` record (how it ended, whether it is complete) under `live`.
fn extra_of(
    session: &std::collections::BTreeMap<String, String>,
    live: Option<&std::collections::BTreeMap<String, String>>,
) -> serde_json::Value {
    let mut extra = serde_json::to_value(session).unwrap_or(serde_json::Value::Null);
    if let (Some(live), Some(map)) = (live, extra.as_object_mut()) {
        map.insert(
            crate::live::LIVE_METADATA.to_owned(),
            serde_json::to_value(live).unwrap_or(serde_json::Value::Null),
        );
    }
    extra
}

/// The store's indexed columns of a skill plus its full parameters.
fn to_new_skill(s: &Skill) -> NewSkill {
    let p = &s.parameters;
    let (shape, mass, mu) = match &p.object {
        Some(o) => (o.shape.into(), o.mass, o.mu),
        None => (ObjectShape::Unknown, 0.0, 0.0),
    };
    let start = s
        .phases
        .first()
        .map(|x| x.start_ns)
        .unwrap_or(p.source.start_ns);
    let end = s.phases.last().map(|x| x.end_ns).unwrap_or(p.source.end_ns);
    NewSkill {
        object_shape: shape,
        object_name: p.object.as_ref().and_then(|o| o.name.clone()),
        object_mass: mass,
        mu,
        contact_count: p.contact_count as i64,
        contact_model: p.contact_model,
        // The label the store's `grasp_type` filter documents: the family and the number of
        // opposing virtual fingers, e.g. `precision-2vf` (the family alone filters all of them).
        grasp_type: format!(
            "{}-{}vf",
            p.grasp_type.label, p.grasp_type.opposing_virtual_fingers
        ),
        quality: p.quality.as_ref().map(|q| q.epsilon).unwrap_or(0.0),
        volume: p.quality.as_ref().map(|q| q.volume).unwrap_or(0.0),
        duration_s: end.saturating_sub(start) as f64 * 1e-9,
        start_ns: start as i64,
        end_ns: end as i64,
        phase_durations: p.phase_durations.iter().map(|(k, v)| (*k, *v)).collect(),
        feature: p.feature.to_vec(),
        params: serde_json::to_value(s).unwrap_or(serde_json::Value::Null),
        approach: None,
        matched_skill_id: None,
    }
}

/// Ingests an upload streamed to disk ([`StagedBlob`], finished): analysed from the file in
/// two streamed passes on a blocking thread, then moved to its content address in the store
/// with its rows. Memory does not grow with the file. Nothing is stored if it is refused.
pub async fn ingest_staged(
    store: &Store,
    staged: StagedBlob,
    name: String,
) -> Result<IngestOutcome, IngestError> {
    let prepared = tokio::task::spawn_blocking(move || analyse_staged(staged, &name))
        .await
        .map_err(|e| task_failed("analysis", e))??;
    prepared.commit(store).await
}

/// Ingests a session file: copied into the store's staging area a megabyte at a time while
/// hashed, then as [`ingest_staged`]. Memory does not grow with the file.
pub async fn ingest_file(
    store: &Store,
    path: PathBuf,
    name: String,
) -> Result<IngestOutcome, IngestError> {
    let staging = store.clone();
    let prepared = tokio::task::spawn_blocking(move || prepare_file(&staging, &path, &name))
        .await
        .map_err(|e| task_failed("analysis", e))??;
    prepared.commit(store).await
}

/// A session file staged in the store (copied while hashed) and analysed: its transaction
/// is all that is left ([`Prepared::commit`]). Dropped instead, nothing is stored.
#[derive(Debug)]
pub struct Prepared {
    staged: StagedBlob,
    meta: SessionMeta,
    skills: Vec<NewSkill>,
}

impl Prepared {
    /// Stores the session: its file moved to its content address, its rows in one
    /// transaction ([`Store::ingest_staged`]).
    pub async fn commit(self, store: &Store) -> Result<IngestOutcome, IngestError> {
        Ok(store
            .ingest_staged(self.staged, self.meta, self.skills)
            .await?)
    }
}

/// Copies the session file at `path` into the store's staging area a megabyte at a time while
/// hashing it, and analyses the copy ([`analyse_source`], two streamed passes; its errors
/// name the file `name`). Blocking: call on a blocking thread. Memory does not grow with the
/// file.
pub fn prepare_file(store: &Store, path: &Path, name: &str) -> Result<Prepared, IngestError> {
    use std::io::Read;
    let io = |e: std::io::Error| {
        IngestError::from(RecordingError::io(format!("reading {}", path.display()), e))
    };
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut staged = store.stage_upload()?;
    // A megabyte at a time, into a buffer reused from one file to the next.
    let mut buffer = CHUNK_BUFFERS.take(1 << 20);
    buffer.resize(1 << 20, 0);
    let copied = loop {
        match file.read(&mut buffer) {
            Ok(0) => break Ok(()),
            Ok(n) => {
                if let Err(e) = staged.write(&buffer[..n]) {
                    break Err(IngestError::from(e));
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => break Err(io(e)),
        }
    };
    CHUNK_BUFFERS.give(buffer);
    copied?;
    analyse_staged(staged, name)
}

/// Finishes `staged` (its hash; its fsync starts beside) and analyses it; errors name it
/// `name`. Blocking.
fn analyse_staged(mut staged: StagedBlob, name: &str) -> Result<Prepared, IngestError> {
    staged.finish()?;
    // The file is ours, not the client's: errors name what they sent it as.
    let (meta, skills) = analyse_source(&SessionSource::File(staged.path()))
        .map_err(|e| rename(e, staged.path(), name))?;
    Ok(Prepared {
        staged,
        meta,
        skills,
    })
}

/// Session files analysed at once by [`ingest_files`] as `icms ingest` runs it: one file at a
/// time leaves the cores idle while its two reading threads hand chunks over and while its
/// commit waits for fsyncs (measured on two cores with 10 s sessions: 46-49 files a second
/// one at a time, 60-68 two at a time, no more with three).
pub const INGEST_FILES_IN_FLIGHT: usize = 2;

/// Ingests session files one transaction each, in the order given, as [`ingest_file`] does
/// each, but overlapping them: up to `in_flight` files are staged and analysed at once on
/// blocking threads, ahead of the store's commits, which stay one at a time and in order (the
/// next file's analysis runs while a session's file and rows are made durable). `each` gets
/// each file's index and outcome in order, as soon as its commit ends; a file that fails does
/// not stop the others. Memory: `in_flight` analyses' worth.
pub async fn ingest_files(
    store: &Store,
    files: &[(PathBuf, String)],
    in_flight: usize,
    mut each: impl FnMut(usize, Result<IngestOutcome, IngestError>),
) {
    type Task = tokio::task::JoinHandle<Result<Prepared, IngestError>>;
    let in_flight = in_flight.max(1);
    let mut pending: VecDeque<(usize, Task)> = VecDeque::with_capacity(in_flight);
    let mut next = 0;
    let mut start = |pending: &mut VecDeque<(usize, Task)>| {
        while pending.len() < in_flight && next < files.len() {
            let (path, name) = files[next].clone();
            let staging = store.clone();
            let task = tokio::task::spawn_blocking(move || prepare_file(&staging, &path, &name));
            pending.push_back((next, task));
            next += 1;
        }
    };
    start(&mut pending);
    while let Some((i, task)) = pending.pop_front() {
        let prepared = task.await.map_err(|e| task_failed("analysis", e));
        // Its analysis is over: the next file's starts while this one commits.
        start(&mut pending);
        let outcome = match prepared {
            Ok(Ok(p)) => p.commit(store).await,
            Ok(Err(e)) | Err(e) => Err(e),
        };
        each(i, outcome);
    }
}

/// The error of a blocking task (`what`) that panicked or was cancelled.
fn task_failed(what: &str, e: tokio::task::JoinError) -> IngestError {
    IngestError::Store(StoreError::InvalidInput(format!("{what} task failed: {e}")))
}

/// `e` with the staged file's path replaced by `name` in its message.
fn rename(e: RecordingError, path: &std::path::Path, name: &str) -> RecordingError {
    let shown = path.display().to_string();
    match e {
        RecordingError::InvalidInput { location, detail } => RecordingError::InvalidInput {
            location: location.replace(&shown, name),
            detail,
        },
        RecordingError::ReplayRecording { what, .. } => RecordingError::ReplayRecording {
            name: name.to_owned(),
            what,
        },
        other => other,
    }
}

/// Ingests session bytes: analysis on a blocking thread (never on the async workers), then one
/// atomic, idempotent store transaction. The same bytes again give the same session id.
pub async fn ingest_bytes(
    store: &Store,
    bytes: Vec<u8>,
    name: String,
) -> Result<IngestOutcome, IngestError> {
    let (bytes, analysed) = tokio::task::spawn_blocking(move || {
        let r = analyse(&bytes, &name);
        (bytes, r)
    })
    .await
    .map_err(|e| task_failed("analysis", e))?;
    let (meta, skills) = analysed?;
    Ok(store.ingest(&bytes, meta, skills).await?)
}
