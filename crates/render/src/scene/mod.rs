//! The CPU scene description: meshes, materials, textures, instances and cameras, loaded from
//! glTF 2.0 and independent of the GPU. The Vulkan upload code consumes these types as they are.

mod camera;
pub mod export;
mod geometry;
mod load;
mod load_curves;
pub mod material;
mod material_record;
mod morph;
pub mod shapes;

use std::path::PathBuf;

use glam::{Mat4, Vec3};

pub use camera::Camera;
pub use export::write_glb;
pub use material_record::{materials_json, MaterialRecord};

/// Everything that can go wrong building a [`Scene`]; each variant names its input and says
/// what the user can do about it.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("scene file {} does not exist; check the path", path.display())]
    NotFound { path: PathBuf },
    #[error(
        "{} is not a readable glTF 2.0 file ({source}); re-export it as .glb or .gltf 2.0",
        path.display()
    )]
    Gltf {
        path: PathBuf,
        #[source]
        source: gltf::Error,
    },
    #[error(
        "{} contains no triangle or curve geometry in its scene; export the meshes as triangles \
         (and hair as LINES / LINE_STRIP with a _RADIUS attribute)",
        path.display()
    )]
    NoGeometry { path: PathBuf },
    #[error("{}: mesh '{mesh}' is unusable: {reason}; re-export the mesh", path.display())]
    BadPrimitive {
        path: PathBuf,
        mesh: String,
        reason: String,
    },
    #[error("{}: image {index} is unusable: {reason}; re-encode it as PNG or JPEG", path.display())]
    BadTexture {
        path: PathBuf,
        index: usize,
        reason: String,
    },
    #[error("{}: node hierarchy is invalid: {reason}; fix the node tree", path.display())]
    BadNode { path: PathBuf, reason: String },
    #[error("invalid camera: {reason}")]
    BadCamera { reason: String },
    #[error("cannot write {}: {reason}", path.display())]
    Export { path: PathBuf, reason: String },
    #[error("mesh '{mesh}': cannot apply morph weights: {reason}")]
    BadMorph { mesh: String, reason: String },
    #[error(
        "{}: material '{material}': {key} {reason}; fix the material's extras.lightfarm \
         (the schema is in README.md, Materials)",
        path.display()
    )]
    BadMaterial {
        path: PathBuf,
        material: String,
        /// The offending key as a path, e.g. `extras.lightfarm.subsurface_radius`.
        key: String,
        reason: String,
    },
}

/// One BLAS: all triangle primitives of one glTF mesh, merged.
#[derive(Clone, Debug)]
pub struct Mesh {
    pub name: String,
    /// Object space.
    pub positions: Vec<[f32; 3]>,
    /// Per vertex, unit length; area-weighted smooth normals when the file has none.
    pub normals: Vec<[f32; 3]>,
    /// TEXCOORD_0; zeros when absent.
    pub uvs: Vec<[f32; 2]>,
    /// xyz + handedness w (bitangent = cross(normal, xyz) * w); zeros when there are no UVs.
    pub tangents: Vec<[f32; 4]>,
    /// Three per triangle.
    pub indices: Vec<u32>,
    /// One per triangle, index into [`Scene::materials`].
    pub triangle_materials: Vec<u32>,
    /// Blend shapes in file order; see [`Mesh::apply_morphs`].
    pub morph_targets: Vec<MorphTarget>,
}

/// One glTF morph target (blend shape) of a merged [`Mesh`]: per-vertex offsets in the same
/// vertex order as [`Mesh::positions`].
#[derive(Clone, Debug)]
pub struct MorphTarget {
    /// From the mesh's `extras.targetNames`, else `target{i}`.
    pub name: String,
    pub position_deltas: Vec<[f32; 3]>,
    /// Empty when the file has no NORMAL deltas for this target.
    pub normal_deltas: Vec<[f32; 3]>,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Replaces the normals by area-weighted smooth normals of the current positions, for
    /// meshes deformed by something other than a rigid transform.
    pub fn recompute_normals(&mut self) {
        self.normals = geometry::smooth_normals(&self.positions, &self.indices);
    }

    /// [`Mesh::recompute_normals`] with vertex `i` welded to vertex `weld[i]` (one entry per
    /// vertex): copies of a surface point split only for their UVs or materials get one normal,
    /// so the split does not shade as a crease.
    pub fn recompute_normals_welded(&mut self, weld: &[u32]) {
        self.normals = geometry::welded_normals(&self.positions, &self.indices, weld);
    }

    /// Replaces the tangents by ones derived from the UVs and normals (as for a glTF file
    /// without TANGENT), for meshes built in code.
    pub fn recompute_tangents(&mut self) {
        self.tangents =
            geometry::uv_tangents(&self.positions, &self.normals, &self.uvs, &self.indices);
    }
}

/// Fibres: polylines with a radius per vertex, rendered as round cones with spherical caps
/// (Cycles' "thick linear" curves) with one material, in world space. Strand `i` is
/// `points[offsets[i]..offsets[i + 1]]`; every strand has at least two points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Curves {
    pub name: String,
    pub points: Vec<[f32; 3]>,
    /// Metres, one per point, > 0.
    pub radii: Vec<f32>,
    /// `strand_count + 1` entries, starting at 0 and ending at `points.len()`.
    pub offsets: Vec<u32>,
    /// Index into [`Scene::materials`].
    pub material: u32,
}

/// Strands × segments beyond which a curve set is refused: 16 M segments (512 MiB of GPU
/// segments) is far above any head of hair (the built-in styles stay under 1 M).
pub const MAX_CURVE_SEGMENTS: usize = 1 << 24;

impl Curves {
    pub fn strand_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Segments over all strands.
    pub fn segment_count(&self) -> usize {
        self.offsets
            .windows(2)
            .map(|w| (w[1].saturating_sub(w[0]) as usize).saturating_sub(1))
            .sum()
    }

    /// Checks the invariants the GPU packing relies on; the reason names the first offending
    /// strand or point.
    pub fn validate(&self) -> Result<(), String> {
        if self.radii.len() != self.points.len() {
            return Err(format!(
                "{} radii for {} points; every point needs a radius",
                self.radii.len(),
                self.points.len()
            ));
        }
        match (self.offsets.first(), self.offsets.last()) {
            (Some(0), Some(&last)) if last as usize == self.points.len() => {}
            _ => {
                return Err(format!(
                    "strand offsets must run from 0 to the point count {}",
                    self.points.len()
                ))
            }
        }
        for (i, w) in self.offsets.windows(2).enumerate() {
            if w[1] < w[0] + 2 {
                return Err(format!(
                    "strand {i} has {} points; a strand needs at least 2",
                    w[1].saturating_sub(w[0])
                ));
            }
        }
        for (i, (p, &r)) in self.points.iter().zip(&self.radii).enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                return Err(format!("point {i} is not finite ({p:?})"));
            }
            if !(r.is_finite() && r > 0.0) {
                return Err(format!(
                    "point {i} has radius {r}; radii must be > 0 metres"
                ));
            }
        }
        let segments = self.segment_count();
        if segments > MAX_CURVE_SEGMENTS {
            return Err(format!(
                "{segments} segments, more than the {MAX_CURVE_SEGMENTS} a curve set may have"
            ));
        }
        Ok(())
    }
}

/// Decoded image, RGBA8 as stored in the file (no colour-space conversion).
#[derive(Clone, Debug)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    pub rgba8: Vec<u8>,
}

#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    /// Linear factor.
    pub base_color: [f32; 4],
    /// Index into [`Scene::textures`]; sRGB-encoded data.
    pub base_color_texture: Option<u32>,
    pub metallic: f32,
    pub roughness: f32,
    /// glTF packing: G = roughness, B = metallic.
    pub metallic_roughness_texture: Option<u32>,
    pub normal_texture: Option<u32>,
    pub normal_scale: f32,
    /// KHR_materials_specular specularFactor.
    pub specular: f32,
    /// KHR_materials_specular specularColorFactor.
    pub specular_color: [f32; 3],
    /// KHR_materials_transmission transmissionFactor.
    pub transmission: f32,
    /// KHR_materials_ior.
    pub ior: f32,
    pub double_sided: bool,
    /// Coverage in [0, 1] (glTF alpha): 1 for OPAQUE, the base-colour alpha for BLEND, 0 or 1 by
    /// the cutoff for MASK. Rendered as stochastic see-through (MakeHuman's corneas are BLEND 0.08
    /// in the file; the `cornea` model makes them clear instead).
    pub opacity: f32,
    /// Which surface model renders this material: [`MaterialModel::Gltf`] (the glTF
    /// metallic-roughness mapping) unless the file's `extras.lightfarm` names another. The
    /// layered models read every field below with Standard Surface semantics: `base_color`
    /// (× texture) is the diffuse colour, `metallic` the metalness, `roughness` the specular
    /// roughness, `specular` / `specular_color` / `ior` the dielectric specular layer.
    pub model: MaterialModel,
    /// What the `id` pass reports for pixels of this material.
    pub class: ObjectClass,
    /// Standard Surface `subsurface`: the fraction of the base that scatters below the surface
    /// (random walk) rather than diffusely at it.
    pub subsurface: f32,
    /// `subsurface_color`; `None` uses the base colour (with its texture), as the paper's skin.
    pub subsurface_color: Option<[f32; 3]>,
    /// `subsurface_radius`: mean free path per channel, in units of `subsurface_scale`.
    pub subsurface_radius: [f32; 3],
    /// `subsurface_scale` in scene units (metres): the paper's 0.225 cm is 0.00225.
    pub subsurface_scale: f32,
    /// `subsurface_anisotropy`: Henyey–Greenstein g of the medium, in (-1, 1).
    pub subsurface_anisotropy: f32,
    /// `coat` weight, `coat_color`, `coat_roughness`, `coat_IOR`: a clear GGX layer on top.
    pub coat: f32,
    pub coat_color: [f32; 3],
    pub coat_roughness: f32,
    pub coat_ior: f32,
    /// `sheen` weight, `sheen_color`, `sheen_roughness`: a Charlie sheen over the base.
    pub sheen: f32,
    pub sheen_color: [f32; 3],
    pub sheen_roughness: f32,
    /// A map multiplying `specular` (its A channel, linear, as KHR_materials_specular's
    /// specularTexture), e.g. a scan's specular-intensity map.
    pub specular_texture: Option<u32>,
    /// Standard Surface `thin_walled`: a transmissive surface (transmission > 0.5) is a thin
    /// clear sheet, one surface that reflects and passes light straight through (an eye's
    /// cornea), instead of the boundary of a refracting solid (a lens).
    pub thin_walled: bool,
    /// [`MaterialModel::Hair`] (fibres only): melanin and melanin redness in [0, 1] (the
    /// absorption σa they give is [`crate::hair::sigma_a_from_melanin`]), longitudinal and
    /// azimuthal roughness βm, βn in [0, 1], cuticle tilt α in degrees; `ior` is the fibre's.
    pub melanin: f32,
    pub melanin_redness: f32,
    pub longitudinal_roughness: f32,
    pub azimuthal_roughness: f32,
    pub cuticle_tilt_deg: f32,
}

/// The surface models a material can name in `extras.lightfarm.model`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum MaterialModel {
    /// The glTF 2.0 metallic-roughness mapping (Lambert + GGX, KHR_materials_specular).
    #[default]
    Gltf,
    /// The paper's aiStandardSurface skin: random-walk subsurface, specular, coat, sheen.
    Skin,
    /// Eyes: base colour, glossy specular, a coat; no subsurface, no sheen.
    Eye,
    /// Gums, tongue, inner mouth: wet, short-radius subsurface.
    Mouth,
    /// Teeth: a little subsurface under a glossy enamel specular.
    Teeth,
    /// Garments: diffuse + GGX with the file's colour and roughness.
    Cloth,
    /// Glossy plastic (glasses frames, headsets).
    Plastic,
    /// Metal: F0 = base colour.
    Metal,
    /// Eyeglass lens: the smooth dielectric.
    Lens,
    /// An eye's cornea: a thin-walled clear sheet (IOR 1.376) over the iris.
    Cornea,
    /// Hair fibres (curves only): Chiang et al. 2016, absorption from melanin.
    Hair,
}

impl MaterialModel {
    /// Index the shaders switch on (`MODEL_*` in shaders/inc/bindings.wgsl): 0 is the glTF
    /// mapping, anything else the layered Standard Surface.
    pub fn gpu_index(self) -> u32 {
        self as u32
    }
}

/// Object classes of the `id` pass (the table is written into every EXR header).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ObjectClass {
    #[default]
    Other = 0,
    Skin = 1,
    Eyes = 2,
    Mouth = 3,
    Hair = 4,
    Garment = 5,
    Frame = 6,
    Lens = 7,
    Headset = 8,
}

impl ObjectClass {
    pub const ALL: [ObjectClass; 9] = [
        ObjectClass::Other,
        ObjectClass::Skin,
        ObjectClass::Eyes,
        ObjectClass::Mouth,
        ObjectClass::Hair,
        ObjectClass::Garment,
        ObjectClass::Frame,
        ObjectClass::Lens,
        ObjectClass::Headset,
    ];

    pub fn name(self) -> &'static str {
        match self {
            ObjectClass::Other => "other",
            ObjectClass::Skin => "skin",
            ObjectClass::Eyes => "eyes",
            ObjectClass::Mouth => "mouth",
            ObjectClass::Hair => "hair",
            ObjectClass::Garment => "garment",
            ObjectClass::Frame => "frame",
            ObjectClass::Lens => "lens",
            ObjectClass::Headset => "headset",
        }
    }
}

impl Default for Material {
    /// The glTF 2.0 defaults, so a primitive without a material renders as the spec says.
    fn default() -> Self {
        Material {
            name: "default".to_string(),
            base_color: [1.0; 4],
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            metallic_roughness_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            specular: 1.0,
            specular_color: [1.0; 3],
            transmission: 0.0,
            ior: 1.5,
            double_sided: false,
            opacity: 1.0,
            model: MaterialModel::Gltf,
            class: ObjectClass::Other,
            subsurface: 0.0,
            subsurface_color: None,
            subsurface_radius: [1.0; 3],
            subsurface_scale: 0.01,
            subsurface_anisotropy: 0.0,
            coat: 0.0,
            coat_color: [1.0; 3],
            coat_roughness: 0.1,
            coat_ior: 1.5,
            sheen: 0.0,
            sheen_color: [1.0; 3],
            sheen_roughness: 0.3,
            specular_texture: None,
            thin_walled: false,
            melanin: 0.5,
            melanin_redness: 0.2,
            longitudinal_roughness: 0.3,
            azimuthal_roughness: 0.3,
            cuticle_tilt_deg: 2.0,
        }
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Instance {
    pub mesh: u32,
    /// Object to world.
    pub transform: Mat4,
}

#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub meshes: Vec<Mesh>,
    /// Fibre sets (hair, eyebrows, eyelashes), world space.
    pub curves: Vec<Curves>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub instances: Vec<Instance>,
    pub cameras: Vec<Camera>,
}

impl Scene {
    /// Loads the default scene (or scene 0) of a .glb/.gltf file; see [`load`] for details.
    pub fn load_gltf(path: &std::path::Path) -> Result<Scene, SceneError> {
        load::load_gltf(path)
    }

    /// World-space axis-aligned bounds over all instanced vertices and curve points, `None` for
    /// an empty scene.
    pub fn world_bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        let mut any = false;
        for inst in &self.instances {
            let Some(mesh) = self.meshes.get(inst.mesh as usize) else {
                continue;
            };
            for p in &mesh.positions {
                let w = inst.transform.transform_point3(Vec3::from(*p));
                if w.is_finite() {
                    lo = lo.min(w);
                    hi = hi.max(w);
                    any = true;
                }
            }
        }
        for p in self.curves.iter().flat_map(|c| &c.points) {
            let w = Vec3::from(*p);
            if w.is_finite() {
                lo = lo.min(w);
                hi = hi.max(w);
                any = true;
            }
        }
        any.then_some((lo, hi))
    }

    /// Triangles over all instances (an instanced mesh counts once per instance).
    pub fn triangle_count(&self) -> usize {
        self.instances
            .iter()
            .filter_map(|i| self.meshes.get(i.mesh as usize))
            .map(Mesh::triangle_count)
            .sum()
    }

    /// Appends `material`, `mesh` (all its triangles set to that material) and one instance of
    /// it; returns the new mesh's index.
    pub fn add_mesh_instance(
        &mut self,
        mut mesh: Mesh,
        material: Material,
        transform: Mat4,
    ) -> u32 {
        let material_index = self.materials.len() as u32;
        self.materials.push(material);
        mesh.triangle_materials = vec![material_index; mesh.triangle_count()];
        let mesh_index = self.meshes.len() as u32;
        self.meshes.push(mesh);
        self.instances.push(Instance {
            mesh: mesh_index,
            transform,
        });
        mesh_index
    }
}
