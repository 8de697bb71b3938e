//! A head asset in the canonical frame: its scene, skin surface and landmarks.

use std::collections::BTreeMap;
use std::path::Path;

use glam::{Mat4, Vec3};
use lightfarm_render::scene::{MaterialModel, ObjectClass, Scene};
use lightfarm_scene::catalog::Asset;

use crate::eyelids::{find_lids, EyeLids, LidPoints};
use crate::landmarks::{HeadSurface, Landmarks};
use crate::SubjectError;

/// Material names (lower-cased substrings) that mark skin: hair roots go there and strands
/// must stay outside it.
const SKIN_NAMES: [&str; 1] = ["skin"];

/// Material names of eyeballs, in order of preference: the sclera/eyeball mesh gives the
/// eyeball centre; a cornea bulges forward, so it is used only when nothing else is there.
const EYE_NAMES: [&[&str]; 2] = [&["sclera", "eyes", "eyeball"], &["cornea", "iris"]];

/// The model and class of a built-in head's material, by lower-cased material name
/// (MakeHuman: skin, eyes, cornea, teeth, tongue; ICT FaceKit: skin, gums_tongue, teeth,
/// sclera, iris, eyelashes; the Lee Perry-Smith scan: LeePerrySmith_skin). A `None` model keeps
/// the glTF one and only sets the class; unknown names are not mapped at all.
fn head_material(name: &str) -> Option<(Option<MaterialModel>, ObjectClass)> {
    use MaterialModel as M;
    use ObjectClass as C;
    Some(match name {
        "skin" | "skin_face" | "skin_body" | "leeperrysmith_skin" => (Some(M::Skin), C::Skin),
        "eyes" | "sclera" | "iris" => (Some(M::Eye), C::Eyes),
        "cornea" => (Some(M::Cornea), C::Eyes),
        "teeth" => (Some(M::Teeth), C::Mouth),
        "tongue" | "gums_tongue" => (Some(M::Mouth), C::Mouth),
        "eyelashes" => (None, C::Hair),
        _ => return None,
    })
}

/// Gives the head's materials their models ([`head_material`], presets of
/// [`lightfarm_render::scene::Material::apply_model`]) and classes. A material whose file
/// carries `extras.lightfarm` (its model is no longer glTF) is left as the file says, and so is
/// any name not in the table.
pub fn assign_head_materials(scene: &mut Scene) {
    for m in scene.materials.iter_mut() {
        if m.model != MaterialModel::Gltf {
            continue;
        }
        if let Some((model, class)) = head_material(&m.name.to_ascii_lowercase()) {
            if let Some(model) = model {
                m.apply_model(model);
            }
            m.class = class;
        }
    }
}

/// A loaded head, every mesh already moved into the canonical frame.
#[derive(Clone, Debug)]
pub struct Head {
    pub id: String,
    pub scene: Scene,
    pub surface: HeadSurface,
    pub landmarks: Landmarks,
    /// Lid margins of the eyes whose margins were found ([`crate::eyelids`]); empty for heads
    /// without eyeball meshes (the scan).
    pub eyelids: Vec<EyeLids>,
}

fn asset_error(asset: &Asset, reason: impl Into<String>) -> SubjectError {
    SubjectError::Asset {
        asset: asset.id.clone(),
        reason: reason.into(),
    }
}

fn material_matches(scene: &Scene, material: u32, names: &[&str]) -> bool {
    scene
        .materials
        .get(material as usize)
        .map(|m| m.name.to_ascii_lowercase())
        .is_some_and(|n| names.iter().any(|k| n.contains(k)) && !n.contains("lash"))
}

impl Head {
    /// Loads `asset` (a head file at `path`), gives its materials their models
    /// ([`assign_head_materials`]), applies the expression's morph weights (unknown morph names
    /// are an error naming them), and moves it into the canonical frame. Eyeballs that cover
    /// their iris get a clear cornea ([`crate::cornea::clear_corneas`]) after the landmarks are
    /// found, so the eyeball centres are those of the whole balls.
    pub fn load(
        asset: &Asset,
        path: &Path,
        expression: &BTreeMap<String, f64>,
    ) -> Result<Head, SubjectError> {
        let mut scene = Scene::load_gltf(path)?;
        assign_head_materials(&mut scene);
        Head::from_scene(asset, scene, expression)
    }

    /// [`Head::load`] for a scene already in memory (a generated person: `asset` is then a
    /// catalog-less description carrying its id, no frame and no landmark table).
    pub fn from_scene(
        asset: &Asset,
        mut scene: Scene,
        expression: &BTreeMap<String, f64>,
    ) -> Result<Head, SubjectError> {
        if scene.instances.is_empty() {
            return Err(asset_error(asset, "the file has no mesh instances"));
        }
        if let Some(frame) = &asset.frame {
            let to_canonical =
                Mat4::from_translation(Vec3::from_array(frame.translate.map(|v| v as f32)))
                    * Mat4::from_scale(Vec3::splat(frame.scale as f32));
            for inst in scene.instances.iter_mut() {
                inst.transform = to_canonical * inst.transform;
            }
        }
        // Lid margins are found with the eyes open (the neutral pose) and then follow the
        // expression's morphs.
        let neutral = skin_surface(&scene);
        let lids = find_head_lids(&scene, &neutral);
        if !expression.is_empty() {
            let available: usize = scene.meshes.iter().map(|m| m.morph_targets.len()).sum();
            if available == 0 {
                return Err(asset_error(
                    asset,
                    format!(
                        "the sample asks for expression weights {:?} but the head has no morph \
                         targets: select heads with tag morphs=arkit52 or set \
                         subject.expression_probability = 0",
                        expression.keys().collect::<Vec<_>>()
                    ),
                ));
            }
            for mesh in scene.meshes.iter_mut() {
                if !mesh.morph_targets.is_empty() {
                    mesh.apply_morphs(expression)
                        .map_err(|e| asset_error(asset, e.to_string()))?;
                }
            }
        }
        // Without an expression the posed skin is the neutral one.
        let surface = if expression.is_empty() {
            neutral
        } else {
            skin_surface(&scene)
        };
        if surface.triangles.is_empty() {
            return Err(asset_error(
                asset,
                "no triangles with a skin material (a material name containing \"skin\")",
            ));
        }
        let landmarks = match &asset.landmarks {
            Some(table) => landmarks_from_table(asset, table)?,
            None => detect_landmarks(&scene, &surface).map_err(|r| asset_error(asset, r))?,
        };
        crate::cornea::clear_corneas(&mut scene);
        let eyelids = match lids {
            Ok(lids) => lids.iter().map(|l| l.place(&surface)).collect(),
            Err(reason) => {
                tracing::debug!(head = %asset.id, "no eyelid margins: {reason}");
                Vec::new()
            }
        };
        Ok(Head {
            id: asset.id.clone(),
            scene,
            surface,
            landmarks,
            eyelids,
        })
    }
}

/// Triangles of every eye material ([`EYE_NAMES`]), canonical frame.
fn eye_triangles(scene: &Scene) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
            continue;
        };
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let material = mesh.triangle_materials.get(t).copied().unwrap_or(u32::MAX);
            if !EYE_NAMES
                .iter()
                .any(|n| material_matches(scene, material, n))
            {
                continue;
            }
            let p = |v: u32| {
                mesh.positions
                    .get(v as usize)
                    .map(|p| inst.transform.transform_point3(Vec3::from(*p)))
            };
            if let (Some(a), Some(b), Some(c)) = (p(tri[0]), p(tri[1]), p(tri[2])) {
                out.push([a, b, c]);
            }
        }
    }
    out
}

/// Both eyes' lid margins on the neutral `skin`: each eyeball's centre is the middle of its
/// eye triangles' bounding box (the triangles on its side of x = 0).
fn find_head_lids(scene: &Scene, skin: &HeadSurface) -> Result<Vec<LidPoints>, String> {
    let eyes = eye_triangles(scene);
    [1.0f32, -1.0]
        .into_iter()
        .map(|side| {
            let mine: Vec<[Vec3; 3]> = eyes
                .iter()
                .filter(|t| t.iter().all(|p| p.x * side > 0.0))
                .copied()
                .collect();
            let Some(centre) = bbox_centre(mine.iter().flatten()) else {
                return Err(format!("no eye triangles at x * {side} > 0"));
            };
            find_lids(skin, &mine, centre, side)
        })
        .collect()
}

/// Middle of the bounding box of `points`; `None` when there are none.
fn bbox_centre<'a>(points: impl Iterator<Item = &'a Vec3>) -> Option<Vec3> {
    let (lo, hi) = points.fold(None, |acc: Option<(Vec3, Vec3)>, p| match acc {
        None => Some((*p, *p)),
        Some((lo, hi)) => Some((lo.min(*p), hi.max(*p))),
    })?;
    Some((lo + hi) * 0.5)
}

/// World-space (canonical) skin triangles of every instance, vertices shared per mesh.
pub fn skin_surface(scene: &Scene) -> HeadSurface {
    let mut surface = HeadSurface::default();
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
            continue;
        };
        let normal_matrix = inst.transform.inverse().transpose();
        let mut remap = vec![u32::MAX; mesh.positions.len()];
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let material = mesh.triangle_materials.get(t).copied().unwrap_or(u32::MAX);
            if !material_matches(scene, material, &SKIN_NAMES) {
                continue;
            }
            let mut out = [0u32; 3];
            for (k, &v) in tri.iter().enumerate() {
                let v = v as usize;
                if v >= mesh.positions.len() {
                    continue;
                }
                if remap[v] == u32::MAX {
                    remap[v] = surface.positions.len() as u32;
                    let p = inst
                        .transform
                        .transform_point3(Vec3::from(mesh.positions[v]));
                    let n = mesh.normals.get(v).copied().unwrap_or([0.0, 1.0, 0.0]);
                    let n = normal_matrix
                        .transform_vector3(Vec3::from(n))
                        .normalize_or(Vec3::Y);
                    surface.positions.push(p);
                    surface.normals.push(n);
                }
                out[k] = remap[v];
            }
            surface.triangles.push(out);
        }
    }
    surface
}

fn landmarks_from_table(
    asset: &Asset,
    table: &BTreeMap<String, [f64; 3]>,
) -> Result<Landmarks, SubjectError> {
    let get = |name: &str| {
        table
            .get(name)
            .map(|v| Vec3::from_array(v.map(|c| c as f32)))
            .ok_or_else(|| asset_error(asset, format!("landmarks.{name} is missing")))
    };
    Ok(Landmarks {
        eye_left: get("eye_left")?,
        eye_right: get("eye_right")?,
        ear_left: get("ear_left")?,
        ear_right: get("ear_right")?,
        nose_bridge: get("nose_bridge")?,
        crown: get("crown")?,
    })
}

/// Landmarks of a head with eye meshes: eyeball centres from the eye geometry, the rest from
/// the skin relative to them (see [`Landmarks`] for the definitions).
pub fn detect_landmarks(scene: &Scene, skin: &HeadSurface) -> Result<Landmarks, String> {
    let mut eyes: Vec<Vec3> = Vec::new();
    for names in EYE_NAMES {
        for inst in &scene.instances {
            let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
                continue;
            };
            for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
                let material = mesh.triangle_materials.get(t).copied().unwrap_or(u32::MAX);
                if !material_matches(scene, material, names) {
                    continue;
                }
                eyes.extend(tri.iter().filter_map(|&v| {
                    mesh.positions
                        .get(v as usize)
                        .map(|p| inst.transform.transform_point3(Vec3::from(*p)))
                }));
            }
        }
        if !eyes.is_empty() {
            break;
        }
    }
    let centre = |side: f32| bbox_centre(eyes.iter().filter(|p| p.x * side > 0.0));
    let (Some(eye_left), Some(eye_right)) = (centre(1.0), centre(-1.0)) else {
        return Err(
            "no eye meshes on both sides (materials named sclera/eyes/eyeball/cornea/iris): \
                    give the head a `landmarks` table in the catalog"
                .into(),
        );
    };
    let eye_y = (eye_left.y + eye_right.y) * 0.5;
    let eye_z = (eye_left.z + eye_right.z) * 0.5;
    let pts = &skin.positions;

    // The ear attachment lies 5.5-13.5 cm behind the eyeball centres on every head here; the
    // widest skin point at eye height within that slab is where a temple arm rests.
    let in_ear_band =
        |p: &&Vec3| (p.y - eye_y).abs() < 0.03 && p.z < eye_z - 0.055 && p.z > eye_z - 0.135;
    let ear_left = pts
        .iter()
        .filter(in_ear_band)
        .max_by(|a, b| a.x.total_cmp(&b.x))
        .copied();
    let ear_right = pts
        .iter()
        .filter(in_ear_band)
        .min_by(|a, b| a.x.total_cmp(&b.x))
        .copied();
    let (Some(ear_left), Some(ear_right)) = (ear_left, ear_right) else {
        return Err("no skin at eye height 5.5-13.5 cm behind the eyes to find the ears".into());
    };
    let mut nose_bridge = None;
    for half_width in [0.006, 0.012, 0.02] {
        nose_bridge = pts
            .iter()
            .filter(|p| p.x.abs() < half_width && (p.y - eye_y).abs() < 0.01)
            .max_by(|a, b| a.z.total_cmp(&b.z))
            .copied();
        if nose_bridge.is_some() {
            break;
        }
    }
    let Some(nose_bridge) = nose_bridge else {
        return Err("no skin on the midline at eye height to find the nose bridge".into());
    };
    let Some(crown) = pts.iter().max_by(|a, b| a.y.total_cmp(&b.y)).copied() else {
        return Err("the skin has no vertices".into());
    };
    Ok(Landmarks {
        eye_left,
        eye_right,
        ear_left,
        ear_right,
        nose_bridge,
        crown,
    })
}
