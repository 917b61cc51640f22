//! Store tests: skill filters, sorting and cursor pagination.

use crate::store_common;

use store_common::Backend;

use std::collections::HashSet;

use dfs_core::contact::ContactModel;
use dfs_core::scenario::Phase;
use services::store::bench::generate_synthetic;
use services::store::{
    ObjectShape, SkillQuery, SkillRecord, SortField, SortKey, SortOrder, Store, StoreError,
};

/// Every skill of the store, read one page at a time.
async fn walk(store: &Store, q: &SkillQuery) -> Vec<SkillRecord> {
    let mut q = q.clone();
    let mut out = Vec::new();
    loop {
        let page = store.query_skills(&q).await.unwrap();
        assert!(page.items.len() <= q.limit as usize);
        out.extend(page.items);
        match page.next_cursor {
            Some(c) => q.cursor = Some(c),
            None => return out,
        }
    }
}

fn matches(q: &SkillQuery, s: &SkillRecord) -> bool {
    let ge = |v: f64, b: Option<f64>| b.is_none_or(|b| v >= b);
    let le = |v: f64, b: Option<f64>| b.is_none_or(|b| v <= b);
    q.object_shape.as_ref().is_none_or(|x| *x == s.object_shape)
        && ge(s.object_mass, q.mass_min)
        && le(s.object_mass, q.mass_max)
        && ge(s.mu, q.mu_min)
        && le(s.mu, q.mu_max)
        && q.contact_count.is_none_or(|x| x == s.contact_count)
        && q.contact_model
            .as_ref()
            .is_none_or(|x| *x == s.contact_model)
        && q.grasp_type.as_ref().is_none_or(|x| {
            // A family (`precision`) matches its bare label and its `-<n>vf` labels.
            *x == s.grasp_type || s.grasp_type.starts_with(&format!("{x}-"))
        })
        && ge(s.quality, q.min_quality)
        && q.phase.as_ref().is_none_or(|p| {
            s.phase_durations
                .iter()
                .any(|(n, d)| n == p && ge(*d, q.phase_min_s) && le(*d, q.phase_max_s))
        })
}

fn sort_value(sort: SortKey, s: &SkillRecord) -> f64 {
    match sort.field {
        SortField::Id => s.id as f64,
        SortField::Quality => s.quality,
        SortField::Mass => s.object_mass,
        SortField::Duration => s.duration_s,
    }
}

async fn filters_sorts_and_cursors_walk_every_matching_skill_exactly_once(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    generate_synthetic(&store, 2500, 11).await.unwrap();
    let all = walk(
        &store,
        &SkillQuery {
            limit: 1000,
            ..SkillQuery::default()
        },
    )
    .await;
    assert_eq!(all.len(), 2500);

    let filters = vec![
        SkillQuery::default(),
        SkillQuery {
            object_shape: Some("box".parse().unwrap()),
            ..SkillQuery::default()
        },
        SkillQuery {
            mass_min: Some(0.5),
            mass_max: Some(1.0),
            ..SkillQuery::default()
        },
        SkillQuery {
            mu_min: Some(0.6),
            mu_max: Some(0.9),
            contact_count: Some(3),
            ..SkillQuery::default()
        },
        SkillQuery {
            contact_model: Some("soft_finger".parse().unwrap()),
            grasp_type: Some("power-3vf".into()),
            ..SkillQuery::default()
        },
        SkillQuery {
            min_quality: Some(0.4),
            object_shape: Some("sphere".parse().unwrap()),
            ..SkillQuery::default()
        },
        SkillQuery {
            phase: Some("lift".parse().unwrap()),
            phase_min_s: Some(0.5),
            phase_max_s: Some(0.7),
            ..SkillQuery::default()
        },
        SkillQuery {
            phase: Some("retreat".parse().unwrap()),
            ..SkillQuery::default()
        },
        SkillQuery {
            grasp_type: Some("precision".into()),
            mass_max: Some(0.8),
            ..SkillQuery::default()
        },
    ];
    let sorts = [
        SortKey::new(SortField::Id, SortOrder::Asc),
        SortKey::new(SortField::Id, SortOrder::Desc),
        SortKey::new(SortField::Quality, SortOrder::Desc),
        SortKey::new(SortField::Mass, SortOrder::Asc),
        SortKey::new(SortField::Duration, SortOrder::Desc),
    ];
    for f in &filters {
        let expected: HashSet<i64> = all.iter().filter(|s| matches(f, s)).map(|s| s.id).collect();
        for sort in sorts {
            let q = SkillQuery {
                sort,
                limit: 37,
                ..f.clone()
            };
            let got = walk(&store, &q).await;
            let ids: Vec<i64> = got.iter().map(|s| s.id).collect();
            let unique: HashSet<i64> = ids.iter().copied().collect();
            assert_eq!(unique.len(), ids.len(), "a row came twice for {q:?}");
            assert_eq!(unique, expected, "wrong rows for {q:?}");
            for w in got.windows(2) {
                let (a, b) = (sort_value(sort, &w[0]), sort_value(sort, &w[1]));
                let ordered = match sort.order {
                    SortOrder::Asc => a < b || (a == b && w[0].id < w[1].id),
                    SortOrder::Desc => a > b || (a == b && w[0].id > w[1].id),
                };
                assert!(
                    ordered,
                    "out of order for {sort}: {} then {}",
                    w[0].id, w[1].id
                );
            }
        }
    }
}

async fn ties_in_the_sort_value_are_paged_through_by_id(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let mut same = store_common::skills(5, 30);
    for s in &mut same {
        s.quality = 0.25;
    }
    store
        .ingest(
            &store_common::fake_mcap(5, 100),
            store_common::meta(5, 30),
            same,
        )
        .await
        .unwrap();
    let q = SkillQuery {
        sort: SortKey::new(SortField::Quality, SortOrder::Desc),
        limit: 4,
        ..SkillQuery::default()
    };
    let got: Vec<i64> = walk(&store, &q).await.iter().map(|s| s.id).collect();
    let mut expected = got.clone();
    expected.sort_unstable_by(|a, b| b.cmp(a));
    expected.dedup();
    assert_eq!(got, expected);
    assert_eq!(got.len(), 30);
}

async fn a_malformed_or_foreign_cursor_is_a_bad_cursor(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    generate_synthetic(&store, 30, 3).await.unwrap();
    for bad in [
        "",
        "zz",
        "not hex at all",
        "00ff00",
        &hex::encode("v1|id:asc|x"),
    ] {
        let q = SkillQuery {
            cursor: Some(bad.to_string()),
            ..SkillQuery::default()
        };
        assert!(
            matches!(store.query_skills(&q).await, Err(StoreError::BadCursor)),
            "{bad:?}"
        );
    }
    let first = store
        .query_skills(&SkillQuery {
            limit: 5,
            ..SkillQuery::default()
        })
        .await
        .unwrap();
    let cursor = first.next_cursor.unwrap();
    // A cursor of one sort order is refused for another.
    let q = SkillQuery {
        cursor: Some(cursor.clone()),
        sort: SortKey::new(SortField::Quality, SortOrder::Asc),
        ..SkillQuery::default()
    };
    assert!(matches!(
        store.query_skills(&q).await,
        Err(StoreError::BadCursor)
    ));
    // Session cursors and skill cursors do not mix.
    assert!(matches!(
        store.list_sessions(10, Some(&cursor)).await,
        Err(StoreError::BadCursor)
    ));
}

async fn out_of_range_queries_are_invalid(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let bad = [
        SkillQuery {
            limit: 0,
            ..SkillQuery::default()
        },
        SkillQuery {
            limit: 1001,
            ..SkillQuery::default()
        },
        SkillQuery {
            mass_min: Some(2.0),
            mass_max: Some(1.0),
            ..SkillQuery::default()
        },
        SkillQuery {
            mu_min: Some(f64::NAN),
            ..SkillQuery::default()
        },
        SkillQuery {
            phase_min_s: Some(1.0),
            ..SkillQuery::default()
        },
    ];
    for q in bad {
        assert!(
            matches!(
                store.query_skills(&q).await,
                Err(StoreError::InvalidQuery(_))
            ),
            "{q:?}"
        );
    }
    // A value no skill can have is a typo, not an empty page: the error names the filter. A
    // shape, contact model or phase is typed, so a bad one is refused where it is parsed.
    for value in ["pinch", "power-xvf"] {
        let q = SkillQuery {
            grasp_type: Some(value.to_owned()),
            ..SkillQuery::default()
        };
        match store.query_skills(&q).await {
            Err(StoreError::InvalidQuery(m)) => assert!(m.starts_with("grasp_type"), "{m}"),
            other => panic!("{q:?} gave {other:?}"),
        }
    }
    for (value, message) in [
        (
            "torus",
            "unknown shape \"torus\"; expected one of sphere, box, cylinder, unknown",
        ),
        ("Sphere", "unknown shape \"Sphere\""),
    ] {
        let e = value.parse::<ObjectShape>().unwrap_err().to_string();
        assert!(e.starts_with(message), "{e}");
    }
    let e = "magic".parse::<ContactModel>().unwrap_err().to_string();
    assert!(e.starts_with("unknown contact model \"magic\""), "{e}");
    let e = "juggle".parse::<Phase>().unwrap_err().to_string();
    assert!(e.starts_with("unknown phase \"juggle\""), "{e}");
    // As a query's JSON, too (the form `SkillQuery` is sent in).
    let e = serde_json::from_value::<SkillQuery>(serde_json::json!({"object_shape": "torus"}))
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown shape \"torus\""), "{e}");
    assert!(matches!(
        store.list_sessions(0, None).await,
        Err(StoreError::InvalidQuery(_))
    ));
    assert!("-colour".parse::<SortKey>().is_err());
}

async fn sessions_page_through_in_id_order(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    for i in 0..7 {
        store
            .ingest(
                &store_common::fake_mcap(i, 64),
                store_common::meta(i, 1),
                store_common::skills(i, 1),
            )
            .await
            .unwrap();
    }
    let mut cursor = None;
    let mut ids = Vec::new();
    loop {
        let page = store.list_sessions(3, cursor.as_deref()).await.unwrap();
        ids.extend(page.items.iter().map(|s| s.id));
        match page.next_cursor {
            Some(c) => cursor = Some(c),
            None => break,
        }
    }
    assert_eq!(ids, (1..=7).collect::<Vec<i64>>());
}

#[tokio::test]
async fn a_stored_row_with_an_unknown_shape_contact_model_or_phase_is_refused_naming_it() {
    use sqlx::Connection as _;
    let tmp = tempfile::tempdir().unwrap();
    let store = Store::open(tmp.path()).await.unwrap();
    let out = store
        .ingest(
            &store_common::fake_mcap(1, 64),
            store_common::meta(1, 3),
            store_common::skills(1, 3),
        )
        .await
        .unwrap();
    let [a, b, c] = out.skill_ids[..] else {
        panic!("{out:?}")
    };
    for id in [a, b, c] {
        store.get_skill(id).await.unwrap();
    }
    store.close().await;
    // Rows changed behind the store's back: a TEXT column holding a name the types do not know.
    let opts = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(tmp.path().join(services::store::DB_FILE));
    let mut conn = sqlx::SqliteConnection::connect_with(&opts).await.unwrap();
    for (q, id) in [
        ("UPDATE skills SET object_shape = 'torus' WHERE id = ?", a),
        ("UPDATE skills SET contact_model = 'magic' WHERE id = ?", b),
        (
            "UPDATE skills SET phase_durations = '[[\"juggle\", 1.0]]' WHERE id = ?",
            c,
        ),
        (
            "UPDATE sessions SET meta = json_set(meta, '$.object_shape', 'torus') WHERE id = ?",
            out.session_id,
        ),
    ] {
        sqlx::query(q).bind(id).execute(&mut conn).await.unwrap();
    }
    conn.close().await.unwrap();
    let store = Store::open(tmp.path()).await.unwrap();
    for (id, message) in [
        (
            a,
            format!("skill {a}: object_shape: unknown shape \"torus\""),
        ),
        (
            b,
            format!("skill {b}: contact_model: unknown contact model \"magic\""),
        ),
        (
            c,
            format!("skill {c}: phase_durations: unknown phase \"juggle\""),
        ),
    ] {
        match store.get_skill(id).await {
            Err(StoreError::Corrupt(m)) => assert!(m.starts_with(&message), "{m}"),
            other => panic!("skill {id} gave {other:?}"),
        }
    }
    match store.get_session(out.session_id).await {
        Err(StoreError::Corrupt(m)) => assert!(
            m.starts_with(&format!(
                "session {}: meta: unknown shape \"torus\"",
                out.session_id
            )),
            "{m}"
        ),
        other => panic!("the session gave {other:?}"),
    }
    store.close().await;
}

backend_tests!(
    filters_sorts_and_cursors_walk_every_matching_skill_exactly_once,
    ties_in_the_sort_value_are_paged_through_by_id,
    a_malformed_or_foreign_cursor_is_a_bad_cursor,
    out_of_range_queries_are_invalid,
    sessions_page_through_in_id_order,
);
