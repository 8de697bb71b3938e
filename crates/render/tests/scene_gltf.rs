//! glTF loading: real assets, malformed inputs, the .glb writer round trip and `--camera`.

use std::path::{Path, PathBuf};

use glam::{Mat4, Quat, Vec3};
use lightfarm_render::scene::{shapes, write_glb, Camera, Material, Scene, Texture};

/// A file of the built-in asset pack; a missing one fails the test.
fn asset(rel: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets")
        .join(rel);
    assert!(
        path.is_file(),
        "{} is missing from the checkout: these tests read only files committed to the repository",
        path.display()
    );
    path
}

fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lightfarm-scene-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("create temp dir");
    dir
}

fn check_consistent(scene: &Scene, what: &str) {
    assert!(!scene.meshes.is_empty(), "{what}: no meshes");
    assert!(!scene.instances.is_empty(), "{what}: no instances");
    assert!(scene.triangle_count() > 0, "{what}: no triangles");
    for inst in &scene.instances {
        assert!(
            (inst.mesh as usize) < scene.meshes.len(),
            "{what}: instance mesh out of range"
        );
        assert!(inst.transform.is_finite());
    }
    for m in &scene.meshes {
        let n = m.positions.len();
        assert_eq!(m.normals.len(), n, "{what}/{}", m.name);
        assert_eq!(m.uvs.len(), n);
        assert_eq!(m.tangents.len(), n);
        assert_eq!(m.indices.len() % 3, 0);
        assert_eq!(m.triangle_materials.len(), m.indices.len() / 3);
        assert!(
            m.indices.iter().all(|&i| (i as usize) < n),
            "{what}: index out of range"
        );
        assert!(m
            .triangle_materials
            .iter()
            .all(|&t| (t as usize) < scene.materials.len()));
        for nrm in &m.normals {
            let l = Vec3::from(*nrm).length();
            assert!(
                (l - 1.0).abs() < 1e-3,
                "{what}/{}: normal length {l}",
                m.name
            );
        }
    }
    for (i, t) in scene.textures.iter().enumerate() {
        assert!(t.width > 0 && t.height > 0, "{what}: texture {i} empty");
        assert_eq!(t.rgba8.len(), 4 * (t.width * t.height) as usize);
    }
    for mat in &scene.materials {
        for tex in [
            mat.base_color_texture,
            mat.metallic_roughness_texture,
            mat.normal_texture,
        ] {
            assert!(tex.is_none_or(|t| (t as usize) < scene.textures.len()));
        }
    }
}

#[test]
fn loads_lee_perry_smith_head() {
    let scene = Scene::load_gltf(&asset("heads/LeePerrySmith_textured.glb")).expect("head loads");
    check_consistent(&scene, "head");
    assert!(
        !scene.textures.is_empty(),
        "textured head decoded no textures"
    );
    // The scan's three maps: colour, the tangent-space normal map and the specular map
    // (KHR_materials_specular, A channel; scripts/derive_lee_perry_smith.py).
    let skin = &scene.materials[0];
    assert_eq!(skin.name, "LeePerrySmith_skin");
    let (Some(colour), Some(normal), Some(spec)) = (
        skin.base_color_texture,
        skin.normal_texture,
        skin.specular_texture,
    ) else {
        panic!("the skin has all three maps: {skin:?}");
    };
    assert_eq!(scene.textures.len(), 3);
    assert!(colour != normal && normal != spec && colour != spec);
    let spec = &scene.textures[spec as usize];
    assert_eq!((spec.width, spec.height), (1024, 1024));
    let alpha: Vec<u8> = spec.rgba8.chunks_exact(4).map(|p| p[3]).collect();
    let mean = alpha.iter().map(|&a| f64::from(a)).sum::<f64>() / alpha.len() as f64 / 255.0;
    assert!(
        (0.2..0.3).contains(&mean) && alpha.iter().any(|&a| a > 200) && alpha.contains(&0),
        "the specular map varies over the face (mean {mean:.3})"
    );
    let normal = &scene.textures[normal as usize];
    let blue = normal
        .rgba8
        .chunks_exact(4)
        .map(|p| f64::from(p[2]))
        .sum::<f64>()
        / (normal.rgba8.len() / 4) as f64;
    assert!(
        blue > 200.0,
        "a tangent-space normal map is mostly +Z: mean blue {blue}"
    );
    let (lo, hi) = scene.world_bounds().expect("bounds");
    assert!((hi - lo).max_element() > 0.0);
    println!(
        "head: {} meshes, {} triangles, {} textures, bounds {lo} .. {hi}",
        scene.meshes.len(),
        scene.triangle_count(),
        scene.textures.len()
    );
}

#[test]
fn loads_sunglasses_with_transmissive_lenses() {
    let scene =
        Scene::load_gltf(&asset("accessories/SunglassesKhronos.glb")).expect("sunglasses load");
    check_consistent(&scene, "sunglasses");
    for m in &scene.materials {
        println!(
            "sunglasses material '{}': transmission {} ior {} specular {} base {:?}",
            m.name, m.transmission, m.ior, m.specular, m.base_color
        );
    }
    assert!(
        scene.materials.iter().any(|m| m.transmission > 0.0),
        "no transmissive material in the sunglasses"
    );
}

fn assert_err_names(path: &Path) {
    let err = Scene::load_gltf(path).expect_err("malformed input must fail");
    let msg = err.to_string();
    println!("{}: {msg}", path.display());
    assert!(
        msg.contains(&path.display().to_string()),
        "error does not name the file: {msg}"
    );
}

#[test]
fn malformed_files_are_errors_naming_the_path() {
    let dir = scratch_dir("bad");
    let empty = dir.join("empty.glb");
    std::fs::write(&empty, b"").unwrap();
    assert_err_names(&empty);

    let random = dir.join("random.glb");
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    std::fs::write(&random, &bytes).unwrap();
    assert_err_names(&random);

    assert_err_names(&dir.join("does_not_exist.glb"));

    // A truncated copy of a real file.
    let source = std::fs::read(asset("accessories/SunglassesKhronos.glb")).expect("read asset");
    let truncated = dir.join("truncated.glb");
    std::fs::write(&truncated, &source[..100]).unwrap();
    assert_err_names(&truncated);

    // Three vertices, one triangle; the JSON is altered per case.
    let bin: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .chain([0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()))
        .collect();
    std::fs::write(dir.join("tri.bin"), &bin).unwrap();
    let gltf_json = |index2: u32, pos_count: u32| {
        let mut idx_bin = bin.clone();
        idx_bin[44..48].copy_from_slice(&index2.to_le_bytes());
        std::fs::write(dir.join(format!("tri{index2}.bin")), &idx_bin).unwrap();
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
            "accessors":[
              {{"bufferView":0,"componentType":5126,"count":{pos_count},"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
              {{"bufferView":1,"componentType":5125,"count":3,"type":"SCALAR"}}],
            "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":12}}],
            "buffers":[{{"byteLength":48,"uri":"tri{index2}.bin"}}]}}"#
        )
    };
    let good = dir.join("good.gltf");
    std::fs::write(&good, gltf_json(2, 3)).unwrap();
    let scene = Scene::load_gltf(&good).expect("the unaltered triangle loads");
    assert_eq!(scene.triangle_count(), 1);
    // No normals and no material in the file: computed normals, one appended default.
    assert_eq!(scene.meshes[0].normals[0], [0.0, 0.0, 1.0]);
    assert_eq!(scene.materials.len(), 1);

    let bad_index = dir.join("bad_index.gltf");
    std::fs::write(&bad_index, gltf_json(7, 3)).unwrap();
    assert_err_names(&bad_index);

    let bad_accessor = dir.join("bad_accessor.gltf");
    std::fs::write(&bad_accessor, gltf_json(2, 1000)).unwrap();
    assert_err_names(&bad_accessor);

    let zero_accessor = dir.join("zero_accessor.gltf");
    std::fs::write(&zero_accessor, gltf_json(2, 0)).unwrap();
    assert_err_names(&zero_accessor);

    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn write_glb_round_trip_preserves_geometry_materials_transforms() {
    let dir = scratch_dir("roundtrip");
    let path = dir.join("lens.glb");
    let mut scene = Scene::default();
    let skin = Material {
        name: "ball".into(),
        base_color: [0.8, 0.5, 0.4, 1.0],
        metallic: 0.0,
        roughness: 0.45,
        ..Material::default()
    };
    let lens = Material {
        name: "lens".into(),
        base_color: [1.0, 1.0, 1.0, 1.0],
        metallic: 0.0,
        roughness: 0.05,
        transmission: 0.9,
        ior: 1.6,
        specular: 0.7,
        specular_color: [0.9, 1.0, 0.8],
        double_sided: true,
        ..Material::default()
    };
    let ball_xf = Mat4::from_translation(Vec3::new(0.0, 0.1, 0.0));
    let lens_xf = Mat4::from_scale_rotation_translation(
        Vec3::new(1.0, 0.5, 1.0),
        Quat::from_rotation_y(0.3),
        Vec3::new(0.0, 0.1, 0.3),
    );
    scene.add_mesh_instance(shapes::icosphere(0.1, 3), skin.clone(), ball_xf);
    scene.add_mesh_instance(shapes::quad(0.2, 0.1), lens.clone(), lens_xf);
    scene
        .cameras
        .push(Camera::parse_cli("0,0.1,1.2:0,0.1,0:30").unwrap());
    write_glb(&scene, &path).expect("write glb");

    let back = Scene::load_gltf(&path).expect("load written glb");
    check_consistent(&back, "round trip");
    assert_eq!(back.triangle_count(), scene.triangle_count());
    assert_eq!(back.instances.len(), 2);
    for (a, b) in scene.instances.iter().zip(&back.instances) {
        assert!(
            a.transform.abs_diff_eq(b.transform, 1e-6),
            "{} vs {}",
            a.transform,
            b.transform
        );
        let (ma, mb) = (
            &scene.meshes[a.mesh as usize],
            &back.meshes[b.mesh as usize],
        );
        assert_eq!(ma.positions, mb.positions);
        assert_eq!(ma.indices, mb.indices);
    }
    let find = |name: &str| back.materials.iter().find(|m| m.name == name).expect(name);
    let (l, s) = (find("lens"), find("ball"));
    assert_eq!(l.transmission, 0.9);
    assert_eq!(l.ior, 1.6);
    assert_eq!(l.specular, 0.7);
    assert_eq!(l.specular_color, [0.9, 1.0, 0.8]);
    assert!(l.double_sided);
    assert_eq!((l.metallic, l.roughness), (0.0, 0.05));
    assert_eq!(s.base_color, skin.base_color);
    assert_eq!((s.transmission, s.ior, s.specular), (0.0, 1.5, 1.0));
    assert_eq!(back.cameras.len(), 1);
    let (c0, c1) = (scene.cameras[0], back.cameras[0]);
    assert!(c0.position.abs_diff_eq(c1.position, 1e-5));
    assert!(c0.forward.abs_diff_eq(c1.forward, 1e-5));
    assert!(c0.up.abs_diff_eq(c1.up, 1e-5));
    assert!((c0.yfov_deg - c1.yfov_deg).abs() < 1e-4);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Textures go into the file as PNGs and come back byte for byte, each still named by the
/// material slot that used it; a material naming a texture the scene lacks is an error.
#[test]
fn write_glb_round_trip_preserves_textures() {
    let dir = scratch_dir("textures");
    let path = dir.join("textured.glb");
    let mut scene = Scene::default();
    // Distinct, non-constant bytes per texture (and alpha not all 255) so a swap or a colour
    // conversion would show.
    let texture = |w: u32, h: u32, seed: u32| Texture {
        width: w,
        height: h,
        rgba8: (0..w * h * 4)
            .map(|i| (i.wrapping_mul(2_654_435_761).wrapping_add(seed) >> 7) as u8)
            .collect(),
    };
    scene.textures = vec![
        texture(8, 4, 1),
        texture(4, 4, 2),
        texture(2, 6, 3),
        texture(5, 3, 4),
    ];
    let skin = Material {
        name: "skin".into(),
        base_color_texture: Some(2),
        metallic_roughness_texture: Some(0),
        normal_texture: Some(3),
        normal_scale: 0.5,
        specular_texture: Some(1),
        ..Material::default()
    };
    scene.add_mesh_instance(shapes::icosphere(0.1, 2), skin, Mat4::IDENTITY);
    write_glb(&scene, &path).expect("write glb");
    let back = Scene::load_gltf(&path).expect("load written glb");
    check_consistent(&back, "textured round trip");
    let m = back
        .materials
        .iter()
        .find(|m| m.name == "skin")
        .expect("skin");
    let bytes = |t: Option<u32>| &back.textures[t.expect("a texture") as usize];
    for (got, want) in [
        (bytes(m.base_color_texture), &scene.textures[2]),
        (bytes(m.metallic_roughness_texture), &scene.textures[0]),
        (bytes(m.normal_texture), &scene.textures[3]),
        (bytes(m.specular_texture), &scene.textures[1]),
    ] {
        assert_eq!((got.width, got.height), (want.width, want.height));
        assert!(got.rgba8 == want.rgba8, "texture bytes changed");
    }
    assert_eq!(m.normal_scale, 0.5);

    scene.materials[0].normal_texture = Some(9);
    let e = write_glb(&scene, &dir.join("bad.glb"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("'skin' names texture 9"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn camera_cli_parsing() {
    let c = Camera::parse_cli("0,0.1,1.2:0,0.1,0:30").expect("valid camera");
    assert!(c.position.abs_diff_eq(Vec3::new(0.0, 0.1, 1.2), 1e-6));
    assert!(c.forward.abs_diff_eq(-Vec3::Z, 1e-6));
    assert!(c.up.abs_diff_eq(Vec3::Y, 1e-6));
    assert_eq!(c.yfov_deg, 30.0);
    // Looking straight down falls back to +Z for up.
    let down = Camera::parse_cli(" 0,2,0 : 0,0,0 : 45 ").expect("looking down");
    assert!(down.up.abs_diff_eq(Vec3::Z, 1e-6) || down.up.abs_diff_eq(-Vec3::Z, 1e-6));
    assert!(down.up.dot(down.forward).abs() < 1e-6);
    for bad in [
        "1,2",
        "a,b,c:0,0,0:30",
        "0,0,1:0,0,0:0",
        "0,0,1:0,0,0:200",
        "1,1,1:1,1,1:30",
        "",
        "0,0,1:0,0,0:x",
    ] {
        let err = Camera::parse_cli(bad).expect_err(bad).to_string();
        assert!(err.contains("--camera"), "{bad}: {err}");
        assert!(err.contains("px,py,pz:tx,ty,tz:fov_deg"), "{bad}: {err}");
    }
}

#[test]
fn frame_bounds_fits_the_narrower_dimension() {
    let (lo, hi) = (Vec3::splat(-0.1), Vec3::splat(0.1));
    let wide = Camera::frame_bounds(lo, hi, 2.0);
    let tall = Camera::frame_bounds(lo, hi, 0.5);
    assert!(wide.forward.abs_diff_eq(-Vec3::Z, 1e-6) && wide.yfov_deg == 30.0);
    assert!(
        tall.position.z > wide.position.z,
        "a narrow image must back the camera off"
    );
    let r = (hi - lo).length() * 0.5;
    let half = 15f32.to_radians();
    assert!((wide.position.z * half.sin() - r).abs() < 1e-5);
}

#[test]
fn shapes_are_closed_unit_normal_and_outward() {
    for mesh in [
        shapes::uv_sphere(0.5, 24, 12),
        shapes::icosphere(0.5, 2),
        shapes::quad(1.0, 2.0),
    ] {
        assert_eq!(mesh.triangle_materials.len(), mesh.indices.len() / 3);
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            assert!((Vec3::from(*n).length() - 1.0).abs() < 1e-5);
            if mesh.name != "quad" {
                assert!(
                    (Vec3::from(*p).length() - 0.5).abs() < 1e-5,
                    "{}: off sphere",
                    mesh.name
                );
            }
        }
        for t in mesh.indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|k| Vec3::from(mesh.positions[t[k] as usize]));
            let geo = (b - a).cross(c - a);
            assert!(geo.length() > 0.0, "{}: degenerate triangle", mesh.name);
            let n = Vec3::from(mesh.normals[t[0] as usize]);
            assert!(geo.dot(n) > 0.0, "{}: inward-wound triangle", mesh.name);
        }
        for (t, n) in mesh.tangents.iter().zip(&mesh.normals) {
            let tv = Vec3::new(t[0], t[1], t[2]);
            assert!((tv.length() - 1.0).abs() < 1e-4 && tv.dot(Vec3::from(*n)).abs() < 1e-4);
            assert!(t[3] == 1.0 || t[3] == -1.0);
        }
    }
    assert_eq!(shapes::icosphere(1.0, 2).triangle_count(), 320);
}
