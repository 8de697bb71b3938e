//! Minimal .glb writer so tests and tools can turn scenes into files that go through the real
//! loader (and open in Blender): geometry, materials with their glTF factors and textures
//! (base colour, metallic-roughness, normal, KHR_materials_specular's specular texture; each
//! texture a PNG inside the file, bytes as in [`Scene::textures`]; `hair` materials carry their
//! `extras.lightfarm`, other models are written as their glTF factors), one node per instance,
//! one mesh and node per curve set (one indexed `LINES` primitive with `POSITION` and
//! `_RADIUS`, which the loader chains back into the same strands) and the perspective cameras.

use std::path::Path;

use glam::{Mat4, Vec3};
use serde_json::{json, Value};

use super::load_curves::RADIUS_ATTRIBUTE;
use super::{Curves, Material, MaterialModel, Scene, SceneError};

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const MODE_LINES: u32 = 1;

/// Accumulates the single binary buffer with its views and accessors.
#[derive(Default)]
struct Bin {
    data: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Bin {
    fn push(&mut self, bytes: &[u8], target: u32, accessor: Value) -> usize {
        let view = self.view(bytes);
        self.views[view]["target"] = json!(target);
        let mut accessor = accessor;
        accessor["bufferView"] = json!(view);
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// A view of `bytes` with no target (what images use). All components are 4 bytes wide,
    /// so 4-byte alignment satisfies glTF's rules.
    fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.data.len().is_multiple_of(4) {
            self.data.push(0);
        }
        self.views.push(json!({
            "buffer": 0,
            "byteOffset": self.data.len(),
            "byteLength": bytes.len(),
        }));
        self.data.extend_from_slice(bytes);
        self.views.len() - 1
    }

    fn floats<const N: usize>(&mut self, items: &[[f32; N]], ty: &str, bounds: bool) -> usize {
        let mut acc = json!({"componentType": FLOAT, "count": items.len(), "type": ty});
        if bounds {
            // POSITION accessors must carry min/max per the glTF spec.
            let mut lo = [f32::INFINITY; N];
            let mut hi = [f32::NEG_INFINITY; N];
            for it in items {
                for k in 0..N {
                    lo[k] = lo[k].min(it[k]);
                    hi[k] = hi[k].max(it[k]);
                }
            }
            acc["min"] = json!(lo.to_vec());
            acc["max"] = json!(hi.to_vec());
        }
        let bytes: Vec<u8> = items
            .iter()
            .flatten()
            .flat_map(|f| f.to_le_bytes())
            .collect();
        self.push(&bytes, ARRAY_BUFFER, acc)
    }
}

fn material_json(m: &Material) -> Value {
    let d = Material::default();
    let mut ext = serde_json::Map::new();
    if m.transmission != d.transmission {
        ext.insert(
            "KHR_materials_transmission".into(),
            json!({"transmissionFactor": m.transmission}),
        );
    }
    if m.ior != d.ior {
        ext.insert("KHR_materials_ior".into(), json!({"ior": m.ior}));
    }
    if m.specular != d.specular
        || m.specular_color != d.specular_color
        || m.specular_texture.is_some()
    {
        let mut spec =
            json!({"specularFactor": m.specular, "specularColorFactor": m.specular_color});
        if let Some(t) = m.specular_texture {
            spec["specularTexture"] = json!({"index": t});
        }
        ext.insert("KHR_materials_specular".into(), spec);
    }
    let mut v = json!({
        "name": m.name,
        "pbrMetallicRoughness": {
            "baseColorFactor": m.base_color,
            "metallicFactor": m.metallic,
            "roughnessFactor": m.roughness,
        },
        "doubleSided": m.double_sided,
    });
    if let Some(t) = m.base_color_texture {
        v["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": t});
    }
    if let Some(t) = m.metallic_roughness_texture {
        v["pbrMetallicRoughness"]["metallicRoughnessTexture"] = json!({"index": t});
    }
    if let Some(t) = m.normal_texture {
        v["normalTexture"] = json!({"index": t, "scale": m.normal_scale});
    }
    if !ext.is_empty() {
        v["extensions"] = Value::Object(ext);
    }
    if m.model == MaterialModel::Hair {
        // The hair preset sets the fibre parameters, so all of them are written as overrides.
        v["extras"] = json!({"lightfarm": {
            "model": MaterialModel::Hair.name(),
            "melanin": m.melanin,
            "melanin_redness": m.melanin_redness,
            "longitudinal_roughness": m.longitudinal_roughness,
            "azimuthal_roughness": m.azimuthal_roughness,
            "cuticle_tilt": m.cuticle_tilt_deg,
            "specular_IOR": m.ior,
        }});
    }
    v
}

/// One mesh of `curves`: a single `LINES` primitive over the points in strand order, u32
/// indices pairing each point with the next one of its strand.
fn curves_mesh(bin: &mut Bin, curves: &Curves, scene: &Scene) -> Result<Value, String> {
    curves.validate()?;
    let material = scene
        .materials
        .get(curves.material as usize)
        .ok_or_else(|| format!("its material {} does not exist", curves.material))?;
    if material.model != MaterialModel::Hair {
        return Err(format!(
            "its material '{}' has model \"{}\"; curves need a hair material \
             (MaterialModel::Hair), which is what the loader accepts",
            material.name, material.model
        ));
    }
    let mut indices: Vec<u32> = Vec::with_capacity(2 * curves.segment_count());
    for w in curves.offsets.windows(2) {
        for i in w[0]..w[1] - 1 {
            indices.extend([i, i + 1]);
        }
    }
    let radii: Vec<[f32; 1]> = curves.radii.iter().map(|&r| [r]).collect();
    let attributes = json!({
        "POSITION": bin.floats(&curves.points, "VEC3", true),
        RADIUS_ATTRIBUTE: bin.floats(&radii, "SCALAR", false),
    });
    let acc = json!({"componentType": UNSIGNED_INT, "count": indices.len(), "type": "SCALAR"});
    let bytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
    let indices = bin.push(&bytes, ELEMENT_ARRAY_BUFFER, acc);
    Ok(json!({
        "name": curves.name,
        "primitives": [{
            "attributes": attributes,
            "indices": indices,
            "material": curves.material,
            "mode": MODE_LINES,
        }],
    }))
}

/// A texture as an RGBA PNG, bytes unchanged (sRGB or linear as the material reads them).
fn png_bytes(t: &super::Texture) -> Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let n = (t.width as usize) * (t.height as usize) * 4;
    if t.width == 0 || t.height == 0 || t.rgba8.len() != n {
        return Err(format!(
            "{}x{} texture has {} bytes, expected {n}",
            t.width,
            t.height,
            t.rgba8.len()
        ));
    }
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(&t.rgba8, t.width, t.height, image::ExtendedColorType::Rgba8)
    .map_err(|e| e.to_string())?;
    Ok(out)
}

/// Writes `scene` as a binary glTF 2.0 file.
pub fn write_glb(scene: &Scene, path: &Path) -> Result<(), SceneError> {
    let err = |reason: String| SceneError::Export {
        path: path.to_path_buf(),
        reason,
    };
    for m in &scene.materials {
        let named = [
            m.base_color_texture,
            m.metallic_roughness_texture,
            m.normal_texture,
            m.specular_texture,
        ];
        if let Some(t) = named
            .into_iter()
            .flatten()
            .find(|&t| t as usize >= scene.textures.len())
        {
            return Err(err(format!(
                "material '{}' names texture {t}, but the scene has {}",
                m.name,
                scene.textures.len()
            )));
        }
    }
    let mut bin = Bin::default();
    let mut images = Vec::new();
    for (ti, t) in scene.textures.iter().enumerate() {
        let png = png_bytes(t).map_err(|e| err(format!("texture {ti}: {e}")))?;
        images.push(json!({"bufferView": bin.view(&png), "mimeType": "image/png"}));
    }
    let mut meshes = Vec::new();
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        let n = mesh.positions.len();
        if mesh.normals.len() != n || mesh.uvs.len() != n || mesh.tangents.len() != n {
            return Err(err(format!(
                "mesh {mi} '{}' has attribute arrays of different lengths",
                mesh.name
            )));
        }
        if mesh.triangle_materials.len() != mesh.triangle_count() || n == 0 {
            return Err(err(format!(
                "mesh {mi} '{}' is empty or its triangle_materials do not match its triangles",
                mesh.name
            )));
        }
        let mut attributes = json!({
            "POSITION": bin.floats(&mesh.positions, "VEC3", true),
            "NORMAL": bin.floats(&mesh.normals, "VEC3", false),
            "TEXCOORD_0": bin.floats(&mesh.uvs, "VEC2", false),
        });
        // An all-zero tangent array means "no UVs"; glTF forbids zero-length tangents.
        if mesh
            .tangents
            .iter()
            .all(|t| t[0] != 0.0 || t[1] != 0.0 || t[2] != 0.0)
        {
            attributes["TANGENT"] = json!(bin.floats(&mesh.tangents, "VEC4", false));
        }
        // glTF primitives carry one material each, so triangles are grouped by material.
        let mut groups: Vec<(u32, Vec<u32>)> = Vec::new();
        for (tri, &mat) in mesh.indices.chunks_exact(3).zip(&mesh.triangle_materials) {
            if tri.iter().any(|&i| i as usize >= n) || mat as usize >= scene.materials.len() {
                return Err(err(format!(
                    "mesh {mi} '{}' has an index or material out of range",
                    mesh.name
                )));
            }
            match groups.iter_mut().find(|g| g.0 == mat) {
                Some(g) => g.1.extend_from_slice(tri),
                None => groups.push((mat, tri.to_vec())),
            }
        }
        let primitives: Vec<Value> = groups
            .iter()
            .map(|(mat, idx)| {
                let acc =
                    json!({"componentType": UNSIGNED_INT, "count": idx.len(), "type": "SCALAR"});
                let bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
                let indices = bin.push(&bytes, ELEMENT_ARRAY_BUFFER, acc);
                json!({"attributes": attributes, "indices": indices, "material": mat, "mode": 4})
            })
            .collect();
        meshes.push(json!({"name": mesh.name, "primitives": primitives}));
    }

    let mut nodes: Vec<Value> = Vec::new();
    for inst in &scene.instances {
        if inst.mesh as usize >= scene.meshes.len() {
            return Err(err(format!(
                "an instance refers to missing mesh {}",
                inst.mesh
            )));
        }
        nodes.push(json!({"mesh": inst.mesh, "matrix": inst.transform.to_cols_array().to_vec()}));
    }
    // Curves are world space: a node without a transform each, so the loader bakes nothing.
    for (ci, curves) in scene.curves.iter().enumerate() {
        let mesh = curves_mesh(&mut bin, curves, scene)
            .map_err(|reason| err(format!("curve set {ci} '{}': {reason}", curves.name)))?;
        nodes.push(json!({"mesh": meshes.len()}));
        meshes.push(mesh);
    }
    let mut cameras = Vec::new();
    for (ci, cam) in scene.cameras.iter().enumerate() {
        // glTF cameras look along local -Z with local +Y up.
        let right = cam.forward.cross(cam.up).normalize_or_zero();
        let m = Mat4::from_cols(
            right.extend(0.0),
            cam.up.extend(0.0),
            (-cam.forward).extend(0.0),
            cam.position.extend(1.0),
        );
        if right == Vec3::ZERO || !m.is_finite() {
            return Err(err(format!("camera {ci} has no valid orientation")));
        }
        cameras.push(json!({
            "type": "perspective",
            "perspective": {"yfov": cam.yfov_deg.to_radians(), "znear": 0.01},
        }));
        nodes.push(json!({"camera": ci, "matrix": m.to_cols_array().to_vec()}));
    }
    while !bin.data.len().is_multiple_of(4) {
        bin.data.push(0);
    }

    let used: Vec<&str> = [
        "KHR_materials_transmission",
        "KHR_materials_ior",
        "KHR_materials_specular",
    ]
    .into_iter()
    .filter(|e| {
        scene.materials.iter().any(|m| {
            material_json(m)
                .get("extensions")
                .is_some_and(|x| x.get(*e).is_some())
        })
    })
    .collect();
    let mut root = json!({
        "asset": {"version": "2.0", "generator": "lightfarm"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": scene.materials.iter().map(material_json).collect::<Vec<_>>(),
        "accessors": bin.accessors,
        "bufferViews": bin.views,
        "buffers": [{"byteLength": bin.data.len()}],
    });
    if !cameras.is_empty() {
        root["cameras"] = json!(cameras);
    }
    if !images.is_empty() {
        // One texture per image with a repeating, mipmapped sampler: the loader's "texture i
        // is image i".
        root["textures"] = json!((0..images.len())
            .map(|i| json!({"source": i, "sampler": 0}))
            .collect::<Vec<_>>());
        root["images"] = json!(images);
        root["samplers"] =
            json!([{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}]);
    }
    if !used.is_empty() {
        root["extensionsUsed"] = json!(used);
    }
    // Validating through gltf-json catches a malformed document here, not in the reader.
    let mut text = serde_json::to_vec(&root).map_err(|e| err(e.to_string()))?;
    gltf::json::Root::from_slice(&text)
        .map_err(|e| err(format!("internal error, generated invalid glTF JSON: {e}")))?;
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }

    let total = 12
        + 8
        + text.len()
        + if bin.data.is_empty() {
            0
        } else {
            8 + bin.data.len()
        };
    let total =
        u32::try_from(total).map_err(|_| err("scene exceeds the 4 GiB .glb limit".into()))?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    if !bin.data.is_empty() {
        out.extend_from_slice(&(bin.data.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin.data);
    }
    std::fs::write(path, out)
        .map_err(|e| err(format!("{e}; check the directory exists and is writable")))
}
