//! `extras.lightfarm` validation: every bad model, key, type or value fails the load with an
//! error naming the file, the material and the key.

mod common;

use lightfarm_render::scene::{Scene, SceneError};
use serde_json::{json, Value};

use common::gltf_files::{gltf_material, scratch_dir, write_gltf};

#[test]
fn bad_extras_fail_naming_file_material_and_key() {
    let dir = scratch_dir("errors");
    let accepted_models =
        "\"skin\", \"eye\", \"mouth\", \"teeth\", \"cloth\", \"plastic\", \"metal\", \"lens\", \"cornea\"";
    // (case, extras.lightfarm, key the error names, text it must contain)
    let cases: Vec<(&str, Value, &str, &str)> = vec![
        (
            "unknown_model",
            json!({"model": "velvet"}),
            "extras.lightfarm.model",
            accepted_models,
        ),
        (
            "gltf_model",
            json!({"model": "gltf"}),
            "extras.lightfarm.model",
            accepted_models,
        ),
        (
            "model_type",
            json!({"model": 3}),
            "extras.lightfarm.model",
            "not a number",
        ),
        (
            "missing_model",
            json!({"specular": 0.5}),
            "extras.lightfarm.model",
            "is missing",
        ),
        (
            "not_object",
            json!("skin"),
            "extras.lightfarm",
            "must be an object",
        ),
        (
            "unknown_key",
            json!({"model": "skin", "roughness": 0.3}),
            "extras.lightfarm.roughness",
            "specular_roughness",
        ),
        (
            "lowercase_ior",
            json!({"model": "skin", "specular_ior": 1.4}),
            "extras.lightfarm.specular_ior",
            "specular_IOR",
        ),
        (
            "wrong_type",
            json!({"model": "skin", "coat": "thin"}),
            "extras.lightfarm.coat",
            "a number in [0, 1], not a string",
        ),
        (
            "bool_type",
            json!({"model": "eye", "sheen": true}),
            "extras.lightfarm.sheen",
            "not a boolean",
        ),
        (
            "thin_walled_type",
            json!({"model": "lens", "thin_walled": 1}),
            "extras.lightfarm.thin_walled",
            "must be true or false, not a number",
        ),
        (
            "colour_length",
            json!({"model": "skin", "coat_color": [1, 1]}),
            "extras.lightfarm.coat_color",
            "has 2 elements",
        ),
        (
            "colour_element",
            json!({"model": "skin", "sheen_color": [1, "x", 1]}),
            "extras.lightfarm.sheen_color",
            "[r, g, b]",
        ),
        (
            "colour_range",
            json!({"model": "skin", "base_color": [0.5, 1.2, 0.5]}),
            "extras.lightfarm.base_color",
            "outside [0, 1]",
        ),
        (
            "weight_range",
            json!({"model": "skin", "coat": 1.5}),
            "extras.lightfarm.coat",
            "outside [0, 1]",
        ),
        (
            "negative_weight",
            json!({"model": "skin", "subsurface": -0.1}),
            "extras.lightfarm.subsurface",
            "outside [0, 1]",
        ),
        (
            "ior_range",
            json!({"model": "teeth", "specular_IOR": 0.5}),
            "extras.lightfarm.specular_IOR",
            "outside [1, 3]",
        ),
        (
            "coat_ior_range",
            json!({"model": "eye", "coat_IOR": 3.5}),
            "extras.lightfarm.coat_IOR",
            "outside [1, 3]",
        ),
        (
            "negative_radius",
            json!({"model": "skin", "subsurface_radius": [-1.0, 0.35, 0.2]}),
            "extras.lightfarm.subsurface_radius",
            "outside (0, 100]",
        ),
        (
            "zero_radius",
            json!({"model": "skin", "subsurface_radius": [1.0, 0.0, 0.2]}),
            "extras.lightfarm.subsurface_radius",
            "outside (0, 100]",
        ),
        (
            "huge_radius",
            json!({"model": "skin", "subsurface_radius": [1.0, 0.35, 101]}),
            "extras.lightfarm.subsurface_radius",
            "outside (0, 100]",
        ),
        (
            "scalar_radius",
            json!({"model": "skin", "subsurface_radius": 1.0}),
            "extras.lightfarm.subsurface_radius",
            "3 numbers in (0, 100]",
        ),
        (
            "zero_scale",
            json!({"model": "skin", "subsurface_scale": 0.0}),
            "extras.lightfarm.subsurface_scale",
            "outside (0, 1]",
        ),
        (
            "scale_in_cm",
            json!({"model": "skin", "subsurface_scale": 2.25}),
            "extras.lightfarm.subsurface_scale",
            "outside (0, 1]",
        ),
        (
            "anisotropy_range",
            json!({"model": "skin", "subsurface_anisotropy": 0.99}),
            "extras.lightfarm.subsurface_anisotropy",
            "outside [-0.95, 0.95]",
        ),
        (
            "overflowing_number",
            json!({"model": "skin", "sheen": 1e300}),
            "extras.lightfarm.sheen",
            "not a finite 32-bit number",
        ),
        (
            "null_weight",
            json!({"model": "skin", "opacity": null}),
            "extras.lightfarm.opacity",
            "not null",
        ),
    ];
    for (case, lightfarm, key, fragment) in cases {
        let material = format!("mat_{case}");
        // A good material first, so the error must name the bad one.
        let path = write_gltf(
            &dir,
            case,
            &[
                gltf_material("fine", Some(json!({"lightfarm": {"model": "skin"}}))),
                gltf_material(&material, Some(json!({"lightfarm": lightfarm}))),
            ],
        );
        let err = Scene::load_gltf(&path).expect_err(case);
        let msg = err.to_string();
        println!("{case}: {msg}");
        match &err {
            SceneError::BadMaterial {
                path: p,
                material: m,
                key: k,
                ..
            } => {
                assert_eq!(p, &path, "{case}");
                assert_eq!(m, &material, "{case}");
                assert_eq!(k, key, "{case}");
            }
            other => panic!("{case}: expected BadMaterial, got {other:?}"),
        }
        for needle in [
            &path.display().to_string(),
            &format!("'{material}'"),
            key,
            fragment,
            "README.md",
        ] {
            assert!(msg.contains(needle), "{case}: '{needle}' not in: {msg}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
