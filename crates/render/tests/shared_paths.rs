//! Shared paths (LightingSchedule::Shared, the default): one camera path serves every lighting of
//! a render. Each lighting's image and passes must equal, within noise, the same lighting traced
//! on its own paths (LightingSchedule::Separate): per 6 × 6 block, the two means agree within a
//! few standard errors, the standard errors estimated from four seeds per schedule (the sss pass
//! of a small light is heavy-tailed: two seeds can agree by chance on a rare bright path). With
//! the same seed the two schedules agree bit for bit: a lighting draws its shadow rays from a
//! stream of its own. The test also shows that its statistic rejects a lighting that is 10 %
//! too bright, so it can fail.
//!
//! LightingSchedule::Mixture (one shadow ray per vertex for all lightings, aimed by the mixture
//! of their distributions) is a different estimator of the same images: the same block test
//! against separate renders, and the same camera paths (aux passes) as shared paths.

mod common;

use std::path::Path;

use glam::Vec3;
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::passes::{LitPasses, Pass};
use lightfarm_render::scene::Camera;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{EnvLight, LightingSchedule, RenderOutput, RenderSettings, Renderer};

const SIZE: usize = 24;
const BLOCK: usize = 6;
const SPP: u32 = 64;

fn park() -> EnvLight {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/hdri/rooitou_park_1k.hdr");
    EnvLight {
        name: "rooitou".into(),
        hdri: Hdri::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        transform: EnvTransform {
            rotation_deg: 70.0,
            ..EnvTransform::default()
        },
    }
}

/// A warm patch high on one side over a dim blue sky: light the other two do not share.
fn patch() -> EnvLight {
    let (w, h) = (64u32, 32u32);
    let mut texels = vec![[0.05f32, 0.08, 0.15]; (w * h) as usize];
    for y in 4..8 {
        for x in 10..16 {
            texels[(y * w + x) as usize] = [40.0, 25.0, 10.0];
        }
    }
    EnvLight {
        name: "patch".into(),
        hdri: Hdri::from_texels(w, h, texels).expect("hdri"),
        transform: EnvTransform::default(),
    }
}

fn lights() -> Vec<EnvLight> {
    vec![park(), patch(), common::constant_light(0.5)]
}

fn render(renderer: &Renderer, seed: u32) -> RenderOutput {
    let camera = Camera::look_at(Vec3::new(0.0, 0.02, 0.1), Vec3::ZERO, 30.0).expect("camera");
    let settings = RenderSettings {
        width: SIZE as u32,
        height: SIZE as u32,
        spp: SPP,
        seed,
        max_depth: 8,
        rr_depth: 3,
        camera,
        passes: Pass::ALL.to_vec(),
    };
    let packed = pack_scene(&common::skin_floor_lens()).expect("pack");
    renderer
        .render(&packed, &lights(), &settings, &mut |_| {})
        .expect("render")
}

fn luminance(c: [f32; 3]) -> f64 {
    0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2])
}

/// One quantity of one lighting, per pixel (luminance of lit or of a pass).
type Image = Vec<f64>;

fn images(out: &RenderOutput, light: usize) -> Vec<(&'static str, Image)> {
    let lum = |v: &[[f32; 3]]| v.iter().map(|c| luminance(*c)).collect::<Image>();
    let p: &LitPasses = &out.passes[light];
    vec![
        ("lit", lum(&out.lit[light])),
        ("diffuse", lum(&p.diffuse)),
        ("specular", lum(&p.specular)),
        ("sss", lum(&p.sss)),
    ]
}

/// z-scores of shared against separate over every block of every quantity with light in it;
/// `scale` multiplies the separate means (1 for the real test, else a deliberate error).
fn z_scores(shared: &[RenderOutput], separate: &[RenderOutput], scale: f64) -> Vec<(String, f64)> {
    let mut z = Vec::new();
    for light in 0..lights().len() {
        let s: Vec<_> = shared.iter().map(|o| images(o, light)).collect();
        let p: Vec<_> = separate.iter().map(|o| images(o, light)).collect();
        for q in 0..s[0].len() {
            let x: Vec<&[f64]> = s.iter().map(|i| i[q].1.as_slice()).collect();
            let y: Vec<&[f64]> = p.iter().map(|i| i[q].1.as_slice()).collect();
            z.extend(common::blocks::block_z(
                &format!("lighting {light} {}", s[0][q].0),
                &x,
                &y,
                SIZE,
                BLOCK,
                scale,
            ));
        }
    }
    z
}

#[test]
fn every_lighting_of_shared_paths_matches_that_lighting_traced_alone() {
    let shared_renderer = common::renderer();
    assert_eq!(
        shared_renderer.lighting_schedule(),
        LightingSchedule::Shared
    );
    let mut separate_renderer = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    separate_renderer.set_lighting_schedule(LightingSchedule::Separate);

    let mut mixture_renderer = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    mixture_renderer.set_lighting_schedule(LightingSchedule::Mixture);

    let shared: Vec<RenderOutput> = (11..15).map(|s| render(shared_renderer, s)).collect();
    let separate: Vec<RenderOutput> = (21..25).map(|s| render(&separate_renderer, s)).collect();
    // Eight seeds: under the mixture the small patch gets a third of the shadow rays, and the
    // standard errors of its heavy-tailed sss pass need more than four renders to settle.
    let mixture: Vec<RenderOutput> = (11..19).map(|s| render(&mixture_renderer, s)).collect();
    for (name, out) in [
        ("shared", &shared[0]),
        ("separate", &separate[0]),
        ("mixture", &mixture[0]),
    ] {
        println!(
            "{name}: {} rays in {:.2} s ({} lightings)",
            out.stats.rays, out.stats.seconds, out.stats.lightings
        );
    }
    // The camera rays, and so the aux passes, come from the seed alone; so do the paths and,
    // a lighting's shadow rays being drawn from its own stream, every lighting's image: shared
    // paths are the separate estimator, bit for bit, at a fraction of the rays.
    let same_seed = render(&separate_renderer, 11);
    assert_eq!(shared[0].lit, same_seed.lit);
    for (a, b) in shared[0].passes.iter().zip(&same_seed.passes) {
        assert_eq!(a.diffuse, b.diffuse);
        assert_eq!(a.shadow, b.shadow);
    }
    assert_same_camera_paths(&shared[0], &same_seed);
    // Extension rays are traced once instead of once per lighting.
    assert_fewer_rays("shared paths", &shared[0], "separate", &separate[0], 0.75);

    let z = z_scores(&shared, &separate, 1.0);
    common::blocks::assert_null("shared against separate", &z, 100);

    // The path's own stream is drawn the same under both: same camera rays, same paths.
    assert_same_camera_paths(&mixture[0], &shared[0]);
    // One shadow ray per vertex instead of one per lighting (three here). The skin's random
    // walks cast most of this scene's rays, so the saving is ~13 %, not two thirds.
    assert_fewer_rays("mixture", &mixture[0], "shared", &shared[0], 0.95);
    let z = z_scores(&mixture, &separate, 1.0);
    common::blocks::assert_null("mixture against separate", &z, 100);

    // The same statistic on a lighting 10 % too bright.
    let wrong = z_scores(&shared, &separate, 1.1);
    let wrong_chi2 = common::blocks::mean_z2(&wrong);
    println!("with a 10 % error: mean z² {wrong_chi2:.3}");
    assert!(
        wrong_chi2 > 1.5,
        "a 10 % error went unnoticed: mean z² {wrong_chi2}"
    );
}

/// The camera-ray passes of two renders are the same bit for bit.
fn assert_same_camera_paths(a: &RenderOutput, b: &RenderOutput) {
    assert_eq!(a.albedo, b.albedo);
    assert_eq!(a.normal, b.normal);
    assert_eq!(a.mask, b.mask);
    assert_eq!(a.id, b.id);
}

/// `a` cast fewer than `ratio` times the rays of `b`.
fn assert_fewer_rays(a_name: &str, a: &RenderOutput, b_name: &str, b: &RenderOutput, ratio: f64) {
    assert!(
        (a.stats.rays as f64) < ratio * b.stats.rays as f64,
        "{a_name} cast {} rays, {b_name} {}",
        a.stats.rays,
        b.stats.rays
    );
}
