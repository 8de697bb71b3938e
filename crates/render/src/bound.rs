//! The device buffers of one scene and its lightings, bound in the order of
//! shaders/inc/bindings.wgsl, shared by the integrator, the tables kernel and the probes.

use std::sync::Arc;

use crate::gpu_env::PackedEnv;
use crate::gpu_scene::PackedScene;
use crate::gpu_types::Params;
use crate::vulkan::{GpuBuffer, GpuContext, GpuImage, Resource};
use crate::RenderError;

/// Device buffers of a scene and its lights, bound in the order of shaders/inc/bindings.wgsl.
pub(crate) struct Bound {
    pub params: GpuBuffer,
    /// BVH nodes, five records each.
    pub nodes: GpuImage,
    /// Triangle (three records) and fibre-segment positions, bits of `[f32; 4]`.
    pub tri_pos: GpuImage,
    pub scene: [GpuBuffer; 5],
    pub env: [GpuBuffer; 3],
}

impl Bound {
    pub fn upload(
        ctx: &Arc<GpuContext>,
        params: &Params,
        scene: &PackedScene,
        env: &PackedEnv,
    ) -> Result<Bound, RenderError> {
        Ok(Bound {
            params: GpuBuffer::from_slice(ctx, "params", std::slice::from_ref(params))?,
            nodes: GpuImage::from_records(ctx, "bvh nodes", bytemuck::cast_slice(&scene.nodes))?,
            tri_pos: GpuImage::from_records(
                ctx,
                "triangle positions",
                bytemuck::cast_slice(&scene.tri_pos),
            )?,
            scene: [
                GpuBuffer::from_slice(ctx, "triangle attributes", &scene.tri_attr)?,
                GpuBuffer::from_slice(ctx, "instances", &scene.instances)?,
                GpuBuffer::from_slice(ctx, "materials", &scene.materials)?,
                GpuBuffer::from_slice(ctx, "texture data", &scene.tex_data)?,
                GpuBuffer::from_slice(ctx, "texture descriptors", &scene.tex_desc)?,
            ],
            env: [
                GpuBuffer::from_slice(ctx, "environment texels", &env.texels)?,
                GpuBuffer::from_slice(ctx, "environment distributions", &env.dist)?,
                GpuBuffer::from_slice(ctx, "environment descriptors", &env.desc)?,
            ],
        })
    }

    /// All 17 bindings, with the read-write ones (and the probe input) given, then the
    /// albedo tables.
    pub fn bindings<'a>(
        &'a self,
        rw: [&'a GpuBuffer; 5],
        tables: &'a GpuBuffer,
    ) -> Vec<Resource<'a>> {
        let mut v = vec![
            Resource::Buffer(&self.params),
            Resource::Image(&self.nodes),
            Resource::Image(&self.tri_pos),
        ];
        v.extend(self.scene.iter().map(Resource::Buffer));
        v.extend(self.env.iter().map(Resource::Buffer));
        v.extend(rw.map(Resource::Buffer));
        v.push(Resource::Buffer(tables));
        v
    }
}
