//! Settings of `icms serve`: the command-line arguments ([`ServeArgs`], also read from
//! `ICMS_TOKEN`) and the checked configuration they become ([`ServeConfig`]).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use axum::http::HeaderValue;
use services::store::{Blobs, Database, StoreError, JOB_LEASE};

use crate::http::server::{default_max_connections, ConnectionLimits};
use crate::http::{LayerConfig, StateConfig};
use crate::jobs::WorkerConfig;

/// Default largest request body: 256 MiB.
pub const DEFAULT_MAX_BODY: usize = 256 * 1024 * 1024;

/// Default largest session upload: 2 GiB, three hours of session at the 11.4 MB a minute of
/// format 2 (uploads are streamed to disk, not held in memory).
pub const DEFAULT_MAX_UPLOAD: usize = 2 << 30;

/// Arguments of `icms serve`.
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
    /// Address to listen on, host:port (a host name such as localhost is resolved). Anything
    /// but a loopback address needs a token.
    #[arg(long, default_value = "127.0.0.1:8080", value_parser = listen_address)]
    pub addr: SocketAddr,
    /// Where the store is: data directory, data base, bucket.
    #[command(flatten)]
    pub store: StoreArgs,
    /// Bearer token that write requests (uploads, simulations, deletes) must send; reads stay
    /// open. Without one, writes are open too (allowed on a loopback address only).
    #[arg(long, env = "ICMS_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Do not seed an empty data base with simulated sessions of the built-in scenarios.
    #[arg(long)]
    pub no_demo: bool,
    /// Largest request body, bytes, but for session uploads (over it: 413).
    #[arg(long, default_value_t = DEFAULT_MAX_BODY)]
    pub max_body: usize,
    /// Largest session upload (`POST /api/v1/sessions`), bytes (over it: 413). Uploads are
    /// streamed to disk: the default, 2 GiB, is three hours of session.
    #[arg(long, default_value_t = DEFAULT_MAX_UPLOAD)]
    pub max_upload: usize,
    /// Origin allowed to call the API from a browser (repeatable). Default: none, no CORS.
    #[arg(long = "cors-origin")]
    pub cors_origins: Vec<String>,
    /// Time limit of one request in seconds, body included (over it: 503).
    #[arg(long, default_value_t = 120.0)]
    pub request_timeout: f64,
    /// Simulations and replays this server runs at once: its job workers, which take jobs
    /// submitted through any server on the same data base. 0: none; the jobs are run by other
    /// servers and `icms worker`s on the same PostgreSQL data base (not allowed with SQLite,
    /// whose file no other process may write).
    #[arg(long, default_value_t = 2)]
    pub max_simulations: usize,
    /// Longest a simulation or replay request waits for its job, seconds (at most 80 % of
    /// --request-timeout): finished by then it is answered 201 with its result, otherwise
    /// 202 with the job's URL. 0: always 202.
    #[arg(long, default_value_t = 30.0)]
    pub job_wait: f64,
    /// Longest a job may run, seconds: then it is stopped and failed (503), nothing stored.
    #[arg(long, default_value_t = 600.0)]
    pub job_timeout: f64,
    /// Jobs that may wait for a worker; further simulation and replay requests get 503 with
    /// `Retry-After`.
    #[arg(long, default_value_t = 1000)]
    pub max_queued_jobs: usize,
    /// MiB of skill JSON the server keeps in memory for `GET /api/v1/skills/{id}` (0: none).
    #[arg(long, default_value_t = 64)]
    pub cache_mib: usize,
    /// Session uploads read and segmented at once (each holds up to a bounded multiple of its
    /// size in memory, see docs/api.md); further uploads wait up to `--queue-wait` seconds for
    /// a turn, then get 503 with `Retry-After`.
    #[arg(long, default_value_t = 2)]
    pub max_ingests: usize,
    /// Longest wait of an upload for a free turn before 503, seconds.
    #[arg(long, default_value_t = 10.0)]
    pub queue_wait: f64,
    /// Seconds a client may take from a request's first byte to the end of its headers.
    #[arg(long, default_value_t = 10.0)]
    pub header_timeout: f64,
    /// Seconds a connection may sit idle (after connecting, or between requests) before it is
    /// closed.
    #[arg(long, default_value_t = 30.0)]
    pub keep_alive_timeout: f64,
    /// Most connections open at once; more wait in the kernel's backlog. Default 1024, or the
    /// descriptor limit less 64 when that is lower.
    #[arg(long)]
    pub max_connections: Option<usize>,
    /// Live glove sessions (`GET /api/v1/live`) at once; more are answered 503.
    #[arg(long, default_value_t = 16)]
    pub max_live: usize,
    /// Threads stepping the live sessions' DFS, shared by all of them. Default: the number of
    /// cores.
    #[arg(long)]
    pub live_threads: Option<usize>,
    /// Seconds without a sample after which a live session ends (stored as incomplete).
    #[arg(long, default_value_t = 10.0)]
    pub live_silence: f64,
    /// Publish every live session's hand, object and forces through the Foxglove SDK's
    /// WebSocket server on this address (host:port, e.g. 127.0.0.1:8765): the Foxglove app's
    /// "Open connection" shows them as they happen, each session under `/live/N/`.
    #[arg(long, value_parser = listen_address)]
    pub foxglove: Option<SocketAddr>,
}

/// Where the data is: the data directory, and optionally a PostgreSQL data base and an
/// S3-compatible bucket. Every command that opens the skill data base takes these (`icms
/// serve`, `icms worker`, `icms ingest`, `icms skills`, `icms replay`, ...).
#[derive(Debug, Clone, clap::Args)]
pub struct DataArgs {
    /// Data directory: SQLite database and MCAP blobs, created and migrated on first start.
    /// With --database-url, it holds the MCAP blobs only; with --blobs, copies of them. One
    /// process at a time writes a data directory.
    #[arg(long, default_value = "icms-data")]
    pub data: PathBuf,
    /// PostgreSQL data base to keep the rows in instead of the data directory's SQLite file
    /// (postgres://user:password@host:port/dbname), migrated on start. It must answer within
    /// 5 s. Default: none, SQLite. See docs/backends.md.
    #[arg(long, env = "DATABASE_URL", hide_env_values = true, value_name = "URL")]
    pub database_url: Option<String>,
    /// S3-compatible bucket to keep the session and replay files in instead of the data
    /// directory (s3://bucket or s3://bucket/prefix). Endpoint and credentials come from
    /// AWS_ENDPOINT_URL, AWS_REGION, AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY; the bucket must
    /// answer within 10 s. Default: none, files in the data directory. See docs/backends.md.
    #[arg(long, env = "ICMS_BLOBS", value_name = "URL")]
    pub blobs: Option<String>,
}

impl DataArgs {
    /// The defaults (SQLite, files in the directory) in data directory `data`.
    pub fn in_dir(data: PathBuf) -> DataArgs {
        DataArgs {
            data,
            database_url: None,
            blobs: None,
        }
    }

    /// The checked data base and blobs, errors naming the option.
    pub fn resolve(&self) -> Result<(Database, Blobs), ConfigError> {
        let database = Database::from_url(self.database_url.as_deref()).map_err(|e| match e {
            StoreError::InvalidInput(m) => ConfigError::DatabaseUrl(m),
            other => ConfigError::DatabaseUrl(other.to_string()),
        })?;
        let blobs = Blobs::from_arg(self.blobs.as_deref()).map_err(|e| match e {
            StoreError::InvalidInput(m) => ConfigError::Blobs(m),
            other => ConfigError::Blobs(other.to_string()),
        })?;
        Ok((database, blobs))
    }
}

/// Where a store is and how much of the data directory its copies of a bucket's files may
/// take: the options `icms serve` and `icms worker` share.
#[derive(Debug, Clone, clap::Args)]
pub struct StoreArgs {
    /// The data directory, data base and bucket.
    #[command(flatten)]
    pub at: DataArgs,
    /// MiB of the data directory the copies of the bucket's files may take (with --blobs):
    /// past it, the least recently used copies (unused for 10 minutes) are removed; they stay
    /// in the bucket and are downloaded again when next read.
    #[arg(long, default_value_t = DEFAULT_BLOB_CACHE_MIB)]
    pub blob_cache_mib: u64,
}

impl Default for StoreArgs {
    fn default() -> Self {
        StoreArgs::in_dir(PathBuf::from("icms-data"))
    }
}

impl StoreArgs {
    /// The defaults (SQLite, files in the directory) in data directory `data`.
    pub fn in_dir(data: PathBuf) -> StoreArgs {
        StoreArgs {
            at: DataArgs::in_dir(data),
            blob_cache_mib: DEFAULT_BLOB_CACHE_MIB,
        }
    }

    /// The checked data base, blobs and copy-cache bound, errors naming the option.
    pub fn resolve(&self) -> Result<(Database, Blobs, u64), ConfigError> {
        let (database, blobs) = self.at.resolve()?;
        Ok((database, blobs, blob_cache_bytes(self.blob_cache_mib)?))
    }
}

/// Largest accepted `--max-body` and `--max-upload`: 64 GiB.
pub const MAX_MAX_BODY: usize = 64 << 30;
/// Longest accepted `--request-timeout`, `--queue-wait`, `--header-timeout` and
/// `--keep-alive-timeout`: one day.
pub const MAX_TIMEOUT_S: f64 = 86_400.0;
/// Largest accepted `--max-simulations`, `--max-ingests`, `--max-live` and `--live-threads`.
pub const MAX_WORKERS: usize = 256;
/// Default `--blob-cache-mib`: 10 GiB of copies of a bucket's blobs.
pub const DEFAULT_BLOB_CACHE_MIB: u64 = 10 * 1024;

/// `--blob-cache-mib` in bytes, if it is at least 1 and at most 2^40 MiB.
pub fn blob_cache_bytes(mib: u64) -> Result<u64, ConfigError> {
    if (1..=1 << 40).contains(&mib) {
        Ok(mib << 20)
    } else {
        Err(ConfigError::OutOfRange(format!(
            "--blob-cache-mib must be in 1..={}, got {mib}",
            1u64 << 40
        )))
    }
}

/// Largest accepted `--max-queued-jobs`.
pub const MAX_QUEUED_JOBS: usize = 1_000_000;
/// Largest accepted `--cache-mib` (64 GiB).
pub const MAX_CACHE_MIB: usize = 1 << 16;
/// Largest accepted `--max-connections`.
pub const MAX_CONNECTIONS: usize = 1 << 20;

/// `value` seconds as a duration, if it is in (0, [`MAX_TIMEOUT_S`]]; else the error names
/// `option`.
pub(crate) fn seconds(option: &str, value: f64) -> Result<Duration, ConfigError> {
    if value.is_finite() && value > 0.0 && value <= MAX_TIMEOUT_S {
        Ok(Duration::from_secs_f64(value))
    } else {
        Err(ConfigError::OutOfRange(format!(
            "{option} must be a number of seconds in (0, {MAX_TIMEOUT_S}], got {value}"
        )))
    }
}

/// `value` if it is in `lo..=hi`; else the error names `option`.
pub(crate) fn count(
    option: &str,
    value: usize,
    lo: usize,
    hi: usize,
) -> Result<usize, ConfigError> {
    if (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err(ConfigError::OutOfRange(format!(
            "{option} must be in {lo}..={hi}, got {value}"
        )))
    }
}

/// `--addr`: an IP address and port, or a host name and port resolved to its first address
/// (`localhost:8080`).
fn listen_address(s: &str) -> Result<SocketAddr, String> {
    if let Ok(addr) = s.parse() {
        return Ok(addr);
    }
    let expected = "expected host:port, e.g. 127.0.0.1:8080, [::1]:8080 or localhost:8080";
    match std::net::ToSocketAddrs::to_socket_addrs(s) {
        Ok(mut addrs) => addrs
            .next()
            .ok_or_else(|| format!("{s:?} resolves to no address; {expected}")),
        Err(e) => Err(format!("{s:?}: {e}; {expected}")),
    }
}

impl Default for ServeArgs {
    fn default() -> Self {
        ServeArgs {
            addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            store: StoreArgs::default(),
            token: None,
            no_demo: false,
            max_body: DEFAULT_MAX_BODY,
            max_upload: DEFAULT_MAX_UPLOAD,
            cors_origins: Vec::new(),
            request_timeout: 120.0,
            max_simulations: 2,
            job_wait: 30.0,
            job_timeout: 600.0,
            max_queued_jobs: 1000,
            cache_mib: 64,
            max_ingests: 2,
            queue_wait: 10.0,
            header_timeout: 10.0,
            keep_alive_timeout: 30.0,
            max_connections: None,
            max_live: 16,
            live_threads: None,
            live_silence: 10.0,
            foxglove: None,
        }
    }
}

/// A checked server configuration.
#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// Address to listen on (port 0: any free port).
    pub addr: SocketAddr,
    /// Data directory.
    pub data: PathBuf,
    /// Where the rows are: the data directory's SQLite file or a PostgreSQL data base.
    pub database: Database,
    /// Where the blobs are: the data directory or a bucket.
    pub blobs: Blobs,
    /// Bytes the data directory's copies of a bucket's blobs may take.
    pub blob_cache_bytes: u64,
    /// Seed an empty data base with simulated sessions.
    pub demo: bool,
    /// Handler state settings (token, body limit, job wait, cache).
    pub state: StateConfig,
    /// This server's job workers.
    pub workers: WorkerConfig,
    /// Address of the Foxglove WebSocket server publishing live sessions, if any.
    pub foxglove: Option<SocketAddr>,
    /// Layer settings (time limit, CORS).
    pub layers: LayerConfig,
    /// Connection settings (timeouts, connection limit).
    pub connections: ConnectionLimits,
}

/// Why a configuration is refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Listening beyond this machine without a token would let anyone write.
    #[error(
        "refusing to serve on {0} without a token: anyone who can reach it could upload and \
         delete. Set ICMS_TOKEN or --token, or listen on a loopback address (127.0.0.1)"
    )]
    OpenNonLoopback(SocketAddr),
    /// An empty token.
    #[error("the token is empty")]
    EmptyToken,
    /// A CORS origin that is not an origin (`scheme://host[:port]`, as browsers send it).
    #[error(
        "--cors-origin {0:?} is not an origin: expected http:// or https:// followed by a host \
         and an optional port, with no path (for example http://localhost:5173)"
    )]
    BadOrigin(String),
    /// A setting out of range.
    #[error("{0}")]
    OutOfRange(String),
    /// A --database-url (or DATABASE_URL) that names no backend this binary has.
    #[error("{0}")]
    DatabaseUrl(String),
    /// A --blobs (or ICMS_BLOBS) that names no object store this binary has.
    #[error("{0}")]
    Blobs(String),
}

impl ServeArgs {
    /// The checked configuration.
    pub fn into_config(self) -> Result<ServeConfig, ConfigError> {
        let token = match self.token {
            Some(t) if t.trim().is_empty() => return Err(ConfigError::EmptyToken),
            Some(t) => Some(t.trim().to_string()),
            None => None,
        };
        if token.is_none() && !self.addr.ip().is_loopback() {
            return Err(ConfigError::OpenNonLoopback(self.addr));
        }
        let (database, blobs, blob_cache_bytes) = self.store.resolve()?;
        let request_timeout = seconds("--request-timeout", self.request_timeout)?;
        let queue_wait = seconds("--queue-wait", self.queue_wait)?;
        let header_timeout = seconds("--header-timeout", self.header_timeout)?;
        let keep_alive_timeout = seconds("--keep-alive-timeout", self.keep_alive_timeout)?;
        let live_silence = seconds("--live-silence", self.live_silence)?;
        let max_body = count("--max-body", self.max_body, 1, MAX_MAX_BODY)?;
        let max_upload = count("--max-upload", self.max_upload, 1, MAX_MAX_BODY)?;
        let max_simulations = count("--max-simulations", self.max_simulations, 0, MAX_WORKERS)?;
        if max_simulations == 0 && database == Database::Sqlite {
            return Err(ConfigError::OutOfRange(
                "--max-simulations 0 leaves the jobs to other processes, and with SQLite (no \
                 --database-url) no other process may write the data directory: nothing would \
                 run them. Give --max-simulations 1 or more, or a PostgreSQL --database-url \
                 with `icms worker`s"
                    .into(),
            ));
        }
        let job_timeout = seconds("--job-timeout", self.job_timeout)?;
        if !(self.job_wait.is_finite() && (0.0..=MAX_TIMEOUT_S).contains(&self.job_wait)) {
            return Err(ConfigError::OutOfRange(format!(
                "--job-wait must be a number of seconds in [0, {MAX_TIMEOUT_S}], got {}",
                self.job_wait
            )));
        }
        let job_wait = Duration::from_secs_f64(self.job_wait).min(request_timeout.mul_f64(0.8));
        let max_queued_jobs = count(
            "--max-queued-jobs",
            self.max_queued_jobs,
            1,
            MAX_QUEUED_JOBS,
        )? as u64;
        let max_ingests = count("--max-ingests", self.max_ingests, 1, MAX_WORKERS)?;
        let cache_bytes = count("--cache-mib", self.cache_mib, 0, MAX_CACHE_MIB)? << 20;
        let max_live = count("--max-live", self.max_live, 1, MAX_WORKERS)?;
        let live_threads = match self.live_threads {
            Some(n) => count("--live-threads", n, 1, MAX_WORKERS)?,
            None => std::thread::available_parallelism().map_or(2, |n| n.get()),
        };
        let max_connections = match self.max_connections {
            Some(n) => count("--max-connections", n, 1, MAX_CONNECTIONS)?,
            None => default_max_connections(),
        };
        let cors_origins = self
            .cors_origins
            .iter()
            .map(|o| {
                is_origin(o)
                    .then(|| HeaderValue::from_str(o).ok())
                    .flatten()
                    .ok_or_else(|| ConfigError::BadOrigin(o.clone()))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(ServeConfig {
            addr: self.addr,
            data: self.store.at.data,
            database,
            blobs,
            blob_cache_bytes,
            demo: !self.no_demo,
            foxglove: self.foxglove,
            state: StateConfig {
                token,
                max_body,
                max_upload,
                job_wait,
                max_queued_jobs,
                max_ingests,
                queue_wait,
                cache_bytes,
                max_live,
                live_threads,
                live_silence,
            },
            workers: WorkerConfig {
                count: max_simulations,
                job_timeout,
                lease: JOB_LEASE,
            },
            layers: LayerConfig {
                request_timeout,
                cors_origins,
            },
            connections: ConnectionLimits {
                header_timeout,
                keep_alive_timeout,
                max_connections,
                ..ConnectionLimits::default()
            },
        })
    }
}

/// `scheme://host[:port]` with an http(s) scheme and nothing after the authority: the form of
/// a browser's `Origin` header, the only thing a CORS allow-list entry can match.
fn is_origin(o: &str) -> bool {
    let rest = o
        .strip_prefix("http://")
        .or_else(|| o.strip_prefix("https://"));
    let Some(authority) = rest else {
        return false;
    };
    // An IPv6 literal is bracketed: its colons are not the port's.
    let (host, after) = match authority.strip_prefix('[') {
        Some(v6) => match v6.split_once(']') {
            Some((addr, after)) => (addr, after),
            None => return false,
        },
        None => {
            let end = authority.find(':').unwrap_or(authority.len());
            authority.split_at(end)
        }
    };
    let port_ok = after.is_empty()
        || after
            .strip_prefix(':')
            .is_some_and(|p| p.parse::<u16>().is_ok());
    !host.is_empty()
        && host
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-.:".contains(c))
        && port_ok
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cors_origins_must_be_origins_and_simulations_at_least_one() {
        let with_origin = |o: &str| {
            ServeArgs {
                cors_origins: vec![o.into()],
                ..ServeArgs::default()
            }
            .into_config()
        };
        for good in [
            "http://localhost:5173",
            "https://example.org",
            "http://127.0.0.1:8080",
            "http://[::1]:3000",
            "http://[::1]",
        ] {
            assert!(with_origin(good).is_ok(), "{good}");
        }
        for bad in [
            "notaurl",
            "*",
            "http://",
            "ftp://example.org",
            "https://example.org/",
            "https://example.org/app",
            "http://localhost:99999",
            "http://exa mple.org",
            "http://a:b:c",
            "http://[::1",
        ] {
            assert!(
                matches!(with_origin(bad), Err(ConfigError::BadOrigin(_))),
                "{bad}"
            );
        }
        // No workers: only where other processes can run the jobs (PostgreSQL).
        let a = ServeArgs {
            max_simulations: 0,
            ..ServeArgs::default()
        };
        let e = a.into_config().unwrap_err().to_string();
        assert!(
            e.contains("--max-simulations") && e.contains("icms worker"),
            "{e}"
        );
        let a = ServeArgs {
            max_simulations: 0,
            store: StoreArgs {
                at: DataArgs {
                    database_url: Some("postgres://icms@localhost/icms".into()),
                    ..DataArgs::in_dir("icms-data".into())
                },
                ..StoreArgs::default()
            },
            ..ServeArgs::default()
        };
        assert_eq!(a.into_config().unwrap().workers.count, 0);
    }

    #[test]
    fn every_numeric_option_is_range_checked_without_panicking() {
        let bad_seconds = [0.0, -1.0, 1e30, f64::INFINITY, f64::NAN, 86_401.0];
        type Set = fn(&mut ServeArgs, f64);
        let timeouts: [(&str, Set); 5] = [
            ("--request-timeout", |a, v| a.request_timeout = v),
            ("--job-timeout", |a, v| a.job_timeout = v),
            ("--queue-wait", |a, v| a.queue_wait = v),
            ("--header-timeout", |a, v| a.header_timeout = v),
            ("--keep-alive-timeout", |a, v| a.keep_alive_timeout = v),
        ];
        for (name, set) in timeouts {
            for v in bad_seconds {
                let mut a = ServeArgs::default();
                set(&mut a, v);
                let e = a.into_config().unwrap_err().to_string();
                assert!(e.contains(name) && e.contains("seconds"), "{name} {v}: {e}");
            }
            let mut a = ServeArgs::default();
            set(&mut a, 86_400.0);
            assert!(a.into_config().is_ok(), "{name} of a day");
        }
        type SetN = fn(&mut ServeArgs, usize);
        let counts: [(&str, SetN, usize); 10] = [
            ("--max-queued-jobs", |a, v| a.max_queued_jobs = v, 0),
            (
                "--max-queued-jobs",
                |a, v| a.max_queued_jobs = v,
                usize::MAX,
            ),
            ("--max-body", |a, v| a.max_body = v, 0),
            ("--max-upload", |a, v| a.max_upload = v, 0),
            ("--max-upload", |a, v| a.max_upload = v, usize::MAX),
            ("--max-body", |a, v| a.max_body = v, usize::MAX),
            ("--max-simulations", |a, v| a.max_simulations = v, 100_000),
            ("--max-ingests", |a, v| a.max_ingests = v, 0),
            ("--cache-mib", |a, v| a.cache_mib = v, usize::MAX),
            ("--max-connections", |a, v| a.max_connections = Some(v), 0),
        ];
        for (name, set, v) in counts {
            let mut a = ServeArgs::default();
            set(&mut a, v);
            let e = a.into_config().unwrap_err().to_string();
            assert!(e.contains(name), "{name} {v}: {e}");
        }
        for v in [0, u64::MAX] {
            let a = ServeArgs {
                store: StoreArgs {
                    blob_cache_mib: v,
                    ..StoreArgs::default()
                },
                ..ServeArgs::default()
            };
            let e = a.into_config().unwrap_err().to_string();
            assert!(e.contains("--blob-cache-mib"), "{v}: {e}");
        }
    }

    #[test]
    fn the_job_wait_may_be_zero_and_stays_within_the_request_time_limit() {
        for bad in [-1.0, f64::NAN, f64::INFINITY, 86_401.0] {
            let a = ServeArgs {
                job_wait: bad,
                ..ServeArgs::default()
            };
            let e = a.into_config().unwrap_err().to_string();
            assert!(e.contains("--job-wait"), "{bad}: {e}");
        }
        let wait = |job_wait, request_timeout| {
            ServeArgs {
                job_wait,
                request_timeout,
                ..ServeArgs::default()
            }
            .into_config()
            .unwrap()
            .state
            .job_wait
        };
        assert_eq!(wait(0.0, 120.0), Duration::ZERO);
        assert_eq!(wait(30.0, 120.0), Duration::from_secs(30));
        // A wait the request's time limit would cut short is shortened, so the client gets
        // its 202 rather than a 503.
        assert_eq!(wait(30.0, 10.0), Duration::from_secs(8));
    }

    #[test]
    fn serving_beyond_loopback_needs_a_token() {
        let open = ServeArgs {
            addr: "0.0.0.0:8080".parse().unwrap(),
            ..ServeArgs::default()
        };
        assert!(matches!(
            open.clone().into_config(),
            Err(ConfigError::OpenNonLoopback(_))
        ));
        let with_token = ServeArgs {
            token: Some("s3cret".into()),
            ..open
        };
        assert!(with_token.into_config().is_ok());
        assert!(
            ServeArgs::default().into_config().is_ok(),
            "loopback is fine"
        );
    }

    #[test]
    fn a_listen_address_may_name_its_host() {
        let local = listen_address("localhost:8080").unwrap();
        assert!(local.ip().is_loopback() && local.port() == 8080, "{local}");
        assert_eq!(
            listen_address("[::1]:9").unwrap(),
            "[::1]:9".parse().unwrap()
        );
        for bad in ["localhost", "8080", "localhost:port", ""] {
            let e = listen_address(bad).unwrap_err();
            assert!(e.contains("expected host:port"), "{bad}: {e}");
        }
    }

    #[test]
    fn an_empty_token_is_refused() {
        let a = ServeArgs {
            token: Some("  ".into()),
            ..ServeArgs::default()
        };
        assert!(matches!(a.into_config(), Err(ConfigError::EmptyToken)));
    }
}
