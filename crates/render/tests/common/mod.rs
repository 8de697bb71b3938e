//! Helpers shared by the render crate's device tests.
#![allow(dead_code)]

pub mod blocks;
pub mod bsdf_ref;
pub mod fibres;
pub mod gltf_files;
pub mod hair_ref;
pub mod sphere_chi2;

use std::sync::{Arc, OnceLock};

use glam::{Mat4, Vec3};
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::gpu_scene::{pack_scene, PackedScene};
use lightfarm_render::scene::{shapes, Camera, Material, Scene};
use lightfarm_render::vulkan::{DeviceRequest, GpuContext};
use lightfarm_render::{EnvLight, RenderOutput, RenderSettings, Renderer};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// One renderer per test binary: pipeline creation on lavapipe costs seconds.
pub fn renderer() -> &'static Renderer {
    static R: OnceLock<Renderer> = OnceLock::new();
    R.get_or_init(|| {
        Renderer::new(&DeviceRequest::Auto)
            .expect("a Vulkan device (install libvulkan1 mesa-vulkan-drivers)")
    })
}

pub fn ctx() -> Arc<GpuContext> {
    renderer().context().clone()
}

pub fn material(base: f32, specular: f32) -> Material {
    Material {
        name: "test".into(),
        base_color: [base, base, base, 1.0],
        metallic: 0.0,
        roughness: 0.5,
        specular,
        ..Material::default()
    }
}

/// Clear, smooth glass of index 1.5: what the renderer treats as a lens (transmission > 0.5).
pub fn clear_glass(name: &str) -> Material {
    Material {
        name: name.into(),
        transmission: 1.0,
        ior: 1.5,
        roughness: 0.0,
        metallic: 0.0,
        ..Material::default()
    }
}

/// A diffuse sphere of radius 0.5 at the origin, albedo `albedo`, no specular layer.
pub fn sphere_scene(albedo: f32) -> Scene {
    let mut scene = Scene::default();
    scene.add_mesh_instance(
        shapes::icosphere(0.5, 5),
        material(albedo, 0.0),
        Mat4::IDENTITY,
    );
    scene
}

pub fn front_camera() -> Camera {
    Camera::look_at(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 30.0).expect("valid camera")
}

/// Camera ray (world direction) through sub-pixel point (sx, sy) ∈ [-1, 1]² of `front_camera`.
pub fn front_ray(sx: f32, sy: f32) -> Vec3 {
    let tan_half = (15.0f32).to_radians().tan();
    Vec3::new(sx * tan_half, sy * tan_half, -1.0).normalize()
}

/// For each pixel, the mean of `f(cos θ)` over 8×8 sub-pixel rays that hit the analytic sphere
/// of `radius` at the origin (θ between the ray and the sphere's normal), or None where a
/// sub-pixel ray misses it.
pub fn over_sphere_pixels(size: u32, radius: f32, f: impl Fn(f64) -> f64) -> Vec<Option<f64>> {
    let eye = Vec3::new(0.0, 0.0, 3.0);
    let mut out = Vec::new();
    for py in 0..size {
        for px in 0..size {
            let mut sum = Some(0.0);
            for a in 0..8 {
                for b in 0..8 {
                    let sx = ((px as f32 + (a as f32 + 0.5) / 8.0) / size as f32) * 2.0 - 1.0;
                    let sy = 1.0 - ((py as f32 + (b as f32 + 0.5) / 8.0) / size as f32) * 2.0;
                    let d = front_ray(sx, sy);
                    let bq = eye.dot(d);
                    let disc = bq * bq - (eye.length_squared() - radius * radius);
                    if disc < 0.0 {
                        sum = None;
                        continue;
                    }
                    let hit = eye + d * (-bq - disc.sqrt());
                    let n = hit / radius;
                    sum = sum.map(|s| s + f(f64::from(n.dot(-d))) / 64.0);
                }
            }
            out.push(sum);
        }
    }
    out
}

pub fn constant_light(value: f32) -> EnvLight {
    EnvLight {
        name: "constant".into(),
        hdri: Hdri::constant(64, 32, [value; 3]),
        transform: EnvTransform::default(),
    }
}

pub fn render(scene: &Scene, lights: &[EnvLight], size: u32, spp: u32, seed: u32) -> RenderOutput {
    let packed: PackedScene = pack_scene(scene).expect("pack scene");
    let settings = RenderSettings {
        width: size,
        height: size,
        spp,
        seed,
        max_depth: 8,
        rr_depth: 5,
        camera: front_camera(),
        passes: Vec::new(),
    };
    renderer()
        .render(&packed, lights, &settings, &mut |_| {})
        .expect("render")
}

/// Renders in a furnace of 1 with paths long enough (16) that light shuttling between a
/// sphere and a shell around it is not cut off: at 8 scattering events ~3% of it is.
pub fn render_deep(
    scene: &Scene,
    camera: Camera,
    size: u32,
    spp: u32,
    seed: u32,
    passes: Vec<lightfarm_render::passes::Pass>,
) -> RenderOutput {
    try_render_deep(scene, camera, size, spp, seed, passes).expect("render")
}

/// `render_deep`, with the renderer's answer as it is.
pub fn try_render_deep(
    scene: &Scene,
    camera: Camera,
    size: u32,
    spp: u32,
    seed: u32,
    passes: Vec<lightfarm_render::passes::Pass>,
) -> Result<RenderOutput, lightfarm_render::RenderError> {
    let settings = RenderSettings {
        width: size,
        height: size,
        spp,
        seed,
        max_depth: 16,
        rr_depth: 16,
        camera,
        passes,
    };
    let packed = pack_scene(scene).expect("pack");
    renderer().render(&packed, &[constant_light(1.0)], &settings, &mut |_| {})
}

/// A white (albedo 1) Lambertian sphere of radius 0.3 inside a hollow glass shell (η = 1.5,
/// radii 0.49 and 0.5; the inner wall faces inwards, towards the air it bounds).
pub fn white_sphere_in_a_glass_shell() -> Scene {
    let mut scene = Scene::default();
    scene.add_mesh_instance(
        shapes::icosphere(0.3, 5),
        material(1.0, 0.0),
        Mat4::IDENTITY,
    );
    let glass = clear_glass("glass");
    scene.add_mesh_instance(shapes::icosphere(0.5, 5), glass.clone(), Mat4::IDENTITY);
    let mut inner = shapes::icosphere(0.49, 5);
    for t in inner.indices.chunks_exact_mut(3) {
        t.swap(1, 2);
    }
    for n in &mut inner.normals {
        *n = n.map(|c| -c);
    }
    scene.add_mesh_instance(inner, glass, Mat4::IDENTITY);
    scene
}

/// Pearson's chi-square goodness of fit as pbrt-v4 and Mitsuba 3 run it: cells with expected
/// count < 5 are pooled, a sample in a cell of zero expected count fails outright, and the
/// p-value is compared against 0.01 with a Šidák correction for `tests` tests.
pub fn chi2_test(
    name: &str,
    observed: &[f64],
    expected: &[f64],
    tests: u32,
) -> Result<f64, String> {
    assert_eq!(observed.len(), expected.len());
    let mut chi2 = 0.0;
    let mut dof = 0i64;
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    for (o, e) in observed.iter().zip(expected) {
        if *e == 0.0 {
            if *o > 0.0 {
                return Err(format!("{name}: {o} samples in a cell of zero probability"));
            }
            continue;
        }
        if *e < 5.0 {
            pool_o += o;
            pool_e += e;
        } else {
            chi2 += (o - e) * (o - e) / e;
            dof += 1;
        }
    }
    if pool_e > 0.0 {
        chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
        dof += 1;
    }
    dof -= 1;
    if dof < 1 {
        return Err(format!("{name}: too few cells for a chi-square test"));
    }
    let p = 1.0
        - ChiSquared::new(dof as f64)
            .map_err(|e| e.to_string())?
            .cdf(chi2);
    let alpha = 1.0 - (1.0f64 - 0.01).powf(1.0 / tests as f64);
    if p < alpha {
        return Err(format!(
            "{name}: chi2 = {chi2:.1} with {dof} dof, p = {p:.3e} < {alpha:.3e}"
        ));
    }
    Ok(p)
}

/// A skin sphere (the paper's preset) on a glossy floor, with a lens in front of part of it:
/// walks, bounces between skin and floor (walks after the first), refraction and shadows.
pub fn skin_floor_lens() -> Scene {
    let mut scene = Scene::default();
    let mut skin = Material {
        name: "skin".into(),
        base_color: [0.8, 0.5, 0.4, 1.0],
        ..Material::default()
    };
    skin.apply_model(lightfarm_render::scene::MaterialModel::Skin);
    scene.add_mesh_instance(shapes::icosphere(0.02, 4), skin, Mat4::IDENTITY);
    scene.add_mesh_instance(
        shapes::quad(0.2, 0.2),
        material(0.6, 0.5),
        Mat4::from_translation(Vec3::new(0.0, -0.02, 0.0))
            * Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_2),
    );
    scene.add_mesh_instance(
        shapes::icosphere(0.006, 3),
        clear_glass("lens"),
        Mat4::from_translation(Vec3::new(0.01, 0.005, 0.03)),
    );
    scene
}
