//! Ingest: a session file becomes a stored session with its skills, in one step — read and
//! validated (CRC prevalidation, record limits, decompression bounded by the upload's length,
//! contents checked), segmented into hand-independent skills, and stored atomically and
//! idempotently by [`Store::ingest`].
//!
//! Memory: reading an upload of `N` bytes holds at most
//! [`ReadLimits::decompressed_limit`]`(N)` (`128 N + 1 MiB`, at most 4 GiB) of decompressed
//! and indexed data besides the upload itself and the contact and object samples decoded (see
//! [`ReadLimits`]).

use crate::error::RecordingError;
use crate::mcap_io::ReadLimits;
use crate::segmentation::{segment, SegmentParams, Skill};
use crate::session::{read_session_bytes_with, DecodeTopics};
use crate::store::{IngestOutcome, NewSkill, SessionMeta, Store, StoreError, UNKNOWN_SHAPE};

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
    let session = read_session_bytes_with(
        bytes,
        name,
        &ReadLimits::default(),
        DecodeTopics::SEGMENTATION,
    )?;
    // A replay's MCAP reads like a session but is a robot replaying a skill: its "skill" would
    // be shape `unknown` with no parameters.
    session.ensure_grasp_session(name)?;
    let seg = segment(&session, &SegmentParams::default());
    let m = &session.metadata;
    let object: serde_json::Value = m
        .get("object")
        .and_then(|s| serde_json::from_str(s).ok())
        .unwrap_or(serde_json::Value::Null);
    let duration_ns = match (session.object.first(), session.object.last()) {
        (Some(a), Some(b)) => b.0.saturating_sub(a.0),
        _ => 0,
    };
    let meta = SessionMeta {
        scenario: m.get("scenario").cloned(),
        seed: m.get("seed").and_then(|s| s.parse().ok()),
        hand: m.get("hand").cloned().unwrap_or_else(|| "unknown".into()),
        object_shape: object
            .get("shape")
            .and_then(|v| v.as_str())
            .unwrap_or("unknown")
            .to_string(),
        object_mass: object.get("mass").and_then(|v| v.as_f64()).unwrap_or(0.0),
        mu: object.get("mu").and_then(|v| v.as_f64()).unwrap_or(0.0),
        duration_ns,
        started_at: m.get("started_at").cloned(),
        extra: serde_json::to_value(m).unwrap_or(serde_json::Value::Null),
    };
    let skills = seg.skills.iter().map(to_new_skill).collect();
    Ok((meta, skills))
}

/// The store's indexed columns of a skill plus its full parameters.
fn to_new_skill(s: &Skill) -> NewSkill {
    let p = &s.parameters;
    let (shape, mass, mu) = match &p.object {
        Some(o) => (o.shape.clone(), o.mass, o.mu),
        None => (UNKNOWN_SHAPE.to_owned(), 0.0, 0.0),
    };
    let start = s
        .phases
        .first()
        .map(|x| x.start_ns)
        .unwrap_or(p.source.start_ns);
    let end = s.phases.last().map(|x| x.end_ns).unwrap_or(p.source.end_ns);
    NewSkill {
        object_shape: shape,
        object_mass: mass,
        mu,
        contact_count: p.contact_count as i64,
        contact_model: p.contact_model.clone(),
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
        phase_durations: p
            .phase_durations
            .iter()
            .map(|(k, v)| (k.clone(), *v))
            .collect(),
        feature: p.feature.to_vec(),
        params: serde_json::to_value(s).unwrap_or(serde_json::Value::Null),
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
    .map_err(|e| {
        IngestError::Store(StoreError::InvalidInput(format!(
            "analysis task failed: {e}"
        )))
    })?;
    let (meta, skills) = analysed?;
    Ok(store.ingest(&bytes, meta, skills).await?)
}
