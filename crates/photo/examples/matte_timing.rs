//! Times MODNet matting on the public-domain portraits (BENCHMARKS.md, "Matting"): the first
//! call of a photo size (tract optimises a plan for it) and the median of `ROUNDS` later calls.
//!
//!   cargo build --workspace --examples && $CARGO_TARGET_DIR/debug/examples/matte_timing [ROUNDS]

use std::time::Instant;

use lightfarm_photo::Matting;

fn main() {
    let rounds: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5)
        .max(1);
    let matting =
        Matting::load(&lightfarm_photo::builtin_modnet()).unwrap_or_else(|e| panic!("{e}"));
    println!("photo                 size       first call ms  median ms");
    for name in ["astronaut.png", "grace_hopper.jpg", "camera.png"] {
        let path = lightfarm_scene::catalog::builtin_assets_dir()
            .join("photos")
            .join(name);
        let img = image::open(&path)
            .unwrap_or_else(|e| panic!("{}: {e}; run ./scripts/fetch-models.sh", path.display()))
            .to_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let srgb: Vec<[f32; 3]> = img
            .pixels()
            .map(|p| p.0.map(|v| f32::from(v) / 255.0))
            .collect();
        let mut times = Vec::new();
        for _ in 0..=rounds {
            let t = Instant::now();
            matting
                .alpha(&srgb, w, h)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let first = times.remove(0);
        times.sort_by(f64::total_cmp);
        println!(
            "{name:<21} {:<10} {first:>13.0} {:>10.0}",
            format!("{w}x{h}"),
            times[times.len() / 2]
        );
    }
}
