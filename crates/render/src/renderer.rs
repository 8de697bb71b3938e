//! Dispatches the integrator: uploads a packed scene and its lightings, runs the samples in
//! chunks (so progress is visible and no single dispatch runs for minutes), and resolves the
//! accumulators into the sample's passes.

use std::sync::Arc;
use std::time::Instant;

use crate::bound::Bound;
use crate::counters::{TraversalCounts, TC_FIRST, TC_WORDS};
use crate::gpu_env::{pack_lightings, EnvLight, Lighting, PackedEnv};
use crate::gpu_scene::PackedScene;
use crate::gpu_types::{Params, Push, NEE_MIXTURE, PASS_VEC4S};
use crate::passes::{LitPasses, Pass};
use crate::render_output::AuxImages;
pub use crate::render_output::{Progress, RenderOutput, RenderStats};
use crate::schedule::{LightingSchedule, WalkSchedule};
use crate::settings::camera_params;
pub use crate::settings::{RenderSettings, MAX_LIGHTS, MAX_SIZE, MAX_SPP};
use crate::shaders;
use crate::vulkan::{ComputeKernel, DeviceInfo, DeviceRequest, GpuBuffer, GpuContext};
use crate::RenderError;

/// Paths per round of the walk-dispatch schedule: its job slots (JOB_VEC4S vec4s plus one
/// queue entry each, 192 bytes) must fit lavapipe's 128 MiB storage-buffer range.
const DISPATCH_PATHS: u64 = 1 << 19;
const JOB_BYTES: u64 = (11 + 1) * 16;
const STAGE_PATHS: u32 = 1;
const STAGE_WALKS: u32 = 2;
const STAGE_GATHER: u32 = 3;
const STAGE_LOOP_PROBE: u32 = 4;

/// How many times the integrator's `report_cut_loops` loop has to turn: a driver that has
/// ended the invocation's loops still turns it twice (Mesa 22 peels one turn), so the check
/// asks for more. It is read from `params` so that no compiler can unroll the loop.
const LOOP_CHECK_TURNS: u32 = 8;
/// The turns of the same loop in the start-up probe (STAGE_LOOP_PROBE): above the 65,535 of
/// all loops together that Mesa 22's llvmpipe allows an invocation.
const LOOP_PROBE_TURNS: u32 = 100_000;

/// The variable that replaces the built-in integrator with a SPIR-V file, for kernel work:
/// `bench/kernel_ab.sh` compiles two `shaders/` trees (`examples/compile_kernel.rs`) and times
/// the same binary with each.
pub const INTEGRATOR_SPV_VAR: &str = "LIGHTFARM_INTEGRATOR_SPV";

fn integrator_spirv() -> Result<Vec<u32>, RenderError> {
    let Some(path) = std::env::var_os(INTEGRATOR_SPV_VAR) else {
        return Ok(shaders::integrator());
    };
    let bad = |why: String| {
        RenderError::InvalidSettings(format!(
            "{INTEGRATOR_SPV_VAR}={}: {why}; unset it to render with the built-in integrator",
            path.to_string_lossy()
        ))
    };
    let bytes = std::fs::read(&path).map_err(|e| bad(format!("cannot read it: {e}")))?;
    if bytes.len() % 4 != 0 || bytes.get(..4) != Some(&0x0723_0203u32.to_le_bytes()[..]) {
        return Err(bad("not a little-endian SPIR-V module".into()));
    }
    tracing::warn!(path = %path.to_string_lossy(), "rendering with an integrator from {INTEGRATOR_SPV_VAR}");
    Ok(shaders::words(&bytes))
}

pub struct Renderer {
    ctx: Arc<GpuContext>,
    integrator: ComputeKernel,
    tables: GpuBuffer,
    walk: WalkSchedule,
    lightings: LightingSchedule,
    /// The integrator with traversal counters, compiled on first use.
    counting: Option<ComputeKernel>,
    count: bool,
    /// At most this many lightings share a camera path (None: as many as memory allows).
    group_limit: Option<usize>,
    /// The driver ends an invocation's loops once they have turned 65,535 times in all (the
    /// start-up probe found it): every dispatch then takes one sample per pixel.
    cuts_loops: bool,
    /// The integrator's invocations take pixels off a queue (`set_pixel_queue`).
    pixel_queue: bool,
}

impl Renderer {
    pub fn new(request: &DeviceRequest) -> Result<Renderer, RenderError> {
        let ctx = GpuContext::new(request)?;
        let integrator = ComputeKernel::with_bindings(
            &ctx,
            "integrator",
            &integrator_spirv()?,
            &shaders::BINDINGS,
            std::mem::size_of::<Push>() as u32,
        )?;
        let tables = crate::tables::compute(&ctx)?;
        let mut renderer = Renderer {
            ctx,
            integrator,
            tables,
            walk: WalkSchedule::default(),
            lightings: LightingSchedule::default(),
            counting: None,
            count: false,
            group_limit: None,
            cuts_loops: false,
            pixel_queue: false,
        };
        renderer.cuts_loops = renderer.warm_up()?;
        // On a CPU device a thread renders one fixed block of workgroups, so one pixel per
        // invocation leaves a thread idle once its block is done (1.80 of 2 cores busy on a
        // head render, Mesa 25); a GPU rebalances its workgroups itself. Not where loops are cut: an
        // invocation that renders many pixels turns its loops far more than 65,535 times.
        renderer.pixel_queue = renderer.ctx.is_cpu() && !renderer.cuts_loops;
        if renderer.cuts_loops {
            let info = renderer.ctx.info();
            tracing::warn!(
                device = %info.name,
                driver = %info.driver,
                "this driver ends shader loops after 65,535 turns (Mesa 22's llvmpipe): rendering \
                 one sample per pixel and dispatch, which is slower; Mesa 25 or newer has no such \
                 limit (source scripts/lavapipe-backports.sh)"
            );
        }
        Ok(renderer)
    }

    /// lavapipe compiles a pipeline with LLVM on its first dispatch (seconds for the
    /// integrator); a dispatch here keeps that out of every render's timing and progress. It is
    /// the probe of whether the driver cuts loops short (STAGE_LOOP_PROBE), which it answers.
    fn warm_up(&self) -> Result<bool, RenderError> {
        let params = Params {
            loop_check: LOOP_PROBE_TURNS,
            ..Params::default()
        };
        let bound = Bound::upload(
            &self.ctx,
            &params,
            &PackedScene::empty(),
            &PackedEnv::default(),
        )?;
        let rw: Vec<GpuBuffer> = (0..5)
            .map(|_| GpuBuffer::zeroed(&self.ctx, "warm-up", 16))
            .collect::<Result<_, _>>()?;
        let bindings = bound.bindings([&rw[0], &rw[1], &rw[2], &rw[3], &rw[4]], &self.tables);
        let push = Push {
            mode: STAGE_LOOP_PROBE,
            ..Push::default()
        };
        self.integrator
            .dispatch_resources(&bindings, bytemuck::bytes_of(&push), [1, 1, 1])?;
        let counters: Vec<u32> = rw[2].read()?;
        Ok(counters[2] > 0)
    }

    /// Whether the driver ends an invocation's loops after 65,535 turns in all, so that every
    /// dispatch takes one sample per pixel (found by the start-up probe).
    pub fn cuts_loops(&self) -> bool {
        self.cuts_loops
    }

    /// Whether the integrator's invocations take their pixels off a queue until the image is
    /// done (true) or render one pixel each, the one their workgroup names (false), for the
    /// renders that follow. The images are the same either way; the default is the queue on CPU
    /// devices, where it keeps every thread busy to the end of a dispatch, unless the driver
    /// cuts loops (`cuts_loops`), where it is refused.
    pub fn set_pixel_queue(&mut self, on: bool) -> Result<(), RenderError> {
        if on && self.cuts_loops {
            let info = self.ctx.info();
            return Err(RenderError::InvalidSettings(format!(
                "{} ({}) ends shader loops after 65,535 turns, and an invocation that takes \
                 pixels off the queue turns them more often: render without the pixel queue, \
                 or on Mesa 25 or newer (source scripts/lavapipe-backports.sh)",
                info.name, info.driver
            )));
        }
        self.pixel_queue = on;
        Ok(())
    }

    pub fn pixel_queue(&self) -> bool {
        self.pixel_queue
    }

    /// Chooses where subsurface walks run for the renders that follow (the megakernel unless
    /// set; BENCHMARKS.md compares the two).
    pub fn set_walk_schedule(&mut self, walk: WalkSchedule) {
        self.walk = walk;
    }

    pub fn walk_schedule(&self) -> WalkSchedule {
        self.walk
    }

    /// Chooses whether the lightings of a render share their camera paths (the default) for the
    /// renders that follow. The walk-dispatch schedule always traces them separately.
    pub fn set_lighting_schedule(&mut self, lightings: LightingSchedule) {
        self.lightings = lightings;
    }

    pub fn lighting_schedule(&self) -> LightingSchedule {
        self.lightings
    }

    /// Caps how many lightings share one set of camera paths (and one accumulator) for the
    /// renders that follow; by default the cap is what one storage buffer may span. A smaller
    /// cap saves device memory at the cost of tracing the paths once per group.
    pub fn set_lightings_per_path(&mut self, limit: Option<usize>) {
        self.group_limit = limit.map(|l| l.max(1));
    }

    /// Turns the per-pixel traversal counters (crate::counters) on or off for the renders that
    /// follow. Their kernel is compiled on first use (seconds on lavapipe); it casts the same
    /// rays as the production kernel, a little slower.
    pub fn set_traversal_counters(&mut self, on: bool) -> Result<(), RenderError> {
        if on && !self.ctx.has_subgroup_counting() {
            return Err(RenderError::InvalidSettings(format!(
                "traversal counters need subgroup ballot and arithmetic operations in compute \
                 shaders, which {} ({}) does not offer: count on another device (lavapipe has \
                 them) or render without counters",
                self.ctx.info().name,
                self.ctx.info().driver
            )));
        }
        if on && self.counting.is_none() {
            self.counting = Some(ComputeKernel::with_bindings(
                &self.ctx,
                "integrator with traversal counters",
                &shaders::integrator_counters(),
                &shaders::BINDINGS,
                std::mem::size_of::<Push>() as u32,
            )?);
        }
        self.count = on;
        Ok(())
    }

    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    pub fn device(&self) -> &DeviceInfo {
        self.ctx.info()
    }

    /// Renders every lighting of `lights` with the same camera samples, plus the passes.
    pub fn render(
        &self,
        scene: &PackedScene,
        lights: &[EnvLight],
        settings: &RenderSettings,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<RenderOutput, RenderError> {
        let lightings: Vec<Lighting> = lights.iter().map(Lighting::Map).collect();
        self.render_lightings(scene, &lightings, settings, progress)
    }

    /// `render` for any mix of environment maps and disc lights (the OLAT basis).
    pub fn render_lightings(
        &self,
        scene: &PackedScene,
        lights: &[Lighting],
        settings: &RenderSettings,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<RenderOutput, RenderError> {
        settings.validate()?;
        if lights.is_empty() || lights.len() > MAX_LIGHTS {
            return Err(RenderError::InvalidSettings(format!(
                "{} lightings given: pass 1..={MAX_LIGHTS} --hdri",
                lights.len()
            )));
        }
        for light in lights {
            if let Lighting::Disc(d) = light {
                let ok = d.radius_deg > 0.0
                    && d.radius_deg <= 90.0
                    && d.direction.iter().all(|v| v.is_finite())
                    && d.direction.iter().any(|v| *v != 0.0)
                    && d.radiance.iter().all(|v| v.is_finite() && *v >= 0.0);
                if !ok {
                    return Err(RenderError::InvalidSettings(format!(
                        "disc light {:?}: needs a nonzero finite direction, a radius in (0, 90] \
                         degrees (got {}) and finite radiance >= 0 (got {:?})",
                        d.name, d.radius_deg, d.radiance
                    )));
                }
            }
        }
        let start = Instant::now();
        let (w, h) = (settings.width, settings.height);
        let pixels = w as u64 * h as u64;
        let (cam_pos, cam_right, cam_up, cam_fwd) = camera_params(settings);
        let params = Params {
            width: w,
            height: h,
            spp: settings.spp,
            seed: settings.seed,
            max_depth: settings.max_depth,
            rr_depth: settings.rr_depth,
            num_lights: lights.len() as u32,
            tlas_node_offset: scene.tlas_node_offset,
            scene_flags: scene.scene_flags(),
            pixel_queue: self.pixel_queue as u32,
            loop_check: LOOP_CHECK_TURNS,
            _pad: 0,
            cam_pos,
            cam_right,
            cam_up,
            cam_fwd,
        };
        let env = pack_lightings(lights);
        let bound = Bound::upload(&self.ctx, &params, scene, &env)?;
        let aux = GpuBuffer::zeroed(&self.ctx, "pass accumulator", pixels * 4 * 16)?;
        let kernel = match (&self.counting, self.count) {
            (Some(k), true) => k,
            _ => &self.integrator,
        };
        let counting = self.count;
        let counters = GpuBuffer::zeroed(
            &self.ctx,
            "ray counter",
            if counting {
                (TC_FIRST as u64 + TC_WORDS as u64 * pixels) * 4
            } else {
                TC_FIRST as u64 * 4
            },
        )?;
        let dispatch = self.walk == WalkSchedule::Dispatch;
        if dispatch && counting {
            return Err(RenderError::InvalidSettings(
                "traversal counters count the megakernel's rays: render without the \
                 walk-dispatch schedule to count them"
                    .into(),
            ));
        }
        if dispatch && pixels > DISPATCH_PATHS {
            return Err(RenderError::InvalidSettings(format!(
                "{w}x{h} is more than the {DISPATCH_PATHS} pixels the walk-dispatch schedule \
                 holds: render it with the megakernel (the default)"
            )));
        }
        // The radiance and passes' accumulators hold one group of lightings at a time (read
        // back after it), sized to what one storage buffer may span (128 MiB on lavapipe: 32
        // lightings at 512²); each group traces its own camera paths.
        let split = Pass::needs_split(&settings.passes);
        let lit_bytes = pixels * 16;
        let pass_bytes = pixels * PASS_VEC4S as u64 * 16;
        let range = self.ctx.max_storage_buffer_range();
        let group = if dispatch || self.lightings == LightingSchedule::Separate {
            1
        } else {
            let per_group = if split {
                lit_bytes.max(pass_bytes)
            } else {
                lit_bytes
            };
            let fit = (range / per_group).clamp(1, lights.len() as u64) as usize;
            fit.min(self.group_limit.unwrap_or(usize::MAX))
        };
        let lit = GpuBuffer::zeroed(&self.ctx, "radiance accumulator", lit_bytes * group as u64)?;
        // About a million paths per dispatch (fewer as more lightings share them): long enough
        // to keep a GPU busy, short enough for a responsive progress bar on lavapipe and for the
        // ray counter (u32) not to wrap. The walk-dispatch schedule holds half that many in its
        // job slots.
        let paths = if dispatch {
            DISPATCH_PATHS
        } else {
            (2 << 20) / (1 + group as u64)
        };
        let per_dispatch = if self.cuts_loops {
            1
        } else {
            (paths / pixels).clamp(1, settings.spp as u64) as u32
        };
        // The integrator's probe input is the walk-dispatch schedule's job slots.
        let jobs = GpuBuffer::zeroed(
            &self.ctx,
            "walk jobs",
            if dispatch {
                per_dispatch as u64 * pixels * JOB_BYTES
            } else {
                16
            },
        )?;
        let pass_acc = GpuBuffer::zeroed(
            &self.ctx,
            "pass accumulator",
            if split { pass_bytes * group as u64 } else { 16 },
        )?;
        let bindings = bound.bindings([&lit, &aux, &counters, &jobs, &pass_acc], &self.tables);
        let mut lit_passes = Vec::new();
        let mut lit_images: Vec<Vec<[f32; 3]>> = Vec::with_capacity(lights.len());
        let spp = settings.spp as f32;
        let n = pixels as usize;
        let groups = [w.div_ceil(8), h.div_ceil(8), 1];
        let groups_of_lights: Vec<(u32, u32)> = (0..lights.len())
            .step_by(group)
            .map(|first| (first as u32, group.min(lights.len() - first) as u32))
            .collect();
        let total = settings.spp as u64 * groups_of_lights.len() as u64;
        let mut done = 0u64;
        let mut rays = 0u64;
        // integrator_counters writes its SIMD-group width to word 3 of every dispatch.
        let mut simd_width = 0u32;
        for &(light, shared) in &groups_of_lights {
            let mut s = 0u32;
            while s < settings.spp {
                let count = per_dispatch.min(settings.spp - s);
                let push = Push {
                    sample_start: s,
                    sample_count: count,
                    light,
                    count: shared,
                    write_aux: (light == 0) as u32,
                    passes: split as u32,
                    nee: if self.lightings == LightingSchedule::Mixture {
                        NEE_MIXTURE
                    } else {
                        0
                    },
                    ..Default::default()
                };
                if dispatch {
                    let stage = |mode: u32| Push { mode, ..push };
                    let slots = count as u64 * pixels;
                    kernel.dispatch_resources(
                        &bindings,
                        bytemuck::bytes_of(&stage(STAGE_PATHS)),
                        groups,
                    )?;
                    kernel.dispatch_resources(
                        &bindings,
                        bytemuck::bytes_of(&Push {
                            write_aux: 0,
                            ..stage(STAGE_WALKS)
                        }),
                        [slots.div_ceil(64) as u32, 1, 1],
                    )?;
                    kernel.dispatch_resources(
                        &bindings,
                        bytemuck::bytes_of(&stage(STAGE_GATHER)),
                        groups,
                    )?;
                } else {
                    kernel.dispatch_resources(&bindings, bytemuck::bytes_of(&push), groups)?;
                }
                // With counters on this reads the per-pixel words too; they accumulate across
                // dispatches, only the renderer's own words before TC_FIRST are reset.
                let c: Vec<u32> = counters.read()?;
                if c[2] > 0 {
                    let info = self.ctx.info();
                    return Err(RenderError::LoopsCut {
                        device: info.name.clone(),
                        driver: info.driver.clone(),
                        invocations: c[2],
                    });
                }
                rays += c[0] as u64;
                simd_width = simd_width.max(c[3]);
                counters.write(&[0u32; TC_FIRST])?;
                s += count;
                done += count as u64;
                progress(Progress { done, total });
            }
            if split {
                let acc: Vec<[f32; 4]> = pass_acc.read()?;
                let per_light = pixels as usize * PASS_VEC4S;
                for slot in acc.chunks_exact(per_light).take(shared as usize) {
                    lit_passes.push(LitPasses::resolve(
                        slot,
                        pixels as usize,
                        settings.spp as f32,
                    ));
                }
                pass_acc.write(&vec![[0f32; 4]; acc.len()])?;
            }
            let lit_sum: Vec<[f32; 4]> = lit.read()?;
            for slot in lit_sum.chunks_exact(n).take(shared as usize) {
                lit_images.push(
                    slot.iter()
                        .map(|v| [v[0] / spp, v[1] / spp, v[2] / spp])
                        .collect(),
                );
            }
            if shared as usize != lights.len() {
                lit.write(&vec![[0f32; 4]; lit_sum.len()])?;
            }
        }

        let traversal = if counting {
            Some(TraversalCounts::from_words(
                &counters.read()?,
                w,
                h,
                simd_width,
            ))
        } else {
            None
        };
        let aux = AuxImages::resolve(&aux.read()?, spp);
        let seconds = start.elapsed().as_secs_f64();
        let samples = pixels * settings.spp as u64 * lights.len() as u64;
        let info = self.ctx.info();
        Ok(RenderOutput {
            width: w,
            height: h,
            lit: lit_images,
            albedo: aux.albedo,
            normal: aux.normal,
            normal_lens: aux.normal_lens,
            mask: aux.mask,
            pass_set: {
                let mut v = settings.passes.clone();
                v.sort();
                v.dedup();
                v
            },
            passes: lit_passes,
            id: aux.id,
            stats: RenderStats {
                seconds,
                samples,
                samples_per_second: samples as f64 / seconds.max(1e-9),
                rays,
                rays_per_second: rays as f64 / seconds.max(1e-9),
                device: info.name.clone(),
                device_kind: info.kind.clone(),
                width: w,
                height: h,
                spp: settings.spp,
                lightings: lights.len(),
                lightings_per_path: group,
                triangles: scene.triangle_count,
                curve_segments: scene.segment_count,
                geometry_bytes: scene.geometry_bytes(),
                olat_lights: 0,
                olat_seconds: 0.0,
            },
            traversal,
            olat: Vec::new(),
        })
    }
}
