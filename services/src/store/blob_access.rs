//! Where the store's blobs are, behind its rows: the cross-server blob lock ingests and
//! sweeps take (with a bucket and PostgreSQL), uploading a new blob to the bucket, the data
//! directory's copy of a blob (downloaded when missing), and removing a blob.

use std::path::PathBuf;

use super::catalog::ExclusiveBlobGuard;
use super::{blob, CrossServerBlobHold, Store, StoreError};

impl Store {
    /// The cross-server blob lock, shared: held by an ingest from its blob upload to its
    /// row's commit, so that no other server's sweep or delete removes the object meanwhile.
    /// Needed only with a bucket (the data directory is one process's) and a catalog that
    /// several servers share (PostgreSQL); empty otherwise. Waits only while another server
    /// holds it exclusively, which it does briefly and never waiting itself.
    pub(crate) async fn shared_blob_hold(&self) -> Result<CrossServerBlobHold, StoreError> {
        if self.inner.remote.is_none() {
            return Ok(CrossServerBlobHold(None));
        }
        Ok(CrossServerBlobHold(
            self.inner.catalog.shared_blob_guard().await?,
        ))
    }

    /// Test hook: takes [`Store::shared_blob_hold`] as an ingest does, for a test to hold it
    /// across another store's sweep.
    #[doc(hidden)]
    pub async fn hold_shared_blob_lock(&self) -> Result<CrossServerBlobHold, StoreError> {
        self.shared_blob_hold().await
    }

    /// The cross-server blob lock, exclusive, if no other server holds it (see
    /// [`Store::shared_blob_hold`]); [`ExclusiveBlobGuard::NotNeeded`] without a bucket or
    /// with SQLite. Never waits.
    pub(crate) async fn try_exclusive_blob_hold(&self) -> Result<ExclusiveBlobGuard, StoreError> {
        if self.inner.remote.is_none() {
            return Ok(ExclusiveBlobGuard::NotNeeded);
        }
        self.inner.catalog.try_exclusive_blob_guard().await
    }

    /// Uploads the blob at `rel`, just written to the data directory, to the store's bucket
    /// (if it has one), before any row names it.
    pub(super) async fn publish(&self, rel: &str) -> Result<(), StoreError> {
        match &self.inner.remote {
            Some(remote) => remote.upload(&self.inner.dir.join(rel), rel).await,
            None => Ok(()),
        }
    }

    /// The path of the blob at `rel` in the data directory; with a bucket, a missing copy is
    /// downloaded first (checked against the hash its path names).
    pub(crate) async fn local_blob(&self, rel: &str) -> Result<PathBuf, StoreError> {
        let path = self.inner.dir.join(rel);
        let Some(remote) = &self.inner.remote else {
            return Ok(path);
        };
        if tokio::fs::metadata(&path).await.is_ok_and(|m| m.is_file()) {
            // Used now: trimming the copies keeps it a while (Store::trim_blob_copies).
            let touched = path.clone();
            let _ = tokio::task::spawn_blocking(move || blob::touch(&touched)).await;
            return Ok(path);
        }
        let sha256 = blob::sha256_of(rel)
            .ok_or_else(|| StoreError::Corrupt(format!("{rel:?} is not a blob path")))?;
        remote.download(rel, &sha256, &path).await?;
        Ok(path)
    }

    /// Removes the blob at `rel`: its file, and its object if the store has a bucket. Call
    /// once no row names it.
    pub(crate) async fn remove_blob(&self, rel: &str) -> Result<(), StoreError> {
        let dir = self.inner.dir.clone();
        let owned = rel.to_owned();
        tokio::task::spawn_blocking(move || blob::remove(&dir, &owned))
            .await
            .map_err(|e| StoreError::Corrupt(format!("blob removal task failed: {e}")))??;
        match &self.inner.remote {
            Some(remote) => remote.delete(rel).await,
            None => Ok(()),
        }
    }
}
