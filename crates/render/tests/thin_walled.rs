//! Thin-walled clear sheets (`thin_walled`, the `cornea` model): one surface that reflects
//! 2R/(1 + R) of the light (R: Fresnel of one interface; the two faces and the light between
//! them summed) and passes the rest straight through, seen through by every pass but `lit`.

mod common;

use glam::{Mat4, Vec3};
use lightfarm_render::passes::Pass;
use lightfarm_render::scene::{shapes, Camera, Material, MaterialModel, ObjectClass, Scene};
use lightfarm_render::RenderOutput;

const CORNEA_IOR: f64 = 1.376;

fn cornea() -> Material {
    let mut m = Material {
        name: "cornea".into(),
        ..Material::default()
    };
    m.apply_model(MaterialModel::Cornea);
    m
}

/// A diffuse sphere of radius 0.3 (albedo `inner`) inside a thin clear shell of radius 0.5,
/// or without the shell.
fn scene(inner: f32, shell: bool) -> Scene {
    let mut scene = Scene::default();
    let mut m = common::material(inner, 0.0);
    m.class = ObjectClass::Skin;
    scene.add_mesh_instance(shapes::icosphere(0.3, 5), m, Mat4::IDENTITY);
    if shell {
        scene.add_mesh_instance(shapes::icosphere(0.5, 5), cornea(), Mat4::IDENTITY);
    }
    scene
}

fn render(scene: &Scene, camera: Camera, size: u32, spp: u32, passes: Vec<Pass>) -> RenderOutput {
    common::render_deep(scene, camera, size, spp, 11, passes)
}

fn grey(p: [f32; 3]) -> f64 {
    f64::from(p[0] + p[1] + p[2]) / 3.0
}

/// Furnace with a white sphere inside a thin clear shell, seen from inside the shell: nothing
/// absorbs, so every pixel is 1. Light through the sheet is found both by shadow rays (its
/// transmittance 1 − 2R/(1+R)) and by BSDF-sampled paths passing straight through; counted
/// twice this would read ~1.05, and a shadow ray blocked by the sheet would read less than 1.
#[test]
fn furnace_white_sphere_inside_a_thin_shell_is_one() {
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 0.45), Vec3::ZERO, 20.0).expect("camera");
    let out = render(&scene(1.0, true), camera, 24, 64, Vec::new());
    assert!(
        out.mask.iter().all(|m| *m > 0.999),
        "the sphere fills the view"
    );
    let mean = out.lit[0].iter().copied().map(grey).sum::<f64>() / out.lit[0].len() as f64;
    println!("white sphere inside a thin shell, seen from inside: {mean:.4}");
    assert!(
        (mean - 1.0).abs() < 0.005,
        "furnace inside a thin sheet: {mean} is not 1"
    );
}

/// A black sphere behind the sheet: a camera ray either reflects off the sheet into the
/// environment of 1 (probability 2R/(1+R) at the sheet's angle of incidence) or passes
/// straight through onto the black sphere. A solid dielectric boundary would reflect R alone
/// (about half as much) and bend the rays; the pixels over the black sphere are left with the
/// sheet's reflectance, averaged over each pixel's sub-pixel rays.
#[test]
fn black_sphere_behind_a_thin_shell_shows_the_sheet_reflectance() {
    use common::bsdf_ref::fresnel_dielectric;
    let size = 48;
    let out = render(
        &scene(0.0, true),
        common::front_camera(),
        size,
        256,
        Vec::new(),
    );
    // A ray meeting the inner sphere (radius ρ) at cosine c passes the centre at b = ρ·√(1 − c²)
    // and meets the shell of radius 0.5 at sin θ = b / 0.5, undeviated.
    const INNER: f64 = 0.3;
    let expected = common::over_sphere_pixels(size, INNER as f32, |c| {
        let s = INNER * (1.0 - c * c).max(0.0).sqrt() / 0.5;
        let r = fresnel_dielectric((1.0 - s * s).sqrt(), CORNEA_IOR);
        2.0 * r / (1.0 + r)
    });
    let (mut got, mut want, mut n) = (0.0f64, 0.0f64, 0usize);
    for (i, e) in expected.iter().enumerate() {
        if let Some(e) = e {
            got += grey(out.lit[0][i]);
            want += e;
            n += 1;
        }
    }
    assert!(n > 150, "the inner sphere covers {n} pixels");
    let (got, want) = (got / n as f64, want / n as f64);
    println!("thin sheet over a black sphere: rendered {got:.4}, analytic {want:.4} over {n} px");
    // Per sample a Bernoulli of p ≈ 0.05 (σ ≈ 0.22): over ~190 px × 256 spp the mean is good
    // to ~0.001; a single interface (R ≈ 0.025) is 10σ away.
    assert!(
        (got - want).abs() < 0.004,
        "thin sheet reflectance: rendered {got} vs analytic {want}"
    );
}

/// The passes look through the sheet: mask, albedo, normal and id are those of the sphere
/// behind it (as without the sheet), and a sheet is no lens, so `normal_lens` is the normal.
#[test]
fn passes_see_through_a_thin_sheet() {
    let size = 24;
    let passes = vec![Pass::Id];
    let plain = render(
        &scene(0.5, false),
        common::front_camera(),
        size,
        4,
        passes.clone(),
    );
    let sheet = render(&scene(0.5, true), common::front_camera(), size, 4, passes);
    assert_eq!(
        sheet.mask, plain.mask,
        "the sheet does not count in the mask"
    );
    assert_eq!(
        sheet.id, plain.id,
        "the id is the sphere's behind the sheet"
    );
    assert!(
        sheet.id.contains(&(ObjectClass::Skin as u32 + 1)),
        "the sphere's class shows"
    );
    for (p, (a, b)) in sheet.albedo.iter().zip(&plain.albedo).enumerate() {
        assert!(
            (0..3).all(|k| (a[k] - b[k]).abs() < 1e-6),
            "pixel {p}: albedo {a:?} through the sheet, {b:?} without"
        );
    }
    for (p, (a, b)) in sheet.normal.iter().zip(&plain.normal).enumerate() {
        assert!(
            (0..3).all(|k| (a[k] - b[k]).abs() < 1e-5),
            "pixel {p}: normal {a:?} through the sheet, {b:?} without"
        );
    }
    assert_eq!(
        sheet.normal_lens, sheet.normal,
        "no lens: normal_lens is the normal"
    );
}
