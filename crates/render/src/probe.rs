//! Runs the shaders' own sampling routines and traversal on the device, so the tests check the
//! code that renders rather than a CPU re-implementation of it (shaders/kernels/probe.wgsl and
//! trace_rays.wgsl).

use std::sync::Arc;

use crate::bound::Bound;
use crate::gpu_env::{pack_lightings, Lighting, PackedEnv};
use crate::gpu_scene::PackedScene;
use crate::gpu_types::{Params, Push};
use crate::shaders;
use crate::vulkan::{ComputeKernel, GpuBuffer, GpuContext};
use crate::RenderError;

mod fibre;
pub use fibre::ProbeFibre;

/// The largest batch one probe call accepts: one dispatch of 64-wide groups, of which Vulkan
/// guarantees 65,535 per dimension (lavapipe allows no more).
pub const MAX_PROBE: usize = 64 * 65_535;

/// Surface parameters as the shaders' `Surface` struct sees them (α, not roughness). The
/// fields after `ior` are the layered model's (used when `model` is not 0, the glTF mapping).
#[derive(Clone, Copy, Debug)]
pub struct ProbeSurface {
    pub base: [f32; 3],
    pub metallic: f32,
    pub alpha: f32,
    pub specular: f32,
    pub spec_color: [f32; 3],
    pub transmission: f32,
    pub ior: f32,
    pub model: u32,
    pub sss: f32,
    pub sss_color: [f32; 3],
    pub sss_mfp: [f32; 3],
    pub sss_g: f32,
    pub coat: f32,
    pub coat_color: [f32; 3],
    pub coat_alpha: f32,
    pub coat_ior: f32,
    pub sheen: f32,
    pub sheen_color: [f32; 3],
    pub sheen_rough: f32,
}

impl Default for ProbeSurface {
    /// A white glTF dielectric with the layered parameters off.
    fn default() -> Self {
        ProbeSurface {
            base: [1.0; 3],
            metallic: 0.0,
            alpha: 0.25,
            specular: 1.0,
            spec_color: [1.0; 3],
            transmission: 0.0,
            ior: 1.5,
            model: 0,
            sss: 0.0,
            sss_color: [1.0; 3],
            sss_mfp: [0.01; 3],
            sss_g: 0.0,
            coat: 0.0,
            coat_color: [1.0; 3],
            coat_alpha: 0.01,
            coat_ior: 1.5,
            sheen: 0.0,
            sheen_color: [1.0; 3],
            sheen_rough: 0.3,
        }
    }
}

#[derive(Clone, Copy, Debug)]
pub struct BsdfProbeSample {
    pub wi: [f32; 3],
    pub pdf: f32,
    pub weight: [f32; 3],
    pub valid: bool,
    pub delta: bool,
    /// The subsurface lobe was picked (no direction; `weight` is what enters the medium).
    pub subsurface: bool,
}

impl BsdfProbeSample {
    /// Decodes the two vec4s a sampling probe mode writes: (wi, pdf), (weight, flags) with
    /// flag bits 1 valid, 2 delta, 4 subsurface (the fibre mode writes only the valid bit).
    pub(crate) fn decode(c: &[[f32; 4]]) -> BsdfProbeSample {
        let flags = c[1][3] as u32;
        BsdfProbeSample {
            wi: [c[0][0], c[0][1], c[0][2]],
            pdf: c[0][3],
            weight: [c[1][0], c[1][1], c[1][2]],
            valid: flags & 1 != 0,
            delta: flags & 2 != 0,
            subsurface: flags & 4 != 0,
        }
    }
}

/// (single-scattering albedo α, the forward fit's slab reflectance of α) per channel.
pub type AlbedoPair = ([f32; 3], [f32; 3]);

/// A closest hit as the shader reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuHit {
    pub t: f32,
    pub instance: u32,
    pub slot: u32,
}

/// One probe dispatch: what goes in, how much comes out.
struct Job {
    input: Vec<[f32; 4]>,
    out_vec4s: usize,
    push: Push,
    seed: u32,
}

pub struct Probe {
    ctx: Arc<GpuContext>,
    probe: ComputeKernel,
    trace: ComputeKernel,
    tables: GpuBuffer,
    /// 0, or 1 + the axis of the deliberately biased samplers (see [`Probe::biased`]).
    mutate: u32,
}

fn check_len(n: usize) -> Result<(), RenderError> {
    if n == 0 || n > MAX_PROBE {
        return Err(RenderError::InvalidSettings(format!(
            "probe batch of {n}: use 1..={MAX_PROBE}"
        )));
    }
    Ok(())
}

impl Probe {
    pub fn new(ctx: &Arc<GpuContext>) -> Result<Probe, RenderError> {
        let push = std::mem::size_of::<Push>() as u32;
        Ok(Probe {
            ctx: ctx.clone(),
            probe: ComputeKernel::with_bindings(
                ctx,
                "probe",
                &shaders::probe(),
                &shaders::BINDINGS,
                push,
            )?,
            trace: ComputeKernel::with_bindings(
                ctx,
                "trace_rays",
                &shaders::trace_rays(),
                &shaders::BINDINGS,
                push,
            )?,
            tables: crate::tables::compute(ctx)?,
            mutate: 0,
        })
    }

    /// The directional-albedo tables the kernels read (see [`crate::tables`]).
    pub fn tables(&self) -> Result<Vec<[f32; 4]>, RenderError> {
        crate::tables::read(&self.tables)
    }

    /// Makes the BSDF and environment samplers deliberately wrong (`Some(axis)`) or right again
    /// (`None`), for showing that a statistical test rejects a biased sampler: a sample whose
    /// direction has a negative component on `axis` (0 = x, 1 = y, 2 = z; the local frame for
    /// BSDFs, world space for the environment) is redrawn with probability 0.1, so the sampled
    /// density is off by ±5% of the reported pdf when that half holds half the probability.
    /// The pdfs (`bsdf_eval`, `env_eval`) stay correct.
    pub fn set_bias(&mut self, axis: Option<usize>) {
        self.mutate = axis.map_or(0, |a| 1 + a.min(2) as u32);
    }

    fn run(
        &self,
        kernel: &ComputeKernel,
        scene: &PackedScene,
        env: &PackedEnv,
        job: Job,
    ) -> Result<Vec<[f32; 4]>, RenderError> {
        let Job {
            input,
            out_vec4s,
            mut push,
            seed,
        } = job;
        push.mutate = self.mutate;
        let params = Params {
            seed,
            tlas_node_offset: scene.tlas_node_offset,
            scene_flags: scene.scene_flags(),
            ..Default::default()
        };
        let bound = Bound::upload(&self.ctx, &params, scene, env)?;
        let dummy = |label| GpuBuffer::zeroed(&self.ctx, label, 16);
        let (lit, aux, counters) = (dummy("unused")?, dummy("unused")?, dummy("unused")?);
        let pin = GpuBuffer::from_slice(&self.ctx, "probe input", &input)?;
        let pout = GpuBuffer::zeroed(&self.ctx, "probe output", (out_vec4s as u64) * 16)?;
        let bindings = bound.bindings([&lit, &aux, &counters, &pin, &pout], &self.tables);
        kernel.dispatch_resources(
            &bindings,
            bytemuck::bytes_of(&push),
            [(push.count).div_ceil(64), 1, 1],
        )?;
        let mut out: Vec<[f32; 4]> = pout.read()?;
        out.truncate(out_vec4s);
        Ok(out)
    }

    fn surface_input(s: &ProbeSurface, wo: [f32; 3]) -> Vec<[f32; 4]> {
        let v = |c: [f32; 3], w: f32| [c[0], c[1], c[2], w];
        vec![
            v(s.base, s.metallic),
            [s.alpha, s.specular, s.transmission, s.ior],
            v(s.spec_color, s.model as f32),
            v(s.sss_color, s.sss),
            v(s.sss_mfp, s.sss_g),
            v(s.coat_color, s.coat),
            [s.coat_alpha, s.coat_ior, s.sheen, s.sheen_rough],
            v(s.sheen_color, 0.0),
            v(wo, 0.0),
        ]
    }

    /// `n` samples of the BSDF for direction `wo` (local frame, z = normal).
    pub fn bsdf_samples(
        &self,
        s: &ProbeSurface,
        wo: [f32; 3],
        n: usize,
        seed: u32,
    ) -> Result<Vec<BsdfProbeSample>, RenderError> {
        check_len(n)?;
        let push = Push {
            mode: 0,
            count: n as u32,
            ..Default::default()
        };
        let input = Self::surface_input(s, wo);
        let out = self.run(
            &self.probe,
            &PackedScene::empty(),
            &PackedEnv::default(),
            Job {
                input,
                out_vec4s: 2 * n,
                push,
                seed,
            },
        )?;
        Ok(out.chunks_exact(2).map(BsdfProbeSample::decode).collect())
    }

    /// (f·cos, pdf) of the BSDF for each `wi`.
    pub fn bsdf_eval(
        &self,
        s: &ProbeSurface,
        wo: [f32; 3],
        wis: &[[f32; 3]],
    ) -> Result<Vec<([f32; 3], f32)>, RenderError> {
        check_len(wis.len())?;
        let mut input = Self::surface_input(s, wo);
        input.extend(wis.iter().map(|w| [w[0], w[1], w[2], 0.0]));
        let push = Push {
            mode: 1,
            count: wis.len() as u32,
            ..Default::default()
        };
        let out = self.run(
            &self.probe,
            &PackedScene::empty(),
            &PackedEnv::default(),
            Job {
                input,
                out_vec4s: wis.len(),
                push,
                seed: 0,
            },
        )?;
        Ok(out.iter().map(|v| ([v[0], v[1], v[2]], v[3])).collect())
    }

    /// `n` (world direction, solid-angle pdf) samples of the environment light.
    pub fn env_samples<'a>(
        &self,
        light: impl Into<Lighting<'a>>,
        n: usize,
        seed: u32,
    ) -> Result<Vec<([f32; 3], f32)>, RenderError> {
        check_len(n)?;
        let env = pack_lightings(&[light.into()]);
        let push = Push {
            mode: 2,
            count: n as u32,
            ..Default::default()
        };
        let out = self.run(
            &self.probe,
            &PackedScene::empty(),
            &env,
            Job {
                input: vec![[0.0; 4]],
                out_vec4s: n,
                push,
                seed,
            },
        )?;
        Ok(out.iter().map(|v| ([v[0], v[1], v[2]], v[3])).collect())
    }

    /// (pdf, radiance) of the environment light for each world direction.
    pub fn env_eval<'a>(
        &self,
        light: impl Into<Lighting<'a>>,
        dirs: &[[f32; 3]],
    ) -> Result<Vec<(f32, [f32; 3])>, RenderError> {
        check_len(dirs.len())?;
        let env = pack_lightings(&[light.into()]);
        let input: Vec<[f32; 4]> = dirs.iter().map(|d| [d[0], d[1], d[2], 0.0]).collect();
        let push = Push {
            mode: 3,
            count: dirs.len() as u32,
            ..Default::default()
        };
        let out = self.run(
            &self.probe,
            &PackedScene::empty(),
            &env,
            Job {
                input,
                out_vec4s: dirs.len(),
                push,
                seed: 0,
            },
        )?;
        Ok(out.iter().map(|v| (v[0], [v[1], v[2], v[3]])).collect())
    }

    /// Closest hits of world-space rays (origin, direction, tmin, tmax) against `scene`.
    pub fn trace(
        &self,
        scene: &PackedScene,
        rays: &[([f32; 3], [f32; 3], f32, f32)],
    ) -> Result<Vec<Option<GpuHit>>, RenderError> {
        check_len(rays.len())?;
        let mut input = Vec::with_capacity(2 * rays.len());
        for (o, d, tmin, tmax) in rays {
            input.push([o[0], o[1], o[2], *tmin]);
            input.push([d[0], d[1], d[2], *tmax]);
        }
        let push = Push {
            count: rays.len() as u32,
            ..Default::default()
        };
        let out = self.run(
            &self.trace,
            scene,
            &PackedEnv::default(),
            Job {
                input,
                out_vec4s: rays.len(),
                push,
                seed: 0,
            },
        )?;
        Ok(out
            .iter()
            .map(|v| {
                (v[0] >= 0.0).then(|| GpuHit {
                    t: v[0],
                    instance: v[1].to_bits(),
                    slot: v[2].to_bits(),
                })
            })
            .collect())
    }

    fn simple(
        &self,
        mode: u32,
        input: Vec<[f32; 4]>,
        n: usize,
        out_vec4s: usize,
        seed: u32,
    ) -> Result<Vec<[f32; 4]>, RenderError> {
        check_len(n)?;
        let push = Push {
            mode,
            count: n as u32,
            ..Default::default()
        };
        self.run(
            &self.probe,
            &PackedScene::empty(),
            &PackedEnv::default(),
            Job {
                input,
                out_vec4s,
                push,
                seed,
            },
        )
    }

    /// `n` free flights of the subsurface walk's spectral-MIS distance sampler for a medium of
    /// subsurface colour `color`, anisotropy `g` and mean free path `mfp`, with the walk's
    /// throughput `throughput`: (t, collision pdf at t, probability of flying past t, channel).
    pub fn sss_flights(
        &self,
        throughput: [f32; 3],
        color: [f32; 3],
        g: f32,
        mfp: [f32; 3],
        n: usize,
        seed: u32,
    ) -> Result<Vec<[f32; 4]>, RenderError> {
        let input = vec![
            [throughput[0], throughput[1], throughput[2], 0.0],
            [color[0], color[1], color[2], g],
            [mfp[0], mfp[1], mfp[2], 0.0],
        ];
        self.simple(4, input, n, n, seed)
    }

    /// `n` Henyey–Greenstein scatterings of propagation direction `dir`: (new direction, pdf).
    pub fn hg_samples(
        &self,
        dir: [f32; 3],
        g: f32,
        n: usize,
        seed: u32,
    ) -> Result<Vec<([f32; 3], f32)>, RenderError> {
        let out = self.simple(5, vec![[dir[0], dir[1], dir[2], g]], n, n, seed)?;
        Ok(out.iter().map(|v| ([v[0], v[1], v[2]], v[3])).collect())
    }

    /// The shader's albedo inversion for (subsurface colour, g): (single-scattering albedo α,
    /// the forward fit's slab reflectance of α).
    pub fn sss_albedo(&self, colors: &[([f32; 3], f32)]) -> Result<Vec<AlbedoPair>, RenderError> {
        let input = colors.iter().map(|(c, g)| [c[0], c[1], c[2], *g]).collect();
        let out = self.simple(6, input, colors.len(), 2 * colors.len(), 0)?;
        Ok(out
            .chunks_exact(2)
            .map(|c| ([c[0][0], c[0][1], c[0][2]], [c[1][0], c[1][1], c[1][2]]))
            .collect())
    }
}
