//! The skill filter query in SQLite: the shared builder ([`crate::store::skill_filter`]) with
//! SQLite's index hints and its keyset cursor.
//!
//! SQLite's planner takes the first usable index, so the query says which one drives the
//! scan: every other filtered column is written `+col`. The cursor of a sort by a value is
//! `col >= v AND (col > v OR id > i)` (or `<=`/`<`), which the `(col, id)` index range-scans.

use sqlx::{QueryBuilder, Sqlite, SqlitePool};

use crate::store::query::SkillFilter;
use crate::store::rows::{convert, SkillRow};
use crate::store::skill_filter::{build, Direction, FilterDialect};
use crate::store::types::SkillRecord;
use crate::store::StoreError;

impl FilterDialect for Sqlite {
    const EVERY_ROW: &'static str = "1 = 1";
    const UNARY_PLUS_HINTS: bool = true;

    fn push_after_value(
        b: &mut QueryBuilder<'_, Sqlite>,
        column: &'static str,
        dir: Direction,
        value: f64,
        id: i64,
    ) {
        // `col >= v` (or `<=`) lets SQLite range-scan the index; the OR breaks ties by id.
        b.push(" AND ")
            .push(column)
            .push(dir.after_or_level)
            .push_bind(value)
            .push(" AND (")
            .push(column)
            .push(dir.after)
            .push_bind(value)
            .push(" OR id")
            .push(dir.after)
            .push_bind(id)
            .push(")");
    }
}

/// The skills `f` selects, in its order, at most `f.fetch`.
pub(super) async fn fetch(
    pool: &SqlitePool,
    f: &SkillFilter<'_>,
) -> Result<Vec<SkillRecord>, StoreError> {
    let rows: Vec<SkillRow> = build::<Sqlite>(f).build_query_as().fetch_all(pool).await?;
    convert(rows)
}
