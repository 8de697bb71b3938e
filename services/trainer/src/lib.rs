//! The trainer: reads rendered samples, computes light maps, trains the relighting networks
//! (`lightfarm-nets`) with resumable checkpoints, relights portraits and evaluates models.
//!
//! Map: [`config`] (train.toml) → [`data`] (folder export → seeded batches on background
//! threads, using [`sample`] to decode EXRs and [`lights`] for prefiltered HDRIs) → [`train`]
//! (loop, loss log, checkpoints; [`step`] the gradients of one step, in micro-batches) → [`infer`] (load a model, relight an image) and [`eval`].

pub mod adapt;
pub mod config;
pub mod data;
pub mod eval;
pub mod eval_real;
pub mod farm;
pub mod image_io;
pub mod infer;
pub mod lights;
pub mod loss_scale;
pub mod olat_sample;
pub mod sample;
pub mod sample_cache;
pub mod service;
mod step;
pub mod train;

use std::path::{Path, PathBuf};

pub use config::{NetConfig, TrainConfig};
pub use train::{train, Observer, StepLog, TrainSummary};

#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("{0}")]
    Config(String),
    #[error("{0}")]
    Input(String),
    #[error("sample {name}: {reason}")]
    Sample { name: String, reason: String },
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error("training diverged at step {step} (loss {loss}); lower `lr` or resume from an earlier checkpoint")]
    Diverged { step: u64, loss: f32 },
    #[error(transparent)]
    Photo(#[from] lightfarm_photo::PhotoError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

impl TrainError {
    pub fn io(path: &Path, source: std::io::Error) -> TrainError {
        TrainError::Io {
            path: path.to_owned(),
            source,
        }
    }
}
