//! The store's rows as the data base gives them: plain column types, one struct per query
//! shape, read by both backends (services' SQLite queries and this crate's PostgreSQL ones,
//! through sqlx's `query_as!` or `FromRow`). services converts them into the records callers
//! get, checking every column.

/// A row of `skills`, with its session's segmentation version.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct SkillRow {
    /// Column `id`.
    pub id: i64,
    /// Column `session_id`.
    pub session_id: i64,
    /// Column `object_shape`.
    pub object_shape: String,
    /// Column `object_name`.
    pub object_name: Option<String>,
    /// Column `object_mass`.
    pub object_mass: f64,
    /// Column `mu`.
    pub mu: f64,
    /// Column `contact_count`.
    pub contact_count: i64,
    /// Column `contact_model`.
    pub contact_model: String,
    /// Column `grasp_type`.
    pub grasp_type: String,
    /// Column `quality`.
    pub quality: f64,
    /// Column `volume`.
    pub volume: f64,
    /// Column `duration_s`.
    pub duration_s: f64,
    /// Column `start_ns`.
    pub start_ns: i64,
    /// Column `end_ns`.
    pub end_ns: i64,
    /// Column `phase_durations`.
    pub phase_durations: String,
    /// Column `feature`.
    pub feature: Vec<u8>,
    /// Column `params`.
    pub params: String,
    /// Column `approach`.
    pub approach: Option<Vec<u8>>,
    /// Column `matched_skill_id`.
    pub matched_skill_id: Option<i64>,
    /// Column `created_at`.
    pub created_at: String,
    /// Column `segmentation_version`.
    pub segmentation_version: i64,
}

/// A row of `sessions`, with its skills' ids and matches as JSON arrays.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct SessionRow {
    /// Column `id`.
    pub id: i64,
    /// Column `sha256`.
    pub sha256: String,
    /// Column `size_bytes`.
    pub size_bytes: i64,
    /// Column `blob_path`.
    pub blob_path: String,
    /// Column `meta`.
    pub meta: String,
    /// Column `segmentation_version`.
    pub segmentation_version: i64,
    /// Column `created_at`.
    pub created_at: String,
    /// Column `skill_ids`.
    pub skill_ids: String,
    /// Column `matched_skill_ids`.
    pub matched_skill_ids: String,
}

/// A row of `replays`.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct ReplayRow {
    /// Column `id`.
    pub id: i64,
    /// Column `skill_id`.
    pub skill_id: i64,
    /// Column `hand`.
    pub hand: String,
    /// Column `success`.
    pub success: bool,
    /// Column `failure_reason`.
    pub failure_reason: Option<String>,
    /// Column `report`.
    pub report: String,
    /// Column `sha256`.
    pub sha256: String,
    /// Column `size_bytes`.
    pub size_bytes: i64,
    /// Column `blob_path`.
    pub blob_path: String,
    /// Column `created_at`.
    pub created_at: String,
}

/// The listed columns of a row of `hands`.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct HandSummaryRow {
    /// Column `name`.
    pub name: String,
    /// Column `dof`.
    pub dof: i64,
    /// Column `fingers`.
    pub fingers: String,
    /// Column `dof_names`.
    pub dof_names: String,
    /// Column `torque_limit_min`.
    pub torque_limit_min: f64,
    /// Column `torque_limit_max`.
    pub torque_limit_max: f64,
    /// Column `created_at`.
    pub created_at: String,
}

/// A whole row of `hands`.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct HandRow {
    /// Column `name`.
    pub name: String,
    /// Column `spec`.
    pub spec: String,
    /// Column `urdf`.
    pub urdf: String,
    /// Column `dof`.
    pub dof: i64,
    /// Column `fingers`.
    pub fingers: String,
    /// Column `dof_names`.
    pub dof_names: String,
    /// Column `torque_limit_min`.
    pub torque_limit_min: f64,
    /// Column `torque_limit_max`.
    pub torque_limit_max: f64,
    /// Column `created_at`.
    pub created_at: String,
}

/// The columns of `skills` the in-memory indexes are loaded from.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct IndexedSkillRow {
    /// Column `id`.
    pub id: i64,
    /// Column `feature`.
    pub feature: Vec<u8>,
    /// Column `object_shape`.
    pub object_shape: String,
    /// Column `grasp_type`.
    pub grasp_type: String,
    /// Column `object_name`.
    pub object_name: Option<String>,
    /// Column `approach`.
    pub approach: Option<Vec<u8>>,
}

/// A stored skill as reprocessing compares it with a new one: its id and the columns a
/// skill is identified by. Equality compares every column, the id included.
#[derive(Debug, Clone, PartialEq, sqlx::FromRow)]
pub struct StoredSkillRow {
    /// Column `id`.
    pub id: i64,
    /// Column `object_shape`.
    pub object_shape: String,
    /// Column `object_name`.
    pub object_name: Option<String>,
    /// Column `object_mass`.
    pub object_mass: f64,
    /// Column `mu`.
    pub mu: f64,
    /// Column `contact_count`.
    pub contact_count: i64,
    /// Column `contact_model`.
    pub contact_model: String,
    /// Column `grasp_type`.
    pub grasp_type: String,
    /// Column `quality`.
    pub quality: f64,
    /// Column `volume`.
    pub volume: f64,
    /// Column `duration_s`.
    pub duration_s: f64,
    /// Column `start_ns`.
    pub start_ns: i64,
    /// Column `end_ns`.
    pub end_ns: i64,
    /// Column `phase_durations`.
    pub phase_durations: String,
    /// Column `feature`.
    pub feature: Vec<u8>,
    /// Column `params`.
    pub params: String,
}

/// A content-addressed blob a row names.
#[derive(Debug, Clone, PartialEq, Eq, sqlx::FromRow)]
pub struct BlobRow {
    /// Hex SHA-256 of the bytes.
    pub sha256: String,
    /// Path relative to the data directory.
    pub rel: String,
}

/// A session stale for reprocessing: its id, version and number of skills.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct StaleSessionRow {
    /// Column `id`.
    pub id: i64,
    /// Column `segmentation_version`.
    pub segmentation_version: i64,
    /// Its skills.
    pub skill_count: i64,
}

/// A row of `jobs`.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct JobRow {
    /// Column `id`.
    pub id: i64,
    /// Column `kind`.
    pub kind: String,
    /// Column `request`.
    pub request: String,
    /// Column `state`.
    pub state: String,
    /// Column `cancel_requested`.
    pub cancel_requested: bool,
    /// Column `attempts`.
    pub attempts: i64,
    /// Column `worker`.
    pub worker: Option<String>,
    /// Column `session_id`.
    pub session_id: Option<i64>,
    /// Column `session_created`.
    pub session_created: Option<bool>,
    /// Column `replay_id`.
    pub replay_id: Option<i64>,
    /// Column `error_status`.
    pub error_status: Option<i64>,
    /// Column `error_detail`.
    pub error_detail: Option<String>,
    /// Column `created_at`.
    pub created_at: String,
    /// Column `started_at`.
    pub started_at: Option<String>,
    /// Column `finished_at`.
    pub finished_at: Option<String>,
}
