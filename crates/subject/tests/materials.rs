//! Material models of the built-in heads (by material name) and of the assembler's own parts:
//! strands, garments, glasses, headsets.

use std::collections::{BTreeMap, BTreeSet};

use lightfarm_render::scene::{Material, MaterialModel, MaterialRecord, ObjectClass, Scene};
use lightfarm_scene::expand::expand;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::{AssetKind, Catalog};
use lightfarm_subject::head::assign_head_materials;
use lightfarm_subject::{assemble, Head};
use serde_json::json;

fn catalog() -> Catalog {
    Catalog::builtin().unwrap_or_else(|e| panic!("catalog: {e}"))
}

/// What a built-in head's material must become, by name; `None` for names of no head.
fn expected(name: &str) -> Option<(MaterialModel, ObjectClass)> {
    use MaterialModel as M;
    use ObjectClass as C;
    Some(match name {
        "skin" | "LeePerrySmith_skin" => (M::Skin, C::Skin),
        "eyes" | "sclera" | "iris" => (M::Eye, C::Eyes),
        "cornea" => (M::Cornea, C::Eyes),
        "teeth" => (M::Teeth, C::Mouth),
        "tongue" | "gums_tongue" => (M::Mouth, C::Mouth),
        "eyelashes" => (M::Gltf, C::Hair),
        _ => return None,
    })
}

#[test]
fn built_in_heads_map_their_materials_by_name() {
    let catalog = catalog();
    let mut seen: BTreeMap<&str, BTreeSet<String>> = BTreeMap::new();
    for asset in catalog.of_kind(AssetKind::Head) {
        let head = Head::load(asset, &catalog.path_of(asset), &BTreeMap::new())
            .unwrap_or_else(|e| panic!("{}: {e}", asset.id));
        let family = match asset.tags.get("source").map(String::as_str) {
            Some("makehuman") => "makehuman",
            Some("scan") => "scan",
            _ => "ict",
        };
        let raw = Scene::load_gltf(&catalog.path_of(asset)).expect("the file loads");
        for (m, file) in head.scene.materials.iter().zip(&raw.materials) {
            seen.entry(family).or_default().insert(m.name.clone());
            assert_eq!(file.model, MaterialModel::Gltf, "the files carry no extras");
            match expected(&m.name) {
                Some((model, class)) => {
                    assert_eq!(m.model, model, "{}: {}", asset.id, m.name);
                    assert_eq!(m.class, class, "{}: {}", asset.id, m.name);
                    // The presets keep the file's colour and texture.
                    assert_eq!(m.base_color, file.base_color, "{}: {}", asset.id, m.name);
                    assert_eq!(m.base_color_texture, file.base_color_texture);
                    assert_eq!(m.normal_texture, file.normal_texture);
                    if model == MaterialModel::Skin {
                        assert_eq!(m.subsurface, 0.95);
                        assert_eq!(m.subsurface_scale, 0.00225);
                        assert_eq!(m.subsurface_color, None);
                    }
                    if model == MaterialModel::Gltf {
                        assert_eq!(
                            MaterialRecord::from(m),
                            MaterialRecord {
                                class,
                                ..file.into()
                            },
                            "eyelashes: only the class changes"
                        );
                    }
                }
                None => panic!("{}: {} is a material of no known head", asset.id, m.name),
            }
        }
        // The file's materials come first; ICT heads get a cornea cut from the sclera after
        // them (tests/cornea.rs).
        for m in &head.scene.materials[raw.materials.len()..] {
            assert_eq!(
                family, "ict",
                "{}: only ICT heads get a new material",
                asset.id
            );
            assert_eq!(
                (m.name.as_str(), m.model),
                ("cornea", MaterialModel::Cornea)
            );
            seen.entry(family).or_default().insert(m.name.clone());
        }
        if family == "makehuman" {
            assert!(
                head.scene
                    .materials
                    .iter()
                    .any(|m| m.name == "skin" && m.base_color_texture.is_some()),
                "{}: the MakeHuman skin keeps its texture",
                asset.id
            );
        }
    }
    let names = |list: &[&str]| list.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
    assert_eq!(
        seen["makehuman"],
        names(&["skin", "eyes", "cornea", "teeth", "tongue"])
    );
    assert_eq!(
        seen["ict"],
        names(&[
            "skin",
            "gums_tongue",
            "teeth",
            "sclera",
            "iris",
            "eyelashes",
            "cornea"
        ])
    );
    assert_eq!(seen["scan"], names(&["LeePerrySmith_skin"]));
}

#[test]
fn a_head_file_with_extras_lightfarm_keeps_its_model() {
    let dir = std::env::temp_dir().join(format!(
        "lightfarm-subject-materials-{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let bin: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .chain([0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()))
        .collect();
    std::fs::write(dir.join("tri.bin"), bin).expect("write bin");
    let material = |name: &str, extras: Option<serde_json::Value>| {
        let mut m = json!({"name": name, "pbrMetallicRoughness": {"metallicFactor": 0.0}});
        if let Some(e) = extras {
            m["extras"] = e;
        }
        m
    };
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [
            {"attributes": {"POSITION": 0}, "indices": 1, "material": 0},
            {"attributes": {"POSITION": 0}, "indices": 1, "material": 1}
        ]}],
        "materials": [
            material("skin", Some(json!({"lightfarm": {"model": "skin", "subsurface": 0.5}}))),
            material("teeth", Some(json!({"lightfarm": {"model": "plastic"}}))),
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 12}
        ],
        "buffers": [{"byteLength": 48, "uri": "tri.bin"}],
    });
    let path = dir.join("head.gltf");
    std::fs::write(&path, doc.to_string()).expect("write gltf");
    let mut scene = Scene::load_gltf(&path).expect("loads");
    assign_head_materials(&mut scene);
    let skin = &scene.materials[0];
    assert_eq!(skin.model, MaterialModel::Skin);
    assert_eq!(skin.subsurface, 0.5, "the file's override is not undone");
    let teeth = &scene.materials[1];
    assert_eq!(teeth.model, MaterialModel::Plastic, "the file's model wins");
    assert_eq!(teeth.class, ObjectClass::Other);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The factors the glTF mapping renders with: the assembler's presets must leave them alone on
/// glasses and headsets, so these look as before.
fn gltf_look(m: &Material) -> Vec<f32> {
    let mut v = m.base_color.to_vec();
    v.extend(m.specular_color);
    v.extend([
        m.metallic,
        m.roughness,
        m.specular,
        m.ior,
        m.transmission,
        m.opacity,
    ]);
    v
}

#[test]
fn assembled_parts_get_models_and_classes() {
    let catalog = catalog();
    let text = "name = \"materials-test\"\nseed = 5\ncount = 100\nwidth = 64\nheight = 64\n\
                spp = 4\n[subject]\nglasses_probability = 1.0\nheadset_probability = 1.0\n\
                garment_probability = 1.0\n";
    let spec = DatasetSpec::from_toml_str(text, "materials-test.toml")
        .and_then(|s| s.validate(&catalog))
        .unwrap_or_else(|e| panic!("spec: {e}"));
    let mut glasses_seen = BTreeSet::new();
    let mut classes_seen = BTreeSet::new();
    let mut index = 0;
    while glasses_seen.len() < catalog.of_kind(AssetKind::Glasses).len() {
        assert!(index < 30, "30 samples did not use every glasses model");
        let sample = expand(&spec, index).expect("expand");
        index += 1;
        let glasses = sample.glasses.as_ref().expect("glasses probability 1");
        if !glasses_seen.insert(glasses.id.clone()) {
            continue;
        }
        let a = assemble(&sample, &catalog).unwrap_or_else(|e| panic!("{index}: {e}"));
        let file_materials = |id: &str| {
            let asset = catalog.get(id).expect("in the catalog");
            Scene::load_gltf(&catalog.path_of(asset))
                .expect("loads")
                .materials
        };
        let glasses_file = file_materials(&glasses.id);
        let headset_file = file_materials(&sample.headset.as_ref().expect("headset").id);
        let garment = sample.garment.as_ref().expect("garment");
        let fibres: Vec<&str> = a.scene.curves.iter().map(|c| c.name.as_str()).collect();
        // Every head but the scan (no eyeballs, lashes in its texture) grows lashes.
        let expected_fibres: &[&str] = if sample.head.id == "lee_perry_smith" {
            &["hair", "eyebrows"]
        } else {
            &["hair", "eyebrows", "eyelashes"]
        };
        assert_eq!(fibres, expected_fibres, "sample {}", index - 1);
        for c in &a.scene.curves {
            assert_eq!(
                a.scene.materials[c.material as usize].name, "hair",
                "{}",
                c.name
            );
        }
        for m in &a.scene.materials {
            classes_seen.insert(m.class.name());
            let what = format!("sample {} ({}): '{}'", index - 1, glasses.id, m.name);
            if let Some((model, class)) = expected(&m.name) {
                assert_eq!((m.model, m.class), (model, class), "{what}");
                continue;
            }
            if m.name == "hair" {
                // Hair and eyebrows are fibres sharing the sample's Chiang material.
                assert_eq!(
                    (m.model, m.class),
                    (MaterialModel::Hair, ObjectClass::Hair),
                    "{what}"
                );
                assert!(
                    (f64::from(m.melanin) - sample.hair.melanin).abs() < 1e-6,
                    "{what}"
                );
                continue;
            }
            if m.name == "clothes" {
                assert_eq!(
                    (m.model, m.class),
                    (MaterialModel::Cloth, ObjectClass::Garment),
                    "{what}"
                );
                assert_eq!(
                    m.specular, 0.5,
                    "{what}: the garment's weak reflection is kept"
                );
                assert_eq!(m.roughness, garment.roughness as f32, "{what}");
                assert_eq!(m.metallic, 0.0);
                continue;
            }
            let (file, class) = match (
                glasses_file.iter().find(|f| f.name == m.name),
                headset_file.iter().find(|f| f.name == m.name),
            ) {
                (Some(f), None) => (
                    f,
                    if m.model == MaterialModel::Lens {
                        ObjectClass::Lens
                    } else {
                        ObjectClass::Frame
                    },
                ),
                (None, Some(f)) => (f, ObjectClass::Headset),
                _ => panic!("{what}: not from the head, the glasses or the headset"),
            };
            assert_eq!(m.class, class, "{what}");
            let want = if m.name.contains("lens") {
                MaterialModel::Lens
            } else if file.metallic >= 0.5 {
                MaterialModel::Metal
            } else {
                MaterialModel::Plastic
            };
            assert_eq!(m.model, want, "{what}");
            assert_eq!(
                gltf_look(m),
                gltf_look(file),
                "{what}: the glTF factors are unchanged"
            );
        }
    }
    for class in [
        "skin", "eyes", "mouth", "hair", "garment", "frame", "lens", "headset",
    ] {
        assert!(
            classes_seen.contains(class),
            "no material of class {class}: {classes_seen:?}"
        );
    }
}

/// The dataset spec validates pass names against its own list (it does not link the renderer);
/// it must be the renderer's list, in the renderer's order.
#[test]
fn spec_pass_names_are_the_renderers() {
    let render: Vec<&str> = lightfarm_render::passes::Pass::ALL
        .iter()
        .map(|p| p.name())
        .collect();
    assert_eq!(render, lightfarm_scene::spec::PASS_NAMES);
    let defaults: Vec<&str> = lightfarm_render::passes::Pass::DEFAULT
        .iter()
        .map(|p| p.name())
        .collect();
    assert_eq!(defaults, lightfarm_scene::spec::DEFAULT_PASSES);
}
