//! Material models and `extras.lightfarm`: presets, overrides, files without extras, and the
//! material record (the validation errors are material_errors.rs).

mod common;

use std::path::Path;

use lightfarm_render::scene::material::{EXTRAS_MODELS, OVERRIDE_KEYS};
use lightfarm_render::scene::{
    materials_json, Material, MaterialModel, MaterialRecord, ObjectClass, Scene,
};
use serde_json::{json, Value};

use common::gltf_files::{
    close, close3, gltf_material, load, scratch_dir, write_glb_file, write_gltf,
};

/// The paper's skin preset, field by field, on a material whose file said base colour
/// (0.7, 0.5, 0.4).
fn assert_skin_preset(m: &Material) {
    assert_eq!(m.model, MaterialModel::Skin);
    assert_eq!(m.class, ObjectClass::Skin);
    assert!(close(m.subsurface, 0.95));
    assert_eq!(
        m.subsurface_color, None,
        "subsurface colour is the base colour"
    );
    assert!(close3(m.subsurface_radius, [1.0, 0.35, 0.2]));
    assert!(close(m.subsurface_scale, 0.00225), "0.225 cm in metres");
    assert!(close(m.subsurface_anisotropy, 0.0));
    assert!(close(m.specular, 1.0));
    assert!(close3(m.specular_color, [0.82; 3]));
    assert!(close(m.roughness, 0.4));
    assert!(close(m.ior, 1.5));
    assert!(close(m.coat, 0.1));
    assert!(close3(m.coat_color, [1.0; 3]));
    assert!(close(m.coat_roughness, 0.25));
    assert!(close(m.coat_ior, 1.5));
    assert!(close(m.sheen, 0.1));
    assert!(close3(m.sheen_color, [1.0; 3]));
    assert!(close(m.sheen_roughness, 0.3));
    assert!(close(m.metallic, 0.0));
    assert!(close(m.transmission, 0.0));
}

#[test]
fn skin_model_gets_the_paper_preset_in_gltf_and_glb() {
    let dir = scratch_dir("skin");
    let materials = [gltf_material(
        "face",
        Some(json!({"lightfarm": {"model": "skin"}})),
    )];
    for path in [
        write_gltf(&dir, "skin", &materials),
        write_glb_file(&dir, "skin", &materials),
    ] {
        let scene = load(&path);
        let m = &scene.materials[0];
        assert_eq!(m.name, "face");
        assert_skin_preset(m);
        // What the preset does not decide stays as the file says.
        assert_eq!(m.base_color, [0.7, 0.5, 0.4, 0.9], "{}", path.display());
        assert!(close(m.opacity, 1.0), "OPAQUE");
        assert!(close(m.normal_scale, 1.0));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn overrides_win_over_the_preset() {
    let dir = scratch_dir("overrides");
    let path = write_gltf(
        &dir,
        "overrides",
        &[gltf_material(
            "face",
            Some(json!({"lightfarm": {
                "model": "skin",
                "base_color": [0.2, 0.3, 0.4],
                "specular_roughness": 0.55,
                "specular_IOR": 1.4,
                "specular_color": 0.5,
                "subsurface": 0.5,
                "subsurface_color": [0.9, 0.3, 0.2],
                "subsurface_radius": [2.0, 1.0, 0.5],
                "subsurface_scale": 0.004,
                "subsurface_anisotropy": -0.3,
                "coat": 0.0,
                "coat_color": [0.9, 0.8, 0.7],
                "coat_roughness": 0.6,
                "coat_IOR": 1.3,
                "sheen": 0.25,
                "sheen_color": 0.6,
                "sheen_roughness": 0.7,
                "metalness": 0.1,
                "specular": 0.75,
                "transmission": 0.2,
                "opacity": 0.5,
                "thin_walled": true
            }, "other_tool": {"ignored": true}})),
        )],
    );
    let m = &load(&path).materials[0];
    assert_eq!(m.model, MaterialModel::Skin);
    assert_eq!(m.class, ObjectClass::Skin);
    assert_eq!(
        m.base_color,
        [0.2, 0.3, 0.4, 0.9],
        "RGB overridden, alpha kept"
    );
    assert!(close(m.roughness, 0.55));
    assert!(close(m.ior, 1.4));
    assert!(close3(m.specular_color, [0.5; 3]), "one number is grey");
    assert!(close(m.subsurface, 0.5));
    assert_eq!(m.subsurface_color, Some([0.9, 0.3, 0.2]));
    assert!(close3(m.subsurface_radius, [2.0, 1.0, 0.5]));
    assert!(close(m.subsurface_scale, 0.004));
    assert!(close(m.subsurface_anisotropy, -0.3));
    assert!(close(m.coat, 0.0));
    assert!(close3(m.coat_color, [0.9, 0.8, 0.7]));
    assert!(close(m.coat_roughness, 0.6));
    assert!(close(m.coat_ior, 1.3));
    assert!(close(m.sheen, 0.25));
    assert!(close3(m.sheen_color, [0.6; 3]));
    assert!(close(m.sheen_roughness, 0.7));
    assert!(close(m.metallic, 0.1));
    assert!(close(m.specular, 0.75));
    assert!(close(m.transmission, 0.2));
    assert!(close(m.opacity, 0.5));
    assert!(m.thin_walled);

    // `subsurface_color: null` is the base colour again; untouched keys keep the preset.
    let path = write_gltf(
        &dir,
        "null_colour",
        &[gltf_material(
            "face",
            Some(json!({"lightfarm": {"model": "mouth", "subsurface_color": null, "coat": 0.5}})),
        )],
    );
    let m = &load(&path).materials[0];
    assert_eq!(m.model, MaterialModel::Mouth);
    assert_eq!(m.subsurface_color, None);
    assert!(close(m.coat, 0.5));
    assert!(close(m.coat_ior, 1.33), "preset saliva IOR kept");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn without_extras_lightfarm_a_material_is_unchanged_gltf() {
    let dir = scratch_dir("plain");
    let path = write_gltf(
        &dir,
        "plain",
        &[
            gltf_material("plain", None),
            gltf_material("other_extras", Some(json!({"exporter": {"id": 7}}))),
            gltf_material("scalar_extras", Some(json!(3))),
        ],
    );
    let scene = load(&path);
    let expected = Material {
        name: "plain".into(),
        base_color: [0.7, 0.5, 0.4, 0.9],
        metallic: 0.3,
        roughness: 0.8,
        ..Material::default()
    };
    for m in &scene.materials {
        assert_eq!(m.model, MaterialModel::Gltf, "{}", m.name);
        assert_eq!(m.class, ObjectClass::Other, "{}", m.name);
        let named = Material {
            name: m.name.clone(),
            ..expected.clone()
        };
        assert_eq!(MaterialRecord::from(m), MaterialRecord::from(&named));
    }
    // A committed asset with no extras keeps its glTF values.
    let glasses =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/accessories/glasses_rect.glb");
    let scene = load(&glasses);
    assert!(scene
        .materials
        .iter()
        .all(|m| m.model == MaterialModel::Gltf && m.class == ObjectClass::Other));
    let lens = scene
        .materials
        .iter()
        .find(|m| m.name == "lens")
        .expect("lens");
    assert!(close(lens.transmission, 1.0) && close(lens.ior, 1.5) && lens.subsurface == 0.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_preset_sets_its_model_and_class() {
    let dir = scratch_dir("presets");
    let materials: Vec<Value> = EXTRAS_MODELS
        .iter()
        .map(|m| gltf_material(m.name(), Some(json!({"lightfarm": {"model": m.name()}}))))
        .collect();
    let scene = load(&write_gltf(&dir, "presets", &materials));
    for (model, m) in EXTRAS_MODELS.iter().zip(&scene.materials) {
        assert_eq!(m.model, *model);
        assert_eq!(MaterialModel::parse(model.name()), Some(*model));
        assert_eq!(m.class, model.class(), "{model}");
        let kept_colour = [0.7, 0.5, 0.4, 0.9];
        assert_eq!(m.base_color, kept_colour, "{model} keeps the file's colour");
        match model {
            MaterialModel::Skin => assert_skin_preset(m),
            MaterialModel::Eye => {
                assert_eq!(m.class, ObjectClass::Eyes);
                assert!(m.subsurface == 0.0 && m.sheen == 0.0 && m.metallic == 0.0);
                assert!(close(m.specular, 1.0) && close3(m.specular_color, [1.0; 3]));
                assert!(close(m.roughness, 0.1) && close(m.ior, 1.5));
                assert!(close(m.coat, 0.5) && close(m.coat_roughness, 0.1));
                assert!(close(m.coat_ior, 1.376));
            }
            MaterialModel::Mouth => {
                assert_eq!(m.class, ObjectClass::Mouth);
                assert!(close(m.subsurface, 0.6));
                assert!(close3(m.subsurface_radius, [1.0, 0.4, 0.25]));
                assert!(close(m.subsurface_scale, 0.001));
                assert!(close(m.specular, 1.0) && close(m.roughness, 0.3));
                assert!(close(m.coat, 0.3) && close(m.coat_roughness, 0.1));
                assert!(close(m.coat_ior, 1.33) && m.sheen == 0.0);
            }
            MaterialModel::Teeth => {
                assert_eq!(m.class, ObjectClass::Mouth);
                assert!(close(m.subsurface, 0.3));
                assert!(close3(m.subsurface_radius, [1.0, 0.8, 0.6]));
                assert!(close(m.subsurface_scale, 0.0005));
                assert!(close(m.specular, 1.0) && close(m.roughness, 0.2));
                assert!(close(m.ior, 1.6) && m.coat == 0.0);
            }
            MaterialModel::Cloth => {
                assert_eq!(m.class, ObjectClass::Garment);
                assert!(m.subsurface == 0.0 && m.coat == 0.0 && m.sheen == 0.0);
                assert!(close(m.specular, 1.0) && close(m.ior, 1.5));
                assert!(close(m.roughness, 0.8), "cloth keeps the file's roughness");
            }
            MaterialModel::Plastic => {
                assert_eq!(m.class, ObjectClass::Other);
                assert!(close(m.specular, 1.0) && close(m.ior, 1.5) && m.metallic == 0.0);
                assert!(close(m.roughness, 0.8));
            }
            MaterialModel::Metal => {
                assert_eq!(m.class, ObjectClass::Other);
                assert!(close(m.metallic, 1.0) && close(m.roughness, 0.8));
            }
            MaterialModel::Lens => {
                assert_eq!(m.class, ObjectClass::Lens);
                assert!(close(m.transmission, 1.0) && m.metallic == 0.0);
                assert!(close(m.ior, 1.5), "no KHR_materials_ior: 1.5");
                assert!(!m.thin_walled, "a lens is a solid's surface");
            }
            MaterialModel::Cornea => {
                assert_eq!(m.class, ObjectClass::Eyes);
                assert!(close(m.transmission, 1.0) && m.metallic == 0.0 && m.thin_walled);
                assert!(close(m.ior, 1.376) && close(m.specular, 1.0));
                assert!(close(m.opacity, 1.0), "clear, not the file's 0.9 coverage");
            }
            MaterialModel::Hair => {
                assert_eq!(m.class, ObjectClass::Hair);
                assert!(close(m.ior, 1.55) && close(m.cuticle_tilt_deg, 2.0));
                assert!(close(m.longitudinal_roughness, 0.3) && close(m.azimuthal_roughness, 0.3));
                assert!(close(m.opacity, 1.0) && m.transmission == 0.0);
            }
            MaterialModel::Gltf => unreachable!("gltf is not an extras model"),
        }
    }
    assert_eq!(MaterialModel::parse("gltf"), Some(MaterialModel::Gltf));
    assert_eq!(MaterialModel::parse("Skin"), None, "names are exact");

    // The lens preset keeps the file's KHR_materials_ior.
    let mut lens = gltf_material("lens", Some(json!({"lightfarm": {"model": "lens"}})));
    lens["extensions"] = json!({"KHR_materials_ior": {"ior": 1.7}});
    let m = &load(&write_gltf(&dir, "lens_ior", &[lens])).materials[0];
    assert!(close(m.ior, 1.7) && close(m.transmission, 1.0));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every key of a material record, which must hold every parameter that affects rendering.
const RECORD_KEYS: [&str; 30] = [
    "name",
    "model",
    "class",
    "base_color",
    "base_color_texture",
    "metalness",
    "specular",
    "specular_color",
    "specular_roughness",
    "specular_IOR",
    "specular_texture",
    "metallic_roughness_texture",
    "normal_texture",
    "normal_scale",
    "transmission",
    "opacity",
    "double_sided",
    "subsurface",
    "subsurface_color",
    "subsurface_radius",
    "subsurface_scale",
    "subsurface_anisotropy",
    "coat",
    "coat_color",
    "coat_roughness",
    "coat_IOR",
    "sheen",
    "sheen_color",
    "sheen_roughness",
    "thin_walled",
];

#[test]
fn materials_json_records_every_parameter_in_material_order() {
    // Distinct values everywhere (powers of two stay exact through f32 -> JSON -> f64).
    let special = Material {
        name: "special".into(),
        base_color: [0.5, 0.25, 0.125, 0.75],
        base_color_texture: Some(3),
        metallic: 0.0625,
        roughness: 0.375,
        metallic_roughness_texture: Some(4),
        normal_texture: Some(5),
        normal_scale: 0.875,
        specular: 0.5,
        specular_color: [0.25, 0.5, 0.75],
        transmission: 0.125,
        ior: 1.25,
        double_sided: true,
        opacity: 0.625,
        model: MaterialModel::Teeth,
        class: ObjectClass::Mouth,
        subsurface: 0.3125,
        subsurface_color: Some([0.75, 0.5, 0.25]),
        subsurface_radius: [2.0, 1.5, 0.5],
        subsurface_scale: 0.0078125,
        subsurface_anisotropy: -0.25,
        coat: 0.4375,
        coat_color: [0.875, 0.75, 0.625],
        coat_roughness: 0.1875,
        coat_ior: 1.375,
        sheen: 0.15625,
        sheen_color: [0.5, 0.625, 0.75],
        sheen_roughness: 0.5625,
        specular_texture: Some(6),
        thin_walled: true,
        ..Material::default()
    };
    let scene = Scene {
        materials: vec![Material::default(), special],
        ..Scene::default()
    };
    let json = materials_json(&scene);
    let list = json.as_array().expect("an array");
    assert_eq!(list.len(), 2);
    assert_eq!(list[0]["name"], "default");
    assert_eq!(list[0]["model"], "gltf");
    assert_eq!(list[0]["subsurface_color"], Value::Null);
    assert_eq!(list[0]["base_color_texture"], Value::Null);
    let r = list[1].as_object().expect("an object");
    let mut keys: Vec<&str> = r.keys().map(String::as_str).collect();
    keys.sort_unstable();
    let mut expected = RECORD_KEYS.to_vec();
    expected.sort_unstable();
    assert_eq!(keys, expected, "the record's keys");
    // Every extras.lightfarm key is recorded under the same name (the fibre's in `hair`, which
    // only a hair material has).
    let fibre_keys = [
        "melanin",
        "melanin_redness",
        "longitudinal_roughness",
        "azimuthal_roughness",
        "cuticle_tilt",
    ];
    for key in OVERRIDE_KEYS.iter().filter(|k| !fibre_keys.contains(k)) {
        assert!(r.contains_key(*key), "{key} is not recorded");
    }
    let mut hair = Material {
        melanin: 0.75,
        melanin_redness: 0.25,
        ..Material::default()
    };
    hair.apply_model(MaterialModel::Hair);
    let rec = materials_json(&Scene {
        materials: vec![hair],
        ..Scene::default()
    });
    let h = rec[0]["hair"].as_object().expect("a hair record");
    for key in fibre_keys {
        assert!(h.contains_key(key), "{key} is not recorded for hair");
    }
    assert_eq!(h["melanin"], 0.75);
    let sigma = lightfarm_render::hair::sigma_a_from_melanin(0.75, 0.25);
    assert_eq!(h["sigma_a"][2].as_f64().map(|x| x as f32), Some(sigma[2]));
    assert!(h["sigma_set"].as_str().is_some_and(|s| s.contains("0.506")));
    let want = json!({
        "name": "special", "model": "teeth", "class": "mouth",
        "base_color": [0.5, 0.25, 0.125, 0.75], "base_color_texture": 3,
        "metalness": 0.0625, "specular": 0.5, "specular_color": [0.25, 0.5, 0.75],
        "specular_roughness": 0.375, "specular_IOR": 1.25, "specular_texture": 6,
        "metallic_roughness_texture": 4, "normal_texture": 5, "normal_scale": 0.875,
        "transmission": 0.125, "opacity": 0.625, "double_sided": true,
        "subsurface": 0.3125, "subsurface_color": [0.75, 0.5, 0.25],
        "subsurface_radius": [2.0, 1.5, 0.5], "subsurface_scale": 0.0078125,
        "subsurface_anisotropy": -0.25, "thin_walled": true,
        "coat": 0.4375, "coat_color": [0.875, 0.75, 0.625], "coat_roughness": 0.1875,
        "coat_IOR": 1.375,
        "sheen": 0.15625, "sheen_color": [0.5, 0.625, 0.75], "sheen_roughness": 0.5625,
    });
    assert_eq!(list[1], want);

    // Numbers are the f32's shortest decimal, so a header reads 0.82, not 0.8199999928474426.
    let mut skin = Material::default();
    skin.apply_model(MaterialModel::Skin);
    let json = materials_json(&Scene {
        materials: vec![skin],
        ..Scene::default()
    });
    let text = json.to_string();
    assert!(
        text.contains("\"specular_color\":[0.82,0.82,0.82]"),
        "{text}"
    );
    assert!(text.contains("\"subsurface_scale\":0.00225"), "{text}");
    assert_eq!(
        json[0]["specular_roughness"].as_f64().map(|x| x as f32),
        Some(0.4)
    );
}
