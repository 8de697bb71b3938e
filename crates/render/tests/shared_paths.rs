//! Shared paths (LightingSchedule::Shared, the default): one camera path serves every lighting of
//! a render. Each lighting's image and passes must equal, within noise, the same lighting traced
//! on its own paths (LightingSchedule::Separate): per 6 × 6 block, the two means agree within a
//! few standard errors, the standard errors estimated from two seeds per schedule. The test also
//! shows that its statistic rejects a lighting that is 10 % too bright, so it can fail.

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
const SPP: u32 = 16;

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

/// Per block: mean of the two renders, and the variance of that mean from the per-pixel
/// differences of the two seeds ((a − b)² / 2 estimates a pixel's variance).
fn block_stats(a: &Image, b: &Image) -> Vec<(f64, f64)> {
    let n = SIZE / BLOCK;
    let mut out = Vec::new();
    for by in 0..n {
        for bx in 0..n {
            let (mut mean, mut var) = (0.0, 0.0);
            for y in by * BLOCK..(by + 1) * BLOCK {
                for x in bx * BLOCK..(bx + 1) * BLOCK {
                    let p = y * SIZE + x;
                    mean += (a[p] + b[p]) / 2.0;
                    var += (a[p] - b[p]).powi(2) / 2.0 / 2.0;
                }
            }
            let m = (BLOCK * BLOCK) as f64;
            out.push((mean / m, var / (m * m)));
        }
    }
    out
}

/// z-scores of shared against separate over every block of every quantity with light in it;
/// `scale` multiplies the separate means (1 for the real test, else a deliberate error).
fn z_scores(
    shared: &[RenderOutput; 2],
    separate: &[RenderOutput; 2],
    scale: f64,
) -> Vec<(String, f64)> {
    let mut z = Vec::new();
    for light in 0..lights().len() {
        let (sa, sb) = (images(&shared[0], light), images(&shared[1], light));
        let (pa, pb) = (images(&separate[0], light), images(&separate[1], light));
        for q in 0..sa.len() {
            let s = block_stats(&sa[q].1, &sb[q].1);
            let p = block_stats(&pa[q].1, &pb[q].1);
            for (i, ((ms, vs), (mp, vp))) in s.iter().zip(&p).enumerate() {
                let v = vs + vp * scale * scale;
                if v <= 0.0 {
                    assert_eq!(
                        *ms, *mp,
                        "lighting {light} {} block {i}: no noise, so equal",
                        sa[q].0
                    );
                    continue;
                }
                z.push((
                    format!("lighting {light} {} block {i}", sa[q].0),
                    (ms - mp * scale) / v.sqrt(),
                ));
            }
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

    let shared = [render(shared_renderer, 11), render(shared_renderer, 12)];
    let separate = [
        render(&separate_renderer, 13),
        render(&separate_renderer, 14),
    ];
    for (name, out) in [("shared", &shared[0]), ("separate", &separate[0])] {
        println!(
            "{name}: {} rays in {:.2} s ({} lightings)",
            out.stats.rays, out.stats.seconds, out.stats.lightings
        );
    }
    // The camera rays, and so the aux passes, come from the seed alone.
    let same_seed = render(&separate_renderer, 11);
    assert_eq!(shared[0].albedo, same_seed.albedo);
    assert_eq!(shared[0].normal, same_seed.normal);
    assert_eq!(shared[0].mask, same_seed.mask);
    assert_eq!(shared[0].id, same_seed.id);
    // Extension rays are traced once instead of once per lighting.
    assert!(
        (shared[0].stats.rays as f64) < 0.75 * separate[0].stats.rays as f64,
        "shared paths cast {} rays, separate {}",
        shared[0].stats.rays,
        separate[0].stats.rays
    );

    let z = z_scores(&shared, &separate, 1.0);
    assert!(z.len() > 100, "{} blocks with light in them", z.len());
    let chi2 = z.iter().map(|(_, z)| z * z).sum::<f64>() / z.len() as f64;
    let beyond3 = z.iter().filter(|(_, z)| z.abs() > 3.0).count();
    let (worst, zmax) = z
        .iter()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .expect("blocks");
    println!(
        "{} block tests: mean z² {chi2:.3}, {beyond3} beyond 3 SE, worst {worst} at {zmax:.2} SE",
        z.len()
    );
    // Under the null each z is close to N(0, 1): its squares average ≈ 1 (a much smaller value
    // would mean inflated standard errors, a test that cannot fail), 0.27 % lie beyond 3 and
    // none (at this count) beyond 4.5.
    assert!((0.6..1.5).contains(&chi2), "mean z² {chi2}");
    assert!(
        beyond3 * 100 <= z.len(),
        "{beyond3} of {} blocks beyond 3 SE",
        z.len()
    );
    assert!(zmax.abs() < 4.5, "{worst}: {zmax:.2} standard errors apart");

    // The same statistic on a lighting 10 % too bright.
    let wrong = z_scores(&shared, &separate, 1.1);
    let wrong_chi2 = wrong.iter().map(|(_, z)| z * z).sum::<f64>() / wrong.len() as f64;
    println!("with a 10 % error: mean z² {wrong_chi2:.3}");
    assert!(
        wrong_chi2 > 1.5,
        "a 10 % error went unnoticed: mean z² {wrong_chi2}"
    );
}
