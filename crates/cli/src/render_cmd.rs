//! `lightfarm render` and `lightfarm devices`.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::output::{write_exr, write_preview_png, write_rgb8_png};
use lightfarm_render::passes::Pass;
use lightfarm_render::scene::{materials_json, Camera, Scene};
use lightfarm_render::vulkan::{list_devices, DeviceRequest};
use lightfarm_render::{
    EnvLight, LightingSchedule, RenderSettings, Renderer, WalkSchedule, RENDERER_VERSION,
};

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The scene: a glTF 2.0 file (.glb or .gltf).
    #[arg(long)]
    scene: PathBuf,
    /// An HDR environment map (.hdr or .exr, lat-long). Repeat for more lightings (lit0, lit1, ...).
    #[arg(long, required = true)]
    hdri: Vec<PathBuf>,
    /// Rotation of the environment about +Y in degrees: once for all maps, or once per --hdri.
    #[arg(long, allow_hyphen_values = true)]
    hdri_rotation: Vec<f32>,
    /// Mirror the environment maps horizontally (u -> 1 - u).
    #[arg(long)]
    hdri_flip: bool,
    /// Camera as "px,py,pz:tx,ty,tz:fov_deg" (position, target, vertical field of view). Default:
    /// the scene's first glTF camera, else a framing of the scene from +Z.
    #[arg(long, allow_hyphen_values = true)]
    camera: Option<String>,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "512x512")]
    size: String,
    /// Samples per pixel (per lighting).
    #[arg(long, default_value_t = 256)]
    spp: u32,
    /// Seed of the random sequences; the same seed on the same device gives the same image.
    #[arg(long, default_value_t = 0)]
    seed: u32,
    /// Maximum path length (scattering events).
    #[arg(long, default_value_t = 8)]
    max_depth: u32,
    /// The appendix passes to add, comma-separated: diffuse, specular, sss, coat, sheen
    /// (per lighting; the five sum to lit), shadow (per lighting), id; "none" for none.
    #[arg(long, default_value = "diffuse,specular,shadow,id")]
    passes: String,
    /// Output multi-layer EXR.
    #[arg(long)]
    out: PathBuf,
    /// Write render statistics as JSON here.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Write a tone-mapped PNG of lit0 here.
    #[arg(long)]
    preview: Option<PathBuf>,
    /// Vulkan device: auto, gpu, cpu, an index from `lightfarm devices`, or part of its name.
    #[arg(long, env = "LIGHTFARM_DEVICE", default_value = "auto")]
    device: String,
    /// Where subsurface random walks run: "megakernel" (in the path's invocation) or
    /// "dispatch" (queued and run side by side by a dispatch of their own; at most 524288
    /// pixels). Same image either way; BENCHMARKS.md times both.
    #[arg(long, default_value = "megakernel")]
    walk: String,
    /// How the lightings are traced: "shared" (each camera path serves every --hdri, one shadow
    /// ray per lighting), "mixture" (shared paths, one shadow ray per vertex for all of them,
    /// aimed by the mixture of their distributions) or "separate" (each lighting traces its own
    /// paths). Same images within noise; BENCHMARKS.md times all three. --walk dispatch always
    /// traces them separately.
    #[arg(long, default_value = "shared")]
    lightings: String,
    /// Count the BVH traversal per pixel (node and primitive tests, BLAS entries, stack depth,
    /// overflows and rays with a NaN or infinite origin or direction) and write a heat map of node tests per ray here (PNG; overflowing pixels
    /// green). The totals go into --stats as "traversal". Costs a kernel compile and some speed.
    #[arg(long)]
    counters: Option<PathBuf>,
}

fn parse_size(s: &str) -> Result<(u32, u32)> {
    let parse = || -> Option<(u32, u32)> {
        let (w, h) = s.trim().split_once(['x', 'X'])?;
        Some((w.trim().parse().ok()?, h.trim().parse().ok()?))
    };
    parse().with_context(|| format!("--size '{s}' is not WIDTHxHEIGHT (e.g. --size 512x512)"))
}

fn load_lights(args: &RenderArgs) -> Result<Vec<EnvLight>> {
    let rotations: Vec<f32> = match args.hdri_rotation.len() {
        0 => vec![0.0; args.hdri.len()],
        1 => vec![args.hdri_rotation[0]; args.hdri.len()],
        n if n == args.hdri.len() => args.hdri_rotation.clone(),
        n => bail!(
            "--hdri-rotation was given {n} times for {} --hdri: give it once (for all) or once per --hdri",
            args.hdri.len()
        ),
    };
    if let Some(r) = rotations.iter().find(|r| !r.is_finite()) {
        bail!("--hdri-rotation {r} is not a finite angle in degrees");
    }
    args.hdri
        .iter()
        .zip(rotations)
        .map(|(path, rotation_deg)| {
            let hdri = Hdri::load(path).with_context(|| format!("--hdri {}", path.display()))?;
            Ok(EnvLight {
                name: path.display().to_string(),
                hdri,
                transform: EnvTransform {
                    rotation_deg,
                    flip: args.hdri_flip,
                },
            })
        })
        .collect()
}

fn choose_camera(args: &RenderArgs, scene: &Scene, aspect: f32) -> Result<Camera> {
    if let Some(c) = &args.camera {
        return Ok(Camera::parse_cli(c)?);
    }
    if let Some(c) = scene.cameras.first() {
        return Ok(*c);
    }
    let (min, max) = scene
        .world_bounds()
        .with_context(|| format!("--scene {} has no geometry to frame", args.scene.display()))?;
    Ok(Camera::frame_bounds(min, max, aspect))
}

/// `--passes a,b,c` (or `none`) as the renderer's pass list.
fn parse_passes(text: &str) -> Result<Vec<Pass>> {
    let t = text.trim();
    if t.is_empty() || t == "none" {
        return Ok(Vec::new());
    }
    let names: Vec<&str> = t.split(',').map(str::trim).collect();
    Pass::parse_list(&names).map_err(|e| anyhow::anyhow!("--passes {text}: {e}"))
}

/// Refuses an output path whose directory does not exist, naming the flag.
pub(crate) fn ensure_parent(path: &Path, flag: &str) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            bail!(
                "{flag} {}: the directory {} does not exist",
                path.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

pub fn run(args: RenderArgs) -> Result<()> {
    let (width, height) = parse_size(&args.size)?;
    ensure_parent(&args.out, "--out")?;
    if let Some(p) = &args.stats {
        ensure_parent(p, "--stats")?;
    }
    if let Some(p) = &args.preview {
        ensure_parent(p, "--preview")?;
    }
    if let Some(p) = &args.counters {
        ensure_parent(p, "--counters")?;
    }
    let device: DeviceRequest = args.device.parse().context("--device")?;
    let walk = WalkSchedule::parse(&args.walk).with_context(|| {
        format!(
            "--walk '{}' is not a schedule: use megakernel or dispatch",
            args.walk
        )
    })?;
    let lightings = LightingSchedule::parse(&args.lightings).with_context(|| {
        format!(
            "--lightings '{}' is not a schedule: use shared, mixture or separate",
            args.lightings
        )
    })?;
    let scene = Scene::load_gltf(&args.scene)
        .with_context(|| format!("--scene {}", args.scene.display()))?;
    let lights = load_lights(&args)?;
    let camera = choose_camera(&args, &scene, width as f32 / height as f32)?;
    let passes = parse_passes(&args.passes)?;
    let settings = RenderSettings {
        width,
        height,
        spp: args.spp,
        seed: args.seed,
        max_depth: args.max_depth,
        rr_depth: 5,
        camera,
        passes: passes.clone(),
    };
    settings.validate()?;

    let pack_start = std::time::Instant::now();
    let packed = pack_scene(&scene).with_context(|| format!("--scene {}", args.scene.display()))?;
    let pack_seconds = pack_start.elapsed().as_secs_f64();
    let mut renderer = Renderer::new(&device)?;
    renderer.set_walk_schedule(walk);
    renderer.set_lighting_schedule(lightings);
    renderer.set_traversal_counters(args.counters.is_some())?;
    tracing::info!(
        device = %renderer.device().name,
        triangles = packed.triangle_count,
        curve_segments = packed.segment_count,
        geometry_mib = packed.geometry_bytes() as f64 / (1 << 20) as f64,
        bvh_seconds = pack_seconds,
        "rendering"
    );

    let bar = ProgressBar::new(args.spp as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} spp (per set of paths)  eta {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let out = renderer.render(&packed, &lights, &settings, &mut |p| {
        bar.set_length(p.total);
        bar.set_position(p.done)
    })?;
    bar.finish_and_clear();

    let spec = serde_json::json!({
        "scene": args.scene.display().to_string(),
        "hdri": lights.iter().map(|l| serde_json::json!({
            "path": l.name, "rotation_deg": l.transform.rotation_deg, "flip": l.transform.flip,
        })).collect::<Vec<_>>(),
        "camera": {
            "position": camera.position.to_array(), "forward": camera.forward.to_array(),
            "up": camera.up.to_array(), "yfov_deg": camera.yfov_deg,
        },
        "width": width, "height": height, "spp": args.spp, "seed": args.seed, "max_depth": args.max_depth,
        "passes": passes.iter().map(|p| p.name()).collect::<Vec<_>>(),
    });
    let mut stats = serde_json::to_value(&out.stats)?;
    // The BVH builds and flattening, before the render's own time.
    stats["bvh_build_seconds"] = serde_json::json!(pack_seconds);
    if let (Some(path), Some(t)) = (&args.counters, &out.traversal) {
        stats["traversal"] = serde_json::to_value(t.summary())?;
        write_rgb8_png(path, width, height, &t.heat_map(None))?;
    }
    let attributes = vec![
        (
            "lightfarm.renderer".to_string(),
            RENDERER_VERSION.to_string(),
        ),
        ("lightfarm.spec".to_string(), spec.to_string()),
        // Every material parameter as loaded (after extras.lightfarm), in material order.
        (
            "lightfarm.materials".to_string(),
            materials_json(&scene).to_string(),
        ),
        ("lightfarm.stats".to_string(), stats.to_string()),
    ];
    let mut attributes = attributes;
    if passes.contains(&Pass::Id) {
        attributes.push((
            "lightfarm.id_table".to_string(),
            lightfarm_render::output::id_table_json(),
        ));
    }
    write_exr(&args.out, &out, &attributes)?;
    if let Some(p) = &args.preview {
        write_preview_png(p, &out, 0)?;
    }
    if let Some(p) = &args.stats {
        let text = serde_json::to_string_pretty(&stats)?;
        std::fs::write(p, text + "\n").with_context(|| format!("--stats {}", p.display()))?;
    }
    eprintln!(
        "{}: {}x{} x {} spp x {} lightings in {:.2} s on {} ({:.3} M samples/s, {:.2} M rays/s)",
        args.out.display(),
        width,
        height,
        args.spp,
        lights.len(),
        out.stats.seconds,
        out.stats.device,
        out.stats.samples_per_second / 1e6,
        out.stats.rays_per_second / 1e6
    );
    Ok(())
}

pub fn devices() -> Result<()> {
    for d in list_devices()? {
        println!(
            "{}: {} ({}, driver {}, Vulkan {})",
            d.index, d.name, d.kind, d.driver, d.api_version
        );
    }
    Ok(())
}
