//! Opening a store: the data directory made and its writer lock taken, the catalog opened
//! on SQLite or connected to on PostgreSQL (its follower started), the blobs' bucket connected
//! to, and the in-memory indexes loaded.

use std::path::Path;
use std::sync::Arc;

use super::catalog::{Catalog, IndexedSkill};
use super::knn::FeatureIndex;
use super::{
    blob, postgres, remote, sqlite, stored_template, Blobs, Database, Durability, Inner, Store,
    StoreError, BUCKET_CONNECT_TIMEOUT, PG_CONNECT_TIMEOUT,
};
use crate::assist::index::RecognitionIndex;

/// The file in the data directory whose lock says a process writes it (`flock`, released by
/// the kernel when the process ends, however it ends). It holds the writer's pid and command
/// line, for the message another process gets.
pub const WRITER_LOCK_FILE: &str = "icms.lock";

/// Takes the data directory's writer lock, or says who holds it.
fn lock_for_writing(data_dir: &Path) -> Result<std::fs::File, StoreError> {
    use std::io::{Read, Seek, Write};
    let path = data_dir.join(WRITER_LOCK_FILE);
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(|e| StoreError::io(&path, e))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut holder = String::new();
            let _ = Read::by_ref(&mut file)
                .take(512)
                .read_to_string(&mut holder);
            let holder = holder.trim();
            return Err(StoreError::InUse {
                dir: data_dir.to_path_buf(),
                holder: if holder.is_empty() {
                    "it did not say which".to_owned()
                } else {
                    holder.to_owned()
                },
            });
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(StoreError::io(&path, e)),
    }
    let command: Vec<String> = std::env::args().collect();
    let mut me = format!("pid {}: {}", std::process::id(), command.join(" "));
    if let Some((end, _)) = me.char_indices().nth(400) {
        me.truncate(end);
    }
    // Who holds it is only a courtesy to the next one: the lock itself is what counts.
    let _ = file
        .set_len(0)
        .and_then(|()| file.rewind())
        .and_then(|()| file.write_all(me.as_bytes()));
    Ok(file)
}

impl Store {
    /// Opens (creating and migrating if needed) the store in `data_dir`.
    ///
    /// Refuses a database that is not ours ([`StoreError::NotOurs`]) or that a newer binary
    /// migrated ([`StoreError::SchemaTooNew`]) before touching it. Settings: WAL journal,
    /// `foreign_keys=ON`, busy timeout 5 s, `synchronous=FULL` (a commit is on disk before it returns: an
    /// acknowledged write survives a power cut; the cost is in BENCHMARKS.md). Loads the feature
    /// index.
    ///
    /// Takes the data directory's writer lock ([`WRITER_LOCK_FILE`]): while this store is
    /// open, another process's open to write fails with [`StoreError::InUse`] naming it (two
    /// `icms serve` on one directory would each answer from caches the other's writes leave
    /// stale). Stores opened to read ([`Store::open_existing`]) take no lock.
    pub async fn open(data_dir: &Path) -> Result<Store, StoreError> {
        Self::open_with(data_dir, true, Durability::Full, true).await
    }

    /// [`Store::open`] with another [`Durability`]: `icms bench ingest` measures what
    /// `synchronous=FULL` costs against `NORMAL` with it.
    pub async fn open_with_durability(
        data_dir: &Path,
        durability: Durability,
    ) -> Result<Store, StoreError> {
        Self::open_with(data_dir, true, durability, true).await
    }

    /// Opens the store in `data_dir` like [`Store::open`], but only if a data base is already
    /// there: without one (no database file, or an empty file) it fails with
    /// [`StoreError::NoDataBase`] and creates nothing, neither the directory nor a file. For
    /// commands that only read (`icms skills`, `icms hands --data`): a mistyped directory must
    /// not leave an empty data base behind and answer as if it held no skills. An existing data
    /// base of an older schema is still migrated. It takes no writer lock, so it reads beside
    /// a running `icms serve`.
    pub async fn open_existing(data_dir: &Path) -> Result<Store, StoreError> {
        Self::open_with(data_dir, false, Durability::Full, false).await
    }

    /// [`Store::open_existing`] for a command that writes (`icms reprocess`, `icms replay
    /// --data`): it takes the writer lock as [`Store::open`] does.
    pub async fn open_existing_to_write(data_dir: &Path) -> Result<Store, StoreError> {
        Self::open_with(data_dir, false, Durability::Full, true).await
    }

    async fn open_with(
        data_dir: &Path,
        create: bool,
        durability: Durability,
        write: bool,
    ) -> Result<Store, StoreError> {
        Self::open_sqlite(data_dir, create, durability, write, None).await
    }

    async fn open_sqlite(
        data_dir: &Path,
        create: bool,
        durability: Durability,
        write: bool,
        remote: Option<remote::RemoteBlobs>,
    ) -> Result<Store, StoreError> {
        if create {
            Self::create_data_dir(data_dir).await?;
        }
        let db_path = sqlite::locate(data_dir, create).await?;
        let writer = if write {
            Some(Self::take_writer_lock(data_dir).await?)
        } else {
            None
        };
        let catalog = sqlite::SqliteCatalog::open(&db_path, create, durability).await?;
        Self::assemble(data_dir, Box::new(catalog), writer, remote).await
    }

    /// Opens the store of `data_dir` with its rows in `database`: [`Store::open`] for
    /// [`Database::Sqlite`]; for [`Database::Postgres`], the data directory (created if
    /// missing) holds the blobs and its writer lock is taken as [`Store::open`] takes it,
    /// and the data base is connected to (within [`PG_CONNECT_TIMEOUT`], else
    /// [`StoreError::Unreachable`] naming it) and migrated.
    ///
    /// A PostgreSQL store follows the writes made through every other server on the same
    /// data base (`LISTEN/NOTIFY`): its k-nearest and recognition indexes take them in as
    /// their notifications arrive, and [`Store::skill_changes`] tells whoever caches skills.
    /// A lost listening connection is made again and both indexes reloaded, so staleness is
    /// bounded by how long the data base is out of reach, plus one reload (details in
    /// `postgres/follow.rs` and docs/backends.md).
    pub async fn open_in(data_dir: &Path, database: &Database) -> Result<Store, StoreError> {
        Self::open_on(data_dir, database, &Blobs::Local).await
    }

    /// [`Store::open_in`] with the blobs in `blobs`: for [`Blobs::S3`], the bucket is
    /// connected to first (configured from the environment, see [`Blobs`]) and must answer a
    /// listing within [`BUCKET_CONNECT_TIMEOUT`], else [`StoreError::ObjectStore`] naming it;
    /// the data directory then keeps copies of the blobs this process writes or reads.
    pub async fn open_on(
        data_dir: &Path,
        database: &Database,
        blobs: &Blobs,
    ) -> Result<Store, StoreError> {
        let remote = match blobs {
            Blobs::Local => None,
            Blobs::S3(bucket) => {
                Some(remote::RemoteBlobs::connect(bucket, BUCKET_CONNECT_TIMEOUT).await?)
            }
        };
        let url = match database {
            Database::Sqlite => {
                return Self::open_sqlite(data_dir, true, Durability::Full, true, remote).await
            }
            Database::Postgres(url) => url,
        };
        Self::create_data_dir(data_dir).await?;
        let writer = Self::take_writer_lock(data_dir).await?;
        let catalog = postgres::PgCatalog::connect(url, PG_CONNECT_TIMEOUT).await?;
        // Listening before the indexes load: no write committed after the load is missed.
        let listener = postgres::follow::Listener::connect(&catalog, url).await?;
        let store = Self::assemble(data_dir, Box::new(catalog), Some(writer), remote).await?;
        listener.follow(&store);
        Ok(store)
    }

    /// Creates the data directory if missing, refusing a file in its place.
    async fn create_data_dir(data_dir: &Path) -> Result<(), StoreError> {
        // create_dir_all on a file says only "File exists".
        if tokio::fs::metadata(data_dir)
            .await
            .is_ok_and(|m| !m.is_dir())
        {
            return Err(StoreError::io(
                data_dir,
                std::io::Error::new(
                    std::io::ErrorKind::NotADirectory,
                    "it is a file, not a directory (the data directory holds the data base \
                     and the session files)",
                ),
            ));
        }
        tokio::fs::create_dir_all(data_dir)
            .await
            .map_err(|e| StoreError::io(data_dir, e))
    }

    async fn take_writer_lock(data_dir: &Path) -> Result<std::fs::File, StoreError> {
        let dir = data_dir.to_path_buf();
        tokio::task::spawn_blocking(move || lock_for_writing(&dir))
            .await
            .map_err(|e| StoreError::io(data_dir, std::io::Error::other(e)))?
    }

    /// The store around an opened catalog: leftover temporary blobs removed, the in-memory
    /// indexes loaded.
    async fn assemble(
        data_dir: &Path,
        catalog: Box<dyn Catalog>,
        writer: Option<std::fs::File>,
        remote: Option<remote::RemoteBlobs>,
    ) -> Result<Store, StoreError> {
        let dir = data_dir.to_path_buf();
        let swept = tokio::task::spawn_blocking(move || blob::sweep_temp_files(&dir))
            .await
            .unwrap_or(0);
        if swept > 0 {
            tracing::info!(
                swept,
                "removed temporary blob files left by interrupted ingests"
            );
        }

        let skills = catalog.indexed_skills().await?;
        let mut entries = Vec::with_capacity(skills.len());
        let mut templates = Vec::with_capacity(skills.len());
        for s in skills {
            let IndexedSkill {
                id,
                feature,
                object_shape,
                grasp_type,
                object_name,
                approach,
            } = s;
            entries.push((id, feature));
            templates.push(stored_template(
                id,
                &object_shape,
                &grasp_type,
                object_name,
                approach,
                feature,
            ));
        }
        Ok(Store {
            inner: Arc::new(Inner {
                dir: data_dir.to_path_buf(),
                catalog,
                remote,
                index: std::sync::RwLock::new(FeatureIndex::from_entries(entries)),
                recognition: std::sync::RwLock::new(Arc::new(RecognitionIndex::new(templates))),
                blob_lock: tokio::sync::RwLock::new(()),
                writer: std::sync::Mutex::new(writer),
                follow: postgres::follow::Follow::new(),
            }),
        })
    }
}
