//! The PostgreSQL offline query data in `store-postgres/.sqlx/` is current, as
//! `sqlx_offline_data.rs` checks SQLite's `.sqlx/`:
//!
//! - every stored query, described against a schema `migrations/postgres` makes today (in the
//!   data base of `ICMS_TEST_POSTGRES_URL`), gives the columns, types, nullability and
//!   parameters its data says (skipped, saying so, without that variable);
//! - every checked query of `store-postgres/src` has one data file and no file is left over.
//!
//! Both fail with the fix: run `scripts/sqlx-prepare` and commit `store-postgres/.sqlx/`.

use std::path::{Path, PathBuf};

use sqlx::{Connection, Executor, PgConnection};

use super::sqlx_offline_data::{
    checked_queries_in, data_files, described_columns, stored_columns, stored_queries, StoredQuery,
};
use super::store_common::postgres_url_or_skip;

/// The crate's `.sqlx` directory.
fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../store-postgres/.sqlx")
}

/// A type as the data files name it (`Int8`, `Int8Array`) in PostgreSQL's words (`INT8`,
/// `INT8[]`), as a description gives them.
fn sql_name(stored: &str) -> String {
    match stored.strip_suffix("Array") {
        Some(base) => format!("{}[]", base.to_uppercase()),
        None => stored.to_uppercase(),
    }
}

fn described_as_json(d: &sqlx::Describe<sqlx::Postgres>) -> serde_json::Value {
    use sqlx::TypeInfo;
    let columns = described_columns(d);
    let parameters: Vec<String> = match d.parameters() {
        Some(sqlx::Either::Left(types)) => types.iter().map(|t| t.name().to_owned()).collect(),
        _ => Vec::new(),
    };
    serde_json::json!({ "columns": columns, "parameters": parameters })
}

fn stored_shape(describe: &serde_json::Value) -> serde_json::Value {
    let empty = Vec::new();
    let columns = stored_columns(describe, sql_name);
    let parameters: Vec<String> = describe["parameters"]["Left"]
        .as_array()
        .unwrap_or(&empty)
        .iter()
        .map(|t| sql_name(t.as_str().unwrap_or("")))
        .collect();
    serde_json::json!({ "columns": columns, "parameters": parameters })
}

#[tokio::test]
async fn every_stored_postgres_query_describes_today_as_its_data_says() {
    let Some(base) =
        postgres_url_or_skip("every_stored_postgres_query_describes_today_as_its_data_says")
    else {
        return;
    };
    let schema = format!("offline_data_{}", std::process::id());
    let mut admin = PgConnection::connect(&base).await.unwrap();
    admin
        .execute(format!("DROP SCHEMA IF EXISTS {schema} CASCADE; CREATE SCHEMA {schema}").as_str())
        .await
        .unwrap();
    let sep = if base.contains('?') { '&' } else { '?' };
    let url = format!("{base}{sep}options=-c%20search_path%3D{schema}");
    let mut conn = PgConnection::connect(&url).await.unwrap();
    store_postgres::MIGRATOR.run(&mut conn).await.unwrap();
    for StoredQuery {
        path,
        query,
        describe,
    } in stored_queries(&data_dir(), "PostgreSQL")
    {
        let shown = path.display();
        let described = conn
            .describe(query.as_str())
            .await
            .unwrap_or_else(|e| panic!("{shown}: the query no longer prepares: {e}\n{query}"));
        assert_eq!(
            described_as_json(&described),
            stored_shape(&describe),
            "{shown}: the schema migrations/postgres makes today describes this query \
             otherwise than its stored data: run scripts/sqlx-prepare\n{query}"
        );
    }
    conn.close().await.unwrap();
    admin
        .execute(format!("DROP SCHEMA {schema} CASCADE").as_str())
        .await
        .unwrap();
    admin.close().await.unwrap();
}

#[test]
fn every_checked_postgres_query_has_one_data_file_and_no_file_is_left_over() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../store-postgres/src");
    let queries = checked_queries_in(&src);
    let files = data_files(&data_dir()).len();
    assert!(queries > 0, "no checked queries under {}", src.display());
    assert_eq!(
        files, queries,
        "{queries} checked queries in store-postgres/src but {files} data files in \
         store-postgres/.sqlx/: run scripts/sqlx-prepare"
    );
}
