//! The skill filter query in PostgreSQL: the shared builder ([`crate::store::skill_filter`])
//! without index hints, with PostgreSQL's keyset cursor.
//!
//! PostgreSQL's planner chooses its indexes by cost, so there are no SQLite `+col` hints; the
//! cursor is a row comparison, `(col, id) > (v, id)`, which a `(col, id)` index range-scans
//! (every filter index of `migrations/postgres` ends in `id` for it).

use sqlx::{PgPool, Postgres, QueryBuilder};

use crate::store::query::SkillFilter;
use crate::store::rows::{convert, SkillRow};
use crate::store::skill_filter::{build, Direction, FilterDialect};
use crate::store::types::SkillRecord;
use crate::store::StoreError;

impl FilterDialect for Postgres {
    const EVERY_ROW: &'static str = "TRUE";
    const UNARY_PLUS_HINTS: bool = false;

    fn push_after_value(
        b: &mut QueryBuilder<'_, Postgres>,
        column: &'static str,
        dir: Direction,
        value: f64,
        id: i64,
    ) {
        b.push(" AND (")
            .push(column)
            .push(", id)")
            .push(dir.after)
            .push("(")
            .push_bind(value)
            .push(", ")
            .push_bind(id)
            .push(")");
    }
}

/// The skills `f` selects, in its order, at most `f.fetch`.
pub(super) async fn fetch(
    pool: &PgPool,
    f: &SkillFilter<'_>,
) -> Result<Vec<SkillRecord>, StoreError> {
    // Not a cached prepared statement: PostgreSQL plans an unnamed one with the values bound
    // (a custom plan), where a cached one goes over to a generic plan after five runs, which
    // cannot know how selective a mass window or a minimum quality is and (measured on
    // 100 000 skills) picks a bitmap scan and a sort: 35 ms instead of 1 ms.
    let rows: Vec<SkillRow> = build::<Postgres>(f)
        .build_query_as()
        .persistent(false)
        .fetch_all(pool)
        .await?;
    convert(rows)
}
