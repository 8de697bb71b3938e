//! Errors of the scene crate. Every variant names the file (and, where there is one, the key)
//! the problem came from, because these errors mostly reach a person editing a TOML file.

use std::path::PathBuf;

/// An error loading or checking scene inputs (the asset catalog, later the job spec).
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML; `reason` carries the parser's line/column message.
    #[error("{path}: invalid TOML: {reason}")]
    Toml { path: PathBuf, reason: String },
    /// A value is well-formed TOML but not acceptable; `reason` says how to fix it.
    #[error("{path}: `{key}`: {reason}")]
    Invalid {
        path: PathBuf,
        key: String,
        reason: String,
    },
    /// An asset file's bytes differ from the hash the catalog pins.
    #[error("{path}: hash mismatch for asset `{id}` ({file}): catalog says {expected}, file is {actual}")]
    HashMismatch {
        path: PathBuf,
        id: String,
        file: PathBuf,
        expected: String,
        actual: String,
    },
}
