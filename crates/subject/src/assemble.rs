//! One [`SampleSpec`] → the scene, camera and lighting the renderer takes.

use std::collections::BTreeMap;
use std::path::PathBuf;

use glam::{Mat4, Quat, Vec3};
use lightfarm_render::passes::Pass;
use lightfarm_render::scene::{Camera, MaterialModel, Mesh, ObjectClass, Scene};
use lightfarm_scene::catalog::{Asset, AssetKind, Catalog};
use lightfarm_scene::expand::SampleSpec;

use crate::garment::{Body, CoverMap, GarmentFit};
use crate::glasses::{glasses_materials, place_glasses};
use crate::hair::{grow_eyebrows, grow_eyelashes, grow_hair, hair_fibre_material, Strands};
use crate::head::Head;
use crate::headset::{fit_headset, headset_materials};
use crate::landmarks::Landmarks;
use crate::SubjectError;

/// Where the camera looks, relative to the head: a little below the eyes and at the centre of
/// the skull, so a 30° camera 1 m away frames the head and shoulders as in the paper's figures.
const AIM_BELOW_EYES_M: f32 = 0.06;
const AIM_BEHIND_EYES_M: f32 = 0.085;

/// What the renderer needs for one sample.
#[derive(Clone, Debug)]
pub struct Assembled {
    pub scene: Scene,
    pub camera: Camera,
    /// The two environment maps: file, rotation (degrees about +Y), horizontal flip.
    pub lighting: Vec<(PathBuf, f32, bool)>,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub seed: u32,
    /// The appendix passes the sample asks for.
    pub passes: Vec<Pass>,
    /// Lights of the OLAT basis to render it under as well (0: none).
    pub olat: u32,
    pub stats: AssemblyStats,
}

/// Sizes of what was built, for logs and tests.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct AssemblyStats {
    pub hair_strands: usize,
    pub eyebrow_strands: usize,
    pub eyelash_strands: usize,
    pub triangles: usize,
    /// Skin triangles removed because the garment covers them.
    pub hidden_skin_triangles: usize,
    /// Skin vertices left outside the garment where it is worn (skin through cloth): 0 on a
    /// good fit.
    pub skin_through_garment: usize,
}

/// Resolves a sample's asset to its catalog entry and file, refusing a hash mismatch: a sample
/// expanded against other bytes would otherwise render silently different.
pub(crate) fn resolve<'a>(
    catalog: &'a Catalog,
    id: &str,
    blake3: &str,
    kind: AssetKind,
) -> Result<(&'a Asset, PathBuf), SubjectError> {
    let asset = catalog.get(id).ok_or_else(|| SubjectError::Asset {
        asset: id.to_owned(),
        reason: format!(
            "not in the catalog at {}: the sample was expanded against another asset pack",
            catalog.root.display()
        ),
    })?;
    if asset.kind != kind {
        return Err(SubjectError::Asset {
            asset: id.to_owned(),
            reason: format!("is a {}, the sample uses it as a {kind}", asset.kind),
        });
    }
    if !asset.blake3.eq_ignore_ascii_case(blake3) {
        return Err(SubjectError::Asset {
            asset: id.to_owned(),
            reason: format!(
                "the sample pins blake3 {blake3} but the catalog has {}: re-expand the sample \
                 against this catalog or install the asset pack it was made with",
                asset.blake3
            ),
        });
    }
    Ok((asset, catalog.path_of(asset)))
}

/// Appends every mesh, material, texture and instance of `src`, instances moved by `transform`.
pub fn append_scene(dst: &mut Scene, src: &Scene, transform: Mat4) {
    let material_base = dst.materials.len() as u32;
    let texture_base = dst.textures.len() as u32;
    let mesh_base = dst.meshes.len() as u32;
    dst.textures.extend(src.textures.iter().cloned());
    dst.materials.extend(src.materials.iter().map(|m| {
        let mut m = m.clone();
        for t in [
            &mut m.base_color_texture,
            &mut m.metallic_roughness_texture,
            &mut m.normal_texture,
            &mut m.specular_texture,
        ]
        .into_iter()
        .flatten()
        {
            *t += texture_base;
        }
        m
    }));
    dst.meshes.extend(src.meshes.iter().map(|mesh| {
        let mut mesh = mesh.clone();
        for m in mesh.triangle_materials.iter_mut() {
            *m += material_base;
        }
        mesh
    }));
    dst.instances.extend(
        src.instances
            .iter()
            .map(|i| lightfarm_render::scene::Instance {
                mesh: i.mesh + mesh_base,
                transform: transform * i.transform,
            }),
    );
    // Fibres are in world space: their points move, their radii scale with the transform.
    let scale = transform.determinant().abs().cbrt();
    dst.curves.extend(src.curves.iter().map(|c| {
        let mut c = c.clone();
        for p in c.points.iter_mut() {
            *p = transform.transform_point3(Vec3::from(*p)).to_array();
        }
        for r in c.radii.iter_mut() {
            *r *= scale;
        }
        c.material += material_base;
        c
    }));
}

/// The camera of a sample: on a sphere of `radius_m` about the world origin at the sampled
/// yaw (0 = in front of the face, +Z) and pitch (positive = above), looking at the origin.
pub fn sample_camera(sample: &SampleSpec) -> Result<Camera, SubjectError> {
    let c = &sample.camera;
    let rotation = Quat::from_rotation_y((c.yaw_deg as f32).to_radians())
        * Quat::from_rotation_x(-(c.pitch_deg as f32).to_radians());
    let position = rotation * Vec3::new(0.0, 0.0, c.radius_m as f32);
    Ok(Camera::look_at(position, Vec3::ZERO, c.fov_deg as f32)?)
}

/// Where the head's frame goes in the world: the aim point moved to the sampled offset.
pub fn subject_transform(lm: &Landmarks, offset_m: [f64; 3]) -> Mat4 {
    let eyes = lm.eye_centre();
    let aim = Vec3::new(
        eyes.x,
        eyes.y - AIM_BELOW_EYES_M,
        eyes.z - AIM_BEHIND_EYES_M,
    );
    Mat4::from_translation(Vec3::from_array(offset_m.map(|v| v as f32)) - aim)
}

fn load_scene(path: &std::path::Path, asset: &Asset) -> Result<Scene, SubjectError> {
    Scene::load_gltf(path).map_err(|e| SubjectError::Asset {
        asset: asset.id.clone(),
        reason: e.to_string(),
    })
}

/// World-space (head-frame) triangles of every instance of `scene` under `transform`.
fn triangles_of(scene: &Scene, transform: Mat4) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
            continue;
        };
        let m = transform * inst.transform;
        for tri in mesh.indices.chunks_exact(3) {
            let p = |k: usize| {
                mesh.positions
                    .get(tri[k] as usize)
                    .map(|p| m.transform_point3(Vec3::from(*p)))
            };
            if let (Some(a), Some(b), Some(c)) = (p(0), p(1), p(2)) {
                out.push([a, b, c]);
            }
        }
    }
    out
}

/// Removes the head's skin triangles the garment covers; returns how many.
/// Removes the skin the garment covers; returns (triangles removed, skin vertices still poking
/// through the cloth).
fn hide_covered_skin(head: &mut Head, cover: &CoverMap, collar_y: f32) -> (usize, usize) {
    let mut removed = 0;
    let mut poking = 0;
    let skin: Vec<bool> = head
        .scene
        .materials
        .iter()
        .map(|m| m.name.to_ascii_lowercase().contains("skin"))
        .collect();
    // Each head mesh is instanced once; editing it in place is then the same as editing
    // the instance.
    let instances: Vec<(u32, Mat4)> = head
        .scene
        .instances
        .iter()
        .map(|i| (i.mesh, i.transform))
        .collect();
    for (mesh_index, transform) in instances {
        let Some(mesh) = head.scene.meshes.get_mut(mesh_index as usize) else {
            continue;
        };
        let mut world: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| transform.transform_point3(Vec3::from(*p)))
            .collect();
        let covered: Vec<bool> = world
            .iter()
            .map(|p| p.y < collar_y - 0.005 && cover.covers(*p, 0.03))
            .collect();
        removed += retain_triangles(mesh, |material, tri| {
            let is_skin = skin.get(material as usize).copied().unwrap_or(false);
            !(is_skin
                && tri
                    .iter()
                    .all(|&v| covered.get(v as usize).copied().unwrap_or(false)))
        });
        let mut visible = vec![false; world.len()];
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let material = mesh.triangle_materials.get(t).copied().unwrap_or(0);
            if skin.get(material as usize).copied().unwrap_or(false) {
                for &v in tri {
                    if let Some(f) = visible.get_mut(v as usize) {
                        *f = true;
                    }
                }
            }
        }
        // Covered skin kept at the edge of the removed region (its triangle has an uncovered
        // corner) would pierce the cloth: it moves to just inside it.
        let to_mesh = transform.inverse();
        for (v, p) in world.iter_mut().enumerate() {
            if !(visible[v] && covered[v]) {
                continue;
            }
            if let Some(q) = cover.pull_inside(*p, 0.002) {
                mesh.positions[v] = to_mesh.transform_point3(q).to_array();
                *p = q;
            }
        }
        // 5 mm: the cover map's bins are 1 cm by 5°.
        for (v, p) in world.iter().enumerate() {
            if visible[v] && p.y < collar_y - 0.02 && cover.pokes_through(*p, 0.005) {
                poking += 1;
                tracing::debug!(
                    vertex = v,
                    mesh = mesh.name.as_str(),
                    position = ?p,
                    below_collar_m = collar_y - p.y,
                    outside_cloth_m = cover.outside_by(*p),
                    covered = covered[v],
                    "skin through the garment"
                );
            }
        }
    }
    (removed, poking)
}

/// The head's skin triangles in world space.
fn skin_triangles(head: &Head) -> Vec<[Vec3; 3]> {
    let scene = &head.scene;
    let mut out = Vec::new();
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
            continue;
        };
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let m = mesh.triangle_materials.get(t).copied().unwrap_or(0);
            let is_skin = scene
                .materials
                .get(m as usize)
                .is_some_and(|m| m.name.to_ascii_lowercase().contains("skin"));
            let corner = |k: usize| {
                mesh.positions
                    .get(tri[k] as usize)
                    .map(|p| inst.transform.transform_point3(Vec3::from(*p)))
            };
            if let (true, Some(a), Some(b), Some(c)) = (is_skin, corner(0), corner(1), corner(2)) {
                out.push([a, b, c]);
            }
        }
    }
    out
}

/// Keeps the triangles of `mesh` for which `keep(material, indices)` holds (a triangle without
/// a material entry counts as material 0); returns how many were dropped.
fn retain_triangles(mesh: &mut Mesh, mut keep: impl FnMut(u32, &[u32]) -> bool) -> usize {
    let mut indices = Vec::with_capacity(mesh.indices.len());
    let mut materials = Vec::with_capacity(mesh.triangle_materials.len());
    let mut dropped = 0;
    for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
        let material = mesh.triangle_materials.get(t).copied().unwrap_or(0);
        if keep(material, tri) {
            indices.extend_from_slice(tri);
            materials.push(material);
        } else {
            dropped += 1;
        }
    }
    mesh.indices = indices;
    mesh.triangle_materials = materials;
    dropped
}

/// Drops every triangle whose material is named `name` (case-insensitive).
fn remove_material_triangles(scene: &mut Scene, name: &str) {
    let doomed: Vec<bool> = scene
        .materials
        .iter()
        .map(|m| m.name.eq_ignore_ascii_case(name))
        .collect();
    for mesh in scene.meshes.iter_mut() {
        retain_triangles(mesh, |material, _| {
            !doomed.get(material as usize).copied().unwrap_or(false)
        });
    }
}

/// Builds sample `sample`'s scene from the assets of `catalog`.
pub fn assemble(sample: &SampleSpec, catalog: &Catalog) -> Result<Assembled, SubjectError> {
    let mut head = match &sample.head.synthetic {
        Some(synthetic) => crate::synthetic::synthetic_head(catalog, synthetic, sample)?,
        None => {
            let (head_asset, head_path) = resolve(
                catalog,
                &sample.head.id,
                &sample.head.blake3,
                AssetKind::Head,
            )?;
            Head::load(head_asset, &head_path, &sample.head.expression.weights)?
        }
    };
    let lm = head.landmarks;
    let to_world = subject_transform(&lm, sample.camera.subject_offset_m);
    let camera = sample_camera(sample)?;

    let mut stats = AssemblyStats::default();
    let mut parts = Scene::default();

    if let Some(g) = &sample.garment {
        let (asset, path) = resolve(catalog, &g.id, &g.blake3, AssetKind::Garment)?;
        let mut garment = load_scene(&path, asset)?;
        let (fitted, fitted_eyes) = garment_fitted_body(catalog, asset)?;
        let fit = match Body::measure(&head.surface, &lm) {
            Some(target) => {
                tracing::debug!(
                    neck = ?target.neck.centre,
                    neck_half_width_m = target.neck.half_width,
                    shoulder_half_width_m = target.shoulder_half_width,
                    eyes = ?lm.eye_centre(),
                    "garment fit: the body measured"
                );
                GarmentFit::new(&fitted, &target)
            }
            // ICT FaceKit meshes stop at the throat: no neck to measure.
            None => GarmentFit::by_eyes(&fitted, fitted_eyes, lm.eye_centre()),
        };
        for m in garment.materials.iter_mut() {
            // The cloth preset first (class garment), then the sampled look, as before.
            if m.model == MaterialModel::Gltf {
                m.apply_model(MaterialModel::Cloth);
            }
            m.class = ObjectClass::Garment;
            let [r, g_, b] = g.color_rgb.map(|v| v as f32);
            m.base_color = [r, g_, b, 1.0];
            m.base_color_texture = None;
            m.metallic = 0.0;
            m.roughness = g.roughness as f32;
            // Cloth has a weak, rough sheen-like reflection rather than a plastic highlight.
            m.specular = 0.5;
            m.double_sided = true;
        }
        fit.warp_scene(&mut garment);
        // A build the warp does not capture (a deep chest, a broad back) would leave skin
        // through the cloth: the cloth moves out to clear the skin by 4 mm.
        let skin = CoverMap::new(fit.body_axis(), &skin_triangles(&head));
        for mesh in garment.meshes.iter_mut() {
            let mut moved = false;
            for p in mesh.positions.iter_mut() {
                if let Some(q) = skin.push_outside(Vec3::from(*p), 0.004) {
                    *p = q.to_array();
                    moved = true;
                }
            }
            if moved {
                mesh.recompute_normals();
            }
        }
        let tris = triangles_of(&garment, Mat4::IDENTITY);
        let collar_y = tris
            .iter()
            .flatten()
            .map(|p| p.y)
            .fold(f32::NEG_INFINITY, f32::max);
        let cover = CoverMap::new(fit.body_axis(), &tris);
        (stats.hidden_skin_triangles, stats.skin_through_garment) =
            hide_covered_skin(&mut head, &cover, collar_y);
        append_scene(&mut parts, &garment, Mat4::IDENTITY);
    }

    let strands =
        grow_hair(&head.surface, &lm, &sample.hair, sample.hair.seed).map_err(|reason| {
            SubjectError::Asset {
                asset: format!("hair ({} on {})", sample.hair.style, head.id),
                reason,
            }
        })?;
    let brows = grow_eyebrows(&head.surface, &lm, sample.hair.seed ^ 0x9E37_79B9_7F4A_7C15);
    stats.hair_strands = strands.strand_count();
    stats.eyebrow_strands = brows.strand_count();
    let lashes = grow_eyelashes(
        &head.surface,
        &head.eyelids,
        sample.hair.seed ^ 0x2545_F491_4F6C_DD1D,
    );
    stats.eyelash_strands = lashes.strand_count();
    if lashes.strand_count() > 0 {
        // The fibres replace a head's own eyelash cards (the ICT heads' triangle strips).
        remove_material_triangles(&mut head.scene, "eyelashes");
    }
    let hair_material = parts.materials.len() as u32;
    parts
        .materials
        .push(hair_fibre_material("hair", &sample.hair));
    add_fibres(&mut parts, &strands, "hair", hair_material);
    add_fibres(&mut parts, &brows, "eyebrows", hair_material);
    add_fibres(&mut parts, &lashes, "eyelashes", hair_material);

    if let Some(g) = &sample.glasses {
        let (asset, path) = resolve(catalog, &g.id, &g.blake3, AssetKind::Glasses)?;
        let mut glasses = load_scene(&path, asset)?;
        glasses_materials(&mut glasses);
        let placed = place_glasses(&glasses, &lm, &head.surface)?;
        append_scene(&mut parts, &placed, Mat4::IDENTITY);
    }
    if let Some(h) = &sample.headset {
        let (asset, path) = resolve(catalog, &h.id, &h.blake3, AssetKind::Headset)?;
        let mut headset = load_scene(&path, asset)?;
        headset_materials(&mut headset);
        let fit = fit_headset(&headset, &lm).map_err(|reason| SubjectError::Asset {
            asset: asset.id.clone(),
            reason,
        })?;
        append_scene(&mut parts, &headset, fit);
    }

    let mut scene = Scene::default();
    append_scene(&mut scene, &head.scene, to_world);
    append_scene(&mut scene, &parts, to_world);
    stats.triangles = scene.triangle_count();

    let lighting = sample
        .lighting
        .iter()
        .map(|l| {
            let (_, path) = resolve(catalog, &l.hdri, &l.blake3, AssetKind::Hdri)?;
            Ok((path, l.rotation_deg as f32, l.flip))
        })
        .collect::<Result<Vec<_>, SubjectError>>()?;
    Ok(Assembled {
        scene,
        camera,
        lighting,
        width: sample.render.width,
        height: sample.render.height,
        spp: sample.render.spp,
        seed: sample.render.seed,
        passes: Pass::parse_list(&sample.render.passes).map_err(|reason| SubjectError::Asset {
            asset: "render.passes".into(),
            reason,
        })?,
        olat: sample.render.olat,
        stats,
    })
}

fn add_fibres(scene: &mut Scene, strands: &Strands, name: &str, material: u32) {
    if strands.strand_count() > 0 {
        scene.curves.push(strands.to_curves(name, material));
    }
}

/// The body a garment was fitted to (catalog tag `fitted_to`, a head id), and its eye centre.
fn garment_fitted_body(catalog: &Catalog, garment: &Asset) -> Result<(Body, Vec3), SubjectError> {
    let err = |reason: String| SubjectError::Asset {
        asset: garment.id.clone(),
        reason,
    };
    let body = garment.tags.get("fitted_to").ok_or_else(|| {
        err("has no `fitted_to` tag naming the head whose body it was fitted to".into())
    })?;
    let head_asset = catalog
        .get(body)
        .filter(|a| a.kind == AssetKind::Head)
        .ok_or_else(|| {
            err(format!(
                "tag fitted_to = {body:?} is not a head in the catalog"
            ))
        })?;
    let head = Head::load(head_asset, &catalog.path_of(head_asset), &BTreeMap::new())?;
    let measured = Body::measure(&head.surface, &head.landmarks).ok_or_else(|| {
        err(format!(
            "its body {body} has no neck 1.5-8 cm below the chin"
        ))
    })?;
    Ok((measured, head.landmarks.eye_centre()))
}
