//! What a render is asked for: the image size, samples, path depth, camera and passes, the
//! limits that catch typos before they become hour-long renders, and the camera's vectors as the
//! integrator reads them.

use crate::passes::Pass;
use crate::scene::Camera;
use crate::RenderError;

/// Limits that catch typos (`--spp 2560000`) before they turn into hour-long renders or
/// allocations the device cannot make.
pub const MAX_SIZE: u32 = 16384;
pub const MAX_SPP: u32 = 1 << 20;
/// Lightings of one render: the virtual light stage's 168 OLAT lights and more. Their
/// accumulators are grouped to what one storage buffer may span, so the count is bounded by
/// the cost of the NEE loop (one shadow ray per lighting per vertex), not by memory.
pub const MAX_LIGHTS: usize = 1024;

#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub seed: u32,
    /// Maximum number of scattering events on a path.
    pub max_depth: u32,
    /// Russian roulette starts at this depth.
    pub rr_depth: u32,
    pub camera: Camera,
    /// The appendix passes to produce besides lit, albedo, normals and mask (crate::passes).
    pub passes: Vec<Pass>,
}

impl RenderSettings {
    pub fn validate(&self) -> Result<(), RenderError> {
        let bad = |m: String| Err(RenderError::InvalidSettings(m));
        if self.width == 0 || self.height == 0 || self.width > MAX_SIZE || self.height > MAX_SIZE {
            return bad(format!(
                "--size {}x{} is out of range: width and height must be 1..={MAX_SIZE}",
                self.width, self.height
            ));
        }
        if self.spp == 0 || self.spp > MAX_SPP {
            return bad(format!(
                "--spp {} is out of range: use 1..={MAX_SPP}",
                self.spp
            ));
        }
        if self.max_depth == 0 || self.max_depth > 1024 {
            return bad(format!(
                "max depth {} is out of range: use 1..=1024",
                self.max_depth
            ));
        }
        Ok(())
    }
}

pub(crate) fn camera_params(settings: &RenderSettings) -> ([f32; 4], [f32; 4], [f32; 4], [f32; 4]) {
    let cam = &settings.camera;
    let fwd = cam.forward.normalize();
    let right = fwd.cross(cam.up).normalize();
    let up = right.cross(fwd);
    let tan_half = (cam.yfov_deg.to_radians() * 0.5).tan();
    let aspect = settings.width as f32 / settings.height as f32;
    let r = right * tan_half * aspect;
    let u = up * tan_half;
    (
        [cam.position.x, cam.position.y, cam.position.z, 0.0],
        [r.x, r.y, r.z, 0.0],
        [u.x, u.y, u.z, 0.0],
        [fwd.x, fwd.y, fwd.z, 0.0],
    )
}
