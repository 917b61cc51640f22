//! The test PostgreSQL for the end-to-end tests that start servers and workers on it
//! (`ICMS_TEST_POSTGRES_URL`, which scripts/test sets).

use std::io::Write;

use sqlx::Connection as _;

/// The test data base's URL, or `None` (after saying so on stderr) to skip; a failure instead
/// under `ICMS_REQUIRE_TOOLS` (scripts/test), where a missing server must not pass.
pub fn postgres_or_skip(test: &str) -> Option<String> {
    match std::env::var("ICMS_TEST_POSTGRES_URL") {
        Ok(url) if !url.is_empty() => Some(url),
        _ => {
            assert!(
                std::env::var_os("ICMS_REQUIRE_TOOLS").is_none_or(|v| v.is_empty()),
                "ICMS_TEST_POSTGRES_URL is not set but ICMS_REQUIRE_TOOLS is"
            );
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED {test}: ICMS_TEST_POSTGRES_URL is not set (scripts/test sets it)"
            );
            None
        }
    }
}

/// A fresh schema `schema` in the test data base at `base` (dropped first if there); the URL
/// that works in it.
pub fn fresh_schema(rt: &tokio::runtime::Runtime, base: &str, schema: &str) -> String {
    rt.block_on(async {
        let mut conn = sqlx::PgConnection::connect(base).await.unwrap();
        for q in [
            format!("DROP SCHEMA IF EXISTS {schema} CASCADE"),
            format!("CREATE SCHEMA {schema}"),
        ] {
            sqlx::query(&q).execute(&mut conn).await.unwrap();
        }
        conn.close().await.unwrap();
    });
    let sep = if base.contains('?') { '&' } else { '?' };
    format!("{base}{sep}options=-c%20search_path%3D{schema}")
}
