//! The coordinator's errors, and their one mapping to gRPC status codes.

use tonic::{Code, Status};

#[derive(Debug, thiserror::Error)]
pub enum CoordError {
    #[error("unknown job `{0}`: list jobs with `lightfarm jobs`")]
    UnknownJob(String),
    /// Something other than a job that does not exist (a sample not committed yet).
    #[error("{0}")]
    NotFound(String),
    #[error("bad dataset spec: {0}")]
    BadSpec(String),
    #[error("{0}")]
    Invalid(String),
    #[error("{0}")]
    Conflict(String),
    #[error("{0}")]
    LeaseLost(String),
    #[error("{0}")]
    TooLarge(String),
    #[error("{0}")]
    Corrupt(String),
    #[error("storage: {0}")]
    Storage(String),
    #[error("{0}")]
    Store(#[from] lightfarm_store::StoreError),
}

impl From<CoordError> for Status {
    fn from(e: CoordError) -> Status {
        let code = match &e {
            CoordError::UnknownJob(_) | CoordError::NotFound(_) => Code::NotFound,
            CoordError::BadSpec(_) | CoordError::Invalid(_) | CoordError::Corrupt(_) => {
                Code::InvalidArgument
            }
            CoordError::Conflict(_) | CoordError::LeaseLost(_) => Code::FailedPrecondition,
            CoordError::TooLarge(_) => Code::ResourceExhausted,
            CoordError::Storage(_) => Code::Internal,
            CoordError::Store(s) => match s {
                lightfarm_store::StoreError::NotFound { .. } => Code::NotFound,
                lightfarm_store::StoreError::TooLarge { .. } => Code::ResourceExhausted,
                lightfarm_store::StoreError::Mismatch { .. } => Code::DataLoss,
                _ => Code::Internal,
            },
        };
        Status::new(code, e.to_string())
    }
}
