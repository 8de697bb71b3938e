//! `lightfarm adapt`: the paper's synthetic-to-real adaptation (section 4.3). A model trained
//! on renders stays frozen; f_Ā learns from a folder of real portraits, with the OLAT and
//! relative lighting-consistency losses, the VGG similarity of Ā to A and a GAN on R̄.
//!
//! [`config`] (adapt.toml) → [`photos`] (the folder, matted and cropped on first use, cached)
//! → [`run`] (loop, loss log) → [`checkpoint`] (complete models for `relight`).

pub mod checkpoint;
pub mod config;
pub mod photos;
pub mod run;

pub use config::AdaptConfig;
pub use run::{adapt, AdaptLog, AdaptObserver, AdaptSummary};
