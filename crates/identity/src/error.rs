//! Errors of identity generation; each names the model file or parameter at fault.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum IdentityError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A model file that is not what the generator expects: `what` says which part.
    #[error("{path}: {what}: {reason}")]
    Model {
        path: PathBuf,
        what: String,
        reason: String,
    },
    /// A missing model file, with the command that installs it.
    #[error("{path} is missing: {fix}")]
    Missing { path: PathBuf, fix: String },
    #[error("identity {identity}: {reason}")]
    Generate { identity: String, reason: String },
}

pub(crate) fn model_error(
    path: &std::path::Path,
    what: impl Into<String>,
    reason: impl Into<String>,
) -> IdentityError {
    IdentityError::Model {
        path: path.to_path_buf(),
        what: what.into(),
        reason: reason.into(),
    }
}
