//! Known-answer renders (pbrt-v4 integrators_test style) on the device: the white furnace,
//! environment orientation, the passes' geometry and determinism.

mod common;

use glam::{Mat4, Vec3};
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::scene::{shapes, Material};
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
    assert!(
        plain.normal_lens.iter().all(|n| *n == [0.0; 3]),
        "no lens, no lens normals"
    );
    assert!(plain
        .albedo
        .iter()
        .zip(&plain.mask)
        .all(|(a, m)| *m == 0.0 || (a[0] - 0.5).abs() < 1e-4));

    // A clear lens in front of the left half: only normal_lens sees it.
    let mut scene = common::sphere_scene(0.5);
    let lens = Material {
        name: "lens".into(),
        transmission: 1.0,
        ior: 1.5,
        roughness: 0.0,
        metallic: 0.0,
        ..Material::default()
    };
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
        if nl != [0.0; 3] {
            lens_pixels += 1;
            assert!(x < size as f32 / 2.0, "lens normals only on the left");
            assert!(nl[2] > 0.99, "the lens faces the camera: {nl:?}");
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

/// glTF alpha: a mostly transparent veil (opacity 0.1, like MakeHuman's corneas) in front of the
/// sphere is invisible to the passes and dims the image by about its opacity; an opaque one hides
/// the sphere.
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
            shapes::quad(3.0, 3.0),
            m,
            Mat4::from_translation(Vec3::new(0.0, 0.0, 1.0)),
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
    let (a, b) = (plain.lit[0][centre][0], thin.lit[0][centre][0]);
    // 10% of camera rays stop at the veil, which (diffuse 0.9, lit by 1 from the front and the
    // sphere behind) is bright too: the pixel stays within a few tenths of the plain value.
    assert!((b - a).abs() < 0.15, "veiled {b} vs plain {a}");
    let opaque = veiled(1.0);
    assert!(
        (opaque.albedo[centre][0] - 0.9).abs() < 1e-4,
        "an opaque veil hides the sphere: {:?}",
        opaque.albedo[centre]
    );
}
