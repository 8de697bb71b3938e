//! The virtual light stage (issue 15): OLAT lights rendered as analytic discs, many lightings
//! sharing camera paths in groups, and relighting as the weighted sum of the OLAT images.
//!
//! Scene: a skin sphere on a glossy floor (subsurface walks, interreflection, shadows).
//!
//! - Each disc renders, within noise, as the lat-long map `OlatBasis::map` makes of it (the one
//!   definition in crates/light), also when its lightings are split into groups that trace their
//!   own paths; a 10 % error and two swapped lights are rejected by the same statistic.
//! - For an HDRI that is itself a sum of OLAT lights, Σ weightᵢ × OLAT imageᵢ over all 168
//!   lights equals a direct render of that HDRI within noise.

mod common;

use glam::Vec3;
use lightfarm_light::{EnvTransform, Hdri, OlatBasis};
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::scene::Camera;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{DiscLight, EnvLight, Lighting, RenderOutput, RenderSettings, Renderer};

const SIZE: usize = 24;
/// Independent renders (seeds) per estimator: the per-pixel variance each block's standard
/// error comes from has three degrees of freedom, so the z-scores are close to normal.
const SEEDS: u32 = 4;
const BLOCK: usize = 4;
const SPP: u32 = 16;
/// The relighting test's: the direct render samples a mixture of three small lights, whose
/// noise has heavier tails; more samples per pixel and more blocks.
const RELIGHT_SIZE: usize = 32;
const RELIGHT_SPP: u32 = 64;

fn settings(seed: u32, size: usize, spp: u32) -> RenderSettings {
    RenderSettings {
        width: size as u32,
        height: size as u32,
        spp,
        seed,
        max_depth: 8,
        rr_depth: 3,
        camera: Camera::look_at(Vec3::new(0.0, 0.02, 0.1), Vec3::ZERO, 30.0).expect("camera"),
        passes: Vec::new(),
    }
}

fn render(renderer: &Renderer, lights: &[Lighting], seed: u32) -> RenderOutput {
    render_at(renderer, lights, seed, SIZE, SPP)
}

fn render_at(
    renderer: &Renderer,
    lights: &[Lighting],
    seed: u32,
    size: usize,
    spp: u32,
) -> RenderOutput {
    let packed = pack_scene(&skin_floor()).expect("pack");
    renderer
        .render_lightings(&packed, lights, &settings(seed, size, spp), &mut |_| {})
        .expect("render")
}

/// The shared skin-floor-lens scene without its lens: light through a lens from a 4° disc is
/// a caustic only BSDF sampling finds, whose rare bright samples would make the two-seed
/// variance estimates (and so the z-scores) heavy-tailed.
fn skin_floor() -> lightfarm_render::scene::Scene {
    let mut scene = common::skin_floor_lens();
    let lens = scene.instances.pop();
    assert!(lens.is_some(), "the scene has its lens last");
    scene
}

fn luminance(img: &[[f32; 3]]) -> Vec<f64> {
    img.iter()
        .map(|c| 0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2]))
        .collect()
}

fn map_light(basis: &OlatBasis, i: usize) -> EnvLight {
    EnvLight {
        name: format!("olat map {i}"),
        hdri: basis.map(i),
        transform: EnvTransform::default(),
    }
}

/// Lights that reach the camera's side of the skin sphere, from different sides.
fn front_lights(basis: &OlatBasis) -> [usize; 3] {
    let unit = |v: [f64; 3]| {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / l, v[1] / l, v[2] / l]
    };
    [
        basis.nearest(unit([0.4, 0.6, 0.7])),
        basis.nearest(unit([-0.8, 0.3, 0.5])),
        basis.nearest(unit([0.1, 0.9, 0.2])),
    ]
}

#[test]
fn olat_discs_render_as_their_maps_in_groups_of_any_size() {
    let mut renderer = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    let basis = OlatBasis::paper();
    let chosen = front_lights(&basis);
    let discs = DiscLight::olat(&basis);
    let disc_set: Vec<Lighting> = chosen.iter().map(|&i| Lighting::Disc(&discs[i])).collect();
    let maps: Vec<EnvLight> = chosen.iter().map(|&i| map_light(&basis, i)).collect();
    let map_set: Vec<Lighting> = maps.iter().map(Lighting::Map).collect();

    // Discs in groups of two (lightings 0-1 share paths, lighting 2 has its own), maps all
    // on one set of paths.
    renderer.set_lightings_per_path(Some(2));
    let d: Vec<RenderOutput> = (0..SEEDS)
        .map(|s| render(&renderer, &disc_set, 1 + s))
        .collect();
    assert_eq!(d[0].stats.lightings_per_path, 2);
    renderer.set_lightings_per_path(None);
    let m: Vec<RenderOutput> = (0..SEEDS)
        .map(|s| render(&renderer, &map_set, 11 + s))
        .collect();
    assert_eq!(m[0].stats.lightings_per_path, 3);

    let z_for = |a: usize, b: usize, scale: f64| {
        let x: Vec<Vec<f64>> = d.iter().map(|o| luminance(&o.lit[a])).collect();
        let y: Vec<Vec<f64>> = m.iter().map(|o| luminance(&o.lit[b])).collect();
        common::blocks::block_z(
            &format!("disc {} against map {}", chosen[a], chosen[b]),
            &x.iter().map(Vec::as_slice).collect::<Vec<_>>(),
            &y.iter().map(Vec::as_slice).collect::<Vec<_>>(),
            SIZE,
            BLOCK,
            scale,
        )
    };
    let mut z = Vec::new();
    for (k, light) in chosen.iter().enumerate() {
        let zk = z_for(k, k, 1.0);
        assert!(zk.len() > 10, "light {light}: {} lit blocks", zk.len());
        z.extend(zk);
    }
    common::blocks::assert_null("OLAT discs against their maps", &z, 60);

    let wrong: Vec<_> = (0..chosen.len()).flat_map(|k| z_for(k, k, 1.1)).collect();
    let wrong = common::blocks::mean_z2(&wrong);
    println!("with a 10 % error: mean z² {wrong:.3}");
    assert!(wrong > 1.5, "a 10 % error went unnoticed: mean z² {wrong}");
    let swapped = common::blocks::mean_z2(&z_for(0, 1, 1.0));
    println!("two lights swapped: mean z² {swapped:.3}");
    assert!(
        swapped > 3.0,
        "swapped lights went unnoticed: mean z² {swapped}"
    );
}

#[test]
fn relighting_from_all_168_olat_images_equals_a_direct_render() {
    let renderer = common::renderer();
    let basis = OlatBasis::paper();
    let chosen = front_lights(&basis);
    let colours = [[2.0f32, 1.2, 0.6], [0.3, 0.6, 1.5], [1.0, 1.0, 1.0]];
    // The HDRI: the three lights' maps, coloured.
    let mut texels = vec![[0f32; 3]; (basis.width * basis.height) as usize];
    for (&i, c) in chosen.iter().zip(colours) {
        for (t, v) in texels.iter_mut().zip(&basis.map(i).texels) {
            for ch in 0..3 {
                t[ch] += v[ch] * c[ch];
            }
        }
    }
    let hdri = Hdri::from_texels(basis.width, basis.height, texels).expect("hdri");
    let transform = EnvTransform::default();
    let weights = basis.weights(&hdri, &transform);
    for (i, w) in weights.iter().enumerate() {
        let want = chosen
            .iter()
            .position(|&c| c == i)
            .map_or([0.0; 3], |k| colours[k]);
        for ch in 0..3 {
            assert!(
                (w[ch] - want[ch] as f64).abs() < 1e-4,
                "weight of light {i}: {w:?}, want {want:?}"
            );
        }
    }

    let discs = DiscLight::olat(&basis);
    let all: Vec<Lighting> = discs.iter().map(Lighting::Disc).collect();
    let at =
        |lights: &[Lighting], seed| render_at(renderer, lights, seed, RELIGHT_SIZE, RELIGHT_SPP);
    let olat: Vec<RenderOutput> = (0..SEEDS).map(|s| at(&all, 21 + s)).collect();
    assert_eq!(olat[0].lit.len(), 168);
    assert_eq!(olat[0].stats.lightings_per_path, 168);
    let relit: Vec<Vec<f64>> = olat
        .iter()
        .map(|o| {
            let images: Vec<&[[f32; 3]]> = o.lit.iter().map(|v| v.as_slice()).collect();
            luminance(&basis.relight(&weights, &images).expect("relight"))
        })
        .collect();
    let env = EnvLight {
        name: "sum of three OLAT lights".into(),
        hdri,
        transform,
    };
    let direct: Vec<Vec<f64>> = (0..SEEDS)
        .map(|s| luminance(&at(&[Lighting::Map(&env)], 31 + s).lit[0]))
        .collect();
    let relit: Vec<&[f64]> = relit.iter().map(Vec::as_slice).collect();
    let direct: Vec<&[f64]> = direct.iter().map(Vec::as_slice).collect();
    let z = common::blocks::block_z(
        "relit against direct",
        &relit,
        &direct,
        RELIGHT_SIZE,
        BLOCK,
        1.0,
    );
    common::blocks::assert_null("relit from 168 OLAT images against a direct render", &z, 40);
    let wrong = common::blocks::block_z(
        "relit against direct",
        &relit,
        &direct,
        RELIGHT_SIZE,
        BLOCK,
        1.1,
    );
    let wrong = common::blocks::mean_z2(&wrong);
    println!("with a 10 % error: mean z² {wrong:.3}");
    assert!(wrong > 1.5, "a 10 % error went unnoticed: mean z² {wrong}");
}
