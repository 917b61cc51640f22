//! Reprocessing: the stored sessions whose skills an older segmentation made
//! ([`SEGMENTATION_VERSION`] recorded below the current one) are segmented again from their
//! stored files, so that a data base keeps up with improvements to segmentation and physics
//! (`icms reprocess`).
//!
//! Each session goes through what an ingest does, [`crate::ingest::analyse`] on its stored
//! bytes (checked against their SHA-256 first), and its skills are replaced in one transaction
//! ([`Store::replace_session_skills`]): skills that come out the same are kept with their ids
//! and replays, the others are removed with their replays (a replay retargeted parameters
//! that no longer exist), the new ones added, and the version recorded.
//!
//! - **Idempotent**: a session is picked only while its version is below the current one, and
//!   its transaction raises it; a second run finds nothing to do (sessions that failed are
//!   tried again).
//! - **Interruptible**: a kill at any moment leaves every session either as it was or fully
//!   reprocessed (its transaction commits or not); the next run takes up the rest. The `stop`
//!   flag ends a run between two sessions.
//! - **Failures are per session**: a session whose file cannot be read, does not match its
//!   recorded hash, no longer reads as a session or cannot be stored is reported and keeps its
//!   skills and version; the others are reprocessed.
//!
//! Sessions are processed one at a time, each file read into memory as an ingest reads it
//! (the same bounds). The session rows' metadata is left as stored.

use std::sync::atomic::{AtomicBool, Ordering};

use serde::Serialize;

use crate::ingest::analyse;
use crate::segmentation::SEGMENTATION_VERSION;
use crate::store::{ReplacedSkills, StaleSession, Store, StoreError};

/// A session that could not be reprocessed; it keeps its skills and version.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FailedSession {
    /// Session id.
    pub session_id: i64,
    /// The segmentation version its skills still have.
    pub segmentation_version: u32,
    /// Why: the file could not be read or does not match its hash, does not read as a session
    /// (with the reader's reason), or the store refused.
    pub error: String,
}

/// What a reprocessing run did.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct ReprocessReport {
    /// The current segmentation version: what reprocessed sessions now have.
    pub segmentation_version: u32,
    /// Sessions segmented by an older version when the run began.
    pub sessions_stale: usize,
    /// Of these, sessions reprocessed (their skills replaced or confirmed, the version raised).
    pub sessions_reprocessed: usize,
    /// Sessions deleted, or reprocessed by another process, while the run went on.
    pub sessions_skipped: usize,
    /// Sessions that failed (see `failed`).
    pub sessions_failed: usize,
    /// Sessions not reached because the run was stopped.
    pub sessions_left: usize,
    /// Sessions a newer segmentation made the skills of (a newer binary's): left alone.
    pub sessions_newer: u64,
    /// Skills of the reprocessed sessions before.
    pub skills_before: usize,
    /// Skills of the reprocessed sessions after.
    pub skills_after: usize,
    /// Skills that came out the same: kept, with their ids and replays.
    pub skills_kept: usize,
    /// Skills removed (they did not come out of the new segmentation the same).
    pub skills_removed: usize,
    /// Skills added.
    pub skills_added: usize,
    /// Replays removed with the removed skills.
    pub replays_removed: usize,
    /// Whether the run was stopped before the last session.
    pub interrupted: bool,
    /// Each reprocessed session, by ascending id.
    pub sessions: Vec<ReplacedSkills>,
    /// Each failed session, by ascending id.
    pub failed: Vec<FailedSession>,
}

/// Progress of a run, reported as it goes.
#[derive(Debug, Clone, Copy)]
pub enum ReprocessEvent<'a> {
    /// Session `index` (from 0) of `total` is being read and segmented.
    Started {
        /// Position of the session in the run.
        index: usize,
        /// Sessions in the run.
        total: usize,
        /// The session.
        session: &'a StaleSession,
    },
    /// A session was reprocessed.
    Reprocessed(&'a ReplacedSkills),
    /// A session was deleted, or reprocessed by another process, meanwhile.
    Skipped(&'a StaleSession),
    /// A session failed; it keeps its skills and version.
    Failed(&'a FailedSession),
}

/// Reprocesses every session of `store` whose skills a segmentation older than
/// [`SEGMENTATION_VERSION`] made, in ascending id order, reporting each step to `on_event`.
/// Checks `stop` before each session and ends the run when it is set.
///
/// Fails only if the sessions cannot be listed; a session that fails is reported in the
/// result (and to `on_event`) and the run goes on.
pub async fn reprocess(
    store: &Store,
    stop: &AtomicBool,
    mut on_event: impl FnMut(ReprocessEvent<'_>),
) -> Result<ReprocessReport, StoreError> {
    let stale = store
        .sessions_segmented_before(SEGMENTATION_VERSION)
        .await?;
    let mut report = ReprocessReport {
        segmentation_version: SEGMENTATION_VERSION,
        sessions_stale: stale.len(),
        sessions_newer: store.sessions_segmented_after(SEGMENTATION_VERSION).await?,
        ..ReprocessReport::default()
    };
    for (index, session) in stale.iter().enumerate() {
        if stop.load(Ordering::Relaxed) {
            report.interrupted = true;
            report.sessions_left = stale.len() - index;
            break;
        }
        on_event(ReprocessEvent::Started {
            index,
            total: stale.len(),
            session,
        });
        match reprocess_one(store, session).await {
            Ok(Some(done)) => {
                on_event(ReprocessEvent::Reprocessed(&done));
                report.sessions_reprocessed += 1;
                report.skills_kept += done.kept_skill_ids.len();
                report.skills_removed += done.removed_skill_ids.len();
                report.skills_added += done.added_skill_ids.len();
                report.skills_before += done.kept_skill_ids.len() + done.removed_skill_ids.len();
                report.skills_after += done.kept_skill_ids.len() + done.added_skill_ids.len();
                report.replays_removed += done.replays_removed;
                report.sessions.push(done);
            }
            Ok(None) => {
                on_event(ReprocessEvent::Skipped(session));
                report.sessions_skipped += 1;
            }
            Err(error) => {
                let failed = FailedSession {
                    session_id: session.id,
                    segmentation_version: session.segmentation_version,
                    error,
                };
                on_event(ReprocessEvent::Failed(&failed));
                report.failed.push(failed);
            }
        }
    }
    report.sessions_failed = report.failed.len();
    Ok(report)
}

/// Reads, segments and stores one session: `Ok(None)` if it was deleted or brought up to
/// date meanwhile, `Err` with the reason if it failed.
async fn reprocess_one(
    store: &Store,
    session: &StaleSession,
) -> Result<Option<ReplacedSkills>, String> {
    let id = session.id;
    let bytes = match store.read_session_blob(id).await {
        Ok(bytes) => bytes,
        Err(StoreError::SessionNotFound(_)) => return Ok(None),
        Err(e) => return Err(e.to_string()),
    };
    let name = format!("session {id}");
    let analysed = tokio::task::spawn_blocking(move || analyse(&bytes, &name))
        .await
        .map_err(|e| format!("segmentation failed: {e}"))?;
    let (_meta, skills) = analysed.map_err(|e| {
        // The reader's errors may start with the name given, which the report already says.
        let e = e.to_string();
        e.strip_prefix(&format!("session {id}: "))
            .map(str::to_owned)
            .unwrap_or(e)
    })?;
    match store
        .replace_session_skills(id, skills, SEGMENTATION_VERSION)
        .await
    {
        Ok(done) => Ok(done),
        Err(StoreError::SessionNotFound(_)) => Ok(None),
        Err(e) => Err(e.to_string()),
    }
}
