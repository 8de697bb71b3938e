//! What `output::write_exr` writes decodes, channel by channel and bit for bit, to the passes
//! that were rendered: the file is read back by channel name with the exr crate (not through
//! the writer's own channel list), on a non-square image whose lightings, albedo and normals
//! all differ per channel, so a swapped, transposed or rounded channel fails.

mod common;

use std::collections::HashMap;

use glam::{Mat4, Vec3};
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::output::{write_exr, write_preview_png};
use lightfarm_render::scene::shapes;
use lightfarm_render::{EnvLight, RenderOutput};

/// Every channel of the first layer of an EXR file, by name, plus its string attributes.
fn read_channels(
    path: &std::path::Path,
) -> (
    usize,
    usize,
    HashMap<String, Vec<f32>>,
    HashMap<String, String>,
) {
    let img = exr::prelude::read_all_flat_layers_from_file(path).expect("read the EXR back");
    let layer = &img.layer_data[0];
    let channels = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    let attrs = layer
        .attributes
        .other
        .iter()
        .filter_map(|(k, v)| match v {
            exr::prelude::AttributeValue::Text(t) => Some((k.to_string(), t.to_string())),
            _ => None,
        })
        .collect();
    (layer.size.0, layer.size.1, channels, attrs)
}

/// Asserts that `channels[name]` holds exactly `values` (bit patterns, not approximately).
fn same_bits(channels: &HashMap<String, Vec<f32>>, name: &str, values: impl Iterator<Item = f32>) {
    let got = channels
        .get(name)
        .unwrap_or_else(|| panic!("channel {name} missing from {:?}", channels.keys()));
    let want: Vec<f32> = values.collect();
    assert_eq!(got.len(), want.len(), "{name}: length");
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!(
            g.to_bits(),
            w.to_bits(),
            "{name}[{i}]: file {g} vs rendered {w}"
        );
    }
}

/// Checks a decoded file against the passes that were written, every channel by its name.
fn assert_file_holds(out: &RenderOutput, channels: &HashMap<String, Vec<f32>>) {
    let rgb = |v: &[[f32; 3]], k: usize| v.iter().map(move |p| p[k]).collect::<Vec<_>>();
    for (l, lit) in out.lit.iter().enumerate() {
        for (k, c) in ["R", "G", "B"].iter().enumerate() {
            same_bits(channels, &format!("lit{l}.{c}"), rgb(lit, k).into_iter());
        }
    }
    for (k, c) in ["R", "G", "B"].iter().enumerate() {
        same_bits(
            channels,
            &format!("albedo.{c}"),
            rgb(&out.albedo, k).into_iter(),
        );
    }
    for (k, c) in ["X", "Y", "Z"].iter().enumerate() {
        same_bits(
            channels,
            &format!("normal.{c}"),
            rgb(&out.normal, k).into_iter(),
        );
        same_bits(
            channels,
            &format!("normal_lens.{c}"),
            rgb(&out.normal_lens, k).into_iter(),
        );
    }
    same_bits(channels, "mask.A", out.mask.iter().copied());
    let expected = 3 * out.lit.len() + 3 + 6 + 1;
    assert_eq!(channels.len(), expected, "channels: {:?}", channels.keys());
}

fn coloured_light(value: [f32; 3], hot: (u32, u32)) -> EnvLight {
    let (w, h) = (32u32, 16u32);
    let mut texels = vec![value; (w * h) as usize];
    texels[(hot.1 * w + hot.0) as usize] = [400.0, 100.0, 20.0];
    EnvLight {
        name: "coloured".into(),
        hdri: Hdri::from_texels(w, h, texels).expect("hdri"),
        transform: EnvTransform::default(),
    }
}

#[test]
fn the_exr_holds_exactly_the_rendered_passes() {
    let mut scene = lightfarm_render::scene::Scene::default();
    let mut red = common::material(0.5, 0.5);
    red.base_color = [0.8, 0.3, 0.1, 1.0];
    scene.add_mesh_instance(shapes::icosphere(0.5, 3), red, Mat4::IDENTITY);
    let lens = common::clear_glass("lens");
    // Tilted, so normal_lens has three different non-zero components.
    scene.add_mesh_instance(
        shapes::quad(0.5, 0.5),
        lens,
        Mat4::from_translation(Vec3::new(-0.3, 0.1, 1.0))
            * Mat4::from_rotation_y(0.4)
            * Mat4::from_rotation_x(0.3),
    );
    let lights = [
        coloured_light([0.2, 0.5, 1.0], (8, 5)),
        coloured_light([1.0, 0.6, 0.1], (24, 9)),
    ];
    let packed = lightfarm_render::gpu_scene::pack_scene(&scene).expect("pack");
    let settings = lightfarm_render::RenderSettings {
        width: 20,
        height: 12,
        spp: 4,
        seed: 3,
        max_depth: 8,
        rr_depth: 5,
        camera: common::front_camera(),
        passes: Vec::new(),
    };
    let out = common::renderer()
        .render(&packed, &lights, &settings, &mut |_| {})
        .expect("render");
    // The comparison means something only if the passes are not trivial.
    assert_ne!(out.lit[0], out.lit[1], "two lightings, two images");
    assert!(out.mask.iter().any(|m| *m > 0.0) && out.mask.contains(&0.0));
    assert!(
        out.normal_lens.iter().any(|n| n.iter().all(|c| *c != 0.0)),
        "lens normals"
    );
    assert!(
        out.albedo.iter().any(|a| a[0] != a[1] && a[1] != a[2]),
        "coloured albedo"
    );

    let dir = tempfile_dir();
    let path = dir.join("passes.exr");
    let attrs = [("lightfarm.test".to_string(), "{\"k\": 1}".to_string())];
    write_exr(&path, &out, &attrs).expect("write");
    let (w, h, channels, text) = read_channels(&path);
    assert_eq!((w, h), (20, 12), "width × height");
    assert_file_holds(&out, &channels);
    assert_eq!(
        text.get("lightfarm.test").map(String::as_str),
        Some("{\"k\": 1}")
    );

    // The preview is lit0, black off the subject.
    let png = dir.join("preview.png");
    write_preview_png(&png, &out, 0).expect("preview");
    let img = image::open(&png).expect("png").to_rgb8();
    assert_eq!(img.dimensions(), (20, 12));
    for (i, m) in out.mask.iter().enumerate() {
        let px = img.get_pixel(i as u32 % 20, i as u32 / 20).0;
        if *m == 0.0 {
            assert_eq!(px, [0, 0, 0], "background pixel {i} of the preview");
        }
    }
    assert!(
        img.pixels().any(|p| p.0 != [0, 0, 0]),
        "the preview shows the subject"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

fn tempfile_dir() -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("lightfarm-output-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}
