//! The multi-row skill insert, the same in every backend: a session's skills and their phase
//! rows, built at run time from typed parts (`push_values` binding every value) for any
//! [`sqlx::Database`] whose connections take the columns' Rust types. The placeholders are
//! the backend's own (`?` in SQLite, `$n` in PostgreSQL): [`QueryBuilder`] writes them.
//!
//! Built at run time, not one checked statement per row, because a statement inserts many
//! rows: one checked statement per row, tried in SQLite, made `icms bench store`'s generation
//! of 100 000 skills 3.4 times slower (29 s → 100 s, six statements per skill, each a round
//! trip to the connection's thread), and a session's ingest slower with it. The columns are
//! the ones every backend's checked queries read back, so a renamed column fails every store
//! test at once.

use dfs_core::names::Named;
use sqlx::{Database, Encode, Postgres, QueryBuilder, Sqlite, Type};

use super::catalog::CheckedSkill;
use super::rows::{approach_to_blob, feature_to_blob};
use super::StoreError;

/// A backend that runs the statements built here.
///
/// Running a [`QueryBuilder`] is written per backend: sqlx ties a built query's borrow of its
/// builder to the lifetime of the bound arguments where the backend's argument type has one
/// (SQLite's), and code generic over the backend cannot see that the builder may still be
/// dropped once that borrow ends. [`run_built`] writes the same two functions for each.
pub(crate) trait RunBuilt: Database {
    /// Runs `b`, a statement ending in `RETURNING id`, on `conn`: the ids, in the order the
    /// data base gives them.
    async fn fetch_ids(
        conn: &mut Self::Connection,
        b: QueryBuilder<'_, Self>,
    ) -> Result<Vec<i64>, sqlx::Error>;

    /// Runs `b` on `conn`.
    async fn execute(
        conn: &mut Self::Connection,
        b: QueryBuilder<'_, Self>,
    ) -> Result<(), sqlx::Error>;
}

/// Implements [`RunBuilt`] for a backend.
macro_rules! run_built {
    ($db:ty) => {
        impl RunBuilt for $db {
            async fn fetch_ids(
                conn: &mut Self::Connection,
                mut b: QueryBuilder<'_, Self>,
            ) -> Result<Vec<i64>, sqlx::Error> {
                b.build_query_scalar().fetch_all(conn).await
            }

            async fn execute(
                conn: &mut Self::Connection,
                mut b: QueryBuilder<'_, Self>,
            ) -> Result<(), sqlx::Error> {
                b.build().execute(conn).await.map(drop)
            }
        }
    };
}

run_built!(Sqlite);
run_built!(Postgres);

/// Skills per statement: 18 bound values each, 9 000 in all, far below SQLite's variable
/// limit (32 766) and PostgreSQL's 65 535 parameters per statement.
const SKILLS_PER_STATEMENT: usize = 500;

/// Phase rows per statement: 4 bound values each.
const PHASES_PER_STATEMENT: usize = 2000;

/// Inserts checked skills of `session_id` and their phase rows on `tx` (a connection inside a
/// transaction); returns their ids in the order of `skills`.
pub(crate) async fn insert_skills<'a, DB>(
    tx: &mut DB::Connection,
    session_id: i64,
    skills: impl Iterator<Item = &'a CheckedSkill> + Send,
) -> Result<Vec<i64>, StoreError>
where
    DB: RunBuilt,
    for<'q> i64: Encode<'q, DB> + Type<DB>,
    for<'q> Option<i64>: Encode<'q, DB> + Type<DB>,
    for<'q> f64: Encode<'q, DB> + Type<DB>,
    for<'q> &'q str: Encode<'q, DB> + Type<DB>,
    for<'q> Option<&'q str>: Encode<'q, DB> + Type<DB>,
    for<'q> &'q [u8]: Encode<'q, DB> + Type<DB>,
    for<'q> Option<&'q [u8]>: Encode<'q, DB> + Type<DB>,
{
    let skills: Vec<&CheckedSkill> = skills.collect();
    let mut ids = Vec::with_capacity(skills.len());
    for chunk in skills.chunks(SKILLS_PER_STATEMENT) {
        let mut rows = Vec::with_capacity(chunk.len());
        for c in chunk {
            let s = &c.skill;
            rows.push((
                s,
                feature_to_blob(&c.feature),
                serde_json::to_string(&s.phase_durations)?,
                serde_json::to_string(&s.params)?,
                s.approach.as_deref().map(approach_to_blob),
            ));
        }
        let mut b: QueryBuilder<DB> = QueryBuilder::new(
            "INSERT INTO skills (session_id, object_shape, object_name, object_mass, mu, \
             contact_count, contact_model, grasp_type, quality, volume, duration_s, start_ns, \
             end_ns, phase_durations, feature, params, approach, matched_skill_id) ",
        );
        b.push_values(&rows, |mut r, (s, feature, phases, params, approach)| {
            r.push_bind(session_id)
                .push_bind(s.object_shape.name())
                .push_bind(s.object_name.as_deref())
                .push_bind(s.object_mass)
                .push_bind(s.mu)
                .push_bind(s.contact_count)
                .push_bind(s.contact_model.name())
                .push_bind(s.grasp_type.as_str())
                .push_bind(s.quality)
                .push_bind(s.volume)
                .push_bind(s.duration_s)
                .push_bind(s.start_ns)
                .push_bind(s.end_ns)
                .push_bind(phases.as_str())
                .push_bind(feature.as_slice())
                .push_bind(params.as_str())
                .push_bind(approach.as_deref())
                .push_bind(s.matched_skill_id);
        });
        b.push(" RETURNING id");
        let mut chunk_ids = DB::fetch_ids(&mut *tx, b).await?;
        // RETURNING's order is unspecified, but the ids one statement takes (SQLite's
        // AUTOINCREMENT, PostgreSQL's identity) rise in the order of its rows.
        chunk_ids.sort_unstable();
        if chunk_ids.len() != chunk.len() {
            return Err(StoreError::Corrupt(
                "skill insert returned a wrong row count".into(),
            ));
        }
        let phases: Vec<(i64, i64, &str, f64)> = chunk
            .iter()
            .zip(&chunk_ids)
            .flat_map(|(c, id)| {
                c.skill
                    .phase_durations
                    .iter()
                    .enumerate()
                    .map(move |(ord, (phase, d))| (*id, ord as i64, phase.name(), *d))
            })
            .collect();
        for pchunk in phases.chunks(PHASES_PER_STATEMENT) {
            let mut b: QueryBuilder<DB> =
                QueryBuilder::new("INSERT INTO skill_phases (skill_id, ord, name, duration_s) ");
            b.push_values(pchunk, |mut r, (id, ord, name, d)| {
                r.push_bind(*id)
                    .push_bind(*ord)
                    .push_bind(*name)
                    .push_bind(*d);
            });
            DB::execute(&mut *tx, b).await?;
        }
        ids.extend(chunk_ids);
    }
    Ok(ids)
}
