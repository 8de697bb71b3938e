//! Glasses: the materials of the procedural frames and of any glasses model (see the parent
//! module).

#[allow(unused_imports)]
use super::*;

// Models and classes set here live in memory only: `write_glb` writes glTF factors, so the
// generated files (and their catalog hashes) do not carry them; `glasses_materials` sets them
// again on whatever glasses file is loaded.

pub(super) fn gold() -> Material {
    Material {
        name: "frame_metal_gold".to_string(),
        // Linear reflectance of gold at normal incidence.
        base_color: [1.0, 0.766, 0.336, 1.0],
        metallic: 1.0,
        roughness: 0.3,
        model: MaterialModel::Metal,
        class: ObjectClass::Frame,
        ..Material::default()
    }
}

pub(super) fn dark_plastic(name: &str, roughness: f32) -> Material {
    Material {
        name: name.to_string(),
        base_color: [0.018, 0.012, 0.010, 1.0],
        metallic: 0.0,
        roughness,
        model: MaterialModel::Plastic,
        class: ObjectClass::Frame,
        ..Material::default()
    }
}

pub(super) fn silicone() -> Material {
    Material {
        name: "nose_pad".to_string(),
        base_color: [0.75, 0.75, 0.72, 1.0],
        metallic: 0.0,
        roughness: 0.35,
        model: MaterialModel::Plastic,
        class: ObjectClass::Frame,
        ..Material::default()
    }
}

pub(super) fn lens_material() -> Material {
    Material {
        name: "lens".to_string(),
        base_color: [1.0; 4],
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        ior: 1.5,
        model: MaterialModel::Lens,
        class: ObjectClass::Lens,
        ..Material::default()
    }
}

/// Gives a glasses model's materials their models and classes: the lenses ([`lens_materials`])
/// become `lens` / class lens, the rest frame parts (class frame): `metal` when the file's
/// metalness is at least 0.5, else `plastic` (silicone pads included). Both presets keep the
/// file's colour and roughness, so the frames look as before. A material whose file carries
/// `extras.lightfarm` keeps its model; its class is still the part's role.
pub fn glasses_materials(scene: &mut Scene) {
    let is_lens = lens_materials(scene);
    for (m, lens) in scene.materials.iter_mut().zip(is_lens) {
        let (model, class) = if lens {
            (MaterialModel::Lens, ObjectClass::Lens)
        } else if m.metallic >= 0.5 {
            (MaterialModel::Metal, ObjectClass::Frame)
        } else {
            (MaterialModel::Plastic, ObjectClass::Frame)
        };
        if m.model == MaterialModel::Gltf {
            m.apply_model(model);
        }
        m.class = class;
    }
}
