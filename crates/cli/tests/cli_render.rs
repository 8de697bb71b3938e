//! `lightfarm render` end to end: a real render of the built-in head, and malformed inputs that
//! must end in an error naming the bad file or flag, never a panic.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn lightfarm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lightfarm"))
        .args(args)
        .output()
        .expect("run lightfarm")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lightfarm-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

fn asset(rel: &str) -> String {
    repo().join("assets").join(rel).display().to_string()
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
    let names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for n in lightfarm_render::output::channel_names(2) {
        assert!(names.contains(&n), "channel {n} missing from {names:?}");
    }
    let attrs = &layer.attributes.other;
    assert!(
        attrs.contains_key(&exr::prelude::Text::from("lightfarm.spec")),
        "spec attribute missing"
    );
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
    ] {
        let err = fails(&[
            "render", "--scene", &head, "--hdri", &studio, flag, value, "--out", out_s,
        ]);
        assert!(err.contains(flag), "{flag} {value}: {err}");
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
