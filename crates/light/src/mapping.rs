//! Direction <-> lat-long mapping and the per-sample environment transform.
//!
//! Every consumer (CPU sampler, WGSL integrator, light-map kernels, reference renderers) must
//! agree on this mapping bit-for-bit in spirit, so it lives in one place and is pinned by tests.

use std::f32::consts::{PI, TAU};

/// Largest f32 below 1; keeps u and v inside [0, 1) so `floor(u * width)` never reaches `width`.
pub(crate) const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Direction -> lat-long (u, v), the project convention:
/// u = atan2(x, -z)/(2π) wrapped to [0, 1), v = acos(y)/π; u = 0 -> -Z, u = 0.25 -> +X,
/// u = 0.5 -> +Z, v = 0 -> +Y.
///
/// `d` need not be normalized; a zero or non-finite vector maps to (0, 0) rather than NaN so
/// texel indexing downstream stays in range.
pub fn dir_to_uv(d: [f32; 3]) -> [f32; 2] {
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if !len.is_finite() || len <= 0.0 {
        return [0.0, 0.0];
    }
    let y = (d[1] / len).clamp(-1.0, 1.0);
    let mut u = d[0].atan2(-d[2]) / TAU;
    if u < 0.0 {
        u += 1.0;
    }
    // -tiny + 1 rounds to exactly 1.0, which is the same meridian as 0.
    if u >= 1.0 {
        u = 0.0;
    }
    let v = (y.acos() / PI).min(1.0);
    [u, v]
}

/// Lat-long (u, v) -> unit direction; inverse of [`dir_to_uv`] with φ = 2πu, θ = πv:
/// (sinθ sinφ, cosθ, -sinθ cosφ).
pub fn uv_to_dir(uv: [f32; 2]) -> [f32; 3] {
    let phi = TAU * uv[0];
    let theta = PI * uv[1];
    let (sin_t, cos_t) = theta.sin_cos();
    let (sin_p, cos_p) = phi.sin_cos();
    [sin_t * sin_p, cos_t, -sin_t * cos_p]
}

/// Per-sample rotation about +Y and horizontal flip (u -> 1-u, i.e. env-local x negated).
///
/// The paper augments lighting by rotating and mirroring the HDRI per sample; applying it to
/// directions instead of resampling the map keeps the map and its sampling tables shared.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnvTransform {
    pub rotation_deg: f32,
    pub flip: bool,
}

impl EnvTransform {
    /// World -> env-local: e = F · R_y(-θ) · d, with R_y(θ): x' = cosθ x + sinθ z,
    /// z' = -sinθ x + cosθ z; F negates x when `flip`.
    pub fn world_to_env(&self, d: [f32; 3]) -> [f32; 3] {
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        // R_y(-θ): x' = cosθ x - sinθ z, z' = sinθ x + cosθ z.
        let x = c * d[0] - s * d[2];
        let z = s * d[0] + c * d[2];
        let x = if self.flip { -x } else { x };
        [x, d[1], z]
    }

    /// Env-local -> world, the exact inverse of [`EnvTransform::world_to_env`]:
    /// d = R_y(θ) · F · e.
    pub fn env_to_world(&self, e: [f32; 3]) -> [f32; 3] {
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        let ex = if self.flip { -e[0] } else { e[0] };
        let x = c * ex + s * e[2];
        let z = -s * ex + c * e[2];
        [x, e[1], z]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() < 1e-5
    }

    #[test]
    fn u_stays_below_one_just_left_of_minus_z() {
        // atan2 of a tiny negative x gives -tiny; wrapping must not produce u == 1.
        let uv = dir_to_uv([-1e-9, 0.0, -1.0]);
        assert!(uv[0] < 1.0 && uv[0] >= 0.0, "u = {}", uv[0]);
    }

    #[test]
    fn degenerate_direction_maps_inside_the_map() {
        assert_eq!(dir_to_uv([0.0, 0.0, 0.0]), [0.0, 0.0]);
        assert_eq!(dir_to_uv([f32::NAN, 0.0, 1.0]), [0.0, 0.0]);
        let uv = dir_to_uv([0.0, 5.0, 0.0]);
        assert!(close(uv[1], 0.0));
    }

    #[test]
    fn transform_identity_is_identity() {
        let d = [0.3, -0.4, 0.866];
        let e = EnvTransform::default().world_to_env(d);
        assert!(d.iter().zip(e).all(|(a, b)| close(*a, b)));
    }
}
