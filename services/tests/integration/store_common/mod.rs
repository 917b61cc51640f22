//! Helpers shared by the store tests: deterministic fake MCAP bytes, metadata and skills, and
//! the backends every behavioural test runs against ([`Backend`], [`backend_tests!`]).
#![allow(dead_code)]

use std::io::Write as _;
use std::path::Path;

use services::store::{Database, Store, StoreError, DB_FILE};
use sha2::{Digest, Sha256};
use sqlx::Connection as _;

use dfs_core::replay::{ReplayParams, ReplayReport};
use services::replay::{load_builtin_hand, replay_skill, skill_spec_from_json, ReplaySource};
use services::store::bench::{synthetic_blob, synthetic_skill, SplitMix64};
use services::store::{NewSkill, SessionMeta};

/// Deterministic pseudo-MCAP bytes number `i` of `len` bytes (distinct for distinct `i`).
pub fn fake_mcap(i: u64, len: usize) -> Vec<u8> {
    synthetic_blob(i, len)
}

/// Metadata of a test session; `extra` records `i` and the number of skills.
pub fn meta(i: u64, n_skills: usize) -> SessionMeta {
    SessionMeta {
        scenario: Some("test".into()),
        seed: Some(i),
        hand: "glove10".into(),
        object_shape: "sphere".parse().unwrap(),
        object_mass: 0.5,
        mu: 0.8,
        duration_ns: 10_000_000_000,
        started_at: Some("2026-01-01T00:00:00Z".into()),
        extra: serde_json::json!({ "i": i, "skills": n_skills }),
    }
}

/// `n` synthetic skills drawn from `seed`.
pub fn skills(seed: u64, n: usize) -> Vec<NewSkill> {
    let mut rng = SplitMix64::new(seed);
    (0..n).map(|_| synthetic_skill(&mut rng)).collect()
}

/// The MCAP blobs under a data directory.
pub fn blob_count(dir: &Path) -> usize {
    fn walk(p: &Path, n: &mut usize) {
        for e in std::fs::read_dir(p).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                walk(&e.path(), n);
            } else if e.path().extension().is_some_and(|x| x == "mcap") {
                *n += 1;
            }
        }
    }
    let mut n = 0;
    let root = dir.join("blobs");
    if root.exists() {
        walk(&root, &mut n);
    }
    n
}

/// A report of a replay that fails at once: a 0.4 m sphere does not fit in the gripper.
pub fn unreachable_report() -> ReplayReport {
    let skill = serde_json::json!({
        "phases": [
            {"name": "approach", "start_ns": 0, "end_ns": 500_000_000u64},
            {"name": "grasp", "start_ns": 500_000_000u64, "end_ns": 1_000_000_000u64},
            {"name": "lift", "start_ns": 1_000_000_000u64, "end_ns": 1_500_000_000u64},
            {"name": "release", "start_ns": 1_500_000_000u64, "end_ns": 2_000_000_000u64}
        ],
        "object": {"shape": "sphere", "size": [0.2], "mass": 0.3, "mu": 0.8},
        "contact_model": "soft_finger",
        "contacts": [
            {"finger": "thumb", "position_b": [0.2, 0.0, 0.0], "normal_b": [-1.0, 0.0, 0.0]},
            {"finger": "index", "position_b": [-0.2, 0.0, 0.0], "normal_b": [1.0, 0.0, 0.0]}
        ]
    });
    let spec = skill_spec_from_json(&skill, "big sphere").unwrap();
    let hand = load_builtin_hand("gripper").unwrap();
    replay_skill(
        &hand,
        &spec,
        &ReplayParams::default(),
        &ReplaySource::default(),
        None,
    )
    .unwrap()
}

/// The variable naming the PostgreSQL data base the store's tests also run against
/// (`postgres://user:password@host:port/db`; scripts/test sets it, to the server
/// scripts/test-postgres starts). Each test works in a schema of its own in that data base.
pub const POSTGRES_URL_VAR: &str = "ICMS_TEST_POSTGRES_URL";

/// The URL in [`POSTGRES_URL_VAR`] if it is set; otherwise `None`, after a line on the
/// standard error that says `test` was skipped and why (written past the harness's capture, so
/// that it shows in every run). Panics instead under `ICMS_REQUIRE_TOOLS` (scripts/test), so a
/// run that should test PostgreSQL cannot pass without it.
pub fn postgres_url_or_skip(test: &str) -> Option<String> {
    match std::env::var(POSTGRES_URL_VAR) {
        Ok(url) if !url.is_empty() => Some(url),
        _ => {
            // scripts/test sets both: there a missing server fails the test instead of
            // skipping it.
            assert!(
                std::env::var_os("ICMS_REQUIRE_TOOLS").is_none_or(|v| v.is_empty()),
                "{test}: {POSTGRES_URL_VAR} is not set but ICMS_REQUIRE_TOOLS is"
            );
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED {test}: {POSTGRES_URL_VAR} is not set (scripts/test sets it)"
            );
            None
        }
    }
}

/// A store backend a test runs against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// The data directory's SQLite file.
    Sqlite,
    /// A schema of its own in the data base of [`POSTGRES_URL_VAR`].
    Postgres,
}

impl Backend {
    /// [`Backend::Postgres`] if [`POSTGRES_URL_VAR`] is set; otherwise `None`, skipping as
    /// [`postgres_url_or_skip`] says.
    pub fn postgres_or_skip(test: &str) -> Option<Backend> {
        postgres_url_or_skip(&format!("{test} on PostgreSQL")).map(|_| Backend::Postgres)
    }

    /// The schema of the store of `dir`: named after the directory, so that reopening the
    /// same directory finds the same rows, and tests in parallel never share one.
    fn schema(dir: &Path) -> String {
        let hash = Sha256::digest(dir.to_string_lossy().as_bytes());
        format!("t_{}", hex::encode(&hash[..12]))
    }

    /// The URL of the test data base with `dir`'s schema as its search path.
    fn url(dir: &Path) -> String {
        let base = std::env::var(POSTGRES_URL_VAR).expect("ICMS_TEST_POSTGRES_URL is set");
        let sep = if base.contains('?') { '&' } else { '?' };
        format!(
            "{base}{sep}options=-c%20search_path%3D{}",
            Self::schema(dir)
        )
    }

    /// Where the store of `dir` keeps its rows on this backend (its schema made if missing).
    pub async fn database(self, dir: &Path) -> Database {
        match self {
            Backend::Sqlite => Database::Sqlite,
            Backend::Postgres => {
                let base = std::env::var(POSTGRES_URL_VAR).expect("ICMS_TEST_POSTGRES_URL is set");
                let mut conn = sqlx::PgConnection::connect(&base)
                    .await
                    .unwrap_or_else(|e| panic!("{POSTGRES_URL_VAR}: cannot connect: {e}"));
                sqlx::query(&format!(
                    "CREATE SCHEMA IF NOT EXISTS {}",
                    Self::schema(dir)
                ))
                .execute(&mut conn)
                .await
                .unwrap();
                conn.close().await.unwrap();
                Database::Postgres(Self::url(dir))
            }
        }
    }

    /// Opens (creating) the store of data directory `dir` on this backend.
    pub async fn try_open(self, dir: &Path) -> Result<Store, StoreError> {
        let database = self.database(dir).await;
        Store::open_in(dir, &database).await
    }

    /// [`Backend::try_open`], which must succeed.
    pub async fn open(self, dir: &Path) -> Store {
        self.try_open(dir)
            .await
            .unwrap_or_else(|e| panic!("opening a store on {self:?} in {}: {e}", dir.display()))
    }

    /// Runs SQL on the store of `dir` behind its back, each statement with its one bound
    /// integer if any (written `?`, as SQLite takes it; `$1` on PostgreSQL).
    pub async fn sql(self, dir: &Path, statements: &[(&str, Option<i64>)]) {
        match self {
            Backend::Sqlite => {
                let opts = sqlx::sqlite::SqliteConnectOptions::new()
                    .filename(dir.join(DB_FILE))
                    .foreign_keys(true);
                let mut conn = sqlx::SqliteConnection::connect_with(&opts).await.unwrap();
                for (q, bind) in statements {
                    let mut q = sqlx::query(q);
                    if let Some(b) = bind {
                        q = q.bind(*b);
                    }
                    q.execute(&mut conn).await.unwrap();
                }
                conn.close().await.unwrap();
            }
            Backend::Postgres => {
                let mut conn = sqlx::PgConnection::connect(&Self::url(dir)).await.unwrap();
                for (q, bind) in statements {
                    let text = q.replace('?', "$1");
                    let mut q = sqlx::query(&text);
                    if let Some(b) = bind {
                        q = q.bind(*b);
                    }
                    q.execute(&mut conn).await.unwrap();
                }
                conn.close().await.unwrap();
            }
        }
    }

    /// The one integer `query` answers on the store of `dir`.
    pub async fn count(self, dir: &Path, query: &str) -> i64 {
        match self {
            Backend::Sqlite => {
                let opts = sqlx::sqlite::SqliteConnectOptions::new().filename(dir.join(DB_FILE));
                let mut conn = sqlx::SqliteConnection::connect_with(&opts).await.unwrap();
                let n = sqlx::query_scalar(query)
                    .fetch_one(&mut conn)
                    .await
                    .unwrap();
                conn.close().await.unwrap();
                n
            }
            Backend::Postgres => {
                let mut conn = sqlx::PgConnection::connect(&Self::url(dir)).await.unwrap();
                let n = sqlx::query_scalar(query)
                    .fetch_one(&mut conn)
                    .await
                    .unwrap();
                conn.close().await.unwrap();
                n
            }
        }
    }
}

/// Test functions `async fn name(backend: Backend)` run as tests `sqlite::name` and
/// `postgres::name` (the latter skipped, saying so, without [`POSTGRES_URL_VAR`]).
#[macro_export]
macro_rules! backend_tests {
    ($($name:ident),* $(,)?) => {
        mod sqlite {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
                async fn $name() {
                    super::$name(super::store_common::Backend::Sqlite).await
                }
            )*
        }
        mod postgres {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
                async fn $name() {
                    if let Some(b) =
                        super::store_common::Backend::postgres_or_skip(stringify!($name))
                    {
                        super::$name(b).await
                    }
                }
            )*
        }
    };
}
