//! Every built-in head shows its iris through a clear cornea: MakeHuman's cornea meshes get the
//! `cornea` model by name, ICT FaceKit's closed scleras get a cornea cap cut over each iris.

use std::collections::BTreeMap;

use glam::Vec3;
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::scene::{Camera, MaterialModel, ObjectClass, Scene};
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{EnvLight, RenderSettings, Renderer};
use lightfarm_scene::{AssetKind, Catalog};
use lightfarm_subject::Head;

fn heads() -> Vec<(String, Head)> {
    let catalog = Catalog::builtin().unwrap_or_else(|e| panic!("catalog: {e}"));
    catalog
        .of_kind(AssetKind::Head)
        .into_iter()
        .filter(|a| a.tags.get("source").map(String::as_str) != Some("scan"))
        .map(|asset| {
            let head = Head::load(asset, &catalog.path_of(asset), &BTreeMap::new())
                .unwrap_or_else(|e| panic!("{}: {e}", asset.id));
            (asset.id.clone(), head)
        })
        .collect()
}

/// World-space triangles of the scene with their material names.
fn triangles(scene: &Scene) -> Vec<([Vec3; 3], String)> {
    let mut out = Vec::new();
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh as usize];
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let p = [tri[0], tri[1], tri[2]].map(|v| {
                inst.transform
                    .transform_point3(Vec3::from(mesh.positions[v as usize]))
            });
            let m = &scene.materials[mesh.triangle_materials[t] as usize];
            out.push((p, m.name.clone()));
        }
    }
    out
}

/// Möller–Trumbore: the distance along `dir` to the triangle, if hit in front.
fn hit(o: Vec3, dir: Vec3, p: &[Vec3; 3]) -> Option<f32> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let h = dir.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-12 {
        return None;
    }
    let s = o - p[0];
    let u = s.dot(h) / det;
    let q = s.cross(e1);
    let v = dir.dot(q) / det;
    let t = e2.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some(t)
}

/// Material names met by a ray, nearest first.
fn along(tris: &[([Vec3; 3], String)], o: Vec3, dir: Vec3) -> Vec<String> {
    let mut hits: Vec<(f32, &String)> = tris
        .iter()
        .filter_map(|(p, name)| hit(o, dir, p).map(|t| (t, name)))
        .collect();
    hits.sort_by(|a, b| a.0.total_cmp(&b.0));
    hits.into_iter().map(|(_, n)| n.clone()).collect()
}

/// The centroid of each side's iris (`iris` triangles, or for MakeHuman, whose iris is painted
/// on the `eyes` ball, the front-most point of that ball), world space.
fn pupils(tris: &[([Vec3; 3], String)]) -> [Vec3; 2] {
    let side = |s: f32| {
        let irises: Vec<Vec3> = tris
            .iter()
            .filter(|(p, n)| n == "iris" && p[0].x * s > 0.0)
            .map(|(p, _)| (p[0] + p[1] + p[2]) / 3.0)
            .collect();
        if !irises.is_empty() {
            return irises.iter().sum::<Vec3>() / irises.len() as f32;
        }
        tris.iter()
            .filter(|(p, n)| n == "eyes" && p[0].x * s > 0.0)
            .flat_map(|(p, _)| p.iter().copied())
            .max_by(|a, b| a.z.total_cmp(&b.z))
            .expect("an eye on each side")
    };
    [side(1.0), side(-1.0)]
}

#[test]
fn every_built_in_head_sees_its_iris_through_a_clear_cornea() {
    for (id, head) in heads() {
        let corneas: Vec<_> = head
            .scene
            .materials
            .iter()
            .filter(|m| m.name == "cornea")
            .collect();
        assert_eq!(corneas.len(), 1, "{id}: one cornea material");
        let c = corneas[0];
        assert_eq!(
            (
                c.model,
                c.class,
                c.thin_walled,
                c.transmission,
                c.opacity,
                c.ior
            ),
            (
                MaterialModel::Cornea,
                ObjectClass::Eyes,
                true,
                1.0,
                1.0,
                1.376
            ),
            "{id}: the cornea is a clear thin sheet"
        );
        let tris = triangles(&head.scene);
        for (k, pupil) in pupils(&tris).into_iter().enumerate() {
            // From 5 cm in front of the pupil, straight back (the face looks along +Z).
            let met = along(&tris, pupil + Vec3::Z * 0.05, -Vec3::Z);
            let eye: Vec<&String> = met
                .iter()
                .filter(|n| ["cornea", "sclera", "iris", "eyes"].contains(&n.as_str()))
                .collect();
            assert_eq!(
                eye.first().map(|s| s.as_str()),
                Some("cornea"),
                "{id} eye {k}: the first eye surface in front of the pupil ({met:?})"
            );
            let behind = eye.iter().find(|n| n.as_str() != "cornea");
            assert!(
                matches!(behind.map(|s| s.as_str()), Some("iris") | Some("eyes")),
                "{id} eye {k}: behind the cornea is the iris, not an opaque shell ({met:?})"
            );
        }
    }
}

/// End to end on the ICT head: a camera looking into the eye sees the iris's colour in the
/// albedo pass (before, the sclera's 0.85 grey covered it), and the pupil's id is eyes.
#[test]
fn the_ict_iris_shows_in_the_albedo_pass() {
    let (id, head) = heads()
        .into_iter()
        .find(|(id, _)| id.starts_with("ict_"))
        .expect("an ICT head in the catalog");
    let tris = triangles(&head.scene);
    let pupil = pupils(&tris)[0];
    let iris = head
        .scene
        .materials
        .iter()
        .find(|m| m.name == "iris")
        .expect("an iris material")
        .base_color;
    let renderer = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device (lavapipe in CI)");
    let packed = pack_scene(&head.scene).expect("pack");
    let camera = Camera::look_at(pupil + Vec3::Z * 0.04, pupil, 4.0).expect("camera");
    let settings = RenderSettings {
        width: 4,
        height: 4,
        spp: 1,
        seed: 1,
        max_depth: 2,
        rr_depth: 2,
        camera,
        passes: vec![lightfarm_render::passes::Pass::Id],
    };
    let light = EnvLight {
        name: "constant".into(),
        hdri: Hdri::constant(16, 8, [1.0; 3]),
        transform: EnvTransform::default(),
    };
    let out = renderer
        .render(&packed, &[light], &settings, &mut |_| {})
        .expect("render");
    for (p, a) in out.albedo.iter().enumerate() {
        assert!(
            (0..3).all(|k| (a[k] - iris[k]).abs() < 1e-4),
            "{id} pixel {p}: albedo {a:?}, the iris is {iris:?}"
        );
        assert_eq!(out.id[p], ObjectClass::Eyes as u32 + 1, "{id} pixel {p}");
    }
}
