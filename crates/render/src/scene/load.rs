//! glTF 2.0 (.glb / .gltf) to [`Scene`]: default scene's node tree, merged triangle primitives
//! per mesh, line primitives with `_RADIUS` as fibres ([`super::load_curves`]),
//! metallic-roughness materials with the specular/transmission/ior extensions and
//! `extras.lightfarm` ([`super::material`]), images as RGBA8 and perspective cameras.

use std::path::Path;

use glam::{Mat4, Vec3};

use super::geometry::{orthogonal_up, smooth_normals, unit_or_fallback, uv_tangents};
use super::load_curves::{is_curve_mode, read_mesh_curves, to_world};
use super::morph::{read_primitive_targets, target_names, MorphMerge};
use super::{Camera, Instance, Material, Mesh, Scene, SceneError, Texture};

/// Deeper hierarchies than this are almost certainly cycles, which the glTF validator of the
/// `gltf` crate does not reject.
const MAX_NODE_DEPTH: usize = 256;

pub(crate) fn load_gltf(path: &Path) -> Result<Scene, SceneError> {
    if !path.exists() {
        return Err(SceneError::NotFound {
            path: path.to_path_buf(),
        });
    }
    let (doc, buffers, images) = import_lenient(path).map_err(|source| SceneError::Gltf {
        path: path.to_path_buf(),
        source,
    })?;
    let buffer_bytes: Vec<&[u8]> = buffers.iter().map(|b| b.0.as_slice()).collect();

    let textures = images
        .iter()
        .enumerate()
        .map(|(index, img)| to_rgba8(img).map_err(|reason| bad_texture(path, index, reason)))
        .collect::<Result<Vec<_>, _>>()?;
    let mut materials: Vec<Material> = doc
        .materials()
        .map(|m| convert_material(m, path))
        .collect::<Result<_, _>>()?;

    // Lazily appended so files whose primitives all have materials carry no extra entry.
    let mut default_material: Option<u32> = None;
    let mut meshes: Vec<Option<Mesh>> = Vec::new();
    // Object-space curve sets per glTF mesh, placed per node below.
    let mut mesh_curves = Vec::new();
    for mesh in doc.meshes() {
        mesh_curves.push(read_mesh_curves(
            path,
            &mesh,
            &mesh_name(&mesh),
            &buffer_bytes,
            &materials,
        )?);
        let merged = load_mesh(
            path,
            &mesh,
            &buffer_bytes,
            &mut materials,
            &mut default_material,
        )?;
        meshes.push(merged);
    }

    let mut scene = Scene {
        textures,
        materials,
        ..Scene::default()
    };
    // Keep only meshes with triangles and renumber instances to match.
    let mut remap = vec![None; meshes.len()];
    for (i, m) in meshes.into_iter().enumerate() {
        if let Some(m) = m {
            remap[i] = Some(scene.meshes.len() as u32);
            scene.meshes.push(m);
        }
    }

    let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => {
            tracing::warn!(path = %path.display(), "glTF file has no scene; using all root nodes");
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    is_child[c.index()] = true;
                }
            }
            doc.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    };
    // Pushed in reverse so that popping visits nodes in file order, keeping output stable.
    let mut stack: Vec<(gltf::Node, Mat4, usize)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, Mat4::IDENTITY, 0))
        .collect();
    while let Some((node, parent, depth)) = stack.pop() {
        if depth > MAX_NODE_DEPTH {
            return Err(SceneError::BadNode {
                path: path.to_path_buf(),
                reason: format!(
                    "nesting deeper than {MAX_NODE_DEPTH} (a cycle through node {})",
                    node.index()
                ),
            });
        }
        let global = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            if let Some(Some(mesh_index)) = remap.get(mesh.index()) {
                scene.instances.push(Instance {
                    mesh: *mesh_index,
                    transform: global,
                });
            }
            for curves in mesh_curves.get(mesh.index()).into_iter().flatten() {
                let world = to_world(curves, global).map_err(|reason| SceneError::BadNode {
                    path: path.to_path_buf(),
                    reason: format!("node {}: {reason}", node.index()),
                })?;
                scene.curves.push(world);
            }
        }
        if let Some(cam) = node.camera() {
            match convert_camera(&cam, global) {
                Some(c) => scene.cameras.push(c),
                None => tracing::warn!(
                    path = %path.display(),
                    camera = cam.index(),
                    "skipping a camera that is orthographic or degenerately transformed"
                ),
            }
        }
        let children: Vec<gltf::Node> = node.children().collect();
        for child in children.into_iter().rev() {
            stack.push((child, global, depth + 1));
        }
    }
    if scene.instances.is_empty() && scene.curves.is_empty() {
        return Err(SceneError::NoGeometry {
            path: path.to_path_buf(),
        });
    }
    tracing::debug!(
        path = %path.display(),
        meshes = scene.meshes.len(),
        instances = scene.instances.len(),
        triangles = scene.triangle_count(),
        curve_sets = scene.curves.len(),
        "loaded glTF scene"
    );
    Ok(scene)
}

type Imported = (
    gltf::Document,
    Vec<gltf::buffer::Data>,
    Vec<gltf::image::Data>,
);

/// `gltf::import`, except that an accessor with neither `bufferView` nor `sparse` is accepted.
/// glTF 2.0 defines such an accessor as all zeros, and blend-shape exporters emit them for
/// targets that do not touch a primitive, but the `gltf` 1.4 validator reports them as
/// missing and would reject the whole file. Every other validation error still fails the
/// load; base attributes and indices without a bufferView are rejected by [`check_accessor`].
fn import_lenient(path: &Path) -> Result<Imported, gltf::Error> {
    use gltf::json::validation::{Error as Invalid, Validate};
    let file = std::fs::File::open(path).map_err(gltf::Error::Io)?;
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_reader_without_validation(std::io::BufReader::new(file))?;
    let json = document.as_json();
    let mut errors = Vec::new();
    json.validate(json, gltf::json::Path::new, &mut |path, error| {
        let path = path();
        let zero_accessor = matches!(error, Invalid::Missing) && {
            let p = path.as_str();
            p.starts_with("accessors[")
                && p.ends_with("].bufferView")
                && p.matches('.').count() == 1
        };
        if !zero_accessor {
            errors.push((path, error));
        }
    });
    if !errors.is_empty() {
        return Err(gltf::Error::Validation(errors));
    }
    // Same base directory rule as `gltf::import`, for external buffers and images.
    let base = path.parent().unwrap_or_else(|| Path::new("./"));
    let buffers = gltf::import_buffers(&document, Some(base), blob)?;
    let images = gltf::import_images(&document, Some(base), &buffers)?;
    Ok((document, buffers, images))
}

fn bad_texture(path: &Path, index: usize, reason: String) -> SceneError {
    SceneError::BadTexture {
        path: path.to_path_buf(),
        index,
        reason,
    }
}

fn convert_camera(cam: &gltf::Camera, global: Mat4) -> Option<Camera> {
    let gltf::camera::Projection::Perspective(p) = cam.projection() else {
        return None;
    };
    let position = global.transform_point3(Vec3::ZERO);
    let forward = global.transform_vector3(-Vec3::Z).normalize_or_zero();
    let up_hint = global.transform_vector3(Vec3::Y);
    let yfov_deg = p.yfov().to_degrees();
    if forward == Vec3::ZERO || !position.is_finite() || !(yfov_deg > 0.0 && yfov_deg < 180.0) {
        return None;
    }
    Some(Camera {
        position,
        forward,
        up: orthogonal_up(forward, up_hint),
        yfov_deg,
    })
}

/// The glTF material `m` of the file at `path`, with its `extras.lightfarm` applied (see
/// [`super::material`]); a bad `extras.lightfarm` is an error.
fn convert_material(m: gltf::Material, path: &Path) -> Result<Material, SceneError> {
    let pbr = m.pbr_metallic_roughness();
    // Scene::textures holds one entry per glTF image, so a texture resolves to its image.
    let tex = |info: Option<gltf::texture::Info>| {
        info.map(|i| {
            if i.tex_coord() != 0 {
                tracing::warn!(material = ?m.name(), "texture uses TEXCOORD_{}; only TEXCOORD_0 is loaded", i.tex_coord());
            }
            i.texture().source().index() as u32
        })
    };
    let defaults = Material::default();
    let (specular, specular_color) = m
        .specular()
        .map(|s| (s.specular_factor(), s.specular_color_factor()))
        .unwrap_or((defaults.specular, defaults.specular_color));
    let specular_texture = tex(m.specular().and_then(|s| s.specular_texture()));
    let normal = m.normal_texture();
    let mut material = Material {
        name: m
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0))),
        base_color: pbr.base_color_factor(),
        base_color_texture: tex(pbr.base_color_texture()),
        metallic: pbr.metallic_factor(),
        roughness: pbr.roughness_factor(),
        metallic_roughness_texture: tex(pbr.metallic_roughness_texture()),
        normal_texture: normal.as_ref().map(|n| n.texture().source().index() as u32),
        normal_scale: normal.as_ref().map_or(1.0, |n| n.scale()),
        specular,
        specular_color,
        specular_texture,
        transmission: m
            .transmission()
            .map_or(defaults.transmission, |t| t.transmission_factor()),
        ior: m.ior().unwrap_or(defaults.ior),
        double_sided: m.double_sided(),
        opacity: match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => 1.0,
            gltf::material::AlphaMode::Blend => pbr.base_color_factor()[3].clamp(0.0, 1.0),
            gltf::material::AlphaMode::Mask => {
                if pbr.base_color_factor()[3] >= m.alpha_cutoff().unwrap_or(0.5) {
                    1.0
                } else {
                    0.0
                }
            }
        },
        ..defaults
    };
    if let Some(extras) = m.extras() {
        super::material::apply_extras(&mut material, extras.get(), path)?;
    }
    Ok(material)
}

/// The mesh's name in the file, else `mesh<index>`.
fn mesh_name(mesh: &gltf::Mesh) -> String {
    mesh.name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("mesh{}", mesh.index()))
}

/// Merges the triangle primitives of `mesh`; `None` when it has none.
fn load_mesh(
    path: &Path,
    mesh: &gltf::Mesh,
    buffers: &[&[u8]],
    materials: &mut Vec<Material>,
    default_material: &mut Option<u32>,
) -> Result<Option<Mesh>, SceneError> {
    let name = mesh_name(mesh);
    let bad = |reason: String| SceneError::BadPrimitive {
        path: path.to_path_buf(),
        mesh: name.clone(),
        reason,
    };
    let mut out = Mesh {
        name: name.clone(),
        positions: Vec::new(),
        normals: Vec::new(),
        uvs: Vec::new(),
        tangents: Vec::new(),
        indices: Vec::new(),
        triangle_materials: Vec::new(),
        morph_targets: Vec::new(),
    };
    let mut morphs = MorphMerge::new();
    for prim in mesh.primitives() {
        if is_curve_mode(prim.mode()) {
            continue;
        }
        if prim.mode() != gltf::mesh::Mode::Triangles {
            tracing::warn!(path = %path.display(), mesh = %name, mode = ?prim.mode(), "skipping a non-triangle primitive");
            continue;
        }
        for (_, accessor) in prim.attributes() {
            check_accessor(&accessor, buffers).map_err(&bad)?;
        }
        if let Some(a) = prim.indices() {
            check_accessor(&a, buffers).map_err(&bad)?;
        }
        let reader = prim.reader(|b| buffers.get(b.index()).copied());
        let positions: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or_else(|| {
                bad(format!(
                    "primitive {} has no POSITION attribute",
                    prim.index()
                ))
            })?
            .collect();
        let n = positions.len();
        let indices: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..n as u32).collect(),
        };
        if !indices.len().is_multiple_of(3) {
            return Err(bad(format!(
                "primitive {} has {} indices, not a multiple of 3",
                prim.index(),
                indices.len()
            )));
        }
        if let Some(&i) = indices.iter().find(|&&i| i as usize >= n) {
            return Err(bad(format!(
                "primitive {} has index {i} but only {n} vertices",
                prim.index()
            )));
        }
        let uvs: Option<Vec<[f32; 2]>> = reader
            .read_tex_coords(0)
            .map(|t| t.into_f32().collect::<Vec<_>>())
            .filter(|t| t.len() == n);
        let file_normals: Option<Vec<[f32; 3]>> = reader
            .read_normals()
            .map(|r| r.collect::<Vec<_>>())
            .filter(|v| v.len() == n);
        let normals = match file_normals {
            Some(file) => {
                // Degenerate normals in the file fall back to the computed smooth normal.
                let mut computed: Option<Vec<[f32; 3]>> = None;
                file.iter()
                    .enumerate()
                    .map(|(i, v)| {
                        let u = Vec3::from(*v).normalize_or_zero();
                        if u != Vec3::ZERO && u.is_finite() {
                            u.to_array()
                        } else {
                            computed.get_or_insert_with(|| smooth_normals(&positions, &indices))[i]
                        }
                    })
                    .collect()
            }
            None => smooth_normals(&positions, &indices),
        };
        let file_tangents: Option<Vec<[f32; 4]>> = reader
            .read_tangents()
            .map(|r| r.collect::<Vec<_>>())
            .filter(|v| v.len() == n);
        let tangents = match (&uvs, file_tangents) {
            (_, Some(t)) => t
                .into_iter()
                .map(|t| {
                    let xyz = unit_or_fallback(Vec3::new(t[0], t[1], t[2]));
                    [xyz[0], xyz[1], xyz[2], if t[3] < 0.0 { -1.0 } else { 1.0 }]
                })
                .collect(),
            (Some(uv), None) => uv_tangents(&positions, &normals, uv, &indices),
            (None, None) => vec![[0.0; 4]; n],
        };
        let prim_targets = read_primitive_targets(&prim, buffers, n).map_err(&bad)?;
        let material = match prim.material().index() {
            Some(m) => m as u32,
            None => *default_material.get_or_insert_with(|| {
                materials.push(Material::default());
                (materials.len() - 1) as u32
            }),
        };
        let base = out.positions.len() as u64;
        if base + n as u64 > u32::MAX as u64 {
            return Err(bad("more than 2^32 vertices".to_string()));
        }
        let base = base as u32;
        out.indices.extend(indices.iter().map(|i| i + base));
        out.triangle_materials
            .extend(std::iter::repeat_n(material, indices.len() / 3));
        out.positions.extend(positions);
        out.normals.extend(normals);
        out.uvs.extend(uvs.unwrap_or_else(|| vec![[0.0; 2]; n]));
        out.tangents.extend(tangents);
        morphs.push(&name, prim_targets, n);
    }
    let target_count = mesh
        .primitives()
        .find(|p| p.mode() == gltf::mesh::Mode::Triangles)
        .map_or(0, |p| p.morph_targets().len());
    let names = (target_count > 0)
        .then(|| target_names(mesh, target_count))
        .flatten();
    out.morph_targets = morphs.finish(names);
    Ok((!out.indices.is_empty()).then_some(out))
}

/// Bounds-checks an accessor before the `gltf` reader walks it: the reader computes
/// `stride * (count - 1)` unchecked, which panics on a zero count or overflows on a hostile one.
pub(super) fn check_accessor(a: &gltf::Accessor, buffers: &[&[u8]]) -> Result<(), String> {
    let idx = a.index();
    if a.sparse().is_some() {
        return Err(format!("accessor {idx} is sparse, which is not supported"));
    }
    let count = a.count();
    if count == 0 {
        return Err(format!("accessor {idx} has count 0"));
    }
    let Some(view) = a.view() else {
        return Err(format!("accessor {idx} has no bufferView"));
    };
    let elem = a.size();
    let stride = view.stride().unwrap_or(elem);
    let needed = stride
        .checked_mul(count - 1)
        .and_then(|x| x.checked_add(elem))
        .and_then(|x| x.checked_add(a.offset()));
    let buf_len = buffers.get(view.buffer().index()).map_or(0, |b| b.len());
    let view_end = view.offset().checked_add(view.length());
    match (needed, view_end) {
        (Some(needed), Some(view_end)) if needed <= view.length() && view_end <= buf_len => Ok(()),
        _ => Err(format!(
            "accessor {idx} ({count} elements) reaches past its bufferView {} or buffer {}",
            view.index(),
            view.buffer().index()
        )),
    }
}

fn to_rgba8(img: &gltf::image::Data) -> Result<Texture, String> {
    use gltf::image::Format;
    let (channels, bytes_per) = match img.format {
        Format::R8 => (1, 1),
        Format::R8G8 => (2, 1),
        Format::R8G8B8 => (3, 1),
        Format::R8G8B8A8 => (4, 1),
        Format::R16 => (1, 2),
        Format::R16G16 => (2, 2),
        Format::R16G16B16 => (3, 2),
        Format::R16G16B16A16 => (4, 2),
        Format::R32G32B32FLOAT => (3, 4),
        Format::R32G32B32A32FLOAT => (4, 4),
    };
    let pixels = (img.width as usize)
        .checked_mul(img.height as usize)
        .ok_or("image dimensions overflow")?;
    let expected = pixels * channels * bytes_per;
    if pixels == 0 || img.pixels.len() < expected {
        return Err(format!(
            "{}x{} {:?} image has {} bytes of pixel data, expected {expected}",
            img.width,
            img.height,
            img.format,
            img.pixels.len()
        ));
    }
    // R8 / R16 come from greyscale images, hence the replication. Each sample to 8 bits without colour conversion: 16-bit keeps its high byte, float is
    // clamped to [0,1].
    let sample = |i: usize| -> u8 {
        let o = i * bytes_per;
        let s = &img.pixels[o..o + bytes_per];
        match bytes_per {
            1 => s[0],
            2 => (u16::from_ne_bytes([s[0], s[1]]) >> 8) as u8,
            _ => {
                let f = f32::from_ne_bytes([s[0], s[1], s[2], s[3]]);
                (f.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
            }
        }
    };
    let mut rgba8 = Vec::with_capacity(pixels * 4);
    for p in 0..pixels {
        let c = |k: usize| sample(p * channels + k);
        let px = match channels {
            1 => [c(0), c(0), c(0), 255],
            // The gltf crate reports grey+alpha images (PNG LumaA) as R8G8 / R16G16.
            2 => [c(0), c(0), c(0), c(1)],
            3 => [c(0), c(1), c(2), 255],
            _ => [c(0), c(1), c(2), c(3)],
        };
        rgba8.extend_from_slice(&px);
    }
    Ok(Texture {
        width: img.width,
        height: img.height,
        rgba8,
    })
}
