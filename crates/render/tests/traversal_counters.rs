//! The traversal counters (crates/render/src/counters.rs, `integrator_counters`): exact counts
//! where they are known, the same image as the production kernel, and the ICT heads — 35×
//! slower per ray than the other heads on an H100, 31× on Mesa 26's lavapipe, from NaN rays
//! (BENCHMARKS.md) — costing the traversal about what a comparable scan costs, with no stack
//! overflow and no ray with a NaN or infinite origin or direction. Mesa 25 (CI) never made those NaNs; run this on
//! Mesa 26 with `scripts/lavapipe-trixie.sh test`.

mod common;

use std::path::Path;

use glam::{Mat4, Vec3};
use lightfarm_render::counters::TraversalSummary;
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::scene::{shapes, Camera, Scene};
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{RenderOutput, RenderSettings, Renderer};

fn counting() -> Renderer {
    let mut r = Renderer::new(&DeviceRequest::Auto).expect("a Vulkan device");
    r.set_traversal_counters(true)
        .expect("the counters' kernel");
    r
}

fn render(
    r: &Renderer,
    scene: &Scene,
    camera: Camera,
    size: u32,
    spp: u32,
    max_depth: u32,
) -> RenderOutput {
    let settings = RenderSettings {
        width: size,
        height: size,
        spp,
        seed: 3,
        max_depth,
        rr_depth: 5,
        camera,
        passes: Vec::new(),
    };
    let packed = pack_scene(scene).expect("pack");
    r.render(
        &packed,
        &[common::constant_light(1.0)],
        &settings,
        &mut |_| {},
    )
    .expect("render")
}

/// Pixels of a 32² render at `spp` of `scene`: (background pixels whose every ray ended after one
/// node test and no primitive test, object pixels), after `check` of every pixel's counts
/// (rays, node tests, primitive tests, BLAS entries, covered).
fn classify(scene: &Scene, spp: u32, check: impl Fn(usize, [u32; 4], bool)) -> (usize, usize) {
    let r = counting();
    let out = render(&r, scene, common::front_camera(), 32, spp, 2);
    let t = out.traversal.expect("counters");
    let (mut root_only, mut covered) = (0, 0);
    for p in 0..32 * 32 {
        assert_eq!(t.overflows[p], 0);
        let counts = [t.rays[p], t.nodes[p], t.prims[p], t.blas[p]];
        check(p, counts, out.mask[p] == 1.0);
        if out.mask[p] == 0.0 && counts[..3] == [spp, spp, 0] {
            root_only += 1;
        } else if out.mask[p] == 1.0 {
            covered += 1;
        }
    }
    (root_only, covered)
}

#[test]
fn one_instance_rays_start_at_its_blas_root() {
    // One sphere, one instance: the walk skips the TLAS (SCENE_ONE_INSTANCE), so every ray enters
    // the sphere's BLAS. A camera ray far from the sphere ends after the BLAS root's test; one
    // onto it goes deeper, and so do its shadow and bounce rays.
    let spp = 4;
    let (root_only, covered) = classify(
        &common::sphere_scene(0.5),
        spp,
        |p, [rays, nodes, prims, blas], on| {
            assert_eq!(blas, rays, "pixel {p}: every ray enters the one BLAS");
            if on {
                assert!(rays > spp, "pixel {p}: shadow and bounce rays");
                assert!(
                    nodes >= rays + spp && prims >= spp,
                    "pixel {p}: {nodes} nodes, {prims} primitives for {rays} rays"
                );
            }
        },
    );
    assert!(
        root_only > 50 && covered > 50,
        "{root_only} background, {covered} sphere pixels"
    );
}

#[test]
fn rays_that_miss_test_the_tlas_root_only_and_rays_onto_a_sphere_enter_its_blas() {
    // Two spheres, two instances: a camera ray that misses both boxes ends after the TLAS root's
    // test; a camera ray onto a sphere enters its BLAS, and so do the shadow and bounce rays
    // from it except where the spawn offset puts them just outside the box (where the sphere
    // touches its box).
    let mut scene = Scene::default();
    for x in [-0.4, 0.4] {
        scene.add_mesh_instance(
            shapes::icosphere(0.3, 4),
            common::material(0.5, 0.0),
            Mat4::from_translation(Vec3::new(x, 0.0, 0.0)),
        );
    }
    let spp = 4;
    let (root_only, covered) = classify(&scene, spp, |p, [rays, nodes, prims, blas], on| {
        if !on && nodes == spp {
            assert_eq!(
                (rays, prims, blas),
                (spp, 0, 0),
                "background pixel {p}: rays, primitive tests, BLAS entries"
            );
        }
        if on {
            assert!(rays > spp, "pixel {p}: shadow and bounce rays");
            // A ray enters each sphere's BLAS at most once.
            assert!(
                (spp..=2 * rays).contains(&blas),
                "pixel {p}: {blas} BLAS entries for {rays} rays"
            );
            assert!(
                nodes >= 2 * rays && prims >= spp,
                "pixel {p}: {nodes} nodes"
            );
        }
    });
    assert!(
        root_only > 50 && covered > 50,
        "{root_only} background, {covered} sphere pixels"
    );
}

#[test]
fn counting_renders_the_production_kernels_image() {
    let mut scene = common::sphere_scene(0.7);
    scene.add_mesh_instance(
        shapes::quad(3.0, 3.0),
        common::material(0.5, 0.5),
        Mat4::from_translation(Vec3::new(0.0, -0.5, 0.0))
            * Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_2),
    );
    let a = render(common::renderer(), &scene, common::front_camera(), 24, 4, 8);
    let b = render(&counting(), &scene, common::front_camera(), 24, 4, 8);
    assert!(a.traversal.is_none());
    assert_eq!(a.stats.rays, b.stats.rays, "the same rays");
    assert_eq!(a.lit, b.lit, "the same image");
    let t = b.traversal.expect("counters").summary();
    assert_eq!(t.rays, b.stats.rays, "every ray counted once");
}

fn head(name: &str) -> (Scene, Camera) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/heads")
        .join(name);
    let scene = Scene::load_gltf(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (min, max) = scene.world_bounds().expect("bounds");
    (scene, Camera::frame_bounds(min, max, 1.0))
}

fn head_counts(r: &Renderer, name: &str) -> (TraversalSummary, usize) {
    let (scene, camera) = head(name);
    let out = render(r, &scene, camera, 32, 4, 8);
    let t = out.traversal.expect("counters").summary();
    println!("{name}: {} triangles, {t:?}", out.stats.triangles);
    // A NaN shading frame (the ICT heads' eyes, meshes without UVs, before 2026-12-05 on
    // devices that flush denormals) sends NaN rays on.
    assert_eq!(
        t.nonfinite, 0,
        "{name}: rays with a NaN or infinite origin or direction"
    );
    (t, out.stats.triangles)
}

#[test]
fn the_ict_heads_cost_the_traversal_what_a_comparable_scan_costs() {
    let r = counting();
    let (scan, scan_tris) = head_counts(&r, "mh_head_01_f_young_caucasian.glb");
    let (lee, _) = head_counts(&r, "LeePerrySmith_textured.glb");
    for ict in ["ict_head_seed7_1.glb", "ict_head_seed7_2.glb"] {
        let (t, tris) = head_counts(&r, ict);
        assert_eq!(t.overflows, 0, "{ict}: stack overflows");
        assert!(t.max_depth < 24, "{ict}: stack depth {}", t.max_depth);
        // A BVH's cost per ray grows with the log of its size: allow 2× for the other mesh,
        // whatever its triangle count (the ICT heads have ~3× the scans').
        for (other, o) in [("the MakeHuman scan", &scan), ("LeePerrySmith", &lee)] {
            let ratio = t.nodes_per_ray / o.nodes_per_ray;
            let prims = t.prims_per_ray / o.prims_per_ray;
            assert!(
                (0.5..2.0).contains(&ratio) && (0.5..2.0).contains(&prims),
                "{ict} ({tris} triangles) against {other} ({scan_tris}): node tests per ray \
                 ×{ratio:.2}, primitive tests ×{prims:.2}"
            );
        }
    }
}

#[test]
fn simd_lanes_are_all_busy_when_every_ray_does_the_same_work() {
    // A sphere far to the side: every camera ray misses it and its walk is one turn of the BLAS
    // loop (the root's test, no child hit), the same in every lane, so every lane of every
    // SIMD group takes part in every turn, and no primitive is tested. 16² keeps every group
    // full on 8- and 32-wide devices.
    let mut scene = Scene::default();
    scene.add_mesh_instance(
        shapes::icosphere(0.5, 3),
        common::material(0.5, 0.0),
        Mat4::from_translation(Vec3::new(100.0, 0.0, 0.0)),
    );
    let r = counting();
    let t = render(&r, &scene, common::front_camera(), 16, 2, 2)
        .traversal
        .expect("counters")
        .summary();
    assert!(
        t.simd_width.is_power_of_two() && t.simd_width <= 128,
        "SIMD width {}",
        t.simd_width
    );
    assert_eq!(t.rays, 16 * 16 * 2);
    assert_eq!(t.loop_lanes_busy, Some(1.0), "{t:?}");
    assert_eq!(t.prim_lanes_busy, None, "{t:?}");
}

#[test]
fn simd_lanes_wait_for_each_other_on_a_sphere() {
    // Camera rays onto the sphere and off it, then shadow and bounce rays in random
    // directions: lanes of a group end their walks at different turns, and only some lanes of
    // a group have a leaf's triangles to test at a time.
    let r = counting();
    let t = render(
        &r,
        &common::sphere_scene(0.5),
        common::front_camera(),
        32,
        4,
        4,
    )
    .traversal
    .expect("counters")
    .summary();
    let busy = t.loop_lanes_busy.expect("BLAS loop turns");
    let prims = t.prim_lanes_busy.expect("primitive tests");
    assert!(busy > 0.0 && busy < 1.0, "{t:?}");
    assert!(prims > 0.0 && prims < busy, "{t:?}");
}
