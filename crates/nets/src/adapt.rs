//! Synthetic-to-real adaptation (paper section 4.3). A model trained on renders is frozen; the
//! albedo residual network f_Ā, a [`ResNet`], refines its albedo from the photo,
//! Ā = A + f_Ā(I, N, A), and Ā replaces A for f_S and f_R. Only f_Ā trains, on unpaired real
//! portraits, with self-supervised losses that keep the relighting the renders taught:
//! OLAT consistency, relative consistency, VGG similarity of Ā to A, identity and a GAN on R̄.
//!
//! The ablation "direct syn2real" instead adds the residual to the relit image:
//! R̄ = R + f(I, N, R) ([`AdaptTarget::Relit`]).

use burn::prelude::*;
use serde::{Deserialize, Serialize};

use crate::lightmap::LightBatch;
use crate::loss::masked_l1;
use crate::relight::{Decomposition, RelightNet, Relit};
use crate::resnet::{ResNet, ResNetConfig};
use crate::NetsError;

/// Where the adaptation network's residual goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AdaptTarget {
    /// The paper's method: a residual on the albedo, δĀ = f_Ā(I, N, A).
    Albedo,
    /// The ablation "direct syn2real": a residual on the relit image, δR̄ = f(I, N, R).
    Relit,
}

/// The weights of section 4.3's adaptation loss, the paper's (10, 10, 10, 1, 1). The identity
/// term needs a face-recognition network; the trainer runs dlib's (crate lightfarm-face).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdaptWeights {
    pub olat: f64,
    pub relative: f64,
    pub similarity: f64,
    pub identity: f64,
    pub gan: f64,
}

impl Default for AdaptWeights {
    fn default() -> Self {
        AdaptWeights {
            olat: 10.0,
            relative: 10.0,
            similarity: 10.0,
            identity: 1.0,
            gan: 1.0,
        }
    }
}

/// The trainable part of an adapted model.
#[derive(Module, Debug)]
pub struct Adapter {
    pub f: ResNet,
    #[module(skip)]
    pub target: AdaptTarget,
}

impl Adapter {
    /// The paper's f_Ā (32 channels, 9 blocks), its output starting at zero so the adapted
    /// model starts as the base model.
    pub fn new(target: AdaptTarget, device: &Device) -> Result<Adapter, NetsError> {
        Adapter::with_config(target, ResNetConfig::new(9, 3), device)
    }

    /// `cfg`'s channel counts are set here (I, N and A or R in; a residual out).
    pub fn with_config(
        target: AdaptTarget,
        cfg: ResNetConfig,
        device: &Device,
    ) -> Result<Adapter, NetsError> {
        let cfg = ResNetConfig {
            in_channels: 9,
            out_channels: 3,
            ..cfg
        };
        Ok(Adapter {
            f: cfg.init(device)?,
            target,
        })
    }

    /// Ā = A + f_Ā(I, N, A); with [`AdaptTarget::Relit`] the decomposition is kept.
    pub fn refine(&self, input: Tensor<4>, d: &Decomposition) -> Decomposition {
        match self.target {
            AdaptTarget::Albedo => {
                let delta = self.f.forward(Tensor::cat(
                    vec![input, d.normal.clone(), d.albedo.clone()],
                    1,
                ));
                Decomposition {
                    albedo: d.albedo.clone() + delta,
                    ..d.clone()
                }
            }
            AdaptTarget::Relit => d.clone(),
        }
    }

    /// The adapted model's output under `light`: `base` renders the refined decomposition
    /// (albedo target), or its output gets f's residual (relit target).
    pub fn relight(
        &self,
        base: &RelightNet,
        input: Tensor<4>,
        mask: Tensor<4>,
        light: &LightBatch,
        refined: &Decomposition,
    ) -> Relit {
        let out = base.render(input.clone(), mask.clone(), light, refined);
        match self.target {
            AdaptTarget::Albedo => out,
            AdaptTarget::Relit => {
                let delta = self.f.forward(Tensor::cat(
                    vec![input, refined.normal.clone(), out.relit.clone()],
                    1,
                ));
                Relit {
                    relit: (out.relit.clone() + delta) * mask,
                    ..out
                }
            }
        }
    }
}

/// OLAT consistency, ‖(R̄_o1 + R̄_o2) − R̄_o1+o2‖₁ over the foreground: relighting is linear
/// in the light, so two lights relit separately and summed must equal both relit at once.
pub fn olat_consistency(
    r_o1: Tensor<4>,
    r_o2: Tensor<4>,
    r_o12: Tensor<4>,
    mask: Tensor<4>,
) -> Tensor<1> {
    masked_l1(r_o1 + r_o2, r_o12, mask)
}

/// Relative consistency, ‖(R_i − R_j) − (R̄_i − R̄_j)‖₁: the change between two lightings is
/// what the base model (R, no gradient) says, so adaptation changes appearance, not lighting.
pub fn relative_consistency(
    r_i: Tensor<4>,
    r_j: Tensor<4>,
    rbar_i: Tensor<4>,
    rbar_j: Tensor<4>,
    mask: Tensor<4>,
) -> Tensor<1> {
    masked_l1(r_i.detach() - r_j.detach(), rbar_i - rbar_j, mask)
}
