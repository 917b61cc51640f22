//! The PostgreSQL queries of the ICMS store (services' `PgCatalog` runs them), each one of
//! sqlx's compile-time-checked macros, checked against the schema `migrations/postgres` makes,
//! and the plain [`rows`] both store backends read.
//!
//! A crate of its own because sqlx's macros describe every query of a crate against one data
//! base while they are prepared: services' SQLite queries against a fresh SQLite file, these
//! against a live PostgreSQL. The build script keeps the workspace's `DATABASE_URL` (SQLite's)
//! away from them: they build from `store-postgres/.sqlx`, or live against
//! `ICMS_POSTGRES_DATABASE_URL` when it is set (`scripts/sqlx-prepare` regenerates the data
//! that way). The one query built at run time, the skill filter, and the multi-row inserts are
//! services' (`store::postgres`), from typed parts with every value bound.

pub mod jobs;
pub mod rows;

use sqlx::migrate::Migrator;
use sqlx::{PgConnection, PgExecutor};

use rows::{
    BlobRow, HandRow, HandSummaryRow, IndexedSkillRow, ReplayRow, SessionRow, SkillRow,
    StaleSessionRow, StoredSkillRow,
};

/// The PostgreSQL schema's migrations, `migrations/postgres` (the same versions as SQLite's
/// `migrations/`, one for one).
pub static MIGRATOR: Migrator = sqlx::migrate!("../migrations/postgres");

/// The channel every change to `skills` is notified on (migrations/postgres/0006_skill_notify.sql:
/// a trigger sends `{"schema": …, "op": "INSERT" | "UPDATE" | "DELETE" | "TRUNCATE", "ids":
/// […]}` at the commit of each statement that changes skills, at most 300 ids a message).
pub const SKILLS_CHANNEL: &str = "icms_skills";

/// A query's result.
pub type Result<T> = std::result::Result<T, sqlx::Error>;

// ---- sessions ----

/// The id of the session of these bytes.
pub async fn session_id_of<'e>(e: impl PgExecutor<'e>, sha256: &str) -> Result<Option<i64>> {
    sqlx::query_scalar!("SELECT id FROM sessions WHERE sha256 = $1", sha256)
        .fetch_optional(e)
        .await
}

/// The ids of a session's skills and the skills they were matched to, by ascending id.
pub async fn session_skill_ids<'e>(
    e: impl PgExecutor<'e>,
    session_id: i64,
) -> Result<Vec<(i64, Option<i64>)>> {
    Ok(sqlx::query!(
        "SELECT id, matched_skill_id FROM skills WHERE session_id = $1 ORDER BY id",
        session_id
    )
    .fetch_all(e)
    .await?
    .into_iter()
    .map(|r| (r.id, r.matched_skill_id))
    .collect())
}

/// The columns of a new session row.
#[derive(Debug, Clone, Copy)]
pub struct NewSessionRow<'a> {
    /// Hex SHA-256 of the bytes.
    pub sha256: &'a str,
    /// Size of the blob, bytes.
    pub size_bytes: i64,
    /// Path of the blob relative to the data directory.
    pub blob_path: &'a str,
    /// The scenario's name, if any.
    pub scenario: Option<&'a str>,
    /// The hand's name.
    pub hand: &'a str,
    /// The object shape's name.
    pub object_shape: &'a str,
    /// The session's length, ns.
    pub duration_ns: i64,
    /// The metadata as JSON.
    pub meta: &'a str,
    /// Version of the segmentation that made its skills.
    pub segmentation_version: i64,
}

/// Inserts a session row; its id, or `None` when a session of these bytes exists.
pub async fn insert_session(conn: &mut PgConnection, s: NewSessionRow<'_>) -> Result<Option<i64>> {
    sqlx::query_scalar!(
        r#"INSERT INTO sessions (sha256, size_bytes, blob_path, scenario, hand, object_shape,
               duration_ns, meta, segmentation_version)
           VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)
           ON CONFLICT (sha256) DO NOTHING RETURNING id AS "id!""#,
        s.sha256,
        s.size_bytes,
        s.blob_path,
        s.scenario,
        s.hand,
        s.object_shape,
        s.duration_ns,
        s.meta,
        s.segmentation_version,
    )
    .fetch_optional(conn)
    .await
}

/// One session with its skill ids.
pub async fn session<'e>(e: impl PgExecutor<'e>, id: i64) -> Result<Option<SessionRow>> {
    sqlx::query_as!(
        SessionRow,
        r#"SELECT id, sha256, size_bytes, blob_path, meta, segmentation_version, created_at,
               COALESCE((SELECT json_agg(id ORDER BY id) FROM skills
                   WHERE session_id = s.id), '[]')::text AS "skill_ids!",
               COALESCE((SELECT json_agg(matched_skill_id ORDER BY id) FROM skills
                   WHERE session_id = s.id), '[]')::text AS "matched_skill_ids!"
           FROM sessions s WHERE id = $1"#,
        id
    )
    .fetch_optional(e)
    .await
}

/// The filters of a session listing.
#[derive(Debug, Clone, Copy)]
pub struct SessionListing<'a> {
    /// Only this scenario's.
    pub scenario: Option<&'a str>,
    /// Only this hand's.
    pub hand: Option<&'a str>,
    /// Only this object shape's.
    pub object_shape: Option<&'a str>,
    /// Rows to fetch at most.
    pub fetch: i64,
}

/// Sessions with an id below `before`, newest first.
pub async fn sessions_before<'e>(
    e: impl PgExecutor<'e>,
    before: i64,
    f: SessionListing<'_>,
) -> Result<Vec<SessionRow>> {
    sqlx::query_as!(
        SessionRow,
        r#"SELECT id, sha256, size_bytes, blob_path, meta, segmentation_version, created_at,
               COALESCE((SELECT json_agg(id ORDER BY id) FROM skills
                   WHERE session_id = s.id), '[]')::text AS "skill_ids!",
               COALESCE((SELECT json_agg(matched_skill_id ORDER BY id) FROM skills
                   WHERE session_id = s.id), '[]')::text AS "matched_skill_ids!"
           FROM sessions s
           WHERE id < $1 AND ($2::text IS NULL OR scenario = $2)
               AND ($3::text IS NULL OR hand = $3) AND ($4::text IS NULL OR object_shape = $4)
           ORDER BY id DESC LIMIT $5"#,
        before,
        f.scenario,
        f.hand,
        f.object_shape,
        f.fetch,
    )
    .fetch_all(e)
    .await
}

/// Sessions with an id above `after`, oldest first.
pub async fn sessions_after<'e>(
    e: impl PgExecutor<'e>,
    after: i64,
    f: SessionListing<'_>,
) -> Result<Vec<SessionRow>> {
    sqlx::query_as!(
        SessionRow,
        r#"SELECT id, sha256, size_bytes, blob_path, meta, segmentation_version, created_at,
               COALESCE((SELECT json_agg(id ORDER BY id) FROM skills
                   WHERE session_id = s.id), '[]')::text AS "skill_ids!",
               COALESCE((SELECT json_agg(matched_skill_id ORDER BY id) FROM skills
                   WHERE session_id = s.id), '[]')::text AS "matched_skill_ids!"
           FROM sessions s
           WHERE id > $1 AND ($2::text IS NULL OR scenario = $2)
               AND ($3::text IS NULL OR hand = $3) AND ($4::text IS NULL OR object_shape = $4)
           ORDER BY id LIMIT $5"#,
        after,
        f.scenario,
        f.hand,
        f.object_shape,
        f.fetch,
    )
    .fetch_all(e)
    .await
}

/// The blob of session `id`.
pub async fn session_blob<'e>(e: impl PgExecutor<'e>, id: i64) -> Result<Option<BlobRow>> {
    sqlx::query_as!(
        BlobRow,
        "SELECT sha256, blob_path AS rel FROM sessions WHERE id = $1",
        id
    )
    .fetch_optional(e)
    .await
}

/// Deletes the replays of a session's skills; their blobs.
pub async fn delete_session_replays(conn: &mut PgConnection, id: i64) -> Result<Vec<BlobRow>> {
    sqlx::query_as!(
        BlobRow,
        r#"DELETE FROM replays WHERE skill_id IN (SELECT id FROM skills WHERE session_id = $1)
           RETURNING sha256 AS "sha256!", blob_path AS "rel!""#,
        id
    )
    .fetch_all(conn)
    .await
}

/// Deletes a session's skills (their phase rows cascade); their ids.
pub async fn delete_session_skills(conn: &mut PgConnection, id: i64) -> Result<Vec<i64>> {
    sqlx::query_scalar!(
        r#"DELETE FROM skills WHERE session_id = $1 RETURNING id AS "id!""#,
        id
    )
    .fetch_all(conn)
    .await
}

/// Deletes a session row; its blob.
pub async fn delete_session_row(conn: &mut PgConnection, id: i64) -> Result<Option<BlobRow>> {
    sqlx::query_as!(
        BlobRow,
        r#"DELETE FROM sessions WHERE id = $1 RETURNING sha256 AS "sha256!", blob_path AS "rel!""#,
        id
    )
    .fetch_optional(conn)
    .await
}

/// Every blob path a session or a replay names.
pub async fn referenced_blob_paths<'e>(e: impl PgExecutor<'e>) -> Result<Vec<String>> {
    sqlx::query_scalar!(
        r#"SELECT blob_path AS "blob_path!" FROM sessions UNION SELECT blob_path FROM replays"#
    )
    .fetch_all(e)
    .await
}

/// Whether a session or a replay names the blob of these bytes.
pub async fn blob_is_referenced<'e>(e: impl PgExecutor<'e>, sha256: &str) -> Result<bool> {
    sqlx::query_scalar!(
        r#"SELECT EXISTS (SELECT 1 FROM sessions WHERE sha256 = $1)
               OR EXISTS (SELECT 1 FROM replays WHERE sha256 = $1) AS "found!""#,
        sha256
    )
    .fetch_one(e)
    .await
}

// ---- skills ----

/// One skill.
pub async fn skill<'e>(e: impl PgExecutor<'e>, id: i64) -> Result<Option<SkillRow>> {
    sqlx::query_as!(
        SkillRow,
        r#"SELECT id, session_id, object_shape, object_name, object_mass, mu, contact_count,
               contact_model, grasp_type, quality, volume, duration_s, start_ns, end_ns,
               phase_durations, feature, params, approach, matched_skill_id, created_at,
               (SELECT segmentation_version FROM sessions WHERE sessions.id = skills.session_id)
                   AS "segmentation_version!"
           FROM skills WHERE id = $1"#,
        id
    )
    .fetch_optional(e)
    .await
}

/// The skills of `ids` (in any order; missing ids left out).
pub async fn skills_by_id<'e>(e: impl PgExecutor<'e>, ids: &[i64]) -> Result<Vec<SkillRow>> {
    sqlx::query_as!(
        SkillRow,
        r#"SELECT id, session_id, object_shape, object_name, object_mass, mu, contact_count,
               contact_model, grasp_type, quality, volume, duration_s, start_ns, end_ns,
               phase_durations, feature, params, approach, matched_skill_id, created_at,
               (SELECT segmentation_version FROM sessions WHERE sessions.id = skills.session_id)
                   AS "segmentation_version!"
           FROM skills WHERE id = ANY($1)"#,
        ids
    )
    .fetch_all(e)
    .await
}

/// Every skill as the in-memory indexes need it.
pub async fn indexed_skills<'e>(e: impl PgExecutor<'e>) -> Result<Vec<IndexedSkillRow>> {
    sqlx::query_as!(
        IndexedSkillRow,
        "SELECT id, feature, object_shape, grasp_type, object_name, approach FROM skills"
    )
    .fetch_all(e)
    .await
}

/// The skills of `ids` as the in-memory indexes need them (missing ids left out): what a
/// server loads of the skills another server stored or changed.
pub async fn indexed_skills_by_id<'e>(
    e: impl PgExecutor<'e>,
    ids: &[i64],
) -> Result<Vec<IndexedSkillRow>> {
    sqlx::query_as!(
        IndexedSkillRow,
        "SELECT id, feature, object_shape, grasp_type, object_name, approach FROM skills
         WHERE id = ANY($1)",
        ids
    )
    .fetch_all(e)
    .await
}

/// The schema of the `skills` table the connection's search path finds: the one the change
/// notifications of migrations/postgres/0006_skill_notify.sql name.
pub async fn skills_schema<'e>(e: impl PgExecutor<'e>) -> Result<String> {
    sqlx::query_scalar!(
        r#"SELECT n.nspname::text AS "schema!" FROM pg_class c
           JOIN pg_namespace n ON n.oid = c.relnamespace
           WHERE c.oid = 'skills'::regclass"#
    )
    .fetch_one(e)
    .await
}

/// Deletes the replays of one skill; their blobs.
pub async fn delete_skill_replays(conn: &mut PgConnection, id: i64) -> Result<Vec<BlobRow>> {
    sqlx::query_as!(
        BlobRow,
        r#"DELETE FROM replays WHERE skill_id = $1
           RETURNING sha256 AS "sha256!", blob_path AS "rel!""#,
        id
    )
    .fetch_all(conn)
    .await
}

/// Deletes one skill row (its phase rows cascade); rows deleted.
pub async fn delete_skill(conn: &mut PgConnection, id: i64) -> Result<u64> {
    Ok(sqlx::query!("DELETE FROM skills WHERE id = $1", id)
        .execute(conn)
        .await?
        .rows_affected())
}

// ---- hands and replays ----

/// The columns of a new hand row.
#[derive(Debug, Clone, Copy)]
pub struct NewHandRow<'a> {
    /// The hand's name.
    pub name: &'a str,
    /// The hand spec as JSON.
    pub spec: &'a str,
    /// The URDF text.
    pub urdf: &'a str,
    /// Independent joints.
    pub dof: i64,
    /// Fingertip names as JSON.
    pub fingers: &'a str,
    /// DOF names as JSON.
    pub dof_names: &'a str,
    /// Lowest torque limit.
    pub torque_limit_min: f64,
    /// Highest torque limit.
    pub torque_limit_max: f64,
}

/// Stores an uploaded hand; its creation time, or `None` when the name is taken.
pub async fn insert_hand<'e>(e: impl PgExecutor<'e>, h: NewHandRow<'_>) -> Result<Option<String>> {
    sqlx::query_scalar!(
        r#"INSERT INTO hands (name, spec, urdf, dof, fingers, dof_names, torque_limit_min,
               torque_limit_max) VALUES ($1, $2, $3, $4, $5, $6, $7, $8)
           ON CONFLICT (name) DO NOTHING RETURNING created_at AS "created_at!""#,
        h.name,
        h.spec,
        h.urdf,
        h.dof,
        h.fingers,
        h.dof_names,
        h.torque_limit_min,
        h.torque_limit_max,
    )
    .fetch_optional(e)
    .await
}

/// The uploaded hands, by upload.
pub async fn hands<'e>(e: impl PgExecutor<'e>) -> Result<Vec<HandSummaryRow>> {
    sqlx::query_as!(
        HandSummaryRow,
        "SELECT name, dof, fingers, dof_names, torque_limit_min, torque_limit_max, created_at
         FROM hands ORDER BY id"
    )
    .fetch_all(e)
    .await
}

/// One uploaded hand.
pub async fn hand<'e>(e: impl PgExecutor<'e>, name: &str) -> Result<Option<HandRow>> {
    sqlx::query_as!(
        HandRow,
        "SELECT name, spec, urdf, dof, fingers, dof_names, torque_limit_min, torque_limit_max,
             created_at
         FROM hands WHERE name = $1",
        name
    )
    .fetch_optional(e)
    .await
}

/// The columns of a new replay row: what both backends insert (services' catalog takes it
/// as it is).
#[derive(Debug, Clone, Copy)]
pub struct NewReplayRow<'a> {
    /// The replayed skill.
    pub skill_id: i64,
    /// The hand's name.
    pub hand: &'a str,
    /// Whether the object was held.
    pub success: bool,
    /// Why not.
    pub failure_reason: Option<&'a str>,
    /// The report as JSON.
    pub report: &'a str,
    /// Hex SHA-256 of the blob.
    pub sha256: &'a str,
    /// Size of the blob, bytes.
    pub size_bytes: i64,
    /// Path of the blob relative to the data directory.
    pub blob_path: &'a str,
}

/// Stores a replay if its skill exists.
pub async fn insert_replay<'e>(
    e: impl PgExecutor<'e>,
    r: NewReplayRow<'_>,
) -> Result<Option<ReplayRow>> {
    sqlx::query_as!(
        ReplayRow,
        r#"INSERT INTO replays (skill_id, hand, success, failure_reason, report, sha256,
               size_bytes, blob_path)
           SELECT $1, $2, $3, $4, $5, $6, $7, $8 WHERE EXISTS (SELECT 1 FROM skills WHERE id = $1)
           RETURNING id AS "id!", skill_id AS "skill_id!", hand AS "hand!",
               success AS "success!", failure_reason, report AS "report!",
               sha256 AS "sha256!", size_bytes AS "size_bytes!", blob_path AS "blob_path!",
               created_at AS "created_at!""#,
        r.skill_id,
        r.hand,
        r.success,
        r.failure_reason,
        r.report,
        r.sha256,
        r.size_bytes,
        r.blob_path,
    )
    .fetch_optional(e)
    .await
}

/// One replay.
pub async fn replay<'e>(e: impl PgExecutor<'e>, id: i64) -> Result<Option<ReplayRow>> {
    sqlx::query_as!(
        ReplayRow,
        "SELECT id, skill_id, hand, success, failure_reason, report, sha256, size_bytes,
             blob_path, created_at
         FROM replays WHERE id = $1",
        id
    )
    .fetch_optional(e)
    .await
}

/// Makes the transaction just begun on `conn` read one snapshot (`REPEATABLE READ`).
pub async fn repeatable_read(conn: &mut PgConnection) -> Result<()> {
    sqlx::query!("SET TRANSACTION ISOLATION LEVEL REPEATABLE READ")
        .execute(conn)
        .await?;
    Ok(())
}

/// Whether skill `id` exists.
pub async fn skill_exists<'e>(e: impl PgExecutor<'e>, id: i64) -> Result<bool> {
    sqlx::query_scalar!(
        r#"SELECT EXISTS (SELECT 1 FROM skills WHERE id = $1) AS "found!""#,
        id
    )
    .fetch_one(e)
    .await
}

/// The replays of one skill by ascending id.
pub async fn replays_of<'e>(e: impl PgExecutor<'e>, skill_id: i64) -> Result<Vec<ReplayRow>> {
    sqlx::query_as!(
        ReplayRow,
        "SELECT id, skill_id, hand, success, failure_reason, report, sha256, size_bytes,
             blob_path, created_at
         FROM replays WHERE skill_id = $1 ORDER BY id",
        skill_id
    )
    .fetch_all(e)
    .await
}

/// The blob path of replay `id`.
pub async fn replay_blob_path<'e>(e: impl PgExecutor<'e>, id: i64) -> Result<Option<String>> {
    sqlx::query_scalar!("SELECT blob_path FROM replays WHERE id = $1", id)
        .fetch_optional(e)
        .await
}

// ---- reprocessing ----

/// The sessions segmented by a version below `version`, by ascending id.
pub async fn sessions_segmented_before<'e>(
    e: impl PgExecutor<'e>,
    version: i64,
) -> Result<Vec<StaleSessionRow>> {
    sqlx::query_as!(
        StaleSessionRow,
        r#"SELECT id, segmentation_version,
               (SELECT count(*) FROM skills WHERE session_id = s.id) AS "skill_count!"
           FROM sessions s WHERE segmentation_version < $1 ORDER BY id"#,
        version
    )
    .fetch_all(e)
    .await
}

/// Number of sessions segmented by a version above `version`.
pub async fn sessions_segmented_after<'e>(e: impl PgExecutor<'e>, version: i64) -> Result<i64> {
    sqlx::query_scalar!(
        r#"SELECT count(*) AS "n!" FROM sessions WHERE segmentation_version > $1"#,
        version
    )
    .fetch_one(e)
    .await
}

/// The segmentation version of a session, its row locked until the transaction ends.
pub async fn session_version_for_update(
    conn: &mut PgConnection,
    session_id: i64,
) -> Result<Option<i64>> {
    sqlx::query_scalar!(
        "SELECT segmentation_version FROM sessions WHERE id = $1 FOR UPDATE",
        session_id
    )
    .fetch_optional(conn)
    .await
}

/// A session's skills as reprocessing compares them, by ascending id.
pub async fn stored_skills_of(
    conn: &mut PgConnection,
    session_id: i64,
) -> Result<Vec<StoredSkillRow>> {
    sqlx::query_as!(
        StoredSkillRow,
        "SELECT id, object_shape, object_name, object_mass, mu, contact_count, contact_model,
             grasp_type, quality, volume, duration_s, start_ns, end_ns, phase_durations,
             feature, params
         FROM skills WHERE session_id = $1 ORDER BY id",
        session_id
    )
    .fetch_all(conn)
    .await
}

/// Sets a skill's approach template.
pub async fn set_approach(conn: &mut PgConnection, id: i64, approach: Option<&[u8]>) -> Result<()> {
    sqlx::query!(
        "UPDATE skills SET approach = $1 WHERE id = $2",
        approach,
        id
    )
    .execute(conn)
    .await?;
    Ok(())
}

/// Deletes the replays of the skills `ids`; their blobs.
pub async fn delete_replays_of_skills(
    conn: &mut PgConnection,
    ids: &[i64],
) -> Result<Vec<BlobRow>> {
    sqlx::query_as!(
        BlobRow,
        r#"DELETE FROM replays WHERE skill_id = ANY($1)
           RETURNING sha256 AS "sha256!", blob_path AS "rel!""#,
        ids
    )
    .fetch_all(conn)
    .await
}

/// Deletes the skills `ids`; rows deleted.
pub async fn delete_skills(conn: &mut PgConnection, ids: &[i64]) -> Result<u64> {
    Ok(sqlx::query!("DELETE FROM skills WHERE id = ANY($1)", ids)
        .execute(conn)
        .await?
        .rows_affected())
}

/// Sets a session's segmentation version.
pub async fn set_segmentation_version(
    conn: &mut PgConnection,
    session_id: i64,
    version: i64,
) -> Result<()> {
    sqlx::query!(
        "UPDATE sessions SET segmentation_version = $1 WHERE id = $2",
        version,
        session_id
    )
    .execute(conn)
    .await?;
    Ok(())
}

// ---- the data base ----

/// `synchronous_commit`, the setting that says when a commit counts as done.
pub async fn synchronous_commit<'e>(e: impl PgExecutor<'e>) -> Result<String> {
    sqlx::query_scalar!(r#"SELECT current_setting('synchronous_commit') AS "s!""#)
        .fetch_one(e)
        .await
}

/// Rows of `skills` whose session is missing, or phase rows whose skill is (none while the
/// foreign keys hold).
pub async fn dangling_rows<'e>(e: impl PgExecutor<'e>) -> Result<i64> {
    sqlx::query_scalar!(
        r#"SELECT (SELECT count(*) FROM skills k
                   WHERE NOT EXISTS (SELECT 1 FROM sessions s WHERE s.id = k.session_id))
             + (SELECT count(*) FROM skill_phases p
                   WHERE NOT EXISTS (SELECT 1 FROM skills k WHERE k.id = p.skill_id))
             + (SELECT count(*) FROM replays r
                   WHERE NOT EXISTS (SELECT 1 FROM skills k WHERE k.id = r.skill_id))
             AS "n!""#
    )
    .fetch_one(e)
    .await
}

/// Refreshes the planner's statistics.
pub async fn analyze<'e>(e: impl PgExecutor<'e>) -> Result<()> {
    sqlx::query!("ANALYZE").execute(e).await?;
    Ok(())
}
