//! A real photograph, made ready for the relighting networks. Synthetic samples come with their
//! coverage mask; a photograph does not, so its foreground comes from a matting network, MODNet
//! (Ke et al. 2022), as in the paper (section 4.3). The network ships as ONNX and runs on the
//! pure-Rust `tract-onnx`, so it works on an offline CPU machine.

mod matte;

pub use matte::{builtin_modnet, LazyMatting, Matting, MODNET_FILE, MODNET_FIX};

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum PhotoError {
    #[error("{path}: {reason}")]
    Model { path: PathBuf, reason: String },
    #[error("{0}")]
    Input(String),
}
