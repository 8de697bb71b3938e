use std::collections::HashMap;
use std::io::{Cursor, Read};
use std::sync::{Arc, RwLock, RwLockReadGuard, RwLockWriteGuard};

use crate::blob::{check_hash, BlobStore, BlobWriter, Hash, Tally};
use crate::StoreError;

type Blobs = HashMap<Hash, Arc<Vec<u8>>>;

/// The in-memory twin of [`crate::DiskBlobStore`], for tests and tools that must not touch
/// disk. It enforces the same limits and hash checks so tests against it mean something.
#[derive(Clone)]
pub struct MemoryBlobStore {
    blobs: Arc<RwLock<Blobs>>,
    max_blob_bytes: u64,
}

impl MemoryBlobStore {
    pub fn new(max_blob_bytes: u64) -> Self {
        MemoryBlobStore {
            blobs: Arc::new(RwLock::new(HashMap::new())),
            max_blob_bytes,
        }
    }

    /// Number of stored blobs.
    pub fn len(&self) -> usize {
        self.read_lock().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    // A panic elsewhere while holding the lock can't leave the map half-updated (every
    // mutation is a single insert), so a poisoned lock is still safe to use.
    fn read_lock(&self) -> RwLockReadGuard<'_, Blobs> {
        self.blobs.read().unwrap_or_else(|p| p.into_inner())
    }

    fn write_lock(&self) -> RwLockWriteGuard<'_, Blobs> {
        self.blobs.write().unwrap_or_else(|p| p.into_inner())
    }

    fn get(&self, hash: &str) -> Result<Arc<Vec<u8>>, StoreError> {
        check_hash(hash)?;
        self.read_lock()
            .get(hash)
            .cloned()
            .ok_or_else(|| StoreError::NotFound {
                hash: hash.to_owned(),
            })
    }
}

impl BlobStore for MemoryBlobStore {
    fn begin(&self) -> Result<Box<dyn BlobWriter>, StoreError> {
        Ok(Box::new(MemoryWriter {
            store: self.clone(),
            buf: Vec::new(),
            tally: Tally::new(self.max_blob_bytes),
        }))
    }

    fn contains(&self, hash: &str) -> Result<bool, StoreError> {
        check_hash(hash)?;
        Ok(self.read_lock().contains_key(hash))
    }

    fn size(&self, hash: &str) -> Result<Option<u64>, StoreError> {
        check_hash(hash)?;
        Ok(self.read_lock().get(hash).map(|b| b.len() as u64))
    }

    fn read(&self, hash: &str) -> Result<Vec<u8>, StoreError> {
        Ok(self.get(hash)?.as_ref().clone())
    }

    fn open(&self, hash: &str) -> Result<Box<dyn Read + Send>, StoreError> {
        Ok(Box::new(Cursor::new(SharedBytes(self.get(hash)?))))
    }
}

/// Lets a reader share the stored bytes instead of copying a large asset.
struct SharedBytes(Arc<Vec<u8>>);

impl AsRef<[u8]> for SharedBytes {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

struct MemoryWriter {
    store: MemoryBlobStore,
    buf: Vec<u8>,
    tally: Tally,
}

impl BlobWriter for MemoryWriter {
    fn write(&mut self, chunk: &[u8]) -> Result<(), StoreError> {
        if let Err(e) = self.tally.admit(chunk) {
            self.buf = Vec::new();
            return Err(e);
        }
        self.buf.extend_from_slice(chunk);
        Ok(())
    }

    fn written(&self) -> u64 {
        self.tally.written()
    }

    fn finish(
        self: Box<Self>,
        expected_size: u64,
        expected_blake3: &str,
    ) -> Result<Hash, StoreError> {
        let hash = self.tally.verify(expected_size, expected_blake3)?;
        let MemoryWriter { store, buf, .. } = *self;
        store
            .write_lock()
            .entry(hash.clone())
            .or_insert_with(|| Arc::new(buf));
        Ok(hash)
    }
}
