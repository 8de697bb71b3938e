//! The shader's two-level CWBVH traversal against obvhs' CPU traversal of the same BVHs and
//! against brute force, on random rays: the same closest t and the same triangle.

mod common;

use glam::{Mat4, Quat, Vec3, Vec3A};
use lightfarm_render::gpu_scene::{pack_scene, PackedScene};
use lightfarm_render::gpu_types::SCENE_ONE_INSTANCE;
use lightfarm_render::probe::Probe;
use lightfarm_render::scene::{shapes, Scene};
use obvhs::ray::{Ray, RayHit};

/// xorshift: the test's rays are reproducible without another dependency.
struct Rand(u64);
impl Rand {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn dir(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(self.next(), self.next(), self.next()) * 2.0 - Vec3::ONE;
            let l = v.length();
            if l > 0.05 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

fn test_scene() -> Scene {
    let head = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/heads/LeePerrySmith_textured.glb");
    let mut scene = if head.exists() {
        Scene::load_gltf(&head).expect("load head")
    } else {
        eprintln!("{} missing: testing on spheres only", head.display());
        Scene::default()
    };
    let m = common::material(0.5, 0.5);
    // Two instances of one mesh (instancing), one rotated and non-uniformly scaled.
    let mesh = scene.add_mesh_instance(
        shapes::icosphere(0.1, 3),
        m.clone(),
        Mat4::from_translation(Vec3::new(0.15, 0.05, 0.1)),
    );
    scene.instances.push(lightfarm_render::scene::Instance {
        mesh,
        transform: Mat4::from_scale_rotation_translation(
            Vec3::new(1.0, 0.5, 2.0),
            Quat::from_rotation_y(0.7),
            Vec3::new(-0.2, -0.1, 0.0),
        ),
    });
    scene.add_mesh_instance(
        shapes::quad(0.5, 0.5),
        m,
        Mat4::from_translation(Vec3::new(0.0, 0.0, -0.2)),
    );
    scene
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct RefHit {
    t: f32,
    instance: u32, // scene instance index
    blas: u32,
    tri: u32,
}

fn cpu_two_level(
    packed: &PackedScene,
    scene: &Scene,
    o: Vec3,
    d: Vec3,
    brute: bool,
) -> Option<RefHit> {
    let mut best: Option<RefHit> = None;
    for (gi, &si) in packed.instance_order.iter().enumerate() {
        let bi = packed.instance_blas[gi];
        let blas = &packed.blas[bi as usize];
        let inv = scene.instances[si as usize].transform.inverse();
        let ray = Ray::new(
            Vec3A::from(inv.transform_point3(o)),
            Vec3A::from(inv.transform_vector3(d)),
            0.0,
            f32::INFINITY,
        );
        let tmax = best.map(|b| b.t).unwrap_or(f32::INFINITY);
        let mut found: Option<(f32, u32)> = None;
        if brute {
            for (k, tri) in blas.triangles.iter().enumerate() {
                let t = tri.intersect(&ray);
                if t < tmax && found.is_none_or(|f| t < f.0) {
                    found = Some((t, k as u32));
                }
            }
        } else {
            let mut hit = RayHit::none();
            let r = Ray { tmax, ..ray };
            if blas.bvh.ray_traverse(r, &mut hit, |ray, id| {
                blas.triangles[blas.bvh.primitive_indices[id] as usize].intersect(ray)
            }) {
                found = Some((hit.t, blas.bvh.primitive_indices[hit.primitive_id as usize]));
            }
        }
        if let Some((t, tri)) = found {
            best = Some(RefHit {
                t,
                instance: si,
                blas: bi,
                tri,
            });
        }
    }
    best
}

#[test]
fn gpu_traversal_matches_obvhs_and_brute_force() {
    let scene = test_scene();
    let packed = pack_scene(&scene).expect("pack");
    assert_eq!(packed.scene_flags() & SCENE_ONE_INSTANCE, 0);
    check_against_cpu(&scene, &packed, 5_000);
}

/// A scene of one instance skips the TLAS (SCENE_ONE_INSTANCE): the walk starts at the
/// instance's leaf. Rotated, non-uniformly scaled and moved, so that the ray must still be taken
/// into object space.
#[test]
fn single_instance_scene_skips_the_tlas_and_matches_obvhs() {
    let mut scene = Scene::default();
    let m = common::material(0.5, 0.5);
    scene.add_mesh_instance(
        shapes::icosphere(0.3, 3),
        m,
        Mat4::from_scale_rotation_translation(
            Vec3::new(1.0, 0.6, 1.7),
            Quat::from_rotation_z(0.4) * Quat::from_rotation_y(0.9),
            Vec3::new(0.3, -0.2, 0.1),
        ),
    );
    let packed = pack_scene(&scene).expect("pack");
    assert_ne!(packed.scene_flags() & SCENE_ONE_INSTANCE, 0);
    check_against_cpu(&scene, &packed, 3_000);
}

/// How far the shader's t may be from the CPU's on the same triangle: 1e-5 relative, more at
/// grazing incidence, where t moves by the rounding of the ray's object-space origin (each side
/// transforms it with its own order of operations) over the cosine to the triangle's normal.
fn t_tolerance(packed: &PackedScene, scene: &Scene, c: &RefHit, d: Vec3) -> f32 {
    let tri = &packed.blas[c.blas as usize].triangles[c.tri as usize];
    let n = Vec3::from((tri.v1 - tri.v0).cross(tri.v2 - tri.v0));
    let d_obj = scene.instances[c.instance as usize]
        .transform
        .inverse()
        .transform_vector3(d);
    let cos = (n.dot(d_obj) / (n.length() * d_obj.length())).abs();
    1e-5 * c.t.max(1.0) / cos.max(0.01)
}

/// 20,000 random rays, traced by the shader and by obvhs on the CPU (and by brute force): the
/// same closest t and the same triangle of the same instance.
fn check_against_cpu(scene: &Scene, packed: &PackedScene, min_hits: usize) {
    let (min, max) = scene.world_bounds().expect("bounds");
    let centre = (min + max) * 0.5;
    let radius = (max - min).length();
    let mut rng = Rand(0x9e3779b97f4a7c15);
    let mut rays = Vec::new();
    for i in 0..20_000 {
        // Half aimed at points inside the bounds from outside, half from inside in any direction.
        let (o, d) = if i % 2 == 0 {
            let o = centre + rng.dir() * radius;
            let target = min + (max - min) * Vec3::new(rng.next(), rng.next(), rng.next());
            (o, (target - o).normalize())
        } else {
            (
                min + (max - min) * Vec3::new(rng.next(), rng.next(), rng.next()),
                rng.dir(),
            )
        };
        rays.push((o, d));
    }
    let probe = Probe::new(&common::ctx()).expect("probe");
    let gpu = probe
        .trace(
            packed,
            &rays
                .iter()
                .map(|(o, d)| (o.to_array(), d.to_array(), 0.0, f32::INFINITY))
                .collect::<Vec<_>>(),
        )
        .expect("trace");
    let (mut hits, mut mismatches) = (0, Vec::new());
    for (k, ((o, d), g)) in rays.iter().zip(&gpu).enumerate() {
        let cpu = cpu_two_level(packed, scene, *o, *d, false);
        let brute = cpu_two_level(packed, scene, *o, *d, true);
        assert_eq!(
            cpu, brute,
            "ray {k}: obvhs traversal and brute force disagree"
        );
        let g = g.map(|h| {
            let (blas, tri) = packed.slot_triangle[h.slot as usize];
            RefHit {
                t: h.t,
                instance: packed.instance_order[h.instance as usize],
                blas,
                tri,
            }
        });
        match (g, cpu) {
            (None, None) => {}
            (Some(g), Some(c))
                if g.instance == c.instance
                    && g.tri == c.tri
                    && (g.t - c.t).abs() <= t_tolerance(packed, scene, &c, *d) =>
            {
                hits += 1
            }
            other => mismatches.push((k, other)),
        }
    }
    assert!(
        hits > min_hits,
        "only {hits} rays hit: the test scene is not being exercised"
    );
    assert!(
        mismatches.is_empty(),
        "{} of {} rays differ, first: {:?}",
        mismatches.len(),
        rays.len(),
        &mismatches[..mismatches.len().min(5)]
    );
}

/// The largest batch `Probe` takes is one dispatch of Vulkan's guaranteed 65,535 groups of 64:
/// it traces (every ray onto a quad, so every hit is checked), and one ray more is refused with
/// the limit in the message. The batch was 2²² once, one group over, and failed at dispatch.
#[test]
fn largest_probe_batch_traces_in_one_dispatch() {
    use lightfarm_render::probe::MAX_PROBE;
    let mut scene = Scene::default();
    scene.add_mesh_instance(
        shapes::quad(1.0, 1.0),
        common::material(0.5, 0.5),
        Mat4::IDENTITY,
    );
    let packed = pack_scene(&scene).expect("pack");
    let probe = Probe::new(&common::ctx()).expect("probe");
    let mut rng = Rand(7);
    let rays: Vec<_> = (0..MAX_PROBE)
        .map(|_| {
            let (x, y) = (rng.next() - 0.5, rng.next() - 0.5);
            ([x * 0.9, y * 0.9, 1.0], [0.0, 0.0, -1.0], 0.0, f32::MAX)
        })
        .collect();
    let hits = probe
        .trace(&packed, &rays)
        .expect("the largest batch traces");
    assert_eq!(hits.len(), MAX_PROBE);
    let missed = hits
        .iter()
        .filter(|h| !h.is_some_and(|h| (h.t - 1.0).abs() < 1e-5))
        .count();
    assert_eq!(
        missed, 0,
        "rays onto the quad that missed it or hit at t != 1"
    );
    let mut one_more = rays;
    one_more.push(one_more[0]);
    let err = probe
        .trace(&packed, &one_more)
        .expect_err("a batch over the limit is refused");
    assert!(
        err.to_string().contains(&MAX_PROBE.to_string()),
        "the refusal names the limit: {err}"
    );
}
