//! The driver's own ray queries (VK_KHR_ray_query) against the renderer's software CWBVH
//! traversal, on the same rays through the same scene: closest-hit throughput of each, and
//! whether they find the same hits. This is the measurement behind the optional ray-query path
//! of issue 15 (BENCHMARKS.md, "Ray queries on lavapipe").
//!
//! Usage: cargo run --release -p lightfarm-render --example ray_query_cost -- [SCENE.glb] [SIZE] [ROUNDS]
//! (defaults: the LeePerrySmith head, 2000, 5; SIZE 64..=2047). SIZE² camera rays from +Z, then one diffuse
//! bounce ray from each camera hit; both paths trace every set, taking turns, ROUNDS times.
//! Needs a device with VK_KHR_ray_query: lavapipe from Mesa 24.1 (`source
//! scripts/lavapipe-backports.sh`), or an RTX-class GPU.

mod rq;

use std::time::Instant;

use glam::Vec3;
use lightfarm_render::gpu_scene::{pack_scene, PackedScene};
use lightfarm_render::probe::{GpuHit, Probe, MAX_PROBE};
use lightfarm_render::scene::Scene;
use lightfarm_render::vulkan::{DeviceRequest, GpuContext};

type Ray = ([f32; 3], [f32; 3], f32, f32);
type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// A hit as (scene instance, triangle of its mesh, t), whichever path found it.
type Hit = Option<(u32, u32, f32)>;

fn compile(src: &str) -> Res<Vec<u32>> {
    let module = naga::front::wgsl::parse_str(src).map_err(|e| e.emit_to_string(src))?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string(src))?;
    // The renderer's naga options (kernel_source.rs), and no state tracking around the query:
    // the kernel uses it in the one valid order.
    let options = naga::back::spv::Options {
        lang_version: (1, 4),
        force_loop_bounding: false,
        emit_int_div_checks: false,
        ray_query_initialization_tracking: false,
        ..Default::default()
    };
    let pipeline = naga::back::spv::PipelineOptions {
        shader_stage: naga::ShaderStage::Compute,
        entry_point: "main".into(),
    };
    Ok(naga::back::spv::write_vec(
        &module,
        &info,
        &options,
        Some(&pipeline),
    )?)
}

/// xorshift64, so the bounce directions are the same every run.
struct Rand(u64);
impl Rand {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn camera_rays(lo: Vec3, hi: Vec3, size: u32) -> Vec<Ray> {
    let center = (lo + hi) * 0.5;
    let radius = (hi - lo).length() * 0.5;
    let half = 15f32.to_radians().tan();
    // Far enough that the bounding sphere fills the 30° view.
    let eye = center + Vec3::Z * (radius / 15f32.to_radians().sin());
    let mut rays = Vec::with_capacity((size * size) as usize);
    for y in 0..size {
        for x in 0..size {
            let u = ((x as f32 + 0.5) / size as f32 * 2.0 - 1.0) * half;
            let v = (1.0 - (y as f32 + 0.5) / size as f32 * 2.0) * half;
            let d = Vec3::new(u, v, -1.0).normalize();
            rays.push((eye.to_array(), d.to_array(), 0.0, f32::MAX));
        }
    }
    rays
}

/// The triangle's world-space corners.
fn corners(scene: &Scene, inst: u32, tri: u32) -> Option<[Vec3; 3]> {
    let instance = scene.instances.get(inst as usize)?;
    let mesh = scene.meshes.get(instance.mesh as usize)?;
    let mut out = [Vec3::ZERO; 3];
    for (k, c) in out.iter_mut().enumerate() {
        let vi = *mesh.indices.get(tri as usize * 3 + k)? as usize;
        *c = instance
            .transform
            .transform_point3(Vec3::from(*mesh.positions.get(vi)?));
    }
    Some(out)
}

/// From each hit, one cosine-distributed ray about the geometric normal on the side the ray
/// came from: what a diffuse bounce traces.
fn bounce_rays(scene: &Scene, rays: &[Ray], hits: &[Hit], scale: f32) -> Vec<Ray> {
    let mut rng = Rand(0x9e37_79b9_7f4a_7c15);
    let mut out = Vec::new();
    for (ray, hit) in rays.iter().zip(hits) {
        let Some((inst, tri, t)) = *hit else { continue };
        let Some([a, b, c]) = corners(scene, inst, tri) else {
            continue;
        };
        let d = Vec3::from(ray.1);
        let mut n = (b - a).cross(c - a).normalize_or_zero();
        if n == Vec3::ZERO {
            continue;
        }
        if n.dot(d) > 0.0 {
            n = -n;
        }
        let p = Vec3::from(ray.0) + d * t + n * (1e-4 * scale);
        let (r1, r2) = (rng.next(), rng.next());
        let (s, phi) = (r1.sqrt(), std::f32::consts::TAU * r2);
        let tangent = n.any_orthonormal_vector();
        let bitangent = n.cross(tangent);
        let w = tangent * (s * phi.cos()) + bitangent * (s * phi.sin()) + n * (1.0 - r1).sqrt();
        out.push((p.to_array(), w.normalize().to_array(), 0.0, f32::MAX));
    }
    out
}

fn software_hits(packed: &PackedScene, hits: &[Option<GpuHit>]) -> Vec<Hit> {
    hits.iter()
        .map(|h| {
            let h = (*h)?;
            let inst = *packed.instance_order.get(h.instance as usize)?;
            let (_, tri) = *packed.slot_triangle.get(h.slot as usize)?;
            Some((inst, tri, h.t))
        })
        .collect()
}

struct RqRun<'a> {
    dev: &'a rq::RqDevice,
    kernel: &'a rq::Kernel,
    rays_buf: usize,
    hits_buf: usize,
}

impl RqRun<'_> {
    /// Uploads the rays, traces them and reads the hits back, as `Probe::trace` does.
    fn trace(&self, rays: &[Ray]) -> Res<Vec<Hit>> {
        let mut input: Vec<[f32; 4]> = Vec::with_capacity(rays.len() * 2);
        for (o, d, tmin, tmax) in rays {
            input.push([o[0], o[1], o[2], *tmin]);
            input.push([d[0], d[1], d[2], *tmax]);
        }
        self.dev
            .write(self.rays_buf, bytemuck::cast_slice(&input))?;
        self.dev
            .submit(|_, cmd| self.kernel.record(cmd, rays.len() as u32))?;
        let out = self.dev.read_vec4(self.hits_buf, rays.len())?;
        Ok(out
            .iter()
            .map(|v| (v[0] >= 0.0).then(|| (v[1].to_bits(), v[2].to_bits(), v[0])))
            .collect())
    }
}

/// Same hit or miss, same triangle, and t within 1e-4 relative (two watertight-enough
/// intersectors can disagree on rays that graze an edge).
fn agreement(a: &[Hit], b: &[Hit]) -> (usize, usize, usize) {
    let (mut status, mut tri, mut t) = (0, 0, 0);
    for (x, y) in a.iter().zip(b) {
        match (x, y) {
            (None, None) => {}
            (Some((ia, ta, da)), Some((ib, tb, db))) => {
                if (ia, ta) != (ib, tb) {
                    tri += 1;
                }
                if (da - db).abs() > 1e-4 * da.abs().max(1.0) {
                    t += 1;
                }
            }
            _ => status += 1,
        }
    }
    (status, tri, t)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ray_query_cost: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Res<()> {
    let args: Vec<String> = std::env::args().collect();
    let default = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../assets/heads/LeePerrySmith_textured.glb"
    );
    let path = args.get(1).map_or(default, |s| s.as_str());
    let size: u32 = args.get(2).map_or(Ok(2000), |s| s.parse())?;
    let rounds: usize = args.get(3).map_or(Ok(5), |s| s.parse())?;
    // Each timing subtracts a 64-ray call, so a set must be far larger than that.
    if (size as usize).pow(2) > MAX_PROBE || size < 64 || rounds == 0 {
        return Err(format!(
            "SIZE must be 64..={} and ROUNDS ≥ 1",
            (MAX_PROBE as f64).sqrt() as u32
        )
        .into());
    }
    let scene = Scene::load_gltf(std::path::Path::new(path)).map_err(|e| format!("{path}: {e}"))?;
    if !scene.curves.is_empty() {
        eprintln!("note: the scene's curves are left out of both structures' comparison (ray queries here are triangles only)");
    }
    let (lo, hi) = scene.world_bounds().ok_or("the scene is empty")?;
    let triangles: usize = scene
        .instances
        .iter()
        .filter_map(|i| scene.meshes.get(i.mesh as usize))
        .map(|m| m.indices.len() / 3)
        .sum();

    let t0 = Instant::now();
    let packed = pack_scene(&scene)?;
    let sw_build = t0.elapsed().as_secs_f64();
    let ctx = GpuContext::new(&DeviceRequest::Auto)?;
    let probe = Probe::new(&ctx)?;

    let mut dev = rq::RqDevice::new()?;
    let t0 = Instant::now();
    let tlas = dev.build_scene(&scene)?;
    let rq_build = t0.elapsed().as_secs_f64();
    let n_max = MAX_PROBE as u64;
    let rays_buf = dev.host_buffer(n_max * 32)?;
    let hits_buf = dev.host_buffer(n_max * 16)?;
    let spirv = compile(include_str!("kernel.wgsl"))?;
    let kernel = dev.kernel(&spirv, tlas, rays_buf, hits_buf)?;
    let run = RqRun {
        dev: &dev,
        kernel: &kernel,
        rays_buf,
        hits_buf,
    };

    println!(
        "scene: {path} ({triangles} triangles, {} instances)",
        scene.instances.len()
    );
    println!(
        "software CWBVH (obvhs, the renderer's kernel): {} ; build + pack {sw_build:.3} s",
        ctx.info().name
    );
    println!(
        "ray queries (driver's BVH, VK_KHR_ray_query): {} ; BLAS + TLAS build {rq_build:.3} s",
        dev.name
    );

    let camera = camera_rays(lo, hi, size);
    let first = run.trace(&camera)?;
    let bounce = bounce_rays(&scene, &camera, &first, (hi - lo).length());
    // The per-call cost apart from tracing (uploads, submission, readback) on 64 rays.
    let tiny = &camera[..64];
    println!();
    println!("| rays | count | software M rays/s | ray-query M rays/s | ray query / software | hit or miss differs | other triangle | t differs |");
    println!("|---|---|---|---|---|---|---|---|");
    for (name, rays) in [("camera", &camera), ("diffuse bounce", &bounce)] {
        if rays.len() < 1024 {
            println!(
                "| {name} | {} | too few rays to time: frame the scene larger | | | | | |",
                rays.len()
            );
            continue;
        }
        let (mut sw, mut hq) = (Vec::new(), Vec::new());
        let mut check = (0, 0, 0);
        // An untimed round first: a driver may compile the pipeline at its first dispatch.
        probe.trace(&packed, tiny)?;
        run.trace(tiny)?;
        for round in 0..rounds {
            let t = Instant::now();
            probe.trace(&packed, tiny)?;
            let sw_fixed = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let s = probe.trace(&packed, rays)?;
            sw.push(rays.len() as f64 / (t.elapsed().as_secs_f64() - sw_fixed).max(1e-9) / 1e6);
            let t = Instant::now();
            run.trace(tiny)?;
            let rq_fixed = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let r = run.trace(rays)?;
            hq.push(rays.len() as f64 / (t.elapsed().as_secs_f64() - rq_fixed).max(1e-9) / 1e6);
            if round == 0 {
                check = agreement(&software_hits(&packed, &s), &r);
            }
        }
        let (status, tri, t) = check;
        let line = |v: &mut Vec<f64>| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(0.0, f64::max);
            let m = median(v);
            (m, format!("{m:.2} ({lo:.2}–{hi:.2})"))
        };
        let (ms, s_txt) = line(&mut sw);
        let (mq, q_txt) = line(&mut hq);
        println!(
            "| {name} | {} | {s_txt} | {q_txt} | {:.2}× | {status} | {tri} | {t} |",
            rays.len(),
            mq / ms
        );
    }
    drop(kernel);
    Ok(())
}
