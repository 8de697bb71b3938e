//! Scene description for lightfarm's virtual light stage.
//!
//! Today this is the asset catalog (`catalog`): the list of heads, HDR environment maps and
//! accessories a dataset job may draw from, each pinned by a BLAKE3 hash so that a render farm
//! renders exactly the bytes the job was specified against. The light-stage job spec and its
//! deterministic expansion into samples follow in `spec` / `expand`.

pub mod catalog;
pub mod error;
pub mod expand;
pub mod identity;
pub mod rng;
pub mod spec;
mod validate;

pub use catalog::{Asset, AssetKind, Catalog};
pub use error::SceneError;
