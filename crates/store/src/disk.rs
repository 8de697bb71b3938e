use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, ErrorKind, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use crate::blob::{check_hash, BlobStore, BlobWriter, Hash, Tally, CHUNK};
use crate::StoreError;

const TMP_DIR: &str = "tmp";

/// Blobs on local disk: `root/ab/abcdef…` (the first two hex digits fan out the directory),
/// uploads in progress under `root/tmp/`.
///
/// One process owns a root at a time: [`DiskBlobStore::open`] deletes whatever is in
/// `root/tmp/`, which would include another live process's uploads.
#[derive(Clone)]
pub struct DiskBlobStore {
    inner: Arc<Inner>,
}

struct Inner {
    root: PathBuf,
    tmp: PathBuf,
    max_blob_bytes: u64,
    next_tmp: AtomicU64,
    /// Skip the per-blob fsyncs; the owner calls [`BlobStore::sync`] before relying on
    /// durability (group commit: one file-system sync for many uploads).
    deferred_sync: bool,
}

impl DiskBlobStore {
    /// Opens (creating if needed) the store at `root`; blobs larger than `max_blob_bytes` are
    /// refused. Temp files left by a killed process are removed here, since nothing can ever
    /// finish them.
    pub fn open(root: &Path, max_blob_bytes: u64) -> Result<Self, StoreError> {
        Self::open_with(root, max_blob_bytes, false)
    }

    /// As [`open`](Self::open); with `deferred_sync` a finished blob is renamed into place
    /// without fsyncs, and durability comes from calling [`BlobStore::sync`] (which syncs the
    /// whole file system once) before acknowledging. After a process crash (kill -9) both
    /// modes keep every finished blob; they differ only on power loss before the sync.
    pub fn open_with(
        root: &Path,
        max_blob_bytes: u64,
        deferred_sync: bool,
    ) -> Result<Self, StoreError> {
        let tmp = root.join(TMP_DIR);
        fs::create_dir_all(&tmp).map_err(|e| StoreError::io(&tmp, e))?;
        let mut removed = 0usize;
        for entry in fs::read_dir(&tmp).map_err(|e| StoreError::io(&tmp, e))? {
            let entry = entry.map_err(|e| StoreError::io(&tmp, e))?;
            let path = entry.path();
            let res = if entry.file_type().map(|t| t.is_dir()).unwrap_or(false) {
                fs::remove_dir_all(&path)
            } else {
                fs::remove_file(&path)
            };
            match res {
                Ok(()) => removed += 1,
                Err(e) if e.kind() == ErrorKind::NotFound => {}
                Err(e) => return Err(StoreError::io(&path, e)),
            }
        }
        if removed > 0 {
            tracing::warn!(
                root = %root.display(),
                removed,
                "removed unfinished uploads left by an earlier run"
            );
        }
        Ok(DiskBlobStore {
            inner: Arc::new(Inner {
                root: root.to_path_buf(),
                tmp,
                max_blob_bytes,
                next_tmp: AtomicU64::new(0),
                deferred_sync,
            }),
        })
    }

    pub fn root(&self) -> &Path {
        &self.inner.root
    }

    pub fn max_blob_bytes(&self) -> u64 {
        self.inner.max_blob_bytes
    }

    /// Where the blob `hash` lives (whether or not it exists); errors on a malformed hash so
    /// no caller-supplied string can address a file outside the root.
    pub fn blob_path(&self, hash: &str) -> Result<PathBuf, StoreError> {
        check_hash(hash)?;
        Ok(self.inner.root.join(&hash[..2]).join(hash))
    }

    /// Files currently under `root/tmp/` (uploads in progress); for health checks and tests.
    pub fn temp_files(&self) -> Result<Vec<PathBuf>, StoreError> {
        let tmp = &self.inner.tmp;
        let mut out = Vec::new();
        for entry in fs::read_dir(tmp).map_err(|e| StoreError::io(tmp, e))? {
            out.push(entry.map_err(|e| StoreError::io(tmp, e))?.path());
        }
        Ok(out)
    }
}

impl BlobStore for DiskBlobStore {
    fn sync(&self) -> Result<(), StoreError> {
        if !self.inner.deferred_sync {
            return Ok(());
        }
        sync_file_system(&self.inner.root)
    }

    fn begin(&self) -> Result<Box<dyn BlobWriter>, StoreError> {
        let n = self.inner.next_tmp.fetch_add(1, Ordering::Relaxed);
        let path = self
            .inner
            .tmp
            .join(format!("upload-{}-{n}", std::process::id()));
        // create_new: a leftover with the same name would otherwise be appended to silently.
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|e| StoreError::io(&path, e))?;
        Ok(Box::new(DiskWriter {
            store: self.clone(),
            file: Some(BufWriter::with_capacity(CHUNK, file)),
            tmp_path: path,
            tally: Tally::new(self.inner.max_blob_bytes),
        }))
    }

    fn contains(&self, hash: &str) -> Result<bool, StoreError> {
        Ok(self.size(hash)?.is_some())
    }

    fn size(&self, hash: &str) -> Result<Option<u64>, StoreError> {
        let path = self.blob_path(hash)?;
        match fs::metadata(&path) {
            Ok(m) => Ok(Some(m.len())),
            Err(e) if e.kind() == ErrorKind::NotFound => Ok(None),
            Err(e) => Err(StoreError::io(&path, e)),
        }
    }

    fn read(&self, hash: &str) -> Result<Vec<u8>, StoreError> {
        let path = self.blob_path(hash)?;
        fs::read(&path).map_err(|e| not_found_or_io(hash, &path, e))
    }

    fn open(&self, hash: &str) -> Result<Box<dyn Read + Send>, StoreError> {
        let path = self.blob_path(hash)?;
        let f = File::open(&path).map_err(|e| not_found_or_io(hash, &path, e))?;
        Ok(Box::new(f))
    }
}

fn not_found_or_io(hash: &str, path: &Path, e: std::io::Error) -> StoreError {
    if e.kind() == ErrorKind::NotFound {
        StoreError::NotFound {
            hash: hash.to_owned(),
        }
    } else {
        StoreError::io(path, e)
    }
}

struct DiskWriter {
    store: DiskBlobStore,
    /// None once the temp file is gone (finished, or discarded after an error).
    file: Option<BufWriter<File>>,
    tmp_path: PathBuf,
    tally: Tally,
}

impl DiskWriter {
    fn discard(&mut self) {
        if self.file.take().is_some() {
            if let Err(e) = fs::remove_file(&self.tmp_path) {
                if e.kind() != ErrorKind::NotFound {
                    tracing::warn!(path = %self.tmp_path.display(), error = %e, "could not remove an unfinished upload");
                }
            }
        }
    }

    fn install(&mut self, hash: &str) -> Result<(), StoreError> {
        let Some(buf) = self.file.take() else {
            return Err(StoreError::Invalid(
                "the upload was already discarded after an earlier error".into(),
            ));
        };
        let file = buf
            .into_inner()
            .map_err(|e| StoreError::io(&self.tmp_path, e.into_error()))?;
        // The rename must not become visible before the data is on disk, or a power cut could
        // leave a blob whose bytes don't match its name.
        let durable_now = !self.store.inner.deferred_sync;
        if durable_now {
            file.sync_all()
                .map_err(|e| StoreError::io(&self.tmp_path, e))?;
        }
        drop(file);
        let dest = self.store.blob_path(hash)?;
        let dir = dest.parent().map(Path::to_path_buf).unwrap_or_default();
        let new_dir = !dir.exists();
        fs::create_dir_all(&dir).map_err(|e| StoreError::io(&dir, e))?;
        // Same name means same content, so a concurrent upload of the same sample that got
        // there first is as good as ours; renaming over it is harmless either way.
        fs::rename(&self.tmp_path, &dest).map_err(|e| StoreError::io(&dest, e))?;
        if durable_now {
            sync_dir(&dir)?;
            if new_dir {
                sync_dir(self.store.root())?;
            }
        }
        Ok(())
    }
}

impl BlobWriter for DiskWriter {
    fn write(&mut self, chunk: &[u8]) -> Result<(), StoreError> {
        if let Err(e) = self.tally.admit(chunk) {
            self.discard();
            return Err(e);
        }
        let Some(file) = self.file.as_mut() else {
            return Err(StoreError::Invalid(
                "the upload was already discarded after an earlier error".into(),
            ));
        };
        if let Err(e) = file.write_all(chunk) {
            let err = StoreError::io(&self.tmp_path, e);
            self.discard();
            return Err(err);
        }
        Ok(())
    }

    fn written(&self) -> u64 {
        self.tally.written()
    }

    fn finish(
        mut self: Box<Self>,
        expected_size: u64,
        expected_blake3: &str,
    ) -> Result<Hash, StoreError> {
        let hash = match self.tally.verify(expected_size, expected_blake3) {
            Ok(h) => h,
            Err(e) => {
                self.discard();
                return Err(e);
            }
        };
        if let Err(e) = self.install(&hash) {
            // `install` may have taken the file already; make sure the temp is gone.
            let _ = fs::remove_file(&self.tmp_path);
            return Err(e);
        }
        tracing::debug!(%hash, size = expected_size, "blob stored");
        Ok(hash)
    }
}

impl Drop for DiskWriter {
    fn drop(&mut self) {
        self.discard();
    }
}

fn sync_dir(dir: &Path) -> Result<(), StoreError> {
    // Directory fsync makes the rename itself durable; it is a Unix notion.
    #[cfg(unix)]
    {
        File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(|e| StoreError::io(dir, e))?;
    }
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// One `syncfs(2)` for the file system holding `root`: every deferred blob and rename at once.
fn sync_file_system(root: &Path) -> Result<(), StoreError> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let dir = File::open(root).map_err(|e| StoreError::io(root, e))?;
        // SAFETY: syncfs takes a valid open file descriptor, which `dir` holds for the call.
        let rc = unsafe { libc::syncfs(dir.as_raw_fd()) };
        if rc != 0 {
            return Err(StoreError::io(root, std::io::Error::last_os_error()));
        }
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    {
        // Elsewhere a full sync(2) is the portable equivalent.
        let _ = root;
        std::process::Command::new("sync")
            .status()
            .map(|_| ())
            .map_err(|e| StoreError::io(root, e))
    }
}
