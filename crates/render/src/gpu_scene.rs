//! Flattens a [`Scene`] into the arrays the shaders read: one obvhs CWBVH per mesh (BLAS) and per
//! curve set (`gpu_curves`), a CWBVH over the instances (TLAS), triangles and fibre segments
//! reordered into leaf order, materials and textures.
//! Pure CPU work with no Vulkan, so the traversal tests can use the same data as a reference.

use std::time::Duration;

use glam::{Mat4, Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::{build_cwbvh, build_cwbvh_from_tris};
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

use crate::gpu_curves::{pack_curve_set, CurveBlas};
use crate::gpu_types::{
    InstanceGpu, MaterialGpu, INST_CURVES, MAT_FLAG_LENS, MAT_FLAG_THIN, NO_NODE, NO_TEX,
    SCENE_HAS_LENS, SCENE_ONE_INSTANCE, TRI_ATTR_VEC4S,
};
use crate::scene::{Material, MaterialModel, Scene};
use crate::RenderError;

/// One bottom-level structure: a mesh's triangles in object space.
pub struct Blas {
    pub mesh: u32,
    pub bvh: CwBvh,
    /// Object-space triangles in the mesh's original order (the CPU reference intersects these).
    pub triangles: Vec<Triangle>,
    pub node_offset: u32,
    pub tri_offset: u32,
}

/// Everything the kernels need about the geometry and its materials.
pub struct PackedScene {
    pub nodes: Vec<CwBvhNode>,
    pub tri_pos: Vec<[f32; 4]>,
    pub tri_attr: Vec<[f32; 4]>,
    /// In TLAS leaf order: GPU instance i is `scene.instances[instance_order[i]]`, or curve set
    /// `curve_blas[instance_curves[i]]` where `instance_order[i]` is `u32::MAX`.
    pub instances: Vec<InstanceGpu>,
    pub instance_order: Vec<u32>,
    /// Index into `blas` for each GPU instance (`u32::MAX` for curves).
    pub instance_blas: Vec<u32>,
    /// Index into `curve_blas` for each GPU instance (`u32::MAX` for meshes).
    pub instance_curves: Vec<u32>,
    /// One per curve set with segments.
    pub curve_blas: Vec<CurveBlas>,
    /// Fibre segments over all curve sets (strand segments; the BVH holds their pieces).
    pub segment_count: usize,
    pub materials: Vec<MaterialGpu>,
    pub tex_data: Vec<u32>,
    pub tex_desc: Vec<[u32; 4]>,
    pub tlas_node_offset: u32,
    pub blas: Vec<Blas>,
    /// For each triangle slot: (blas index, triangle index within the mesh).
    pub slot_triangle: Vec<(u32, u32)>,
    pub triangle_count: usize,
}

fn build_params() -> BvhBuildParams {
    // Spatial splits would duplicate triangles across leaves; keep one slot per triangle.
    let mut p = BvhBuildParams::medium_build();
    p.pre_split = false;
    p.max_prims_per_leaf = 3;
    p
}

fn material_gpu(m: &Material, texture_count: u32) -> MaterialGpu {
    let tex = |t: Option<u32>| t.filter(|&i| i < texture_count).unwrap_or(NO_TEX);
    let clear = m.transmission > 0.5;
    let flags = match (clear, m.thin_walled) {
        (false, _) => 0,
        (true, false) => MAT_FLAG_LENS,
        (true, true) => MAT_FLAG_THIN,
    };
    MaterialGpu {
        base_color: m.base_color,
        mrst: [
            m.metallic.clamp(0.0, 1.0),
            m.roughness.clamp(0.0, 1.0),
            m.specular.clamp(0.0, 1.0),
            m.transmission.clamp(0.0, 1.0),
        ],
        spec_color_ior: [
            m.specular_color[0].max(0.0),
            m.specular_color[1].max(0.0),
            m.specular_color[2].max(0.0),
            m.ior.clamp(1.0, 4.0),
        ],
        tex: [
            tex(m.base_color_texture),
            tex(m.metallic_roughness_texture),
            tex(m.normal_texture),
            flags,
        ],
        extra: [m.normal_scale, m.opacity.clamp(0.0, 1.0), 0.0, 0.0],
        sss: match m.subsurface_color {
            Some(c) => [c[0], c[1], c[2], m.subsurface.clamp(0.0, 1.0)],
            None => [-1.0, -1.0, -1.0, m.subsurface.clamp(0.0, 1.0)],
        },
        sss_mfp: [
            (m.subsurface_radius[0] * m.subsurface_scale).max(1e-7),
            (m.subsurface_radius[1] * m.subsurface_scale).max(1e-7),
            (m.subsurface_radius[2] * m.subsurface_scale).max(1e-7),
            m.subsurface_anisotropy.clamp(-0.95, 0.95),
        ],
        coat: [
            m.coat_color[0],
            m.coat_color[1],
            m.coat_color[2],
            m.coat.clamp(0.0, 1.0),
        ],
        coat_sheen: [
            m.coat_roughness.clamp(0.0, 1.0),
            m.coat_ior.clamp(1.0, 3.0),
            m.sheen.clamp(0.0, 1.0),
            m.sheen_roughness.clamp(0.0, 1.0),
        ],
        sheen_color: [m.sheen_color[0], m.sheen_color[1], m.sheen_color[2], 0.0],
        tex2: [
            tex(m.specular_texture),
            m.model.gpu_index(),
            m.class as u32,
            0,
        ],
        hair_sigma: [0.0; 4],
        hair: [0.0; 4],
    }
}

/// A hair material: the fibre's absorption and roughness, and its diffuse-equivalent colour as
/// the base colour (the albedo pass).
fn hair_gpu(m: &Material, texture_count: u32) -> MaterialGpu {
    let mut g = material_gpu(m, texture_count);
    let sigma = crate::hair::sigma_a_from_melanin(m.melanin, m.melanin_redness);
    let bn = m.azimuthal_roughness.clamp(0.0, 1.0);
    let c = crate::hair::color_of_sigma_a(sigma, bn);
    g.base_color = [c[0], c[1], c[2], 1.0];
    g.hair_sigma = [sigma[0], sigma[1], sigma[2], 0.0];
    g.hair = [
        m.longitudinal_roughness.clamp(0.0, 1.0),
        bn,
        m.cuticle_tilt_deg.clamp(-10.0, 10.0).to_radians(),
        0.0,
    ];
    g.tex = [NO_TEX, NO_TEX, NO_TEX, 0];
    g.extra[1] = 1.0;
    g
}

fn transform_aabb(m: &Mat4, a: &Aabb) -> Aabb {
    let mut out = Aabb::empty();
    for i in 0..8 {
        let c = Vec3::new(
            if i & 1 == 0 { a.min.x } else { a.max.x },
            if i & 2 == 0 { a.min.y } else { a.max.y },
            if i & 4 == 0 { a.min.z } else { a.max.z },
        );
        out.extend(Vec3A::from(m.transform_point3(c)));
    }
    out
}

fn mat_cols(m: &Mat4) -> [[f32; 4]; 4] {
    m.to_cols_array_2d()
}

/// Builds the BVHs and flattens `scene`. Meshes without triangles are skipped.
pub fn pack_scene(scene: &Scene) -> Result<PackedScene, RenderError> {
    let mut blas: Vec<Blas> = Vec::new();
    let mut mesh_blas: Vec<Option<u32>> = vec![None; scene.meshes.len()];
    let mut nodes: Vec<CwBvhNode> = Vec::new();
    let mut tri_pos = Vec::new();
    let mut tri_attr = Vec::new();
    let mut slot_triangle = Vec::new();
    let material_count = scene.materials.len() as u32;

    for (mi, mesh) in scene.meshes.iter().enumerate() {
        let tri_count = mesh.indices.len() / 3;
        if tri_count == 0 {
            continue;
        }
        let vcount = mesh.positions.len();
        let idx = |k: usize| -> Result<usize, RenderError> {
            let i = mesh.indices[k] as usize;
            if i >= vcount {
                return Err(RenderError::InvalidScene(format!(
                    "mesh '{}' index {i} is out of range ({vcount} vertices)",
                    mesh.name
                )));
            }
            Ok(i)
        };
        let mut tris = Vec::with_capacity(tri_count);
        for t in 0..tri_count {
            let (a, b, c) = (idx(3 * t)?, idx(3 * t + 1)?, idx(3 * t + 2)?);
            tris.push(Triangle {
                v0: Vec3A::from(mesh.positions[a]),
                v1: Vec3A::from(mesh.positions[b]),
                v2: Vec3A::from(mesh.positions[c]),
            });
        }
        let bvh = build_cwbvh_from_tris(&tris, build_params(), &mut Duration::default());
        let node_offset = nodes.len() as u32;
        let tri_offset = slot_triangle.len() as u32;
        nodes.extend_from_slice(&bvh.nodes);
        let bi = blas.len() as u32;
        for &prim in &bvh.primitive_indices {
            let t = prim as usize;
            let ids = [
                mesh.indices[3 * t] as usize,
                mesh.indices[3 * t + 1] as usize,
                mesh.indices[3 * t + 2] as usize,
            ];
            for &v in &ids {
                let p = mesh.positions[v];
                tri_pos.push([p[0], p[1], p[2], 0.0]);
            }
            let n = |v: usize| mesh.normals.get(v).copied().unwrap_or([0.0; 3]);
            let uv = |v: usize| mesh.uvs.get(v).copied().unwrap_or([0.0; 2]);
            let (n0, n1, n2) = (n(ids[0]), n(ids[1]), n(ids[2]));
            let (uv0, uv1, uv2) = (uv(ids[0]), uv(ids[1]), uv(ids[2]));
            let mat = mesh
                .triangle_materials
                .get(t)
                .copied()
                .unwrap_or(0)
                .min(material_count.saturating_sub(1));
            tri_attr.push([n0[0], n0[1], n0[2], uv0[0]]);
            tri_attr.push([n1[0], n1[1], n1[2], uv0[1]]);
            tri_attr.push([n2[0], n2[1], n2[2], uv1[0]]);
            tri_attr.push([uv1[1], uv2[0], uv2[1], f32::from_bits(mat)]);
            let mut tan = [0.0f32; 4];
            for &v in &ids {
                if let Some(tv) = mesh.tangents.get(v) {
                    for k in 0..3 {
                        tan[k] += tv[k];
                    }
                    tan[3] = if tv[3] < 0.0 { -1.0 } else { 1.0 };
                }
            }
            tri_attr.push(tan);
            slot_triangle.push((bi, prim));
        }
        mesh_blas[mi] = Some(bi);
        blas.push(Blas {
            mesh: mi as u32,
            bvh,
            triangles: tris,
            node_offset,
            tri_offset,
        });
    }
    debug_assert_eq!(tri_attr.len(), slot_triangle.len() * TRI_ATTR_VEC4S);

    // Fibres: one BLAS per curve set, segments after the triangles in tri_pos.
    let mut curve_blas: Vec<CurveBlas> = Vec::new();
    for (ci, c) in scene.curves.iter().enumerate() {
        if c.material >= material_count {
            return Err(RenderError::InvalidScene(format!(
                "curves '{}' use material {} but the scene has {material_count}",
                c.name, c.material
            )));
        }
        if let Some(b) = pack_curve_set(ci as u32, c, &mut nodes, &mut tri_pos)? {
            curve_blas.push(b);
        }
    }
    let segment_count = curve_blas.iter().map(|b| b.strand_segments).sum();

    // Top level over the instances whose mesh has triangles.
    let mut live: Vec<(u32, u32, Mat4)> = Vec::new(); // (scene instance, blas, transform)
    for (ii, inst) in scene.instances.iter().enumerate() {
        let Some(Some(bi)) = mesh_blas.get(inst.mesh as usize) else {
            continue;
        };
        if inst.transform.determinant().abs() < 1e-20 || !inst.transform.is_finite() {
            return Err(RenderError::InvalidScene(format!(
                "instance {ii} has a singular or non-finite transform"
            )));
        }
        live.push((ii as u32, *bi, inst.transform));
    }
    let mut triangle_count = 0usize;
    let mut instances = Vec::new();
    let mut instance_order = Vec::new();
    let mut instance_blas = Vec::new();
    let mut instance_curves = Vec::new();
    let tlas_node_offset = if live.is_empty() && curve_blas.is_empty() {
        NO_NODE
    } else {
        let mut boxes: Vec<Aabb> = live
            .iter()
            .map(|(_, bi, m)| transform_aabb(m, &blas[*bi as usize].bvh.total_aabb))
            .collect();
        boxes.extend(curve_blas.iter().map(|b| b.bvh.total_aabb));
        let tlas = build_cwbvh(&boxes, build_params(), &mut Duration::default());
        let offset = nodes.len() as u32;
        nodes.extend_from_slice(&tlas.nodes);
        for &leaf in &tlas.primitive_indices {
            let leaf = leaf as usize;
            if let Some(&(ii, bi, m)) = live.get(leaf) {
                let b = &blas[bi as usize];
                instances.push(InstanceGpu {
                    obj_to_world: mat_cols(&m),
                    world_to_obj: mat_cols(&m.inverse()),
                    node_offset: b.node_offset,
                    tri_offset: b.tri_offset,
                    flags: 0,
                    material: 0,
                });
                instance_order.push(ii);
                instance_blas.push(bi);
                instance_curves.push(u32::MAX);
                triangle_count += b.triangles.len();
            } else {
                let ci = leaf - live.len();
                let b = &curve_blas[ci];
                instances.push(InstanceGpu {
                    obj_to_world: mat_cols(&Mat4::IDENTITY),
                    world_to_obj: mat_cols(&Mat4::IDENTITY),
                    node_offset: b.node_offset,
                    tri_offset: b.seg_offset,
                    flags: INST_CURVES,
                    material: scene.curves[b.set as usize].material,
                });
                instance_order.push(u32::MAX);
                instance_blas.push(u32::MAX);
                instance_curves.push(ci as u32);
            }
        }
        offset
    };

    let mut tex_data = Vec::new();
    let mut tex_desc = Vec::new();
    for (ti, t) in scene.textures.iter().enumerate() {
        let expected = t.width as usize * t.height as usize * 4;
        if t.width == 0 || t.height == 0 || t.rgba8.len() != expected {
            return Err(RenderError::InvalidScene(format!(
                "texture {ti} has {} bytes for {}x{} RGBA8",
                t.rgba8.len(),
                t.width,
                t.height
            )));
        }
        tex_desc.push([tex_data.len() as u32, t.width, t.height, 0]);
        tex_data.extend(
            t.rgba8
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])),
        );
    }
    let tex_count = scene.textures.len() as u32;
    let mut materials: Vec<MaterialGpu> = scene
        .materials
        .iter()
        .map(|m| match m.model {
            MaterialModel::Hair => hair_gpu(m, tex_count),
            _ => material_gpu(m, tex_count),
        })
        .collect();
    if materials.is_empty() {
        materials.push(material_gpu(&Material::default(), 0));
    }

    Ok(PackedScene {
        nodes,
        tri_pos,
        tri_attr,
        instances,
        instance_order,
        instance_blas,
        instance_curves,
        curve_blas,
        segment_count,
        materials,
        tex_data,
        tex_desc,
        tlas_node_offset,
        blas,
        slot_triangle,
        triangle_count,
    })
}

impl PackedScene {
    /// Bytes of geometry the kernels read: BVH nodes, triangle positions and attributes, fibre
    /// segments.
    pub fn geometry_bytes(&self) -> u64 {
        (self.nodes.len() * std::mem::size_of::<CwBvhNode>()
            + (self.tri_pos.len() + self.tri_attr.len()) * 16) as u64
    }

    /// SCENE_HAS_LENS when some material is a lens or a thin clear sheet (shadow rays must
    /// then look through it); SCENE_ONE_INSTANCE when the TLAS holds a single instance, whose
    /// box test would only repeat the BLAS root's.
    pub fn scene_flags(&self) -> u32 {
        let lens = self
            .materials
            .iter()
            .any(|m| m.tex[3] & (MAT_FLAG_LENS | MAT_FLAG_THIN) != 0);
        let mut flags = 0;
        if lens {
            flags |= SCENE_HAS_LENS;
        }
        if self.instances.len() == 1 {
            flags |= SCENE_ONE_INSTANCE;
        }
        flags
    }

    /// A scene with no geometry (every ray misses); the probes bind it when they test sampling alone.
    pub fn empty() -> PackedScene {
        PackedScene {
            nodes: Vec::new(),
            tri_pos: Vec::new(),
            tri_attr: Vec::new(),
            instances: Vec::new(),
            instance_order: Vec::new(),
            instance_blas: Vec::new(),
            instance_curves: Vec::new(),
            curve_blas: Vec::new(),
            segment_count: 0,
            materials: vec![material_gpu(&Material::default(), 0)],
            tex_data: Vec::new(),
            tex_desc: Vec::new(),
            tlas_node_offset: NO_NODE,
            blas: Vec::new(),
            slot_triangle: Vec::new(),
            triangle_count: 0,
        }
    }
}
