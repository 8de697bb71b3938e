//! Losses of section 4.2: L1 on N, N_l, A and the relit image (in log(1 + x)), ‖δR‖₁, a PatchGAN
//! (least-squares) adversarial loss on R, and the perceptual (VGG) loss on R when the user
//! supplies VGG16 weights ([`crate::vgg`]; none ship with the project).

use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::PaddingConfig2d;
use burn::prelude::*;
use burn::tensor::activation::leaky_relu;
use serde::{Deserialize, Serialize};

use crate::precision::compute_in;
use crate::relight::Relit;
use crate::vgg::{perceptual_loss, Vgg16};

/// Loss weights. The paper does not list them; these follow Total Relighting's balance (all
/// reconstruction terms equal, a small adversarial term) with δR regularised at a tenth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LossWeights {
    pub normal: f64,
    pub normal_lens: f64,
    pub albedo: f64,
    pub relit: f64,
    pub residual: f64,
    pub adversarial: f64,
    /// Weight of the VGG perceptual loss; used only when VGG weights are given.
    pub perceptual: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        LossWeights {
            normal: 1.0,
            normal_lens: 1.0,
            albedo: 1.0,
            relit: 1.0,
            residual: 0.1,
            adversarial: 0.01,
            perceptual: 1.0,
        }
    }
}

/// Ground truth for one batch, all [B, C, H, W].
#[derive(Clone, Debug)]
pub struct Targets {
    pub normal: Tensor<4>,
    pub normal_lens: Tensor<4>,
    pub albedo: Tensor<4>,
    pub relit: Tensor<4>,
    pub mask: Tensor<4>,
}

/// Each term (unweighted) and the weighted total; the terms are what the loss curves show.
#[derive(Clone, Debug)]
pub struct GeneratorLoss {
    pub total: Tensor<1>,
    pub normal: Tensor<1>,
    pub normal_lens: Tensor<1>,
    pub albedo: Tensor<1>,
    pub relit: Tensor<1>,
    pub residual: Option<Tensor<1>>,
    pub adversarial: Option<Tensor<1>>,
    pub perceptual: Option<Tensor<1>>,
}

/// sign(x)·log(1 + |x|).
pub fn symlog(x: Tensor<4>) -> Tensor<4> {
    x.clone().sign() * x.abs().log1p()
}

/// Mean absolute error over the pixels where `mask` > 0 (mask-weighted), per channel.
pub fn masked_l1(pred: Tensor<4>, target: Tensor<4>, mask: Tensor<4>) -> Tensor<1> {
    let channels = pred.dims()[1] as f64;
    let num = ((pred - target).abs() * mask.clone()).sum();
    let den = mask.sum().mul_scalar(channels).add_scalar(1e-6);
    num / den
}

pub fn generator_loss(
    out: &Relit,
    t: &Targets,
    w: &LossWeights,
    critic: Option<&PatchGan>,
    vgg: Option<&Vgg16>,
) -> GeneratorLoss {
    let normal = masked_l1(out.normal.clone(), t.normal.clone(), t.mask.clone());
    let normal_lens = masked_l1(
        out.normal_lens.clone(),
        t.normal_lens.clone(),
        t.mask.clone(),
    );
    let albedo = masked_l1(out.albedo.clone(), t.albedo.clone(), t.mask.clone());
    // The relit image is compared through sign(x)·log(1 + |x|): HDR targets under a sun span
    // 10^3, and a linear L1 spent the network on highlights no display shows (and diverged at
    // high lr); unlike a clamp, the signed form still pulls negative predictions up.
    let relit = masked_l1(
        symlog(out.relit.clone()),
        symlog(t.relit.clone()),
        t.mask.clone(),
    );
    let mut total = normal.clone().mul_scalar(w.normal)
        + normal_lens.clone().mul_scalar(w.normal_lens)
        + albedo.clone().mul_scalar(w.albedo)
        + relit.clone().mul_scalar(w.relit);
    let residual = out.residual.as_ref().map(|r| {
        let zero = r.zeros_like();
        masked_l1(r.clone(), zero, t.mask.clone())
    });
    if let Some(r) = &residual {
        total = total + r.clone().mul_scalar(w.residual);
    }
    let adversarial = critic.filter(|_| w.adversarial > 0.0).map(|d| {
        // Least-squares GAN: the generator wants the critic to say 1.
        d.forward(out.relit.clone(), t.mask.clone())
            .sub_scalar(1.0)
            .powi_scalar(2)
            .mean()
    });
    if let Some(a) = &adversarial {
        total = total + a.clone().mul_scalar(w.adversarial);
    }
    let perceptual = vgg
        .filter(|_| w.perceptual > 0.0)
        .map(|v| perceptual_loss(v, out.relit.clone(), t.relit.clone(), t.mask.clone()));
    if let Some(p) = &perceptual {
        total = total + p.clone().mul_scalar(w.perceptual);
    }
    GeneratorLoss {
        total,
        normal,
        normal_lens,
        albedo,
        relit,
        residual,
        adversarial,
        perceptual,
    }
}

/// Least-squares critic loss: real patches → 1, generated → 0.
pub fn critic_loss(
    critic: &PatchGan,
    real: Tensor<4>,
    fake: Tensor<4>,
    mask: Tensor<4>,
) -> Tensor<1> {
    let r = critic
        .forward(real, mask.clone())
        .sub_scalar(1.0)
        .powi_scalar(2)
        .mean();
    let f = critic.forward(fake, mask).powi_scalar(2).mean();
    (r + f).mul_scalar(0.5)
}

#[derive(Config, Debug)]
pub struct PatchGanConfig {
    /// Channels of the first layer, doubled at each of the three stride-2 layers.
    #[config(default = 32)]
    pub width: usize,
}

impl PatchGanConfig {
    pub fn init(&self, device: &Device) -> PatchGan {
        let w = self.width.max(1);
        let down = |i, o| {
            Conv2dConfig::new([i, o], [4, 4])
                .with_stride([2, 2])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(device)
        };
        PatchGan {
            layers: vec![down(4, w), down(w, 2 * w), down(2 * w, 4 * w)],
            head: Conv2dConfig::new([4 * w, 1], [3, 3])
                .with_padding(PaddingConfig2d::Same)
                .init(device),
        }
    }
}

/// A 70×70-style PatchGAN (three stride-2 4×4 convolutions and a 1-channel head) judging the
/// tone-mapped relit image with its mask.
#[derive(Module, Debug)]
pub struct PatchGan {
    layers: Vec<Conv2d>,
    head: Conv2d,
}

impl PatchGan {
    /// Per-patch realness scores [B, 1, H/8, W/8]; HDR input is compressed with x/(1+x).
    /// Computes in its weights' precision and answers in `image`'s ([`crate::precision`]).
    pub fn forward(&self, image: Tensor<4>, mask: Tensor<4>) -> Tensor<4> {
        let image = image.clone().clamp_min(0.0) / image.clamp_min(0.0).add_scalar(1.0);
        let x = Tensor::cat(vec![image, mask], 1);
        compute_in(x, self.head.weight.val().dtype(), |mut x| {
            for layer in &self.layers {
                x = leaky_relu(layer.forward(x), 0.2);
            }
            self.head.forward(x)
        })
    }
}
