//! Generated people: determinism, diversity and robustness over many identity ids.

mod common;

use lightfarm_identity::makehuman::bust::{SLOT_EYES, SLOT_FACE, SLOT_FACE_CENTRE};
use lightfarm_identity::person::{chromophores, generate, TextureSize};
use lightfarm_identity::skin::chromophore::{ita_deg, skin_category};
use lightfarm_identity::skin::maps::{albedo_table, skin_textures, SkinLook};
use lightfarm_scene::identity::{sample_identity, IdentitySpec};

const SEED: u64 = 7;

fn person_hash(k: u64) -> String {
    let id = sample_identity(&IdentitySpec::default(), SEED, k);
    let p = generate(common::model(), &id, TextureSize::SMALL).unwrap();
    let mut h = blake3::Hasher::new();
    for m in &p.scene.meshes {
        h.update(bytemuck::cast_slice(&m.positions));
    }
    for t in &p.scene.textures {
        h.update(&t.rgba8);
    }
    h.finalize().to_hex().to_string()
}

/// Identity k is a pure function of (seed, k): the same bytes twice, and pinned by a golden
/// hash so a change of the generator is noticed (bump `identity::GENERATOR` with it).
#[test]
fn identities_are_deterministic_and_distinct() {
    let a: Vec<String> = (0..3).map(person_hash).collect();
    let b: Vec<String> = (0..3).map(person_hash).collect();
    assert_eq!(a, b, "generation is not deterministic");
    assert_ne!(a[0], a[1]);
    assert_ne!(a[1], a[2]);
    let golden = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/golden_people.txt"),
    )
    .expect("tests/data/golden_people.txt");
    let golden: Vec<&str> = golden.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(
        a, golden,
        "identities 0..3 of seed 7 changed: if intended, bump GENERATOR and update the file"
    );
}

/// Two identities differ in shape and in albedo, not just somewhere in the bytes.
#[test]
fn identities_differ_in_shape_and_colour() {
    let spec = IdentitySpec::default();
    let m = common::model();
    let p: Vec<_> = (0..2)
        .map(|k| generate(m, &sample_identity(&spec, SEED, k), TextureSize::SMALL).unwrap())
        .collect();
    // The bust's cut follows each body, so compare the shaped base meshes vertex by vertex.
    let shape = |k: u64| {
        let id = sample_identity(&spec, SEED, k);
        lightfarm_identity::person::shape_of(&id)
    };
    let (a, _) = lightfarm_identity::makehuman::bust::shaped_positions(m, &shape(0)).unwrap();
    let (b, _) = lightfarm_identity::makehuman::bust::shaped_positions(m, &shape(1)).unwrap();
    let max_d = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max);
    // Decimetres: more than 5 mm somewhere on the body.
    assert!(max_d > 0.05, "shapes differ by at most {max_d} dm");
    let ca = p[0].record.chromophores;
    let cb = p[1].record.chromophores;
    assert!(ca != cb);
}

/// Cheek-patch ITA° over 500 identities: the six categories in the spec's proportions.
#[test]
fn skin_tones_cover_the_six_categories_in_proportion() {
    let m = common::model();
    let f = m.face_uv;
    let c = f.cheeks[0];
    let r = 0.4 * f.uv_per_cm;
    let spec = IdentitySpec {
        skin_types: [1.0, 1.0, 2.0, 2.0, 1.0, 1.0],
        ..IdentitySpec::default()
    };
    let n = 500;
    let mut counts = [0usize; 6];
    for k in 0..n {
        let id = sample_identity(&spec, SEED, k);
        let look = SkinLook {
            base: chromophores(&id),
            freckles: 0.0,
            beard: 0.0,
            seed: id.skin.texture_seed,
        };
        // A 8 mm patch of the left cheek, averaged in linear light.
        let t = skin_textures(
            m,
            &look,
            &albedo_table(&look),
            [[c[0] - r, c[1] - r], [c[0] + r, c[1] + r]],
            8,
            8,
        );
        let mut sum = [0.0f64; 3];
        for px in t.albedo.rgba8.chunks_exact(4) {
            for ch in 0..3 {
                let s = f64::from(px[ch]) / 255.0;
                sum[ch] += if s <= 0.04045 {
                    s / 12.92
                } else {
                    ((s + 0.055) / 1.055).powf(2.4)
                };
            }
        }
        let rgb = sum.map(|x| x / 64.0);
        counts[usize::from(skin_category(ita_deg(rgb)) - 1)] += 1;
    }
    let w = spec.skin_types;
    let total: f64 = w.iter().sum();
    eprintln!("cheek categories over {n} identities: {counts:?}");
    for (i, &got) in counts.iter().enumerate() {
        let want = w[i] / total * n as f64;
        // The cheek is redder than the base albedo, so a few people land one category over;
        // ±35 % of the expected count (≥ 4σ of the binomial at these n) still catches a
        // model or sampler that misses a category.
        assert!(
            (got as f64 - want).abs() < 0.35 * want + 8.0,
            "category {}: {got} of {n}, expected ~{want:.0} ({counts:?})",
            i + 1
        );
    }
}

/// A few hundred consecutive identities: finite meshes, both eyes inside the head, the face
/// textured. (`lightfarm people check --count 1000` dresses and renders 1,000.)
#[test]
fn hundreds_of_identities_generate_clean_meshes() {
    let m = common::model();
    let spec = IdentitySpec::default();
    for k in 0..200 {
        let id = sample_identity(&spec, SEED, k);
        let b = lightfarm_identity::makehuman::bust::build(
            m,
            &lightfarm_identity::person::shape_of(&id),
        )
        .unwrap();
        let mesh = &b.mesh;
        assert!(
            mesh.positions.iter().flatten().all(|x| x.is_finite()),
            "identity {k}: NaN position"
        );
        assert!(
            mesh.normals.iter().all(|n| n.iter().all(|x| x.is_finite())
                && (n[0] * n[0] + n[1] * n[1] + n[2] * n[2] - 1.0).abs() < 1e-3),
            "identity {k}: bad normal"
        );
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        let mut eye = [[0.0f32; 3]; 2];
        let mut eye_n = [0usize; 2];
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let slot = mesh.triangle_materials[t];
            for &v in tri {
                let p = mesh.positions[v as usize];
                if slot == SLOT_FACE || slot == SLOT_FACE_CENTRE {
                    for a in 0..3 {
                        lo[a] = lo[a].min(p[a]);
                        hi[a] = hi[a].max(p[a]);
                    }
                } else if slot == SLOT_EYES {
                    let s = usize::from(p[0] < 0.0);
                    for a in 0..3 {
                        eye[s][a] += p[a];
                    }
                    eye_n[s] += 1;
                }
            }
        }
        for s in 0..2 {
            assert!(eye_n[s] > 0, "identity {k}: eye {s} missing");
            let c = eye[s].map(|x| x / eye_n[s] as f32);
            for a in 0..3 {
                assert!(
                    c[a] > lo[a] && c[a] < hi[a],
                    "identity {k}: eye {s} centre {c:?} outside the head {lo:?}..{hi:?}"
                );
            }
        }
        // A head is 18-27 cm tall from chin to crown in the face island.
        let h = hi[1] - lo[1];
        assert!(
            (0.15..0.35).contains(&h),
            "identity {k}: head island {h} m tall"
        );
    }
}

/// Iris colour follows the person's iris melanin, which follows skin tone: blue and grey
/// irises among light skin, brown among dark; the texture's iris shows the colour.
#[test]
fn iris_colour_follows_melanin() {
    use lightfarm_identity::eyes::{eye_texture, iris_colour, EyeLook};
    let spec = IdentitySpec::default();
    let (mut light, mut light_blue, mut dark, mut dark_light_iris) = (0, 0, 0, 0);
    for k in 0..500 {
        let id = sample_identity(&spec, SEED, k);
        assert!((0.0..=1.0).contains(&id.iris_melanin), "identity {k}");
        if id.skin.category <= 2 {
            light += 1;
            light_blue += usize::from(id.iris_melanin < 0.25);
        } else if id.skin.category >= 5 {
            dark += 1;
            dark_light_iris += usize::from(id.iris_melanin < 0.7);
        }
    }
    assert!(
        light_blue * 5 > light,
        "{light_blue} of {light} light-skinned people have blue or grey eyes"
    );
    assert_eq!(dark_light_iris, 0, "of {dark} dark-skinned people");

    let m = common::model();
    let iris_mean = |melanin: f32| {
        let tex = eye_texture(
            &m.eye_texture,
            &m.irises,
            &EyeLook {
                iris_melanin: melanin,
                vessels: 0.5,
                seed: 9,
            },
            256,
        );
        let scale = 256.0 / m.eye_texture.width as f32;
        let mut sum = [0.0f64; 3];
        let mut n = 0;
        for iris in &m.irises {
            let (cx, cy, r) = (
                iris.centre[0] * scale,
                iris.centre[1] * scale,
                iris.radius * scale,
            );
            for y in 0..256 {
                for x in 0..256 {
                    let d = ((x as f32 + 0.5 - cx).powi(2) + (y as f32 + 0.5 - cy).powi(2)).sqrt();
                    if (0.45 * r..0.8 * r).contains(&d) {
                        let i = (y * 256 + x) * 4;
                        for (s, &b) in sum.iter_mut().zip(&tex.rgba8[i..i + 3]) {
                            *s += f64::from(b);
                        }
                        n += 1;
                    }
                }
            }
        }
        sum.map(|s| s / n as f64)
    };
    let blue = iris_mean(0.0);
    let brown = iris_mean(1.0);
    assert!(blue[2] > blue[0] + 20.0, "blue iris texels {blue:?}");
    assert!(brown[0] > brown[2] + 10.0, "brown iris texels {brown:?}");
    assert!(iris_colour(0.0)[2] > iris_colour(0.0)[0]);
}
