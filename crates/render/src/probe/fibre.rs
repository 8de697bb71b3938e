//! Probes of the fibre model (shaders/inc/hair.wgsl), modes 7–9 of probe.wgsl.

use super::{BsdfProbeSample, Probe};
use crate::RenderError;

/// A fibre as hair.wgsl takes it; directions are in its frame (x along the fibre).
#[derive(Clone, Copy, Debug)]
pub struct ProbeFibre {
    /// Absorption per unit radius.
    pub sigma_a: [f32; 3],
    /// Longitudinal roughness βm.
    pub beta_m: f32,
    /// Azimuthal roughness βn.
    pub beta_n: f32,
    /// Cuticle tilt, radians.
    pub alpha: f32,
    pub ior: f32,
    /// Where the ray met the cross-section, in [-1, 1].
    pub h: f32,
}

impl Default for ProbeFibre {
    fn default() -> Self {
        ProbeFibre {
            sigma_a: [0.0; 3],
            beta_m: 0.3,
            beta_n: 0.3,
            alpha: 2f32.to_radians(),
            ior: 1.55,
            h: 0.0,
        }
    }
}

impl ProbeFibre {
    fn input(&self, wo: [f32; 3]) -> Vec<[f32; 4]> {
        let s = self.sigma_a;
        vec![
            [s[0], s[1], s[2], self.h],
            [self.beta_m, self.beta_n, self.alpha, self.ior],
            [wo[0], wo[1], wo[2], 0.0],
        ]
    }
}

impl Probe {
    /// `n` samples of the fibre for direction `wo`.
    pub fn fibre_samples(
        &self,
        f: &ProbeFibre,
        wo: [f32; 3],
        n: usize,
        seed: u32,
    ) -> Result<Vec<BsdfProbeSample>, RenderError> {
        let out = self.simple(7, f.input(wo), n, 2 * n, seed)?;
        Ok(out.chunks_exact(2).map(BsdfProbeSample::decode).collect())
    }

    /// (f·cos, pdf) of the fibre for each `wi`.
    pub fn fibre_eval(
        &self,
        f: &ProbeFibre,
        wo: [f32; 3],
        wis: &[[f32; 3]],
    ) -> Result<Vec<([f32; 3], f32)>, RenderError> {
        let mut input = f.input(wo);
        input.extend(wis.iter().map(|w| [w[0], w[1], w[2], 0.0]));
        let out = self.simple(8, input, wis.len(), wis.len(), 0)?;
        Ok(out.iter().map(|v| ([v[0], v[1], v[2]], v[3])).collect())
    }

    /// `n` one-sample estimates of the fibre's albedo ∫ f·cos dωi, each for its own uniformly
    /// random wo and h (`f.h` is ignored): wi drawn half from the fibre's sampler and half
    /// uniformly, weighted by the mixture of both densities. Their mean is the albedo only if the
    /// sampler's reported pdf is its true density, so this tests f and the sampler together.
    pub fn fibre_furnace(
        &self,
        f: &ProbeFibre,
        n: usize,
        seed: u32,
    ) -> Result<Vec<[f32; 3]>, RenderError> {
        let out = self.simple(9, f.input([0.0, 0.0, 1.0]), n, n, seed)?;
        Ok(out.iter().map(|v| [v[0], v[1], v[2]]).collect())
    }
}
