//! Robot hands and replays in the store.
//!
//! Hands: the built-in ones come from code ([`dfs_core::hand::BUILTIN_HANDS`]) and are never
//! rows; uploaded ones are rows of `hands`, written only after their model was built from the
//! URDF and spec (so a stored hand always loads), under a name no built-in or other hand has.
//! Replays: a report plus the replay's MCAP as a content-addressed blob (written atomically and
//! fsynced before the row commits, like a session's), deleted with their skill. A blob is
//! unlinked only when no session or replay row names it any more.

use std::path::PathBuf;
use std::sync::OnceLock;

use dfs_core::hand::{HandModel, HandSpec, BUILTIN_HANDS};
use dfs_core::replay::ReplayReport;

use super::catalog::{BlobRef, ExclusiveBlobGuard, NewHand, NewReplayRow};
use super::error::StoreError;
use super::types::{Hand, HandSummary, Replay};
use super::{blob, StagedBlob, Store};
use crate::replay::{load_builtin_hand, LoadedHand};

/// Longest hand name.
pub const MAX_HAND_NAME: usize = 64;

impl HandSummary {
    /// The summary of a loaded hand.
    pub fn of(hand: &LoadedHand, builtin: bool, created_at: Option<String>) -> HandSummary {
        let m = &hand.model;
        let mut fingers = vec![m.fingertips[hand.thumb].name.clone()];
        fingers.extend(
            m.fingertips
                .iter()
                .enumerate()
                .filter(|(k, _)| *k != hand.thumb)
                .map(|(_, t)| t.name.clone()),
        );
        let lo = m.torque_limit.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = m.torque_limit.iter().copied().fold(0.0, f64::max);
        HandSummary {
            name: m.name.clone(),
            builtin,
            fingers,
            dof: m.dof(),
            dof_names: m.dof_names.clone(),
            torque_limit: [lo, hi],
            created_at,
        }
    }
}

impl Hand {
    /// The hand ready to replay on (builds its model; a stored hand was validated when stored).
    pub fn load(&self) -> Result<LoadedHand, StoreError> {
        if self.summary.builtin {
            return load_builtin_hand(&self.summary.name)
                .map_err(|e| StoreError::Corrupt(format!("built-in hand: {e}")));
        }
        let (Some(spec), Some(urdf)) = (&self.spec, &self.urdf) else {
            return Err(StoreError::Corrupt(format!(
                "hand {:?} has no spec or URDF",
                self.summary.name
            )));
        };
        build(spec.clone(), urdf.clone())
            .map_err(|e| StoreError::Corrupt(format!("stored hand {:?}: {e}", self.summary.name)))
    }
}

/// The hand model of `spec` and `urdf`; the error names the problem.
fn build(spec: HandSpec, urdf: String) -> Result<LoadedHand, StoreError> {
    let model =
        HandModel::from_urdf(&urdf, &spec).map_err(|e| StoreError::InvalidHand(e.to_string()))?;
    Ok(LoadedHand {
        thumb: spec.thumb_index(),
        model,
        spec: Some(spec),
        urdf: Some(urdf),
    })
}

/// The built-in hands' summaries, computed once.
fn builtin_summaries() -> &'static [HandSummary] {
    static CELL: OnceLock<Vec<HandSummary>> = OnceLock::new();
    CELL.get_or_init(|| {
        BUILTIN_HANDS
            .iter()
            .map(|name| {
                let hand = load_builtin_hand(name).expect("every built-in hand loads");
                HandSummary::of(&hand, true, None)
            })
            .collect()
    })
}

/// A hand name is usable as a URL path segment and a file name: 1 to 64 of `A-Z a-z 0-9 . _ -`,
/// starting with a letter or digit.
fn check_hand_name(name: &str) -> Result<(), StoreError> {
    let ok = !name.is_empty()
        && name.len() <= MAX_HAND_NAME
        && name.starts_with(|c: char| c.is_ascii_alphanumeric())
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'));
    if ok {
        Ok(())
    } else {
        Err(StoreError::InvalidHand(format!(
            "name {name:?}: use 1 to {MAX_HAND_NAME} letters, digits, '.', '_' or '-', \
             starting with a letter or digit"
        )))
    }
}

impl Store {
    /// Stores an uploaded hand after building its model from `urdf` and `spec` (the hand's name
    /// is the spec's). Refused, storing nothing: an invalid URDF or spec
    /// ([`StoreError::InvalidHand`], naming the problem: a URDF that does not parse, a kinematic
    /// loop, several roots, an unknown fingertip link, a negative mass or radius, ...), a name
    /// that is not URL-safe ([`StoreError::InvalidHand`]), a name of a built-in hand (in any
    /// case) or of a stored hand ([`StoreError::Conflict`]).
    pub async fn put_hand(&self, spec: HandSpec, urdf: String) -> Result<Hand, StoreError> {
        let name = spec.name.clone();
        check_hand_name(&name)?;
        if let Some(builtin) = BUILTIN_HANDS.iter().find(|b| b.eq_ignore_ascii_case(&name)) {
            // "Allegro" beside "allegro" reads as the same hand in every listing and replay.
            return Err(StoreError::Conflict(if *builtin == name {
                format!(
                    "{name:?} is a built-in hand, which cannot be replaced; choose another name"
                )
            } else {
                format!(
                    "{name:?} differs from the built-in hand {builtin:?} only in case; choose \
                     another name"
                )
            }));
        }
        // Building a model parses the URDF and factorises inertias: CPU work, off the workers.
        let hand = tokio::task::spawn_blocking(move || build(spec, urdf))
            .await
            .map_err(|e| StoreError::Corrupt(format!("hand builder task failed: {e}")))??;
        let summary = HandSummary::of(&hand, false, None);
        let (Some(spec), Some(urdf)) = (hand.spec, hand.urdf) else {
            return Err(StoreError::Corrupt("a built hand lost its spec".into()));
        };
        let spec_json = serde_json::to_string(&spec)?;
        let created_at = self
            .inner
            .catalog
            .insert_hand(NewHand {
                name: &name,
                spec_json: &spec_json,
                urdf: &urdf,
                summary: &summary,
            })
            .await?;
        let Some(created_at) = created_at else {
            return Err(StoreError::Conflict(format!(
                "a hand named {name:?} is already stored; choose another name"
            )));
        };
        tracing::debug!(hand = %name, "stored hand");
        Ok(Hand {
            summary: HandSummary {
                created_at: Some(created_at),
                ..summary
            },
            spec: Some(spec),
            urdf: Some(urdf),
        })
    }

    /// Every hand: the built-in ones in their fixed order, then the uploaded ones by upload.
    pub async fn list_hands(&self) -> Result<Vec<HandSummary>, StoreError> {
        let mut out = builtin_summaries().to_vec();
        out.extend(self.inner.catalog.hands().await?);
        Ok(out)
    }

    /// One hand, built-in or uploaded, with its spec and URDF.
    pub async fn get_hand(&self, name: &str) -> Result<Hand, StoreError> {
        if let Some(summary) = builtin_summaries().iter().find(|h| h.name == name) {
            let (spec, urdf) = match dfs_core::hand::builtin_spec(name) {
                Some((s, u)) => (Some(s), Some(u.to_owned())),
                None => (None, None),
            };
            return Ok(Hand {
                summary: summary.clone(),
                spec,
                urdf,
            });
        }
        self.inner
            .catalog
            .hand(name)
            .await?
            .ok_or_else(|| StoreError::HandNotFound(name.to_owned()))
    }

    /// Stores a replay of skill `skill_id` on `hand`: its MCAP bytes as a content-addressed blob
    /// (written atomically and fsynced first), then its row. [`StoreError::SkillNotFound`] if
    /// the skill is gone (deleted while the replay ran); nothing is stored then.
    pub async fn insert_replay(
        &self,
        skill_id: i64,
        hand: &str,
        report: &ReplayReport,
        mcap: Vec<u8>,
    ) -> Result<Replay, StoreError> {
        let guard = self.inner.blob_lock.read().await;
        let size = mcap.len() as i64;
        let (sha256, rel) = self
            .write_blob(move |dir| {
                let sha = blob::sha256_hex(&mcap);
                blob::write_atomic(dir, &sha, &mcap).map(|rel| (sha, rel))
            })
            .await?;
        self.insert_replay_row(skill_id, hand, report, (sha256, size, rel), guard)
            .await
    }

    /// [`Store::insert_replay`] of a replay recorded straight into a [`StagedBlob`] (through its
    /// [`StagedWriter`](super::StagedWriter), then finished): the file is moved to its content
    /// address, never read into memory.
    pub async fn insert_replay_staged(
        &self,
        skill_id: i64,
        hand: &str,
        report: &ReplayReport,
        mcap: StagedBlob,
    ) -> Result<Replay, StoreError> {
        let guard = self.inner.blob_lock.read().await;
        let (sha256, size) = (mcap.sha256().to_owned(), mcap.len() as i64);
        let rel = self.write_blob(move |dir| mcap.commit(dir)).await?;
        self.insert_replay_row(skill_id, hand, report, (sha256, size, rel), guard)
            .await
    }

    /// The row of a replay whose blob (sha256, size, relative path) is written to the data
    /// directory, under the blob lock's read `guard`: the blob is uploaded to the bucket (if
    /// any) and the row inserted holding the cross-server blob lock shared
    /// ([`Store::shared_blob_hold`]).
    async fn insert_replay_row(
        &self,
        skill_id: i64,
        hand: &str,
        report: &ReplayReport,
        (sha256, size, rel): (String, i64, String),
        guard: tokio::sync::RwLockReadGuard<'_, ()>,
    ) -> Result<Replay, StoreError> {
        let report_json = serde_json::to_string(report)?;
        let blob = BlobRef { sha256, rel };
        let hold = self.shared_blob_hold().await?;
        let replay = async {
            self.publish(&blob.rel).await?;
            self.inner
                .catalog
                .insert_replay(NewReplayRow {
                    skill_id,
                    hand,
                    success: report.success,
                    failure_reason: report.failure_reason.map(|r| r.name()),
                    report: &report_json,
                    sha256: &blob.sha256,
                    size_bytes: size,
                    blob_path: &blob.rel,
                })
                .await
        }
        .await;
        hold.release().await;
        let Some(replay) = replay? else {
            // The skill was deleted while the replay ran: remove the blob unless a row names
            // the same bytes. Under the exclusive locks (in-process, and across servers if
            // free) no writer of the same bytes is between writing its blob and inserting
            // its row.
            drop(guard);
            let _exclusive = self.inner.blob_lock.write().await;
            self.remove_unreferenced_blobs(&[blob]).await;
            return Err(StoreError::SkillNotFound(skill_id));
        };
        tracing::debug!(replay_id = replay.id, skill_id, hand, "stored replay");
        Ok(replay)
    }

    /// One replay.
    pub async fn get_replay(&self, id: i64) -> Result<Replay, StoreError> {
        self.inner
            .catalog
            .replay(id)
            .await?
            .ok_or(StoreError::ReplayNotFound(id))
    }

    /// The replays of one skill, by ascending id; [`StoreError::SkillNotFound`] if no such
    /// skill.
    pub async fn list_replays(&self, skill_id: i64) -> Result<Vec<Replay>, StoreError> {
        self.inner
            .catalog
            .replays_of(skill_id)
            .await?
            .ok_or(StoreError::SkillNotFound(skill_id))
    }

    /// Absolute path of a replay's MCAP blob.
    pub async fn replay_blob_path(&self, id: i64) -> Result<PathBuf, StoreError> {
        let rel = self
            .inner
            .catalog
            .replay_blob_path(id)
            .await?
            .ok_or(StoreError::ReplayNotFound(id))?;
        self.local_blob(&rel).await
    }

    /// Unlinks the blobs of `deleted` that no session or replay row names any more. Call with
    /// the blob lock held exclusively, after the rows' deletion committed. Best effort: a
    /// leftover blob is harmless garbage, which the orphan sweep removes later.
    ///
    /// With a bucket shared by several servers, the removals also hold the cross-server blob
    /// lock exclusively ([`Store::try_exclusive_blob_hold`]), so that no other server is
    /// between uploading the same bytes again and committing a row that names them. If
    /// another server is ingesting, the blobs are left for the sweep rather than waited on.
    pub(super) async fn remove_unreferenced_blobs(&self, deleted: &[BlobRef]) {
        if deleted.is_empty() {
            return;
        }
        let exclusive = match self.try_exclusive_blob_hold().await {
            Ok(ExclusiveBlobGuard::Held(g)) => Some(g),
            Ok(ExclusiveBlobGuard::NotNeeded) => None,
            Ok(ExclusiveBlobGuard::Busy) => {
                tracing::info!(
                    blobs = deleted.len(),
                    "another server is ingesting into the bucket: deleted rows' blobs are left \
                     for the orphan sweep"
                );
                return;
            }
            Err(e) => {
                tracing::warn!(error = %e, "could not take the blob lock to remove blobs");
                return;
            }
        };
        self.remove_unreferenced_blobs_locked(deleted).await;
        if let Some(g) = exclusive {
            g.release().await;
        }
    }

    /// [`Store::remove_unreferenced_blobs`] once every blob lock it needs is held.
    async fn remove_unreferenced_blobs_locked(&self, deleted: &[BlobRef]) {
        let mut seen = std::collections::BTreeSet::new();
        for BlobRef { sha256, rel } in deleted {
            if !seen.insert(sha256.as_str()) {
                continue;
            }
            match self.inner.catalog.blob_is_referenced(sha256).await {
                Ok(false) => {
                    if let Err(e) = self.remove_blob(rel).await {
                        tracing::warn!(error = %e, "could not remove a deleted row's blob");
                    }
                }
                Ok(true) => {}
                Err(e) => tracing::warn!(error = %e, "could not check a blob's references"),
            }
        }
    }
}
