//! Per-pixel light maps on the device (paper section 4.1): L_d from the SH irradiance at the
//! normal, L_s^n from the Phong-prefiltered maps at the reflection vector (camera at +Z), and
//! L_{s,l}^1024 at the reflection of the lens normal.
//!
//! Normals are in camera space (+X right, +Y up, +Z toward the camera). Each batch item carries
//! the rotation camera → env-local directions (camera basis, HDRI rotation and flip folded into
//! one matrix), so the prefiltered maps of an HDRI serve every sample lit by it.

use burn::prelude::*;
use burn::tensor::ops::{GridSampleOptions, GridSamplePaddingMode, InterpolateMode};
use lightfarm_light::{PrefilteredEnv, PHONG_EXPONENTS};

use crate::NetsError;

/// Index of the lens-glare map (exponent 1024) in [`PHONG_EXPONENTS`].
pub const LENS_MAP: usize = 4;

/// One batch item's lighting as the host prepares it.
#[derive(Clone, Debug)]
pub struct LightInput<'a> {
    pub env: &'a PrefilteredEnv,
    /// Multiplies every map: the trainer's exposure normalisation of the HDRI.
    pub scale: f32,
    /// Row-major 3×3 taking camera-space directions to env-local ones.
    pub camera_to_env: [[f32; 3]; 3],
}

/// A batch's lighting on the device.
#[derive(Clone, Debug)]
pub struct LightBatch {
    /// [B, 9, 3]: coefficients of irradiance/π (already convolved with the clamped cosine).
    sh: Tensor<3>,
    /// [B, 3, 3]: camera → env-local.
    rotation: Tensor<3>,
    /// One [B, 3, H_k, W_k + 2] per Phong exponent; one wrapped column each side so bilinear
    /// lookups wrap in longitude.
    phong: Vec<Tensor<4>>,
}

impl LightBatch {
    pub fn new(items: &[LightInput<'_>], device: &Device) -> Result<LightBatch, NetsError> {
        if items.is_empty() {
            return Err(NetsError::Shape(
                "a light batch needs at least one item".into(),
            ));
        }
        let b = items.len();
        let mut sh = Vec::with_capacity(b * 27);
        let mut rot = Vec::with_capacity(b * 9);
        for item in items {
            if item.env.phong.len() != PHONG_EXPONENTS.len() {
                return Err(NetsError::Shape(format!(
                    "a prefiltered environment has {} Phong maps, the networks need {}",
                    item.env.phong.len(),
                    PHONG_EXPONENTS.len()
                )));
            }
            for c in item.env.sh.irradiance_coeffs() {
                sh.extend(c.map(|v| v * item.scale));
            }
            for row in item.camera_to_env {
                rot.extend(row);
            }
        }
        let mut phong = Vec::with_capacity(PHONG_EXPONENTS.len());
        for k in 0..PHONG_EXPONENTS.len() {
            let (w, h) = (items[0].env.phong[k].width, items[0].env.phong[k].height);
            let wp = w + 2;
            let mut data = Vec::with_capacity(b * 3 * h * wp);
            for item in items {
                let map = &item.env.phong[k];
                if (map.width, map.height) != (w, h) {
                    return Err(NetsError::Shape(format!(
                        "Phong-{} maps of one batch differ in size ({}x{} vs {w}x{h})",
                        map.exponent, map.width, map.height
                    )));
                }
                for ch in 0..3 {
                    for row in 0..h {
                        let texel = |col: usize| map.texels[row * w + col][ch] * item.scale;
                        data.push(texel(w - 1));
                        data.extend((0..w).map(texel));
                        data.push(texel(0));
                    }
                }
            }
            phong.push(Tensor::from_data(
                TensorData::new(data, [b, 3, h, wp]),
                device,
            ));
        }
        Ok(LightBatch {
            sh: Tensor::from_data(TensorData::new(sh, [b, 9, 3]), device),
            rotation: Tensor::from_data(TensorData::new(rot, [b, 3, 3]), device),
            phong,
        })
    }

    pub fn len(&self) -> usize {
        self.sh.dims()[0]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// L_d: irradiance/π at each pixel's normal; `normal` is [B, 3, H, W].
    pub fn diffuse(&self, normal: Tensor<4>) -> Tensor<4> {
        let [b, _, h, w] = normal.dims();
        let e = self.to_env(normal);
        let (x, y, z) = components(e);
        let ones = x.ones_like();
        let basis = Tensor::cat(
            vec![
                ones.mul_scalar(0.282_094_8),
                y.clone().mul_scalar(0.488_602_5),
                z.clone().mul_scalar(0.488_602_5),
                x.clone().mul_scalar(0.488_602_5),
                (x.clone() * y.clone()).mul_scalar(1.092_548_4),
                (y.clone() * z.clone()).mul_scalar(1.092_548_4),
                (z.clone() * z.clone())
                    .mul_scalar(3.0)
                    .sub_scalar(1.0)
                    .mul_scalar(0.315_391_57),
                (x.clone() * z).mul_scalar(1.092_548_4),
                (x.clone() * x - y.clone() * y).mul_scalar(0.546_274_2),
            ],
            1,
        );
        self.sh
            .clone()
            .swap_dims(1, 2)
            .matmul(basis)
            .reshape([b, 3, h, w])
    }

    /// L_s^n for map `k` of [`PHONG_EXPONENTS`] at the mirror reflection of the view direction
    /// (0, 0, 1) about `normal`.
    pub fn specular(&self, normal: Tensor<4>, k: usize) -> Tensor<4> {
        let [b, _, h, w] = normal.dims();
        let nz = normal.clone().narrow(1, 2, 1);
        // r = 2 (n·v) n − v with v = +Z.
        let r = normal * nz.mul_scalar(2.0) - self.view(b, h, w, &self.sh.device());
        let (x, y, z) = components(self.to_env(r));
        let u = x.atan2(z.neg()).div_scalar(std::f64::consts::TAU);
        let u = u.clone() - u.floor();
        let v = y.clamp(-1.0, 1.0).acos().div_scalar(std::f64::consts::PI);
        let map = &self.phong[k];
        let width = map.dims()[3] - 2;
        let gx = u
            .mul_scalar(2.0 * width as f64)
            .add_scalar(2.0)
            .div_scalar((width + 2) as f64)
            .sub_scalar(1.0);
        let gy = v.mul_scalar(2.0).sub_scalar(1.0);
        let grid = Tensor::cat(vec![gx.reshape([b, h, w, 1]), gy.reshape([b, h, w, 1])], 3);
        map.clone().grid_sample_2d(
            grid,
            GridSampleOptions::new(InterpolateMode::Bilinear)
                .with_padding_mode(GridSamplePaddingMode::Border)
                .with_align_corners(false),
        )
    }

    /// [B, 3, H*W] env-local directions of camera-space `d` [B, 3, H, W].
    fn to_env(&self, d: Tensor<4>) -> Tensor<3> {
        let [b, c, h, w] = d.dims();
        self.rotation.clone().matmul(d.reshape([b, c, h * w]))
    }

    fn view(&self, b: usize, h: usize, w: usize, device: &Device) -> Tensor<4> {
        Tensor::<1>::from_data(TensorData::new(vec![0f32, 0.0, 1.0], [3]), device)
            .reshape([1, 3, 1, 1])
            .expand([b, 3, h, w])
    }
}

fn components(e: Tensor<3>) -> (Tensor<3>, Tensor<3>, Tensor<3>) {
    (
        e.clone().narrow(1, 0, 1),
        e.clone().narrow(1, 1, 1),
        e.narrow(1, 2, 1),
    )
}
