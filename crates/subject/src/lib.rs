//! Geometry of one light-stage sample.
//!
//! `lightfarm-scene` says *what* a sample is (asset ids, hair parameters, camera angles) and
//! stays free of geometry so the coordinator can expand specs without linking the renderer.
//! This crate turns that description into a [`lightfarm_render::scene::Scene`]: it loads the
//! head and applies the expression, grows strand hair and eyebrows on the scalp, places the
//! garment, fits glasses and headsets to the head's landmarks, and poses the camera.
//!
//! Every head is first brought into one canonical frame (metres, +Y up, face towards +Z, origin
//! near the centre of the skull base, the frame of the MakeHuman heads), so the generators
//! below can use fixed anatomical distances.

pub mod assemble;
pub mod cornea;
pub mod eyelids;
pub mod garment;
pub mod glasses;
pub mod hair;
pub mod head;
pub mod headset;
pub mod landmarks;
pub mod render;
pub mod sanity;
pub mod synthetic;

pub use assemble::{assemble, Assembled, AssemblyStats};
pub use head::Head;
pub use landmarks::{HeadSurface, Landmarks};

/// Errors of subject assembly; each names the asset or parameter at fault.
#[derive(Debug, thiserror::Error)]
pub enum SubjectError {
    #[error("{asset}: {reason}")]
    Asset { asset: String, reason: String },
    #[error("{0}")]
    Scene(#[from] lightfarm_render::scene::SceneError),
    #[error("{0}")]
    Render(#[from] lightfarm_render::RenderError),
}
