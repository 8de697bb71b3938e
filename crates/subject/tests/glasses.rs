//! Procedural glasses, anchors of any glasses model, and their fit to real heads.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use glam::Vec3;
use lightfarm_render::scene::{shapes, write_glb, Material, Scene};
use lightfarm_subject::glasses::{
    fit_glasses, glasses_anchors, place_glasses, procedural_glasses, FrameStyle,
};
use lightfarm_subject::{HeadSurface, Landmarks, SubjectError};

const ASSETS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets");
const MM: f32 = 0.001;

fn asset(rel: &str) -> PathBuf {
    Path::new(ASSETS).join(rel)
}

fn models() -> Vec<(&'static str, Scene)> {
    let khronos = Scene::load_gltf(&asset("accessories/SunglassesKhronos.glb"))
        .expect("the Khronos sunglasses load");
    vec![
        ("round", procedural_glasses(FrameStyle::Round)),
        ("rect", procedural_glasses(FrameStyle::Rectangular)),
        ("khronos", khronos),
    ]
}

struct Head {
    name: &'static str,
    lm: Landmarks,
    skin: SkinGrid,
}

fn v(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x, y, z)
}

/// Three real heads (two MakeHuman, one ICT), loaded as the assembler loads them: canonical
/// frame, skin surface, detected landmarks.
fn heads() -> Vec<Head> {
    let catalog = lightfarm_scene::Catalog::builtin().expect("catalog");
    [
        "mh01_f_young_caucasian",
        "mh04_m_middleaged_caucasian",
        "ict_seed7_1",
    ]
    .into_iter()
    .map(|name| {
        let a = catalog
            .get(name)
            .unwrap_or_else(|| panic!("{name} in the catalog"));
        let head = lightfarm_subject::Head::load(a, &catalog.path_of(a), &BTreeMap::new())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        Head {
            name,
            lm: head.landmarks,
            skin: SkinGrid::new(head.surface),
        }
    })
    .collect()
}

/// Skin triangles bucketed in a uniform grid for signed-distance queries.
struct SkinGrid {
    surface: HeadSurface,
    cells: HashMap<[i32; 3], Vec<usize>>,
}

const CELL: f32 = 0.01;

fn cell_of(p: Vec3) -> [i32; 3] {
    let c = (p / CELL).floor();
    [c.x as i32, c.y as i32, c.z as i32]
}

impl SkinGrid {
    fn new(surface: HeadSurface) -> SkinGrid {
        let mut cells: HashMap<[i32; 3], Vec<usize>> = HashMap::new();
        for (t, tri) in surface.triangles.iter().enumerate() {
            let p = tri.map(|i| surface.positions[i as usize]);
            let (lo, hi) = (
                cell_of(p[0].min(p[1]).min(p[2])),
                cell_of(p[0].max(p[1]).max(p[2])),
            );
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        cells.entry([x, y, z]).or_default().push(t);
                    }
                }
            }
        }
        SkinGrid { surface, cells }
    }

    /// Signed distance to the skin within ~1 cell: negative inside (against the skin normal
    /// at the closest point); `None` when no skin is near.
    fn signed_distance(&self, p: Vec3) -> Option<f32> {
        let c = cell_of(p);
        let mut best: Option<(f32, Vec3, Vec3)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(tris) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for &t in tris {
                        let idx = self.surface.triangles[t];
                        let [a, b, cc] = idx.map(|i| self.surface.positions[i as usize]);
                        let (q, bary, interior) = closest_on_triangle(p, a, b, cc);
                        let d = p.distance_squared(q);
                        if best.is_none_or(|(bd, _, _)| d < bd) {
                            // Inside a face its plane decides; on an edge or corner the
                            // interpolated vertex normal does, as the face normal is ambiguous.
                            let normal = if interior {
                                (b - a).cross(cc - a)
                            } else {
                                let [na, nb, nc] = idx.map(|i| self.surface.normals[i as usize]);
                                na * bary.x + nb * bary.y + nc * bary.z
                            };
                            best = Some((d, q, normal));
                        }
                    }
                }
            }
        }
        best.map(|(d, q, n)| {
            let d = d.sqrt();
            if (p - q).dot(n) < 0.0 {
                -d
            } else {
                d
            }
        })
    }
}

/// Closest point on triangle abc (Ericson, Real-Time Collision Detection 5.1.5): the point,
/// its barycentric coordinates, and whether it lies strictly inside the face.
fn closest_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, Vec3, bool) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, Vec3::X, false);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, Vec3::Y, false);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, Vec3::new(1.0 - v, v, 0.0), false);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, Vec3::Z, false);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, Vec3::new(1.0 - w, 0.0, w), false);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, Vec3::new(0.0, 1.0 - w, w), false);
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (a + ab * v + ac * w, Vec3::new(1.0 - v - w, v, w), true)
}

/// All vertices of a scene in world space.
fn world_vertices(scene: &Scene) -> Vec<Vec3> {
    scene
        .instances
        .iter()
        .flat_map(|inst| {
            scene.meshes[inst.mesh as usize]
                .positions
                .iter()
                .map(move |p| inst.transform.transform_point3(Vec3::from(*p)))
        })
        .collect()
}

fn assert_near(what: &str, got: Vec3, want: Vec3, tol: f32) {
    assert!(
        got.distance(want) <= tol,
        "{what}: {got:?} is {:.2} mm from {want:?} (tolerance {:.1} mm)",
        got.distance(want) / MM,
        tol / MM
    );
}

#[test]
fn procedural_anchors_match_their_construction() {
    for style in [FrameStyle::Round, FrameStyle::Rectangular] {
        let a = glasses_anchors(&procedural_glasses(style)).expect("anchors");
        let what = format!("{style:?}");
        // Lens centroids sit slightly behind z = 0 because the lenses are curved menisci.
        assert_near(
            &format!("{what} left lens"),
            a.lens_left,
            v(0.032, 0.0, -0.001),
            1.5 * MM,
        );
        assert_near(
            &format!("{what} right lens"),
            a.lens_right,
            v(-0.032, 0.0, -0.001),
            1.5 * MM,
        );
        assert!((a.lens_left.x - 0.032).abs() < 0.05 * MM, "{what}: {a:?}");
        assert!((a.lens_right.x + 0.032).abs() < 0.05 * MM, "{what}: {a:?}");
        assert!(
            a.forward.dot(Vec3::Z) > 0.9999,
            "{what}: forward {:?}",
            a.forward
        );
        assert!(a.up.dot(Vec3::Y) > 0.9999, "{what}: up {:?}", a.up);
        // The temples bend down around the ear from (±0.069, −0.002, −0.100).
        assert_near(
            &format!("{what} left ear"),
            a.ear_left,
            v(0.069, -0.002, -0.100),
            5.0 * MM,
        );
        assert_near(
            &format!("{what} right ear"),
            a.ear_right,
            v(-0.069, -0.002, -0.100),
            5.0 * MM,
        );
    }
}

#[test]
fn khronos_sunglasses_anchors() {
    let scene = Scene::load_gltf(&asset("accessories/SunglassesKhronos.glb")).expect("load");
    let lens_materials: Vec<&Material> = scene
        .materials
        .iter()
        .filter(|m| m.name.contains("lens"))
        .collect();
    assert!(
        lens_materials.len() == 2 && lens_materials.iter().all(|m| m.transmission == 1.0),
        "the loader sees KHR_materials_transmission on the Khronos lenses: {lens_materials:?}"
    );
    let a = glasses_anchors(&scene).expect("anchors");
    println!("Khronos sunglasses: {a:?}");
    // Authored in metres, +Y up, looking down +Z, the lens centres 78 mm apart at y ≈ 31 mm.
    assert!(a.forward.dot(Vec3::Z) > 0.99, "forward {:?}", a.forward);
    assert!(a.up.dot(Vec3::Y) > 0.99, "up {:?}", a.up);
    assert!(a.lens_left.x > 0.03 && a.lens_right.x < -0.03, "{a:?}");
    assert!(
        (a.lens_left.x + a.lens_right.x).abs() < 1.0 * MM,
        "asymmetric lenses: {a:?}"
    );
    // Only the "lens" materials count: the nose pads are transmissive too.
    assert_near(
        "left lens",
        a.lens_left,
        v(0.0392, 0.0309, 0.0009),
        0.5 * MM,
    );
    assert_near(
        "right lens",
        a.lens_right,
        v(-0.0389, 0.0309, 0.0009),
        0.5 * MM,
    );
    // The ear hooks bend down between 105 and 140 mm behind the lenses.
    for ear in [a.ear_left, a.ear_right] {
        assert!(ear.z < -0.105 && ear.z > -0.14, "ear rest point {ear:?}");
        assert!(ear.x.abs() > 0.06, "ear rest point {ear:?}");
    }
    assert!(a.ear_left.x > 0.0 && a.ear_right.x < 0.0, "{a:?}");

    // A file whose lenses carry no transmission is read by material name instead.
    let mut opaque = scene.clone();
    for m in &mut opaque.materials {
        m.transmission = 0.0;
    }
    let b = glasses_anchors(&opaque).expect("anchors by name");
    assert_near("left lens by name", b.lens_left, a.lens_left, 0.01 * MM);
}

/// Lens centres after [`fit_glasses`] alone, and the nose clearance.
#[test]
fn fit_puts_lenses_in_front_of_the_eyes() {
    let heads = heads();
    for (model, scene) in models() {
        let a = glasses_anchors(&scene).expect("anchors");
        for head in &heads {
            let what = format!("{model} on {}", head.name);
            let lm = &head.lm;
            let m = fit_glasses(&a, lm);
            let left = m.transform_point3(a.lens_left);
            let right = m.transform_point3(a.lens_right);
            assert!(left.x > 0.0 && right.x < 0.0, "{what}: left lens not on +X");
            for (lens, eye) in [(left, lm.eye_left), (right, lm.eye_right)] {
                let d = lens - eye;
                assert!(
                    d.x.abs() <= 6.0 * MM && d.y.abs() <= 6.0 * MM,
                    "{what}: lens {lens:?} is off its eye {eye:?} by {d:?}"
                );
                // A nose bridge more than 32 mm in front of the eyes (the ICT head's) pushes
                // the lenses further out than that; the nose wins.
                let max = (35.0 * MM).max(lm.nose_bridge.z + 4.0 * MM - eye.z);
                assert!(
                    d.z >= 15.0 * MM && d.z <= max,
                    "{what}: lens {:.1} mm in front of the eye centre",
                    d.z / MM
                );
                assert!(
                    lens.z >= lm.nose_bridge.z + 2.5 * MM,
                    "{what}: lens plane {:.1} mm in front of the nose bridge",
                    (lens.z - lm.nose_bridge.z) / MM
                );
            }
            let f = m.transform_vector3(a.forward).normalize();
            assert!(
                f.z > 15f32.to_radians().cos() - 1e-4,
                "{what}: pitched beyond 15°: {f:?}"
            );
        }
    }
}

/// The complete placement: temples on the ears, nothing through the skin.
#[test]
fn placed_glasses_rest_on_the_ears_outside_the_skin() {
    let heads = heads();
    for (model, scene) in models() {
        for head in &heads {
            let what = format!("{model} on {}", head.name);
            let placed = place_glasses(&scene, &head.lm, &head.skin.surface).expect("place");
            // Found again from the placed geometry, not from the fit's own arithmetic.
            let a = glasses_anchors(&placed).expect("anchors of the placed glasses");
            assert_near(
                &format!("{what}: left temple"),
                a.ear_left,
                head.lm.ear_left,
                15.0 * MM,
            );
            assert_near(
                &format!("{what}: right temple"),
                a.ear_right,
                head.lm.ear_right,
                15.0 * MM,
            );
            assert!(a.lens_left.x > 0.0, "{what}: left lens on the −X side");
            for (lens, eye) in [
                (a.lens_left, head.lm.eye_left),
                (a.lens_right, head.lm.eye_right),
            ] {
                let d = lens - eye;
                // Skin contact (brows, a high nose) may push the frame up to 6 mm further out
                // than the landmark fit; the ICT head's nose bridge alone asks for 46 mm.
                let max = (35.0 * MM).max(head.lm.nose_bridge.z + 3.0 * MM - eye.z) + 6.0 * MM;
                assert!(
                    d.x.abs() <= 6.0 * MM
                        && d.y.abs() <= 6.0 * MM
                        && d.z >= 15.0 * MM
                        && d.z <= max,
                    "{what}: lens {lens:?} is off its eye {eye:?} by {:.1?} mm",
                    d / MM
                );
            }

            let vertices = world_vertices(&placed);
            let mut inside = 0;
            let mut deepest = 0.0f32;
            for p in &vertices {
                if let Some(d) = head.skin.signed_distance(*p) {
                    if d < 0.0 {
                        inside += 1;
                        deepest = deepest.max(-d);
                    }
                }
            }
            let fraction = inside as f32 / vertices.len() as f32;
            println!(
                "{what}: {inside}/{} vertices inside the skin, deepest {:.2} mm",
                vertices.len(),
                deepest / MM
            );
            assert!(
                fraction <= 0.01 && deepest <= 3.0 * MM,
                "{what}: {inside} of {} vertices inside the skin, deepest {:.2} mm",
                vertices.len(),
                deepest / MM
            );
        }
    }
}

/// Without a skin surface only the temples move: the front stays where the fit puts it.
#[test]
fn placing_without_skin_keeps_the_fitted_front() {
    let lm = heads().swap_remove(0).lm;
    for (model, scene) in models() {
        let a = glasses_anchors(&scene).expect("anchors");
        let m = fit_glasses(&a, &lm);
        let placed = place_glasses(&scene, &lm, &HeadSurface::default()).expect("place");
        let b = glasses_anchors(&placed).expect("anchors of the placed glasses");
        assert_near(
            &format!("{model}: left lens"),
            b.lens_left,
            m.transform_point3(a.lens_left),
            0.01 * MM,
        );
        assert_near(
            &format!("{model}: right lens"),
            b.lens_right,
            m.transform_point3(a.lens_right),
            0.01 * MM,
        );
        let spread = b.ear_left.x - b.ear_right.x;
        let unbent = (m.transform_point3(a.ear_left) - m.transform_point3(a.ear_right)).x;
        assert!(
            spread > unbent + 10.0 * MM,
            "{model}: temples not spread ({spread} vs {unbent})"
        );
    }
}

#[test]
fn lenses_are_closed_dielectric_slabs_after_a_round_trip() {
    for style in [FrameStyle::Round, FrameStyle::Rectangular] {
        let path = std::env::temp_dir().join(format!(
            "lightfarm_glasses_{style:?}_{}.glb",
            std::process::id()
        ));
        write_glb(&procedural_glasses(style), &path).expect("write");
        let scene = Scene::load_gltf(&path).expect("load");
        let _ = std::fs::remove_file(&path);

        let lens: Vec<u32> = (0..scene.materials.len() as u32)
            .filter(|&m| scene.materials[m as usize].transmission > 0.0)
            .collect();
        assert_eq!(lens.len(), 1, "{style:?}: one lens material");
        let mat = &scene.materials[lens[0] as usize];
        assert_eq!(
            (mat.transmission, mat.ior, mat.roughness),
            (1.0, 1.5, 0.0),
            "{style:?}"
        );
        assert_eq!(mat.metallic, 0.0, "{style:?}");

        // Weld by position: faces and edge band have their own vertices (hard edges).
        let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
        let mut tris: Vec<[u32; 3]> = Vec::new();
        let mut volume = [0.0f64; 2];
        for inst in &scene.instances {
            let mesh = &scene.meshes[inst.mesh as usize];
            for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
                if mesh.triangle_materials[t] != lens[0] {
                    continue;
                }
                let p = [0, 1, 2].map(|k| Vec3::from(mesh.positions[tri[k] as usize]));
                let n = [0, 1, 2].map(|k| Vec3::from(mesh.normals[tri[k] as usize]));
                let face = (p[1] - p[0]).cross(p[2] - p[0]);
                assert!(
                    face.dot(n[0] + n[1] + n[2]) > 0.0,
                    "{style:?}: lens triangle wound against its normals"
                );
                let w = p.map(|q| {
                    let fresh = ids.len() as u32;
                    *ids.entry(q.to_array().map(f32::to_bits)).or_insert(fresh)
                });
                tris.push(w);
                let side = usize::from(p[0].x < 0.0);
                volume[side] += f64::from(p[0].dot(p[1].cross(p[2]))) / 6.0;
            }
        }
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let open = edges.values().filter(|&&n| n != 2).count();
        assert_eq!(
            open, 0,
            "{style:?}: {open} lens edges not shared by exactly 2 triangles"
        );
        // Outward winding encloses positive volume: about area × 2 mm per lens.
        for v in volume {
            assert!(v > 1.5e-6 && v < 6e-6, "{style:?}: lens volume {v} m³");
        }
    }
}

#[test]
fn procedural_models_have_a_few_thousand_triangles() {
    for style in [FrameStyle::Round, FrameStyle::Rectangular] {
        let n = procedural_glasses(style).triangle_count();
        assert!((2000..10000).contains(&n), "{style:?}: {n} triangles");
    }
}

#[test]
fn regenerated_assets_are_byte_identical() {
    for (style, file) in [
        (FrameStyle::Round, "glasses_round.glb"),
        (FrameStyle::Rectangular, "glasses_rect.glb"),
    ] {
        let fresh = std::env::temp_dir().join(format!("lightfarm_{}_{file}", std::process::id()));
        write_glb(&procedural_glasses(style), &fresh).expect("write");
        let new = std::fs::read(&fresh).expect("read back");
        let _ = std::fs::remove_file(&fresh);
        let checked_in = std::fs::read(asset(&format!("accessories/{file}"))).unwrap_or_default();
        assert!(
            new == checked_in,
            "assets/accessories/{file} differs from what the generator makes now: rerun \
             `cargo run -p lightfarm-subject --example make_glasses` and update its blake3 in \
             assets/catalog.toml"
        );
    }
}

#[test]
fn anchors_without_lenses_name_what_is_missing() {
    let mut scene = Scene::default();
    let frame = Material {
        name: "frame".to_string(),
        ..Material::default()
    };
    scene.add_mesh_instance(shapes::quad(0.1, 0.04), frame, glam::Mat4::IDENTITY);
    let err = glasses_anchors(&scene).expect_err("no lenses");
    assert!(matches!(err, SubjectError::Asset { .. }), "{err:?}");
    let text = err.to_string();
    assert!(
        text.contains("no lens triangles") && text.contains("transmission"),
        "{text}"
    );
}
