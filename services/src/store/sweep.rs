//! Keeping the blob files bounded: trimming the data directory's copies of a bucket's blobs
//! to a size, least recently used first, and sweeping the blobs no row references.

use std::path::Path;
use std::time::Duration;

use super::catalog::ExclusiveBlobGuard;
use super::{blob, Store, StoreError};

/// What [`Store::trim_blob_copies`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct TrimReport {
    /// Copies found.
    pub copies: usize,
    /// Their bytes, before.
    pub bytes: u64,
    /// Copies removed.
    pub removed: usize,
    /// Their bytes.
    pub removed_bytes: u64,
}

/// [`Store::trim_blob_copies`]'s work, blocking.
fn trim_copies(dir: &Path, max_bytes: u64, min_age: Duration) -> TrimReport {
    let mut files = blob::blob_files(dir);
    let mut report = TrimReport {
        copies: files.len(),
        bytes: files.iter().map(|(f, _)| f.bytes).sum(),
        ..TrimReport::default()
    };
    let mut left = report.bytes;
    // Least recently used first.
    files.sort_by_key(|(_, modified)| *modified);
    for (f, _) in files {
        if left <= max_bytes {
            break;
        }
        let path = dir.join(&f.rel);
        // Read again: a copy used since the listing is young again.
        let old = std::fs::metadata(&path)
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age >= min_age);
        if !old {
            continue;
        }
        if blob::remove(dir, &f.rel).is_ok() {
            report.removed += 1;
            report.removed_bytes += f.bytes;
            left -= f.bytes;
        }
    }
    report
}

/// What [`Store::sweep_orphan_blobs`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct SweepReport {
    /// Blob files old enough to be looked at.
    pub examined: usize,
    /// Unreferenced ones removed.
    pub removed: usize,
    /// Their bytes.
    pub removed_bytes: u64,
    /// Nothing was removed because another server on the same data base and bucket was
    /// ingesting (it held the cross-server blob lock shared): the next sweep tries again.
    pub skipped_busy: bool,
}

impl Store {
    /// Bounds the data directory's copies of a bucket's blobs to `max_bytes`: while they hold
    /// more, removes the least recently used copy (by its modification time, which writing,
    /// downloading and each read through [`Store::local_blob`] set) that was last used at least
    /// `min_age` ago. The objects stay in the bucket; a removed copy is downloaded again when
    /// next read. Without a bucket the files are the blobs themselves: nothing is removed.
    ///
    /// It holds the blob lock that ingests hold from their copy's write to their commit, so no
    /// copy an ingest is uploading goes; a copy just downloaded or read is younger than
    /// `min_age` (the server uses [`ORPHAN_BLOB_MIN_AGE`]) and stays, and each candidate's
    /// time is read again just before its removal, so one read since the listing stays too.
    ///
    /// [`ORPHAN_BLOB_MIN_AGE`]: super::ORPHAN_BLOB_MIN_AGE
    pub async fn trim_blob_copies(
        &self,
        max_bytes: u64,
        min_age: Duration,
    ) -> Result<TrimReport, StoreError> {
        if self.inner.remote.is_none() {
            return Ok(TrimReport::default());
        }
        // No ingest of this process is between its copy's write and its upload and commit
        // (they hold the lock shared), so no copy is removed from under an upload.
        let _no_ingest = self.inner.blob_lock.write().await;
        let dir = self.inner.dir.clone();
        tokio::task::spawn_blocking(move || trim_copies(&dir, max_bytes, min_age))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob copy trimming task failed: {e}")))
    }

    /// Removes blob files that no session or replay references (a blob written by an ingest
    /// whose transaction then failed, a kill between a delete's commit and its file removal)
    /// and that were last modified at least `min_age` ago; with a bucket, its objects too.
    ///
    /// Safe beside ingests in this process: the files are listed first, then, holding the
    /// blob lock every ingest holds from its blob write to its commit, the referenced paths are
    /// read and only listed files that no row names are removed; a blob an ingest is about to
    /// reference is either not listed yet or already committed. `min_age` guards ingests of
    /// another process on the same directory (`icms ingest --data` beside a server), which
    /// commit within seconds of their blob write: the server sweeps with
    /// [`ORPHAN_BLOB_MIN_AGE`].
    ///
    /// With a bucket shared by several servers on one PostgreSQL data base, another server's
    /// ingest is not under this lock but under its cross-server counterpart, an advisory lock
    /// of the data base ([`BLOB_LOCK_CLASS`]): every ingest holds it shared from its blob
    /// upload to its row's commit, and the sweep, holding the in-process lock, tries it
    /// exclusively before reading the referenced paths and keeps it until its last removal.
    /// While another server is ingesting the sweep does not wait: it removes nothing this
    /// round, logs it and says so ([`SweepReport::skipped_busy`]). So no removal runs while
    /// any server is between an upload and its commit, and a blob committed before the lock
    /// was taken is among the referenced paths: the window the former look-up-then-remove
    /// check left (another server uploading the same bytes again and committing between the
    /// two) is closed. Each candidate's object is still looked up again just before its
    /// removal, so an object written since the listing, or within `min_age`, is left alone
    /// (docs/backends.md).
    ///
    /// [`ORPHAN_BLOB_MIN_AGE`]: super::ORPHAN_BLOB_MIN_AGE
    /// [`BLOB_LOCK_CLASS`]: super::BLOB_LOCK_CLASS
    pub async fn sweep_orphan_blobs(&self, min_age: Duration) -> Result<SweepReport, StoreError> {
        let dir = self.inner.dir.clone();
        let mut listed = tokio::task::spawn_blocking(move || blob::blobs_older_than(&dir, min_age))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob listing task failed: {e}")))?;
        if let Some(remote) = &self.inner.remote {
            // A copy in the data directory and its object are one blob.
            let local: std::collections::HashSet<String> =
                listed.iter().map(|b| b.rel.clone()).collect();
            let objects = remote.blobs_older_than(min_age).await?;
            listed.extend(objects.into_iter().filter(|b| !local.contains(&b.rel)));
        }
        let mut report = SweepReport {
            examined: listed.len(),
            ..SweepReport::default()
        };
        if listed.is_empty() {
            return Ok(report);
        }
        let _guard = self.inner.blob_lock.write().await;
        let exclusive = match self.try_exclusive_blob_hold().await? {
            ExclusiveBlobGuard::Busy => {
                tracing::info!(
                    examined = report.examined,
                    "another server is ingesting into the bucket: unreferenced blobs are left \
                     for the next sweep"
                );
                report.skipped_busy = true;
                return Ok(report);
            }
            ExclusiveBlobGuard::Held(g) => Some(g),
            ExclusiveBlobGuard::NotNeeded => None,
        };
        let done = self.remove_orphans(listed, min_age, &mut report).await;
        if let Some(g) = exclusive {
            g.release().await;
        }
        done.map(|()| report)
    }

    /// The sweep's removals of the `listed` blobs that no row names, under the blob locks.
    async fn remove_orphans(
        &self,
        listed: Vec<blob::BlobFile>,
        min_age: Duration,
        report: &mut SweepReport,
    ) -> Result<(), StoreError> {
        let referenced = self.inner.catalog.referenced_blob_paths().await?;
        for orphan in listed.into_iter().filter(|b| !referenced.contains(&b.rel)) {
            if let Some(remote) = &self.inner.remote {
                let young = remote
                    .modified(&orphan.rel)
                    .await?
                    .is_some_and(|t| t.elapsed().map_or(true, |age| age < min_age));
                if young {
                    continue;
                }
            }
            match self.remove_blob(&orphan.rel).await {
                Ok(()) => {
                    report.removed += 1;
                    report.removed_bytes += orphan.bytes;
                }
                Err(e) => {
                    tracing::warn!(error = %e, blob = %orphan.rel, "could not remove an orphan blob")
                }
            }
        }
        Ok(())
    }
}
