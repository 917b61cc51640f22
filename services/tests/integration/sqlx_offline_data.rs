//! The offline query data in `.sqlx/` is current. sqlx's checked query macros build from it
//! when no data base is at hand (every build but a developer's with `DATABASE_URL` set), so:
//!
//! - a query changed without its data fails the build itself (no data file has the new
//!   query's hash; `scripts/test` builds with `SQLX_OFFLINE=true`);
//! - a migration changed without the data would build against the old schema's types: the
//!   first test describes every stored query against a data base the migrations make today
//!   and compares with what is stored;
//! - a data file no query uses any more is left over: the second test counts them against the
//!   checked queries in the sources.
//!
//! Both fail with the fix: run `scripts/sqlx-prepare` and commit `.sqlx/`.

use std::path::{Path, PathBuf};

use services::store::{Store, DB_FILE};
use sha2::{Digest, Sha256};
use sqlx::{Connection, Executor, SqliteConnection};

/// The workspace's `.sqlx` directory.
fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../.sqlx")
}

/// Every `query-*.json` file of the `.sqlx` directory `dir`, parsed, with its path (shared
/// with `sqlx_offline_data_postgres.rs`).
pub(super) fn data_files(dir: &Path) -> Vec<(PathBuf, serde_json::Value)> {
    let mut out = Vec::new();
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
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

/// A query's data file: where it is, the query's text and its stored `describe`.
pub(super) struct StoredQuery {
    pub path: PathBuf,
    pub query: String,
    pub describe: serde_json::Value,
}

/// The query data files of `dir` (at least one), each checked to be `db_name`'s and named for
/// the hash of its query's text, as the macros look it up.
pub(super) fn stored_queries(dir: &Path, db_name: &str) -> Vec<StoredQuery> {
    let files = data_files(dir);
    assert!(!files.is_empty(), "no query data in {}", dir.display());
    files
        .into_iter()
        .map(|(path, data)| {
            let shown = path.display();
            assert_eq!(data["db_name"], db_name, "{shown}");
            let query = data["query"]
                .as_str()
                .unwrap_or_else(|| panic!("{shown}: no query"))
                .to_owned();
            // The macros find a query's data by the hash of its text, in the file's name.
            let hash = hex::encode(Sha256::digest(query.as_bytes()));
            assert_eq!(data["hash"], hash, "{shown}: the hash is not the query's");
            assert!(
                path.ends_with(format!("query-{hash}.json")),
                "{shown}: named for another hash than its query's ({hash})"
            );
            StoredQuery {
                query,
                describe: data["describe"].clone(),
                path,
            }
        })
        .collect()
}

/// What the macros take from a query's description, as the data files hold it: each
/// column's name, SQL type and nullability, and the number of parameters. (The description's
/// own serde form is compiled only into the macros' copy of sqlx.)
fn described_as_json(d: &sqlx::Describe<sqlx::Sqlite>) -> serde_json::Value {
    let columns = described_columns(d);
    let parameters = match d.parameters() {
        Some(sqlx::Either::Right(n)) => serde_json::json!(n),
        Some(sqlx::Either::Left(types)) => serde_json::json!(types.len()),
        None => serde_json::Value::Null,
    };
    serde_json::json!({ "columns": columns, "parameters": parameters })
}

/// A description's columns as the data files hold them: name, SQL type and nullability
/// (shared with `sqlx_offline_data_postgres.rs`).
pub(super) fn described_columns<DB: sqlx::Database>(
    d: &sqlx::Describe<DB>,
) -> Vec<serde_json::Value> {
    use sqlx::{Column, TypeInfo};
    d.columns()
        .iter()
        .enumerate()
        .map(|(i, c)| {
            serde_json::json!({
                "name": c.name(),
                "type": c.type_info().name(),
                "nullable": d.nullable(i),
            })
        })
        .collect()
}

/// The same from a data file's `describe`, its type names made SQL names by `sql_name`
/// (shared with `sqlx_offline_data_postgres.rs`).
pub(super) fn stored_columns(
    describe: &serde_json::Value,
    sql_name: impl Fn(&str) -> String,
) -> Vec<serde_json::Value> {
    let empty = Vec::new();
    describe["columns"]
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
        .collect()
}

/// The same from a data file's `describe`: its type names are sqlx's SQLite data types, whose
/// SQL names [`described_as_json`] compares.
fn stored_shape(describe: &serde_json::Value) -> serde_json::Value {
    let sql_name = |t: &str| match t {
        "Null" => "NULL",
        "Text" => "TEXT",
        "Float" => "REAL",
        "Blob" => "BLOB",
        "Int4" | "Integer" => "INTEGER",
        "Numeric" => "NUMERIC",
        "Bool" => "BOOLEAN",
        "Date" => "DATE",
        "Time" => "TIME",
        "Datetime" => "DATETIME",
        other => panic!("unknown SQLite data type {other:?} in .sqlx"),
    };
    let columns = stored_columns(describe, |t| sql_name(t).to_owned());
    let parameters = match &describe["parameters"] {
        serde_json::Value::Object(p) => p
            .get("Right")
            .cloned()
            .or_else(|| {
                p.get("Left")
                    .and_then(|l| l.as_array())
                    .map(|l| l.len().into())
            })
            .unwrap_or(serde_json::Value::Null),
        _ => serde_json::Value::Null,
    };
    serde_json::json!({ "columns": columns, "parameters": parameters })
}

#[tokio::test]
async fn every_stored_query_describes_today_as_its_data_says() {
    let tmp = tempfile::tempdir().unwrap();
    Store::open(tmp.path()).await.unwrap().close().await;
    let opts = sqlx::sqlite::SqliteConnectOptions::new().filename(tmp.path().join(DB_FILE));
    let mut conn = SqliteConnection::connect_with(&opts).await.unwrap();
    for StoredQuery {
        path,
        query,
        describe,
    } in stored_queries(&data_dir(), "SQLite")
    {
        let shown = path.display();
        let described = conn
            .describe(query.as_str())
            .await
            .unwrap_or_else(|e| panic!("{shown}: the query no longer prepares: {e}\n{query}"));
        assert_eq!(
            described_as_json(&described),
            stored_shape(&describe),
            "{shown}: the schema the migrations make today describes this query otherwise \
             than its stored data: run scripts/sqlx-prepare\n{query}"
        );
    }
    conn.close().await.unwrap();
}

/// The checked query macro calls in the Rust files under `dir` (shared with
/// `sqlx_offline_data_postgres.rs`).
pub(super) fn checked_queries_in(dir: &Path) -> usize {
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            n += checked_queries_in(&path);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path).unwrap();
            n += ["sqlx::query!(", "sqlx::query_as!(", "sqlx::query_scalar!("]
                .iter()
                .map(|m| text.matches(m).count())
                .sum::<usize>();
        }
    }
    n
}

#[test]
fn every_checked_query_has_one_data_file_and_no_file_is_left_over() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let queries = checked_queries_in(&src);
    let files = data_files(&data_dir()).len();
    assert!(queries > 0, "no checked queries under {}", src.display());
    // Two calls of the same text would share a file; the store's queries are all distinct.
    assert_eq!(
        files, queries,
        "{queries} checked queries in services/src but {files} data files in .sqlx/: run \
         scripts/sqlx-prepare"
    );
}
