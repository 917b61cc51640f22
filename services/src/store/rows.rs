//! The store's rows as the data base gives them (`sqlx::FromRow`, plain column types), and
//! their conversion into the records callers get: JSON columns parsed, names checked against
//! dfs-core's types, feature vectors decoded. A row that does not convert is
//! [`StoreError::Corrupt`], naming the row and the column.
//!
//! The columns hold the same representation in every backend (TEXT for names and JSON, a
//! little-endian `f32` BLOB for vectors), so these conversions are shared.

use dfs_core::names::Named;
use dfs_core::replay::FailureReason;

use super::catalog::IndexedSkill;
use super::error::StoreError;
use super::types::{HandSummary, Replay, SessionRecord, SkillRecord, StaleSession, FEATURE_DIM};
use crate::assist::features::{TEMPLATE_DIM, TEMPLATE_DIM_V2};

pub(crate) use store_postgres::rows::{
    HandRow, HandSummaryRow, IndexedSkillRow, JobRow, ReplayRow, SessionRow, SkillRow,
    StaleSessionRow, StoredSkillRow,
};

/// A feature vector as its column holds it.
pub(crate) fn feature_to_blob(f: &[f32; FEATURE_DIM]) -> Vec<u8> {
    f.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// An approach template as its column holds it.
pub(crate) fn approach_to_blob(a: &[f32]) -> Vec<u8> {
    a.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// `N` little-endian `f32` from the column `what` of skill `id`.
fn floats<const N: usize>(id: i64, what: &str, bytes: &[u8]) -> Result<[f32; N], StoreError> {
    if bytes.len() != N * 4 {
        return Err(StoreError::Corrupt(format!(
            "skill {id}: {what} has {} bytes, expected {}",
            bytes.len(),
            N * 4
        )));
    }
    let mut f = [0.0f32; N];
    for (v, c) in f.iter_mut().zip(bytes.chunks_exact(4)) {
        *v = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    }
    Ok(f)
}

/// The feature vector of skill `id` from its column.
pub(crate) fn feature_from_blob(id: i64, bytes: &[u8]) -> Result<[f32; FEATURE_DIM], StoreError> {
    floats(id, "feature", bytes)
}

/// The approach template of skill `id` from its column (`None` for NULL).
pub(crate) fn approach_from_blob(
    id: i64,
    bytes: Option<&[u8]>,
) -> Result<Option<[f32; TEMPLATE_DIM]>, StoreError> {
    // A template stored by segmentation version 2 lacks the grip and the scene: read with
    // them not seen.
    bytes
        .map(|b| match b.len() / 4 {
            TEMPLATE_DIM_V2 => {
                let old: [f32; TEMPLATE_DIM_V2] = floats(id, "approach", b)?;
                let mut t = [f32::NAN; TEMPLATE_DIM];
                t[..TEMPLATE_DIM_V2].copy_from_slice(&old);
                Ok(t)
            }
            _ => floats(id, "approach", b),
        })
        .transpose()
}

/// The name in the TEXT column `column` of skill `id`'s row as a value of `T` (a shape, a
/// contact model): a name `T` does not know is a corrupt row, named.
fn named<T: Named>(id: i64, column: &str, text: &str) -> Result<T, StoreError> {
    T::from_name(text).map_err(|e| StoreError::Corrupt(format!("skill {id}: {column}: {e}")))
}

/// A segmentation version from its signed column.
fn segmentation_version(v: i64) -> Result<u32, StoreError> {
    u32::try_from(v)
        .map_err(|_| StoreError::Corrupt(format!("segmentation version {v} is out of range")))
}

/// The segmentation version of session `session_id` from its signed column.
pub(crate) fn session_version(session_id: i64, v: i64) -> Result<u32, StoreError> {
    u32::try_from(v).map_err(|_| {
        StoreError::Corrupt(format!(
            "session {session_id}: segmentation version {v} is out of range"
        ))
    })
}

impl TryFrom<SkillRow> for SkillRecord {
    type Error = StoreError;

    fn try_from(r: SkillRow) -> Result<Self, StoreError> {
        let id = r.id;
        Ok(SkillRecord {
            id,
            session_id: r.session_id,
            object_shape: named(id, "object_shape", &r.object_shape)?,
            object_name: r.object_name,
            object_mass: r.object_mass,
            mu: r.mu,
            contact_count: r.contact_count,
            contact_model: named(id, "contact_model", &r.contact_model)?,
            grasp_type: r.grasp_type,
            quality: r.quality,
            volume: r.volume,
            duration_s: r.duration_s,
            start_ns: r.start_ns,
            end_ns: r.end_ns,
            phase_durations: serde_json::from_str(&r.phase_durations)
                .map_err(|e| StoreError::Corrupt(format!("skill {id}: phase_durations: {e}")))?,
            feature: feature_from_blob(id, &r.feature)?.to_vec(),
            params: serde_json::from_str(&r.params)?,
            approach: approach_from_blob(id, r.approach.as_deref())?
                .map(|a| a.iter().map(|v| v.is_finite().then_some(*v)).collect()),
            matched_skill_id: r.matched_skill_id,
            segmentation_version: segmentation_version(r.segmentation_version)?,
            created_at: r.created_at,
        })
    }
}

impl TryFrom<SessionRow> for SessionRecord {
    type Error = StoreError;

    fn try_from(r: SessionRow) -> Result<Self, StoreError> {
        let id = r.id;
        Ok(SessionRecord {
            id,
            sha256: r.sha256,
            size_bytes: r.size_bytes,
            blob_path: r.blob_path,
            meta: serde_json::from_str(&r.meta)
                .map_err(|e| StoreError::Corrupt(format!("session {id}: meta: {e}")))?,
            skill_ids: serde_json::from_str(&r.skill_ids)?,
            matched_skill_ids: serde_json::from_str(&r.matched_skill_ids)?,
            segmentation_version: segmentation_version(r.segmentation_version)?,
            created_at: r.created_at,
        })
    }
}

impl TryFrom<ReplayRow> for Replay {
    type Error = StoreError;

    fn try_from(r: ReplayRow) -> Result<Self, StoreError> {
        let id = r.id;
        let mut report: serde_json::Value = serde_json::from_str(&r.report)?;
        // Replays stored before the report took the torque the joints applied (clamped at the
        // limit) hold the peak of the torque asked for, which could exceed it. The applied
        // torque's peak is that, at most 1: the same number the report gives today.
        if let Some(ratio) = report.get_mut("peak_torque_ratio") {
            if ratio.as_f64().is_some_and(|r| r > 1.0) {
                *ratio = 1.0.into();
            }
        }
        Ok(Replay {
            id,
            skill_id: r.skill_id,
            hand: r.hand,
            success: r.success,
            failure_reason: r
                .failure_reason
                .as_deref()
                .map(FailureReason::from_name)
                .transpose()
                .map_err(|e| StoreError::Corrupt(format!("replay {id}: failure_reason: {e}")))?,
            report,
            sha256: r.sha256,
            size_bytes: r.size_bytes,
            blob_path: r.blob_path,
            created_at: r.created_at,
        })
    }
}

impl TryFrom<HandSummaryRow> for HandSummary {
    type Error = StoreError;

    fn try_from(r: HandSummaryRow) -> Result<Self, StoreError> {
        Ok(HandSummary {
            name: r.name,
            builtin: false,
            fingers: serde_json::from_str(&r.fingers)?,
            dof: usize::try_from(r.dof)
                .map_err(|_| StoreError::Corrupt(format!("dof {}", r.dof)))?,
            dof_names: serde_json::from_str(&r.dof_names)?,
            torque_limit: [r.torque_limit_min, r.torque_limit_max],
            created_at: Some(r.created_at),
        })
    }
}

impl TryFrom<HandRow> for super::types::Hand {
    type Error = StoreError;

    fn try_from(r: HandRow) -> Result<Self, StoreError> {
        let spec = serde_json::from_str(&r.spec)?;
        Ok(super::types::Hand {
            summary: HandSummaryRow {
                name: r.name,
                dof: r.dof,
                fingers: r.fingers,
                dof_names: r.dof_names,
                torque_limit_min: r.torque_limit_min,
                torque_limit_max: r.torque_limit_max,
                created_at: r.created_at,
            }
            .try_into()?,
            spec: Some(spec),
            urdf: Some(r.urdf),
        })
    }
}

impl TryFrom<IndexedSkillRow> for IndexedSkill {
    type Error = StoreError;

    fn try_from(r: IndexedSkillRow) -> Result<Self, StoreError> {
        Ok(IndexedSkill {
            id: r.id,
            feature: feature_from_blob(r.id, &r.feature)?,
            approach: approach_from_blob(r.id, r.approach.as_deref())?,
            object_shape: r.object_shape,
            grasp_type: r.grasp_type,
            object_name: r.object_name,
        })
    }
}

impl TryFrom<StaleSessionRow> for StaleSession {
    type Error = StoreError;

    fn try_from(r: StaleSessionRow) -> Result<Self, StoreError> {
        Ok(StaleSession {
            id: r.id,
            segmentation_version: session_version(r.id, r.segmentation_version)?,
            skill_count: usize::try_from(r.skill_count).unwrap_or(0),
        })
    }
}

/// Converts every row of `rows`, stopping at the first that fails.
pub(crate) fn convert<R, T: TryFrom<R, Error = StoreError>>(
    rows: Vec<R>,
) -> Result<Vec<T>, StoreError> {
    rows.into_iter().map(T::try_from).collect()
}
