//! obvhs builds its BVHs on every core (its `parallel` feature: PLOC, reinsertion and the
//! leaf collapse split their work across rayon's threads). A farm renders each sample on
//! whatever worker leases it, and every worker must write the same bytes, so the packed scene
//! (nodes, primitive order, segment records) must not depend on the number of threads. The
//! scene is big enough to take obvhs' parallel paths (≥ 500,000 primitives in one BLAS), and
//! holds exact duplicates, whose equal sort keys are where an unstable parallel sort could
//! order them differently.

mod common;

use common::fibres::{hair_material, hanging_strands};
use glam::Mat4;
use lightfarm_render::gpu_scene::{pack_scene, PackedScene};
use lightfarm_render::scene::{shapes, Instance, Material, Scene};

fn scene() -> Scene {
    let mut s = Scene {
        materials: vec![Material::default(), hair_material(0.5, 0.2)],
        ..Default::default()
    };
    // 26,000 strands of 12 segments, two pieces each in the BVH: 624,000 primitives, plus 2,000
    // strands repeated bit for bit.
    let mut hair = hanging_strands(26_000, 13, 0.2, 0.25, 6e-5, 11);
    let (pts, radii) = (
        hair.points[..2000 * 13].to_vec(),
        hair.radii[..2000 * 13].to_vec(),
    );
    hair.points.extend_from_slice(&pts);
    hair.radii.extend_from_slice(&radii);
    for _ in 0..2000 {
        let end = *hair.offsets.last().unwrap_or(&0);
        hair.offsets.push(end + 13);
    }
    hair.material = 1;
    s.curves.push(hair);
    // A mesh whose two copies of each face overlap exactly.
    let mut mesh = shapes::icosphere(0.1, 5);
    let n = mesh.indices.len();
    mesh.indices.extend_from_within(..n);
    s.meshes.push(mesh);
    s.instances.push(Instance {
        mesh: 0,
        transform: Mat4::IDENTITY,
    });
    s
}

fn packed_with(threads: usize, scene: &Scene) -> PackedScene {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a rayon pool")
        .install(|| pack_scene(scene))
        .expect("the test scene packs")
}

/// Everything of a packed scene the device reads, as bytes.
fn device_bytes(p: &PackedScene) -> Vec<Vec<u8>> {
    let mut out = vec![
        bytemuck::cast_slice(&p.nodes).to_vec(),
        bytemuck::cast_slice(&p.tri_pos).to_vec(),
        bytemuck::cast_slice(&p.tri_attr).to_vec(),
        bytemuck::cast_slice(&p.instances).to_vec(),
    ];
    for b in &p.curve_blas {
        out.push(bytemuck::cast_slice(&b.bvh.primitive_indices).to_vec());
    }
    for b in &p.blas {
        out.push(bytemuck::cast_slice(&b.bvh.primitive_indices).to_vec());
    }
    out
}

#[test]
fn the_packed_scene_is_the_same_for_any_thread_count() {
    let scene = scene();
    let one = packed_with(1, &scene);
    assert!(
        one.curve_blas[0].segments.len() >= 500_000,
        "{} primitives: too few for obvhs' parallel paths",
        one.curve_blas[0].segments.len()
    );
    let reference = device_bytes(&one);
    for threads in [2, 3, 8] {
        let other = device_bytes(&packed_with(threads, &scene));
        assert_eq!(other.len(), reference.len());
        for (k, (a, b)) in reference.iter().zip(&other).enumerate() {
            assert!(
                a == b,
                "{threads} threads: device array {k} differs from the one-thread build"
            );
        }
    }
}
