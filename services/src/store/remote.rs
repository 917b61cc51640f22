//! Blobs in an S3-compatible bucket (`icms serve --blobs s3://bucket/prefix`), through the
//! `object_store` crate.
//!
//! The bucket is the truth; the data directory keeps a local copy of each blob this process
//! wrote or read (content-addressed, so a copy is never stale), at the same relative path as
//! the object's key under the prefix: `PREFIX/blobs/sha256/ab/cdef….mcap`. A blob is written
//! to the data directory first (hashed on the way, as without a bucket), then uploaded; its
//! row commits only after the upload did, and an upload is atomic (a single PUT, or a
//! multipart upload that appears whole when completed), so no row ever names a half-stored
//! object. A download is written beside its final path, checked against the SHA-256 its row
//! records, and renamed into place.
//!
//! Endpoint, region and credentials come from the usual variables (`AWS_ENDPOINT_URL`,
//! `AWS_REGION`, `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`, …), as the
//! AWS tools read them; an `http://` endpoint (a local S3 server) is allowed as given.

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use futures_util::StreamExt;
use object_store::aws::AmazonS3Builder;
use object_store::path::Path as ObjectPath;
use object_store::{ClientOptions, ObjectStore, ObjectStoreExt, PutPayload, RetryConfig};
use sha2::{Digest, Sha256};
use tokio::io::AsyncWriteExt;

use super::blob::BlobFile;
use super::error::StoreError;

/// How long start-up waits for the bucket to answer before it is reported unreachable.
pub const BUCKET_CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// Blobs up to this size go up in one PUT; larger ones in parts of this size.
const PART_BYTES: usize = 16 << 20;

/// Parts of one multipart upload in flight at once (so an upload holds at most this many
/// parts in memory).
const PARTS_IN_FLIGHT: usize = 2;

/// Where a store keeps its blobs.
#[derive(Clone, Default, PartialEq, Eq)]
pub enum Blobs {
    /// Files in the data directory: the default.
    #[default]
    Local,
    /// Objects in an S3-compatible bucket.
    S3(S3Bucket),
}

/// An S3-compatible bucket and the key prefix the blobs go under.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct S3Bucket {
    /// The bucket's name.
    pub bucket: String,
    /// The key prefix (no leading or trailing `/`; empty for the bucket's root).
    pub prefix: String,
    /// The endpoint URL; `None`: `AWS_ENDPOINT_URL` (or `AWS_ENDPOINT`), else AWS's.
    pub endpoint: Option<String>,
    /// Access key id and secret; `None`: from the environment (`AWS_ACCESS_KEY_ID`, ... and
    /// the rest of the AWS credential chain).
    pub credentials: Option<(String, String)>,
}

impl S3Bucket {
    /// `s3://bucket/prefix`.
    pub fn url(&self) -> String {
        if self.prefix.is_empty() {
            format!("s3://{}", self.bucket)
        } else {
            format!("s3://{}/{}", self.bucket, self.prefix)
        }
    }
}

impl Blobs {
    /// The location a `--blobs` argument names: none or an empty one is the data directory,
    /// `s3://bucket[/prefix]` a bucket; anything else is refused naming what is accepted.
    pub fn from_arg(arg: Option<&str>) -> Result<Blobs, StoreError> {
        let refuse = |why: &str| {
            Err(StoreError::InvalidInput(format!(
                "--blobs {:?} {why}: expected s3://BUCKET or s3://BUCKET/PREFIX (endpoint and \
                 credentials from AWS_ENDPOINT_URL, AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY, \
                 AWS_REGION); without --blobs the blobs are files in the data directory",
                arg.unwrap_or_default()
            )))
        };
        let Some(arg) = arg.map(str::trim).filter(|a| !a.is_empty()) else {
            return Ok(Blobs::Local);
        };
        let Some(rest) = arg.strip_prefix("s3://") else {
            return refuse("is not an s3:// URL");
        };
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        // S3's bucket naming rules (3-63 of a-z, 0-9, '.', '-', starting and ending with a
        // letter or digit).
        let bucket_ok = (3..=63).contains(&bucket.len())
            && bucket
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'.' || b == b'-')
            && bucket.starts_with(|c: char| c.is_ascii_alphanumeric())
            && bucket.ends_with(|c: char| c.is_ascii_alphanumeric());
        if !bucket_ok {
            return refuse(
                "does not name a valid bucket (3-63 lower-case letters, digits, '.' or '-')",
            );
        }
        let prefix = prefix.trim_matches('/');
        if prefix.split('/').any(|p| p == "." || p == "..")
            || prefix.contains("//")
            || prefix.chars().any(|c| c.is_control())
        {
            return refuse("has a prefix with empty, '.' or '..' parts or control characters");
        }
        Ok(Blobs::S3(S3Bucket {
            bucket: bucket.to_owned(),
            prefix: prefix.to_owned(),
            ..S3Bucket::default()
        }))
    }

    /// What logs and messages show of it.
    pub fn describe(&self) -> String {
        match self {
            Blobs::Local => "files in the data directory".to_owned(),
            Blobs::S3(b) => b.url(),
        }
    }
}

impl std::fmt::Debug for Blobs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

/// A bucket the store's blobs live in.
pub(crate) struct RemoteBlobs {
    store: Arc<dyn ObjectStore>,
    prefix: String,
    /// `s3://bucket/prefix at ENDPOINT`, for messages.
    name: String,
}

impl std::fmt::Debug for RemoteBlobs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name)
    }
}

impl RemoteBlobs {
    /// Connects to `bucket` (what it leaves unset from the environment) and checks, within
    /// `timeout`, that it answers a listing of the prefix: a missing bucket, wrong credentials
    /// or an endpoint that does not answer are [`StoreError::ObjectStore`] naming it.
    pub(crate) async fn connect(
        bucket: &S3Bucket,
        timeout: Duration,
    ) -> Result<RemoteBlobs, StoreError> {
        let mut builder = AmazonS3Builder::from_env().with_bucket_name(&bucket.bucket);
        if let Some(endpoint) = &bucket.endpoint {
            builder = builder.with_endpoint(endpoint);
        }
        if let Some((id, secret)) = &bucket.credentials {
            builder = builder
                .with_access_key_id(id)
                .with_secret_access_key(secret);
        }
        let endpoint = builder
            .get_config_value(&object_store::aws::AmazonS3ConfigKey::Endpoint)
            .unwrap_or_else(|| "AWS's S3".to_owned());
        // A local S3 server (s3s-fs, MinIO) without TLS, as the user named it.
        let allow_http = endpoint.starts_with("http://");
        let name = format!("{} at {endpoint}", bucket.url());
        let unreachable = |reason: String| StoreError::ObjectStore {
            bucket: name.clone(),
            reason,
        };
        let store = builder
            .with_client_options(
                ClientOptions::new()
                    .with_allow_http(allow_http)
                    .with_connect_timeout(Duration::from_secs(5))
                    .with_timeout(Duration::from_secs(120)),
            )
            .with_retry(RetryConfig {
                max_retries: 3,
                retry_timeout: Duration::from_secs(30),
                ..RetryConfig::default()
            })
            .build()
            .map_err(|e| unreachable(e.to_string()))?;
        let remote = RemoteBlobs {
            store: Arc::new(store),
            prefix: bucket.prefix.clone(),
            name: name.clone(),
        };
        let root = remote.key("blobs");
        let probe = remote.store.list_with_delimiter(Some(&root));
        match tokio::time::timeout(timeout, probe).await {
            Ok(Ok(_)) => Ok(remote),
            Ok(Err(e)) => Err(unreachable(e.to_string())),
            Err(_) => Err(unreachable(format!(
                "no answer within {} s",
                timeout.as_secs()
            ))),
        }
    }

    /// The object key of a blob's relative path.
    fn key(&self, rel: &str) -> ObjectPath {
        if self.prefix.is_empty() {
            ObjectPath::from(rel)
        } else {
            ObjectPath::from(format!("{}/{rel}", self.prefix))
        }
    }

    fn error(&self, what: &str, e: impl std::fmt::Display) -> StoreError {
        StoreError::ObjectStore {
            bucket: self.name.clone(),
            reason: format!("{what}: {e}"),
        }
    }

    /// Uploads the local file `path` as the blob at `rel`, whether or not the object exists
    /// already: a new upload also renews the object's modification time, which keeps the
    /// orphan sweep of another server (it removes only objects unreferenced *and* older than
    /// its minimum age) off a blob this ingest is about to reference again.
    pub(crate) async fn upload(&self, path: &Path, rel: &str) -> Result<(), StoreError> {
        let key = self.key(rel);
        let mut file = tokio::fs::File::open(path)
            .await
            .map_err(|e| StoreError::io(path, e))?;
        let len = file
            .metadata()
            .await
            .map_err(|e| StoreError::io(path, e))?
            .len();
        if len <= PART_BYTES as u64 {
            let mut bytes = Vec::with_capacity(len as usize);
            tokio::io::AsyncReadExt::read_to_end(&mut file, &mut bytes)
                .await
                .map_err(|e| StoreError::io(path, e))?;
            self.store
                .put(&key, PutPayload::from(bytes))
                .await
                .map_err(|e| self.error(&format!("uploading {rel}"), e))?;
            return Ok(());
        }
        let upload = self
            .store
            .put_multipart(&key)
            .await
            .map_err(|e| self.error(&format!("starting the upload of {rel}"), e))?;
        let mut writer = object_store::WriteMultipart::new_with_chunk_size(upload, PART_BYTES);
        let mut buf = vec![0u8; 1 << 20];
        loop {
            let n = match tokio::io::AsyncReadExt::read(&mut file, &mut buf).await {
                Ok(n) => n,
                Err(e) => {
                    let _ = writer.abort().await;
                    return Err(StoreError::io(path, e));
                }
            };
            if n == 0 {
                break;
            }
            if let Err(e) = writer.wait_for_capacity(PARTS_IN_FLIGHT).await {
                let _ = writer.abort().await;
                return Err(self.error(&format!("uploading {rel}"), e));
            }
            writer.write(&buf[..n]);
        }
        writer
            .finish()
            .await
            .map_err(|e| self.error(&format!("completing the upload of {rel}"), e))?;
        Ok(())
    }

    /// Downloads the blob at `rel` to `dest`, checked against `sha256`: written beside `dest`,
    /// hashed on the way, fsynced, then renamed into place. A missing object or one whose bytes
    /// are not the recorded ones is an error, and nothing is left at `dest`.
    pub(crate) async fn download(
        &self,
        rel: &str,
        sha256: &str,
        dest: &Path,
    ) -> Result<(), StoreError> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let dir = dest.parent().ok_or_else(|| {
            StoreError::Corrupt(format!("blob path {} has no directory", dest.display()))
        })?;
        tokio::fs::create_dir_all(dir)
            .await
            .map_err(|e| StoreError::io(dir, e))?;
        let tmp = dir.join(format!(
            ".download.{}.{}.tmp",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let result = self.download_to(rel, sha256, &tmp).await;
        let result = match result {
            Ok(()) => tokio::fs::rename(&tmp, dest)
                .await
                .map_err(|e| StoreError::io(dest, e)),
            Err(e) => Err(e),
        };
        if result.is_err() {
            let _ = tokio::fs::remove_file(&tmp).await;
        }
        result
    }

    async fn download_to(&self, rel: &str, sha256: &str, tmp: &Path) -> Result<(), StoreError> {
        let got = self
            .store
            .get(&self.key(rel))
            .await
            .map_err(|e| self.error(&format!("downloading {rel}"), e))?;
        let mut stream = got.into_stream();
        let mut file = tokio::fs::File::create(tmp)
            .await
            .map_err(|e| StoreError::io(tmp, e))?;
        let mut hasher = Sha256::new();
        while let Some(piece) = stream.next().await {
            let piece = piece.map_err(|e| self.error(&format!("downloading {rel}"), e))?;
            hasher.update(&piece);
            file.write_all(&piece)
                .await
                .map_err(|e| StoreError::io(tmp, e))?;
        }
        let found = hex::encode(hasher.finalize());
        if found != sha256 {
            return Err(StoreError::Corrupt(format!(
                "the object {rel} in {} has SHA-256 {found}, not the {sha256} its row records",
                self.name
            )));
        }
        file.sync_all().await.map_err(|e| StoreError::io(tmp, e))?;
        Ok(())
    }

    /// Removes the object at `rel` (one that is already gone is no error).
    pub(crate) async fn delete(&self, rel: &str) -> Result<(), StoreError> {
        match self.store.delete(&self.key(rel)).await {
            Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
            Err(e) => Err(self.error(&format!("removing {rel}"), e)),
        }
    }

    /// When the object at `rel` was last written, `None` if there is none.
    pub(crate) async fn modified(&self, rel: &str) -> Result<Option<SystemTime>, StoreError> {
        match self.store.head(&self.key(rel)).await {
            Ok(meta) => Ok(Some(meta.last_modified.into())),
            Err(object_store::Error::NotFound { .. }) => Ok(None),
            Err(e) => Err(self.error(&format!("looking up {rel}"), e)),
        }
    }

    /// The blobs in the bucket last written at least `min_age` ago (objects under the prefix
    /// whose keys are not blob paths are left out, and so never removed).
    pub(crate) async fn blobs_older_than(
        &self,
        min_age: Duration,
    ) -> Result<Vec<BlobFile>, StoreError> {
        let now = SystemTime::now();
        let root = self.key("blobs/sha256");
        let strip = if self.prefix.is_empty() {
            String::new()
        } else {
            format!("{}/", self.prefix)
        };
        let mut listing = self.store.list(Some(&root));
        let mut old = Vec::new();
        while let Some(meta) = listing.next().await {
            let meta = meta.map_err(|e| self.error("listing the blobs", e))?;
            let key = meta.location.as_ref();
            let Some(rel) = key.strip_prefix(&strip) else {
                continue;
            };
            if !super::blob::is_blob_path(rel) {
                continue;
            }
            let modified: SystemTime = meta.last_modified.into();
            if now.duration_since(modified).unwrap_or_default() >= min_age {
                old.push(BlobFile {
                    rel: rel.to_owned(),
                    bytes: meta.size,
                });
            }
        }
        Ok(old)
    }
}
