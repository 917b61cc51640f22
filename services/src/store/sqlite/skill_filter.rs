//! The skill filter query, the one query the SQLite backend builds at run time: its filters
//! and sort come in any combination, and the plan that stays fast for each (which index
//! drives the scan) shows in its text. It is built from the typed parts of a validated
//! [`SkillFilter`]: every piece of SQL text below is a literal chosen by a `match` or an `if`,
//! every value is bound, and the rows come back through [`SkillRow`]'s `FromRow`.

use dfs_core::names::Named;
use sqlx::{QueryBuilder, Sqlite, SqlitePool};

use crate::store::query::{After, GraspFilter, SkillFilter, SortField, SortOrder};
use crate::store::rows::{convert, SkillRow};
use crate::store::types::SkillRecord;
use crate::store::StoreError;

/// The skills `f` selects, in its order, at most `f.fetch`.
pub(super) async fn fetch(
    pool: &SqlitePool,
    f: &SkillFilter<'_>,
) -> Result<Vec<SkillRecord>, StoreError> {
    let rows: Vec<SkillRow> = build(f).build_query_as().fetch_all(pool).await?;
    convert(rows)
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

/// `" AND col"` with a unary `+` unless the column drives the scan: `+col` keeps SQLite from
/// choosing that column's index.
fn and_column(b: &mut QueryBuilder<'_, Sqlite>, driving: bool, column: &'static str) {
    b.push(if driving { " AND " } else { " AND +" })
        .push(column);
}

/// The query of `f`.
///
/// Plan: walk the index that yields the sort order (with an equality prefix where a composite
/// index has one) and test the other filters row by row, so that a page costs about
/// `fetch / selectivity` index steps whatever the table size, instead of sorting every match
/// of a range filter.
pub(super) fn build<'a>(f: &'a SkillFilter<'_>) -> QueryBuilder<'a, Sqlite> {
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
         FROM skills WHERE 1 = 1",
    );
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
        b.push(" AND +mu >= ").push_bind(v);
    }
    if let Some(v) = f.mu_max {
        b.push(" AND +mu <= ").push_bind(v);
    }
    if let Some(v) = f.contact_count {
        b.push(" AND +contact_count = ").push_bind(v);
    }
    if let Some(v) = f.contact_model {
        b.push(" AND +contact_model = ").push_bind(v.name());
    }
    match f.grasp {
        Some(GraspFilter::Label(v)) => {
            and_column(&mut b, grasp_leads, "grasp_type");
            b.push(" = ").push_bind(v);
        }
        // The family's bare label and every `<family>-<n>vf` label: `precision` ≤ label <
        // `precision.` ('.' follows '-').
        Some(GraspFilter::Family(family)) => {
            b.push(" AND +grasp_type >= ")
                .push_bind(family)
                .push(" AND +grasp_type < ")
                .push_bind(format!("{family}."));
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
    let (cmp, cmp_eq, dir) = match sort.order {
        SortOrder::Asc => (" > ", " >= ", " ASC"),
        SortOrder::Desc => (" < ", " <= ", " DESC"),
    };
    match f.after {
        Some(After::Int(id)) => {
            b.push(" AND id").push(cmp).push_bind(id);
        }
        Some(After::Real(v, id)) => {
            // `col >= v` (or `<=`) lets SQLite range-scan the index; the OR breaks ties by id.
            b.push(" AND ")
                .push(col)
                .push(cmp_eq)
                .push_bind(v)
                .push(" AND (")
                .push(col)
                .push(cmp)
                .push_bind(v)
                .push(" OR id")
                .push(cmp)
                .push_bind(id)
                .push(")");
        }
        None => {}
    }
    b.push(" ORDER BY ");
    if sort.field != SortField::Id {
        b.push(col).push(dir).push(", ");
    }
    b.push("id").push(dir);
    b.push(" LIMIT ").push_bind(f.fetch);
    b
}
