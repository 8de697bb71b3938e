//! Known-answer renders (pbrt-v4 integrators_test style) on the device: the white furnace,
//! environment orientation, the passes' geometry and determinism.

mod common;

use glam::{Mat4, Vec3};
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::scene::{shapes, Material, Scene};
use lightfarm_render::EnvLight;

/// Furnace: a diffuse sphere of albedo a (specular 0) in a constant environment of 1 reflects
/// exactly a everywhere (a convex object: every path leaves after one bounce).
#[test]
fn white_furnace_diffuse_sphere_equals_albedo() {
    let a = 0.8f32;
    let size = 48;
    let out = common::render(
        &common::sphere_scene(a),
        &[common::constant_light(1.0)],
        size,
        64,
        1,
    );
    let lit = &out.lit[0];
    let (mut sum, mut count) = (0.0f64, 0usize);
    for (p, m) in lit.iter().zip(&out.mask) {
        if *m > 0.999 {
            for c in p {
                assert!((c - a).abs() < 0.12, "pixel {c} is not {a} within noise");
            }
            sum += (p[0] + p[1] + p[2]) as f64 / 3.0;
            count += 1;
        }
    }
    assert!(count > 500, "the sphere covers {count} pixels");
    let mean = sum / count as f64;
    assert!(
        (mean - a as f64).abs() < 0.005 * a as f64,
        "furnace mean {mean} vs albedo {a}"
    );
    // Background stays 0 (the sample contract).
    for (p, m) in lit.iter().zip(&out.mask) {
        if *m == 0.0 {
            assert_eq!(*p, [0.0; 3]);
        }
    }
}

fn hot_texel_light(u: f32, v: f32, transform: EnvTransform) -> EnvLight {
    let (w, h) = (64u32, 32u32);
    let mut texels = vec![[0.0f32; 3]; (w * h) as usize];
    let x = ((u * w as f32) as u32).min(w - 1);
    let y = ((v * h as f32) as u32).min(h - 1);
    texels[(y * w + x) as usize] = [2000.0; 3];
    EnvLight {
        name: "hot texel".into(),
        hdri: Hdri::from_texels(w, h, texels).expect("hdri"),
        transform,
    }
}

/// Brightness-weighted mean position of the sphere's image in [-1, 1]² (x right, y up).
fn lit_centroid(light: EnvLight) -> (f32, f32, f32) {
    let size = 32u32;
    let out = common::render(&common::sphere_scene(0.8), &[light], size, 32, 2);
    let (mut sx, mut sy, mut sw) = (0.0f32, 0.0f32, 0.0f32);
    for (i, p) in out.lit[0].iter().enumerate() {
        let l = p[0] + p[1] + p[2];
        let x = ((i as u32 % size) as f32 + 0.5) / size as f32 * 2.0 - 1.0;
        let y = 1.0 - ((i as u32 / size) as f32 + 0.5) / size as f32 * 2.0;
        sx += l * x;
        sy += l * y;
        sw += l;
    }
    (sx / sw.max(1e-9), sy / sw.max(1e-9), sw)
}

#[test]
fn hot_texel_lights_the_expected_side() {
    // u = 0.25 is +X: the right side of a sphere seen from +Z.
    let (x, y, _) = lit_centroid(hot_texel_light(0.25, 0.5, EnvTransform::default()));
    assert!(x > 0.15 && y.abs() < 0.05, "+X light: centroid ({x}, {y})");
    // Flipped: the same texel now lights from -X.
    let (x, _, _) = lit_centroid(hot_texel_light(
        0.25,
        0.5,
        EnvTransform {
            rotation_deg: 0.0,
            flip: true,
        },
    ));
    assert!(x < -0.15, "flipped +X light: centroid x {x}");
    // Rotated by -90° about +Y, +X goes to +Z: the face toward the camera, centred.
    let (x, y, w) = lit_centroid(hot_texel_light(
        0.25,
        0.5,
        EnvTransform {
            rotation_deg: -90.0,
            flip: false,
        },
    ));
    assert!(
        x.abs() < 0.05 && y.abs() < 0.05 && w > 0.0,
        "+Z light: centroid ({x}, {y})"
    );
    // Near the top row (v small) is +Y: the top of the image.
    let (_, y, _) = lit_centroid(hot_texel_light(0.5, 0.1, EnvTransform::default()));
    assert!(y > 0.15, "+Y light: centroid y {y}");
    // u = 0.5 is +Z, toward the camera; +90° rotation takes +Z to +X.
    let (x, _, _) = lit_centroid(hot_texel_light(
        0.5,
        0.5,
        EnvTransform {
            rotation_deg: 90.0,
            flip: false,
        },
    ));
    assert!(x > 0.15, "+Z rotated by 90°: centroid x {x}");
}

/// Fraction of each pixel covered by the analytic sphere (radius 0.5 at the origin) seen by
/// `front_camera`, estimated with 16×16 sub-pixel rays.
fn analytic_coverage(size: u32) -> Vec<f32> {
    let tan_half = (15.0f32).to_radians().tan();
    let eye = Vec3::new(0.0, 0.0, 3.0);
    let mut out = Vec::new();
    for py in 0..size {
        for px in 0..size {
            let mut hits = 0;
            for a in 0..16 {
                for b in 0..16 {
                    let sx = ((px as f32 + (a as f32 + 0.5) / 16.0) / size as f32) * 2.0 - 1.0;
                    let sy = 1.0 - ((py as f32 + (b as f32 + 0.5) / 16.0) / size as f32) * 2.0;
                    let d = Vec3::new(sx * tan_half, sy * tan_half, -1.0).normalize();
                    let bq = eye.dot(d);
                    let c = eye.length_squared() - 0.25;
                    if bq * bq - c >= 0.0 {
                        hits += 1;
                    }
                }
            }
            out.push(hits as f32 / 256.0);
        }
    }
    out
}

#[test]
fn passes_normals_mask_and_lens() {
    let size = 40u32;
    let plain = common::render(
        &common::sphere_scene(0.5),
        &[common::constant_light(1.0)],
        size,
        64,
        3,
    );
    // Mask = analytic coverage.
    let analytic = analytic_coverage(size);
    let (ms, as_): (f32, f32) = (plain.mask.iter().sum(), analytic.iter().sum());
    assert!(
        (ms - as_).abs() < 0.01 * as_,
        "mask area {ms} vs analytic {as_}"
    );
    for (m, a) in plain.mask.iter().zip(&analytic) {
        assert!((m - a).abs() < 0.2, "mask {m} vs coverage {a}");
        if *a == 1.0 {
            // The tessellated sphere is inscribed in the analytic one: it may miss a sliver.
            assert!(
                *m > 0.9,
                "mask {m} where the analytic sphere covers the pixel"
            );
        }
        if *a == 0.0 {
            assert_eq!(*m, 0.0);
        }
    }
    // Normals: unit, camera space, and where they should point.
    for (n, m) in plain.normal.iter().zip(&plain.mask) {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if *m > 0.0 {
            assert!((len - 1.0).abs() < 1e-3, "normal length {len}");
            assert!(n[2] > -0.05, "visible normals face the camera: {n:?}");
        } else {
            assert_eq!(len, 0.0);
        }
    }
    let at = |x: u32, y: u32| plain.normal[(y * size + x) as usize];
    let c = at(size / 2, size / 2);
    assert!(c[2] > 0.98, "centre normal {c:?}");
    let right = at(size / 2 + 8, size / 2);
    assert!(right[0] > 0.5, "right of centre points +X: {right:?}");
    let top = at(size / 2, size / 2 - 9);
    assert!(top[1] > 0.5, "above centre points +Y: {top:?}");
    // No lens: the normal with lenses is the normal, bit for bit (the paper's N_l = N).
    assert!(
        plain
            .normal_lens
            .iter()
            .zip(&plain.normal)
            .all(|(nl, n)| nl.map(f32::to_bits) == n.map(f32::to_bits)),
        "no lens: normal_lens must equal normal"
    );
    assert!(plain
        .albedo
        .iter()
        .zip(&plain.mask)
        .all(|(a, m)| *m == 0.0 || (a[0] - 0.5).abs() < 1e-4));

    // A clear lens in front of the left half: only normal_lens sees it, and off the lens it is
    // the normal bit for bit.
    let mut scene = common::sphere_scene(0.5);
    let lens = common::clear_glass("lens");
    scene.add_mesh_instance(
        shapes::quad(0.6, 0.6),
        lens,
        Mat4::from_translation(Vec3::new(-0.35, 0.0, 1.0)),
    );
    let with_lens = common::render(&scene, &[common::constant_light(1.0)], size, 64, 3);
    let mut lens_pixels = 0;
    for i in 0..(size * size) as usize {
        let x = (i as u32 % size) as f32;
        let nl = with_lens.normal_lens[i];
        let differs = |j: usize| {
            with_lens.normal_lens[j].map(f32::to_bits) != with_lens.normal[j].map(f32::to_bits)
        };
        if differs(i) {
            lens_pixels += 1;
            assert!(x < size as f32 / 2.0, "lens normals only on the left");
            // Pixels on the lens's edge mix lens and sphere normals; inside it, only the lens.
            let s = size as usize;
            let inside = i % s > 0
                && i % s + 1 < s
                && i >= s
                && i + s < s * s
                && [i - 1, i + 1, i - s, i + s].into_iter().all(differs);
            assert!(!inside || nl[2] > 0.99, "the lens faces the camera: {nl:?}");
        }
        assert_eq!(
            with_lens.mask[i], plain.mask[i],
            "the lens does not count in the mask"
        );
        for k in 0..3 {
            assert!(
                (with_lens.normal[i][k] - plain.normal[i][k]).abs() < 1e-3,
                "the lens does not count in normal: pixel {i} {:?} vs {:?}",
                with_lens.normal[i],
                plain.normal[i]
            );
        }
    }
    assert!(lens_pixels > 50, "lens covers {lens_pixels} pixels");
}

#[test]
fn same_seed_same_image_other_seed_other_noise() {
    let scene = common::sphere_scene(0.7);
    let light = hot_texel_light(0.3, 0.4, EnvTransform::default());
    let lights = [light, common::constant_light(0.5)];
    let a = common::render(&scene, &lights, 24, 8, 42);
    let b = common::render(&scene, &lights, 24, 8, 42);
    let c = common::render(&scene, &lights, 24, 8, 43);
    assert_eq!(a.lit, b.lit);
    assert_eq!(a.normal, b.normal);
    assert_eq!(a.mask, b.mask);
    assert_ne!(a.lit[0], c.lit[0]);
    assert_eq!(a.lit.len(), 2);
}

/// glTF alpha: a mostly transparent veil (opacity 0.1, like MakeHuman's corneas) right in front
/// of the camera is invisible to the passes, and the pixel is the analytic mix: a camera ray
/// stops at the veil with probability 0.1 and sees its lit front (a white-furnace Lambertian of
/// albedo 0.9: 0.9), else passes on to the sphere (furnace: its albedo 0.5). The veil sits
/// 0.1 m from the eye, so it shadows the sphere by a negligible solid angle (< 0.1%).
#[test]
fn partial_coverage_is_seen_through() {
    let size = 24u32;
    let light = [common::constant_light(1.0)];
    let plain = common::render(&common::sphere_scene(0.5), &light, size, 64, 4);
    let veiled = |opacity: f32| {
        let mut scene = common::sphere_scene(0.5);
        let mut m = common::material(0.9, 0.0);
        m.opacity = opacity;
        scene.add_mesh_instance(
            shapes::quad(0.2, 0.2),
            m,
            Mat4::from_translation(Vec3::new(0.0, 0.0, 2.9)),
        );
        common::render(&scene, &light, size, 64, 4)
    };
    let thin = veiled(0.1);
    let centre = ((size / 2) * size + size / 2) as usize;
    assert_eq!(thin.mask, plain.mask, "the veil does not count in the mask");
    assert!(
        (thin.albedo[centre][0] - 0.5).abs() < 1e-4,
        "albedo seen through the veil: {:?}",
        thin.albedo[centre]
    );
    // Mean over the pixels the sphere covers fully: the mix's per-sample standard deviation is
    // 0.4·√(0.1·0.9) = 0.12, so over ~150 px × 64 spp the mean is good to ~0.001.
    let mean = |out: &lightfarm_render::RenderOutput| {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (p, m) in out.lit[0].iter().zip(&plain.mask) {
            if *m > 0.999 {
                sum += f64::from(p[0] + p[1] + p[2]) / 3.0;
                n += 1;
            }
        }
        assert!(n > 100, "the sphere covers {n} pixels");
        sum / n as f64
    };
    let (a, b) = (mean(&plain), mean(&thin));
    let expected = 0.1 * 0.9 + 0.9 * 0.5;
    assert!((a - 0.5).abs() < 0.005, "plain furnace sphere {a}");
    assert!(
        (b - expected).abs() < 0.006,
        "veiled {b} vs the analytic mix {expected} (plain {a})"
    );
    let opaque = veiled(1.0);
    assert!(
        (opaque.albedo[centre][0] - 0.9).abs() < 1e-4,
        "an opaque veil hides the sphere: {:?}",
        opaque.albedo[centre]
    );
    let c = mean(&opaque);
    assert!(
        (c - 0.9).abs() < 0.005,
        "the opaque veil is a furnace Lambertian: {c}"
    );
}

/// Furnace: a GGX metal sphere with F0 = 1 in a constant environment of 1 reflects, at each
/// point, the directional albedo of single-scattering GGX at its viewing angle: ≤ 1, and equal
/// to the albedo tabulated by CPU quadrature (tests/common/bsdf_ref.rs).
#[test]
fn furnace_rough_metal_sphere_matches_the_ggx_albedo() {
    let roughness = 0.8f32;
    let alpha = f64::from(roughness * roughness);
    // E(cos θo) tabulated on 65 points, linearly interpolated.
    let table: Vec<f64> = (0..=64)
        .map(|i| common::bsdf_ref::ggx_albedo((i as f64 / 64.0).max(1e-3), alpha, 256))
        .collect();
    let albedo = |c: f64| {
        let x = c.clamp(0.0, 1.0) * 64.0;
        let i = (x.floor() as usize).min(63);
        table[i] + (table[i + 1] - table[i]) * (x - i as f64)
    };
    let mut scene = Scene::default();
    scene.add_mesh_instance(
        shapes::icosphere(0.5, 5),
        Material {
            name: "mirror metal".into(),
            base_color: [1.0; 4],
            metallic: 1.0,
            roughness,
            specular: 1.0,
            ..Material::default()
        },
        Mat4::IDENTITY,
    );
    let size = 48;
    let out = common::render(&scene, &[common::constant_light(1.0)], size, 64, 5);
    let expected = common::over_sphere_pixels(size, 0.5, albedo);
    let (mut got, mut want, mut n) = (0.0f64, 0.0f64, 0usize);
    for ((p, m), e) in out.lit[0].iter().zip(&out.mask).zip(&expected) {
        for c in p {
            assert!(
                *c <= 1.0 + 0.15,
                "pixel {c}: a metal in a furnace of 1 gains energy"
            );
        }
        if let (Some(e), true) = (e, *m > 0.999) {
            got += f64::from(p[0] + p[1] + p[2]) / 3.0;
            want += e;
            n += 1;
        }
    }
    assert!(n > 500, "the sphere covers {n} pixels");
    let (got, want) = (got / n as f64, want / n as f64);
    println!("GGX r={roughness} furnace sphere: rendered {got:.4}, tabulated {want:.4}");
    assert!(
        want < 0.97,
        "the test needs a lossy lobe: tabulated mean {want}"
    );
    assert!(
        (got - want).abs() < 0.01,
        "rendered mean {got} vs the tabulated GGX albedo {want}"
    );
}

/// Furnace with clear glass: nothing absorbs, so radiance is 1 everywhere inside the shell,
/// and a camera between the sphere and the shell sees exactly 1. The light reaching the sphere
/// through the glass is estimated twice — shadow rays through thin glass, and BSDF-sampled
/// paths refracted through it — and must be counted once (multiple importance sampling across
/// the refraction chain); counted twice, this reads ~1.04 and more.
#[test]
fn furnace_white_sphere_inside_clear_glass_is_one() {
    let camera =
        lightfarm_render::scene::Camera::look_at(Vec3::new(0.0, 0.0, 0.45), Vec3::ZERO, 20.0)
            .expect("camera");
    let out = common::render_deep(
        &common::white_sphere_in_a_glass_shell(),
        camera,
        24,
        64,
        6,
        Vec::new(),
    );
    assert!(
        out.mask.iter().all(|m| *m > 0.999),
        "the sphere fills the view"
    );
    let mean = out.lit[0]
        .iter()
        .map(|p| f64::from(p[0] + p[1] + p[2]) / 3.0)
        .sum::<f64>()
        / out.lit[0].len() as f64;
    println!("white sphere inside a glass shell, seen from inside: {mean:.4}");
    assert!(
        (mean - 1.0).abs() < 0.005,
        "furnace inside glass: {mean} is not 1"
    );
}

/// The same scene from outside: each pixel is the sphere's radiance 1 times the probability
/// that the camera ray gets through the shell, T = (1 − F₁)(1 − F₂) / (1 − F₁F₂) (Fresnel at
/// the outer and inner wall, the internal reflections between them summed); the rest of the
/// camera rays reflect off the glass into the environment, which the sample contract records
/// as background (0). The impact parameter b of a ray about the centre is kept through every
/// refraction of concentric spheres, so sin θ = b / R at each wall of radius R (in air).
/// Radiance leaving glass must have been scaled by 1/η² going in and η² coming out.
#[test]
fn furnace_white_sphere_seen_through_clear_glass() {
    use common::bsdf_ref::fresnel_dielectric;
    let size = 48;
    // A camera ray gets through or not (σ ≈ 0.27 per sample): 256 spp over ~190 px puts the
    // mean's noise near 0.001.
    let out = common::render_deep(
        &common::white_sphere_in_a_glass_shell(),
        common::front_camera(),
        size,
        256,
        6,
        Vec::new(),
    );
    // Per pixel, the mean of T over sub-pixel rays, from their impact parameter: a ray
    // meeting a sphere of radius ρ at cosine c passes the centre at b = ρ·√(1 − c²). Pixels
    // with a ray passing near the white sphere's silhouette (b > 0.28) are left out.
    const KEEP: f64 = 0.28;
    let transmission = common::over_sphere_pixels(size, KEEP as f32, |c| {
        let impact = KEEP * (1.0 - c * c).max(0.0).sqrt();
        let wall = |radius: f64| {
            let s = impact / radius;
            fresnel_dielectric((1.0 - s * s).sqrt(), 1.5)
        };
        let (f1, f2) = (wall(0.5), wall(0.49));
        (1.0 - f1) * (1.0 - f2) / (1.0 - f1 * f2)
    });
    let (mut got, mut want, mut n) = (0.0f64, 0.0f64, 0usize);
    for (i, t) in transmission.iter().enumerate() {
        if let Some(t) = t {
            assert!(
                out.mask[i] > 0.999 && out.albedo[i][0] > 0.999,
                "pixel {i} sees the sphere"
            );
            got += f64::from(out.lit[0][i][0] + out.lit[0][i][1] + out.lit[0][i][2]) / 3.0;
            want += t;
            n += 1;
        }
    }
    assert!(n > 150, "the sphere covers {n} pixels");
    let (got, want) = (got / n as f64, want / n as f64);
    println!(
        "white sphere through a glass shell: rendered {got:.4}, analytic {want:.4} over {n} px"
    );
    assert!(
        (got - want).abs() < 0.006,
        "through glass: rendered {got} vs analytic {want}"
    );
}
