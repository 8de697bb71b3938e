//! Packs environment lights (HDRI + rotation/flip + sampling tables) into the flat arrays of
//! `shaders/inc/env.wgsl`.

use lightfarm_light::{EnvSampler, EnvTransform, Hdri};

use crate::gpu_types::EnvDesc;

/// One lighting of a render: an HDRI and how it is oriented.
#[derive(Clone, Debug)]
pub struct EnvLight {
    /// What the user called it (file name), recorded in the output's metadata.
    pub name: String,
    pub hdri: Hdri,
    pub transform: EnvTransform,
}

#[derive(Default)]
pub struct PackedEnv {
    pub texels: Vec<[f32; 4]>,
    pub dist: Vec<f32>,
    pub desc: Vec<EnvDesc>,
}

pub fn pack_envs(lights: &[EnvLight]) -> PackedEnv {
    let mut out = PackedEnv::default();
    for light in lights {
        let hdri = &light.hdri;
        let sampler = EnvSampler::new(hdri);
        let dist = &sampler.dist;
        let texel_offset = out.texels.len() as u32;
        out.texels
            .extend(hdri.texels.iter().map(|t| [t[0], t[1], t[2], 0.0]));
        let cond_func_offset = out.dist.len() as u32;
        for row in &dist.conditional {
            out.dist.extend_from_slice(&row.func);
        }
        let cond_cdf_offset = out.dist.len() as u32;
        for row in &dist.conditional {
            out.dist.extend_from_slice(&row.cdf);
        }
        let marg_func_offset = out.dist.len() as u32;
        out.dist.extend_from_slice(&dist.marginal.func);
        let marg_cdf_offset = out.dist.len() as u32;
        out.dist.extend_from_slice(&dist.marginal.cdf);
        let theta = light.transform.rotation_deg.to_radians();
        out.desc.push(EnvDesc {
            width: hdri.width,
            height: hdri.height,
            texel_offset,
            cond_func_offset,
            cond_cdf_offset,
            marg_func_offset,
            marg_cdf_offset,
            flip: light.transform.flip as u32,
            cos_rot: theta.cos(),
            sin_rot: theta.sin(),
            marg_integral: dist.marginal.integral,
            _pad: 0.0,
        });
    }
    out
}
