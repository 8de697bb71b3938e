//! Writes the benchmark's analytic scene: a diffuse sphere (radius 0.5 at the origin, albedo 0.8,
//! specular 0) as a .glb, the same scene bench/mitsuba_ref.py builds for Mitsuba.
//! Usage: cargo run --example bench_scene -- OUT.glb [SPECULAR ROUGHNESS]  (default 0 1: pure diffuse)

use glam::Mat4;
use lightfarm_render::scene::{shapes, write_glb, Material, Scene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .ok_or("usage: bench_scene OUT.glb [SPECULAR ROUGHNESS]")?;
    let specular: f32 = args.get(2).map_or(Ok(0.0), |s| s.parse())?;
    let roughness: f32 = args.get(3).map_or(Ok(1.0), |s| s.parse())?;
    let mut scene = Scene::default();
    let material = Material {
        name: "bench 0.8".into(),
        base_color: [0.8, 0.8, 0.8, 1.0],
        metallic: 0.0,
        roughness,
        specular,
        ..Material::default()
    };
    scene.add_mesh_instance(shapes::icosphere(0.5, 6), material, Mat4::IDENTITY);
    write_glb(&scene, std::path::Path::new(out))?;
    Ok(())
}
