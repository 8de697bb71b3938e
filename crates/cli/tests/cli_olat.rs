//! `lightfarm relight-olat` end to end: a farm sample rendered with OLAT layers (`olat = 8`
//! under [lighting]) relit under a posed HDRI is Σ weightᵢ × OLAT imageᵢ, exactly as computed
//! here from the file; samples without OLAT layers, missing HDRIs and broken files are refused
//! with errors naming them. (That the sum equals a direct render of the HDRI within noise is
//! crates/render/tests/olat.rs.)

mod common;

use std::path::Path;

use common::{lightfarm, repo};
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::Renderer;
use lightfarm_trainer::olat_sample::decode_olat;

fn spec(olat: u32) -> String {
    format!(
        "name = \"olat\"\nseed = 3\ncount = 1\nwidth = 24\nheight = 24\nspp = 4\n\
         [lighting]\nolat = {olat}\n[subject]\nhair_styles = [\"buzz\"]\n"
    )
}

fn render_sample(renderer: &Renderer, olat: u32, path: &Path) {
    let catalog = lightfarm_scene::Catalog::builtin().expect("catalog");
    let resolved = lightfarm_scene::spec::DatasetSpec::from_toml_str(&spec(olat), "olat.toml")
        .and_then(|s| s.validate(&catalog))
        .expect("spec");
    let sample = lightfarm_scene::expand::expand(&resolved, 0).expect("expand");
    let json = lightfarm_scene::expand::expand_json(&resolved, 0).expect("json");
    lightfarm_worker::render_to_exr(renderer, &catalog, &sample, &json, path).expect("render");
}

fn read_rgba(path: &Path) -> (usize, Vec<[f32; 4]>) {
    let bytes = std::fs::read(path).expect("relit EXR");
    let (w, _, c) = common::exr_channels(&bytes, &["R", "G", "B", "A"]);
    let px = (0..c[0].len())
        .map(|i| [c[0][i], c[1][i], c[2][i], c[3][i]])
        .collect();
    (w as usize, px)
}

#[test]
fn relight_olat_sums_a_samples_olat_images_under_any_posed_hdri() {
    let dir = tempfile::tempdir().expect("temp dir");
    let renderer = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    let sample = dir.path().join("sample.exr");
    render_sample(&renderer, 8, &sample);
    let bytes = std::fs::read(&sample).expect("sample");
    let olat = decode_olat(&bytes, "sample.exr").expect("OLAT layers");
    assert_eq!(olat.lights.len(), 8);
    assert_eq!(olat.spec.as_ref().map(|s| s.render.olat), Some(8));
    assert!(
        olat.lights.iter().all(|l| l.iter().any(|p| p[1] > 0.0)),
        "every light reaches the subject somewhere"
    );

    let hdri = repo().join("assets/hdri/rooitou_park_1k.hdr");
    let (out, png) = (dir.path().join("relit.exr"), dir.path().join("relit.png"));
    let o = lightfarm(&[
        "relight-olat",
        sample.to_str().expect("path"),
        "--hdri",
        hdri.to_str().expect("path"),
        "--rotation",
        "-60",
        "--flip",
        "--out",
        out.to_str().expect("path"),
        "--png",
        png.to_str().expect("path"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let basis = lightfarm_subject::render::olat_basis(8).expect("basis");
    let env = Hdri::load(&hdri).expect("hdri");
    let transform = EnvTransform {
        rotation_deg: -60.0,
        flip: true,
    };
    let weights = basis.weights(&env, &transform);
    let refs: Vec<&[[f32; 3]]> = olat.lights.iter().map(|v| v.as_slice()).collect();
    let want = basis.relight(&weights, &refs).expect("relight");
    let (w, got) = read_rgba(&out);
    assert_eq!((w, got.len()), (24, 24 * 24));
    for (i, (g, e)) in got.iter().zip(&want).enumerate() {
        assert_eq!([g[0], g[1], g[2]], *e, "pixel {i}");
        assert_eq!(g[3], olat.mask[i], "mask at pixel {i}");
    }
    assert!(want.iter().any(|p| p[0] > 0.0), "a lit subject");
    // Another pose weighs the lights differently: the relighting follows the HDRI.
    let unposed = basis.weights(&env, &EnvTransform::default());
    assert!(weights
        .iter()
        .zip(&unposed)
        .any(|(a, b)| (a[1] - b[1]).abs() > 0.05 * b[1].abs().max(1e-3)));
    let preview = image::open(&png).expect("png");
    assert_eq!((preview.width(), preview.height()), (24, 24));
}

#[test]
fn relight_olat_refuses_what_it_cannot_relight_and_names_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let renderer = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    let plain = dir.path().join("plain.exr");
    render_sample(&renderer, 0, &plain);
    let hdri = repo().join("assets/hdri/rooitou_park_1k.hdr");
    let out = dir.path().join("relit.exr");
    let garbage = dir.path().join("garbage.exr");
    std::fs::write(&garbage, b"not an exr at all").expect("write");
    let run = |sample: &Path, hdri: &str| {
        let o = lightfarm(&[
            "relight-olat",
            sample.to_str().expect("path"),
            "--hdri",
            hdri,
            "--out",
            out.to_str().expect("path"),
        ]);
        assert!(!o.status.success(), "{} accepted", sample.display());
        assert!(!out.exists(), "no output on failure");
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let e = run(&plain, hdri.to_str().expect("path"));
    assert!(e.contains("plain.exr") && e.contains("olat = 168"), "{e}");
    let e = run(&garbage, hdri.to_str().expect("path"));
    assert!(e.contains("garbage.exr") && e.contains("OpenEXR"), "{e}");
    let e = run(&plain, "no_such_hdri");
    assert!(e.contains("--hdri no_such_hdri"), "{e}");
}
