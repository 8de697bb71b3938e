//! lightfarm's path tracer. See README.md in this crate for what it owns.
//!
//! Layout: `scene` (CPU scene from glTF), `gpu_scene` / `gpu_env` (flattening into the shaders'
//! arrays, BVH builds), `gpu_types` (the shared `#[repr(C)]` structs), `vulkan` (the only module
//! that touches ash), `renderer` (dispatching the integrator; `settings`, `render_output` and `bound` hold what it
//! is asked, what it returns and the buffers it binds), `output` (EXR and PNG), `probe`
//! (running the sampling routines and traversal on the device for tests), `tables` (the layered
//! model's directional-albedo tables), `hair` (the fibre material's absorption and colour).

mod bound;
pub mod counters;
pub mod gpu_curves;
pub mod gpu_env;
pub mod gpu_scene;
pub mod gpu_types;
pub mod hair;
pub mod output;
pub mod passes;
pub mod probe;
pub mod render_output;
pub mod renderer;
pub mod scene;
pub mod schedule;
pub mod settings;
pub mod shaders;
pub mod tables;
pub mod vulkan;

pub use gpu_env::{DiscLight, EnvLight, Lighting};
pub use renderer::{RenderOutput, RenderSettings, RenderStats, Renderer};
pub use schedule::{LightingSchedule, WalkSchedule};

/// Version recorded in every output (the sample's `renderer` attribute).
pub const RENDERER_VERSION: &str = concat!("lightfarm-render ", env!("CARGO_PKG_VERSION"));

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Vulkan(#[from] vulkan::VulkanError),
    #[error(transparent)]
    Scene(#[from] scene::SceneError),
    #[error("invalid scene: {0}")]
    InvalidScene(String),
    #[error("invalid render settings: {0}")]
    InvalidSettings(String),
    /// The driver ended the integrator's loops before they were done (kernels/integrator.wgsl,
    /// `report_cut_loops`): the render would have lost samples and traversals.
    #[error(
        "{device} ({driver}) ended the integrator's loops early in {invocations} invocations, \
         so samples were lost and the image would be wrong: Mesa 22's llvmpipe stops every loop \
         of a shader invocation after 65,535 turns in all. Render with Mesa 25 or newer \
         (`source scripts/lavapipe-backports.sh`, with LIGHTFARM_LAVAPIPE unset) or on a GPU"
    )]
    LoopsCut {
        device: String,
        driver: String,
        invocations: u32,
    },
    #[error("cannot write {path}: {reason}")]
    Output {
        path: std::path::PathBuf,
        reason: String,
    },
}
