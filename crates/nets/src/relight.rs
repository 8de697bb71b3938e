//! The relighting network of section 4.2: f_N → (N, N_l), f_A → A, f_S → five Phong weights,
//! f_R → (C_d, C_s, δR) with R = A⊙(C_d·L_d + C_s·L_s) + δR, or — the paper's ablation "w/o
//! improved render net" — f_R → R directly.

use burn::prelude::*;
use burn::tensor::activation::{sigmoid, softmax, softplus, tanh};
use serde::{Deserialize, Serialize};

use crate::lightmap::{LightBatch, LENS_MAP};
use crate::unet::{size_multiple, UNet, UNetConfig};
use crate::NetsError;

/// How f_R produces the relit image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RenderNet {
    /// The paper's improved render net: coefficients for a fixed shading function plus a residual.
    Decomposed,
    /// Total Relighting's black box (the ablation).
    Blackbox,
}

#[derive(Config, Debug)]
pub struct RelightConfig {
    /// UNet channel widths per level, shared by the four networks.
    #[config(default = "vec![32, 64, 128, 256, 512]")]
    pub widths: Vec<usize>,
    #[config(default = "RenderNet::Decomposed")]
    pub render_net: RenderNet,
}

impl RelightConfig {
    /// A few thousand parameters per network: what CPU tests and the demo train.
    pub fn tiny() -> RelightConfig {
        RelightConfig::new().with_widths(vec![8, 16, 32])
    }

    pub fn validate(&self) -> Result<(), NetsError> {
        if self.widths.is_empty()
            || self.widths.len() > 8
            || self.widths.iter().any(|&w| w == 0 || w > 4096)
        {
            return Err(NetsError::Config(format!(
                "widths {:?}: give 1 to 8 levels of 1..=4096 channels, e.g. [32, 64, 128, 256, 512]",
                self.widths
            )));
        }
        Ok(())
    }

    /// Image sides must be multiples of this.
    pub fn size_multiple(&self) -> usize {
        size_multiple(self.widths.len())
    }

    pub fn init(&self, device: &Device) -> Result<RelightNet, NetsError> {
        self.validate()?;
        let unet = |i, o| UNetConfig::new(i, o, self.widths.clone()).init(device);
        let render_out = match self.render_net {
            RenderNet::Decomposed => 9,
            RenderNet::Blackbox => 3,
        };
        Ok(RelightNet {
            f_n: unet(3, 6),
            f_a: unet(6, 3),
            // I, A, L_s^{1,16,32,64}, L_{s,l}^{1024}.
            f_s: unet(3 + 3 + 15, 5),
            // I, A, L_d, L_s.
            f_r: unet(12, render_out),
            render_net: self.render_net,
        })
    }
}

#[derive(Module, Debug)]
pub struct RelightNet {
    pub f_n: UNet,
    pub f_a: UNet,
    pub f_s: UNet,
    pub f_r: UNet,
    #[module(skip)]
    pub render_net: RenderNet,
}

/// Everything the forward pass produces; the intermediates are what `relight` shows and the
/// losses supervise.
#[derive(Clone, Debug)]
pub struct Relit {
    pub normal: Tensor<4>,
    pub normal_lens: Tensor<4>,
    pub albedo: Tensor<4>,
    /// [B, 5, H, W] softmax weights of L_s^{1,16,32,64} and L_{s,l}^{1024}.
    pub weights: Tensor<4>,
    pub diffuse: Tensor<4>,
    pub specular: Tensor<4>,
    /// δR of the decomposed render net (None for the black box).
    pub residual: Option<Tensor<4>>,
    pub relit: Tensor<4>,
}

/// What f_N and f_A infer from a portrait, independent of the target lighting: computed once
/// and rendered under as many lightings as needed ([`RelightNet::render`]).
#[derive(Clone, Debug)]
pub struct Decomposition {
    pub normal: Tensor<4>,
    pub normal_lens: Tensor<4>,
    pub albedo: Tensor<4>,
}

impl RelightNet {
    /// `input`: [B, 3, H, W] masked, exposure-normalised foreground; `mask`: [B, 1, H, W].
    pub fn forward(&self, input: Tensor<4>, mask: Tensor<4>, light: &LightBatch) -> Relit {
        let d = self.decompose(input.clone());
        self.render(input, mask, light, &d)
    }

    /// f_N → (N, N_l), then f_A → A.
    pub fn decompose(&self, input: Tensor<4>) -> Decomposition {
        let geometry = self.f_n.forward(input.clone());
        let normal = unit(tanh(geometry.clone().narrow(1, 0, 3)));
        let normal_lens = unit(tanh(geometry.narrow(1, 3, 3)));
        let albedo = sigmoid(
            self.f_a
                .forward(Tensor::cat(vec![input, normal.clone()], 1)),
        );
        Decomposition {
            normal,
            normal_lens,
            albedo,
        }
    }

    /// f_S and f_R under `light`, from a decomposition (the network's own, or one whose albedo
    /// the synthetic-to-real network refined).
    pub fn render(
        &self,
        input: Tensor<4>,
        mask: Tensor<4>,
        light: &LightBatch,
        d: &Decomposition,
    ) -> Relit {
        let (normal, normal_lens, albedo) =
            (d.normal.clone(), d.normal_lens.clone(), d.albedo.clone());
        // Light maps are looked up, not learned through: the normals get their own supervision
        // and bilinear lookups have no useful gradient across texels.
        let n = normal.clone().detach();
        let diffuse = light.diffuse(n.clone());
        let mut spec: Vec<Tensor<4>> = (0..LENS_MAP)
            .map(|k| light.specular(n.clone(), k))
            .collect();
        spec.push(light.specular(normal_lens.clone().detach(), LENS_MAP));

        // Networks see light maps through log(1 + x): a sun reflected in the 1024 map is 10^4
        // times the mean, and raw values made training diverge; shading uses the raw maps.
        let mut s_in = vec![input.clone(), albedo.clone()];
        s_in.extend(spec.iter().map(|l| l.clone().log1p()));
        let weights = softmax(self.f_s.forward(Tensor::cat(s_in, 1)), 1);
        let specular = spec
            .into_iter()
            .enumerate()
            .map(|(k, l)| l * weights.clone().narrow(1, k, 1))
            .reduce(|a, b| a + b)
            .expect("five specular maps");

        let out = self.f_r.forward(Tensor::cat(
            vec![
                input,
                albedo.clone(),
                diffuse.clone().log1p(),
                specular.clone().log1p(),
            ],
            1,
        ));
        let (relit, residual) = match self.render_net {
            RenderNet::Decomposed => {
                let c_d = softplus(out.clone().narrow(1, 0, 3), 1.0);
                let c_s = softplus(out.clone().narrow(1, 3, 3), 1.0);
                let residual = out.narrow(1, 6, 3);
                let coarse = albedo.clone() * (c_d * diffuse.clone() + c_s * specular.clone());
                (coarse + residual.clone(), Some(residual))
            }
            RenderNet::Blackbox => (out, None),
        };
        Relit {
            normal,
            normal_lens,
            albedo,
            weights,
            diffuse,
            specular,
            residual,
            relit: relit * mask,
        }
    }
}

/// Unit vectors along dim 1; the epsilon keeps the gradient finite at zero.
fn unit(v: Tensor<4>) -> Tensor<4> {
    let len = v.clone().powi_scalar(2).sum_dim(1).add_scalar(1e-8).sqrt();
    v / len
}
