use std::io::Read;
use std::path::Path;

use crate::StoreError;

/// Lower-case hex BLAKE3 of a blob's bytes, 64 characters.
pub type Hash = String;

/// Size of the reads used when hashing or copying files; large enough that syscalls don't
/// dominate, small enough to stay on the stack of a worker thread's buffer.
pub(crate) const CHUNK: usize = 256 * 1024;

/// The hash under which `bytes` is stored.
pub fn hash_hex(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// Whether `s` is a well-formed blob hash. Only such strings ever become paths, which is what
/// keeps a caller-supplied hash from naming a file outside the store.
pub fn is_hash(s: &str) -> bool {
    s.len() == 64 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

pub(crate) fn check_hash(s: &str) -> Result<(), StoreError> {
    if is_hash(s) {
        Ok(())
    } else {
        Err(StoreError::InvalidHash { hash: s.to_owned() })
    }
}

/// Hashes a file by streaming it, returning (hash, size).
pub(crate) fn hash_file(path: &Path) -> Result<(Hash, u64), StoreError> {
    let mut f = std::fs::File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut hasher = blake3::Hasher::new();
    let mut buf = vec![0u8; CHUNK];
    let mut size = 0u64;
    loop {
        let n = f.read(&mut buf).map_err(|e| StoreError::io(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
        size += n as u64;
    }
    Ok((hasher.finalize().to_hex().to_string(), size))
}

/// Content-addressed blobs: sample EXRs and catalog assets.
///
/// A trait so that an object store can replace the local disk later; the coordinator holds it
/// as `Arc<dyn BlobStore>`.
pub trait BlobStore: Send + Sync + 'static {
    /// Starts a streaming write (upload): bytes go to a temp file in the store while being
    /// hashed, and only [`BlobWriter::finish`] makes them visible.
    fn begin(&self) -> Result<Box<dyn BlobWriter>, StoreError>;
    fn contains(&self, hash: &str) -> Result<bool, StoreError>;
    fn size(&self, hash: &str) -> Result<Option<u64>, StoreError>;
    /// Reads a whole blob (samples are a few MB); [`StoreError::NotFound`] if missing.
    /// Does not re-hash; use [`BlobStore::read_verified`] where corruption must be caught.
    fn read(&self, hash: &str) -> Result<Vec<u8>, StoreError>;
    /// Opens a blob for streaming (assets can be bigger); [`StoreError::NotFound`] if missing.
    fn open(&self, hash: &str) -> Result<Box<dyn Read + Send>, StoreError>;

    /// Imports a local file (assets at coordinator start) and returns its hash; a no-op when
    /// the content is already present.
    fn put_file(&self, path: &Path) -> Result<Hash, StoreError> {
        // Hash first so that re-importing the same assets at every start costs one read and
        // no writes.
        let (hash, size) = hash_file(path)?;
        if self.contains(&hash)? {
            return Ok(hash);
        }
        let mut f = std::fs::File::open(path).map_err(|e| StoreError::io(path, e))?;
        let mut w = self.begin()?;
        let mut buf = vec![0u8; CHUNK];
        loop {
            let n = f.read(&mut buf).map_err(|e| StoreError::io(path, e))?;
            if n == 0 {
                break;
            }
            w.write(&buf[..n])?;
        }
        // Verifying against the first pass catches a file that changed while being imported.
        w.finish(size, &hash)
    }

    /// Stores `bytes` and returns their hash; a no-op when already present.
    fn put(&self, bytes: &[u8]) -> Result<Hash, StoreError> {
        let hash = hash_hex(bytes);
        if self.contains(&hash)? {
            return Ok(hash);
        }
        let mut w = self.begin()?;
        w.write(bytes)?;
        w.finish(bytes.len() as u64, &hash)
    }

    /// Makes every finished blob durable (stores opened with deferred sync); a no-op where
    /// each blob is already durable when `finish` returns.
    fn sync(&self) -> Result<(), StoreError> {
        Ok(())
    }

    /// Reads a whole blob and checks that its bytes still hash to `hash`
    /// ([`StoreError::Corrupt`] otherwise).
    fn read_verified(&self, hash: &str) -> Result<Vec<u8>, StoreError> {
        let bytes = self.read(hash)?;
        let got = hash_hex(&bytes);
        if got != hash {
            return Err(StoreError::Corrupt {
                hash: hash.to_owned(),
                reason: format!(
                    "its {} bytes hash to {got}; the file was damaged after it was stored — \
                     restore it from a backup or re-render the sample",
                    bytes.len()
                ),
            });
        }
        Ok(bytes)
    }
}

/// One in-progress streaming write. Dropping it without [`BlobWriter::finish`] discards
/// everything written, so a truncated upload leaves nothing behind.
pub trait BlobWriter: Send {
    /// Appends a chunk; [`StoreError::TooLarge`] once the store's limit would be passed, after
    /// which the writer is dead (the partial data is already discarded).
    fn write(&mut self, chunk: &[u8]) -> Result<(), StoreError>;
    /// Bytes accepted so far.
    fn written(&self) -> u64;
    /// Verifies size and BLAKE3 against what the uploader declared. On success the blob is
    /// durably in place and its hash returned; on any mismatch nothing remains in the store
    /// and the error carries expected vs got.
    fn finish(
        self: Box<Self>,
        expected_size: u64,
        expected_blake3: &str,
    ) -> Result<Hash, StoreError>;
}

/// Size/hash bookkeeping shared by both writers so they reject exactly the same inputs.
pub(crate) struct Tally {
    hasher: blake3::Hasher,
    written: u64,
    limit: u64,
    /// Set once a write went past the limit: the caller may ignore that error and call
    /// `finish`, which must not then store a truncated blob.
    overflowed: Option<u64>,
}

impl Tally {
    pub(crate) fn new(limit: u64) -> Self {
        Tally {
            hasher: blake3::Hasher::new(),
            written: 0,
            limit,
            overflowed: None,
        }
    }

    /// Accounts for `chunk` before it is written; errors if it would pass the limit.
    pub(crate) fn admit(&mut self, chunk: &[u8]) -> Result<(), StoreError> {
        if let Some(got) = self.overflowed {
            return Err(StoreError::TooLarge {
                limit: self.limit,
                got,
            });
        }
        let got = self.written.saturating_add(chunk.len() as u64);
        if got > self.limit {
            self.overflowed = Some(got);
            return Err(StoreError::TooLarge {
                limit: self.limit,
                got,
            });
        }
        self.hasher.update(chunk);
        self.written = got;
        Ok(())
    }

    pub(crate) fn written(&self) -> u64 {
        self.written
    }

    /// The hash of what was written, if it matches the declaration.
    pub(crate) fn verify(
        &self,
        expected_size: u64,
        expected_blake3: &str,
    ) -> Result<Hash, StoreError> {
        if let Some(got) = self.overflowed {
            return Err(StoreError::TooLarge {
                limit: self.limit,
                got,
            });
        }
        let got = self.hasher.finalize().to_hex().to_string();
        if self.written != expected_size || !got.eq_ignore_ascii_case(expected_blake3) {
            return Err(StoreError::Mismatch {
                expected_size,
                got_size: self.written,
                expected_blake3: expected_blake3.to_owned(),
                got_blake3: got,
            });
        }
        Ok(got)
    }
}
