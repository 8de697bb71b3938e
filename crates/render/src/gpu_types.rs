//! `#[repr(C)]` mirrors of the structs in `shaders/inc/bindings.wgsl`: the one place where the
//! host's and the shaders' data layouts meet. Sizes are asserted at compile time.

use bytemuck::{Pod, Zeroable};

pub const NO_NODE: u32 = u32::MAX;
pub const NO_TEX: u32 = u32::MAX;
/// A transmissive material that bounds a refracting solid (an eyeglass lens).
pub const MAT_FLAG_LENS: u32 = 1;
/// A transmissive thin-walled material: a clear sheet that light passes straight through.
pub const MAT_FLAG_THIN: u32 = 2;
/// Some material is see-through (MAT_FLAG_LENS or MAT_FLAG_THIN): shadow rays look through it.
pub const SCENE_HAS_LENS: u32 = 1;
/// The scene has exactly one instance: rays go straight to its BLAS, skipping the TLAS.
pub const SCENE_ONE_INSTANCE: u32 = 2;
/// The instance's BLAS is over fibre segments (INST_CURVES in bindings.wgsl).
pub const INST_CURVES: u32 = 1;
/// vec4s of per-triangle attributes in `tri_attr` (see shaders/inc/traverse.wgsl).
pub const TRI_ATTR_VEC4S: usize = 5;
/// u32 words per CWBVH node.
pub const NODE_WORDS: usize = 20;

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct Params {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub seed: u32,
    pub max_depth: u32,
    pub rr_depth: u32,
    pub num_lights: u32,
    pub tlas_node_offset: u32,
    /// SCENE_HAS_LENS | SCENE_ONE_INSTANCE
    pub scene_flags: u32,
    /// 1: the integrator's invocations take their pixels off a queue until it is empty (CPU
    /// devices, `Renderer::set_pixel_queue`); 0: one pixel each, named by its workgroup.
    pub pixel_queue: u32,
    /// The turns of the integrator's cut-loop check: LOOP_CHECK_TURNS (renderer.rs).
    pub loop_check: u32,
    pub _pad: u32,
    pub cam_pos: [f32; 4],
    pub cam_right: [f32; 4],
    pub cam_up: [f32; 4],
    pub cam_fwd: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct InstanceGpu {
    pub obj_to_world: [[f32; 4]; 4],
    pub world_to_obj: [[f32; 4]; 4],
    pub node_offset: u32,
    /// Triangles: the first triangle slot; curves: the first vec4 of the segments in tri_pos.
    pub tri_offset: u32,
    /// INST_CURVES
    pub flags: u32,
    /// Curves: the material of every segment.
    pub material: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MaterialGpu {
    pub base_color: [f32; 4],
    /// metallic, roughness, specular, transmission
    pub mrst: [f32; 4],
    /// specular colour, ior
    pub spec_color_ior: [f32; 4],
    /// base, metallic-roughness, normal texture (NO_TEX when absent), flags
    pub tex: [u32; 4],
    /// normal scale, opacity
    pub extra: [f32; 4],
    /// subsurface colour (x < 0: the base colour), subsurface weight
    pub sss: [f32; 4],
    /// mean free path (radius × scale, scene units), anisotropy
    pub sss_mfp: [f32; 4],
    /// coat colour, coat weight
    pub coat: [f32; 4],
    /// coat roughness, coat IOR, sheen weight, sheen roughness
    pub coat_sheen: [f32; 4],
    /// sheen colour
    pub sheen_color: [f32; 4],
    /// specular-weight texture, model, object class, unused
    pub tex2: [u32; 4],
    /// Hair: σa per unit radius, unused
    pub hair_sigma: [f32; 4],
    /// Hair: βm, βn, cuticle tilt (radians), unused
    pub hair: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct EnvDesc {
    pub width: u32,
    pub height: u32,
    pub texel_offset: u32,
    pub cond_func_offset: u32,
    /// width × height (probability, bitcast alias index) pairs
    pub alias_offset: u32,
    /// ENV_MAP (0) or ENV_DISC (1)
    pub kind: u32,
    pub _pad1: u32,
    pub flip: u32,
    pub cos_rot: f32,
    pub sin_rot: f32,
    pub marg_integral: f32,
    pub _pad: f32,
    /// Disc: world axis, 1 - cos(angular radius)
    pub disc: [f32; 4],
    /// Disc: radiance, 1 / solid angle
    pub disc_radiance: [f32; 4],
}

pub const ENV_MAP: u32 = 0;
pub const ENV_DISC: u32 = 1;

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct Push {
    pub sample_start: u32,
    pub sample_count: u32,
    pub light: u32,
    pub write_aux: u32,
    pub mode: u32,
    pub count: u32,
    /// Probe kernel only: 0, or 1 + axis of a deliberately wrong sampler (see probe.wgsl);
    /// the tests use it to show that their statistics reject a biased sampler.
    pub mutate: u32,
    /// Integrator only: 1 = accumulate the appendix passes (shaders/kernels/integrator.wgsl).
    pub passes: u32,
    /// Integrator only: NEE_MIXTURE = one shadow ray per vertex from the mixture of the
    /// dispatch's lightings (LightingSchedule::Mixture), else one per lighting.
    pub nee: u32,
}

/// Push::nee: one NEE shadow ray per vertex for all lightings (NEE_MIXTURE in bindings.wgsl).
pub const NEE_MIXTURE: u32 = 1;

const _: () = assert!(std::mem::size_of::<Params>() == 112);
const _: () = assert!(std::mem::size_of::<InstanceGpu>() == 144);
const _: () = assert!(std::mem::size_of::<MaterialGpu>() == 208);
/// Side of the directional-albedo tables (LUT_N in shaders/inc/bindings.wgsl).
pub const LUT_N: usize = 32;
/// vec4s per pixel of the appendix-pass accumulator (PASS_VEC4S in integrator.wgsl).
pub const PASS_VEC4S: usize = 6;
const _: () = assert!(std::mem::size_of::<EnvDesc>() == 80);
const _: () = assert!(std::mem::size_of::<Push>() == 36);
const _: () = assert!(std::mem::size_of::<obvhs::cwbvh::node::CwBvhNode>() == NODE_WORDS * 4);
