//! The appendix passes (crates/render/src/passes.rs, shaders/kernels/integrator.wgsl): the five
//! lobe families sum to lit, shadow is 1 where nothing occludes and below 1 in a cast shadow,
//! id names each pixel's object class, and the EXR carries them with the id table.

// Pixel loops read several parallel passes by index.
#![allow(clippy::needless_range_loop)]

mod common;

use std::path::Path;

use glam::{Mat4, Vec3};
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::output::{id_table_json, pass_channel_names, write_exr};
use lightfarm_render::passes::Pass;
use lightfarm_render::scene::{shapes, Camera, Material, MaterialModel, ObjectClass, Scene};
use lightfarm_render::{EnvLight, RenderOutput, RenderSettings};

fn render(scene: &Scene, lights: &[EnvLight], camera: Camera, size: u32, spp: u32) -> RenderOutput {
    let packed = pack_scene(scene).expect("pack scene");
    let settings = RenderSettings {
        width: size,
        height: size,
        spp,
        seed: 5,
        max_depth: 8,
        rr_depth: 5,
        camera,
        passes: Pass::ALL.to_vec(),
    };
    common::renderer()
        .render(&packed, lights, &settings, &mut |_| {})
        .expect("render")
}

fn real_map() -> EnvLight {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/hdri/rooitou_park_1k.hdr");
    EnvLight {
        name: "rooitou".into(),
        hdri: Hdri::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        transform: EnvTransform::default(),
    }
}

/// A sun: one hot texel straight above (v small = up).
fn sun_above() -> EnvLight {
    let (w, h) = (64u32, 32u32);
    let mut texels = vec![[0.05f32; 3]; (w * h) as usize];
    texels[(w / 2) as usize] = [5000.0; 3];
    EnvLight {
        name: "sun".into(),
        hdri: Hdri::from_texels(w, h, texels).expect("hdri"),
        transform: EnvTransform::default(),
    }
}

fn skin() -> Material {
    let mut m = Material {
        name: "skin".into(),
        base_color: [0.7, 0.45, 0.35, 1.0],
        ..Material::default()
    };
    m.apply_model(MaterialModel::Skin);
    m.subsurface_scale = 0.02;
    m
}

fn plastic() -> Material {
    Material {
        name: "plastic".into(),
        base_color: [0.2, 0.4, 0.8, 1.0],
        metallic: 0.0,
        roughness: 0.3,
        class: ObjectClass::Garment,
        ..Material::default()
    }
}

/// A skin sphere (every family), a glTF plastic sphere (diffuse + specular only) and a lens in
/// front of part of both, under a real sky.
fn mixed_scene() -> Scene {
    let mut scene = Scene::default();
    scene.add_mesh_instance(
        shapes::icosphere(0.3, 4),
        skin(),
        Mat4::from_translation(Vec3::new(-0.35, 0.0, 0.0)),
    );
    scene.add_mesh_instance(
        shapes::icosphere(0.3, 4),
        plastic(),
        Mat4::from_translation(Vec3::new(0.35, 0.0, 0.0)),
    );
    let mut lens = common::clear_glass("lens");
    lens.class = ObjectClass::Lens;
    scene.add_mesh_instance(
        shapes::quad(0.4, 0.4),
        lens,
        Mat4::from_translation(Vec3::new(0.0, 0.2, 0.8)),
    );
    scene
}

#[test]
fn lobe_families_sum_to_lit() {
    let out = render(
        &mixed_scene(),
        &[real_map(), sun_above()],
        common::front_camera(),
        40,
        32,
    );
    assert_eq!(out.passes.len(), 2, "one set of passes per lighting");
    let size = 40usize;
    for (k, lp) in out.passes.iter().enumerate() {
        let mut family_energy = [0.0f64; 5];
        let mut skin_energy = [0.0f64; 5];
        for p in 0..size * size {
            let parts = [
                lp.diffuse[p],
                lp.specular[p],
                lp.sss[p],
                lp.coat[p],
                lp.sheen[p],
            ];
            for c in 0..3 {
                let sum: f32 = parts.iter().map(|x| x[c]).sum();
                let lit = out.lit[k][p][c];
                assert!(
                    (sum - lit).abs() <= 1e-4 * lit.abs() + 1e-6,
                    "lighting {k} pixel {p} channel {c}: passes sum to {sum}, lit {lit}"
                );
                for (f, x) in parts.iter().enumerate() {
                    assert!(x[c] >= 0.0, "lighting {k} pixel {p}: family {f} negative");
                    family_energy[f] += f64::from(x[c]);
                    if out.id[p] == ObjectClass::Skin as u32 + 1 {
                        skin_energy[f] += f64::from(x[c]);
                    }
                }
            }
            // The plastic (right half, no lens) has no subsurface, coat or sheen.
            if p % size > size * 3 / 4 && out.id[p] == ObjectClass::Garment as u32 + 1 {
                assert_eq!(
                    lp.sss[p], [0.0; 3],
                    "plastic pixel {p} has subsurface light"
                );
                assert_eq!(lp.coat[p], [0.0; 3], "plastic pixel {p} has coat light");
            }
        }
        for (f, e) in family_energy.iter().enumerate() {
            assert!(*e > 0.0, "lighting {k}: family {f} is empty over the image");
        }
        // Skin light is mostly subsurface (its subsurface weight is 0.95).
        assert!(
            skin_energy[2] > 5.0 * skin_energy[0],
            "lighting {k}: skin families {skin_energy:?}"
        );
    }
}

#[test]
fn shadow_is_one_unoccluded_and_below_one_in_a_cast_shadow() {
    // A convex sphere cannot shadow itself.
    let mut scene = Scene::default();
    scene.add_mesh_instance(shapes::icosphere(0.4, 4), plastic(), Mat4::IDENTITY);
    let out = render(&scene, &[sun_above()], common::front_camera(), 32, 16);
    for (p, s) in out.passes[0].shadow.iter().enumerate() {
        if out.mask[p] > 0.0 {
            assert!(
                (*s - 1.0).abs() < 1e-6,
                "pixel {p}: shadow {s} on an unoccluded sphere"
            );
        }
    }
    // The same sphere above a floor, the sun overhead, seen from above and in front.
    let floor = Material {
        name: "floor".into(),
        base_color: [0.8, 0.8, 0.8, 1.0],
        metallic: 0.0,
        specular: 0.0,
        ..Material::default()
    };
    scene.add_mesh_instance(
        shapes::quad(4.0, 4.0),
        floor,
        Mat4::from_translation(Vec3::new(0.0, -0.6, 0.0))
            * Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_2),
    );
    let camera =
        Camera::look_at(Vec3::new(0.0, 2.5, 2.5), Vec3::new(0.0, -0.6, 0.0), 40.0).expect("camera");
    let size = 48usize;
    let out = render(&scene, &[sun_above()], camera, size as u32, 32);
    let shadow = &out.passes[0].shadow;
    let floor_id = ObjectClass::Other as u32 + 1;
    let (mut dark, mut lit) = (0, 0);
    for p in 0..size * size {
        if out.id[p] != floor_id || out.mask[p] < 1.0 {
            continue;
        }
        assert!(
            (0.0..=1.0).contains(&shadow[p]),
            "shadow {} out of range",
            shadow[p]
        );
        if shadow[p] < 0.2 {
            dark += 1;
        }
        if shadow[p] > 0.999 {
            lit += 1;
        }
    }
    assert!(dark > 20, "only {dark} floor pixels in the sphere's shadow");
    assert!(lit > 200, "only {lit} fully lit floor pixels");
}

#[test]
fn id_names_the_object_class_of_each_pixel() {
    let out = render(&mixed_scene(), &[real_map()], common::front_camera(), 40, 4);
    let size = 40usize;
    let at = |x: usize, y: usize| out.id[y * size + x];
    // Pixel centres well inside each sphere, below the lens; a corner is background.
    assert_eq!(at(12, 22), ObjectClass::Skin as u32 + 1, "skin sphere");
    assert_eq!(
        at(28, 22),
        ObjectClass::Garment as u32 + 1,
        "plastic sphere"
    );
    assert_eq!(at(0, 0), 0, "background");
    for p in 0..size * size {
        if out.mask[p] == 0.0 {
            assert_eq!(
                out.id[p], 0,
                "pixel {p} has no surface but id {}",
                out.id[p]
            );
        }
        // Lenses count in no pass but normal_lens: the id is the surface behind.
        assert_ne!(
            out.id[p],
            ObjectClass::Lens as u32 + 1,
            "pixel {p} reports the lens"
        );
    }
}

#[test]
fn exr_carries_the_passes_and_the_id_table() {
    let out = render(
        &mixed_scene(),
        &[real_map(), sun_above()],
        common::front_camera(),
        8,
        2,
    );
    let dir = std::env::temp_dir().join(format!("lightfarm-passes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("passes.exr");
    write_exr(
        &path,
        &out,
        &[("lightfarm.id_table".to_string(), id_table_json())],
    )
    .expect("write");
    let image = exr::prelude::read_all_flat_layers_from_file(&path).expect("read back");
    let layer = &image.layer_data[0];
    let names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for want in pass_channel_names(2, &Pass::ALL) {
        assert!(names.contains(&want), "{want} missing from {names:?}");
    }
    let table = layer
        .attributes
        .other
        .get(&exr::prelude::Text::from("lightfarm.id_table"))
        .expect("id table attribute");
    match table {
        exr::prelude::AttributeValue::Text(t) => {
            assert_eq!(t.to_string(), id_table_json());
            let v: serde_json::Value = serde_json::from_str(&t.to_string()).expect("json");
            assert_eq!(v["0"], "background");
            assert_eq!(v["2"], "skin");
        }
        other => panic!("id table is {other:?}"),
    }
    std::fs::remove_dir_all(&dir).ok();
}
