//! Textures reach the shading: base colour (sRGB-decoded, glTF uv orientation), and normal maps
//! through the tangent frame, read back from the albedo and normal passes.

mod common;

use glam::Mat4;
use lightfarm_render::scene::{shapes, Scene, Texture};

fn srgb_to_linear(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn textured_quad(base: Option<Texture>, normal: Option<Texture>) -> Scene {
    let mut scene = Scene::default();
    let mut material = common::material(1.0, 0.0);
    if let Some(t) = base {
        scene.textures.push(t);
        material.base_color_texture = Some(scene.textures.len() as u32 - 1);
    }
    if let Some(t) = normal {
        scene.textures.push(t);
        material.normal_texture = Some(scene.textures.len() as u32 - 1);
        material.normal_scale = 1.0;
    }
    scene.add_mesh_instance(shapes::quad(1.0, 1.0), material, Mat4::IDENTITY);
    scene
}

#[test]
fn base_color_texture_is_srgb_decoded_and_oriented() {
    // Quadrants of a 4x4 texture (2x2 texels each, so bilinear filtering inside a quadrant sees
    // one colour).
    let (texels, tex) = quadrant_texture();
    let size = 32u32;
    let out = common::render(
        &textured_quad(Some(tex), None),
        &[common::constant_light(1.0)],
        size,
        4,
        1,
    );
    // Quadrant centres of the quad (it spans ±0.62 in NDC): u, v = 0.25 / 0.75 land on texel centres.
    let px = |ndc: f32| ((ndc + 1.0) * 0.5 * size as f32) as u32;
    let at = |x: f32, y: f32| out.albedo[(px(-y) * size + px(x)) as usize];
    let expect = |t: [u8; 4]| {
        [
            srgb_to_linear(t[0]),
            srgb_to_linear(t[1]),
            srgb_to_linear(t[2]),
        ]
    };
    for ((x, y), texel) in [
        ((-0.31, 0.31), texels[0]),
        ((0.31, 0.31), texels[1]),
        ((-0.31, -0.31), texels[2]),
        ((0.31, -0.31), texels[3]),
    ] {
        let got = at(x, y);
        let want = expect(texel);
        for k in 0..3 {
            assert!(
                (got[k] - want[k]).abs() < 0.03,
                "albedo at ({x}, {y}) = {got:?}, texel {want:?}"
            );
        }
    }
}

/// The 4x4 texture of four 2x2-texel quadrants (top red, green; bottom blue, white).
fn quadrant_texture() -> ([[u8; 4]; 4], Texture) {
    let texels: [[u8; 4]; 4] = [
        [200, 30, 30, 255],
        [30, 200, 30, 255],
        [30, 30, 200, 255],
        [255, 255, 255, 255],
    ];
    let mut rgba8 = Vec::new();
    for y in 0..4 {
        for x in 0..4 {
            rgba8.extend_from_slice(&texels[(y / 2) * 2 + x / 2]);
        }
    }
    (
        texels,
        Texture {
            width: 4,
            height: 4,
            rgba8,
        },
    )
}

/// The glTF default sampler repeats: uvs over three tiles each way show the texture 3x3 times,
/// both just outside the unit square ([-1, 2]: one tile off each edge) and far from it
/// ([-7, -4] x [5, 8]), where the shader wraps texel coordinates by a different route.
#[test]
fn base_color_texture_repeats_outside_the_unit_square() {
    for origin in [[-1.0f32, -1.0], [-7.0, 5.0]] {
        let (texels, tex) = quadrant_texture();
        let mut scene = textured_quad(Some(tex), None);
        for uv in &mut scene.meshes[0].uvs {
            *uv = [origin[0] + 3.0 * uv[0], origin[1] + 3.0 * uv[1]];
        }
        let size = 64u32;
        let out = common::render(&scene, &[common::constant_light(1.0)], size, 4, 1);
        let px = |ndc: f32| ((ndc + 1.0) * 0.5 * size as f32) as u32;
        for tile in [[0u32, 0u32], [1, 1], [2, 0], [0, 2], [2, 2]] {
            for (q, texel) in texels.iter().enumerate() {
                let (qx, qy) = ((q % 2) as f32, (q / 2) as f32);
                // Quad uv (before the tiling) of the quadrant's centre, and its NDC.
                let u = (tile[0] as f32 + 0.25 + 0.5 * qx) / 3.0;
                let v = (tile[1] as f32 + 0.25 + 0.5 * qy) / 3.0;
                let (x, y) = (-0.62 + 1.24 * u, 0.62 - 1.24 * v);
                let got = out.albedo[(px(-y) * size + px(x)) as usize];
                for k in 0..3 {
                    let want = srgb_to_linear(texel[k]);
                    assert!(
                        (got[k] - want).abs() < 0.03,
                        "uv origin {origin:?}, tile {tile:?}, quadrant {q}: albedo {got:?}, \
                         texel {texel:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn normal_map_tilts_the_shading_normal_along_the_tangent() {
    // Tangent-space normal (0.6, 0, 0.8): tilted toward the tangent (+X on the quad).
    let enc = |v: f32| ((v * 0.5 + 0.5) * 255.0).round() as u8;
    let texel = [enc(0.6), enc(0.0), enc(0.8), 255];
    let tex = Texture {
        width: 1,
        height: 1,
        rgba8: texel.to_vec(),
    };
    let size = 16u32;
    let flat = common::render(
        &textured_quad(None, None),
        &[common::constant_light(1.0)],
        size,
        2,
        1,
    );
    let mapped = common::render(
        &textured_quad(None, Some(tex)),
        &[common::constant_light(1.0)],
        size,
        2,
        1,
    );
    let centre = ((size / 2) * size + size / 2) as usize;
    assert!(
        flat.normal[centre][2] > 0.999,
        "unmapped quad faces the camera: {:?}",
        flat.normal[centre]
    );
    let n = mapped.normal[centre];
    assert!(
        (n[0] - 0.6).abs() < 0.02 && n[1].abs() < 0.02 && (n[2] - 0.8).abs() < 0.02,
        "mapped normal {n:?}"
    );
}

/// KHR_materials_specular's specular texture scales the specular weight by its A channel: on a
/// black quad (no diffuse) the half whose texels have A = 0 reflects nothing, the half with
/// A = 255 reflects its dielectric specular; the RGB channels (255 everywhere) do not count.
#[test]
fn specular_texture_scales_the_specular_by_its_alpha() {
    let mut rgba8 = Vec::new();
    for _y in 0..4 {
        for x in 0..4 {
            rgba8.extend_from_slice(&[255, 255, 255, if x < 2 { 0 } else { 255 }]);
        }
    }
    let mut scene = Scene::default();
    scene.textures.push(Texture {
        width: 4,
        height: 4,
        rgba8,
    });
    let mut material = common::material(0.0, 1.0);
    material.specular_texture = Some(0);
    scene.add_mesh_instance(shapes::quad(1.0, 1.0), material, Mat4::IDENTITY);
    let size = 32u32;
    let out = common::render(&scene, &[common::constant_light(1.0)], size, 16, 1);
    let px = |ndc: f32| ((ndc + 1.0) * 0.5 * size as f32) as u32;
    let lum = |x: f32| {
        let p = out.lit[0][(px(0.0) * size + px(x)) as usize];
        (p[0] + p[1] + p[2]) / 3.0
    };
    let (off, on) = (lum(-0.31), lum(0.31));
    println!("specular texture: A = 0 reflects {off}, A = 255 reflects {on}");
    assert!(off.abs() < 1e-6, "A = 0: no specular, got {off}");
    assert!(on > 0.02, "A = 255: the full specular layer, got {on}");
}
