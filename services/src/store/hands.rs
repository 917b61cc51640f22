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
use dfs_core::names::Named;
use dfs_core::replay::{FailureReason, ReplayReport};
use sqlx::sqlite::SqliteRow;
use sqlx::{Row as _, Sqlite};

use super::error::StoreError;
use super::types::{Hand, HandSummary, Replay};
use super::{blob, StagedBlob, Store};
use crate::replay::{load_builtin_hand, LoadedHand};

/// Longest hand name.
pub const MAX_HAND_NAME: usize = 64;

const REPLAY_COLUMNS: &str = "id, skill_id, hand, success, failure_reason, report, sha256, \
     size_bytes, blob_path, created_at";

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

fn row_to_summary(row: &SqliteRow) -> Result<HandSummary, StoreError> {
    let fingers: String = row.try_get("fingers")?;
    let dof_names: String = row.try_get("dof_names")?;
    let dof: i64 = row.try_get("dof")?;
    Ok(HandSummary {
        name: row.try_get("name")?,
        builtin: false,
        fingers: serde_json::from_str(&fingers)?,
        dof: usize::try_from(dof).map_err(|_| StoreError::Corrupt(format!("dof {dof}")))?,
        dof_names: serde_json::from_str(&dof_names)?,
        torque_limit: [
            row.try_get("torque_limit_min")?,
            row.try_get("torque_limit_max")?,
        ],
        created_at: Some(row.try_get("created_at")?),
    })
}

fn row_to_replay(row: &SqliteRow) -> Result<Replay, StoreError> {
    let id: i64 = row.try_get("id")?;
    let report: String = row.try_get("report")?;
    let mut report: serde_json::Value = serde_json::from_str(&report)?;
    // Replays stored before the report took the torque the joints applied (clamped at the
    // limit) hold the peak of the torque asked for, which could exceed it. The applied torque's
    // peak is that, at most 1: the same number the report gives today.
    if let Some(ratio) = report.get_mut("peak_torque_ratio") {
        if ratio.as_f64().is_some_and(|r| r > 1.0) {
            *ratio = 1.0.into();
        }
    }
    Ok(Replay {
        id,
        skill_id: row.try_get("skill_id")?,
        hand: row.try_get("hand")?,
        success: row.try_get("success")?,
        failure_reason: row
            .try_get::<Option<&str>, _>("failure_reason")?
            .map(FailureReason::from_name)
            .transpose()
            .map_err(|e| StoreError::Corrupt(format!("replay {id}: failure_reason: {e}")))?,
        report,
        sha256: row.try_get("sha256")?,
        size_bytes: row.try_get("size_bytes")?,
        blob_path: row.try_get("blob_path")?,
        created_at: row.try_get("created_at")?,
    })
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
        let created_at: Option<String> = sqlx::query_scalar(
            "INSERT INTO hands (name, spec, urdf, dof, fingers, dof_names, torque_limit_min, \
             torque_limit_max) VALUES (?, ?, ?, ?, ?, ?, ?, ?) \
             ON CONFLICT (name) DO NOTHING RETURNING created_at",
        )
        .bind(&name)
        .bind(serde_json::to_string(&spec)?)
        .bind(&urdf)
        .bind(summary.dof as i64)
        .bind(serde_json::to_string(&summary.fingers)?)
        .bind(serde_json::to_string(&summary.dof_names)?)
        .bind(summary.torque_limit[0])
        .bind(summary.torque_limit[1])
        .fetch_optional(&self.inner.pool)
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
        let rows = sqlx::query(
            "SELECT name, dof, fingers, dof_names, torque_limit_min, torque_limit_max, \
             created_at FROM hands ORDER BY id",
        )
        .fetch_all(&self.inner.pool)
        .await?;
        let mut out = builtin_summaries().to_vec();
        for row in &rows {
            out.push(row_to_summary(row)?);
        }
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
        let row = sqlx::query(
            "SELECT name, spec, urdf, dof, fingers, dof_names, torque_limit_min, \
             torque_limit_max, created_at FROM hands WHERE name = ?",
        )
        .bind(name)
        .fetch_optional(&self.inner.pool)
        .await?
        .ok_or_else(|| StoreError::HandNotFound(name.to_owned()))?;
        let spec: String = row.try_get("spec")?;
        Ok(Hand {
            summary: row_to_summary(&row)?,
            spec: Some(serde_json::from_str(&spec)?),
            urdf: Some(row.try_get("urdf")?),
        })
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
        let dir = self.inner.dir.clone();
        let size = mcap.len() as i64;
        let (sha256, rel) = tokio::task::spawn_blocking(move || {
            let sha = blob::sha256_hex(&mcap);
            blob::write_atomic(&dir, &sha, &mcap).map(|rel| (sha, rel))
        })
        .await
        .map_err(|e| StoreError::Corrupt(format!("blob writer task failed: {e}")))??;
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
        let dir = self.inner.dir.clone();
        let (sha256, size) = (mcap.sha256().to_owned(), mcap.len() as i64);
        let rel = tokio::task::spawn_blocking(move || mcap.commit(&dir))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob writer task failed: {e}")))??;
        self.insert_replay_row(skill_id, hand, report, (sha256, size, rel), guard)
            .await
    }

    /// The row of a replay whose blob (sha256, size, relative path) is written, under the
    /// blob lock's read `guard`.
    async fn insert_replay_row(
        &self,
        skill_id: i64,
        hand: &str,
        report: &ReplayReport,
        (sha256, size, rel): (String, i64, String),
        guard: tokio::sync::RwLockReadGuard<'_, ()>,
    ) -> Result<Replay, StoreError> {
        let report_json = serde_json::to_string(report)?;
        let row = sqlx::query(&format!(
            "INSERT INTO replays (skill_id, hand, success, failure_reason, report, sha256, \
             size_bytes, blob_path) SELECT ?, ?, ?, ?, ?, ?, ?, ? \
             WHERE EXISTS (SELECT 1 FROM skills WHERE id = ?) RETURNING {REPLAY_COLUMNS}"
        ))
        .bind(skill_id)
        .bind(hand)
        .bind(report.success)
        .bind(report.failure_reason.map(|r| r.name()))
        .bind(&report_json)
        .bind(&sha256)
        .bind(size)
        .bind(&rel)
        .bind(skill_id)
        .fetch_optional(&self.inner.pool)
        .await?;
        let Some(row) = row else {
            // The skill was deleted while the replay ran: remove the blob unless a row names
            // the same bytes. Under the exclusive lock no writer of the same bytes is between
            // writing its blob and inserting its row.
            drop(guard);
            let _exclusive = self.inner.blob_lock.write().await;
            self.remove_unreferenced_blobs(&[(sha256, rel)]).await;
            return Err(StoreError::SkillNotFound(skill_id));
        };
        let replay = row_to_replay(&row)?;
        tracing::debug!(replay_id = replay.id, skill_id, hand, "stored replay");
        Ok(replay)
    }

    /// One replay.
    pub async fn get_replay(&self, id: i64) -> Result<Replay, StoreError> {
        let row = sqlx::query(&format!(
            "SELECT {REPLAY_COLUMNS} FROM replays WHERE id = ?"
        ))
        .bind(id)
        .fetch_optional(&self.inner.pool)
        .await?
        .ok_or(StoreError::ReplayNotFound(id))?;
        row_to_replay(&row)
    }

    /// The replays of one skill, by ascending id; [`StoreError::SkillNotFound`] if no such
    /// skill.
    pub async fn list_replays(&self, skill_id: i64) -> Result<Vec<Replay>, StoreError> {
        let mut tx = self.inner.pool.begin().await?;
        let exists: Option<i64> = sqlx::query_scalar("SELECT id FROM skills WHERE id = ?")
            .bind(skill_id)
            .fetch_optional(&mut *tx)
            .await?;
        if exists.is_none() {
            return Err(StoreError::SkillNotFound(skill_id));
        }
        let rows = sqlx::query(&format!(
            "SELECT {REPLAY_COLUMNS} FROM replays WHERE skill_id = ? ORDER BY id"
        ))
        .bind(skill_id)
        .fetch_all(&mut *tx)
        .await?;
        tx.commit().await?;
        rows.iter().map(row_to_replay).collect()
    }

    /// Absolute path of a replay's MCAP blob.
    pub async fn replay_blob_path(&self, id: i64) -> Result<PathBuf, StoreError> {
        let rel: String = sqlx::query_scalar("SELECT blob_path FROM replays WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.inner.pool)
            .await?
            .ok_or(StoreError::ReplayNotFound(id))?;
        Ok(self.inner.dir.join(rel))
    }

    /// Unlinks the blobs of `deleted` (sha256, relative path) that no session or replay row
    /// names any more. Call with the blob lock held exclusively, after the rows' deletion
    /// committed. Best effort: a leftover blob is harmless garbage.
    pub(super) async fn remove_unreferenced_blobs(&self, deleted: &[(String, String)]) {
        let mut seen = std::collections::BTreeSet::new();
        for (sha256, rel) in deleted {
            if !seen.insert(sha256.as_str()) {
                continue;
            }
            let referenced: Result<Option<i64>, sqlx::Error> = sqlx::query_scalar(
                "SELECT 1 FROM sessions WHERE sha256 = ?1 \
                 UNION ALL SELECT 1 FROM replays WHERE sha256 = ?1 LIMIT 1",
            )
            .bind(sha256)
            .fetch_optional(&self.inner.pool)
            .await;
            match referenced {
                Ok(None) => {
                    if let Err(e) = blob::remove(&self.inner.dir, rel) {
                        tracing::warn!(error = %e, "could not remove a deleted row's blob");
                    }
                }
                Ok(Some(_)) => {}
                Err(e) => tracing::warn!(error = %e, "could not check a blob's references"),
            }
        }
    }
}

/// Deletes the replays of the skills `skill_ids_sql` selects (a subquery binding one value)
/// inside `tx`; returns their blobs as (sha256, relative path).
pub(super) async fn delete_replays_of(
    tx: &mut sqlx::Transaction<'_, Sqlite>,
    skill_ids_sql: &str,
    bound: i64,
) -> Result<Vec<(String, String)>, StoreError> {
    let rows = sqlx::query(&format!(
        "DELETE FROM replays WHERE skill_id IN ({skill_ids_sql}) RETURNING sha256, blob_path"
    ))
    .bind(bound)
    .fetch_all(&mut **tx)
    .await?;
    rows.iter()
        .map(|r| Ok((r.try_get(0)?, r.try_get(1)?)))
        .collect()
}
