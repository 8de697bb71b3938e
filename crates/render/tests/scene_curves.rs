//! Fibres in glTF: `LINE_STRIP` / `LINES` primitives with `_RADIUS` load as [`Curves`], the .glb
//! writer round-trips them bit for bit, and every malformed input is an error naming the file,
//! the primitive and the problem.

#[path = "common/gltf_files.rs"]
mod gltf_files;

use std::path::{Path, PathBuf};

use glam::{Mat4, Quat, Vec3};
use gltf_files::{load, scratch_dir, write_gltf_document};
use lightfarm_render::scene::{
    shapes, write_glb, Curves, Material, MaterialModel, Scene, MAX_CURVE_SEGMENTS,
};
use serde_json::{json, Value};

const FLOAT: u32 = 5126;
const UNSIGNED_BYTE: u32 = 5121;
const UNSIGNED_INT: u32 = 5125;
const LINES: u32 = 1;
const LINE_STRIP: u32 = 3;

/// The binary buffer, views and accessors of a test document.
#[derive(Default)]
struct Doc {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Doc {
    fn accessor(&mut self, bytes: &[u8], mut accessor: Value) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views.push(json!({
            "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()
        }));
        self.bin.extend_from_slice(bytes);
        accessor["bufferView"] = json!(self.views.len() - 1);
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn positions(&mut self, p: &[[f32; 3]]) -> usize {
        let finite = p.iter().flatten().copied().filter(|c| c.is_finite());
        let lo = finite.clone().fold(f32::INFINITY, f32::min);
        let hi = finite.fold(f32::NEG_INFINITY, f32::max);
        let bytes: Vec<u8> = p.iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
        self.accessor(
            &bytes,
            json!({"componentType": FLOAT, "count": p.len(), "type": "VEC3",
                   "min": [lo, lo, lo], "max": [hi, hi, hi]}),
        )
    }

    fn floats(&mut self, v: &[f32], ty: &str, count: usize) -> usize {
        let bytes: Vec<u8> = v.iter().flat_map(|f| f.to_le_bytes()).collect();
        self.accessor(
            &bytes,
            json!({"componentType": FLOAT, "count": count, "type": ty}),
        )
    }

    fn radii(&mut self, r: &[f32]) -> usize {
        self.floats(r, "SCALAR", r.len())
    }

    fn indices(&mut self, i: &[u32]) -> usize {
        let bytes: Vec<u8> = i.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.accessor(
            &bytes,
            json!({"componentType": UNSIGNED_INT, "count": i.len(), "type": "SCALAR"}),
        )
    }

    /// Writes `<dir>/<stem>.gltf` with `meshes`, one node per entry of `nodes`, and the
    /// materials [hair (0), plain glTF (1)].
    fn write(&self, dir: &Path, stem: &str, meshes: Value, nodes: Value) -> PathBuf {
        let node_count = nodes.as_array().map_or(0, Vec::len);
        let document = json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": (0..node_count).collect::<Vec<_>>()}],
            "nodes": nodes,
            "meshes": meshes,
            "materials": [hair_material_json(), {"name": "plastic"}],
            "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": [],
        });
        write_gltf_document(dir, stem, &document, &self.bin)
    }
}

fn hair_material_json() -> Value {
    json!({
        "name": "hair",
        "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.2, 0.1, 1.0]},
        "extras": {"lightfarm": {
            "model": "hair", "melanin": 0.8, "melanin_redness": 0.35,
            "longitudinal_roughness": 0.25, "azimuthal_roughness": 0.4, "cuticle_tilt": 3.0,
            "specular_IOR": 1.6
        }}
    })
}

/// Four points along +X with radii 1, 2, 3, 4 × 10⁻⁴ m.
fn four_points() -> (Vec<[f32; 3]>, Vec<f32>) {
    let p = (0..4).map(|i| [i as f32 * 0.01, 0.1, -0.2]).collect();
    let r = (1..=4).map(|i| i as f32 * 1e-4).collect();
    (p, r)
}

fn strands(c: &Curves) -> Vec<Vec<[f32; 3]>> {
    c.offsets
        .windows(2)
        .map(|w| c.points[w[0] as usize..w[1] as usize].to_vec())
        .collect()
}

fn bits(v: &[[f32; 3]]) -> Vec<[u32; 3]> {
    v.iter().map(|p| p.map(f32::to_bits)).collect()
}

fn radius_bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|r| r.to_bits()).collect()
}

/// The load error of `path`, checked to name the file and to contain every one of `parts`.
fn load_error(path: &Path, parts: &[&str]) -> String {
    let err = match Scene::load_gltf(path) {
        Ok(_) => panic!("{} must not load", path.display()),
        Err(e) => e.to_string(),
    };
    println!("{err}");
    assert!(
        err.contains(&path.display().to_string()),
        "error does not name the file: {err}"
    );
    for part in parts {
        assert!(err.contains(part), "error lacks {part:?}: {err}");
    }
    err
}

/// A hair material with non-default fibre parameters, as a [`Scene`] holds it.
fn hair_material() -> Material {
    let mut m = Material {
        name: "auburn".into(),
        base_color: [0.4, 0.2, 0.1, 1.0],
        ..Material::default()
    };
    m.apply_model(MaterialModel::Hair);
    m.melanin = 0.7123;
    m.melanin_redness = 0.4567;
    m.longitudinal_roughness = 0.2345;
    m.azimuthal_roughness = 0.6789;
    m.cuticle_tilt_deg = -2.75;
    m.ior = 1.5432;
    m
}

/// Pseudo-random awkward floats (full mantissas), deterministic.
fn noise(state: &mut u64) -> f32 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 40) as f32 / (1u64 << 24) as f32
}

#[test]
fn write_glb_round_trips_curves_bit_exactly() {
    let dir = scratch_dir("curves-roundtrip");
    let path = dir.join("hair.glb");
    let mut scene = Scene::default();
    // A triangle mesh first, so curve meshes and materials do not sit at index 0.
    scene.add_mesh_instance(
        shapes::icosphere(0.1, 2),
        Material {
            name: "scalp".into(),
            ..Material::default()
        },
        Mat4::IDENTITY,
    );
    scene.materials.push(hair_material());
    let hair = (scene.materials.len() - 1) as u32;
    let mut state = 0x9e37_79b9_7f4a_7c15;
    let mut set = |name: &str, lengths: &[usize]| {
        let mut c = Curves {
            name: name.into(),
            material: hair,
            offsets: vec![0],
            ..Curves::default()
        };
        for &n in lengths {
            // Each strand starts where the previous one ended: the loader must keep them apart.
            let start = c.points.last().copied();
            for k in 0..n {
                let p = match (k, start) {
                    (0, Some(s)) => s,
                    _ => [
                        noise(&mut state) - 0.5,
                        noise(&mut state) * 0.3,
                        -noise(&mut state) * 1e-3,
                    ],
                };
                c.points.push(p);
                c.radii.push(1e-5 + noise(&mut state) * 7e-5);
            }
            c.offsets.push(c.points.len() as u32);
        }
        c.validate().expect("test curves are valid");
        c
    };
    let head = set("head", &[2, 5, 3, 9]);
    let brows = set("brows", &[4]);
    scene.curves = vec![head, brows];
    write_glb(&scene, &path).expect("write glb");

    let back = load(&path);
    assert_eq!(back.triangle_count(), scene.triangle_count());
    assert_eq!(back.curves.len(), 2);
    for (a, b) in scene.curves.iter().zip(&back.curves) {
        // The loader names a set after its glTF mesh and primitive.
        assert_eq!(b.name, format!("{}/0", a.name));
        assert_eq!(b.offsets, a.offsets, "{}: strands", a.name);
        assert_eq!(bits(&b.points), bits(&a.points), "{}: points", a.name);
        assert_eq!(radius_bits(&b.radii), radius_bits(&a.radii), "{}", a.name);
        let (ma, mb) = (
            &scene.materials[a.material as usize],
            &back.materials[b.material as usize],
        );
        assert_eq!(mb.name, ma.name);
        assert_eq!(mb.model, MaterialModel::Hair);
        let params = |m: &Material| {
            [
                m.melanin,
                m.melanin_redness,
                m.longitudinal_roughness,
                m.azimuthal_roughness,
                m.cuticle_tilt_deg,
                m.ior,
            ]
            .map(f32::to_bits)
        };
        assert_eq!(params(mb), params(ma), "hair parameters");
        assert_eq!(mb.base_color, ma.base_color);
    }

    // Curves without triangles are a scene of their own.
    let alone = dir.join("alone.glb");
    let only_curves = Scene {
        curves: scene.curves.clone(),
        materials: scene.materials.clone(),
        ..Scene::default()
    };
    write_glb(&only_curves, &alone).expect("write curves-only glb");
    let back = load(&alone);
    assert_eq!(back.triangle_count(), 0);
    assert_eq!(back.curves.len(), 2);
    assert_eq!(bits(&back.curves[1].points), bits(&scene.curves[1].points));
    assert!(back.world_bounds().is_some());

    // A curve set with a material that is not hair would not load back: refused at writing.
    let mut plastic = only_curves.clone();
    plastic.materials[scene.curves[0].material as usize].model = MaterialModel::Plastic;
    let err = write_glb(&plastic, &dir.join("plastic.glb")).expect_err("non-hair curves");
    assert!(err.to_string().contains("hair"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn line_strips_and_lines_load_as_strands_in_world_space() {
    let dir = scratch_dir("curves-modes");
    let mut doc = Doc::default();
    let (p, r) = four_points();
    let strip_pos = doc.positions(&p);
    let strip_r = doc.radii(&r);
    // LINES without indices: pairs (0,1) (1',2) (3,4), 1' a copy of 1, so the first two chain.
    let lines_p = vec![p[0], p[1], p[1], p[2], p[3], [0.5, 0.5, 0.5]];
    let lines_r = vec![r[0], r[1], r[1], r[2], r[3], 5e-4];
    let lines_pos = doc.positions(&lines_p);
    let lines_rad = doc.radii(&lines_r);
    // Same position, different radius: not the same vertex, so a new strand.
    let split_p = vec![p[0], p[1], p[1], p[2]];
    let split_r = vec![r[0], r[1], r[3], r[2]];
    let split_pos = doc.positions(&split_p);
    let split_rad = doc.radii(&split_r);
    let pair_idx = doc.indices(&[0, 1, 1, 2, 3, 2, 2, 0]);
    let strip_idx = doc.indices(&[3, 1, 2]);
    let tri = doc.positions(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let prim = |mode: u32, pos: usize, rad: usize, idx: Option<usize>| {
        let mut v = json!({"attributes": {"POSITION": pos, "_RADIUS": rad},
                           "mode": mode, "material": 0});
        if let Some(i) = idx {
            v["indices"] = json!(i);
        }
        v
    };
    let meshes = json!([
        {"name": "fibres", "primitives": [
            prim(LINE_STRIP, strip_pos, strip_r, None),
            prim(LINES, lines_pos, lines_rad, None),
            prim(LINES, strip_pos, strip_r, Some(pair_idx)),
            prim(LINE_STRIP, strip_pos, strip_r, Some(strip_idx)),
            prim(LINES, split_pos, split_rad, None),
        ]},
        {"name": "scalp", "primitives": [
            {"attributes": {"POSITION": tri}, "material": 1},
            prim(LINE_STRIP, strip_pos, strip_r, None),
        ]}
    ]);
    let xf = Mat4::from_scale_rotation_translation(
        Vec3::new(1.0, 2.0, 4.0),
        Quat::from_rotation_z(0.5),
        Vec3::new(0.1, -0.3, 2.0),
    );
    let nodes = json!([
        {"mesh": 0},
        {"mesh": 0, "matrix": xf.to_cols_array().to_vec()},
        {"mesh": 1},
    ]);
    let path = doc.write(&dir, "modes", meshes, nodes);
    let scene = load(&path);

    // Mesh 1 keeps its triangle and adds a curve set; every set uses the hair material.
    assert_eq!(scene.triangle_count(), 1);
    assert_eq!(scene.curves.len(), 11);
    for c in &scene.curves {
        c.validate().expect("loaded curves are valid");
        assert_eq!(c.material, 0, "{}", c.name);
    }
    let hair = &scene.materials[0];
    assert_eq!(hair.model, MaterialModel::Hair);
    assert_eq!(
        (
            hair.melanin,
            hair.melanin_redness,
            hair.longitudinal_roughness,
            hair.azimuthal_roughness,
            hair.cuticle_tilt_deg,
            hair.ior
        ),
        (0.8, 0.35, 0.25, 0.4, 3.0, 1.6)
    );
    let names: Vec<&str> = scene.curves.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "fibres/0", "fibres/1", "fibres/2", "fibres/3", "fibres/4", "fibres/0", "fibres/1",
            "fibres/2", "fibres/3", "fibres/4", "scalp/1"
        ]
    );

    let c = &scene.curves[..5];
    // LINE_STRIP: one strand over the vertices.
    assert_eq!(strands(&c[0]), vec![p.clone()]);
    assert_eq!(c[0].radii, r);
    assert_eq!(bits(&c[0].points), bits(&p));
    // LINES without indices: chained by equal position and radius.
    assert_eq!(
        strands(&c[1]),
        vec![vec![p[0], p[1], p[2]], vec![p[3], [0.5, 0.5, 0.5]]]
    );
    assert_eq!(c[1].radii, [r[0], r[1], r[2], r[3], 5e-4]);
    // LINES with indices: chained by index; (3,2) does not continue (1,2).
    assert_eq!(
        strands(&c[2]),
        vec![vec![p[0], p[1], p[2]], vec![p[3], p[2], p[0]]]
    );
    assert_eq!(c[2].radii, [r[0], r[1], r[2], r[3], r[2], r[0]]);
    // LINE_STRIP with indices: the index sequence.
    assert_eq!(strands(&c[3]), vec![vec![p[3], p[1], p[2]]]);
    // Equal position but another radius is not a shared vertex.
    assert_eq!(c[4].offsets, [0, 2, 4]);
    assert_eq!(c[4].radii, split_r);

    // The transformed node: points through the matrix, radii × cbrt(1·2·4) = 2.
    for (a, b) in scene.curves[..5].iter().zip(&scene.curves[5..10]) {
        assert_eq!(a.offsets, b.offsets);
        for (pa, pb) in a.points.iter().zip(&b.points) {
            let want = xf.transform_point3(Vec3::from(*pa));
            assert!(want.abs_diff_eq(Vec3::from(*pb), 1e-6), "{want} vs {pb:?}");
        }
        for (ra, rb) in a.radii.iter().zip(&b.radii) {
            assert!((rb - 2.0 * ra).abs() <= 1e-6 * ra, "{ra} → {rb}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// One mesh "fibres" whose primitive 0 is `primitive` (built on `doc`), written to `stem`.
fn one_primitive(dir: &Path, stem: &str, doc: &Doc, primitive: Value) -> PathBuf {
    doc.write(
        dir,
        stem,
        json!([{"name": "fibres", "primitives": [primitive]}]),
        json!([{"mesh": 0}]),
    )
}

#[test]
fn line_primitives_need_a_float_radius_per_vertex() {
    let dir = scratch_dir("curves-radius");
    let (p, r) = four_points();

    let mut doc = Doc::default();
    let pos = doc.positions(&p);
    let path = one_primitive(
        &dir,
        "no_radius",
        &doc,
        json!({"attributes": {"POSITION": pos}, "mode": LINE_STRIP, "material": 0}),
    );
    load_error(&path, &["'fibres'", "primitive 0", "LINE_STRIP", "_RADIUS"]);

    let mut doc = Doc::default();
    let pos = doc.positions(&p);
    let vec3: Vec<f32> = r.iter().flat_map(|&x| [x; 3]).collect();
    let rad = doc.floats(&vec3, "VEC3", 4);
    let path = one_primitive(
        &dir,
        "vec3_radius",
        &doc,
        json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "mode": LINES, "material": 0}),
    );
    load_error(
        &path,
        &["primitive 0", "LINES", "_RADIUS", "float", "SCALAR"],
    );

    let mut doc = Doc::default();
    let pos = doc.positions(&p);
    let bytes = [1u8, 2, 3, 4];
    let rad = doc.accessor(
        &bytes,
        json!({"componentType": UNSIGNED_BYTE, "count": 4, "type": "SCALAR", "normalized": true}),
    );
    let path = one_primitive(
        &dir,
        "byte_radius",
        &doc,
        json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "mode": LINES, "material": 0}),
    );
    load_error(&path, &["primitive 0", "_RADIUS", "float", "SCALAR"]);

    let mut doc = Doc::default();
    let pos = doc.positions(&p);
    let rad = doc.radii(&r[..3]);
    let path = one_primitive(
        &dir,
        "short_radius",
        &doc,
        json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "mode": LINES, "material": 0}),
    );
    load_error(
        &path,
        &["primitive 0", "_RADIUS has 3 elements for 4 vertices"],
    );

    for (stem, bad, shown) in [
        ("zero_radius", 0.0f32, "0"),
        ("negative_radius", -1e-4, "-0.0001"),
        ("infinite_radius", f32::INFINITY, "inf"),
        ("nan_radius", f32::NAN, "NaN"),
    ] {
        let mut doc = Doc::default();
        let pos = doc.positions(&p);
        let mut radii = r.clone();
        radii[2] = bad;
        let rad = doc.radii(&radii);
        let path = one_primitive(
            &dir,
            stem,
            &doc,
            json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "mode": LINE_STRIP,
                   "material": 0}),
        );
        let what = format!("vertex 2 has _RADIUS {shown};");
        load_error(&path, &["primitive 0", &what, "> 0"]);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_line_geometry_is_an_error_naming_the_primitive() {
    let dir = scratch_dir("curves-geometry");
    let (p, r) = four_points();
    // Primitive 1 is the bad one: the triangle before it loads.
    let with_triangle = |doc: &mut Doc, stem: &str, bad: Value| {
        let tri = doc.positions(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        doc.write(
            &dir,
            stem,
            json!([{"name": "fibres", "primitives": [
                {"attributes": {"POSITION": tri}, "material": 1}, bad]}]),
            json!([{"mesh": 0}]),
        )
    };

    let mut doc = Doc::default();
    let mut nan = p.clone();
    nan[3][1] = f32::NAN;
    let pos = doc.positions(&nan);
    let rad = doc.radii(&r);
    let path = with_triangle(
        &mut doc,
        "nan_position",
        json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "mode": LINES, "material": 0}),
    );
    load_error(
        &path,
        &["primitive 1", "vertex 3 has POSITION", "not finite"],
    );

    let mut doc = Doc::default();
    let pos = doc.positions(&p[..1]);
    let rad = doc.radii(&r[..1]);
    let path = with_triangle(
        &mut doc,
        "one_point",
        json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "mode": LINE_STRIP,
               "material": 0}),
    );
    load_error(&path, &["primitive 1", "a strand of 1 point", "at least 2"]);

    let mut doc = Doc::default();
    let pos = doc.positions(&p);
    let rad = doc.radii(&r);
    let idx = doc.indices(&[0, 1, 2]);
    let path = with_triangle(
        &mut doc,
        "odd_pairs",
        json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "indices": idx,
               "mode": LINES, "material": 0}),
    );
    load_error(&path, &["primitive 1", "3 indices, not a multiple of 2"]);

    let mut doc = Doc::default();
    let pos = doc.positions(&p);
    let rad = doc.radii(&r);
    let idx = doc.indices(&[0, 1, 1, 9]);
    let path = with_triangle(
        &mut doc,
        "bad_index",
        json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "indices": idx,
               "mode": LINES, "material": 0}),
    );
    load_error(&path, &["primitive 1", "index 9", "only 4 vertices"]);

    // A u8 index accessor claiming more segments than a curve set may have, over 4 bytes.
    let mut doc = Doc::default();
    let pos = doc.positions(&p);
    let rad = doc.radii(&r);
    let count = MAX_CURVE_SEGMENTS + 2;
    let idx = doc.accessor(
        &[0, 1, 2, 3],
        json!({"componentType": UNSIGNED_BYTE, "count": count, "type": "SCALAR"}),
    );
    let path = with_triangle(
        &mut doc,
        "absurd",
        json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "indices": idx,
               "mode": LINE_STRIP, "material": 0}),
    );
    let what = format!("{} segments, more than the {MAX_CURVE_SEGMENTS}", count - 1);
    load_error(&path, &["primitive 1", &what, "absurd segment counts"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn line_primitives_need_a_hair_material() {
    let dir = scratch_dir("curves-material");
    let (p, r) = four_points();
    for (stem, material, what) in [
        ("plastic", Some(1), "material 'plastic' of model \"gltf\""),
        ("none", None, "without a material"),
    ] {
        let mut doc = Doc::default();
        let pos = doc.positions(&p);
        let rad = doc.radii(&r);
        let mut prim = json!({"attributes": {"POSITION": pos, "_RADIUS": rad}, "mode": LINES});
        if let Some(m) = material {
            prim["material"] = json!(m);
        }
        let path = one_primitive(&dir, stem, &doc, prim);
        load_error(
            &path,
            &["primitive 0", what, "extras.lightfarm.model = \"hair\""],
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn curves_under_a_singular_node_transform_are_an_error() {
    let dir = scratch_dir("curves-node");
    let (p, r) = four_points();
    let mut doc = Doc::default();
    let pos = doc.positions(&p);
    let rad = doc.radii(&r);
    let path = doc.write(
        &dir,
        "flat",
        json!([{"name": "fibres", "primitives": [
            {"attributes": {"POSITION": pos, "_RADIUS": rad}, "mode": LINES, "material": 0}]}]),
        json!([{"mesh": 0, "scale": [1.0, 0.0, 1.0]}]),
    );
    load_error(&path, &["node 0", "fibres/0", "singular"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_file_without_triangles_or_curves_has_no_geometry() {
    let dir = scratch_dir("curves-empty");
    let path = dir.join("empty.gltf");
    let document = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "lonely"}],
    });
    std::fs::write(&path, document.to_string()).expect("write gltf");
    load_error(&path, &["no triangle or curve geometry", "_RADIUS"]);
    let _ = std::fs::remove_dir_all(&dir);
}
