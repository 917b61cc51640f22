//! The skill filter query, the one query the store builds at run time for reading: its filters
//! and sort come in any combination, and the plan that stays fast for each shows in its text.
//! It is built once for every backend, here, from the typed parts of a validated
//! [`SkillFilter`]: every piece of SQL text below is a literal chosen by a `match` or an `if`,
//! every value is bound (the placeholders are the backend's own, which [`QueryBuilder`]
//! writes), and the rows come back through [`super::rows::SkillRow`]'s `FromRow`.
//!
//! Where the dialects differ, a backend says how through [`FilterDialect`]: SQLite's planner
//! is steered by unary `+` on the columns whose index must not drive the scan, PostgreSQL's
//! chooses by cost; and the keyset cursor of a sort by a value is written the way each
//! backend's index range-scans it.

use dfs_core::names::Named;
use sqlx::{Database, Encode, QueryBuilder, Type};

use super::query::{After, GraspFilter, SkillFilter, SortField, SortOrder};

/// The comparisons of a sort direction: what comes after a cursor, and how `ORDER BY` says it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Direction {
    /// Strictly after: ` > ` ascending, ` < ` descending.
    pub after: &'static str,
    /// After or level with: ` >= ` ascending, ` <= ` descending.
    pub after_or_level: &'static str,
    /// ` ASC` or ` DESC`.
    pub order_by: &'static str,
}

impl Direction {
    /// The comparisons of `order`.
    fn of(order: SortOrder) -> Direction {
        match order {
            SortOrder::Asc => Direction {
                after: " > ",
                after_or_level: " >= ",
                order_by: " ASC",
            },
            SortOrder::Desc => Direction {
                after: " < ",
                after_or_level: " <= ",
                order_by: " DESC",
            },
        }
    }
}

/// What a backend writes its own way in the skill filter query.
pub(crate) trait FilterDialect: Database {
    /// The condition after `WHERE` that every row meets, which the filters follow with
    /// ` AND …`.
    const EVERY_ROW: &'static str;

    /// Whether a column whose index must not drive the scan is written `+col`, which keeps
    /// SQLite from choosing that index.
    const UNARY_PLUS_HINTS: bool;

    /// Pushes ` AND …`: the rows after the cursor `(value, id)` of a sort by `column` in
    /// direction `dir` (ties broken by id the same way).
    fn push_after_value(
        b: &mut QueryBuilder<'_, Self>,
        column: &'static str,
        dir: Direction,
        value: f64,
        id: i64,
    );
}

/// The column a sort field sorts by.
fn sort_column(field: SortField) -> &'static str {
    match field {
        SortField::Id => "id",
        SortField::Quality => "quality",
        SortField::Mass => "object_mass",
        SortField::Duration => "duration_s",
    }
}

/// `" AND col"`, in SQLite with a unary `+` unless the column drives the scan.
fn and_column<DB: FilterDialect>(b: &mut QueryBuilder<'_, DB>, driving: bool, column: &str) {
    b.push(if DB::UNARY_PLUS_HINTS && !driving {
        " AND +"
    } else {
        " AND "
    })
    .push(column);
}

/// The query of `f` in backend `DB`.
///
/// Plan (SQLite's hints; PostgreSQL's planner comes to the same by cost): walk the index that
/// yields the sort order (with an equality prefix where a composite index has one) and test
/// the other filters row by row, so that a page costs about `fetch / selectivity` index steps
/// whatever the table size, instead of sorting every match of a range filter.
pub(crate) fn build<'a, DB>(f: &'a SkillFilter<'_>) -> QueryBuilder<'a, DB>
where
    DB: FilterDialect,
    for<'q> i64: Encode<'q, DB> + Type<DB>,
    for<'q> f64: Encode<'q, DB> + Type<DB>,
    for<'q> &'q str: Encode<'q, DB> + Type<DB>,
    for<'q> String: Encode<'q, DB> + Type<DB>,
{
    let sort = f.sort;
    let shape_leads =
        f.object_shape.is_some() && matches!(sort.field, SortField::Quality | SortField::Mass);
    let grasp_leads = !shape_leads
        && matches!(f.grasp, Some(GraspFilter::Label(_)))
        && sort.field == SortField::Quality;
    let by_mass = sort.field == SortField::Mass;
    let by_quality = sort.field == SortField::Quality;

    let mut b = QueryBuilder::new(
        "SELECT id, session_id, object_shape, object_name, object_mass, mu, contact_count, \
         contact_model, grasp_type, quality, volume, duration_s, start_ns, end_ns, \
         phase_durations, feature, params, approach, matched_skill_id, created_at, \
         (SELECT segmentation_version FROM sessions WHERE sessions.id = skills.session_id) \
         AS segmentation_version \
         FROM skills WHERE ",
    );
    b.push(DB::EVERY_ROW);
    if let Some(v) = f.object_shape {
        and_column(&mut b, shape_leads, "object_shape");
        b.push(" = ").push_bind(v.name());
    }
    if let Some(v) = f.mass_min {
        and_column(&mut b, by_mass, "object_mass");
        b.push(" >= ").push_bind(v);
    }
    if let Some(v) = f.mass_max {
        and_column(&mut b, by_mass, "object_mass");
        b.push(" <= ").push_bind(v);
    }
    if let Some(v) = f.mu_min {
        and_column(&mut b, false, "mu");
        b.push(" >= ").push_bind(v);
    }
    if let Some(v) = f.mu_max {
        and_column(&mut b, false, "mu");
        b.push(" <= ").push_bind(v);
    }
    if let Some(v) = f.contact_count {
        and_column(&mut b, false, "contact_count");
        b.push(" = ").push_bind(v);
    }
    if let Some(v) = f.contact_model {
        and_column(&mut b, false, "contact_model");
        b.push(" = ").push_bind(v.name());
    }
    match f.grasp {
        Some(GraspFilter::Label(v)) => {
            and_column(&mut b, grasp_leads, "grasp_type");
            b.push(" = ").push_bind(v);
        }
        // The family's bare label and every `<family>-<n>vf` label: `precision` ≤ label <
        // `precision.` ('.' follows '-'; PostgreSQL's column compares bytes, COLLATE "C").
        Some(GraspFilter::Family(family)) => {
            and_column(&mut b, false, "grasp_type");
            b.push(" >= ").push_bind(family);
            and_column(&mut b, false, "grasp_type");
            b.push(" < ").push_bind(format!("{family}."));
        }
        None => {}
    }
    if let Some(v) = f.min_quality {
        and_column(&mut b, by_quality, "quality");
        b.push(" >= ").push_bind(v);
    }
    if let Some(p) = f.phase {
        b.push(
            " AND EXISTS (SELECT 1 FROM skill_phases p WHERE p.skill_id = skills.id AND p.name = ",
        )
        .push_bind(p.phase.name());
        if let Some(v) = p.min_s {
            b.push(" AND p.duration_s >= ").push_bind(v);
        }
        if let Some(v) = p.max_s {
            b.push(" AND p.duration_s <= ").push_bind(v);
        }
        b.push(")");
    }
    let col = sort_column(sort.field);
    let dir = Direction::of(sort.order);
    match f.after {
        Some(After::Int(id)) => {
            b.push(" AND id").push(dir.after).push_bind(id);
        }
        Some(After::Real(v, id)) => DB::push_after_value(&mut b, col, dir, v, id),
        None => {}
    }
    b.push(" ORDER BY ");
    if sort.field != SortField::Id {
        b.push(col).push(dir.order_by).push(", ");
    }
    b.push("id").push(dir.order_by);
    b.push(" LIMIT ").push_bind(f.fetch);
    b
}
