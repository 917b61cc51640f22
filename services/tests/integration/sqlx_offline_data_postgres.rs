//! The PostgreSQL offline query data in `store-postgres/.sqlx/` is current, as
//! `sqlx_offline_data.rs` checks SQLite's `.sqlx/`:
//!
//! - every stored query, described against a schema `migrations/postgres` makes today (in the
//!   data base of `ICMS_TEST_POSTGRES_URL`), gives the columns, types, nullability and
//!   parameters its data says (skipped, saying so, without that variable);
//! - every checked query of `store-postgres/src` has one data file and no file is left over.
//!
//! Both fail with the fix: run `scripts/sqlx-prepare` and commit `store-postgres/.sqlx/`.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};
use sqlx::{Connection, Executor, PgConnection};

/// The crate's `.sqlx` directory.
fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../store-postgres/.sqlx")
}

/// Every `query-*.json` file, parsed, with its path.
fn data_files() -> Vec<(PathBuf, serde_json::Value)> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(data_dir()).expect("store-postgres/.sqlx exists") {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name.starts_with("query-") && name.ends_with(".json") {
            let text = std::fs::read_to_string(&path).unwrap();
            let data = serde_json::from_str(&text)
                .unwrap_or_else(|e| panic!("{}: not JSON: {e}", path.display()));
            out.push((path, data));
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
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
    use sqlx::{Column, TypeInfo};
    let columns: Vec<serde_json::Value> = d
        .columns()
        .iter()
        .enumerate()
        .map(|(i, c)| {
            serde_json::json!({
                "name": c.name(),
                "type": c.type_info().name(),
                "nullable": d.nullable(i),
            })
        })
        .collect();
    let parameters: Vec<String> = match d.parameters() {
        Some(sqlx::Either::Left(types)) => types.iter().map(|t| t.name().to_owned()).collect(),
        _ => Vec::new(),
    };
    serde_json::json!({ "columns": columns, "parameters": parameters })
}

fn stored_shape(describe: &serde_json::Value) -> serde_json::Value {
    let empty = Vec::new();
    let columns: Vec<serde_json::Value> = describe["columns"]
        .as_array()
        .unwrap_or(&empty)
        .iter()
        .enumerate()
        .map(|(i, c)| {
            serde_json::json!({
                "name": c["name"],
                "type": sql_name(c["type_info"].as_str().unwrap_or("")),
                "nullable": describe["nullable"][i],
            })
        })
        .collect();
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
    let Ok(base) = std::env::var("ICMS_TEST_POSTGRES_URL") else {
        // scripts/test sets both: there a missing server fails the test instead of skipping it.
        assert!(
            std::env::var_os("ICMS_REQUIRE_TOOLS").is_none_or(|v| v.is_empty()),
            "ICMS_TEST_POSTGRES_URL is not set but ICMS_REQUIRE_TOOLS is"
        );
        let _ = writeln!(
            std::io::stderr(),
            "SKIPPED every_stored_postgres_query_describes_today_as_its_data_says: \
             ICMS_TEST_POSTGRES_URL is not set (scripts/test sets it)"
        );
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
    let files = data_files();
    assert!(
        !files.is_empty(),
        "no query data in {}",
        data_dir().display()
    );
    for (path, data) in &files {
        let shown = path.display();
        assert_eq!(data["db_name"], "PostgreSQL", "{shown}");
        let query = data["query"]
            .as_str()
            .unwrap_or_else(|| panic!("{shown}: no query"));
        let hash = hex::encode(Sha256::digest(query.as_bytes()));
        assert_eq!(data["hash"], hash, "{shown}: the hash is not the query's");
        assert!(
            path.ends_with(format!("query-{hash}.json")),
            "{shown}: named for another hash than its query's ({hash})"
        );
        let described = conn
            .describe(query)
            .await
            .unwrap_or_else(|e| panic!("{shown}: the query no longer prepares: {e}\n{query}"));
        assert_eq!(
            described_as_json(&described),
            stored_shape(&data["describe"]),
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
    let mut queries = 0;
    for entry in std::fs::read_dir(&src).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path).unwrap();
            queries += ["sqlx::query!(", "sqlx::query_as!(", "sqlx::query_scalar!("]
                .iter()
                .map(|m| text.matches(m).count())
                .sum::<usize>();
        }
    }
    let files = data_files().len();
    assert!(queries > 0, "no checked queries under {}", src.display());
    assert_eq!(
        files, queries,
        "{queries} checked queries in store-postgres/src but {files} data files in \
         store-postgres/.sqlx/: run scripts/sqlx-prepare"
    );
}
