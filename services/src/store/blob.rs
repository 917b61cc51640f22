//! Content-addressed MCAP blobs: `blobs/sha256/ab/cdef….mcap` under the data directory, written
//! atomically (temporary file in the same directory, write, fsync, rename, fsync directory).

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use sha2::{Digest, Sha256};

use super::error::StoreError;

/// Hex SHA-256 of `bytes`.
pub(crate) fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

/// Path of a blob relative to the data directory, with `/` separators.
pub(crate) fn relative_path(sha256: &str) -> String {
    format!("blobs/sha256/{}/{}.mcap", &sha256[..2], &sha256[2..])
}

fn sync_dir(dir: &Path) -> Result<(), StoreError> {
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(|e| StoreError::io(dir, e))
}

/// Writes `bytes` as the blob named by `sha256` under `data_dir`, unless a complete one is
/// already there (a leftover of an ingest killed before its row committed, or a concurrent
/// ingest of the same file). Returns the relative path. Blocking: call on a blocking thread.
pub(crate) fn write_atomic(
    data_dir: &Path,
    sha256: &str,
    bytes: &[u8],
) -> Result<String, StoreError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let rel = relative_path(sha256);
    let path = data_dir.join(&rel);
    let dir = path.parent().expect("blob path has a parent").to_path_buf();
    if let Ok(md) = fs::metadata(&path) {
        // Renamed only after its fsync, so a file with the right size is complete.
        if md.is_file() && md.len() == bytes.len() as u64 {
            return Ok(rel);
        }
    }
    if !dir.is_dir() {
        fs::create_dir_all(&dir).map_err(|e| StoreError::io(&dir, e))?;
        // Make the new shard directory's entry durable too.
        if let Some(parent) = dir.parent() {
            sync_dir(parent)?;
        }
    }
    let tmp: PathBuf = dir.join(format!(
        ".{}.{}.{}.tmp",
        &sha256[2..],
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut f = File::create(&tmp).map_err(|e| StoreError::io(&tmp, e))?;
        f.write_all(bytes).map_err(|e| StoreError::io(&tmp, e))?;
        f.sync_all().map_err(|e| StoreError::io(&tmp, e))?;
        drop(f);
        fs::rename(&tmp, &path).map_err(|e| StoreError::io(&path, e))?;
        sync_dir(&dir)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result.map(|()| rel)
}

/// Removes a blob (after its row is gone); a missing file is not an error.
pub(crate) fn remove(data_dir: &Path, rel: &str) -> Result<(), StoreError> {
    let path = data_dir.join(rel);
    match fs::remove_file(&path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(StoreError::io(path, e)),
    }
}
