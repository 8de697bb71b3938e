//! `lightfarm render` end to end: a real render of the built-in head, and malformed inputs that
//! must end in an error naming the bad file or flag, never a panic.

mod common;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use common::{lightfarm, repo};
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::scene::{materials_json, Camera, Scene};
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{EnvLight, RenderOutput, RenderSettings, Renderer};

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lightfarm-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

fn asset(rel: &str) -> String {
    repo().join("assets").join(rel).display().to_string()
}

/// Renders in this process what the `lightfarm.spec` header attribute of `lightfarm render`'s
/// output describes (scene, HDRIs with rotation and flip, camera, size, spp, seed, depth).
fn render_from_spec(spec: &serde_json::Value) -> RenderOutput {
    let f32s = |v: &serde_json::Value| -> glam::Vec3 {
        let a: Vec<f32> = v
            .as_array()
            .expect("a 3-vector")
            .iter()
            .map(|x| x.as_f64().expect("a number") as f32)
            .collect();
        glam::Vec3::new(a[0], a[1], a[2])
    };
    let num = |k: &str| spec[k].as_u64().unwrap_or_else(|| panic!("spec.{k}")) as u32;
    let scene = Scene::load_gltf(Path::new(spec["scene"].as_str().expect("scene"))).expect("scene");
    let lights: Vec<EnvLight> = spec["hdri"]
        .as_array()
        .expect("hdri list")
        .iter()
        .map(|h| {
            let path = h["path"].as_str().expect("hdri path");
            EnvLight {
                name: path.to_string(),
                hdri: Hdri::load(Path::new(path)).expect("hdri"),
                transform: EnvTransform {
                    rotation_deg: h["rotation_deg"].as_f64().expect("rotation") as f32,
                    flip: h["flip"].as_bool().expect("flip"),
                },
            }
        })
        .collect();
    let c = &spec["camera"];
    let camera = Camera {
        position: f32s(&c["position"]),
        forward: f32s(&c["forward"]),
        up: f32s(&c["up"]),
        yfov_deg: c["yfov_deg"].as_f64().expect("fov") as f32,
    };
    let settings = RenderSettings {
        width: num("width"),
        height: num("height"),
        spp: num("spp"),
        seed: num("seed"),
        max_depth: num("max_depth"),
        // Not in the spec: the CLI's fixed Russian-roulette depth.
        rr_depth: 5,
        camera,
        passes: lightfarm_render::passes::Pass::parse_list(
            &spec["passes"]
                .as_array()
                .expect("spec.passes")
                .iter()
                .map(|p| p.as_str().expect("a pass name"))
                .collect::<Vec<_>>(),
        )
        .expect("passes"),
    };
    Renderer::new(&DeviceRequest::Auto)
        .expect("a Vulkan device")
        .render(
            &pack_scene(&scene).expect("pack"),
            &lights,
            &settings,
            &mut |_| {},
        )
        .expect("render")
}

/// Runs a render that must fail; returns stderr after checking the failure is clean.
fn fails(args: &[&str]) -> String {
    let out = lightfarm(args);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(
        out.status.code(),
        Some(1),
        "expected a clean failure for {args:?}, stderr: {err}"
    );
    assert!(!err.contains("panicked"), "panicked for {args:?}: {err}");
    err
}

#[test]
fn renders_the_head_with_two_lightings_stats_and_preview() {
    let out = tmp("head.exr");
    let stats = tmp("head.json");
    let preview = tmp("head.png");
    let head = asset("heads/LeePerrySmith_textured.glb");
    let (studio, park) = (
        asset("hdri/studio_small_03_1k.hdr"),
        asset("hdri/rooitou_park_1k.hdr"),
    );
    let o = lightfarm(&[
        "render",
        "--scene",
        &head,
        "--hdri",
        &studio,
        "--hdri",
        &park,
        "--hdri-rotation",
        "30",
        "--hdri-rotation",
        "-45",
        "--size",
        "32x24",
        "--spp",
        "4",
        "--seed",
        "5",
        "--out",
        out.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--preview",
        preview.to_str().unwrap(),
    ]);
    assert!(
        o.status.success(),
        "render failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    for key in ["seconds", "samples_per_second", "rays_per_second", "device"] {
        assert!(s.get(key).is_some(), "stats lack {key}: {s}");
    }
    assert!(s["samples_per_second"].as_f64().unwrap() > 0.0);
    let img = exr::prelude::read_all_flat_layers_from_file(&out).expect("read exr back");
    let layer = &img.layer_data[0];
    assert_eq!((layer.size.0, layer.size.1), (32, 24));
    let channels: HashMap<String, Vec<f32>> = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    let spec = match layer
        .attributes
        .other
        .get(&exr::prelude::Text::from("lightfarm.spec"))
    {
        Some(exr::prelude::AttributeValue::Text(t)) => {
            serde_json::from_str::<serde_json::Value>(&t.to_string()).expect("spec is JSON")
        }
        other => panic!("spec attribute missing or not text: {other:?}"),
    };
    // The materials as loaded, every parameter (the LeePerrySmith file carries no extras).
    let materials = match layer
        .attributes
        .other
        .get(&exr::prelude::Text::from("lightfarm.materials"))
    {
        Some(exr::prelude::AttributeValue::Text(t)) => {
            serde_json::from_str::<serde_json::Value>(&t.to_string()).expect("materials is JSON")
        }
        other => panic!("materials attribute missing or not text: {other:?}"),
    };
    let scene = Scene::load_gltf(Path::new(&head)).expect("head");
    assert_eq!(materials, materials_json(&scene));
    assert_eq!(materials[0]["name"], "LeePerrySmith_skin");
    assert_eq!(materials[0]["model"], "gltf");
    // The header's spec is enough to render the same passes again in this process, and the
    // file must hold exactly those passes, each channel under its own name.
    let rendered = render_from_spec(&spec);
    assert_ne!(
        rendered.lit[0], rendered.lit[1],
        "two lightings, two images"
    );
    assert!(
        rendered.mask.iter().any(|m| *m > 0.5),
        "the head is in view"
    );
    let rgb = |v: &[[f32; 3]], k: usize| v.iter().map(|p| p[k]).collect::<Vec<f32>>();
    let mut expected: Vec<(String, Vec<f32>)> = Vec::new();
    for (l, lit) in rendered.lit.iter().enumerate() {
        for (k, c) in ["R", "G", "B"].iter().enumerate() {
            expected.push((format!("lit{l}.{c}"), rgb(lit, k)));
        }
    }
    for (k, c) in ["R", "G", "B"].iter().enumerate() {
        expected.push((format!("albedo.{c}"), rgb(&rendered.albedo, k)));
    }
    for (k, c) in ["X", "Y", "Z"].iter().enumerate() {
        expected.push((format!("normal.{c}"), rgb(&rendered.normal, k)));
        expected.push((format!("normal_lens.{c}"), rgb(&rendered.normal_lens, k)));
    }
    expected.push(("mask.A".into(), rendered.mask.clone()));
    // The default appendix passes, per lighting, and the id.
    assert_eq!(
        rendered.pass_set,
        lightfarm_render::passes::Pass::DEFAULT.to_vec(),
        "lightfarm render writes the default passes"
    );
    for (l, lp) in rendered.passes.iter().enumerate() {
        for (k, c) in ["R", "G", "B"].iter().enumerate() {
            expected.push((format!("diffuse{l}.{c}"), rgb(&lp.diffuse, k)));
            expected.push((format!("specular{l}.{c}"), rgb(&lp.specular, k)));
        }
        expected.push((format!("shadow{l}.A"), lp.shadow.clone()));
    }
    expected.push((
        "id.A".into(),
        rendered.id.iter().map(|v| *v as f32).collect(),
    ));
    assert_eq!(channels.len(), expected.len(), "{:?}", channels.keys());
    for (name, want) in &expected {
        let got = channels
            .get(name)
            .unwrap_or_else(|| panic!("channel {name} missing from {:?}", channels.keys()));
        let same = got.len() == want.len()
            && got
                .iter()
                .zip(want)
                .all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same, "channel {name} differs from the rendered pass");
    }
    let png = image::open(&preview).expect("preview png");
    assert_eq!((png.width(), png.height()), (32, 24));
}

#[test]
fn malformed_inputs_name_the_file_or_flag() {
    let head = asset("heads/LeePerrySmith_textured.glb");
    let studio = asset("hdri/studio_small_03_1k.hdr");
    let out = tmp("bad.exr");
    let out_s = out.to_str().unwrap();

    // Truncated HDR and EXR, a broken glTF, a missing file.
    let bytes = std::fs::read(&studio).unwrap();
    let trunc_hdr = tmp("trunc.hdr");
    std::fs::write(&trunc_hdr, &bytes[..2000]).unwrap();
    let trunc_s = trunc_hdr.to_str().unwrap();
    let err = fails(&[
        "render", "--scene", &head, "--hdri", trunc_s, "--size", "8x8", "--spp", "1", "--out",
        out_s,
    ]);
    assert!(err.contains("trunc.hdr"), "{err}");

    let trunc_exr = tmp("trunc.exr");
    let mut exr_bytes = Vec::new();
    {
        let good = tmp("good.exr");
        let o = lightfarm(&[
            "render",
            "--scene",
            &head,
            "--hdri",
            &studio,
            "--size",
            "8x8",
            "--spp",
            "1",
            "--out",
            good.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        exr_bytes.extend_from_slice(&std::fs::read(&good).unwrap());
    }
    std::fs::write(&trunc_exr, &exr_bytes[..exr_bytes.len() / 2]).unwrap();
    let err = fails(&[
        "render",
        "--scene",
        &head,
        "--hdri",
        trunc_exr.to_str().unwrap(),
        "--size",
        "8x8",
        "--spp",
        "1",
        "--out",
        out_s,
    ]);
    assert!(err.contains("trunc.exr"), "{err}");

    let broken = tmp("broken.glb");
    let glb = std::fs::read(&head).unwrap();
    std::fs::write(&broken, &glb[..glb.len() / 3]).unwrap();
    let err = fails(&[
        "render",
        "--scene",
        broken.to_str().unwrap(),
        "--hdri",
        &studio,
        "--size",
        "8x8",
        "--spp",
        "1",
        "--out",
        out_s,
    ]);
    assert!(err.contains("broken.glb"), "{err}");

    let err = fails(&[
        "render",
        "--scene",
        "/no/such/scene.glb",
        "--hdri",
        &studio,
        "--out",
        out_s,
    ]);
    assert!(err.contains("/no/such/scene.glb"), "{err}");

    // Absurd parameters name their flag.
    for (flag, value) in [
        ("--size", "0x0"),
        ("--size", "banana"),
        ("--size", "100000x10"),
        ("--spp", "0"),
        ("--spp", "4000000000"),
        ("--lightings", "banana"),
    ] {
        let err = fails(&[
            "render", "--scene", &head, "--hdri", &studio, flag, value, "--out", out_s,
        ]);
        assert!(err.contains(flag), "{flag} {value}: {err}");
        if flag == "--lightings" {
            assert!(err.contains("shared, mixture or separate"), "{err}");
        }
    }
    let err = fails(&[
        "render", "--scene", &head, "--hdri", &studio, "--camera", "1,2:3", "--size", "8x8",
        "--out", out_s,
    ]);
    assert!(err.contains("--camera"), "{err}");
    let err = fails(&[
        "render",
        "--scene",
        &head,
        "--hdri",
        &studio,
        "--device",
        "no-such-gpu",
        "--size",
        "8x8",
        "--out",
        out_s,
    ]);
    assert!(err.to_lowercase().contains("device"), "{err}");
    let err = fails(&[
        "render",
        "--scene",
        &head,
        "--hdri",
        &studio,
        "--size",
        "8x8",
        "--out",
        "/no/such/dir/out.exr",
    ]);
    assert!(err.contains("--out"), "{err}");
    assert!(!out.exists(), "nothing written on failure");
}
