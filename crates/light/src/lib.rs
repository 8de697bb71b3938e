//! HDR environment lighting for lightfarm: loading lat-long maps (Radiance `.hdr`, OpenEXR),
//! the project's direction <-> lat-long convention, the per-sample rotation/flip, and the
//! importance-sampling tables the GPU integrator reads.
//!
//! Conventions (DESIGN.md): +Y up; u = atan2(x, -z)/2π in [0, 1), v = acos(y)/π; row 0 of a
//! map is the top (v = 0 = +Y). Texels are linear RGB.

mod distribution;
mod hdri;
mod lightmaps;
mod load;
mod mapping;
mod olat;
mod sampler;

pub use distribution::{Distribution1D, Distribution2D};
pub use hdri::Hdri;
pub use lightmaps::{
    default_resolution, downsample, prefilter_phong, sh9_basis, PrefilteredEnv, PrefilteredMap,
    ShRadiance, PHONG_EXPONENTS,
};
pub use load::LightError;
pub use mapping::{dir_to_uv, uv_to_dir, EnvTransform};
pub use olat::{olat_directions, olat_layer, OlatBasis, OLAT_DISC_DEG, OLAT_LIGHTS};
pub use sampler::EnvSampler;
