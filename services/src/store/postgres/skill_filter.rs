//! The skill filter query in PostgreSQL, built at run time like the SQLite backend's
//! (`store::sqlite::skill_filter`) from the typed parts of a validated [`SkillFilter`]: every
//! piece of SQL text below is a literal chosen by a `match` or an `if`, every value is bound,
//! and the rows come back through [`SkillRow`]'s `FromRow`.
//!
//! PostgreSQL's planner chooses its indexes by cost, so there are no SQLite `+col` hints; the
//! cursor is a row comparison, `(col, id) > (v, id)`, which a `(col, id)` index range-scans
//! (every filter index of `migrations/postgres` ends in `id` for it).

use dfs_core::names::Named;
use sqlx::{PgPool, Postgres, QueryBuilder};

use crate::store::query::{After, GraspFilter, SkillFilter, SortField, SortOrder};
use crate::store::rows::{convert, SkillRow};
use crate::store::types::SkillRecord;
use crate::store::StoreError;

/// The skills `f` selects, in its order, at most `f.fetch`.
pub(super) async fn fetch(
    pool: &PgPool,
    f: &SkillFilter<'_>,
) -> Result<Vec<SkillRecord>, StoreError> {
    // Not a cached prepared statement: PostgreSQL plans an unnamed one with the values bound
    // (a custom plan), where a cached one goes over to a generic plan after five runs, which
    // cannot know how selective a mass window or a minimum quality is and (measured on
    // 100 000 skills) picks a bitmap scan and a sort: 35 ms instead of 1 ms.
    let rows: Vec<SkillRow> = build(f)
        .build_query_as()
        .persistent(false)
        .fetch_all(pool)
        .await?;
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

/// The query of `f`.
pub(super) fn build<'a>(f: &'a SkillFilter<'_>) -> QueryBuilder<'a, Postgres> {
    let sort = f.sort;
    let mut b = QueryBuilder::new(
        "SELECT id, session_id, object_shape, object_name, object_mass, mu, contact_count, \
         contact_model, grasp_type, quality, volume, duration_s, start_ns, end_ns, \
         phase_durations, feature, params, approach, matched_skill_id, created_at, \
         (SELECT segmentation_version FROM sessions WHERE sessions.id = skills.session_id) \
         AS segmentation_version \
         FROM skills WHERE TRUE",
    );
    if let Some(v) = f.object_shape {
        b.push(" AND object_shape = ").push_bind(v.name());
    }
    if let Some(v) = f.mass_min {
        b.push(" AND object_mass >= ").push_bind(v);
    }
    if let Some(v) = f.mass_max {
        b.push(" AND object_mass <= ").push_bind(v);
    }
    if let Some(v) = f.mu_min {
        b.push(" AND mu >= ").push_bind(v);
    }
    if let Some(v) = f.mu_max {
        b.push(" AND mu <= ").push_bind(v);
    }
    if let Some(v) = f.contact_count {
        b.push(" AND contact_count = ").push_bind(v);
    }
    if let Some(v) = f.contact_model {
        b.push(" AND contact_model = ").push_bind(v.name());
    }
    match f.grasp {
        Some(GraspFilter::Label(v)) => {
            b.push(" AND grasp_type = ").push_bind(v);
        }
        // The family's bare label and every `<family>-<n>vf` label: `precision` ≤ label <
        // `precision.` ('.' follows '-'; the column compares bytes, COLLATE "C").
        Some(GraspFilter::Family(family)) => {
            b.push(" AND grasp_type >= ")
                .push_bind(family)
                .push(" AND grasp_type < ")
                .push_bind(format!("{family}."));
        }
        None => {}
    }
    if let Some(v) = f.min_quality {
        b.push(" AND quality >= ").push_bind(v);
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
    let (cmp, dir) = match sort.order {
        SortOrder::Asc => (" > ", " ASC"),
        SortOrder::Desc => (" < ", " DESC"),
    };
    match f.after {
        Some(After::Int(id)) => {
            b.push(" AND id").push(cmp).push_bind(id);
        }
        Some(After::Real(v, id)) => {
            b.push(" AND (")
                .push(col)
                .push(", id)")
                .push(cmp)
                .push("(")
                .push_bind(v)
                .push(", ")
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
