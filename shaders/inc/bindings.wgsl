// Every kernel of the renderer sees the same 17 storage-buffer bindings (set 0), declared once here
// and mirrored by `crates/render/src/gpu_types.rs`. A kernel that does not use a binding still gets a
// (dummy) buffer bound there, which keeps the host side uniform.

struct Params {
    width: u32,
    height: u32,
    spp: u32,
    seed: u32,
    max_depth: u32,
    rr_depth: u32,
    num_lights: u32,
    tlas_node_offset: u32, // NO_NODE when the scene is empty
    scene_flags: u32,      // SCENE_HAS_LENS (some material is MAT_FLAG_CLEAR), SCENE_ONE_INSTANCE
    pixel_queue: u32,      // 1: invocations take pixels off a queue (kernels/integrator.wgsl main)
    loop_check: u32,       // LOOP_CHECK_TURNS (kernels/integrator.wgsl, report_cut_loops)
    _pad2: u32,
    cam_pos: vec4<f32>,
    cam_right: vec4<f32>, // scaled by tan(fov/2) * aspect
    cam_up: vec4<f32>,    // scaled by tan(fov/2)
    cam_fwd: vec4<f32>,
};

struct Instance {
    obj_to_world: mat4x4<f32>, // column-major affine
    world_to_obj: mat4x4<f32>,
    node_offset: u32,          // first CWBVH node of this instance's BLAS in `nodes`
    // Triangles: the BLAS's first triangle slot (leaf order) in tri_pos / tri_attr. Curves
    // (INST_CURVES): the first vec4 of its segments in tri_pos, SEGMENT_VEC4S per segment in
    // leaf order (traverse.wgsl `intersect_segment`), object space.
    tri_offset: u32,
    flags: u32,                // INST_CURVES
    material: u32,             // curves: the material of every segment
};

struct Material {
    base_color: vec4<f32>,
    // metallic, roughness, specular, transmission
    mrst: vec4<f32>,
    // specular colour rgb, ior
    spec_color_ior: vec4<f32>,
    // base texture, metallic-roughness texture, normal texture (NO_TEX when absent), flags (MAT_FLAG_*)
    tex: vec4<u32>,
    // normal scale, opacity (coverage; < 1 is stochastically see-through), unused x2
    extra: vec4<f32>,
    // Standard Surface layers of the MODEL_* > 0 materials (zero for the glTF mapping):
    // subsurface colour rgb (x < 0: the base colour), subsurface weight
    sss: vec4<f32>,
    // mean free path rgb in scene units (radius x scale), anisotropy g
    sss_mfp: vec4<f32>,
    // coat colour rgb, coat weight
    coat: vec4<f32>,
    // coat roughness, coat ior, sheen weight, sheen roughness
    coat_sheen: vec4<f32>,
    // sheen colour rgb, unused
    sheen_color: vec4<f32>,
    // specular-weight texture (its A channel; NO_TEX when absent), model (MODEL_*), object class (id pass), unused
    tex2: vec4<u32>,
    // MODEL_HAIR: fibre absorption σa per unit radius (rgb), unused; (βm, βn, cuticle tilt α in
    // radians, unused). The base colour holds the fibre's diffuse-equivalent colour.
    hair_sigma: vec4<f32>,
    hair: vec4<f32>,
};

struct EnvDesc {
    width: u32,
    height: u32,
    texel_offset: u32,    // into env_texels
    cond_func_offset: u32, // into env_dist: height rows of `width` values
    alias_offset: u32,     // width * height (keep probability, bitcast alias index) pairs
    kind: u32,             // ENV_MAP, or ENV_DISC (the fields above and rotation unused)
    _pad1: u32,
    flip: u32,
    cos_rot: f32,
    sin_rot: f32,
    marg_integral: f32,
    _pad: f32,
    // ENV_DISC: world axis, 1 - cos(angular radius); radiance rgb, 1 / solid angle
    disc: vec4<f32>,
    disc_radiance: vec4<f32>,
};

struct Push {
    sample_start: u32,
    sample_count: u32,
    light: u32,
    write_aux: u32,
    mode: u32,   // probe / test kernels: what to run; integrator: the stage (STAGE_*)
    count: u32,  // probe / test kernels: how many items; integrator: lightings sharing each path
    mutate: u32, // probe kernel: 0, or 1 + axis of a deliberately biased sampler (tests only)
    passes: u32, // integrator: 1 = accumulate the appendix passes of its lightings into probe_out
    nee: u32,    // integrator: NEE_MIXTURE = one shadow ray per vertex for all its lightings
};

const NEE_MIXTURE: u32 = 1u;

const NO_NODE: u32 = 0xffffffffu;
const NO_TEX: u32 = 0xffffffffu;
const MAT_FLAG_LENS: u32 = 1u; // transmissive, bounds a refracting solid (a lens)
const MAT_FLAG_THIN: u32 = 2u; // transmissive and thin-walled: a clear sheet (a cornea)
const MAT_FLAG_CLEAR: u32 = 3u; // either: shadow rays and the passes look through it
// Material models (crates/render/src/scene/mod.rs MaterialModel): 0 is the glTF
// metallic-roughness mapping, everything above it the layered Standard Surface (layered.wgsl).
const MODEL_GLTF: u32 = 0u;
// Environment lights (EnvDesc.kind): a lat-long map, or a disc of constant radiance at infinity
// (an OLAT light of the virtual light stage).
const ENV_MAP: u32 = 0u;
const ENV_DISC: u32 = 1u;
// Side of the directional-albedo tables (`tables`, written once by kernels/tables.wgsl).
const LUT_N: u32 = 32u;
const SCENE_HAS_LENS: u32 = 1u;
const SCENE_ONE_INSTANCE: u32 = 2u;
// The instance's BLAS is over fibre segments (round cones with spherical caps), not triangles.
const INST_CURVES: u32 = 1u;
const PI: f32 = 3.14159265358979;
const INV_PI: f32 = 0.318309886183791;

@group(0) @binding(0) var<storage, read> params: Params;
// BVH nodes and triangle / fibre-segment positions, the traversal's scattered reads, as records
// of 4096-wide R32G32B32A32_UINT images (crates/render/src/vulkan/image.rs): lavapipe turns a
// storage-buffer load at a different address per lane into a bounds-checked scalar load and
// branch per lane and component, an image read into vector loads.
@group(0) @binding(1) var nodes: texture_storage_2d<rgba32uint, read>;
@group(0) @binding(2) var tri_pos: texture_storage_2d<rgba32uint, read>;
@group(0) @binding(3) var<storage, read> tri_attr: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> instances: array<Instance>;
@group(0) @binding(5) var<storage, read> materials: array<Material>;
@group(0) @binding(6) var<storage, read> tex_data: array<u32>;
@group(0) @binding(7) var<storage, read> tex_desc: array<vec4<u32>>;
@group(0) @binding(8) var<storage, read> env_texels: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read> env_dist: array<f32>;
@group(0) @binding(10) var<storage, read> env_desc: array<EnvDesc>;
@group(0) @binding(11) var<storage, read_write> accum_lit: array<vec4<f32>>;
@group(0) @binding(12) var<storage, read_write> accum_aux: array<vec4<f32>>;
// The integrator's counters. Words 0-7 are reset by the host after each dispatch (each round of
// three in the walk-dispatch schedule): [0] rays traced, [1] the walk queue's length
// (inc/walk_queue.wgsl), [2] invocations whose loops the driver cut (report_cut_loops), [3]
// the SIMD-group width in integrator_counters (unused otherwise), [4] the pixel queue's next
// entry (params.pixel_queue), [5-7] unused. From TC_FIRST on: the traversal counters of
// integrator_counters.
@group(0) @binding(13) var<storage, read_write> counters: array<atomic<u32>>;
// The probe kernels' input; the integrator's walk-dispatch schedule keeps its job slots here
// (inc/walk_queue.wgsl), hence read_write.
@group(0) @binding(14) var<storage, read_write> probe_in: array<vec4<f32>>;
@group(0) @binding(15) var<storage, read_write> probe_out: array<vec4<f32>>;
// Directional albedo of the layered model's lobes, LUT_N x LUT_N cells over (cos θ, roughness):
// (GGX with F = 1 - Schlick term, GGX Schlick term, Charlie sheen, unused); see layered.wgsl.
@group(0) @binding(16) var<storage, read> tables: array<vec4<f32>>;

var<immediate> pc: Push;
