//! The layered surface model's directional-albedo tables (shaders/kernels/tables.wgsl): the
//! albedo scaling of each layer removes the energy of the layers above it, E(cos θo, roughness),
//! integrated from the shaders' own lobes once per device when a renderer or probe starts.

use std::sync::Arc;

use crate::bound::Bound;
use crate::gpu_env::PackedEnv;
use crate::gpu_scene::PackedScene;
use crate::gpu_types::{Params, Push, LUT_N};
use crate::shaders;
use crate::vulkan::{ComputeKernel, GpuBuffer, GpuContext};
use crate::RenderError;

/// Runs the table kernel; the result is bound at `tables` (binding 16) of every kernel:
/// `LUT_N × LUT_N` vec4s, cell `r · LUT_N + μ` = (A, B, E_sheen, 0) for μ = (i + ½)/LUT_N and
/// roughness r = j/(LUT_N − 1), where a Schlick GGX lobe of α = r² reflects F0·A + B.
pub fn compute(ctx: &Arc<GpuContext>) -> Result<GpuBuffer, RenderError> {
    let kernel = ComputeKernel::with_bindings(
        ctx,
        "tables",
        &shaders::tables(),
        &shaders::BINDINGS,
        std::mem::size_of::<Push>() as u32,
    )?;
    let bound = Bound::upload(
        ctx,
        &Params::default(),
        &PackedScene::empty(),
        &PackedEnv::default(),
    )?;
    let dummies: Vec<GpuBuffer> = (0..5)
        .map(|_| GpuBuffer::zeroed(ctx, "unused", 16))
        .collect::<Result<_, _>>()?;
    let cells = (LUT_N * LUT_N) as u64;
    let out = GpuBuffer::zeroed(ctx, "albedo tables", cells * 16)?;
    let bindings = bound.bindings(
        [&dummies[0], &dummies[1], &dummies[2], &dummies[3], &out],
        &dummies[4],
    );
    kernel.dispatch_resources(
        &bindings,
        bytemuck::bytes_of(&Push::default()),
        [(cells as u32).div_ceil(64), 1, 1],
    )?;
    Ok(out)
}

/// The tables as the host reads them back, for tests and tools: `[A, B, E_sheen, 0]` per cell.
pub fn read(tables: &GpuBuffer) -> Result<Vec<[f32; 4]>, RenderError> {
    let mut v: Vec<[f32; 4]> = tables.read()?;
    v.truncate(LUT_N * LUT_N);
    Ok(v)
}
