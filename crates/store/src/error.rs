use std::path::{Path, PathBuf};

/// Everything that can go wrong in the store. Messages name the input and, where there is one,
/// the fix, because they end up verbatim in gRPC statuses and CLI output.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("blob {hash} is not in the store; upload or import it first")]
    NotFound { hash: String },
    #[error(
        "blob is larger than the store's limit of {limit} bytes (got at least {got}); \
         nothing was stored — raise the limit or send a smaller file"
    )]
    TooLarge { limit: u64, got: u64 },
    #[error(
        "upload does not match its declaration: expected {expected_size} bytes with BLAKE3 \
         {expected_blake3}, got {got_size} bytes with BLAKE3 {got_blake3}; nothing was stored, \
         send the file again"
    )]
    Mismatch {
        expected_size: u64,
        got_size: u64,
        expected_blake3: String,
        got_blake3: String,
    },
    #[error("blob {hash} is corrupt: {reason}")]
    Corrupt { hash: String, reason: String },
    #[error("{hash:?} is not a blob hash (expected 64 lower-case hex characters of BLAKE3)")]
    InvalidHash { hash: String },
    #[error("invalid input: {0}")]
    Invalid(String),
    #[error("sample index (sled): {0}")]
    Sled(String),
    #[error("export: {0}")]
    Export(String),
}

impl StoreError {
    pub(crate) fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        StoreError::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
}

impl From<sled::Error> for StoreError {
    fn from(e: sled::Error) -> Self {
        StoreError::Sled(e.to_string())
    }
}
