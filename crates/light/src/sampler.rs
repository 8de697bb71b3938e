//! Importance sampling of a lat-long environment map by luminance.

use std::f32::consts::PI;

use crate::distribution::Distribution2D;
use crate::hdri::Hdri;
use crate::mapping::{dir_to_uv, uv_to_dir};

/// Importance sampler for a lat-long map: a [`Distribution2D`] over
/// luminance(u, v) · sin(πv) (pbrt-v3 `infinite.cpp` style), with the solid-angle density
/// p(ω) = p(u, v) / (2π² sinθ), and 0 where sinθ = 0.
///
/// The sinθ factor in the table cancels the lat-long stretching near the poles, so samples
/// follow the radiance as seen on the sphere, not on the rectangle.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvSampler {
    pub dist: Distribution2D,
    pub width: u32,
    pub height: u32,
}

impl EnvSampler {
    /// Builds the tables: cell (x, y) holds luminance(texel) · sin(π (y + 0.5) / height).
    pub fn new(hdri: &Hdri) -> Self {
        let width = hdri.width.max(1);
        let height = hdri.height.max(1);
        let (w, h) = (width as usize, height as usize);
        let mut func = Vec::with_capacity(w * h);
        for y in 0..h {
            let sin_theta = (PI * (y as f32 + 0.5) / h as f32).sin();
            for x in 0..w {
                let texel = hdri.texels.get(y * w + x).copied().unwrap_or([0.0; 3]);
                func.push(Hdri::luminance(texel) * sin_theta);
            }
        }
        let dist = Distribution2D::new(&func, w, h);
        EnvSampler {
            dist,
            width,
            height,
        }
    }

    /// Maps uniform `u` to (env-local unit direction, solid-angle pdf). A pdf of 0 marks a
    /// sample that must be discarded (only possible exactly at a pole).
    pub fn sample(&self, u: [f32; 2]) -> ([f32; 3], f32) {
        let (uv, pdf_uv) = self.dist.sample_continuous(u);
        let dir = uv_to_dir(uv);
        (dir, solid_angle_pdf(pdf_uv, dir))
    }

    /// Solid-angle density of sampling env-local direction `dir_env`.
    pub fn pdf(&self, dir_env: [f32; 3]) -> f32 {
        let uv = dir_to_uv(dir_env);
        let len =
            (dir_env[0] * dir_env[0] + dir_env[1] * dir_env[1] + dir_env[2] * dir_env[2]).sqrt();
        if !len.is_finite() || len <= 0.0 {
            return 0.0;
        }
        let unit = [dir_env[0] / len, dir_env[1] / len, dir_env[2] / len];
        solid_angle_pdf(self.dist.pdf(uv), unit)
    }
}

/// p(ω) = p(u, v) / (2π² sinθ). sinθ is taken from the direction itself (not from v) so that
/// `sample` and `pdf` compute it identically from the same unit vector.
fn solid_angle_pdf(pdf_uv: f32, unit_dir: [f32; 3]) -> f32 {
    let sin_theta = (unit_dir[0] * unit_dir[0] + unit_dir[2] * unit_dir[2]).sqrt();
    if sin_theta <= 0.0 || pdf_uv <= 0.0 {
        return 0.0;
    }
    pdf_uv / (2.0 * PI * PI * sin_theta)
}
